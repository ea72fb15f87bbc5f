"""Author cases/scenes/meshes/core_sample.obj: the closed surface of a rock core specimen for
cases/scenes/core_sample.toml.

An NX core, 54 mm in diameter and 135 mm long (height / diameter 2.5, as suggested for uniaxial
compression tests), as a closed triangulated cylinder: 96 facets around, the end faces fanned
from their centres.  Its axis is the z axis, the bottom face at z = 0.  Units: metres.

    python -m cases.make.core_sample        # rewrites cases/scenes/meshes/core_sample.obj
    sgim build cases/scenes/core_sample.toml -o out/core_sample
"""
from __future__ import annotations

import math

from cases import SCENES

RADIUS = 0.027
HEIGHT = 0.135
SEGMENTS = 96

OUT = SCENES / "meshes" / "core_sample.obj"


def cylinder(radius=RADIUS, height=HEIGHT, seg=SEGMENTS):
    """Vertices and outward-wound triangles of a closed cylinder on the z axis."""
    verts = []
    for z in (0.0, height):
        for k in range(seg):
            a = 2.0 * math.pi * k / seg
            verts.append((radius * math.cos(a), radius * math.sin(a), z))
    verts += [(0.0, 0.0, 0.0), (0.0, 0.0, height)]
    cb, ct = 2 * seg, 2 * seg + 1
    faces = []
    for k in range(seg):
        k1 = (k + 1) % seg
        faces += [(k, k1, seg + k1), (k, seg + k1, seg + k)]  # side, normal outwards
        faces.append((cb, k1, k))  # bottom, normal -z
        faces.append((ct, seg + k, seg + k1))  # top, normal +z
    return verts, faces


def obj_text():
    verts, faces = cylinder()
    lines = [f"# NX core specimen: cylinder radius {RADIUS} m, height {HEIGHT} m, {SEGMENTS} segments "
             f"(written by cases/make/core_sample.py)"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in verts]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def main():
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(obj_text())
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
