"""Random dense packing (sgim/rpack.py, sgim/_rpack.py) against brute-force references.

Every check here recomputes what it checks from the definition with plain NumPy / SciPy
(O(n^2) distances, analytic shapes, Delaunay circumspheres), never from sgim's own kernels.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.spatial import Delaunay, cKDTree

from sgim.rpack import RadiusLaw, RandomSpec, Region, contact_pairs, largest_empty_sphere, pack_region, \
    pack_statistics
from sgim.scene import SceneError, load_scene

ROOT = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------------------
# independent references

def brute_pairs(X, R, tol):
    """All pairs i < j with |ci - cj| <= (ri + rj)(1 + tol), by the O(n^2) definition."""
    out = []
    for i in range(len(X) - 1):
        d = np.sqrt(((X[i + 1:] - X[i]) ** 2).sum(1))
        j = np.nonzero(d <= (R[i] + R[i + 1:]) * (1 + tol))[0] + i + 1
        out.extend((i, int(k)) for k in j)
    return np.array(out, np.int64).reshape(-1, 2)


def brute_max_overlap(X, R):
    """max over pairs of (ri + rj - d) / min(ri, rj), by the O(n^2) definition (0 when none)."""
    best = 0.0
    for i in range(len(X) - 1):
        d = np.sqrt(((X[i + 1:] - X[i]) ** 2).sum(1))
        ov = (R[i] + R[i + 1:] - d) / np.minimum(R[i], R[i + 1:])
        if len(ov):
            best = max(best, float(ov.max()))
    return best


def box_pack(L, law, seed=1, lo=0.0):
    reg = Region(np.full(3, lo), np.full(3, lo + L))
    res = pack_region(reg, RandomSpec(seed=seed, law=law))
    return reg, res.centres, res.radii


CONST = RadiusLaw("constant", {"radius": 1.0})


@pytest.fixture(scope="module")
def equal_box():
    return box_pack(16.0, CONST)


@pytest.fixture(scope="module")
def ratio2_box():
    return box_pack(24.0, RadiusLaw("uniform", {"min": 1.0, "max": 2.0}), seed=5)


# ---------------------------------------------------------------------------
# equal spheres in a box

def test_equal_box_no_overlap_inside_and_touching(equal_box):
    reg, X, R = equal_box
    L = 16.0
    assert len(X) > 300
    assert brute_max_overlap(X, R) <= 1e-6  # the default tolerance
    # every sphere inside the box (brute force)
    assert np.all(X - R[:, None] >= -1e-6 * R[:, None])
    assert np.all(X + R[:, None] <= L + 1e-6 * R[:, None])
    # spheres rest on the floor and touch the four side walls; the packing reaches the ceiling within r
    for a in range(3):
        assert np.sum(np.abs(X[:, a] - R) < 1e-9) > 5
    for a in range(2):
        assert np.sum(np.abs(L - X[:, a] - R) < 1e-9) > 5
    ext = (X + R[:, None]).max(0)
    assert np.all(L - ext < 1.0)


def test_statistics_match_brute_force(equal_box):
    reg, X, R = equal_box
    st = pack_statistics(X, R, reg, reg.volume(), 1e-3, les=False)
    assert st["density"] == pytest.approx(np.sum(4 / 3 * np.pi * R ** 3) / 16.0 ** 3, rel=1e-12)
    ref = brute_pairs(X, R, 1e-3)
    assert st["contacts"] == len(ref)
    assert st["coordination"] == pytest.approx(2 * len(ref) / len(X))
    assert st["max_overlap"] == pytest.approx(max(brute_max_overlap(X, R), 0.0), abs=1e-12)
    # a pocket-filled packing: every sphere rests on supports, coordination near 6
    assert 5.0 < st["coordination"] < 7.0


def test_same_seed_same_packing_and_other_seed_differs():
    _, X1, R1 = box_pack(9.0, CONST, seed=7)
    _, X2, R2 = box_pack(9.0, CONST, seed=7)
    _, X3, _ = box_pack(9.0, CONST, seed=8)
    assert np.array_equal(X1, X2) and np.array_equal(R1, R2)
    assert len(X3) != len(X1) or not np.allclose(X3, X1)


def test_tolerance_near_rounding_keeps_pockets():
    """An overlap tolerance near the rounding error (1e-12): no overlap beyond it (brute force), and
    the pockets that touch their supports exactly are still made: about as many spheres as at 1e-6."""
    reg = Region(np.zeros(3), np.full(3, 10.0))
    tiny = pack_region(reg, RandomSpec(seed=4, law=CONST, overlap=1e-12))
    ref = pack_region(reg, RandomSpec(seed=4, law=CONST))
    assert brute_max_overlap(tiny.centres, tiny.radii) <= 1e-12
    assert len(tiny.radii) >= 0.97 * len(ref.radii)


def test_density_of_a_larger_box_bulk():
    """Bulk density (centres in the inner box) of equal spheres: random close-ish, well above 0.58."""
    reg, X, R = box_pack(30.0, CONST, seed=2)
    a = 4.0
    inner = np.all((X > a) & (X < 30.0 - a), axis=1)
    phi_in = inner.sum() * 4 / 3 * np.pi / (30.0 - 2 * a) ** 3
    assert 0.59 < phi_in < 0.64
    # no crystal: the global bond-orientational order Q6 of contacts is small (FCC 0.57, HCP 0.48)
    pr = cKDTree(X[inner]).query_pairs(2.0 * (1 + 1e-6), output_type="ndarray")
    v = X[inner][pr[:, 1]] - X[inner][pr[:, 0]]
    v /= np.linalg.norm(v, axis=1)[:, None]
    from scipy.special import sph_harm_y

    th = np.arccos(np.clip(v[:, 2], -1, 1))
    ph = np.arctan2(v[:, 1], v[:, 0])
    q = [abs(np.mean(sph_harm_y(6, m, th, ph))) ** 2 for m in range(-6, 7)]
    Q6 = math.sqrt(4 * math.pi / 13 * sum(q))
    assert Q6 < 0.1


# ---------------------------------------------------------------------------
# zones: a constant radius in a wide region is packed by two threads (sgim/rpack.py, _zones)

def slab_density(X, R, lo, hi, axis, edges, margin):
    """Solid fraction of slabs [edges[k], edges[k+1]] across axis, centres at least margin from the
    other walls, by the exact volume of each sphere between two planes (spherical caps)."""
    other = [a for a in range(3) if a != axis]
    keep = np.all((X[:, other] > lo[other] + margin) & (X[:, other] < hi[other] - margin), axis=1)
    x, r = X[keep, axis], R[keep]

    def below(h):  # volume of each sphere below the plane at h
        t = np.clip(h - (x - r), 0.0, 2.0 * r)
        return np.pi * t * t * (3.0 * r - t) / 3.0

    area = np.prod(hi[other] - lo[other] - 2.0 * margin)
    return np.array([(below(b) - below(a)).sum() / ((b - a) * area) for a, b in zip(edges[:-1], edges[1:])])


@pytest.fixture(scope="module")
def zoned_box():
    reg = Region(np.zeros(3), np.array([64.0, 12.0, 12.0]))
    spec = RandomSpec(seed=3, law=RadiusLaw("constant", {"radius": 0.5}))
    return reg, spec, pack_region(reg, spec), pack_region(reg, spec, parallel=False)


def test_zones_no_overlap_inside_and_as_dense_as_one_zone(zoned_box):
    reg, spec, zoned, one = zoned_box
    X, R = zoned.centres, zoned.radii
    assert zoned.stats["counters"]["zones"] == 4 and one.stats["counters"]["zones"] == 1
    assert brute_max_overlap(X, R) <= 1e-6
    assert np.all(X - R[:, None] >= reg.lo - 1e-6 * R[:, None])
    assert np.all(X + R[:, None] <= reg.hi + 1e-6 * R[:, None])
    for a in range(3):  # spheres touch the floor and the side walls
        assert np.sum(np.abs(X[:, a] - R) < 1e-9) > 20
    assert abs(len(R) - len(one.radii)) < 0.003 * len(one.radii)
    # slabs 2 m wide across the cut (x = 32; the strip is x in [28, 36]): no seam at the strip's
    # edges or the cut, each slab within 0.02 of the one-zone packing's mean over the same slabs
    edges = np.arange(4.0, 60.0 + 1e-9, 2.0)
    dz = slab_density(X, R, reg.lo, reg.hi, 0, edges, 2.0)
    d1 = slab_density(one.centres, one.radii, reg.lo, reg.hi, 0, edges, 2.0)
    assert np.all(np.abs(dz - d1.mean()) < 0.02), dz
    assert abs(dz.mean() - d1.mean()) < 0.004


def test_zones_do_not_depend_on_threads(zoned_box, monkeypatch):
    """The zones A and B are filled in one thread, one after the other: the same packing."""
    import sgim.rpack as P

    class Inline:
        def __init__(self, n):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def submit(self, fn, *args):
            class Done:
                def __init__(self, v):
                    self.v = v

                def result(self):
                    return self.v
            return Done(fn(*args))

    reg, spec, zoned, _ = zoned_box
    monkeypatch.setattr(P, "ThreadPoolExecutor", Inline)
    again = pack_region(reg, spec)
    assert np.array_equal(again.centres, zoned.centres) and np.array_equal(again.radii, zoned.radii)


@pytest.mark.parametrize("short", ["spheres", "pockets"])
def test_zone_out_of_room_packs_in_one_zone(zoned_box, monkeypatch, short):
    import sgim.rpack as P

    reg, spec, _, one = zoned_box
    real = P._zones

    def small(*a):  # room for the seeds, not for the packing
        ZG, zcap, zccap = real(*a)
        if short == "spheres":
            return ZG, np.full(4, 500, np.int64), zccap
        return ZG, zcap, np.full(4, 300, np.int64)

    monkeypatch.setattr(P, "_zones", small)
    res = pack_region(reg, spec)
    assert res.stats["counters"]["zones"] == 1
    assert np.array_equal(res.centres, one.centres)


def test_zones_only_where_they_apply():
    """A radius law, or a region narrower than six strip half widths: one zone."""
    reg = Region(np.zeros(3), np.array([64.0, 12.0, 8.0]))
    law = pack_region(reg, RandomSpec(seed=1, law=RadiusLaw("uniform", {"min": 0.4, "max": 0.6})))
    assert law.stats["counters"]["zones"] == 1
    narrow = pack_region(Region(np.zeros(3), np.array([22.0, 12.0, 8.0])),
                         RandomSpec(seed=1, law=RadiusLaw("constant", {"radius": 0.5})))
    assert narrow.stats["counters"]["zones"] == 1


def test_largest_empty_sphere_matches_delaunay(equal_box):
    """Equal spheres: the largest hole away from the walls is at the Delaunay circumcentre with the
    largest circumradius; its radius is that circumradius minus r."""
    reg, X, R = equal_box
    tri = Delaunay(X)
    P = X[tri.simplices]
    A = 2 * (P[:, 1:] - P[:, :1])
    b = (P[:, 1:] ** 2).sum(-1) - (P[:, :1] ** 2).sum(-1)
    ok = np.abs(np.linalg.det(A)) > 1e-9
    cc = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
    rho = np.linalg.norm(cc - P[ok][:, 0], axis=1) - 1.0
    # in the sub-box [m, 16 - m]: circumspheres centred 1 or more inside it are empty spheres of the
    # sub-box (rho < 1), so the largest of them is a lower bound; the largest circumsphere of all is
    # an upper bound (the clearance peaks at Voronoi vertices)
    m = 3.5
    inner = np.all((cc > m + 1) & (cc < 16.0 - m - 1), axis=1)
    ref_lo = float(rho[inner].max())
    ref_hi = float(rho[np.all((cc > m) & (cc < 16.0 - m), axis=1)].max())
    sub = Region(np.full(3, m), np.full(3, 16.0 - m))
    got = largest_empty_sphere(X, R, sub)
    assert ref_lo * (1 - 1e-4) <= got["radius"] <= ref_hi + 1e-9
    if got["radius"] > ref_lo * (1 + 1e-4):  # then it must be a hole near the sub-box walls
        assert min(np.min(np.array(got["centre"]) - m), np.min(16.0 - m - np.array(got["centre"]))) < 1.0
    # and in the whole box no hole fits a sphere of the packing's radius
    whole = largest_empty_sphere(X, R, reg)
    assert ref_lo - 1e-9 <= whole["radius"] < 1.0


# ---------------------------------------------------------------------------
# unequal spheres

def test_ratio2_no_overlap_law_and_density(ratio2_box):
    reg, X, R = ratio2_box
    assert brute_max_overlap(X, R) <= 1e-6
    assert np.all(X - R[:, None] >= -1e-6) and np.all(X + R[:, None] <= 24.0 + 1e-6)
    # the radius law is uniform on [1, 2] (Kolmogorov-Smirnov)
    assert stats.kstest(R, "uniform", args=(1.0, 1.0)).pvalue > 0.01
    # bulk solid fraction: share of grid points of the inner box [4, 20]^3 covered by a sphere
    g = np.linspace(4.0, 20.0, 64)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    d, j = cKDTree(X).query(P, k=8)
    covered = np.any(d < R[j], axis=1)
    assert covered.mean() > 0.6


def test_contact_pairs_equal_brute_force_for_unequal_radii(ratio2_box):
    """The [bonds] tolerance for unequal radii: contact when |ci - cj| <= (ri + rj)(1 + tol)."""
    reg, X, R = ratio2_box
    for tol in (1e-9, 1e-3, 0.05):  # pocket-filled spheres touch exactly: tol 0 would be decided by rounding
        got, off = contact_pairs(X, R, tol)
        ref = brute_pairs(X, R, tol)
        assert np.array_equal(got, ref)  # same pairs, same order (i ascending, then j)
        assert np.array_equal(off, np.searchsorted(got[:, 0], np.arange(len(X) + 1))) if len(got) else True


def test_touching_pairs_branch_for_wide_radius_range():
    """sgim/cutting.py hands unequal radii (ratio > 2) to the multi-level grid: same pairs as brute force."""
    from sgim.cutting import SphereGrid, touching_pairs

    rng = np.random.default_rng(4)
    X = rng.uniform(0, 12, (600, 3))
    R = rng.uniform(0.2, 1.6, 600)  # overlapping on purpose: the pair rule is geometric
    grid = SphereGrid.build(X, 2 * R.max() * 1.01)
    got, off = touching_pairs(X, R, grid, 0.01)
    assert np.array_equal(got, brute_pairs(X, R, 0.01))


def test_build_bonds_for_unequal_radii(tmp_path):
    """sgim build on a random packing: the bond list is every pair with |ci - cj| <= (ri + rj)(1 + tol)."""
    from sgim.builder import build_model

    (tmp_path / "s.toml").write_text("""
