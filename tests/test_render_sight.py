"""Pictures draw only the spheres that can show (sgim/render.py in_sight, sgim/_render.py; issue 15, point 4).

The selection is compared with a brute-force transcription of its definition (every pixel cell of the picture
against every sphere, window coordinates from VTK's own camera matrix), and the pictures with the selection
against the pictures of every sphere, drawn by VTK: the same pixels, with most spheres of a dense block left out.
"""
from __future__ import annotations

import numpy as np
import pytest

import sgim.render as render_mod
from sgim.render import Frame, in_sight, sight_tolerances
from sgim.scene import scene_from_dict
from test_pictures_paraview import _model


def _block(n=10, seed=5, offset=0.0):
    """n^3 spheres of radius 0.5 on a grid of spacing 0.7, moved by up to 0.15 each way (they overlap): a dense
    block with a red slab through its middle and a green and a blue layer on either side."""
    rng = np.random.default_rng(seed)
    g = 0.7 * np.arange(n)
    c = np.array([[x, y, z] for z in g for y in g for x in g]) + rng.uniform(-0.15, 0.15, (n ** 3, 3))
    colour = np.zeros(n ** 3, int)
    mid = 0.35 * n
    colour[np.abs(c[:, 0] - mid) < 0.5] = 1
    colour[np.abs(c[:, 0] - mid + 1.2) < 0.35] = 2
    colour[np.abs(c[:, 0] - mid - 1.2) < 0.35] = 3
    return _model(c + offset, np.full(n ** 3, 0.5), colour)


def _vtk_window_coords(frame, points):
    """Window x, y and the depth along the view of `points`, from VTK's camera (its composite projection matrix
    and direction of projection), independently of Frame.project."""
    cam = frame.pl.camera
    m = np.array([[cam.GetCompositeProjectionTransformMatrix(frame.W / frame.H, -1, 1).GetElement(i, j)
                   for j in range(4)] for i in range(4)])
    h = np.c_[points, np.ones(len(points))] @ m.T
    ndc = h[:, :3] / h[:, 3:]
    x, y = (ndc[:, 0] + 1) * frame.W / 2, (ndc[:, 1] + 1) * frame.H / 2
    t = (points - np.array(cam.position)) @ np.array(cam.direction)
    return x, y, t - t.min()


def _brute_force(occluders, candidates, W, H, R, eps, bulge, tol):
    """The definition, cell by cell: a candidate sprite (x, y, t) may show unless, at every pixel cell within
    R + eps of its centre, some occluder holding the whole cell (its farthest corner within R - eps) draws a depth
    certainly in front of the nearest depth the candidate can draw there."""
    ci, cj = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    occ = np.full((H, W), np.inf)
    for xk, yk, tk in zip(*occluders):
        far = np.hypot(np.maximum(abs(ci - xk), abs(ci + 1 - xk)), np.maximum(abs(cj - yk), abs(cj + 1 - yk)))
        holds = far <= R - eps
        depth = tk - bulge * np.sqrt(np.maximum(1 - ((far + eps) / R) ** 2, 0))
        occ[holds] = np.minimum(occ[holds], depth[holds])
    shows = np.zeros(len(candidates[0]), bool)
    for k, (xk, yk, tk) in enumerate(zip(*candidates)):
        near = np.hypot(np.clip(xk, ci, ci + 1) - xk, np.clip(yk, cj, cj + 1) - yk)
        reach = near <= R + eps
        depth = tk - bulge * np.sqrt(np.maximum(1 - (np.maximum(near - eps, 0) / R) ** 2, 0))
        shows[k] = np.any(reach & ~(occ < depth - tol))
    return shows


def _extremes(c):
    """The rows with the least and the largest value of each column (kept with what shows: VTK's float32
    rounding of the drawn points depends on their bounds)."""
    return np.unique([int(np.argmin(c[:, a])) for a in range(3)] + [int(np.argmax(c[:, a])) for a in range(3)])


