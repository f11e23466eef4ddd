#!/usr/bin/env python3
"""Writes the efficiency benchmark's large scene: a Cornell-like room with a displaced floor and
16 tessellated spheres in four materials, as binary PLY meshes plus the same scene in rayfarm's
JSON (scene.json) and Mitsuba 3 XML (scene.xml), into a directory.

    python3 bench/make_million_scene.py OUT_DIR [--triangles 1000000] [--res 512]

Deterministic (no randomness; the same arguments give the same bytes) and Python 3 standard
library only. About 40% of the triangles are the displaced floor grid, 60% the spheres; the
walls and the light are two triangles each.

Materials, identical in both files (docs/formats/mitsuba.md, "Benchmark scenes"):
- diffuse walls, floor and spheres: rayfarm "diffuse" = Mitsuba "twosided" "diffuse";
- rough gold: rayfarm "rough_conductor" (GGX alpha 0.15, RGB eta/k of rayfarm's gold preset) =
  Mitsuba "twosided" "roughconductor" (ggx, alpha 0.15, the same rgb eta/k);
- silver mirror: rayfarm "conductor" (RGB eta/k below) = Mitsuba "twosided" "conductor" (the same
  rgb eta/k). (A rough plastic was here: Mitsuba's roughplastic weighs its diffuse base with
  precomputed rough transmittance tables where rayfarm uses the smooth Fresnel terms, so the two
  images differed and the benchmark could not compare them.)
- glass: rayfarm "dielectric" ior 1.5 = Mitsuba "dielectric" int_ior 1.5, ext_ior 1;
- the light: a one-sided area light facing down.
"""
import argparse
import json
import math
import os
import struct

ROOM_LIGHT = (15.0, 13.0, 10.0)
GOLD_ETA = (0.143, 0.374, 1.442)
GOLD_K = (3.983, 2.385, 1.603)
SILVER_ETA = (0.155, 0.117, 0.138)
SILVER_K = (4.83, 3.12, 2.15)


