#!/usr/bin/env python3
"""Writes the small glTF test inputs of tests/gltf_test.cpp (and the parser's fuzzing corpus).

Run from this directory: python3 generate.py. Every file is written from the data below, so the
expected values in tests/gltf_test.cpp can be read off this script. Buffers are embedded as data:
URIs; one test image (checker.png) is an external file, and the malformed inputs are in bad/.
"""
import base64
import copy
import json
import math
import os
import struct
import zlib


def png(width, height, rows, channels=3):
    """A minimal 8-bit PNG (colour type 2 = RGB, 0 = grey)."""
    raw = b"".join(b"\x00" + bytes(r) for r in rows)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ctype = {1: 0, 3: 2, 4: 6}[channels]
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, ctype, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


# 2x2 RGB texels, top row first: (R, G, B) per texel.
TEXELS = [[(255, 0, 0), (0, 255, 0)], [(0, 0, 255), (255, 255, 255)]]
TEXTURE_PNG = png(2, 2, [sum((list(t) for t in row), []) for row in TEXELS])
# metallic-roughness map: G = roughness, B = metallic; texel values chosen to be distinct.
MR_TEXELS = [[(0, 64, 0), (0, 128, 0)], [(0, 192, 0), (0, 255, 0)]]
MR_PNG = png(2, 2, [sum((list(t) for t in row), []) for row in MR_TEXELS])