[domain]
min = [0, 0, 0]
max = [9, 8, 7]
[packing]
kind = "random"
seed = 9
[packing.distribution]
law = "uniform"
min = 0.3
max = 0.6
[bonds]
tolerance = 0.02
[output]
formats = ["npz"]
""")
    m = build_model(load_scene(tmp_path / "s.toml"))
    assert np.array_equal(m.bonds, brute_pairs(m.centers, m.radii, 0.02))
    st = m.meta["packing"]["statistics"]
    assert st["contacts"] == len(m.bonds) and st["contact_gap"] == 0.02


def test_lognormal_law_recovered():
    law = RadiusLaw("lognormal", {"median": 0.5, "sigma": 0.2})
    reg = Region(np.zeros(3), np.full(3, 14.0))
    R = pack_region(reg, RandomSpec(seed=2, law=law)).radii
    ln = np.log(R)
    n = len(R)
    assert n > 1500
    # maximum-likelihood estimates of the lognormal's parameters, within 4 standard errors
    assert abs(ln.mean() - math.log(0.5)) < 4 * 0.2 / math.sqrt(n)
    assert abs(ln.std(ddof=1) - 0.2) < 4 * 0.2 / math.sqrt(2 * n)


def test_truncated_lognormal_sampler():
    law = RadiusLaw("lognormal", {"median": 1.0, "sigma": 0.5, "min": 0.7, "max": 1.6})
    r = law.sample(np.random.default_rng(0), 100_000)
    assert r.min() >= 0.7 and r.max() <= 1.6
    # truncated normal of ln r: compare with scipy's truncnorm (an independent implementation)
    a, b = math.log(0.7) / 0.5, math.log(1.6) / 0.5
    assert stats.kstest(np.log(r) / 0.5, stats.truncnorm(a, b).cdf).pvalue > 0.01


def test_sieve_curve_recovered():
    sizes = [0.5, 1.0, 2.0, 3.0]
    passing = [0.0, 20.0, 70.0, 100.0]
    law = RadiusLaw("sieve", {"sizes": sizes, "passing": passing})
    d = 2 * law.sample(np.random.default_rng(1), 400_000)
    mass = d ** 3
    for s, p in zip(sizes, passing):
        assert 100 * mass[d <= s].sum() / mass.sum() == pytest.approx(p, abs=0.5)
    # and in a packing (mass fractions by sphere volume)
    reg = Region(np.zeros(3), np.full(3, 16.0))
    R = pack_region(reg, RandomSpec(seed=3, law=law)).radii
    m = R ** 3
    for s, p in zip(sizes, passing):
        assert 100 * m[2 * R <= s + 1e-12].sum() / m.sum() == pytest.approx(p, abs=5.0)


# ---------------------------------------------------------------------------
# regions: fill shape, excavation, cavity (scene files)

def test_core_sample_case():
    """cases/scenes/core_sample.toml: a sieve-curve packing fills the closed cylinder of
    cases/scenes/meshes/core_sample.obj to its surface, and the joint colours the spheres within 2 r."""
    from sgim.builder import build_model
    from sgim.scene import dip_to_normal

    scene = load_scene(ROOT / "cases" / "scenes" / "core_sample.toml")
    m = build_model(scene)
    X, R, C = m.centers, m.radii, m.colour
    rc, h = 0.027, 0.135
    assert len(R) > 10_000
    assert brute_max_overlap(X, R) <= 1e-6
    # inside the cylinder (the faceted surface lies inside the circle), touching it: the packing's
    # bounding box is the cylinder's within one radius
    assert np.all(np.hypot(X[:, 0], X[:, 1]) + R <= rc * (1 + 1e-9))
    assert np.all(X[:, 2] - R >= -1e-6 * R) and np.all(X[:, 2] + R <= h + 1e-6 * R)
    lo, hi = (X - R[:, None]).min(0), (X + R[:, None]).max(0)
    assert np.all(np.abs(lo - [-rc, -rc, 0.0]) < R.max()) and np.all(np.abs(hi - [rc, rc, h]) < R.max())
    # the sieve curve (percent passing by mass at each size)
    mass = R ** 3
    for size, p in zip([0.002, 0.0025, 0.00315, 0.004], [0.0, 25.0, 65.0, 100.0]):
        assert 100 * mass[2 * R <= size * (1 + 1e-12)].sum() / mass.sum() == pytest.approx(p, abs=5.0)
    # the joint (a disc wider than the core): green and blue are the spheres within 2 r of its
    # plane, one colour on each side
    d = (X - [0.0, 0.0, 0.0675]) @ dip_to_normal(60.0, 90.0)
    assert np.array_equal(C >= 2, np.abs(d) <= 2 * R)
    sides = {int(np.sign(d[C == k]).min() * np.sign(d[C == k]).max()) for k in (2, 3)}
    assert sides == {1} and np.sign(d[C == 2][0]) != np.sign(d[C == 3][0])
    st = m.meta["packing"]["statistics"]
    assert 0.58 < st["density"] < 0.66 and 5.0 < st["coordination"] < 7.0


def _ellipsoid_stl(path, c, ax, seg=40):
    from sgim import shapes
    import meshio

    v, f = shapes.ellipsoid(np.array(c, float), np.array(ax, float), seg)
    meshio.write(str(path), meshio.Mesh(v, [("triangle", f)]))
    return v


def test_fill_shape_scene(tmp_path):
    v = _ellipsoid_stl(tmp_path / "egg.stl", (5.0, 5.0, 4.0), (4.0, 3.0, 2.5))
    (tmp_path / "s.toml").write_text("""
