"""Off-screen pictures on a machine without a display: drawn, and nothing from VTK on the terminal (VTK's
default window would try the X server first and print "bad X server connection"); run as subprocesses since
VTK writes its warnings to file descriptor 2 itself."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from sgim.render import VTK_WINDOW, offscreen_vtk
from test_dda_cli import SCENE as DDA_SCENE  # two blocks, 0.2 s, png among the formats
from test_scene_cli import GOOD  # the small jointed and faulted scene of the CLI tests

BIN = Path(sys.executable).parent
NOISE = re.compile(r"vtk|warn|x server|display", re.IGNORECASE)


def _headless_env():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", VTK_WINDOW)}
    return env


def _run(cmd, cwd):
    exe = BIN / cmd[0]
    argv = [str(exe)] if exe.exists() else [sys.executable, "-m", f"{cmd[0]}.cli"]
    return subprocess.run(argv + cmd[1:], cwd=cwd, env=_headless_env(), capture_output=True, text=True, timeout=300)


def _pixels(path):
    import matplotlib.image as mpimg

    return np.asarray(mpimg.imread(str(path)), float)[..., :3]


def _noise(stderr):
    return [line for line in stderr.splitlines() if NOISE.search(line)]


def test_sgim_build_and_show_png_without_display_are_quiet(tmp_path):
    (tmp_path / "scene.toml").write_text(GOOD)
    res = _run(["sgim", "build", "scene.toml", "-o", "out", "--formats", "npz,png", "--quiet"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert _noise(res.stderr) == [], res.stderr
    img = _pixels(tmp_path / "out" / "model.png")
    assert img.std() > 0.02, "blank picture"
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    assert ((r > g + 0.25) & (r > b + 0.25)).sum() > 200, "no red spheres drawn"
    res = _run(["sgim", "show", "out/model.npz", "-o", "x.png", "--width", "400", "--height", "300"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert _noise(res.stderr) == [], res.stderr
    assert _pixels(tmp_path / "x.png").shape == (300, 400, 3)


def test_dda_run_png_without_display_is_quiet(tmp_path):
    (tmp_path / "scene.toml").write_text(DDA_SCENE)
    res = _run(["dda", "run", "scene.toml", "-o", "out", "--quiet"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert _noise(res.stderr) == [], res.stderr
    assert _pixels(tmp_path / "out" / "final.png").std() > 0.02, "blank picture"


def test_offscreen_vtk_leaves_a_display_and_the_users_choice_alone(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv(VTK_WINDOW, raising=False)
    with offscreen_vtk() as window:
        assert window in ("vtkEGLRenderWindow", "vtkOSOpenGLRenderWindow")
        assert os.environ[VTK_WINDOW] == window
    assert VTK_WINDOW not in os.environ
    monkeypatch.setenv(VTK_WINDOW, "vtkXOpenGLRenderWindow")
    with offscreen_vtk() as window:
        assert window is None and os.environ[VTK_WINDOW] == "vtkXOpenGLRenderWindow"
    monkeypatch.delenv(VTK_WINDOW)
    monkeypatch.setenv("DISPLAY", ":0")
    with offscreen_vtk() as window:
        assert window is None and VTK_WINDOW not in os.environ
