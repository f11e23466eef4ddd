#!/usr/bin/env python3
"""Writes scene.json: a one-second shot (frames 0-23 at 24 fps) for motion blur.

A small room lit by a ceiling lamp: a ball bounces across it three times, a cube spins two full
turns on the floor, and the camera dollies in slightly. A 180-degree shutter (open for half of each frame), so
every frame shows the blur a film camera would. The ball's track is keyed four times a frame
(its arcs between keys are chords a quarter of a frame long); the cube's turn once a frame (30
degrees, interpolated by slerp). Deterministic: run it again and the file is the same.

    python3 scenes/shot/make_scene.py
    ./rayfarm render scenes/shot/scene.json --frames 0-23 -o shot/shot.####.exr
"""
import json
import math
import os

FRAMES = 24
BALL_R = 0.35


def ball_key(f):
    """The ball's centre at frame f (a float): across the room, three bounces."""
    x = -1.4 + 2.8 * f / FRAMES
    phase = (f / FRAMES) * 3.0  # three bounces
    y = BALL_R + 1.6 * abs(math.sin(math.pi * phase))
    return [round(x, 6), round(y, 6), 0.3]


shapes = [
    {"type": "rectangle", "name": "floor", "material": "white",
     "transform": [{"scale": 2.5}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}}]},
    {"type": "rectangle", "name": "back", "material": "white",
     "transform": [{"scale": 2.5}, {"translate": [0, 2.5, -2.5]}]},
    {"type": "rectangle", "name": "left", "material": "red",
     "transform": [{"scale": 2.5}, {"rotate": {"axis": [0, 1, 0], "angle_deg": 90}},
                   {"translate": [-2.5, 2.5, 0]}]},
    {"type": "rectangle", "name": "right", "material": "green",
     "transform": [{"scale": 2.5}, {"rotate": {"axis": [0, 1, 0], "angle_deg": -90}},
                   {"translate": [2.5, 2.5, 0]}]},
    {"type": "rectangle", "name": "ceiling", "material": "white",
     "transform": [{"scale": 2.5}, {"rotate": {"axis": [1, 0, 0], "angle_deg": 90}},
                   {"translate": [0, 5, 0]}]},
    {"type": "rectangle", "name": "lamp", "material": "black",
     "emission": {"radiance": [18, 16, 13]},
     "transform": [{"scale": 0.6}, {"rotate": {"axis": [1, 0, 0], "angle_deg": 90}},
                   {"translate": [0, 4.99, 0]}]},
    {"type": "sphere", "name": "ball", "material": "orange", "radius": BALL_R,
     "keyframes": [{"frame": k / 4, "transform": {"translate": ball_key(k / 4)}}
                   for k in range(4 * FRAMES + 1)]},
    {"type": "cube", "name": "cube", "material": "gold",
     "transform": [{"scale": 0.35}, {"translate": [0, 0.35, 0]}],
     "keyframes": [{"frame": f, "transform": [{"rotate": {"axis": [0, 1, 0], "angle_deg": 30 * f}},
                                               {"translate": [0.2, 0, -1.2]}]}
                   for f in range(FRAMES + 1)]},
]

scene = {
    "format": "rayfarm-scene",
    "version": 1,
    "time": {"fps": 24, "shutter": {"open": 0, "close": 0.5}},
    "camera": {"fov_deg": 36, "keyframes": [
        {"frame": 0, "look_at": {"eye": [0, 2.3, 9.0], "target": [0, 1.5, 0], "up": [0, 1, 0]}},
        {"frame": FRAMES, "look_at": {"eye": [0, 2.1, 8.2], "target": [0, 1.5, 0], "up": [0, 1, 0]}}]},
    "film": {"resolution": [320, 240], "filter": {"type": "gaussian"}},
    "render": {"spp": 64, "integrator": {"type": "path", "max_depth": 6}},
    "materials": {
        "white": {"type": "diffuse", "reflectance": 0.7},
        "red": {"type": "diffuse", "reflectance": [0.6, 0.08, 0.06]},
        "green": {"type": "diffuse", "reflectance": [0.12, 0.45, 0.1]},
        "black": {"type": "diffuse", "reflectance": 0},
        "orange": {"type": "plastic", "reflectance": [0.8, 0.3, 0.05], "roughness": 0.1},
        "gold": {"type": "rough_conductor", "preset": "gold", "roughness": 0.2},
    },
    "shapes": shapes,
}

here = os.path.dirname(os.path.abspath(__file__))
with open(os.path.join(here, "scene.json"), "w") as f:
    json.dump(scene, f, indent=1)
    f.write("\n")
