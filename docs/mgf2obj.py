#!/usr/bin/env python3
"""Converts an MGF scene (the Materials and Geometry Format of Radiance and RenderPark's test
interiors) to OBJ + MTL for `antiradiance solve`. Python 3 standard library only.

    mgf2obj.py SCENE.mgf OUT.obj [--divisions N]

writes OUT.obj and OUT.mtl (the MTL beside the OBJ, named after it). What it keeps:

- faces (`f`), one-sided in their file order (MGF's front is counter-clockwise, as OBJ's),
  ear-clipped into triangles; `sides 2` is not carried over (solve with `--two-sided` for
  that): files as found are what the solver is measured on;
- `cyl`, `cone`, `sph`, `ring` and `torus` tessellated with N divisions a quarter circle
  (default 5, as MGF's own library), `prism` refused;
- transforms (`xf` blocks and `i FILE xf-args`, with `-t -rx -ry -rz -s -mx -my -mz -a -i`),
  includes relative to the including file;
- materials: `Kd` from `rd` and its colour (`cxy`, CIE 1931 chromaticity, through Radiance's
  RGB primaries with an equal-energy white, so grey stays grey), `Ke` from `ed` (lux) divided
  by 179 lm/W with its colour; specular and transmitted parts are dropped (the solver is
  diffuse). A material defined again under the same name with other values gets a new name
  (`NAME__2`);
- MGF's z up becomes y up: (x, y, z) -> (x, z, -y).

Vertices are shared where their positions agree to 1e-6, and triangles whose corners coincide
are dropped.
"""

import math
import os
import sys

WHITE_EFFICACY = 179.0  # lm / W, Radiance's


def mat_mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def identity():
    return [[float(i == j) for j in range(4)] for i in range(4)]


def apply(m, p):
    return [m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3] for i in range(3)]


def op_matrix(op, value):
    t = identity()
    if op == 't':
        for i in range(3):
            t[i][3] = value[i]
    elif op == 's':
        for i in range(3):
            t[i][i] = value
    elif op in ('rx', 'ry', 'rz'):
        c, s = math.cos(math.radians(value)), math.sin(math.radians(value))
        i, j = {'rx': (1, 2), 'ry': (2, 0), 'rz': (0, 1)}[op]
        t[i][i], t[i][j], t[j][i], t[j][j] = c, -s, s, c
    else:  # mx, my, mz
        i = 'xyz'.index(op[1])
        t[i][i] = -1.0
    return t


def xf_instances(args):
    """The transforms an `xf` argument list makes: one, or one per array element (`-a`)."""
    segments = [[1, []]]
    i = 0
    while i < len(args):
        a = args[i]
        if a == '-a':
            segments.append([int(args[i + 1]), []])
            i += 2
        elif a == '-t':
            segments[-1][1].append(('t', [float(x) for x in args[i + 1:i + 4]]))
            i += 4
        elif a in ('-rx', '-ry', '-rz', '-s'):
            segments[-1][1].append((a[1:], float(args[i + 1])))
            i += 2
        elif a in ('-mx', '-my', '-mz'):
            segments[-1][1].append((a[1:], None))
            i += 1
        elif a == '-i':
            ops = list(segments[-1][1])
            segments[-1][1] = ops * int(args[i + 1])
            i += 2
        else:
            raise ValueError(f"xf: unknown argument {a}")
    mats = [identity()]
    for count, ops in segments:
        step = identity()
        for op, value in ops:
            step = mat_mul(op_matrix(op, value), step)
        powers = [identity()]
        for _ in range(1, count):
            powers.append(mat_mul(step, powers[-1]))
        if count == 1:
            powers = [step]
        mats = [mat_mul(p, m) for p in powers for m in mats]
    return mats


def chromaticity_to_rgb(x, y, lum):
    """Linear RGB (Radiance's primaries, equal-energy white) of chromaticity (x, y) at luminance lum."""
    if y <= 0.0:
        return [lum, lum, lum]
    big_x, big_z = x / y * lum, (1.0 - x - y) / y * lum
    # XYZ -> RGB for primaries r (0.640, 0.330), g (0.290, 0.600), b (0.150, 0.060), white E.
    m = [[2.565313, -1.16685, -0.398463], [-1.022108, 1.978287, 0.043822], [0.074724, -0.25194, 1.177215]]
    rgb = [m[i][0] * big_x + m[i][1] * lum + m[i][2] * big_z for i in range(3)]
    return [max(c, 0.0) for c in rgb]


