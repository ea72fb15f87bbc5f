"""Numba kernels: random dense packing by pocket filling, and packing statistics.

Algorithm (see sgim/rpack.py for the user-facing description)
------------------------------------------------------------
A *pocket* is a position where a new sphere of radius r touches three supports at once:
three spheres, two spheres and a plane, or one sphere and two planes.  Planes are the six
walls of the domain box and the tangent planes of the constraint surfaces (excavation
surfaces, cavities, the fill shape) at the foot of the closest point.  After each sphere is
placed, every pocket it forms with its neighbours is computed in closed form, checked, and
queued by its height z.  The lowest pocket is taken and filled.  Seeds (sphere positions on
the floor of the region) start the process; it ends when no pocket is left.

The queue is a bucket queue: buckets QRES x the smallest grid level's largest radius high,
each a list taken newest first (the pockets made by the last spheres placed, which are still
in the cache; within a bucket the order is not by height).  A queued pocket is removed as soon as a new sphere covers
it: the pocket touches the sphere that made it, so a sphere that covers it lies within
r + r_maker + 2 r_pocket of its maker, a neighbour the new sphere gathers anyway; each sphere
keeps the list of its queued pockets.  For a constant radius this is complete and a pocket
taken from the queue needs no further check; with a radius law or a grading the pocket may be
filled by another radius than it was made for, and it is checked again against the spheres
placed since it was made.

Every placed sphere touches its supports exactly (up to rounding), so the overlap is zero up
to the stated tolerance and spheres touch the walls and surfaces they rest on.

A position P for a sphere of radius r is *admissible* when
  * it overlaps no placed sphere j by more than ``tol * min(r, r_j)``;
  * it lies in the box shrunk by r (allowance ``tol * r``);
  * its distance to every constraint surface is at least ``r (1 - tol)``;
  * it is not above an excavation surface in vertical projection (the exact rule).
The side of closed surfaces is not tested for pockets: a pocket touches an admissible sphere,
and a path of length r_S + r from an admissible centre cannot cross a surface while keeping
both ends at distance >= r_S and >= r from it (seeds are tested in full by the caller).

Radius modes: 0 constant radius; 1 a radius law given as a pre-drawn sequence, placed through
a small pool (each pocket takes the largest pooled radius that fits: the placed radii are the
drawn sequence minus what is left in the pool at the end); 2 graded: the radius is a function
of the distance to named objects (sgim/grading.py), times an optional spread factor from a
pre-drawn sequence.

Neighbour search: a multi-level grid of linked lists (level k holds radii in
[r0 2^k, r0 2^(k+1)), cell 2 x the level's largest radius), with block counts so that a large
query over a fine level skips empty space.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from . import _excavate as EX
from . import _meshq as MQ

SUP_NONE = -100  # seed: no supports
SUP_PLANE0 = -20  # the candidate's first stored plane
SUP_PLANE1 = -21  # its second stored plane
# box walls: -1 - w, w = 0..5 for x-, x+, y-, y+, z-, z+

BLOCK = 4  # cells per block side (block counts of the level grid)
BIG = 1e300
DEEP = 0.5  # see the pair loop of fill()
PAD = 8  # vector length the neighbour loops are padded to
PCAP = 16384  # pairs solved in one chunk (>= the neighbour cap, so one neighbour's pairs always fit)


# ---------------------------------------------------------------------------
# closed-form pockets

@njit(cache=True, inline="always")
def pocket_sss(ax, ay, az, da, bx, by, bz, db, cx, cy, cz, dc, out):
    """Points P with |P-a| = da, |P-b| = db, |P-c| = dc: count (0 or 2) written to out[0:2]."""
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    uv = ux * vx + uy * vy + uz * vz
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    det = nx * nx + ny * ny + nz * nz
    if det <= 1e-12 * uu * vv:
        return 0
    ku = 0.5 * (da * da + uu - db * db)
    kv = 0.5 * (da * da + vv - dc * dc)
    al = (ku * vv - kv * uv) / det
    be = (kv * uu - ku * uv) / det
    g2 = (da * da - al * ku - be * kv) / det
    if g2 < 0.0:
        return 0
    g = math.sqrt(g2)
    px = ax + al * ux + be * vx
    py = ay + al * uy + be * vy
    pz = az + al * uz + be * vz
    out[0, 0], out[0, 1], out[0, 2] = px + g * nx, py + g * ny, pz + g * nz
    out[1, 0], out[1, 1], out[1, 2] = px - g * nx, py - g * ny, pz - g * nz
    return 2


@njit(cache=True, inline="always")
def pocket_ssp(ax, ay, az, da, bx, by, bz, db, nx, ny, nz, h, out):
    """Points P with |P-a| = da, |P-b| = db and n.P = h (n unit)."""
    ha = nx * ax + ny * ay + nz * az - h
    hb = nx * bx + ny * by + nz * bz - h
    ra2 = da * da - ha * ha
    rb2 = db * db - hb * hb
    if ra2 < 0.0 or rb2 < 0.0:
        return 0
    pax, pay, paz = ax - ha * nx, ay - ha * ny, az - ha * nz
    ex, ey, ez = bx - hb * nx - pax, by - hb * ny - pay, bz - hb * nz - paz
    e2 = ex * ex + ey * ey + ez * ez
    if e2 <= 1e-24 * (da * da + db * db):
        return 0
    e = math.sqrt(e2)
    x = (ra2 - rb2 + e2) / (2.0 * e)
    y2 = ra2 - x * x
    if y2 < 0.0:
        return 0
    y = math.sqrt(y2)
    ux, uy, uz = ex / e, ey / e, ez / e
    wx, wy, wz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
    qx, qy, qz = pax + x * ux, pay + x * uy, paz + x * uz
    out[0, 0], out[0, 1], out[0, 2] = qx + y * wx, qy + y * wy, qz + y * wz
    out[1, 0], out[1, 1], out[1, 2] = qx - y * wx, qy - y * wy, qz - y * wz
    return 2


@njit(cache=True, inline="always")
def pocket_spp(ax, ay, az, da, n1x, n1y, n1z, h1, n2x, n2y, n2z, h2, out):
    """Points P with |P-a| = da, n1.P = h1, n2.P = h2 (unit normals)."""
    c = n1x * n2x + n1y * n2y + n1z * n2z
    s2 = 1.0 - c * c
    if s2 <= 1e-12:
        return 0
    f1 = (h1 - h2 * c) / s2
    f2 = (h2 - h1 * c) / s2
    p0x, p0y, p0z = f1 * n1x + f2 * n2x, f1 * n1y + f2 * n2y, f1 * n1z + f2 * n2z
    dx, dy, dz = n1y * n2z - n1z * n2y, n1z * n2x - n1x * n2z, n1x * n2y - n1y * n2x
    dl = math.sqrt(dx * dx + dy * dy + dz * dz)
    dx, dy, dz = dx / dl, dy / dl, dz / dl
    wx, wy, wz = p0x - ax, p0y - ay, p0z - az
    b = dx * wx + dy * wy + dz * wz
    cc = wx * wx + wy * wy + wz * wz - da * da
    disc = b * b - cc
    if disc < 0.0:
        return 0
    s = math.sqrt(disc)
    t0, t1 = -b + s, -b - s
    out[0, 0], out[0, 1], out[0, 2] = p0x + t0 * dx, p0y + t0 * dy, p0z + t0 * dz
    out[1, 0], out[1, 1], out[1, 2] = p0x + t1 * dx, p0y + t1 * dy, p0z + t1 * dz
    return 2


# ---------------------------------------------------------------------------
# bucket queue of candidates (the packer's priority queue)
#
# Buckets of height QRES x the smallest level's largest radius hold doubly linked lists of
# candidates (newest first); bmin never exceeds the lowest non-empty bucket.  Every candidate
# made by a placed sphere is also on its creator's list, so that the candidates a new sphere
# covers are removed when it is placed (its neighbours' lists) instead of being popped stale.

QRES = 0.1


@njit(cache=True, inline="always")
def q_bucket(key, qz0, qinv, nbk):
    return min(max(int((key - qz0) * qinv), 0), nbk - 1)


@njit(cache=True, inline="always")
def q_push(bhead, CI, ohead, c, b, owner):
    """Queue candidate c in bucket b and on its creator's list (owner < 0: none).
    CI[c]: 4 bucket, 5 next, 6 previous in the bucket; 7 next, 8 previous on the creator's list."""
    h = bhead[b]
    CI[c, 4] = b
    CI[c, 5] = h
    CI[c, 6] = -1
    if h >= 0:
        CI[h, 6] = c
    bhead[b] = c
    if owner >= 0:
        h = ohead[owner]
        CI[c, 7] = h
        CI[c, 8] = -1
        if h >= 0:
            CI[h, 8] = c
        ohead[owner] = c


@njit(cache=True, inline="always")
def q_remove(bhead, CI, ohead, c, owner):
    p, q = CI[c, 6], CI[c, 5]
    if p >= 0:
        CI[p, 5] = q
    else:
        bhead[CI[c, 4]] = q
    if q >= 0:
        CI[q, 6] = p
    if owner >= 0:
        p, q = CI[c, 8], CI[c, 7]
        if p >= 0:
            CI[p, 7] = q
        else:
            ohead[owner] = q
        if q >= 0:
            CI[q, 8] = p


