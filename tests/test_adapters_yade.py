"""YADE adapter (adapters/yade.py, adapters/yade_poly.py): real YADE runs checked against independent
references: the per-pair bond rule read back from YADE after the bonding step, free fall (1/2 g t^2), bonds
breaking at their tensile force (a suddenly loaded spring peaks at twice its static force), a hanging jointed
column whose part below a through-going joint falls (a plane test on the centres), engine errors, missing bond
pairs, time limits, and a polyhedral block sliding on an incline (1/2 g (sin a - tan phi cos a) t^2)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from adapters import yade
from adapters.process import EngineError
from adapters.result import RunResult
from adapters.spec import from_model
from engine_runs import G, hand_run, require_engine


require_engine("yade", module=True)


def deck(run, tmp_path, name="deck", **kw):
    folder = tmp_path / name
    folder.mkdir()
    run.save(folder / "run.npz")
    info = yade.write_deck(run, folder, **kw)
    assert set(info["files"]) <= {p.name for p in folder.iterdir()}
    return folder


def sgim_model(extent, discs, radius=0.05):
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    data = {"name": "yade_test", "domain": {"min": [0.0, 0.0, 0.0], "max": list(extent)},
            "packing": {"kind": "fcc", "radius": radius}, "bonds": {"rule": "colour"}, "discontinuity": discs}
    return build_model(scene_from_dict(data))


def pair_set(i, j):
    return set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist()))


# -- sphere decks ---------------------------------------------------------------------------------------------
def test_bonding_step_gives_exactly_the_per_pair_rule(tmp_path):
    """A joint disc (zero thickness) and a fault (thick band): after the bonding step YADE's cohesive pairs are
    exactly the run's bond list and its smooth-joint pairs exactly the joint pairs; every other touching pair
    of the model is a plain contact."""
    model = sgim_model((0.6, 0.6, 0.6), [
        {"name": "joint", "centre": [0.3, 0.3, 0.3], "normal": [0.3, 0.2, 1.0], "radius": 0.2, "thickness": 0.0},
        {"name": "fault", "centre": [0.3, 0.3, 0.3], "normal": [1.0, 0.0, 0.0], "radius": 1.0, "thickness": 0.1}])
    run = from_model(model, duration=2e-4)
    assert len(run.joint_i) > 5 and len(run.cut_i) > len(run.joint_i) and run.n_bonds > 100
    folder = deck(run, tmp_path, dump_bonds=True)
    res = yade.run_deck(folder, tmp_path / "out")
    assert res.complete and res.engine == "yade" and res.steps == run.steps
    z = np.load(tmp_path / "out" / "yade_bonds.npz")
    # the reference: the model's own pair list and flags (independent of the run arrays' construction)
    pairs = np.asarray(model.bonds).reshape(-1, 2)
    bonded = np.asarray(model.bonded, bool)
    assert pair_set(z["cohesive"][:, 0], z["cohesive"][:, 1]) == pair_set(pairs[bonded, 0], pairs[bonded, 1])
    assert pair_set(z["joint"][:, 0], z["joint"][:, 1]) == pair_set(run.joint_i, run.joint_j)
    setup = res.extra["setup"]
    assert setup["bonds_missing"] == 0 and setup["joints_missing"] == 0
    assert 0 < setup["unbonded_contacts"] <= int((~bonded).sum()) - len(run.joint_i)
    assert np.all(res.bond_intact) and len(res.bond_intact) == run.n_bonds
    back = RunResult.load(tmp_path / "out")
    assert back.status == "complete" and np.array_equal(back.final_pos, res.final_pos)


def test_free_fall(tmp_path):
    """One unbonded sphere falls 1/2 g t^2 (leapfrog: exact to a relative 1 / steps)."""
    run = hand_run([[0.0, 0.0, 1.0]], 0.1, dt=1e-4, duration=0.2, record_every=0.02)
    res = yade.run_deck(deck(run, tmp_path), tmp_path / "out")
    t = res.time
    assert len(t) == 11 and t[-1] == pytest.approx(0.2, rel=1e-9)
    drop = 1.0 - res.pos[:, 0, 2]
    np.testing.assert_allclose(drop[1:], 0.5 * G * t[1:] ** 2, rtol=1e-2)
    assert 1.0 - res.final_pos[0, 2] == pytest.approx(0.5 * G * 0.2 ** 2, rel=1e-3)
    assert res.final_vel[0, 2] == pytest.approx(-G * 0.2, rel=1e-6)
    mass = 2600.0 * 4.0 / 3.0 * math.pi * 0.1 ** 3
    assert res.series["kinetic"][-1] == pytest.approx(0.5 * mass * (G * 0.2) ** 2, rel=1e-6)
    assert np.allclose(res.final_pos[0, :2], 0.0)


def test_bond_breaks_at_its_tensile_force(tmp_path):
    """Spheres hanging on bonds from fixed ones, gravity switched on at t = 0: an undamped spring peaks at
    twice the static force m g, so bonds with ft < 2 m g break and those with ft > 2 m g hold."""
    r = 0.05
    mass = 2600.0 * 4.0 / 3.0 * math.pi * r ** 3
    factors = [1.9, 1.96, 2.04, 2.1]
    centers, bonds, fixed = [], [], []
    for k in range(len(factors)):
        x = 1.0 * k
        centers += [[x, 0.0, 1.0], [x, 0.0, 1.0 - 2 * r]]
        fixed.append(2 * k)
        bonds.append((2 * k, 2 * k + 1))
    ft = np.array(factors) * mass * G
    run = hand_run(centers, r, fixed=fixed, bonds=bonds, kn=1e6, ft=ft, dt=2e-5, duration=0.02)
    res = yade.run_deck(deck(run, tmp_path), tmp_path / "out")
    assert res.bond_intact.tolist() == [f > 2.0 for f in factors]
    assert res.extra["cracks"]["tension"] == 2 and res.series["bonds_intact"][-1] == 2
    hanging = np.arange(1, 2 * len(factors), 2)
    fell = (1.0 - 2 * r) - res.final_pos[hanging, 2] > 0.1 * 0.5 * G * 0.02 ** 2
    assert fell.tolist() == [f < 2.0 for f in factors]
    assert np.allclose(res.final_pos[0::2], run.centers[0::2])  # fixed spheres never move


def test_hanging_column_below_a_through_going_joint_falls(tmp_path):
    """A bonded FCC column hangs from its fixed top; a joint cuts it through at mid height: every sphere
    below the joint plane falls freely, every other sphere stays (the reference: the plane test on the
    centres)."""
    model = sgim_model((0.3, 0.3, 1.0), [{"name": "joint", "centre": [0.15, 0.15, 0.52], "normal": [0.1, 0.0, 1.0],
                                          "radius": 5.0, "thickness": 0.0}])
    c = np.asarray(model.centers)
    fixed = c[:, 2] > 0.9
    run = from_model(model, fixed=fixed, duration=0.08, record_every=0.02, kn=1e7)
    res = yade.run_deck(deck(run, tmp_path), tmp_path / "out")
    n = np.array([0.1, 0.0, 1.0]) / np.linalg.norm([0.1, 0.0, 1.0])
    below = (c - [0.15, 0.15, 0.52]) @ n < 0
    assert 0 < below.sum() < len(c)
    drop = c[:, 2] - res.final_pos[:, 2]
    free_fall = 0.5 * G * 0.08 ** 2
    assert np.all(drop[below] > 0.5 * free_fall)
    assert np.all(np.abs(res.final_pos[~below] - c[~below]).max(1) < 0.02 * free_fall)
    assert np.all(res.bond_intact)
    assert len(run.joint_i) > 0 and res.extra["setup"]["joints_found"] == len(run.joint_i)


def test_block_slides_on_a_smooth_joint_as_on_an_incline(tmp_path):
    """A bonded FCC column cut through by a joint dipping 40 degrees (joint friction 20): the part above the
    joint slides down-dip as a block on an incline, 1/2 g (sin b - tan phi cos b) t^2 (within 2 %), the part
    below (fixed at its foot) stays. A joint normal of the wrong sign makes this run blow up."""
    beta, phi, T = math.radians(40.0), math.radians(20.0), 0.1
    n = np.array([math.sin(beta), 0.0, math.cos(beta)])
    model = sgim_model((0.4, 0.4, 0.8), [{"name": "joint", "centre": [0.2, 0.2, 0.4], "normal": n.tolist(),
                                          "radius": 5.0, "thickness": 0.0}])
    c = np.asarray(model.centers)
    run = from_model(model, fixed=c[:, 2] < 0.1, duration=T, record_every=T / 4, kn=1e8, friction_deg=30.0,
                     joint_friction_deg=math.degrees(phi))
    above = (c - [0.2, 0.2, 0.4]) @ n > 0
    assert len(run.joint_i) > 10 and np.all(above[run.joint_i] != above[run.joint_j])
    res = yade.run_deck(deck(run, tmp_path), tmp_path / "out")
    down = np.array([math.cos(beta), 0.0, -math.sin(beta)])
    s = (res.final_pos[above] - c[above]) @ down
    ref = 0.5 * G * (math.sin(beta) - math.tan(phi) * math.cos(beta)) * res.time[-1] ** 2
    np.testing.assert_allclose(s, ref, rtol=0.02)
    assert np.abs(res.final_pos[~above] - c[~above]).max() < 1e-3 * ref


def test_missing_bond_pair_fails_loudly(tmp_path):
    """A bond between two spheres far apart has no YADE interaction: the run stops with one clear line."""
    run = hand_run([[0, 0, 0], [0, 0, 0.1], [0, 0, 1.0]], 0.05, bonds=[(0, 1), (0, 2)], duration=1e-3)
    with pytest.raises(EngineError) as exc:
        yade.run_deck(deck(run, tmp_path), tmp_path / "out")
    msg = str(exc.value)
    assert "1 of 2 bond-list pairs" in msg and "\n" not in msg
    assert exc.value.result is not None and not exc.value.result.complete
    assert json.loads((tmp_path / "out" / "result.json").read_text())["status"] == "incomplete"


def test_engine_error_mid_run(tmp_path):
    """A time step far beyond the stable one blows the bonded column up mid-run: EngineError with the
    script's blow-up line, the records so far kept and marked incomplete."""
    model = sgim_model((0.2, 0.2, 0.4), [])
    run = from_model(model, fixed=np.asarray(model.centers)[:, 2] > 0.3, kn=1e7)
    run.dt *= 30.0
    run.duration, run.record_every = 300 * run.dt, 10 * run.dt
    with pytest.raises(EngineError) as exc:
        yade.run_deck(deck(run, tmp_path), tmp_path / "out")
    assert "blow-up" in str(exc.value) and str(exc.value).startswith("yade: exit status 4")
    res = exc.value.result
    assert res.status == "incomplete" and len(res.time) >= 1
    assert RunResult.load(tmp_path / "out").status == "incomplete"


