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
    assert rows[0].startswith("time_s,kinetic_J,potential_J") and len(rows) == len(s["time"]) + 1


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


# --- VTU frame series, .pvd index, CSV and PNG of block and sphere scenes ------------------------------------

def _pvd(path):
    """(time, file, part) of each DataSet of a ParaView collection, read with the standard XML parser."""
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file"), int(d.get("part"))) for d in root.iter("DataSet")]


def _record_at(times, t):
    k = int(np.argmin(np.abs(times - t)))
    assert abs(times[k] - t) < 1e-8  # the .pvd holds 9 significant digits
    return k


def _box_centres(mesh):
    """{block: mean of the vertices its cells use}; the blocks here are boxes, whose vertex mean is the centroid."""
    used = {}
    for c, bid in zip(mesh.cells, mesh.cell_data["block"]):
        for row, b in zip(c.data, bid):
            used.setdefault(int(b), set()).update(int(v) for v in np.ravel(row))
    return {b: mesh.points[sorted(v)].mean(axis=0) for b, v in used.items()}


def test_block_scene_pvd_lists_every_frame_and_frames_match_the_series(tmp_path):
    import meshio

    out = tmp_path / "out"
    assert main(["run", str(_write(tmp_path, SCENE.replace("frames = 2", "frames = 4"))), "-o", str(out),
                 "--quiet"]) == 0
    s = np.load(out / "series.npz")
    entries = _pvd(out / "blocks.pvd")
    assert len(entries) == 5 and len(list((out / "frames").glob("*.vtu"))) == 5
    t = [e[0] for e in entries]
    assert t[0] == 0.0 and all(b > a for a, b in zip(t, t[1:])) and t[-1] == pytest.approx(s["time"][-1], abs=1e-8)
    for time, name, _ in entries:
        k = _record_at(s["time"], time)
        centres = _box_centres(meshio.read(out / name))
        for b in (0, 1):
            assert centres[b] == pytest.approx(s["pos"][k, b], abs=1e-9)


def _layer_model(tmp_path):
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    d = {"name": "layer", "domain": {"min": [0, 0, 0], "max": [1, 1, 0.4]},
         "packing": {"kind": "cubic", "radius": 0.1}, "bonds": {"rule": "colour"},
         "discontinuity": [{"name": "j", "centre": [0.5, 0.5, 0.2], "dip": 0.0, "dip_direction": 0.0,
                            "radius": 5.0, "thickness": 0.0}]}
    model = build_model(scene_from_dict(d, "layer.toml"))
    model.save(tmp_path / "model.npz")
    return model


SPHERE_SCENE = """
name = "drop"
[simulation]
duration = 0.3
record_every = 0.02
frames = 3
[contact]
kn = 1e7
friction = 30.0
damping = 0.3
[spheres]
model = "model.npz"
fixed = ["z<0.15"]
[[block]]
name = "floor"
shape = "brick"
size = 2.0
width = 2.0
height = 0.2
center = [0.5, 0.5, -0.2]
fixed = true
[[block]]
name = "cube"
shape = "cube"
size = 0.4
center = [0.5, 0.5, 0.75]
velocity = [0.3, 0.0, -1.0]
"""


