#!/usr/bin/env python3
"""Writes a small scene where antiradiance's bins show: one tube light right under its housing.

Python 3 standard library only:

    tube_under_housing.py OUT.obj [--housing-albedo A] [--tube-albedo A]
        writes OUT.obj and OUT.mtl beside it (albedos 0.8 and 0.5 unless given)
    tube_under_housing.py OUT.obj --blocker yes|no
        the same room with black walls, its floor (albedo 0.7) in 8 x 8 squares, the housing's
        underside alone as the light (radiance 5) and, with `yes`, a closed black blocker
        32 x 2.5 mm in section in the tube's place, 14 mm under it

A closed 4 x 3 x 4 m room (albedo 0.7, facing in), a housing block 1.28 x 0.07 x 0.12 m
(albedo 0.8) 10 cm under the ceiling, and under it, 14 mm below the housing, an emitting tube
1.2 m long of radius 16 mm (16 sides, closed by fans; radiance 25, 25, 23) - the classroom's
tube lights (`antiradiance scene classroom`) alone in a room. Metres, y up. The housing's
underside, lit from 14 mm, is the brightest surface, and the tube blocks a wide part of the
room's view of it: light that antiradiance must cancel through a blocker seen at grazing
directions. docs/ARCHITECTURE.md ("Sender spread") has the figures.
"""

import math
import os
import sys


def main(argv):
    args = argv[1:]
    albedo = {"--housing-albedo": 0.8, "--tube-albedo": 0.5}
    blocker = None
    while len(args) >= 3 and (args[-2] in albedo or args[-2] == "--blocker"):
        if args[-2] == "--blocker":
            if args[-1] not in ("yes", "no"):
                break
            blocker = args[-1] == "yes"
        else:
            albedo[args[-2]] = float(args[-1])
        args = args[:-2]
    if len(args) != 1 or not all(0.0 <= a < 1.0 for a in albedo.values()):
        sys.stderr.write(__doc__)
        return 2
    out = args[0]
    vertices, faces = [], []

    def tri(a, b, c, material):
        i = len(vertices)
        vertices.extend([a, b, c])
        faces.append((i, i + 1, i + 2, material))

    def quad(a, b, c, d, material):
        tri(a, b, c, material)
        tri(a, c, d, material)

    def block(lo, hi, material, inward=False):
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        sides = [
            ((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)),
            ((x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)),
            ((x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)),
            ((x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)),
            ((x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)),
            ((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)),
        ]
        for q in sides:
            quad(*((q[0], q[3], q[2], q[1]) if inward else q), material)

    def tube(x0, y, z, length, radius, sides, material):
        ring = [
            (y + radius * math.cos(2 * math.pi * k / sides), z + radius * math.sin(2 * math.pi * k / sides))
            for k in range(sides)
        ]
        for k in range(sides):
            (ya, za), (yb, zb) = ring[k], ring[(k + 1) % sides]
            quad((x0, ya, za), (x0, yb, zb), (x0 + length, yb, zb), (x0 + length, ya, za), material)
        (y0, z0) = ring[0]
        for k in range(1, sides - 1):
            (ya, za), (yb, zb) = ring[k], ring[k + 1]
            tri((x0, y0, z0), (x0, yb, zb), (x0, ya, za), material)
            tri((x0 + length, y0, z0), (x0 + length, ya, za), (x0 + length, yb, zb), material)

    if blocker is None:
        block((0, 0, 0), (4, 3, 4), "wall", inward=True)
        block((1.36, 2.83, 1.94), (2.64, 2.9, 2.06), "housing")
        tube(1.4, 2.8, 2.0, 1.2, 0.016, 16, "tube")
        h, t = albedo["--housing-albedo"], albedo["--tube-albedo"]
        materials = (
            "newmtl wall\nKd 0.7 0.7 0.7\n"
            f"newmtl housing\nKd {h} {h} {h}\n"
            f"newmtl tube\nKd {t} {t} {t}\nKe 25 25 23\n"
        )
    else:
        block((0, 0, 0), (4, 3, 4), "wall", inward=True)
        del faces[:2]  # the floor, replaced by a grid
        for i in range(8):
            for j in range(8):
                (x0, x1, z0, z1) = (i / 2, (i + 1) / 2, j / 2, (j + 1) / 2)
                quad((x0, 0, z0), (x0, 0, z1), (x1, 0, z1), (x1, 0, z0), "floor")
        quad((1.36, 2.83, 1.94), (2.64, 2.83, 1.94), (2.64, 2.83, 2.06), (1.36, 2.83, 2.06), "light")
        if blocker:
            block((1.4, 2.8135, 1.984), (2.6, 2.816, 2.016), "blocker")
        materials = (
            "newmtl wall\nKd 0 0 0\nnewmtl floor\nKd 0.7 0.7 0.7\n"
            "newmtl light\nKd 0 0 0\nKe 5 5 5\nnewmtl blocker\nKd 0 0 0\n"
        )

    mtl = os.path.splitext(out)[0] + ".mtl"
    with open(mtl, "w") as f:
        f.write(materials)
    with open(out, "w") as f:
        f.write(f"mtllib {os.path.basename(mtl)}\n")
        for v in vertices:
            f.write("v %.6f %.6f %.6f\n" % v)
        current = None
        for a, b, c, material in faces:
            if material != current:
                f.write(f"usemtl {material}\n")
                current = material
            f.write(f"f {a + 1} {b + 1} {c + 1}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
