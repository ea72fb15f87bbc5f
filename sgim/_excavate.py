"""Numba kernels: excavation of lattice columns by triangulated surfaces.

Column by column, the kernels decide which lattice sites survive without ever
materialising the sites that are removed:

* below ``zlo`` (lower than any excavating space of the column's facets, with a
  safety margin) every site is kept without a test;
* at or above ``zhi`` (above a facet whose vertical prism holds the column with
  a margin) every site is removed without a test;
* sites in between are tested with the exact predicate of the rule.

The predicates are the single source of truth; the margins only decide which
sites need a test, so the kept set equals a brute-force evaluation of the
predicate at every site.

Facet record layouts
--------------------
``pc`` (paper rule, 34 columns): [A0 B0 C0 D0] + [Ak Bk Ck Dk Dk0] for k = 1..6
(see :func:`sgim.geometry.paper_facets`).
``ec`` (exact rule, 12 columns): p0 (3), e1 = p1 - p0 (3), e2 = p2 - p0 (3), n = e1 x e2 (3).
``fb`` (both, 8 columns): xmin xmax ymin ymax zmin zmax, |n|/|nz| of the rule's own
normal (inf when its z component is exactly 0), rule code (0 paper, 1 exact).
Several surfaces with different rules are merged into one facet set.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

RULE_PAPER = 0.0
RULE_EXACT = 1.0


# The paper's "<=" tests (eq. 7 and 11) describe closed prisms.  Evaluated literally in
# floating point, a site lying exactly on an edge shared by two facets can fail the test
# of both facets by one rounding error, leaving whole rows of sites standing above the
# surface.  Each closed comparison therefore allows ROUND times the magnitude of its terms.
# The strict "distance < r" tests are tightened by the same amount: a site at distance
# exactly r (common: lattice layers at z.5 under berms at whole metres with r = 0.5) is
# kept, as the strict inequality says, instead of being removed or kept by rounding.
ROUND = 1e-12

# the facet records (pc, ec, fb; see above) binned on a plan grid: the first entry of each cell
# (cell_start) in cell_facets, the grid's origin (g0x, g0y), cell size gs and cells gnx x gny
Bins = namedtuple("Bins", "pc ec fb cell_start cell_facets g0x g0y gs gnx gny")
# the sites of a column family: z = za + zb (c0 + c1 m), m = 0 .. nz - 1 (sgim/packing.py)
Steps = namedtuple("Steps", "za zb c0 c1 nz")


@njit(cache=True, inline="always")
def _slab(pc, f, k, x, y, z):
    b = 4 + 5 * k
    a, bb, c, d, d0 = pc[f, b], pc[f, b + 1], pc[f, b + 2], pc[f, b + 3], pc[f, b + 4]
    w = abs(d - d0) + ROUND * (abs(a * x) + abs(bb * y) + abs(c * z) + abs(d) + abs(d0))
    return abs(a * x + bb * y + c * z + d) <= w and abs(a * x + bb * y + c * z + d0) <= w


@njit(cache=True)
def paper_hit(pc, f, x, y, z, r):
    """True when (x, y, z) lies in the paper's excavating space of facet f (eq. 7 and 11)."""
    A0, B0, C0, D0 = pc[f, 0], pc[f, 1], pc[f, 2], pc[f, 3]
    nn = math.sqrt(A0 * A0 + B0 * B0 + C0 * C0)
    if abs(A0 * x + B0 * y + C0 * z + D0) / nn < r - ROUND * (abs(A0 * x) + abs(B0 * y) + abs(C0 * z) + abs(D0)) / nn:
        if _slab(pc, f, 0, x, y, z) and _slab(pc, f, 1, x, y, z) and _slab(pc, f, 2, x, y, z):
            return True
    if C0 != 0.0:
        h = -(A0 * x + B0 * y + D0) / C0
        if z >= h - ROUND * (abs(z) + abs(h)):
            if _slab(pc, f, 3, x, y, z) and _slab(pc, f, 4, x, y, z) and _slab(pc, f, 5, x, y, z):
                return True
    return False


