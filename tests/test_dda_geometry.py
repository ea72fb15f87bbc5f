"""Block geometry for the DDA engine: shapes, hulls, mesh import, cutting, Hoek & Bray, scene generators.

References are independent of the code under test: closed-form volumes, scipy's ConvexHull / linprog /
HalfspaceIntersection, hand-computed cuts, a direct vector-statics solution of the wedge written here.
"""

import itertools
import math

import meshio
import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from dda import cut as C
from dda import generate as G
from dda import hoekbray as HB
from dda import shapes as S
from dda.blockspec import BlockSpec
from sgim.geometry import MeshError

# ------------------------------------------------------------------------------------------------ references


def convex_problems(spec, tol=1e-8):
    """Independent check: closed, consistently oriented, planar faces, convex, normals outward."""
    v = np.asarray(spec.vertices, float)
    scale = np.linalg.norm(v.max(0) - v.min(0))
    directed = []
    for f in spec.faces:
        for k in range(len(f)):
            directed.append((f[k], f[(k + 1) % len(f)]))
    errs = []
    if len(set(directed)) != len(directed):
        errs.append("directed edge repeated")
    ds = set(directed)
    if any((b, a) not in ds for a, b in directed):
        errs.append("open edge")
    inner = v.mean(0)
    for f in spec.faces:
        p = v[f]
        n = np.zeros(3)
        for k in range(len(p)):
            n += np.cross(p[k], p[(k + 1) % len(p)])
        n /= np.linalg.norm(n)
        if np.abs((p - p[0]) @ n).max() > tol * scale:
            errs.append("face not planar")
        if ((v - p[0]) @ n).max() > tol * scale:
            errs.append("vertex outside a face plane")
        if (p.mean(0) - inner) @ n <= 0:
            errs.append("face normal inward")
    if sorted({i for f in spec.faces for i in f}) != list(range(len(v))):
        errs.append("unused vertex")
    return errs


def overlap_depth(p, q):
    """Largest t such that a point lies at least t inside every face plane of both blocks (linprog).

    t > 0 means the interiors overlap; touching blocks give t = 0. Planes from scipy's ConvexHull.
    """
    rows, rhs = [], []
    for s in (p, q):
        e = ConvexHull(s.vertices).equations
        rows.append(np.column_stack([e[:, :3], np.ones(len(e))]))
        rhs.append(-e[:, 3])
    res = linprog([0, 0, 0, -1], A_ub=np.vstack(rows), b_ub=np.concatenate(rhs),
                  bounds=[(None, None)] * 3 + [(None, 1e6)], method="highs")
    assert res.status == 0
    return -res.fun


def assert_no_overlap(blocks, tol=1e-9):
    lo = np.array([b.vertices.min(0) for b in blocks])
    hi = np.array([b.vertices.max(0) for b in blocks])
    scale = float(np.max(hi - lo))
    for i, j in itertools.combinations(range(len(blocks)), 2):
        if np.all(lo[i] < hi[j]) and np.all(lo[j] < hi[i]):
            d = overlap_depth(blocks[i], blocks[j])
            assert d <= tol * scale, (blocks[i].name, blocks[j].name, d)


def hull_volume(spec):
    return ConvexHull(spec.vertices).volume


def edge_lengths(spec):
    e = {tuple(sorted((f[k], f[(k + 1) % len(f)]))) for f in spec.faces for k in range(len(f))}
    return np.array([np.linalg.norm(spec.vertices[a] - spec.vertices[b]) for a, b in e])


# ------------------------------------------------------------------------------------------------ shapes

CLOSED = {  # name: (volume for size a, faces, vertices, regular: all edges = a)
    "tetrahedron": (lambda a: a ** 3 / (6 * math.sqrt(2)), 4, 4, True),
    "pyramid": (lambda a: a ** 3 / (3 * math.sqrt(2)), 5, 5, True),
    "cube": (lambda a: a ** 3, 6, 8, True),
    "octahedron": (lambda a: math.sqrt(2) / 3 * a ** 3, 8, 6, True),
    "brick": (lambda a: a * a / 2 * a / 4, 6, 8, False),
    "prism": (lambda a: math.sqrt(3) / 4 * a * a * a, 5, 6, True),
}


