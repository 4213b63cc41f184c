#!/usr/bin/env bash
# Runs `.ci/run` as a fresh machine would: in a new Debian 12 root made with
# debootstrap (minbase, plus gcc, git, curl and this machine's CA bundle), on a fresh
# clone of REV, with the host's Rust toolchain but an empty cargo registry, so apt,
# PyPI, npm and crates.io all start from scratch (docs/benchmarks.md, "CI on a fresh
# machine").
#
#   sudo scripts/ci-fresh-root.sh NAME [REV] > ci-NAME.log 2>&1
#
# The root is /work/deb-NAME (ROOT_DIR overrides /work); it is unmounted and removed
# at the end unless KEEP=1. Run it with nothing else on the machine: its times are
# quoted.
set -euo pipefail
name=${1:?usage: ci-fresh-root.sh NAME [REV]}
rev=${2:-HEAD}
repo=$(git -C "$(dirname "$0")/.." rev-parse --show-toplevel)
root=${ROOT_DIR:-/work}/deb-$name
t0=$SECONDS
say() { echo "== fresh-root: $1 ($((SECONDS - t0)) s)"; }

cleanup() {
  for m in root/.rustup proc dev sys tmp; do
    mountpoint -q "$root/$m" && umount -R "$root/$m" || true
  done
  [ "${KEEP:-0}" = 1 ] || rm -rf "$root"
}
trap cleanup EXIT

command -v debootstrap >/dev/null || apt-get install -y -qq debootstrap >/dev/null
[ -e "$root" ] && { echo "$root exists: remove it first" >&2; exit 1; }
debootstrap --variant=minbase bookworm "$root" http://deb.debian.org/debian >/dev/null
say "debootstrap done"

# What a machine of this kind has before CI: the CA bundle its registries need,
# pip's and npm's settings, gcc, git and curl, the Rust toolchain.
cp /etc/resolv.conf "$root/etc/"
mkdir -p "$root/usr/local/share/ca-certificates"
for f in /usr/local/share/ca-certificates/*.crt; do cp "$f" "$root/usr/local/share/ca-certificates/"; done
cp /etc/apt/sources.list.d/debian.sources "$root/etc/apt/sources.list.d/" 2>/dev/null &&
  rm -f "$root/etc/apt/sources.list"
mkdir -p "$root/etc" "$root/root/.cargo/bin" "$root/root/.rustup"
[ -e /etc/pip.conf ] && cp /etc/pip.conf "$root/etc/"
[ -e /root/.npmrc ] && cp /root/.npmrc "$root/root/"
for m in proc dev sys tmp; do mount --rbind "/$m" "$root/$m"; done
mount --rbind /root/.rustup "$root/root/.rustup"
cp -a /root/.cargo/bin/. "$root/root/.cargo/bin/"
chroot "$root" bash -c 'apt-get update -qq && apt-get install -y -qq --no-install-recommends \
  gcc libc6-dev git curl ca-certificates >/dev/null && update-ca-certificates >/dev/null'
say "base packages in"

git clone -q "$repo" "$root/root/jderobot"
git -C "$root/root/jderobot" checkout -q "$rev"
say "cloned $(git -C "$root/root/jderobot" rev-parse --short HEAD)"

set +e
chroot "$root" env -i HOME=/root CI=true TERM=dumb \
  PATH=/root/.cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
  bash -c 'cd /root/jderobot && time bash .ci/run'
rc=$?
set -e
say "ci rc=$rc"
exit $rc