[domain]
min = [0, 0, 0]
max = [10, 10, 8]
[packing]
kind = "random"
radius = 0.3
seed = 4
fill = "egg.stl"
[output]
formats = ["npz"]
""")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "sgim.cli", "build", str(tmp_path / "s.toml"), "-o", str(out), "--quiet"],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    z = np.load(out / "model.npz")
    X, R = z["centers"], z["radii"]
    # inside the analytic ellipsoid (which contains the inscribed triangulation), by a margin of r:
    # sample the sphere surface of each sphere and test every sample point
    dirs = np.random.default_rng(0).normal(size=(64, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    pts = X[:, None, :] + R[:, None, None] * dirs[None]
    q = (((pts - [5.0, 5.0, 4.0]) / [4.0, 3.0, 2.5]) ** 2).sum(-1)
    assert np.all(q <= 1.0 + 1e-9)
    # no shrinking: the packing's bounding box matches the surface's within one radius
    lo_s, hi_s = v.min(0), v.max(0)
    lo_p, hi_p = (X - R[:, None]).min(0), (X + R[:, None]).max(0)
    assert np.all(lo_p - lo_s < 0.3) and np.all(hi_s - hi_p < 0.3)
    meta = json.loads(str(z["meta"]))["packing"]
    assert meta["statistics"]["max_overlap"] <= 1e-6
    vol = 4 / 3 * np.pi * 4.0 * 3.0 * 2.5
    assert meta["statistics"]["region_volume"] == pytest.approx(vol, rel=0.02)


@pytest.mark.parametrize("radii,zones", [('[packing.distribution]\nlaw = "uniform"\nmin = 0.3\nmax = 0.45', 1),
                                          ("radius = 0.3", 4)], ids=["law", "zones"])
def test_excavation_and_cavity_scene(tmp_path, radii, zones):
    """Excavation surface (exact rule) and a circular tunnel: every sphere is admissible by brute force
    (a radius law in one zone; a constant radius in zones, the surfaces crossing the strip)."""
    sys.path.insert(0, str(Path(__file__).parent))
    from sgim_ref import removed_mask

    (tmp_path / "s.toml").write_text("""
