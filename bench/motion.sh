#!/usr/bin/env bash
# What motion costs (docs/performance.md, "Motion blur"): the million-triangle scene
# (bench/make_million_scene.py) rendered still and with one object moving 10% of the room's
# extent during the shutter plus a moving camera, and with that object deforming instead (the same
# slide plus a squash, as vertex keys), at equal spp, interleaved ROUNDS times; then a
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
# The same with the gold spheres deforming instead of sliding: the same slide plus a squash to 90%
# of their height above the floor over the shot (vertex keys from a second PLY file with the
# same triangles, so every vertex moves on its own), the camera moving as above.
import struct
ply = open(d + '/spheres_gold.ply', 'rb').read()
end = ply.index(b'end_header\n') + len(b'end_header\n')
header = ply[:end].decode('ascii').split('\n')
nv = int(next(l for l in header if l.startswith('element vertex')).split()[2])
stride = 24 if 'property float nx' in header else 12
body = bytearray(ply[end:])
floor_y = min(struct.unpack_from('<f', body, i * stride + 4)[0] for i in range(nv))
for i in range(nv):
    x, y, z = struct.unpack_from('<3f', body, i * stride)
    struct.pack_into('<3f', body, i * stride, x + 4.8, floor_y + 0.9 * (y - floor_y), z)
open(d + '/spheres_gold_24.ply', 'wb').write(ply[:end] + bytes(body))
deforming = json.loads(json.dumps(moving))
for s in deforming['shapes']:
    if s['name'] == 'spheres_gold':
        del s['keyframes']
        s['deform'] = [{'frame': 0}, {'frame': 24, 'file': 'spheres_gold_24.ply'}]
json.dump(deforming, open(d + '/deforming.json', 'w'), indent=1)
PY
seconds() {  # SCENE: the render seconds of the summary line
  "$BIN" --threads "${THREADS:-1}" render "$1" --spp "$SPP" --passes 16 -o "$out/x.exr" 2>&1 |
    awk -F'|' '/^spp/ {print $2+0}'
}
ts=() tm=() td=()
for ((i = 0; i < ROUNDS; i++)); do
  ts+=("$(seconds "$out/scene.json")")
  tm+=("$(seconds "$out/moving.json")")
  td+=("$(seconds "$out/deforming.json")")
done
"$BIN" --threads "${THREADS:-1}" render "$out/moving.json" --frames 0-23 --spp 1 --passes 1 \
  -o "$out/shot.####.exr" >"$out/shot.log" 2>&1
"$BIN" --threads "${THREADS:-1}" render "$out/deforming.json" --frames 0-23 --spp 1 --passes 1 \
  -o "$out/shot.####.exr" >"$out/deform.log" 2>&1
python3 - "${ts[*]}" "${tm[*]}" "${td[*]}" "$out/shot.log" "$SPP" "$RES" "$out/deform.log" <<'PY'
import re, statistics, sys
still, moving, deforming = ([float(x) for x in a.split()] for a in sys.argv[1:4])
log = open(sys.argv[4]).read()
spp, res = sys.argv[5], sys.argv[6]
print('still    ', still)
print('moving   ', moving)
print('deforming', deforming)
ms, mm, md = (statistics.median(x) for x in (still, moving, deforming))
print('%sx%s, %s spp: median still %.3f s, moving %.3f s: x%.3f | min x%.3f'
      % (res, res, spp, ms, mm, mm / ms, min(moving) / min(still)))
print('%sx%s, %s spp: median still %.3f s, deforming %.3f s: x%.3f | min x%.3f'
      % (res, res, spp, ms, md, md / ms, min(deforming) / min(still)))
dframes = [float(x) for x in re.findall(r'frame \d+: BVH built in ([\d.]+) s',
                                        open(sys.argv[7]).read())]
if len(dframes) == 24:
    print('deforming shot: frame BVH build median %.4f s (max %.4f)'
          % (statistics.median(dframes), max(dframes)))
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