@pytest.mark.parametrize("moving", [True, False])
def test_sphere_scene_writes_a_frame_series_pvd_csv_and_png(tmp_path, moving):
    import meshio

    model = _layer_model(tmp_path)
    text = SPHERE_SCENE if moving else SPHERE_SCENE[:SPHERE_SCENE.index("[[block]]\nname = \"cube\"")]
    out = tmp_path / "out"
    assert main(["run", str(_write(tmp_path, text)), "-o", str(out), "--quiet"]) == 0
    for f in ("series.npz", "series.csv", "spheres.pvd", "spheres.vtu", "blocks.vtu", "final.png", "summary.json"):
        assert (out / f).is_file(), f
    assert (out / "final.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    s = np.load(out / "series.npz")
    entries = _pvd(out / "spheres.pvd")
    for part in (0, 1):
        ts = [e[0] for e in entries if e[2] == part]
        assert len(ts) == 4 and ts[0] == 0.0 and all(b > a for a, b in zip(ts, ts[1:]))
        assert ts[-1] == pytest.approx(s["time"][-1], abs=1e-8) and ts[-1] == pytest.approx(0.3, rel=1e-3)
    assert len(list((out / "frames").glob("spheres_*.vtu"))) == 4
    n_moving = sum(1 for e in entries if e[2] == 1 and "blocks_" in e[1])
    assert n_moving == (4 if moving else 0)
    for time, name, part in entries:
        assert (out / name).is_file()
        k = _record_at(s["time"], time)
        m = meshio.read(out / name)
        if part == 0:
            assert m.points == pytest.approx(s["pos"][k], abs=1e-12)
            assert m.point_data["radius"] == pytest.approx(model.radii)
            assert m.point_data["velocity"] == pytest.approx(s["vel"][k], abs=1e-12)
            assert np.array_equal(m.point_data["colour"], model.colour)
        else:
            centres = _box_centres(m)
            assert centres[0] == pytest.approx([0.5, 0.5, -0.2], abs=1e-12)  # the fixed floor
            if moving:
                assert centres[1] == pytest.approx(s["block_pos"][k, 1], abs=1e-9)
    if moving:  # the cube moved: the frames are not all the same state
        assert np.linalg.norm(s["block_pos"][-1, 1] - s["block_pos"][0, 1]) > 0.05
    import csv

    rows = list(csv.reader((out / "series.csv").open()))
    assert rows[0][:2] == ["time_s", "kinetic_J"] and len(rows) == len(s["time"]) + 1
    assert [float(r[0]) for r in rows[1:]] == pytest.approx(s["time"].tolist(), abs=1e-12)
    free = s["pos"][:, ~s["fixed"]]
    disp = np.array([np.mean([np.linalg.norm(p[i] - free[0][i]) for i in range(free.shape[1])]) for p in free])
    assert [float(r[rows[0].index("mean_displacement_m")]) for r in rows[1:]] == pytest.approx(disp, abs=1e-12)


def test_a_generator_parameter_typo_names_the_allowed_parameters(tmp_path, capsys):
    import inspect

    from dda.generate import GENERATORS
    from dda.scene import generator_parameters

    scene = _write(tmp_path, 'name = "x"\n[simulation]\nduration = 1\n[contact]\nkn = 1e9\n'
                             '[[generate]]\nkind = "incline"\nangel = 30\n')
    assert main(["run", str(scene), "-o", str(tmp_path / "out")]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "generate[0].angel = 30" in line and "did you mean 'angle'" in line and "unexpected keyword" not in line
    assert line.endswith(", ".join(inspect.signature(GENERATORS["incline"]).parameters))
    assert "progress" in inspect.signature(GENERATORS["box_cut"]).parameters  # the run's callback ...
    assert "progress" not in generator_parameters(GENERATORS["box_cut"])  # ... is no scene key


def test_every_optional_generator_parameter_refuses_a_string(tmp_path, capsys):
    """The parameters a generator leaves to its own choice (default None) are checked like the others: a length
    given as "1.0" or a material given as a number is one line naming the key, not a silently converted run."""
    import inspect

    from dda.generate import GENERATORS
    from dda.scene import generator_parameters

    cases = [(kind, p) for kind, fn in GENERATORS.items() for p in generator_parameters(fn)
             if inspect.signature(fn).parameters[p].default is None]
    assert len(cases) >= 9  # height, depth, base_length, ..., the optional materials
    for kind, p in cases:
        bad = '"1.0"' if not p.endswith("material") else "1.0"
        scene = _write(tmp_path, f'name = "x"\n[simulation]\nduration = 1\n[contact]\nkn = 1e9\n'
                                 f'[[generate]]\nkind = "{kind}"\n{p} = {bad}\n')
        out = tmp_path / f"out_{kind}_{p}"
        assert main(["run", str(scene), "-o", str(out), "--quiet"]) == 2, (kind, p)
        (line,) = capsys.readouterr().err.strip().splitlines()
        assert f"generate[0].{p} = " in line and "must be a" in line, line
        assert not out.exists()
