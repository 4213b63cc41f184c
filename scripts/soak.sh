#!/usr/bin/env bash
# Memory soak (issue 28): runs scripts/soak-server.conf (simulator + headless introrob
# + networkserver + recorder) and scripts/soak-client.conf (a networkclient that
# subscribes to it and records), samples the server's VmRSS every INTERVAL seconds
# into a CSV, and prints RSS at 1, 5, 10, 30 and 60 min, the least-squares growth
# rate over the last half of the run (at most the last 30 min), and the maximum.
#
#   scripts/soak.sh [SECONDS] [OUTDIR]      (default 3600 s, /tmp/jde-soak-PID)
#   JDEROBOT=target/release/jderobot INTERVAL=10 PORT=3011 scripts/soak.sh 600
#   SERVER_CONF=scripts/soak-server-norec.conf scripts/soak.sh   (another robot side)
#
# Old split parts of the recordings are deleted as the run goes (the newest two of
# each are kept), so the disk does not fill.
set -euo pipefail

SECS=${1:-3600}
OUT=${2:-/tmp/jde-soak-$$}
INTERVAL=${INTERVAL:-10}
PORT=${PORT:-3011}
SERVER_CONF=${SERVER_CONF:-scripts/soak-server.conf}
REPO=$(cd "$(dirname "$0")/.." && pwd)
BIN=${JDEROBOT:-$REPO/target/release/jderobot}
[ -x "$BIN" ] || { echo "soak.sh: no jderobot binary at $BIN (set JDEROBOT=...)" >&2; exit 2; }
mkdir -p "$OUT"

conf_of() { case $1 in server) case $SERVER_CONF in /*) echo "$SERVER_CONF" ;; *) echo "$REPO/$SERVER_CONF" ;; esac ;; *) echo "$REPO/scripts/soak-client.conf" ;; esac; }
for side in server client; do
    sed -e "s|@SOAK_DIR@|$OUT|g" -e "s|@PORT@|$PORT|g" -e "s|\.\./assets/|$REPO/assets/|g" \
        "$(conf_of $side)" > "$OUT/$side.conf"
done

"$BIN" --headless --no-shell --for "$SECS" "$OUT/server.conf" > "$OUT/server.log" 2>&1 &
SERVER=$!
sleep 2
# The client lives a little shorter, so the server never sees it outlive the run.
"$BIN" --headless --no-shell --for "$((SECS - 5))" "$OUT/client.conf" > "$OUT/client.log" 2>&1 &
CLIENT=$!
trap 'kill $SERVER $CLIENT 2>/dev/null || true' EXIT INT TERM

CSV=$OUT/rss.csv
echo "t_s,server_rss_kb,client_rss_kb" > "$CSV"
start=$(date +%s)
rss() { awk '/^VmRSS:/ {print $2}' "/proc/$1/status" 2>/dev/null || echo ""; }
prune() { # keep the newest two parts of each recording
    for base in server client; do
        { ls -1t "$OUT/$base"*.mcap 2>/dev/null || true; } | tail -n +3 | xargs -r rm -f
    done
}
while kill -0 "$SERVER" 2>/dev/null; do
    now=$(( $(date +%s) - start ))
    s=$(rss "$SERVER"); c=$(rss "$CLIENT")
    [ -n "$s" ] && echo "$now,$s,${c:-}" >> "$CSV"
    prune
    sleep "$INTERVAL"
done
wait "$SERVER" && src=0 || src=$?
wait "$CLIENT" 2>/dev/null && crc=0 || crc=$?
echo "server exit $src, client exit $crc; samples in $CSV; logs in $OUT"

python3 - "$CSV" <<'PY'
import csv, sys
rows = [(int(r["t_s"]), int(r["server_rss_kb"]), r["client_rss_kb"]) for r in csv.DictReader(open(sys.argv[1]))]
if not rows:
    sys.exit("no samples")
def at(minute):
    t = minute * 60
    best = min(rows, key=lambda r: abs(r[0] - t))
    return f"{best[1] / 1024:.2f} MB (t={best[0]} s)" if abs(best[0] - t) <= 30 else "-"
for m in (1, 5, 10, 30, 60):
    print(f"server RSS at {m:2d} min: {at(m)}")
end = rows[-1][0]
tail = [r for r in rows if r[0] >= max(end - 1800, end / 2)]
n = len(tail)
if n >= 3:
    mx = sum(r[0] for r in tail) / n
    my = sum(r[1] for r in tail) / n
    slope = sum((r[0] - mx) * (r[1] - my) for r in tail) / sum((r[0] - mx) ** 2 for r in tail)
    print(f"growth over the last {tail[-1][0] - tail[0][0]} s ({n} samples): {slope:.3f} KB/s "
          f"(least squares; {slope * 3600 / 1024:.2f} MB/h)")
    print(f"  range there: {min(r[1] for r in tail) / 1024:.2f} .. {max(r[1] for r in tail) / 1024:.2f} MB")
mxr = max(rows, key=lambda r: r[1])
print(f"server RSS max: {mxr[1] / 1024:.2f} MB at t={mxr[0]} s; first {rows[0][1] / 1024:.2f} MB, last {rows[-1][1] / 1024:.2f} MB")
cl = [int(r[2]) for r in rows if r[2]]
if cl:
    print(f"client RSS first {cl[0] / 1024:.2f} MB, last {cl[-1] / 1024:.2f} MB, max {max(cl) / 1024:.2f} MB")
PY