def test_broken_script_error_line(tmp_path):
    """A YADE-side Python exception surfaces as the EngineError's message."""
    run = hand_run([[0, 0, 0]], 0.05, duration=1e-3)
    folder = deck(run, tmp_path)
    (folder / "script.py").write_text("raise ValueError('deck is damaged')\n")
    with pytest.raises(EngineError, match="ValueError: deck is damaged"):
        yade.run_deck(folder, tmp_path / "out")


def test_time_limit_keeps_partial_results(tmp_path):
    """A run longer than its time limit is killed: EngineError, and the records written so far come back in a
    result marked incomplete."""
    model = sgim_model((0.3, 0.3, 0.6), [])
    run = from_model(model, fixed=np.asarray(model.centers)[:, 2] > 0.5, kn=1e7)
    run.duration, run.record_every = 1e5 * run.dt, 50 * run.dt
    with pytest.raises(EngineError, match="time limit") as exc:
        yade.run_deck(deck(run, tmp_path), tmp_path / "out", timeout=6)
    res = exc.value.result
    assert res.status == "incomplete" and 2 <= len(res.time) < run.steps // run.record_steps
    assert len(res.series["kinetic"]) == len(res.time) and res.pos.shape[1:] == (run.n, 3)
    assert np.all(np.isfinite(res.final_pos))
    back = RunResult.load(tmp_path / "out")
    assert back.status == "incomplete" and "time limit" in back.message