class Material:
    def __init__(self):
        self.rd, self.rd_c = 0.0, (1 / 3, 1 / 3)
        self.ed, self.ed_c = 0.0, (1 / 3, 1 / 3)

    def copy(self):
        m = Material()
        m.__dict__.update(self.__dict__)
        return m

    def key(self):
        return (self.rd, self.rd_c, self.ed, self.ed_c)


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def ear_clip(points):
    """Triangles of a planar polygon (counter-clockwise about its front), by ear clipping in
    the plane of its largest normal component; a fan when no ear is found."""
    n = len(points)
    if n < 3:
        return []
    if n == 3:
        return [points]
    normal = [0.0, 0.0, 0.0]
    for i in range(n):
        a, b = points[i], points[(i + 1) % n]
        normal[0] += (a[1] - b[1]) * (a[2] + b[2])
        normal[1] += (a[2] - b[2]) * (a[0] + b[0])
        normal[2] += (a[0] - b[0]) * (a[1] + b[1])
    axis = max(range(3), key=lambda k: abs(normal[k]))
    if normal[axis] == 0.0:
        return [[points[0], points[i], points[i + 1]] for i in range(1, n - 1)]
    u, v = [(1, 2), (2, 0), (0, 1)][axis]
    sign = 1.0 if normal[axis] > 0 else -1.0
    flat = [(p[u], p[v]) for p in points]

    def turn(o, a, b):
        return ((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])) * sign

    left = list(range(n))
    out = []
    while len(left) > 3:
        m = len(left)
        for k in range(m):
            ia, ib, ic = left[k - 1], left[k], left[(k + 1) % m]
            a, b, c = flat[ia], flat[ib], flat[ic]
            if turn(a, b, c) <= 0:
                continue
            inside = any(
                flat[j] not in (a, b, c)
                and turn(a, b, flat[j]) > 0
                and turn(b, c, flat[j]) > 0
                and turn(c, a, flat[j]) > 0
                for j in left
                if j not in (ia, ib, ic)
            )
            if not inside:
                out.append([points[ia], points[ib], points[ic]])
                left.pop(k)
                break
        else:
            out.extend([points[left[0]], points[left[k]], points[left[k + 1]]] for k in range(1, len(left) - 1))
            return out
    out.append([points[i] for i in left])
    return out


