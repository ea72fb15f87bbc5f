"""Built-in closed and open surfaces as triangle meshes (vertices (n,3), faces (m,3)).

Closed shapes for cavities (faces oriented outward):

- :func:`sweep`: a convex section swept along a polyline, mitred joints, flat end caps;
  :func:`circular_tunnel` and :func:`horseshoe_tunnel` use it.
- :func:`ellipsoid` (a spherical or ellipsoidal cavern), :func:`box` (an axis-aligned chamber).

Open surfaces for discontinuities (faces oriented with upward normals):

- :func:`listric`: a listric fault whose dip flattens linearly with depth.

Section frame: along a path segment with unit tangent t, the section's v axis is the
upward direction made perpendicular to t and u = v x t (horizontal), so (u, v, t) is
right-handed: a horizontal tunnel heading east has v = +z and u = +y (north).  A vertical
segment uses +x in place of "up".
Sections are convex polygons listed counter-clockwise in (u, v).  At an inner path point
the ring lies in the mitre plane (normal t_in + t_out): the two tubes meet there exactly
for bends within a vertical or a horizontal plane.
"""
from __future__ import annotations

import math

import numpy as np

from .portable import each, matmul, norm


class ShapeError(ValueError):
    """A shape parameter is unusable; ``where`` names the parameter, ``value`` the value."""

    def __init__(self, message, where="", value=None):
        super().__init__(message)
        self.message, self.where, self.value = message, where, value


MAX_BEND_DEG = 90.0


def frame(t):
    """(u, v) of the section plane for unit tangent t."""
    t = np.asarray(t, float)
    ref = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 1.0 - 1e-9 else np.array([1.0, 0.0, 0.0])
    v = ref - matmul(ref, t) * t
    v /= norm(v)
    u = np.cross(v, t)
    return u, v


def circular_section(radius, segments):
    a = 2.0 * np.pi * np.arange(segments) / segments
    return np.column_stack([radius * each(math.cos, a), radius * each(math.sin, a)])


def horseshoe_section(width, height, segments):
    """Flat invert at v = 0 (the path runs along the invert centre), vertical walls,
    semicircular crown of radius width/2 reaching v = height."""
    rc = width / 2.0
    hs = height - rc  # spring line
    narc = max(int(segments) - 3, 4)
    a = np.pi * np.arange(narc + 1) / narc
    arc = np.column_stack([rc * each(math.cos, a), hs + rc * each(math.sin, a)])
    pts = [[-rc, 0.0], [rc, 0.0]]
    # with no wall (height = width / 2) the arc ends are the invert corners already
    pts += (arc if hs > 1e-12 * width else arc[1:-1]).tolist()
    return np.array(pts)


