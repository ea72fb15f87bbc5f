"""`dda run` contract: outputs, one-line errors naming file/key/value, no output left on bad input,
blow-up writes the last good state with exit status 3."""
import json
import math

import numpy as np
import pytest

from dda.cli import main

SCENE = """
name = "cli_incline"
[simulation]
duration = 0.2
record_every = 0.02
frames = 2
[contact]
kn = 1e10
friction = 20.0
damping = 0.2
[[material]]
name = "rock"
density = 2600.0
[[block]]
name = "base"
fixed = true
vertices = [[-3, -2, -1], [3, -2, -1], [3, 2, -1], [-3, 2, -1], [-3, -2, 0], [3, -2, 0], [3, 2, 0], [-3, 2, 0]]
faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
[[block]]
name = "cube"
shape = "cube"
size = 1.0
center = [0.0, 0.0, 0.6]
velocity = [1.0, 0.0, 0.0]
[output]
formats = ["npz", "csv", "vtu", "png"]
"""


def _write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_run_writes_series_final_state_and_vtu(tmp_path):
    scene = _write(tmp_path, SCENE)
    out = tmp_path / "out"
    assert main(["run", str(scene), "-o", str(out), "--quiet"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"series.npz", "series.csv", "final.npz", "blocks.pvd", "frames", "summary.json", "final.png"} <= names
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())
    s = np.load(out / "series.npz")
    assert s["pos"].shape[1:] == (2, 3) and s["time"][0] == 0.0 and s["time"][-1] == pytest.approx(0.2, abs=1e-3)
    # the cube falls 0.1 m onto the base and slides with friction 20 deg: it moved along +x
    assert s["pos"][-1, 1, 0] > 0.05
    assert len(list((out / "frames").glob("*.vtu"))) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["blocks"] == 2
    rows = (out / "series.csv").read_text().splitlines()
    assert rows[0].startswith("time,kinetic,potential") and len(rows) == len(s["time"]) + 1


@pytest.mark.parametrize("edit,key", [
    (("kn = 1e10", "kn = -1"), "contact.kn"),
    (("friction = 20.0", "friction = 95.0"), "contact.friction"),
    (("duration = 0.2", "duration = 'long'"), "simulation.duration"),
    (('shape = "cube"', 'shape = "blob"'), "block[1].shape"),
    (("faces = [[0, 3, 2, 1]", "faces = [[0, 3, 2, 9]"), "block[0].faces[0]"),
    (("faces = [[0, 3, 2, 1]", "faces = [[0, 1, 2, 3]"), "block[0]"),
    (("[output]", "[outputs]"), "outputs"),
])
def test_bad_input_is_one_line_naming_file_and_key(tmp_path, capsys, edit, key):
    scene = _write(tmp_path, SCENE.replace(*edit))
    out = tmp_path / "out"
    assert main(["run", str(scene), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(scene) in err and key in err
    assert not out.exists() and not any(p.name.startswith(".") for p in tmp_path.iterdir())


def test_unknown_generator_is_reported(tmp_path, capsys):
    scene = _write(tmp_path, SCENE + '\n[[generate]]\nkind = "nonsense"\n')
    assert main(["run", str(scene), "-o", str(tmp_path / "out")]) == 2
    assert "generate[0].kind" in capsys.readouterr().err


def test_blow_up_writes_last_good_state_and_exits_3(tmp_path, capsys):
    scene = _write(tmp_path, SCENE.replace("duration = 0.2", "duration = 0.2\ndt = 0.002"))
    out = tmp_path / "out"
    assert main(["run", str(scene), "-o", str(out), "--quiet"]) == 3
    assert "blow-up" in capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "blow-up"
    final = np.load(out / "final.npz")
    assert np.all(np.isfinite(final["pos"]))


def test_generated_incline_scene_matches_the_analytical_slide(tmp_path):
    text = """
[simulation]
duration = 0.5
frames = 1
[contact]
kn = 1e11
ks = 1e11
friction = 20.0
damping = 0.2
[[generate]]
kind = "incline"
angle = 30.0
size = 1.0
height = 1.0
[output]
formats = ["npz"]
"""
    out = tmp_path / "o"
    assert main(["run", str(_write(tmp_path, text)), "-o", str(out), "--quiet"]) == 0
    s = np.load(out / "series.npz")
    t = s["time"][-1]
    a = math.radians(30.0)
    ref = 0.5 * 9.81 * (math.sin(a) - math.tan(math.radians(20.0)) * math.cos(a)) * t * t
    d = np.linalg.norm(s["pos"][-1, 1] - s["pos"][0, 1])
    # the generated block starts touching (no static overlap), which costs a little more than in the engine test
    assert d == pytest.approx(ref, rel=5e-3)
