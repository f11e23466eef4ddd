#!/usr/bin/env bash
# Farm benchmarks on loopback (not timed tests; numbers for docs/performance.md):
#   1. lease + complete round trips per second with tiny tasks (8x8 pixels, 1 spp): the
#      coordinator's per-task cost (RPCs, durable task file, checkpoint, SQLite) with 1 and 2 workers;
#   2. the farm overhead: the same job through a coordinator and 2 workers on this machine against
#      `rayfarm render` of it, as a ratio of wall-clock times.
#
#   bench/farm_bench.sh [TINY_TASKS] [SCENE_ARGS...]
set -euo pipefail
cd "$(dirname "$0")/.."
TASKS=${1:-1000}
shift || true
JOB_ARGS=${*:-scenes/cornell-box/scene.json --spp 256 --passes 16 --res 256x256}
B=${RAYFARM_BIN:-build/bin/rayfarm}
[ -n "${RAYFARM_BIN:-}" ] || ./rayfarm --help >/dev/null  # build first
DIR=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$DIR"' EXIT

start_coordinator() {
  : >"$DIR/coord-$1.log"  # exists before the poll below reads it (the & subshell opens it late)
  $B coordinator --listen 127.0.0.1:0 --state-dir "$DIR/state-$1" >"$DIR/coord-$1.log" 2>&1 &
  COORD=$!
  for _ in $(seq 500); do
    port=$(sed -n 's/.*(port \([0-9]*\)).*/\1/p' "$DIR/coord-$1.log")
    [ -n "$port" ] && break
    sleep 0.02
  done
  export RAYFARM_COORDINATOR=127.0.0.1:$port
}
now() { date +%s.%N; }

echo "farm bench: $(nproc) cores, $(uname -m)"
for workers in 1 2; do
  start_coordinator "tiny$workers"
  job=$($B submit scenes/cornell-box/scene.json --res 8x8 --tile-size 8 --spp "$TASKS" \
    --passes "$TASKS" --name tiny 2>/dev/null)
  t0=$(now)
  pids=()
  for w in $(seq "$workers"); do
    $B worker --exit-when-idle --cache-dir "$DIR/cache" --threads 1 >"$DIR/tiny-w$w.log" 2>&1 &
    pids+=($!)
  done
  $B watch "$job" >/dev/null
  t1=$(now)
  echo "round trips: $TASKS tiny tasks, $workers worker(s): $(awk -v n="$TASKS" -v a="$t0" -v b="$t1" \
    'BEGIN{printf "%.2f s, %.0f lease+complete round trips/s", b-a, n/(b-a)}')"
  wait "${pids[@]}" 2>/dev/null || true
  kill "$COORD" 2>/dev/null || true
  wait "$COORD" 2>/dev/null || true
done

t0=$(now)
$B render $JOB_ARGS -q -o "$DIR/local.exr" >/dev/null 2>&1
t1=$(now)
echo "overhead: $JOB_ARGS"
awk -v a="$t0" -v b="$t1" 'BEGIN{printf "  local render %.2f s\n", b - a}'
# One worker using all cores for one task at a time, against two sharing the machine.
for workers in 1 2; do
  start_coordinator "overhead$workers"
  job=$($B submit $JOB_ARGS --name overhead 2>/dev/null)
  t2=$(now)
  pids=()
  for w in $(seq "$workers"); do
    $B worker --exit-when-idle --cache-dir "$DIR/cache" >"$DIR/over$workers-w$w.log" 2>&1 &
    pids+=($!)
  done
  $B watch "$job" >/dev/null
  t3=$(now)
  $B fetch "$job" -o "$DIR/out$workers" 2>/dev/null
  same=$($B compare "$DIR/out$workers/$job.0000.exr" "$DIR/local.exr" | awk '{print $2}')
  awk -v t0="$t0" -v t1="$t1" -v t2="$t2" -v t3="$t3" -v n="$workers" -v same="$same" \
    'BEGIN{l = t1 - t0; f = t3 - t2; printf "  coordinator + %d worker(s) %.2f s | farm/local %.3f | farm vs local RMSE %s\n", n, f, f/l, same}'
  wait "${pids[@]}" 2>/dev/null || true
  kill "$COORD" 2>/dev/null || true
  wait "$COORD" 2>/dev/null || true
done

# 3. the web monitor's cost on the round trips above: 5 open pages against none, interleaved
#    rounds (bench/monitor_bench.py; needs the client venv, tools/python-venv.sh build/pyvenv).
if [ -x build/pyvenv/bin/python ]; then
  RAYFARM_BIN="$B" build/pyvenv/bin/python bench/monitor_bench.py --skip-scale --rounds 4
else
  echo "monitor: no build/pyvenv (tools/python-venv.sh build/pyvenv); skipped"
fi
