"""Excavation (paper eq. 1-12 and the exact rule) against independent brute force.

The reference (tests/sgim_ref.py) builds the full cubic lattice from eq. 1-2 and evaluates
the paper's seven steps with determinants written out, vectorised over every site for each
facet, with the documented rounding allowance ROUND = 1e-12 (see sgim_ref's docstring).
"""
from __future__ import annotations

import subprocess
import sys
import textwrap
import tracemalloc

import numpy as np
import pytest

import sgim_ref as ref
import sgim_scenes as gen
from sgim.excavate import FacetSet, kept_sites
from sgim.geometry import triangulate_plan
from sgim.packing import make_lattice
from sgim.scene import Surface


def facet_set(surfaces):
    return FacetSet([Surface(f"s{k}", np.asarray(v, float), np.asarray(f, np.int64), rule, f"excavation[{k}]")
                     for k, (v, f, rule) in enumerate(surfaces)])


def sgim_kept(kind, lo, hi, r, surfaces):
    return kept_sites(make_lattice(kind, lo, hi, r), facet_set(surfaces), lo, hi)


def assert_same_sites(got, want):
    got = np.asarray(got)
    assert got.ndim == 2 and got.shape[1] == 3
    g, w = ref.as_set(got), ref.as_set(want)
    assert len(g) == len(got), "kept_sites returned duplicated sites"
    extra, missing = sorted(g - w)[:5], sorted(w - g)[:5]
    assert g == w, f"{len(g - w)} sites kept that should go (e.g. {extra}); {len(w - g)} missing (e.g. {missing})"


def nontrivial_scene(seed, rules, kinds=("plan", "steep", "soup", "vertical"), lattice_sites=None):
    """A random box and surfaces that remove some but not all of the lattice (reference count)."""
    rng = np.random.default_rng(seed)
    while True:
        lo, hi, r = gen.random_box(rng)
        surfaces = gen.random_surfaces(rng, lo, hi, rules=rules, kinds=kinds)
        sites = ref.cubic_sites(lo, hi, r) if lattice_sites is None else lattice_sites(lo, hi, r)
        if not surfaces:
            continue
        frac = ref.removed_mask(sites, surfaces, r).mean()
        if 0.05 < frac < 0.95:
            return lo, hi, r, surfaces, sites


# ---------------------------------------------------------------------------
# eq. 1-2

@pytest.mark.parametrize("lo,hi,r", [
    ((0, 0, 0), (4, 4, 4), 0.5),
    ((0, 0, 0), (2.5, 3.5, 1.5), 0.5),  # extent / 2r = 2.5, 3.5, 1.5: round half up -> 3, 4, 2
    ((-150, -125, 0), (-140, -117, 6), 0.5),
    ((1.3, -2.7, 0.4), (5.9, 1.1, 3.3), 0.37),
    ((-3.0, 2.0, -1.0), (-1.7, 6.1, 0.1), 0.26),
])
def test_cubic_lattice_is_eq_1_2(lo, hi, r):
    want = ref.cubic_sites(lo, hi, r)
    lat = make_lattice("cubic", lo, hi, r)
    assert lat.n_sites == len(want)
    assert_same_sites(lat.all_centres(), want)
    # and excavation by nothing keeps the whole basic model
    assert_same_sites(kept_sites(lat, FacetSet([]), lo, hi), want)


def test_round_half_up_counts():
    # 2.5 layers round up to 3 (banker's rounding would give 2)
    assert make_lattice("cubic", (0, 0, 0), (2.5, 2.5, 2.5), 0.5).n_sites == 27
    assert make_lattice("cubic", (0, 0, 0), (2.4, 2.4, 2.4), 0.5).n_sites == 8


# ---------------------------------------------------------------------------
# the paper's rule and the exact rule on random scenes

@pytest.mark.parametrize("seed", range(40))
def test_paper_rule_random_scenes(seed):
    lo, hi, r, surfaces, sites = nontrivial_scene(1000 + seed, rules=("paper",))
    assert_same_sites(sgim_kept("cubic", lo, hi, r, surfaces), ref.kept(sites, surfaces, r))


@pytest.mark.parametrize("seed", range(25))
def test_exact_rule_random_scenes(seed):
    lo, hi, r, surfaces, sites = nontrivial_scene(2000 + seed, rules=("exact",))
    assert_same_sites(sgim_kept("cubic", lo, hi, r, surfaces), ref.kept(sites, surfaces, r))


