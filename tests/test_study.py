"""Batch studies (cases/lib/study.py, cases/lib/_batch.py): parsing and sampling against transcriptions of the
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

from cases.lib.study import dump_toml, load_study, main
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
from cases.lib.study import Evaluator

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
        evaluator = "noop"
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
        evaluator = "noop"
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
        evaluator = "noop"
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
        evaluator = "noop"
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
    files = [REPO / "cases" / "scenes" / "dda_wedge.toml", REPO / "cases" / "scenes" / "open_pit_dfn.toml",
             *sorted((REPO / "cases" / "scenes" / "crossval").glob("*.toml"))]
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
        evaluator = "noop"
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
        evaluator = "{engine}"
        [parameters]
        "contact.friction" = {{ grid = [1.0] }}
    """)
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "evaluator" in err and words in err
    assert not out.exists()


def test_other_study_in_the_same_folder_is_refused(tmp_path, capsys):
    a = write_study(tmp_path / "a", """
        base = "base.toml"
        evaluator = "noop"
        results = ["value"]
        [parameters]
        "contact.friction" = { grid = [1.0, 2.0] }
    """)
    b = write_study(tmp_path / "b", """
        base = "base.toml"
        evaluator = "noop"
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
        evaluator = "noop"
        [parameters]
        "contact.frictio" = { grid = [1.0] }
    """)
    out = tmp_path / "out"
    r = run_mpi(2, "run", path, "-o", out)
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if "cases study: error:" in ln]
    assert len(lines) == 1 and "unknown parameter path" in lines[0]
    assert not out.exists()
    for opts, words in ((["--timeout", "inf"], "--timeout"), (["--bogus"], "--bogus")):  # once, not once per rank
        r = run_mpi(2, "run", path, "-o", out, *opts)
        lines = [ln for ln in r.stderr.splitlines() if "cases study: error:" in ln]
        assert r.returncode != 0 and len(lines) == 1 and words in lines[0], r.stderr
        assert not out.exists()


