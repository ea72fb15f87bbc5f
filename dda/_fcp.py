"""numba kernels: Fast Common-Plane (FCP) search and contact points of two convex polyhedra.

Convention: the common-plane normal ``n`` points from block A to block B. The gap of a direction is
``min_B (x . n) - max_A (x . n)``: positive when the plane separates the blocks, negative (minus the overlap
along n) when they overlap. FCP maximises the gap over the candidate planes of the digest, starting from the
cached plane of the pair (or the centroid bisector), and stops when the plane no longer changes.

Contact points: the candidates are the vertices of either block inside the overlap slab and the crossings of
an edge of A with an edge of B seen along n. A point of A's surface (vertex or edge crossing) has the depth
of B behind it along -n (the line through it is clipped against B); a vertex of B the depth of A beyond it
along n. The contact point is the middle of that overlap segment. Where the other block is thin (its part of
the line ends before it reaches the point, a corner of it sunk into this block), the point still bears when that
part lies inside the point's own block: the surfaces overlap along the line by the same depth (``_reaches``).
A block resting on a face thus gets the corners
of the clipped contact polygon (4 for a block on a larger face), an edge on a face its two clipped ends, an
edge across an edge their crossing, a vertex on a face the vertex.

A point in the crease where two blocks meet (a wedge's lower edge between its two joint blocks) has sunk into
both, so it lies just outside each one's side face by its depth in the other. It gets one contact per block,
with that block's facing plane and its depth below that plane (see ``clip_line``). Seen along n such a vertex
lies beyond the edge of the facing face; the crossing of its edges with that edge is then not a corner of the
contact polygon but the vertex's own contact, and is left out (``_crease_covered``). Counted as well, it
doubled the crease's stiffness and, coming and going with small rocking, gave points without shear history
that stayed locked and resisted sliding like viscous dampers (a prism in a V-groove crept instead of sliding).
Candidates closer in the plane than twice the plane's overlap are one contact point (the deepest is kept, a
vertex's id is preferred).
"""
from __future__ import annotations

import numpy as np
from numba import njit

MAXP = 16  # contact points kept per pair


@njit(cache=True, inline="always")
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def gap_along(vert, va0, va1, vb0, vb1, n0, n1, n2):
    """(gap, index of A's vertex farthest along n, index of B's vertex farthest against n)."""
    amax = -1e300
    ia = va0
    for v in range(va0, va1):
        s = vert[v, 0] * n0 + vert[v, 1] * n1 + vert[v, 2] * n2
        if s > amax:
            amax = s
            ia = v
    bmin = 1e300
    ib = vb0
    for v in range(vb0, vb1):
        s = vert[v, 0] * n0 + vert[v, 1] * n1 + vert[v, 2] * n2
        if s < bmin:
            bmin = s
            ib = v
    return bmin - amax, ia, ib, amax, bmin


@njit(cache=True)
def _gather_edges(vert, v, he_origin, he_next, he_pair, he_face, vert_he, out_dir, out_face):
    """Edges leaving vertex v (unit directions) and the faces around it; returns their count."""
    start = vert_he[v]
    e = start
    k = 0
    while k < out_dir.shape[0]:
        w = he_origin[he_next[e]]
        d0 = vert[w, 0] - vert[v, 0]
        d1 = vert[w, 1] - vert[v, 1]
        d2 = vert[w, 2] - vert[v, 2]
        ln = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if ln > 0:
            out_dir[k, 0] = d0 / ln
            out_dir[k, 1] = d1 / ln
            out_dir[k, 2] = d2 / ln
        else:
            out_dir[k, 0] = 0.0
            out_dir[k, 1] = 0.0
            out_dir[k, 2] = 0.0
        out_face[k] = he_face[e]
        k += 1
        e = he_next[he_pair[e]]
        if e == start:
            break
    return k