def test_no_spheres_is_refused(tmp_path):
    from adapters.spec import SpecError

    run = hand_run(np.zeros((0, 3)), 0.05)
    with pytest.raises(SpecError, match="no spheres"):
        yade.write_deck(run, tmp_path / "deck")
    assert not (tmp_path / "deck").exists()


def test_missing_engine(tmp_path, monkeypatch):
    run = hand_run([[0, 0, 0]], 0.05, duration=1e-3)
    folder = deck(run, tmp_path)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(EngineError, match="yade: not found on PATH"):
        yade.run_deck(folder, tmp_path / "out")
    assert not (tmp_path / "out").exists()


# -- polyhedra ------------------------------------------------------------------------------------------------
def test_polyhedra_incline_slides_as_analytical(tmp_path):
    """cases/scenes/dda_incline.toml in YADE Polyhedra: the block slides 1/2 g (sin a - tan phi cos a) t^2 down the
    slope (a = 30, phi = 20 degrees), within 1 %."""
    from pathlib import Path

    from adapters.yade_poly import run_polyhedra_deck, write_polyhedra_deck

    scene = Path(__file__).resolve().parents[1] / "cases" / "scenes" / "dda_incline.toml"
    T = 0.3
    info = write_polyhedra_deck(scene, tmp_path / "deck", duration=T, record_every=0.05)
    res = run_polyhedra_deck(tmp_path / "deck", tmp_path / "out")
    assert res.engine == "yade-polyhedra" and res.complete and info["n"] == 2
    a = math.radians(30.0)
    down = np.array([math.cos(a), 0.0, -math.sin(a)])  # the generator's slope descends toward +x
    s = (res.final_pos[1] - res.x0[1]) @ down
    ref = 0.5 * G * (math.sin(a) - math.tan(math.radians(20.0)) * math.cos(a)) * res.time[-1] ** 2
    assert s == pytest.approx(ref, rel=0.01)
    assert np.allclose(res.final_pos[0], res.x0[0])  # the base is fixed
    assert res.pos.shape == (len(res.time), 2, 3) and len(res.bond_intact) == 0
    mass = 2600.0 * 1.0
    v = G * (math.sin(a) - math.tan(math.radians(20.0)) * math.cos(a)) * res.time[-1]
    assert res.series["kinetic"][-1] == pytest.approx(0.5 * mass * v * v, rel=0.02)


