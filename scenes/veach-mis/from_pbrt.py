#!/usr/bin/env python3
"""Regenerates scene.json from Bitterli's pbrt-v4 Veach MIS scene (../shared/scenes/veach-mis).

Run from this directory: python3 from_pbrt.py ../../../shared/scenes/veach-mis/pbrt/scene-v4.pbrt
The geometry, materials, lights and camera are copied; the film is halved to 640x360.
"""
import json
import re
import sys

text = open(sys.argv[1]).read()


def numbers(block, name):
    m = re.search(r'"[a-z0-9]+ ' + name + r'"\s*\[([^\]]*)\]', block)
    return [float(v) for v in m.group(1).split()] if m else None


materials = {}
for m in re.finditer(r'MakeNamedMaterial "(\w+)"(.*?)(?=MakeNamedMaterial|NamedMaterial "|\Z)', text, re.S):
    name, body = m.group(1), m.group(2)
    if '"conductor"' in body:
        materials[name] = {"type": "rough_conductor", "roughness": numbers(body, "uroughness")[0],
                           "eta": numbers(body, "eta"), "k": numbers(body, "k")}
    else:
        materials[name] = {"type": "diffuse", "reflectance": numbers(body, "reflectance")}

shapes = []
current = None
for m in re.finditer(r'NamedMaterial "(\w+)"|Shape "trianglemesh"(.*?)(?="integer indices"\s*\[[^\]]*\])("integer indices"\s*\[[^\]]*\])', text, re.S):
    if m.group(1):
        current = m.group(1)
        continue
    block = m.group(2) + m.group(3)
    pos = numbers(block, "P")
    idx = [int(v) for v in numbers(block, "indices")]
    shapes.append({"type": "mesh", "name": current, "material": current, "positions": pos, "indices": idx})

for m in re.finditer(r'"rgb L" \[([^\]]*)\].*?Transform \[([^\]]*)\].*?"float radius" \[([^\]]*)\]', text, re.S):
    L = [float(v) for v in m.group(1).split()]
    t = [float(v) for v in m.group(2).split()]
    r = float(m.group(3))
    shapes.append({"type": "sphere", "name": "light r=%g" % r, "material": "Null", "center": t[12:15],
                   "radius": r, "emission": {"radiance": L}})

scene = {
    "format": "rayfarm-scene", "version": 1,
    # pbrt's world-to-camera matrix puts the eye at (28.2792, 3.5, 0) looking down -x, +y up.
    "camera": {"fov_deg": 20.114292,
               "look_at": {"eye": [28.2792, 3.5, 0], "target": [0, 3.5, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [640, 360], "filter": {"type": "triangle", "radius": 1}},
    "render": {"integrator": {"type": "path", "max_depth": 3}, "spp": 64, "passes": 16, "seed": 1},
    "materials": materials,
    "shapes": shapes,
}
json.dump(scene, open("scene.json", "w"), indent=1)
print("wrote scene.json:", len(shapes), "shapes,", len(materials), "materials")
