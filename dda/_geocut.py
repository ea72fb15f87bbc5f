"""Numba kernels of the block model's cutting (dda/geoblocks.py, dda/geoexcavate.py): overlap of one convex
polygon with many (separating axes), in the plan or in a cutter's plane."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _separated(p, q, eps):
    """True when an edge normal of the convex polygon p separates p and q (gap or contact within eps)."""
    n = p.shape[0]
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        ax, ay = p[j, 1] - p[i, 1], p[i, 0] - p[j, 0]
        ln = math.sqrt(ax * ax + ay * ay)
        if ln == 0.0:
            continue
        ax /= ln
        ay /= ln
        pmin = pmax = p[0, 0] * ax + p[0, 1] * ay
        for k in range(1, n):
            t = p[k, 0] * ax + p[k, 1] * ay
            pmin = min(pmin, t)
            pmax = max(pmax, t)
        qmin = qmax = q[0, 0] * ax + q[0, 1] * ay
        for k in range(1, q.shape[0]):
            t = q[k, 0] * ax + q[k, 1] * ay
            qmin = min(qmin, t)
            qmax = max(qmax, t)
        if pmax - qmin <= eps or qmax - pmin <= eps:
            return True
    return False


@njit(cache=True)
def overlap_mask(fp, polys, ids, eps):
    """For each k, True when the convex polygon fp (m, 2) and polys[ids[k]] (p, 2) (a convex polygon, or a
    segment when p = 2) overlap by more than eps along every separating axis."""
    out = np.zeros(ids.shape[0], np.bool_)
    for k in range(ids.shape[0]):
        q = polys[ids[k]]
        out[k] = not (_separated(fp, q, eps) or _separated(q, fp, eps))
    return out


@njit(cache=True)
def signed_snapped(v, nx, ny, nz, d, rel):
    """Signed distances of the vertices to the plane (nx, ny, nz) . x = d (unit normal); those within rel times
    the vertices' box diagonal are set to 0."""
    lo = v[0].copy()
    hi = v[0].copy()
    for i in range(1, v.shape[0]):
        for a in range(3):
            lo[a] = min(lo[a], v[i, a])
            hi[a] = max(hi[a], v[i, a])
    eps = rel * math.sqrt((hi[0] - lo[0]) ** 2 + (hi[1] - lo[1]) ** 2 + (hi[2] - lo[2]) ** 2)
    s = np.empty(v.shape[0])
    for i in range(v.shape[0]):
        t = v[i, 0] * nx + v[i, 1] * ny + v[i, 2] * nz - d
        s[i] = 0.0 if abs(t) <= eps else t
    return s


@njit(cache=True)
def _compact(allv, ptr, idx, nf, ni):
    """The vertices used by faces ptr/idx (nf faces, ni indices) and the faces renumbered."""
    remap = np.full(allv.shape[0], -1, np.int64)
    k = 0
    for j in range(ni):
        if remap[idx[j]] < 0:
            remap[idx[j]] = k
            k += 1
    out = np.empty((k, 3))
    for i in range(allv.shape[0]):
        if remap[i] >= 0:
            out[remap[i]] = allv[i]
    nidx = np.empty(ni, np.int64)
    for j in range(ni):
        nidx[j] = remap[idx[j]]
    return out, ptr[:nf + 1].copy(), nidx


@njit(cache=True)
def _cap(allv, s, nv, nnew, nx, ny, nz):
    """Indices of the points on the plane (vertices with s == 0 and the new points), counter-clockwise about n."""
    m = nnew
    for i in range(nv):
        if s[i] == 0.0:
            m += 1
    on = np.empty(m, np.int64)
    k = 0
    for i in range(nv):
        if s[i] == 0.0:
            on[k] = i
            k += 1
    for i in range(nnew):
        on[k] = nv + i
        k += 1
    c = np.zeros(3)
    for i in range(m):
        c += allv[on[i]]
    c /= m
    far, best = 0, -1.0
    for i in range(m):
        dd = ((allv[on[i]] - c) ** 2).sum()
        if dd > best:
            best, far = dd, i
    e1 = allv[on[far]] - c
    dn = e1[0] * nx + e1[1] * ny + e1[2] * nz
    e1[0] -= dn * nx
    e1[1] -= dn * ny
    e1[2] -= dn * nz
    e1 /= math.sqrt((e1 ** 2).sum())
    e2 = np.array([ny * e1[2] - nz * e1[1], nz * e1[0] - nx * e1[2], nx * e1[1] - ny * e1[0]])
    ang = np.empty(m)
    for i in range(m):
        w = allv[on[i]] - c
        ang[i] = math.atan2((w * e2).sum(), (w * e1).sum())
    return on[np.argsort(ang, kind="mergesort")]


