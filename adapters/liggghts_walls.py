"""LIGGGHTS decks with rigid-side joints as mesh walls (run.extra ``liggghts_joint_walls`` = true).

LIGGGHTS-PUBLIC has no smooth joint: a joint between moving spheres and fixed rock written as sphere contacts
is the fixed spheres' bumpy surface, on which a sliding block interlocks. Where one side of a joint is fixed
rock (a wedge, planar sliding, a block on an incline), the usual LIGGGHTS model of a fixed sliding surface is
a triangulated wall: ``fix mesh/surface`` from an STL file with an atom type of its own, and ``fix wall/gran``
with the sphere-wall friction of that type in the ``coefficientFriction peratomtypepair`` matrix.

With run.extra ``liggghts_joint_walls`` true and smooth joints (without them joint pairs are plain contacts in
every engine), for every joint (joint_disc) that has pairs of one fixed and one free sphere (``wall_planes``):

- the wall's normal is the mean joint normal of those pairs, signed to point from the fixed to the free side;
- the wall plane n.x = d touches the nearest free sphere of those pairs (d = min over them of n.c - r: the
  sphere surface touching the joint plane);
- the fixed spheres on the fixed side of a walled joint (n.c no more than that of the pairs' fixed spheres) are
  left out (``dropped``): they stay in the data file (the runner's atom ids) with atom type DROPPED_TYPE, which
  every ``neigh_modify exclude type`` keeps out of every contact, and are never integrated;
- the wall is one rectangle (two triangles) in that plane covering the projection of the dropped spheres
  behind it (the rock it stands for), enlarged by their largest radius; atom type WALL_TYPE, whose friction
  with every sphere type is run.joint_friction_deg, stiffness run.kn / run.ks and normal damping with the
  sphere's own mass (as a fixed partner).

``wall_notes`` are the deck's approximations (RunResult.extra["approximations"]).
Plain numpy on a SphereRun: the deck writer and the tests read it.
"""
from __future__ import annotations

import numpy as np

from .spec import SpecError

DROPPED_TYPE, WALL_TYPE = 9, 10  # after the 8 sphere types of adapters/liggghts_deck.py (colour x fixed)
WALL_TYPES = 10
PLANAR_DEG = 1e-3  # a walled joint's pair normals may differ from their mean by this much [deg]


def flag(run, key):
    """run.extra[key] as a bool (absent: False); SpecError naming the key and value unless true or false."""
    value = run.extra.get(key, False)
    if value is True or value is False or (isinstance(value, int) and value in (0, 1)):
        return bool(value)
    raise SpecError(f"{run.source or run.name}: run.extra {key} = {value!r}: expected true or false")


def joint_walls(run):
    """True when the deck writes the rigid sides of joints as mesh walls (run.extra ``liggghts_joint_walls``)
    and some joint pair joins a fixed and a free sphere."""
    if not flag(run, "liggghts_joint_walls") or not len(run.joint_i) or not run.smooth_joints:
        return False
    fixed = np.asarray(run.fixed, bool)
    return bool(np.any(fixed[run.joint_i] != fixed[run.joint_j]))


