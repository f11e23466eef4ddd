#!/usr/bin/env bash
# Time-to-error against Mitsuba 3 on the same scene files (bench/peers.py; docs/performance.md).
#
#   bench/peers.sh [--scale S] [SCENE...]     SCENE: cornell-box veach-mis million veach-bidir
#
# Sets up, once, what the benchmark needs and the build does not: Debian's libllvm19 (Mitsuba's
# LLVM backend needs LLVM >= 17) and a venv with Mitsuba 3.9.1 and numpy from PyPI, in
# ${RAYFARM_BENCH_DIR:-~/.cache/rayfarm-bench}. Mitsuba is never a build or test dependency.
# References are cached there too; the first full run takes about an hour on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${RAYFARM_BENCH_DIR:-$HOME/.cache/rayfarm-bench}
MITSUBA_VERSION=3.9.1
mkdir -p "$WORK"
if ! ldconfig -p | grep -q 'libLLVM-19\|libLLVM.so.19'; then
  sudo=(); [ "$(id -u)" -ne 0 ] && sudo=(sudo)
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >&2
fi
if ! "$WORK/venv/bin/python" -c "import mitsuba, numpy; assert mitsuba.__version__ == '$MITSUBA_VERSION'" 2>/dev/null; then
  python3 -m venv "$WORK/venv"
  "$WORK/venv/bin/pip" install -q "mitsuba==$MITSUBA_VERSION" numpy >&2
fi
# Mitsuba finds LLVM through DRJIT_LIBLLVM_PATH when the default name is not on the path.
if [ -z "${DRJIT_LIBLLVM_PATH:-}" ]; then
  lib=$(ldconfig -p | sed -n 's/.*libLLVM-19.so[^ ]* => \(.*\)/\1/p;s/.*libLLVM.so.19[^ ]* => \(.*\)/\1/p' | head -1)
  [ -n "$lib" ] && export DRJIT_LIBLLVM_PATH="$lib"
fi
./rayfarm --help >/dev/null  # build first (Release)
exec "$WORK/venv/bin/python" bench/peers.py --work "$WORK" "$@"
