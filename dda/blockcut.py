"""Convex blocks whose faces remember what made them, split by planes; the exact "does this cutter reach this
block" tests of the block model (dda/geoblocks.py).

A :class:`TBlock` is a convex polyhedron: vertices (n, 3), faces (vertex index lists, counter-clockwise seen from
outside) and, per face, the id of its *source* (an entry of the builder's source table: the domain box, a joint
set plane, a disc, a facet of a surface). :func:`split` cuts a block by a plane directly, face by face
(Sutherland-Hodgman on each face polygon, one new vertex per crossed edge, the cap polygon on the plane ordered
around the plane's normal): the faces keep their sources and the two caps get the cutting plane's source, so no
convex hull has to be rebuilt and no face has to be recognised again.

Tolerance: a vertex within ``rel`` (1e-9) times the block's diagonal of the plane is taken as lying on it: it
goes to both pieces and no intersection point is made next to it; a plane that only touches a block leaves it
whole.

Reach tests (exact, in the cutter's plane): the section of a block by a plane is a convex polygon; a disc
reaches the block when the polygon's distance to the disc's centre is at most its radius; a triangle reaches
it when the polygon and the triangle overlap with positive area (separating axes).
"""
from __future__ import annotations

import math

import numpy as np

from ._geocut import (edges_csr, face_planes_csr, hull2d, origin_distance, overlap_mask, section_2d, signed_snapped,
                      split_csr, volume_centroid_csr)

REL = 1e-9  # snapping tolerance, relative to a block's diagonal


class TBlock:
    """A convex block: vertices (n, 3), faces as CSR (``fptr``, ``fidx``: face k is fidx[fptr[k]:fptr[k+1]],
    counter-clockwise seen from outside), a source id per face (``src``) and a material ("rock", or a fault's
    name)."""

    __slots__ = ("v", "fptr", "fidx", "src", "material", "_edges")

    def __init__(self, v, faces, src, material="rock"):
        self.v = np.ascontiguousarray(v, dtype=np.float64).reshape(-1, 3)
        self.fptr = np.concatenate([[0], np.cumsum([len(f) for f in faces])]).astype(np.int64)
        self.fidx = np.array([i for f in faces for i in f], np.int64)
        self.src = np.asarray(src, np.int64).copy()
        self.material = material
        self._edges = None

    @classmethod
    def from_csr(cls, v, fptr, fidx, src, material="rock"):
        b = cls.__new__(cls)
        b.v, b.fptr, b.fidx, b.src, b.material, b._edges = v, fptr, fidx, src, material, None
        return b

    @property
    def faces(self):
        f = self.fidx.tolist()
        p = self.fptr.tolist()
        return [f[a:b] for a, b in zip(p[:-1], p[1:])]

    def diag(self):
        return float(np.linalg.norm(self.v.max(0) - self.v.min(0)))

    def edges(self):
        """(m, 2) unique undirected edges."""
        if self._edges is None:
            self._edges = edges_csr(len(self.v), self.fptr, self.fidx)
        return self._edges

    def volume_centroid(self):
        vol, c = volume_centroid_csr(self.v, self.fptr, self.fidx)
        return vol, c

    def volume(self):
        return volume_centroid_csr(self.v, self.fptr, self.fidx)[0]


def fan(faces):
    """Triangles (k, 3) of the faces' fans and the face of each triangle."""
    tri, owner = [], []
    for k, f in enumerate(faces):
        for a, b in zip(f[1:-1], f[2:]):
            tri.append((f[0], a, b))
            owner.append(k)
    return np.array(tri, dtype=np.int64).reshape(-1, 3), np.array(owner, dtype=np.int64)


def face_planes(b: TBlock):
    """Outward unit normals (k, 3) and offsets (k,) of every face (Newell's method)."""
    return face_planes_csr(b.v, b.fptr, b.fidx)


def signed(b: TBlock, n, d):
    """Signed distances of the vertices to the plane n . x = d (unit n), those within the tolerance set to 0."""
    return signed_snapped(b.v, float(n[0]), float(n[1]), float(n[2]), float(d), REL)


