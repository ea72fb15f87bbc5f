"""LIGGGHTS adapter (adapters/liggghts.py): decks checked by an independent reader of the data file, and real
LIGGGHTS runs against analytical values (free fall, a bond breaking in tension, a jointed hanging column),
lost particles, engine errors, time limits, MPI, and the sjkr / clumps variants."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from adapters import liggghts
from adapters.process import EngineError
from adapters.result import RunResult
from adapters.spec import from_model
from engine_runs import G, hand_run, require_engine


require_engine("liggghts", module=True)


def deck(run, path, variant="bonds"):
    path.mkdir(parents=True, exist_ok=True)
    run.save(path / "run.npz")
    info = liggghts.write_deck(run, path, variant=variant)
    (path / "deck.json").write_text(json.dumps({"engine": "liggghts", **info}))
    return path


def column_model(joint=True):
    """FCC block 0.4 x 0.4 x 0.6 m (r = 0.05) with a horizontal through-going joint at z = 0.3 (or none)."""
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    data = {"name": "column", "domain": {"min": [0, 0, 0], "max": [0.4, 0.4, 0.6]},
            "packing": {"kind": "fcc", "radius": 0.05}}
    if joint:
        data["discontinuity"] = [{"name": "j", "centre": [0.2, 0.2, 0.3], "normal": [0, 0, 1], "radius": 5.0}]
    return build_model(scene_from_dict(data))


def column_run(duration=0.1, **kw):
    model = column_model()
    fixed = model.centers[:, 2] > model.centers[:, 2].max() - 0.01
    run = from_model(model, kn=1e7, fixed=fixed, duration=duration, record_every=duration / 5, **kw)
    return model, run


# -- deck ---------------------------------------------------------------------------------------------------
def parse_data(path):
    """Independent reader: header counts, Atoms rows, Bond Coeffs rows, Bonds rows of a LIGGGHTS data file."""
    head, sections, cur = {}, {}, None
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line:
            continue
        if line in ("Atoms", "Bonds", "Bond Coeffs"):
            cur = line
            sections[cur] = []
            continue
        if cur is None:
            parts = line.split()
            if len(parts) >= 2 and parts[-1] in ("atoms", "bonds") or line.endswith("types"):
                head[" ".join(parts[1:])] = int(parts[0])
            continue
        sections[cur].append([float(x) for x in line.split()])
    return head, {k: np.array(v) for k, v in sections.items()}


def test_deck_holds_exactly_the_runs_bonds(tmp_path):
    model, run = column_run()
    assert run.n_bonds > 100 and len(run.cut_i) > 10
    deck(run, tmp_path / "d")
    head, sec = parse_data(tmp_path / "d" / "data")
    assert head["atoms"] == run.n and head["bonds"] == run.n_bonds and head["bond types"] == run.n_bonds
    atoms = sec["Atoms"]
    assert np.array_equal(atoms[:, 0], np.arange(1, run.n + 1))
    assert np.array_equal(atoms[:, 2:5], run.centers)                       # full precision
    # contact diameters 2 r (1 - 1e-3) keep bonded neighbours clear of the granular contact; masses are kept
    assert np.allclose(atoms[:, 5], 2 * run.radii * (1 - 1e-3), rtol=1e-15, atol=0)
    mass = atoms[:, 6] * np.pi / 6 * atoms[:, 5] ** 3
    assert np.allclose(mass, run.density * 4 / 3 * np.pi * run.radii ** 3, rtol=1e-12, atol=0)
    bonds = sec["Bonds"].astype(np.int64)
    # one type per bond, and the set of bonded pairs is the run's bond set, nothing more
    assert len(np.unique(bonds[:, 1])) == len(bonds)
    got = {(min(a, b) - 1, max(a, b) - 1) for a, b in bonds[:, 2:4]}
    want = set(zip(run.bond_i.tolist(), run.bond_j.tolist()))
    assert got == want
    # cut pairs (the joint) carry no bond
    assert not ({tuple(p) for p in np.c_[run.cut_i, run.cut_j].tolist()} & got)
    coeff = {int(t): (k, r0) for t, k, r0 in sec["Bond Coeffs"]}
    key = {(min(a, b) - 1, max(a, b) - 1): t for _, t, a, b in bonds}
    for k in range(run.n_bonds):
        K, r0 = coeff[key[(run.bond_i[k], run.bond_j[k])]]
        assert K == run.bond_kn[k] / 2 and r0 == run.bond_len0[k]
    text = (tmp_path / "d" / "in").read_text()
    for needed in ("atom_style hybrid granular molecular", "bond_style harmonic", "units si", "newton off",
                   "communicate single vel yes", "hooke/stiffness", f"timestep {run.dt:.17g}"):
        assert needed in text


# -- runs -----------------------------------------------------------------------------------------------
def test_free_fall_matches_half_g_t2(tmp_path):
    run = hand_run([[0, 0, 0]], 0.05, dt=1e-4, duration=0.2, record_every=0.02)
    res = liggghts.run_deck(deck(run, tmp_path / "d"), tmp_path / "out")
    assert res.complete and res.engine == "liggghts"
    t = res.time
    assert len(t) == 11 and np.allclose(t, np.linspace(0, 0.2, 11))
    z = res.pos[:, 0, 2]
    assert np.allclose(z, -0.5 * G * t ** 2, rtol=1e-9, atol=1e-12)
    assert np.allclose(res.final_vel[0], [0, 0, -G * 0.2], rtol=1e-9)
    m = 2600.0 * 4 / 3 * math.pi * 0.05 ** 3  # hand_run's density
    assert np.allclose(res.series["kinetic"], 0.5 * m * (G * t) ** 2, rtol=1e-9)
    back = RunResult.load(tmp_path / "out")
    assert back.status == "complete" and np.array_equal(back.final_pos, res.final_pos)


@pytest.mark.parametrize("nprocs", [1, 2])
def test_bond_breaks_in_tension_when_force_exceeds_strength(tmp_path, nprocs):
    """Two pendulums hung from fixed spheres on bonds: undamped, the extension is x(t) = (m g / k)(1 - cos wt)
    (max 2 m g / k). Bond 0 (ft = 1.5 m g) must break when k x first exceeds ft (w t = 2 pi / 3); bond 1
    (ft = 2.5 m g) never."""
    r, kn, rho = 0.05, 1e5, 2000.0
    m = rho * 4 / 3 * math.pi * r ** 3
    w = math.sqrt(kn / m)
    dt = 0.002 / w
    t_break = (2 * math.pi / 3) / w
    run = hand_run([[0, 0, 0], [0, 0, -2 * r], [1, 0, 0], [1, 0, -2 * r]], r, fixed=(0, 2),
                   bonds=[(0, 1), (2, 3)], kn=kn, ft=[1.5 * m * G, 2.5 * m * G], dt=dt, duration=1.6 * t_break,
                   record_every=dt, density=rho, liggghts_check_steps=1)
    run.kn = 1e3  # the contact spring: irrelevant here (the pairs only separate)
    res = liggghts.run_deck(deck(run, tmp_path / "d"), tmp_path / "out", np=nprocs)
    assert res.complete
    assert res.bond_intact.tolist() == [False, True]
    drop = np.flatnonzero(res.series["bonds_intact"] < 2)[0]
    k_exact = math.ceil(t_break / dt)
    assert abs(drop - k_exact) <= 2, (drop, k_exact)
    # after the break the sphere flies free: it ends well below the one still hanging
    ext = -(res.pos[:, 3, 2] - res.pos[0, 3, 2])
    assert ext.max() <= 2 * m * G / kn * 1.001 and ext.max() >= 2 * m * G / kn * 0.99
    assert res.final_pos[1, 2] < res.final_pos[3, 2] - 0.5 * m * G / kn
    assert "Deleting bonds" in (tmp_path / "out" / "liggghts.log").read_text()


def test_hanging_jointed_column_part_below_joint_falls(tmp_path):
    model, run = column_run()
    res = liggghts.run_deck(deck(run, tmp_path / "d"), tmp_path / "out")
    assert res.complete and res.bond_intact.all()
    below = model.centers[:, 2] < 0.3
    d = res.displacement()
    fall = 0.5 * G * run.duration ** 2
    assert np.all(np.abs(d[below, 2] + fall) < 0.05 * fall)      # falls freely (bonded: together)
    assert np.all(np.linalg.norm(d[~below], axis=1) < 0.05 * fall)  # the rest hangs (elastic sag only)
    assert res.series["atoms"].tolist() == [run.n] * len(res.time)


def test_lost_particle_is_detected(tmp_path):
    run = hand_run([[0, 0, 0], [0.5, 0, 0]], 0.05, fixed=(1,), dt=1e-4, duration=0.5, record_every=0.05,
                   liggghts_box_margin=0.01)
    with pytest.raises(EngineError, match="lost 1 of 2 particles") as exc:
        liggghts.run_deck(deck(run, tmp_path / "d"), tmp_path / "out")
    res = exc.value.result
    assert res is not None and res.status == "incomplete" and "lost" in res.message
    assert RunResult.load(tmp_path / "out").status == "incomplete"
    # the last good record: the sphere still inside the box (fell less than margin + radius + 0.05 m)
    assert 0 < len(res.time) < 11 and res.final_pos[0, 2] > -0.5 * G * 0.5 ** 2


def test_engine_error_mid_run_carries_liggghts_error_line(tmp_path):
    """A bonded pair falling out of the box: the lower sphere leaves first and LIGGGHTS stops with its own
    'Bond atoms missing' error."""
    run = hand_run([[0, 0, 0], [0, 0, -0.1], [0.5, 0, 0]], 0.05, fixed=(2,), bonds=[(0, 1)], kn=1e5, dt=1e-4,
                   duration=0.5, record_every=0.05, liggghts_box_margin=0.01)
    with pytest.raises(EngineError) as exc:
        liggghts.run_deck(deck(run, tmp_path / "d"), tmp_path / "out")
    msg = str(exc.value)
    assert "ERROR" in msg and "Bond atoms" in msg, msg
    assert exc.value.result.status == "incomplete"


def test_time_limit_gives_incomplete_result(tmp_path):
    run = hand_run([[0, 0, 0]], 0.05, dt=1e-7, duration=1.0, record_every=0.01)
    with pytest.raises(EngineError, match="time limit") as exc:
        liggghts.run_deck(deck(run, tmp_path / "d"), tmp_path / "out", timeout=2)
    res = exc.value.result
    assert res.status == "incomplete" and res.steps < run.steps
    assert RunResult.load(tmp_path / "out").status == "incomplete"


def test_missing_engine_fails_before_anything_starts(tmp_path, monkeypatch):
    run = hand_run([[0, 0, 0]], 0.05)
    d = deck(run, tmp_path / "d")
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    with pytest.raises(EngineError, match="liggghts: not found on PATH"):
        liggghts.run_deck(d, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_mpi_two_ranks_match_one_rank(tmp_path):
    model, run = column_run(duration=0.04)
    d = deck(run, tmp_path / "d")
    r1 = liggghts.run_deck(d, tmp_path / "o1", np=1)
    r2 = liggghts.run_deck(d, tmp_path / "o2", np=2)
    assert r1.complete and r2.complete
    assert "2 procs" in (tmp_path / "o2" / "liggghts.log").read_text()
    assert np.allclose(r2.final_pos, r1.final_pos, rtol=0, atol=1e-10)
    assert np.allclose(r2.final_vel, r1.final_vel, rtol=0, atol=1e-8)


def test_clumps_jointed_column_falls_apart_as_two_rigid_bodies(tmp_path):
    model, run = column_run()
    d = deck(run, tmp_path / "d", variant="clumps")
    assert "fix bodies clump rigid molecule" in (d / "in").read_text()
    res = liggghts.run_deck(d, tmp_path / "out")
    assert res.complete
    below = model.centers[:, 2] < 0.3
    disp = res.displacement()
    fall = 0.5 * G * run.duration ** 2
    # the lower body translates rigidly (one displacement for all its spheres) in free fall; the upper body
    # holds a fixed sphere: it does not move
    assert np.ptp(disp[below], axis=0).max() < 1e-12
    assert np.allclose(disp[below], [0, 0, -fall], rtol=0, atol=1e-3 * fall)
    assert np.all(disp[~below] == 0.0)


def test_sjkr_colour_rule_cohesion_holds_intact_drops_across_joint(tmp_path):
    model, run = column_run()
    d = deck(run, tmp_path / "d", variant="sjkr")
    assert "cohesion sjkr" in (d / "in").read_text()
    res = liggghts.run_deck(d, tmp_path / "out")
    assert res.complete
    below = model.centers[:, 2] < 0.3
    drop = -res.displacement()[:, 2]
    fall = 0.5 * G * run.duration ** 2
    assert np.all(drop[below] > 0.8 * fall)
    assert np.all(drop[~below] < 0.3 * fall)


def test_cohesion_matrix_is_the_colour_rule():
    coh = liggghts.cohesion_matrix()
    names = ("intact", "red", "green", "blue")
    for a in range(8):
        for b in range(8):
            ca, cb = names[a % 4], names[b % 4]
            cut = "red" in (ca, cb) or {ca, cb} == {"green", "blue"}
            assert coh[a, b] == (not cut)
