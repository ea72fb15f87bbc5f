"""Scene generators: parameters -> list of :class:`dda.blockspec.BlockSpec`.

``GENERATORS[name](**params)`` builds the blocks of a standard scene. Parameters are plain numbers, lists
and dicts so that a scene file can pass them through. Units are metres and degrees; x east, y north, z up.
Fixed blocks have ``fixed=True``. Every random choice comes from ``numpy.random.default_rng(seed)``.

=====================  ==================================================================================
``incline``            fixed inclined base and one block resting on it; the slope descends toward +x.
                       ``angle=30, size=1.0, height=None (=size/2), base_length=10.0, base_thickness=1.0,
                       position=-2.5`` (block centre along the slope, from the base's middle).
                       Blocks: ``base`` (fixed), ``block``.
``wedge``              Hoek & Bray wedge (``dda.hoekbray``): the free tetrahedron bounded by joints A, B, the
                       slope face and the top surface, and three fixed convex blocks of the rock mass:
                       ``below_a`` (below A, above B), ``below_b`` (below B, above A), ``below_ab`` (below
                       both), each bounded by the face, the top and a box ``margin`` x the wedge size around
                       the wedge. ``joint_a=(45, 5), joint_b=(55, 135), face=(65, 65), top=(0, 0),
                       height=10.0, margin=0.5``. Blocks: ``wedge``, then the fixed ones.
``toppling``           column of width ``b`` (down the slope), height ``h`` and depth ``depth`` (default b)
                       standing on a fixed base inclined at ``alpha`` degrees (descending toward +x).
                       ``b=1.0, h=3.0, alpha=20.0, depth=None, base_length=None, base_thickness=None``.
                       Blocks: ``base`` (fixed), ``column``.
``brick_wall``         ``layers`` x ``per_layer`` bricks (``brick=(length, thickness, height)``) along y,
                       staggered by half a brick every other layer, on a fixed ground; a fixed ramp inclined
                       at ``ramp_angle`` ending ``gap`` before the wall at height ``hit_height`` (default
                       0.6 x the wall height, where the bricks above weigh little enough for the projectile
                       to break through); a cube projectile of edge ``projectile`` resting on the ramp
                       ``run`` (slope length) above its lower end, with ``projectile_velocity`` along the ramp.
                       ``layers=10, per_layer=13, brick=(0.4, 0.2, 0.2), ramp_angle=35.0, gap=0.1, run=2.0,
                       projectile=0.6, projectile_velocity=0.0``. The gap is small against the projectile,
                       which leaves the ramp with its front already at the wall (a gap about as wide as the
                       tilted cube let it drop into the gap and wedge between the ramp's end and the wall's
                       foot). Blocks: ``ground``, ``ramp`` (fixed),
                       ``brick_L_K`` (layer L, index K), ``projectile``.
``falling_polyhedra``  ``n`` blocks of the paper's four shapes (tetrahedron, pyramid, cube, octahedron; edge
                       ``size``), random shape and uniformly random orientation, on a grid of ``side`` x
                       ``side`` columns (default ceil(n^(1/3))), each cell jittered by up to ``jitter`` of the
                       free space; cell size 2 R (1 + ``spacing``), R the largest circumradius, so bounding
                       spheres never meet; lowest layer ``clearance`` above a fixed floor.
                       ``n=1500, size=1.0, seed=0, spacing=0.1, jitter=1.0, clearance=0.1, side=None,
                       shapes=PAPER_SHAPES``. Blocks: ``floor`` (fixed, first), ``poly_I``.
``stack``              ``n`` boxes ``size`` wide, ``height`` tall (default size/2) stacked exactly touching
                       on a fixed floor; ``offset`` shifts each block along x by that fraction of ``size``
                       (alternating sign). ``n=10, size=1.0, height=None, offset=0.0``.
                       Blocks: ``floor`` (fixed), ``block_K`` bottom to top.
``box_cut``            the box ``lo``..``hi`` cut by ``planes`` (each ``{normal, point}`` or
                       ``{dip, dip_direction, point}``) and ``joint_sets`` (each ``{dip, dip_direction,
                       spacing, origin=(0,0,0), extent=None}``, the joint description of SGIM), see
                       ``dda.cut``; ``floor=True`` adds a fixed floor under the box.
                       ``lo=(0,0,0), hi=(10,10,5), joint_sets=(), planes=(), floor=True, sliver="merge"``.
                       Blocks: ``floor`` (fixed, if any), ``block_K``.
=====================  ==================================================================================
"""