@pytest.mark.parametrize("seed", range(15))
def test_mixed_rules_several_surfaces(seed):
    rng = np.random.default_rng(3000 + seed)
    lo, hi, r = gen.random_box(rng)
    surfaces = []
    for kind, rule in (("plan", "paper"), ("steep", "exact"), ("soup", "paper"), ("vertical", "exact")):
        surfaces += gen.random_surfaces(rng, lo, hi, rules=(rule,), kinds=(kind,))[:1]
    sites = ref.cubic_sites(lo, hi, r)
    assert_same_sites(sgim_kept("cubic", lo, hi, r, surfaces), ref.kept(sites, surfaces, r))


@pytest.mark.parametrize("seed", range(10))
def test_exact_rule_removes_at_least_what_the_paper_rule_removes(seed):
    """Space I lies within r of the facet and space II above it, so the exact rule keeps a
    subset of what the paper's rule keeps."""
    paper, exact = _paper_and_exact(6000 + seed)
    assert exact <= paper


def _paper_and_exact(seed):
    lo, hi, r, surfaces, sites = nontrivial_scene(seed, rules=("paper",), kinds=("plan", "steep", "soup"))
    paper = ref.as_set(sgim_kept("cubic", lo, hi, r, surfaces))
    exact = ref.as_set(sgim_kept("cubic", lo, hi, r, [(v, f, "exact") for v, f, _ in surfaces]))
    return paper, exact


def test_exact_rule_closes_gaps_at_edges():
    """...and it does remove more on most scenes (sites near edges, outside every prism)."""
    fewer = sum(len(e) < len(p) for p, e in (_paper_and_exact(6000 + s) for s in range(10)))
    assert fewer >= 5


@pytest.mark.parametrize("kind", ["hexagonal", "fcc"])
@pytest.mark.parametrize("seed", range(10))
def test_close_packed_lattices(kind, seed):
    def all_centres(lo, hi, r):
        return make_lattice(kind, lo, hi, r).all_centres()

    lo, hi, r, surfaces, sites = nontrivial_scene(4000 + seed, rules=("paper", "exact"), lattice_sites=all_centres)
    assert_same_sites(sgim_kept(kind, lo, hi, r, surfaces), ref.kept(sites, surfaces, r))


def test_random_scenes_cover_the_intended_cases():
    """The generators do produce steep facets, vertical facets (C0 == 0) and facets partly
    outside the box (otherwise the random tests above would not cover them)."""
    steep = vertical = outside = 0
    for seed in range(40):
        lo, hi, r, surfaces, _ = nontrivial_scene(1000 + seed, rules=("paper",))
        for v, f, _rule in surfaces:
            for tri in v[f]:
                A, B, C, _ = ref.plane_abcd(*tri)
                vertical += C == 0.0
                steep += C != 0.0 and abs(C) < 0.3 * np.sqrt(A * A + B * B + C * C)
                outside += bool(np.any(tri < lo) or np.any(tri > hi))
    assert vertical >= 5 and steep >= 20 and outside >= 20, (vertical, steep, outside)


# ---------------------------------------------------------------------------
# closed forms (checks of the reference as much as of sgim)

@pytest.mark.parametrize("rule", ["paper", "exact"])
@pytest.mark.parametrize("gx,gy", [(0.0, 0.0), (0.31, -0.17), (1.7, 0.4)])
def test_inclined_plane_closed_form(rule, gx, gy):
    """A plane z = c + gx x + gy y covering the box with room to spare: a site is kept
    exactly when it lies below the plane at a distance of at least r."""
    lo, hi, r = np.array([-0.3, 0.2, -1.1]), np.array([5.2, 4.9, 6.3]), 0.45
    c0 = 2.9137

    def h(x, y):
        return c0 + gx * x + gy * y

    big = 30.0
    corners = [(-big, -big), (big, -big), (big, big), (-big, big)]
    verts = np.array([(x, y, h(x, y)) for x, y in corners])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    sites = ref.cubic_sites(lo, hi, r)
    depth = (h(sites[:, 0], sites[:, 1]) - sites[:, 2]) / np.sqrt(1 + gx * gx + gy * gy)
    want = sites[depth >= r]
    assert 0 < len(want) < len(sites)
    assert_same_sites(ref.kept(sites, [(verts, faces, rule)], r), want)
    assert_same_sites(sgim_kept("cubic", lo, hi, r, [(verts, faces, rule)]), want)


# ---------------------------------------------------------------------------
# vertical facets: space I but no space II

VERTICAL_TRI = np.array([[2.5, 0.3, 0.2], [2.5, 3.7, 0.2], [2.5, 2.0, 1.9]])  # in the plane x = 2.5


