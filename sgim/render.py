"""Off-screen pictures of sphere models in the paper's colours (pyvista / VTK)."""
from __future__ import annotations

import contextlib
import functools
import os
import sys

import numpy as np

from .model import SphereModel, atomic_path
from .scene import parse_cut

COLOURS = np.array([
    [0.80, 0.74, 0.60],  # intact: sandstone
    [0.86, 0.08, 0.08],  # red: inside a fault
    [0.10, 0.68, 0.18],  # green
    [0.12, 0.30, 0.92],  # blue
])


VTK_WINDOW = "VTK_DEFAULT_OPENGL_WINDOW"


@functools.lru_cache(maxsize=None)
def _headless_window_class():
    """VTK's render window that needs no X server, by the libraries this machine has: EGL (Mesa's software
    renderer, or a GPU's driver), else OSMesa; None when neither is there."""
    if not sys.platform.startswith("linux"):
        return None
    from ctypes.util import find_library

    for lib, window in (("EGL", "vtkEGLRenderWindow"), ("OSMesa", "vtkOSOpenGLRenderWindow")):
        if find_library(lib):
            return window
    return None


@contextlib.contextmanager
def offscreen_vtk():
    """Around the making of an off-screen pyvista Plotter: without a display (DISPLAY unset) VTK's default
    window first tries the X server, fails and writes "bad X server connection" to the terminal before it
    falls back to EGL; here the window that needs no X server is asked for from the start (VTK reads
    VTK_DEFAULT_OPENGL_WINDOW whenever it makes a window). A VTK_DEFAULT_OPENGL_WINDOW set by the user, or a
    display, leaves VTK's choice alone. Yields the window class asked for, or None."""
    window = None
    if not os.environ.get(VTK_WINDOW) and not os.environ.get("DISPLAY"):
        window = _headless_window_class()
    if window is None:
        yield None
        return
    os.environ[VTK_WINDOW] = window
    try:
        yield window
    finally:
        os.environ.pop(VTK_WINDOW, None)


def visible_spheres(model: SphereModel, hide_intact=False, cut_away=()):
    """Indices of the spheres to draw and whether each is on the outside of what is drawn.

    A sphere is hidden by the others when it keeps all its lattice neighbours among
    the drawn spheres; only the exposed ones need drawing when intact spheres are opaque.
    """
    keep = np.ones(model.n, bool)
    for expr in cut_away:
        axis, sign, value = parse_cut(expr)
        keep &= ~(sign * (model.centers[:, axis] - value) > 0)
    if hide_intact:
        keep &= model.colour != 0
    coord = int(model.meta.get("packing", {}).get("coordination", 0) or 0)
    exposed = np.ones(model.n, bool)
    if coord and len(model.bonds):
        both = keep[model.bonds[:, 0]] & keep[model.bonds[:, 1]]
        deg = np.bincount(model.bonds[both].ravel(), minlength=model.n)
        exposed = deg < coord
    return np.nonzero(keep)[0], exposed


def render(model: SphereModel, path, hide_intact=False, translucent=False, cut_away=(), width=1600, height=1100,
           title=None):
    import pyvista as pv

    pv.OFF_SCREEN = True
    idx, exposed = visible_spheres(model, hide_intact, cut_away)
    col = model.colour[idx]
    # opaque intact spheres hidden by their neighbours are never seen
    if translucent:
        solid = idx[(col != 0)]
        ghost = idx[(col == 0) & exposed[idx]]
    else:
        solid = idx[(col != 0) | exposed[idx]]
        ghost = idx[:0]
    with offscreen_vtk():
        pl = pv.Plotter(off_screen=True, window_size=(int(width), int(height)))
    pl.set_background("white")
    lo, hi = model.centers.min(0) if model.n else np.zeros(3), model.centers.max(0) if model.n else np.ones(3)
    span = float(np.max(hi - lo)) or 1.0
    r = float(np.median(model.radii)) if model.n else 1.0
    px = max(1.5, 1.6 * width * 2 * r / span)
    if len(solid):
        cloud = pv.PolyData(model.centers[solid])
        cloud["rgb"] = (COLOURS[model.colour[solid]] * 255).astype(np.uint8)
        pl.add_mesh(cloud, scalars="rgb", rgb=True, render_points_as_spheres=True, point_size=px)
    if len(ghost):
        g = pv.PolyData(model.centers[ghost])
        pl.add_mesh(g, color=COLOURS[0], opacity=0.06, render_points_as_spheres=True, point_size=px)
    outline = pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
    pl.add_mesh(outline, style="wireframe", color="grey", line_width=1)
    if title:
        pl.add_text(title, font_size=10, color="black")
    # look from the south-south-east, 35 degrees above the horizon
    centre = (lo + hi) / 2
    az, el = np.radians(-150.0), np.radians(35.0)
    eye = centre + 2.2 * span * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    pl.camera_position = [tuple(eye), tuple(centre), (0.0, 0.0, 1.0)]
    pl.reset_camera()
    pl.camera.zoom(1.35)
    with atomic_path(path) as tmp:
        pl.screenshot(tmp + ".png")
        os.replace(tmp + ".png", tmp)
    pl.close()
    return {"drawn": int(len(solid) + len(ghost)), "selected": int(len(idx))}
