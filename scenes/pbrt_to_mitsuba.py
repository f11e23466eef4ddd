#!/usr/bin/env python3
"""Converts Bitterli's pbrt-v4 scenes shipped here to Mitsuba 3 XML (scene.xml beside them).

Usage (from the repository root):
    python3 scenes/pbrt_to_mitsuba.py scenes/veach-mis/scene-v4.pbrt
    python3 scenes/pbrt_to_mitsuba.py scenes/veach-bidir/scene-v4.pbrt

It reads the small subset of pbrt-v4 these files use (Integrator, Transform, Sampler,
PixelFilter, Film, Camera "perspective", MakeNamedMaterial / NamedMaterial with diffuse,
conductor and dielectric, Shape trianglemesh / plymesh / sphere, AreaLightSource "diffuse",
AttributeBegin / AttributeEnd) and refuses anything else. Deterministic: the same input gives
the same bytes. Python 3 standard library only.

Mapping (docs/formats/mitsuba.md has the reasons):
- pbrt's Transform before WorldBegin is world-to-camera, column-major. pbrt's camera looks down
  +z with +x to the image's right; Mitsuba's looks down +z with +x to the image's left, so
  Mitsuba's to_world = inverse(world_to_camera) * diag(-1, 1, 1).
- pbrt's fov is across the shorter image axis: fov_axis "smaller".
- maxdepth d (scattering events) is Mitsuba's max_depth d + 1. Mitsuba 3 has no bdpt, so the
  integrator is a $integrator default of "path" (rayfarm reads "bdpt" too).
- pbrt's materials are two-sided, Mitsuba's are not: every bsdf is wrapped in "twosided",
  except dielectrics (two-sided in both).
- conductor roughness with remaproughness false is the GGX alpha: roughconductor "ggx".
- dielectric eta e: int_ior e, ext_ior 1 (Mitsuba's default exterior is air, 1.000277).
- a trianglemesh becomes an ascii PLY in meshes/ (positions and indices). pbrt turns each
  triangle's geometric normal towards the shading normals N when they are given (area lights
  emit on that side); the converter winds each triangle so its right-hand normal agrees with N.
- triangle filter of radius r: tent of radius r; diffuse area lights: one-sided area emitters.
"""
import os
import re
import sys


def tokenize(text):
    tokens = []
    for m in re.finditer(r'#[^\n]*|"[^"]*"|\[|\]|[^\s\[\]"]+', text):
        t = m.group(0)
        if not t.startswith('#'):
            tokens.append(t)
    return tokens


def parse(tokens):
    """Yields (directive, positional args, {"type name": [values]})."""
    i = 0
    while i < len(tokens):
        name = tokens[i]
        i += 1
        args, params = [], {}
        while i < len(tokens) and (tokens[i].startswith('"') or tokens[i] == '[' or
                                   re.match(r'^[-+.\d]', tokens[i])):
            t = tokens[i]
            if t.startswith('"') and ' ' in t.strip('"') and i + 1 < len(tokens):
                key = t.strip('"')
                i += 1
                if tokens[i] == '[':
                    j = tokens.index(']', i)
                    vals = tokens[i + 1:j]
                    i = j + 1
                else:
                    vals = [tokens[i]]
                    i += 1
                params[key] = [v.strip('"') for v in vals]
            elif t == '[':
                j = tokens.index(']', i)
                args.append([float(v) for v in tokens[i + 1:j]])
                i = j + 1
            else:
                args.append(t.strip('"'))
                i += 1
        yield name, args, params


def param(params, name, default=None):
    for key, vals in params.items():
        if key.split()[1] == name:
            return vals
    return default


def matmul(a, b):
    return [[sum(a[r][k] * b[k][c] for k in range(4)) for c in range(4)] for r in range(4)]


def inverse_rigid(m):
    """Inverse of a rotation + translation (row-major 4x4)."""
    r = [[m[c][rr] for c in range(3)] for rr in range(3)]  # transpose of the 3x3
    t = [m[0][3], m[1][3], m[2][3]]
    out = [[0.0] * 4 for _ in range(4)]
    for i in range(3):
        for j in range(3):
            out[i][j] = r[i][j]
        out[i][3] = -sum(r[i][k] * t[k] for k in range(3))
    out[3][3] = 1.0
    return out


def from_column_major(v):
    return [[v[c * 4 + r] for c in range(4)] for r in range(4)]


def fmt(x):
    s = '%.9g' % x
    return '0' if s == '-0' else s


