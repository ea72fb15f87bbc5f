"""Numba kernels for triangulated discontinuities: spheres near a surface, bonds crossing it."""
from __future__ import annotations

import math

from numba import njit, prange

from ._meshq import ray_hits


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


@njit(cache=True, parallel=True)
def crossing_cuts(D, cand, c, bond_start, bonds, by, index, eps):
    """Geometric rule for one surface joint: a bond (i, j) of a candidate sphere i that is not
    cut yet is cut by ``index`` when the segment between the centres crosses the surface."""
    for q in prange(cand.shape[0]):
        i = cand[q]
        for b in range(bond_start[i], bond_start[i + 1]):
            if by[b] >= 0:
                continue
            j = bonds[b, 1]
            dx, dy, dz = c[j, 0] - c[i, 0], c[j, 1] - c[i, 1], c[j, 2] - c[i, 2]
            if ray_hits(D, 0, c[i, 0], c[i, 1], c[i, 2], dx, dy, dz, 1.0, eps, True)[1] >= 0:
                by[b] = index
