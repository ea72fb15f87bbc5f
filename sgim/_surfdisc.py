"""Numba kernels for triangulated discontinuities: spheres near a surface, bonds crossing it."""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._excavate import ROUND
from ._meshq import closest_on_tri, ray_hits, signed_point


@njit(cache=True, inline="always")
def _cells(lo, hi, g0, cs, dims, a):
    i0 = min(max(int(math.floor((lo - g0[a]) / cs)), 0), dims[a] - 1)
    i1 = min(max(int(math.floor((hi - g0[a]) / cs)), 0), dims[a] - 1)
    return i0, i1


@njit(cache=True, parallel=True)
def mark_near(D, c, start, order, g0, cs, dims, band, mark):
    """mark[i] = 1 for every sphere centre inside some face's bounding box padded by band.

    Work follows the surface: each face visits the grid cells of its padded box only.
    (Concurrent faces may write the same 1 to one entry.)
    """
    tv = D[4]
    for f in prange(tv.shape[0]):
        t = tv[f]
        lx = min(t[0], t[3], t[6]) - band
        hx = max(t[0], t[3], t[6]) + band
        ly = min(t[1], t[4], t[7]) - band
        hy = max(t[1], t[4], t[7]) + band
        lz = min(t[2], t[5], t[8]) - band
        hz = max(t[2], t[5], t[8]) + band
        x0, x1 = _cells(lx, hx, g0, cs, dims, 0)
        y0, y1 = _cells(ly, hy, g0, cs, dims, 1)
        z0, z1 = _cells(lz, hz, g0, cs, dims, 2)
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    cell = (iz * dims[1] + iy) * dims[0] + ix
                    for q in range(start[cell], start[cell + 1]):
                        i = order[q]
                        if lx <= c[i, 0] <= hx and ly <= c[i, 1] <= hy and lz <= c[i, 2] <= hz:
                            mark[i] = 1


@njit(cache=True, inline="always")
def _seg_d2(qx, qy, qz, t, a, b):
    """Squared distance from q to the segment between vertices a and b of triangle t (9 floats)."""
    ax, ay, az = t[3 * a], t[3 * a + 1], t[3 * a + 2]
    ux, uy, uz = t[3 * b] - ax, t[3 * b + 1] - ay, t[3 * b + 2] - az
    wx, wy, wz = qx - ax, qy - ay, qz - az
    uu = ux * ux + uy * uy + uz * uz
    s = (wx * ux + wy * uy + wz * uz) / uu if uu > 0.0 else 0.0
    s = min(max(s, 0.0), 1.0)
    dx, dy, dz = wx - s * ux, wy - s * uy, wz - s * uz
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, parallel=True)
def boundary_ties(D, pts, face, tie, bnd):
    """bnd[i] = True also where the closest point of pts[i] (on face[i]) lies within tie[i] of the surface's
    boundary (a boundary edge or vertex of that face): the foot is then on the boundary, whichever Voronoi
    region rounding gave it."""
    tv, fedge, fvert, ebnd, vbnd = D[4], D[6], D[7], D[10], D[11]
    for i in prange(pts.shape[0]):
        f = face[i]
        if f < 0 or bnd[i]:
            continue
        t = tv[f]
        qx, qy, qz, _ = closest_on_tri(pts[i, 0], pts[i, 1], pts[i, 2], t)
        t2 = tie[i] * tie[i]
        for e in range(3):  # edge e runs from vertex e to vertex e + 1
            if vbnd[fvert[f, e]] != 0:
                dx, dy, dz = qx - t[3 * e], qy - t[3 * e + 1], qz - t[3 * e + 2]
                if dx * dx + dy * dy + dz * dz <= t2:
                    bnd[i] = True
            if ebnd[fedge[f, e]] != 0 and _seg_d2(qx, qy, qz, t, e, (e + 1) % 3) <= t2:
                bnd[i] = True


@njit(cache=True, inline="always")
def _tie(c, i, vscale):
    return ROUND * (abs(c[i, 0]) + abs(c[i, 1]) + abs(c[i, 2]) + vscale)


@njit(cache=True, parallel=True)
def crossing_cuts(D, cand, c, bond_start, bonds, by, index, eps, vscale, lmax):
    """Geometric rule for one surface joint: a bond (i, j) of a candidate sphere i that is not
    cut yet is cut by ``index`` when the segment between the centres crosses the surface.

    An end within the tie allowance of the surface lies on it, on the green side (offset <= 0): its bond is
    cut when the other end is on the blue side (offset > its allowance), not when both ends are on the
    surface; rounding does not decide whether the segment touches the surface there."""
    for q in prange(cand.shape[0]):
        i = cand[q]
        ti = _tie(c, i, vscale)
        on_i = signed_point(D, 0, c[i, 0], c[i, 1], c[i, 2], ti)[0] < np.inf
        for b in range(bond_start[i], bond_start[i + 1]):
            if by[b] >= 0:
                continue
            j = bonds[b, 1]
            tj = _tie(c, j, vscale)
            on_j = signed_point(D, 0, c[j, 0], c[j, 1], c[j, 2], tj)[0] < np.inf
            if on_i or on_j:
                if on_i and on_j:
                    continue
                o, to = (j, tj) if on_i else (i, ti)
                so = signed_point(D, 0, c[o, 0], c[o, 1], c[o, 2], 2.0 * lmax)[0]
                if to < so < np.inf:  # the other end is blue
                    by[b] = index
                continue
            dx, dy, dz = c[j, 0] - c[i, 0], c[j, 1] - c[i, 1], c[j, 2] - c[i, 2]
            if ray_hits(D, 0, c[i, 0], c[i, 1], c[i, 2], dx, dy, dz, 1.0, eps, True)[1] >= 0:
                by[b] = index
