"""`dda run` states its answer: the [[report]] quantities of a scene (printed, in summary.json, with the error
against a stated reference), time-series plot and CSV units, --json on stdout, and progress lines of the whole
run with steps/s and an ETA.

References: the analytical slide of a block on an incline, s = 1/2 g (sin a - tan phi cos a) t^2; the run's own
series.npz read back (displacement, rotation from the quaternions by the definition of the rotation angle); a
breadth-first search over the intact bonds for the detached spheres."""
import json
import math
from collections import deque
from pathlib import Path

import numpy as np
import pytest

from dda.cli import main

HERE = Path(__file__).resolve().parent
CASES = HERE.parent / "cases" / "scenes"

from test_dda_cli import SCENE, SPHERE_SCENE, _layer_model, _write  # noqa: E402 - the scenes of the run contract


def _run(capsys, *argv):
    code = main(["run", *map(str, argv)])
    return code, capsys.readouterr()


def test_incline_states_its_slide_distance_against_the_analytical_reference(tmp_path, capsys):
    out = tmp_path / "out"
    code, cap = _run(capsys, CASES / "dda_incline.toml", "-o", out, "--json")
    assert code == 0
    summary = json.loads(cap.out)  # --json: the summary alone on stdout
    assert summary == json.loads((out / "summary.json").read_text())
    # progress lines: the whole run's simulated time (10 frames of 0.1 s: not 100 % at every frame's end),
    # steps per second, and no temporary folder named
    steps = [ln for ln in cap.err.splitlines() if "] t = " in ln]
    pct = [float(ln.split("(")[1].split("%")[0]) for ln in steps]
    assert steps and all(" of 1 s (" in ln for ln in steps) and pct == sorted(pct) and pct[-1] == 100.0
    assert pct.count(100.0) == 1 and "steps/s" in steps[-1]
    assert ".part" not in cap.err and ".rockdem" not in cap.err and str(out) in cap.err
    (a,) = summary["answers"]
    g, alpha, phi = 9.81, math.radians(30.0), math.radians(20.0)
    exact = 0.5 * g * (math.sin(alpha) - math.tan(phi) * math.cos(alpha)) * summary["time"] ** 2
    assert a["label"] == "slide distance" and a["unit"] == "m"
    assert a["value"] == pytest.approx(exact, rel=1e-3)
    s = np.load(out / "series.npz")
    i = list(s["names"]).index("block")
    assert a["value"] == pytest.approx(float(np.linalg.norm(s["pos"][-1, i] - s["pos"][0, i])), rel=1e-12)
    assert a["reference"] == 0.9064 and a["error"] == pytest.approx((a["value"] - 0.9064) / 0.9064, rel=1e-12)
    assert (out / "series.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    header = (out / "series.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time_s" and "kinetic_J" in header and "balance_error_J" in header
    assert header[-1] == "mean_displacement_m" and "contacts" in header


def test_reported_quantities_against_the_series_and_printed_lines(tmp_path, capsys):
    report = """
[[report]]
quantity = "displacement"
block = "cube"
component = "x"
reference = 0.1
[[report]]
label = "turn of the cube"
quantity = "rotation"
block = "cube"
[[report]]
quantity = "moved"
above = 0.01
[[report]]
quantity = "energy_error"
"""
    scene = _write(tmp_path, SCENE.replace("[output]", report + "[output]"))
    out = tmp_path / "out"
    code, cap = _run(capsys, scene, "-o", out)
    assert code == 0
    answers = json.loads((out / "summary.json").read_text())["answers"]
    s = np.load(out / "series.npz")
    dx = float(s["pos"][-1, 1, 0] - s["pos"][0, 1, 0])
    q0, q1 = s["quat"][0, 1], s["quat"][-1, 1]
    # the angle of the relative rotation q1 q0^-1 by its definition: 2 atan2(|vector part|, |scalar part|)
    w = q1[0] * q0[0] + np.dot(q1[1:], q0[1:])
    v = -q1[0] * q0[1:] + q0[0] * q1[1:] - np.cross(q1[1:], q0[1:])
    angle = math.degrees(2.0 * math.atan2(np.linalg.norm(v), abs(w)))
    moved = int(np.sum(np.linalg.norm(s["pos"][-1] - s["pos"][0], axis=1)[~s["fixed"]] > 0.01))
    by = {a["label"]: a for a in answers}
    assert by["displacement x of cube"]["value"] == pytest.approx(dx, rel=1e-12)
    assert by["displacement x of cube"]["error"] == pytest.approx((dx - 0.1) / 0.1, rel=1e-12)
    assert by["turn of the cube"]["value"] == pytest.approx(angle, abs=1e-6) and by["turn of the cube"]["unit"] == "deg"
    assert by["bodies moved more than 0.01 m"]["value"] == moved == 1
    assert by["energy balance error"]["value"] == pytest.approx(float(s["energy"][-1, -1]), rel=1e-12, abs=1e-12)
    lines = [ln.strip() for ln in cap.out.splitlines()]
    assert f"displacement x of cube: {dx:.6g} m (reference 0.1 m: error {100 * (dx - 0.1) / 0.1:+.3g} %)" in lines
    assert f"turn of the cube: {by['turn of the cube']['value']:.6g} deg" in lines


def _detached_bfs(n, bi, bj, intact, anchor):
    adj = [[] for _ in range(n)]
    for a, b, ok in zip(bi, bj, intact):
        if ok:
            adj[a].append(b)
            adj[b].append(a)
    seen = set(np.flatnonzero(anchor).tolist())
    queue = deque(seen)
    while queue:
        for b in adj[queue.popleft()]:
            if b not in seen:
                seen.add(b)
                queue.append(b)
    return n - len(seen)


def test_sphere_run_states_broken_bonds_and_detached_spheres(tmp_path, capsys):
    _layer_model(tmp_path)
    text = SPHERE_SCENE.replace('fixed = ["z<0.15"]', 'fixed = ["z<0.15"]\nbond_tensile = 1e3\nbond_shear = 1e3')
    out = tmp_path / "out"
    code, cap = _run(capsys, _write(tmp_path, text), "-o", out, "--quiet")
    assert code == 0 and cap.out == ""
    summary = json.loads((out / "summary.json").read_text())
    by = {a["quantity"]: a for a in summary["answers"]}  # no [[report]]: the default answers
    s = np.load(out / "series.npz")
    assert by["bonds_broken"]["value"] == int(len(s["bond_intact"]) - s["bond_intact"].sum()) > 0
    ref = _detached_bfs(len(s["radii"]), s["bond_i"], s["bond_j"], s["bond_intact"], s["fixed"])
    assert by["detached"]["value"] == ref
    free = ~s["fixed"]
    spheres = np.linalg.norm(s["pos"][-1][free] - s["pos"][0][free], axis=1).max()
    cube = np.linalg.norm(s["block_pos"][-1, 1] - s["block_pos"][0, 1])  # block 0 is the fixed floor
    assert by["max_displacement"]["value"] == pytest.approx(float(max(spheres, cube)), rel=1e-12)
    assert (out / "series.png").is_file()


@pytest.mark.parametrize("table,key", [
    ('quantity = "speed"\nblock = "cube"', "report[0].quantity"),
    ('quantity = "displacement"\nblock = "cub"', "report[0].block"),
    ('quantity = "displacement"', "report[0].block"),
    ('quantity = "rotation"\nblock = "cube"\ncomponent = "x"', "report[0].component"),
    ('quantity = "detached"', "report[0].quantity"),
    ('quantity = "displacement"\nblock = "cube"\nreference = "far"', "report[0].reference"),
    ('quantity = "moved"\nbloc = "cube"', "report[0].bloc"),
])
def test_a_bad_report_table_is_one_line_naming_the_key(tmp_path, capsys, table, key):
    scene = _write(tmp_path, SCENE.replace("[output]", f"[[report]]\n{table}\n[output]"))
    out = tmp_path / "out"
    code, cap = _run(capsys, scene, "-o", out)
    assert code == 2 and not out.exists()
    (line,) = cap.err.strip().splitlines()
    assert str(scene) in line and key in line


def test_progress_spans_the_whole_run_with_rate_and_eta():
    from dda.progress import RunProgress

    lines = []
    clock = RunProgress(lines.append, t_end=2.0, t_start=0.0, steps=0, every=0.0)
    clock.update(0.5, 100)  # the first update: the base of the rates (its wall time holds the compile)
    clock.update(1.0, 200, "x", end=True)  # a piece ends at half the run: its end is not the run's
    clock.update(2.0, 400, end=True)
    assert lines[0].startswith("t = 0.5 of 2 s ( 25.0 %)") and "ETA" not in lines[0]
    assert lines[1].startswith("t = 1 of 2 s ( 50.0 %)") and "steps/s  ETA" in lines[1] and lines[1].endswith("x")
    assert lines[2].startswith("t = 2 of 2 s (100.0 %)") and "ETA" not in lines[2]