@njit(cache=True)
def _plan_side(ax, ay, bx, by, x, y):
    return (bx - ax) * (y - ay) - (by - ay) * (x - ax)


@njit(cache=True)
def _plan_side_tol(ax, ay, bx, by, x, y):
    # scaled by the coordinates (not by the products, which vanish near the edge), so that a
    # column that rounding puts one ulp outside a surface covering the domain belongs to it
    return ROUND * (abs(bx - ax) + abs(by - ay)) * (abs(x) + abs(y) + abs(ax) + abs(ay))


@njit(cache=True)
def tri_dist2(ec, f, x, y, z):
    """Squared distance from a point to triangle f (closest point on the closed triangle)."""
    ax, ay, az = ec[f, 0], ec[f, 1], ec[f, 2]
    abx, aby, abz = ec[f, 3], ec[f, 4], ec[f, 5]
    acx, acy, acz = ec[f, 6], ec[f, 7], ec[f, 8]
    apx, apy, apz = x - ax, y - ay, z - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz
    bpx, bpy, bpz = apx - abx, apy - aby, apz - abz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        qx, qy, qz = apx - v * abx, apy - v * aby, apz - v * abz
        return qx * qx + qy * qy + qz * qz
    cpx, cpy, cpz = apx - acx, apy - acy, apz - acz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        qx, qy, qz = apx - w * acx, apy - w * acy, apz - w * acz
        return qx * qx + qy * qy + qz * qz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        bcx, bcy, bcz = acx - abx, acy - aby, acz - abz
        qx, qy, qz = bpx - w * bcx, bpy - w * bcy, bpz - w * bcz
        return qx * qx + qy * qy + qz * qz
    nx, ny, nz = ec[f, 9], ec[f, 10], ec[f, 11]
    s = nx * apx + ny * apy + nz * apz
    return s * s / (nx * nx + ny * ny + nz * nz)


@njit(cache=True)
def exact_above(ec, f, x, y, z):
    """True when (x, y) lies in the plan projection of facet f (closed) and z is on or above it."""
    nz = ec[f, 11]
    if nz == 0.0:
        return False
    ax, ay = ec[f, 0], ec[f, 1]
    bx, by = ax + ec[f, 3], ay + ec[f, 4]
    cx, cy = ax + ec[f, 6], ay + ec[f, 7]
    s1 = _plan_side(ax, ay, bx, by, x, y)
    s2 = _plan_side(bx, by, cx, cy, x, y)
    s3 = _plan_side(cx, cy, ax, ay, x, y)
    t1 = _plan_side_tol(ax, ay, bx, by, x, y)
    t2 = _plan_side_tol(bx, by, cx, cy, x, y)
    t3 = _plan_side_tol(cx, cy, ax, ay, x, y)
    if not ((s1 >= -t1 and s2 >= -t2 and s3 >= -t3) or (s1 <= t1 and s2 <= t2 and s3 <= t3)):
        return False
    h = ec[f, 2] - (ec[f, 9] * (x - ax) + ec[f, 10] * (y - ay)) / nz
    return z >= h - ROUND * (abs(z) + abs(h))


@njit(cache=True)
def exact_hit(ec, f, x, y, z, r):
    if exact_above(ec, f, x, y, z):
        return True
    return tri_dist2(ec, f, x, y, z) < r * r - _dist2_round(ec, f, x, y, z)


@njit(cache=True)
def _dist2_round(ec, f, x, y, z):
    """Rounding allowance of a squared distance from (x, y, z) to facet f (see ROUND)."""
    s = abs(x) + abs(y) + abs(z) + abs(ec[f, 0]) + abs(ec[f, 1]) + abs(ec[f, 2])
    return ROUND * s * s


@njit(cache=True)
def site_removed(pc, ec, fb, f, x, y, z, r):
    if fb[f, 7] == RULE_PAPER:
        return paper_hit(pc, f, x, y, z, r)
    return exact_hit(ec, f, x, y, z, r)