@njit(cache=True)
def fcp(vert, fnw, va0, va1, vb0, vb1, he_origin, he_next, he_pair, he_face, vert_he, n_init, tol, maxit, out_n):
    """Fast Common-Plane search. Writes the unit normal (A -> B) into out_n and returns
    (gap, ia, ib, sA, sB, iterations): sA = max_A x.n, sB = min_B x.n; the plane is x.n = (sA + sB) / 2."""
    n0, n1, n2 = n_init[0], n_init[1], n_init[2]
    ln = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    n0 /= ln
    n1 /= ln
    n2 /= ln
    g, ia, ib, sa, sb = gap_along(vert, va0, va1, vb0, vb1, n0, n1, n2)
    dirA = np.empty((24, 3))
    dirB = np.empty((24, 3))
    faceA = np.empty(24, np.int64)
    faceB = np.empty(24, np.int64)
    it = 0
    while it < maxit:
        it += 1
        bg = g
        b0, b1, b2 = n0, n1, n2
        bia, bib, bsa, bsb = ia, ib, sa, sb
        ka = _gather_edges(vert, ia, he_origin, he_next, he_pair, he_face, vert_he, dirA, faceA)
        kb = _gather_edges(vert, ib, he_origin, he_next, he_pair, he_face, vert_he, dirB, faceB)
        d0 = vert[ib, 0] - vert[ia, 0]
        d1 = vert[ib, 1] - vert[ia, 1]
        d2 = vert[ib, 2] - vert[ia, 2]
        dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        # candidates: c = 0 bisector of AB; 1..ka faces at A; faces at B; edge x edge; edge-perpendicular
        ncand = 1 + ka + kb + ka * kb + ka + kb
        for c in range(ncand):
            c0 = 0.0
            c1 = 0.0
            c2 = 0.0
            if c == 0:
                if dl <= 0:
                    continue
                c0, c1, c2 = d0 / dl, d1 / dl, d2 / dl
            elif c <= ka:
                f = faceA[c - 1]
                c0, c1, c2 = fnw[f, 0], fnw[f, 1], fnw[f, 2]
            elif c <= ka + kb:
                f = faceB[c - 1 - ka]
                c0, c1, c2 = -fnw[f, 0], -fnw[f, 1], -fnw[f, 2]
            elif c <= ka + kb + ka * kb:
                m = c - 1 - ka - kb
                p = m // kb
                q = m - p * kb
                c0 = dirA[p, 1] * dirB[q, 2] - dirA[p, 2] * dirB[q, 1]
                c1 = dirA[p, 2] * dirB[q, 0] - dirA[p, 0] * dirB[q, 2]
                c2 = dirA[p, 0] * dirB[q, 1] - dirA[p, 1] * dirB[q, 0]
                cl = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
                if cl < 1e-9:
                    continue
                c0 /= cl
                c1 /= cl
                c2 /= cl
            else:
                if dl <= 0:
                    continue
                m = c - 1 - ka - kb - ka * kb
                if m < ka:
                    e0, e1, e2 = dirA[m, 0], dirA[m, 1], dirA[m, 2]
                else:
                    e0, e1, e2 = dirB[m - ka, 0], dirB[m - ka, 1], dirB[m - ka, 2]
                t = d0 * e0 + d1 * e1 + d2 * e2
                c0 = d0 - t * e0
                c1 = d1 - t * e1
                c2 = d2 - t * e2
                cl = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
                if cl < 1e-9 * dl:
                    continue
                c0 /= cl
                c1 /= cl
                c2 /= cl
            if c0 * n0 + c1 * n1 + c2 * n2 < 0:
                c0, c1, c2 = -c0, -c1, -c2
            cg, cia, cib, csa, csb = gap_along(vert, va0, va1, vb0, vb1, c0, c1, c2)
            if cg > bg + tol:
                bg = cg
                b0, b1, b2 = c0, c1, c2
                bia, bib, bsa, bsb = cia, cib, csa, csb
        if bg > g + tol:
            g = bg
            n0, n1, n2 = b0, b1, b2
            ia, ib, sa, sb = bia, bib, bsa, bsb
        else:
            break
    out_n[0] = n0
    out_n[1] = n1
    out_n[2] = n2
    return g, ia, ib, sa, sb, it


