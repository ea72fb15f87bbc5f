"""Property tests: random small scenes through the whole pipeline (scene_from_dict -> build_model)."""
from __future__ import annotations

import copy
import math

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from sgim.builder import build_model
from sgim.scene import SceneError, scene_from_dict
from sgim_check import check_model

SETTINGS = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


TRIANGLE = np.array([[-1.0, -1.0, 0.0], [1.0, -0.5, 0.3], [0.0, 1.0, -0.2]])


@st.composite
def scene_dicts(draw, rule=None):
    lo = np.array(draw(st.tuples(fl(-20, 20), fl(-20, 20), fl(-20, 20))))
    ext = np.array(draw(st.tuples(fl(2.5, 6.0), fl(2.5, 6.0), fl(2.5, 6.0))))
    hi = lo + ext
    r = draw(fl(0.25, 0.6))
    kind = draw(st.sampled_from(["cubic", "hexagonal", "fcc"]))
    excavation = []
    for _ in range(draw(st.integers(0, 2))):
        if draw(st.booleans()):
            # a height field given as points, triangulated in plan by sgim
            corners = [(-0.2, -0.2), (1.2, -0.2), (1.2, 1.2), (-0.2, 1.2), (0.5, 0.5)]
            pts = []
            for (u, v) in corners:
                du, dv = draw(fl(-0.15, 0.15)), draw(fl(-0.15, 0.15))
                z = lo[2] + ext[2] * draw(fl(0.1, 1.2))
                pts.append([lo[0] + ext[0] * (u + du), lo[1] + ext[1] * (v + dv), z])
            excavation.append({"points": pts, "rule": draw(st.sampled_from(["paper", "exact"]))})
        else:
            verts, faces = [], []
            for f in range(draw(st.integers(1, 3))):
                c = lo + ext * np.array([draw(fl(0.0, 1.0)), draw(fl(0.0, 1.0)), draw(fl(0.2, 1.0))])
                size = draw(fl(0.5, 3.0))
                steep = draw(fl(0.2, 6.0))
                jitter = np.array(draw(st.lists(fl(-0.3, 0.3), min_size=9, max_size=9))).reshape(3, 3)
                tri = c + size * (TRIANGLE + jitter) * [1.0, 1.0, steep]
                verts += tri.tolist()
                faces.append([3 * f, 3 * f + 1, 3 * f + 2])
            excavation.append({"vertices": verts, "faces": faces, "rule": draw(st.sampled_from(["paper", "exact"]))})
    discs = []
    for _ in range(draw(st.integers(0, 3))):
        t = {"centre": (lo + ext * np.array([draw(fl(0.1, 0.9)) for _ in range(3)])).tolist(),
             "radius": draw(fl(0.3, 6.0))}
        if draw(st.booleans()):
            n = [draw(fl(-1.0, 1.0)) for _ in range(3)]
            assume(math.sqrt(sum(v * v for v in n)) > 0.1)
            t["normal"] = n
        else:
            t["dip"] = draw(fl(0.0, 90.0))
            t["dip_direction"] = draw(fl(0.0, 360.0))
        t["thickness"] = draw(st.one_of(st.just(0.0), fl(0.1, 2.0)))
        discs.append(t)
    return {
        "domain": {"min": lo.tolist(), "max": hi.tolist()},
        "packing": {"kind": kind, "radius": r},
        "excavation": excavation,
        "discontinuity": discs,
        "bonds": {"rule": rule or draw(st.sampled_from(["colour", "geometric"])),
                  "tolerance": draw(fl(1e-4, 0.2))},
    }


def load(d):
    try:
        return scene_from_dict(copy.deepcopy(d), "hypothesis.toml")
    except SceneError:
        assume(False)


@settings(max_examples=35, **SETTINGS)
@given(scene_dicts())
def test_pipeline_matches_brute_force(d):
    """Kept set, membership table, colours, touching pairs and the bond rule all equal the
    independent references."""
    scene = load(d)
    m = build_model(scene)
    check_model(d, scene, m)


@settings(max_examples=35, **SETTINGS)
@given(scene_dicts())
def test_structural_invariants(d):
    scene = load(d)
    m = build_model(scene)
    n, tol = len(m.centers), scene.bonds.tolerance
    b = m.bonds
    # bonds: i < j, unique, sorted, none longer than (ri + rj)(1 + tol)
    assert b.shape == (len(m.bonded), 2)
    if len(b):
        assert np.all(b[:, 0] < b[:, 1]) and b.min() >= 0 and b.max() < n
        key = b[:, 0] * n + b[:, 1]
        assert np.all(np.diff(key) > 0)
        length = np.linalg.norm(m.centers[b[:, 1]] - m.centers[b[:, 0]], axis=1)
        assert np.all(length <= (m.radii[b[:, 0]] + m.radii[b[:, 1]]) * (1 + tol))
    # colours consistent with membership
    kinds = [set() for _ in range(n)]
    for s, k, kind in zip(m.member_sphere, m.member_disc, m.member_kind):
        kinds[s].add((int(k), int(kind)))
    for i in range(n):
        own = {kind for _, kind in kinds[i]}
        if not own:
            assert m.colour[i] == 0 and m.colour_source[i] == -1
        elif 1 in own:
            assert m.colour[i] == 1 and (int(m.colour_source[i]), 1) in kinds[i]
        else:
            assert m.colour[i] in (2, 3) and (int(m.colour_source[i]), int(m.colour[i])) in kinds[i]
    # thick discs only make red, joints only green / blue
    thick = m.disc_thickness[m.member_disc] > 0 if len(m.member_disc) else np.zeros(0, bool)
    assert np.all((m.member_kind == 1) == thick)
    # no bond with a red sphere; the colour rule never bonds green to blue
    ci, cj = m.colour[b[:, 0]], m.colour[b[:, 1]]
    assert not np.any(m.bonded & ((ci == 1) | (cj == 1)))
    if scene.bonds.rule == "colour":
        assert not np.any(m.bonded & (((ci == 2) & (cj == 3)) | ((ci == 3) & (cj == 2))))
    assert np.array_equal(m.cut_by == -1, m.bonded)


@settings(max_examples=20, **SETTINGS)
@given(scene_dicts())
def test_same_scene_same_model(d):
    a = build_model(load(d))
    b = build_model(load(d))
    for key in a.ARRAYS:
        x, y = getattr(a, key), getattr(b, key)
        assert x.dtype == y.dtype and np.array_equal(x, y), key
    assert a.disc_name == b.disc_name and a.meta == b.meta
