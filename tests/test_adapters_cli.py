"""`adapters export` / `adapters run` on the command line: every target, real engine runs, and bad input.

References: the sgim model itself (its spheres and bonded pairs), read back from the exported files by meshio
or by parsing the text; the engines' runs are checked for their status and contract (one line, exit status,
partial results kept), their physics in tests/test_adapters_{yade,liggghts,inhouse}.py and tests/test_crossval.py.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from adapters.result import RunResult
from engine_runs import require_engine
from sgim.builder import build_model
from sgim.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
HANG = ROOT / "cases" / "scenes" / "crossval" / "hang_joint.toml"
MODEL = ROOT / "cases" / "scenes" / "crossval" / "hang_joint_model.toml"


def cli(*args, env=None):
    return subprocess.run([sys.executable, "-m", "adapters.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=600)


@pytest.fixture(scope="module")
def model():
    return build_model(load_scene(MODEL))


def test_export_vtu_holds_the_models_spheres_and_bonded_pairs(tmp_path, model):
    r = cli("export", HANG, "--to", "vtu", "-o", tmp_path / "v", "--quiet")
    assert r.returncode == 0, r.stderr
    pts = meshio.read(tmp_path / "v" / "spheres.vtu")
    assert np.array_equal(pts.points, model.centers)
    assert np.array_equal(pts.point_data["radius"], model.radii)
    lines = meshio.read(tmp_path / "v" / "bonds.vtu").cells_dict["line"]
    want = {tuple(p) for p in np.asarray(model.bonds)[np.asarray(model.bonded, bool)].tolist()}
    assert {tuple(sorted(p)) for p in lines.tolist()} == want
    info = json.loads((tmp_path / "v" / "deck.json").read_text())
    assert info["engine"] == "vtu" and info["n"] == model.n and info["n_bonds"] == len(want)


def test_export_pfc_text_lists_every_ball_and_contact(tmp_path, model):
    r = cli("export", MODEL, "--to", "pfc-text", "-o", tmp_path / "p", "--quiet")
    assert r.returncode == 0, r.stderr
    balls = np.loadtxt(tmp_path / "p" / "balls.txt")
    contacts = np.loadtxt(tmp_path / "p" / "contacts.txt", dtype=np.int64)
    assert np.array_equal(balls[:, 1:4], model.centers) and np.array_equal(balls[:, 5], model.colour)
    assert np.array_equal(contacts[:, :2] - 1, model.bonds)
    assert np.array_equal(contacts[:, 2].astype(bool), model.bonded)


@pytest.mark.parametrize("engine", ["yade", "liggghts"])
def test_export_and_run_each_engine(tmp_path, engine):
    require_engine(engine)
    deck = tmp_path / engine
    r = cli("export", HANG, "--to", engine, "-o", deck, "--duration", "0.01", "--quiet")
    assert r.returncode == 0, r.stderr
    info = json.loads((deck / "deck.json").read_text())
    assert info["engine"] == engine and info["n_joints"] > 0
    r = cli("run", deck, "--json", "--quiet")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    res = RunResult.load(deck / "result")
    assert summary["status"] == res.status == "complete" and res.engine == engine
    assert res.steps == info["steps"] and res.n == info["n"]
    # 0.01 s of gravity: the fixed top does not move; the spheres that no bond ties to it (bond graph) fall
    # 1/2 g t^2 (times 0.8 where Cundall's local damping 0.2 acts: YADE), the others hold
    from adapters.spec import SphereRun
    from cases.lib.crossval import detached_reference

    run = SphereRun.load(deck / "run.npz")
    loose = detached_reference(run)
    assert 0 < loose.sum() < run.n
    dz = -res.displacement()[:, 2]
    assert np.all(res.displacement()[run.fixed] == 0.0)
    free_fall = 0.5 * 9.81 * run.steps * run.dt * run.steps * run.dt
    assert np.all((dz[loose] > 0.75 * free_fall) & (dz[loose] < 1.01 * free_fall))
    assert np.all(np.abs(dz[~loose]) < 0.25 * free_fall)  # the held part sags elastically (undamped: twice)


def test_run_in_house_from_a_deck(tmp_path):
    require_engine("liggghts")
    deck = tmp_path / "d"
    assert cli("export", HANG, "--to", "liggghts", "-o", deck, "--duration", "0.005", "--quiet").returncode == 0
    r = cli("run", deck, "--in-house", "--json", "--quiet")
    assert r.returncode == 0, r.stderr
    assert RunResult.load(deck / "result-dda").engine == "dda"


def test_bad_input_one_line_and_nothing_left(tmp_path):
    empty = tmp_path / "empty.toml"
    empty.write_text('name = "empty"\n[domain]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\n[packing]\nkind = "cubic"\n'
                     'radius = 0.1\n[[cavity]]\nshape = "box"\nmin = [-1, -1, -1]\nmax = [2, 2, 2]\n')
    cases = [
        (("export", empty, "--to", "yade", "-o", tmp_path / "a"), "the model has no spheres"),
        (("export", HANG, "--to", "abaqus", "-o", tmp_path / "b"), "unknown target 'abaqus'"),
        (("export", ROOT / "cases" / "scenes" / "dda_incline.toml", "--to", "liggghts", "-o", tmp_path / "c"),
         "exports to yade (Polyhedra) only"),
        (("export", tmp_path / "nope.npz", "--to", "yade", "-o", tmp_path / "d"), "no such file"),
        (("export", HANG, "--to", "yade", "-o", tmp_path / "e", "--duration", "-1"), "--duration must be > 0"),
        (("run", tmp_path), "not a deck folder"),
    ]
    for args, words in cases:
        r = cli(*args)
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and words in lines[0], (args, r.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.toml"]


@pytest.mark.parametrize("engine", ["yade", "liggghts"])
def test_engine_missing_from_path(tmp_path, engine):
    require_engine(engine)
    deck = tmp_path / "d"
    assert cli("export", HANG, "--to", engine, "-o", deck, "--duration", "0.005", "--quiet").returncode == 0
    env = dict(os.environ, PATH=str(Path(sys.executable).parent))  # python, but no engines
    r = cli("run", deck, env=env)
    assert r.returncode == 3
    assert f"{engine}: not found on PATH" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (deck / "result").exists()


@pytest.mark.parametrize("engine", ["yade", "liggghts"])
def test_time_limit_keeps_partial_results(tmp_path, engine):
    require_engine(engine)
    deck = tmp_path / "d"
    assert cli("export", HANG, "--to", engine, "-o", deck, "--duration", "20", "--quiet").returncode == 0
    r = cli("run", deck, "--timeout", "6", "--quiet")
    assert r.returncode == 3
    assert "time limit" in r.stderr and "partial results kept" in r.stderr
    res = RunResult.load(deck / "result")
    assert res.status == "incomplete" and "time limit" in res.message


def test_engine_error_mid_run_is_surfaced(tmp_path):
    require_engine("liggghts")
    deck = tmp_path / "d"
    assert cli("export", HANG, "--to", "liggghts", "-o", deck, "--duration", "0.005", "--quiet").returncode == 0
    with open(deck / "in", "a") as fh:
        fh.write("\nno_such_command_xyz\n")
    r = cli("run", deck, "--quiet")
    assert r.returncode == 3
    assert "ERROR: Unknown command: no_such_command_xyz" in r.stderr.splitlines()[0]
    assert RunResult.load(deck / "result").status == "incomplete"


def test_an_engine_dies_with_a_killed_caller(tmp_path):
    # a caller (e.g. a study case past its time limit) started an engine and is killed with SIGKILL: the engine
    # must not live on (PR_SET_PDEATHSIG in adapters.process.die_with_parent)
    import signal
    import time

    pidfile = tmp_path / "engine.pid"
    caller = subprocess.Popen([sys.executable, "-c", (
        "import sys; from adapters.process import run_process; "
        f"run_process(['sh', '-c', 'echo $$ > {pidfile}; exec sleep 60'], '.', '{tmp_path / 'log'}', timeout=120)")],
        cwd=ROOT)
    for _ in range(200):
        if pidfile.exists() and pidfile.read_text().strip():
            break
        time.sleep(0.05)
    engine = int(pidfile.read_text())

    def alive(pid):  # a zombie waiting for its new parent to reap it counts as dead
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except (FileNotFoundError, IndexError):
            return False

    assert alive(engine)
    caller.send_signal(signal.SIGKILL)
    caller.wait()
    for _ in range(100):
        if not alive(engine):
            break
        time.sleep(0.05)
    else:
        os.kill(engine, signal.SIGKILL)
        raise AssertionError("the engine outlived its killed caller")
