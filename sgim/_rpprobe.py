"""Numba kernels of the random packing's statistics: clearance of a point, largest-empty-sphere probes and
their local ascent (see sgim/rpack.py, largest_empty_sphere)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from . import _meshq as MQ
from ._rpgrid import BLOCK, block_cells, cell_range
from ._rpregion import above_excavation, region_contains


@njit(cache=True)
def clearance_point(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, px, py, pz, search, eps, gbuf):
    """Clearance of P: distance to the nearest sphere surface, box face or constraint surface
    (capped at search); -inf outside the box or above an excavation.  With gbuf (m,3), also the
    unit directions away from the constraints within eps of the minimum.
    Returns (clearance, nearest sphere or -1, number of directions)."""
    rlo0 = G.rmax[0] * 0.5
    if exc.gnx > 0 and above_excavation(exc, px, py, pz):
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
        found = _nearest_pass(X, R, G, head, nxt, bcnt, px, py, pz, lim)
        if found[1] >= 0 and found[0] < best:
            best, bj = found[0], found[1]
        if best <= rho or rho >= search:
            break
        rho *= 2.0
    best = surface_clearance(Dc, px, py, pz, best)
    if gbuf is None:
        return best, bj, 0
    return _active_dirs(X, R, G, lo, hi, head, nxt, Dc, px, py, pz, best, bj, eps, gbuf)


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
def _nearest_pass(X, R, G, head, nxt, bcnt, px, py, pz, lim):
    """Nearest sphere surface within lim of P: (distance, sphere) or (lim, -1)."""
    dims, coff, rmax = G.dims, G.coff, G.rmax
    best = lim
    bj = -1
    for k in range(dims.shape[0]):
        x0, x1, y0, y1, z0, z1 = cell_range(G, k, px, py, pz, best + rmax[k])
        for bz in range(z0 // BLOCK, z1 // BLOCK + 1):
            for by in range(y0 // BLOCK, y1 // BLOCK + 1):
                for bx in range(x0 // BLOCK, x1 // BLOCK + 1):
                    iz0, iz1, iy0, iy1, ix0, ix1 = block_cells(G, bcnt, k, bx, by, bz, x0, x1, y0, y1, z0, z1)
                    for iz in range(iz0, iz1):
                        for iy in range(iy0, iy1):
                            base = coff[k] + (iz * dims[k, 1] + iy) * dims[k, 0]
                            for ix in range(ix0, ix1):
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
def _active_dirs(X, R, G, lo, hi, head, nxt, Dc, px, py, pz, best, bj, eps, gbuf):
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
    dims, coff, rmax = G.dims, G.coff, G.rmax
    for k in range(dims.shape[0]):
        x0, x1, y0, y1, z0, z1 = cell_range(G, k, px, py, pz, lim + rmax[k])
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

@njit(cache=True, parallel=True)
def probe_best(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, role, near_s, k, seed, shell, search, Dnone, exc_none):
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
            c, jn, m = clearance_point(X, R, G, head, nxt, bcnt, lo, hi, Dnone, exc_none, px, py, pz, search, 0.0, None)
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
def ascend_many(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, pts, search, scale, iters):
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
        c, bj, m = clearance_point(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, px, py, pz, search, eps + s, g)
        for it in range(iters):
            if c == -np.inf or m == 0 or s < 1e-7 * scale[i]:
                break
            dl = min_norm_hull(g, m, d)
            if dl < 1e-9:
                s *= 0.5  # balanced for this active band: narrow it
                c, bj, m = clearance_point(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, px, py, pz, search,
                                           eps + s, g)
                continue
            qx, qy, qz = px + s * d[0] / dl, py + s * d[1] / dl, pz + s * d[2] / dl
            c2, bj2, m2 = clearance_point(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, qx, qy, qz, search, 0.0,
                                          None)
            if c2 > c:
                px, py, pz, c, bj = qx, qy, qz, c2, bj2
                s *= 1.5
            else:
                s *= 0.5
            c, bj, m = clearance_point(X, R, G, head, nxt, bcnt, lo, hi, Dc, exc, px, py, pz, search, eps + s, g)
        res[i] = c
        near[i] = bj
        pos[i, 0], pos[i, 1], pos[i, 2] = px, py, pz
    return res, pos, near
