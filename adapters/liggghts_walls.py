"""LIGGGHTS decks with rigid-side joints as mesh walls (run.extra ``joint_walls``, adapters/joint_walls.py).

LIGGGHTS-PUBLIC has no smooth joint: a joint between moving spheres and fixed rock written as sphere contacts
is the fixed spheres' bumpy surface, on which a sliding block interlocks. Where one side of a joint is fixed
rock (a wedge, planar sliding, a block on an incline), the usual LIGGGHTS model of a fixed sliding surface is
a triangulated wall: ``fix mesh/surface`` from an STL file with an atom type of its own, and ``fix wall/gran``
with the sphere-wall friction of that type in the ``coefficientFriction peratomtypepair`` matrix.

The walls' geometry is adapters/joint_walls.py's (one plane per walled joint side, touching the nearest free
sphere of its pairs; the rock behind it; in mode "pairs" the grown contact radii of the clumps variant). Here:

- the fixed spheres the walls stand for stay in the data file (the runner's atom ids) with atom type
  DROPPED_TYPE, which every ``neigh_modify exclude type`` keeps out of every contact, and are never integrated;
- each wall is its rectangle as two triangles (wall_K.stl), atom type WALL_TYPE, whose friction with every
  sphere type is run.joint_friction_deg, stiffness run.kn / run.ks and normal damping with the sphere's own
  mass (as a fixed partner).

``wall_notes`` are the deck's approximations (RunResult.extra["approximations"]).
"""
from __future__ import annotations

import numpy as np

from .joint_walls import (PLANAR_DEG, all_walled, dropped, flag, joint_walls, mode, notes, wall_planes,
                          wall_radii, wall_triangles)

DROPPED_TYPE, WALL_TYPE = 9, 10  # after the 8 sphere types of adapters/liggghts_deck.py (colour x fixed)
WALL_TYPES = 10


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


def exclusions():
    """``neigh_modify exclude type`` pairs: the dropped spheres' type with every sphere type."""
    return [(DROPPED_TYPE, t) for t in range(1, DROPPED_TYPE + 1)]


def wall_notes(run, planes=None):
    """extra.approximations of a deck with joint walls."""
    return notes(run, "a plane mesh wall (fix mesh/surface + wall/gran)", planes)


__all__ = ["flag", "mode", "PLANAR_DEG", "DROPPED_TYPE", "WALL_TYPE", "WALL_TYPES", "joint_walls", "wall_planes",
           "dropped", "wall_triangles", "write_stl", "wall_commands", "all_walled", "wall_radii", "exclusions",
           "wall_notes"]
