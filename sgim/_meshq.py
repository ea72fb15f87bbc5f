"""Numba kernels for triangle-mesh queries (see sgim/meshquery.py for the Python API).

Data layout ("mesh data", a tuple ``D`` built by :meth:`sgim.meshquery.TriMesh.kernel_data`
or :class:`sgim.meshquery.MeshSet`), every array C-contiguous:

====  ==============  ==========================================================
D[0]  node_lo (nn,3)  bounding box of each BVH node
D[1]  node_hi (nn,3)
D[2]  node_kid (nn,2) children of an inner node (-1, -1 for a leaf)
D[3]  node_rng (nn,2) faces [start, end) of a leaf
D[4]  tv (m,9)        triangle corners a, b, c (faces are stored in BVH order)
D[5]  fn (m,3)        unit face normals (orientation of the corner order)
D[6]  fedge (m,3)     edge id of local edges (v0 v1), (v1 v2), (v2 v0)
D[7]  faces (m,3)     vertex ids
D[8]  epn (ne,3)      edge pseudo-normals (sum of the unit normals of the edge's faces)
D[9]  vpn (nv,3)      vertex pseudo-normals (angle-weighted sum of incident unit normals)
D[10] ebnd (ne,) u1   1 for a boundary edge (used by one face)
D[11] vbnd (nv,) u1   1 for a vertex on a boundary edge
D[12] roots (K,)      BVH root node of each mesh of a set
D[13] fstart (K+1,)   faces of mesh k are fstart[k] .. fstart[k+1]-1
====  ==============  ==========================================================

Closest-point regions: 0 face interior, 1..3 corner v0..v2, 4..6 edge (v0 v1), (v1 v2), (v2 v0).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

LEAF = 4
STACK = 96

# three fixed ray directions, far apart and off every axis and diagonal
RAYS = np.array([
    [0.5360165264763574, 0.6113941946155532, 0.5821580394512519],
    [-0.7035231582151893, 0.3126815092956398, -0.6382050127604111],
    [0.2315063510468447, -0.8862348624187351, 0.4013025178836412],
])
RAYS = RAYS / np.linalg.norm(RAYS, axis=1)[:, None]


# ---------------------------------------------------------------------------
# construction helpers

@njit(cache=True)
def build_bvh(tri, leaf):
    """Top-down BVH by median split of centroids along the widest axis.

    tri (m,9) corners.  Returns (order, node_lo, node_hi, node_kid, node_rng): faces must be
    permuted by ``order`` so that each leaf holds a contiguous range.
    """
    m = tri.shape[0]
    cen = np.empty((m, 3))
    flo = np.empty((m, 3))
    fhi = np.empty((m, 3))
    for f in range(m):
        for a in range(3):
            x0, x1, x2 = tri[f, a], tri[f, 3 + a], tri[f, 6 + a]
            flo[f, a] = min(x0, x1, x2)
            fhi[f, a] = max(x0, x1, x2)
            cen[f, a] = (x0 + x1 + x2) / 3.0
    order = np.arange(m)
    cap = max(2 * m, 1)
    lo = np.empty((cap, 3))
    hi = np.empty((cap, 3))
    kid = np.full((cap, 2), -1, np.int64)
    rng = np.zeros((cap, 2), np.int64)
    st_node = np.empty(cap, np.int64)
    st_s = np.empty(cap, np.int64)
    st_e = np.empty(cap, np.int64)
    nn = 1
    top = 0
    st_node[0], st_s[0], st_e[0] = 0, 0, m
    top = 1
    while top > 0:
        top -= 1
        node, s, e = st_node[top], st_s[top], st_e[top]
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for a in range(3):
            lo[node, a] = np.inf
            hi[node, a] = -np.inf
        for q in range(s, e):
            f = order[q]
            for a in range(3):
                lo[node, a] = min(lo[node, a], flo[f, a])
                hi[node, a] = max(hi[node, a], fhi[f, a])
                clo[a] = min(clo[a], cen[f, a])
                chi[a] = max(chi[a], cen[f, a])
        rng[node, 0], rng[node, 1] = s, e
        if e - s <= leaf:
            continue
        ax = 0
        if chi[1] - clo[1] > chi[ax] - clo[ax]:
            ax = 1
        if chi[2] - clo[2] > chi[ax] - clo[ax]:
            ax = 2
        seg = order[s:e].copy()
        keys = np.empty(e - s)
        for q in range(e - s):
            keys[q] = cen[seg[q], ax]
        srt = np.argsort(keys, kind="mergesort")
        for q in range(e - s):
            order[s + q] = seg[srt[q]]
        mid = (s + e) // 2
        kid[node, 0], kid[node, 1] = nn, nn + 1
        st_node[top], st_s[top], st_e[top] = nn, s, mid
        top += 1
        st_node[top], st_s[top], st_e[top] = nn + 1, mid, e
        top += 1
        nn += 2
    return order, lo[:nn].copy(), hi[:nn].copy(), kid[:nn].copy(), rng[:nn].copy()


@njit(cache=True)
def orient_faces(twin, he_dir, m):
    """Consistent orientation by breadth-first search across manifold edges.

    Half-edge 3f+k is the local edge k of face f; twin[h] is the other half-edge of a
    manifold edge (-1 on boundary and non-manifold edges); he_dir[h] is +1 when the half-edge
    runs from the lower to the higher vertex id, else -1.  Returns (flip (m,) bool: faces to
    reverse so that each connected patch is consistent with its first face, comp (m,) patch id).
    """
    flip = np.zeros(m, np.bool_)
    comp = np.full(m, -1, np.int64)
    queue = np.empty(m, np.int64)
    nc = 0
    for seed in range(m):
        if comp[seed] >= 0:
            continue
        comp[seed] = nc
        head, tail = 0, 1
        queue[0] = seed
        while head < tail:
            f = queue[head]
            head += 1
            for k in range(3):
                h = 3 * f + k
                o = twin[h]
                if o < 0:
                    continue
                g = o // 3
                if comp[g] >= 0:
                    continue
                # consistent neighbours run their shared edge in opposite directions
                same = he_dir[h] == he_dir[o]
                comp[g] = nc
                flip[g] = (not flip[f]) if same else flip[f]
                queue[tail] = g
                tail += 1
        nc += 1
    return flip, comp


# ---------------------------------------------------------------------------
# point - triangle

@njit(cache=True, inline="always")
def closest_on_tri(px, py, pz, t):
    """Closest point of triangle t (9 floats) to p: (qx, qy, qz, region)."""
    ax, ay, az = t[0], t[1], t[2]
    abx, aby, abz = t[3] - ax, t[4] - ay, t[5] - az
    acx, acy, acz = t[6] - ax, t[7] - ay, t[8] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, 1
    bpx, bpy, bpz = px - t[3], py - t[4], pz - t[5]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return t[3], t[4], t[5], 2
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, 4
    cpx, cpy, cpz = px - t[6], py - t[7], pz - t[8]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return t[6], t[7], t[8], 3
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, 6
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return t[3] + w * (t[6] - t[3]), t[4] + w * (t[7] - t[4]), t[5] + w * (t[8] - t[5]), 5
    den = va + vb + vc
    v = vb / den
    w = vc / den
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w, 0


@njit(cache=True, inline="always")
def _box_d2(lo, hi, n, px, py, pz):
    dx = max(lo[n, 0] - px, 0.0, px - hi[n, 0])
    dy = max(lo[n, 1] - py, 0.0, py - hi[n, 1])
    dz = max(lo[n, 2] - pz, 0.0, pz - hi[n, 2])
    return dx * dx + dy * dy + dz * dz


@njit(cache=True)
def closest_point(D, k, px, py, pz, maxd2):
    """Closest point of mesh k of D to p within squared distance maxd2.

    Returns (d2, qx, qy, qz, face, region); face = -1 (d2 = inf) when nothing is within maxd2.
    """
    lo, hi, kid, rng, tv = D[0], D[1], D[2], D[3], D[4]
    best = maxd2
    bf, breg = -1, 0
    bx, by, bz = np.nan, np.nan, np.nan
    stack = np.empty(STACK, np.int64)
    sd = np.empty(STACK)
    root = D[12][k]
    d0 = _box_d2(lo, hi, root, px, py, pz)
    if d0 > best:
        return np.inf, bx, by, bz, -1, 0
    stack[0] = root
    sd[0] = d0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if sd[top] > best:
            continue
        c0 = kid[node, 0]
        if c0 < 0:
            for f in range(rng[node, 0], rng[node, 1]):
                qx, qy, qz, reg = closest_on_tri(px, py, pz, tv[f])
                d2 = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
                if d2 < best or (d2 == best and bf < 0):
                    best, bf, breg = d2, f, reg
                    bx, by, bz = qx, qy, qz
            continue
        c1 = kid[node, 1]
        da = _box_d2(lo, hi, c0, px, py, pz)
        db = _box_d2(lo, hi, c1, px, py, pz)
        if da > db:  # push the farther child first
            c0, c1 = c1, c0
            da, db = db, da
        if db <= best:
            stack[top] = c1
            sd[top] = db
            top += 1
        if da <= best:
            stack[top] = c0
            sd[top] = da
            top += 1
    if bf < 0:
        return np.inf, bx, by, bz, -1, 0
    return best, bx, by, bz, bf, breg


@njit(cache=True, inline="always")
def region_normal(D, f, reg):
    """Pseudo-normal of the feature of face f named by the closest-point region."""
    if reg == 0:
        return D[5][f, 0], D[5][f, 1], D[5][f, 2]
    if reg <= 3:
        v = D[7][f, reg - 1]
        return D[9][v, 0], D[9][v, 1], D[9][v, 2]
    e = D[6][f, reg - 4]
    return D[8][e, 0], D[8][e, 1], D[8][e, 2]


@njit(cache=True, inline="always")
def region_on_boundary(D, f, reg):
    if reg == 0:
        return False
    if reg <= 3:
        return D[11][D[7][f, reg - 1]] != 0
    return D[10][D[6][f, reg - 4]] != 0


@njit(cache=True)
def signed_point(D, k, px, py, pz, maxd):
    """Signed distance of p to mesh k (pseudo-normal sign), inf beyond maxd; and the face."""
    d2, qx, qy, qz, f, reg = closest_point(D, k, px, py, pz, maxd * maxd if maxd < np.inf else np.inf)
    if f < 0:
        return np.inf, -1
    nx, ny, nz = region_normal(D, f, reg)
    s = (px - qx) * nx + (py - qy) * ny + (pz - qz) * nz
    d = math.sqrt(d2)
    return (d if s >= 0.0 else -d), f


# ---------------------------------------------------------------------------
# rays and segments

@njit(cache=True, inline="always")
def _ray_box(lo, hi, n, ox, oy, oz, ix, iy, iz, tmax):
    t0x = (lo[n, 0] - ox) * ix
    t1x = (hi[n, 0] - ox) * ix
    t0y = (lo[n, 1] - oy) * iy
    t1y = (hi[n, 1] - oy) * iy
    t0z = (lo[n, 2] - oz) * iz
    t1z = (hi[n, 2] - oz) * iz
    tn = max(min(t0x, t1x), min(t0y, t1y), min(t0z, t1z), 0.0)
    tf = min(max(t0x, t1x), max(t0y, t1y), max(t0z, t1z), tmax)
    return tn <= tf * (1.0 + 1e-12) + 1e-300


@njit(cache=True, inline="always")
def ray_tri(ox, oy, oz, dx, dy, dz, t, eps):
    """Moeller-Trumbore: ray parameter of the hit with triangle t, or -1 (barycentric slack eps)."""
    e1x, e1y, e1z = t[3] - t[0], t[4] - t[1], t[5] - t[2]
    e2x, e2y, e2z = t[6] - t[0], t[7] - t[1], t[8] - t[2]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return -1.0
    inv = 1.0 / det
    sx, sy, sz = ox - t[0], oy - t[1], oz - t[2]
    u = (sx * px + sy * py + sz * pz) * inv
    if u < -eps or u > 1.0 + eps:
        return -1.0
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < -eps or u + v > 1.0 + eps:
        return -1.0
    return (e2x * qx + e2y * qy + e2z * qz) * inv


@njit(cache=True)
def ray_hits(D, k, ox, oy, oz, dx, dy, dz, tmax, eps, first):
    """Hits of the ray o + t d, 0 <= t <= tmax, with mesh k.

    Returns (count, face): the number of triangles crossed and one face crossed (-1 if none).
    With ``first`` the walk stops at the first hit found (any one, not the nearest).
    """
    lo, hi, kid, rng, tv = D[0], D[1], D[2], D[3], D[4]
    ix = 1.0 / dx if dx != 0.0 else 1e300
    iy = 1.0 / dy if dy != 0.0 else 1e300
    iz = 1.0 / dz if dz != 0.0 else 1e300
    stack = np.empty(STACK, np.int64)
    stack[0] = D[12][k]
    top = 1
    count = 0
    hitf = -1
    while top > 0:
        top -= 1
        node = stack[top]
        if not _ray_box(lo, hi, node, ox, oy, oz, ix, iy, iz, tmax):
            continue
        if kid[node, 0] < 0:
            for f in range(rng[node, 0], rng[node, 1]):
                t = ray_tri(ox, oy, oz, dx, dy, dz, tv[f], eps)
                if t >= 0.0 and t <= tmax:
                    count += 1
                    hitf = f
                    if first:
                        return count, hitf
            continue
        stack[top] = kid[node, 0]
        stack[top + 1] = kid[node, 1]
        top += 2
    return count, hitf


@njit(cache=True)
def inside_point(D, k, px, py, pz):
    """Ray-parity vote (two rays, a third on disagreement): is p inside closed mesh k?"""
    a = ray_hits(D, k, px, py, pz, RAYS[0, 0], RAYS[0, 1], RAYS[0, 2], np.inf, 0.0, False)[0] & 1
    b = ray_hits(D, k, px, py, pz, RAYS[1, 0], RAYS[1, 1], RAYS[1, 2], np.inf, 0.0, False)[0] & 1
    if a == b:
        return a == 1
    c = ray_hits(D, k, px, py, pz, RAYS[2, 0], RAYS[2, 1], RAYS[2, 2], np.inf, 0.0, False)[0] & 1
    return c == 1


@njit(cache=True)
def in_root_box(D, k, px, py, pz, pad):
    n = D[12][k]
    lo, hi = D[0], D[1]
    return (lo[n, 0] - pad <= px <= hi[n, 0] + pad and lo[n, 1] - pad <= py <= hi[n, 1] + pad
            and lo[n, 2] - pad <= pz <= hi[n, 2] + pad)


@njit(cache=True)
def clearance_point(D, px, py, pz, maxd):
    """Signed clearance of p to the union of the meshes of D (closed, outward oriented).

    The minimum over meshes of the signed distance: > 0 outside every mesh (the distance to
    the nearest surface), < 0 inside one.  Points farther than maxd from every surface give
    +inf when outside all meshes and -inf when inside one.
    """
    best = np.inf
    for k in range(D[12].shape[0]):
        if not in_root_box(D, k, px, py, pz, maxd):
            continue
        s, f = signed_point(D, k, px, py, pz, maxd)
        if f < 0:
            if inside_point(D, k, px, py, pz):
                return -np.inf
            continue
        if s < best:
            best = s
    return best


# ---------------------------------------------------------------------------
# vectorised queries over many points

@njit(cache=True, parallel=True)
def closest_many(D, k, pts, maxd):
    n = pts.shape[0]
    dist = np.empty(n)
    foot = np.empty((n, 3))
    face = np.empty(n, np.int64)
    bnd = np.zeros(n, np.bool_)
    m2 = maxd * maxd if maxd < np.inf else np.inf
    for i in prange(n):
        d2, qx, qy, qz, f, reg = closest_point(D, k, pts[i, 0], pts[i, 1], pts[i, 2], m2)
        face[i] = f
        foot[i, 0], foot[i, 1], foot[i, 2] = qx, qy, qz
        if f < 0:
            dist[i] = np.inf
        else:
            dist[i] = math.sqrt(d2)
            bnd[i] = region_on_boundary(D, f, reg)
    return dist, foot, face, bnd


@njit(cache=True, parallel=True)
def signed_many(D, k, pts, maxd):
    n = pts.shape[0]
    out = np.empty(n)
    for i in prange(n):
        out[i] = signed_point(D, k, pts[i, 0], pts[i, 1], pts[i, 2], maxd)[0]
    return out


@njit(cache=True, parallel=True)
def signed_full_many(D, k, pts, maxd):
    """Signed distance, face and whether the foot is on the surface boundary."""
    n = pts.shape[0]
    sd = np.empty(n)
    face = np.empty(n, np.int64)
    bnd = np.zeros(n, np.bool_)
    m2 = maxd * maxd if maxd < np.inf else np.inf
    for i in prange(n):
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        d2, qx, qy, qz, f, reg = closest_point(D, k, px, py, pz, m2)
        face[i] = f
        if f < 0:
            sd[i] = np.inf
            continue
        nx, ny, nz = region_normal(D, f, reg)
        s = (px - qx) * nx + (py - qy) * ny + (pz - qz) * nz
        d = math.sqrt(d2)
        sd[i] = d if s >= 0.0 else -d
        bnd[i] = region_on_boundary(D, f, reg)
    return sd, face, bnd


@njit(cache=True, parallel=True)
def inside_many(D, k, pts):
    n = pts.shape[0]
    out = np.zeros(n, np.bool_)
    for i in prange(n):
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        if in_root_box(D, k, px, py, pz, 0.0):
            out[i] = inside_point(D, k, px, py, pz)
    return out


@njit(cache=True, parallel=True)
def clearance_many(D, pts, maxd):
    n = pts.shape[0]
    out = np.empty(n)
    for i in prange(n):
        out[i] = clearance_point(D, pts[i, 0], pts[i, 1], pts[i, 2], maxd)
    return out


@njit(cache=True, parallel=True)
def removed_by_cavity(D, k, pts, rad):
    """True where the sphere (centre p, radius rad[i]) overlaps closed mesh k: its centre is
    inside, or closer than its radius to the surface.  Only points in the mesh's bounding box
    padded by the largest radius are tested."""
    n = pts.shape[0]
    out = np.zeros(n, np.bool_)
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, rad[i])
    for i in prange(n):
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        if not in_root_box(D, k, px, py, pz, rmax):
            continue
        r2 = rad[i] * rad[i]
        d2 = closest_point(D, k, px, py, pz, r2)[0]
        if d2 < r2:
            out[i] = True
        else:
            out[i] = inside_point(D, k, px, py, pz)
    return out


@njit(cache=True, parallel=True)
def segments_cross(D, k, a, b, eps):
    """Face of mesh k crossed by each segment a[i] -> b[i] (-1: none)."""
    n = a.shape[0]
    out = np.full(n, -1, np.int64)
    for i in prange(n):
        dx, dy, dz = b[i, 0] - a[i, 0], b[i, 1] - a[i, 1], b[i, 2] - a[i, 2]
        out[i] = ray_hits(D, k, a[i, 0], a[i, 1], a[i, 2], dx, dy, dz, 1.0, eps, True)[1]
    return out
