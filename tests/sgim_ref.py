"""Independent reference implementations for the sgim tests (no sgim kernel is called here).

Plain NumPy transcriptions of Huang et al. (2013), "Generating irregular models for 3D
spherical-particle-based numerical methods":

* eq. 1-2    the cubic lattice (basic model);
* eq. 3-12   the excavating spaces I and II of a triangular facet (the 'paper' rule);
* eq. 13-16  red / green / blue membership of a sphere near a disc discontinuity;

plus the 'exact' excavation rule (a site is removed when it lies within r of the closed
triangle, or on / above the triangle in vertical projection), touching pairs by brute force
and both bond rules.  Everything is vectorised over all sites for one facet / disc at a time.

Rounding allowance (documented in sgim/_excavate.py and applied here on purpose)
---------------------------------------------------------------------------------
The paper's closed comparisons ("<=", ">=") describe closed prisms.  Evaluated literally in
floating point, a site that lies exactly on an edge shared by two facets may fail the test of
both facets by one rounding error.  sgim therefore evaluates every closed comparison with a
relative allowance ROUND = 1e-12 times the magnitude of the terms; this reference uses the
same allowance:

* slab of side plane k (eq. 7 / 11):
      |Ak x + Bk y + Ck z + Dk|  <= w  and  |Ak x + Bk y + Ck z + Dk0| <= w,
      w = |Dk - Dk0| + ROUND (|Ak x| + |Bk y| + |Ck z| + |Dk| + |Dk0|)
* on or above the facet plane (eq. 11, and the exact rule):  z >= h - ROUND (|z| + |h|)
* plan point-in-triangle (exact rule), per edge u->v and edge function
      e = (vx - ux)(y - uy) - (vy - uy)(x - ux):
      e >= -ROUND (|vx - ux| + |vy - uy|) (|x| + |y| + |ux| + |uy|)
  (scaled by the coordinates, not by the terms, which vanish near the edge: a lattice row
  that rounding puts one ulp outside a surface covering the domain exactly belongs to it)

Strict comparisons (distance "< r") are tightened by the same kind of allowance, so a site at
distance exactly r is kept as the strict inequality says:
      paper:  |A0 x + B0 y + C0 z + D0| / |n| < r - ROUND (|A0 x| + |B0 y| + |C0 z| + |D0|) / |n|
      exact:  dist^2 < r^2 - ROUND (|x| + |y| + |z| + |ax| + |ay| + |az|)^2   (a: first vertex)  With random float input the
allowance changes nothing but a set of measure ~1e-12; it only matters for sites placed
exactly on facet edges, which the regression tests build on purpose.

The colours (eq. 13-16) and the geometric rule's sides and radius take the same kind of allowance,
tie = ROUND (|x0| + |y0| + |z0| + |x1| + |y1| + |z1|) (sphere centre O and disc centre M, a length;
sgim/_cut.py), so that ties in a lattice are decided as the closed inequalities say:
      eq. 13:      |MO x S| / |S| <= R + tie
      eq. 14:      |S.(M - O)| / |S| <= d / 2 + tie
      eq. 15 / 16: |S.(M - O)| / |S| <= 2r + tie, green where S.(M - O) / |S| >= -tie (the plane included:
                   its offset is then 0), blue otherwise
(tests/test_colour_ties.py checks the same ties against exact rational arithmetic instead.)
"""
from __future__ import annotations

import math

import numpy as np

ROUND = 1e-12


# ---------------------------------------------------------------------------
# eq. 1-2: the basic model

def round_half_up(v):
    return int(math.floor(v + 0.5))


def cubic_sites(lo, hi, r):
    """All centres of the paper's cubic basic model, as an (n, 3) array.

    I, J, K = (z2 - z1) / 2r, (y2 - y1) / 2r, (x2 - x1) / 2r rounded (half up) to integers;
    x = x1 + r (2k - 1), y = y1 + r (2j - 1), z = z1 + r (2i - 1).
    """
    x1, y1, z1 = (float(v) for v in lo)
    x2, y2, z2 = (float(v) for v in hi)
    I = round_half_up((z2 - z1) / (2 * r))  # noqa: E741
    J = round_half_up((y2 - y1) / (2 * r))
    K = round_half_up((x2 - x1) / (2 * r))
    out = []
    for i in range(1, I + 1):
        for j in range(1, J + 1):
            for k in range(1, K + 1):
                out.append((x1 + r * (2 * k - 1), y1 + r * (2 * j - 1), z1 + r * (2 * i - 1)))
    return np.array(out, float).reshape(-1, 3)


