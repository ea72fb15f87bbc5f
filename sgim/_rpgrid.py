"""Numba kernels of the random packer's multi-level grid of linked lists (see sgim/_rpack.py).

Level k holds radii in [r0 2^k, r0 2^(k+1)) in cells 2 x the level's largest radius, with block counts
(BLOCK^3 cells) so that a large query over a fine level skips empty space.  One walk (cell_range: the
cells within reach on each level; block_cells: the cells of one block, none when it is empty) serves
every query: the packer's gather and overlap test, the contact pairs,
the overlap statistics and the clearance probes (sgim/_rpprobe.py).
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

BLOCK = 4  # cells per block side (block counts of the level grid)

# grid geometry, one row per level: origin (L,3), cell size (L,), cells (L,3), first cell of each level
# (L+1,), smallest and largest radius (L,), blocks (L,3), first block of each level (L+1,)
Grid = namedtuple("Grid", "org cs dims coff rlo rmax bdims boff")


# ---------------------------------------------------------------------------
# multi-level grid of linked lists
#
# G (Grid): org (L,3), cs (L,), dims (L,3), coff (L+1,), rlo (L,), rmax (L,), bdims (L,3), boff (L+1,)
# head (coff[L],) int32: newest sphere of each cell (-1 empty); nxt (n,) int32: next older sphere
# bcnt (boff[L],) int32: spheres per block of BLOCK^3 cells

@njit(cache=True, inline="always")
def level_of(rlo, r):
    k = rlo.shape[0] - 1
    while k > 0 and r < rlo[k]:
        k -= 1
    return k


@njit(cache=True, inline="always")
def _cidx(org, cs, dims, k, a, v):
    return min(max(int(math.floor((v - org[k, a]) / cs[k])), 0), dims[k, a] - 1)


@njit(cache=True, inline="always")
def cell_range(G, k, px, py, pz, ext):
    """The cells of level k within ext of P along each axis: x0, x1, y0, y1, z0, z1 (inclusive)."""
    org, cs, dims = G.org, G.cs, G.dims
    return (_cidx(org, cs, dims, k, 0, px - ext), _cidx(org, cs, dims, k, 0, px + ext),
            _cidx(org, cs, dims, k, 1, py - ext), _cidx(org, cs, dims, k, 1, py + ext),
            _cidx(org, cs, dims, k, 2, pz - ext), _cidx(org, cs, dims, k, 2, pz + ext))


@njit(cache=True, inline="always")
def block_cells(G, bcnt, k, bx, by, bz, x0, x1, y0, y1, z0, z1):
    """The cells x0..x1, y0..y1, z0..z1 of level k that lie in block (bx, by, bz), as range bounds
    (iz0, iz1, iy0, iy1, ix0, ix1); empty ranges when the block holds no sphere."""
    if bcnt[G.boff[k] + (bz * G.bdims[k, 1] + by) * G.bdims[k, 0] + bx] == 0:
        return 0, 0, 0, 0, 0, 0
    return (max(z0, bz * BLOCK), min(z1, bz * BLOCK + BLOCK - 1) + 1, max(y0, by * BLOCK),
            min(y1, by * BLOCK + BLOCK - 1) + 1, max(x0, bx * BLOCK), min(x1, bx * BLOCK + BLOCK - 1) + 1)


@njit(cache=True, error_model="numpy")
def grid_insert(G, head, nxt, bcnt, i, x, y, z, r):
    org, cs, dims, coff, rlo, rmax, bdims, boff = G
    k = level_of(rlo, r)
    ix = _cidx(org, cs, dims, k, 0, x)
    iy = _cidx(org, cs, dims, k, 1, y)
    iz = _cidx(org, cs, dims, k, 2, z)
    c = coff[k] + (iz * dims[k, 1] + iy) * dims[k, 0] + ix
    nxt[i] = head[c]
    head[c] = i
    b = boff[k] + ((iz // BLOCK) * bdims[k, 1] + iy // BLOCK) * bdims[k, 0] + ix // BLOCK
    bcnt[b] += 1


@njit(cache=True, error_model="numpy")
def grid_gather(G, head, nxt, bcnt, XR, px, py, pz, reach, out, cap, skip):
    """Spheres j != skip with |P - x_j| < reach + r_j, written to out; returns the count (<= cap).
    XR (n,4): centre and radius of each sphere side by side (32 bytes a sphere: one cache line or less)."""
    org, cs, dims, coff, rmax = G.org, G.cs, G.dims, G.coff, G.rmax
    m = 0
    for k in range(org.shape[0]):
        ext = reach + rmax[k]
        x0, x1, y0, y1, z0, z1 = cell_range(G, k, px, py, pz, ext)
        nxk, nyk = dims[k, 0], dims[k, 1]
        if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) <= 216:
            ck = cs[k]
            e2 = ext * ext
            for iz in range(z0, z1 + 1):
                cz0 = org[k, 2] + iz * ck
                gz = max(cz0 - pz, pz - cz0 - ck, 0.0)
                if gz * gz > e2:
                    continue
                for iy in range(y0, y1 + 1):
                    cy0 = org[k, 1] + iy * ck
                    gy = max(cy0 - py, py - cy0 - ck, 0.0)
                    gyz = gz * gz + gy * gy
                    if gyz > e2:
                        continue
                    base = coff[k] + (iz * nyk + iy) * nxk
                    for ix in range(x0, x1 + 1):
                        cx0 = org[k, 0] + ix * ck
                        gx = max(cx0 - px, px - cx0 - ck, 0.0)
                        if gyz + gx * gx > e2:  # the cell lies beyond the reach
                            continue
                        j = head[base + ix]
                        while j >= 0:
                            # appended without a branch (out has room for one more than cap - 1)
                            dx = XR[j, 0] - px
                            dy = XR[j, 1] - py
                            dz = XR[j, 2] - pz
                            lim = reach + XR[j, 3]
                            out[m] = j
                            m += (dx * dx + dy * dy + dz * dz < lim * lim) & (j != skip)
                            m = min(m, cap - 1)
                            j = nxt[j]
            continue
        for bz in range(z0 // BLOCK, z1 // BLOCK + 1):
            for by in range(y0 // BLOCK, y1 // BLOCK + 1):
                for bx in range(x0 // BLOCK, x1 // BLOCK + 1):
                    iz0, iz1, iy0, iy1, ix0, ix1 = block_cells(G, bcnt, k, bx, by, bz, x0, x1, y0, y1, z0, z1)
                    for iz in range(iz0, iz1):
                        for iy in range(iy0, iy1):
                            base = coff[k] + (iz * nyk + iy) * nxk
                            for ix in range(ix0, ix1):
                                j = head[base + ix]
                                while j >= 0:
                                    if j != skip:
                                        dx = XR[j, 0] - px
                                        dy = XR[j, 1] - py
                                        dz = XR[j, 2] - pz
                                        lim = reach + XR[j, 3]
                                        if dx * dx + dy * dy + dz * dz < lim * lim and m < cap:
                                            out[m] = j
                                            m += 1
                                    j = nxt[j]
    return m


@njit(cache=True, error_model="numpy")
def grid_overlaps(G, head, nxt, bcnt, XR, px, py, pz, r, tol, stamp):
    """Does a sphere (P, r) overlap a placed sphere j >= stamp by more than tol * min(r, r_j)?"""
    dims, coff, rmax = G.dims, G.coff, G.rmax
    for k in range(dims.shape[0]):
        x0, x1, y0, y1, z0, z1 = cell_range(G, k, px, py, pz, r + rmax[k])
        nxk, nyk = dims[k, 0], dims[k, 1]
        small = (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) <= 216
        # few cells: all of them, one block; many: block by block, empty blocks skipped
        for bz in range(0 if small else z0 // BLOCK, 1 if small else z1 // BLOCK + 1):
            for by in range(0 if small else y0 // BLOCK, 1 if small else y1 // BLOCK + 1):
                for bx in range(0 if small else x0 // BLOCK, 1 if small else x1 // BLOCK + 1):
                    if small:
                        iz0, iz1, iy0, iy1, ix0, ix1 = z0, z1 + 1, y0, y1 + 1, x0, x1 + 1
                    else:
                        iz0, iz1, iy0, iy1, ix0, ix1 = block_cells(G, bcnt, k, bx, by, bz, x0, x1, y0, y1, z0, z1)
                    for iz in range(iz0, iz1):
                        for iy in range(iy0, iy1):
                            base = coff[k] + (iz * nyk + iy) * nxk
                            for ix in range(ix0, ix1):
                                j = head[base + ix]
                                while j >= stamp:
                                    dx = XR[j, 0] - px
                                    dy = XR[j, 1] - py
                                    dz = XR[j, 2] - pz
                                    lim = r + XR[j, 3] - tol * min(r, XR[j, 3])
                                    if dx * dx + dy * dy + dz * dz < lim * lim:
                                        return True
                                    j = nxt[j]
    return False


# ---------------------------------------------------------------------------
# static multi-level grid over finished spheres: pairs, contacts

@njit(cache=True)
def grid_build(X, R, G):
    head = np.full(G.coff[-1], -1, np.int32)
    nxt = np.full(X.shape[0], -1, np.int32)
    bcnt = np.zeros(G.boff[-1], np.int32)
    for i in range(X.shape[0]):
        grid_insert(G, head, nxt, bcnt, i, X[i, 0], X[i, 1], X[i, 2], R[i])
    return head, nxt, bcnt


@njit(cache=True)
def _pairs_of(i, X, R, G, head, nxt, bcnt, tol, out_j, pos):
    """Pairs (i, j), j > i, with |ci - cj| <= (ri + rj)(1 + tol); with out_j, written there sorted by j."""
    px, py, pz, ri = X[i, 0], X[i, 1], X[i, 2], R[i]
    dims, coff, rmax = G.dims, G.coff, G.rmax
    n = 0
    for k in range(dims.shape[0]):
        x0, x1, y0, y1, z0, z1 = cell_range(G, k, px, py, pz, (ri + rmax[k]) * (1.0 + tol))
        nxk, nyk = dims[k, 0], dims[k, 1]
        for bz in range(z0 // BLOCK, z1 // BLOCK + 1):
            for by in range(y0 // BLOCK, y1 // BLOCK + 1):
                for bx in range(x0 // BLOCK, x1 // BLOCK + 1):
                    iz0, iz1, iy0, iy1, ix0, ix1 = block_cells(G, bcnt, k, bx, by, bz, x0, x1, y0, y1, z0, z1)
                    for iz in range(iz0, iz1):
                        for iy in range(iy0, iy1):
                            base = coff[k] + (iz * nyk + iy) * nxk
                            for ix in range(ix0, ix1):
                                j = head[base + ix]
                                while j > i:  # lists run from the newest (largest) index down
                                    dx = X[j, 0] - px
                                    dy = X[j, 1] - py
                                    dz = X[j, 2] - pz
                                    lim = (ri + R[j]) * (1.0 + tol)
                                    if dx * dx + dy * dy + dz * dz <= lim * lim:
                                        if out_j is not None:
                                            p = pos + n
                                            while p > pos and out_j[p - 1] > j:
                                                out_j[p] = out_j[p - 1]
                                                p -= 1
                                            out_j[p] = j
                                        n += 1
                                    j = nxt[j]
    return n


@njit(cache=True, parallel=True)
def count_pairs(X, R, G, head, nxt, bcnt, tol):
    counts = np.empty(X.shape[0], np.int64)
    for i in prange(X.shape[0]):
        counts[i] = _pairs_of(i, X, R, G, head, nxt, bcnt, tol, None, 0)
    return counts


@njit(cache=True, parallel=True)
def fill_pairs(X, R, G, head, nxt, bcnt, tol, offsets, out):
    for i in prange(X.shape[0]):
        k = _pairs_of(i, X, R, G, head, nxt, bcnt, tol, out[:, 1], offsets[i])
        for q in range(offsets[i], offsets[i] + k):
            out[q, 0] = i


@njit(cache=True, parallel=True)
def overlap_stats(X, R, G, head, nxt, bcnt):
    """Largest overlap (ri + rj - d) / min(ri, rj) of each sphere with a later one (0 if none)."""
    dims, coff, rmax = G.dims, G.coff, G.rmax
    out = np.zeros(X.shape[0])
    for i in prange(X.shape[0]):
        px, py, pz, ri = X[i, 0], X[i, 1], X[i, 2], R[i]
        best = 0.0
        for k in range(dims.shape[0]):
            x0, x1, y0, y1, z0, z1 = cell_range(G, k, px, py, pz, ri + rmax[k])
            for iz in range(z0, z1 + 1):
                for iy in range(y0, y1 + 1):
                    base = coff[k] + (iz * dims[k, 1] + iy) * dims[k, 0]
                    for ix in range(x0, x1 + 1):
                        j = head[base + ix]
                        while j > i:
                            d = math.sqrt((X[j, 0] - px) ** 2 + (X[j, 1] - py) ** 2 + (X[j, 2] - pz) ** 2)
                            ov = (ri + R[j] - d) / min(ri, R[j])
                            if ov > best:
                                best = ov
                            j = nxt[j]
        out[i] = best
    return out
