#!/usr/bin/env bash
# Golden images: the current tree must render exactly what the base commit renders.
#
#   tests/golden/check.sh [BASE_COMMIT]
#
# Builds BASE_COMMIT out of tree (cached) and the current tree (./rayfarm, RAYFARM_BUILD_DIR),
# renders every shipped scene with every integrator with both binaries, small and with fixed
# seeds, and requires bit-identical sample planes (tests/tools/rfb_diff.cpp), identical settings
# text, EXR pixels, old partial buffers that still merge with new ones, and bit-identical farm
# renders. Both binaries read the current tree's scenes: this checks the code, not the scenes. A
# shipped scene the base build cannot read (scenes/shot's keyframes before motion) is skipped
# with a SKIPPED line.
#
# BASE_COMMIT defaults to tests/golden/BASE. That file names the last commit whose images are
# the reference. A refactor never touches it; only a deliberate image change (a bug fix, a
# better estimator) moves it to the commit that made the change, saying why
# (tests/golden/README.md, "Bumping BASE").
#
# Environment: RAYFARM_GOLDEN_CACHE (base builds, default ~/.cache/rayfarm-golden),
# RAYFARM_BUILD_DIR (the current tree's build), RAYFARM_GOLDEN_KEEP=1 (keep the renders even
# when everything is identical; they are always kept when something differs).
# Exit: 0 all identical, 1 something differs, 2 setup error (build, farm start).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"

die() {
  printf 'golden: error: %s\n' "$*" >&2
  exit 2
}
log() { printf 'golden: %s\n' "$*" >&2; }

BASE_REF=${1:-$(tr -d '[:space:]' <tests/golden/BASE)}
# A shallow clone may lack the base: fetch it if a remote has it. RAYFARM_GOLDEN_IF_AVAILABLE=1 (CI)
# turns a base that cannot be had into a loud skip instead of a failure.
if ! git rev-parse --verify --quiet "$BASE_REF^{commit}" >/dev/null; then
  git fetch --quiet --unshallow 2>/dev/null || git fetch --quiet origin "$BASE_REF" 2>/dev/null || true
fi
if ! BASE=$(git rev-parse --verify --quiet "$BASE_REF^{commit}"); then
  if [ "${RAYFARM_GOLDEN_IF_AVAILABLE:-0}" = 1 ]; then
    log "SKIPPED: base commit '$BASE_REF' is not in this clone's history and could not be fetched"
    exit 0
  fi
  die "base commit '$BASE_REF' is not in this repository (a shallow clone? git fetch origin $BASE_REF)"
fi
CACHE="${RAYFARM_GOLDEN_CACHE:-$HOME/.cache/rayfarm-golden}/$BASE"
NEW_BUILD="${RAYFARM_BUILD_DIR:-$ROOT/build}"
JOBS="${RAYFARM_BUILD_JOBS:-$(nproc)}"

