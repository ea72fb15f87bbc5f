"""Curved and triangulated discontinuities (``[[discontinuity]]`` with a mesh or a shape).

They join the discs in the membership table (sphere, discontinuity, kind, signed offset)
with indices after every disc, so colours and both bond rules of sgim/cutting.py apply
unchanged:

- offset = signed distance of the sphere centre to the surface (pseudo-normal sign, the
  surface's normals pointing upward on average): the analogue of S.(O - M);
- a sphere is a member only when its closest point on the surface is not on the surface's
  boundary (its foot falls on the surface): the analogue of the disc radius (eq. 13);
- fault (thickness t > 0): red when |offset| <= t / 2 (eq. 14);
- joint: within 2r, green where offset <= 0 (S.(M - O) >= 0), blue otherwise (eq. 15-16);
- geometric bond rule: a pair is cut when the segment between the centres crosses the
  surface (discs first: the lowest discontinuity index cuts).

Ties take the discs' tie allowance (sgim/_cut.py), with the largest |V|_1 of the surface's vertices for
|M|_1: a centre within it of the surface lies on it (offset 0, green), one within it of the 2r band or the
t/2 slab is inside, one whose closest point lies within it of the surface's boundary has its foot on the
boundary (not a member), and a bond with one end on the surface is cut when the other end is blue.
"""
from __future__ import annotations

import numpy as np

from . import _cut
from . import _surfdisc as K
from .cutting import Membership

CROSS_EPS = 1e-9  # barycentric slack of the segment-triangle test (shared edges count)


def near_spheres(mesh, centres, grid, band):
    """Indices of the spheres whose centre lies in some face's box padded by band."""
    mark = np.zeros(len(centres), np.uint8)
    if len(centres):
        K.mark_near(mesh.kernel_data(), centres, *grid.args(), float(band), mark)
    return np.nonzero(mark)[0]


def surface_members(mesh, thickness, centres, radii, grid):
    """(sphere, kind, offset) of the members of one surface discontinuity, by sphere."""
    band = thickness / 2.0 if thickness > 0 else 2.0 * float(radii.max())
    vscale = _vertex_scale(mesh)
    pad = _cut.ROUND * (float(np.abs(centres).sum(1).max()) + vscale) if len(centres) else 0.0
    cand = near_spheres(mesh, centres, grid, band + 2.0 * pad)
    pts = np.ascontiguousarray(centres[cand])
    sd, face, bnd = mesh.signed_closest(pts, max_dist=band + 2.0 * pad)
    tie = _cut.ROUND * (np.abs(pts).sum(1) + vscale)  # the tie allowance (sgim/_cut.py)
    K.boundary_ties(mesh.kernel_data(), pts, face, tie, bnd)
    sd = np.where(np.abs(sd) <= tie, 0.0, sd)  # on the surface
    lim = thickness / 2.0 if thickness > 0 else 2.0 * radii[cand]
    ok = np.isfinite(sd) & ~bnd & (np.abs(sd) <= lim + tie)
    s, off = cand[ok], sd[ok]
    if thickness > 0:
        kind = np.full(len(s), _cut.KIND_INSIDE, np.int8)
    else:
        kind = np.where(off <= 0.0, _cut.KIND_GREEN, _cut.KIND_BLUE).astype(np.int8)
    return s, kind, off


def _vertex_scale(mesh):
    """The largest |x| + |y| + |z| of the surface's vertices (the |M|_1 of its tie allowance)."""
    return float(np.abs(mesh.vertices).sum(1).max()) if len(mesh.vertices) else 0.0


def membership_with_surfaces(mem: Membership, surfaces, first_index, centres, radii, grid) -> Membership:
    """The disc membership table extended by the rows of the surface discontinuities."""
    if not surfaces or len(centres) == 0:
        return mem
    S, D, Kd, O = [mem.sphere], [mem.disc], [mem.kind], [mem.offset]
    for j, surf in enumerate(surfaces):
        s, k, o = surface_members(surf.mesh, surf.thickness, centres, radii, grid)
        S.append(s.astype(np.int64))
        D.append(np.full(len(s), first_index + j, np.int32))
        Kd.append(k)
        O.append(o)
    return Membership(np.concatenate(S), np.concatenate(D), np.concatenate(Kd), np.concatenate(O))


def surface_geometric_cuts(cut_by, surfaces, first_index, centres, radii, grid, bonds, bond_start, tol):
    """Add the cuts of the surface joints to ``cut_by`` of the geometric rule (in place; returned)."""
    if not surfaces or len(bonds) == 0:
        return cut_by
    lmax = 2.0 * float(radii.max()) * (1.0 + tol)
    c = np.ascontiguousarray(centres)
    for j, surf in enumerate(surfaces):
        if surf.thickness > 0:
            continue  # faults cut through their red spheres
        cand = near_spheres(surf.mesh, c, grid, lmax)
        K.crossing_cuts(surf.mesh.kernel_data(), cand, c, bond_start, bonds, cut_by, np.int32(first_index + j),
                        CROSS_EPS, _vertex_scale(surf.mesh), lmax)
    return cut_by


def surface_arrays(surfaces, first_index):
    """model.npz arrays describing the surface discontinuities (see sgim/model.py)."""
    vs, fs, vstart, fstart = [], [], [0], [0]
    for s in surfaces:
        fs.append(s.mesh.faces + vstart[-1])
        vs.append(s.mesh.vertices)
        vstart.append(vstart[-1] + len(s.mesh.vertices))
        fstart.append(fstart[-1] + len(s.mesh.faces))
    kind = np.concatenate([np.zeros(first_index, np.int8), np.ones(len(surfaces), np.int8)])
    return {
        "discontinuity_kind": kind,
        "surf_index": np.arange(first_index, first_index + len(surfaces), dtype=np.int32),
        "surf_name": [s.name for s in surfaces],
        "surf_thickness": np.array([s.thickness for s in surfaces], float),
        "surf_vertices": np.concatenate(vs) if vs else np.zeros((0, 3)),
        "surf_faces": np.concatenate(fs).astype(np.int64) if fs else np.zeros((0, 3), np.int64),
        "surf_vertex_start": np.array(vstart, np.int64),
        "surf_face_start": np.array(fstart, np.int64),
    }
