"""numba kernels: the contact law of a point by the kind of the face it lies on (the block model of an sgim scene,
dda/geoblocks.py and dda/georun.py).

A face of a cut block remembers what made it: a joint set plane, a disc (joint or fault), a facet of a
triangulated discontinuity, an intact split. The law table's rows (``lawtab[r, r]``, one "material" per kind
and discontinuity: dda/georun.py) then hold the laws, and per face ``face_row[f]`` names its row (-1: the
blocks' materials decide, as in every other scene), ``face_shape[f]`` says where the row holds (0 the whole
face; 1 inside a disc, ``face_geo[f]`` = body-frame centre, normal and radius; 2 inside a triangle,
``face_geo[f]`` = its three body-frame corners) and outside it the intact-rock row ``intact_row`` holds.

Per pair (``law_face``): the face of A whose outward normal is within about 8 degrees of the common plane's
normal, else B's face facing the other way (a face-to-face contact of two cut blocks has both; an edge or vertex
of A on a face of B only B's). Per point (``point_row``): that face's row, or the intact row when the point lies
outside the face's disc or triangle (the point taken into the face owner's body frame, so that the disc moves
with the block).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from sgim._dfn import _edge_circle as edge_circle

from ._kinematics import quat_matrix

ALIGNED = 0.99  # cos of about 8 degrees, as the crease rule of dda/_fcp.py


@njit(cache=True, inline="always")
def law_face(i, j, nrm, fnw, fs, face_row):
    """(face, owner) whose row decides the law of pair (i, j) with common-plane normal nrm (A = i -> B = j), or
    (-1, -1) when neither block has a face with a row facing the contact."""
    for side in range(2):
        b = i if side == 0 else j
        sgn = 1.0 if side == 0 else -1.0
        best = -1
        bd = ALIGNED
        for f in range(fs[b], fs[b + 1]):
            d = sgn * (fnw[f, 0] * nrm[0] + fnw[f, 1] * nrm[1] + fnw[f, 2] * nrm[2])
            if d > bd:
                bd = d
                best = f
        if best >= 0 and face_row[best] >= 0:
            return best, b
    return -1, -1


@njit(cache=True, inline="always")
def point_row(f, owner, P, pos, quat, face_row, face_shape, face_geo, intact_row, R):
    """The law row of the contact point P (world) on face f of block `owner` (see the module docstring)."""
    shape = face_shape[f]
    if shape == 0:
        return face_row[f]
    quat_matrix(quat[owner], R)
    d0 = P[0] - pos[owner, 0]
    d1 = P[1] - pos[owner, 1]
    d2 = P[2] - pos[owner, 2]
    x0 = R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2
    x1 = R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2
    x2 = R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2
    g = face_geo[f]
    if shape == 1:
        r0 = x0 - g[0]
        r1 = x1 - g[1]
        r2 = x2 - g[2]
        rn = r0 * g[3] + r1 * g[4] + r2 * g[5]
        if r0 * r0 + r1 * r1 + r2 * r2 - rn * rn > g[6] * g[6]:
            return intact_row
        return face_row[f]
    # a triangle: inside when the point is on the inner side of its three edges (seen along its normal)
    e10 = g[3] - g[0]
    e11 = g[4] - g[1]
    e12 = g[5] - g[2]
    e20 = g[6] - g[0]
    e21 = g[7] - g[1]
    e22 = g[8] - g[2]
    n0 = e11 * e22 - e12 * e21
    n1 = e12 * e20 - e10 * e22
    n2 = e10 * e21 - e11 * e20
    for k in range(3):
        a = 3 * k
        b = 3 * ((k + 1) % 3)
        ea0 = g[b] - g[a]
        ea1 = g[b + 1] - g[a + 1]
        ea2 = g[b + 2] - g[a + 2]
        p0 = x0 - g[a]
        p1 = x1 - g[a + 1]
        p2 = x2 - g[a + 2]
        c0 = ea1 * p2 - ea2 * p1
        c1 = ea2 * p0 - ea0 * p2
        c2 = ea0 * p1 - ea1 * p0
        if c0 * n0 + c1 * n1 + c2 * n2 < 0.0:
            return intact_row
    return face_row[f]


def no_kinds():
    """The face-kind arrays of a run without kinds (every law from the blocks' materials)."""
    return np.full(0, -1, np.int64), np.zeros(0, np.int64), np.zeros((0, 9)), -1


@njit(cache=True, inline="always")
def intact_share(f, owner, p_pos, k, rows, nrm, pos, quat, face_geo, intact_row, R):
    """(area per intact point, area per joint point) of a contact whose face f (of block `owner`) is a disc's:
    the contact polygon's area outside the disc over the intact points, inside it over the others (the
    cohesion of a rock bridge acts on the bridge's area however many points stand for it). (-1, -1) when the
    points are not of both kinds."""
    n_int = 0
    for q in range(k):
        if rows[q] == intact_row:
            n_int += 1
    if n_int == 0 or n_int == k or k < 3:
        return -1.0, -1.0
    quat_matrix(quat[owner], R)
    g = face_geo[f]
    c = np.empty(3)
    for a in range(3):
        c[a] = pos[owner, a] + R[a, 0] * g[0] + R[a, 1] * g[1] + R[a, 2] * g[2]
    if abs(nrm[0]) < 0.9:
        a0, a1, a2 = 0.0, nrm[2], -nrm[1]
    else:
        a0, a1, a2 = -nrm[2], 0.0, nrm[0]
    al = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    e1 = np.array([a0 / al, a1 / al, a2 / al])
    e2 = np.array([nrm[1] * e1[2] - nrm[2] * e1[1], nrm[2] * e1[0] - nrm[0] * e1[2], nrm[0] * e1[1] - nrm[1] * e1[0]])
    u = np.empty(k)
    v = np.empty(k)
    ang = np.empty(k)
    for q in range(k):
        u[q] = (p_pos[q, 0] - c[0]) * e1[0] + (p_pos[q, 1] - c[1]) * e1[1] + (p_pos[q, 2] - c[2]) * e1[2]
        v[q] = (p_pos[q, 0] - c[0]) * e2[0] + (p_pos[q, 1] - c[1]) * e2[1] + (p_pos[q, 2] - c[2]) * e2[2]
    cu = u.mean()
    cv = v.mean()
    for q in range(k):
        ang[q] = np.arctan2(v[q] - cv, u[q] - cu)
    order = np.argsort(ang)
    total = 0.0
    inside = 0.0
    for q in range(k):
        p = order[q]
        s = order[(q + 1) % k]
        total += 0.5 * (u[p] * v[s] - u[s] * v[p])
        inside += edge_circle(u[p], v[p], u[s], v[s], g[6])
    return max(total - inside, 0.0) / n_int, max(inside, 0.0) / (k - n_int)