class Converter:
    def __init__(self, divisions):
        self.divisions = divisions
        self.vertices = {}  # name -> [position, normal]
        self.colors = {}
        self.color, self.color_name = (1 / 3, 1 / 3), None
        self.materials = {'_default': Material()}
        self.alias, self.versions = {}, {}
        self.material = '_default'
        self.current_vertex = None
        self.stack = [identity()]
        self.positions, self.position_index = [], {}
        self.faces = []  # (material name, [index, index, index])
        self.used = {}

    def run_file(self, path):
        with open(path, errors='replace') as fh:
            text = fh.read().replace('\\\n', ' ')
        lines = []
        for line in text.split('\n'):
            line = line.split('#', 1)[0].split()
            if line:
                lines.append(line)
        self.run(lines, os.path.dirname(path))

    def run(self, lines, base):
        i = 0
        while i < len(lines):
            words = lines[i]
            if words[0] == 'xf' and len(words) > 1:
                depth, j = 1, i + 1
                while j < len(lines):
                    if lines[j][0] == 'xf':
                        depth += 1 if len(lines[j]) > 1 else -1
                        if depth == 0:
                            break
                    j += 1
                for m in xf_instances(words[1:]):
                    self.stack.append(mat_mul(self.stack[-1], m))
                    self.run(lines[i + 1:j], base)
                    self.stack.pop()
                i = j + 1
                continue
            if words[0] != 'xf':
                self.entity(words, base)
            i += 1

    def entity(self, w, base):
        k = w[0]
        if k == 'i':
            path = os.path.join(base, w[1])
            for m in (xf_instances(w[2:]) if len(w) > 2 else [identity()]):
                self.stack.append(mat_mul(self.stack[-1], m))
                self.run_file(path)
                self.stack.pop()
        elif k == 'v':
            if len(w) >= 3 and w[2] == '=':
                self.vertices[w[1]] = list(self.vertices[w[3]]) if len(w) >= 4 else [[0.0] * 3, None]
            self.current_vertex = w[1]
        elif k == 'p':
            self.vertices[self.current_vertex][0] = [float(x) for x in w[1:4]]
        elif k == 'n':
            self.vertices[self.current_vertex][1] = [float(x) for x in w[1:4]]
        elif k == 'c':
            if len(w) == 1:
                self.color, self.color_name = (1 / 3, 1 / 3), None
            else:
                if len(w) >= 3 and w[2] == '=':
                    self.colors[w[1]] = self.colors[w[3]] if len(w) >= 4 else (1 / 3, 1 / 3)
                self.color_name = w[1]
                self.color = self.colors.get(w[1], (1 / 3, 1 / 3))
        elif k == 'cxy':
            self.color = (float(w[1]), float(w[2]))
            if self.color_name is not None:
                self.colors[self.color_name] = self.color
        elif k == 'm':
            if len(w) == 1:
                self.material = '_default'
                return
            name = w[1]
            if len(w) >= 3 and w[2] == '=':
                new = self.materials[self.alias.get(w[3], w[3])].copy() if len(w) >= 4 else Material()
                version = self.versions.get(name, 0) + 1
                self.versions[name] = version
                self.alias[name] = name if version == 1 else f"{name}__{version}"
                self.materials[self.alias[name]] = new
                self.color, self.color_name = (1 / 3, 1 / 3), None
            self.material = self.alias.get(name, name)
            self.materials.setdefault(self.material, Material())
        elif k == 'rd':
            m = self.materials[self.material]
            m.rd, m.rd_c = float(w[1]), self.color
        elif k == 'ed':
            m = self.materials[self.material]
            m.ed, m.ed_c = float(w[1]), self.color
        elif k == 'f':
            self.polygon([self.point(self.vertices[v][0]) for v in w[1:]])
        elif k in ('cyl', 'cone'):
            r2 = float(w[2]) if k == 'cyl' else float(w[4])
            self.cone(w[1], float(w[2]), w[3], r2)
        elif k == 'sph':
            self.sphere(w[1], float(w[2]))
        elif k == 'ring':
            self.ring(w[1], float(w[2]), float(w[3]))
        elif k == 'torus':
            self.torus(w[1], float(w[2]), float(w[3]))
        elif k == 'prism':
            raise ValueError(f"{k} is not supported")
        # Other entities (rs, td, ts, ir, sides, o, ies, fh, cspec, cct, cmix) carry nothing
        # a diffuse one-sided solve uses.

    def point(self, p):
        return apply(self.stack[-1], p)

    def polygon(self, points):
        self.used[self.material] = self.materials[self.material]
        for tri in ear_clip(points):
            index = []
            for p in tri:
                key = tuple(round(x, 6) for x in p)
                if key not in self.position_index:
                    self.positions.append(key)
                    self.position_index[key] = len(self.positions)
                index.append(self.position_index[key])
            if len(set(index)) == 3:
                self.faces.append((self.material, index))

    def circle(self, center, axis, radius):
        length = math.sqrt(sum(a * a for a in axis))
        axis = [a / length for a in axis]
        helper = [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0]
        u = cross(axis, helper)
        norm = math.sqrt(sum(x * x for x in u))
        u = [x / norm for x in u]
        v = cross(axis, u)
        n = 4 * self.divisions
        return [
            [center[i] + radius * (math.cos(2 * math.pi * j / n) * u[i] + math.sin(2 * math.pi * j / n) * v[i]) for i in range(3)]
            for j in range(n)
        ]

    def cone(self, v1, r1, v2, r2):
        p1, p2 = self.vertices[v1][0], self.vertices[v2][0]
        inward = r1 < 0 or r2 < 0
        axis = sub(p2, p1)
        a, b = self.circle(p1, axis, abs(r1)), self.circle(p2, axis, abs(r2))
        n = len(a)
        for j in range(n):
            k = (j + 1) % n
            quad = [a[j], a[k], b[k], b[j]]
            if r1 == 0:
                quad = [a[j], b[k], b[j]]
            elif r2 == 0:
                quad = [a[j], a[k], b[j]]
            if inward:
                quad = quad[::-1]
            self.polygon([self.point(p) for p in quad])

    def sphere(self, vc, r):
        c = self.vertices[vc][0]
        inward, r = r < 0, abs(r)
        nu, nv = 4 * self.divisions, 2 * self.divisions

        def at(i, j):
            th, ph = math.pi * i / nv, 2 * math.pi * j / nu
            return [c[0] + r * math.sin(th) * math.cos(ph), c[1] + r * math.sin(th) * math.sin(ph), c[2] + r * math.cos(th)]

        for i in range(nv):
            for j in range(nu):
                quad = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]
                if i == 0:
                    quad = quad[:3]
                elif i == nv - 1:
                    quad = [quad[0], quad[1], quad[3]]
                if inward:
                    quad = quad[::-1]
                self.polygon([self.point(p) for p in quad])

    def torus(self, vc, r_min, r_max):
        # MGF: the tube spans r_min..r_max from the centre in the plane across the centre's
        # normal; negative radii turn the surface inward.
        center, normal = self.vertices[vc]
        inward = r_min < 0 or r_max < 0
        r_min, r_max = abs(r_min), abs(r_max)
        ring, tube = (r_min + r_max) / 2, (r_max - r_min) / 2
        length = math.sqrt(sum(a * a for a in normal))
        axis = [a / length for a in normal]
        spine = self.circle(center, axis, ring)
        n = len(spine)
        m = 4 * self.divisions

        def at(i, j):
            # Point j of the tube's cross-section at spine point i.
            out = [spine[i][c] - center[c] for c in range(3)]
            norm = math.sqrt(sum(x * x for x in out))
            out = [x / norm for x in out]
            a = 2 * math.pi * j / m
            return [spine[i][c] + tube * (math.cos(a) * out[c] + math.sin(a) * axis[c]) for c in range(3)]

        for i in range(n):
            for j in range(m):
                i1, j1 = (i + 1) % n, (j + 1) % m
                quad = [at(i, j), at(i1, j), at(i1, j1), at(i, j1)]
                if inward:
                    quad = quad[::-1]
                self.polygon([self.point(p) for p in quad])

    def ring(self, vc, r1, r2):
        center, normal = self.vertices[vc]
        a, b = self.circle(center, normal, r1), self.circle(center, normal, r2)
        n = len(a)
        for j in range(n):
            k = (j + 1) % n
            quad = [center, b[j], b[k]] if r1 == 0 else [a[j], b[j], b[k], a[k]]
            self.polygon([self.point(p) for p in quad])


