"""Batch studies (cases/study.py, cases/_batch.py): parsing and sampling against transcriptions of the
definitions, the results table under faults (a case that raises, hangs, is killed; a rank killed; the whole job
killed and started again), serial against `mpirun -n 2`, bad input."""
from __future__ import annotations

import csv
import fcntl
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cases.study import dump_toml, load_study, main
from engine_runs import CI

REPO = Path(__file__).resolve().parent.parent

BASE = """\
name = "base"
[contact]
kn = 1e10
friction = 18.0
damping = 0.1
mode = "ok"
flag = true
[[generate]]
kind = "wedge"
joint_a = [45.0, 5.0]
height = 10.0
[dfn]
seed = 7
[[joint_set]]
name = "J1"
dip = 60.0
dip_direction = 200.0
"""

# evaluators for the fault tests (imported by the case processes from the study's folder)
PLUGIN = '''
import os, signal, time
from pathlib import Path
import numpy as np
from cases.study import Evaluator

def faulty(scene_path, case_dir, params):
    mode = params.get("contact.mode", "ok")
    out = Path(case_dir).parent.parent
    if mode == "raise":
        raise ValueError("friction out of range\\nsecond line")
    if mode == "hang":
        time.sleep(600)
    if mode == "kill_once":
        marker = out / ("killed_" + Path(case_dir).name)
        if not marker.exists():
            marker.write_text("x")
            os.kill(os.getpid(), signal.SIGKILL)
    if mode == "kill_always":
        os.kill(os.getpid(), signal.SIGKILL)
    if os.environ.get("ROCKDEM_STUDY_RANK") == "1" and (out.parent / "kill_rank_1").exists():
        (out.parent / "kill_rank_1").unlink()
        os.kill(int(os.environ["ROCKDEM_STUDY_PARENT"]), signal.SIGKILL)
    time.sleep(float(params.get("contact.damping", 0.0)))
    x = float(params["contact.friction"])
    value = float(np.sum(np.sin(np.arange(1, 2001) * x) / np.arange(1, 2001)))
    return {"value": value, "twice": 2.0 * x, "mode_len": len(mode)}

missing = Evaluator(faulty, needs=("rockdem-no-such-engine",), description="needs an engine nobody has")
'''


def write_study(folder, body, base=BASE):
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.toml").write_text(base)
    (folder / "study_plugin.py").write_text(PLUGIN)
    path = folder / "study.toml"
    path.write_text(textwrap.dedent(body))
    return path