# ---------------------------------------------------------------------------
# eq. 3-12: the paper's excavating space

def det3(a, b, c):
    """Determinant of the 3x3 matrix with rows a, b, c (rule of Sarrus)."""
    return (a[0] * b[1] * c[2] + a[1] * b[2] * c[0] + a[2] * b[0] * c[1]
            - a[2] * b[1] * c[0] - a[0] * b[2] * c[1] - a[1] * b[0] * c[2])


def plane_abcd(P, Q, R):
    """Eq. 4: A, B, C, D of the plane through P, Q, R (scalars)."""
    (xa, ya, za), (xb, yb, zb), (xc, yc, zc) = P, Q, R
    A = det3((ya, za, 1.0), (yb, zb, 1.0), (yc, zc, 1.0))
    B = -det3((xa, za, 1.0), (xb, zb, 1.0), (xc, zc, 1.0))
    C = det3((xa, ya, 1.0), (xb, yb, 1.0), (xc, yc, 1.0))
    D = -det3((xa, ya, za), (xb, yb, zb), (xc, yc, zc))
    return A, B, C, D


def _slab(x, y, z, P, Q, R, opposite):
    """Between side plane PQR (eq. 6 / 10) and its parallel through `opposite` (eq. 8 / 12)."""
    A, B, C, D = plane_abcd(P, Q, R)
    D0 = -A * opposite[0] - B * opposite[1] - C * opposite[2]
    v = A * x + B * y + C * z
    w = abs(D - D0) + ROUND * (np.abs(A * x) + np.abs(B * y) + np.abs(C * z) + abs(D) + abs(D0))
    return (np.abs(v + D) <= w) & (np.abs(v + D0) <= w)


def paper_space(sites, tri, r):
    """Which sites lie in the excavating space Omega = I u II of one facet (eq. 3-12).

    Returns (in_space_I, in_space_II) boolean arrays.
    """
    x, y, z = sites[:, 0], sites[:, 1], sites[:, 2]
    L0, M0, N0 = (tuple(float(c) for c in p) for p in tri)
    A0, B0, C0, D0 = plane_abcd(L0, M0, N0)  # step 1
    # step 2 (eq. 5): the prism along the normal n1 = {A0, B0, C0}
    L1 = (L0[0] + A0, L0[1] + B0, L0[2] + C0)
    M1 = (M0[0] + A0, M0[1] + B0, M0[2] + C0)
    # steps 3-4 (eq. 6-8)
    nn = math.sqrt(A0 * A0 + B0 * B0 + C0 * C0)
    dist = np.abs(A0 * x + B0 * y + C0 * z + D0) / nn
    slack = ROUND * (np.abs(A0 * x) + np.abs(B0 * y) + np.abs(C0 * z) + abs(D0)) / nn
    s1 = (dist < r - slack) & _slab(x, y, z, L0, L1, M0, N0) & _slab(x, y, z, M0, M1, N0, L0) \
        & _slab(x, y, z, L0, L1, N0, M0)
    # steps 5-7 (eq. 9-12): the vertical prism, only when C0 != 0
    if C0 == 0.0:
        return s1, np.zeros(len(sites), bool)
    L2 = (L0[0], L0[1], L0[2] + 1.0)
    M2 = (M0[0], M0[1], M0[2] + 1.0)
    h = -(A0 * x + B0 * y + D0) / C0
    s2 = (z >= h - ROUND * (np.abs(z) + np.abs(h))) & _slab(x, y, z, L0, L2, M0, N0) \
        & _slab(x, y, z, M0, M2, N0, L0) & _slab(x, y, z, L0, L2, N0, M0)
    return s1, s2


# ---------------------------------------------------------------------------
# the exact rule

def _seg_dist2(p, a, b):
    ab = b - a
    t = ((p - a) @ ab) / float(ab @ ab)
    t = np.clip(t, 0.0, 1.0)
    q = a + t[:, None] * ab
    return ((p - q) ** 2).sum(1)


def triangle_dist2(p, tri):
    """Squared distance from points p (n, 3) to the closed triangle tri (3, 3).

    Projection onto the plane; when the foot lies inside the triangle the distance is the
    distance to the plane, otherwise the smallest distance to the three edges.
    """
    a, b, c = (np.asarray(v, float) for v in tri)
    n = np.cross(b - a, c - a)
    nn = float(n @ n)
    s = ((p - a) @ n) / nn
    foot = p - s[:, None] * n
    inside = np.ones(len(p), bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(v - u, foot - u) @ n) >= 0.0
    plane_d2 = s * s * nn
    edge_d2 = np.minimum(np.minimum(_seg_dist2(p, a, b), _seg_dist2(p, b, c)), _seg_dist2(p, c, a))
    return np.where(inside, plane_d2, edge_d2)


