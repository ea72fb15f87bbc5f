"""Numba kernels: sphere grid, discontinuity membership, colours, bonds and bond rules.

Ties (the paper's eq. 13-16 and the bond rules are closed inequalities, and a joint at a round coordinate
through a lattice puts centres exactly on its plane, at exactly 2r from it or at exactly R from its axis):
every comparison allows the excavation's tie allowance, ROUND (sgim/_excavate.py) times the magnitudes of the
coordinates, |O|_1 + |M|_1 (a length), so that a centre within it of the joint plane lies on the plane (offset
0, green, as S.(M - O) >= 0 says) and one within it of the 2r band, the d/2 slab or the radius R is inside,
the same on both sides of the plane, whatever the rounding of the lattice coordinates.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._excavate import ROUND

KIND_INSIDE = 1  # inside a thick discontinuity (red)
KIND_GREEN = 2  # within 2r of a joint, S.(M - O) >= 0 (the plane included)
KIND_BLUE = 3  # within 2r of a joint, S.(M - O) < 0


@njit(cache=True, inline="always")
def tie_allowance(x0, y0, z0, x1, y1, z1):
    """The length within which a closed inequality of eq. 13-16 holds as a tie: ROUND (|O|_1 + |M|_1).

    The rounding of the coordinates (a lattice site, a disc centre typed in decimal) and of the products is a
    few ulps of these magnitudes; ROUND is thousands of ulps and far below any lattice spacing."""
    return ROUND * (abs(x0) + abs(y0) + abs(z0) + abs(x1) + abs(y1) + abs(z1))


# ---------------------------------------------------------------------------
# uniform grid over the spheres (counting sort by cell)

@njit(cache=True)
def build_grid(c, g0, cs, dims):
    n = c.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny * nz + 1, np.int64)
    for i in range(n):
        ix = min(max(int((c[i, 0] - g0[0]) / cs), 0), nx - 1)
        iy = min(max(int((c[i, 1] - g0[1]) / cs), 0), ny - 1)
        iz = min(max(int((c[i, 2] - g0[2]) / cs), 0), nz - 1)
        cell[i] = (iz * ny + iy) * nx + ix
        start[cell[i] + 1] += 1
    for k in range(nx * ny * nz):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return start, order


@njit(cache=True)
def _cell_range(lo, hi, g0, cs, dims, a):
    i0 = min(max(int(math.floor((lo - g0[a]) / cs)), 0), dims[a] - 1)
    i1 = min(max(int(math.floor((hi - g0[a]) / cs)), 0), dims[a] - 1)
    return i0, i1


@njit(cache=True)
def _box_cells(M, ext, g0, cs, dims):
    """Cell index ranges (lo3, hi3) of the box M +- ext."""
    lo3 = np.empty(3, np.int64)
    hi3 = np.empty(3, np.int64)
    for ax in range(3):
        lo3[ax], hi3[ax] = _cell_range(M[ax] - ext, M[ax] + ext, g0, cs, dims, ax)
    return lo3, hi3


@njit(cache=True)
def _dominant_axis(S):
    a = 0
    if abs(S[1]) > abs(S[a]):
        a = 1
    if abs(S[2]) > abs(S[a]):
        a = 2
    return a


@njit(cache=True)
def _slab_cells(M, S, band, g0, cs, dims, a, b, e, ib, ie, lo_a, hi_a):
    """Range (i0, i1) of cells along axis a (the normal's dominant axis), within [lo_a, hi_a], of the
    column (ib, ie) on the other axes (b, e) whose cell boxes meet the slab |S.(x - M)| <= band |S|.

    A disc's work then follows its area (times the slab's thickness in cells), not its bounding box.
    The cell boxes are padded by a small margin so that a centre sorted into a cell by rounding is
    never missed; the spheres found are tested exactly afterwards."""
    ns = math.sqrt(S[0] * S[0] + S[1] * S[1] + S[2] * S[2])
    eps = _grid_pad(M, g0, cs, dims)  # >= the tie allowance of every centre in the grid
    tb0 = S[b] * (g0[b] + ib * cs - eps - M[b])
    tb1 = S[b] * (g0[b] + (ib + 1) * cs + eps - M[b])
    te0 = S[e] * (g0[e] + ie * cs - eps - M[e])
    te1 = S[e] * (g0[e] + (ie + 1) * cs + eps - M[e])
    tmin = min(tb0, tb1) + min(te0, te1)
    tmax = max(tb0, tb1) + max(te0, te1)
    w = (band + eps) * ns
    u0 = (-w - tmax) / S[a]
    u1 = (w - tmin) / S[a]
    if u0 > u1:
        u0, u1 = u1, u0
    f0 = min(max((M[a] + u0 - eps - g0[a]) / cs, float(lo_a)), float(hi_a + 1))
    f1 = min(max((M[a] + u1 + eps - g0[a]) / cs, float(lo_a - 1)), float(hi_a))
    return int(math.floor(f0)), int(math.floor(f1))


# ---------------------------------------------------------------------------
# discontinuity membership (the paper's equations 13-16)

@njit(cache=True)
def _disc_test(c, rad, i, M, S, R, d):
    """Membership kind of sphere i for disc (M, S, R, d) or 0; and signed offset S.(O-M)/|S| (0 on the plane).

    Eq. 13-16 with the tie allowance of the module docstring."""
    A, B, C = S[0], S[1], S[2]
    ns = math.sqrt(A * A + B * B + C * C)
    tie = tie_allowance(c[i, 0], c[i, 1], c[i, 2], M[0], M[1], M[2])
    mx, my, mz = c[i, 0] - M[0], c[i, 1] - M[1], c[i, 2] - M[2]  # vector MO
    cx = my * C - mz * B
    cy = mz * A - mx * C
    cz = mx * B - my * A
    dot = A * (M[0] - c[i, 0]) + B * (M[1] - c[i, 1]) + C * (M[2] - c[i, 2])  # S.(M - O)
    off = -dot / ns
    if abs(off) <= tie:  # on the plane
        off = 0.0
    if math.sqrt(cx * cx + cy * cy + cz * cz) / ns > R + tie:  # eq. 13
        return 0, off
    if d != 0.0:
        if abs(off) <= d / 2.0 + tie:  # eq. 14
            return KIND_INSIDE, off
        return 0, off
    if abs(off) <= 2.0 * rad[i] + tie:  # eq. 15 / 16: green where S.(M - O) >= 0, i.e. off <= 0
        return (KIND_GREEN if off <= 0.0 else KIND_BLUE), off
    return 0, off


@njit(cache=True)
def _grid_pad(M, g0, cs, dims):
    """Margin that keeps a centre sorted into a cell by rounding (or lying within the tie allowance) in
    the cell ranges a disc visits; the spheres found are tested exactly afterwards."""
    scale = (abs(g0[0]) + abs(g0[1]) + abs(g0[2]) + abs(M[0]) + abs(M[1]) + abs(M[2])
             + (dims[0] + dims[1] + dims[2]) * cs)
    return 1e-6 * cs + 1e-12 * scale


@njit(cache=True)
def _disc_pass(c, rad, start, order, g0, cs, dims, M, S, R, d, rmax, out_s, out_k, out_o, pos):
    """Count (out_* empty) or write into out_*[pos:] the spheres disc (M, S, R, d) holds; returns the count. One
    signature for both: each specialisation costs seconds of compilation."""
    write = out_s.shape[0] > 0
    band = d / 2.0 if d != 0.0 else 2.0 * rmax
    ext = R + band + _grid_pad(M, g0, cs, dims)
    lo3, hi3 = _box_cells(M, ext, g0, cs, dims)
    a = _dominant_axis(S)
    b, e = max((a + 1) % 3, (a + 2) % 3), min((a + 1) % 3, (a + 2) % 3)  # inner loop on the smaller stride
    idx = np.empty(3, np.int64)
    n = 0
    for ib in range(lo3[b], hi3[b] + 1):
        idx[b] = ib
        for ie in range(lo3[e], hi3[e] + 1):
            idx[e] = ie
            i0, i1 = _slab_cells(M, S, band, g0, cs, dims, a, b, e, ib, ie, lo3[a], hi3[a])
            for ia in range(i0, i1 + 1):
                idx[a] = ia
                cell = (idx[2] * dims[1] + idx[1]) * dims[0] + idx[0]
                for q in range(start[cell], start[cell + 1]):
                    i = order[q]
                    k, off = _disc_test(c, rad, i, M, S, R, d)
                    if k != 0:
                        if write:
                            out_s[pos + n] = i
                            out_k[pos + n] = k
                            out_o[pos + n] = off
                        n += 1
    return n


@njit(cache=True, parallel=True)
def disc_members(c, rad, start, order, g0, cs, dims, centres, normals, radii, thick, rmax, offsets, out_s, out_k,
                 out_o):
    """The number of spheres each disc holds; with out_* not empty also the rows (sphere, kind, offset), disc k's
    in offsets[k]:offsets[k + 1]. One kernel for the counting and the writing pass (empty arrays when counting):
    each parallel kernel costs seconds of compilation."""
    nd = centres.shape[0]
    counts = np.zeros(nd, np.int64)
    write = out_s.shape[0] > 0
    for k in prange(nd):
        pos = offsets[k] if write else np.int64(0)
        counts[k] = _disc_pass(c, rad, start, order, g0, cs, dims, centres[k], normals[k], radii[k], thick[k],
                               rmax, out_s, out_k, out_o, pos)
    return counts


@njit(cache=True)
def colours_from_members(n, msph, mdisc, mkind, moff):
    """Colour and colour source per sphere: red wins; else the nearest joint plane decides.

    Rows are in disc order, so ties in distance go to the lower disc index.
    """
    colour = np.zeros(n, np.int8)
    source = np.full(n, -1, np.int32)
    best = np.full(n, np.inf)
    for q in range(len(msph)):
        i = msph[q]
        a = abs(moff[q])
        if mkind[q] == KIND_INSIDE:
            if colour[i] != 1 or a < best[i]:
                colour[i] = 1
                source[i] = mdisc[q]
                best[i] = a
        elif colour[i] != 1 and a < best[i]:
            colour[i] = mkind[q]
            source[i] = mdisc[q]
            best[i] = a
    return colour, source


# ---------------------------------------------------------------------------
# bonds: every pair with centre distance <= (ri + rj)(1 + tol), i < j, sorted

@njit(cache=True)
def _pairs_of(i, c, rad, start, order, g0, cs, dims, tol, out_j, pos):
    """Count (out_j empty) or write into out_j[pos:], sorted, the spheres j > i that touch sphere i; returns the
    count. One signature for both callers (an empty column when counting, i as int64: prange hands its loops an
    unsigned index): each specialisation costs seconds of compilation."""
    write = out_j.shape[0] > 0
    ix = min(max(int((c[i, 0] - g0[0]) / cs), 0), dims[0] - 1)
    iy = min(max(int((c[i, 1] - g0[1]) / cs), 0), dims[1] - 1)
    iz = min(max(int((c[i, 2] - g0[2]) / cs), 0), dims[2] - 1)
    n = 0
    for jz in range(max(iz - 1, 0), min(iz + 2, dims[2])):
        for jy in range(max(iy - 1, 0), min(iy + 2, dims[1])):
            for jx in range(max(ix - 1, 0), min(ix + 2, dims[0])):
                cell = (jz * dims[1] + jy) * dims[0] + jx
                for q in range(start[cell], start[cell + 1]):
                    j = order[q]
                    if j <= i:
                        continue
                    dx = c[j, 0] - c[i, 0]
                    dy = c[j, 1] - c[i, 1]
                    dz = c[j, 2] - c[i, 2]
                    lim = (rad[i] + rad[j]) * (1.0 + tol)
                    if dx * dx + dy * dy + dz * dz <= lim * lim:
                        if write:
                            # insertion keeps each row sorted by j
                            p = pos + n
                            while p > pos and out_j[p - 1] > j:
                                out_j[p] = out_j[p - 1]
                                p -= 1
                            out_j[p] = j
                        n += 1
    return n


@njit(cache=True, parallel=True)
def sphere_pairs(c, rad, start, order, g0, cs, dims, tol, offsets, out):
    """The number of touching spheres j > i of each sphere i; with `out` not empty also the pairs (i, j), sphere
    i's in rows offsets[i]:offsets[i + 1] sorted by j. One kernel for the counting and the writing pass (empty
    offsets and out when counting): each parallel kernel costs seconds of compilation."""
    n = c.shape[0]
    counts = np.empty(n, np.int64)
    write = out.shape[0] > 0
    for i in prange(n):
        pos = offsets[i] if write else np.int64(0)
        k = _pairs_of(np.int64(i), c, rad, start, order, g0, cs, dims, tol, out[:, 1], pos)
        counts[i] = k
        if write:
            for q in range(pos, pos + k):
                out[q, 0] = i
    return counts


# ---------------------------------------------------------------------------
# bond rules

@njit(cache=True)
def green_blue_cutter(bonds, cut, colour, source, mstart, mdisc, mkind, moff):
    """Which discontinuity cut each cut bond under the colour rule (-1 for bonded pairs).

    A red sphere's bonds are cut by its fault.  A green-blue pair is cut by a joint
    that holds the two spheres on opposite sides (the nearest such joint), or, if
    their colours come from different joints, by the joint that coloured sphere i.
    """
    m = bonds.shape[0]
    by = np.full(m, -1, np.int32)
    for b in range(m):
        if not cut[b]:
            continue
        i, j = bonds[b, 0], bonds[b, 1]
        if colour[i] == 1:
            by[b] = source[i]
            continue
        if colour[j] == 1:
            by[b] = source[j]
            continue
        best = np.inf
        for p in range(mstart[i], mstart[i + 1]):
            for q in range(mstart[j], mstart[j + 1]):
                if mdisc[p] == mdisc[q] and mkind[p] + mkind[q] == 5:  # green + blue
                    s = abs(moff[p]) + abs(moff[q])
                    if s < best:
                        best = s
                        by[b] = mdisc[p]
        if by[b] < 0:
            by[b] = source[i]
    return by


@njit(cache=True, inline="always")
def _side_dot(c, i, M, A, B, C, ns):
    """S.(M - O) of centre i, 0 when O lies on the plane within the tie allowance."""
    s = A * (M[0] - c[i, 0]) + B * (M[1] - c[i, 1]) + C * (M[2] - c[i, 2])
    if abs(s) / ns <= tie_allowance(c[i, 0], c[i, 1], c[i, 2], M[0], M[1], M[2]):
        return 0.0
    return s


@njit(cache=True)
def geometric_cuts(c, rad, start, order, g0, cs, dims, bond_start, bonds, colour, source,
                   centres, normals, radii, thick, lmax):
    """Geometric rule: cut a bond when a red sphere ends it (by that fault) or when the
    segment between centres crosses a zero-thickness disc inside its radius (lowest disc id).

    The ends' sides are those of eq. 15 / 16 with the tie allowance (a centre on the plane is on the green
    side: a bond from it is cut when the other end is blue); the crossing point is inside the radius with the
    tie allowance too."""
    m = bonds.shape[0]
    by = np.full(m, -1, np.int32)
    for b in range(m):
        i, j = bonds[b, 0], bonds[b, 1]
        if colour[i] == 1:
            by[b] = source[i]
        elif colour[j] == 1:
            by[b] = source[j]
    for k in range(centres.shape[0]):
        if thick[k] != 0.0:
            continue
        M, S, R = centres[k], normals[k], radii[k]
        A, B, C = S[0], S[1], S[2]
        ns = math.sqrt(A * A + B * B + C * C)
        ext = R + lmax + _grid_pad(M, g0, cs, dims)
        lo3, hi3 = _box_cells(M, ext, g0, cs, dims)
        a = _dominant_axis(S)
        ab, ae = max((a + 1) % 3, (a + 2) % 3), min((a + 1) % 3, (a + 2) % 3)
        idx = np.empty(3, np.int64)
        for ib in range(lo3[ab], hi3[ab] + 1):
            idx[ab] = ib
            for ie in range(lo3[ae], hi3[ae] + 1):
                idx[ae] = ie
                i0, i1 = _slab_cells(M, S, lmax, g0, cs, dims, a, ab, ae, ib, ie, lo3[a], hi3[a])
                for ia in range(i0, i1 + 1):
                    idx[a] = ia
                    cell = (idx[2] * dims[1] + idx[1]) * dims[0] + idx[0]
                    for q in range(start[cell], start[cell + 1]):
                        i = order[q]
                        si = _side_dot(c, i, M, A, B, C, ns)
                        if abs(si) / ns > lmax:
                            continue
                        for b in range(bond_start[i], bond_start[i + 1]):
                            if by[b] >= 0:
                                continue
                            j = bonds[b, 1]
                            sj = _side_dot(c, j, M, A, B, C, ns)
                            if (si >= 0.0) == (sj >= 0.0):  # same side (green: S.(M - O) >= 0)
                                continue
                            t = si / (si - sj)  # in [0, 1]: one end >= 0, the other < 0
                            x = c[i, 0] + t * (c[j, 0] - c[i, 0])
                            y = c[i, 1] + t * (c[j, 1] - c[i, 1])
                            z = c[i, 2] + t * (c[j, 2] - c[i, 2])
                            px, py, pz = x - M[0], y - M[1], z - M[2]
                            qx = py * C - pz * B
                            qy = pz * A - px * C
                            qz = px * B - py * A
                            if math.sqrt(qx * qx + qy * qy + qz * qz) / ns <= R + tie_allowance(x, y, z, M[0], M[1],
                                                                                                 M[2]):
                                by[b] = k
    return by