[domain]
min = [0, 0, 0]
max = [16, 10, 12]
[packing]
kind = "random"
seed = 2
""" + radii + """
[[excavation]]
name = "face"
rule = "exact"
points = [[-1, -1, 10], [-1, 11, 10], [6, -1, 10], [6, 11, 10], [10, -1, 5], [10, 11, 5], [17, -1, 5], [17, 11, 5]]
[[cavity]]
name = "T"
shape = "circular_tunnel"
path = [[-1, 5, 3], [17, 5, 3]]
radius = 1.5
segments = 32
[output]
formats = ["npz"]
""")
    from sgim.builder import build_model

    scene = load_scene(tmp_path / "s.toml")
    model = build_model(scene)
    X, R = model.centers, model.radii
    assert len(X) > 1000
    assert model.meta["packing"]["counters"]["zones"] == zones
    sc = scene.excavations[0]
    # the exact rule with each sphere's own radius (less the overlap tolerance 1e-6 r)
    assert not removed_mask(X, [(sc.vertices, sc.faces, "exact")], R * (1 - 2e-6)).any()
    # tunnel: distance to the axis (y = 5, z = 3) at least the polygon's inradius plus r
    rho = np.hypot(X[:, 1] - 5.0, X[:, 2] - 3.0)
    assert np.all(rho >= 1.5 * math.cos(math.pi / 32) + R - 1e-6)
    # spheres reach the surfaces: some touch the tunnel and the excavation face
    assert np.sum(rho - R < 1.5 + 1e-3) > 10
    assert brute_max_overlap(X, R) <= 1e-6


# ---------------------------------------------------------------------------
# bad input: one clear line, exit 2, no output

BASE = """
[domain]
min = [0, 0, 0]
max = [10, 10, 10]
[packing]
kind = "random"
{packing}
[[excavation]]
name = "top"
points = [[-1, -1, 8], [11, -1, 8], [-1, 11, 8], [11, 11, 9]]
"""

BAD = [
    ("inverted", '[packing.distribution]\nlaw = "uniform"\nmin = 1.0\nmax = 0.5', "packing.distribution.max"),
    ("negative", 'radius = -0.5', "packing.radius"),
    ("negative-min", '[packing.distribution]\nlaw = "uniform"\nmin = -1.0\nmax = 0.5', "packing.distribution.min"),
    ("unknown-law", '[packing.distribution]\nlaw = "gamma"\nmin = 1.0', "packing.distribution.law"),
    ("sieve-not-monotone", '[packing.distribution]\nlaw = "sieve"\nsizes = [0.5, 1.0, 2.0]\npassing = [0, 60, 40]',
     "packing.distribution.passing[2]"),
    ("sieve-sizes", '[packing.distribution]\nlaw = "sieve"\nsizes = [0.5, 0.4, 2.0]\npassing = [0, 60, 100]',
     "packing.distribution.sizes[1]"),
    ("sieve-end", '[packing.distribution]\nlaw = "sieve"\nsizes = [0.5, 1.0]\npassing = [0, 90]',
     "packing.distribution.passing[1]"),
    ("both", 'radius = 0.5\n[packing.distribution]\nlaw = "uniform"\nmin = 0.5\nmax = 1.0', "packing"),
    ("grading-name", '[packing.grading]\nnear = ["nope"]\nfine_radius = 0.2\ncoarse_radius = 0.8\n'
                     'coarse_distance = 3.0', "packing.grading.near"),
    ("grading-inverted", '[packing.grading]\nnear = ["top"]\nfine_radius = 0.8\ncoarse_radius = 0.2\n'
                         'coarse_distance = 3.0', "packing.grading.coarse_radius"),
    ("grading-distances", '[packing.grading]\nnear = ["top"]\nfine_radius = 0.2\ncoarse_radius = 0.8\n'
                          'fine_distance = 4.0\ncoarse_distance = 3.0', "packing.grading.coarse_distance"),
    ("seed", 'radius = 0.5\nseed = -3', "packing.seed"),
    ("overlap", 'radius = 0.5\noverlap = 0.5', "packing.overlap"),
    ("unknown-key", 'radius = 0.5\nfoo = 1', "packing.foo"),
    ("fill-missing", 'radius = 0.5\nfill = "nothere.stl"', "packing.fill"),
]


@pytest.mark.parametrize("name,packing,key", BAD, ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, name, packing, key):
    p = tmp_path / "bad.toml"
    p.write_text(BASE.format(packing=packing))
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert e.value.key == key
    assert "\n" not in str(e.value)


def test_open_fill_surface_refused(tmp_path):
    import meshio

    v = np.array([[1.0, 1, 1], [9, 1, 1], [1, 9, 1], [1, 1, 9]])
    meshio.write(str(tmp_path / "open.stl"), meshio.Mesh(v, [("triangle", np.array([[0, 1, 2], [0, 1, 3]]))]))
    p = tmp_path / "bad.toml"
    p.write_text(BASE.format(packing='radius = 0.5\nfill = "open.stl"'))
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert e.value.key == "packing.fill" and "not closed" in e.value.message


def test_cli_bad_input_leaves_nothing(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(BASE.format(packing='[packing.distribution]\nlaw = "uniform"\nmin = 1.0\nmax = 0.5'))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "sgim.cli", "build", str(p), "-o", str(out)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "packing.distribution.max" in r.stderr
    assert not out.exists() and not any(tmp_path.glob(".out*"))