def _rings(path, section, piece):
    """Ring vertices (list of (ns,3)) along the path, checked for crossing rings."""
    P = np.asarray(path, float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2:
        raise ShapeError("path needs at least two points [x, y, z]", "path", None)
    seg = np.diff(P, axis=0)
    L = np.linalg.norm(seg, axis=1)
    scale = float(np.abs(section).max())
    for i in np.nonzero(~(L > 1e-9 * max(scale, 1.0)))[0]:
        raise ShapeError("repeats the previous path point", f"path[{i + 1}]", P[i + 1].tolist())
    T = seg / L[:, None]
    # mitre normals: caps perpendicular to the end segments
    M = [T[0]]
    for i in range(1, len(P) - 1):
        c = float(np.clip(matmul(T[i - 1], T[i]), -1.0, 1.0))
        bend = math.degrees(math.acos(c))
        if bend > MAX_BEND_DEG:
            raise ShapeError(f"bend of {bend:.1f} degrees exceeds {MAX_BEND_DEG:g}", f"path[{i}]", P[i].tolist())
        m = T[i - 1] + T[i]
        M.append(m / norm(m))
    M.append(T[-1])
    rings = []
    for i in range(len(P) - 1):
        t = T[i]
        u, v = frame(t)
        base = section[:, :1] * u + section[:, 1:] * v  # (ns, 3) offsets from the axis
        # position along t of each ring point in the mitre planes at both ends
        s0 = -matmul(base, M[i]) / matmul(t, M[i])
        s1 = -matmul(base, M[i + 1]) / matmul(t, M[i + 1]) + L[i]
        if np.any(s1 <= s0 + 1e-9 * L[i]):
            raise ShapeError("path segment too short for its bends and the section size",
                             f"path[{i}]..path[{i + 1}]", [P[i].tolist(), P[i + 1].tolist()])
        if i == 0:
            rings.append(P[i] + base + s0[:, None] * t)
        a, b = float(s0.max()), float(s1.min())
        if b > a:
            npc = max(int(math.ceil((b - a) / piece)), 1)
            for s in np.linspace(a, b, npc + 1)[1:-1]:
                rings.append(P[i] + base + s * t)
        rings.append(P[i] + base + s1[:, None] * t)
    return rings, T


def sweep(path, section, piece=None):
    """Closed mesh of a convex section (counter-clockwise (u, v) polygon) swept along path."""
    section = np.asarray(section, float)
    ns = len(section)
    if piece is None:
        piece = 2.0 * float(np.abs(section).max())
    rings, T = _rings(path, section, piece)
    nr = len(rings)
    V = np.vstack(rings + [rings[0].mean(0, keepdims=True), rings[-1].mean(0, keepdims=True)])
    c0, c1 = nr * ns, nr * ns + 1
    F = []
    j = np.arange(ns)
    jn = (j + 1) % ns
    for k in range(nr - 1):
        a, b = k * ns + j, k * ns + jn
        c, d = (k + 1) * ns + jn, (k + 1) * ns + j
        F.append(np.column_stack([a, b, c]))
        F.append(np.column_stack([a, c, d]))
    F.append(np.column_stack([np.full(ns, c0), jn, j]))
    last = (nr - 1) * ns
    F.append(np.column_stack([np.full(ns, c1), last + j, last + jn]))
    return V, np.vstack(F).astype(np.int64)


def circular_tunnel(path, radius, segments=48, piece=None):
    if not radius > 0:
        raise ShapeError("must be > 0", "radius", radius)
    _check_segments(segments)
    return sweep(path, circular_section(radius, int(segments)), piece)


def horseshoe_tunnel(path, width, height, segments=48, piece=None):
    if not width > 0:
        raise ShapeError("must be > 0", "width", width)
    if not height >= width / 2.0:
        raise ShapeError(f"must be >= width / 2 = {width / 2:g} (the crown is a half circle)", "height", height)
    _check_segments(segments)
    return sweep(path, horseshoe_section(width, height, int(segments)), piece)


def _check_segments(segments):
    if isinstance(segments, bool) or not float(segments).is_integer() or not 8 <= segments <= 4096:
        raise ShapeError("must be an integer from 8 to 4096", "segments", segments)


def ellipsoid(centre, radii, segments=48):
    """Closed ellipsoid (semi-axes along x, y, z) from a latitude-longitude grid."""
    _check_segments(segments)
    r = np.asarray(radii, float)
    if np.any(~(r > 0)):
        raise ShapeError("semi-axes must be > 0", "radii", r.tolist())
    nlon = int(segments)
    nlat = max(nlon // 2, 4)
    th = np.pi * np.arange(1, nlat) / nlat  # polar angle of the inner rings
    ph = 2 * np.pi * np.arange(nlon) / nlon
    sth, cth, sph, cph = each(math.sin, th), each(math.cos, th), each(math.sin, ph), each(math.cos, ph)
    ring = np.stack([np.outer(sth, cph), np.outer(sth, sph), np.outer(cth, np.ones(nlon))], -1).reshape(-1, 3)
    V = np.vstack([ring, [[0, 0, 1]], [[0, 0, -1]]]) * r + np.asarray(centre, float)
    top, bot = len(ring), len(ring) + 1
    F = []
    j = np.arange(nlon)
    jn = (j + 1) % nlon
    F.append(np.column_stack([np.full(nlon, top), j, jn]))
    for k in range(nlat - 2):
        a, b = k * nlon + j, k * nlon + jn
        c, d = (k + 1) * nlon + jn, (k + 1) * nlon + j
        F.append(np.column_stack([a, d, c]))
        F.append(np.column_stack([a, c, b]))
    last = (nlat - 2) * nlon
    F.append(np.column_stack([np.full(nlon, bot), last + jn, last + j]))
    return V, np.vstack(F).astype(np.int64)


def box(lo, hi):
    """Closed axis-aligned box, 12 outward triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if np.any(~(hi > lo)):
        raise ShapeError("max must exceed min on every axis", "max", hi.tolist())
    V = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    F = []
    for q in quads:
        F += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return V, np.array(F, np.int64)


# ---------------------------------------------------------------------------
# listric fault

def listric_profile(dip_top, dip_bottom, depth, d):
    """Horizontal offset (towards the dip direction) of the fault at depth d below its trace.

    The dip falls linearly from dip_top at the trace to dip_bottom at ``depth``:
    x(d) = integral_0^d cot(delta(s)) ds, with delta(s) = a + b s.
    """
    a = math.radians(dip_top)
    b = (math.radians(dip_bottom) - a) / depth
    d = np.asarray(d, float)
    if abs(b) * depth < 1e-12:
        return d / math.tan(a)
    return each(math.log, each(math.sin, a + b * d) / math.sin(a)) / b


def listric(trace, dip_direction, dip_top, dip_bottom, depth, length, resolution):
    """Open listric fault: trace point (top centre), strike length, depth below the trace.

    Points X(a, d) = trace + a s + x(d) h - d z for a in [-length/2, length/2], d in [0, depth],
    with h the horizontal dip direction and s the strike.  Faces have upward normals.
    """
    for name, val, lo, hi in (("dip_top", dip_top, 0.0, 90.0), ("dip_bottom", dip_bottom, 0.0, 90.0)):
        if not lo < val <= hi:
            raise ShapeError(f"must be in ({lo:g}, {hi:g}]", name, val)
    for name, val in (("depth", depth), ("length", length), ("resolution", resolution)):
        if not val > 0:
            raise ShapeError("must be > 0", name, val)
    dd = math.radians(dip_direction)
    h = np.array([math.sin(dd), math.cos(dd), 0.0])
    s = np.array([-math.cos(dd), math.sin(dd), 0.0])
    # down-dip samples spaced by arc length about ``resolution``
    fine = np.linspace(0.0, depth, 2001)
    xf = listric_profile(dip_top, dip_bottom, depth, fine)
    arc = np.concatenate([[0.0], np.cumsum(np.sqrt(np.diff(xf) ** 2 + np.diff(fine) ** 2))])
    nd = max(int(math.ceil(arc[-1] / resolution)), 1)
    na = max(int(math.ceil(length / resolution)), 1)
    if (nd + 1) * (na + 1) > 4_000_000:
        raise ShapeError(f"gives {(nd + 1) * (na + 1)} vertices (more than 4 million)", "resolution", resolution)
    d = np.interp(np.linspace(0.0, arc[-1], nd + 1), arc, fine)
    x = listric_profile(dip_top, dip_bottom, depth, d)
    a = np.linspace(-length / 2.0, length / 2.0, na + 1)
    A, Dd = np.meshgrid(a, d, indexing="ij")  # (na+1, nd+1)
    X = np.meshgrid(a, x, indexing="ij")[1]
    V = (np.asarray(trace, float) + A[..., None] * s + X[..., None] * h - Dd[..., None] * np.array([0, 0, 1.0]))
    V = V.reshape(-1, 3)
    idx = np.arange((na + 1) * (nd + 1)).reshape(na + 1, nd + 1)
    p, q = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    r_, w = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.vstack([np.column_stack([p, q, r_]), np.column_stack([p, r_, w])]).astype(np.int64)
    # upward normals
    t = V[F]
    nz = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2]
    F[nz < 0] = F[nz < 0][:, [0, 2, 1]]
    return V, F