from __future__ import annotations

import math

import numpy as np

from sgim.geometry import dip_to_normal

from . import cut as _cut
from . import hoekbray
from .blockspec import BlockSpec
from .shapes import (PAPER_SHAPES, GeometryError, box, circumradius, convex_hull, random_rotation, rotation_about,
                     shape, transformed)


def _tilted(spec, angle, **fields):
    """Rotate about the y axis through the origin so that +x descends at ``angle`` degrees."""
    return transformed(spec, rotation=rotation_about((0.0, 1.0, 0.0), angle), about=(0.0, 0.0, 0.0), **fields)


def incline(angle=30.0, size=1.0, height=None, base_length=10.0, base_thickness=1.0, position=-2.5,
            material="rock", base_material=None):
    """Fixed inclined base and one block resting on its surface (see module docstring)."""
    h = size / 2 if height is None else float(height)
    if not (0 <= angle < 90 and size > 0 and h > 0 and base_length > size and base_thickness > 0):
        raise GeometryError("incline needs 0 <= angle < 90, size, height, base_thickness > 0, base_length > size")
    base = box((-base_length / 2, -size, -base_thickness), (base_length / 2, size, 0.0))
    blk = box((position - size / 2, -size / 2, 0.0), (position + size / 2, size / 2, h))
    return [_tilted(base, angle, name="base", fixed=True, material=base_material or material),
            _tilted(blk, angle, name="block", material=material)]


def wedge(joint_a=(45.0, 5.0), joint_b=(55.0, 135.0), face=(65.0, 65.0), top=(0.0, 0.0), height=10.0,
          margin=0.5, material="rock", crease=1e-3):
    """The Hoek & Bray wedge and three fixed blocks holding it (see module docstring)."""
    a, b, f, t, dt, verts = hoekbray.wedge_geometry(tuple(joint_a), tuple(joint_b), tuple(face),
                                                    None if top is None else tuple(top), float(height))
    w = convex_hull(verts, name="wedge", material=material)
    ext = np.ptp(verts, axis=0).max()
    lo = verts.min(0) - margin * ext
    hi = verts.max(0) + margin * ext
    hi[2] = max(hi[2], verts[:, 2].max() + margin * ext)
    domain = box(lo, hi)
    out = [w]
    # below_ab stops short of the line of intersection by a thin void (crease = 1e-3 x the wedge size): the
    # wedge's lower edge then rests on below_a and below_b alone, each bearing by its own joint plane, and a
    # third block meeting the edge at a point of two planes cannot take over part of the load on a normal
    # chosen by the penetration depths
    sink = crease * ext
    for name, sa, sb, off in (("below_a", 1, -1, 0.0), ("below_b", -1, 1, 0.0), ("below_ab", 1, 1, sink)):
        piece = domain
        for plane in ((sa * a, -off), (sb * b, -off), (f, 0.0), (t, dt)):
            piece = _cut.clip(piece, plane)
            if piece is None:
                raise GeometryError(f"wedge: fixed block {name} is empty; increase margin")
        out.append(BlockSpec(piece.vertices, piece.faces, name=name, fixed=True, material=material))
    return out


def toppling(b=1.0, h=3.0, alpha=20.0, depth=None, base_length=None, base_thickness=None, material="rock"):
    """A column b wide and h tall on a fixed base inclined at alpha (see module docstring)."""
    d = b if depth is None else float(depth)
    if not (b > 0 and h > 0 and d > 0 and 0 <= alpha < 90):
        raise GeometryError("toppling needs b, h, depth > 0 and 0 <= alpha < 90")
    length = base_length if base_length is not None else 4 * (b + h)
    thick = base_thickness if base_thickness is not None else max(b, h) / 2
    base = box((-length / 2, -d, -thick), (length / 2, d, 0.0))
    col = box((-b / 2, -d / 2, 0.0), (b / 2, d / 2, h))
    return [_tilted(base, alpha, name="base", fixed=True, material=material),
            _tilted(col, alpha, name="column", material=material)]