@pytest.mark.parametrize("name", sorted(CLOSED))
def test_shape_library(name):
    vol, nf, nv, regular = CLOSED[name]
    a = 1.7
    s = S.shape(name, a, center=(1.0, -2.0, 3.0))
    assert convex_problems(s) == []
    assert len(s.faces) == nf and len(s.vertices) == nv
    assert S.volume(s) == pytest.approx(vol(a), rel=1e-12)
    assert hull_volume(s) == pytest.approx(vol(a), rel=1e-12)
    # centroid at the requested centre: average of a uniform sample inside (rejection via hull planes)
    e = ConvexHull(s.vertices).equations
    rng = np.random.default_rng(3)
    pts = rng.uniform(s.vertices.min(0), s.vertices.max(0), (200000, 3))
    pts = pts[(pts @ e[:, :3].T + e[:, 3] <= 0).all(1)]
    assert np.allclose(pts.mean(0), (1.0, -2.0, 3.0), atol=0.01 * a)
    if regular:
        assert np.allclose(edge_lengths(s), a)
    r = S.random_rotation(np.random.default_rng(5))
    t = S.shape(name, a, rotation=r)
    assert convex_problems(t) == []
    assert S.volume(t) == pytest.approx(vol(a), rel=1e-12)


def test_shape_errors():
    with pytest.raises(S.GeometryError):
        S.shape("dodecahedron", 1.0)
    with pytest.raises(S.GeometryError):
        S.shape("cube", -1.0)


def test_checker_detects_defects():
    cube = S.shape("cube", 1.0)
    flipped = BlockSpec(cube.vertices, [cube.faces[0][::-1]] + cube.faces[1:])
    assert convex_problems(flipped) and S.check_convex(flipped)
    open_ = BlockSpec(cube.vertices, cube.faces[1:])
    assert S.check_convex(open_)
    # vertex pushed inward: faces still closed but no longer convex
    v = cube.vertices.copy()
    v[0] *= -0.2  # past the plane of its three neighbours
    tris = [[f[0], f[k], f[k + 1]] for f in cube.faces for k in range(1, len(f) - 1)]
    assert S.check_convex(BlockSpec(v, tris))


def test_convex_hull_merges_coplanar_triangles():
    rng = np.random.default_rng(0)
    # points on the faces of the unit cube plus its corners and interior points
    pts = rng.uniform(0, 1, (300, 3))
    face = rng.integers(0, 6, 300)
    pts[np.arange(300), face % 3] = (face // 3).astype(float)
    corners = np.array(list(itertools.product((0.0, 1.0), repeat=3)))
    inner = rng.uniform(0.2, 0.8, (50, 3))
    h = S.convex_hull(np.vstack([pts, corners, inner]))
    assert len(h.faces) == 6 and all(len(f) == 4 for f in h.faces)
    assert len(h.vertices) == 8
    assert convex_problems(h) == []
    # collinear point on an edge is not kept as a vertex
    h2 = S.convex_hull(np.vstack([corners, [[0.5, 0.0, 0.0]]]))
    assert len(h2.vertices) == 8


def test_convex_hull_random_cloud():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(80, 3))
    h = S.convex_hull(pts)
    assert convex_problems(h) == []
    assert S.volume(h) == pytest.approx(ConvexHull(pts).volume, rel=1e-10)
    with pytest.raises(S.GeometryError):
        S.convex_hull([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])