# ---------------------------------------------------------------------------
# multi-level grid of linked lists
#
# G = (org (L,3), cs (L,), dims (L,3), coff (L+1,), rlo (L,), rmax (L,), bdims (L,3), boff (L+1,))
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


@njit(cache=True, error_model="numpy")
def grid_insert(org, cs, dims, coff, rlo, bdims, boff, head, nxt, bcnt, i, x, y, z, r):
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
def grid_gather(org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, XR,
                px, py, pz, reach, out, cap, skip):
    """Spheres j != skip with |P - x_j| < reach + r_j, written to out; returns the count (<= cap).
    XR (n,4): centre and radius of each sphere side by side (32 bytes a sphere: one cache line or less)."""
    m = 0
    for k in range(org.shape[0]):
        ext = reach + rmax[k]
        x0 = _cidx(org, cs, dims, k, 0, px - ext)
        x1 = _cidx(org, cs, dims, k, 0, px + ext)
        y0 = _cidx(org, cs, dims, k, 1, py - ext)
        y1 = _cidx(org, cs, dims, k, 1, py + ext)
        z0 = _cidx(org, cs, dims, k, 2, pz - ext)
        z1 = _cidx(org, cs, dims, k, 2, pz + ext)
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
                    if bcnt[boff[k] + (bz * bdims[k, 1] + by) * bdims[k, 0] + bx] == 0:
                        continue
                    for iz in range(max(z0, bz * BLOCK), min(z1, bz * BLOCK + BLOCK - 1) + 1):
                        for iy in range(max(y0, by * BLOCK), min(y1, by * BLOCK + BLOCK - 1) + 1):
                            base = coff[k] + (iz * nyk + iy) * nxk
                            for ix in range(max(x0, bx * BLOCK), min(x1, bx * BLOCK + BLOCK - 1) + 1):
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
def grid_overlaps(org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, XR, px, py, pz, r, tol, stamp):
    """Does a sphere (P, r) overlap a placed sphere j >= stamp by more than tol * min(r, r_j)?"""
    for k in range(org.shape[0]):
        ext = r + rmax[k]
        x0 = _cidx(org, cs, dims, k, 0, px - ext)
        x1 = _cidx(org, cs, dims, k, 0, px + ext)
        y0 = _cidx(org, cs, dims, k, 1, py - ext)
        y1 = _cidx(org, cs, dims, k, 1, py + ext)
        z0 = _cidx(org, cs, dims, k, 2, pz - ext)
        z1 = _cidx(org, cs, dims, k, 2, pz + ext)
        nxk, nyk = dims[k, 0], dims[k, 1]
        if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) <= 216:
            for iz in range(z0, z1 + 1):
                for iy in range(y0, y1 + 1):
                    base = coff[k] + (iz * nyk + iy) * nxk
                    for ix in range(x0, x1 + 1):
                        j = head[base + ix]
                        while j >= stamp:
                            dx = XR[j, 0] - px
                            dy = XR[j, 1] - py
                            dz = XR[j, 2] - pz
                            lim = r + XR[j, 3] - tol * min(r, XR[j, 3])
                            if dx * dx + dy * dy + dz * dz < lim * lim:
                                return True
                            j = nxt[j]
            continue
        for bz in range(z0 // BLOCK, z1 // BLOCK + 1):
            for by in range(y0 // BLOCK, y1 // BLOCK + 1):
                for bx in range(x0 // BLOCK, x1 // BLOCK + 1):
                    if bcnt[boff[k] + (bz * bdims[k, 1] + by) * bdims[k, 0] + bx] == 0:
                        continue
                    for iz in range(max(z0, bz * BLOCK), min(z1, bz * BLOCK + BLOCK - 1) + 1):
                        for iy in range(max(y0, by * BLOCK), min(y1, by * BLOCK + BLOCK - 1) + 1):
                            base = coff[k] + (iz * nyk + iy) * nxk
                            for ix in range(max(x0, bx * BLOCK), min(x1, bx * BLOCK + BLOCK - 1) + 1):
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
def above_excavation(ec, cstart, cfac, g0x, g0y, gs, gnx, gny, px, py, pz):
    """Is P on or above an excavation facet in vertical projection (the exact rule's space)?"""
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


# ---------------------------------------------------------------------------
# the packer


@njit(cache=True)
def _grow2(a, n):
    b = np.empty((n, a.shape[1]), a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _grow1(a, n, fill):
    b = np.full(n, fill, a.dtype)
    b[:a.shape[0]] = a
    return b


# zones (parallel packing of a constant radius): the region is cut across its longer horizontal
# axis into two halves A, B and a strip of half width w around the cut, itself in two sides
# SA, SB.  The packing rises in bands: A and B fill their pockets below the band's top at the same
# time, then the strip fills its own.  w is wide enough (see sgim/rpack.py) that a sphere placed
# in A reads and writes nothing that B reads or writes, so the result does not depend on the
# threads, only on the zones.  One zone (0) when not parallel.
ZSN, ZCN, ZNF, ZHN, ZBM = 0, 1, 2, 3, 4  # per zone: spheres, fresh candidate slots used, free slots, queued, lowest bucket
ST_DONE, ST_PAUSE, ST_FULL = 0, 1, 2


@njit(cache=True, inline="always")
def zone_of(ZG, x, y):
    """ZG = (parallel, axis, cut, half width): 0 (A), 1 (B), 2 (SA), 3 (SB); 0 when not parallel."""
    if ZG[0] == 0.0:
        return 0
    v = x if ZG[1] == 0.0 else y
    if v < ZG[2] - ZG[3]:
        return 0
    if v >= ZG[2] + ZG[3]:
        return 1
    return 2 if v < ZG[2] else 3


@njit(cache=True)
def _alloc_cand(kz, ZS, cbase, cend, CF, CI, cpl, freel, grow):
    """A candidate slot in zone kz (its free list first): (slot or -1 when full, arrays, grown
    when grow)."""
    if ZS[kz, ZNF] > 0:
        ZS[kz, ZNF] -= 1
        return freel[cbase[kz] + ZS[kz, ZNF]], CF, CI, cpl, freel
    c = cbase[kz] + ZS[kz, ZCN]
    if c == cend[kz]:
        if not grow:
            return -1, CF, CI, cpl, freel
        ncap = 2 * CF.shape[0]  # one zone: its range is the whole array
        CF = _grow2(CF, ncap)
        CI = _grow2(CI, ncap)
        cpl = _grow2(cpl, ncap)
        freel = _grow1(freel, ncap, 0)
        cend[kz] = ncap
    ZS[kz, ZCN] += 1
    return c, CF, CI, cpl, freel


@njit(cache=True, inline="always")
def _push_pocket(qx, qy, qz, rn, i, s1, s2, snx, sny, snz, sh, ZG, ZS, cbase, cend, CF, CI, cpl, freel, grow, bhead,
                 ohead, qz0, qinv, cnt):
    """Queue the pocket (q, rn) made by sphere i with supports s1, s2 (spheres, walls, or the
    stored plane (sn, sh) when s2 is SUP_PLANE0) in the zone of q.  Returns (slot or -1 when the
    zone is full, the arrays, grown when grow)."""
    kz = zone_of(ZG, qx, qy)
    cc, CF, CI, cpl, freel = _alloc_cand(kz, ZS, cbase, cend, CF, CI, cpl, freel, grow)
    if cc < 0:
        return cc, CF, CI, cpl, freel
    CI[cc, 9] = kz
    CF[cc, 0], CF[cc, 1], CF[cc, 2] = qx, qy, qz
    CF[cc, 3] = rn
    CI[cc, 3] = i + 1
    CI[cc, 0], CI[cc, 1], CI[cc, 2] = i, s1, s2
    if s2 == SUP_PLANE0:
        cpl[cc, 0], cpl[cc, 1], cpl[cc, 2], cpl[cc, 3] = snx, sny, snz, sh
    bq = q_bucket(qz, qz0, qinv, bhead.shape[1])
    q_push(bhead[kz], CI, ohead, cc, bq, i)
    ZS[kz, ZBM] = min(ZS[kz, ZBM], bq)
    ZS[kz, ZHN] += 1
    cnt[2] += 1
    return cc, CF, CI, cpl, freel


@njit(cache=True, inline="always")
def _free_cand(c, ZS, cbase, CI, freel):
    kz = CI[c, 9]
    freel[cbase[kz] + ZS[kz, ZNF]] = c
    ZS[kz, ZNF] += 1


@njit(cache=True, error_model="numpy")
def pack_init(lo, hi, tol, G, Dc, exc, mode, rconst, rseq, pool_size, grade, Dg, goff, discs, fseq,
               seeds, seed_r, X0, R0, cap0, ZG, zcap, zccap):
    """State of a pocket-filling packing (see sgim/rpack.py, _pack_kernel, for the loop that fills it).

    lo, hi      domain box; tol: overlap tolerance (fraction of the smaller radius)
    G           grid geometry (org, cs, dims, coff, rlo, rmax, bdims, boff)
    Dc          constraint meshes (sgim._meshq data; no mesh: roots of length 0)
    exc         excavation above-test: (ec, cell_start, cell_facets, g0x, g0y, gs, gnx, gny)
    mode        0 constant rconst; 1 radius sequence rseq through a pool of pool_size; 2 graded
    grade       (rf, rc, df, dc, spread) for mode 2; Dg, goff, discs = (centres, normals, radii,
                half thickness): the named objects; fseq: spread factors (mode 2)
    seeds       (k,3) seed positions, seed_r their radii (mode 2 recomputes them)
    X0, R0      spheres already placed (kept as they are; one zone only)
    cap0        sphere capacity (one zone: grows as needed)
    ZG          zones (see zone_of); zcap, zccap (4,): sphere and candidate room of each zone when
                parallel (fixed)
    Returns the state: spheres, grid, candidates, queues, zone counters, pool, the work arrays of
    two threads; CNT[0, 8] = 1 when the seeds do not fit a zone.
    """
    org, cs, dims, coff, rlo, rmax, bdims, boff = G
    rf, rc, df, dcg, spread = grade
    dcen, dnrm, drad, dhalf = discs
    has_mesh = Dc[12].shape[0] > 0
    nz = 4 if ZG[0] != 0.0 else 1
    grow = nz == 1

    sbase = np.zeros(nz, np.int64)
    send = np.zeros(nz, np.int64)
    cbase = np.zeros(nz, np.int64)
    cend = np.zeros(nz, np.int64)
    if nz == 1:
        send[0] = max(cap0, X0.shape[0] + 16)
        cend[0] = max(1024, 4 * seeds.shape[0] + 4096)
    else:
        for k in range(nz):
            sbase[k] = send[k - 1] if k > 0 else 0
            send[k] = sbase[k] + zcap[k]
            cbase[k] = cend[k - 1] if k > 0 else 0
            cend[k] = cbase[k] + zccap[k]
    cap = send[nz - 1]
    ccap = cend[nz - 1]
    X = np.empty((cap, 3))
    R = np.empty(cap)
    XR = np.empty((cap, 4))  # X and R side by side for the grid kernels
    DGL = np.zeros(cap)  # bounds of the grading distance of each sphere (mode 2)
    DGH = np.zeros(cap)
    nxt = np.full(cap, -1, np.int32)
    FP = np.zeros((cap, 4))  # each sphere's tangent plane on the nearest constraint surface
    FPk = np.full(cap, -1, np.int8)  # its mesh (-1: none within reach)
    head = np.full(coff[-1], -1, np.int32)
    bcnt = np.zeros(boff[-1], np.int32)
    ZS = np.zeros((nz, 8), np.int64)
    n = 0
    for i in range(X0.shape[0]):
        X[n] = X0[i]
        R[n] = R0[i]
        XR[n, 0], XR[n, 1], XR[n, 2], XR[n, 3] = X0[i, 0], X0[i, 1], X0[i, 2], R0[i]
        if mode == 2:
            DGL[n] = near_distance(Dg, goff, dcen, dnrm, drad, dhalf, X0[i, 0], X0[i, 1], X0[i, 2], dcg)
            DGH[n] = DGL[n] if DGL[n] < dcg else BIG
        grid_insert(org, cs, dims, coff, rlo, bdims, boff, head, nxt, bcnt, n, X[n, 0], X[n, 1], X[n, 2], R[n])
        if has_mesh:
            reach = 3.0 * R[n]
            best2 = np.inf
            for k in range(min(Dc[12].shape[0], 64)):
                if not MQ.in_root_box(Dc, k, X[n, 0], X[n, 1], X[n, 2], reach):
                    continue
                d2, qx, qy, qz, f, reg = MQ.closest_point(Dc, k, X[n, 0], X[n, 1], X[n, 2], reach * reach)
                if f >= 0 and 0.0 < d2 < best2:
                    best2 = d2
                    dd = math.sqrt(d2)
                    FP[n, 0], FP[n, 1], FP[n, 2] = (X[n, 0] - qx) / dd, (X[n, 1] - qy) / dd, (X[n, 2] - qz) / dd
                    FP[n, 3] = FP[n, 0] * qx + FP[n, 1] * qy + FP[n, 2] * qz
                    FPk[n] = k
        n += 1
    n_initial = n
    ZS[0, ZSN] = n

    # candidates
    # a candidate in two rows: CF position and radius; CI supports (3), the number of spheres
    # when it was made, its queue links (bucket, next, previous; creator's list next, previous)
    # and its zone (9)
    CF = np.empty((ccap, 4))
    CI = np.empty((ccap, 16), np.int32)
    cpl = np.empty((ccap, 8))
    freel = np.empty(ccap, np.int64)
    # the queue of each zone (see q_push): bucket of each candidate, links in its bucket and on its
    # creator's list
    ohead = np.full(cap, -1, np.int32)  # each sphere's newest queued candidate
    qz0 = lo[2] - 4.0 * rmax[-1]
    qspan = hi[2] - qz0 + 4.0 * rmax[-1]
    nbk = min(int(qspan / (QRES * rmax[0])) + 2, 1 << 22)
    qinv = (nbk - 2) / qspan
    bhead = np.full((nz, nbk), -1, np.int64)
    for k in range(nz):
        ZS[k, ZBM] = nbk - 1

    # pool of radii (mode 1), sorted descending; MS: pooled radii, next draw, spread factors used
    pool = np.empty(max(pool_size, 1))
    MS = np.zeros(4, np.int64)
    if mode == 1:
        while MS[0] < pool_size and MS[1] < rseq.shape[0]:
            v = rseq[MS[1]]
            MS[1] += 1
            p = MS[0]
            while p > 0 and pool[p - 1] < v:
                pool[p] = pool[p - 1]
                p -= 1
            pool[p] = v
            MS[0] += 1

    # work arrays of the two threads
    nbcap = 4096
    NB = np.empty((2, nbcap), np.int64)
    NBX = np.empty((2, nbcap, 3))
    NBR = np.empty((2, nbcap))
    NBH = np.empty((2, nbcap), np.int64)
    NT = np.empty((2, 6, nbcap))  # per neighbour, for the (S, A, B) pockets (see there)
    SQ = np.empty((2, 7, PCAP))
    PP = np.empty((2, 2, PCAP), np.int32)  # the pairs (A, B) of a chunk
    OUT = np.empty((2, 4, 3))
    npl_cap = 6 + 64 + 256
    PL = np.empty((2, npl_cap, 4))  # planes near the new sphere: nx ny nz h (kept side: n.x >= h)
    PLID = np.empty((2, npl_cap), np.int64)
    PLOWN = np.full((2, npl_cap), -1, np.int64)  # -1: for every neighbour; a: only for neighbour a
    # counters of each zone: pops, placed, pockets pushed, pop rejects, seeds placed, -, -, covered
    CNT = np.zeros((nz, 9), np.int64)

    for s in range(seeds.shape[0]):
        kz = zone_of(ZG, seeds[s, 0], seeds[s, 1])
        c, CF, CI, cpl, freel = _alloc_cand(kz, ZS, cbase, cend, CF, CI, cpl, freel, grow)
        if c < 0:
            CNT[0, 8] = 1
            break
        CF[c, 0], CF[c, 1], CF[c, 2] = seeds[s, 0], seeds[s, 1], seeds[s, 2]
        CF[c, 3] = seed_r[s]
        CI[c, 3] = 0
        CI[c, 0] = SUP_NONE
        CI[c, 1] = SUP_NONE
        CI[c, 2] = SUP_NONE
        CI[c, 9] = kz
        # seeds go by the height of the floor under them (not of their centre: no sifting by
        # radius) and before the pockets at the same height
        b = q_bucket(seeds[s, 2] - seed_r[s] - 1e-9 * (abs(seeds[s, 2]) + seed_r[s]), qz0, qinv, nbk)
        q_push(bhead[kz], CI, ohead, c, b, -1)
        ZS[kz, ZBM] = min(ZS[kz, ZBM], b)
        ZS[kz, ZHN] += 1

    return (X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, head, bcnt, CF, CI, cpl, freel, bhead, ZS, sbase, send, cbase,
            cend, CNT, MS, pool, qz0, qinv, n_initial,
            (NB[0], NBX[0], NBR[0], NBH[0], NT[0], SQ[0], PP[0], OUT[0], PL[0], PLID[0], PLOWN[0]),
            (NB[1], NBX[1], NBR[1], NBH[1], NT[1], SQ[1], PP[1], OUT[1], PL[1], PLID[1], PLOWN[1]))


@njit(cache=True)
def lowest_bucket(ZS, bhead):
    """Lowest queued bucket over all zones (-1: none queued)."""
    lowest = -1
    for k in range(ZS.shape[0]):
        if ZS[k, ZHN] > 0:
            while bhead[k, ZS[k, ZBM]] < 0:
                ZS[k, ZBM] += 1
            if lowest < 0 or ZS[k, ZBM] < lowest:
                lowest = ZS[k, ZBM]
    return lowest


@njit(cache=True)
def pack_finish(X, R, DGL, ZS, sbase, CNT, MS, n_initial):
    """The packing's spheres, zone by zone, and its counters."""
    nz = ZS.shape[0]
    cnt = np.zeros(9, np.int64)
    for k in range(nz):
        for q in range(9):
            cnt[q] += CNT[k, q]
    cnt[5] = n_initial
    cnt[6] = MS[0]
    ntot = 0
    for k in range(nz):
        ntot += ZS[k, ZSN]
    Xo = np.empty((ntot, 3))
    Ro = np.empty(ntot)
    Do = np.empty(ntot)
    o = 0
    for k in range(nz):
        for i in range(sbase[k], sbase[k] + ZS[k, ZSN]):
            Xo[o, 0], Xo[o, 1], Xo[o, 2] = X[i, 0], X[i, 1], X[i, 2]
            Ro[o] = R[i]
            Do[o] = DGL[i]
            o += 1
    return Xo, Ro, Do, cnt


@njit(cache=True, error_model="numpy", nogil=True)
def fill(z0, z1, bz, budget, grow, args, X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, head, bcnt, CF, CI, cpl, freel,
         bhead, ZS, ZG, sbase, send, cbase, cend, CNT, MS, pool, qz0, qinv, W):
    """Fill the pockets of zones z0..z1 below bucket bz, lowest first, for at most budget spheres.
    Returns (status, the arrays, grown when grow)."""
    lo, hi, tol, G, Dc, exc, mode, rconst, rseq, grade, Dg, goff, discs, fseq = args
    nb, nbx, nbr, nbh, NT, SQ, PP, OUT, pl, plid, plown = W
    nU, nV, nW, nUU, nKU, nL2 = NT[0], NT[1], NT[2], NT[3], NT[4], NT[5]
    PA, PB = PP[0], PP[1]
    out, out2 = OUT[0:2], OUT[2:4]
    org, cs, dims, coff, rlo, rmax, bdims, boff = G
    ec, cstart, cfac, g0x, g0y, gs, gnx, gny = exc
    rf, rc, df, dcg, spread = grade
    dcen, dnrm, drad, dhalf = discs
    has_mesh = Dc[12].shape[0] > 0
    check_region = has_mesh or gnx > 0
    tiny_tol = tol < 1e-9
    nbcap = nb.shape[0]
    cnt = CNT[z0]
    npool, iseq, ifac = MS[0], MS[1], MS[2]
    pdl, pdh = 0.0, 0.0
    stop = cnt[1] + budget
    status = ST_DONE
    while True:
        if cnt[1] >= stop:
            status = ST_PAUSE
            break
        kp = -1
        bb = bz
        for k in range(z0, z1 + 1):
            if ZS[k, ZHN] > 0:
                bm = ZS[k, ZBM]
                while bhead[k, bm] < 0:
                    bm += 1
                ZS[k, ZBM] = bm
                if bm < bb:
                    bb = bm
                    kp = k
        if kp < 0:
            break
        c = bhead[kp, bb]
        q_remove(bhead[kp], CI, ohead, c, CI[c, 0])
        ZS[kp, ZHN] -= 1
        _free_cand(c, ZS, cbase, CI, freel)
        cnt[0] += 1
        r0 = CF[c, 3]
        px, py, pz = 0.0, 0.0, 0.0
        placed = False
        rr = r0
        # --- choose the radius and the exact position ---------------------------------
        seed = CI[c, 0] == SUP_NONE
        if mode != 0 and not seed:
            # a pocket that the spheres placed since it was made fill for its own radius is gone
            # for the others too (most pops end here, without trying other radii)
            if grid_overlaps(org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, XR, CF[c, 0], CF[c, 1],
                             CF[c, 2], r0, tol, CI[c, 3]):
                cnt[3] += 1
                continue
        ntry = npool if (mode == 1 and not seed) else 1
        for t in range(ntry):
            px, py, pz = CF[c, 0], CF[c, 1], CF[c, 2]
            if mode == 0 or seed:
                rr = r0  # seeds keep the radius they were made with
            elif mode == 1:
                rr = pool[t]
                if rr != r0:
                    if not _reposition(CI, cpl, c, X, R, lo, hi, rr, CF, out):
                        continue
                    px, py, pz = out[0, 0], out[0, 1], out[0, 2]
            else:
                fac = fseq[ifac % fseq.shape[0]] if fseq.shape[0] > 0 else 1.0
                rr = r0
                ok = True
                # the distance is 1-Lipschitz: from the creating sphere's bounds, |P - S| <= R_S + rmax
                sS = CI[c, 0]
                dlo, dhi = -1.0, BIG
                if sS >= 0:
                    dlo = DGL[sS] - (R[sS] + rc * (1.0 + spread))
                    dhi = DGH[sS] + R[sS] + rc * (1.0 + spread)
                if dlo >= dcg or dhi <= df:
                    rnew = (rc if dlo >= dcg else rf) * fac
                    if rnew != rr:
                        rr = rnew
                        if not _reposition(CI, cpl, c, X, R, lo, hi, rr, CF, out):
                            break
                        px, py, pz = out[0, 0], out[0, 1], out[0, 2]
                    pdl, pdh = max(dlo, 0.0), dhi
                else:
                    # fixed point r = law(d(P(r))) * factor, damped after a few rounds; a pocket
                    # where it does not settle is dropped (its radius would not follow the law)
                    conv = False
                    for it in range(40):
                        d = near_distance(Dg, goff, dcen, dnrm, drad, dhalf, px, py, pz, dcg)
                        pdl, pdh = d, d
                        rnew = grade_radius(d, rf, rc, df, dcg) * fac
                        if abs(rnew - rr) <= 1e-12 * rnew:
                            conv = True
                            break
                        rr = rnew if it < 10 else rr + 0.5 * (rnew - rr)
                        if not _reposition(CI, cpl, c, X, R, lo, hi, rr, CF, out):
                            break
                        px, py, pz = out[0, 0], out[0, 1], out[0, 2]
                    if not conv:
                        break
            moved = rr != r0
            if moved or CI[c, 0] == SUP_NONE:
                if not in_box(lo, hi, px, py, pz, rr, tol):
                    continue
                if check_region and not _region_ok(px, py, pz, rr, tol, has_mesh, Dc, ec, cstart, cfac, g0x, g0y,
                                                   gs, gnx, gny):
                    continue
            stamp = 0 if moved else CI[c, 3]
            # a constant-radius pocket still queued is clear: the spheres placed since it was made
            # removed it if they covered it (see the covering step below)
            if not (mode == 0 and not seed) and grid_overlaps(org, cs, dims, coff, rmax, bdims, boff, head, nxt,
                                                              bcnt, XR, px, py, pz, rr, tol, stamp):
                continue
            placed = True
            if mode == 1 and not seed:
                for q in range(t, npool - 1):
                    pool[q] = pool[q + 1]
                npool -= 1
                if iseq < rseq.shape[0]:
                    v = rseq[iseq]
                    iseq += 1
                    p = npool
                    while p > 0 and pool[p - 1] < v:
                        pool[p] = pool[p - 1]
                        p -= 1
                    pool[p] = v
                    npool += 1
            break
        if not placed:
            cnt[3] += 1
            continue
        # --- place ---------------------------------------------------------------
        i = sbase[kp] + ZS[kp, ZSN]
        if i == send[kp]:
            if not grow:
                return ST_FULL, X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, CF, CI, cpl, freel
            cap = X.shape[0] + X.shape[0] // 2 + 16  # one zone: its range is the whole array
            X = _grow2(X, cap)
            XR = _grow2(XR, cap)
            R = _grow1(R, cap, 0.0)
            DGL = _grow1(DGL, cap, 0.0)
            DGH = _grow1(DGH, cap, 0.0)
            nxt = _grow1(nxt, cap, -1)
            FP = _grow2(FP, cap)
            FPk = _grow1(FPk, cap, -1)
            ohead = _grow1(ohead, cap, -1)
            send[kp] = cap
        ZS[kp, ZSN] += 1
        X[i, 0], X[i, 1], X[i, 2] = px, py, pz
        R[i] = rr
        XR[i, 0], XR[i, 1], XR[i, 2], XR[i, 3] = px, py, pz, rr
        if mode == 2:
            if not seed:
                ifac += 1
            if seed:
                pdl = near_distance(Dg, goff, dcen, dnrm, drad, dhalf, px, py, pz, dcg)
                pdh = pdl if pdl < dcg else BIG
            DGL[i], DGH[i] = pdl, (pdh if pdh < dcg else BIG)
        grid_insert(org, cs, dims, coff, rlo, bdims, boff, head, nxt, bcnt, i, px, py, pz, rr)
        cnt[1] += 1
        if CI[c, 0] == SUP_NONE:
            cnt[4] += 1

        # --- new pockets ---------------------------------------------------------
        if mode == 0:
            rn = rconst
        elif mode == 1:
            if npool == 0:
                continue
            rn = pool[npool - 1]
        else:
            rn = grade_radius(DGL[i], rf, rc, df, dcg) * (1.0 - spread)
        m = grid_gather(org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, XR, px, py, pz,
                        rr + 2.0 * rn, nb, nbcap, i)
        # remove the queued pockets the new sphere covers.  A pocket Q of radius rq made by sphere
        # j touches it (|Q - x_j| = r_j + rq); covered, |Q - P| < rr + rq, so |P - x_j| < rr + r_j + 2 rq:
        # j is among the neighbours gathered when rq <= rn (always for a constant radius)
        for a in range(m):
            c2 = ohead[nb[a]]
            while c2 >= 0:
                c3 = CI[c2, 7]
                rq = CF[c2, 3]
                dx = CF[c2, 0] - px
                dy = CF[c2, 1] - py
                dz = CF[c2, 2] - pz
                lim = rq + rr - tol * min(rq, rr)
                if dx * dx + dy * dy + dz * dz < lim * lim:
                    kq = CI[c2, 9]
                    q_remove(bhead[kq], CI, ohead, c2, nb[a])
                    ZS[kq, ZHN] -= 1
                    _free_cand(c2, ZS, cbase, CI, freel)
                    cnt[7] += 1
                c2 = c3
        # the nearest neighbour first: it excludes the most pocket directions (tried before the others)
        best = BIG
        ab = 0
        for a in range(m):
            j = nb[a]
            dj = (XR[j, 0] - px) ** 2 + (XR[j, 1] - py) ** 2 + (XR[j, 2] - pz) ** 2 - (XR[j, 3] + rr) ** 2
            if dj < best:
                best = dj
                ab = a
        if m > 0:
            j = nb[ab]
            nb[ab] = nb[0]
            nb[0] = j
        for a in range(m):
            j = nb[a]
            nbx[a, 0], nbx[a, 1], nbx[a, 2] = XR[j, 0], XR[j, 1], XR[j, 2]
            nbr[a] = XR[j, 3]
        # planes near the new sphere
        npl = 0
        for w in range(6):
            ax = w // 2
            if w % 2 == 0:
                hgt = X[i, ax] - lo[ax]
            else:
                hgt = hi[ax] - X[i, ax]
            if hgt < rr + 2.0 * rn:
                pl[npl, 0], pl[npl, 1], pl[npl, 2] = 0.0, 0.0, 0.0
                if w % 2 == 0:
                    pl[npl, ax] = 1.0
                    pl[npl, 3] = lo[ax]
                else:
                    pl[npl, ax] = -1.0
                    pl[npl, 3] = -hi[ax]
                plid[npl] = -1 - w
                npl += 1
        for p in range(npl):
            plown[p] = -1
        if has_mesh:
            reach = rr + 2.0 * rn
            best2 = np.inf
            for k in range(min(Dc[12].shape[0], 64)):
                if not MQ.in_root_box(Dc, k, px, py, pz, reach):
                    continue
                d2, qx, qy, qz, f, reg = MQ.closest_point(Dc, k, px, py, pz, reach * reach)
                if f < 0 or d2 <= 0.0:
                    continue
                dd = math.sqrt(d2)
                pl[npl, 0], pl[npl, 1], pl[npl, 2] = (px - qx) / dd, (py - qy) / dd, (pz - qz) / dd
                pl[npl, 3] = pl[npl, 0] * qx + pl[npl, 1] * qy + pl[npl, 2] * qz
                plid[npl] = SUP_PLANE0
                plown[npl] = -1
                if d2 < best2:  # the sphere's own tangent plane, for the pockets of later neighbours
                    best2 = d2
                    FP[i, 0], FP[i, 1], FP[i, 2], FP[i, 3] = pl[npl, 0], pl[npl, 1], pl[npl, 2], pl[npl, 3]
                    FPk[i] = k
                npl += 1
            # the tangent planes of the neighbours (a curved or kinked surface: the pocket touching S,
            # A and the surface may rest on the part of the surface nearest to A, not to S)
            npl0 = npl
            for a in range(m):
                ja = nb[a]
                if FPk[ja] < 0 or npl == pl.shape[0]:
                    continue
                same = False
                for p in range(npl0):
                    if plid[p] == SUP_PLANE0 and pl[p, 0] * FP[ja, 0] + pl[p, 1] * FP[ja, 1] + pl[p, 2] * FP[ja, 2] \
                            > 1.0 - 1e-9 and abs(pl[p, 3] - FP[ja, 3]) <= 1e-9 * (1.0 + abs(FP[ja, 3])):
                        same = True
                if same or FP[ja, 0] * px + FP[ja, 1] * py + FP[ja, 2] * pz - FP[ja, 3] >= rr + 2.0 * rn:
                    continue
                pl[npl, 0], pl[npl, 1], pl[npl, 2], pl[npl, 3] = FP[ja, 0], FP[ja, 1], FP[ja, 2], FP[ja, 3]
                plid[npl] = SUP_PLANE0
                plown[npl] = a
                npl += 1

        # (S, A, B)
        zcut = pz - DEEP * (rr + rn)
        # per neighbour (structure of arrays): position relative to S, |.|^2, the term of the
        # pocket solve that depends on one neighbour only, the squared clearance limit for rn
        ds = rr + rn
        ds2 = ds * ds
        for a in range(m):
            ua, va, wa = nbx[a, 0] - px, nbx[a, 1] - py, nbx[a, 2] - pz
            nU[a], nV[a], nW[a] = ua, va, wa
            uua = ua * ua + va * va + wa * wa
            nUU[a] = uua
            dba = nbr[a] + rn
            nKU[a] = 0.5 * (ds2 + uua - dba * dba)
            lm = rn + nbr[a] - tol * min(rn, nbr[a])
            nL2[a] = lm * lm
        # the box shrunk by rn (allowance tol rn), relative to S
        bxlo, bxhi = lo[0] + rn - tol * rn - px, hi[0] - rn + tol * rn - px
        bylo, byhi = lo[1] + rn - tol * rn - py, hi[1] - rn + tol * rn - py
        bzlo, bzhi = lo[2] + rn - tol * rn - pz, hi[2] - rn + tol * rn - pz
        # neighbours above zcut, in order: a neighbour below it pairs only with these
        nhigh = 0
        for a in range(m):
            nbh[nhigh] = a
            nhigh += nW[a] + pz >= zcut
        # pad the neighbour terms to a multiple of PAD with far-away dummies (the clearance loop
        # below then runs whole vector lengths, no remainder)
        mp = min((m + PAD - 1) // PAD * PAD, nbcap)
        for e in range(m, mp):
            nU[e], nV[e], nW[e], nL2[e] = 1e100, 0.0, 0.0, 0.0
        # the pairs (A, B), A < B, within reach of each other, in chunks of at most PCAP: first
        # listed without a branch, then solved in one loop, then checked
        hp = 0  # nbh[hp:] are the neighbours above zcut with an index > a
        a0 = 0
        while a0 < m:
            npb = 0
            while a0 < m and npb + m - a0 <= PCAP:
                a = a0
                a0 += 1
                while hp < nhigh and nbh[hp] <= a:
                    hp += 1
                ux, uy, uz = nU[a], nV[a], nW[a]
                ra2 = nbr[a] + 2.0 * rn
                alow = uz + pz < zcut
                nbt = (nhigh - hp) if alow else (m - a - 1)
                for t in range(nbt):
                    b = nbh[hp + t] if alow else a + 1 + t
                    lim = ra2 + nbr[b]
                    PA[npb] = a
                    PB[npb] = b
                    npb += (ux - nU[b]) ** 2 + (uy - nV[b]) ** 2 + (uz - nW[b]) ** 2 < lim * lim
            for t in range(npb, (npb + PAD - 1) // PAD * PAD):
                PA[t] = 0  # A = B: no pocket
                PB[t] = 0
            # the pockets |Q| = ds, |Q - A| = ra + rn, |Q - B| = rb + rn (Q relative to S):
            # Q = al A + be B +- g (A x B); none (g < 0) where g2 < 0 or A, B are aligned with S
            for t in range((npb + PAD - 1) // PAD * PAD):
                a = PA[t]
                b = PB[t]
                ux, uy, uz, uu, ku = nU[a], nV[a], nW[a], nUU[a], nKU[a]
                vx, vy, vz, vv, kv = nU[b], nV[b], nW[b], nUU[b], nKU[b]
                uv = ux * vx + uy * vy + uz * vz
                nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
                det = nx * nx + ny * ny + nz * nz
                idet = 1.0 / max(det, 1e-300)
                al = (ku * vv - kv * uv) * idet
                be = (kv * uu - ku * uv) * idet
                g2 = (ds2 - al * ku - be * kv) * idet
                gg = math.sqrt(max(g2, 0.0))
                g = gg if ((det > 1e-12 * uu * vv) & (g2 >= 0.0)) else -1.0
                SQ[0, t] = al * ux + be * vx
                SQ[1, t] = al * uy + be * vy
                SQ[2, t] = al * uz + be * vz
                SQ[3, t] = g * nx
                SQ[4, t] = g * ny
                SQ[5, t] = g * nz
                SQ[6, t] = g
            for t in range(npb):
                if SQ[6, t] < 0.0:
                    continue
                a = PA[t]
                b = PB[t]
                for q in range(2):
                    if q == 0:
                        qx, qy, qz = SQ[0, t] + SQ[3, t], SQ[1, t] + SQ[4, t], SQ[2, t] + SQ[5, t]
                    else:
                        qx, qy, qz = SQ[0, t] - SQ[3, t], SQ[1, t] - SQ[4, t], SQ[2, t] - SQ[5, t]
                    if not (bxlo <= qx <= bxhi and bylo <= qy <= byhi and bzlo <= qz <= bzhi):
                        continue
                    # clear of every neighbour: the nearest first, then all of them without a branch
                    # (A and B touch Q, tol min(r) beyond the limit: they never count unless tol is
                    # near the rounding error, where they are left out by name)
                    if not tiny_tol and (nU[0] - qx) ** 2 + (nV[0] - qy) ** 2 + (nW[0] - qz) ** 2 < nL2[0]:
                        continue
                    nblk = 0
                    for e in range(mp):
                        dx = nU[e] - qx
                        dy = nV[e] - qy
                        dz = nW[e] - qz
                        nblk += dx * dx + dy * dy + dz * dz < nL2[e]
                    if nblk > 0 and tiny_tol:
                        nblk = 0
                        for e in range(m):
                            if e != a and e != b and (nU[e] - qx) ** 2 + (nV[e] - qy) ** 2 + (nW[e] - qz) ** 2 < nL2[e]:
                                nblk += 1
                    if nblk > 0:
                        continue
                    qx, qy, qz = qx + px, qy + py, qz + pz
                    if check_region and not _region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, ec, cstart, cfac, g0x,
                                                       g0y, gs, gnx, gny):
                        continue
                    cc, CF, CI, cpl, freel = _push_pocket(qx, qy, qz, rn, i, nb[a], nb[b], 0.0, 0.0, 0.0, 0.0, ZG, ZS,
                                                          cbase, cend, CF, CI, cpl, freel, grow, bhead, ohead, qz0,
                                                          qinv, cnt)
                    if cc < 0:
                        return ST_FULL, X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, CF, CI, cpl, freel
        # (S, A, plane) and (S, plane, plane)
        for p in range(npl):
            nx_, ny_, nz_, h0 = pl[p, 0], pl[p, 1], pl[p, 2], pl[p, 3]
            for a in range(m):
                if plown[p] >= 0 and plown[p] != a:
                    continue
                ax_, ay_, az_, ra = nbx[a, 0], nbx[a, 1], nbx[a, 2], nbr[a]
                if nx_ * ax_ + ny_ * ay_ + nz_ * az_ - h0 >= ra + 2.0 * rn:
                    continue
                k2 = pocket_ssp(px, py, pz, rr + rn, ax_, ay_, az_, ra + rn, nx_, ny_, nz_, h0 + rn, out)
                for q in range(k2):
                    qx, qy, qz = out[q, 0], out[q, 1], out[q, 2]
                    if not (in_box(lo, hi, qx, qy, qz, rn, tol) and _clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, a, -1)):
                        continue
                    snx, sny, snz, sh = nx_, ny_, nz_, h0
                    if check_region and not _region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, ec, cstart, cfac, g0x,
                                                       g0y, gs, gnx, gny):
                        if plid[p] != SUP_PLANE0:
                            continue
                        ok, qx, qy, qz, snx, sny, snz, sh = _refine(0, px, py, pz, rr + rn, ax_, ay_, az_, ra + rn,
                                                                    0.0, 0.0, 0.0, 0.0, nx_, ny_, nz_, h0, rn, tol,
                                                                    qx, qy, qz, Dc, out2)
                        if not ok or not (in_box(lo, hi, qx, qy, qz, rn, tol)
                                          and _clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, a, -1)):
                            continue
                        if gnx > 0 and above_excavation(ec, cstart, cfac, g0x, g0y, gs, gnx, gny, qx, qy, qz):
                            continue
                    cc, CF, CI, cpl, freel = _push_pocket(qx, qy, qz, rn, i, nb[a], plid[p], snx, sny, snz, sh, ZG,
                                                          ZS, cbase, cend, CF, CI, cpl, freel, grow, bhead, ohead, qz0,
                                                          qinv, cnt)
                    if cc < 0:
                        return ST_FULL, X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, CF, CI, cpl, freel
            for p2 in range(p + 1, npl):
                if (plid[p] == SUP_PLANE0 and plid[p2] == SUP_PLANE0) or plown[p] >= 0 or plown[p2] >= 0:
                    continue
                mx_, my_, mz_, h1 = pl[p2, 0], pl[p2, 1], pl[p2, 2], pl[p2, 3]
                k2 = pocket_spp(px, py, pz, rr + rn, nx_, ny_, nz_, h0 + rn, mx_, my_, mz_, h1 + rn, out)
                sp = p if plid[p] == SUP_PLANE0 else p2  # the surface plane, if any
                for q in range(k2):
                    qx, qy, qz = out[q, 0], out[q, 1], out[q, 2]
                    if not (in_box(lo, hi, qx, qy, qz, rn, tol) and _clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, -1, -1)):
                        continue
                    snx, sny, snz, sh = pl[sp, 0], pl[sp, 1], pl[sp, 2], pl[sp, 3]
                    if check_region and not _region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, ec, cstart, cfac, g0x,
                                                       g0y, gs, gnx, gny):
                        if plid[sp] != SUP_PLANE0:
                            continue
                        wp = p2 if sp == p else p
                        ok, qx, qy, qz, snx, sny, snz, sh = _refine(1, px, py, pz, rr + rn, 0.0, 0.0, 0.0, 0.0,
                                                                    pl[wp, 0], pl[wp, 1], pl[wp, 2], pl[wp, 3] + rn,
                                                                    snx, sny, snz, sh, rn, tol, qx, qy, qz, Dc, out2)
                        if not ok or not (in_box(lo, hi, qx, qy, qz, rn, tol)
                                          and _clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, -1, -1)):
                            continue
                        if gnx > 0 and above_excavation(ec, cstart, cfac, g0x, g0y, gs, gnx, gny, qx, qy, qz):
                            continue
                    # a wall first, then the other support (a wall or the stored plane)
                    w1, w2 = plid[p], plid[p2]
                    if w1 == SUP_PLANE0:
                        w1, w2 = w2, w1
                    cc, CF, CI, cpl, freel = _push_pocket(qx, qy, qz, rn, i, w1, w2, snx, sny, snz, sh, ZG, ZS, cbase,
                                                          cend, CF, CI, cpl, freel, grow, bhead, ohead, qz0, qinv, cnt)
                    if cc < 0:
                        return ST_FULL, X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, CF, CI, cpl, freel
    if grow:  # one zone (a radius law or a grading: their pool and draws are sequential)
        MS[0], MS[1], MS[2] = npool, iseq, ifac
    return status, X, R, XR, DGL, DGH, nxt, FP, FPk, ohead, CF, CI, cpl, freel