def above_triangle(p, tri):
    """On or above the triangle in vertical projection (closed plan triangle, with ROUND)."""
    a, b, c = (np.asarray(v, float) for v in tri)
    n = np.cross(b - a, c - a)
    if n[2] == 0.0:
        return np.zeros(len(p), bool)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    pos = np.ones(len(p), bool)
    neg = np.ones(len(p), bool)
    for u, v in ((a, b), (b, c), (c, a)):
        t1 = (v[0] - u[0]) * (y - u[1])
        t2 = (v[1] - u[1]) * (x - u[0])
        e = t1 - t2
        tol = ROUND * (abs(v[0] - u[0]) + abs(v[1] - u[1])) * (np.abs(x) + np.abs(y) + abs(u[0]) + abs(u[1]))
        pos &= e >= -tol
        neg &= e <= tol
    h = a[2] - (n[0] * (x - a[0]) + n[1] * (y - a[1])) / n[2]
    return (pos | neg) & (z >= h - ROUND * (np.abs(z) + np.abs(h)))


def exact_space(sites, tri, r):
    a = np.asarray(tri[0], float)
    scale = np.abs(sites).sum(1) + np.abs(a).sum()
    return above_triangle(sites, tri) | (triangle_dist2(sites, tri) < r * r - ROUND * scale * scale)


def removed_mask(sites, surfaces, r):
    """surfaces: iterable of (vertices, faces, rule); union of the excavating spaces."""
    sites = np.asarray(sites, float).reshape(-1, 3)
    out = np.zeros(len(sites), bool)
    for verts, faces, rule in surfaces:
        verts = np.asarray(verts, float)
        for f in np.asarray(faces):
            tri = verts[f]
            if rule == "paper":
                s1, s2 = paper_space(sites, tri, r)
                out |= s1 | s2
            elif rule == "exact":
                out |= exact_space(sites, tri, r)
            else:
                raise ValueError(rule)
    return out


def kept(sites, surfaces, r):
    sites = np.asarray(sites, float).reshape(-1, 3)
    return sites[~removed_mask(sites, surfaces, r)]


def as_set(points):
    return {tuple(map(float, p)) for p in np.asarray(points).reshape(-1, 3)}


# ---------------------------------------------------------------------------
# eq. 13-16: colours

def unit(v):
    v = np.asarray(v, float)
    return v / math.sqrt(float(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))


def dip_normal(dip, dipdir):
    """Upward unit normal of a plane given as dip / dip direction in degrees (x east, y north)."""
    d, a = math.radians(dip), math.radians(dipdir)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def disc_membership(centres, radii, M, S, R, d):
    """Eq. 13-16 for one disc: (kind, signed offset S.(O - M)/|S|) per sphere; kind 0 = none.

    kind 1: red (d != 0, |S.(M - O)|/|S| <= d/2); kind 2: green (d == 0, within 2r,
    S.(M - O) >= 0); kind 3: blue (d == 0, within 2r, S.(M - O) < 0); always inside the
    infinite cylinder |MO x S| / |S| <= R.
    """
    A, B, C = (float(s) for s in S)
    ns = math.sqrt(A * A + B * B + C * C)
    x0, y0, z0 = centres[:, 0], centres[:, 1], centres[:, 2]
    x1, y1, z1 = (float(m) for m in M)
    # MO x S
    mx, my, mz = x0 - x1, y0 - y1, z0 - z1
    cx = my * C - mz * B
    cy = mz * A - mx * C
    cz = mx * B - my * A
    tie = ROUND * (np.abs(x0) + np.abs(y0) + np.abs(z0) + abs(x1) + abs(y1) + abs(z1))
    in_cyl = np.sqrt(cx * cx + cy * cy + cz * cz) / ns <= R + tie  # eq. 13
    dot = A * (x1 - x0) + B * (y1 - y0) + C * (z1 - z0)  # S.(M - O)
    dist = np.abs(dot) / ns
    on_plane = dist <= tie
    kind = np.zeros(len(centres), np.int8)
    if d != 0:
        kind[in_cyl & (dist <= d / 2.0 + tie)] = 1  # eq. 14
    else:
        near = in_cyl & (dist <= 2.0 * np.asarray(radii) + tie)
        kind[near & ((dot >= 0.0) | on_plane)] = 2  # eq. 15
        kind[near & (dot < 0.0) & ~on_plane] = 3  # eq. 16
    return kind, np.where(on_plane, 0.0, -dot / ns)


