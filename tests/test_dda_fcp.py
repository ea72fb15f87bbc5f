"""Fast Common-Plane against independent references: the distance of two convex polytopes from a
quadratic programme (scipy), and the separating-axis overlap depth (all face normals and edge-pair cross
products, brute force in numpy)."""
import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial import ConvexHull

from dda._fcp import MAXP, contact_points, fcp
from dda.blockspec import BlockSpec
from dda.simulation import Simulation
from dda.system import BlockSystem


def random_hull(rng, n=9, scale=1.0):
    pts = rng.normal(size=(n, 3)) * scale * rng.uniform(0.5, 1.5, size=3)
    hull = ConvexHull(pts)
    keep = np.unique(hull.simplices)
    remap = -np.ones(n, int)
    remap[keep] = np.arange(len(keep))
    v = pts[keep]
    c = v.mean(0)
    faces = []
    for tri in hull.simplices:
        a, b, d = remap[tri]
        if np.dot(np.cross(v[b] - v[a], v[d] - v[a]), v[a] - c) < 0:
            b, d = d, b
        faces.append([int(a), int(b), int(d)])
    return v, faces


def qp_distance(va, vb):
    """min |x - y| over x in conv(va), y in conv(vb) (barycentric weights, SLSQP)."""
    na, nb = len(va), len(vb)

    def f(w):
        d = w[:na] @ va - w[na:] @ vb
        return d @ d

    def g(w):
        d = w[:na] @ va - w[na:] @ vb
        return np.r_[2 * va @ d, -2 * vb @ d]

    w0 = np.r_[np.full(na, 1 / na), np.full(nb, 1 / nb)]
    cons = [{"type": "eq", "fun": lambda w: w[:na].sum() - 1}, {"type": "eq", "fun": lambda w: w[na:].sum() - 1}]
    r = minimize(f, w0, jac=g, bounds=[(0, 1)] * (na + nb), constraints=cons, method="SLSQP",
                 options={"ftol": 1e-16, "maxiter": 500})
    return float(np.sqrt(max(r.fun, 0.0)))


def sat_gap(va, fa, vb, fb):
    """max over face normals and edge-pair cross products of min_B - max_A (the best separating axis)."""
    axes = []
    for v, fs in ((va, fa), (vb, fb)):
        for f in fs:
            axes.append(np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]]))
    ea = [va[f[(k + 1) % len(f)]] - va[f[k]] for f in fa for k in range(len(f))]
    eb = [vb[f[(k + 1) % len(f)]] - vb[f[k]] for f in fb for k in range(len(f))]
    for x in ea:
        for y in eb:
            axes.append(np.cross(x, y))
    best = -np.inf
    for ax in axes:
        ln = np.linalg.norm(ax)
        if ln < 1e-12:
            continue
        ax = ax / ln
        for s in (ax, -ax):
            best = max(best, (vb @ s).min() - (va @ s).max())
    return best


def _pair(rng, offset):
    va, fa = random_hull(rng)
    vb, fb = random_hull(rng)
    d = rng.normal(size=3)
    vb = vb + offset * d / np.sqrt(np.sum(d * d))  # (np.linalg.norm of a vector calls BLAS: CPU-dependent bits)
    bs = BlockSystem()
    bs.add_block(BlockSpec(va, fa))
    bs.add_block(BlockSpec(vb, fb))
    sim = Simulation(bs, gravity=(0, 0, 0), dt=1e-3)
    return sim, va, fa, vb, fb


def _fcp(sim, n0):
    A = sim.A
    out = np.zeros(3)
    g, ia, ib, sa, sb, it = fcp(sim.vert, sim.fnw, A.vert_start[0], A.vert_start[1], A.vert_start[1],
                                A.vert_start[2], A.he_origin, A.he_next, A.he_pair, A.he_face, A.vert_he,
                                np.asarray(n0, float), 1e-13, 100, out)
    return g, out, sa, sb, it


def test_fcp_gap_equals_the_distance_of_separated_pairs():
    rng = np.random.default_rng(42)
    worse = 0
    n = 60
    for _ in range(n):
        sim, va, fa, vb, fb = _pair(rng, rng.uniform(4.0, 7.0))
        ref = qp_distance(va, vb)
        if ref < 1e-3:
            continue
        n0 = sim.pos[1] - sim.pos[0]
        g, nrm, sa, sb, it = _fcp(sim, n0)
        assert g <= ref + 1e-6  # a plane's gap never exceeds the distance
        if g < ref - 1e-6 * max(1.0, ref):
            worse += 1
    assert worse <= 1  # FCP's local search reaches the true distance (the best plane)


