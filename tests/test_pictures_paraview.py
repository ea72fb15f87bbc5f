"""Report-ready pictures and ParaView files (issue 19, points 3 and 5).

Pictures are checked by their pixels against what was drawn: the legend's swatches in the side panel, no model
pixel in the title band or the panel (at 400 x 300 and 1600 x 1100), a tall column shown whole (its red top and
blue bottom layers both visible, clear of the picture's edges), the scale bar's length against the column's
known height on screen (parallel camera: h cos(elevation) + 2 r), DDA blocks in the colour map's colours for
their displacements. ParaView files are read back with meshio / pyvista and compared with the model's arrays, the
engine's result.npz and the deck's run.npz, and with a membership table rebuilt by a plain loop.
"""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib.image as mpimg
import meshio
import numpy as np
import pytest

from adapters.result import RunResult
from adapters.spec import SphereRun
from engine_runs import hand_run, require_engine
from sgim.model import SphereModel
from sgim.render import COLOURS, CUT_COLOUR, Frame, cut_mask, render, visible_spheres
from test_scene_cli import GOOD

ROOT = Path(__file__).resolve().parents[1]


def _model(centers, radii, colour):
    n = len(centers)
    z = np.zeros(0)
    return SphereModel(centers=np.asarray(centers, float), radii=np.asarray(radii, float),
                       colour=np.asarray(colour, np.int8), colour_source=np.full(n, -1, np.int32),
                       bonds=np.zeros((0, 2), np.int64), bonded=np.zeros(0, bool), cut_by=np.zeros(0, np.int32),
                       member_sphere=np.zeros(0, np.int64), member_disc=np.zeros(0, np.int32),
                       member_kind=np.zeros(0, np.int8), member_offset=z, disc_centre=np.zeros((0, 3)),
                       disc_normal=np.zeros((0, 3)), disc_radius=z, disc_thickness=z, disc_name=[])


def _column(h=10.0, r=0.5):
    """A vertical column of touching spheres 0 <= z <= h: the top sphere red, the bottom one blue, the rest
    intact."""
    z = np.arange(r, h, 2 * r)
    colour = np.zeros(len(z), int)
    colour[-1], colour[0] = 1, 3
    return _model(np.c_[np.zeros_like(z), np.zeros_like(z), z], np.full(len(z), r), colour)


def _pixels(path):
    return np.asarray(mpimg.imread(str(path)), float)[..., :3]


def _near(img, rgb, tol=0.12):
    """Pixels of colour `rgb` (greys of anti-aliased text and lines excluded: the colours here are not grey)."""
    coloured = img.max(axis=2) - img.min(axis=2) > 0.08
    return np.all(np.abs(img - np.asarray(rgb)[None, None, :]) < tol, axis=2) & coloured


def _layout(w, h, title):
    f = Frame(w, h, title)
    f.close()
    return f.title_px, f.panel_px, f.fs


def test_cut_away_removes_the_spheres_meeting_every_condition():
    rng = np.random.default_rng(3)
    c = rng.uniform(-10, 60, (2000, 3))
    m = _model(c, np.full(2000, 0.1), np.zeros(2000, int))
    gone = (c[:, 1] < 0) & (c[:, 2] > 50)  # the corner, by hand
    assert np.array_equal(cut_mask(c, ["y<0", "z>50"]), gone)
    assert np.array_equal(cut_mask(c, ["y < 0"]), c[:, 1] < 0)
    assert not cut_mask(c, []).any()
    idx, _ = visible_spheres(m, cut_away=["y<0", "z>50"])
    assert np.array_equal(idx, np.flatnonzero(~gone))


