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
    cand = near_spheres(mesh, centres, grid, band)
    sd, face, bnd = mesh.signed_closest(centres[cand], max_dist=band)
    lim = thickness / 2.0 if thickness > 0 else 2.0 * radii[cand]
    ok = np.isfinite(sd) & ~bnd & (np.abs(sd) <= lim)
    s, off = cand[ok], sd[ok]
    if thickness > 0:
        kind = np.full(len(s), _cut.KIND_INSIDE, np.int8)
    else:
        kind = np.where(off <= 0.0, _cut.KIND_GREEN, _cut.KIND_BLUE).astype(np.int8)
    return s, kind, off


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
                        CROSS_EPS)
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
