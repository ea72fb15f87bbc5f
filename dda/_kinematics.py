"""numba kernels: rotations of the block engine (quaternion to matrix, angular velocity, quaternion turn).

They are inlined where they are called (``inline="always"``): a call that numba does not inline, inside a
per-block or per-point loop, keeps it from removing the reference-count increments and decrements of the arrays
the loop's inlined helpers hold across that call (dda/_narrow.py's docstring)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def quat_matrix(q, R):
    """R = the rotation matrix of the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True, inline="always")
def ang_vel(R, inertia_i, L, out):
    # w = R I^-1 R^T L
    b0 = R[0, 0] * L[0] + R[1, 0] * L[1] + R[2, 0] * L[2]
    b1 = R[0, 1] * L[0] + R[1, 1] * L[1] + R[2, 1] * L[2]
    b2 = R[0, 2] * L[0] + R[1, 2] * L[1] + R[2, 2] * L[2]
    b0 /= inertia_i[0]
    b1 /= inertia_i[1]
    b2 /= inertia_i[2]
    for a in range(3):
        out[a] = R[a, 0] * b0 + R[a, 1] * b1 + R[a, 2] * b2


@njit(cache=True, inline="always")
def turn(q, w, h, out):
    """out = exp(w h) * q (w in the world frame), normalised."""
    wl = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    th = wl * h
    if wl > 0.0:
        s = np.sin(0.5 * th) / wl
        c = np.cos(0.5 * th)
    else:
        s = 0.5 * h
        c = 1.0
    p0, p1, p2, p3 = c, s * w[0], s * w[1], s * w[2]
    o0 = p0 * q[0] - p1 * q[1] - p2 * q[2] - p3 * q[3]
    o1 = p0 * q[1] + p1 * q[0] + p2 * q[3] - p3 * q[2]
    o2 = p0 * q[2] - p1 * q[3] + p2 * q[0] + p3 * q[1]
    o3 = p0 * q[3] + p1 * q[2] - p2 * q[1] + p3 * q[0]
    ln = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    out[0] = o0 / ln
    out[1] = o1 / ln
    out[2] = o2 / ln
    out[3] = o3 / ln


@njit(cache=True, inline="always")
def omega(j, kin, static, wpres, quat, inertia, angmom, R, out):
    """World angular velocity of body j (prescribed, zero when fixed or asleep, else R I^-1 R^T L)."""
    if kin[j]:
        for a in range(3):
            out[a] = wpres[j, a]
    elif static[j]:
        for a in range(3):
            out[a] = 0.0
    else:
        quat_matrix(quat[j], R)
        ang_vel(R, inertia[j], angmom[j], out)