@njit(cache=True)
def _plane_height(pc, ec, fb, f, x, y):
    if fb[f, 7] == RULE_PAPER:
        return -(pc[f, 0] * x + pc[f, 1] * y + pc[f, 3]) / pc[f, 2]
    nz = ec[f, 11]
    return ec[f, 2] - (ec[f, 9] * (x - ec[f, 0]) + ec[f, 10] * (y - ec[f, 1])) / nz


@njit(cache=True)
def _certainly_inside_plan(pc, ec, fb, f, x, y, z, tol):
    """Column (x, y) lies inside the facet's vertical prism with a relative margin."""
    if fb[f, 7] == RULE_PAPER:
        for k in range(3, 6):
            b = 4 + 5 * k
            a, bb, c, d, d0 = pc[f, b], pc[f, b + 1], pc[f, b + 2], pc[f, b + 3], pc[f, b + 4]
            w = abs(d - d0)
            lim = w * (1.0 - tol) - tol * (abs(d) + abs(d0))
            if not (abs(a * x + bb * y + c * z + d) <= lim and abs(a * x + bb * y + c * z + d0) <= lim):
                return False
        return True
    ax, ay = ec[f, 0], ec[f, 1]
    bx, by = ax + ec[f, 3], ay + ec[f, 4]
    cx, cy = ax + ec[f, 6], ay + ec[f, 7]
    s1 = _plan_side(ax, ay, bx, by, x, y)
    s2 = _plan_side(bx, by, cx, cy, x, y)
    s3 = _plan_side(cx, cy, ax, ay, x, y)
    area = abs(_plan_side(ax, ay, bx, by, cx, cy))
    m = tol * area
    return (s1 > m and s2 > m and s3 > m) or (s1 < -m and s2 < -m and s3 < -m)


@njit(cache=True)
def _column_bounds(B, x, y, r, eps, tol):
    """(zlo, zhi, cell): sites below zlo are kept, sites at/above zhi removed, in between tested."""
    pc, ec, fb, cell_start, cell_facets, g0x, g0y, gs, gnx, gny = B
    zlo = np.inf
    zhi = np.inf
    # clamp like bin_facets: a column on the box face may round one ulp past the grid
    ix = min(max(int(math.floor((x - g0x) / gs)), 0), gnx - 1)
    iy = min(max(int(math.floor((y - g0y) / gs)), 0), gny - 1)
    cell = iy * gnx + ix
    for q in range(cell_start[cell], cell_start[cell + 1]):
        f = cell_facets[q]
        if x < fb[f, 0] - r - eps or x > fb[f, 1] + r + eps or y < fb[f, 2] - r - eps or y > fb[f, 3] + r + eps:
            continue
        lo = fb[f, 4] - r
        steep = fb[f, 6]
        if steep < np.inf:
            h = _plane_height(pc, ec, fb, f, x, y)
            lo = max(lo, h - r * steep)
            if _certainly_inside_plan(pc, ec, fb, f, x, y, h, tol):
                zhi = min(zhi, h + eps * (1.0 + abs(h)))
        zlo = min(zlo, lo - eps * (1.0 + abs(lo)))
    return zlo, zhi, cell


@njit(cache=True)
def _first_at_or_above(za, zb, c0, c1, nz, zval):
    """Smallest m in [0, nz] with za + zb*(c0 + c1*m) >= zval (nz if none)."""
    if zval == np.inf:
        return nz
    t = math.ceil(((zval - za) / zb - c0) / c1)
    m = int(min(max(t, 0.0), float(nz)))
    while m > 0 and za + zb * (c0 + c1 * (m - 1)) >= zval:
        m -= 1
    while m < nz and za + zb * (c0 + c1 * m) < zval:
        m += 1
    return m