@njit(cache=True, inline="always")
def _clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, a, b):
    """The new pocket overlaps none of the new sphere's neighbours except a and b (complete: any
    sphere that overlaps it is a neighbour of the new sphere)."""
    for e in range(m):
        if e == a or e == b:
            continue
        dx = nbx[e, 0] - qx
        dy = nbx[e, 1] - qy
        dz = nbx[e, 2] - qz
        lim = rn + nbr[e] - tol * min(rn, nbr[e])
        if dx * dx + dy * dy + dz * dz < lim * lim:
            return False
    return True


@njit(cache=True)
def _region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, ec, cstart, cfac, g0x, g0y, gs, gnx, gny):
    """The constraint meshes and the excavation test."""
    if has_mesh and mesh_clear(Dc, qx, qy, qz, rn, tol) >= 0:
        return False
    if gnx > 0 and above_excavation(ec, cstart, cfac, g0x, g0y, gs, gnx, gny, qx, qy, qz):
        return False
    return True


@njit(cache=True)
def _refine(kind, sx, sy, sz, ds, ax, ay, az, da, mx, my, mz, hm, nx, ny, nz, h0, rn, tol, qx, qy, qz, Dc,
            out2):
    """A pocket against a curved constraint surface: replace the tangent plane (n, h0) by the
    tangent plane at the pocket's own foot point until the pocket clears every mesh (at most
    four rounds).  The other support is sphere a (kind 0, contact distance da) or the plane
    m.P = hm (kind 1, already offset).  Returns (ok, qx, qy, qz, nx, ny, nz, h0)."""
    for it in range(5):
        km = mesh_clear(Dc, qx, qy, qz, rn, tol)
        if km < 0:
            return True, qx, qy, qz, nx, ny, nz, h0
        if it == 4:
            break
        d2, fx, fy, fz, f, reg = MQ.closest_point(Dc, km, qx, qy, qz, np.inf)
        if f < 0 or d2 <= 0.0:
            break
        dd = math.sqrt(d2)
        tx, ty, tz = (qx - fx) / dd, (qy - fy) / dd, (qz - fz) / dd
        if tx * nx + ty * ny + tz * nz < 0.0:  # the pocket crossed the surface
            tx, ty, tz = -tx, -ty, -tz
        nx, ny, nz = tx, ty, tz
        h0 = tx * fx + ty * fy + tz * fz
        if kind == 0:
            k = pocket_ssp(sx, sy, sz, ds, ax, ay, az, da, nx, ny, nz, h0 + rn, out2)
        else:
            k = pocket_spp(sx, sy, sz, ds, nx, ny, nz, h0 + rn, mx, my, mz, hm, out2)
        if k == 0:
            break
        e0 = (out2[0, 0] - qx) ** 2 + (out2[0, 1] - qy) ** 2 + (out2[0, 2] - qz) ** 2
        e1 = (out2[1, 0] - qx) ** 2 + (out2[1, 1] - qy) ** 2 + (out2[1, 2] - qz) ** 2
        w = 0 if e0 <= e1 else 1
        qx, qy, qz = out2[w, 0], out2[w, 1], out2[w, 2]
    return False, qx, qy, qz, nx, ny, nz, h0


