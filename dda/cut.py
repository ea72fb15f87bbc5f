"""Cutting convex polyhedra by planes and joint sets into convex blocks.

A plane is ``(normal, offset)`` meaning ``normal . x = offset`` (the normal need not be unit), or
``(normal, point)`` with a 3-vector point on it. "Below" a plane is the side ``normal . x < offset``.

Joint sets use the joint description of SGIM (``sgim.geometry.dip_to_normal``): dip / dip direction in
degrees (x east, y north, z up; upward unit normal), a spacing measured along the normal, an origin point
that one plane of the set passes through, and an optional extent.

Robustness (``tol``, ``min_volume``, ``sliver``):

- a vertex whose distance to the plane is within ``tol`` times the piece's size is taken as lying on the
  plane: it goes to both pieces and no intersection point is made next to it; a plane that only touches a
  piece (every vertex on one side or on the plane) leaves it whole;
- a cut that would leave a piece of volume below ``min_volume`` (default ``sliver_fraction`` = 1e-6 times
  the domain's volume) is a sliver cut. With ``sliver="merge"`` (default) the piece is not cut by that
  plane, so the sliver stays merged with its neighbour and total volume is kept exactly; with
  ``sliver="drop"`` the piece is cut and the sliver discarded (total volume shrinks by the slivers).

Pieces are rebuilt with :func:`dda.shapes.convex_hull`, so every piece is convex with merged polygon faces
ordered counter-clockwise seen from outside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sgim.geometry import dip_to_normal
from sgim.portable import matmul, norm

from .blockspec import BlockSpec
from .shapes import GeometryError, box, convex_hull, prism_from_polygon, volume


@dataclass
class JointSet:
    """A set of parallel persistent joints.

    ``extent``: optional axis-aligned box ``((xmin, ymin, zmin), (xmax, ymax, zmax))`` where the set exists.
    A plane of the set cuts a piece only when the piece's section by the plane lies inside the box (within
    the tolerance), so that blocks stay convex and no joint runs beyond its extent; pieces the box does not
    hold whole along the section are left uncut by that plane.
    """

    dip: float
    dip_direction: float
    spacing: float
    origin: tuple = (0.0, 0.0, 0.0)
    extent: tuple | None = None
    name: str = ""

    def normal(self) -> np.ndarray:
        return dip_to_normal(self.dip, self.dip_direction)


def _plane(p):
    n, q = p
    n = np.asarray(n, float).reshape(3)
    nn = norm(n)
    if not nn > 0 or not np.all(np.isfinite(n)):
        raise GeometryError(f"plane normal must be a finite non-zero vector (got {n.tolist()})")
    q = np.asarray(q, float)
    d = matmul(n, q) if q.ndim == 1 and q.size == 3 else float(q)
    return n / nn, d / nn


def joint_planes(js: JointSet, domain: BlockSpec) -> list:
    """Planes ``(unit normal, offset)`` of joint set ``js`` that cross ``domain`` (sorted by offset)."""
    if not (np.isfinite(js.spacing) and js.spacing > 0):
        raise GeometryError(f"joint set spacing must be > 0 (got {js.spacing})")
    n = js.normal()
    d0 = matmul(n, np.asarray(js.origin, float))
    s = matmul(domain.vertices, n)
    lo, hi = s.min(), s.max()
    if js.extent is not None:
        blo, bhi = (np.asarray(b, float) for b in js.extent)
        corners = np.array([[x, y, z] for x in (blo[0], bhi[0]) for y in (blo[1], bhi[1]) for z in (blo[2], bhi[2])])
        e = matmul(corners, n)
        lo, hi = max(lo, e.min()), min(hi, e.max())
    k0 = int(np.ceil((lo - d0) / js.spacing))
    k1 = int(np.floor((hi - d0) / js.spacing))
    return [(n, d0 + k * js.spacing) for k in range(k0, k1 + 1) if lo < d0 + k * js.spacing < hi]


def _edges(spec):
    e = set()
    for f in spec.faces:
        for a, b in zip(f, f[1:] + f[:1]):
            e.add((min(a, b), max(a, b)))
    return np.array(sorted(e), dtype=np.int64).reshape(-1, 2)


def _section(spec, n, d, eps):
    """Signed distances (snapped to 0 within eps) and the points of the section polygon."""
    v = spec.vertices
    s = matmul(v, n) - d
    s[np.abs(s) <= eps] = 0.0
    e = _edges(spec)
    sa, sb = s[e[:, 0]], s[e[:, 1]]
    cross = (sa * sb) < 0
    a, b = v[e[cross, 0]], v[e[cross, 1]]
    t = (sa[cross] / (sa[cross] - sb[cross]))[:, None]
    pts = np.vstack([a + t * (b - a), v[s == 0.0]])
    return s, pts


def split(spec: BlockSpec, plane, tol: float = 1e-9, **fields):
    """Split ``spec`` by ``plane`` into ``(below, above)``; a side with no volume is None.

    ``tol`` is relative to the piece's size. Faces are rebuilt by convex_hull (``fields`` go to BlockSpec,
    by default the piece keeps ``spec``'s name, material, fixed flag and dof).
    """
    n, d = _plane(plane)
    v = spec.vertices
    eps = tol * norm(np.ptp(v, axis=0))
    s, sec = _section(spec, n, d, eps)
    if not (s < 0).any():
        return None, spec
    if not (s > 0).any():
        return spec, None
    keep = dict(name=spec.name, fixed=spec.fixed, material=spec.material, dof=spec.dof,
                velocity=spec.velocity, angular_velocity=spec.angular_velocity)
    keep.update(fields)
    out = []
    for side in (s < 0, s > 0):
        pts = np.vstack([v[side], sec])
        try:
            out.append(convex_hull(pts, tol=tol, **keep))
        except GeometryError:
            out.append(None)  # flat: no volume on this side
    return out[0], out[1]


def clip(spec: BlockSpec, plane, tol: float = 1e-9):
    """The part of ``spec`` below ``plane`` (``normal . x <= offset``), or None if nothing is left."""
    return split(spec, plane, tol)[0]


def _in_box(pts, extent, eps):
    lo, hi = (np.asarray(b, float) for b in extent)
    return bool(np.all(pts >= lo - eps) and np.all(pts <= hi + eps))


def cut_convex(spec: BlockSpec, planes, tol: float = 1e-9, min_volume: float | None = None,
               sliver: str = "merge", sliver_fraction: float = 1e-6, extents=None, progress=None) -> list[BlockSpec]:
    """Cut the convex polyhedron ``spec`` by every plane in ``planes`` (persistent: each plane cuts every
    piece it crosses). Returns the convex pieces, named ``"{spec.name}{k}"`` in a stable order.

    ``extents``: optional list (one item per plane, None for unbounded) of boxes ``(lo, hi)``: a plane cuts a
    piece only if the piece's section lies inside its box. See the module docstring for ``tol``,
    ``min_volume``, ``sliver``.
    """
    if sliver not in ("merge", "drop"):
        raise GeometryError(f"sliver must be 'merge' or 'drop' (got {sliver!r})")
    planes = [_plane(p) for p in planes]
    if extents is None:
        extents = [None] * len(planes)
    if len(extents) != len(planes):
        raise GeometryError("extents must give one entry per plane")
    if min_volume is None:
        min_volume = sliver_fraction * volume(spec)
    pieces = [spec]
    for k, ((n, d), ext) in enumerate(zip(planes, extents)):
        nxt = []
        for piece in pieces:
            s = matmul(piece.vertices, n) - d
            if s.min() >= 0 or s.max() <= 0:
                nxt.append(piece)
                continue
            if ext is not None:
                eps = tol * norm(np.ptp(piece.vertices, axis=0))
                _, sec = _section(piece, n, d, eps)
                box_eps = max(eps, tol * float(np.ptp(np.asarray(ext, float), axis=0).max()))
                if len(sec) == 0 or not _in_box(sec, ext, box_eps):
                    nxt.append(piece)
                    continue
            below, above = split(piece, (n, d), tol)
            vb = volume(below) if below is not None else 0.0
            va = volume(above) if above is not None else 0.0
            small = [p for p, vol in ((below, vb), (above, va)) if vol < min_volume]
            if not small:
                nxt += [below, above]
            elif sliver == "merge":
                nxt.append(piece)
            else:
                nxt += [p for p, vol in ((below, vb), (above, va)) if vol >= min_volume and p is not None]
        pieces = nxt
        if progress is not None:
            progress(k + 1, len(planes))
    for i, p in enumerate(pieces):
        p.name = f"{spec.name}{i}"
    return pieces


def cut_domain(domain: BlockSpec, planes=(), joint_sets=(), **kw) -> list[BlockSpec]:
    """Cut a convex domain by explicit ``planes`` then by every plane of each joint set."""
    pl = [_plane(p) for p in planes]
    ext = [None] * len(pl)
    for js in joint_sets:
        jp = joint_planes(js, domain)
        pl += jp
        ext += [js.extent] * len(jp)
    return cut_convex(domain, pl, extents=ext, **kw)


def cut_box(lo, hi, planes=(), joint_sets=(), name="block", **kw) -> list[BlockSpec]:
    """Cut the axis-aligned box ``lo``..``hi`` by planes and joint sets into convex blocks."""
    return cut_domain(box(lo, hi, name=name), planes, joint_sets, **kw)


def cut_prism(polygon, z0, z1, planes=(), joint_sets=(), name="block", **kw) -> list[BlockSpec]:
    """Cut the right prism over the convex plan ``polygon`` between ``z0`` and ``z1``."""
    return cut_domain(prism_from_polygon(polygon, z0, z1, name=name), planes, joint_sets, **kw)