def test_polyhedra_deck_refuses_what_it_cannot_run(tmp_path):
    """Prescribed blocks and point loads have no counterpart in the polyhedra deck: one-line SceneError before
    anything is written; a folder that is no deck gives EngineError."""
    from adapters.yade_poly import run_polyhedra_deck, write_polyhedra_deck
    from sgim.scene import SceneError

    base = """name = "x"
[simulation]
duration = 0.1
[contact]
kn = 1e9
[[block]]
shape = "cube"
size = 1.0
fixed = true
[[block]]
name = "b"
shape = "cube"
size = 1.0
center = [0.0, 0.0, 1.0]
"""
    for extra, key in (("prescribed = true\nvelocity = [1.0, 0.0, 0.0]\n", "prescribed"),
                       ("[[load]]\nblock = \"b\"\nforce = [1.0, 0.0, 0.0]\n", "load")):
        scene = tmp_path / f"{key}.toml"
        scene.write_text(base + extra)
        with pytest.raises(SceneError, match=key) as exc:
            write_polyhedra_deck(scene, tmp_path / key)
        assert "\n" not in str(exc.value) and not (tmp_path / key).exists()
    with pytest.raises(EngineError, match="not a YADE polyhedra deck"):
        run_polyhedra_deck(tmp_path, tmp_path / "out")
