"""Numba kernels for the discrete fracture network: the area of a disc inside a box.

The disc (centre M, unit normal n, radius R) is described in its own plane with an
orthonormal basis (u, v).  The square [-1.5R, 1.5R]^2 of that plane, which holds the disc, is
clipped by the six half-spaces of the box (Sutherland-Hodgman in plane coordinates); the
area of the disc inside the box is then the area of the circle inside that convex polygon,
summed exactly over the polygon's edges: for each edge (p, q) the signed area of the
circle inside the triangle (centre, p, q) is a triangle where the edge runs inside the
circle and a circular sector where it runs outside.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_MAXV = 16  # 4 square corners + at most one new vertex per clipping plane


@njit(cache=True)
def plane_basis(n):
    """Orthonormal (u, v) with u, v, n right-handed."""
    ax, ay, az = (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0)
    # u = a x n, normalised
    ux = ay * n[2] - az * n[1]
    uy = az * n[0] - ax * n[2]
    uz = ax * n[1] - ay * n[0]
    s = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux / s, uy / s, uz / s
    # v = n x u
    vx = n[1] * uz - n[2] * uy
    vy = n[2] * ux - n[0] * uz
    vz = n[0] * uy - n[1] * ux
    return ux, uy, uz, vx, vy, vz


@njit(cache=True)
def _clip(ps, pt, m, a, b, c, ws, wt):
    """Keep the part of polygon (ps, pt)[:m] where a s + b t >= c; result in (ws, wt)."""
    k = 0
    for i in range(m):
        j = i + 1 if i + 1 < m else 0
        fi = a * ps[i] + b * pt[i] - c
        fj = a * ps[j] + b * pt[j] - c
        if fi >= 0.0:
            ws[k] = ps[i]
            wt[k] = pt[i]
            k += 1
        if (fi >= 0.0) != (fj >= 0.0):
            t = fi / (fi - fj)
            ws[k] = ps[i] + t * (ps[j] - ps[i])
            wt[k] = pt[i] + t * (pt[j] - pt[i])
            k += 1
    return k


@njit(cache=True)
def _edge_circle(ax, ay, bx, by, R):
    """Signed area of the circle |x| <= R inside the triangle (0, a, b)."""
    dx, dy = bx - ax, by - ay
    A = dx * dx + dy * dy
    ts = np.empty(4)
    ts[0] = 0.0
    k = 1
    if A > 0.0:
        B = ax * dx + ay * dy
        C = ax * ax + ay * ay - R * R
        disc = B * B - A * C
        if disc > 0.0:
            s = math.sqrt(disc)
            t1 = (-B - s) / A
            t2 = (-B + s) / A
            if 0.0 < t1 < 1.0:
                ts[k] = t1
                k += 1
            if 0.0 < t2 < 1.0:
                ts[k] = t2
                k += 1
    ts[k] = 1.0
    k += 1
    area = 0.0
    for q in range(k - 1):
        t0, t1 = ts[q], ts[q + 1]
        px, py = ax + t0 * dx, ay + t0 * dy
        qx, qy = ax + t1 * dx, ay + t1 * dy
        tm = 0.5 * (t0 + t1)
        mx, my = ax + tm * dx, ay + tm * dy
        cr = px * qy - py * qx
        if mx * mx + my * my < R * R:  # a piece inside the circle (a tangent edge's midpoint is not)
            area += 0.5 * cr
        else:
            area += 0.5 * R * R * math.atan2(cr, px * qx + py * qy)
    return area


@njit(cache=True)
def disc_box_area(M, n, R, lo, hi):
    """Area of the disc (M, n, R) inside the box [lo, hi]."""
    ux, uy, uz, vx, vy, vz = plane_basis(n)
    ps = np.empty(_MAXV)
    pt = np.empty(_MAXV)
    ws = np.empty(_MAXV)
    wt = np.empty(_MAXV)
    h = 1.5 * R  # a square well around the disc
    ps[0], pt[0] = -h, -h
    ps[1], pt[1] = h, -h
    ps[2], pt[2] = h, h
    ps[3], pt[3] = -h, h
    m = 4
    U = (ux, uy, uz)
    V = (vx, vy, vz)
    for ax in range(3):
        # x_ax = M_ax + s U_ax + t V_ax >= lo_ax   and   <= hi_ax
        m = _clip(ps, pt, m, U[ax], V[ax], lo[ax] - M[ax], ws, wt)
        if m == 0:
            return 0.0
        m = _clip(ws, wt, m, -U[ax], -V[ax], M[ax] - hi[ax], ps, pt)
        if m == 0:
            return 0.0
    area = 0.0
    for i in range(m):
        j = i + 1 if i + 1 < m else 0
        area += _edge_circle(ps[i], pt[i], ps[j], pt[j], R)
    area = abs(area)
    if area <= 1e-12 * R * R:  # rounding residue of a polygon that misses the disc
        return 0.0
    return area


@njit(cache=True, parallel=True)
def clipped_areas(centres, normals, radii, lo, hi):
    """Area inside the box [lo, hi] of each disc."""
    n = radii.shape[0]
    out = np.empty(n)
    for k in prange(n):
        out[k] = disc_box_area(centres[k], normals[k], radii[k], lo, hi)
    return out
