#!/usr/bin/env bash
# The coordinator's cost per durable task (docs/performance.md, "The farm"; not a CI test): a
# coordinator and W simulated workers (build/bin/soak_load, the real protocol, none misbehaving)
# on a job of tiny tasks (8x8 pixels, 1 spp: rendering is negligible) for S seconds. Reports
# tasks merged a second, the coordinator's CPU per task (its task-clock), its fsync, fdatasync
# and syncfs calls per task (perf's syscall tracepoints: its own flushes and SQLite's), and the
# load generator's CPU per task, which shares the machine.
#
# Each worker count runs once per batch size in RAYFARM_BENCH_BATCHES (default "1 32"): tasks
# asked for per lease and results sent per upload (soak_load --batch; the coordinator decides
# how many tasks it hands out).
#
#   bench/durable_bench.sh [WORKERS...]     (default: 1 8 32; RAYFARM_BENCH_SECONDS=10)
set -euo pipefail
cd "$(dirname "$0")/.."
B=${RAYFARM_BIN:-build/bin/rayfarm}
LOAD=${RAYFARM_SOAK_LOAD:-build/bin/soak_load}
SECONDS_EACH=${RAYFARM_BENCH_SECONDS:-10}
[ -n "${RAYFARM_BIN:-}" ] || ./rayfarm --help >/dev/null  # build first
command -v perf >/dev/null || { echo "durable_bench: needs perf (linux-perf)" >&2; exit 2; }
DIR=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$DIR"' EXIT
WORKER_COUNTS=("$@")
read -r -a BATCHES <<<"${RAYFARM_BENCH_BATCHES:-1 32}"
[ ${#WORKER_COUNTS[@]} -gt 0 ] || WORKER_COUNTS=(1 8 32)

echo "durable bench: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), ${SECONDS_EACH} s per run"
for workers in "${WORKER_COUNTS[@]}"; do
for batch in "${BATCHES[@]}"; do
  : >"$DIR/coord-$workers.log"
  $B coordinator --listen 127.0.0.1:0 --state-dir "$DIR/state-$workers" >"$DIR/coord-$workers.log" 2>&1 &
  coord=$!
  port=""
  for _ in $(seq 500); do
    port=$(sed -n 's/.*(port \([0-9]*\)).*/\1/p' "$DIR/coord-$workers.log")
    [ -n "$port" ] && break
    sleep 0.02
  done
  [ -n "$port" ] || { cat "$DIR/coord-$workers.log" >&2; exit 1; }
  export RAYFARM_COORDINATOR=127.0.0.1:$port
  # 64 tiles a pass, more passes than the run can merge.
  $B submit scenes/cornell-box/scene.json --res 64x64 --tile-size 8 --spp 4000 --passes 4000 \
    --name durable >/dev/null
  perf stat -x, -e task-clock,syscalls:sys_enter_fsync,syscalls:sys_enter_fdatasync,syscalls:sys_enter_syncfs -p "$coord" \
    -o "$DIR/perf-$workers.txt" &
  perf_pid=$!
  sleep 0.2
  /usr/bin/env time -f "%U %S" -o "$DIR/load-$workers.time" "$LOAD" --coordinator "127.0.0.1:$port" \
    --workers "$workers" --seconds "$SECONDS_EACH" --kill 0 --stall 0 --corrupt 0 \
    --batch "$batch" --cache "$DIR/cache-$workers" >"$DIR/load-$workers.json" 2>"$DIR/load-$workers.log"
  kill -INT "$perf_pid"
  wait "$perf_pid" 2>/dev/null || true
  merged=$(sed -n 's/.*"merged": \([0-9]*\).*/\1/p' "$DIR/load-$workers.json")
  secs=$(sed -n 's/.*"seconds": \([0-9.]*\).*/\1/p' "$DIR/load-$workers.json")
  cpu_ms=$(awk -F, '$3 == "task-clock" { print $1 }' "$DIR/perf-$workers.txt")
  fsyncs=$(awk -F, '$3 ~ /sys_enter_(fsync|fdatasync|syncfs)/ { n += $1 } END { print n + 0 }' "$DIR/perf-$workers.txt")
  syncfs=$(awk -F, '$3 ~ /sys_enter_syncfs/ { n += $1 } END { print n + 0 }' "$DIR/perf-$workers.txt")
  read -r lu ls <"$DIR/load-$workers.time"
  awk -v w="$workers" -v b="$batch" -v m="$merged" -v s="$secs" -v c="$cpu_ms" -v f="$fsyncs" -v sf="$syncfs" -v lu="$lu" -v ls="$ls" 'BEGIN {
    printf "  %3d workers, batch %2d: %6d tasks in %.1f s, %6.0f tasks/s | coordinator %5.0f us CPU/task, %.2f flushes/task (%.2f syncfs) | load generator %5.0f us CPU/task\n",
      w, b, m, s, m / s, 1000 * c / m, f / m, sf / m, 1e6 * (lu + ls) / m }'
  kill "$coord" 2>/dev/null || true
  wait "$coord" 2>/dev/null || true
  rm -rf "$DIR/state-$workers" "$DIR/cache-$workers"
done
done
