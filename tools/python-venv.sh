#!/usr/bin/env bash
# The Python client's test venv (clients/python/README.md): Debian's Python with its
# python3-grpcio, python3-protobuf, numpy, pytest and OpenImageIO bindings
# (--system-site-packages), the client installed offline from the repository, and pyoidn from
# PyPI for the denoising test. `./rayfarm test` runs it before ctest; the ctest test
# Python.Client runs pytest in it (and is skipped, saying why, where there is none).
#
#   tools/python-venv.sh [VENV]      default: build/pyvenv
#
# Reinstalls the client only when clients/python or proto/rayfarm.proto changed. Without PyPI
# (offline) the venv is made without pyoidn and the denoising test is skipped, loudly.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${1:-$ROOT/build/pyvenv}"
PYOIDN=pyoidn==2.5.1.0
log() { printf 'python-venv: %s\n' "$*" >&2; }

"$ROOT/tools/install-debian-packages.sh" python3-venv python3-setuptools python3-wheel python3-grpcio \
  python3-protobuf python3-numpy python3-pytest python3-openimageio python3-cffi \
  protobuf-compiler protobuf-compiler-grpc chromium chromium-driver python3-selenium

# Debian's interpreter, whatever python3 comes first on PATH: the system packages are its.
if [ ! -x "$VENV/bin/python" ]; then
  log "making $VENV"
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
stamp=$(cd "$ROOT" && { find clients/python -type f -not -path '*/__pycache__/*' |
  LC_ALL=C sort | xargs cat; cat proto/rayfarm.proto; } | sha256sum | cut -c1-16)
if [ "$(cat "$VENV/.client-stamp" 2>/dev/null)" != "$stamp" ]; then
  log "installing clients/python"
  # A copy, so that the build writes nothing into the source tree (build/, *.egg-info).
  src=$(mktemp -d)
  trap 'rm -rf "$src"' EXIT
  mkdir -p "$src/clients" "$src/proto"
  cp -r "$ROOT/clients/python" "$src/clients/"
  cp "$ROOT/proto/rayfarm.proto" "$src/proto/"
  "$VENV/bin/pip" install --quiet --no-build-isolation --no-deps --no-index "$src/clients/python"
  echo "$stamp" >"$VENV/.client-stamp"
fi
if ! "$VENV/bin/python" -c 'import pyoidn' 2>/dev/null; then
  "$VENV/bin/pip" install --quiet --disable-pip-version-check "$PYOIDN" ||
    log "WARNING: $PYOIDN could not be installed (no PyPI?); the denoising test will be skipped"
fi
