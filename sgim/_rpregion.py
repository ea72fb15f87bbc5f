"""Numba kernels of the random packer's region (box, constraint meshes, excavation "above" test) and
of the grading law's distance to named objects (see sgim/_rpack.py, sgim/grading.py)."""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from . import _excavate as EX
from . import _meshq as MQ

# the excavation above-test: facet records, per plan cell the first of its facets (cstart) and the facets
# (cfac), the plan grid's origin, cell size and cells (gnx = 0: no excavation)
Exc = namedtuple("Exc", "ec cstart cfac g0x g0y gs gnx gny")


# ---------------------------------------------------------------------------
# region: box, constraint meshes, excavation "above" test

@njit(cache=True, inline="always")
def in_box(lo, hi, px, py, pz, r, tol):
    a = tol * r
    return (lo[0] + r - a <= px <= hi[0] - r + a and lo[1] + r - a <= py <= hi[1] - r + a
            and lo[2] + r - a <= pz <= hi[2] - r + a)


@njit(cache=True)
def mesh_clear(Dc, px, py, pz, r, tol):
    """-1 when (P, r) keeps at least r (1 - tol) from every constraint mesh, else the mesh index."""
    lim = r * (1.0 - tol)
    for k in range(Dc[12].shape[0]):
        if not MQ.in_root_box(Dc, k, px, py, pz, lim):
            continue
        d2 = MQ.closest_point(Dc, k, px, py, pz, lim * lim)[0]
        if d2 < lim * lim:
            return k
    return -1


@njit(cache=True)
def above_excavation(exc, px, py, pz):
    """Is P on or above an excavation facet (exc: Exc) in vertical projection (the exact rule's space)?"""
    ec, cstart, cfac, g0x, g0y, gs, gnx, gny = exc
    if gnx == 0:
        return False
    ix = min(max(int(math.floor((px - g0x) / gs)), 0), gnx - 1)
    iy = min(max(int(math.floor((py - g0y) / gs)), 0), gny - 1)
    c = iy * gnx + ix
    for q in range(cstart[c], cstart[c + 1]):
        if EX.exact_above(ec, cfac[q], px, py, pz):
            return True
    return False


# ---------------------------------------------------------------------------
# grading law (the radius as a function of the distance to named objects)

@njit(cache=True, inline="always")
def grade_radius(d, rf, rc, df, dc):
    """Fine radius rf up to distance df, coarse rc beyond dc, geometric interpolation with a
    smoothstep weight s = t^2 (3 - 2t), t = (d - df) / (dc - df), in between."""
    if d <= df:
        return rf
    if d >= dc:
        return rc
    t = (d - df) / (dc - df)
    s = t * t * (3.0 - 2.0 * t)
    return rf * math.exp(s * math.log(rc / rf))


@njit(cache=True)
def disc_distance(cx, cy, cz, nx, ny, nz, R, px, py, pz):
    """Distance from P to a disc (centre c, unit normal n, radius R)."""
    wx, wy, wz = px - cx, py - cy, pz - cz
    h = wx * nx + wy * ny + wz * nz
    qx, qy, qz = wx - h * nx, wy - h * ny, wz - h * nz
    rho = math.sqrt(qx * qx + qy * qy + qz * qz)
    if rho <= R:
        return abs(h)
    return math.sqrt(h * h + (rho - R) ** 2)


@njit(cache=True)
def near_distance(Dg, goff, dcen, dnrm, drad, dhalf, px, py, pz, dmax):
    """Distance from P to the nearest named object (meshes of Dg less goff[k], discs less their
    half thickness), at least 0; dmax when nothing is nearer than dmax."""
    best = dmax
    for k in range(Dg[12].shape[0]):
        lim = best + goff[k]
        if not MQ.in_root_box(Dg, k, px, py, pz, lim):
            continue
        d2 = MQ.closest_point(Dg, k, px, py, pz, lim * lim)[0]
        if d2 < lim * lim:
            best = min(best, max(math.sqrt(d2) - goff[k], 0.0))
    for k in range(dcen.shape[0]):
        d = disc_distance(dcen[k, 0], dcen[k, 1], dcen[k, 2], dnrm[k, 0], dnrm[k, 1], dnrm[k, 2], drad[k],
                          px, py, pz) - dhalf[k]
        if d < best:
            best = max(d, 0.0)
    return best


@njit(cache=True, parallel=True)
def near_distance_many(Dg, goff, dcen, dnrm, drad, dhalf, pts, dmax):
    out = np.empty(pts.shape[0])
    for i in prange(pts.shape[0]):
        out[i] = near_distance(Dg, goff, dcen, dnrm, drad, dhalf, pts[i, 0], pts[i, 1], pts[i, 2], dmax)
    return out


@njit(cache=True)
def region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, exc):
    """The constraint meshes and the excavation test."""
    if has_mesh and mesh_clear(Dc, qx, qy, qz, rn, tol) >= 0:
        return False
    if exc.gnx > 0 and above_excavation(exc, qx, qy, qz):
        return False
    return True


@njit(cache=True)
def region_contains(lo, hi, Dc, exc, role, px, py, pz):
    """Is the point in the region: the box, not above an excavation (exact rule), outside every
    cavity (role 1) and inside the fill shape (role 2); excavation meshes (role 0) bound only
    spheres of positive radius."""
    if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1] and lo[2] <= pz <= hi[2]):
        return False
    if exc.gnx > 0 and above_excavation(exc, px, py, pz):
        return False
    for k in range(role.shape[0]):
        if role[k] == 1 and MQ.in_root_box(Dc, k, px, py, pz, 0.0) and MQ.inside_point(Dc, k, px, py, pz):
            return False
        if role[k] == 2 and not (MQ.in_root_box(Dc, k, px, py, pz, 0.0) and MQ.inside_point(Dc, k, px, py, pz)):
            return False
    return True


@njit(cache=True, parallel=True)
def mesh_distance_many(Dc, pts, maxd):
    """Distance from each point to the nearest mesh of Dc (inf beyond maxd[i])."""
    out = np.full(pts.shape[0], np.inf)
    for i in prange(pts.shape[0]):
        m2 = maxd[i] * maxd[i]
        for k in range(Dc[12].shape[0]):
            if not MQ.in_root_box(Dc, k, pts[i, 0], pts[i, 1], pts[i, 2], maxd[i]):
                continue
            d2 = MQ.closest_point(Dc, k, pts[i, 0], pts[i, 1], pts[i, 2], m2)[0]
            if d2 < m2:
                m2 = d2
                out[i] = math.sqrt(d2)
    return out