@njit(cache=True, error_model="numpy")
def _support_plane(sup, cpl, c, k, lo, hi):
    """Plane (n, h) of support code sup (a wall or stored plane k)."""
    if sup == SUP_PLANE0 or sup == SUP_PLANE1:
        o = 0 if sup == SUP_PLANE0 else 4
        return cpl[c, o], cpl[c, o + 1], cpl[c, o + 2], cpl[c, o + 3]
    w = -1 - sup
    ax = w // 2
    n = np.zeros(3)
    if w % 2 == 0:
        n[ax] = 1.0
        return n[0], n[1], n[2], lo[ax]
    n[ax] = -1.0
    return n[0], n[1], n[2], -hi[ax]


@njit(cache=True, error_model="numpy")
def _reposition(csup, cpl, c, X, R, lo, hi, r, cpos, out):
    """Position of candidate c's pocket for radius r (the solution nearest its stored position),
    written to out[0]; False when the pocket does not exist for r."""
    s0, s1, s2 = csup[c, 0], csup[c, 1], csup[c, 2]
    if s0 == SUP_NONE:
        out[0, 0], out[0, 1], out[0, 2] = cpos[c, 0], cpos[c, 1], cpos[c, 2]
        return True
    k = 0
    if s1 >= 0 and s2 >= 0:
        k = pocket_sss(X[s0, 0], X[s0, 1], X[s0, 2], R[s0] + r, X[s1, 0], X[s1, 1], X[s1, 2], R[s1] + r,
                       X[s2, 0], X[s2, 1], X[s2, 2], R[s2] + r, out)
    elif s1 >= 0:
        nx, ny, nz, h = _support_plane(s2, cpl, c, 0, lo, hi)
        k = pocket_ssp(X[s0, 0], X[s0, 1], X[s0, 2], R[s0] + r, X[s1, 0], X[s1, 1], X[s1, 2], R[s1] + r,
                       nx, ny, nz, h + r, out)
    else:
        nx, ny, nz, h = _support_plane(s1, cpl, c, 0, lo, hi)
        mx, my, mz, h2 = _support_plane(s2, cpl, c, 0, lo, hi)
        k = pocket_spp(X[s0, 0], X[s0, 1], X[s0, 2], R[s0] + r, nx, ny, nz, h + r, mx, my, mz, h2 + r, out)
    if k == 0:
        return False
    d0 = (out[0, 0] - cpos[c, 0]) ** 2 + (out[0, 1] - cpos[c, 1]) ** 2 + (out[0, 2] - cpos[c, 2]) ** 2
    d1 = (out[1, 0] - cpos[c, 0]) ** 2 + (out[1, 1] - cpos[c, 1]) ** 2 + (out[1, 2] - cpos[c, 2]) ** 2
    if d1 < d0:
        out[0, 0], out[0, 1], out[0, 2] = out[1, 0], out[1, 1], out[1, 2]
    return True