def _basis(n):
    """Two unit vectors (u, v) spanning the plane of the unit normal n."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def wall_planes(run):
    """One dict per walled joint side: disc (joint_disc), normal (3,) from the fixed to the free side, offset d
    (the plane n.x = d), back (the largest n.c of the pairs' fixed spheres: the fixed spheres with n.c <= back
    are the rock the wall stands for), pairs (number of fixed-free joint pairs). A joint with fixed rock on both
    of its sides in places gets a wall for each side. [] when the deck has no walls; SpecError for a joint that
    is not planar (its pairs' normals differ by more than PLANAR_DEG: a wall is one plane)."""
    if not joint_walls(run):
        return []
    fixed = np.asarray(run.fixed, bool)
    c, r = np.asarray(run.centers, float), np.asarray(run.radii, float)
    i, j = np.asarray(run.joint_i), np.asarray(run.joint_j)
    mixed = fixed[i] != fixed[j]
    normal = np.asarray(run.joint_normal, float).reshape(-1, 3) * np.where(fixed[i], 1.0, -1.0)[:, None]  # -> free
    out = []
    for disc in np.unique(np.asarray(run.joint_disc)[mixed]):
        on = np.flatnonzero(mixed & (np.asarray(run.joint_disc) == disc))
        side = normal[on] @ normal[on[0]] >= 0.0
        for k in (on[side], on[~side]):
            if not len(k):
                continue
            n = np.sum(normal[k], axis=0)
            n /= np.linalg.norm(n)
            spread = float(np.degrees(np.arccos(np.clip(np.min(normal[k] @ n), -1.0, 1.0))))
            if spread > PLANAR_DEG:
                raise SpecError(f"{run.source or run.name}: run.extra liggghts_joint_walls: joint {int(disc)} is not "
                                f"planar (its pairs' normals differ by up to {spread:.3g} deg from their mean): a "
                                "wall is one plane")
            free, rock = np.where(fixed[i[k]], j[k], i[k]), np.where(fixed[i[k]], i[k], j[k])
            out.append(dict(disc=int(disc), normal=n, offset=float(np.min(c[free] @ n - r[free])),
                            back=float(np.max(c[rock] @ n)), pairs=int(len(k))))
    return out


def dropped(run, planes=None):
    """(n,) bool: the fixed spheres on the fixed side of a walled joint (n.c <= back), which the walls stand
    for."""
    planes = wall_planes(run) if planes is None else planes
    fixed = np.asarray(run.fixed, bool)
    out = np.zeros(run.n, bool)
    for p in planes:
        out |= fixed & (np.asarray(run.centers, float) @ p["normal"] <= p["back"])
    return out


def wall_triangles(run, planes=None):
    """(walls, 2, 3, 3): each wall's two triangles (vertices counter-clockwise about its normal): the rectangle
    in its plane over the projection of the dropped spheres behind it, enlarged by their largest radius."""
    planes = wall_planes(run) if planes is None else planes
    gone = dropped(run, planes)
    c, r = np.asarray(run.centers, float), np.asarray(run.radii, float)
    out = np.zeros((len(planes), 2, 3, 3))
    for w, p in enumerate(planes):
        n, d = p["normal"], p["offset"]
        behind = gone & (c @ n <= p["back"])
        u, v = _basis(n)
        pu, pv = c[behind] @ u, c[behind] @ v
        grow = float(r[behind].max())
        (u0, u1), (v0, v1) = (pu.min() - grow, pu.max() + grow), (pv.min() - grow, pv.max() + grow)
        corner = [d * n + a * u + b * v for a, b in ((u0, v0), (u1, v0), (u1, v1), (u0, v1))]
        out[w] = [[corner[0], corner[1], corner[2]], [corner[0], corner[2], corner[3]]]
    return out


def wall_radii(run, planes=None):
    """(n,) contact radii with run.extra ``liggghts_wall_radii``: every free sphere of a walled joint's pairs
    touches the walls (its radius is the least distance from its centre to a wall plane it lies in front of),
    as every pair of a
    smooth joint is in contact at its own reference gap; the other spheres keep theirs. Without the option the
    free side rests on its lowest spheres alone (on the r = 0.5 wedge, two per wall: a rigid body on four
    points cannot slide without turning, so it slid at 0.66 % above Hoek & Bray's angle)."""
    planes = wall_planes(run) if planes is None else planes
    r = np.asarray(run.radii, float).copy()
    if not planes or not flag(run, "liggghts_wall_radii"):
        return r
    fixed = np.asarray(run.fixed, bool)
    i, j = np.asarray(run.joint_i), np.asarray(run.joint_j)
    mixed = (fixed[i] != fixed[j]) & np.isin(run.joint_disc, [p["disc"] for p in planes])
    free = np.unique(np.where(fixed[i[mixed]], j[mixed], i[mixed]))
    c = np.asarray(run.centers, float)[free]
    h = np.array([c @ p["normal"] - p["offset"] for p in planes])
    r[free] = np.min(np.where(h > 0.0, h, np.inf), axis=0)  # in front of its own wall at least (h >= r there)
    return r


def write_stl(path, triangles, normal, name="wall"):
    """An ASCII STL file of `triangles` (k, 3, 3) with the facet normal `normal` (3,)."""
    nrm = " ".join(f"{x:.17g}" for x in normal)
    lines = [f"solid {name}"]
    for tri in np.asarray(triangles, float):
        lines += [f"facet normal {nrm}", "outer loop"]
        lines += ["vertex " + " ".join(f"{x:.17g}" for x in p) for p in tri]
        lines += ["endloop", "endfacet"]
    lines.append(f"endsolid {name}")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def wall_commands(planes, group, model, keywords):
    """The deck's ``fix mesh/surface`` (files wall_K.stl) and ``fix wall/gran`` lines: `model` as the pair
    style's (e.g. "hooke/stiffness tangential history"), its `keywords` after the meshes."""
    if not planes:
        return []
    ids = [f"jw{k + 1}" for k in range(len(planes))]
    out = [f"fix {m} all mesh/surface file wall_{k + 1}.stl type {WALL_TYPE}" for k, m in enumerate(ids)]
    out.append(f"fix jwalls {group} wall/gran model {model} mesh n_meshes {len(ids)} meshes {' '.join(ids)} "
               f"{keywords}".rstrip())
    return out


def all_walled(run):
    """True when the deck has walls and no joint pair joins two free spheres: no joint pair that moves is left
    as a sphere contact (pairs of two fixed spheres never move)."""
    fixed = np.asarray(run.fixed, bool)
    return joint_walls(run) and not bool(np.any(~fixed[run.joint_i] & ~fixed[run.joint_j]))


def exclusions():
    """``neigh_modify exclude type`` pairs: the dropped spheres' type with every sphere type."""
    return [(DROPPED_TYPE, t) for t in range(1, DROPPED_TYPE + 1)]


def wall_notes(run, planes=None):
    """extra.approximations of a deck with joint walls."""
    planes = wall_planes(run) if planes is None else planes
    if not planes:
        return []
    gone = int(dropped(run, planes).sum())
    fixed = np.asarray(run.fixed, bool)
    mixed = int(np.sum(fixed[run.joint_i] != fixed[run.joint_j]))
    return [f"liggghts_joint_walls: the fixed side of {len(planes)} joint(s) is a plane mesh wall (fix "
            f"mesh/surface + wall/gran, friction spheres.joint_friction = {run.joint_friction_deg:g} deg) touching "
            f"the nearest free sphere of its {mixed} fixed-free joint pairs; the {gone} fixed spheres behind the "
            "walls take part in no contact. The wall is a flat surface where the smooth joint is a plane between "
            "sphere pairs: " + ("every free sphere of those pairs touches it (liggghts_wall_radii: contact radius "
                                "= its centre's distance to the nearest wall, masses kept)"
                                if flag(run, "liggghts_wall_radii") else
                                "the free side rests on its lowest spheres (those nearest the plane), not on every "
                                "joint pair")]


__all__ = ["flag", "PLANAR_DEG", "DROPPED_TYPE", "WALL_TYPE", "WALL_TYPES", "joint_walls", "wall_planes", "dropped", "wall_triangles",
           "write_stl", "wall_commands", "all_walled", "wall_radii", "exclusions", "wall_notes"]