def brick_wall(layers=10, per_layer=13, brick=(0.4, 0.2, 0.2), ramp_angle=35.0, gap=0.1, run=2.0,
               projectile=0.6, projectile_velocity=0.0, hit_height=None, material="rock",
               brick_material=None, projectile_material=None):
    """Staggered brick wall, fixed ground, fixed ramp and a projectile on the ramp (see module docstring)."""
    bl, bt, bh = (float(x) for x in brick)
    layers, per_layer = int(layers), int(per_layer)
    if not (layers >= 1 and per_layer >= 1 and bl > 0 and bt > 0 and bh > 0 and 0 < ramp_angle < 90
            and gap >= 0 and run > 0 and projectile > 0 and (hit_height is None or hit_height > 0)):
        raise GeometryError("brick_wall: check layers, per_layer, brick sizes, ramp_angle in (0, 90), run, projectile")
    wall_h = layers * bh
    zh = 0.6 * wall_h if hit_height is None else float(hit_height)
    width = per_layer * bl + bl / 2
    # ramp: trapezoid in x-z (lower end at x = -gap, height zh; slope rises toward -x), extruded in y
    slope_len = run + 1.5 * projectile
    x_e = -gap
    x_s = x_e - slope_len * math.cos(math.radians(ramp_angle))
    z_s = zh + slope_len * math.sin(math.radians(ramp_angle))
    ymid = 0.0
    yw = max(2 * projectile, bl)
    ramp_pts = [(x_s, ymid - yw, 0.0), (x_e, ymid - yw, 0.0), (x_e, ymid - yw, zh), (x_s, ymid - yw, z_s),
                (x_s, ymid + yw, 0.0), (x_e, ymid + yw, 0.0), (x_e, ymid + yw, zh), (x_s, ymid + yw, z_s)]
    out = []
    # the ground reaches far enough behind the wall to catch the bricks thrown off by the impact
    reach = max(1.0, 2.5 * wall_h)
    ground = box((x_s - 1.0, -width / 2 - reach, -0.5), (bt + reach, width / 2 + reach, 0.0))
    out.append(BlockSpec(ground.vertices, ground.faces, name="ground", fixed=True, material=material))
    out.append(convex_hull(ramp_pts, name="ramp", fixed=True, material=material))
    y0 = -per_layer * bl / 2
    for L in range(layers):
        shift = bl / 2 if L % 2 else 0.0
        for k in range(per_layer):
            ya = y0 + shift + k * bl - bl / 4
            out.append(box((0.0, ya, L * bh), (bt, ya + bl, (L + 1) * bh), name=f"brick_{L}_{k}",
                           material=brick_material or material))
    # projectile: cube on the ramp surface, its centre 'run' up the slope from the lower end
    up = np.array([-math.cos(math.radians(ramp_angle)), 0.0, math.sin(math.radians(ramp_angle))])
    nrm = np.array([math.sin(math.radians(ramp_angle)), 0.0, math.cos(math.radians(ramp_angle))])
    c = np.array([x_e, ymid, zh]) + up * (run + projectile / 2) + nrm * (projectile / 2)
    cube = shape("cube", projectile, rotation=rotation_about((0, 1, 0), ramp_angle), center=c)
    v = -up * float(projectile_velocity)
    out.append(BlockSpec(cube.vertices, cube.faces, name="projectile", velocity=tuple(v.tolist()),
                         material=projectile_material or material))
    return out


