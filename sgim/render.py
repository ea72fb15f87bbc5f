"""Off-screen pictures of sphere models in the paper's colours (pyvista / VTK)."""
from __future__ import annotations

import contextlib
import functools
import os
import sys
from ctypes.util import find_library

import numpy as np

from ._render import column_bounds, front_depths, mark_extremes, project_rows, reaches_front
from .common import atomic_path
from .model import SphereModel
from .portable import matmul, norm, sin_cos_deg
from .scene import parse_cut

# pyvista and vtk are imported inside the functions that draw: they take seconds to load, and only pictures need them

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


def _vtk():
    """The VTK classes the frame draws with, taken from their own modules (``import vtk`` loads every module of
    VTK: seconds on a busy machine; pyvista's plotting has loaded the text and OpenGL renderers they need)."""
    from types import SimpleNamespace

    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData, vtkPolyLine
    from vtkmodules.vtkFiltersSources import vtkRegularPolygonSource
    from vtkmodules.vtkRenderingCore import vtkActor2D, vtkPolyDataMapper2D, vtkTextActor

    return SimpleNamespace(vtkPoints=vtkPoints, vtkCellArray=vtkCellArray, vtkPolyData=vtkPolyData,
                           vtkPolyLine=vtkPolyLine, vtkRegularPolygonSource=vtkRegularPolygonSource,
                           vtkActor2D=vtkActor2D, vtkPolyDataMapper2D=vtkPolyDataMapper2D, vtkTextActor=vtkTextActor)


CUT_COLOUR = np.array([0.95, 0.45, 0.05])  # orange: where spheres were cut away
COLOUR_LABELS = ("intact rock", "fault (red)", "joint, green side", "joint, blue side")


def parse_cuts(cut_away):
    """[(axis, sign, value)] of the cut-away expressions (ValueError for a bad one)."""
    return [parse_cut(e) for e in cut_away]


def cut_mask(centers, cut_away):
    """True for the spheres cut away: those whose centre satisfies every condition of `cut_away` (so
    ``['y<0', 'z>50']`` removes the corner y < 0 and z > 50; one condition removes a half-space; none removes
    nothing)."""
    cuts = parse_cuts(cut_away)
    if not cuts:
        return np.zeros(len(centers), bool)
    gone = np.ones(len(centers), bool)
    for axis, sign, value in cuts:
        gone &= sign * (centers[:, axis] - value) > 0
    return gone


def visible_spheres(model: SphereModel, hide_intact=False, cut_away=()):
    """Indices of the spheres to draw and whether each is on the outside of what is drawn.

    A sphere is hidden by the others when it keeps all its lattice neighbours among
    the drawn spheres; only the exposed ones need drawing when intact spheres are opaque.
    `cut_away`: see :func:`cut_mask` (a sphere is removed when it satisfies all the conditions).
    """
    keep = ~cut_mask(model.centers, cut_away)
    if hide_intact:
        keep &= model.colour != 0
    coord = int(model.meta.get("packing", {}).get("coordination", 0) or 0)
    exposed = np.ones(model.n, bool)
    if coord and len(model.bonds):
        both = keep[model.bonds[:, 0]] & keep[model.bonds[:, 1]]
        deg = np.bincount(model.bonds[both].ravel(), minlength=model.n)
        exposed = deg < coord
    return np.nonzero(keep)[0], exposed


# -- picture frame: title band, model area, side panel (legend, colour bar, scale bar) ------------------------

