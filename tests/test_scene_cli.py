"""The sgim command line contract, run as a subprocess, and the files it writes."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import sgim_ref as ref

_SCRIPT = Path(sys.executable).parent / "sgim"
SGIM = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "sgim.cli"]


def sgim(*args, cwd, timeout=240):
    return subprocess.run([*SGIM, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout)


BASE = """\
name = "small"
[domain]
min = [0.0, -2.0, 0.0]
max = [5.0, 2.0, 4.0]
[packing]
kind = "cubic"
radius = 0.5
"""

GOOD = BASE + """\
[bonds]
rule = "colour"
tolerance = 0.001

[[excavation]]
name = "hill"
points = [[-1.0, -3.0, 3.4], [6.0, -3.0, 2.9], [6.0, 3.0, 3.6], [-1.0, 3.0, 3.1], [2.5, 0.2, 3.9]]

[[discontinuity]]
name = "joint"
centre = [2.4, 0.1, 1.7]
dip = 70.0
dip_direction = 95.0
radius = 3.0

[[discontinuity]]
name = "fault"
centre = [2.0, -0.3, 2.2]
normal = [0.1, 0.9, 0.4]
radius = 6.0
thickness = 0.8
"""

NONTRI = "MESH"  # placeholder: the case writes a quad-only mesh file


def _quads(path):
    import meshio

    pts = np.array([[0.0, -2.0, 3.0], [5.0, -2.0, 3.0], [5.0, 2.0, 3.0], [0.0, 2.0, 3.0], [2.5, 0.0, 3.5]])
    meshio.write(str(path), meshio.Mesh(pts, [("quad", np.array([[0, 1, 2, 3]]))]))


def _garbage_high(path):
    path.write_bytes(bytes((0x80 + 37 * i) % 256 for i in range(300)))


def _garbage_nul(path):
    path.write_bytes(b"\x00\x01garbage\xfe\xff" * 40)


def _garbage_short(path):
    path.write_bytes(b"\xff\xfe\x00garbage\x9c" * 5)


# (id, scene text, files to write {name: writer}, key path, value as shown)
BAD = [
    ("collinear", BASE + '[[excavation]]\nvertices = [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [2.0, 2.0, 1.0]]\n'
     'faces = [[0, 1, 2]]\n', {}, "excavation[0].faces[0]", "[[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [2.0, 2.0, 1.0]]"),
    ("repeated", BASE + '[[excavation]]\nvertices = [[0.0, 0.0, 1.0], [4.0, 1.0, 1.0], [0.0, 0.0, 1.0]]\n'
     'faces = [[0, 1, 2]]\n', {}, "excavation[0].faces[0]", "[[0.0, 0.0, 1.0], [4.0, 1.0, 1.0], [0.0, 0.0, 1.0]]"),
    ("repeated-points", BASE + '[[excavation]]\npoints = [[0.0, 0.0, 1.0], [4.0, 1.0, 1.0], [2.0, 3.0, 2.0], '
     '[4.0, 1.0, 1.5]]\n', {}, "excavation[0].points[3]", "[4.0, 1.0, 1.5]"),
    ("nan", BASE.replace("min = [0.0, -2.0, 0.0]", "min = [0.0, nan, 0.0]"), {}, "domain.min[1]", "nan"),
    ("inf-radius", BASE.replace("radius = 0.5", "radius = inf"), {}, "packing.radius", "inf"),
    ("inf-vertex", BASE + '[[excavation]]\nvertices = [[0.0, 0.0, 1.0], [4.0, 1.0, -inf], [1.0, 3.0, 1.0]]\n'
     'faces = [[0, 1, 2]]\n', {}, "excavation[0].vertices[1]", "-inf"),
    ("zero-radius", BASE.replace("radius = 0.5", "radius = 0.0"), {}, "packing.radius", "0.0"),
    ("negative-radius", BASE.replace("radius = 0.5", "radius = -0.25"), {}, "packing.radius", "-0.25"),
    ("empty-box", BASE.replace("max = [5.0, 2.0, 4.0]", "max = [5.0, -2.0, 4.0]"), {}, "domain.max[1]", "-2.0"),
    ("inverted-box", BASE.replace("max = [5.0, 2.0, 4.0]", "max = [5.0, 2.0, -3.0]"), {}, "domain.max[2]",
     "-3.0"),
    ("zero-normal", BASE + '[[discontinuity]]\ncentre = [1.0, 0.0, 1.0]\nnormal = [0.0, 0.0, 0.0]\nradius = 1.0\n',
     {}, "discontinuity[0].normal", "[0.0, 0.0, 0.0]"),
    ("negative-thickness", BASE + '[[discontinuity]]\ncentre = [1.0, 0.0, 1.0]\nnormal = [0.0, 0.0, 1.0]\n'
     'radius = 1.0\nthickness = -0.5\n', {}, "discontinuity[0].thickness", "-0.5"),
    ("garbage-stl", BASE + '[[excavation]]\nfile = "garbage.stl"\n', {"garbage.stl": _garbage_high},
     "excavation[0].file", "'garbage.stl'"),
    ("garbage-stl-2", BASE + '[[excavation]]\nfile = "garbage.stl"\n', {"garbage.stl": _garbage_nul},
     "excavation[0].file", "'garbage.stl'"),
    ("garbage-stl-short", BASE + '[[excavation]]\nfile = "garbage.stl"\n', {"garbage.stl": _garbage_short},
     "excavation[0].file", "'garbage.stl'"),
    ("quads-vtu", BASE + '[[excavation]]\nfile = "quads.vtu"\n', {"quads.vtu": _quads},
     "excavation[0].file", "'quads.vtu'"),
    ("quads-obj", BASE + '[[excavation]]\nfile = "quads.obj"\n', {"quads.obj": _quads},
     "excavation[0].file", "'quads.obj'"),
    ("outside-box", BASE + '[[excavation]]\npoints = [[10.0, 0.0, 1.0], [12.0, 0.0, 1.0], [11.0, 1.5, 2.0]]\n',
     {}, "excavation[0]", "10.0"),
    ("unknown-top", "colour = 3\n" + BASE, {}, "colour", "3"),
    ("unknown-nested", BASE.replace("radius = 0.5", "radius = 0.5\nradios = 0.7"), {}, "packing.radios", "0.7"),
    ("unknown-disc", BASE + '[[discontinuity]]\ncentre = [1.0, 0.0, 1.0]\nnormal = [0.0, 0.0, 1.0]\n'
     'radius = 1.0\nstrike = 30.0\n', {}, "discontinuity[0].strike", "30.0"),
]


@pytest.mark.parametrize("text,files,key,value", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, text, files, key, value):
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    for name, write in files.items():
        write(tmp_path / name)
    before = set(os.listdir(tmp_path))
    res = sgim("build", scene, "-o", tmp_path / "out", cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 1, f"stderr must be one line, got {len(lines)}:\n{res.stderr}"
    line = lines[0]
    assert str(scene) in line, line
    assert f" {key} = " in line, line
    assert value in line, line
    after = set(os.listdir(tmp_path))
    assert after == before, f"left behind: {sorted(after - before)}"


def test_bad_inputs_are_valid_except_for_the_defect(tmp_path):
    """Control for test_bad_input: the base scene (and the good one) build fine."""
    for k, text in enumerate((BASE, GOOD)):
        (tmp_path / f"s{k}.toml").write_text(text)
        res = sgim("build", f"s{k}.toml", "-o", f"o{k}", "--formats", "npz", "--quiet", cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert res.stderr == "" and (tmp_path / f"o{k}" / "model.npz").is_file()


# ---------------------------------------------------------------------------
# a good build

@pytest.fixture(scope="module")
def built(tmp_path_factory):
    d = tmp_path_factory.mktemp("good")
    (d / "scene.toml").write_text(GOOD)
    res = sgim("build", "scene.toml", "-o", "out", "--json", "--formats", "npz,vtu,txt,png", cwd=d)
    assert res.returncode == 0, res.stderr
    return d, res


def test_build_json_counts(built):
    d, res = built
    info = json.loads(res.stdout)
    assert info["spheres"] == info["intact"] + info["red"] + info["green"] + info["blue"]
    assert info["bonds"] == info["bonded"] + info["cut"]
    assert info["discontinuities"] == 2
    z = np.load(d / "out" / "model.npz")
    assert info["spheres"] == len(z["centers"])
    assert [info[k] for k in ("intact", "red", "green", "blue")] == np.bincount(z["colour"], minlength=4).tolist()
    assert info["bonds"] == len(z["bonds"]) and info["bonded"] == int(z["bonded"].sum())
    assert info["memberships"] == len(z["member_sphere"])
    assert info["red"] > 0 and info["green"] > 0 and info["blue"] > 0 and info["cut"] > 0
    summary = json.loads((d / "out" / "summary.json").read_text())
    assert {k: summary[k] for k in ("spheres", "bonds", "bonded")} == {k: info[k] for k in ("spheres", "bonds",
                                                                                         "bonded")}
    assert sorted(os.listdir(d)) == ["out", "scene.toml"]  # no temp folder left


def test_model_npz_layout(built):
    d, _ = built
    with np.load(d / "out" / "model.npz", allow_pickle=False) as z:
        n = len(z["centers"])
        m = len(z["bonds"])
        k = len(z["member_sphere"])
        expect = {
            "centers": ("f8", (n, 3)), "radii": ("f8", (n,)), "colour": ("i1", (n,)),
            "colour_source": ("i4", (n,)), "bonds": ("i8", (m, 2)), "bonded": ("b1", (m,)),
            "cut_by": ("i4", (m,)), "member_sphere": ("i8", (k,)), "member_disc": ("i4", (k,)),
            "member_kind": ("i1", (k,)), "member_offset": ("f8", (k,)), "disc_centre": ("f8", (2, 3)),
            "disc_normal": ("f8", (2, 3)), "disc_radius": ("f8", (2,)), "disc_thickness": ("f8", (2,)),
        }
        for key, (dt, shape) in expect.items():
            assert z[key].dtype == np.dtype(dt), key
            assert z[key].shape == shape, key
        assert n > 0 and m > 0 and k > 0
        assert np.all(z["radii"] == 0.5)
        b = z["bonds"]
        assert np.all(b[:, 0] < b[:, 1]) and b.min() >= 0 and b.max() < n
        assert np.all(np.diff(b[:, 0] * n + b[:, 1]) > 0), "bonds sorted and unique"
        assert np.array_equal(b, ref.touching_pairs(z["centers"], z["radii"], 1e-3))
        assert set(np.unique(z["colour"])) <= {0, 1, 2, 3}
        assert set(np.unique(z["member_kind"])) <= {1, 2, 3}
        assert np.all((z["member_sphere"] >= 0) & (z["member_sphere"] < n))
        assert np.all((z["member_disc"] >= 0) & (z["member_disc"] < 2))
        assert np.array_equal(z["cut_by"] == -1, z["bonded"])
        assert list(z["disc_name"]) == ["joint", "fault"]
        meta = json.loads(str(z["meta"]))
        assert meta["scene"] == "small" and meta["packing"]["kind"] == "cubic"
        assert str(z["scene_toml"]) == GOOD


def test_vtu_matches_npz(built):
    import meshio

    d, _ = built
    z = np.load(d / "out" / "model.npz")
    mesh = meshio.read(d / "out" / "model.vtu")
    assert np.array_equal(np.asarray(mesh.points, float), z["centers"])
    assert np.array_equal(mesh.point_data["radius"], z["radii"])
    assert np.array_equal(mesh.point_data["colour"], z["colour"])
    nb = np.bincount(z["bonds"][z["bonded"]].ravel(), minlength=len(z["centers"]))
    assert np.array_equal(mesh.point_data["bonds"], nb)


def test_text_files_match_npz(built):
    d, _ = built
    z = np.load(d / "out" / "model.npz")
    balls = np.loadtxt(d / "out" / "balls.txt", comments="#", ndmin=2)
    assert balls.shape == (len(z["centers"]), 6)
    assert np.array_equal(balls[:, 0], np.arange(1, len(z["centers"]) + 1))
    assert np.array_equal(balls[:, 1:4], z["centers"])
    assert np.array_equal(balls[:, 4], z["radii"])
    assert np.array_equal(balls[:, 5], z["colour"])
    bonds = np.loadtxt(d / "out" / "bonds.txt", comments="#", dtype=np.int64, ndmin=2)
    assert bonds.shape == (len(z["bonds"]), 4)
    assert np.array_equal(bonds[:, :2] - 1, z["bonds"])
    assert np.array_equal(bonds[:, 2], z["bonded"].astype(int))
    assert np.array_equal(bonds[:, 3], z["cut_by"])


def test_info(built):
    d, _ = built
    z = np.load(d / "out" / "model.npz")
    res = sgim("info", "out/model.npz", cwd=d)
    assert res.returncode == 0, res.stderr
    cc = np.bincount(z["colour"], minlength=4)
    spheres = next(line for line in res.stdout.splitlines() if line.startswith("spheres"))
    assert spheres.split() == ["spheres", str(len(z["centers"])), "intact", str(cc[0]), "red", str(cc[1]),
                               "green", str(cc[2]), "blue", str(cc[3])]
    assert "joint" in res.stdout and "fault" in res.stdout
    # lengths with units and a readable precision: "r = 0.5 m", "radius 40 m, thickness 2 m"
    packing = next(line for line in res.stdout.splitlines() if line.startswith("packing"))
    r = float(packing.split("r = ")[1].split()[0])
    assert packing.split("r = ")[1].split()[1] == "m" and len(repr(r)) <= 9
    fault = next(line for line in res.stdout.splitlines() if "(fault" in line)
    assert " m, thickness " in fault and fault.endswith(" m)") and "d = " not in res.stdout
    res = sgim("info", "out/model.npz", "--json", cwd=d)
    info = json.loads(res.stdout)
    assert info["spheres"] == len(z["centers"]) and info["bonded"] == int(z["bonded"].sum())


def test_info_on_a_missing_model(tmp_path):
    res = sgim("info", "nothing.npz", cwd=tmp_path)
    assert res.returncode == 2 and len(res.stderr.splitlines()) == 1 and "nothing.npz" in res.stderr


def _png_pixels(path):
    import matplotlib.image as mpimg

    img = mpimg.imread(str(path))
    return np.asarray(img, float)[..., :3]


def test_show_png(built):
    d, _ = built
    z = np.load(d / "out" / "model.npz")
    res = sgim("show", "out/model.npz", "-o", "x.png", "--hide-intact", "--translucent", "--cut-away", "y>0",
               "--width", "400", "--height", "300", cwd=d)
    assert res.returncode == 0, res.stderr
    selected = int(((z["colour"] != 0) & (z["centers"][:, 1] <= 0)).sum())
    assert selected > 0
    assert f"of {selected} selected" in res.stdout
    img = _png_pixels(d / "x.png")
    assert img.shape == (300, 400, 3)
    assert img.std() > 0.02, "blank picture"
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    coloured = ((r > g + 0.25) & (r > b + 0.25)) | ((g > r + 0.2) & (g > b + 0.2)) | ((b > r + 0.3) & (b > g + 0.2))
    assert coloured.sum() > 200, "no red, green or blue spheres drawn"
    os.unlink(d / "x.png")


def test_show_bad_cut_away(built):
    d, _ = built
    res = sgim("show", "out/model.npz", "-o", "y.png", "--cut-away", "q>1", cwd=d)
    assert res.returncode == 2
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and "--cut-away" in lines[0] and "'q>1'" in lines[0], res.stderr
    assert not (d / "y.png").exists()


def test_build_png_written(built):
    d, _ = built
    img = _png_pixels(d / "out" / "model.png")
    assert img.std() > 0.02


def test_rebuild_replaces_output(tmp_path):
    (tmp_path / "scene.toml").write_text(GOOD)
    for force in ([], ["--force"]):  # the second build replaces the first's output (sgim/outdir.py)
        res = sgim("build", "scene.toml", "-o", "out", "--formats", "npz", "--quiet", *force, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    assert sorted(os.listdir(tmp_path)) == ["out", "scene.toml"]
    assert sorted(os.listdir(tmp_path / "out")) == [".rockdem-output", "model.npz", "summary.json"]
    shutil.rmtree(tmp_path / "out")