def split(b: TBlock, n, d, source, s=None):
    """Cut ``b`` by the plane n . x = d (unit n) into (below, above): below is n . x <= d. A side without volume
    is None (the block is returned whole on the other side). Both caps get face source ``source``."""
    if s is None:
        s = signed(b, n, d)
    if not (s < 0).any():
        return None, b
    if not (s > 0).any():
        return b, None
    r = split_csr(b.v, b.fptr, b.fidx, b.src, s, int(source), float(n[0]), float(n[1]), float(n[2]))
    return TBlock.from_csr(*r[:4], b.material), TBlock.from_csr(*r[4:], b.material)


def plane_basis(n):
    """Two unit vectors e1, e2 with (e1, e2, n) right-handed."""
    nx, ny, nz = (float(x) for x in n)
    # h x n for h = x (or y when n is near x), and n x e1, in scalars (np.cross costs 40 us a call)
    e1 = np.array((0.0, -nz, ny) if abs(nx) < 0.9 else (nz, 0.0, -nx))
    e1 /= np.linalg.norm(e1)
    ex, ey, ez = e1.tolist()
    return e1, np.array([ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex])


def section(b: TBlock, n, d, s=None):
    """Points of the section polygon of ``b`` by the plane n . x = d (empty when the plane does not cross the
    block's interior)."""
    if s is None:
        s = signed(b, n, d)
    if not ((s < 0).any() and (s > 0).any()):
        return np.zeros((0, 3))
    e = b.edges()
    sa, sb = s[e[:, 0]], s[e[:, 1]]
    cr = sa * sb < 0
    a, c = b.v[e[cr, 0]], b.v[e[cr, 1]]
    t = (sa[cr] / (sa[cr] - sb[cr]))[:, None]
    return np.vstack([a + t * (c - a), b.v[s == 0.0]])


def convex_polygon_2d(p):
    """Counter-clockwise convex hull (monotone chain) of 2D points; collinear points dropped."""
    p = np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 2)
    if len(p) < 3:
        return p.copy()
    return hull2d(p)


def disc_reaches(b: TBlock, centre, n, radius, basis=None, s=None):
    """True when the disc (centre, unit normal n, radius) meets the interior of block ``b``'s section by its
    plane (the exact test: distance from the centre to the section polygon <= radius). ``basis``: the plane's
    (e1, e2) when known; ``s``: the snapped signed distances when known."""
    if s is None:
        s = signed(b, n, float(np.dot(n, centre)))
    if not ((s < 0).any() and (s > 0).any()):
        return False
    e1, e2 = plane_basis(n) if basis is None else basis
    c = np.asarray(centre, float)
    poly = section_2d(b.v, b.edges(), s, c[0], c[1], c[2], e1, e2)
    return len(poly) >= 3 and origin_distance(poly) <= radius


def triangle_reaches(b: TBlock, tri, n=None, basis=None):
    """True when the triangle ``tri`` (3, 3) meets block ``b`` with positive area in the triangle's plane (unit
    normal ``n`` and its ``basis`` (e1, e2) when known)."""
    if n is None:
        n = unit(np.cross(tri[1] - tri[0], tri[2] - tri[0]))
    s = signed(b, n, float(n @ tri[0]))
    if not ((s < 0).any() and (s > 0).any()):
        return False
    e1, e2 = plane_basis(n) if basis is None else basis
    o = tri[0]
    p = section_2d(b.v, b.edges(), s, o[0], o[1], o[2], e1, e2)
    if len(p) < 3:
        return False
    t = np.ascontiguousarray(np.column_stack([(tri - o) @ e1, (tri - o) @ e2]))
    if (t[1, 0] - t[0, 0]) * (t[2, 1] - t[0, 1]) - (t[1, 1] - t[0, 1]) * (t[2, 0] - t[0, 0]) < 0:
        t = t[::-1].copy()
    return bool(overlap_mask(p, t[None], np.zeros(1, np.int64), REL * b.diag())[0])


def euler_characteristic(b: TBlock):
    return len(b.v) - len(b.edges()) + len(b.faces)


def unit(v):
    v = np.asarray(v, float)
    return v / math.sqrt(float(v @ v))