def main():
    args = sys.argv[1:]
    divisions = 5
    if '--divisions' in args:
        i = args.index('--divisions')
        divisions = int(args[i + 1])
        del args[i:i + 2]
    if len(args) != 2:
        sys.exit(__doc__)
    src, dst = args
    conv = Converter(divisions)
    conv.run_file(src)
    # Materials defined again with the same values keep their first name.
    canonical, first = {}, {}
    for name, m in conv.used.items():
        canonical[name] = first.setdefault((name.split('__')[0], m.key()), name)
    mtl = os.path.splitext(dst)[0] + '.mtl'
    with open(mtl, 'w') as fh:
        for name, m in conv.used.items():
            if canonical[name] != name:
                continue
            kd = [min(c, 0.99) for c in chromaticity_to_rgb(*m.rd_c, m.rd)]
            fh.write(f"newmtl {name}\n# mgf: rd {m.rd} cxy {m.rd_c[0]:.4f} {m.rd_c[1]:.4f} ed {m.ed}\n")
            fh.write(f"Kd {kd[0]:.6f} {kd[1]:.6f} {kd[2]:.6f}\n")
            if m.ed > 0:
                ke = [c * m.ed / WHITE_EFFICACY for c in chromaticity_to_rgb(*m.ed_c, 1.0)]
                fh.write(f"Ke {ke[0]:.6f} {ke[1]:.6f} {ke[2]:.6f}\n")
            fh.write("\n")
    with open(dst, 'w') as fh:
        fh.write(f"# {os.path.basename(src)}, converted by docs/mgf2obj.py: one-sided in file order, y up\n")
        fh.write(f"mtllib {os.path.basename(mtl)}\n")
        for p in conv.positions:
            fh.write(f"v {p[0]:.6f} {p[2]:.6f} {-p[1]:.6f}\n")
        current = None
        for name, index in conv.faces:
            name = canonical[name]
            if name != current:
                fh.write(f"usemtl {name}\n")
                current = name
            fh.write("f " + " ".join(map(str, index)) + "\n")
    print(f"{dst}: {len(conv.faces)} triangles, {len(conv.positions)} vertices", file=sys.stderr)


if __name__ == '__main__':
    main()
