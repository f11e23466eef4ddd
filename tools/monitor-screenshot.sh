#!/usr/bin/env bash
# Copies the web monitor's screenshot that the browser test (ctest Browser.Monitor) wrote to the
# build directory into docs/img for the README. CI never runs this: a test does not rewrite a
# tracked file.
#   tools/monitor-screenshot.sh [BUILD_DIR]     default: build
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
[ -f "$BUILD/monitor.png" ] ||
  { echo "no $BUILD/monitor.png: run the test first (cd $BUILD && ctest -R Browser.Monitor)" >&2; exit 1; }
cp "$BUILD/monitor.png" "$ROOT/docs/img/monitor.png"
echo "docs/img/monitor.png updated from $BUILD/monitor.png"
