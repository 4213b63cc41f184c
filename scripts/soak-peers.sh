#!/usr/bin/env bash
# Soak with the peers of issue 38: one jderobot process drives the gz-transport peer
# robot (tests/gazebo/peer.cc: odometry, a lidar, cmd_vel) with introrob, reads the
# NAOqi stand-in (tests/emulators/naoqi.py on the real libqi: head, sonars, a camera)
# and serves it all on Foxglove, while the official Foxglove client
# (tests/foxglove_node/client.js: subscribe, decode, call a service, drive /cmd_vel)
# connects and leaves every CLIENT_EVERY seconds. Samples the robot process's VmRSS
# and open descriptors every INTERVAL seconds into a CSV; at the end (`--for`)
# measures how long the process took to stop, and prints RSS and fds first/last/max,
# the least-squares RSS growth over the second half, and the clients' successes.
#
#   scripts/soak-peers.sh [SECONDS=3600] [OUTDIR=/tmp/jde-soak-peers-PID]
#   JDEROBOT=target/release/jderobot PEER=target/gazebo-peer/peer PY=target/py-venv/bin/python
set -euo pipefail

SECS=${1:-3600}
OUT=${2:-/tmp/jde-soak-peers-$$}
INTERVAL=${INTERVAL:-10}
CLIENT_EVERY=${CLIENT_EVERY:-10}
REPO=$(cd "$(dirname "$0")/.." && pwd)
BIN=${JDEROBOT:-$REPO/target/release/jderobot}
PEER=${PEER:-$REPO/target/gazebo-peer/peer}
PY=${PY:-$REPO/target/py-venv/bin/python}
NODE_DIR=$REPO/tests/foxglove_node
for f in "$BIN" "$PEER" "$PY"; do
    [ -x "$f" ] || { echo "soak-peers.sh: missing $f (build jderobot with gazebo,naobody,foxglove; run the gazebo tests once to build the peer; the py-venv with qi)" >&2; exit 2; }
done
[ -d "$NODE_DIR/node_modules" ] || { echo "soak-peers.sh: run npm ci in $NODE_DIR" >&2; exit 2; }
mkdir -p "$OUT"
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
NAO_PORT=$(free_port); FOX_PORT=$(free_port)
PART=soak$$

IGN_IP=127.0.0.1 IGN_PARTITION=$PART "$PEER" robot --model robot1 --lidar /lidar \
    > "$OUT/gz-peer.log" 2>&1 < /dev/null &
GZ=$!
"$PY" "$REPO/tests/emulators/naoqi.py" --url "tcp://127.0.0.1:$NAO_PORT" > "$OUT/naoqi.log" 2>&1 < /dev/null &
NAO=$!
trap 'kill $GZ $NAO ${ROBOT:-} 2>/dev/null || true' EXIT INT TERM
for _ in $(seq 100); do grep -q READY "$OUT/naoqi.log" && break; sleep 0.2; done

cat > "$OUT/robot.conf" <<CONF
driver gazebo
partition $PART
ip 127.0.0.1
provides encoders robot1
provides motors robot1
provides laser lidar
end_driver
driver naobody
host 127.0.0.1
port $NAO_PORT
provides ptmotors
provides ptencoders
provides sonars
provides colorA
end_driver
schema introrob
behaviour vff
target 4000 0
end_schema
service foxglove
port $FOX_PORT
end_service
load_driver gazebo
load_driver naobody
load_schema introrob
load_service foxglove
run introrob
CONF

"$BIN" --headless --no-shell --for "$SECS" "$OUT/robot.conf" > "$OUT/robot.log" 2>&1 &
ROBOT=$!
start=$(date +%s.%N)
clients_ok=0; clients_failed=0
CSV=$OUT/samples.csv
echo "t_s,rss_kb,fds" > "$CSV"
next_client=5; next_sample=0
while kill -0 "$ROBOT" 2>/dev/null; do
    now=$(python3 -c "print(int($(date +%s.%N) - $start))")
    if [ "$now" -ge "$next_sample" ]; then
        rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$ROBOT/status" 2>/dev/null || true)
        fds=$(ls "/proc/$ROBOT/fd" 2>/dev/null | wc -l || true)
        [ -n "$rss" ] && echo "$now,$rss,$fds" >> "$CSV"
        next_sample=$((now + INTERVAL))
    fi
    if [ "$now" -ge "$next_client" ] && [ "$now" -lt "$((SECS - 30))" ]; then
        if (cd "$NODE_DIR" && FOXGLOVE_EXPECT=laser,encoders,/tf,colorA,sonars FOXGLOVE_RUN_AGAIN=1 \
            timeout 30 node client.js "ws://127.0.0.1:$FOX_PORT") \
            > "$OUT/client-last.json" 2>> "$OUT/client.err"; then
            clients_ok=$((clients_ok + 1))
        else
            clients_failed=$((clients_failed + 1))
        fi
        next_client=$((now + CLIENT_EVERY))
    fi
    # Near the end, look often: the stop's latency is measured from `--for`'s end.
    if [ "$now" -ge "$((SECS - INTERVAL - 2))" ]; then sleep 0.05; else sleep 1; fi
done
end=$(date +%s.%N)
wait "$ROBOT" && rc=0 || rc=$?
echo "robot exit $rc; foxglove clients: $clients_ok ok, $clients_failed failed; samples in $CSV; logs in $OUT"
python3 - "$CSV" "$start" "$end" "$SECS" <<'PY'
import csv, sys
rows = [(int(r["t_s"]), int(r["rss_kb"]), int(r["fds"])) for r in csv.DictReader(open(sys.argv[1]))]
start, end, secs = float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
if not rows:
    sys.exit("no samples")
print(f"ran {end - start:.1f} s (asked {secs:.0f} s): the stop at `--for`'s end took at most "
      f"{max(0.0, end - start - secs):.2f} s (start-up counted in; polled every 50 ms)")
print(f"RSS first {rows[0][1] / 1024:.1f} MB (t={rows[0][0]} s), last {rows[-1][1] / 1024:.1f} MB "
      f"(t={rows[-1][0]} s), max {max(r[1] for r in rows) / 1024:.1f} MB")
print(f"fds first {rows[0][2]}, last {rows[-1][2]}, max {max(r[2] for r in rows)}")
half = [r for r in rows if r[0] >= rows[-1][0] / 2]
if len(half) >= 3:
    n = len(half); mx = sum(r[0] for r in half) / n; my = sum(r[1] for r in half) / n
    s = sum((r[0] - mx) * (r[1] - my) for r in half) / sum((r[0] - mx) ** 2 for r in half)
    print(f"RSS growth over the second half ({n} samples): {s * 3600 / 1024:.2f} MB/h (least squares)")
PY
