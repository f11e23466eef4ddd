#!/usr/bin/env bash
# A local render of a frame larger than its memory budget (docs/performance.md, "Frames larger
# than memory"): `rayfarm render` of the Cornell box at RES with --memory BUDGET, the spill files
# in DIR. Prints the frame's planes (104 bytes a pixel), wall time and peak RSS (GNU time), and
# the most disk taken meanwhile (df of DIR's file system sampled every half second: the spill
# files, unlinked, plus the EXR and PNG being written; anything else writing there counts too).
#
#   bench/big_frame.sh [RES=16384x16384] [BUDGET=1G] [DIR=build/big-frame]
#   SPP=1 PASSES=1 DEPTH=1 TILE=256 RAYFARM_BIN=... bench/big_frame.sh ...
set -euo pipefail
cd "$(dirname "$0")/.."
RES=${1:-16384x16384} BUDGET=${2:-1G} DIR=${3:-build/big-frame}
SPP=${SPP:-1} PASSES=${PASSES:-1} DEPTH=${DEPTH:-1} TILE=${TILE:-256}
B=${RAYFARM_BIN:-build/bin/rayfarm}
[ -n "${RAYFARM_BIN:-}" ] || ninja -C build rayfarm >/dev/null
mkdir -p "$DIR"
rm -f "$DIR"/frame.exr "$DIR"/frame.png
used() { df -B1 --output=used "$DIR" | tail -1; }
base=$(used)
peak=$base
/usr/bin/time -f '%e %M' -o "$DIR/time" "$B" render scenes/cornell-box/scene.json --res "$RES" \
  --spp "$SPP" --passes "$PASSES" --max-depth "$DEPTH" --tile-size "$TILE" --memory "$BUDGET" \
  --spill-dir "$DIR" -q -o "$DIR/frame.exr" >"$DIR/summary" &
P=$!
while kill -0 $P 2>/dev/null; do
  u=$(used)
  [ "$u" -gt "$peak" ] && peak=$u
  sleep 0.5
done
wait $P
read -r wall rss_kb <"$DIR/time"
w=${RES%x*} h=${RES#*x}
exr=$(stat -c %s "$DIR/frame.exr")
awk -v w="$w" -v h="$h" -v b="$BUDGET" -v t="$wall" -v r="$rss_kb" -v d="$((peak - base))" \
  -v e="$exr" -v spp="$SPP" -v passes="$PASSES" \
  'BEGIN { printf "%dx%d, %d spp in %d passes: planes %.1f GiB; --memory %s: wall %.0f s, peak RSS %.0f MiB, disk peak %.1f GiB, EXR %.1f GiB\n",
           w, h, spp, passes, w * h * 104 / 2^30, b, t, r / 1024, d / 2^30, e / 2^30 }'
cat "$DIR/summary"
