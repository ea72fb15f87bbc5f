"""Geometry shared by the sphere generator and the block engine.

Orientation conventions (docs/ARCHITECTURE.md): x east, y north, z up; a plane
given as dip / dip direction (degrees) has the upward unit normal
(sin dip sin dipdir, sin dip cos dipdir, cos dip).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .portable import norm, sin_cos_deg


# Coordinates and lengths in scenes and meshes lie within +-MAX_COORD metres: a million kilometres is beyond any
# model, and squares and products of such numbers stay far from overflow (1e308).
MAX_COORD = 1e9
# Sizes (radii, widths, depths, ...) are at least MIN_LENGTH metres: a nanometre; smaller ones underflow areas and
# volumes, and a lattice of them would count more sites per axis than an int64 holds.
MIN_LENGTH = 1e-9


class MeshError(ValueError):
    def __init__(self, message, where="", value=None):
        super().__init__(message)
        self.message, self.where, self.value = message, where, value


def dip_to_normal(dip_deg, dipdir_deg):
    """Upward unit normal of the plane dip / dip direction (degrees), the same bits on every CPU: round
    orientations (multiples of 30 and 45 degrees) give the exact components their symmetry gives them
    (dip 90, dip direction 90 is (1, 0, 0), not (1, 6e-17, 6e-17)), so that a centre lying on a plane through
    a lattice is decided by the paper's inequality, not by rounding (sgim/portable.py)."""
    if np.ndim(dip_deg) or np.ndim(dipdir_deg):
        d, a = np.broadcast_arrays(np.asarray(dip_deg, float), np.asarray(dipdir_deg, float))
        out = np.array([dip_to_normal(x, y) for x, y in zip(d.ravel(), a.ravel())]).reshape(d.shape + (3,))
        return np.moveaxis(out, -1, 0)
    sd, cd = sin_cos_deg(dip_deg)
    sa, ca = sin_cos_deg(dipdir_deg)
    return np.array([sd * sa, sd * ca, cd])


def normal_to_dip(n):
    """Upward unit normal -> (dip, dip direction) in degrees."""
    n = np.asarray(n, float) / norm(n)
    if n[2] < 0:
        n = -n
    dip = np.degrees(np.arccos(np.clip(n[2], -1, 1)))
    dd = np.degrees(np.arctan2(n[0], n[1])) % 360.0
    return float(dip), float(dd)


def facet_degeneracies(verts, faces):
    """Indices of facets whose points are repeated or collinear (zero area)."""
    p0, p1, p2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    cr = np.cross(p1 - p0, p2 - p0)
    area2 = np.linalg.norm(cr, axis=1)
    edge2 = np.maximum.reduce([((p1 - p0) ** 2).sum(1), ((p2 - p1) ** 2).sum(1), ((p0 - p2) ** 2).sum(1)])
    return np.nonzero(~(area2 > 1e-12 * edge2) | (edge2 == 0))[0]


def triangulate_plan(points):
    """Triangulate points in plan view (Delaunay on x, y); returns (vertices, faces)."""
    from scipy.spatial import Delaunay, QhullError  # loaded only when needed (start-up time)

    pts = np.asarray(points, float)
    if len(pts) < 3:
        raise MeshError("at least 3 points are needed", "", len(pts))
    _, first, inv = np.unique(pts[:, :2], axis=0, return_index=True, return_inverse=True)
    if len(first) != len(pts):
        inv = inv.ravel()
        counts = np.bincount(inv)
        dup = np.nonzero(counts[inv] > 1)[0]
        i, j = int(dup[0]), int(dup[1])
        raise MeshError(f"repeats the plan position of points[{i}]", f"[{j}]", pts[j].tolist())
    try:
        tri = Delaunay(pts[:, :2])
    except QhullError:
        raise MeshError("points are collinear in plan view; nothing to triangulate", "", pts[:3].tolist()) from None
    faces = tri.simplices.astype(np.int64)
    # orient every facet counter-clockwise in plan (upward normal)
    p = pts[faces]
    ccw = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0])
    flip = ccw < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    # Delaunay leaves slivers of zero area on collinear hull points: drop them
    keep = np.abs(ccw) > 1e-12 * np.ptp(pts[:, :2], axis=0).max() ** 2
    return pts, faces[keep]


