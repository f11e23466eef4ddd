#!/usr/bin/env bash
# The client's pytest suite in a venv made by tools/python-venv.sh (ctest's Python.Client).
#   clients/python/run-tests.sh VENV [pytest args]
# Exit 77 (ctest: skipped) when VENV has no client installed.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$1"
shift
if ! "$VENV/bin/python" -c 'import rayfarm._proto.rayfarm_pb2' 2>/dev/null; then
  echo "no Python client venv at $VENV: make it with tools/python-venv.sh $VENV" >&2
  exit 77
fi
# From a scratch directory: the installed client is imported, never the source tree's copy
# (which has no generated stubs).
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
cd "$scratch"
"$VENV/bin/python" -m pytest -q -p no:cacheprovider "$HERE/tests" "$@"
