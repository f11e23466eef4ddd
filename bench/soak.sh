#!/usr/bin/env bash
# The soak benchmark (docs/reliability.md; not a CI test): a coordinator, simulated workers
# speaking the real protocol (build/bin/soak_load: some killed and restarted, some stalled past
# their lease, some uploading corrupt results) and a batch of jobs, for about ten minutes. Then:
#   - every job completed, with exactly the spp it asked for in every frame;
#   - no task merged twice (the job store's task events: one merge per task);
#   - every frame equals the local render of the same job (rfb_diff --exr --tolerance: DESIGN.md's
#     merge tolerance);
#   - the coordinator's memory (RSS sampled every 5 s) flat once the jobs are running;
#   - no corrupt result accepted.
# Prints a summary table; exit 1 if a check fails.
#
#   bench/soak.sh [--workers 200] [--jobs 20] [--passes 180] [--minutes 10]
#
# --passes sizes the jobs (each job: 2 frames of 64x64 in 16x16 tiles, 4 spp per pass): 180 passes
# make the default run last about ten minutes on a 2-core machine. The run stops after --minutes
# plus five whether or not the jobs finished (a stall is a failure, not a hang).
set -euo pipefail
cd "$(dirname "$0")/.."
WORKERS=200 JOBS=20 PASSES=180 MINUTES=10
while [ $# -gt 0 ]; do
  case "$1" in
    --workers) WORKERS=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    --passes) PASSES=$2; shift 2 ;;
    --minutes) MINUTES=$2; shift 2 ;;
    *) echo "usage: bench/soak.sh [--workers N] [--jobs N] [--passes N] [--minutes N]" >&2; exit 2 ;;
  esac
done
B=${RAYFARM_BIN:-build/bin/rayfarm}
[ -n "${RAYFARM_BIN:-}" ] || ./rayfarm --help >/dev/null  # build first
ninja -C build soak_load rfb_diff >/dev/null
DIR=$(mktemp -d /tmp/rayfarm-soak.XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT
echo "soak: $WORKERS simulated workers, $JOBS jobs of $PASSES passes, $(nproc) cores; in $DIR"

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

# Jobs: the Cornell box and veach-mis alternately, each with its own seed, frames 1-2.
declare -a ARGS IDS
for j in $(seq 0 $((JOBS - 1))); do
  if [ $((j % 2)) -eq 0 ]; then scene=scenes/cornell-box/scene.json; else scene=scenes/veach-mis/scene.json; fi
  ARGS[$j]="$scene --res 64x64 --spp $((4 * PASSES)) --passes $PASSES --seed $((j + 1))"
  IDS[$j]=$($B submit ${ARGS[$j]} --frames 1-2 --tile-size 16 --name "soak-$j" 2>/dev/null)
done
t0=$(date +%s)

# Memory: the coordinator's resident set every 5 s.
( while kill -0 $COORD 2>/dev/null; do
    echo "$(( $(date +%s) - t0 )) $(awk '/VmRSS/{print $2}' /proc/$COORD/status)"
    sleep 5
  done ) >"$DIR/rss.txt" &

build/bin/soak_load --coordinator "$RAYFARM_COORDINATOR" --workers "$WORKERS" \
  --seconds $(( (MINUTES + 5) * 60 )) --cache "$DIR/load-cache" >"$DIR/load.json" 2>"$DIR/load.log" &
LOAD=$!

# Until every job has ended, or the time is up.
deadline=$(( t0 + (MINUTES + 5) * 60 ))
while :; do
  open=0
  for id in "${IDS[@]}"; do
    $B status "$id" --json 2>/dev/null | grep -q '"state": "\(queued\|running\)"' && open=$((open + 1))
  done
  [ "$open" -eq 0 ] && break
  [ "$(date +%s)" -ge "$deadline" ] && break
  sleep 5
done
elapsed=$(( $(date +%s) - t0 ))
kill -TERM $LOAD
wait $LOAD || true
status=0
fail() { echo "FAIL: $*"; status=1; }

completed=0 exact=0 same=0
for j in $(seq 0 $((JOBS - 1))); do
  id=${IDS[$j]}
  s=$($B status "$id" --json 2>/dev/null)
  if echo "$s" | grep -q '"state": "completed"'; then completed=$((completed + 1)); else fail "$id: $(echo "$s" | grep '"state"')"; fi
  spps=$(echo "$s" | grep -o '"spp": [0-9.]*' | awk '{print $2 + 0}' | sort -u | tr '\n' ' ')
  if [ "$spps" = "$((4 * PASSES)) " ]; then exact=$((exact + 1)); else fail "$id: spp $spps, asked $((4 * PASSES))"; fi
  $B fetch "$id" -o "$DIR/out" 2>/dev/null
  ok=1
  for f in 1 2; do
    $B render ${ARGS[$j]} --frame $f -q -o "$DIR/local-$j-$f.exr" >/dev/null 2>&1
    build/bin/rfb_diff --exr --tolerance "$DIR/out/$id.$(printf %04d $f).exr" \
      "$DIR/local-$j-$f.exr" >"$DIR/diff-$j-$f.txt" 2>&1 ||
      { ok=0; fail "$id frame $f differs from the local render: $(head -3 "$DIR/diff-$j-$f.txt")"; }
  done
  same=$((same + ok))
done

# No task merged twice: one merge event per task in the job store.
twice=$(sqlite3 "$DIR/state/jobs.sqlite" \
  "SELECT COUNT(*) FROM (SELECT job_id, frame, pass, tile FROM task_events WHERE done = 1
   GROUP BY job_id, frame, pass, tile HAVING COUNT(*) > 1)" 2>&1)
[ "$twice" = "0" ] || fail "tasks merged more than once: $twice"
corrupt_accepted=$(grep -o '"corrupt_accepted": [0-9]*' "$DIR/load.json" | awk '{print $2}')
[ "${corrupt_accepted:-1}" = "0" ] || fail "corrupt results accepted: $corrupt_accepted"

# Memory: the resident set a minute in against the end and the peak.
rss_1min=$(awk '$1 >= 60 {print $2; exit}' "$DIR/rss.txt")
rss_end=$(tail -1 "$DIR/rss.txt" | awk '{print $2}')
rss_max=$(awk 'BEGIN{m=0} $2 > m {m=$2} END{print m}' "$DIR/rss.txt")
if [ -n "$rss_1min" ] && [ "$elapsed" -ge 120 ]; then
  growth=$(( (rss_end - rss_1min) / 1024 ))
  [ "$growth" -le 64 ] || fail "coordinator RSS grew by $growth MiB after the first minute"
else
  rss_1min=0
  echo "(run too short to judge memory growth: under two minutes)"
fi

kill $COORD 2>/dev/null || true
echo
echo "| figure | value |"
echo "|---|---|"
echo "| run | $elapsed s, $WORKERS workers, $JOBS jobs x 2 frames x 16 tiles x $PASSES passes |"
echo "| jobs completed | $completed / $JOBS |"
echo "| frames with the exact spp | $exact / $JOBS jobs |"
echo "| jobs whose frames equal the local render | $same / $JOBS |"
echo "| tasks merged twice | $twice |"
echo "| coordinator RSS (MiB): at 1 min / peak / end | $((rss_1min / 1024)) / $((rss_max / 1024)) / $((rss_end / 1024)) |"
echo "| load generator | $(cat "$DIR/load.json") |"
echo
[ $status -eq 0 ] && echo "soak: all checks passed" || echo "soak: FAILED (logs in $DIR)"
exit $status
