"""Rigid-side joints as walls, for every engine (run.extra ``joint_walls`` = "nearest" or "pairs").

Where one side of a joint is fixed rock (a wedge, planar sliding, a block on an incline), a deck can write that
side as a wall with the joint's friction instead of fixed spheres: LIGGGHTS as a mesh wall (adapters/
liggghts_walls.py), YADE as a facet (adapters/yade.py), the in-house engine as a fixed convex slab
(adapters/inhouse.py). This module holds the one geometry they share; each engine writes it its own way.

The option: run.extra ``joint_walls`` (``adapters export --joint-walls``): "nearest" (each wall touches the
nearest free sphere of its joint's pairs), "pairs" (also every free sphere of those pairs gets a contact radius
reaching the wall: LIGGGHTS' clumps variant only), absent / false (no walls). The older LIGGGHTS spelling,
``liggghts_joint_walls`` = true with ``liggghts_wall_radii`` = true for "pairs", is read the same way.

With walls and smooth joints (without them joint pairs are plain contacts in every engine), for every joint
(joint_disc) that has pairs of one fixed and one free sphere (``wall_planes``):

- the wall's normal is the mean joint normal of those pairs, signed to point from the fixed to the free side;
- the wall plane n.x = d touches the nearest free sphere of those pairs (d = min over them of n.c - r: the
  sphere surface touching the joint plane);
- the fixed spheres on the fixed side of a walled joint (n.c no more than that of the pairs' fixed spheres) are
  the rock the wall stands for (``dropped``): they take part in no contact; a bond from one of them to a free
  sphere is refused (the joint does not separate that rock from the moving side);
- the wall covers the projection of the dropped spheres behind it, enlarged by their largest radius
  (``wall_rectangles``: four corners counter-clockwise about the normal).

Plain numpy on a SphereRun: the deck writers, the in-house runner and the tests read it.
"""
from __future__ import annotations

import numpy as np

from .spec import SpecError

MODES = ("nearest", "pairs")
PLANAR_DEG = 1e-3  # a walled joint's pair normals may differ from their mean by this much [deg]


def _name(run):
    return run.source or run.name


def flag(run, key):
    """run.extra[key] as a bool (absent: False); SpecError naming the key and value unless true or false."""
    value = run.extra.get(key, False)
    if value is True or value is False or (isinstance(value, int) and value in (0, 1)):
        return bool(value)
    raise SpecError(f"{_name(run)}: run.extra {key} = {value!r}: expected true or false")


def mode(run):
    """(mode, key): "nearest", "pairs" or None (no walls), and the run.extra key that set it (``joint_walls``, or
    the older ``liggghts_joint_walls`` / ``liggghts_wall_radii``). SpecError in one line for a bad value."""
    if "joint_walls" in run.extra:
        value = run.extra["joint_walls"]
        if value is False or value is None:
            return None, "joint_walls"
        if value is True:
            return "nearest", "joint_walls"
        if value not in MODES:
            raise SpecError(f"{_name(run)}: run.extra joint_walls = {value!r}: expected one of "
                            f"{', '.join(MODES)} (or false)")
        return value, "joint_walls"
    if not flag(run, "liggghts_joint_walls"):
        return None, "liggghts_joint_walls"
    if flag(run, "liggghts_wall_radii"):
        return "pairs", "liggghts_wall_radii"
    return "nearest", "liggghts_joint_walls"


def joint_walls(run):
    """True when the deck writes the rigid sides of joints as walls (``mode``) and some joint pair joins a fixed
    and a free sphere with smooth joints."""
    if mode(run)[0] is None or not len(run.joint_i) or not run.smooth_joints:
        return False
    fixed = np.asarray(run.fixed, bool)
    return bool(np.any(fixed[run.joint_i] != fixed[run.joint_j]))