def test_random_rotation_is_haar():
    rng = np.random.default_rng(7)
    rs = np.array([S.random_rotation(rng) for _ in range(20000)])
    assert np.allclose(np.einsum("nij,nkj->nik", rs, rs), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(rs), 1.0)
    tr = np.trace(rs, axis1=1, axis2=2)
    # Haar measure on SO(3): E[R] = 0, E[tr R] = 0, E[(tr R)^2] = 1
    assert np.abs(rs.mean(0)).max() < 0.02
    assert abs(tr.mean()) < 0.03 and abs((tr ** 2).mean() - 1.0) < 0.05
    # same seed, same rotation
    assert np.array_equal(S.random_rotation(np.random.default_rng(3)), S.random_rotation(np.random.default_rng(3)))


def _cube_mesh():
    c = S.shape("cube", 2.0, center=(1, 1, 1))
    tris = [[f[0], f[k], f[k + 1]] for f in c.faces for k in range(1, len(f) - 1)]
    return c.vertices, np.array(tris)


def test_load_convex_mesh(tmp_path):
    v, t = _cube_mesh()
    p = tmp_path / "cube.stl"
    meshio.write_points_cells(p, v, [("triangle", t)])
    b = S.load_convex_mesh(p, name="c")
    assert b.name == "c" and convex_problems(b) == []
    assert len(b.faces) == 6 and S.volume(b) == pytest.approx(8.0)
    # inward-oriented file is accepted and turned outward
    q = tmp_path / "inv.obj"
    meshio.write_points_cells(q, v, [("triangle", t[:, ::-1])])
    assert S.volume(S.load_convex_mesh(q)) == pytest.approx(8.0)
    # quads
    c = S.shape("cube", 1.0)
    r = tmp_path / "quad.vtu"
    meshio.write_points_cells(r, c.vertices, [("quad", np.array(c.faces))])
    assert S.volume(S.load_convex_mesh(r)) == pytest.approx(1.0)


def test_load_convex_mesh_errors(tmp_path):
    v, t = _cube_mesh()
    p = tmp_path / "open.obj"
    meshio.write_points_cells(p, v, [("triangle", t[1:])])
    with pytest.raises(MeshError, match="not a closed"):
        S.load_convex_mesh(p)
    w = v.copy()
    w[np.argmax(w.sum(1))] = (1.2, 1.2, 1.2)  # corner pushed into the cube: dent
    q = tmp_path / "dent.obj"
    meshio.write_points_cells(q, w, [("triangle", t)])
    with pytest.raises(MeshError, match="not convex"):
        S.load_convex_mesh(q)
    with pytest.raises(MeshError, match="not found"):
        S.load_convex_mesh(tmp_path / "none.stl")
    bad = tmp_path / "bad.stl"
    bad.write_text("solid nothing\n garbage\n")
    with pytest.raises(MeshError):
        S.load_convex_mesh(bad)


# ------------------------------------------------------------------------------------------------ cutting