@pytest.mark.parametrize("size", [(400, 300, 0.0), (1600, 1100, 0.0), (400, 300, 2e4)])
def test_column_shown_whole_with_legend_and_scale_bar_clear_of_the_model(tmp_path, size):
    w, h, far = size  # far: the column moved 20 km from the origin (the camera's clipping range follows)
    m = _column()
    m.centers += far
    info = render(m, tmp_path / "c.png", width=w, height=h, title="a tall column of spheres")
    img = _pixels(tmp_path / "c.png")
    assert img.shape == (h, w, 3)
    title_px, panel_px, fs = _layout(w, h, "t")
    red, blue, sand = _near(img, COLOURS[1], 0.2), _near(img, COLOURS[3], 0.2), _near(img, COLOURS[0], 0.12)
    model_px = red | blue | sand
    # legend: the three colours drawn, as swatches in the side panel
    assert info["legend"] == ["intact rock", "fault (red)", "joint, blue side"]
    panel = np.zeros_like(model_px)
    panel[:, w - panel_px:] = True
    for mask in (red, blue, sand):
        assert (mask & panel).sum() >= 4, "a legend swatch is missing"
    # nothing of the model in the title band, nor in the panel beyond the swatches' column
    assert not model_px[:title_px].any()
    swatch_right = w - panel_px + int(np.ceil(1.7 * fs))  # discs of radius 0.55 fs centred 1.05 fs in
    assert not model_px[:, swatch_right:].any()
    # the column whole: red top and blue bottom both drawn, clear of the model area's edges
    area = model_px[:, :w - panel_px] & ~panel[:, :w - panel_px]
    rows = np.flatnonzero(area.any(axis=1))
    assert (red[:, :w - panel_px]).sum() > 3 and (blue[:, :w - panel_px]).sum() > 3
    assert rows.min() > title_px + 2 and rows.max() < h - 3
    # scale bar: a black horizontal bar at the panel's bottom, info["scale_bar_m"] metres long
    black = np.all(img < 0.25, axis=2)
    bottom = black[int(0.8 * h):, w - panel_px:]
    row = bottom[np.argmax(bottom.sum(axis=1))]
    bar_px = np.ptp(np.flatnonzero(row)) + 1
    px_per_m = bar_px / info["scale_bar_m"]
    # the distance on screen between the red top and blue bottom spheres' centres (their pixels' centroids):
    # 9 m vertically, seen 35 degrees from above by a parallel camera
    top = np.argwhere(red[:, :w - panel_px]).mean(axis=0)
    low = np.argwhere(blue[:, :w - panel_px]).mean(axis=0)
    expect = 9.0 * np.cos(np.radians(35.0)) * px_per_m
    assert abs((low[0] - top[0]) - expect) <= 0.03 * expect + 2, (low[0] - top[0], expect)
    assert abs(low[1] - top[1]) <= 0.01 * expect + 2  # vertical on screen (shading shifts centroids a little)


def test_cut_away_region_is_drawn_and_named(tmp_path):
    rng = np.random.default_rng(0)
    c = rng.uniform(0, 10, (3000, 3))
    m = _model(c, np.full(3000, 0.2), np.zeros(3000, int))
    info = render(m, tmp_path / "cut.png", cut_away=["y<5", "z>5"], width=400, height=300)
    assert info["selected"] == int(np.sum(~((c[:, 1] < 5) & (c[:, 2] > 5))))
    assert info["legend"][-1] == "cut away:\ny<5 and z>5"
    img = _pixels(tmp_path / "cut.png")
    orange = _near(img, CUT_COLOUR, 0.15)
    assert orange[:, :400 - _layout(400, 300, None)[1]].sum() > 30  # the outline, in the model area


def _blocks_and_displacements():
    from dda.render import faces_polydata

    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    pts, fv, fvs, fs = [], [], [0], [0]
    for k, shift in enumerate(([0, 0, -1.0], [0, 0, 0.0], [2.0, 0, 0.0])):
        pts.append(cube * ([4, 3, 1] if k == 0 else 1) + shift - ([1, 1, 0] if k == 0 else 0))
        for f in faces:
            fv += [8 * k + i for i in f]
            fvs.append(len(fv))
        fs.append(fs[-1] + 6)
    return faces_polydata(np.concatenate(pts), fvs, fv, fs, [True, False, False], [0.0, 0.0, 0.3])