def _nice_length(x):
    """The largest of 1, 2, 5 x 10^k not above x (x > 0)."""
    k = np.floor(np.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10 ** k <= x:
            return m * 10 ** k
    return 10 ** k


def length_label(L):
    """'20 mm', '0.5 m', '5 m', '2 km' for a length L [m] (metres from 0.1 m up to 1 km)."""
    for unit, f, least in (("km", 1e3, 1e3), ("m", 1.0, 0.1), ("mm", 1e-3, 1e-3), ("\u00b5m", 1e-6, 0.0)):
        if L >= least * 0.999:
            v = L / f
            return f"{v:.0f} {unit}" if abs(v - round(v)) < 1e-9 else f"{v:g} {unit}"
    return f"{L:g} m"


class Frame:
    """An off-screen pyvista Plotter laid out for a report picture of `width` x `height` pixels: a title band
    at the top, the model fitted by a parallel camera into the area left of a side panel, and the panel holding
    the legend, a colour bar and a scale bar. Text sizes follow the picture height, and nothing in the bands
    overlaps the model's area at any size (400 x 300 as well as 1600 x 1100)."""

    def __init__(self, width, height, title=None):
        import pyvista as pv

        pv.OFF_SCREEN = True
        self.W, self.H = int(width), int(height)
        with offscreen_vtk():  # no X server tried, no warning on the terminal
            self.pl = pv.Plotter(off_screen=True, window_size=(self.W, self.H))
        self.pl.set_background("white")
        self.pl.enable_parallel_projection()
        self.fs = int(np.clip(round(self.H / 55), 8, 20))  # font size [pt]
        self.title_px = int(round(2.2 * self.fs)) if title else int(round(0.6 * self.fs))
        self.panel_px = int(np.clip(0.24 * self.W, 120, 340))
        self.legend = []  # (label, rgb)
        self.title = title
        self.panel_top = self.H - self.title_px  # next free height in the panel (pixels from the bottom)

    # model area in pixels: x in [0, W - panel], y in [0, H - title band]
    @property
    def area(self):
        return 0.0, 0.0, float(self.W - self.panel_px), float(self.H - self.title_px)

    def fit(self, lo, hi, azimuth=-150.0, elevation=35.0):
        """Parallel camera looking from `azimuth` / `elevation` [degrees] that shows the box lo..hi whole,
        axes labels included, centred in the model area. Returns the scale [m per pixel]. The camera's numbers
        have the same bits on every CPU (sgim/portable.py): the spheres drawn (:func:`in_sight`) follow from them."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        span = float(np.max(hi - lo)) or 1.0
        (sa, ca), (se, ce) = sin_cos_deg(azimuth), sin_cos_deg(elevation)
        d = np.array([ce * ca, ce * sa, se])  # towards the eye
        right = np.cross(-d, [0.0, 0.0, 1.0])
        right /= norm(right)
        up = np.cross(right, -d)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        pr, pu = matmul(corners, right), matmul(corners, up)
        x0, y0, x1, y1 = self.area
        # room for the axes' labels and titles around the box
        mx, my = 5.0 * self.fs + 0.04 * (x1 - x0), 4.5 * self.fs + 0.04 * (y1 - y0)
        aw, ah = max(x1 - x0 - 2 * mx, 20.0), max(y1 - y0 - 2 * my, 20.0)
        wr, wu = max(pr.max() - pr.min(), 1e-12 * span), max(pu.max() - pu.min(), 1e-12 * span)
        s = max(wr / aw, wu / ah)
        mid = (lo + hi) / 2
        mid = mid + right * ((pr.max() + pr.min()) / 2 - matmul(mid, right)) \
            + up * ((pu.max() + pu.min()) / 2 - matmul(mid, up))
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        focal = mid - right * (cx - self.W / 2) * s - up * (cy - self.H / 2) * s
        cam = self.pl.camera
        cam.focal_point = tuple(focal)
        cam.position = tuple(focal + d * 4.0 * span)
        cam.up = tuple(up)
        cam.parallel_scale = s * self.H / 2
        self.pl.renderer.ResetCameraClippingRange()
        self.scale, self._d, self._right, self._up, self._focal = s, d, right, up, focal
        return s

    def project(self, points, rows=None):
        """Window coordinates x, y [pixels from the lower left corner] and depth t [m along the view, growing away
        from the eye] of `points` (n x 3), or of points[rows], through the camera of :meth:`fit`, one rounding per
        product and sum (sgim/_render.py, project_rows: the same bits on every CPU)."""
        pts = np.ascontiguousarray(points, dtype=float)
        rows = np.arange(len(pts)) if rows is None else np.asarray(rows, np.int64)
        return project_rows(pts, rows, np.asarray(self._focal, float), np.asarray(self._right, float),
                            np.asarray(self._up, float), np.asarray(self._d, float), float(self.scale),
                            self.W / 2, self.H / 2)

    def axes(self, lo, hi):
        """The box lo..hi in grey with three of its edges as axes (the lower front edges along x and y, the left
        vertical edge along z): ticks at round values, labels in metres and titles 'x [m]' ... placed outside
        the box on screen. Call after :meth:`fit`."""
        import pyvista as pv
        vtk = _vtk()

        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        self.pl.add_mesh(pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])), style="wireframe",
                         color="grey", line_width=1)
        d, right, up, s = self._d, self._right, self._up, self.scale
        centre = (lo + hi) / 2
        corner = np.where(d > 0, hi, lo)  # the corner nearest the eye
        # x and y along the bottom edges through the nearest corner; z on the left-most vertical edge
        verts = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])])
        left = verts[np.argmin(verts @ right[:2])]
        edges = {0: (np.array([lo[0], corner[1], lo[2]]), 0), 1: (np.array([corner[0], lo[1], lo[2]]), 1),
                 2: (np.array([left[0], left[1], lo[2]]), 2)}
        ticks_pts, lines = [], []
        self.axis_labels = []

        def text(label, at, offset_px, size=None):
            t = vtk.vtkTextActor()
            t.SetInput(label)
            tp = t.GetTextProperty()
            tp.SetFontSize(size or self.fs)
            tp.SetColor(0.0, 0.0, 0.0)
            tp.SetJustificationToCentered()
            tp.SetVerticalJustificationToCentered()
            pos = at + (right * offset_px[0] + up * offset_px[1]) * s
            t.GetPositionCoordinate().SetCoordinateSystemToWorld()
            t.GetPositionCoordinate().SetValue(*pos)
            self.pl.renderer.AddViewProp(t)
            self.axis_labels.append(label)

        for k, (start, axis) in edges.items():
            a, b = lo[axis], hi[axis]
            # at most 4 ticks, and at least 5 font sizes apart on screen
            e_px = abs(b - a) * float(np.hypot(right[axis], up[axis])) / s
            most = int(np.clip(e_px // (5.0 * self.fs) + 1, 2, 4))
            step = _nice_length(max(b - a, 1e-12) / max(most - 1, 1))
            vals = np.arange(np.ceil(a / step - 1e-9), np.floor(b / step + 1e-9) + 1) * step
            while len(vals) > most:
                step = _nice_length(2.6 * step)  # the next of 1, 2, 5 x 10^k
                vals = np.arange(np.ceil(a / step - 1e-9), np.floor(b / step + 1e-9) + 1) * step
            vals = vals + 0.0  # no "-0"
            mid = start.copy()
            mid[axis] = (a + b) / 2
            # outward on screen: away from the box's centre, perpendicular to the edge
            e = np.zeros(3)
            e[axis] = 1.0
            e2 = np.array([e @ right, e @ up])
            o2 = np.array([(mid - centre) @ right, (mid - centre) @ up])
            n2 = np.array([-e2[1], e2[0]]) if np.linalg.norm(e2) > 1e-9 else np.array([-1.0, 0.0])
            n2 /= np.linalg.norm(n2)
            if n2 @ o2 < 0:
                n2 = -n2
            tick3 = (right * n2[0] + up * n2[1]) * 0.5 * self.fs * s
            for v in vals:
                p = start.copy()
                p[axis] = v
                ticks_pts += [p, p + tick3]
                lines.append(len(ticks_pts) - 2)
                text(f"{v:.6g}", p, n2 * 2.2 * self.fs)
            if axis == 2:  # above the vertical axis: clear of its tick labels whatever the range
                end = start.copy()
                end[2] = b
                text("z [m]", end, np.array([-1.2 * self.fs, 1.6 * self.fs]))
            else:
                text("xyz"[axis] + " [m]", mid, n2 * 4.2 * self.fs)
        if ticks_pts:
            pts = np.array(ticks_pts)
            cells = np.column_stack([np.full(len(lines), 2), lines, np.array(lines) + 1]).ravel()
            self.pl.add_mesh(pv.PolyData(pts, lines=cells), color="black", line_width=1)

    def add_legend_entry(self, label, rgb):
        self.legend.append((label, np.asarray(rgb, float)))

    def _panel_text(self, text, y_px, size=None, color="black"):
        vtk = _vtk()

        t = vtk.vtkTextActor()
        t.SetInput(text)
        tp = t.GetTextProperty()
        tp.SetFontSize(size or self.fs)
        tp.SetColor(*self._rgb(color))
        tp.SetVerticalJustificationToTop()
        t.SetPosition(self.W - self.panel_px + 0.5 * self.fs, y_px)
        self.pl.renderer.AddViewProp(t)
        return t

    @staticmethod
    def _rgb(color):
        import pyvista as pv

        return pv.Color(color).float_rgb

    def _disc_actor(self, x, y, radius, rgb):
        """A filled disc of `radius` pixels at pixel (x, y) (a legend swatch)."""
        vtk = _vtk()

        src = vtk.vtkRegularPolygonSource()
        src.SetNumberOfSides(24)
        src.SetRadius(radius)
        src.SetCenter(x, y, 0.0)
        mapper = vtk.vtkPolyDataMapper2D()
        mapper.SetInputConnection(src.GetOutputPort())
        act = vtk.vtkActor2D()
        act.SetMapper(mapper)
        act.GetProperty().SetColor(*[float(c) for c in rgb])
        self.pl.renderer.AddViewProp(act)
        return act

    def _draw_legend(self):
        """One row per entry: a disc of the entry's colour and its label in black, top of the side panel."""
        row = 1.7 * self.fs
        y = self.panel_top - 0.6 * self.fs
        x = self.W - self.panel_px + 0.5 * self.fs
        self.legend_actors = []
        for label, rgb in self.legend:
            h = row * (1 + 0.75 * label.count("\n"))
            y -= h
            self.legend_actors.append(self._disc_actor(x + 0.55 * self.fs, y + h - 0.5 * row, 0.55 * self.fs, rgb))
            t = self._panel_text(label, y + h - 0.5 * row + 0.5 * self.fs)
            t.SetPosition(x + 1.6 * self.fs, y + h - 0.5 * row + 0.6 * self.fs)
            self.legend_actors.append(t)
        self.panel_top = y - 0.4 * self.fs

    def colour_bar(self, title, mapper):
        """A vertical colour bar of the scalars drawn by `mapper` (an actor's mapper), in the panel under the
        legend."""
        self._bar = (title, mapper)

    def _draw_colour_bar(self):
        title, mapper = self._bar
        self._panel_text(title, self.panel_top - 0.4 * self.fs)
        top = self.panel_top - 2.6 * self.fs  # under the title, with room for the top label
        bottom = max(top - max(0.3 * self.H, 5 * self.fs), 4.5 * self.fs)
        self.bar_actor = self.pl.add_scalar_bar(
            title="", mapper=mapper, vertical=True, position_x=(self.W - self.panel_px + 0.5 * self.fs) / self.W,
            position_y=bottom / self.H, width=(self.panel_px - 1.0 * self.fs) / self.W,
            height=(top - bottom) / self.H, label_font_size=self.fs, color="black", n_labels=4, fmt="%.3g",
            unconstrained_font_size=True)
        self.bar_actor.SetBarRatio(min(0.9, 1.8 * self.fs / (self.panel_px - 1.0 * self.fs)))
        self.panel_top = bottom

    def _scale_bar(self):
        """A bar of a round length [m] drawn to the picture's scale (exact: the camera is parallel)."""
        vtk = _vtk()

        max_px = 0.7 * (self.panel_px - self.fs)
        L = _nice_length(max_px * self.scale)
        px = L / self.scale
        x0, y0 = self.W - self.panel_px + 0.5 * self.fs, 1.2 * self.fs
        pts = vtk.vtkPoints()
        tick = 0.5 * self.fs
        for p in ((x0, y0 + tick), (x0, y0), (x0 + px, y0), (x0 + px, y0 + tick)):
            pts.InsertNextPoint(p[0], p[1], 0.0)
        line = vtk.vtkPolyLine()
        line.GetPointIds().SetNumberOfIds(4)
        for k in range(4):
            line.GetPointIds().SetId(k, k)
        cells = vtk.vtkCellArray()
        cells.InsertNextCell(line)
        poly = vtk.vtkPolyData()
        poly.SetPoints(pts)
        poly.SetLines(cells)
        mapper = vtk.vtkPolyDataMapper2D()
        mapper.SetInputData(poly)
        bar = vtk.vtkActor2D()
        bar.SetMapper(mapper)
        bar.GetProperty().SetColor(0.0, 0.0, 0.0)
        bar.GetProperty().SetLineWidth(max(1.0, self.fs / 5))
        self.pl.renderer.AddViewProp(bar)
        self._panel_text(length_label(L), y0 + 2.0 * self.fs)
        self.scale_bar_m = L

    def save(self, path):
        """Title, legend and scale bar drawn; the picture written to `path` (temporary name, then renamed)."""
        if self.title:
            vtk = _vtk()

            t = vtk.vtkTextActor()
            t.SetInput(self.title)
            tp = t.GetTextProperty()
            tp.SetFontSize(int(round(1.15 * self.fs)))
            tp.SetColor(0.0, 0.0, 0.0)
            tp.SetVerticalJustificationToCentered()
            t.SetPosition(0.5 * self.fs, self.H - self.title_px / 2)
            self.pl.renderer.AddViewProp(t)
        self._draw_legend()
        if getattr(self, "_bar", None):
            self._draw_colour_bar()
        self._scale_bar()
        self.pl.renderer.ResetCameraClippingRange()  # of everything added since fit()
        with atomic_path(path) as tmp:
            self.pl.screenshot(tmp + ".png")
            os.replace(tmp + ".png", tmp)

    def close(self):
        self.pl.close()


def _cut_box(cuts, lo, hi):
    """The box lo..hi restricted to the cut-away conditions (axis, sign, value): (blo, bhi), or None when empty."""
    blo, bhi = np.array(lo, float), np.array(hi, float)
    for axis, sign, value in cuts:
        if sign > 0:
            blo[axis] = max(blo[axis], value)
        else:
            bhi[axis] = min(bhi[axis], value)
    return (blo, bhi) if np.all(blo < bhi) else None


def _draw_cut(frame, cuts, lo, hi, pad):
    """The cut-away region: its cut faces translucent orange and the region's edges as orange lines."""
    import pyvista as pv

    box = _cut_box(cuts, lo - pad, hi + pad)
    if box is None:
        return False
    blo, bhi = box
    frame.pl.add_mesh(pv.Box(bounds=(blo[0], bhi[0], blo[1], bhi[1], blo[2], bhi[2])), style="wireframe",
                      color=CUT_COLOUR, line_width=max(1.0, frame.fs / 6))
    for axis, sign, value in cuts:
        u, v = [a for a in range(3) if a != axis]
        pts = np.zeros((4, 3))
        pts[:, axis] = value
        pts[:, u] = [blo[u], bhi[u], bhi[u], blo[u]]
        pts[:, v] = [blo[v], blo[v], bhi[v], bhi[v]]
        frame.pl.add_mesh(pv.PolyData(pts, faces=[4, 0, 1, 2, 3]), color=CUT_COLOUR, opacity=0.25)
    return True


# where a sprite's centre may lie off the computed one [pixels]: 0.02 plus the float32 rounding of the coordinates
# VTK draws (a few units in the last place of the largest coordinate); depth likewise [m]
SIGHT_EPS_PX = 0.02
FLOAT32_ULPS = 4 * 2.0 ** -23


def sight_tolerances(frame, centers, px):
    """R [pixels], eps [pixels], bulge [m] and tol [m] of :func:`in_sight` for sprites of `px` pixels: eps is
    SIGHT_EPS_PX plus the float32 rounding of the largest coordinate on screen, tol a thousandth of the bulge plus
    that rounding plus a millionth of the model's size (the depth buffer's resolution)."""
    lo, hi = column_bounds(np.ascontiguousarray(centers, dtype=float)) if len(centers) else (np.zeros(3),) * 2
    big = float(np.maximum(np.abs(lo), np.abs(hi)).max()) * FLOAT32_ULPS
    bulge = px * frame.scale
    eps = SIGHT_EPS_PX + big / frame.scale
    tol = 1e-3 * bulge + big + 1e-6 * float((hi - lo).max())
    return px / 2.0, eps, bulge, tol


def in_sight(frame, centers, solid, ghost, px):
    """The opaque spheres `solid` and translucent `ghost` (indices into `centers`) that can show in the picture,
    drawn as point sprites of `px` pixels through the camera of `frame` (Frame.fit).

    VTK draws a sprite as a disc of radius R = px / 2 pixels whose depth at distance d from its centre is
    t - bulge sqrt(1 - (d / R)^2), bulge = px x the scale in metres per pixel (twice the sprite's radius: VTK's
    gl_FragDepth for points drawn as spheres). A sprite is left out when at every pixel cell its disc reaches, an
    opaque sprite holding that whole cell is certainly in front of it (sgim/_render.py, front_depths and
    reaches_front): none of its samples would pass the depth test, and the picture is the same pixel for pixel
    (tests/test_render_sight.py compares both pictures). Only the opaque sprites hide; translucent ones are
    hidden by them alone. What is left is about the spheres on the outer surface of the body and on the cut-away
    planes, a few layers deep, whatever the number inside."""
    if not len(solid):
        return solid, ghost
    centers = np.ascontiguousarray(centers, dtype=float)
    R, eps, bulge, tol = sight_tolerances(frame, centers, px)
    x, y, t = frame.project(centers, solid)
    buf = front_depths(x, y, t, R, eps, bulge, frame.W, frame.H)
    solid = _with_extremes(solid, centers, reaches_front(x, y, t, buf, R, eps, bulge, tol))
    if len(ghost):
        gx, gy, gt = frame.project(centers, ghost)
        ghost = _with_extremes(ghost, centers, reaches_front(gx, gy, gt, buf, R, eps, bulge, tol))
    return solid, ghost


def _with_extremes(idx, centers, keep):
    """idx[keep] and the spheres of idx with the least and the largest coordinate along each axis: VTK rounds the
    points it draws to float32 about the middle of their bounds, so keeping the bounds keeps the same rounding
    (and the picture the same bit for bit far from the origin too)."""
    keep = keep.copy()
    mark_extremes(centers, np.asarray(idx, np.int64), keep)
    return idx[keep]


def render(model: SphereModel, path, hide_intact=False, translucent=False, cut_away=(), width=1600, height=1100,
           title=None):
    """model.png: the spheres in the paper's colours (intact, red fault, green / blue joint sides) seen from the
    -x, -y side (azimuth -150 degrees) 35 degrees above the horizon through a parallel camera fitted to the
    model, with a legend of the colours drawn, axes in metres, a scale bar, and the cut-away region (a sphere is
    cut away when it satisfies every condition of `cut_away`) outlined in orange. The spheres are point sprites
    of their true size on screen, and only those that can show are drawn (:func:`in_sight`)."""
    import pyvista as pv

    cuts = parse_cuts(cut_away)
    idx, exposed = visible_spheres(model, hide_intact, cut_away)
    col = model.colour[idx]
    # opaque intact spheres hidden by their neighbours are never seen
    if translucent:
        solid = idx[(col != 0)]
        ghost = idx[(col == 0) & exposed[idx]]
    else:
        solid = idx[(col != 0) | exposed[idx]]
        ghost = idx[:0]
    frame = Frame(width, height, title)
    pl = frame.pl
    if model.n:
        rmax = float(model.radii.max())
        lo, hi = column_bounds(np.ascontiguousarray(model.centers, dtype=float))
        lo, hi = lo - rmax, hi + rmax
    else:
        rmax, lo, hi = 1.0, np.zeros(3), np.ones(3)
    s = frame.fit(lo, hi)
    frame.axes(lo, hi)
    r = float(np.median(model.radii)) if model.n else 1.0
    px = float(np.clip(2.0 * r / s, 1.5, 255.0))  # the median sphere's diameter on screen
    selected = len(solid) + len(ghost)
    solid, ghost = in_sight(frame, model.centers, solid, ghost, px)
    if len(solid):
        cloud = pv.PolyData(model.centers[solid])
        cloud["rgb"] = (COLOURS[model.colour[solid]] * 255).astype(np.uint8)
        pl.add_mesh(cloud, scalars="rgb", rgb=True, render_points_as_spheres=True, point_size=px)
    if len(ghost):
        g = pv.PolyData(model.centers[ghost])
        pl.add_mesh(g, color=COLOURS[0], opacity=0.06, render_points_as_spheres=True, point_size=px)
    shown = np.bincount(model.colour[idx], minlength=4) if len(idx) else np.zeros(4, int)
    for k in range(4):
        if shown[k] or (k == 0 and translucent and len(ghost)):
            frame.add_legend_entry(COLOUR_LABELS[k] + (" (faint)" if k == 0 and translucent else ""), COLOURS[k])
    if cuts and _draw_cut(frame, cuts, lo, hi, 0.0):
        frame.add_legend_entry("cut away:\n" + " and ".join(e.replace(" ", "") for e in cut_away), CUT_COLOUR)
    frame.save(path)
    info = {"drawn": int(len(solid) + len(ghost)), "selected": int(len(idx)),
            "hidden": int(selected - len(solid) - len(ghost)),
            "legend": [label for label, _ in frame.legend], "scale_bar_m": frame.scale_bar_m}
    frame.close()
    return info
