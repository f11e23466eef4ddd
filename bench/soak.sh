#!/usr/bin/env bash
# The soak (docs/reliability.md): a coordinator, simulated workers speaking the real protocol
# (build/bin/soak_load, in several processes: some workers killed and restarted, some stalled past
# their lease, some uploading corrupt results) and a batch of jobs. Then:
#   - every job completed, with exactly the spp it asked for in every frame;
#   - no task merged twice, and every task merged (the job store's task events);
#   - every frame equals the local render of the same job (rfb_diff --exr --tolerance: DESIGN.md's
#     merge tolerance);
#   - no corrupt result accepted;
#   - flat: the coordinator's RSS at the end within 10% of minute 2's, and the lease latency p99
#     of the last minute within 1.5 times minute 2's (bench/soak_plot.py).
# Writes soak.svg (lease latency p50/p99, merged tasks/s, coordinator CPU and RSS over time) and
# soak.json (the figures) into --out, prints a summary table; exit 1 if a check fails.
#
#   bench/soak.sh [--workers 1000] [--procs N] [--jobs 100] [--frames 100] [--res 32]
#                 [--tile 16] [--passes 7] [--spp 4] [--minutes 10] [--out build/soak]
#
# The defaults are the farm-scale soak: 1,000 workers in 4 load processes, 100 jobs of 100 frames
# of 32x32 (4 tiles of 16x16), 7 passes of 4 spp: 280,000 tasks, about eleven minutes on a 2-core
# machine. The load runs until every job ended and --minutes passed; it stops after twice
# --minutes plus five whether or not the jobs finished (a stall is a failure, not a hang).
# CI runs a smaller one (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
WORKERS=1000 PROCS=0 JOBS=100 FRAMES=100 RES=32 TILE=16 PASSES=7 SPP=4 MINUTES=10 OUT=build/soak
while [ $# -gt 0 ]; do
  case "$1" in
    --workers) WORKERS=$2; shift 2 ;;
    --procs) PROCS=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    --res) RES=$2; shift 2 ;;
    --tile) TILE=$2; shift 2 ;;
    --passes) PASSES=$2; shift 2 ;;
    --spp) SPP=$2; shift 2 ;;
    --minutes) MINUTES=$2; shift 2 ;;
    --out) OUT=$2; shift 2 ;;
    *) echo "usage: bench/soak.sh [--workers N] [--procs N] [--jobs N] [--frames N] [--res PX]" \
         "[--tile PX] [--passes N] [--spp N] [--minutes N] [--out DIR]" >&2; exit 2 ;;
  esac
done
tools/install-debian-packages.sh python3  # the checks and the timeline (bench/soak_plot.py)
[ "$PROCS" -gt 0 ] || PROCS=$(( (WORKERS + 249) / 250 ))  # 250 simulated workers a process
B=${RAYFARM_BIN:-build/bin/rayfarm}
[ -n "${RAYFARM_BIN:-}" ] || ./rayfarm --help >/dev/null  # build first
ninja -C build soak_load rfb_diff >/dev/null
LOADBIN=${RAYFARM_SOAK_LOAD:-build/bin/soak_load}
DIR=$(mktemp -d /tmp/rayfarm-soak.XXXXXX)
mkdir -p "$OUT"
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT
TILES=$(( ((RES + TILE - 1) / TILE) * ((RES + TILE - 1) / TILE) ))
TASKS=$(( JOBS * FRAMES * TILES * PASSES ))
echo "soak: $WORKERS simulated workers in $PROCS processes, $JOBS jobs x $FRAMES frames of" \
  "${RES}x$RES x $TILES tiles x $PASSES passes ($TASKS tasks), at least $MINUTES minutes," \
  "$(nproc) cores; in $DIR"

: >"$DIR/coordinator.log"  # exists before the poll below reads it (the & subshell opens it late)
$B coordinator --listen 127.0.0.1:0 --state-dir "$DIR/state" --lease-seconds 10 \
  >"$DIR/coordinator.log" 2>&1 &
COORD=$!
for _ in $(seq 500); do
  port=$(sed -n 's/.*(port \([0-9]*\)).*/\1/p' "$DIR/coordinator.log")
  [ -n "$port" ] && break
  sleep 0.02
done
export RAYFARM_COORDINATOR=127.0.0.1:$port