def membership_table(centres, radii, discs):
    """discs: list of (M, S, R, d).  Rows sorted by (disc, sphere): sphere, disc, kind, offset."""
    rows_s, rows_d, rows_k, rows_o = [], [], [], []
    for k, (M, S, R, d) in enumerate(discs):
        kind, off = disc_membership(centres, radii, M, S, R, d)
        idx = np.nonzero(kind)[0]
        rows_s.append(idx)
        rows_d.append(np.full(len(idx), k))
        rows_k.append(kind[idx])
        rows_o.append(off[idx])
    if not rows_s:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0, np.int8), np.zeros(0)
    return (np.concatenate(rows_s), np.concatenate(rows_d), np.concatenate(rows_k), np.concatenate(rows_o))


def colours(n, table):
    """Red wins (nearest red fault is the source); otherwise the nearest joint plane decides
    green or blue; equal distances go to the lower disc index."""
    s, dsc, knd, off = table
    colour = np.zeros(n, np.int8)
    source = np.full(n, -1)
    for i in range(n):
        rows = np.nonzero(s == i)[0]
        if len(rows) == 0:
            continue
        red = [q for q in rows if knd[q] == 1]
        cand = red if red else list(rows)
        best = min(cand, key=lambda q: (abs(off[q]), dsc[q]))
        colour[i] = 1 if red else knd[best]
        source[i] = dsc[best]
    return colour, source


# ---------------------------------------------------------------------------
# bonds

def touching_pairs(centres, radii, tol):
    """All pairs i < j with |ci - cj| <= (ri + rj)(1 + tol), sorted (O(n^2))."""
    c = np.asarray(centres, float)
    rad = np.asarray(radii, float)
    n = len(c)
    out = []
    for i in range(n - 1):
        d = np.sqrt(((c[i + 1:] - c[i]) ** 2).sum(1))
        js = np.nonzero(d <= (rad[i] + rad[i + 1:]) * (1.0 + tol))[0] + i + 1
        out.extend((i, int(j)) for j in js)
    return np.array(out, np.int64).reshape(-1, 2)


def colour_rule_bonded(bonds, colour):
    """No bond when either sphere is red, or when one is green and the other blue."""
    ci, cj = colour[bonds[:, 0]], colour[bonds[:, 1]]
    gb = ((ci == 2) & (cj == 3)) | ((ci == 3) & (cj == 2))
    return ~((ci == 1) | (cj == 1) | gb)


def segment_crosses_disc(a, b, M, S, R):
    """Does segment a-b (arrays (m, 3)) cross the disc plane inside radius R?

    The sides are those of eq. 15/16: S.(M - O) >= 0 (green side, the plane included) and
    S.(M - O) < 0 (blue side); the segment crosses when its ends are on different sides.
    """
    S = np.asarray(S, float)
    M = np.asarray(M, float)
    ns = math.sqrt(float(S @ S))
    mscale = float(np.abs(M).sum())

    def side(o):  # S.(M - O), 0 on the plane (within the tie allowance)
        s = (M - o) @ S
        return np.where(np.abs(s) / ns <= ROUND * (np.abs(o).sum(1) + mscale), 0.0, s)

    sa, sb = side(a), side(b)
    cross = (sa >= 0) != (sb >= 0)
    with np.errstate(invalid="ignore", divide="ignore"):  # t is unused where the ends are on one side
        t = sa / (sa - sb)
        p = a + t[:, None] * (b - a)
        q = p - M
        inplane = q - np.outer(q @ S, S) / float(S @ S)
        return cross & (np.sqrt((inplane ** 2).sum(1)) <= R + ROUND * (np.abs(p).sum(1) + mscale))


def geometric_rule_bonded(centres, bonds, colour, discs):
    """No bond when either sphere is red, or when the segment between the centres crosses a
    zero-thickness disc inside its radius."""
    c = np.asarray(centres, float)
    a, b = c[bonds[:, 0]], c[bonds[:, 1]]
    cut = (colour[bonds[:, 0]] == 1) | (colour[bonds[:, 1]] == 1)
    for (M, S, R, d) in discs:
        if d == 0 and len(bonds):
            cut |= segment_crosses_disc(a, b, M, S, R)
    return ~cut
