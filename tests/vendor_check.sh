#!/usr/bin/env bash
# scripts/vendor-check catches a vendored file changed outside its patch series:
# on copies of vendor/, a byte appended to a file, a file added, and a patch that no
# longer applies each make it fail naming that file or patch; an untouched copy
# passes. Run by .ci/run; needs what the check needs (cargo, crates.io or its cache).
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
check=$root/scripts/vendor-check
work=$(mktemp -d "${TMPDIR:-/tmp}/vendor-check-test.XXXXXX")
trap 'rm -rf "$work"' EXIT
failures=0
fail() { echo "tests/vendor_check.sh: FAILED: $*" >&2; failures=$((failures + 1)); }

# A fresh copy of vendor/ in $work/NAME.
copy() { rm -rf "${work:?}/$1" && cp -a "$root/vendor" "$work/$1"; }

# expect_failure NAME WHAT: the check on $work/NAME exits non-zero and says WHAT.
expect_failure() {
  local out
  if out=$("$check" "$work/$1" 2>&1); then
    fail "$1: the check passed"
    printf '%s\n' "$out" >&2
  elif ! grep -qF -- "$2" <<<"$out"; then
    fail "$1: the check failed without naming $2"
    printf '%s\n' "$out" >&2
  else
    echo "ok: $1: the check fails naming $2"
  fi
}

copy untouched
if out=$("$check" "$work/untouched" 2>&1); then
  echo "ok: an untouched copy passes"
else
  fail "an untouched copy of vendor/ does not pass"
  printf '%s\n' "$out" >&2
fi

copy edited
printf ' ' >>"$work/edited/rustdds/src/rtps/writer.rs"
expect_failure edited "rustdds/src/rtps/writer.rs differs"

copy added
echo '// not from any patch' >"$work/added/mcap/src/extra.rs"
expect_failure added "mcap/src/extra.rs is there but made by no patch"

copy stale
# A context line of the patch changed: it no longer applies.
sed -i 's/^ impl std::fmt::Debug for ServerOptions {$/ impl std::fmt::Debug for ServerOptionz {/' \
  "$work/stale/patches/foxglove/0002-handed-streams-only.patch"
if cmp -s "$root/vendor/patches/foxglove/0002-handed-streams-only.patch" \
  "$work/stale/patches/foxglove/0002-handed-streams-only.patch"; then
  fail "stale: the test's edit of 0002-handed-streams-only.patch changed nothing"
else
  expect_failure stale "patches/foxglove/0002-handed-streams-only.patch does not apply"
fi

[ "$failures" = 0 ] || exit 1
echo "tests/vendor_check.sh: all passed"
