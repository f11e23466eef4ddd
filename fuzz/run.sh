#!/usr/bin/env bash
# The fuzzing stage (fuzz/README.md): builds the libFuzzer targets with clang, AddressSanitizer
# and UBSan in build-san/ (the sanitizer build, tests/sanitize.sh), then runs each for a fixed number of inputs from a fixed seed (so a
# run is repeatable), its corpus seeded from the repository's test files and scenes. Exit status
# 1 and the crashing input in build-san/findings/ when a target crashes, leaks, hangs or runs
# out of memory.
#
#   fuzz/run.sh [SCALE]    SCALE times each target's default number of inputs (default 1)
#
# Budget on the 2-core CI machine: the fuzz targets alone build in about 4 minutes from scratch
# (the whole sanitizer build, tests/sanitize.sh, in about 11); the 9 targets run in under
# 3 minutes (each default is about 15 s of inputs there).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${RAYFARM_FUZZ_BUILD_DIR:-$ROOT/build-san}"
SCALE="${1:-1}"
# Inputs per target at SCALE 1: about 15 s each on the CI machine (the scene targets write a file
# and run a whole importer per input, the others parse from memory; a frame range the fuzzer
# grows to a million frames costs milliseconds under the sanitizers, hence its smaller count).
declare -A RUNS=([fuzz_scene_json]=9000 [fuzz_scene_pbrt]=12000 [fuzz_scene_xml]=24000
                 [fuzz_scene_gltf]=12000 [fuzz_scene_glb]=30000 [fuzz_mesh]=60000 [fuzz_rfb]=60000
                 [fuzz_frame_range]=5000 [fuzz_coordinator]=400)
log() { printf 'fuzz: %s\n' "$*" >&2; }

"$ROOT/tools/install-debian-packages.sh" clang libfuzzer-14-dev

start=$(date +%s)
"$ROOT/tests/sanitize_configure.sh" "$BUILD"
targets=(fuzz_scene_json fuzz_scene_pbrt fuzz_scene_xml fuzz_scene_gltf fuzz_scene_glb fuzz_mesh fuzz_rfb
         fuzz_frame_range fuzz_coordinator)
cmake --build "$BUILD" --target "${targets[@]}" -- -j"$(nproc)" >"$BUILD/build.log" 2>&1 ||
  { tail -40 "$BUILD/build.log" >&2; log "build failed"; exit 1; }
log "built in $(( $(date +%s) - start )) s"

# Seed corpora: the repository's own files of each kind (tests/data/<format>/, the shipped scenes,
# fuzz/seeds/), one flat directory per target; new inputs go to a scratch directory.
WORK="$BUILD/run"
rm -rf "$WORK"
mkdir -p "$WORK" "$BUILD/findings"
seed_dir() {  # seed_dir TARGET PREFIX_BYTE FIND-ARGS...: copies matching files, optionally prefixed
  local t="$1" prefix="$2"; shift 2
  mkdir -p "$WORK/$t/seeds" "$WORK/$t/new"
  local i=0
  while IFS= read -r -d '' f; do
    i=$((i + 1))
    if [ -n "$prefix" ]; then
      { printf "$prefix"; cat "$f"; } >"$WORK/$t/seeds/$i"
    else
      cp "$f" "$WORK/$t/seeds/$i"
    fi
  done < <(find "$ROOT/tests/data" "$ROOT/scenes" "$ROOT/fuzz/seeds" "$ROOT/fuzz/regressions" \
             -type f -size -64k "$@" -print0 2>/dev/null)
}
seed_dir fuzz_scene_json "" -name '*.json'
seed_dir fuzz_scene_pbrt "" -name '*.pbrt'
seed_dir fuzz_scene_xml "" -name '*.xml'
seed_dir fuzz_scene_gltf "" -name '*.gltf'
seed_dir fuzz_scene_glb "" -name '*.glb'
seed_dir fuzz_mesh '\\x00' -name '*.obj'
seed_dir fuzz_mesh '\\x01' -name '*.ply'
seed_dir fuzz_rfb "" -name '*.rfb'
seed_dir fuzz_frame_range "" -name '*.frames'
seed_dir fuzz_coordinator "" -name '*.ops'

status=0
for t in "${targets[@]}"; do
  t0=$(date +%s)
  # -seed fixes the mutation sequence; -runs bounds the work; timeouts and memory limits turn
  # hangs and runaway allocations into findings.
  runs=$(( ${RUNS[$t]} * SCALE ))
  if "$BUILD/fuzz/$t" -seed=1 -runs="$runs" -max_len=16384 -timeout=10 -rss_limit_mb=2048 \
      -malloc_limit_mb=1024 -print_final_stats=1 -artifact_prefix="$BUILD/findings/$t-" \
      "$WORK/$t/new" "$WORK/$t/seeds" >"$WORK/$t.log" 2>&1; then
    log "$t: $(grep -o 'stat::number_of_executed_units: *[0-9]*' "$WORK/$t.log" | grep -o '[0-9]*$') inputs, $(ls "$WORK/$t/seeds" | wc -l) seeds, $(( $(date +%s) - t0 )) s, no finding"
  else
    status=1
    log "$t: FINDING after $(( $(date +%s) - t0 )) s:"
    grep -E "ERROR|SUMMARY|Test unit written|==[0-9]+==" "$WORK/$t.log" | head -12 >&2
  fi
done
log "total $(( $(date +%s) - start )) s"
exit $status
