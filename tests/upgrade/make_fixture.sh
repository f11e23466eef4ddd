#!/usr/bin/env bash
# Writes the upgrade fixture (tests/data/upgrade/state.tar.gz): a coordinator's state directory as
# a build before the task ledger wrote it, for Upgrade.AStateDirectoryOfTheBuildBeforeResumes
# (tests/upgrade_test.cpp). Run it with that build's binary:
#
#   git worktree add /tmp/old 569060f && (cd /tmp/old && ./rayfarm --help >/dev/null)
#   tests/upgrade/make_fixture.sh /tmp/old/build/bin/rayfarm
#
# Four jobs of the Cornell box at 16x16, each with its own arguments (listed in the fixture's
# jobs.txt, so the test renders the same locally):
#   j000001 completed (a worker rendered it);
#   j000002 cancelled after its first pass merged;
#   j000003 failed: three workers failed one of its tasks;
#   j000004 running: a task leased to a worker that was then killed, no result merged (a job
#            with merged results is pinned to the build that made them: only that build's
#            workers finish it, by design).
set -euo pipefail
OLD="${1:?usage: make_fixture.sh OLD_RAYFARM_BINARY}"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
WORK="$(mktemp -d)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$WORK"' EXIT
STATE="$WORK/state"
SCENE="$ROOT/scenes/cornell-box/scene.json"
PORT=$((20000 + RANDOM % 20000))
ADDR="127.0.0.1:$PORT"

start() {
  "$OLD" coordinator --listen "$ADDR" --state-dir "$STATE" --lease-seconds 600 "$@" \
    >>"$WORK/coordinator.log" 2>&1 &
  COORD=$!
  for _ in $(seq 100); do grep -q "(port $PORT)" "$WORK/coordinator.log" && return; sleep 0.1; done
  cat "$WORK/coordinator.log" >&2
  exit 1
}
stop() { kill -TERM "$COORD"; wait "$COORD" || true; }
submit() { "$OLD" submit "$SCENE" --coordinator "$ADDR" "$@"; }
worker() { "$OLD" worker --coordinator "$ADDR" --cache-dir "$WORK/cache" "$@"; }

A1="--res 16x16 --spp 8 --passes 2 --tile-size 8"
A2="--res 16x16 --spp 8 --passes 4 --tile-size 8"
A3="--res 16x16 --spp 4 --passes 2 --tile-size 8"
A4="--res 32x32 --spp 1024 --passes 1 --tile-size 32"

start
# shellcheck disable=SC2086  # the arguments are word lists
j1=$(submit $A1)
worker --exit-when-idle >>"$WORK/worker.log" 2>&1
"$OLD" watch "$j1" --coordinator "$ADDR" >/dev/null
# shellcheck disable=SC2086
j2=$(submit $A2)
worker --max-tasks 4 >>"$WORK/worker.log" 2>&1  # pass 0's four tiles
"$OLD" cancel "$j2" --coordinator "$ADDR"
# shellcheck disable=SC2086
j3=$(submit $A3)
# Three workers whose bundle folder cannot be made (a file is in its place) fail its tasks: a task
# failed on three workers fails the job.
mkdir -p "$WORK/bad/blobs" && : >"$WORK/bad/bundles"
pids=()
for _ in 1 2 3; do
  timeout 60 "$OLD" worker --coordinator "$ADDR" --cache-dir "$WORK/bad" --exit-when-idle \
    >>"$WORK/worker3.log" 2>&1 &
  pids+=($!)
done
wait "${pids[@]}" || true
# shellcheck disable=SC2086
j4=$(submit $A4)
"$OLD" worker --coordinator "$ADDR" --cache-dir "$WORK/cache" >>"$WORK/worker4.log" 2>&1 &
W=$!  # the worker itself (not a subshell), so that the kill below reaches it
for _ in $(seq 200); do grep -q "$j4/.*leased" "$WORK/worker4.log" && break; sleep 0.05; done
kill -KILL "$W"
wait "$W" 2>/dev/null || true
stop
printf '%s %s\n' "$j1" "$A1" "$j2" "$A2" "$j3" "$A3" "$j4" "$A4" >"$STATE/jobs.txt"
"$OLD" --help | head -1 >"$STATE/written-by.txt"
git -C "$(dirname "$OLD")/../.." rev-parse HEAD >>"$STATE/written-by.txt" 2>/dev/null || true
rm -rf "$STATE/lock"
mkdir -p "$ROOT/tests/data/upgrade"
tar -C "$WORK" -czf "$ROOT/tests/data/upgrade/state.tar.gz" state
echo "wrote tests/data/upgrade/state.tar.gz ($(du -h "$ROOT/tests/data/upgrade/state.tar.gz" | cut -f1))"