# --------------------------------------------------------------------------------------------- faults
FAULT_STUDY = """
    base = "base.toml"
    evaluator = "study_plugin:faulty"
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
    evaluator = "study_plugin:faulty"
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
        evaluator = "study_plugin:faulty"
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


# --------------------------------------------------------------------------------------------- issue 17
# 1. a text result or parameter with a line break or a Unicode line separator lost its row when results.csv was
#    rewritten (the csv writer quoted only \n, the reader split a lone \r)
TEXTS = ["sliding\u2028plane A", "a\rb", "a\nb", "a\r\nb", "x\x00y", 'q"q,', "\x85nel", "\u2029p", "\x0b\x0c\x1c\x1d\x1e",
         " lead", "trail ", "", "=1+1", "\u00e9\u20ac\U0001f600", "tab\tsep", "\\"]
TEXT_PLUGIN = f'''
TEXTS = {TEXTS!r}

def text(scene_path, case_dir, params):
    i = int(params["contact.friction"])
    if i < 0:
        return {{"label": "lone \\ud800 surrogate", "v": 0.0}}
    return {{"label": TEXTS[i], "v": float(i)}}
'''


def test_table_keeps_any_character_through_restart_and_retry(tmp_path):
    path = write_study(tmp_path, f"""
        base = "base.toml"
        evaluator = "text_plugin:text"
        results = ["label", "v"]
        [parameters]
        "contact.friction" = {{ list = {json.dumps([float(i) for i in range(-1, len(TEXTS))])} }}
        "contact.mode" = {{ list = ["mode\\u2028two\\rthree\\n"] }}
    """)
    (tmp_path / "text_plugin.py").write_text(TEXT_PLUGIN)
    out = tmp_path / "out"
    for extra in ([], [], ["--retry-failed"]):  # the run, a restart reading the table back, a rewrite (drop)
        assert main(["run", str(path), "-o", str(out), "--quiet", *extra]) == 0
        rows = read_table(out)
        assert [r["case_id"] for r in rows] == [f"c{i:05d}" for i in range(len(TEXTS) + 1)]
        assert rows[0]["status"] == "failed" and "not valid Unicode" in rows[0]["error"]
        assert [r["label"] for r in rows[1:]] == TEXTS
        assert all(r["p:contact.mode"] == "mode\u2028two\rthree\n" for r in rows)
        jl = [json.loads(ln) for ln in (out / "results.jsonl").read_text().split("\n") if ln]
        assert [r["label"] for r in jl[1:]] == TEXTS
    from cases.lib.report import read_results

    _, back = read_results(out)
    assert [r["label"] for r in back[1:] if r["label"] is not None] == [t for t in TEXTS if t.strip()]


# 2. a result named like a column of the runner overwrote it
@pytest.mark.parametrize("name", ["status", "error", "wall_s", "rank", "case_id", "p:contact.friction"])
def test_reserved_result_names_refused_on_load(tmp_path, capsys, name):
    path = write_study(tmp_path, f"""
        base = "base.toml"
        evaluator = "noop"
        results = ["value", "{name}"]
        [parameters]
        "contact.friction" = {{ grid = [1.0] }}
    """)
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "reserved name" in err and name in err
    assert not out.exists()


# 3. every case in a fresh process: a counter, a lowered limit and a crash never reach the next case; serial and
#    MPI (a hostfile naming localhost twice) tables equal
STATE_PLUGIN = '''
import os, resource
CALLS = []

def stateful(scene_path, case_dir, params):
    CALLS.append(1)
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    mode = params["contact.mode"]
    if mode == "lower":
        resource.setrlimit(resource.RLIMIT_NOFILE, (64, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))
        os.environ["LEAK"] = "yes"
    if mode == "crash":
        os.abort()
    return {"calls": len(CALLS), "nofile": soft, "leak": os.environ.get("LEAK", "no"), "pid": os.getpid()}
'''


def test_fresh_process_per_case_serial_equals_mpi_hostfile(tmp_path):
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "state_plugin:stateful"
        results = ["calls", "nofile", "leak", "pid"]
        [parameters]
        "contact.mode" = { list = ["a", "lower", "b", "crash", "c", "lower", "d", "e"] }
    """)
    (tmp_path / "state_plugin.py").write_text(STATE_PLUGIN)
    import resource

    nofile = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    serial, parallel = tmp_path / "serial", tmp_path / "mpi"
    r = subprocess.run(cli("run", path, "-o", serial, "--quiet"), cwd=REPO, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    rows = read_table(serial)
    ok = [row for row in rows if row["status"] == "ok"]
    assert len(ok) == 7 and all(row["calls"] == "1" for row in ok)
    assert [row["leak"] for row in ok] == ["no", "yes", "no", "no", "yes", "no", "no"]  # only the case that set it
    assert all(int(row["nofile"]) == nofile for row in ok)  # the lowered limit did not reach the next case
    assert len({row["pid"] for row in ok}) == 7
    crash = rows[3]
    assert crash["status"] == "failed" and "SIGABRT" in crash["error"] and "2 attempts" in crash["error"]
    hostfile = tmp_path / "hosts"
    hostfile.write_text("localhost\nlocalhost\n")
    r = subprocess.run(mpirun_cmd(2)[:1] + ["--hostfile", str(hostfile)] + mpirun_cmd(2)[1:] +
                       cli("run", path, "-o", parallel, "--quiet"), cwd=REPO, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    rows_m = read_table(parallel)
    assert {row["rank"] for row in rows_m} == {"0", "1"}

    def strip(rs):
        return [{k: v for k, v in x.items() if k not in ("wall_s", "rank", "pid")} for x in rs]

    assert strip(rows) == strip(rows_m)


# 4. the inputs changed between runs: refused with the name of what changed, unless --new-version
def test_fingerprint_refuses_changed_inputs_until_new_version(tmp_path, capsys):
    base = BASE.replace('mode = "ok"', 'mode = "ok"\nmesh = "surface.obj"')
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "study_plugin:faulty"
        results = ["twice"]
        [parameters]
        "contact.friction" = { grid = [1.0, 2.0] }
    """, base=base)
    (tmp_path / "surface.obj").write_text("v 0 0 0\n")
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--quiet"]) == 0
    table = (out / "results.csv").read_bytes()
    assert main(["run", str(path), "-o", str(out), "--quiet"]) == 0  # unchanged: a restart, nothing to do
    edits = [("base.toml", base.replace("kn = 1e10", "kn = 2e10"), "base scene changed"),
             ("surface.obj", "v 0 0 1\n", "file surface.obj changed"),
             ("study_plugin.py", PLUGIN + "\n# edited\n", "evaluator module study_plugin.py changed")]
    capsys.readouterr()
    for name, text, words in edits:
        old = (tmp_path / name).read_text()
        (tmp_path / name).write_text(text)
        assert main(["run", str(path), "-o", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err and "--new-version" in err, err
        assert (out / "results.csv").read_bytes() == table
        (tmp_path / name).write_text(old)
    (tmp_path / "base.toml").write_text(base.replace("kn = 1e10", "kn = 2e10"))
    assert main(["run", str(path), "-o", str(tmp_path / "new"), "--quiet"]) == 0  # a new folder
    assert main(["run", str(path), "-o", str(out), "--quiet", "--new-version"]) == 0
    assert (out / "versions" / "v1" / "results.csv").read_bytes() == table
    assert json.loads((out / "study.json").read_text())["version"] == 2
    assert len(read_table(out)) == 2
    scene = tomllib.loads((out / "cases" / "c00000" / "scene.toml").read_text())
    assert scene["contact"]["kn"] == 2e10


# 5. a broken evaluator module, -o naming a file, --timeout inf and other bad options: one line, exit 2, no folder
BROKEN = {
    "syntax": ("def f(:\n    pass\n", "f", "SyntaxError"),
    "raises": ("raise RuntimeError('no licence server')\n", "f", "no licence server"),
    "not a function": ("f = 42\n", "f", "not a function"),
    "a class": ("class f:\n    pass\n", "f", "not a function"),
}


@pytest.mark.parametrize("what", sorted(BROKEN))
def test_broken_evaluator_module_one_line(tmp_path, capsys, what):
    source, attr, words = BROKEN[what]
    mod = "broken_" + what.replace(" ", "_")
    (tmp_path / f"{mod}.py").write_text(source)
    path = write_study(tmp_path, f"""
        base = "base.toml"
        evaluator = "{mod}:{attr}"
        [parameters]
        "contact.friction" = {{ grid = [1.0] }}
    """)
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and "Traceback" not in err, err
    assert not out.exists()


@pytest.mark.parametrize("opts,words", [(["--timeout", "inf"], "--timeout"), (["--timeout", "nan"], "--timeout"),
                                        (["--timeout", "0"], "--timeout"), (["--timeout", "abc"], "--timeout"),
                                        (["--memory-limit", "0"], "--memory-limit"),
                                        (["--memory-limit", "inf"], "--memory-limit"), (["--bogus"], "--bogus"),
                                        (["-o", "{file}"], "not a folder")])
def test_bad_options_one_line_no_folder(tmp_path, opts, words):
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "noop"
        [parameters]
        "contact.friction" = { grid = [1.0] }
    """)
    (tmp_path / "a_file").write_text("keep")
    out = tmp_path / "out"
    opts = [o.replace("{file}", str(tmp_path / "a_file")) for o in opts]
    args = ["run", str(path)] + (["-o", str(out)] if "-o" not in opts else []) + opts
    r = subprocess.run(cli(*args), cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and lines[0].startswith("cases study: error:"), r.stderr
    assert not out.exists() and (tmp_path / "a_file").read_text() == "keep"


# 6. an invalid base scene: every case failed and the study exited 0
def test_invalid_base_scene_refused_before_any_case(tmp_path, capsys):
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "wedge-hb"
        results = ["fs"]
        [parameters]
        "contact.friction" = { grid = [20.0, 30.0] }
    """)
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "base scene" in err and str(tmp_path / "base.toml") in err, err
    assert not out.exists()


# 7. a runaway case met the OOM killer: now --memory-limit, recorded as the failure reason
MEM_PLUGIN = '''
import numpy as np

def hog(scene_path, case_dir, params):
    mb = params["contact.friction"]
    a = np.ones(int(mb * 1024 * 1024 / 8))
    return {"mb": float(a.nbytes / 2**20)}
'''


def test_memory_limit_per_case_recorded(tmp_path):
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "mem_plugin:hog"
        results = ["mb"]
        [parameters]
        "contact.friction" = { list = [16.0, 4000.0, 16.0] }
    """)
    (tmp_path / "mem_plugin.py").write_text(MEM_PLUGIN)
    out = tmp_path / "out"
    r = subprocess.run(cli("run", path, "-o", out, "--quiet", "--memory-limit", "1000"), cwd=REPO,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    rows = read_table(out)
    assert [row["status"] for row in rows] == ["ok", "failed", "ok"]
    assert "memory limit of 1000 MB per case exceeded" in rows[1]["error"]
    assert float(rows[2]["mb"]) == 16.0  # the next case has its own memory


# SIGTERM (a scheduler ending the job): one line, exit 143, the same command finishes the study
def test_sigterm_stops_cleanly_and_restart_completes(tmp_path):
    path = write_study(tmp_path, RESTART_STUDY)
    study = load_study(path)
    out = tmp_path / "out"
    p = subprocess.Popen(cli("run", path, "-o", out, "--quiet"), cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while time.time() - t0 < 60:
        if (out / "results.csv").exists() and len(read_table(out)) >= 2:
            break
        time.sleep(0.02)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 143 and "terminated (SIGTERM)" in err
    assert 2 <= len(read_table(out)) < len(study.cases)
    r = subprocess.run(cli("run", path, "-o", out, "--quiet"), cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    _check_complete(study, out)


# --------------------------------------------------------------------------------------------- issue 19
def test_study_copied_elsewhere_finds_its_scene_and_json_summaries(tmp_path):
    src = write_study(tmp_path / "orig" / "studies", """
        name = "copied"
        base = "scenes/base.toml"
        evaluator = "noop"
        results = ["value"]
        [parameters]
        "contact.friction" = { grid = [1.0, 2.0] }
    """)
    (src.parent / "scenes").mkdir()
    (src.parent / "base.toml").rename(src.parent / "scenes" / "base.toml")
    dest = tmp_path / "copy"
    shutil.copytree(src.parent, dest)
    shutil.rmtree(tmp_path / "orig")
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    r = subprocess.run(cli("run", dest / "study.toml", "-o", "out", "--json"), cwd=elsewhere, capture_output=True,
                       text=True, timeout=60, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["ok"] == 2 and summary["total"] == 2 and summary["study"] == "copied"
    assert [row["value"] for row in read_table(elsewhere / "out")] == ["1.0", "2.0"]
    r = subprocess.run(cli("report", elsewhere / "out", "--json"), cwd=REPO, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["cases"]["ok"] == 2 and Path(info["report"]).is_file()
    # a study placed in the scenes folder: the line names the folder relative paths are read from
    (dest / "scenes" / "study.toml").write_text((dest / "study.toml").read_text())
    r = subprocess.run(cli("list", dest / "scenes" / "study.toml"), cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "study file's folder" in r.stderr and 'base = "base.toml"?' in r.stderr


def test_evaluator_key_and_its_former_name(tmp_path, capsys):
    body = """
        base = "base.toml"
        {keys}
        results = ["value"]
        [parameters]
        "contact.friction" = {{ grid = [1.0] }}
    """
    a = load_study(write_study(tmp_path / "a", body.format(keys='evaluator = "noop"')))
    b = load_study(write_study(tmp_path / "b", body.format(keys='engine = "noop"')))
    assert a.engine == b.engine == "noop"
    both = write_study(tmp_path / "c", body.format(keys='evaluator = "noop"\n        engine = "noop"'))
    assert main(["list", str(both)]) == 2
    assert "give the evaluator once" in capsys.readouterr().err
    for f in sorted((REPO / "cases" / "scenes" / "studies").glob("*.toml")):
        data = tomllib.loads(f.read_text())
        assert "evaluator" in data and "engine" not in data, f


# 3b. the documented option: --reuse-process runs the cases one after the other in one process per rank (less
#     overhead; the state of a case reaches the next, as the README says)
def test_reuse_process_option_shares_state(tmp_path):
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "state_plugin:stateful"
        results = ["calls", "leak"]
        [parameters]
        "contact.mode" = { list = ["a", "lower", "b"] }
    """)
    (tmp_path / "state_plugin.py").write_text(STATE_PLUGIN)
    out = tmp_path / "out"
    r = subprocess.run(cli("run", path, "-o", out, "--quiet", "--reuse-process"), cwd=REPO, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    rows = read_table(out)
    assert [row["calls"] for row in rows] == ["1", "2", "3"] and rows[2]["leak"] == "yes"


# 8. the framework overhead per case, measured by the benchmark with its machine line (fork per case and
#    --reuse-process, serial and under mpirun)
def test_bench_study_overhead_reports_machine_and_figures():
    mpirun_cmd(2)
    r = subprocess.run([sys.executable, "-m", "cases.bench.study", "--overhead-only", "--noop", "12", "--json"],
                       cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    from sgim.machine import machine_line

    assert lines[0] == machine_line()
    res = json.loads(r.stdout[r.stdout.index("{"):])
    assert set(res["overhead"]) == {"1 fork", "2 fork", "1 reuse", "2 reuse"}
    for v in res["overhead"].values():  # differences of two runs: finite, their size depends on the load
        assert all(math.isfinite(v[k]) for k in ("per_case_ms", "runner_per_case_ms", "cpu_per_case_ms", "load1"))
    assert res["fork"]["cpu_ms"] > 0


def test_file_values_of_parameters_resolved_against_the_study_file(tmp_path):
    """A list of mesh files to vary, written relative to the study file: each case's scene names the file by its
    absolute path (the case runs in its own folder), and the files are part of the fingerprint."""
    base = BASE.replace('mode = "ok"', 'mode = "ok"\nmesh = "none"')
    path = write_study(tmp_path / "s", """
        base = "scenes/base.toml"
        evaluator = "noop"
        results = ["value"]
        [parameters]
        "contact.mesh" = { list = ["meshes/a.obj", "meshes/b.obj", "not-a-file"] }
    """, base=base)
    (tmp_path / "s" / "scenes").mkdir()
    (tmp_path / "s" / "base.toml").rename(tmp_path / "s" / "scenes" / "base.toml")
    (tmp_path / "s" / "meshes").mkdir()
    for n in "ab":
        (tmp_path / "s" / "meshes" / f"{n}.obj").write_text("v 0 0 0\n")
    study = load_study(path)
    names = [tomllib.loads(study.case_scene_text(c))["contact"]["mesh"] for c in study.cases]
    assert names == [str((tmp_path / "s" / "meshes" / "a.obj").resolve()),
                     str((tmp_path / "s" / "meshes" / "b.obj").resolve()), "not-a-file"]
    assert {"file meshes/a.obj", "file meshes/b.obj"} <= set(study.fingerprint())


WARM_PLUGIN = '''
import time
WARMED = []

def fast(scene_path, case_dir, params):
    return {"warmed": len(WARMED)}

def _warm(scene_path):
    time.sleep(1.5)  # a cold kernel compilation
    WARMED.append(1)

fast.warm = _warm
'''


def test_warm_up_runs_once_per_rank_outside_the_time_limit(tmp_path):
    """The evaluator's warm-up (kernel compilation) runs once in the case server, before the cases are forked from
    it: every case sees it done, and its time does not count against the case's time limit."""
    path = write_study(tmp_path, """
        base = "base.toml"
        evaluator = "warm_plugin:fast"
        results = ["warmed"]
        timeout = 0.5
        [parameters]
        "contact.friction" = { grid = [1.0, 2.0, 3.0] }
    """)
    (tmp_path / "warm_plugin.py").write_text(WARM_PLUGIN)
    out = tmp_path / "out"
    for extra in ([], ["--reuse-process"]):
        shutil.rmtree(out, ignore_errors=True)
        r = subprocess.run(cli("run", path, "-o", out, "--quiet", *extra), cwd=REPO, capture_output=True,
                           text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert [(row["status"], row["warmed"]) for row in read_table(out)] == [("ok", "1")] * 3, extra


@pytest.mark.parametrize("body,key,allowed", [
    ('evaluater = "noop"\n"contact.friction" = 1', "evaluater", "evaluator"),
    ('evaluator = "noop"\n[parameters]\n"contact.friction" = { gird = [1.0] }', "contact.friction", "grid, list"),
    ('evaluator = "noop"\n[parameters]\n"contact.friction" = { grid = [1.0] }\n[sampling]\nmetod = "grid"',
     "sampling.metod", "method, samples"),
    ('evaluator = "noop"\n[parameters]\n"contact.friction" = { grid = [1.0] }\n[sampling]\nmethod = "lhs2"',
     "sampling.method", "grid, random, lhs, realisations"),
    ('evaluator = "nop"\n[parameters]\n"contact.friction" = { grid = [1.0] }', "evaluator", "noop")])
def test_study_typos_answered_with_the_allowed_names(tmp_path, capsys, body, key, allowed):
    path = write_study(tmp_path, 'base = "base.toml"\n' + body + "\n")
    assert main(["list", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err and allowed in err and "Traceback" not in err, err


def test_sigterm_under_mpirun_keeps_the_finished_rows(tmp_path):
    """A scheduler's SIGTERM to mpirun: it forwards the signal to the ranks, which stop their cases and close the
    table; the same command finishes the study with no case lost or run twice."""
    path = write_study(tmp_path, RESTART_STUDY.replace("list = [0.15]", "list = [0.4]"))
    study = load_study(path)
    out = tmp_path / "out"
    p = subprocess.Popen(mpirun_cmd(2) + cli("run", path, "-o", out, "--quiet"), cwd=REPO,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while time.time() - t0 < 60:
        if (out / "results.csv").exists() and len(read_table(out)) >= 3:
            break
        time.sleep(0.02)
    p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=30) != 0
    _wait_unlocked(out)
    first = {row["case_id"]: row for row in read_table(out)}
    assert 3 <= len(first) < len(study.cases)
    r = subprocess.run(cli("run", path, "-o", out, "--quiet"), cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    rows = _check_complete(study, out)
    assert {row["case_id"]: row for row in rows if row["case_id"] in first} == first
