#!/usr/bin/env bash
# Runs every row of issue 37's table (docs/benchmarks.md, "Issue 37: every row in
# one run") one after the other, each bench with its reference in the same process
# (medians of alternated rounds, printed by the bench), and keeps the summary lines
# of each in OUT/summary.txt (the full outputs beside it). Release builds.
#
#   scripts/bench-issue37.sh [OUT=target/issue37]
#   ROWS="recorder network" scripts/bench-issue37.sh
#
# Rows: foxglove (frames on `port`/`sdk_port` vs the SDK's server), network
# (networkserver frames vs raw TCP), gazebo (laser latency vs gz-transport's C++
# subscriber), zenoh (frames and motors vs Zenoh alone), recorder (raw frames to
# disk vs the bare write_all), vision (HoughLinesP and LK vs OpenCV on every
# photograph: scripts/compare_photos.py, which makes its own venv). Run it on a
# machine doing nothing else: these are two-core figures.
set -euo pipefail

REPO=$(cd "$(dirname "$0")/.." && pwd)
OUT=${1:-$REPO/target/issue37}
ROWS=${ROWS:-foxglove network gazebo zenoh recorder vision}
FEATURES=foxglove,simulator,networkserver,networkclient,gazebo,zenoh,recorder,replay
mkdir -p "$OUT"
cd "$REPO"

benches=""
for row in $ROWS; do [ "$row" = vision ] || benches="$benches --bench $row"; done
if [ -n "$benches" ]; then
    # shellcheck disable=SC2086
    cargo bench --no-default-features --features "$FEATURES" $benches --no-run 2>&1 | tail -1
fi

# The part of each bench that is the row, and the lines that sum it up.
args() { case $1 in
    foxglove|network) echo frames ;; recorder) echo write ;; *) ;; esac; }
summary() { case $1 in
    foxglove) grep -E "^frames/s|total" ;;
    network) grep -E "^frames/s|^producer|^per frame|^  [0-9]+ % of" ;;
    gazebo) grep -E "median of|LaserScan|frames/s" ;;
    zenoh) grep -E "^median|^  |median p50" ;;
    recorder) grep -E "compression none:|reference" ;;
    vision) grep -E "^OpenCV|worst" ;;
    esac; }

: > "$OUT/summary.txt"
for row in $ROWS; do
    echo "== $row $(date -u +%T) (load $(cut -d' ' -f1-3 /proc/loadavg))" | tee -a "$OUT/summary.txt"
    if [ "$row" = vision ]; then
        python3 scripts/compare_photos.py --rounds 5 > "$OUT/vision.txt" 2>&1 || echo "   (exited $?)"
    elif [ "$row" = zenoh ]; then
        # Both parts: frames, then motors.
        cargo bench -q --no-default-features --features "$FEATURES" --bench zenoh \
            > "$OUT/zenoh.txt" 2>&1 || echo "   (exited $?)"
    else
        # shellcheck disable=SC2046
        cargo bench -q --no-default-features --features "$FEATURES" --bench "$row" \
            -- $(args "$row") > "$OUT/$row.txt" 2>&1 || echo "   (exited $?)"
    fi
    summary "$row" < "$OUT/$row.txt" | tee -a "$OUT/summary.txt" || true
done
echo "outputs: $OUT/ROW.txt, summary in $OUT/summary.txt"