def matrix_text(m):
    return ' '.join(fmt(m[r][c]) for r in range(4) for c in range(4))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def write_ply(path, positions, indices):
    with open(path, 'w', newline='\n') as f:
        f.write('ply\nformat ascii 1.0\n')
        f.write('element vertex %d\nproperty float x\nproperty float y\nproperty float z\n' % len(positions))
        f.write('element face %d\nproperty list uchar int vertex_indices\nend_header\n' % (len(indices) // 3))
        for p in positions:
            f.write('%s %s %s\n' % tuple(fmt(c) for c in p))
        for t in range(0, len(indices), 3):
            f.write('3 %d %d %d\n' % tuple(indices[t:t + 3]))


def convert(pbrt_path):
    scene_dir = os.path.dirname(pbrt_path) or '.'
    text = open(pbrt_path).read()
    out = []
    head = {'integrator': 'path', 'maxdepth': 5, 'spp': 16, 'filter': None, 'res': (1280, 720), 'fov': 90}
    camera_to_world = None
    materials, bsdf_xml = {}, []
    shapes = []
    current_material = None
    area = None
    stack = []
    ctm = [[1.0 if r == c else 0.0 for c in range(4)] for r in range(4)]
    mesh_count = 0
    in_world = False
    for name, args, params in parse(tokenize(text)):
        if name == 'Integrator':
            head['integrator'] = args[0]
            head['maxdepth'] = int(float(param(params, 'maxdepth', [5])[0]))
        elif name == 'Transform':
            ctm = from_column_major(args[0])
            if not in_world:
                camera_to_world = inverse_rigid(ctm)
        elif name == 'Sampler':
            head['spp'] = int(float(param(params, 'pixelsamples', [16])[0]))
        elif name == 'PixelFilter':
            head['filter'] = (args[0], float(param(params, 'xradius', [1])[0]))
        elif name == 'Film':
            head['res'] = (int(float(param(params, 'xresolution')[0])), int(float(param(params, 'yresolution')[0])))
        elif name == 'Camera':
            if args[0] != 'perspective':
                raise SystemExit('unsupported camera ' + args[0])
            head['fov'] = float(param(params, 'fov')[0])
        elif name == 'WorldBegin':
            in_world = True
            ctm = [[1.0 if r == c else 0.0 for c in range(4)] for r in range(4)]
        elif name == 'MakeNamedMaterial':
            mname = args[0]
            kind = param(params, 'type')[0]
            materials[mname] = kind
            bsdf_xml.append(material_xml(mname, kind, params))
        elif name == 'NamedMaterial':
            current_material = args[0]
        elif name == 'AttributeBegin':
            stack.append((ctm, current_material, area))
        elif name == 'AttributeEnd':
            ctm, current_material, area = stack.pop()
        elif name == 'AreaLightSource':
            if args[0] != 'diffuse' or param(params, 'twosided') or param(params, 'scale'):
                raise SystemExit('unsupported area light')
            area = [float(v) for v in param(params, 'L')]
        elif name == 'Shape':
            kind = args[0]
            lines = []
            if kind == 'trianglemesh':
                pos = [float(v) for v in param(params, 'P')]
                pos = [pos[i:i + 3] for i in range(0, len(pos), 3)]
                idx = [int(float(v)) for v in param(params, 'indices')]
                normals = param(params, 'N')
                if normals:
                    n = [float(v) for v in normals]
                    n = [n[i:i + 3] for i in range(0, len(n), 3)]
                    for t in range(0, len(idx), 3):
                        a, b, c = idx[t:t + 3]
                        ng = cross(sub(pos[b], pos[a]), sub(pos[c], pos[a]))
                        ns = [n[a][k] + n[b][k] + n[c][k] for k in range(3)]
                        if dot(ng, ns) < 0:
                            idx[t + 1], idx[t + 2] = c, b
                os.makedirs(os.path.join(scene_dir, 'meshes'), exist_ok=True)
                file = 'meshes/mesh%02d.ply' % mesh_count
                mesh_count += 1
                write_ply(os.path.join(scene_dir, file), pos, idx)
                lines.append('\t<shape type="ply">')
                lines.append('\t\t<string name="filename" value="%s"/>' % file)
                lines.append('\t\t<boolean name="face_normals" value="true"/>')
            elif kind == 'plymesh':
                lines.append('\t<shape type="ply">')
                lines.append('\t\t<string name="filename" value="%s"/>' % param(params, 'filename')[0])
            elif kind == 'sphere':
                lines.append('\t<shape type="sphere">')
                lines.append('\t\t<float name="radius" value="%s"/>' % fmt(float(param(params, 'radius', [1])[0])))
            else:
                raise SystemExit('unsupported shape ' + kind)
            if any(abs(ctm[r][c] - (1.0 if r == c else 0.0)) > 0 for r in range(4) for c in range(4)):
                lines.append('\t\t<transform name="to_world">')
                lines.append('\t\t\t<matrix value="%s"/>' % matrix_text(ctm))
                lines.append('\t\t</transform>')
            lines.append('\t\t<ref id="%s"/>' % current_material)
            if area:
                lines.append('\t\t<emitter type="area">')
                lines.append('\t\t\t<rgb name="radiance" value="%s"/>' % ', '.join(fmt(v) for v in area))
                lines.append('\t\t</emitter>')
            lines.append('\t</shape>')
            shapes.append('\n'.join(lines))
        else:
            raise SystemExit('unsupported directive ' + name)

    to_world = matmul(camera_to_world, [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    integrator = head['integrator']
    out.append('<?xml version="1.0" encoding="utf-8"?>')
    out.append('<!-- Converted from %s by scenes/pbrt_to_mitsuba.py; do not edit by hand. -->'
               % os.path.basename(pbrt_path))
    out.append('<scene version="3.0.0">')
    out.append('\t<default name="integrator" value="%s"/>' % ('path' if integrator == 'bdpt' else integrator))
    out.append('\t<default name="spp" value="%d"/>' % head['spp'])
    out.append('\t<default name="resx" value="%d"/>' % head['res'][0])
    out.append('\t<default name="resy" value="%d"/>' % head['res'][1])
    out.append('\t<default name="max_depth" value="%d"/>' % (head['maxdepth'] + 1))
    if integrator == 'bdpt':
        out.append('\t<!-- pbrt renders this scene with bdpt; Mitsuba 3 has no bdpt (rayfarm reads "bdpt"). -->')
    out.append('\t<integrator type="$integrator">')
    out.append('\t\t<integer name="max_depth" value="$max_depth"/>')
    out.append('\t</integrator>')
    out.append('\t<sensor type="perspective">')
    out.append('\t\t<float name="fov" value="%s"/>' % fmt(head['fov']))
    out.append('\t\t<string name="fov_axis" value="smaller"/>')
    out.append('\t\t<transform name="to_world">')
    out.append('\t\t\t<matrix value="%s"/>' % matrix_text(to_world))
    out.append('\t\t</transform>')
    out.append('\t\t<sampler type="independent">')
    out.append('\t\t\t<integer name="sample_count" value="$spp"/>')
    out.append('\t\t</sampler>')
    out.append('\t\t<film type="hdrfilm">')
    out.append('\t\t\t<integer name="width" value="$resx"/>')
    out.append('\t\t\t<integer name="height" value="$resy"/>')
    ftype, fradius = head['filter'] or ('gaussian', 1.5)
    if ftype == 'triangle':
        out.append('\t\t\t<rfilter type="tent">')
        out.append('\t\t\t\t<float name="radius" value="%s"/>' % fmt(fradius))
        out.append('\t\t\t</rfilter>')
    elif ftype == 'box':
        out.append('\t\t\t<rfilter type="box"/>')
    else:
        raise SystemExit('unsupported filter ' + ftype)
    out.append('\t\t</film>')
    out.append('\t</sensor>')
    out.extend(bsdf_xml)
    out.extend(shapes)
    out.append('</scene>')
    path = os.path.join(scene_dir, 'scene.xml')
    with open(path, 'w', newline='\n') as f:
        f.write('\n'.join(out) + '\n')
    print('wrote', path, ':', len(shapes), 'shapes,', len(materials), 'materials,', mesh_count, 'meshes')


def material_xml(name, kind, params):
    def rgb(key):
        return ', '.join(fmt(float(v)) for v in param(params, key))
    lines = []
    if kind == 'diffuse':
        lines += ['\t<bsdf type="twosided" id="%s">' % name, '\t\t<bsdf type="diffuse">',
                  '\t\t\t<rgb name="reflectance" value="%s"/>' % rgb('reflectance'), '\t\t</bsdf>', '\t</bsdf>']
    elif kind == 'conductor':
        if (param(params, 'remaproughness', ['true'])[0] != 'false' or
                param(params, 'uroughness') != param(params, 'vroughness')):
            raise SystemExit('conductor %s: only remaproughness false, isotropic' % name)
        alpha = float(param(params, 'uroughness', [0])[0])
        lines += ['\t<bsdf type="twosided" id="%s">' % name]
        if alpha > 0:
            lines += ['\t\t<bsdf type="roughconductor">', '\t\t\t<string name="distribution" value="ggx"/>',
                      '\t\t\t<float name="alpha" value="%s"/>' % fmt(alpha)]
        else:
            lines += ['\t\t<bsdf type="conductor">']
        lines += ['\t\t\t<rgb name="eta" value="%s"/>' % rgb('eta'),
                  '\t\t\t<rgb name="k" value="%s"/>' % rgb('k'), '\t\t</bsdf>', '\t</bsdf>']
    elif kind == 'dielectric':
        if float(param(params, 'roughness', [0])[0]) != 0 or param(params, 'uroughness'):
            raise SystemExit('dielectric %s: only smooth' % name)
        lines += ['\t<bsdf type="dielectric" id="%s">' % name,
                  '\t\t<float name="int_ior" value="%s"/>' % fmt(float(param(params, 'eta', [1.5])[0])),
                  '\t\t<float name="ext_ior" value="1"/>', '\t</bsdf>']
    else:
        raise SystemExit('unsupported material ' + kind)
    return '\n'.join(lines)


if __name__ == '__main__':
    convert(sys.argv[1])