def load_mesh_file(path):
    """Read a triangle surface from any meshio format; merge duplicated vertices."""
    import meshio  # loaded only when a mesh file is read (start-up time)

    path = Path(path)
    if not path.is_file():
        raise MeshError("file not found")
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            mesh = meshio.read(str(path))
    except Exception as exc:  # meshio raises many kinds
        raise MeshError(f"unreadable mesh file ({exc.__class__.__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    tris = [c.data for c in mesh.cells if c.type == "triangle"]
    others = sorted({c.type for c in mesh.cells if c.type not in ("triangle", "vertex", "line")})
    if others:
        raise MeshError(f"mesh has non-triangle cells ({', '.join(others)}); triangulate it first")
    if not tris:
        raise MeshError("mesh has no triangle cells")
    pts = np.asarray(mesh.points, float)
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    if not np.all(np.isfinite(pts)):
        raise MeshError("mesh has NaN or infinite coordinates")
    if len(pts) and np.abs(pts).max() > MAX_COORD:
        raise MeshError(f"mesh has coordinates beyond +-{MAX_COORD:g} m (largest {np.abs(pts).max():g})")
    faces = np.concatenate(tris).astype(np.int64)
    uniq, inv = np.unique(pts, axis=0, return_inverse=True)
    faces = inv.ravel()[faces]
    used, faces = np.unique(faces, return_inverse=True)
    return uniq[used], faces.reshape(-1, 3)


# ---------------------------------------------------------------------------
# The paper's plane coefficients (equations 3-12), transcribed literally.

def plane_coefficients(p1, p2, p3):
    """A, B, C, D of the plane through three points by the paper's determinants (eq. 4).

    Works on arrays of points with shape (..., 3).
    """
    x1, y1, z1 = p1[..., 0], p1[..., 1], p1[..., 2]
    x2, y2, z2 = p2[..., 0], p2[..., 1], p2[..., 2]
    x3, y3, z3 = p3[..., 0], p3[..., 1], p3[..., 2]
    a = y1 * (z2 - z3) - z1 * (y2 - y3) + (y2 * z3 - y3 * z2)
    b = -(x1 * (z2 - z3) - z1 * (x2 - x3) + (x2 * z3 - x3 * z2))
    c = x1 * (y2 - y3) - y1 * (x2 - x3) + (x2 * y3 - x3 * y2)
    d = -(x1 * (y2 * z3 - y3 * z2) - y1 * (x2 * z3 - x3 * z2) + z1 * (x2 * y3 - x3 * y2))
    return a, b, c, d


def paper_facets(verts, faces):
    """Coefficients of the paper's excavation test for every facet: array (nf, 34).

    [A0, B0, C0, D0] then, for k = 1..6, [Ak, Bk, Ck, Dk, Dk0] (equations 3-12).
    Side planes 1-3 bound space I (the prism along the facet normal), side
    planes 4-6 bound space II (the vertical prism).
    """
    L0, M0, N0 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    A0, B0, C0, D0 = plane_coefficients(L0, M0, N0)
    n1 = np.stack([A0, B0, C0], axis=-1)
    L1, M1 = L0 + n1, M0 + n1  # eq. 5 (N1 is not needed by the side planes)
    up = np.array([0.0, 0.0, 1.0])
    L2, M2 = L0 + up, M0 + up  # eq. 9
    cols = [A0, B0, C0, D0]
    # eq. 6 and 10: plane L0 L1 M0, M0 M1 N0, L0 L1 N0 (and the same with L2, M2)
    for (P, Q, R, opp) in (
        (L0, L1, M0, N0), (M0, M1, N0, L0), (L0, L1, N0, M0),
        (L0, L2, M0, N0), (M0, M2, N0, L0), (L0, L2, N0, M0),
    ):
        a, b, c, d = plane_coefficients(P, Q, R)
        d0 = -a * opp[:, 0] - b * opp[:, 1] - c * opp[:, 2]  # eq. 8 / 12
        cols += [a, b, c, d, d0]
    return np.ascontiguousarray(np.stack(cols, axis=1))
