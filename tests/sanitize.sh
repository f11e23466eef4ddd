#!/usr/bin/env bash
# The sanitizer stage of CI (.ci/run): one clang build with AddressSanitizer and UBSan
# (-DRAYFARM_SANITIZE=address,undefined) and libFuzzer instrumentation (-DRAYFARM_FUZZ=ON), in
# build-san/, that serves both
#   1. the unit and farm tests, except the statistical ones (SLOW below: convergence and
#      chi-square tests, furnace series, motion blur's means of stills; their code the fast
#      tests run too, and they would take most of an hour under the sanitizers), with the
#      CLI, coordinator and worker processes the farm tests start instrumented as well; a
#      sanitizer report fails the test that triggered it;
#   2. the fuzz targets (fuzz/run.sh, run on the same build).
#
#   tests/sanitize.sh            build, run the tests, then fuzz/run.sh
#   tests/sanitize.sh --no-fuzz  build and run the tests only
#
# Budget on the 2-core CI machine (figures in docs/reliability.md): 14 to 17 minutes to build
# from scratch, 13 to 14 to run the tests, 1.5 to fuzz; under 35 minutes in all (28.5 to 32.5
# measured).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${RAYFARM_SANITIZE_BUILD_DIR:-$ROOT/build-san}"
FUZZ=1
[ "${1:-}" = "--no-fuzz" ] && FUZZ=0
log() { printf 'sanitize: %s\n' "$*" >&2; }

# Statistical tests left out (ctest -E): they check convergence and sampling densities with many
# samples, and cover no code path the remaining tests miss.
SLOW='^(Bdpt|HarnessCornell|HarnessCornellDepth|LightBvh|DirectIntegrator|ProgressivePhotonMapping|'
SLOW+='FilterTest|BsdfEnergy|BsdfSampling|RoughConductor|RelMse|CornellBox|InstantRadiosity|'
SLOW+='Furnace|WhiteFurnace|SamplerTest|LightSampling|Integrators|PathTracer)\.|'
SLOW+='Agree|Converge|MatchesTheReference|ImageMeansMatch|MeanOfStills|^AlbedoDepth/Furnace\.|'
# and the benchmark script's smoke test (it shows bench/farm_bench.sh runs; the farm paths it
# drives are the farm tests' own; about 110 s here)
SLOW+='^Farm\.BenchmarkScript'

# clang and libFuzzer from Debian (the bootstrap of ./rayfarm installed everything else).
"$ROOT/tools/install-debian-packages.sh" clang libfuzzer-14-dev

start=$(date +%s)
"$ROOT/tests/sanitize_configure.sh" "$BUILD"
mkdir -p "$BUILD"
cmake --build "$BUILD" -- -j"$(nproc)" >"$BUILD/build.log" 2>&1 ||
  { tail -40 "$BUILD/build.log" >&2; log "build failed"; exit 1; }
built=$(date +%s)
log "built in $((built - start)) s"

# A sanitizer report ends the process with a failure; leaks are reported at exit.
# new_delete_type_mismatch=0: Debian's OpenImageIO 2.4 frees its TextureSystem through the base
# class with a sized delete inside the library (TextureSystem::create/destroy), which ASan reports
# against every texture test; nothing of ours is involved.
export ASAN_OPTIONS="detect_leaks=1:new_delete_type_mismatch=0:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export LSAN_OPTIONS="suppressions=$ROOT/tests/lsan.supp:print_suppressions=0"
status=0
(cd "$BUILD" && ctest -L unit -E "$SLOW" -j"$(nproc)" --output-on-failure --timeout 1200 \
   >"$BUILD/ctest.log" 2>&1) || status=1
tail -4 "$BUILD/ctest.log" >&2
# On a failure: which tests, then each failed assertion with a few lines of its values (CI
# shows only this output's tail, not ctest.log).
[ $status -eq 0 ] || {
  grep -E "Failed|\*\*\*|ERROR: AddressSanitizer|runtime error" "$BUILD/ctest.log" | head -40 >&2
  grep -E -A6 ": Failure$" "$BUILD/ctest.log" | cut -c1-300 | head -60 >&2
}
tested=$(date +%s)
log "tests in $((tested - built)) s: $(grep -o '[0-9]* tests failed out of [0-9]*' "$BUILD/ctest.log" || true)"

if [ $FUZZ -eq 1 ]; then
  RAYFARM_FUZZ_BUILD_DIR="$BUILD" "$ROOT/fuzz/run.sh" || status=1
fi
log "total $(($(date +%s) - start)) s"
exit $status
