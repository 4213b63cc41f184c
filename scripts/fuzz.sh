#!/usr/bin/env bash
# Fuzzes every parser of outside bytes (tests/fuzz.rs) for SECONDS per target in a
# release build, and prints each target's input count, panics, largest allocation
# and slowest input.   usage: scripts/fuzz.sh [SECONDS=60] [TARGET-SUBSTRING]
set -euo pipefail
cd "$(dirname "$0")/.."
export FUZZ_SECONDS="${1:-60}"
[ -n "${2:-}" ] && export FUZZ_TARGET="$2"
export FUZZ_SEED="${FUZZ_SEED:-$(date +%s)}"
echo "fuzz: ${FUZZ_SECONDS} s per target, seed ${FUZZ_SEED}"
cargo test --release --features full --test core -- every_parser_survives --nocapture 2>&1 | grep -E '^fuzz|panicked|panics;|allocations above|test result'