def falling_polyhedra(n=1500, size=1.0, seed=0, spacing=0.1, jitter=1.0, clearance=0.1, side=None,
                      shapes=PAPER_SHAPES, material="rock", floor_margin=None):
    """n random polyhedra of the paper's shapes, random orientations, non-overlapping, above a floor."""
    n = int(n)
    if n < 1 or not size > 0 or spacing < 0 or not 0 <= jitter <= 1 or clearance < 0:
        raise GeometryError("falling_polyhedra needs n >= 1, size > 0, spacing >= 0, 0 <= jitter <= 1")
    rng = np.random.default_rng(seed)
    protos = [shape(s, size) for s in shapes]  # centred on their centroids
    rmax = max(circumradius(p) for p in protos)
    cell = 2 * rmax * (1 + spacing)
    free = cell / 2 - rmax
    side = int(side) if side is not None else max(1, math.ceil(n ** (1 / 3)))
    out = []
    for i in range(n):
        layer, rest = divmod(i, side * side)
        iy, ix = divmod(rest, side)
        centre = np.array([(ix + 0.5) * cell, (iy + 0.5) * cell, clearance + (layer + 0.5) * cell])
        centre += jitter * free * rng.uniform(-1.0, 1.0, 3)
        k = int(rng.integers(len(protos)))
        blk = transformed(protos[k], rotation=random_rotation(rng), translation=centre, name=f"poly_{i}",
                          material=material)
        out.append(blk)
    span = side * cell
    m = span * 0.25 if floor_margin is None else float(floor_margin)
    floor = box((-m, -m, -max(size, 0.1 * span)), (span + m, span + m, 0.0), name="floor", fixed=True,
                material=material)
    return [floor] + out


def stack(n=10, size=1.0, height=None, offset=0.0, material="rock"):
    """n boxes stacked exactly touching on a fixed floor."""
    h = size / 2 if height is None else float(height)
    if int(n) < 1 or not size > 0 or not h > 0:
        raise GeometryError("stack needs n >= 1, size > 0, height > 0")
    out = [box((-2 * size, -2 * size, -size / 2), (2 * size, 2 * size, 0.0), name="floor", fixed=True,
               material=material)]
    for k in range(int(n)):
        dx = offset * size * (1 if k % 2 else -1) if offset else 0.0
        out.append(box((dx - size / 2, -size / 2, k * h), (dx + size / 2, size / 2, (k + 1) * h), name=f"block_{k}",
                       material=material))
    return out


def _plane_param(p):
    if isinstance(p, dict):
        if "normal" in p:
            return (np.asarray(p["normal"], float), np.asarray(p.get("point", (0, 0, 0)), float))
        return (dip_to_normal(p["dip"], p["dip_direction"]), np.asarray(p.get("point", (0, 0, 0)), float))
    return p


def _joint_param(j):
    if isinstance(j, _cut.JointSet):
        return j
    ext = j.get("extent")
    return _cut.JointSet(float(j["dip"]), float(j["dip_direction"]), float(j["spacing"]),
                         tuple(j.get("origin", (0.0, 0.0, 0.0))),
                         None if ext is None else (tuple(ext[0]), tuple(ext[1])), str(j.get("name", "")))


def box_cut(lo=(0.0, 0.0, 0.0), hi=(10.0, 10.0, 5.0), joint_sets=(), planes=(), floor=True, sliver="merge",
            material="rock", progress=None):
    """A box cut by planes and joint sets, on an optional fixed floor (see module docstring)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pieces = _cut.cut_box(lo, hi, [_plane_param(p) for p in planes], [_joint_param(j) for j in joint_sets],
                          name="block_", sliver=sliver, progress=progress)
    for p in pieces:
        p.material = material
    out = []
    if floor:
        m = 0.25 * float(np.ptp(np.vstack([lo, hi]), axis=0)[:2].max())
        out.append(box((lo[0] - m, lo[1] - m, lo[2] - max(0.1 * (hi[2] - lo[2]), 0.1)), (hi[0] + m, hi[1] + m, lo[2]),
                       name="floor", fixed=True, material=material))
    return out + pieces


GENERATORS = {
    "incline": incline,
    "wedge": wedge,
    "toppling": toppling,
    "brick_wall": brick_wall,
    "falling_polyhedra": falling_polyhedra,
    "stack": stack,
    "box_cut": box_cut,
}
