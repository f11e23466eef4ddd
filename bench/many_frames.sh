#!/usr/bin/env bash
# Coordinator CPU per task on a job of many small frames (docs/performance.md): one job of FRAMES
# frames of 8x8 pixels, 1 tile, 1 pass of 1 spp, through soak_load's simulated workers (none
# killed, stalled or corrupt). Prints the coordinator's CPU (utime + stime) and wall time from
# the first lease to the job's completion, and CPU per task. The per-frame costs of the
# coordinator (its lock held per result, the job's frames looked at) show here; bench/
# durable_bench.sh has one frame.
#
#   bench/many_frames.sh [FRAMES=10000] [WORKERS=64]
#   RAYFARM_BIN=... RAYFARM_SOAK_LOAD=... bench/many_frames.sh   (another build, for A/B runs)
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-10000} WORKERS=${2:-64}
B=${RAYFARM_BIN:-build/bin/rayfarm}
LOAD=${RAYFARM_SOAK_LOAD:-build/bin/soak_load}
[ -n "${RAYFARM_BIN:-}" ] || ninja -C build rayfarm soak_load >/dev/null
D=$(mktemp -d /tmp/rayfarm-many-frames.XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$D"' EXIT
: >"$D/coordinator.log"
$B coordinator --listen 127.0.0.1:0 --state-dir "$D/state" --lease-seconds 30 >"$D/coordinator.log" 2>&1 &
C=$!
for _ in $(seq 500); do
  port=$(sed -n 's/.*(port \([0-9]*\)).*/\1/p' "$D/coordinator.log")
  [ -n "$port" ] && break
  sleep 0.02
done
export RAYFARM_COORDINATOR=127.0.0.1:$port
id=$($B submit scenes/cornell-box/scene.json --res 8x8 --spp 1 --passes 1 --frames "1-$FRAMES" \
  --tile-size 8 2>/dev/null)
cpu0=$(awk '{print $14 + $15}' /proc/$C/stat)
t0=$(date +%s.%N)
"$LOAD" --coordinator "$RAYFARM_COORDINATOR" --workers "$WORKERS" --seconds 3600 --kill 0 \
  --stall 0 --corrupt 0 --cache "$D/cache" >"$D/load.json" 2>"$D/load.log" &
until $B status "$id" 2>/dev/null | grep -q ' completed '; do sleep 0.5; done
cpu1=$(awk '{print $14 + $15}' /proc/$C/stat)
t1=$(date +%s.%N)
awk -v c="$((cpu1 - cpu0))" -v hz="$(getconf CLK_TCK)" -v a="$t0" -v b="$t1" -v n="$FRAMES" \
  'BEGIN { printf "%d frames: coordinator CPU %.2f s (%.0f us a task), wall %.1f s (%.0f tasks/s)\n",
           n, c / hz, 1e6 * c / hz / n, b - a, n / (b - a) }'
