#!/usr/bin/env bash
# Configures the one sanitizer build (tests/sanitize.sh, fuzz/run.sh) in directory $1 unless it
# is configured already: clang, -O1 with line tables, AddressSanitizer + UBSan, and libFuzzer
# instrumentation with the fuzz targets (RAYFARM_FUZZ).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$1"
if [ ! -f "$BUILD/build.ninja" ]; then
  CC=clang CXX=clang++ cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" -DRAYFARM_FUZZ=ON \
    -DRAYFARM_SANITIZE=address,undefined >/dev/null
fi