@njit(cache=True)
def _column_pass(B, x, y, steps, r, eps, tol, out, pos):
    """Count (`out` empty) or write into out[pos:] the kept sites of one column (B: Bins, steps: Steps); returns
    the count. One signature for both: each specialisation costs seconds of compilation."""
    write = out.shape[0] > 0
    pc, ec, fb, cell_start, cell_facets = B.pc, B.ec, B.fb, B.cell_start, B.cell_facets
    za, zb, c0, c1, nz = steps
    zlo, zhi, cell = _column_bounds(B, x, y, r, eps, tol)
    mlo = _first_at_or_above(za, zb, c0, c1, nz, zlo)
    mhi = max(mlo, _first_at_or_above(za, zb, c0, c1, nz, zhi))
    n = 0
    for m in range(mlo):
        if write:
            out[pos + n, 0] = x
            out[pos + n, 1] = y
            out[pos + n, 2] = za + zb * (c0 + c1 * m)
        n += 1
    for m in range(mlo, mhi):
        z = za + zb * (c0 + c1 * m)
        removed = False
        for q in range(cell_start[cell], cell_start[cell + 1]):
            f = cell_facets[q]
            if x < fb[f, 0] - r - eps or x > fb[f, 1] + r + eps or y < fb[f, 2] - r - eps \
                    or y > fb[f, 3] + r + eps:
                continue
            if site_removed(pc, ec, fb, f, x, y, z, r):
                removed = True
                break
        if not removed:
            if write:
                out[pos + n, 0] = x
                out[pos + n, 1] = y
                out[pos + n, 2] = z
            n += 1
    return n


@njit(cache=True, parallel=True)
def column_sites(B, cx, cy, steps, r, eps, tol, offsets, out):
    """The number of kept sites of each column; with `out` not empty also the sites, column i's in rows
    offsets[i]:offsets[i + 1]. One kernel for the counting and the writing pass, called with the same types
    (empty offsets and out when counting): each parallel kernel costs seconds of compilation."""
    counts = np.empty(len(cx), np.int64)
    write = out.shape[0] > 0
    for i in prange(len(cx)):
        pos = offsets[i] if write else np.int64(0)
        counts[i] = _column_pass(B, cx[i], cy[i], steps, r, eps, tol, out, pos)
    return counts


@njit(cache=True)
def _clamped_range(lo, hi, g0, gs, n):
    """Cells [i0, i1] covering [lo, hi], clamped into the grid like the column lookup."""
    i0 = min(max(int(math.floor((lo - g0) / gs)), 0), n - 1)
    i1 = min(max(int(math.floor((hi - g0) / gs)), 0), n - 1)
    return i0, i1


@njit(cache=True)
def bin_facets(fb, g0x, g0y, gs, gnx, gny, pad):
    """CSR lists of the facets whose padded plan box overlaps each grid cell."""
    nf = fb.shape[0]
    counts = np.zeros(gnx * gny + 1, np.int64)
    for f in range(nf):
        i0, i1 = _clamped_range(fb[f, 0] - pad, fb[f, 1] + pad, g0x, gs, gnx)
        j0, j1 = _clamped_range(fb[f, 2] - pad, fb[f, 3] + pad, g0y, gs, gny)
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                counts[j * gnx + i + 1] += 1
    start = np.cumsum(counts)
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int64)
    for f in range(nf):
        i0, i1 = _clamped_range(fb[f, 0] - pad, fb[f, 1] + pad, g0x, gs, gnx)
        j0, j1 = _clamped_range(fb[f, 2] - pad, fb[f, 3] + pad, g0y, gs, gny)
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                c = j * gnx + i
                items[fill[c]] = f
                fill[c] += 1
    return start, items


@njit(cache=True, parallel=True)
def removed_mask(pc, ec, fb, pts, r):
    """Is each point removed by any facet?  Tests every facet: for checks on small scenes."""
    out = np.zeros(len(pts), np.bool_)
    for i in prange(len(pts)):
        for f in range(fb.shape[0]):
            if site_removed(pc, ec, fb, f, pts[i, 0], pts[i, 1], pts[i, 2], r):
                out[i] = True
                break
    return out
