"""Rigid-side joints as walls in YADE and in-house (run.extra joint_walls, adapters/joint_walls.py).

The walls each engine is given are read back and checked against the definition by brute force (the joint's
plane from its dip and dip direction, touching the nearest free sphere of the joint's pairs; the wall covering the
rock behind it; that rock out of every contact): the YADE deck's facets (walls.npz) and the in-house slabs. The
option (`adapters export --joint-walls`, its older LIGGGHTS spelling) and its refusals in one line. The real
engines on walls (the wedge of `cases crossval` against Hoek & Bray, in-house and in YADE): tests/test_crossval_wedge.py.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from adapters import joint_walls as jw
from adapters.deck import export
from adapters.inhouse import run_inhouse, wall_slabs
from adapters.spec import SpecError
from cases.lib import crossval as cv
from engine_runs import hand_run


def _unit(dip, dip_dir):
    d, a = math.radians(dip), math.radians(dip_dir)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def _inside(p, tri, n):
    """Whether the point p (in the plane of the triangle tri, normal n) lies inside it."""
    return all(np.cross(tri[(k + 1) % 3] - tri[k], p - tri[k]) @ n >= -1e-12 for k in range(3))


@pytest.fixture(scope="module")
def wedge():
    return cv.walled_wedge(replace(cv.wedge_run(), joint_friction_deg=19.0))


def _joint_reference(run, k):
    """Brute force for joint k (0: joint A, 1: B): its unit normal from the scene's dip / dip direction, the
    offset of the plane touching the nearest free sphere of its fixed-free pairs, and those free spheres."""
    n = _unit(*(cv.WEDGE["joint_a"], cv.WEDGE["joint_b"])[k])
    pairs = np.flatnonzero((run.joint_disc == k) & (run.fixed[run.joint_i] != run.fixed[run.joint_j]))
    near = np.unique(np.where(run.fixed[run.joint_i[pairs]], run.joint_j[pairs], run.joint_i[pairs]))
    return n, min(float(run.centers[i] @ n - run.radii[i]) for i in near), near


def test_yade_facets_are_the_joint_planes_over_the_rock_behind_them(wedge, tmp_path):
    wedge.save(tmp_path / "run.npz")
    info = export(tmp_path / "run.npz", "yade", tmp_path / "deck", force=True)
    assert info["joint_walls"] == 2 and "walls.npz" in info["files"]
    z = np.load(tmp_path / "deck" / "walls.npz")
    tri, young, gone = z["triangles"], z["young"], z["dropped"]
    c, r, free = wedge.centers, wedge.radii, ~wedge.fixed
    assert np.array_equal(gone, wedge.fixed)  # every fixed sphere of the wedge lies behind a joint
    for k in range(2):
        n, d, near = _joint_reference(wedge, k)
        t = tri[k]
        m = np.cross(t[1] - t[0], t[2] - t[0])
        assert np.allclose(m / np.linalg.norm(m), n, atol=1e-12)  # counter-clockwise about the joint's normal
        assert np.allclose(t @ n, d, atol=1e-9)  # the plane touching the nearest free sphere
        assert min(c[i] @ n - r[i] - d for i in np.flatnonzero(free)) > -1e-9  # no free sphere starts in it
        # the rock behind it: every fixed sphere whose centre lies no higher than its joint pairs' fixed spheres
        pairs = np.flatnonzero((wedge.joint_disc == k) & (wedge.fixed[wedge.joint_i] != wedge.fixed[wedge.joint_j]))
        held = np.where(wedge.fixed[wedge.joint_i[pairs]], wedge.joint_i[pairs], wedge.joint_j[pairs])
        rock = np.flatnonzero(wedge.fixed & (c @ n <= max(c[i] @ n for i in held)))
        assert len(rock) > len(np.unique(held))
        assert all(_inside(c[i] - (c[i] @ n - d) * n, t, n) for i in rock)  # the facet covers its projection
        # facet young: JCFpm's kn of a facet (a sphere of twice the radius) and a sphere of young kn / r is kn
        e1r1, e2r2 = young[k] * 2 * r[near[0]], wedge.kn / r[near[0]] * r[near[0]]
        assert abs(2 * e1r1 * e2r2 / (e1r1 + e2r2) / wedge.kn - 1.0) < 1e-12
    notes = json.loads((tmp_path / "deck" / "deck.json").read_text())["approximations"]
    assert any(a.startswith("joint_walls: the fixed side of 2 joint(s) is a YADE facet") for a in notes)


def test_inhouse_slabs_are_the_joint_planes_and_the_rock_behind_them_is_left_out(wedge):
    kept, slabs = wall_slabs(wedge)
    assert np.array_equal(kept, ~wedge.fixed) and len(slabs) == 2
    for k, spec in enumerate(slabs):
        n, d, _ = _joint_reference(wedge, k)
        v = np.asarray(spec.vertices)
        top = v[spec.faces[0]]
        m = np.cross(top[1] - top[0], top[2] - top[0])
        assert np.allclose(m / np.linalg.norm(m), n, atol=1e-12)  # outward: towards the wedge
        assert np.allclose(top @ n, d, atol=1e-9)
        assert np.all(v @ n <= d + 1e-9) and spec.fixed  # the slab lies behind its top face


def test_joint_walls_option_and_refusals(tmp_path, wedge):
    run = replace(wedge, extra={})
    run.save(tmp_path / "run.npz")
    cli = [sys.executable, "-m", "adapters.cli", "export", str(tmp_path / "run.npz")]
    p = subprocess.run(cli + ["--to", "yade", "-o", str(tmp_path / "d"), "--joint-walls", "nearest", "--json"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["joint_walls"] == 2 and (tmp_path / "d" / "walls.npz").is_file()
    for args, words in ((["--to", "yade", "--joint-walls", "pairs"], "only a rigid body takes"),
                        (["--to", "yade", "--joint-walls", "yes"], "--joint-walls = 'yes': must be one of nearest, "
                                                                  "pairs"),
                        (["--to", "pfc-text", "--joint-walls", "nearest"], "--to yade | liggghts only")):
        p = subprocess.run(cli + ["-o", str(tmp_path / "bad"), *args], capture_output=True, text=True, timeout=600)
        assert p.returncode != 0 and words in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
        assert not (tmp_path / "bad").exists()
    # the older LIGGGHTS spelling means the same walls
    old = replace(wedge, extra={"liggghts_joint_walls": True})
    assert jw.mode(old) == ("nearest", "liggghts_joint_walls")
    assert [p["offset"] for p in jw.wall_planes(old)] == [p["offset"] for p in jw.wall_planes(wedge)]
    with pytest.raises(SpecError, match="run.extra joint_walls = 'all': expected one of nearest, pairs"):
        jw.mode(replace(wedge, extra={"joint_walls": "all"}))
    (tmp_path / "d" / "walls.npz").unlink()
    p = subprocess.run([sys.executable, "-m", "adapters.cli", "run", str(tmp_path / "d")], capture_output=True,
                       text=True, timeout=600)
    assert p.returncode != 0 and "walls.npz" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_rock_behind_a_wall_bonded_to_a_free_sphere_is_refused():
    # a free sphere on a fixed layer, joint pair straight down, and a bond from it to a fixed sphere of that layer
    r = 0.05
    rock = np.array([[2 * r * a, 0.0, -r] for a in range(3)])
    run = hand_run(np.r_[rock, [[0.0, 0.0, r]]], r, fixed=range(3), bonds=[(1, 3)], joint_walls="nearest")
    run = replace(run, joint_i=np.array([0]), joint_j=np.array([3]), joint_disc=np.zeros(1, np.int32),
                  joint_normal=np.array([[0.0, 0.0, 1.0]]))
    with pytest.raises(SpecError, match=r"1 bond\(s\) tie free spheres to the fixed rock behind a joint wall"):
        jw.wall_planes(run)
    with pytest.raises(SpecError, match="bond"):
        run_inhouse(run)
