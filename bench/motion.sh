#!/usr/bin/env bash
# What motion costs (docs/performance.md, "Motion blur"): the million-triangle scene
# (bench/make_million_scene.py) rendered still and with one object moving 10% of the room's
# extent during the shutter plus a moving camera, at equal spp, interleaved ROUNDS times; then a
# 24-frame shot of the moving scene at 1 spp, whose log gives the shot's set-up (parse and the
# geometry no frame changes) and each frame's own BVH build.
#
#   bench/motion.sh [ROUNDS] [SPP] [RES]     defaults: 3 rounds, 64 spp, 256
#   THREADS=N (default 1), RAYFARM=path of the binary (default build/bin/rayfarm)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
ROUNDS=${1:-3} SPP=${2:-64} RES=${3:-256}
BIN=${RAYFARM:-$ROOT/build/bin/rayfarm}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
python3 "$ROOT/bench/make_million_scene.py" "$out" --res "$RES" >/dev/null
python3 - "$out" <<'PY'
import json, sys
d = sys.argv[1]
still = json.load(open(d + '/scene.json'))
moving = json.loads(json.dumps(still))
# The gold spheres (a quarter of the triangles) slide 0.2 units (10% of the 2-unit room) along +x
# over frame 0's shutter, and on at that speed over a 24-frame shot; the camera drifts 0.05.
moving['time'] = {'fps': 24, 'shutter': {'open': 0, 'close': 1}}
for s in moving['shapes']:
    if s['name'] == 'spheres_gold':
        s['keyframes'] = [{'frame': 0}, {'frame': 24, 'transform': {'translate': [4.8, 0, 0]}}]
cam = moving['camera']
look = cam.pop('look_at')
eye2 = [look['eye'][0] + 1.2] + look['eye'][1:]
cam['keyframes'] = [{'frame': 0, 'look_at': look},
                    {'frame': 24, 'look_at': dict(look, eye=eye2)}]
json.dump(moving, open(d + '/moving.json', 'w'), indent=1)
PY
seconds() {  # SCENE: the render seconds of the summary line
  "$BIN" --threads "${THREADS:-1}" render "$1" --spp "$SPP" --passes 16 -o "$out/x.exr" 2>&1 |
    awk -F'|' '/^spp/ {print $2+0}'
}
ts=() tm=()
for ((i = 0; i < ROUNDS; i++)); do
  ts+=("$(seconds "$out/scene.json")")
  tm+=("$(seconds "$out/moving.json")")
done
"$BIN" --threads "${THREADS:-1}" render "$out/moving.json" --frames 0-23 --spp 1 --passes 1 \
  -o "$out/shot.####.exr" >"$out/shot.log" 2>&1
python3 - "${ts[*]}" "${tm[*]}" "$out/shot.log" "$SPP" "$RES" <<'PY'
import re, statistics, sys
still, moving = ([float(x) for x in a.split()] for a in sys.argv[1:3])
log = open(sys.argv[3]).read()
spp, res = sys.argv[4], sys.argv[5]
print('still ', still)
print('moving', moving)
ms, mm = statistics.median(still), statistics.median(moving)
print('%sx%s, %s spp: median still %.3f s, moving %.3f s: x%.3f | min x%.3f'
      % (res, res, spp, ms, mm, mm / ms, min(moving) / min(still)))
m = re.search(r'parsed in ([\d.]+) s, renderer set up in ([\d.]+) s', log)
frames = [float(x) for x in re.findall(r'frame \d+: BVH built in ([\d.]+) s', log)]
if not m or len(frames) != 24:
    sys.exit('motion.sh: the shot log lacks its set-up lines:\n' + log)
parse, setup = float(m.group(1)), float(m.group(2))
first = parse + setup + frames[0]
later = statistics.median(frames[1:])
print('24-frame shot: parse %.3f s + geometry %.3f s + frame 0 BVH %.4f s = first frame %.3f s; '
      'later frames BVH median %.4f s (max %.4f): %.4f of the first frame\'s set-up'
      % (parse, setup, frames[0], first, later, max(frames[1:]), later / first))
PY