@njit(cache=True)
def clip_line(P, n, fnw, fdw, f0, f1, tol, lat=0.0, sgn=-1.0):
    """Interval [lo, hi] of t for which P + t n lies in the convex block with faces f0..f1 (lo > hi: empty).

    A face (nearly) parallel to n only decides whether the line is inside (P on its plane counts as inside);
    this keeps points that lie on a side face of the other block (coplanar faces) from being cut by rounding.

    Face contacts (lat > 0): when the block has a reference face facing the contact (its outward normal within
    about 8 degrees of ``sgn * n``: sgn = -1 for the block on the +n side, +1 for the block on the -n side), the
    point is measured against that face's plane alone as long as it lies within ``lat`` of the block's other
    faces. A vertex sitting in the crease where two blocks meet (a wedge's edge in its groove, a block's corner
    at a joint between two others) has been pushed slightly across the neighbour's boundary by its penetration
    into the neighbour; it still bears on each block by that block's facing plane."""
    lo = -1e300
    hi = 1e300
    fref = -1
    if lat > 0.0:
        best = 0.99
        for f in range(f0, f1):
            nd = sgn * (fnw[f, 0] * n[0] + fnw[f, 1] * n[1] + fnw[f, 2] * n[2])
            if nd > best:
                best = nd
                fref = f
    for f in range(f0, f1):
        nd = fnw[f, 0] * n[0] + fnw[f, 1] * n[1] + fnw[f, 2] * n[2]
        num = fdw[f] - (fnw[f, 0] * P[0] + fnw[f, 1] * P[1] + fnw[f, 2] * P[2])
        if fref >= 0 and f != fref:
            if num < -lat:
                return 1.0, -1.0
            continue
        if nd > 1e-7:
            t = num / nd
            if t < hi:
                hi = t
        elif nd < -1e-7:
            t = num / nd
            if t > lo:
                lo = t
        elif num < -tol:
            return 1.0, -1.0
    return lo, hi


@njit(cache=True)
def _reaches(P, n, fnw, fdw, f0, f1, tol, t, sgn):
    """True when the block with faces f0..f1, which P lies on, reaches along the line P + s n from P to s = t
    (sgn = -1: t < 0, the block lies behind P; sgn = +1: t > 0, beyond P).

    A point of one block's surface whose line along n meets the other block only on the far side of the point
    (the other block is thin there: its part of the line ends before reaching the point) is still a contact
    when that part lies inside the point's own block: the two surfaces overlap along the line by the same
    common-plane depth as for a point inside the other block."""
    lo, hi = clip_line(P, n, fnw, fdw, f0, f1, tol)
    if lo > hi:
        return False
    if sgn < 0.0:
        return lo <= t + tol
    return hi >= t - tol


@njit(cache=True)
def _crease_covered(vert, fnw, fdw, p, x0, x1, n, f0, f1, tol, lat, sgn, overlap):
    """True when vertex p of one block, seen along n, lies beyond the edge x0-x1 between the other block's facing
    face and a side face, and is still a contact point (crease rule: it penetrates the facing face and lies
    within lat of the other faces). The crossing of p's edges with that edge then lies between p and the facing
    face: p is the contact polygon's corner there, and the crossing would count the crease twice."""
    has_ref = False
    for f in range(f0, f1):
        if sgn * (fnw[f, 0] * n[0] + fnw[f, 1] * n[1] + fnw[f, 2] * n[2]) > 0.99:
            has_ref = True
            break
    if not has_ref:
        return False
    on = 10.0 * tol
    side = False
    for f in range(f0, f1):
        if sgn * (fnw[f, 0] * n[0] + fnw[f, 1] * n[1] + fnw[f, 2] * n[2]) > 0.99:
            continue
        if abs(_dot(fnw[f], x0) - fdw[f]) > on or abs(_dot(fnw[f], x1) - fdw[f]) > on:
            continue
        # f is the side face at the edge: p beyond the edge, seen along n (outward in-plane direction m)
        sn = _dot(fnw[f], n)
        m0 = fnw[f, 0] - sn * n[0]
        m1 = fnw[f, 1] - sn * n[1]
        m2 = fnw[f, 2] - sn * n[2]
        if m0 * (p[0] - x0[0]) + m1 * (p[1] - x0[1]) + m2 * (p[2] - x0[2]) > 0.0:
            side = True
            break
    if not side:
        return False
    lo, hi = clip_line(p, n, fnw, fdw, f0, f1, tol, lat, sgn)
    if lo > hi:
        return False
    if sgn < 0.0:
        return min(-lo, overlap) > 0.0 and hi >= -tol
    return min(hi, overlap) > 0.0 and lo <= tol


