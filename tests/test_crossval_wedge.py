"""The sphere wedge of `cases crossval` against Hoek & Bray: its onset within 0.5 % in-house and in YADE.

The wedge's spheres without the mechanisms (free spheres that fewer than three moment-free bonds hold) are
checked against a brute-force transcription of the definition (every subset of a small bond graph), and the
real engines (YADE under CI=true) must let the wedge slide at 0.995 x Hoek & Bray's critical friction and hold it
at 1.005 x, which brackets their onsets within 0.5 % of the reference: on smooth joints, and with the rock below
the joints as joint walls (run.extra joint_walls, adapters/joint_walls.py).
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from cases.lib import crossval as cv
from engine_runs import hand_run, require_engine


def _brute_core(n, fixed, bonds, k=3):
    """The largest set of free spheres each tied by >= k bonds to the set or to fixed spheres: the union of
    every such subset (the union of two such sets is one), by trying all subsets."""
    free = [i for i in range(n) if i not in fixed]
    keep = set(fixed)
    for m in range(len(free) + 1):
        for sub in itertools.combinations(free, m):
            s = set(sub) | set(fixed)
            if all(sum(1 for a, b in bonds if (a == i and b in s) or (b == i and a in s)) >= k for i in sub):
                keep |= s
    return np.array([i in keep for i in range(n)])


def test_rigid_core_is_the_largest_set_held_by_three_bonds_each():
    rng = np.random.default_rng(7)
    n = 11
    for _ in range(12):
        fixed = [0, 1, 2]
        pairs = [(a, b) for a in range(n) for b in range(a + 1, n) if not (a in fixed and b in fixed)]
        bonds = [pairs[k] for k in rng.choice(len(pairs), size=int(rng.integers(10, 26)), replace=False)]
        run = hand_run(rng.random((n, 3)) * 4.0, 0.5, fixed=fixed, bonds=bonds)
        got = cv.rigid_core(run)
        assert np.array_equal(got, _brute_core(n, fixed, bonds))


def test_without_keeps_the_bonds_and_joints_between_the_kept_spheres():
    run = cv.wedge_run(core=False)
    keep = cv.rigid_core(run)
    assert keep.sum() < run.n  # the scene's wedge has spheres that fewer than three bonds hold
    sub = cv.without(run, keep)
    c = np.asarray(run.centers)
    for name in ("bond", "joint"):
        i, j = getattr(run, f"{name}_i"), getattr(run, f"{name}_j")
        both = keep[i] & keep[j]
        si, sj = getattr(sub, f"{name}_i"), getattr(sub, f"{name}_j")
        assert np.array_equal(sub.centers[si], c[i[both]]) and np.array_equal(sub.centers[sj], c[j[both]])
    assert np.array_equal(sub.joint_normal, np.asarray(run.joint_normal).reshape(-1, 3)[keep[run.joint_i]
                                                                                      & keep[run.joint_j]])
    assert np.array_equal(sub.bond_kn, run.bond_kn[keep[run.bond_i] & keep[run.bond_j]])
    assert np.array_equal(sub.fixed, run.fixed[keep]) and sub.fixed.sum() == run.fixed.sum()


@pytest.mark.parametrize("engine,walls", [("dda", False), ("yade", False), ("dda", True), ("yade", True)])
def test_sphere_wedge_slides_half_a_percent_below_hoek_bray_and_holds_half_a_percent_above(engine, walls, tmp_path):
    # Hoek & Bray's critical friction depends on the joint normals and the line of intersection alone; the sphere
    # wedge (r = 0.5, smooth joints, local damping 0.1, 1.2 s per trial) must slide at 0.995 phi_c and come to
    # rest at 1.005 phi_c, so its onset lies within 0.5 % (the criterion before issue 16 put it 1.17 % low).
    # walls: the rock below the joints as joint walls (cv.walled_wedge: an in-house slab, a YADE facet); the wedge
    # first settles onto them (0.14 m, about 1.5 s of its 2.4 s)
    if engine != "dda":
        require_engine(engine)  # skipped without YADE, failed on CI
    base = cv.wedge_run()
    phi_c = cv.wedge_reference(cv.WEDGE).critical_friction
    below, s_below = cv.wedge_trial(engine, base, 0.995 * phi_c, tmp_path, walls=walls)
    above, s_above = cv.wedge_trial(engine, base, 1.005 * phi_c, tmp_path, walls=walls)
    on = " on joint walls" if walls else ""
    assert below, f"{engine}: holds at {0.995 * phi_c:.3f} deg{on} (s at T/2, 3T/4, T = {s_below})"
    assert not above, f"{engine}: slides at {1.005 * phi_c:.3f} deg{on} (s at T/2, 3T/4, T = {s_above})"
    # the one that holds has come to rest, the one that slides keeps going
    # on walls the wedge that holds still creeps by the tail of its settling: 2.9e-6 m in its last quarter (2.4 s)
    rest = 1e-5 if walls else 1e-6
    assert abs(s_above[2] - s_above[1]) < rest < s_below[2] - s_below[1]