@njit(cache=True)
def _clip_faces(v, fptr, fidx, fsrc, s, made, newp):
    """Sutherland-Hodgman on every face: the faces below (s <= 0) and above (s >= 0) as CSR, the new points on
    crossed edges (one per edge, in newp), and their count."""
    nv, nf = v.shape[0], fptr.shape[0] - 1
    size = fidx.shape[0] + 2 * nf + nv + newp.shape[0] + 4
    idx = np.empty((2, size), np.int64)
    ptr = np.zeros((2, nf + 2), np.int64)
    src = np.empty((2, nf + 1), np.int64)
    nfs = np.zeros(2, np.int64)
    nis = np.zeros(2, np.int64)
    nnew = 0
    for f in range(nf):
        a0, m = fptr[f], fptr[f + 1] - fptr[f]
        start = nis.copy()
        for k in range(m):
            a, c = fidx[a0 + k], fidx[a0 + (k + 1) % m]
            sa, sc = s[a], s[c]
            if sa <= 0.0:
                idx[0, nis[0]] = a
                nis[0] += 1
            if sa >= 0.0:
                idx[1, nis[1]] = a
                nis[1] += 1
            if sa * sc < 0.0:
                p, q = min(a, c), max(a, c)
                i = made[p, q]
                if i < 0:
                    i = nv + nnew
                    made[p, q] = i
                    t = s[p] / (s[p] - s[q])
                    newp[nnew] = v[p] + t * (v[q] - v[p])
                    nnew += 1
                for side in range(2):
                    idx[side, nis[side]] = i
                    nis[side] += 1
        for side in range(2):
            if nis[side] - start[side] >= 3:
                src[side, nfs[side]] = fsrc[f]
                nfs[side] += 1
                ptr[side, nfs[side]] = nis[side]
            else:
                nis[side] = start[side]
    return idx, ptr, src, nfs, nis, nnew


@njit(cache=True)
def split_csr(v, fptr, fidx, fsrc, s, source, nx, ny, nz):
    """Cut the convex polyhedron (v, faces fptr/fidx, face sources fsrc) by the plane of unit normal n, with the
    snapped signed distances s of its vertices (both signs present). Returns the pieces below and above as
    (vertices, fptr, fidx, fsrc) each, the caps on the plane with face source ``source``."""
    nv = v.shape[0]
    made = np.full((nv, nv), -1, np.int64)
    newp = np.empty((fidx.shape[0], 3))
    idx, ptr, src, nfs, nis, nnew = _clip_faces(v, fptr, fidx, fsrc, s, made, newp)
    allv = np.empty((nv + nnew, 3))
    allv[:nv] = v
    allv[nv:] = newp[:nnew]
    cap = _cap(allv, s, nv, nnew, nx, ny, nz)
    m = cap.shape[0]
    for side in range(2):
        for j in range(m):
            idx[side, nis[side] + j] = cap[j] if side == 0 else cap[m - 1 - j]
        nis[side] += m
        src[side, nfs[side]] = source
        nfs[side] += 1
        ptr[side, nfs[side]] = nis[side]
    vl, pl, il = _compact(allv, ptr[0], idx[0], nfs[0], nis[0])
    vh, ph, ih = _compact(allv, ptr[1], idx[1], nfs[1], nis[1])
    return vl, pl, il, src[0, :nfs[0]].copy(), vh, ph, ih, src[1, :nfs[1]].copy()


@njit(cache=True)
def volume_centroid_csr(v, fptr, fidx):
    """Volume and centroid of a closed polyhedron with outward faces (fan tetrahedra about the vertex mean)."""
    ref = np.zeros(3)
    for i in range(v.shape[0]):
        ref += v[i]
    ref /= v.shape[0]
    vol = 0.0
    acc = np.zeros(3)
    for f in range(fptr.shape[0] - 1):
        a0 = fptr[f]
        p0 = v[fidx[a0]] - ref
        for k in range(a0 + 1, fptr[f + 1] - 1):
            p1 = v[fidx[k]] - ref
            p2 = v[fidx[k + 1]] - ref
            t = (p0[0] * (p1[1] * p2[2] - p1[2] * p2[1]) + p0[1] * (p1[2] * p2[0] - p1[0] * p2[2])
                 + p0[2] * (p1[0] * p2[1] - p1[1] * p2[0])) / 6.0
            vol += t
            acc += t * (p0 + p1 + p2)
    if vol == 0.0:
        return 0.0, ref
    return vol, ref + acc / (4.0 * vol)