# Jobs: the Cornell box and veach-mis alternately, each with its own seed.
declare -a ARGS IDS
for j in $(seq 0 $((JOBS - 1))); do
  if [ $((j % 2)) -eq 0 ]; then scene=scenes/cornell-box/scene.json; else scene=scenes/veach-mis/scene.json; fi
  ARGS[$j]="$scene --res ${RES}x$RES --spp $((SPP * PASSES)) --passes $PASSES --seed $((j + 1))"
  IDS[$j]=$($B submit ${ARGS[$j]} --frames 1-$FRAMES --tile-size $TILE --name "soak-$j" 2>/dev/null)
done
t0=$(date +%s.%N)

# The coordinator's CPU time (utime + stime, in clock ticks) and resident set every 5 s.
( while kill -0 $COORD 2>/dev/null; do
    echo "$(date +%s.%N) $(awk '{print $14 + $15}' /proc/$COORD/stat)" \
      "$(awk '/VmRSS/{print $2}' /proc/$COORD/status)"
    sleep 5
  done ) >"$DIR/coordinator.txt" &

declare -a LOADS
per=$(( (WORKERS + PROCS - 1) / PROCS ))
for p in $(seq 0 $((PROCS - 1))); do
  n=$(( WORKERS - p * per < per ? WORKERS - p * per : per ))
  "$LOADBIN" --coordinator "$RAYFARM_COORDINATOR" --workers "$n" --first-index $((p * per)) \
    --seed $((p + 1)) --seconds $(( (2 * MINUTES + 5) * 60 )) --cache "$DIR/load-cache-$p" \
    --timeline "$DIR/timeline-$p.jsonl" >"$DIR/load-$p.json" 2>"$DIR/load-$p.log" &
  LOADS[$p]=$!
done

# Until every job has ended and --minutes passed, or the time is up.
deadline=$(( ${t0%.*} + (2 * MINUTES + 5) * 60 ))
min_end=$(( ${t0%.*} + MINUTES * 60 ))
all_ended=""
while :; do
  now=$(date +%s)
  # (a status call that failed says nothing: asked again at the next round)
  if [ -z "$all_ended" ] && listing=$($B status --timeout 30 2>>"$DIR/status.log") &&
    [ "$(grep -c . <<<"$listing")" -eq "$JOBS" ] && ! grep -q ' \(queued\|running\) ' <<<"$listing"; then
    all_ended=$(date +%s.%N)
  fi
  [ -n "$all_ended" ] && [ "$now" -ge "$min_end" ] && break
  [ "$now" -ge "$deadline" ] && break
  sleep 5
done
t_end=$(date +%s.%N)
kill -TERM "${LOADS[@]}"
wait "${LOADS[@]}" || true
elapsed=$(awk -v a="$t0" -v b="$t_end" 'BEGIN{printf "%d", b - a}')
status=0
fail() { echo "FAIL: $*"; status=1; }

# Every job completed with exactly its spp in every frame.
$B status --json >"$DIR/status.json"
read -r completed exact < <(python3 - "$DIR/status.json" $((SPP * PASSES)) <<'PY'
import json, sys
jobs = json.load(open(sys.argv[1]))
spp = float(sys.argv[2])
done = sum(j["state"] == "completed" for j in jobs)
exact = sum(all(f["spp"] == spp for f in j["frames"]) and len(j["frames"]) > 0 for j in jobs)
print(done, exact)
PY
)
[ "$completed" = "$JOBS" ] || fail "$completed of $JOBS jobs completed"
[ "$exact" = "$JOBS" ] || fail "$exact of $JOBS jobs have exactly $((SPP * PASSES)) spp in every frame"

# Every frame equals its local render.
: >"$DIR/pairs.txt"
for j in $(seq 0 $((JOBS - 1))); do
  id=${IDS[$j]}
  $B fetch "$id" -o "$DIR/out" --frames 1-$FRAMES >/dev/null 2>&1 || fail "$id: fetch failed"
  $B render ${ARGS[$j]} --frames 1-$FRAMES -q -o "$DIR/local/$j.####.exr" >/dev/null 2>&1 ||
    fail "job $j: the local render failed"
  for f in $(seq 1 $FRAMES); do
    printf '%s %s\n' "$DIR/out/$id.$(printf %04d $f).exr" "$DIR/local/$j.$(printf %04d $f).exr"
  done >>"$DIR/pairs.txt"