def test_fcp_overlap_matches_the_separating_axis_depth():
    rng = np.random.default_rng(7)
    found = 0
    n = 60
    for _ in range(n):
        sim, va, fa, vb, fb = _pair(rng, rng.uniform(0.5, 2.0))
        ref = sat_gap(va, fa, vb, fb)
        if ref >= 0:
            continue
        g, nrm, sa, sb, it = _fcp(sim, sim.pos[1] - sim.pos[0])
        assert g <= ref + 1e-9
        found += g >= ref - 1e-9 * max(1.0, abs(ref))
    assert found >= 0.9 * n * 0.5


def test_cached_plane_is_kept_or_improved():
    """Restarting from last step's plane (the per-pair cache) never loses gap and settles in <= 2 iterations."""
    rng = np.random.default_rng(3)
    same = 0
    for _ in range(20):
        sim, va, fa, vb, fb = _pair(rng, 5.0)
        g, nrm, sa, sb, it = _fcp(sim, sim.pos[1] - sim.pos[0])
        g2, nrm2, sa, sb, it2 = _fcp(sim, nrm)
        assert it2 <= 2 and g2 >= g - 1e-12
        same += it2 == 1
    assert same >= 15


def _inside(v, faces, p, tol=1e-9):
    """p lies in the convex polyhedron (every face plane, brute force)."""
    c = v.mean(0)
    for f in faces:
        nf = np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]])
        nf /= np.linalg.norm(nf)
        if nf @ (c - v[f[0]]) > 0:
            nf = -nf
        if nf @ (p - v[f[0]]) > tol:
            return False
    return True


def test_contact_points_of_a_shallow_overlap():
    """Pairs brought into a shallow overlap d along their separating normal: each contact point is a
    feature of one block inside the other, its depth the distance along the plane normal to the other block's
    surface (checked by brute-force point-in-polyhedron tests), never deeper than the plane's overlap."""
    rng = np.random.default_rng(11)
    checked = 0
    fallback = 0
    apart = 0
    for _ in range(40):
        sim, va, fa, vb, fb = _pair(rng, rng.uniform(4.0, 6.0))
        g, nrm, sa, sb, it = _fcp(sim, sim.pos[1] - sim.pos[0])
        d = 0.01
        bs = BlockSystem()
        bs.add_block(BlockSpec(va, fa))
        vb2 = vb - (g + d) * nrm
        bs.add_block(BlockSpec(vb2, fb))
        sim = Simulation(bs, gravity=(0, 0, 0), dt=1e-3)
        g, nrm, sa, sb, it = _fcp(sim, nrm)
        if g >= 0:  # the first plane was not the best one: B is still apart, nothing to check
            apart += 1
            continue
        assert -d - 1e-9 <= g  # the best plane overlaps no more than n does
        A = sim.A
        pos = np.zeros((MAXP, 3))
        dep = np.zeros(MAXP)
        ids = np.zeros(MAXP, np.int64)
        k = contact_points(sim.bundles().geometry, 0, 1, nrm, sa, sb, 0.0, 1.0, pos, dep, ids)
        if k == -1:  # tip against tip: no feature inside the other block, the caller uses the support points
            fallback += 1
            continue
        assert k >= 1
        assert np.all(dep[:k] > 0)
        for q in range(k):
            # a point of A's surface (vertex, or edge crossing: id < 0) penetrates B: the segment back along -n
            # to B's surface lies in B and ends on it; a vertex of B penetrates A the same way along +n
            of_a = ids[q] < 0 or ids[q] - 1 < A.vert_start[1]
            other_v, other_f = (vb2, fb) if of_a else (va, fa)
            step = -nrm if of_a else nrm
            feature = pos[q] - 0.5 * dep[q] * step
            surface = pos[q] + 0.5 * dep[q] * step
            # (a side face of the other block may be passed by up to the plane's overlap -g: crease rule)
            lat = -g + 1e-9
            assert _inside(other_v, other_f, feature, lat) and _inside(other_v, other_f, surface, lat)
            assert not _inside(other_v, other_f, surface + 1e-6 * step)
        assert 0.5 * -g <= np.max(dep[:k]) <= -g + 1e-12
        checked += 1
    assert checked + fallback + apart == 40 and fallback <= 6 and apart <= 2