@njit(cache=True)
def edges_csr(nv, fptr, fidx):
    """(m, 2) undirected edges (a < b) of the faces."""
    seen = np.zeros((nv, nv), np.bool_)
    out = np.empty((fidx.shape[0], 2), np.int64)
    m = 0
    for f in range(fptr.shape[0] - 1):
        a0, n = fptr[f], fptr[f + 1] - fptr[f]
        for k in range(n):
            a, b = fidx[a0 + k], fidx[a0 + (k + 1) % n]
            p, q = min(a, b), max(a, b)
            if not seen[p, q]:
                seen[p, q] = True
                out[m, 0] = p
                out[m, 1] = q
                m += 1
    return out[:m].copy()


@njit(cache=True)
def face_planes_csr(v, fptr, fidx):
    """Outward unit normals (Newell's method) and offsets (through the face's vertex mean) of every face."""
    nf = fptr.shape[0] - 1
    n = np.zeros((nf, 3))
    d = np.zeros(nf)
    for f in range(nf):
        a0, m = fptr[f], fptr[f + 1] - fptr[f]
        c = np.zeros(3)
        for k in range(m):
            p, q = v[fidx[a0 + k]], v[fidx[a0 + (k + 1) % m]]
            n[f, 0] += (p[1] - q[1]) * (p[2] + q[2])
            n[f, 1] += (p[2] - q[2]) * (p[0] + q[0])
            n[f, 2] += (p[0] - q[0]) * (p[1] + q[1])
            c += p
        ln = math.sqrt((n[f] ** 2).sum())
        n[f] /= ln
        d[f] = (n[f] * c).sum() / m
    return n, d


@njit(cache=True)
def _turn(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


@njit(cache=True)
def hull2d(p):
    """Counter-clockwise convex hull (monotone chain) of the 2D points p (n, 2); collinear points dropped."""
    o = np.argsort(p[:, 1], kind="mergesort")
    o = o[np.argsort(p[o, 0], kind="mergesort")]
    q = p[o]
    n = q.shape[0]
    out = np.empty((2 * n + 1, 2))
    k = 0
    for i in range(n):  # lower chain
        while k >= 2 and _turn(out[k - 2], out[k - 1], q[i]) <= 0.0:
            k -= 1
        out[k] = q[i]
        k += 1
    lo = k + 1
    for i in range(n - 2, -1, -1):  # upper chain
        while k >= lo and _turn(out[k - 2], out[k - 1], q[i]) <= 0.0:
            k -= 1
        out[k] = q[i]
        k += 1
    return out[:max(k - 1, 0)].copy()


@njit(cache=True)
def section_2d(v, edges, s, ox, oy, oz, e1, e2):
    """The section points of a convex block by a plane (snapped signed distances s of its vertices; edges (m, 2))
    in the plane's coordinates (e1, e2) about the origin o, as a convex counter-clockwise polygon."""
    pts = np.empty((edges.shape[0] + v.shape[0], 2))
    k = 0
    for j in range(edges.shape[0]):
        a, b = edges[j, 0], edges[j, 1]
        if s[a] * s[b] < 0.0:
            t = s[a] / (s[a] - s[b])
            x = v[a, 0] + t * (v[b, 0] - v[a, 0]) - ox
            y = v[a, 1] + t * (v[b, 1] - v[a, 1]) - oy
            z = v[a, 2] + t * (v[b, 2] - v[a, 2]) - oz
            pts[k, 0] = x * e1[0] + y * e1[1] + z * e1[2]
            pts[k, 1] = x * e2[0] + y * e2[1] + z * e2[2]
            k += 1
    for i in range(v.shape[0]):
        if s[i] == 0.0:
            x, y, z = v[i, 0] - ox, v[i, 1] - oy, v[i, 2] - oz
            pts[k, 0] = x * e1[0] + y * e1[1] + z * e1[2]
            pts[k, 1] = x * e2[0] + y * e2[1] + z * e2[2]
            k += 1
    if k < 3:
        return pts[:0].copy()
    return hull2d(pts[:k].copy())


@njit(cache=True)
def origin_distance(poly):
    """Distance from the origin to the convex counter-clockwise polygon poly (0 inside)."""
    n = poly.shape[0]
    inside = True
    best = np.inf
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        ex, ey = b[0] - a[0], b[1] - a[1]
        if ex * (-a[1]) - ey * (-a[0]) < 0.0:
            inside = False
        ee = ex * ex + ey * ey
        t = 0.0 if ee == 0.0 else min(1.0, max(0.0, -(a[0] * ex + a[1] * ey) / ee))
        dx, dy = a[0] + t * ex, a[1] + t * ey
        best = min(best, math.sqrt(dx * dx + dy * dy))
    return 0.0 if inside else best