def write_ply(path, positions, indices, normals=None):
    with open(path, 'wb') as f:
        header = ['ply', 'format binary_little_endian 1.0', 'element vertex %d' % len(positions),
                  'property float x', 'property float y', 'property float z']
        if normals:
            header += ['property float nx', 'property float ny', 'property float nz']
        header += ['element face %d' % (len(indices) // 3), 'property list uchar int vertex_indices',
                   'end_header']
        f.write(('\n'.join(header) + '\n').encode('ascii'))
        vertex = struct.Struct('<6f' if normals else '<3f')
        for i, p in enumerate(positions):
            f.write(vertex.pack(*(tuple(p) + (tuple(normals[i]) if normals else ()))))
        face = struct.Struct('<B3i')
        for t in range(0, len(indices), 3):
            f.write(face.pack(3, indices[t], indices[t + 1], indices[t + 2]))


def quad(p0, p1, p2, p3):
    """Two triangles, wound p0 p1 p2 / p0 p2 p3 (right-hand normal along (p1-p0)x(p2-p0))."""
    return [p0, p1, p2, p3], [0, 1, 2, 0, 2, 3]


def merge(parts):
    pos, idx = [], []
    for p, i in parts:
        base = len(pos)
        pos += p
        idx += [base + k for k in i]
    return pos, idx


def height(x, z):
    return 0.04 * (math.sin(7.0 * x) * math.cos(5.0 * z) + 0.5 * math.sin(13.0 * x + 3.0 * z))


def displaced_grid(n):
    """An n x n grid of quads over the floor [-1, 1]^2, displaced by height(), normal up."""
    pos = []
    for j in range(n + 1):
        for i in range(n + 1):
            x, z = -1 + 2.0 * i / n, -1 + 2.0 * j / n
            pos.append((x, 0.05 + height(x, z), z))
    idx = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c, d = a + 1, a + n + 1, a + n + 2
            idx += [a, c, b, b, c, d]  # (c - a) x (b - a) points up (+y)
    return pos, idx


def sphere(center, r, n_theta, n_phi):
    """UV sphere, pole +y, outward winding, unit vertex normals."""
    pos, nrm = [], []
    for i in range(n_theta + 1):
        th = math.pi * i / n_theta
        for j in range(n_phi + 1):
            ph = 2 * math.pi * j / n_phi
            n = (math.sin(th) * math.cos(ph), math.cos(th), -math.sin(th) * math.sin(ph))
            nrm.append(n)
            pos.append(tuple(center[k] + r * n[k] for k in range(3)))
    idx = []
    row = n_phi + 1
    for i in range(n_theta):
        for j in range(n_phi):
            a = i * row + j
            b, d, e = a + 1, a + row, a + row + 1
            if i != 0:
                idx += [a, d, b]
            if i != n_theta - 1:
                idx += [b, d, e]
    return pos, idx, nrm


def build(triangles):
    grid_n = max(4, int(round(math.sqrt(0.2 * triangles))))
    n_phi = max(6, int(round(math.sqrt(0.6 * triangles / 16))))
    n_theta = max(3, n_phi // 2)
    meshes = {}
    meshes['walls_white'] = merge([
        quad((-1, 2, -1), (-1, 2, 1), (1, 2, 1), (1, 2, -1)),       # ceiling, normal -y
        quad((-1, 0, -1), (1, 0, -1), (1, 2, -1), (-1, 2, -1)),     # back wall, normal +z
        quad((-1, 0, -1), (-1, 0, 1), (1, 0, 1), (1, 0, -1)),       # floor under the grid, normal +y
    ]) + (None,)
    meshes['wall_red'] = quad((-1, 0, 1), (-1, 0, -1), (-1, 2, -1), (-1, 2, 1)) + (None,)   # +x
    meshes['wall_green'] = quad((1, 0, -1), (1, 0, 1), (1, 2, 1), (1, 2, -1)) + (None,)   # -x
    meshes['light'] = quad((-0.25, 1.98, -0.25), (0.25, 1.98, -0.25), (0.25, 1.98, 0.25),
                           (-0.25, 1.98, 0.25)) + (None,)  # normal -y: emits down
    meshes['floor_grid'] = displaced_grid(grid_n) + (None,)
    groups = {'spheres_gold': [], 'spheres_silver': [], 'spheres_glass': [], 'spheres_diffuse': []}
    names = list(groups)
    r = 0.15
    top = 0.05 + 0.04 * 1.5
    for j, z in enumerate((-0.6, -0.2, 0.2, 0.6)):
        for i, x in enumerate((-0.6, -0.2, 0.2, 0.6)):
            groups[names[(i + j) % 4]].append(sphere((x, top + r + 0.01, z), r, n_theta, n_phi))
    for name, parts in groups.items():
        pos, idx, nrm = [], [], []
        for p, i, n in parts:
            base = len(pos)
            pos += p
            nrm += n
            idx += [base + k for k in i]
        meshes[name] = (pos, idx, nrm)
    return meshes


MATERIAL_OF = {'walls_white': 'white', 'wall_red': 'red', 'wall_green': 'green', 'light': 'black',
               'floor_grid': 'white', 'spheres_gold': 'gold', 'spheres_silver': 'silver',
               'spheres_glass': 'glass', 'spheres_diffuse': 'white'}


def json_scene(res, mesh_names):
    materials = {
        'white': {'type': 'diffuse', 'reflectance': [0.725, 0.71, 0.68]},
        'red': {'type': 'diffuse', 'reflectance': [0.63, 0.065, 0.05]},
        'green': {'type': 'diffuse', 'reflectance': [0.14, 0.45, 0.091]},
        'black': {'type': 'diffuse', 'reflectance': [0, 0, 0]},
        'gold': {'type': 'rough_conductor', 'roughness': 0.15, 'eta': list(GOLD_ETA), 'k': list(GOLD_K)},
        'silver': {'type': 'conductor', 'eta': list(SILVER_ETA), 'k': list(SILVER_K)},
        'glass': {'type': 'dielectric', 'ior': 1.5},
    }
    shapes = []
    for name in mesh_names:
        s = {'type': 'ply', 'name': name, 'material': MATERIAL_OF[name], 'file': name + '.ply'}
        if name == 'light':
            s['emission'] = {'radiance': list(ROOM_LIGHT), 'two_sided': False}
        shapes.append(s)
    return {
        'format': 'rayfarm-scene', 'version': 1,
        'camera': {'type': 'perspective', 'fov_deg': 38,
                   'look_at': {'eye': [0, 1, 3.4], 'target': [0, 0.8, 0], 'up': [0, 1, 0]}},
        'film': {'resolution': [res, res], 'filter': {'type': 'triangle', 'radius': 1}},
        'render': {'integrator': {'type': 'path', 'max_depth': 8}, 'spp': 64, 'passes': 16, 'seed': 1},
        'materials': materials,
        'shapes': shapes,
    }


def xml_scene(res, mesh_names):
    def rgb(v):
        return ', '.join('%g' % c for c in v)
    lines = ['<?xml version="1.0" encoding="utf-8"?>',
             '<!-- Written by bench/make_million_scene.py; the same scene as scene.json. -->',
             '<scene version="3.0.0">',
             '\t<default name="spp" value="64"/>',
             '\t<default name="resx" value="%d"/>' % res,
             '\t<default name="resy" value="%d"/>' % res,
             '\t<integrator type="path">',
             '\t\t<integer name="max_depth" value="9"/>',
             '\t</integrator>',
             '\t<sensor type="perspective">',
             '\t\t<float name="fov" value="38"/>',
             '\t\t<string name="fov_axis" value="smaller"/>',
             '\t\t<transform name="to_world">',
             '\t\t\t<lookat origin="0, 1, 3.4" target="0, 0.8, 0" up="0, 1, 0"/>',
             '\t\t</transform>',
             '\t\t<sampler type="independent">',
             '\t\t\t<integer name="sample_count" value="$spp"/>',
             '\t\t</sampler>',
             '\t\t<film type="hdrfilm">',
             '\t\t\t<integer name="width" value="$resx"/>',
             '\t\t\t<integer name="height" value="$resy"/>',
             '\t\t\t<rfilter type="tent">',
             '\t\t\t\t<float name="radius" value="1"/>',
             '\t\t\t</rfilter>',
             '\t\t</film>',
             '\t</sensor>']

    def diffuse(name, c):
        return ['\t<bsdf type="twosided" id="%s">' % name, '\t\t<bsdf type="diffuse">',
                '\t\t\t<rgb name="reflectance" value="%s"/>' % rgb(c), '\t\t</bsdf>', '\t</bsdf>']
    lines += diffuse('white', (0.725, 0.71, 0.68))
    lines += diffuse('red', (0.63, 0.065, 0.05))
    lines += diffuse('green', (0.14, 0.45, 0.091))
    lines += diffuse('black', (0, 0, 0))
    lines += ['\t<bsdf type="twosided" id="gold">', '\t\t<bsdf type="roughconductor">',
              '\t\t\t<string name="distribution" value="ggx"/>', '\t\t\t<float name="alpha" value="0.15"/>',
              '\t\t\t<rgb name="eta" value="%s"/>' % rgb(GOLD_ETA), '\t\t\t<rgb name="k" value="%s"/>' % rgb(GOLD_K),
              '\t\t</bsdf>', '\t</bsdf>']
    lines += ['\t<bsdf type="twosided" id="silver">', '\t\t<bsdf type="conductor">',
              '\t\t\t<rgb name="eta" value="%s"/>' % rgb(SILVER_ETA),
              '\t\t\t<rgb name="k" value="%s"/>' % rgb(SILVER_K), '\t\t</bsdf>', '\t</bsdf>']
    lines += ['\t<bsdf type="dielectric" id="glass">', '\t\t<float name="int_ior" value="1.5"/>',
              '\t\t<float name="ext_ior" value="1"/>', '\t</bsdf>']
    for name in mesh_names:
        lines += ['\t<shape type="ply" id="%s">' % name,
                  '\t\t<string name="filename" value="%s.ply"/>' % name,
                  '\t\t<ref id="%s"/>' % MATERIAL_OF[name]]
        if name == 'light':
            lines += ['\t\t<emitter type="area">', '\t\t\t<rgb name="radiance" value="%s"/>' % rgb(ROOM_LIGHT),
                      '\t\t</emitter>']
        lines += ['\t</shape>']
    lines.append('</scene>')
    return '\n'.join(lines) + '\n'


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('out_dir')
    ap.add_argument('--triangles', type=int, default=1000000, help='approximate total (default 1000000)')
    ap.add_argument('--res', type=int, default=512, help='square image size (default 512)')
    a = ap.parse_args()
    os.makedirs(a.out_dir, exist_ok=True)
    meshes = build(a.triangles)
    total = 0
    for name, (pos, idx, nrm) in meshes.items():
        write_ply(os.path.join(a.out_dir, name + '.ply'), pos, idx, nrm)
        total += len(idx) // 3
    names = list(meshes)
    with open(os.path.join(a.out_dir, 'scene.json'), 'w', newline='\n') as f:
        json.dump(json_scene(a.res, names), f, indent=1)
        f.write('\n')
    with open(os.path.join(a.out_dir, 'scene.xml'), 'w', newline='\n') as f:
        f.write(xml_scene(a.res, names))
    print('wrote %s: %d triangles in %d meshes' % (a.out_dir, total, len(names)))


if __name__ == '__main__':
    main()
