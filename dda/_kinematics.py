"""numba kernels: rotations of the block engine (quaternion to matrix, angular velocity, quaternion turn).

They are inlined where they are called (``inline="always"``): a call that numba does not inline, inside a
per-block or per-point loop, keeps it from removing the reference-count increments and decrements of the arrays
the loop's inlined helpers hold across that call (dda/_narrow.py's docstring)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def rotation(w, x, y, z):
    """The rotation matrix of the unit quaternion (w, x, y, z) as nine scalars, row by row."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


@njit(cache=True, inline="always")
def quat_matrix(q, R):
    """R = the rotation matrix of the unit quaternion q = (w, x, y, z)."""
    R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2] = rotation(q[0], q[1], q[2], q[3])


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
def turned(q0, q1, q2, q3, w0, w1, w2, h):
    """exp(w h) * q (w in the world frame), normalised, as four scalars."""
    wl = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    th = wl * h
    if wl > 0.0:
        s = np.sin(0.5 * th) / wl
        c = np.cos(0.5 * th)
    else:
        s = 0.5 * h
        c = 1.0
    p0, p1, p2, p3 = c, s * w0, s * w1, s * w2
    o0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    o1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    o2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    o3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    ln = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    return o0 / ln, o1 / ln, o2 / ln, o3 / ln


@njit(cache=True, inline="always")
def turn(q, w, h, out):
    """out = exp(w h) * q (w in the world frame), normalised."""
    out[0], out[1], out[2], out[3] = turned(q[0], q[1], q[2], q[3], w[0], w[1], w[2], h)


@njit(cache=True, inline="always")
def spin(j, quat, inertia, angmom):
    """World angular velocity R I^-1 R^T L of body j as three scalars (straight-line code: the counts of the arrays
    it takes cancel where it is inlined)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation(quat[j, 0], quat[j, 1], quat[j, 2], quat[j, 3])
    L0, L1, L2 = angmom[j, 0], angmom[j, 1], angmom[j, 2]
    b0 = r00 * L0 + r10 * L1 + r20 * L2
    b1 = r01 * L0 + r11 * L1 + r21 * L2
    b2 = r02 * L0 + r12 * L1 + r22 * L2
    b0 /= inertia[j, 0]
    b1 /= inertia[j, 1]
    b2 /= inertia[j, 2]
    return r00 * b0 + r01 * b1 + r02 * b2, r10 * b0 + r11 * b1 + r12 * b2, r20 * b0 + r21 * b1 + r22 * b2


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


@njit(cache=True, inline="always")
def place_vertices(i, pos, M, vs, vloc, vert, aabb):
    """World vertices x = pos[i] + M X of block i (M = R for a rigid block, R (I + E) for a deformable one) and
    its box."""
    for a in range(3):
        aabb[i, a] = 1e300
        aabb[i, 3 + a] = -1e300
    for v in range(vs[i], vs[i + 1]):
        for a in range(3):
            x = pos[i, a] + M[a, 0] * vloc[v, 0] + M[a, 1] * vloc[v, 1] + M[a, 2] * vloc[v, 2]
            vert[v, a] = x
            if x < aabb[i, a]:
                aabb[i, a] = x
            if x > aabb[i, 3 + a]:
                aabb[i, 3 + a] = x