# The renders: every shipped scene, small, two passes (the merge check renders them apart),
# several tiles, a fixed seed.
SCENES=()
for f in scenes/*/scene.json; do SCENES+=("$(basename "$(dirname "$f")")"); done
INTEGRATORS=(whitted ao direct path light bdpt ir ppm)
COMMON=(--res 40x30 --spp 4 --passes 2 --seed 7 --tile-size 16)
# Variants beyond the scene's own sampler and filter: Sobol with a gaussian filter (the splat
# filter weights of light tracing and BDPT), and another frame with a triangle filter (the
# frame selects the seed stream).
SOBOL_INTEGRATORS=(direct path light bdpt)
FRAME_INTEGRATORS=(path light ir ppm)
# Merge of an old pass with a new pass (tiled, splatting, per-pass state).
MERGE_INTEGRATORS=(path light ir)
# Through the farm, cornell-box only.
FARM_INTEGRATORS=(path light ir bdpt)

# --- builds -----------------------------------------------------------------------------------

log "building the current tree (./rayfarm)"
./rayfarm --help >/dev/null
NEW_BIN="$NEW_BUILD/bin/rayfarm"
DIFF="$NEW_BUILD/bin/rfb_diff"
[ -x "$NEW_BIN" ] && [ -x "$DIFF" ] || die "no $NEW_BIN or $DIFF after building"

# The base commit's rayfarm, from `git archive` (no .git: its build id says "nogit"), built once
# per commit and then reused. GIT_CEILING_DIRECTORIES keeps its build-id step from finding a
# repository around the cache.
build_base() {
  local bin="$CACHE/build/bin/rayfarm"
  mkdir -p "$CACHE"
  exec 8>"$CACHE/.lock"
  flock 8  # two checks at once build the base once
  if [ -x "$bin" ]; then
    log "base ${BASE:0:12}: cached build $bin"
    return
  fi
  log "building base ${BASE:0:12} in $CACHE (the first time takes minutes)"
  local t0=$SECONDS
  rm -rf "$CACHE/src" "$CACHE/build"
  mkdir -p "$CACHE/src"
  git archive "$BASE" | tar -x -C "$CACHE/src"
  export GIT_CEILING_DIRECTORIES="$CACHE"
  cmake -S "$CACHE/src" -B "$CACHE/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    >"$CACHE/build.log" 2>&1 &&
    cmake --build "$CACHE/build" --target rayfarm -- -j"$JOBS" >>"$CACHE/build.log" 2>&1 || {
    tail -n 30 "$CACHE/build.log" >&2
    die "building base ${BASE:0:12} failed (log: $CACHE/build.log)"
  }
  unset GIT_CEILING_DIRECTORIES
  [ -x "$bin" ] || die "base build made no $bin"
  log "base built in $((SECONDS - t0)) s"
  flock -u 8
}
build_base
OLD_BIN="$CACHE/build/bin/rayfarm"

# --- bookkeeping ------------------------------------------------------------------------------

WORK=$(mktemp -d "${TMPDIR:-/tmp}/rayfarm-golden.XXXXXX")
mkdir -p "$WORK/old" "$WORK/new"
PIDS=()  # every background process this script starts
IDENTICAL=0 DIFFERENT=0 REFUSED=0
# alive PID: running (a child that exited stays a zombie until reaped: not alive).
alive() { [ -e "/proc/$1" ] && ! grep -q '^State:[[:space:]]*Z' "/proc/$1/status" 2>/dev/null; }

# stop PID...: SIGTERM, SIGKILL whatever still runs 10 s later, and reap them all.
stop() {
  local pid i live
  for pid; do kill "$pid" 2>/dev/null || true; done
  for i in $(seq 100); do
    live=0
    for pid; do alive "$pid" && live=1; done
    [ "$live" -eq 0 ] && break
    sleep 0.1
  done
  for pid; do kill -KILL "$pid" 2>/dev/null || true; done
  for pid; do wait "$pid" 2>/dev/null || true; done
}
cleanup() {
  stop "${PIDS[@]}"
  PIDS=()
  if [ "$DIFFERENT" -gt 0 ] || [ -n "${RAYFARM_GOLDEN_KEEP:-}" ]; then
    log "renders and logs kept in $WORK"
  else
    rm -rf "$WORK"
  fi
}
trap cleanup EXIT
trap 'log "interrupted"; exit 130' INT TERM

# result CASE VERDICT [DETAILS]: one line per case. Verdicts: identical; equal within tolerance
# (only where DESIGN.md allows summation-order differences: merges, farm vs local); both refuse;
# DIFFERENT.
result() {
  printf '%-44s %s\n' "$1" "$2${3:+ ($3)}"
  case "$2" in
    identical | "equal within tolerance"*) IDENTICAL=$((IDENTICAL + 1)) ;;
    "both refuse") REFUSED=$((REFUSED + 1)) ;;
    *) DIFFERENT=$((DIFFERENT + 1)) ;;
  esac
}

# compare [rfb_diff options] A B: status 0 equal, 1 different (or the tool failed). Sets
# CMP_VERDICT (the tool's last line: "identical", "equal within tolerance (...)" or a difference),
# CMP_NOTES (its "note:" lines) and CMP_REPORT (all its lines, joined by " | ").
compare() {
  local out rc=0
  out=$("$DIFF" "$@" 2>&1) || rc=$?
  [ "$rc" -le 1 ] || out="rfb_diff failed (exit $rc): $out"
  CMP_VERDICT=$(tail -n1 <<<"$out")
  CMP_NOTES=$(grep '^note: ' <<<"$out" | sed 's/^note: //' | paste -sd ',' - || true)
  CMP_REPORT=$(paste -sd '|' - <<<"$out" | sed 's/|/ | /g')
  [ "$rc" -eq 0 ]
}

first_error() { grep -m1 -i 'error' "$1" || tail -n1 "$1"; }

# render BIN OUT SCENE ARGS...: both passes as OUT.rfb (sample buffer) and OUT.exr; log OUT.log.
render() {
  local bin=$1 out=$2 scene=$3
  shift 3
  "$bin" render "scenes/$scene/scene.json" "$@" --pass-range 0-1 --partial "$out.rfb" \
    -o "$out.exr" -q >"$out.log" 2>&1
}

# --- local renders ----------------------------------------------------------------------------

# local_case SCENE INTEGRATOR VARIANT ARGS...: both binaries, then planes and EXR pixels.
local_case() {
  local scene=$1 integ=$2 variant=$3
  shift 3
  local name="$scene.$integ.$variant" rc_old=0 rc_new=0
  local label="$scene $integ $variant local"
  render "$OLD_BIN" "$WORK/old/$name" "$scene" --integrator "$integ" "${COMMON[@]}" "$@" ||
    rc_old=$?
  render "$NEW_BIN" "$WORK/new/$name" "$scene" --integrator "$integ" "${COMMON[@]}" "$@" ||
    rc_new=$?
  if [ "$rc_old" -ne 0 ] || [ "$rc_new" -ne 0 ]; then
    if [ "$rc_old" -eq "$rc_new" ]; then
      result "$label" "both refuse" "exit $rc_new: $(first_error "$WORK/new/$name.log")"
    else
      local why_old why_new
      why_old=$(first_error "$WORK/old/$name.log")
      why_new=$(first_error "$WORK/new/$name.log")
      result "$label" "DIFFERENT" "base exit $rc_old: $why_old; new exit $rc_new: $why_new"
    fi
    return
  fi
  local planes notes ok=1
  compare "$WORK/old/$name.rfb" "$WORK/new/$name.rfb" || ok=0
  planes=$CMP_REPORT notes=$CMP_NOTES
  compare --exr "$WORK/old/$name.exr" "$WORK/new/$name.exr" || ok=0
  if [ "$ok" -eq 1 ]; then
    result "$label" "identical" "$notes"
  else
    result "$label" "DIFFERENT" "planes: $planes; exr: $CMP_REPORT"
  fi
}

# A shipped scene that the base build cannot read (one using a format feature newer than BASE,
# such as keyframes) has nothing to compare with: it is skipped, loudly, when the current tree
# reads it. One the current tree cannot read either stays in, and fails.
KEPT=()
for scene in "${SCENES[@]}"; do
  probe="$WORK/probe.$scene"
  if ! "$OLD_BIN" render "scenes/$scene/scene.json" --res 4x4 --spp 1 --passes 1 -q \
    -o "$probe.exr" >"$probe.log" 2>&1 &&
    "$NEW_BIN" render "scenes/$scene/scene.json" --res 4x4 --spp 1 --passes 1 -q \
      -o "$probe.new.exr" >>"$probe.log" 2>&1; then
    log "SKIPPED scene $scene: the base build cannot read it ($(first_error "$probe.log"))"
  else
    KEPT+=("$scene")
  fi
done
SCENES=("${KEPT[@]}")

T_LOCAL=$SECONDS
log "local renders: ${#SCENES[@]} scenes, base ${BASE:0:12} vs the current tree"
for scene in "${SCENES[@]}"; do
  for integ in "${INTEGRATORS[@]}"; do local_case "$scene" "$integ" default; done
  for integ in "${SOBOL_INTEGRATORS[@]}"; do
    local_case "$scene" "$integ" sobol-gaussian --sampler sobol --filter gaussian
  done
  for integ in "${FRAME_INTEGRATORS[@]}"; do
    local_case "$scene" "$integ" frame3-triangle --frame 3 --filter triangle
  done
done
T_LOCAL=$((SECONDS - T_LOCAL))

# --- old buffers merge with new ones ----------------------------------------------------------

# Pass 0 from the base, pass 1 from the current tree, merged by the current tree: must merge
# (same identity and settings text) and equal the current tree's render of both passes within
# DESIGN.md's merge tolerance.
merge_case() {
  local scene=$1 integ=$2 name="$1.$2.default"
  local label="$scene $integ base0+new1 merge" m="$WORK/merge.$name"
  if [ ! -f "$WORK/new/$name.rfb" ]; then return; fi  # refused: nothing to merge
  if ! "$OLD_BIN" render "scenes/$scene/scene.json" --integrator "$integ" "${COMMON[@]}" \
    --pass-range 0-0 --partial "$m.old0.rfb" -q >"$m.log" 2>&1 ||
    ! "$NEW_BIN" render "scenes/$scene/scene.json" --integrator "$integ" "${COMMON[@]}" \
      --pass-range 1-1 --partial "$m.new1.rfb" -q >>"$m.log" 2>&1; then
    result "$label" "DIFFERENT" "a one-pass render failed: $(first_error "$m.log")"
    return
  fi
  if ! "$NEW_BIN" merge "$m.old0.rfb" "$m.new1.rfb" -o "$m.rfb" >>"$m.log" 2>&1; then
    result "$label" "DIFFERENT" "merge refused: $(first_error "$m.log")"
    return
  fi
  if compare --tolerance "$WORK/new/$name.rfb" "$m.rfb"; then
    result "$label" "$CMP_VERDICT" "$CMP_NOTES"
  else
    result "$label" "DIFFERENT" "$CMP_REPORT"
  fi
}

T_MERGE=$SECONDS
for scene in "${SCENES[@]}"; do
  for integ in "${MERGE_INTEGRATORS[@]}"; do merge_case "$scene" "$integ"; done
done
T_MERGE=$((SECONDS - T_MERGE))

# --- the farm ---------------------------------------------------------------------------------

# farm TAG BIN: a coordinator and one worker of BIN render FARM_INTEGRATORS on cornell-box;
# the fetched EXRs land in $WORK/farm-TAG/<integrator>.exr.
farm() {
  local tag=$1 bin=$2 dir="$WORK/farm-$1"
  mkdir -p "$dir/out"
  : >"$dir/coordinator.log"  # exists before the poll below reads it (the & subshell opens it late)
  "$bin" coordinator --listen 127.0.0.1:0 --state-dir "$dir/state" >"$dir/coordinator.log" 2>&1 &
  local coord=$!
  PIDS+=("$coord")
  local port="" i
  for i in $(seq 1500); do  # up to 30 s on a loaded machine
    port=$(sed -n 's/.*(port \([0-9]*\)).*/\1/p' "$dir/coordinator.log")
    [ -n "$port" ] && break
    alive "$coord" || break
    sleep 0.02
  done
  [ -n "$port" ] || die "$tag coordinator did not start: $(tail -n3 "$dir/coordinator.log")"
  local addr="127.0.0.1:$port" integ job
  local -A jobs=()
  for integ in "${FARM_INTEGRATORS[@]}"; do
    job=$("$bin" submit scenes/cornell-box/scene.json --integrator "$integ" "${COMMON[@]}" \
      --coordinator "$addr" 2>>"$dir/client.log") || die "$tag submit failed: $(tail -n3 "$dir/client.log")"
    jobs[$integ]=$job
  done
  # Started after the submits: --exit-when-idle exits when nothing is queued or leased.
  "$bin" worker --coordinator "$addr" --exit-when-idle --cache-dir "$dir/cache" \
    >"$dir/worker.log" 2>&1 &
  PIDS+=("$!")
  for integ in "${FARM_INTEGRATORS[@]}"; do
    job=${jobs[$integ]}
    timeout 300 "$bin" watch "$job" --coordinator "$addr" >>"$dir/client.log" 2>&1 ||
      die "$tag farm job $job ($integ) did not complete (logs in $dir)"
    "$bin" fetch "$job" -o "$dir/out" --coordinator "$addr" >>"$dir/client.log" 2>&1 ||
      die "$tag fetch of $job failed: $(tail -n3 "$dir/client.log")"
    local exr=("$dir/out/$job".*.exr)
    [ -f "${exr[0]}" ] || die "$tag fetch of $job wrote no EXR"
    mv "${exr[0]}" "$dir/$integ.exr"
  done
  stop "${PIDS[@]}"  # the coordinator, and the worker if it has not exited by itself yet
  PIDS=()
}