def _extrude(poly_yz, x0, x1):
    """Convex prism along x over a convex (y, z) polygon, faces oriented outward by a centroid test."""
    p = np.asarray(poly_yz, float)
    m = len(p)
    v = np.array([[x0, y, z] for y, z in p] + [[x1, y, z] for y, z in p])
    c = v.mean(0)
    faces = [list(range(m)), list(range(m, 2 * m))] + [[k, (k + 1) % m, m + (k + 1) % m, m + k] for k in range(m)]
    out = []
    for f in faces:
        nrm = np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]])
        out.append(f if nrm @ (v[f[0]] - c) > 0 else f[::-1])
    return BlockSpec(v, out)


@pytest.mark.parametrize("alpha_deg,d1,d2", [(30.0, 1e-3, 1.5e-3), (45.0, 1.4e-3, 1e-3), (60.0, 1e-3, 1.6e-3),
                                             (67.0, 1.2e-3, 1e-3)])
def test_a_vertex_in_a_crease_bears_on_both_blocks(alpha_deg, d1, d2):
    """A prism whose lower edge lies in the crease of a V-groove (two blocks meeting in the vertical plane y = 0),
    sunk by d1 into wall 1 and d2 into wall 2. Its lower-edge vertices are then outside wall 1's side face by
    (d2 - d1) / (2 sin alpha) (or wall 2's), yet against each wall the prism's face must bear with all four corners
    at that wall's depth (analytical: the translation's component along the wall normal), each corner once."""
    a = np.radians(alpha_deg)
    t = np.tan(a)
    n1 = np.array([0.0, np.sin(a), np.cos(a)])   # outward normal of wall 1 (y < 0)
    n2 = np.array([0.0, -np.sin(a), np.cos(a)])  # wall 2 (y > 0)
    # translation s with s.n1 = -d1, s.n2 = -d2
    s = np.array([0.0, (d2 - d1) / (2 * np.sin(a)), -(d1 + d2) / (2 * np.cos(a))])
    bs = BlockSystem()
    w1 = bs.add_block(_extrude([(0, 0), (0, -2), (-2, -2), (-2, 2 * t)], -3, 5), fixed=True)
    w2 = bs.add_block(_extrude([(0, 0), (2, 2 * t), (2, -2), (0, -2)], -3, 5), fixed=True)
    H = 0.6
    prism = _extrude([(0, 0), (H / t, H), (-H / t, H)], 0, 1.5)
    pv = prism.vertices + s
    i = bs.add_block(BlockSpec(pv, prism.faces))
    sim = Simulation(bs, gravity=(0, 0, 0), dt=1e-3)
    A = sim.A
    vs, fs, es = A.vert_start, A.face_start, A.edge_start
    for w, nw, d in ((w1, n1, d1), (w2, n2, d2)):
        out = np.zeros(3)
        g, ia, ib, sa, sb, it = fcp(sim.vert, sim.fnw, vs[i], vs[i + 1], vs[w], vs[w + 1], A.he_origin, A.he_next,
                                    A.he_pair, A.he_face, A.vert_he, -nw, 1e-13, 100, out)
        assert np.allclose(out, -nw, atol=1e-9) and g == pytest.approx(-d, rel=1e-6)
        pos = np.zeros((MAXP, 3))
        dep = np.zeros(MAXP)
        ids = np.zeros(MAXP, np.int64)
        k = contact_points(sim.bundles().geometry, i, w, out, sa, sb, 0.0, 1.0, pos, dep, ids)
        assert k == 4  # the corners only: an edge crossing next to a crease corner is that corner's contact
        assert np.allclose(dep[:k], d, rtol=1e-6)
        # the corners of the prism's face on this wall (brute force: the prism's vertices at depth d below it)
        corners = pv[np.abs(pv @ nw + d) < 1e-9]
        assert len(corners) == 4
        feats = pos[:k] + 0.5 * dep[:k, None] * out
        assert np.allclose(feats @ nw, -d, atol=1e-12)  # every point on the prism's face
        for c in corners:
            assert np.sum(np.linalg.norm(feats - c, axis=1) < 1e-9) == 1
