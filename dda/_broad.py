"""numba kernels: uniform-grid broad phase ("neighbouring cells").

Space is divided into cubic cells of size S. Each block is mapped to the range of cells its bounding box
(enlarged by a small margin) overlaps, and keeps that range until its box leaves it (only then is it
re-mapped). Cells are hashed into buckets (collisions only add candidates that the box test rejects).
Fixed blocks are mapped once into their own grid; only moving blocks look up neighbours, so pairs of fixed
blocks are never tested and the cost follows the moving blocks. Blocks that would cover more than LARGE cells
(a floor, a big base) go to a short list tested against every moving block by box overlap.
"""
from __future__ import annotations

import numpy as np
from numba import njit

LARGE = 64


@njit(cache=True, inline="always")
def _hash(ix, iy, iz, mask):
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)
    return h & mask


@njit(cache=True)
def map_cells(aabb, i, S, margin, cellbox):
    for a in range(3):
        cellbox[i, a] = np.int64(np.floor((aabb[i, a] - margin) / S))
        cellbox[i, 3 + a] = np.int64(np.floor((aabb[i, 3 + a] + margin) / S))


@njit(cache=True)
def n_cells(cellbox, i):
    return (cellbox[i, 3] - cellbox[i, 0] + 1) * (cellbox[i, 4] - cellbox[i, 1] + 1) * (cellbox[i, 5] - cellbox[i, 2] + 1)


@njit(cache=True)
def inside_cells(aabb, i, S, cellbox):
    for a in range(3):
        if np.floor(aabb[i, a] / S) < cellbox[i, a] or np.floor(aabb[i, 3 + a] / S) > cellbox[i, 3 + a]:
            return False
    return True


@njit(cache=True)
def build_grid(bodies, cellbox, large, nbuckets):
    """Counting sort of the (body, cell) entries of `bodies` (skipping large ones) into hash buckets.

    Returns (start (nbuckets+1), entries)."""
    mask = nbuckets - 1
    count = np.zeros(nbuckets + 1, np.int64)
    for k in range(bodies.shape[0]):
        i = bodies[k]
        if large[i]:
            continue
        for ix in range(cellbox[i, 0], cellbox[i, 3] + 1):
            for iy in range(cellbox[i, 1], cellbox[i, 4] + 1):
                for iz in range(cellbox[i, 2], cellbox[i, 5] + 1):
                    count[_hash(ix, iy, iz, mask) + 1] += 1
    for b in range(nbuckets):
        count[b + 1] += count[b]
    entries = np.empty(count[nbuckets], np.int64)
    fill = count[:-1].copy()
    for k in range(bodies.shape[0]):
        i = bodies[k]
        if large[i]:
            continue
        for ix in range(cellbox[i, 0], cellbox[i, 3] + 1):
            for iy in range(cellbox[i, 1], cellbox[i, 4] + 1):
                for iz in range(cellbox[i, 2], cellbox[i, 5] + 1):
                    h = _hash(ix, iy, iz, mask)
                    entries[fill[h]] = i
                    fill[h] += 1
    return count, entries


@njit(cache=True)
def buckets_for(n_entries):
    nb = 16
    while nb < 2 * n_entries:
        nb *= 2
    return nb


@njit(cache=True, inline="always")
def boxes_overlap(aabb, i, j, gap):
    for a in range(3):
        if aabb[i, a] > aabb[j, 3 + a] + gap or aabb[j, a] > aabb[i, 3 + a] + gap:
            return False
    return True


@njit(cache=True)
def _push(pa, pb, npair, i, j):
    if npair >= pa.shape[0]:
        na = np.empty(2 * pa.shape[0] + 16, np.int64)
        nb = np.empty(2 * pa.shape[0] + 16, np.int64)
        na[:npair] = pa[:npair]
        nb[:npair] = pb[:npair]
        pa = na
        pb = nb
    pa[npair] = i
    pb[npair] = j
    return pa, pb


@njit(cache=True)
def find_pairs(active, fixed, large, aabb, cellbox, gap,
               mstart, mentries, mmask, fstart, fentries, fmask, large_list, stamp, tag, pa, pb):
    """Candidate pairs (i, j): i moving; j moving with j > i, or fixed. Boxes overlap within `gap`.

    `stamp` (one int per block) and the counter tag[0] mark the blocks already seen for the current block.
    Returns (pa, pb, count) (the arrays grow when needed)."""
    npair = 0
    nbody = aabb.shape[0]
    for k in range(active.shape[0]):
        i = active[k]
        if large[i]:
            for j in range(nbody):
                if j == i:
                    continue
                if not fixed[j] and large[j] and j < i:
                    continue
                if boxes_overlap(aabb, i, j, gap):
                    pa, pb = _push(pa, pb, npair, i, j)
                    npair += 1
            continue
        tag[0] += 1
        t = tag[0]
        stamp[i] = t
        for ix in range(cellbox[i, 0], cellbox[i, 3] + 1):
            for iy in range(cellbox[i, 1], cellbox[i, 4] + 1):
                for iz in range(cellbox[i, 2], cellbox[i, 5] + 1):
                    h = _hash(ix, iy, iz, mmask)
                    for e in range(mstart[h], mstart[h + 1]):
                        j = mentries[e]
                        if j <= i or stamp[j] == t:
                            continue
                        stamp[j] = t
                        if boxes_overlap(aabb, i, j, gap):
                            pa, pb = _push(pa, pb, npair, i, j)
                            npair += 1
                    if fentries.shape[0] > 0:
                        h = _hash(ix, iy, iz, fmask)
                        for e in range(fstart[h], fstart[h + 1]):
                            j = fentries[e]
                            if stamp[j] == t:
                                continue
                            stamp[j] = t
                            if boxes_overlap(aabb, i, j, gap):
                                pa, pb = _push(pa, pb, npair, i, j)
                                npair += 1
        for e in range(large_list.shape[0]):
            j = large_list[e]
            if j == i or stamp[j] == t:
                continue
            if not fixed[j]:
                continue  # large moving blocks find their pairs themselves
            stamp[j] = t
            if boxes_overlap(aabb, i, j, gap):
                pa, pb = _push(pa, pb, npair, i, j)
                npair += 1
    return pa, pb, npair