def basis(n):
    """Two unit vectors (u, v) spanning the plane of the unit normal n, (u, v, n) right-handed."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def wall_planes(run):
    """One dict per walled joint side: disc (joint_disc), normal (3,) from the fixed to the free side, offset d
    (the plane n.x = d), back (the largest n.c of the pairs' fixed spheres: the fixed spheres with n.c <= back
    are the rock the wall stands for), pairs (number of fixed-free joint pairs). A joint with fixed rock on both
    of its sides in places gets a wall for each side. [] when the deck has no walls; SpecError for a joint that
    is not planar (its pairs' normals differ by more than PLANAR_DEG: a wall is one plane) and for rock behind
    a wall that a bond ties to a free sphere."""
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
                raise SpecError(f"{_name(run)}: run.extra {mode(run)[1]}: joint {int(disc)} is not planar (its "
                                f"pairs' normals differ by up to {spread:.3g} deg from their mean): a wall is one "
                                "plane")
            free, rock = np.where(fixed[i[k]], j[k], i[k]), np.where(fixed[i[k]], i[k], j[k])
            out.append(dict(disc=int(disc), normal=n, offset=float(np.min(c[free] @ n - r[free])),
                            back=float(np.max(c[rock] @ n)), pairs=int(len(k))))
    gone = dropped(run, out)
    tied = gone[run.bond_i] & ~fixed[run.bond_j] | gone[run.bond_j] & ~fixed[run.bond_i]
    if tied.any():
        raise SpecError(f"{_name(run)}: run.extra {mode(run)[1]}: {int(tied.sum())} bond(s) tie free spheres to "
                        "the fixed rock behind a joint wall (the first: spheres "
                        f"{int(run.bond_i[tied][0])}-{int(run.bond_j[tied][0])}); the wall stands for that rock")
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


def wall_rectangles(run, planes=None):
    """(walls, 4, 3): each wall's corners, counter-clockwise about its normal: the rectangle in its plane over
    the projection of the dropped spheres behind it, enlarged by their largest radius."""
    planes = wall_planes(run) if planes is None else planes
    gone = dropped(run, planes)
    c, r = np.asarray(run.centers, float), np.asarray(run.radii, float)
    out = np.zeros((len(planes), 4, 3))
    for w, p in enumerate(planes):
        n, d = p["normal"], p["offset"]
        behind = gone & (c @ n <= p["back"])
        u, v = basis(n)
        pu, pv = c[behind] @ u, c[behind] @ v
        grow = float(r[behind].max())
        (u0, u1), (v0, v1) = (pu.min() - grow, pu.max() + grow), (pv.min() - grow, pv.max() + grow)
        out[w] = [d * n + a * u + b * v for a, b in ((u0, v0), (u1, v0), (u1, v1), (u0, v1))]
    return out


def wall_triangles(run, planes=None):
    """(walls, 2, 3, 3): each wall rectangle as two triangles (vertices counter-clockwise about its normal)."""
    q = wall_rectangles(run, planes)
    return np.stack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=1)


def wall_radii(run, planes=None):
    """(n,) contact radii of mode "pairs": every free sphere of a walled joint's pairs touches the walls (its
    radius is the least distance from its centre to a wall plane it lies in front of), as every pair of a smooth
    joint is in contact at its own reference gap; the other spheres keep theirs. With "nearest" the free side
    rests on its lowest spheres alone (on the r = 0.5 wedge, two per wall: a rigid body on four points cannot
    slide without turning, so it slid at 0.66 % above Hoek & Bray's angle in LIGGGHTS)."""
    planes = wall_planes(run) if planes is None else planes
    r = np.asarray(run.radii, float).copy()
    if not planes or mode(run)[0] != "pairs":
        return r
    fixed = np.asarray(run.fixed, bool)
    i, j = np.asarray(run.joint_i), np.asarray(run.joint_j)
    mixed = (fixed[i] != fixed[j]) & np.isin(run.joint_disc, [p["disc"] for p in planes])
    free = np.unique(np.where(fixed[i[mixed]], j[mixed], i[mixed]))
    c = np.asarray(run.centers, float)[free]
    h = np.array([c @ p["normal"] - p["offset"] for p in planes])
    r[free] = np.min(np.where(h > 0.0, h, np.inf), axis=0)  # in front of its own wall at least (h >= r there)
    return r


def all_walled(run):
    """True when the deck has walls and no joint pair joins two free spheres: no joint pair that moves is left
    as a sphere contact (pairs of two fixed spheres never move)."""
    fixed = np.asarray(run.fixed, bool)
    return joint_walls(run) and not bool(np.any(~fixed[run.joint_i] & ~fixed[run.joint_j]))


def only_nearest(run, engine):
    """SpecError unless the run's walls are of mode "nearest" (or none): `engine` keeps sphere radii."""
    how, key = mode(run)
    if how == "pairs" and joint_walls(run):
        raise SpecError(f"{_name(run)}: run.extra {key}: \"pairs\" grows contact radii, which only a rigid body "
                        f"takes (LIGGGHTS' clumps variant); {engine} takes joint walls = \"nearest\"")


def notes(run, how, planes=None):
    """extra.approximations of a deck with joint walls written as `how` (the engine's words for a wall)."""
    planes = wall_planes(run) if planes is None else planes
    if not planes:
        return []
    gone = int(dropped(run, planes).sum())
    fixed = np.asarray(run.fixed, bool)
    mixed = int(np.sum(fixed[run.joint_i] != fixed[run.joint_j]))
    radii = mode(run)[0] == "pairs"
    return [f"{mode(run)[1]}: the fixed side of {len(planes)} joint(s) is {how}, with friction "
            f"spheres.joint_friction = {run.joint_friction_deg:g} deg and no cohesion, touching the nearest free sphere "
            f"of its {mixed} fixed-free joint pairs; the {gone} fixed spheres behind the walls take part in no contact. The wall is a flat "
            "surface where the smooth joint is a plane between sphere pairs: "
            + ("every free sphere of those pairs touches it (contact radius = its centre's distance to the nearest "
               "wall, masses kept)" if radii else
               "the free side rests on its lowest spheres (those nearest the plane), not on every joint pair")]


__all__ = ["MODES", "PLANAR_DEG", "flag", "mode", "joint_walls", "basis", "wall_planes", "dropped",
           "wall_rectangles", "wall_triangles", "wall_radii", "all_walled", "only_nearest", "notes"]