def test_split_hand_cases():
    cube = S.box((0, 0, 0), (1, 1, 1))
    lo, hi = C.split(cube, ((1, 0, 0), 0.25))
    assert S.volume(lo) == pytest.approx(0.25) and S.volume(hi) == pytest.approx(0.75)
    # plane through the body diagonal plane x = y: two triangular prisms, 5 faces each, on-plane vertices shared
    lo, hi = C.split(cube, ((1, -1, 0), (0, 0, 0)))
    for p in (lo, hi):
        assert convex_problems(p) == [] and len(p.faces) == 5 and len(p.vertices) == 6
        assert S.volume(p) == pytest.approx(0.5)
    # hexagonal section by x + y + z = 1.5
    lo, hi = C.split(cube, ((1, 1, 1), 1.5))
    assert S.volume(lo) == pytest.approx(0.5) and S.volume(hi) == pytest.approx(0.5)
    assert max(len(f) for f in lo.faces) == 6
    # only touching at a corner: nothing to cut
    lo, hi = C.split(cube, ((1, 1, 1), 0.0))
    assert lo is None and hi is cube
    # corner tetrahedron cut at z = 1/2: the top is a tetrahedron of edge 1/2, volume (1/2)^3 / 6
    tet = S.convex_hull([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    lo, hi = C.split(tet, ((0, 0, 1), 0.5))
    assert S.volume(hi) == pytest.approx(0.125 / 6)
    assert S.volume(lo) == pytest.approx(1 / 6 - 0.125 / 6)
    assert len(lo.faces) == 5 and convex_problems(lo) == []


def test_split_near_vertex_is_robust():
    cube = S.box((0, 0, 0), (1, 1, 1))
    # plane through the corner (1,1,1) within rounding: no extra vertex next to it
    lo, hi = C.split(cube, ((1, 1, 0), 2.0 - 1e-13))
    assert hi is None or S.volume(hi) < 1e-12
    pieces = C.cut_convex(cube, [((1, 1, 0), 2.0 - 1e-13), ((1, 0, 0), 0.5)])
    assert len(pieces) == 2 and sum(S.volume(p) for p in pieces) == pytest.approx(1.0)


def test_slivers_merge_or_drop():
    cube = S.box((0, 0, 0), (1, 1, 1))
    merged = C.cut_convex(cube, [((1, 0, 0), 1e-8), ((1, 0, 0), 0.5)])
    assert len(merged) == 2 and sum(S.volume(p) for p in merged) == pytest.approx(1.0, abs=1e-14)
    dropped = C.cut_convex(cube, [((1, 0, 0), 1e-8), ((1, 0, 0), 0.5)], sliver="drop")
    assert len(dropped) == 2 and sum(S.volume(p) for p in dropped) == pytest.approx(1.0 - 1e-8, abs=1e-13)
    kept = C.cut_convex(cube, [((1, 0, 0), 1e-4)], min_volume=1e-6)
    assert len(kept) == 2


def test_joint_set_orientation_matches_sgim():
    # dip 0: horizontal layers, spacing 1
    pieces = C.cut_box((0, 0, 0), (2, 2, 3), joint_sets=[C.JointSet(0.0, 0.0, 1.0)])
    zs = sorted((p.vertices[:, 2].min(), p.vertices[:, 2].max()) for p in pieces)
    assert np.allclose(zs, [(0, 1), (1, 2), (2, 3)])
    # dip 90 toward east (dip direction 90): vertical planes x = const, origin shifts them
    pieces = C.cut_box((0, 0, 0), (5, 1, 1), joint_sets=[C.JointSet(90.0, 90.0, 2.0, origin=(0.5, 0, 0))])
    xs = sorted((round(p.vertices[:, 0].min(), 9), round(p.vertices[:, 0].max(), 9)) for p in pieces)
    assert xs == [(0, 0.5), (0.5, 2.5), (2.5, 4.5), (4.5, 5)]
    # dip 45 toward north: normal (0, sin45, cos45)
    pieces = C.cut_box((0, 0, 0), (1, 4, 4), joint_sets=[C.JointSet(45.0, 0.0, 10.0, origin=(0, 2, 2))])
    assert len(pieces) == 2
    n = np.array([0, 1, 1]) / math.sqrt(2)
    for p in pieces:
        s = p.vertices @ n - n @ (0, 2, 2)
        assert s.min() >= -1e-9 or s.max() <= 1e-9


def _cells(lo, hi, sets):
    """Independent reference: every joint-set cell of the box as a polytope (HalfspaceIntersection)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    normals = [js.normal() for js in sets]
    corners = np.array(list(itertools.product(*zip(lo, hi))))
    ranges = []
    for js, n in zip(sets, normals):
        d0 = n @ np.asarray(js.origin, float)
        s = corners @ n
        ranges.append(range(int(np.floor((s.min() - d0) / js.spacing)), int(np.floor((s.max() - d0) / js.spacing)) + 1))
    out = {}
    for key in itertools.product(*ranges):
        hs = [[-1, 0, 0, lo[0]], [0, -1, 0, lo[1]], [0, 0, -1, lo[2]], [1, 0, 0, -hi[0]], [0, 1, 0, -hi[1]], [0, 0, 1, -hi[2]]]
        for k, js, n in zip(key, sets, normals):
            d0 = n @ np.asarray(js.origin, float)
            hs.append([*(-n), d0 + k * js.spacing])
            hs.append([*n, -(d0 + (k + 1) * js.spacing)])
        hs = np.array(hs)
        a = np.column_stack([hs[:, :3], np.linalg.norm(hs[:, :3], axis=1)])
        r = linprog([0, 0, 0, -1], A_ub=a, b_ub=-hs[:, 3], bounds=[(None, None)] * 3 + [(None, 1e3)], method="highs")
        if r.status == 0 and -r.fun > 1e-6:
            hsi = HalfspaceIntersection(hs, r.x[:3])
            out[key] = ConvexHull(hsi.intersections).volume
    return out


def test_cut_box_by_joint_sets_against_cells():
    sets = [C.JointSet(60, 30, 1.5), C.JointSet(45, 200, 2.0, origin=(0.3, 0, 0)), C.JointSet(10, 100, 1.7)]
    lo, hi = (0, 0, 0), (6, 5, 4)
    pieces = C.cut_box(lo, hi, joint_sets=sets, min_volume=1e-9)
    ref = _cells(lo, hi, sets)
    assert sum(S.volume(p) for p in pieces) == pytest.approx(120.0, rel=1e-12)
    assert len(pieces) == len(ref)
    got = {}
    for p in pieces:
        assert convex_problems(p) == []
        c = S.volume_centroid(p)[1]
        key = tuple(int(np.floor((js.normal() @ c - js.normal() @ np.asarray(js.origin, float)) / js.spacing)) for js in sets)
        # each piece lies inside one slab of every set
        for js, k in zip(sets, key):
            s = p.vertices @ js.normal() - js.normal() @ np.asarray(js.origin, float)
            assert s.min() >= k * js.spacing - 1e-9 and s.max() <= (k + 1) * js.spacing + 1e-9
        assert key not in got
        got[key] = S.volume(p)
    assert set(got) == set(ref)
    for k in ref:
        assert got[k] == pytest.approx(ref[k], rel=1e-9, abs=1e-12)


def test_cut_prism_and_extent():
    tri = [(0, 0), (4, 0), (0, 4)]
    pieces = C.cut_prism(tri, 0, 2, planes=[((0, 0, 1), 1.0), ((1, 0, 0), (1, 0, 0))])
    assert len(pieces) == 4
    assert sum(S.volume(p) for p in pieces) == pytest.approx(16.0)
    assert all(convex_problems(p) == [] for p in pieces)
    # a vertical set present only for x in [0, 5]: the upper half (z > 2) is cut, the lower left whole
    sets = [C.JointSet(0, 0, 2.0), C.JointSet(90, 90, 1.0, extent=((0, 0, 2), (10, 10, 4)))]
    pieces = C.cut_box((0, 0, 0), (4, 1, 4), joint_sets=sets)
    lower = [p for p in pieces if p.vertices[:, 2].max() <= 2 + 1e-9]
    upper = [p for p in pieces if p.vertices[:, 2].min() >= 2 - 1e-9]
    assert len(lower) == 1 and len(upper) == 4
    assert sum(S.volume(p) for p in pieces) == pytest.approx(16.0)


# ------------------------------------------------------------------------------------------------ Hoek & Bray


def _plane_normal(dip, dd):
    d, a = math.radians(dip), math.radians(dd)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def statics_fs(ja, jb, face, height, phi_a, phi_b, ca=0.0, cb=0.0, gamma=25.0, top=(0.0, 0.0)):
    """Direct vector statics of a tetrahedral wedge resting on planes A and B (written for the test).

    Vertices by intersecting the planes (toe at the origin, top through the crest point of the face); weight
    from the tetrahedron volume; equilibrium W + N_A a + N_B b - T s = 0 solved as a 3x3 system with s the
    downward unit vector along the line of intersection; FS = resisting / T.
    """
    a, b, f, t = (_plane_normal(*p) for p in (ja, jb, face, top))
    fd, fa = map(math.radians, face)
    crest = np.array([-math.sin(fa) / math.tan(fd), -math.cos(fa) / math.tan(fd), 1.0]) * height
    d = t @ crest
    p5 = np.linalg.solve([a, b, t], [0, 0, d])
    p1 = np.linalg.solve([a, f, t], [0, 0, d])
    p2 = np.linalg.solve([b, f, t], [0, 0, d])
    vol = abs(np.linalg.det([p5, p1, p2])) / 6
    area_a = np.linalg.norm(np.cross(p5, p1)) / 2
    area_b = np.linalg.norm(np.cross(p5, p2)) / 2
    s = -p5 / np.linalg.norm(p5)
    w = np.array([0, 0, -gamma * vol])
    na, nb, tt = np.linalg.solve(np.column_stack([a, b, -s]), -w)
    res = na * math.tan(math.radians(phi_a)) + nb * math.tan(math.radians(phi_b)) + ca * area_a + cb * area_b
    return res / tt, na, nb, vol


def test_paper_wedge_value():
    r = HB.wedge_fs(**HB.PAPER_CASE)
    assert r.mode == "both planes"
    assert round(r.fs, 3) == 1.302  # the value the digest quotes for Hoek & Bray
    assert r.fs_friction_only == pytest.approx(r.fs, rel=1e-12)
    ref, na, nb, vol = statics_fs((45, 5), (55, 135), (65, 65), 10.0, 25, 25, gamma=HB.PAPER_CASE["unit_weight"])
    assert r.fs == pytest.approx(ref, rel=1e-10)
    assert r.volume == pytest.approx(vol, rel=1e-10)
    assert r.normal_force_a == pytest.approx(na, rel=1e-10) and r.normal_force_b == pytest.approx(nb, rel=1e-10)
    # critical friction: FS = 1 there
    assert HB.wedge_fs(**{**HB.PAPER_CASE, "friction": r.critical_friction}).fs == pytest.approx(1.0, rel=1e-12)
    # with c = 0 the result does not depend on the face direction, height or unit weight
    other = HB.wedge_fs(**{**HB.PAPER_CASE, "face": (70, 80), "height": 3.0, "unit_weight": 10.0})
    assert other.fs == pytest.approx(r.fs, rel=1e-12)


CASES = [  # joint A, joint B, face, top, phi A, phi B, cA, cB
    ((45, 5), (55, 135), (65, 65), (0, 0), 25, 25, 0, 0),
    ((45, 105), (70, 235), (65, 185), (12, 195), 20, 30, 5, 10),
    ((40, 160), (60, 260), (75, 200), (0, 0), 30, 35, 0, 0),
    ((50, 30), (50, 150), (80, 90), (5, 90), 28, 28, 20, 0),
    ((35, 300), (65, 40), (70, 340), (0, 0), 22, 32, 3, 3),
]


@pytest.mark.parametrize("ja,jb,face,top,pa,pb,ca,cb", CASES)
def test_wedge_fs_against_statics(ja, jb, face, top, pa, pb, ca, cb):
    r = HB.wedge_fs(ja, jb, face, top=top, friction=(pa, pb), cohesion=(ca, cb), unit_weight=25.0, height=12.0)
    ref, na, nb, _ = statics_fs(ja, jb, face, 12.0, pa, pb, ca, cb, gamma=25.0, top=top)
    assert na > 0 and nb > 0 and r.mode == "both planes"
    assert r.fs == pytest.approx(ref, rel=1e-9)
    assert r.fs_hoek_bray == pytest.approx(ref, rel=1e-9)
    if ca == cb == 0:
        assert r.fs_friction_only == pytest.approx(ref, rel=1e-9)


def test_wedge_single_plane_and_no_wedge():
    # B nearly vertical and A shallow: the statics on two planes gives N_B < 0, so contact with B is lost and the
    # wedge slides on A alone: FS = tan(phi) / tan(psi_A)
    ref, na, nb, _ = statics_fs((25, 0), (89, 80), (80, 15), 10.0, 20, 20)
    assert nb < 0 < na
    r = HB.wedge_fs((25, 0), (89, 80), (80, 15), friction=20, height=10.0)
    assert r.mode == "plane A" and r.normal_force_b == 0.0
    assert r.fs == pytest.approx(math.tan(math.radians(20)) / math.tan(math.radians(25)), rel=1e-12)
    assert r.critical_friction == pytest.approx(25.0)
    with pytest.raises(HB.WedgeError):  # face flatter than the line of intersection: no daylight
        HB.wedge_fs((45, 5), (55, 135), (20, 65))
    with pytest.raises(HB.WedgeError):
        HB.wedge_fs((45, 5), (45, 5), (65, 65))


# ------------------------------------------------------------------------------------------------ generators


def test_generator_registry():
    assert set(G.GENERATORS) >= {"incline", "wedge", "toppling", "brick_wall", "falling_polyhedra", "stack", "box_cut"}


def _all_convex(blocks):
    for b in blocks:
        assert convex_problems(b) == [], b.name


def test_incline():
    bl = G.GENERATORS["incline"](angle=30.0, size=1.0)
    assert [b.name for b in bl] == ["base", "block"] and bl[0].fixed and not bl[1].fixed
    _all_convex(bl)
    assert_no_overlap(bl)
    # block bottom lies on the base top plane, whose normal is (sin 30, 0, cos 30)
    n = np.array([0.5, 0, math.sqrt(3) / 2])
    top = (bl[0].vertices @ n).max()
    assert (bl[1].vertices @ n).min() == pytest.approx(top, abs=1e-12)
    assert np.sum(np.abs(bl[1].vertices @ n - top) < 1e-9) == 4


def test_wedge_blocks():
    bl = G.GENERATORS["wedge"](**{k: HB.PAPER_CASE[k] for k in ("face", "top", "height")},
                               joint_a=HB.PAPER_CASE["joint_a"], joint_b=HB.PAPER_CASE["joint_b"])
    assert len(bl) == 4 and [b.fixed for b in bl] == [False, True, True, True]
    _all_convex(bl)
    assert_no_overlap(bl)
    w = bl[0]
    assert len(w.vertices) == 4
    ref = statics_fs((45, 5), (55, 135), (65, 65), 10.0, 25, 25)[3]
    assert hull_volume(w) == pytest.approx(ref, rel=1e-10)
    # the wedge's faces on A and on B are shared with fixed blocks: all wedge vertices on those planes
    # are vertices of a face of below_a / below_b lying in the same plane
    for blk, dipdd in ((bl[1], (45, 5)), (bl[2], (55, 135))):
        n = _plane_normal(*dipdd)
        on = w.vertices[np.abs(w.vertices @ n) < 1e-9]
        assert len(on) == 3
        e = ConvexHull(blk.vertices).equations
        face_rows = e[np.abs(np.abs(e[:, :3] @ n) - 1) < 1e-9]
        assert len(face_rows) >= 1
        assert np.allclose(face_rows[:, :3] @ n, 1.0)  # outward normal of below_X points up, into the wedge
        # the wedge face lies inside the fixed block's face polygon: points on it are within the block
        assert ((on.mean(0) @ e[:, :3].T + e[:, 3]) <= 1e-9).all()


@pytest.mark.parametrize("b,h,alpha", [(1.0, 3.0, 20.0), (1.0, 2.0, 30.0), (0.5, 4.0, 5.0)])
def test_toppling_geometry(b, h, alpha):
    bl = G.GENERATORS["toppling"](b=b, h=h, alpha=alpha)
    _all_convex(bl)
    assert_no_overlap(bl)
    col = bl[1]
    assert S.volume(col) == pytest.approx(b * b * h)
    # the vertical through the centroid falls inside the base of the column iff b/h > tan(alpha)
    c = S.volume_centroid(col)[1]
    n = np.array([math.sin(math.radians(alpha)), 0, math.cos(math.radians(alpha))])
    base_pts = col.vertices[np.abs(col.vertices @ n - (col.vertices @ n).min()) < 1e-9]
    assert len(base_pts) == 4
    # downhill toe: the base edge with the largest x; compare plan positions along the slope direction
    inside = c[0] < base_pts[:, 0].max() - 1e-12
    assert inside == (b / h > math.tan(math.radians(alpha)))


def test_brick_wall():
    bl = G.GENERATORS["brick_wall"]()
    names = [b.name for b in bl]
    bricks = [b for b in bl if b.name.startswith("brick_")]
    assert len(bricks) == 130 and names.count("projectile") == 1
    assert {b.name for b in bl if b.fixed} == {"ground", "ramp"}
    _all_convex(bl)
    assert_no_overlap(bl)
    # staggered: odd layers shifted by half a brick
    y = {b.name: b.vertices[:, 1].min() for b in bricks}
    assert y["brick_1_0"] - y["brick_0_0"] == pytest.approx(0.2)
    assert max(b.vertices[:, 2].max() for b in bricks) == pytest.approx(2.0)
    # the projectile rests on the ramp surface and slides toward the wall (+x)
    pr = bl[names.index("projectile")]
    e = ConvexHull(bl[names.index("ramp")].vertices).equations
    outside = (pr.vertices @ e[:, :3].T + e[:, 3]).max(1)  # distance of each vertex outside the ramp
    assert np.sum(np.abs(outside) < 1e-12) == 4 and outside.min() > -1e-12
    assert np.allclose(pr.vertices[:, 1].mean(), 0.0) and pr.velocity == (0.0, 0.0, 0.0)


def test_falling_polyhedra():
    bl = G.GENERATORS["falling_polyhedra"](n=40, seed=11)
    assert len(bl) == 41 and bl[0].fixed and not any(b.fixed for b in bl[1:])
    _all_convex(bl)
    assert_no_overlap(bl)
    vols = {round(S.volume(b), 9) for b in bl[1:]}
    assert vols <= {round(CLOSED[s][0](1.0), 9) for s in S.PAPER_SHAPES} and len(vols) == 4
    assert min(b.vertices[:, 2].min() for b in bl[1:]) > 0
    again = G.GENERATORS["falling_polyhedra"](n=40, seed=11)
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(bl, again))
    other = G.GENERATORS["falling_polyhedra"](n=40, seed=12)
    assert not all(np.array_equal(a.vertices, b.vertices) for a, b in zip(bl[1:], other[1:]))


def test_stack_and_box_cut():
    bl = G.GENERATORS["stack"](n=10, size=1.0)
    assert len(bl) == 11 and bl[0].fixed
    _all_convex(bl)
    assert_no_overlap(bl)
    for k, b in enumerate(bl[1:]):
        assert b.vertices[:, 2].min() == pytest.approx(0.5 * k) and b.vertices[:, 2].max() == pytest.approx(0.5 * k + 0.5)
    bc = G.GENERATORS["box_cut"](lo=(0, 0, 0), hi=(4, 3, 2),
                                 joint_sets=[{"dip": 70, "dip_direction": 120, "spacing": 1.0},
                                             {"dip": 20, "dip_direction": 300, "spacing": 0.8, "origin": [0, 0, 0.1]}],
                                 planes=[{"normal": [0, 1, 0], "point": [0, 1.5, 0]}])
    assert bc[0].fixed and bc[0].name == "floor"
    _all_convex(bc)
    assert_no_overlap(bc)
    assert sum(S.volume(b) for b in bc[1:]) == pytest.approx(24.0)
