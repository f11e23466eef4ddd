#!/usr/bin/env python3
"""Writes scene.gltf and checker.png: a small animated glTF 2.0 scene for rayfarm's glTF importer
(docs/formats/gltf.md), written from the data below so that every number in it can be read here.

    cd scenes/gltf-still-life && python3 make_scene.py

What it holds: a camera; a textured floor (base colour texture: a Lambertian); three spheres, a
gold conductor (metallic 1), a blue plastic (metallic 0, roughness 0.25) and glass
(KHR_materials_transmission with KHR_materials_ior and KHR_materials_volume); a red cube that
turns once about +Y over one second (24 frames: a rotation animation, LINEAR quaternions); an
emissive panel above (an area light, KHR_materials_emissive_strength) and a warm point light
(KHR_lights_punctual). Buffers are embedded as a data: URI; the texture is the file beside it.
"""
import base64
import json
import math
import struct
import zlib


def png(width, height, rows):
    raw = b"".join(b"\x00" + bytes(r) for r in rows)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def checker(n=64, squares=8):
    light, dark = (205, 200, 190), (95, 90, 85)
    rows = []
    for y in range(n):
        row = []
        for x in range(n):
            row += light if ((x * squares // n) + (y * squares // n)) % 2 == 0 else dark
        rows.append(row)
    return png(n, n, rows)


class Builder:
    def __init__(self):
        self.bin = bytearray()
        self.j = {"asset": {"version": "2.0", "generator": "rayfarm scenes/gltf-still-life/make_scene.py"},
                  "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength",
                                     "KHR_materials_transmission", "KHR_materials_ior",
                                     "KHR_materials_volume", "KHR_materials_specular"],
                  "buffers": [], "bufferViews": [], "accessors": [], "meshes": [], "materials": [],
                  "nodes": [], "textures": [], "images": [], "samplers": []}

    def accessor(self, values, kind, ctype=5126, target=None):
        n = {"SCALAR": 1, "VEC3": 3, "VEC2": 2, "VEC4": 4}[kind]
        fmt = {5126: "f", 5125: "I"}[ctype]
        flat = [x for v in values for x in (v if isinstance(v, (list, tuple)) else [v])]
        while len(self.bin) % 4:
            self.bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": 4 * len(flat)}
        if target:
            view["target"] = target
        self.bin += struct.pack("<%d%s" % (len(flat), fmt), *flat)
        self.j["bufferViews"].append(view)
        a = {"bufferView": len(self.j["bufferViews"]) - 1, "componentType": ctype,
             "count": len(flat) // n, "type": kind}
        if ctype == 5126:
            a["min"] = [min(flat[i::n]) for i in range(n)]
            a["max"] = [max(flat[i::n]) for i in range(n)]
        self.j["accessors"].append(a)
        return len(self.j["accessors"]) - 1

    def geometry(self, positions, normals, uvs, indices):
        """Accessors of a shape, which several meshes may share (one per material)."""
        attrs = {"POSITION": self.accessor(positions, "VEC3", target=34962),
                 "NORMAL": self.accessor(normals, "VEC3", target=34962)}
        if uvs:
            attrs["TEXCOORD_0"] = self.accessor(uvs, "VEC2", target=34962)
        return attrs, self.accessor(indices, "SCALAR", 5125, 34963)

    def mesh(self, name, geometry, material):
        attrs, indices = geometry
        prim = {"attributes": dict(attrs), "indices": indices, "material": material}
        self.j["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.j["meshes"]) - 1

    def material(self, m):
        self.j["materials"].append(m)
        return len(self.j["materials"]) - 1

    def node(self, n):
        self.j["nodes"].append(n)
        return len(self.j["nodes"]) - 1


def sphere(radius, rings=32, segments=64):
    pos, nrm, uv, idx = [], [], [], []
    for r in range(rings + 1):
        theta = math.pi * r / rings
        for s in range(segments + 1):
            phi = 2 * math.pi * s / segments
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            pos.append(tuple(radius * c for c in n))
            nrm.append(n)
            uv.append((s / segments, r / rings))
    for r in range(rings):
        for s in range(segments):
            a, b = r * (segments + 1) + s, (r + 1) * (segments + 1) + s
            # Counter-clockwise seen from outside; at the poles one of the two is a point.
            if r > 0:
                idx += [a, a + 1, b]
            if r < rings - 1:
                idx += [a + 1, b + 1, b]
    return pos, nrm, uv, idx


def quad(half, y, facing_up=True):
    pos = [(-half, y, -half), (half, y, -half), (half, y, half), (-half, y, half)]
    n = (0, 1, 0) if facing_up else (0, -1, 0)
    idx = [0, 2, 1, 0, 3, 2] if facing_up else [0, 1, 2, 0, 2, 3]
    return pos, [n] * 4, [(0, 0), (8, 0), (8, 8), (0, 8)], idx


def cube(half):
    pos, nrm, uv, idx = [], [], [], []
    for axis in range(3):
        for sign in (1, -1):
            n = [0, 0, 0]
            n[axis] = sign
            u = [0, 0, 0]
            u[(axis + 1) % 3] = 1
            v = [0, 0, 0]
            v[(axis + 2) % 3] = 1
            base = len(pos)
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                pos.append(tuple(half * (n[i] + du * u[i] + dv * v[i]) for i in range(3)))
                nrm.append(tuple(n))
                uv.append(((du + 1) / 2, (dv + 1) / 2))
            idx += [base, base + 1, base + 2, base, base + 2, base + 3] if sign > 0 else \
                [base, base + 2, base + 1, base, base + 3, base + 2]
    return pos, nrm, uv, idx


def main():
    b = Builder()
    b.j["images"].append({"uri": "checker.png"})
    b.j["samplers"].append({"magFilter": 9728, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497})
    b.j["textures"].append({"source": 0, "sampler": 0})
    # A matte floor: specularFactor 0 says it has no specular coat (a Lambertian).
    floor_mat = b.material({"name": "floor", "pbrMetallicRoughness": {
        "baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}})
    gold = b.material({"name": "gold", "pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 0.78, 0.34, 1], "metallicFactor": 1.0, "roughnessFactor": 0.3}})
    blue = b.material({"name": "blue plastic", "pbrMetallicRoughness": {
        "baseColorFactor": [0.1, 0.25, 0.7, 1], "metallicFactor": 0.0, "roughnessFactor": 0.25}})
    glass = b.material({"name": "glass", "pbrMetallicRoughness": {
        "baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0, "roughnessFactor": 0.0},
        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                       "KHR_materials_ior": {"ior": 1.5},
                       "KHR_materials_volume": {"thicknessFactor": 0.7}}})
    red = b.material({"name": "red plastic", "pbrMetallicRoughness": {
        "baseColorFactor": [0.75, 0.08, 0.06, 1], "metallicFactor": 0.0, "roughnessFactor": 0.4}})
    panel_mat = b.material({"name": "light panel", "emissiveFactor": [1.0, 0.96, 0.9],
                            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 12.0}},
                            "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1],
                                                     "metallicFactor": 0.0, "roughnessFactor": 1.0}})

    unit_sphere = b.geometry(*sphere(1.0))  # one tessellation, three materials, scaled by nodes
    meshes = {
        "floor": b.mesh("floor", b.geometry(*quad(6.0, 0.0)), floor_mat),
        "gold": b.mesh("gold sphere", unit_sphere, gold),
        "blue": b.mesh("blue sphere", unit_sphere, blue),
        "glass": b.mesh("glass sphere", unit_sphere, glass),
        "cube": b.mesh("red cube", b.geometry(*cube(0.35)), red),
        "panel": b.mesh("light panel", b.geometry(*quad(0.9, 0.0, facing_up=False)), panel_mat),
    }
    roots = []
    for name, radius, at in (("gold", 0.55, [-1.1, 0.55, -0.3]), ("blue", 0.45, [0.35, 0.45, 0.6]),
                             ("glass", 0.35, [1.35, 0.35, -0.1])):
        roots.append(b.node({"name": name + " sphere", "mesh": meshes[name], "translation": at,
                             "scale": [radius] * 3}))
    roots.insert(0, b.node({"name": "floor", "mesh": meshes["floor"]}))
    cube_node = b.node({"name": "red cube", "mesh": meshes["cube"], "translation": [0.75, 0.35, -1.5]})
    roots.append(cube_node)
    roots.append(b.node({"name": "light panel", "mesh": meshes["panel"], "translation": [0, 3.2, 0]}))
    b.j["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"name": "warm key", "type": "point", "color": [1.0, 0.85, 0.65], "intensity": 15000.0}]}}
    roots.append(b.node({"name": "warm key", "translation": [-2.5, 2.5, 2.0],
                         "extensions": {"KHR_lights_punctual": {"light": 0}}}))
    # The camera: at (0.4, 1.6, 4.6), looking at (0.1, 0.4, -0.2), +Y up.
    eye, target = (0.4, 1.6, 4.6), (0.1, 0.4, -0.2)
    f = [t - e for t, e in zip(target, eye)]
    pitch = math.atan2(f[1], math.hypot(f[0], f[2]))
    yaw = math.atan2(-f[0], -f[2])
    qy = (0, math.sin(yaw / 2), 0, math.cos(yaw / 2))
    qx = (math.sin(pitch / 2), 0, 0, math.cos(pitch / 2))
    q = (qy[3] * qx[0], qy[1] * qx[3], -qy[1] * qx[0], qy[3] * qx[3])  # qy * qx
    b.j["cameras"] = [{"type": "perspective",
                       "perspective": {"yfov": 0.62, "aspectRatio": 1.5, "znear": 0.05}}]
    roots.append(b.node({"name": "camera", "camera": 0, "translation": list(eye), "rotation": list(q)}))

    # The cube turns once about +Y in one second (24 frames), in 8 LINEAR steps.
    times = [i / 8 for i in range(9)]
    rots = [(0.0, math.sin(math.pi * t), 0.0, math.cos(math.pi * t)) for t in times]
    b.j["animations"] = [{"name": "turn", "channels": [
        {"sampler": 0, "target": {"node": cube_node, "path": "rotation"}}],
        "samplers": [{"input": b.accessor(times, "SCALAR"), "output": b.accessor(rots, "VEC4"),
                      "interpolation": "LINEAR"}]}]

    b.j["scenes"] = [{"name": "still life", "nodes": roots}]
    b.j["scene"] = 0
    b.j["buffers"] = [{"byteLength": len(b.bin),
                       "uri": "data:application/octet-stream;base64," +
                              base64.b64encode(bytes(b.bin)).decode()}]
    with open("scene.gltf", "w") as out:
        json.dump(b.j, out, indent=1)
        out.write("\n")
    with open("checker.png", "wb") as out:
        out.write(checker())


if __name__ == "__main__":
    main()