def test_dda_picture_colours_blocks_by_displacement(tmp_path):
    import matplotlib

    from dda.render import render_meshes

    info = render_meshes(tmp_path / "d.png", blocks=_blocks_and_displacements(), width=400, height=300,
                         title="two blocks   t = 1 s")
    assert info["legend"] == ["fixed block"] and info["displacement_max_m"] == pytest.approx(0.3)
    img = _pixels(tmp_path / "d.png")
    _, panel_px, _ = _layout(400, 300, "t")
    cmap = matplotlib.colormaps["viridis"]
    model = img[:, :400 - panel_px]
    # lit faces darken a colour; its hue stays: compare chromaticity
    def chroma(a):
        return a / np.maximum(a.sum(axis=-1, keepdims=True), 1e-6)

    def share(rgb):
        return (np.abs(chroma(model) - chroma(np.asarray(rgb))).sum(axis=-1) < 0.06).sum()

    assert share(cmap(1.0)[:3]) > 200, "the moved block is not in the colour map's top colour"
    assert share(cmap(0.0)[:3]) > 200, "the block at rest is not in the colour map's bottom colour"
    # the colour bar: both ends of the map in the side panel
    panel = img[:, 400 - panel_px:]
    for end in (0.0, 1.0):
        assert np.all(np.abs(panel - np.asarray(cmap(end)[:3])) < 0.08, axis=2).sum() > 10


