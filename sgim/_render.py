"""numba: which point sprites of an off-screen picture can show in it (sgim/render.py, ``in_sight``).

A sphere is drawn by VTK as a point sprite: a disc of radius R pixels about its centre's window position (x, y),
whose fragments have the depth t - bulge sqrt(1 - (d / R)^2) at distance d from the centre (t: the centre's depth
along the view, bulge = twice the sprite's radius in metres: VTK's gl_FragDepth for points drawn as spheres).
A pixel cell is a unit square [i, i + 1] x [j, j + 1] of window coordinates; every sample VTK takes in a pixel
lies in its cell. Both kernels only compare, add, multiply and take square roots of the numbers they are given:
the same spheres on every CPU. ``column_bounds``, ``mark_extremes`` and ``project_rows`` do in one pass over the
spheres what numpy did in a dozen (the bounds, the extreme rows, the window coordinates: the same bits), which
at 10^7 spheres cost more than the selection itself.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _cells(xc, yc, half, W, H):
    """The pixel cells i0..i1, j0..j1 of a W x H picture that the square of half-side `half` about (xc, yc)
    meets."""
    return (max(int(np.floor(xc - half)), 0), min(int(np.floor(xc + half)), W - 1),
            max(int(np.floor(yc - half)), 0), min(int(np.floor(yc + half)), H - 1))


@njit(cache=True)
def front_depths(x, y, t, R, eps, bulge, W, H):
    """(H, W) array: per pixel cell, the least depth that a sprite holding the whole cell (every point of the
    cell within R - eps of its centre) certainly draws there: t - bulge sqrt(1 - ((d + eps) / R)^2) with d the
    cell's farthest corner; inf where no sprite holds the whole cell."""
    buf = np.full((H, W), np.inf)
    inner = R - eps
    if inner <= 0.0:
        return buf
    inner2 = inner * inner
    for k in range(len(x)):
        xk, yk, tk = x[k], y[k], t[k]
        i0, i1, j0, j1 = _cells(xk, yk, inner, W, H)
        for j in range(j0, j1 + 1):
            dy = max(abs(j - yk), abs(j + 1.0 - yk))
            if dy * dy > inner2:
                continue
            for i in range(i0, i1 + 1):
                dx = max(abs(i - xk), abs(i + 1.0 - xk))
                d2 = dx * dx + dy * dy
                if d2 <= inner2:
                    far = (np.sqrt(d2) + eps) / R
                    depth = tk - bulge * np.sqrt(max(1.0 - far * far, 0.0))
                    if depth < buf[j, i]:
                        buf[j, i] = depth
    return buf


@njit(cache=True)
def reaches_front(x, y, t, buf, R, eps, bulge, tol):
    """True for each sprite that may show in the picture: some pixel cell within R + eps of its centre (inside
    the picture) where `buf` (front_depths) is not in front of the nearest depth the sprite can draw there,
    t - bulge sqrt(1 - ((d - eps) / R)^2) with d the cell's nearest point, by more than `tol`."""
    H, W = buf.shape
    out = np.zeros(len(x), np.bool_)
    outer = R + eps
    outer2 = outer * outer
    for k in range(len(x)):
        xk, yk, tk = x[k], y[k], t[k]
        i0, i1, j0, j1 = _cells(xk, yk, outer, W, H)
        for j in range(j0, j1 + 1):
            dy = 0.0 if j <= yk <= j + 1.0 else min(abs(j - yk), abs(j + 1.0 - yk))
            for i in range(i0, i1 + 1):
                dx = 0.0 if i <= xk <= i + 1.0 else min(abs(i - xk), abs(i + 1.0 - xk))
                d2 = dx * dx + dy * dy
                if d2 > outer2 or buf[j, i] < tk - bulge - tol:
                    continue  # out of reach, or hidden even where the sprite bulges most
                near = max(np.sqrt(d2) - eps, 0.0) / R
                depth = tk - bulge * np.sqrt(max(1.0 - near * near, 0.0))
                if not buf[j, i] < depth - tol:
                    out[k] = True
                    break
            if out[k]:
                break
    return out


@njit(cache=True)
def column_bounds(c):
    """(lo, hi): the least and the largest value of each column of the (n, 3) array c, in one pass (numpy's
    c.min(0) and c.max(0) read the columns strided, one pass each)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for k in range(c.shape[0]):
        for a in range(3):
            v = c[k, a]
            if v < lo[a]:
                lo[a] = v
            if v > hi[a]:
                hi[a] = v
    return lo, hi


@njit(cache=True)
def mark_extremes(c, idx, keep):
    """Sets keep[p] for the first position p of idx whose row c[idx[p]] has the least value of a column, and for
    the first with the largest (numpy's argmin and argmax of c[idx] along each column, without the copy; one
    pass)."""
    if idx.shape[0] == 0:
        return
    plo = np.zeros(3, np.int64)
    phi = np.zeros(3, np.int64)
    vlo = np.empty(3)
    vhi = np.empty(3)
    for a in range(3):
        vlo[a] = c[idx[0], a]
        vhi[a] = vlo[a]
    for p in range(1, idx.shape[0]):
        i = idx[p]
        for a in range(3):
            v = c[i, a]
            if v < vlo[a]:
                vlo[a] = v
                plo[a] = p
            if v > vhi[a]:
                vhi[a] = v
                phi[a] = p
    for a in range(3):
        keep[plo[a]] = True
        keep[phi[a]] = True


@njit(cache=True)
def project_rows(c, idx, focal, right, up, d, scale, half_w, half_h):
    """Window coordinates x, y and depth t of the rows c[idx] (sgim/render.py, Frame.project: the same products
    and sums in the same order, one rounding each)."""
    n = idx.shape[0]
    x = np.empty(n)
    y = np.empty(n)
    t = np.empty(n)
    for k in range(n):
        i = idx[k]
        p0 = c[i, 0] - focal[0]
        p1 = c[i, 1] - focal[1]
        p2 = c[i, 2] - focal[2]
        x[k] = (p0 * right[0] + p1 * right[1] + p2 * right[2]) / scale + half_w
        y[k] = (p0 * up[0] + p1 * up[1] + p2 * up[2]) / scale + half_h
        t[k] = -(p0 * d[0] + p1 * d[1] + p2 * d[2])
    return x, y, t