def read_table(outdir):
    with open(Path(outdir) / "results.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def mpirun_cmd(n):
    exe = shutil.which("mpirun")
    try:
        import mpi4py  # noqa: F401

        have = exe is not None
    except ImportError:
        have = False
    if not have:
        if CI:
            pytest.fail("mpirun and mpi4py are required (CI=true)")
        pytest.skip("mpirun or mpi4py not installed")
    cmd = [exe, "--oversubscribe", "-n", str(n)]
    if os.geteuid() == 0:
        cmd.insert(1, "--allow-run-as-root")
    return cmd


def cli(*args):
    return [sys.executable, "-m", "cases.cli", "study", *map(str, args)]


def run_mpi(n, *args, timeout=120):
    return subprocess.run(mpirun_cmd(n) + cli(*args), cwd=REPO, capture_output=True, text=True, timeout=timeout)


# --------------------------------------------------------------------------------------------- parsing, sampling
def test_grid_product_order_ids_and_case_scene(tmp_path):
    path = write_study(tmp_path, """
        base = "base.toml"
        engine = "noop"
        results = ["value"]
        [parameters]
        "contact.friction" = { grid = [15.0, 20.0, 25.0] }
        "contact.mode" = { list = ["a", "b"] }
        "generate.0.height" = { grid = [5, 7.5] }
    """)
    study = load_study(path)
    expected = []
    for f in (15.0, 20.0, 25.0):
        for m in ("a", "b"):
            for h in (5, 7.5):
                expected.append({"contact.friction": f, "contact.mode": m, "generate.0.height": h})
    assert [c.params for c in study.cases] == expected
    assert [c.case_id for c in study.cases] == [f"c{i:05d}" for i in range(12)]
    base = tomllib.loads(BASE)
    c = study.cases[7]
    scene = tomllib.loads(study.case_scene_text(c))
    base["contact"]["friction"] = expected[7]["contact.friction"]
    base["contact"]["mode"] = expected[7]["contact.mode"]
    base["generate"][0]["height"] = expected[7]["generate.0.height"]
    assert scene == base


def _phi(z):
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def test_latin_hypercube_one_sample_per_stratum(tmp_path):
    n = 40
    path = write_study(tmp_path, f"""
        base = "base.toml"
        engine = "noop"
        seed = 11
        [parameters]
        "contact.friction" = {{ uniform = [20.0, 35.0] }}
        "contact.damping" = {{ normal = [0.1, 0.02] }}
        "generate.0.joint_a" = {{ fisher = {{ dip = 45.0, dip_direction = 5.0, kappa = 30.0 }} }}
        [sampling]
        method = "lhs"
        samples = {n}
    """)
    cases = load_study(path).cases
    assert len(cases) == n
    fr = np.array([c.params["contact.friction"] for c in cases])
    dm = np.array([c.params["contact.damping"] for c in cases])
    assert sorted(np.floor((fr - 20.0) / 15.0 * n).astype(int)) == list(range(n))
    assert sorted(int(_phi((x - 0.1) / 0.02) * n) for x in dm) == list(range(n))
    # the Fisher angle from the mean pole through its distribution function, and the azimuth: one per stratum
    k = 30.0
    m = _pole(45.0, 5.0)
    poles = np.array([_pole(*c.params["generate.0.joint_a"]) for c in cases])
    cos_t = np.clip(poles @ m, -1, 1)
    cdf = (1 - np.exp(-k * (1 - cos_t))) / (1 - np.exp(-2 * k))
    assert sorted(np.floor(cdf * n + 1e-9).astype(int)) == list(range(n))


def _pole(dip, dd):
    d, a = math.radians(dip), math.radians(dd)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def test_fisher_samples_mean_direction_and_concentration(tmp_path):
    n, k = 3000, 20.0
    path = write_study(tmp_path, f"""
        base = "base.toml"
        engine = "noop"
        seed = 5
        [parameters]
        "joint_set.0" = {{ fisher = {{ dip = 30.0, dip_direction = 120.0, kappa = {k} }} }}
        [sampling]
        samples = {n}
    """)
    study = load_study(path)
    assert study.method == "random"
    poles = np.array([_pole(c.params["joint_set.0"]["dip"], c.params["joint_set.0"]["dip_direction"])
                      for c in study.cases])
    mean = poles.mean(axis=0)
    r = np.linalg.norm(mean)
    angle = math.degrees(math.acos(min(1.0, float(mean @ _pole(30.0, 120.0)) / r)))
    assert angle < 1.0  # sd of the mean direction about 1/sqrt(kappa n) = 0.23 degrees
    assert abs(r - (1 / math.tanh(k) - 1 / k)) < 0.005  # mean resultant length of the Fisher distribution
    # the orientation table gets both keys, the other keys stay
    scene = tomllib.loads(study.case_scene_text(study.cases[3]))
    assert scene["joint_set"][0]["name"] == "J1"
    assert scene["joint_set"][0]["dip"] == study.cases[3].params["joint_set.0"]["dip"]


def test_same_seed_same_cases_and_realisations(tmp_path):
    body = """
        base = "base.toml"
        engine = "noop"
        seed = {seed}
        [parameters]
        "dfn.seed" = {{ realisations = 25 }}
        "contact.friction" = {{ uniform = [10.0, 40.0] }}
        [sampling]
        method = "random"
        samples = 3
    """
    a = load_study(write_study(tmp_path / "a", body.format(seed=1))).cases
    b = load_study(write_study(tmp_path / "b", body.format(seed=1))).cases
    c = load_study(write_study(tmp_path / "c", body.format(seed=2))).cases
    assert [(x.case_id, x.params) for x in a] == [(x.case_id, x.params) for x in b]
    assert [x.params for x in a] != [x.params for x in c]
    assert len(a) == 75
    seeds = [x.params["dfn.seed"] for x in a]
    assert all(isinstance(s, int) and s > 0 for s in seeds)
    assert len(set(seeds)) == 25
    assert seeds[:3] == [seeds[0]] * 3  # the realisations are an axis, the samples inner
    assert [x.params["contact.friction"] for x in a[:3]] == [x.params["contact.friction"] for x in a[3:6]]


def test_toml_writer_round_trips_the_scene_files():
    files = [REPO / "cases" / "dda_wedge.toml", REPO / "cases" / "open_pit_dfn.toml",
             *sorted((REPO / "cases" / "crossval").glob("*.toml"))]
    for f in files:
        data = tomllib.loads(f.read_text())
        assert tomllib.loads(dump_toml(data)) == data, f
    odd = {"a.b": 0.1 + 0.2, "t": {"x y": [1e-300, -0.0, 5e300], "s": 'q"\\\n\u00e9'},
           "aot": [{"k": 1, "sub": {"v": [[1, 2], [3]]}}, {"k": 2}], "inline": [{"a": 1}, 2]}
    back = tomllib.loads(dump_toml(odd))
    assert back == odd and math.copysign(1, back["t"]["x y"][1]) == -1


# --------------------------------------------------------------------------------------------- bad input
BAD = {
    "unknown path": ('"contact.frictio" = { grid = [1.0] }', "", "contact.frictio", "unknown parameter path"),
    "unknown index": ('"generate.3.height" = { grid = [1.0] }', "", "generate.3.height", "unknown parameter path"),
    "empty grid": ('"contact.friction" = { grid = [] }', "", "contact.friction", "empty"),
    "empty range": ('"contact.friction" = { uniform = [20.0, 20.0] }', "samples = 4", "contact.friction",
                    "empty range"),
    "zero samples": ('"contact.friction" = { uniform = [10.0, 20.0] }', "samples = 0", "sampling.samples", "> 0"),
    "negative samples": ('"contact.friction" = { uniform = [10.0, 20.0] }', "samples = -3", "sampling.samples",
                         "> 0"),
    "zero realisations": ('"dfn.seed" = { realisations = 0 }', "", "dfn.seed", "> 0"),
    "fisher on a number": ('"contact.kn" = { fisher = { dip = 10.0, dip_direction = 0.0, kappa = 5.0 } }',
                           "samples = 2", "contact.kn", "orientation"),
    "type mismatch": ('"contact.friction" = { list = ["high"] }', "", "contact.friction", "does not fit"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_parameters_one_line_nothing_started(tmp_path, capsys, name):
    param, sampling, key, words = BAD[name]
    path = write_study(tmp_path, f"""
        base = "base.toml"
        engine = "noop"
        [parameters]
        {param}
        [sampling]
        {sampling}
    """.replace("\n        ", "\n"))
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(path) in err and key in err and words in err
    assert not out.exists()


@pytest.mark.parametrize("engine,words", [("nosuch", "unknown evaluator"),
                                         ("study_plugin:missing", "rockdem-no-such-engine: not found"),
                                         ("study_plugin:absent", "has no 'absent'")])
def test_unknown_or_missing_engine(tmp_path, capsys, engine, words):
    path = write_study(tmp_path, f"""
        base = "base.toml"
        engine = "{engine}"
        [parameters]
        "contact.friction" = {{ grid = [1.0] }}
    """)
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "engine" in err and words in err
    assert not out.exists()


def test_other_study_in_the_same_folder_is_refused(tmp_path, capsys):
    a = write_study(tmp_path / "a", """
        base = "base.toml"
        engine = "noop"
        results = ["value"]
        [parameters]
        "contact.friction" = { grid = [1.0, 2.0] }
    """)
    b = write_study(tmp_path / "b", """
        base = "base.toml"
        engine = "noop"
        results = ["value"]
        [parameters]
        "contact.friction" = { grid = [1.0, 3.0] }
    """)
    out = tmp_path / "out"
    assert main(["run", str(a), "-o", str(out), "--quiet"]) == 0
    before = (out / "results.csv").read_bytes()
    assert main(["run", str(b), "-o", str(out), "--quiet"]) == 2
    assert "different study" in capsys.readouterr().err
    assert (out / "results.csv").read_bytes() == before


def test_bad_input_under_mpirun_one_line(tmp_path):
    path = write_study(tmp_path, """
        base = "base.toml"
        engine = "noop"
        [parameters]
        "contact.frictio" = { grid = [1.0] }
    """)
    out = tmp_path / "out"
    r = run_mpi(2, "run", path, "-o", out)
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if "cases study: error:" in ln]
    assert len(lines) == 1 and "unknown parameter path" in lines[0]
    assert not out.exists()


# --------------------------------------------------------------------------------------------- faults
FAULT_STUDY = """
    base = "base.toml"
    engine = "study_plugin:faulty"
    results = ["value", "twice", "mode_len"]
    seed = 3
    timeout = 1.5
    [parameters]
    "contact.mode" = { list = ["ok", "raise", "hang", "kill_once", "kill_always", "ok", "ok"] }
    "contact.friction" = { uniform = [10.0, 40.0] }
    [sampling]
    method = "random"
    samples = 2
"""


def _check_fault_table(study, outdir):
    rows = read_table(outdir)
    ids = [r["case_id"] for r in rows]
    assert ids == [c.case_id for c in study.cases]  # complete, none duplicated, in case order
    jl = [json.loads(ln) for ln in (outdir / "results.jsonl").read_text().splitlines()]
    assert [r["case_id"] for r in jl] == ids
    for case, row, js in zip(study.cases, rows, jl):
        mode = case.params["contact.mode"]
        x = case.params["contact.friction"]
        assert row["p:contact.friction"] == repr(x) and js["p:contact.friction"] == x
        if mode in ("ok", "kill_once"):  # kill_once: the case process died, the case ran again
            assert row["status"] == "ok", row
            ref = sum(math.sin(i * x) / i for i in range(1, 2001))
            assert abs(float(row["value"]) - ref) < 1e-9
            assert float(row["twice"]) == 2.0 * x and js["twice"] == 2.0 * x
            assert (outdir / "cases" / case.case_id / "scene.toml").is_file()
        elif mode == "raise":
            assert row["status"] == "failed" and row["error"] == "ValueError: friction out of range"
            assert "Traceback" in (outdir / "cases" / case.case_id / "error.txt").read_text()
        elif mode == "hang":
            assert row["status"] == "timeout" and "time limit of 1.5 s" in row["error"]
        else:
            assert row["status"] == "failed" and "signal 9" in row["error"] and "2 attempts" in row["error"]
    scene = tomllib.loads((outdir / "cases" / "c00001" / "scene.toml").read_text())
    assert scene["contact"]["friction"] == study.cases[1].params["contact.friction"]
    return rows


def _strip(rows):
    return [{k: v for k, v in r.items() if k not in ("wall_s", "rank")} for r in rows]


def test_faults_serial_and_mpi_tables_identical(tmp_path):
    path = write_study(tmp_path, FAULT_STUDY)
    study = load_study(path)
    serial, parallel = tmp_path / "serial", tmp_path / "mpi"
    r = subprocess.run(cli("run", path, "-o", serial, "--quiet"), cwd=REPO, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    rows_s = _check_fault_table(study, serial)
    assert {row["rank"] for row in rows_s} == {"0"}
    r = run_mpi(2, "run", path, "-o", parallel)
    assert r.returncode == 0, r.stderr
    assert "14/14 cases done" in r.stderr  # progress on rank 0
    rows_m = _check_fault_table(study, parallel)
    assert {row["rank"] for row in rows_m} == {"0", "1"}  # rank 0 runs cases too
    assert _strip(rows_s) == _strip(rows_m)  # every value to the last digit of repr
    assert json.loads((serial / "study.json").read_text())["cases"] == \
        json.loads((parallel / "study.json").read_text())["cases"]


RESTART_STUDY = """
    base = "base.toml"
    engine = "study_plugin:faulty"
    results = ["value", "twice"]
    timeout = 30
    [parameters]
    "contact.friction" = { grid = [11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0, 18.0, 19.0, 20.0, 21.0, 22.0] }
    "contact.damping" = { list = [0.15] }
"""


def _check_complete(study, outdir):
    rows = read_table(outdir)
    assert [r["case_id"] for r in rows] == [c.case_id for c in study.cases]
    assert all(r["status"] == "ok" for r in rows), rows
    for c, r in zip(study.cases, rows):
        assert float(r["twice"]) == 2.0 * c.params["contact.friction"]
    jl = [json.loads(ln)["case_id"] for ln in (outdir / "results.jsonl").read_text().splitlines()]
    assert jl == [c.case_id for c in study.cases]
    return rows


def test_rank_killed_mid_study_then_restart(tmp_path):
    """A rank killed: Open MPI ends the job; started again, the study completes with no case lost or doubled."""
    path = write_study(tmp_path, RESTART_STUDY)
    study = load_study(path)
    out = tmp_path / "out"
    # beside the output folder (a study writes only into a new, empty or its own folder): the first case on
    # rank 1 kills rank 1
    (tmp_path / "kill_rank_1").write_text("x")
    r = run_mpi(2, "run", path, "-o", out, "--quiet")
    assert r.returncode != 0
    assert not (tmp_path / "kill_rank_1").exists()
    first = {row["case_id"]: row for row in read_table(out)}
    assert len(first) < len(study.cases)
    _wait_unlocked(out)
    r = run_mpi(2, "run", path, "-o", out, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = _check_complete(study, out)
    for row in rows:  # the rows of the first run are kept as they were
        if row["case_id"] in first:
            assert row == first[row["case_id"]]


def _wait_unlocked(out, limit=20.0):
    t0 = time.time()
    with open(out / ".lock", "a+") as fh:
        while True:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
                return
            except OSError:
                assert time.time() - t0 < limit, "the killed job's ranks did not stop"
                time.sleep(0.1)


def test_whole_job_killed_then_restart_with_torn_line(tmp_path):
    path = write_study(tmp_path, RESTART_STUDY)
    study = load_study(path)
    out = tmp_path / "out"
    p = subprocess.Popen(mpirun_cmd(2) + cli("run", path, "-o", out, "--quiet"), cwd=REPO,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    t0 = time.time()
    while time.time() - t0 < 60:
        if (out / "results.csv").exists() and len(read_table(out)) >= 3:
            break
        time.sleep(0.02)
    os.killpg(p.pid, signal.SIGKILL)  # mpirun and everything in its group, mid-study
    p.wait()
    _wait_unlocked(out)  # the ranks notice that mpirun has gone and stop
    first = read_table(out)
    assert 3 <= len(first) < len(study.cases)
    # a crash inside a write leaves a torn last line: it is dropped, the case runs again
    with open(out / "results.csv", "a") as fh:
        fh.write("c00011,ok,,0.1,0,11.0,0.")
    with open(out / "results.jsonl", "a") as fh:
        fh.write('{"case_id": "c00011", "status": "ok"}\n{"case_id": "c0001')
    r = subprocess.run(cli("run", path, "-o", out), cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"{len(first)} already in" in r.stderr
    rows = _check_complete(study, out)
    before = {row["case_id"]: row for row in first}
    assert {row["case_id"]: row for row in rows if row["case_id"] in before} == before  # kept, not run again


def test_retry_failed_runs_only_failed_cases(tmp_path):
    path = write_study(tmp_path, """
        base = "base.toml"
        engine = "study_plugin:faulty"
        results = ["twice"]
        [parameters]
        "contact.mode" = { list = ["ok", "raise"] }
        "contact.friction" = { grid = [1.0, 2.0] }
    """)
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--quiet"]) == 0
    rows = read_table(out)
    assert [r["status"] for r in rows] == ["ok", "ok", "failed", "failed"]
    assert main(["run", str(path), "-o", str(out), "--quiet", "--retry-failed"]) == 0
    again = read_table(out)
    assert again[:2] == rows[:2]  # finished cases untouched
    assert [r["case_id"] for r in again] == ["c00000", "c00001", "c00002", "c00003"]
    assert [r["status"] for r in again] == ["ok", "ok", "failed", "failed"]