@pytest.mark.parametrize("rule", ["paper", "exact"])
def test_vertical_facet_has_no_space_II(rule):
    lo, hi, r = (0, 0, 0), (5, 4, 5), 0.5
    faces = np.array([[0, 1, 2]])
    assert ref.plane_abcd(*VERTICAL_TRI)[2] == 0.0
    sites = ref.cubic_sites(lo, hi, r)
    got = sgim_kept("cubic", lo, hi, r, [(VERTICAL_TRI, faces, rule)])
    assert_same_sites(got, ref.kept(sites, [(VERTICAL_TRI, faces, rule)], r))
    gs = ref.as_set(got)
    # the column x = 2.5 lies in the facet's plane; its sites above the facet (z >= 2.5,
    # more than r from the apex) are in its (degenerate) vertical prism but must stay
    above = sites[(sites[:, 0] == 2.5) & (sites[:, 2] >= 2.5)]
    assert len(above) and ref.as_set(above) <= gs
    # sites farther than r from the facet's plane stay, whatever their height
    far = sites[np.abs(sites[:, 0] - 2.5) >= r]
    assert ref.as_set(far) <= gs
    # sites in the facet (distance 0) go
    inside = np.array([[2.5, 1.5, 0.5], [2.5, 2.5, 0.5], [2.5, 2.0, 1.5]])
    assert not (ref.as_set(inside) & gs)
    # control: tilt the facet by a hair and space II appears, removing the sites above it
    tilted = VERTICAL_TRI.copy()
    tilted[2, 0] += 1e-3
    gt = ref.as_set(sgim_kept("cubic", lo, hi, r, [(tilted, faces, rule)]))
    assert not (ref.as_set(above[above[:, 1] == 2.5]) & gt)


# ---------------------------------------------------------------------------
# regression: sites exactly on an edge shared by two facets

# (box x/y origin, corner heights): squares split along their diagonal through lattice columns;
# the literal "<=" evaluation (no rounding allowance) leaves sites standing above these.
SHARED_EDGE_CASES = [
    ((51.7, -143.3), (4.1, 3.1, 2.2, 3.5)),
    ((133.3, 43.1), (2.9, 4.6, 2.4, 4.8)),
    ((-65.9, -71.3), (5.6, 5.4, 3.6, 4.0)),
    ((0.0, 0.0), (2.3, 4.1, 5.7, 3.2)),
]


@pytest.mark.parametrize("rule", ["paper", "exact"])
@pytest.mark.parametrize("origin,zc", SHARED_EDGE_CASES)
def test_sites_on_shared_diagonal_edge_are_removed(rule, origin, zc):
    r, n = 0.5, 8
    lo = np.array([origin[0], origin[1], 0.0])
    hi = lo + 2 * r * n
    x0, y0, x1, y1 = lo[0] + r, lo[1] + r, hi[0] - r, hi[1] - r  # corner lattice columns
    verts = np.array([[x0, y0, zc[0]], [x1, y0, zc[1]], [x1, y1, zc[2]], [x0, y1, zc[3]]])
    for faces in (np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0, 2, 1], [3, 2, 0]])):  # both orientations
        got = sgim_kept("cubic", lo, hi, r, [(verts, faces, rule)])
        t = (got[:, 0] - x0) / (x1 - x0)
        on_diag = np.abs((got[:, 0] - x0) - (got[:, 1] - y0)) < 1e-9
        h = zc[0] + t * (zc[2] - zc[0])
        standing = got[on_diag & (got[:, 2] >= h)]
        assert len(standing) == 0, f"sites left above the shared edge: {standing.tolist()}"
        sites = ref.cubic_sites(lo, hi, r)
        assert np.sum(np.abs((sites[:, 0] - x0) - (sites[:, 1] - y0)) < 1e-9) == n * n  # the edge holds columns
        assert_same_sites(got, ref.kept(sites, [(verts, faces, rule)], r))


# ---------------------------------------------------------------------------
# cost follows what is kept

