"""Numba kernels of the random packer: closed-form pockets (a sphere touching three supports),
a pocket moved for another radius, refined against a curved surface (see sgim/_rpack.py)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _meshq as MQ
from ._rpregion import mesh_clear

SUP_NONE = -100  # seed: no supports
SUP_PLANE0 = -20  # the candidate's first stored plane
SUP_PLANE1 = -21  # its second stored plane
# box walls: -1 - w, w = 0..5 for x-, x+, y-, y+, z-, z+


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


@njit(cache=True, inline="always")
def clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, a, b):
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
def refine(kind, s, a, mpl, npl, rn, tol, q, Dc, out2):
    """A pocket q = (qx, qy, qz) against a curved constraint surface: replace the tangent plane
    npl = (nx, ny, nz, h0) by the tangent plane at the pocket's own foot point until the pocket
    clears every mesh (at most four rounds).  One support is the sphere s = (sx, sy, sz, contact
    distance ds), the other the sphere a = (ax, ay, az, da) (kind 0) or the plane
    mpl = (mx, my, mz, hm): m.P = hm (kind 1, already offset).  Returns (ok, qx, qy, qz, nx, ny, nz, h0)."""
    sx, sy, sz, ds = s
    ax, ay, az, da = a
    mx, my, mz, hm = mpl
    nx, ny, nz, h0 = npl
    qx, qy, qz = q
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
def reposition(csup, cpl, c, X, R, lo, hi, r, cpos, out):
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