class Builder:
    def __init__(self):
        self.bin = bytearray()
        self.j = {"asset": {"version": "2.0", "generator": "rayfarm tests/data/gltf/generate.py"},
                  "buffers": [], "bufferViews": [], "accessors": []}

    def view(self, data, stride=None):
        while len(self.bin) % 4:
            self.bin.append(0)
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.bin += data
        self.j["bufferViews"].append(v)
        return len(self.j["bufferViews"]) - 1

    def accessor(self, values, kind, ctype=5126, **extra):
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        fmt = {5126: "f", 5125: "I", 5123: "H", 5121: "B"}[ctype]
        flat = [x for v in values for x in (v if isinstance(v, (list, tuple)) else [v])]
        view = self.view(struct.pack("<%d%s" % (len(flat), fmt), *flat))
        a = {"bufferView": view, "componentType": ctype, "count": len(flat) // n, "type": kind}
        if kind == "VEC3" and ctype == 5126:
            a["min"] = [min(flat[i::3]) for i in range(3)]
            a["max"] = [max(flat[i::3]) for i in range(3)]
        a.update(extra)
        self.j["accessors"].append(a)
        return len(self.j["accessors"]) - 1

    def quad(self):
        """Accessors of a unit quad in z = 0 facing +z: positions, normals, uvs, u16 indices."""
        p = self.accessor([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], "VEC3")
        n = self.accessor([(0, 0, 1)] * 4, "VEC3")
        t = self.accessor([(0, 1), (1, 1), (1, 0), (0, 0)], "VEC2")  # glTF v runs down
        i = self.accessor([0, 1, 2, 0, 2, 3], "SCALAR", 5123)
        return {"attributes": {"POSITION": p, "NORMAL": n, "TEXCOORD_0": t}, "indices": i}

    def done(self):
        self.j["buffers"] = [{"byteLength": len(self.bin),
                              "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.bin)).decode()}]
        return self.j


def write(name, j):
    os.makedirs(os.path.dirname(name) or ".", exist_ok=True)
    with open(name, "w") as f:
        json.dump(j, f, indent=1)
        f.write("\n")


def data_uri_png(data):
    return "data:image/png;base64," + base64.b64encode(data).decode()


def hierarchy():
    b = Builder()
    b.j["meshes"] = [{"name": "quad", "primitives": [dict(b.quad(), material=0)]}]
    b.j["materials"] = [{"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0}}]
    s = math.sqrt(0.5)
    b.j["nodes"] = [
        {"name": "root", "translation": [0, 0, -5], "children": [1, 2]},
        {"name": "trs", "rotation": [0, s, 0, s], "scale": [2, 2, 2], "mesh": 0},
        {"name": "matrix", "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 3, 0, 0, 1], "mesh": 0},
        {"name": "camera", "translation": [0, 1, 0], "rotation": [0, s, 0, s], "camera": 0},
        {"name": "unused camera", "camera": 0},
    ]
    b.j["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 1.5, "znear": 0.1}}]
    b.j["scenes"] = [{"nodes": [0, 3, 4]}]
    b.j["scene"] = 0
    return b.done()


def animated():
    """Node animations (docs/formats/gltf.md "Animations"; a fuzzing seed): a quad sliding
    (LINEAR translation), one snapping a quarter turn at t = 1 (STEP rotation), one on a cubic
    (CUBICSPLINE translation), a child riding on the first, and a camera."""
    b = Builder()
    b.j["meshes"] = [{"name": "quad", "primitives": [dict(b.quad(), material=0)]}]
    b.j["materials"] = [{"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0}}]
    s = math.sqrt(0.5)
    b.j["nodes"] = [
        {"name": "slide", "mesh": 0, "children": [3]},
        {"name": "snap", "mesh": 0, "translation": [3, 0, 0]},
        {"name": "cubic", "mesh": 0, "translation": [-3, 0, 0]},
        {"name": "rider", "mesh": 0, "translation": [0, 2.5, 0]},
        {"name": "camera", "translation": [0, 1, 12], "camera": 0},
    ]
    b.j["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}]
    times2, times3 = b.accessor([0, 1], "SCALAR"), b.accessor([0, 1, 2], "SCALAR")
    samplers = [
        {"input": times3, "output": b.accessor([(0, 0, 0), (1, 0, 0), (1, 2, 0)], "VEC3")},
        {"input": times2, "interpolation": "STEP", "output": b.accessor([(0, 0, 0, 1), (0, s, 0, s)], "VEC4")},
        {"input": times2, "interpolation": "CUBICSPLINE",
         "output": b.accessor([(0, 0, 0), (-3, 0, 0), (3, 0, 0), (0, 0, 0), (-2, 0, 0), (0, 0, 0)], "VEC3")},
    ]
    b.j["animations"] = [{"name": "shot", "samplers": samplers, "channels": [
        {"sampler": 0, "target": {"node": 0, "path": "translation"}},
        {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
        {"sampler": 2, "target": {"node": 2, "path": "translation"}}]}]
    b.j["scenes"] = [{"nodes": [0, 1, 2, 4]}]
    b.j["scene"] = 0
    return b.done()


def deforming():
    """Skins and morph targets (docs/formats/gltf.md "Skins and morph targets"; a fuzzing seed):
    a quad with two morph targets whose weights animate (LINEAR), and a quad skinned to two
    joints, the second turning a quarter about +z (LINEAR rotation)."""
    b = Builder()
    quad = b.quad()
    lift = b.accessor([(0, 0, 1)] * 4, "VEC3")
    stretch = b.accessor([(0, 0, 0), (1, 0, 0), (1, 0, 0), (0, 0, 0)], "VEC3")
    joints = b.accessor([(0, 0, 0, 0), (1, 0, 0, 0), (1, 0, 0, 0), (0, 1, 0, 0)], "VEC4", 5121)
    weights = b.accessor([(1, 0, 0, 0), (1, 0, 0, 0), (1, 0, 0, 0), (0.5, 0.5, 0, 0)], "VEC4")
    skinned = dict(quad, attributes=dict(quad["attributes"], JOINTS_0=joints, WEIGHTS_0=weights))
    b.j["meshes"] = [
        {"name": "morph", "primitives": [dict(quad, material=0, targets=[{"POSITION": lift}, {"POSITION": stretch}])],
         "weights": [0, 0]},
        {"name": "skinned", "primitives": [dict(skinned, material=0)]},
    ]
    b.j["materials"] = [{"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0}}]
    s = math.sqrt(0.5)
    b.j["nodes"] = [
        {"name": "morphed", "mesh": 0, "translation": [-3, 0, 0]},
        {"name": "root joint", "children": [2]},
        {"name": "turning joint", "translation": [1, 0, 0]},
        {"name": "skinned", "mesh": 1, "skin": 0},
        {"name": "camera", "translation": [0, 1, 12], "camera": 0},
    ]
    ibm = b.accessor([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,
                      1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1], "MAT4")
    b.j["skins"] = [{"joints": [1, 2], "inverseBindMatrices": ibm}]
    b.j["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}]
    times2 = b.accessor([0, 1], "SCALAR")
    samplers = [
        {"input": times2, "output": b.accessor([0, 0, 1, 0.5], "SCALAR")},
        {"input": times2, "output": b.accessor([(0, 0, 0, 1), (0, 0, s, s)], "VEC4")},
    ]
    b.j["animations"] = [{"name": "shot", "samplers": samplers, "channels": [
        {"sampler": 0, "target": {"node": 0, "path": "weights"}},
        {"sampler": 1, "target": {"node": 2, "path": "rotation"}}]}]
    b.j["scenes"] = [{"nodes": [0, 1, 3, 4]}]
    b.j["scene"] = 0
    return b.done()


def lights():
    b = Builder()
    b.j["extensionsUsed"] = ["KHR_lights_punctual"]
    b.j["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "point", "color": [1, 0.5, 0.25], "intensity": 683 * 4},
        {"type": "spot", "intensity": 683, "range": 10, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}},
        {"type": "directional", "intensity": 1366},
    ]}}
    b.j["meshes"] = [{"primitives": [b.quad()]}]
    s = math.sqrt(0.5)
    b.j["nodes"] = [
        {"mesh": 0},
        {"translation": [1, 2, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"translation": [0, 5, 0], "rotation": [-s, 0, 0, s], "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"extensions": {"KHR_lights_punctual": {"light": 2}}},
    ]
    b.j["scenes"] = [{"nodes": [0, 1, 2, 3]}]
    return b.done()


MATERIALS = [
    {"name": "metal", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.6, 0.3, 1], "metallicFactor": 1, "roughnessFactor": 0.5}},
    {"name": "plastic", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1], "metallicFactor": 0, "roughnessFactor": 0.5}},
    {"name": "diffuse", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.7, 0.6, 1], "metallicFactor": 0}},
    {"name": "no specular", "pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0.3},
     "extensions": {"KHR_materials_specular": {"specularFactor": 0}}},
    {"name": "thin glass", "pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0},
     "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.4}}},
    {"name": "solid glass", "pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0.2},
     "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_volume": {"thicknessFactor": 1}}},
    {"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
     "emissiveFactor": [1, 0.5, 0.25], "doubleSided": True,
     "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8}}},
    {"name": "half metal", "pbrMetallicRoughness": {"metallicFactor": 0.3, "roughnessFactor": 0.5}},
    {"name": "blend", "alphaMode": "BLEND", "pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0.5},
     "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1}}},
]


def materials():
    b = Builder()
    q = b.quad()
    b.j["extensionsUsed"] = ["KHR_materials_specular", "KHR_materials_transmission", "KHR_materials_ior",
                             "KHR_materials_volume", "KHR_materials_emissive_strength", "KHR_materials_clearcoat"]
    b.j["materials"] = MATERIALS
    b.j["meshes"] = [{"name": m["name"], "primitives": [dict(q, material=i)]} for i, m in enumerate(MATERIALS)]
    b.j["meshes"].append({"name": "no material", "primitives": [dict(q)]})
    b.j["nodes"] = [{"mesh": i, "translation": [3 * i, 0, 0]} for i in range(len(b.j["meshes"]))]
    b.j["scenes"] = [{"nodes": list(range(len(b.j["nodes"])))}]
    return b.done()


def textured():
    b = Builder()
    b.j["extensionsUsed"] = ["KHR_texture_transform"]
    b.j["images"] = [{"uri": data_uri_png(TEXTURE_PNG)}, {"uri": data_uri_png(MR_PNG)}]
    b.j["samplers"] = [{"wrapS": 33071, "wrapT": 33071}]
    b.j["textures"] = [{"source": 0}, {"source": 1, "sampler": 0}]
    b.j["materials"] = [{"name": "textured", "pbrMetallicRoughness": {
        "baseColorFactor": [0.5, 1, 1, 1],
        "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.5, 0], "scale": [2, 2]}}},
        "metallicFactor": 1, "roughnessFactor": 0.8, "metallicRoughnessTexture": {"index": 1}}}]
    b.j["meshes"] = [{"primitives": [dict(b.quad(), material=0)]}]
    b.j["nodes"] = [{"mesh": 0}]
    b.j["scenes"] = [{"nodes": [0]}]
    return b.done()


def textured_external():
    j = textured()
    j["images"] = [{"uri": "checker.png"}]
    j["textures"] = [{"source": 0}]
    m = j["materials"][0]["pbrMetallicRoughness"]
    del m["metallicRoughnessTexture"]
    m["baseColorTexture"] = {"index": 0}
    del j["samplers"]
    del j["extensionsUsed"]
    return j


def primitives():
    """Strip, fan, points, u8 indices, a non-indexed list and a sparse accessor."""
    b = Builder()
    p = b.accessor([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 2, 0)], "VEC3")
    strip = b.accessor([0, 1, 2, 3, 4], "SCALAR", 5121)
    fan = b.accessor([0, 1, 3, 2], "SCALAR", 5125)
    tri = b.accessor([(0, 0, 0), (1, 0, 0), (0, 1, 0)], "VEC3")
    # Sparse: base positions all at (0, 0, 1) except element 2 replaced by (5, 5, 5).
    base = b.accessor([(0, 0, 1), (1, 0, 1), (0, 1, 1)], "VEC3")
    si = b.view(struct.pack("<H", 2))
    sv = b.view(struct.pack("<3f", 5, 5, 5))
    b.j["accessors"][base]["sparse"] = {"count": 1, "indices": {"bufferView": si, "componentType": 5123},
                                        "values": {"bufferView": sv}}
    b.j["meshes"] = [{"name": "strip", "primitives": [{"attributes": {"POSITION": p}, "indices": strip, "mode": 5}]},
                     {"name": "fan", "primitives": [{"attributes": {"POSITION": p}, "indices": fan, "mode": 6}]},
                     {"name": "points", "primitives": [{"attributes": {"POSITION": p}, "mode": 0}]},
                     {"name": "list", "primitives": [{"attributes": {"POSITION": tri}}]},
                     {"name": "sparse", "primitives": [{"attributes": {"POSITION": base}}]}]
    b.j["nodes"] = [{"mesh": i} for i in range(5)]
    b.j["scenes"] = [{"nodes": [0, 1, 2, 3, 4]}]
    return b.done()


def interleaved():
    """Interleaved float positions and normals (stride 24), normalized u8 uvs (stride 4) and
    KHR_mesh_quantization's plain int16 positions (stride 8)."""
    b = Builder()
    v = b.view(struct.pack("<18f", 0, 0, 0, 0, 0, 1, 2, 0, 0, 0, 0, 1, 0, 2, 0, 0, 0, 1), stride=24)
    b.j["accessors"] += [
        {"bufferView": v, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [2, 2, 0]},
        {"bufferView": v, "byteOffset": 12, "componentType": 5126, "count": 3, "type": "VEC3"}]
    uv = b.view(bytes([0, 255, 0, 0, 255, 255, 0, 0, 0, 0, 0, 0]), stride=4)
    b.j["accessors"].append({"bufferView": uv, "componentType": 5121, "normalized": True, "count": 3, "type": "VEC2"})
    q = b.view(struct.pack("<12h", 0, 0, 0, 0, 4, 0, 0, 0, 0, 4, 0, 0), stride=8)
    b.j["accessors"].append({"bufferView": q, "componentType": 5122, "count": 3, "type": "VEC3",
                             "min": [0, 0, 0], "max": [4, 4, 0]})
    b.j["extensionsUsed"] = ["KHR_mesh_quantization"]
    b.j["extensionsRequired"] = ["KHR_mesh_quantization"]
    b.j["meshes"] = [{"name": "interleaved", "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}}]},
                     {"name": "quantized", "primitives": [{"attributes": {"POSITION": 3}}]}]
    b.j["nodes"] = [{"mesh": 0}, {"mesh": 1}]
    b.j["scenes"] = [{"nodes": [0, 1]}]
    return b.done()


def malformed():
    bad = {}
    base = hierarchy()
    j = copy.deepcopy(base)
    j["accessors"][0]["count"] = 100
    bad["accessor_out_of_bounds.gltf"] = j
    j = copy.deepcopy(base)
    j["buffers"][0]["uri"] = "missing.bin"
    bad["missing_buffer.gltf"] = j
    j = copy.deepcopy(base)
    j["images"] = [{"uri": "../checker.png"}]
    j["textures"] = [{"source": 0}]
    j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    bad["image_outside.gltf"] = j
    j = copy.deepcopy(base)
    j["extensionsUsed"] = j["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    bad["required_extension.gltf"] = j
    j = copy.deepcopy(base)
    b = Builder()
    q = b.quad()
    b.j["accessors"][q["indices"]]  # the index accessor: six u16 values
    b.bin[b.j["bufferViews"][3]["byteOffset"] + 4:b.j["bufferViews"][3]["byteOffset"] + 6] = struct.pack("<H", 7)
    b.j["meshes"] = [{"primitives": [q]}]
    b.j["nodes"] = [{"mesh": 0}]
    b.j["scenes"] = [{"nodes": [0]}]
    bad["bad_index.gltf"] = b.done()
    j = copy.deepcopy(base)
    j["nodes"][1]["children"] = [0]
    bad["cycle.gltf"] = j
    j = copy.deepcopy(base)
    j["bufferViews"][0]["byteStride"] = 6
    bad["bad_stride.gltf"] = j
    j = copy.deepcopy(base)
    j["bufferViews"][0]["byteStride"] = 8  # positions are 12 bytes
    bad["stride_too_small.gltf"] = j
    j = copy.deepcopy(base)
    j["cameras"] = [{"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 10}}]
    bad["orthographic.gltf"] = j
    j = copy.deepcopy(base)
    del j["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    bad["no_position.gltf"] = j
    j = copy.deepcopy(base)
    j["meshes"][0]["primitives"][0]["material"] = 5
    bad["bad_material.gltf"] = j
    for name, j in bad.items():
        write("bad/" + name, j)


def glb(j, bin_bytes):
    js = json.dumps(j, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    bin_bytes = bytes(bin_bytes) + b"\x00" * (-len(bin_bytes) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(bin_bytes), 0x004E4942) + bin_bytes
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def truncated_glb():
    b = Builder()
    b.j["meshes"] = [{"primitives": [b.quad()]}]
    b.j["nodes"] = [{"mesh": 0}]
    b.j["scenes"] = [{"nodes": [0]}]
    j = b.done()
    j["buffers"] = [{"byteLength": len(b.bin)}]
    data = glb(j, b.bin)
    with open("bad/truncated.glb", "wb") as f:
        f.write(data[: len(data) - 40])


if __name__ == "__main__":
    os.chdir(os.path.dirname(os.path.abspath(__file__)))
    write("hierarchy.gltf", hierarchy())
    write("lights.gltf", lights())
    write("materials.gltf", materials())
    write("textured.gltf", textured())
    write("textured_external.gltf", textured_external())
    write("primitives.gltf", primitives())
    write("interleaved.gltf", interleaved())
    write("animated.gltf", animated())
    write("deforming.gltf", deforming())
    with open("checker.png", "wb") as f:
        f.write(TEXTURE_PNG)
    malformed()
    truncated_glb()
