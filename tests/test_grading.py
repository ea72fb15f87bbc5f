"""Graded random packings (sgim/grading.py): the radius law, distances to named objects, and
graded packings checked against independent transcriptions of the definitions."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.spatial import cKDTree

from sgim.builder import build_model
from sgim.grading import Grading
from sgim.scene import SceneError, load_scene


# ---------------------------------------------------------------------------
# independent references

def law_ref(d, rf, rc, df, dc):
    """The documented law, transcribed: r = rf (rc/rf)^s, s = t^2 (3 - 2t), t = (d - df)/(dc - df) in [0, 1]."""
    out = []
    for x in np.atleast_1d(d):
        t = min(max((x - df) / (dc - df), 0.0), 1.0)
        s = t * t * (3 - 2 * t)
        out.append(rf * (rc / rf) ** s)
    return np.array(out)


def disc_dist_ref(p, c, n, R):
    """Distance from points p to the flat disc (centre c, unit normal n, radius R)."""
    w = p - c
    h = w @ n
    inplane = w - np.outer(h, n)
    rho = np.linalg.norm(inplane, axis=1)
    return np.where(rho <= R, np.abs(h), np.sqrt(h ** 2 + (rho - R) ** 2))


def dip_normal(dip, dd):
    a, b = math.radians(dip), math.radians(dd)
    return np.array([math.sin(a) * math.sin(b), math.sin(a) * math.cos(b), math.cos(a)])


# ---------------------------------------------------------------------------
# the law

def test_law_values_and_smoothness():
    g = Grading(["x"], 0.25, 2.0, 1.0, 16.0)
    d = np.linspace(-1, 20, 2001)
    assert np.allclose(g.radius(d), law_ref(d, 0.25, 2.0, 1.0, 16.0), rtol=1e-13)
    assert np.all(g.radius(d[d <= 1.0]) == 0.25) and np.all(g.radius(d[d >= 16.0]) == 2.0)
    assert np.all(np.diff(g.radius(d)) >= 0)
    # C1: the slope vanishes at both ends of the transition
    h = 1e-6
    for x in (1.0, 16.0):
        assert abs(g.radius(x + h) - g.radius(x - h)) / (2 * h) < 1e-4
    # the documented largest relative change per metre: 1.5 ln(coarse/fine) / (dc - df)
    rel = np.diff(np.log(g.radius(d))) / np.diff(d)
    assert rel.max() == pytest.approx(1.5 * math.log(8.0) / 15.0, rel=1e-3)


# ---------------------------------------------------------------------------
# a graded scene: a flat excavation surface and a thick disc (fault)

SCENE = """
[domain]
min = [0, 0, 0]
max = [16, 10, 9]
[packing]
kind = "random"
seed = 11
[packing.grading]
near = ["top", "F"]
fine_radius = 0.2
coarse_radius = 0.6
fine_distance = 0.4
coarse_distance = 3.0
{spread}
[[excavation]]
name = "top"
rule = "exact"
points = [[-1, -1, 8], [17, -1, 8], [-1, 11, 8], [17, 11, 8]]
[[discontinuity]]
name = "F"
centre = [6, 5, 3]
dip = 35
dip_direction = 110
radius = 3.0
thickness = 0.3
[bonds]
tolerance = 1e-3
[output]
formats = ["npz"]
"""


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    p = tmp_path_factory.mktemp("g") / "g.toml"
    p.write_text(SCENE.format(spread=""))
    scene = load_scene(p)
    return scene, build_model(scene)


def ref_distance(X):
    d_top = 8.0 - X[:, 2]  # the surface covers the whole plan: distance to its plane
    n = dip_normal(35, 110)
    d_f = np.maximum(disc_dist_ref(X, np.array([6.0, 5, 3]), n, 3.0) - 0.15, 0.0)
    return np.minimum(d_top, d_f)


def test_radius_follows_the_law(graded):
    scene, m = graded
    X, R = m.centers, m.radii
    assert len(X) > 2000
    assert np.all(X[:, 2] + R <= 8.0 + 1e-6)  # below the excavation surface
    expect = law_ref(ref_distance(X), 0.2, 0.6, 0.4, 3.0)
    assert np.allclose(R, expect, rtol=1e-7)
    # both ends of the law are present
    assert np.sum(R == 0.2) > 100 and np.sum(R == 0.6) > 100


def test_graded_no_overlap_and_no_large_gaps(graded):
    scene, m = graded
    X, R = m.centers, m.radii
    tree = cKDTree(X)
    pr = tree.query_pairs(2 * R.max(), output_type="ndarray")
    d = np.linalg.norm(X[pr[:, 0]] - X[pr[:, 1]], axis=1)
    ov = (R[pr[:, 0]] + R[pr[:, 1]] - d) / np.minimum(R[pr[:, 0]], R[pr[:, 1]])
    assert ov.max() <= 1e-6
    # probes: clearance (to sphere surfaces, the box and the surface) / local radius of the law < 1
    rng = np.random.default_rng(0)
    P = rng.uniform([0, 0, 0], [16, 10, 8], (100_000, 3))
    dist, idx = tree.query(P, k=24)
    clear = np.min(dist - R[idx], axis=1)
    clear = np.minimum(clear, np.min(np.concatenate([P, [16, 10, 8] - P], axis=1), axis=1))
    ok = clear > 0
    ratio = clear[ok] / law_ref(ref_distance(P[ok]), 0.2, 0.6, 0.4, 3.0)
    assert ratio.max() < 1.0
    # the build's own estimate says the same
    les = m.meta["packing"]["statistics"]["largest_empty_sphere"]
    assert les["relative_max"] < 1.0 + 1e-6
    assert ratio.max() <= les["relative_max"] + 0.05


def test_graded_spread(tmp_path):
    p = tmp_path / "g.toml"
    p.write_text(SCENE.format(spread="spread = 0.1").replace("max = [16, 10, 9]", "max = [10, 8, 9]"))
    m = build_model(load_scene(p))
    X, R = m.centers, m.radii
    f = R / law_ref(ref_distance(X), 0.2, 0.6, 0.4, 3.0)
    assert f.min() >= 0.9 - 1e-9 and f.max() <= 1.1 + 1e-9
    assert stats.kstest(f, "uniform", args=(0.9, 0.2)).pvalue > 0.001


def test_near_distance_against_analytic():
    from sgim.grading import NearObjects

    class S:  # a minimal scene: one excavation rectangle and one disc
        pass

    class Surf:
        name = "sq"
        vertices = np.array([[0.0, 0, 1], [4, 0, 1], [0, 4, 1], [4, 4, 1]])
        faces = np.array([[0, 1, 2], [1, 3, 2]])

    class D:
        name = "d"
        centre = np.array([8.0, 2, 2])
        normal = dip_normal(50, 30)
        radius = 1.5
        thickness = 0.0

    sc = S()
    sc.excavations, sc.cavities, sc.surfaces, sc.discontinuities = [Surf()], [], [], [D()]
    near = NearObjects(sc, Grading(["sq", "d"], 0.1, 0.2, 0.0, 1.0))
    rng = np.random.default_rng(1)
    P = rng.uniform([-2, -2, -2], [11, 6, 5], (5000, 3))
    # rectangle [0,4]^2 at z = 1: distance to the clamped projection
    q = np.column_stack([np.clip(P[:, 0], 0, 4), np.clip(P[:, 1], 0, 4), np.ones(len(P))])
    d_sq = np.linalg.norm(P - q, axis=1)
    d_d = disc_dist_ref(P, D.centre, D.normal, 1.5)
    ref = np.minimum(d_sq, d_d)
    got = near.distance(P, 100.0)
    assert np.allclose(got, ref, atol=1e-9)
    capped = near.distance(P, 2.0)
    assert np.allclose(capped, np.minimum(ref, 2.0), atol=1e-9)


# ---------------------------------------------------------------------------
# bad input

BAD = [
    ("near-empty", 'near = []\nfine_radius = 0.2\ncoarse_radius = 0.6\ncoarse_distance = 3.0', "packing.grading.near"),
    ("near-number", 'near = [3]\nfine_radius = 0.2\ncoarse_radius = 0.6\ncoarse_distance = 3.0', "packing.grading.near"),
    ("ratio", 'near = ["top"]\nfine_radius = 0.01\ncoarse_radius = 0.9\ncoarse_distance = 3.0',
     "packing.grading.coarse_radius"),
    ("spread", 'near = ["top"]\nfine_radius = 0.2\ncoarse_radius = 0.6\ncoarse_distance = 3.0\nspread = 0.7',
     "packing.grading.spread"),
    ("missing", 'near = ["top"]\nfine_radius = 0.2\ncoarse_radius = 0.6', "packing.grading.coarse_distance"),
    ("negative-fine", 'near = ["top"]\nfine_radius = -0.2\ncoarse_radius = 0.6\ncoarse_distance = 3.0',
     "packing.grading.fine_radius"),
    ("cavity-name", 'near = ["T9"]\nfine_radius = 0.2\ncoarse_radius = 0.6\ncoarse_distance = 3.0',
     "packing.grading.near"),
]


@pytest.mark.parametrize("name,table,key", BAD, ids=[b[0] for b in BAD])
def test_bad_grading(tmp_path, name, table, key):
    text = SCENE.format(spread="")
    i = text.index("[packing.grading]")
    j = text.index("[[excavation]]")
    text = text[:i] + "[packing.grading]\n" + table + "\n" + text[j:]
    p = tmp_path / "b.toml"
    p.write_text(text)
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert e.value.key == key
