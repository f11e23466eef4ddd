#!/usr/bin/env python3
"""Writes scene.json: a many-light test scene for the light BVH (engine/light_bvh.h).

A long floor with boxes on it, lit only by 256 small lights: a grid of 8 x 16 emissive quads facing
down (lamps) at two heights, and 128 small emissive spheres on the floor and on the boxes. Powers
span two decades and colours vary, so selection by power alone sends most samples to lights far
from the point being shaded. Deterministic: run it again and the file is the same.
"""
import json
import math
import os

lamps_x, lamps_z = 8, 16
shapes = [
    {"type": "rectangle", "name": "floor", "material": "floor",
     "transform": [{"scale": [8, 20, 1]}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}},
                   {"translate": [0, 0, -12]}]},
    {"type": "rectangle", "name": "back", "material": "wall",
     "transform": [{"scale": [8, 4, 1]}, {"translate": [0, 4, -32]}]},
    {"type": "rectangle", "name": "plate", "material": "metal",
     "transform": [{"scale": [1.5, 1, 1]}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -60}},
                   {"translate": [0, 0.9, -1]}]},
]
for k in range(10):
    x = -5 + (k % 5) * 2.5
    z = -4 - (k // 5) * 9 - (k % 3) * 2
    h = 0.4 + 0.25 * (k % 4)
    shapes.append({"type": "cube", "name": f"box{k}", "material": "box",
                   "transform": [{"scale": [0.5, h, 0.5]},
                                 {"rotate": {"axis": [0, 1, 0], "angle_deg": 17 * k}},
                                 {"translate": [x, h, z]}]})
for i in range(lamps_x):
    for j in range(lamps_z):
        x = -7 + 2 * i
        z = 4 - 2.2 * j
        y = 3.0 if (i + j) % 2 else 2.2
        scale = 10 ** (((i * 5 + j * 3) % 7) / 3.0)  # power over two decades
        c = [round(0.3 + 0.7 * ((i * 3 + j) % 4) / 3, 3), round(0.4 + 0.6 * (j % 3) / 2, 3),
             round(0.3 + 0.7 * ((i + 2 * j) % 5) / 4, 3)]
        shapes.append({"type": "rectangle", "name": f"lamp_{i}_{j}", "material": "black",
                       "transform": [{"scale": 0.12}, {"rotate": {"axis": [1, 0, 0], "angle_deg": 90}},
                                     {"translate": [x, y, z]}],
                       "emission": {"radiance": [round(v * scale, 3) for v in c]}})
for k in range(128):
    a = k * 2.399963  # golden angle: spread over the floor
    r = 7.5 * math.sqrt((k + 0.5) / 128)
    x = round(r * math.cos(a), 3)
    z = round(-12 + 2.6 * r * math.sin(a), 3)
    radius = 0.03 + 0.02 * (k % 3)
    scale = 10 ** ((k % 5) / 2.0)
    c = [round(0.2 + 0.8 * (k % 3) / 2, 3), round(0.2 + 0.8 * ((k // 3) % 3) / 2, 3), 0.6]
    shapes.append({"type": "sphere", "name": f"bulb_{k}", "material": "black", "radius": radius,
                   "center": [x, radius + 0.01, z],
                   "emission": {"radiance": [round(v * scale, 3) for v in c]}})

scene = {
    "format": "rayfarm-scene",
    "version": 1,
    "camera": {"type": "perspective", "fov_deg": 50,
               "look_at": {"eye": [0, 3.5, 8], "target": [0, 0.5, -8], "up": [0, 1, 0]}},
    "film": {"resolution": [320, 180], "filter": {"type": "box", "radius": 0.5}},
    "render": {"integrator": {"type": "path", "max_depth": 6}, "spp": 64, "passes": 4, "seed": 1},
    "materials": {
        "floor": {"type": "diffuse", "reflectance": [0.6, 0.6, 0.6]},
        "wall": {"type": "diffuse", "reflectance": [0.5, 0.45, 0.4]},
        "box": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]},
        "metal": {"type": "rough_conductor", "tint": 0.9, "roughness": 0.1},
        "black": {"type": "diffuse", "reflectance": 0},
    },
    "shapes": shapes,
}
out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scene.json")
with open(out, "w") as f:
    json.dump(scene, f, indent=1)
    f.write("\n")
print(f"wrote {out}: {lamps_x * lamps_z} lamps, 128 bulbs")
