"""sgim.meshquery against brute force (numpy, every triangle) and analytic solids."""
from __future__ import annotations

import numpy as np
import pytest

from sgim.meshquery import MeshSet, TriMesh


# ---------------------------------------------------------------------------
# independent references (plain numpy over every triangle)

def _seg_dist(p, a, b):
    """Distance from points p (n,3) to segments a-b (m,3): (n, m)."""
    ab = b - a
    ap = p[:, None, :] - a[None]
    t = np.clip(np.einsum("nmk,mk->nm", ap, ab) / np.einsum("mk,mk->m", ab, ab), 0.0, 1.0)
    q = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - q, axis=2)


def brute_distance(p, V, F):
    """Unsigned distance to each triangle, (n, m): plane projection if it falls inside the
    triangle (barycentric test), else the nearest of the three edges."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    h = np.einsum("nmk,mk->nm", p[:, None, :] - a[None], n)
    proj = p[:, None, :] - h[..., None] * n[None]

    def side(u, v):
        return np.einsum("nmk,mk->nm", np.cross(v[None] - u[None], proj - u[None]), n)

    inside = (side(a, b) >= 0) & (side(b, c) >= 0) & (side(c, a) >= 0)
    edge = np.minimum(np.minimum(_seg_dist(p, a, b), _seg_dist(p, b, c)), _seg_dist(p, c, a))
    return np.where(inside, np.abs(h), edge)


def winding_number(p, V, F):
    """Generalized winding number (Van Oosterom - Strackee solid angles)."""
    a = V[F[:, 0]][None] - p[:, None, :]
    b = V[F[:, 1]][None] - p[:, None, :]
    c = V[F[:, 2]][None] - p[:, None, :]
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    num = np.einsum("nmk,nmk->nm", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("nmk,nmk->nm", a, b) * lc + np.einsum("nmk,nmk->nm", a, c) * lb \
        + np.einsum("nmk,nmk->nm", b, c) * la
    return (2.0 * np.arctan2(num, den)).sum(1) / (4.0 * np.pi)


def icosphere(radius=1.0, level=3):
    """Sphere mesh by subdividing an icosahedron (outward faces)."""
    t = (1 + 5 ** 0.5) / 2
    V = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    F = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    for _ in range(level):
        mid = {}
        out = []

        def m(i, j):
            key = (min(i, j), max(i, j))
            if key not in mid:
                q = V[i] + V[j]
                V.append(q / np.linalg.norm(q))
                mid[key] = len(V) - 1
            return mid[key]

        for a, b, c in F:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            out += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        F = out
    return radius * np.array(V), np.array(F, np.int64)


def box_mesh(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    V = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    F = []
    for q in quads:
        F += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return V, np.array(F, np.int64)


def box_sdf(p, lo, hi):
    c, h = (lo + hi) / 2, (hi - lo) / 2
    q = np.abs(p - c) - h
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)


# ---------------------------------------------------------------------------

def test_closest_matches_brute_force_on_triangle_soup():
    rng = np.random.default_rng(1)
    cen = rng.uniform(-5, 5, (300, 3))
    V = (cen[:, None, :] + rng.normal(0, 0.8, (300, 3, 3))).reshape(-1, 3)
    F = np.arange(900).reshape(300, 3)
    mesh = TriMesh(V, F, orient=False)
    P = rng.uniform(-7, 7, (400, 3))
    ref = brute_distance(P, mesh.vertices, mesh.faces)
    dist, foot, face, _ = mesh.closest(P)
    np.testing.assert_allclose(dist, ref.min(1), rtol=1e-9, atol=1e-12)
    # the foot lies on the reported face at the reported distance
    np.testing.assert_allclose(np.linalg.norm(P - foot, axis=1), dist, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ref[np.arange(len(P)), face], dist, rtol=1e-9, atol=1e-12)
    # band query: exactly the points within max_dist are answered
    d2, foot2, face2, _ = mesh.closest(P, max_dist=0.7)
    near = ref.min(1) <= 0.7
    assert np.array_equal(np.isfinite(d2), near)
    np.testing.assert_allclose(d2[near], ref.min(1)[near], rtol=1e-9)
    assert np.all(face2[~near] == -1) and np.all(np.isnan(foot2[~near]))


def test_sphere_inside_and_signed_distance():
    R = 3.0
    V, F = icosphere(R, 4)
    mesh = TriMesh(V, F)
    assert mesh.closed and mesh.nearly_closed()
    assert mesh.report["flipped_faces"] == 0
    rng = np.random.default_rng(2)
    P = rng.uniform(-4, 4, (20000, 3))
    r = np.linalg.norm(P, axis=1)
    # the chords of a level-4 icosphere stay within 0.2 % of R of the sphere
    gap = 0.004 * R
    away = np.abs(r - R) > gap
    assert np.array_equal(mesh.inside(P)[away], r[away] < R)
    sd = mesh.signed_distance(P)
    np.testing.assert_allclose(sd, r - R, atol=gap)
    ref = brute_distance(P[:500], mesh.vertices, mesh.faces).min(1)
    np.testing.assert_allclose(np.abs(sd[:500]), ref, rtol=1e-9, atol=1e-12)


def test_box_signed_distance_exact():
    lo, hi = np.array([-1.0, -2.0, 0.5]), np.array([3.0, 1.0, 2.0])
    V, F = box_mesh(lo, hi)
    mesh = TriMesh(V, F)
    rng = np.random.default_rng(3)
    P = rng.uniform(lo - 1.5, hi + 1.5, (5000, 3))
    np.testing.assert_allclose(mesh.signed_distance(P), box_sdf(P, lo, hi), atol=1e-12)
    assert np.array_equal(mesh.inside(P), box_sdf(P, lo, hi) < 0)
    # the points of the lattice kind that hit edges and vertices exactly
    g = np.stack(np.meshgrid(*[np.linspace(a - 1, b + 1, 11) for a, b in zip(lo, hi)]), -1).reshape(-1, 3)
    ref = box_sdf(g, lo, hi)
    np.testing.assert_allclose(mesh.signed_distance(g), ref, atol=1e-12)
    off = np.abs(ref) > 1e-9
    assert np.array_equal(mesh.inside(g)[off], ref[off] < 0)


def test_inward_mesh_is_turned_outward_and_flips_repaired():
    V, F = icosphere(2.0, 3)
    rng = np.random.default_rng(4)
    Fin = F[:, [0, 2, 1]].copy()  # every face inward
    mesh = TriMesh(V, Fin)
    assert mesh.volume > 0
    flipped = F.copy()
    pick = rng.choice(len(F), 40, replace=False)
    flipped[pick] = flipped[pick][:, [0, 2, 1]]
    m2 = TriMesh(V, flipped)
    assert m2.report["flipped_faces"] == 40
    P = rng.uniform(-3, 3, (3000, 3))
    r = np.linalg.norm(P, axis=1)
    away = np.abs(r - 2.0) > 0.02
    assert np.all(np.sign(m2.signed_distance(P)[away]) == np.sign(r - 2.0)[away])
    # without repair, parity voting still finds inside
    m3 = TriMesh(V, flipped, orient=False)
    assert np.array_equal(m3.inside(P)[away], (r < 2.0)[away])


def test_defects_weld_degenerate_duplicates_small_hole():
    V, F = icosphere(1.0, 3)
    rng = np.random.default_rng(5)
    # a triangle soup (each face its own corners) with float32-like noise: welding rejoins it
    soup = V[F].reshape(-1, 3) + rng.normal(0, 1e-9, (3 * len(F), 3))
    Fs = np.arange(3 * len(F)).reshape(-1, 3)
    # a duplicated face, a reversed duplicate, a zero-area face
    Fs = np.vstack([Fs, Fs[:2], Fs[5:6, [0, 2, 1]], [[0, 0, 1]]])
    mesh = TriMesh(soup, Fs)
    assert mesh.report["welded_vertices"] == 3 * len(F) - len(V)
    assert mesh.report["duplicate_faces"] == 3 and mesh.report["degenerate_faces"] == 1
    assert mesh.closed and len(mesh.faces) == len(F)
    # a hole of one triangle: not closed, but nearly; a big hole: not nearly closed
    holed = TriMesh(V, F[1:])
    assert not holed.closed and holed.nearly_closed() and len(holed.holes()) == 1
    cap = V[F].mean(1)[:, 2] > 0.5
    assert not TriMesh(V, F[~cap]).nearly_closed()
    P = rng.uniform(-1.3, 1.3, (20000, 3))
    r = np.linalg.norm(P, axis=1)
    away = np.abs(r - 1.0) > 0.02
    wrong = holed.inside(P)[away] != (r < 1.0)[away]
    assert wrong.sum() == 0
    # the reference winding number agrees with the analytic sphere (checks the reference)
    w = winding_number(P[:300], V, F)
    assert np.array_equal((w > 0.5)[away[:300]], (r[:300] < 1)[away[:300]])


def test_slivers_and_t_junction_like_splits():
    """Split faces into slivers (a vertex moved onto / near an edge): inside is unchanged."""
    V, F = box_mesh([0, 0, 0], [2, 2, 2])
    Vl, Fl = list(map(list, V)), []
    for a, b, c in F:  # split every face through a point 1e-7 off the midpoint of its first edge
        m = (V[a] + V[b]) / 2 + 1e-7 * (V[c] - (V[a] + V[b]) / 2)
        Vl.append(list(m))
        k = len(Vl) - 1
        Fl += [[a, k, c], [k, b, c]]
    mesh = TriMesh(np.array(Vl), np.array(Fl), weld=1e-12)
    rng = np.random.default_rng(6)
    P = rng.uniform(-0.5, 2.5, (20000, 3))
    ref = box_sdf(P, np.zeros(3), np.full(3, 2.0))
    away = np.abs(ref) > 1e-5
    assert np.array_equal(mesh.inside(P)[away], ref[away] < 0)
    np.testing.assert_allclose(mesh.closest(P)[0], np.abs(ref), atol=1e-6)


def test_open_disc_boundary_flag():
    """A flat polygon disc: the foot is on the boundary exactly when the projection is outside."""
    n, R = 64, 2.0
    ang = 2 * np.pi * np.arange(n) / n
    V = np.vstack([[0, 0, 0], np.column_stack([R * np.cos(ang), R * np.sin(ang), np.zeros(n)])])
    F = np.array([[0, 1 + i, 1 + (i + 1) % n] for i in range(n)])
    mesh = TriMesh(V, F)
    assert not mesh.closed and len(mesh.boundary_edges) == n
    assert mesh.normals[:, 2].min() > 0.999  # majority orientation kept (counter-clockwise: up)
    rng = np.random.default_rng(7)
    P = rng.uniform(-3, 3, (5000, 3))
    rho = np.linalg.norm(P[:, :2], axis=1)
    apo = R * np.cos(np.pi / n)  # the polygon holds rho < apothem, and nothing beyond R
    dist, foot, face, bnd = mesh.closest(P)
    assert np.all(~bnd[rho < apo - 1e-9]) and np.all(bnd[rho > R + 1e-9])
    inner = rho < apo
    np.testing.assert_allclose(dist[inner], np.abs(P[inner, 2]), atol=1e-12)
    sd, face2, bnd2 = mesh.signed_closest(P)
    assert np.array_equal(bnd2, bnd)
    assert np.all(np.sign(sd[inner]) == np.sign(P[inner, 2]))


def test_segment_crossings_brute_force():
    V, F = icosphere(1.5, 2)
    mesh = TriMesh(V, F)
    rng = np.random.default_rng(8)
    a = rng.uniform(-2, 2, (3000, 3))
    b = a + rng.normal(0, 0.4, (3000, 3))
    hit = mesh.segment_crossings(a, b)
    # independent: a segment crosses the closed surface iff its end points differ in
    # inside / outside or it passes through (then the nearest point of the line is inside)
    ra, rb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    d = b - a
    t = np.clip(-np.einsum("ij,ij->i", a, d) / np.einsum("ij,ij->i", d, d), 0, 1)
    rmin = np.linalg.norm(a + t[:, None] * d, axis=1)
    cross = ((ra < 1.5) != (rb < 1.5)) | ((ra > 1.5) & (rb > 1.5) & (rmin < 1.5))
    clear = (np.abs(ra - 1.5) > 0.05) & (np.abs(rb - 1.5) > 0.05) & (np.abs(rmin - 1.5) > 0.05)
    assert np.array_equal((hit >= 0)[clear], cross[clear])


def test_meshset_clearance_is_min_of_signed_distances():
    V, F = icosphere(1.0, 3)
    Vb, Fb = box_mesh([2, -1, -1], [4, 1, 1])
    m1, m2 = TriMesh(V, F), TriMesh(Vb, Fb)
    ms = MeshSet([m1, m2])
    rng = np.random.default_rng(9)
    P = rng.uniform([-2, -2, -2], [5, 2, 2], (5000, 3))
    ref = np.minimum(m1.signed_distance(P), m2.signed_distance(P))
    np.testing.assert_allclose(ms.clearance(P), ref, atol=1e-12)
    c = ms.clearance(P, max_dist=0.3)
    near = np.abs(ref) <= 0.3
    np.testing.assert_allclose(c[near], ref[near], atol=1e-12)
    far = ~near
    assert np.all(np.isinf(c[far]))
    assert np.array_equal(c[far] < 0, ref[far] < 0)


def test_bad_input():
    V, F = icosphere(1.0, 1)
    with pytest.raises(ValueError):
        TriMesh(V, F + len(V))
    with pytest.raises(ValueError):
        TriMesh(V[:, :2], F)
    with pytest.raises(ValueError):
        TriMesh(np.zeros((3, 3)), [[0, 1, 2]])