def _sgim(*args, cwd):
    return subprocess.run([sys.executable, "-m", "sgim.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def test_model_vtu_holds_ids_memberships_and_bonds_as_lines(tmp_path):
    (tmp_path / "s.toml").write_text(GOOD)
    r = _sgim("build", "s.toml", "-o", "out", "--formats", "npz,vtu", "--quiet", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    m = SphereModel.load(tmp_path / "out" / "model.npz")
    v = meshio.read(tmp_path / "out" / "model.vtu")
    n, nb = m.n, len(m.bonds)
    assert np.array_equal(v.points, m.centers)
    assert np.array_equal(v.cells_dict["vertex"].ravel(), np.arange(n))
    assert np.array_equal(v.cells_dict["line"], m.bonds)
    pd = v.point_data
    assert np.array_equal(pd["id"], np.arange(n)) and np.array_equal(pd["radius"], m.radii)
    assert np.array_equal(pd["colour"], m.colour)
    kinds = dict(zip([c.type for c in v.cells], range(len(v.cells))))
    cd = {k: v.cell_data[k][kinds["line"]] for k in ("bonded", "cut_by", "cell_kind")}
    assert np.array_equal(cd["bonded"], m.bonded.astype(int)) and np.array_equal(cd["cut_by"], m.cut_by)
    assert np.all(cd["cell_kind"] == 1) and np.all(v.cell_data["cell_kind"][kinds["vertex"]] == 0)
    assert (~m.bonded).any() and len(m.member_sphere) > 0  # the scene cuts bonds and has members
    # memberships rebuilt by a plain loop: each sphere's (disc, kind) by ascending disc
    disc = np.asarray(pd["member_disc"]).reshape(n, -1)
    kind = np.asarray(pd["member_kind"]).reshape(n, -1)
    for i in range(n):
        rows = sorted((int(d), int(k)) for s, d, k in zip(m.member_sphere, m.member_disc, m.member_kind) if s == i)
        assert pd["member_count"][i] == len(rows)
        got = [(int(d), int(k)) for d, k in zip(disc[i], kind[i]) if d >= 0]
        assert got == rows[:disc.shape[1]]


def _adapters(*args):
    return subprocess.run([sys.executable, "-m", "adapters.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)


def _pvd(path):
    return [(float(d.get("timestep")), d.get("file")) for d in ET.parse(path).getroot().iter("DataSet")]


def _check_frames(folder, res_folder, run):
    res = RunResult.load(res_folder)
    entries = _pvd(folder / "result.pvd")
    assert len(entries) == len(res.time) and len(res.time) >= 2
    assert np.allclose([t for t, _ in entries], res.time, rtol=1e-8, atol=1e-15)
    for k in (0, len(entries) - 1):
        f = meshio.read(folder / entries[k][1])
        assert np.array_equal(f.points, res.pos[k])
        assert np.allclose(f.point_data["displacement"], res.pos[k] - res.x0)
        assert np.array_equal(f.point_data["radius"], run.radii)
    fin = meshio.read(folder / "final.vtu")
    assert np.array_equal(fin.points, res.final_pos) and np.array_equal(fin.point_data["velocity"], res.final_vel)
    assert np.array_equal(fin.cells_dict["line"], np.c_[run.bond_i, run.bond_j])
    line = [c.type for c in fin.cells].index("line")
    assert np.array_equal(fin.cell_data["intact"][line], res.bond_intact.astype(int))
    return res


def _hand_run(path):
    """Nine spheres in a bonded 3 x 3 wall, its bottom row fixed, under gravity for 0.004 s (records every 1 ms)."""
    c = np.array([[x, 0.0, z] for z in (0.1, 0.3, 0.5) for x in (0.1, 0.3, 0.5)])
    bonds = [(i, i + 1) for i in range(8) if (i + 1) % 3] + [(i, i + 3) for i in range(6)]
    hand_run(c, 0.1, fixed=[0, 1, 2], bonds=bonds, duration=0.004, record_every=0.001).save(path)
    return path


@pytest.mark.parametrize("engine", ["liggghts", "yade", "in-house"])
def test_adapters_run_writes_paraview_frames_for_every_engine(tmp_path, engine):
    if engine != "in-house":
        require_engine(engine)
    deck = tmp_path / "deck"
    r = _adapters("export", _hand_run(tmp_path / "hand.npz"), "--to", "yade" if engine == "yade" else "liggghts",
                  "-o", deck, "--quiet")
    assert r.returncode == 0, r.stderr
    r = _adapters("run", deck, "--quiet", *(["--in-house"] if engine == "in-house" else []))
    assert r.returncode == 0, r.stderr
    out = deck / ("result-dda" if engine == "in-house" else "result")
    res = _check_frames(out, out, SphereRun.load(deck / "run.npz"))
    assert res.engine == {"in-house": "dda"}.get(engine, engine)
    if engine == "liggghts":  # the result exported again into a folder of its own, from result.npz
        r = _adapters("export", out / "result.npz", "--to", "vtu", "-o", tmp_path / "pv", "--quiet")
        assert r.returncode == 0, r.stderr
        _check_frames(tmp_path / "pv", out, SphereRun.load(deck / "run.npz"))
        r = _adapters("export", out / "result.npz", "--to", "yade", "-o", tmp_path / "no", "--quiet")
        assert r.returncode == 2 and "exports to vtu only" in r.stderr and len(r.stderr.splitlines()) == 1
        assert not (tmp_path / "no").exists()


def test_result_without_records_or_run_gives_start_and_end_frames(tmp_path):
    """A result too large for records (pos None) and without its deck's run.npz: two frames (start, end) with
    positions and displacements only, and an empty bond list in final.vtu."""
    from adapters.frames import export_result

    rng = np.random.default_rng(5)
    x0 = rng.random((7, 3))
    res = RunResult(engine="liggghts", x0=x0, final_pos=x0 + 0.1, final_vel=np.ones((7, 3)),
                    bond_intact=np.ones(4, bool), time=np.array([0.0, 0.5, 1.0]), pos=None, steps=100, dt=0.01)
    res.save(tmp_path / "result")
    info = export_result(tmp_path / "result" / "result.npz", tmp_path / "pv")
    assert info["run"] is None and info["frames"] == 2
    entries = _pvd(tmp_path / "pv" / "result.pvd")
    assert [t for t, _ in entries] == [0.0, 1.0]
    end = meshio.read(tmp_path / "pv" / entries[1][1])
    assert np.array_equal(end.points, x0 + 0.1) and "radius" not in end.point_data
    assert np.allclose(end.point_data["displacement_magnitude"], np.sqrt(0.03))
    fin = meshio.read(tmp_path / "pv" / "final.vtu")
    assert "line" not in fin.cells_dict and np.array_equal(fin.point_data["velocity"], np.ones((7, 3)))