def test_selection_matches_its_definition_by_brute_force():
    m = _block(7)
    lo, hi = m.centers.min(0) - 0.5, m.centers.max(0) + 0.5
    frame = Frame(200, 150)
    try:
        s = frame.fit(lo, hi)
        # the window coordinates the selection uses are VTK's
        x, y, t = frame.project(m.centers)
        vx, vy, vt = _vtk_window_coords(frame, m.centers)
        assert np.abs(x - vx).max() < 1e-6 and np.abs(y - vy).max() < 1e-6
        assert np.abs((t - t.min()) - vt).max() < 1e-9 * np.ptp(t) + 1e-12
        px = 2 * 0.5 / s
        R, eps, bulge, tol = sight_tolerances(frame, m.centers, px)
        every = np.arange(len(m.centers))
        solid, ghost = in_sight(frame, m.centers, every, every[:0], px)
        expect = _brute_force((vx, vy, vt), (vx, vy, vt), frame.W, frame.H, R, eps, bulge, tol)
        assert np.array_equal(solid, np.union1d(every[expect], _extremes(m.centers))) and len(ghost) == 0
        assert 0.1 * len(every) < len(solid) < 0.9 * len(every)  # neither all nor none
        # translucent spheres (here the intact and green ones) are hidden by the opaque ones only
        opaque, faint = every[m.colour % 2 == 1], every[m.colour % 2 == 0]
        solid, ghost = in_sight(frame, m.centers, opaque, faint, px)
        at = (vx[opaque], vy[opaque], vt[opaque])
        expect = opaque[_brute_force(at, at, frame.W, frame.H, R, eps, bulge, tol)]
        assert np.array_equal(solid, np.union1d(expect, opaque[_extremes(m.centers[opaque])]))
        behind = (vx[faint], vy[faint], vt[faint])
        expect = faint[_brute_force(at, behind, frame.W, frame.H, R, eps, bulge, tol)]
        assert np.array_equal(ghost, np.union1d(expect, faint[_extremes(m.centers[faint])]))
        assert 0 < len(ghost) < len(faint)
    finally:
        frame.close()


def _pixels(path):
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), int)


@pytest.mark.parametrize("case", ["plain", "translucent_cut", "far"])
def test_picture_is_the_same_pixel_for_pixel_with_every_sphere_drawn(tmp_path, monkeypatch, case):
    m = _block(12, offset=2e4 if case == "far" else 0.0)
    kw = {"width": 400, "height": 300, "title": "block"}
    if case == "translucent_cut":
        kw.update(translucent=True, cut_away=["y<4", "z>3.5"])
    info = render_mod.render(m, tmp_path / "sight.png", **kw)
    monkeypatch.setattr(render_mod, "in_sight", lambda frame, centers, solid, ghost, px: (solid, ghost))
    every = render_mod.render(m, tmp_path / "every.png", **kw)
    assert every["hidden"] == 0 and info["drawn"] + info["hidden"] == every["drawn"]
    # most of a dense block cannot show; in translucent pictures the intact spheres are hidden by the opaque
    # coloured ones only
    assert info["hidden"] > (0.2 if case == "translucent_cut" else 0.6) * every["drawn"], info
    a, b = _pixels(tmp_path / "sight.png"), _pixels(tmp_path / "every.png")
    assert a.shape == b.shape == (300, 400, 3)
    assert np.array_equal(a, b), f"{np.sum(np.any(a != b, axis=2))} pixels differ"


def test_text_export_only_when_asked_for():
    scene = {"domain": {"min": [0, 0, 0], "max": [1, 1, 1]}, "packing": {"kind": "cubic", "radius": 0.5}}
    assert scene_from_dict(scene).formats == ("npz", "vtu", "png")
    assert "txt" in scene_from_dict({**scene, "output": {"formats": ["txt"]}}).formats