@njit(cache=True, inline="always")
def _edge_crossing(vert, he_origin, he_next, scr, na, va0, vb0, ha, hb, P):
    """Where edge ha of A crosses edge hb of B seen along n (2D segment intersection in the plane, coordinates
    in scr) into P; False when they do not cross."""
    pa = he_origin[ha] - va0
    qa = he_origin[he_next[ha]] - va0
    pb = na + he_origin[hb] - vb0
    qb = na + he_origin[he_next[hb]] - vb0
    x1 = scr[pa, 1]
    y1 = scr[pa, 2]
    dx1 = scr[qa, 1] - x1
    dy1 = scr[qa, 2] - y1
    x2 = scr[pb, 1]
    y2 = scr[pb, 2]
    dx2 = scr[qb, 1] - x2
    dy2 = scr[qb, 2] - y2
    den = dx1 * dy2 - dy1 * dx2
    l1 = np.sqrt(dx1 * dx1 + dy1 * dy1)
    l2 = np.sqrt(dx2 * dx2 + dy2 * dy2)
    if abs(den) <= 1e-9 * l1 * l2 or l1 == 0.0 or l2 == 0.0:
        return False
    rx = x2 - x1
    ry = y2 - y1
    t = (rx * dy2 - ry * dx2) / den
    u = (rx * dy1 - ry * dx1) / den
    if t < 0.0 or t > 1.0 or u < 0.0 or u > 1.0:
        return False
    ga = he_origin[ha]
    gq = he_origin[he_next[ha]]
    for j in range(3):
        P[j] = vert[ga, j] + t * (vert[gq, j] - vert[ga, j])
    return True


# not inlined: it calls _crease_covered, and the arrays an inlined kernel takes are counted in and out around
# every call it makes (dda/_narrow.py's docstring); it runs only for crossings that bear
@njit(cache=True)
def _crossing_covered(vert, fnw, fdw, he_origin, he_next, ha, hb, n, fa0, fa1, fb0, fb1, tol, lat, overlap):
    """A crossing of edges ha (A) and hb (B) next to a vertex that bears by the crease rule is that vertex's
    contact."""
    ga = he_origin[ha]
    gq = he_origin[he_next[ha]]
    gb = he_origin[hb]
    gr = he_origin[he_next[hb]]
    return (_crease_covered(vert, fnw, fdw, vert[ga], vert[gb], vert[gr], n, fb0, fb1, tol, lat, -1.0, overlap)
            or _crease_covered(vert, fnw, fdw, vert[gq], vert[gb], vert[gr], n, fb0, fb1, tol, lat, -1.0, overlap)
            or _crease_covered(vert, fnw, fdw, vert[gb], vert[ga], vert[gq], n, fa0, fa1, tol, lat, 1.0, overlap)
            or _crease_covered(vert, fnw, fdw, vert[gr], vert[ga], vert[gq], n, fa0, fa1, tol, lat, 1.0, overlap))


@njit(cache=True, inline="always")
def _keep_point(P, n, e1, e2, depth, mid, cid, merge, lat, k, cu, cv, out_pos, out_depth, out_id):
    """Store the candidate P (depth, id cid) unless a stored point lies within `merge` in the plane and is as
    deep (a deeper one replaces it; when full, it replaces the shallowest point if deeper); returns the count."""
    maxp = out_depth.shape[0]
    u2 = _dot(P, e1)
    v2 = _dot(P, e2)
    dup = -1
    for j in range(k):
        if abs(cu[j] - u2) < merge and abs(cv[j] - v2) < merge:
            dup = j
            break
    slot = k
    if dup >= 0:
        if depth <= out_depth[dup] + 0.01 * lat:
            if cid < out_id[dup] and cid > 0:
                out_id[dup] = cid
            return k
        slot = dup  # a clearly deeper candidate at the same place replaces the stored one
    elif k == maxp:
        # full: replace the shallowest point if this one is deeper
        slot = 0
        for j in range(1, maxp):
            if out_depth[j] < out_depth[slot]:
                slot = j
        if out_depth[slot] >= depth:
            return k
    else:
        k += 1
    cu[slot] = u2
    cv[slot] = v2
    out_depth[slot] = depth
    out_id[slot] = cid
    for j in range(3):
        out_pos[slot, j] = P[j] + mid * n[j]
    return k