done
build/bin/rfb_diff --exr --tolerance --pairs "$DIR/pairs.txt" >"$DIR/diff.txt" 2>&1 ||
  fail "frames differ from the local render: $(head -3 "$DIR/diff.txt")"
same=$(sed -n 's/^[0-9]* pairs: \([0-9]*\) equal.*/\1/p' "$DIR/diff.txt")

# No task merged twice, none missing: one merge event per task in the job store.
read -r twice merges < <(python3 - "$DIR/state/jobs.sqlite" <<'PY'
import sqlite3, sys
db = sqlite3.connect(sys.argv[1])
twice = db.execute("SELECT COUNT(*) FROM (SELECT job_id, frame, pass, tile FROM task_events "
                   "WHERE done = 1 GROUP BY job_id, frame, pass, tile HAVING COUNT(*) > 1)").fetchone()[0]
merges = db.execute("SELECT COUNT(*) FROM task_events WHERE done = 1").fetchone()[0]
print(twice, merges)
PY
)
[ "$twice" = "0" ] || fail "tasks merged more than once: $twice"
[ "$merges" = "$TASKS" ] || fail "$merges merge events for $TASKS tasks"
corrupt_accepted=$(cat "$DIR"/load-*.json | grep -o '"corrupt_accepted": [0-9]*' | awk '{s += $2} END {print s + 0}')
[ "$corrupt_accepted" = "0" ] || fail "corrupt results accepted: $corrupt_accepted"
# The load generator's own CPU (it shares the machine with the coordinator).
load_counts=$(cat "$DIR"/load-*.json | python3 -c '
import json, sys
rows = [json.loads(l) for l in sys.stdin if l.strip()]
keys = ["leased", "merged", "not_needed", "refused", "late_refused", "upload_errors",
        "lease_errors", "kills", "stalls", "corrupt", "corrupt_accepted", "registrations",
        "cpu_seconds"]
print(", ".join(f"{k} {round(sum(r[k] for r in rows), 1):g}" for k in keys))')

# The timeline, its image and the flat verdict.
kill $COORD 2>/dev/null || true
python3 bench/soak_plot.py --start "$t0" --end "$t_end" --coordinator "$DIR/coordinator.txt" \
  --ticks "$(getconf CLK_TCK)" --load "$DIR"/timeline-*.jsonl --svg "$OUT/soak.svg" \
  --summary "$OUT/soak.json" \
  --title "soak: $WORKERS workers, $JOBS jobs x $FRAMES frames, $TASKS tasks, $(nproc) cores" \
  >/dev/null || fail "not flat: $(python3 -c 'import json,sys; print("; ".join(json.load(open(sys.argv[1]))["not_flat_because"]))' "$OUT/soak.json")"
fig() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])' "$OUT/soak.json" "$1"; }

echo
echo "| figure | value |"
echo "|---|---|"
echo "| run | $elapsed s, $WORKERS workers in $PROCS processes, $JOBS jobs x $FRAMES frames x $TILES tiles x $PASSES passes |"
echo "| jobs completed | $completed / $JOBS |"
echo "| jobs with the exact spp in every frame | $exact / $JOBS |"
echo "| frames equal to the local render | ${same:-0} / $((JOBS * FRAMES)) |"
echo "| merge events / tasks / merged twice | $merges / $TASKS / $twice |"
echo "| merged tasks per second | $(awk -v m="$merges" -v e="$elapsed" 'BEGIN{printf "%.0f", m / e}') |"
echo "| lease latency p50 / p99 (ms), minute 2 | $(fig lease_p50_ms_minute_2) / $(fig lease_p99_ms_minute_2) |"
echo "| lease latency p50 / p99 (ms), last minute | $(fig lease_p50_ms_last_minute) / $(fig lease_p99_ms_last_minute) |"
echo "| coordinator RSS (MiB): minute 2 / peak / end | $(fig rss_mib_minute_2) / $(fig rss_mib_peak) / $(fig rss_mib_end) |"
echo "| coordinator CPU (s) | $(fig coordinator_cpu_seconds) |"
echo "| load generators (all processes) | $load_counts |"
echo
echo "timeline: $OUT/soak.svg, figures: $OUT/soak.json"
[ $status -eq 0 ] && echo "soak: all checks passed" || echo "soak: FAILED (logs in $DIR)"
exit $status