def _deep_cut(n):
    """A surface at ~10% height over an n x n x n box of unit spheres (r = 0.5)."""
    z = 0.1 * n
    v = np.array([[-1, -1, z + 0.3], [n + 1, -1, z - 0.3], [n + 1, n + 1, z + 0.1], [-1, n + 1, z + 0.6]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_kept_sites_does_not_materialise_the_cuboid():
    n = 100
    lo, hi = np.zeros(3), np.full(3, float(n))
    lat = make_lattice("cubic", lo, hi, 0.5)
    v, f = _deep_cut(n)
    fs = facet_set([(v, f, "paper")])
    kept_sites(make_lattice("cubic", lo, lo + 8, 0.5), fs, lo, lo + 8)  # load the kernels first
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        out = kept_sites(lat, fs, lo, hi)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert 0.05 * lat.n_sites < len(out) < 0.15 * lat.n_sites
    cuboid = lat.n_sites * 24
    assert peak < cuboid / 4, f"peak {peak} bytes for a {cuboid}-byte cuboid"
    assert peak < 2 * len(out) * 24 + lat.n_sites // n * 64


def test_kept_sites_resident_memory_follows_kept_count():
    """Also covers memory the kernels allocate themselves (invisible to tracemalloc)."""
    code = textwrap.dedent("""
        import resource, numpy as np
        from sgim.excavate import FacetSet, kept_sites
        from sgim.packing import make_lattice
        from sgim.scene import Surface
        n = 200
        z = 0.1 * n
        v = np.array([[-1, -1, z + 0.3], [n + 1, -1, z - 0.3], [n + 1, n + 1, z + 0.1], [-1, n + 1, z + 0.6]])
        fs = FacetSet([Surface('s', v, np.array([[0, 1, 2], [0, 2, 3]]), 'paper', 'k')])
        lo = np.zeros(3)
        kept_sites(make_lattice('cubic', lo, lo + 8, 0.5), fs, lo, lo + 8)
        lat = make_lattice('cubic', lo, lo + n, 0.5)
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        out = kept_sites(lat, fs, lo, lo + n)
        after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        print(lat.n_sites, len(out), (after - before) * 1024)
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    n_sites, n_kept, grown = map(int, res.stdout.split())
    assert n_kept < 0.15 * n_sites
    assert grown < n_sites * 24 / 4, f"resident memory grew by {grown} bytes for {n_sites} sites"


# ---------------------------------------------------------------------------
# lattice columns on the far face of the domain

# (domain min, domain max, r, terrain grid cells per side): extent / 2r is n + 0.5 on an axis,
# so the paper's half-up rounding puts the last lattice row on the domain's far face (an ulp
# beyond it after rounding), and the terrain grid spans the domain exactly.
BOUNDARY_CASES = [
    ((-7.23, -14.68, 4.67), (-0.2, -7.65, 8.0), 0.37, 1),
    ((17.64, -11.95, 19.53), (23.04, -5.83, 25.65), 0.36, 3),
    ((-9.9, 1.17, -0.74), (-4.77, 6.3, 4.39), 0.27, 5),
]


@pytest.mark.parametrize("rule", ["paper", "exact"])
@pytest.mark.parametrize("lo,hi,r,m", BOUNDARY_CASES)
def test_domain_aligned_terrain_grid(lo, hi, r, m, rule):
    """A terrain given on a regular grid that covers the domain exactly (a common DEM set-up):
    the lattice rows on the far faces must be excavated like the others."""
    lo, hi = np.array(lo), np.array(hi)
    xs, ys = np.linspace(lo[0], hi[0], m + 1), np.linspace(lo[1], hi[1], m + 1)
    X, Y = np.meshgrid(xs, ys)
    zmid = lo[2] + 0.5 * (hi[2] - lo[2])
    verts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, zmid)])
    faces = []
    for j in range(m):
        for i in range(m):
            a = j * (m + 1) + i
            faces += [[a, a + 1, a + m + 2], [a, a + m + 2, a + m + 1]]
    faces = np.array(faces)
    got = sgim_kept("cubic", lo, hi, r, [(verts, faces, rule)])
    standing = got[got[:, 2] >= zmid]
    assert len(standing) == 0, f"{len(standing)} sites kept above a flat terrain, e.g. {standing[:3].tolist()}"
    sites = ref.cubic_sites(lo, hi, r)
    assert_same_sites(got, ref.kept(sites, [(verts, faces, rule)], r))


@pytest.mark.parametrize("rule", ["paper", "exact"])
def test_layer_at_distance_exactly_r_is_kept(rule):
    """The rules remove a site closer than r ("<", strict).  Under a flat terrain at a whole
    metre, the lattice layer at z.5 with r = 0.5 lies at distance exactly r: every one of its
    sites must be kept (before the fix rounding removed a random part of the layer)."""
    rng = np.random.default_rng(1)
    xy = np.round(rng.uniform(-1, 11, (40, 2)), 3)
    xy = np.vstack([xy, [[-1, -1], [11, -1], [11, 11], [-1, 11]]])
    verts, faces = triangulate_plan(np.column_stack([xy, np.full(len(xy), 90.0)]))
    lo, hi = np.array([0.0, 0.0, 80.0]), np.array([10.0, 10.0, 92.0])
    got = sgim_kept("cubic", lo, hi, 0.5, [(verts, faces, rule)])
    layer = np.isclose(got[:, 2], 89.5, rtol=0, atol=1e-9)
    assert layer.sum() == 100
    assert got[:, 2].max() == 89.5
