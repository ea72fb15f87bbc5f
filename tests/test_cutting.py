"""Colours, membership and bonds (paper eq. 13-16) against independent brute force.

Scenes are built with sgim.scene.scene_from_dict and run through sgim.builder.build_model;
the references in tests/sgim_ref.py recompute everything from the scene dictionaries.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import sgim_ref as ref
import sgim_scenes as gen
from sgim.scene import scene_from_dict
from sgim_check import build, check_model, reference_sites


# ---------------------------------------------------------------------------
# random scenes

def populated_scene(seed, rule):
    """A random scene whose reference model keeps at least 15% of the lattice."""
    rng = np.random.default_rng(seed)
    while True:
        d = gen.random_scene_dict(rng, rule=rule, ndiscs=int(rng.integers(1, 5)))
        scene = scene_from_dict(copy.deepcopy(d), "random.toml")
        if len(reference_sites(scene)) >= 0.15 * scene.n_lattice_sites:
            return d


@pytest.mark.parametrize("rule", ["colour", "geometric"])
@pytest.mark.parametrize("seed", range(20))
def test_random_scene_against_brute_force(seed, rule):
    d = populated_scene(5000 + seed, rule)
    scene, m = build(d)
    check_model(d, scene, m)


def test_random_scenes_exercise_every_colour_and_rule():
    """The random scenes above do produce red, green and blue spheres and cut bonds."""
    seen = np.zeros(4, int)
    cut = 0
    for seed in range(20):
        _, m = build(populated_scene(5000 + seed, "colour"))
        seen += np.bincount(m.colour, minlength=4)
        cut += int((~m.bonded).sum())
    assert np.all(seen > 0) and cut > 0, (seen, cut)


# ---------------------------------------------------------------------------
# hand-made scenes with a closed-form answer

def box_scene(discs, rule="colour", tol=1e-3, kind="cubic"):
    return {"domain": {"min": [0.0, 0.0, 0.0], "max": [6.0, 5.0, 7.0]},
            "packing": {"kind": kind, "radius": 0.5}, "discontinuity": discs,
            "bonds": {"rule": rule, "tolerance": tol}}


@pytest.mark.parametrize("rule", ["colour", "geometric"])
def test_horizontal_joint_closed_form(rule):
    c = 3.3  # joint plane z = 3.3 through the whole box; layers at z = 0.5, 1.5, ...
    d = box_scene([{"centre": [3.0, 2.5, c], "normal": [0, 0, 1], "radius": 50.0}], rule)
    scene, m = build(d)
    z = m.centers[:, 2]
    want = np.where((z >= c - 1.0) & (z <= c), 2, np.where((z > c) & (z <= c + 1.0), 3, 0))
    assert np.array_equal(m.colour, want)  # green below (S.(M-O) >= 0), blue above
    zi, zj = z[m.bonds[:, 0]], z[m.bonds[:, 1]]
    crossing = (np.minimum(zi, zj) < c) & (np.maximum(zi, zj) > c)
    assert crossing.sum() == 6 * 5
    assert np.array_equal(m.bonded, ~crossing)
    assert np.all(m.cut_by[crossing] == 0)
    check_model(d, scene, m)


def test_fault_is_red_and_cuts_every_bond_of_its_spheres():
    d = box_scene([{"centre": [3.1, 2.4, 3.6], "dip": 60.0, "dip_direction": 110.0, "radius": 50.0,
                    "thickness": 1.3}])
    scene, m = build(d)
    S = ref.dip_normal(60.0, 110.0)
    dist = np.abs((m.centers - [3.1, 2.4, 3.6]) @ S)
    assert np.array_equal(m.colour == 1, dist <= 0.65)
    assert (m.colour == 1).sum() > 10 and not np.isin(m.colour, [2, 3]).any()
    red_bond = (m.colour[m.bonds[:, 0]] == 1) | (m.colour[m.bonds[:, 1]] == 1)
    assert np.array_equal(m.bonded, ~red_bond)
    check_model(d, scene, m)


def test_disc_radius_limits_the_colours():
    R = 1.7
    M = np.array([3.0, 2.5, 3.3])
    d = box_scene([{"centre": M.tolist(), "normal": [0, 0, 1], "radius": R}])
    scene, m = build(d)
    inplane = np.hypot(m.centers[:, 0] - M[0], m.centers[:, 1] - M[1])
    coloured = m.colour != 0
    assert coloured.any()
    assert np.all(inplane[coloured] <= R)
    near = (np.abs(m.centers[:, 2] - M[2]) <= 1.0) & (inplane <= R)
    assert np.array_equal(coloured, near)
    check_model(d, scene, m)


def test_red_wins_over_a_nearer_joint():
    joint = {"centre": [3.0, 2.5, 3.5], "normal": [0, 0, 1], "radius": 50.0}  # through layer z = 3.5
    fault = {"centre": [3.0, 2.5, 3.0], "normal": [0, 0, 1], "radius": 50.0, "thickness": 1.2}
    for order in ([joint, fault], [fault, joint]):
        d = box_scene(order)
        scene, m = build(d)
        layer = m.centers[:, 2] == 3.5
        assert np.all(m.colour[layer] == 1)
        assert np.all(m.colour_source[layer] == order.index(fault))
        check_model(d, scene, m)


def test_equal_distance_tie_goes_to_the_lower_disc_index():
    # sphere layer z = 3.5 lies 0.25 below one joint and 0.25 above the other
    upper = {"centre": [3.0, 2.5, 3.75], "normal": [0, 0, 1], "radius": 50.0}
    lower = {"centre": [3.0, 2.5, 3.25], "normal": [0, 0, 1], "radius": 50.0}
    for order, colour in (([upper, lower], 2), ([lower, upper], 3)):
        d = box_scene(order)
        scene, m = build(d)
        layer = m.centers[:, 2] == 3.5
        assert np.all(m.colour[layer] == colour)
        assert np.all(m.colour_source[layer] == 0)
        check_model(d, scene, m)


def test_geometric_rule_cuts_only_where_the_disc_reaches():
    """A small inclined joint: the colour rule cuts green-blue pairs of its band, the geometric
    rule only the contacts whose segment passes through the disc."""
    disc = {"centre": [3.05, 2.45, 3.37], "normal": [0.2, -0.1, 1.0], "radius": 1.4}
    out = {}
    for rule in ("colour", "geometric"):
        d = box_scene([disc], rule)
        scene, m = build(d)
        check_model(d, scene, m)
        out[rule] = m
    a, b = out["colour"], out["geometric"]
    assert np.array_equal(a.bonds, b.bonds)
    assert (~b.bonded).sum() > 0
    mid = 0.5 * (b.centers[b.bonds[:, 0]] + b.centers[b.bonds[:, 1]])
    M = np.array(disc["centre"])
    assert np.all(np.linalg.norm(mid[~b.bonded] - M, axis=1) <= 1.4 + 1.0)


@pytest.mark.parametrize("kind", ["hexagonal", "fcc"])
def test_close_packed_bonds_and_colours(kind):
    d = box_scene([{"centre": [3.0, 2.5, 3.3], "dip": 35.0, "dip_direction": 200.0, "radius": 2.5},
                   {"centre": [2.0, 2.0, 2.0], "dip": 80.0, "dip_direction": 20.0, "radius": 9.0,
                    "thickness": 0.6}], kind=kind)
    scene, m = build(d)
    check_model(d, scene, m)
    # interior spheres of a close packing touch 12 others
    deg = np.bincount(m.bonds.ravel(), minlength=len(m.centers))
    assert deg.max() == 12


def test_empty_model_and_no_discontinuities():
    # a surface below the whole box removes everything
    d = box_scene([{"centre": [3.0, 2.5, 3.3], "normal": [0, 0, 1], "radius": 5.0}])
    d["excavation"] = [{"points": [[-1, -1, -3.9], [9, -1, -3.95], [9, 9, -3.9], [-1, 9, -3.8]]}]
    d["domain"]["min"][2] = -4.0
    scene, m = build(d)
    assert len(m.centers) == 0 and len(m.bonds) == 0 and len(m.member_sphere) == 0
    check_model(d, scene, m)
    d = box_scene([])
    scene, m = build(d)
    assert np.all(m.colour == 0) and m.bonded.all() and np.all(m.cut_by == -1)
    check_model(d, scene, m)
