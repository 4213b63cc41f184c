#!/usr/bin/env bash
# Runs the benches a refactoring must leave unchanged (interface read, pacing, the 4.3
# network, Zenoh, the recorder, Gazebo) at an older revision and at the working tree,
# alternating before/after in one run, so both sides meet the same machine load.
# Each bench prints its own medians and ratios; this keeps their output side by side
# in OUT (one file per bench and side, rounds appended) and prints where they are.
#
#   scripts/bench-before-after.sh REV [ROUNDS=2] [OUT=target/before-after]
#   BENCHES="interfaces runtime" scripts/bench-before-after.sh 4932fd2^
#
# REV is checked out as a git worktree in BEFORE_DIR (/tmp/jderobot-before: outside
# this workspace, which cargo would refuse) and built in its own target dir
# (release, the benches' features only); nothing of the working tree is touched.
# BUILD_ONLY=1 stops after building (to build under a lock, then run without it).
set -euo pipefail

REV=${1:?usage: scripts/bench-before-after.sh REV [ROUNDS] [OUT]}
ROUNDS=${2:-2}
REPO=$(cd "$(dirname "$0")/.." && pwd)
OUT=${3:-$REPO/target/before-after}
BENCHES=${BENCHES:-interfaces runtime network zenoh recorder gazebo}
FEATURES=networkserver,networkclient,recorder,replay,simulator,zenoh,gazebo
BEFORE=${BEFORE_DIR:-${TMPDIR:-/tmp}/jderobot-before}
mkdir -p "$OUT"

if [ ! -d "$BEFORE" ]; then
    git -C "$REPO" worktree add --detach "$BEFORE" "$REV" >/dev/null
else
    git -C "$BEFORE" checkout -q --detach "$(git -C "$REPO" rev-parse "$REV")"
fi
echo "before: $(git -C "$BEFORE" log -1 --format='%h %s' | cut -c1-90)"
echo "after:  $(git -C "$REPO" log -1 --format='%h %s' | cut -c1-90) (+ working tree)"

bench_args() { local b; for b in $BENCHES; do printf -- '--bench %s ' "$b"; done; }
build() { # DIR TARGET_DIR
    (cd "$1" && CARGO_TARGET_DIR=$2 cargo bench --no-default-features --features "$FEATURES" \
        $(bench_args) --no-run 2>&1 | tail -1)
}
build "$BEFORE" "$REPO/target/before-build"
build "$REPO" "$REPO/target"
[ -z "${BUILD_ONLY:-}" ] || exit 0

run() { # SIDE DIR TARGET_DIR BENCH
    echo "== $1 $4 $(date +%T)" >> "$OUT/$4.$1.txt"
    (cd "$2" && CARGO_TARGET_DIR=$3 timeout 900 cargo bench -q --no-default-features \
        --features "$FEATURES" --bench "$4" >> "$OUT/$4.$1.txt" 2>&1) \
        || echo "   ($1 $4 exited $?)" | tee -a "$OUT/$4.$1.txt"
}
for bench in $BENCHES; do
    for round in $(seq "$ROUNDS"); do
        echo "== $bench round $round/$ROUNDS $(date +%T)"
        run before "$BEFORE" "$REPO/target/before-build" "$bench"
        run after "$REPO" "$REPO/target" "$bench"
    done
done
echo "outputs: $OUT/BENCH.{before,after}.txt"
