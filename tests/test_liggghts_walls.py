"""Rigid-side joints as LIGGGHTS mesh walls (run.extra liggghts_joint_walls, adapters/liggghts_walls.py).

The deck is read back and checked against the definition by brute force (each wall plane from its STL triangles:
the joint's orientation from its dip and dip direction, touching the nearest free sphere of the joint's pairs;
the fixed spheres behind it typed out of every contact; the grown contact radii of liggghts_wall_radii). Real
LIGGGHTS runs (CI=true: no skip): a rigid block on an inclined wall slides as s = 1/2 g (sin a - tan phi cos a)
t^2 and holds when phi > a (bonded by central bonds instead of a clump it rolls: 5/7 g sin a); the sphere wedge
of `cases crossval` slides at 0.995 x Hoek & Bray's critical friction and holds at 1.005 x.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from adapters import liggghts_walls as jw
from adapters.deck import export
from adapters.deck import run as run_deck
from adapters.spec import SpecError
from cases.lib import crossval as cv
from engine_runs import hand_run, require_engine

G = 9.81


def _stl_triangles(path):
    v = [list(map(float, ln.split()[1:])) for ln in path.read_text().splitlines() if ln.strip().startswith("vertex")]
    return np.asarray(v).reshape(-1, 3, 3)


def _atoms(path):
    """(type, diameter, density) per atom id of a LIGGGHTS data file (hybrid granular molecular)."""
    lines = path.read_text().splitlines()
    k = lines.index("Atoms") + 2
    rows = []
    for ln in lines[k:]:
        if not ln.strip():
            break
        rows.append(ln.split())
    rows.sort(key=lambda r: int(r[0]))
    a = np.asarray(rows, float)
    return a[:, 1].astype(int), a[:, 5], a[:, 6]


def _unit(dip, dip_dir):
    d, a = math.radians(dip), math.radians(dip_dir)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def test_wedge_walls_are_the_joint_planes_touching_the_nearest_free_sphere(tmp_path):
    run = cv.liggghts_wedge(replace(cv.wedge_run(), joint_friction_deg=19.0))
    run.save(tmp_path / "run.npz")
    export(tmp_path / "run.npz", "liggghts", tmp_path / "deck", variant="clumps", force=True)
    types, diam, dens = _atoms(tmp_path / "deck" / "data")
    free, c, r = ~run.fixed, run.centers, run.radii
    planes = []
    for k, joint in enumerate((cv.WEDGE["joint_a"], cv.WEDGE["joint_b"]), 1):
        tri = _stl_triangles(tmp_path / "deck" / f"wall_{k}.stl")
        assert tri.shape == (2, 3, 3)
        n = np.cross(tri[0, 1] - tri[0, 0], tri[0, 2] - tri[0, 0])
        n /= np.linalg.norm(n)
        assert np.allclose(n, _unit(*joint), atol=1e-12)  # the joint's own orientation, its upward normal
        d = float(tri[0, 0] @ n)
        assert np.allclose(tri.reshape(-1, 3) @ n, d, atol=1e-9)  # flat
        # brute force: the joint's pairs across it (one sphere fixed, one free), their free spheres' clearance
        pairs = np.flatnonzero((run.joint_disc == k - 1) & (run.fixed[run.joint_i] != run.fixed[run.joint_j]))
        near = np.unique(np.where(run.fixed[run.joint_i[pairs]], run.joint_j[pairs], run.joint_i[pairs]))
        assert abs(min(c[i] @ n - r[i] - d for i in near)) < 1e-9
        assert min(c[i] @ n - r[i] - d for i in np.flatnonzero(free)) > -1e-9  # no free sphere starts in a wall
        planes.append((n, d, near))
    # every fixed sphere lies behind a joint: all of them are the walls' rock, typed out of every contact
    assert np.all(types[run.fixed] == jw.DROPPED_TYPE) and np.all(types[free] <= 4)
    # contact radii: the spheres of the joints' pairs reach the nearest wall, the other free spheres keep theirs
    near = np.union1d(planes[0][2], planes[1][2])
    reach = np.array([min(c[i] @ n - d for n, d, _ in planes) for i in near])
    assert np.allclose(0.5 * diam[near], reach, rtol=1e-12)
    other = np.setdiff1d(np.flatnonzero(free), near)
    assert np.allclose(0.5 * diam[other], r[other], rtol=1e-15)
    assert np.allclose(dens * diam ** 3, run.density * (2 * r) ** 3, rtol=1e-12)  # masses kept


def _block_on_incline(alpha, phi, duration=0.4):
    """A bonded 3 x 3 block of spheres (r = 0.05) on a fixed 14 x 3 layer, joint pairs straight down (normal
    +z), gravity tilted by `alpha` about y (the incline), joint friction `phi`, records every T / 8; joint
    walls."""
    r = 0.05
    xs, ys = np.meshgrid(np.arange(14) * 2 * r - 2 * r, np.arange(3) * 2 * r, indexing="ij")
    rock = np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, -r)]
    bx, by = np.meshgrid(np.arange(3) * 2 * r, np.arange(3) * 2 * r, indexing="ij")
    block = np.c_[bx.ravel(), by.ravel(), np.full(bx.size, r)]
    m = len(rock)
    idx = np.arange(9).reshape(3, 3) + m
    bonds = [(idx[a, b], idx[a + 1, b]) for a in range(2) for b in range(3)]
    bonds += [(idx[a, b], idx[a, b + 1]) for a in range(3) for b in range(2)]
    a = math.radians(alpha)
    run = hand_run(np.r_[rock, block], r, fixed=range(m), bonds=bonds, dt=1e-4, duration=duration,
                   record_every=duration / 8, contact_kn=1e6, gravity=(G * math.sin(a), 0.0, -G * math.cos(a)),
                   liggghts_joint_walls=True)
    below = np.array([int(np.argmin(np.linalg.norm(rock[:, :2] - p[:2], axis=1))) for p in block])
    # contact damping 0.3 of critical: undamped, the block bounces on its normal springs (it starts touching,
    # unloaded), and at every unloading the friction lets it slip a little (1.1 mm in 0.4 s at phi = 35 deg)
    return replace(run, joint_i=below, joint_j=np.arange(m, m + 9), joint_disc=np.zeros(9, np.int32),
                   joint_normal=np.tile([0.0, 0.0, 1.0], (9, 1)), joint_friction_deg=float(phi), damping=0.3)


def _run(run, work):
    run.save(work / "run.npz")
    export(work / "run.npz", "liggghts", work / "deck", variant="clumps", force=True)
    return run_deck(work / "deck", out=work / "deck" / "result")


def test_block_on_an_inclined_wall_slides_as_the_analytical_solution(tmp_path):
    require_engine("liggghts")
    alpha, T = 30.0, 0.4
    for phi in (20.0, 35.0):
        run = _block_on_incline(alpha, phi, T)
        (tmp_path / str(phi)).mkdir()
        res = _run(run, tmp_path / str(phi))
        assert any("liggghts_joint_walls" in a for a in res.extra["approximations"])
        s = float(np.mean(res.displacement()[~run.fixed, 0]))
        a, p = math.radians(alpha), math.radians(phi)
        if phi < alpha:  # the acceleration after the first quarter (the block first settles onto the wall)
            t = res.time[res.time >= T / 4 - 1e-9]
            x = [float(np.mean(res.pos[k][~run.fixed, 0])) for k in np.flatnonzero(res.time >= T / 4 - 1e-9)]
            acc = 2.0 * np.polyfit(t, x, 2)[0]
            ref = G * (math.sin(a) - math.tan(p) * math.cos(a))
            assert abs(acc / ref - 1.0) < 1e-6, (acc, ref)  # measured 1.4e-13: a rigid body under Coulomb friction
            assert abs(s / (0.5 * ref * T ** 2) - 1.0) < 0.02, s  # the whole slide, with the settling
        else:  # holds: the tangential springs' elastic stretch alone (about 1e-5 m)
            assert abs(s) < 1e-4, s
        assert np.all(res.final_pos[~run.fixed, 2] > 0.0)  # on the wall, not through it


def test_wedge_on_walls_slides_below_and_holds_above_hoek_bray(tmp_path):
    require_engine("liggghts")
    base = cv.wedge_run()
    phi_c = cv.wedge_reference(cv.WEDGE).critical_friction
    slides, s = cv.wedge_trial("liggghts", base, 0.995 * phi_c, tmp_path)
    assert slides, s
    holds, s = cv.wedge_trial("liggghts", base, 1.005 * phi_c, tmp_path)
    assert not holds, s


def test_bonded_spheres_roll_on_a_wall_as_ball_bearings(tmp_path):
    # why the wedge runs as a clump: harmonic bonds are central, so each sphere of a bonded block on a wall turns
    # freely and rolls (friction 20 deg > atan(2/7 tan 30 deg), enough to roll): the block accelerates at
    # 5/7 g sin a (translation plus each sphere's spin), not at g (sin a - tan phi cos a)
    require_engine("liggghts")
    run = _block_on_incline(30.0, 20.0, 0.2)
    run.save(tmp_path / "run.npz")
    export(tmp_path / "run.npz", "liggghts", tmp_path / "deck", variant="bonds", force=True)
    res = run_deck(tmp_path / "deck", out=tmp_path / "deck" / "result")
    assert any("rolls on a wall" in a for a in res.extra["approximations"])
    k = np.flatnonzero(res.time >= 0.05 - 1e-9)
    acc = 2.0 * np.polyfit(res.time[k], [float(np.mean(res.pos[q][~run.fixed, 0])) for q in k], 2)[0]
    assert abs(acc / (5.0 / 7.0 * G * 0.5) - 1.0) < 1e-3, acc


def test_bad_wall_options_are_refused_in_one_line(tmp_path):
    run = _block_on_incline(30.0, 20.0)
    run.extra["liggghts_joint_walls"] = "yes"
    run.save(tmp_path / "a.npz")
    with pytest.raises(SpecError, match=r"run.extra liggghts_joint_walls = 'yes': expected true or false"):
        export(tmp_path / "a.npz", "liggghts", tmp_path / "a", force=True)
    run.extra.update(liggghts_joint_walls=True, liggghts_wall_radii=True)
    run.save(tmp_path / "b.npz")
    with pytest.raises(SpecError, match="liggghts_wall_radii .* needs the clumps variant"):
        export(tmp_path / "b.npz", "liggghts", tmp_path / "b", variant="bonds", force=True)


def test_a_joint_with_rock_on_both_sides_gets_a_wall_for_each_side():
    # a fixed layer at z = -r between a block above (z = r) and one below (z = -3 r): two walls, normals +z and
    # -z, each touching its block's spheres (z = 0 and z = -2 r); the fixed layer is the rock of both
    run = _block_on_incline(0.0, 20.0)
    m, r = int(run.fixed.sum()), 0.05
    below = run.centers[m:] - [0.0, 0.0, 4 * r]
    c = np.r_[run.centers, below]
    nb = len(below)
    sub = hand_run(c, r, fixed=range(m), liggghts_joint_walls=True)
    rock = np.r_[run.joint_i, run.joint_i]
    run = replace(sub, joint_i=rock, joint_j=np.r_[run.joint_j, np.arange(len(run.centers), len(c))],
                  joint_disc=np.zeros(18, np.int32), joint_normal=np.r_[np.tile([0.0, 0.0, 1.0], (nb, 1)),
                                                                        np.tile([0.0, 0.0, -1.0], (nb, 1))])
    planes = jw.wall_planes(run)
    assert len(planes) == 2
    got = sorted((float(p["normal"][2]), p["offset"]) for p in planes)
    assert np.allclose([g[0] for g in got], [-1.0, 1.0], atol=1e-15)
    assert np.allclose([g[1] for g in got], [2 * r, 0.0], atol=1e-15)  # -z = 2 r: the plane z = -2 r
    assert np.array_equal(jw.dropped(run), run.fixed)
    run.extra["liggghts_wall_radii"] = True  # each block's spheres touch their own wall; the other is behind them
    assert np.allclose(jw.wall_radii(run), r, rtol=1e-12)
    assert jw.wall_planes(replace(run, smooth_joints=False)) == []  # plain contacts in every engine: no walls


def test_a_curved_joint_is_refused():
    run = _block_on_incline(30.0, 20.0)
    n = run.joint_normal.copy()
    n[0] = [math.sin(math.radians(1.0)), 0.0, math.cos(math.radians(1.0))]  # one pair's normal 1 deg off
    with pytest.raises(SpecError, match="joint 0 is not planar"):
        jw.wall_planes(replace(run, joint_normal=n))


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "adapters.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


def test_export_option_and_deck_check(tmp_path):
    run = _block_on_incline(30.0, 20.0, 0.05)
    run.extra.clear()
    run.save(tmp_path / "run.npz")
    p = _cli("export", tmp_path / "run.npz", "--to", "liggghts", "-o", tmp_path / "d", "--variant", "clumps",
             "--liggghts-joint-walls", "pairs", "--json")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["joint_walls"] == 1 and (tmp_path / "d" / "wall_1.stl").is_file()
    for args, words in ((("--to", "liggghts", "--liggghts-joint-walls", "yes"), "--liggghts-joint-walls = 'yes'"),
                        (("--to", "yade", "--liggghts-joint-walls", "nearest"), "--to liggghts only")):
        p = _cli("export", tmp_path / "run.npz", "-o", tmp_path / "bad", *args)
        assert p.returncode != 0 and words in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    (tmp_path / "d" / "wall_1.stl").unlink()
    p = _cli("run", tmp_path / "d")
    assert p.returncode != 0 and "wall_1.stl" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