@njit(cache=True)
def contact_points(geom, i, j, n, sa, sb, keep_gap, size, out_pos, out_depth, out_id, scr=None, iscr=None):
    """Contact points of blocks A = i and B = j (geom: dda._state.Geometry) for the common-plane normal n (A -> B).

    sa = max_A x.n and sb = min_B x.n (from fcp). Points whose depth exceeds -keep_gap are returned
    (keep_gap > 0 keeps slightly open points, for bonded contacts). Returns the count, or -1 when the blocks
    overlap along n but no candidate lies inside the other block. `scr` (>= nA + nB rows, 3 columns) and `iscr`
    (>= edges of A + edges of B) are optional scratch arrays (allocated when not given)."""
    vert, fnw, fdw = geom.vert, geom.fnw, geom.fdw
    he_origin, he_next, edge_he = geom.he_origin, geom.he_next, geom.edge_he
    va0, va1, fa0, fa1, ea0, ea1 = geom.vs[i], geom.vs[i + 1], geom.fs[i], geom.fs[i + 1], geom.es[i], geom.es[i + 1]
    vb0, vb1, fb0, fb1, eb0, eb1 = geom.vs[j], geom.vs[j + 1], geom.fs[j], geom.fs[j + 1], geom.es[j], geom.es[j + 1]
    nhe = he_origin.shape[0]
    tol = 1e-9 * size
    merge = 1e-7 * size
    # tangent basis
    if abs(n[0]) < 0.9:
        a0, a1, a2 = 0.0, n[2], -n[1]
    else:
        a0, a1, a2 = -n[2], 0.0, n[0]
    al = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    e1 = np.array([a0 / al, a1 / al, a2 / al])
    e2 = np.array([n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0]])
    lo_slab = sb - keep_gap - tol
    hi_slab = sa + keep_gap + tol
    lat = max(sa - sb, 0.0) + tol  # lateral tolerance (crease points, see clip_line)
    merge = max(merge, 2.0 * lat)  # candidates closer than twice the overlap are one contact point
    maxp = out_depth.shape[0]
    cu = np.empty(maxp)
    cv = np.empty(maxp)
    k = 0
    P = np.empty(3)
    na = va1 - va0
    nb = vb1 - vb0
    if scr is None or scr.shape[0] < na + nb:
        scr = np.empty((na + nb, 3))
    if iscr is None or iscr.shape[0] < (ea1 - ea0) + (eb1 - eb0):
        iscr = np.empty((ea1 - ea0) + (eb1 - eb0), np.int64)
    # coordinates of every vertex along n and in the plane, once
    for v in range(va0, va1):
        scr[v - va0, 0] = _dot(vert[v], n)
        scr[v - va0, 1] = _dot(vert[v], e1)
        scr[v - va0, 2] = _dot(vert[v], e2)
    for v in range(vb0, vb1):
        scr[na + v - vb0, 0] = _dot(vert[v], n)
        scr[na + v - vb0, 1] = _dot(vert[v], e1)
        scr[na + v - vb0, 2] = _dot(vert[v], e2)
    # edges that reach into the overlap slab
    nA = 0
    for e in range(ea0, ea1):
        h = edge_he[e]
        if scr[he_origin[h] - va0, 0] >= lo_slab or scr[he_origin[he_next[h]] - va0, 0] >= lo_slab:
            iscr[nA] = h
            nA += 1
    nB = 0
    for e in range(eb0, eb1):
        h = edge_he[e]
        if scr[na + he_origin[h] - vb0, 0] <= hi_slab or scr[na + he_origin[he_next[h]] - vb0, 0] <= hi_slab:
            iscr[nA + nB] = h
            nB += 1
    total = na + nb + nA * nB
    for c in range(total):
        cid = 0
        if c < na:
            if scr[c, 0] < lo_slab:
                continue
            v = va0 + c
            P[0], P[1], P[2] = vert[v, 0], vert[v, 1], vert[v, 2]
            cid = v + 1
        elif c < na + nb:
            if scr[c, 0] > hi_slab:
                continue
            v = vb0 + c - na
            P[0], P[1], P[2] = vert[v, 0], vert[v, 1], vert[v, 2]
            cid = v + 1
        else:
            m = c - na - nb
            ia = m // nB
            ha = iscr[ia]
            hb = iscr[nA + m - ia * nB]
            if not _edge_crossing(vert, he_origin, he_next, scr, na, va0, vb0, ha, hb, P):
                continue
            cid = -(1 + ha * nhe + hb)
        if c < na or c >= na + nb:
            # a point of A's surface: its penetration is B's extent behind it along -n
            lo, hi = clip_line(P, n, fnw, fdw, fb0, fb1, tol, lat, -1.0)
            if lo > hi:
                continue
            if hi < -tol and not _reaches(P, n, fnw, fdw, fa0, fa1, tol, hi, -1.0):
                continue  # B's part of the line lies beyond the point and outside A
            depth = min(-lo, sa - sb)  # never deeper than the plane's overlap
            mid = -0.5 * depth
        else:
            # a vertex of B: A's extent beyond it along n
            lo, hi = clip_line(P, n, fnw, fdw, fa0, fa1, tol, lat, 1.0)
            if lo > hi:
                continue
            if lo > tol and not _reaches(P, n, fnw, fdw, fb0, fb1, tol, lo, 1.0):
                continue
            depth = min(hi, sa - sb)
            mid = 0.5 * depth
        if depth <= -keep_gap:
            continue
        if depth <= 0.0 and keep_gap <= 0.0:
            continue
        if c >= na + nb:
            # a crossing next to a vertex that bears by the crease rule is that vertex's contact
            m = c - na - nb
            ha = iscr[m // nB]
            hb = iscr[nA + m - (m // nB) * nB]
            if _crossing_covered(vert, fnw, fdw, he_origin, he_next, ha, hb, n, fa0, fa1, fb0, fb1, tol, lat,
                                 sa - sb):
                continue
        k = _keep_point(P, n, e1, e2, depth, mid, cid, merge, lat, k, cu, cv, out_pos, out_depth, out_id)
    if k == 0 and sb - sa < 0.0:
        return -1  # overlap without a candidate point: caller uses the support points
    return k


@njit(cache=True)
def polygon_area(pos, k, n):
    """Area of the convex polygon through the k points (projected on the plane of normal n)."""
    if k < 3:
        return 0.0
    if abs(n[0]) < 0.9:
        a0, a1, a2 = 0.0, n[2], -n[1]
    else:
        a0, a1, a2 = -n[2], 0.0, n[0]
    al = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    e1 = np.array([a0 / al, a1 / al, a2 / al])
    e2 = np.array([n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0]])
    u = np.empty(k)
    v = np.empty(k)
    for j in range(k):
        u[j] = _dot(pos[j], e1)
        v[j] = _dot(pos[j], e2)
    cu = u.mean()
    cv = v.mean()
    ang = np.empty(k)
    for j in range(k):
        ang[j] = np.arctan2(v[j] - cv, u[j] - cu)
    order = np.argsort(ang)
    area = 0.0
    for j in range(k):
        p = order[j]
        q = order[(j + 1) % k]
        area += u[p] * v[q] - u[q] * v[p]
    return 0.5 * abs(area)



@njit(cache=True)
def sat_search(vert, fnw, va0, va1, fa0, fa1, ea0, ea1, vb0, vb1, fb0, fb1, eb0, eb1, he_origin, he_next, edge_he,
               n_ref, g_best, out_n):
    """Global separating-axis search (all face normals and all edge-pair cross products, oriented along n_ref).

    If a direction with a larger gap than g_best exists, writes it into out_n and returns its gap; otherwise
    returns g_best. A safety net for FCP's local search, which can stop on a poor plane when its starting plane
    (the centroid bisector of a new pair) is far from the best one."""
    best = g_best
    nA = ea1 - ea0
    nB = eb1 - eb0
    total = (fa1 - fa0) + (fb1 - fb0) + nA * nB
    for c in range(total):
        if c < fa1 - fa0:
            f = fa0 + c
            c0, c1, c2 = fnw[f, 0], fnw[f, 1], fnw[f, 2]
        elif c < (fa1 - fa0) + (fb1 - fb0):
            f = fb0 + c - (fa1 - fa0)
            c0, c1, c2 = -fnw[f, 0], -fnw[f, 1], -fnw[f, 2]
        else:
            m = c - (fa1 - fa0) - (fb1 - fb0)
            p = m // nB
            q = m - p * nB
            ha = edge_he[ea0 + p]
            hb = edge_he[eb0 + q]
            u0 = vert[he_origin[he_next[ha]], 0] - vert[he_origin[ha], 0]
            u1 = vert[he_origin[he_next[ha]], 1] - vert[he_origin[ha], 1]
            u2 = vert[he_origin[he_next[ha]], 2] - vert[he_origin[ha], 2]
            w0 = vert[he_origin[he_next[hb]], 0] - vert[he_origin[hb], 0]
            w1 = vert[he_origin[he_next[hb]], 1] - vert[he_origin[hb], 1]
            w2 = vert[he_origin[he_next[hb]], 2] - vert[he_origin[hb], 2]
            c0 = u1 * w2 - u2 * w1
            c1 = u2 * w0 - u0 * w2
            c2 = u0 * w1 - u1 * w0
            cl = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            ul = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            wl = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            if cl <= 1e-9 * ul * wl:
                continue
            c0 /= cl
            c1 /= cl
            c2 /= cl
            if c0 * n_ref[0] + c1 * n_ref[1] + c2 * n_ref[2] < 0:
                c0, c1, c2 = -c0, -c1, -c2
        cg, cia, cib, csa, csb = gap_along(vert, va0, va1, vb0, vb1, c0, c1, c2)
        if cg > best:
            best = cg
            out_n[0] = c0
            out_n[1] = c1
            out_n[2] = c2
    return best