# ---------------------------------------------------------------------------
# static multi-level grid over finished spheres: pairs, contacts, clearance

@njit(cache=True)
def grid_build(X, R, org, cs, dims, coff, rlo, bdims, boff):
    head = np.full(coff[-1], -1, np.int32)
    nxt = np.full(X.shape[0], -1, np.int32)
    bcnt = np.zeros(boff[-1], np.int32)
    for i in range(X.shape[0]):
        grid_insert(org, cs, dims, coff, rlo, bdims, boff, head, nxt, bcnt, i, X[i, 0], X[i, 1], X[i, 2], R[i])
    return head, nxt, bcnt


@njit(cache=True)
def _pairs_of(i, X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, tol, out_j, pos):
    """Pairs (i, j), j > i, with |ci - cj| <= (ri + rj)(1 + tol); with out_j, written there sorted by j."""
    px, py, pz, ri = X[i, 0], X[i, 1], X[i, 2], R[i]
    n = 0
    for k in range(org.shape[0]):
        ext = (ri + rmax[k]) * (1.0 + tol)
        x0 = _cidx(org, cs, dims, k, 0, px - ext)
        x1 = _cidx(org, cs, dims, k, 0, px + ext)
        y0 = _cidx(org, cs, dims, k, 1, py - ext)
        y1 = _cidx(org, cs, dims, k, 1, py + ext)
        z0 = _cidx(org, cs, dims, k, 2, pz - ext)
        z1 = _cidx(org, cs, dims, k, 2, pz + ext)
        nxk, nyk = dims[k, 0], dims[k, 1]
        for bz in range(z0 // BLOCK, z1 // BLOCK + 1):
            for by in range(y0 // BLOCK, y1 // BLOCK + 1):
                for bx in range(x0 // BLOCK, x1 // BLOCK + 1):
                    if bcnt[boff[k] + (bz * bdims[k, 1] + by) * bdims[k, 0] + bx] == 0:
                        continue
                    for iz in range(max(z0, bz * BLOCK), min(z1, bz * BLOCK + BLOCK - 1) + 1):
                        for iy in range(max(y0, by * BLOCK), min(y1, by * BLOCK + BLOCK - 1) + 1):
                            base = coff[k] + (iz * nyk + iy) * nxk
                            for ix in range(max(x0, bx * BLOCK), min(x1, bx * BLOCK + BLOCK - 1) + 1):
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
def count_pairs(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, tol):
    counts = np.empty(X.shape[0], np.int64)
    for i in prange(X.shape[0]):
        counts[i] = _pairs_of(i, X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, tol, None, 0)
    return counts


@njit(cache=True, parallel=True)
def fill_pairs(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, tol, offsets, out):
    for i in prange(X.shape[0]):
        k = _pairs_of(i, X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, tol, out[:, 1], offsets[i])
        for q in range(offsets[i], offsets[i] + k):
            out[q, 0] = i


@njit(cache=True, parallel=True)
def overlap_stats(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt):
    """Largest overlap (ri + rj - d) / min(ri, rj) of each sphere with a later one (0 if none)."""
    out = np.zeros(X.shape[0])
    for i in prange(X.shape[0]):
        px, py, pz, ri = X[i, 0], X[i, 1], X[i, 2], R[i]
        best = 0.0
        for k in range(org.shape[0]):
            ext = ri + rmax[k]
            x0 = _cidx(org, cs, dims, k, 0, px - ext)
            x1 = _cidx(org, cs, dims, k, 0, px + ext)
            y0 = _cidx(org, cs, dims, k, 1, py - ext)
            y1 = _cidx(org, cs, dims, k, 1, py + ext)
            z0 = _cidx(org, cs, dims, k, 2, pz - ext)
            z1 = _cidx(org, cs, dims, k, 2, pz + ext)
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


@njit(cache=True)
def clearance_point(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi, Dc, exc,
                    px, py, pz, search, eps, gbuf):
    rlo0 = rmax[0] * 0.5
    """Clearance of P: distance to the nearest sphere surface, box face or constraint surface
    (capped at search); -inf outside the box or above an excavation.  With gbuf (m,3), also the
    unit directions away from the constraints within eps of the minimum.
    Returns (clearance, nearest sphere or -1, number of directions)."""
    ec, cstart, cfac, g0x, g0y, gs, gnx, gny = exc
    if gnx > 0 and above_excavation(ec, cstart, cfac, g0x, g0y, gs, gnx, gny, px, py, pz):
        return -np.inf, -1, 0
    best = min(search, px - lo[0], py - lo[1], pz - lo[2], hi[0] - px, hi[1] - py, hi[2] - pz)
    bj = -1
    if best < 0.0:
        return -np.inf, -1, 0
    # iterative deepening: spheres whose surface is within rho, rho doubling from a fraction of
    # the smallest radius until a sphere is found (a wide first search would visit thousands of
    # small spheres around a probe in a fine zone)
    rho = 0.5 * rlo0
    while True:
        lim = min(best, rho)
        found = _nearest_pass(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, px, py, pz, lim)
        if found[1] >= 0 and found[0] < best:
            best, bj = found[0], found[1]
        if best <= rho or rho >= search:
            break
        rho *= 2.0
    best = surface_clearance(Dc, px, py, pz, best)
    if gbuf is None:
        return best, bj, 0
    return _active_dirs(X, R, org, cs, dims, coff, rmax, lo, hi, head, nxt, Dc, px, py, pz, best, bj, eps, gbuf)


@njit(cache=True)
def surface_clearance(Dc, px, py, pz, best):
    """min(best, distance from P to the meshes of Dc)."""
    for k in range(Dc[12].shape[0]):
        if not MQ.in_root_box(Dc, k, px, py, pz, best):
            continue
        d2 = MQ.closest_point(Dc, k, px, py, pz, best * best)[0]
        if d2 < best * best:
            best = math.sqrt(d2)
    return best


@njit(cache=True)
def _nearest_pass(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, px, py, pz, lim):
    """Nearest sphere surface within lim of P: (distance, sphere) or (lim, -1)."""
    best = lim
    bj = -1
    for k in range(org.shape[0]):
        ext = best + rmax[k]
        x0 = _cidx(org, cs, dims, k, 0, px - ext)
        x1 = _cidx(org, cs, dims, k, 0, px + ext)
        y0 = _cidx(org, cs, dims, k, 1, py - ext)
        y1 = _cidx(org, cs, dims, k, 1, py + ext)
        z0 = _cidx(org, cs, dims, k, 2, pz - ext)
        z1 = _cidx(org, cs, dims, k, 2, pz + ext)
        for bz in range(z0 // BLOCK, z1 // BLOCK + 1):
            for by in range(y0 // BLOCK, y1 // BLOCK + 1):
                for bx in range(x0 // BLOCK, x1 // BLOCK + 1):
                    if bcnt[boff[k] + (bz * bdims[k, 1] + by) * bdims[k, 0] + bx] == 0:
                        continue
                    for iz in range(max(z0, bz * BLOCK), min(z1, bz * BLOCK + BLOCK - 1) + 1):
                        for iy in range(max(y0, by * BLOCK), min(y1, by * BLOCK + BLOCK - 1) + 1):
                            base = coff[k] + (iz * dims[k, 1] + iy) * dims[k, 0]
                            for ix in range(max(x0, bx * BLOCK), min(x1, bx * BLOCK + BLOCK - 1) + 1):
                                j = head[base + ix]
                                while j >= 0:
                                    d = math.sqrt((X[j, 0] - px) ** 2 + (X[j, 1] - py) ** 2
                                                  + (X[j, 2] - pz) ** 2) - R[j]
                                    if d < best:
                                        best = d
                                        bj = j
                                    j = nxt[j]
    return best, bj


@njit(cache=True)
def _active_dirs(X, R, org, cs, dims, coff, rmax, lo, hi, head, nxt, Dc, px, py, pz, best, bj, eps, gbuf):
    """Unit directions away from the constraints within eps of the clearance best."""
    lim = best + eps
    m = 0
    cap = gbuf.shape[0]
    for a in range(3):
        if (px if a == 0 else (py if a == 1 else pz)) - lo[a] <= lim and m < cap:
            gbuf[m, 0], gbuf[m, 1], gbuf[m, 2] = 0.0, 0.0, 0.0
            gbuf[m, a] = 1.0
            m += 1
        if hi[a] - (px if a == 0 else (py if a == 1 else pz)) <= lim and m < cap:
            gbuf[m, 0], gbuf[m, 1], gbuf[m, 2] = 0.0, 0.0, 0.0
            gbuf[m, a] = -1.0
            m += 1
    for k in range(org.shape[0]):
        ext = lim + rmax[k]
        x0 = _cidx(org, cs, dims, k, 0, px - ext)
        x1 = _cidx(org, cs, dims, k, 0, px + ext)
        y0 = _cidx(org, cs, dims, k, 1, py - ext)
        y1 = _cidx(org, cs, dims, k, 1, py + ext)
        z0 = _cidx(org, cs, dims, k, 2, pz - ext)
        z1 = _cidx(org, cs, dims, k, 2, pz + ext)
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                base = coff[k] + (iz * dims[k, 1] + iy) * dims[k, 0]
                for ix in range(x0, x1 + 1):
                    j = head[base + ix]
                    while j >= 0:
                        dx, dy, dz = px - X[j, 0], py - X[j, 1], pz - X[j, 2]
                        dd = math.sqrt(dx * dx + dy * dy + dz * dz)
                        if dd - R[j] <= lim and dd > 0.0 and m < cap:
                            gbuf[m, 0], gbuf[m, 1], gbuf[m, 2] = dx / dd, dy / dd, dz / dd
                            m += 1
                        j = nxt[j]
    for k in range(Dc[12].shape[0]):
        if not MQ.in_root_box(Dc, k, px, py, pz, lim):
            continue
        d2, qx, qy, qz, f, reg = MQ.closest_point(Dc, k, px, py, pz, lim * lim)
        if f >= 0 and d2 > 0.0 and m < cap:
            dd = math.sqrt(d2)
            gbuf[m, 0], gbuf[m, 1], gbuf[m, 2] = (px - qx) / dd, (py - qy) / dd, (pz - qz) / dd
            m += 1
    return best, bj, m


@njit(cache=True)
def min_norm_hull(g, m, out):
    """Point of smallest norm in the convex hull of g[0:m] (Gilbert's algorithm): the steepest
    ascent direction of min_j (g_j . d) over unit d; zero at a local maximum of the clearance."""
    out[0], out[1], out[2] = g[0, 0], g[0, 1], g[0, 2]
    for it in range(100):
        best = np.inf
        bj = 0
        for j in range(m):
            v = g[j, 0] * out[0] + g[j, 1] * out[1] + g[j, 2] * out[2]
            if v < best:
                best = v
                bj = j
        xx = out[0] * out[0] + out[1] * out[1] + out[2] * out[2]
        if xx - best <= 1e-12:
            break
        dx, dy, dz = g[bj, 0] - out[0], g[bj, 1] - out[1], g[bj, 2] - out[2]
        dd = dx * dx + dy * dy + dz * dz
        t = min(max((xx - best) / dd, 0.0), 1.0) if dd > 0 else 0.0
        out[0] += t * dx
        out[1] += t * dy
        out[2] += t * dz
    return math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])


@njit(cache=True, inline="always")
def _mix64(z):
    """SplitMix64 finaliser: a well-mixed 64-bit value from a counter."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _unit(seed, i, j, c):
    """Uniform in [0, 1) from the counter (seed, sphere i, probe j, coordinate c): the same value
    on any machine and for any number of threads."""
    z = _mix64(np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(i) * np.uint64(0xD1B54A32D192ED03)
               + np.uint64(4 * j + c) * np.uint64(0x8CB92BA72F3D8DD7) + np.uint64(1))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def region_contains(lo, hi, Dc, exc, role, px, py, pz):
    """Is the point in the region: the box, not above an excavation (exact rule), outside every
    cavity (role 1) and inside the fill shape (role 2); excavation meshes (role 0) bound only
    spheres of positive radius."""
    if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1] and lo[2] <= pz <= hi[2]):
        return False
    ec, cstart, cfac, g0x, g0y, gs, gnx, gny = exc
    if gnx > 0 and above_excavation(ec, cstart, cfac, g0x, g0y, gs, gnx, gny, px, py, pz):
        return False
    for k in range(role.shape[0]):
        if role[k] == 1 and MQ.in_root_box(Dc, k, px, py, pz, 0.0) and MQ.inside_point(Dc, k, px, py, pz):
            return False
        if role[k] == 2 and not (MQ.in_root_box(Dc, k, px, py, pz, 0.0) and MQ.inside_point(Dc, k, px, py, pz)):
            return False
    return True


@njit(cache=True, parallel=True)
def probe_best(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi, Dc, exc, role, near_s,
               k, seed, shell, search, Dnone, exc_none):
    """Largest-empty-sphere probes: k points per sphere, uniform in the shell r .. shell r around it
    (directions uniform on the sphere, radii uniform in volume).  Probes of a sphere near a region
    surface (near_s) are kept only inside the region and measured against the surfaces too;
    the others are inside and nearer to a sphere than to any surface.  Returns, per sphere, its
    best probe by clearance / radius of the nearest sphere: (score (-inf: none), point, nearest)."""
    n = X.shape[0]
    best = np.full(n, -np.inf)
    pts = np.zeros((n, 3))
    near = np.full(n, -1, np.int64)
    s3 = shell ** 3 - 1.0
    for i in prange(n):
        for j in range(k):
            z = 2.0 * _unit(seed, i, j, 0) - 1.0
            ph = 2.0 * math.pi * _unit(seed, i, j, 1)
            rad = R[i] * (1.0 + _unit(seed, i, j, 2) * s3) ** (1.0 / 3.0)
            sxy = math.sqrt(max(1.0 - z * z, 0.0))
            px = X[i, 0] + rad * sxy * math.cos(ph)
            py = X[i, 1] + rad * sxy * math.sin(ph)
            pz = X[i, 2] + rad * z
            # the spheres and the box first: the surfaces can only lower the clearance, so a probe
            # that does not beat the sphere's best so far needs no surface query
            c, jn, m = clearance_point(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi,
                                       Dnone, exc_none, px, py, pz, search, 0.0, None)
            if not c > 0.0 or c / R[max(jn, 0)] <= best[i]:
                continue
            if near_s[i]:
                if not region_contains(lo, hi, Dc, exc, role, px, py, pz):
                    continue
                c = surface_clearance(Dc, px, py, pz, c)
                if not c > 0.0 or c / R[max(jn, 0)] <= best[i]:
                    continue
            best[i] = c / R[max(jn, 0)]
            pts[i, 0], pts[i, 1], pts[i, 2] = px, py, pz
            near[i] = jn
    return best, pts, near


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


@njit(cache=True, parallel=True)
def ascend_many(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi, Dc, exc, pts, search,
                scale, iters):
    """Local ascent of the clearance from each point: steepest ascent direction (min-norm point of
    the active constraints' directions), step doubled on success and halved on failure."""
    res = np.empty(pts.shape[0])
    pos = pts.copy()
    near = np.empty(pts.shape[0], np.int64)
    for i in prange(pts.shape[0]):
        g = np.empty((32, 3))
        d = np.empty(3)
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        eps = 1e-6 * scale[i]
        s = 0.1 * scale[i]
        c, bj, m = clearance_point(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi, Dc,
                                   exc, px, py, pz, search, eps + s, g)
        for it in range(iters):
            if c == -np.inf or m == 0 or s < 1e-7 * scale[i]:
                break
            dl = min_norm_hull(g, m, d)
            if dl < 1e-9:
                s *= 0.5  # balanced for this active band: narrow it
                c, bj, m = clearance_point(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi,
                                           Dc, exc, px, py, pz, search, eps + s, g)
                continue
            qx, qy, qz = px + s * d[0] / dl, py + s * d[1] / dl, pz + s * d[2] / dl
            c2, bj2, m2 = clearance_point(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi,
                                          Dc, exc, qx, qy, qz, search, 0.0, None)
            if c2 > c:
                px, py, pz, c, bj = qx, qy, qz, c2, bj2
                s *= 1.5
            else:
                s *= 0.5
            c, bj, m = clearance_point(X, R, org, cs, dims, coff, rmax, bdims, boff, head, nxt, bcnt, lo, hi, Dc,
                                       exc, px, py, pz, search, eps + s, g)
        res[i] = c
        near[i] = bj
        pos[i, 0], pos[i, 1], pos[i, 2] = px, py, pz
    return res, pos, near