T_FARM=$SECONDS
log "farm: cornell-box, ${FARM_INTEGRATORS[*]}, base and current"
farm old "$OLD_BIN"
farm new "$NEW_BIN"
for integ in "${FARM_INTEGRATORS[@]}"; do
  label="cornell-box $integ default farm"
  name="cornell-box.$integ.default"
  if ! compare --exr "$WORK/farm-old/$integ.exr" "$WORK/farm-new/$integ.exr"; then
    result "$label" "DIFFERENT" "base farm vs new farm: $CMP_REPORT"
    continue
  fi
  # The contract: a farm render equals the local render of the same job, same binary.
  fail="" equal=""
  for side in old new; do
    who=$([ "$side" = old ] && echo base || echo new)
    if compare --exr --tolerance "$WORK/farm-$side/$integ.exr" "$WORK/$side/$name.exr"; then
      equal+="$who farm vs local: $CMP_VERDICT, "
    else
      fail+="$who farm vs local: $CMP_REPORT; "
    fi
  done
  if [ -n "$fail" ]; then
    result "$label" "DIFFERENT" "base farm = new farm, but ${fail%; }"
  else
    result "$label" "identical" "base farm = new farm; ${equal%, }"
  fi
done
T_FARM=$((SECONDS - T_FARM))

# --- summary ----------------------------------------------------------------------------------

echo "golden: base ${BASE:0:12} vs current tree: $IDENTICAL identical, $REFUSED both refuse," \
  "$DIFFERENT DIFFERENT (local ${T_LOCAL} s, merge ${T_MERGE} s, farm ${T_FARM} s)"
[ "$DIFFERENT" -eq 0 ]
