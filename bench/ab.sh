#!/usr/bin/env bash
# A/B timing of two rayfarm binaries on one render (docs/performance.md): ROUNDS rounds, each
# running A then B with one thread (THREADS=N in the environment for more), the render seconds
# read from the summary line; prints both
# lists, the medians and the minima, and the speed-up A/B of each. Alternating the two spreads a
# shared VM's slow spells over both; the minimum is the run least disturbed.
#
#   bench/ab.sh A B ROUNDS SCENE [render options...]
#   bench/ab.sh /tmp/old/rayfarm build/bin/rayfarm 11 scenes/veach-mis/scene.xml \
#     --res 320x180 --spp 16 --sampler sobol-sequence --filter box -q
set -euo pipefail
if [ $# -lt 4 ]; then
  sed -n '2,9p' "$0" >&2
  exit 2
fi
A=$1 B=$2 ROUNDS=$3 SCENE=$4
shift 4
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
seconds() {  # BINARY OPTIONS...: the render seconds of the summary line "spp N | X s | ..."
  local bin=$1
  shift
  "$bin" --threads "${THREADS:-1}" render "$SCENE" "$@" -o "$out/x.exr" 2>&1 | awk -F'|' '/^spp/ {print $2+0}'
}
ta=() tb=()
for ((i = 0; i < ROUNDS; i++)); do
  ta+=("$(seconds "$A" "$@")")
  tb+=("$(seconds "$B" "$@")")
done
python3 - "${ta[*]}" "${tb[*]}" <<'PY'
import statistics, sys
a, b = ([float(x) for x in arg.split()] for arg in sys.argv[1:3])
print('A', a)
print('B', b)
ma, mb = statistics.median(a), statistics.median(b)
print('median A %.3f s, B %.3f s: x%.3f | min A %.3f s, B %.3f s: x%.3f'
      % (ma, mb, ma / mb, min(a), min(b), min(a) / min(b)))
PY
