"""numba: which point sprites of an off-screen picture can show in it (sgim/render.py, ``in_sight``).

A sphere is drawn by VTK as a point sprite: a disc of radius R pixels about its centre's window position (x, y),
whose fragments have the depth t - bulge sqrt(1 - (d / R)^2) at distance d from the centre (t: the centre's depth
along the view, bulge = twice the sprite's radius in metres: VTK's gl_FragDepth for points drawn as spheres).
A pixel cell is a unit square [i, i + 1] x [j, j + 1] of window coordinates; every sample VTK takes in a pixel
lies in its cell. Both kernels only compare, add, multiply and take square roots of the numbers they are given:
the same spheres on every CPU.
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
