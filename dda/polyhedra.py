"""Convex polyhedra: half-edge topology and exact mass properties.

Half-edge arrays (one polyhedron, local indices; :class:`dda.system.BlockSystem` concatenates them with
offsets into one flat set for the whole system):

==============  ==========  ================================================================
array           shape       meaning
==============  ==========  ================================================================
he_origin       (h,) i8     vertex the half-edge starts at
he_next         (h,) i8     next half-edge around the same face (counter-clockwise from outside)
he_prev         (h,) i8     previous half-edge around the same face
he_pair         (h,) i8     the opposite half-edge (same edge, other face)
he_face         (h,) i8     face on the half-edge's left (seen from outside)
vert_he         (n,) i8     one half-edge leaving each vertex
face_he         (f,) i8     one half-edge of each face
==============  ==========  ================================================================

The faces around vertex ``v`` are walked as ``e = vert_he[v]; e = he_next[he_pair[e]]`` ... until the start
half-edge comes back; each step visits one outgoing half-edge (an edge at ``v``) and its face.

Mass properties come from exact volume integrals: each face is fanned into triangles, each triangle and a
reference point form a signed tetrahedron, and the volume, first and second moments of the tetrahedra are
summed (the divergence theorem, exact for any closed polyhedron with outward faces).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sgim.portable import det3, matmul, norm


class PolyhedronError(ValueError):
    """The vertex/face lists do not describe a closed, outward-oriented convex polyhedron."""


@dataclass
class HalfEdges:
    he_origin: np.ndarray
    he_next: np.ndarray
    he_prev: np.ndarray
    he_pair: np.ndarray
    he_face: np.ndarray
    vert_he: np.ndarray
    face_he: np.ndarray

    @property
    def n_half_edges(self):
        return len(self.he_origin)


def half_edges(n_vertices: int, faces) -> HalfEdges:
    """Half-edge topology of a closed polyhedron given counter-clockwise (outward) faces.

    Raises PolyhedronError when an edge is used twice in the same direction (inconsistent orientation),
    when an edge has no opposite half-edge (the surface is not closed), or when a vertex is unused.
    """
    faces = [list(map(int, f)) for f in faces]
    h = sum(len(f) for f in faces)
    origin = np.empty(h, np.int64)
    nxt = np.empty(h, np.int64)
    prv = np.empty(h, np.int64)
    fac = np.empty(h, np.int64)
    face_he = np.empty(len(faces), np.int64)
    index = {}
    e = 0
    for fi, f in enumerate(faces):
        if len(f) < 3:
            raise PolyhedronError(f"face {fi} has {len(f)} vertices (need >= 3)")
        k = len(f)
        face_he[fi] = e
        for j in range(k):
            a, b = f[j], f[(j + 1) % k]
            if not (0 <= a < n_vertices):
                raise PolyhedronError(f"face {fi} uses vertex {a}, outside 0..{n_vertices - 1}")
            if (a, b) in index:
                raise PolyhedronError(f"edge ({a}, {b}) is used twice in the same direction (face {fi}): "
                                      "faces are not consistently counter-clockwise")
            index[(a, b)] = e + j
            origin[e + j] = a
            nxt[e + j] = e + (j + 1) % k
            prv[e + j] = e + (j - 1) % k
            fac[e + j] = fi
        e += k
    pair = np.empty(h, np.int64)
    for (a, b), i in index.items():
        j = index.get((b, a))
        if j is None:
            raise PolyhedronError(f"edge ({a}, {b}) has no opposite face: the surface is not closed")
        pair[i] = j
    vert_he = np.full(n_vertices, -1, np.int64)
    for i in range(h - 1, -1, -1):
        vert_he[origin[i]] = i
    if np.any(vert_he < 0):
        raise PolyhedronError(f"vertex {int(np.nonzero(vert_he < 0)[0][0])} belongs to no face")
    return HalfEdges(origin, nxt, prv, pair, fac, vert_he, face_he)


def faces_around_vertex(he: HalfEdges, v: int) -> list[int]:
    """Faces around vertex v, walked edge -> pair -> next (each face once)."""
    start = he.vert_he[v]
    out = []
    e = start
    while True:
        out.append(int(he.he_face[e]))
        e = he.he_next[he.he_pair[e]]
        if e == start:
            return out
        if len(out) > len(he.he_origin):
            raise PolyhedronError(f"vertex {v}: the faces around it do not form a single fan")


@dataclass
class MassProperties:
    volume: float
    centroid: np.ndarray  # (3,)
    inertia: np.ndarray  # (3,3) second moment tensor of the unit-density body about the centroid


def mass_properties(vertices, faces) -> MassProperties:
    """Exact volume, centroid and inertia tensor (unit density, about the centroid).

    The covariance of the tetrahedron (0, a, b, c) is det / 120 (a a^T + b b^T + c c^T + s s^T) with
    s = a + b + c; everything is summed in a fixed order without BLAS (sgim/portable.py)."""
    v = np.asarray(vertices, float)
    ref = v.mean(0)
    vol = 0.0
    first = np.zeros(3)
    cov = np.zeros((3, 3))  # integral of x x^T about ref
    for f in faces:
        p0 = v[f[0]] - ref
        for a, b in zip(f[1:-1], f[2:]):
            pa = v[a] - ref
            pb = v[b] - ref
            d = det3(np.column_stack((p0, pa, pb)))
            s = p0 + pa + pb
            vol += d / 6.0
            first += d / 6.0 * s / 4.0
            cov += d / 120.0 * (np.outer(p0, p0) + np.outer(pa, pa) + np.outer(pb, pb) + np.outer(s, s))
    if not vol > 0:
        raise PolyhedronError(f"volume {vol:g} is not positive: faces must be counter-clockwise from outside")
    c = first / vol  # centroid relative to ref
    cov_c = cov - vol * np.outer(c, c)  # parallel axis theorem for the covariance
    inertia = np.trace(cov_c) * np.eye(3) - cov_c
    return MassProperties(vol, ref + c, inertia)


def face_planes(vertices, faces):
    """Outward unit normals (Newell) and offsets d (n . x = d on the face) of every face."""
    v = np.asarray(vertices, float)
    nrm = np.zeros((len(faces), 3))
    off = np.zeros(len(faces))
    for k, f in enumerate(faces):
        p = v[f]
        n = np.cross(p, np.roll(p, -1, axis=0)).sum(0)
        ln = norm(n)
        if not ln > 0:
            raise PolyhedronError(f"face {k} has zero area")
        n /= ln
        nrm[k] = n
        off[k] = float(np.mean(matmul(p, n)))
    return nrm, off


def check_convex(vertices, faces, rel_tol=1e-9):
    """Raise PolyhedronError unless every vertex lies on or behind every face plane."""
    v = np.asarray(vertices, float)
    nrm, off = face_planes(v, faces)
    size = float(np.max(np.ptp(v, axis=0))) or 1.0
    dist = matmul(v, nrm.T) - off[None, :]
    worst = float(dist.max())
    if worst > rel_tol * size:
        k = int(np.argmax(dist.max(0)))
        raise PolyhedronError(f"not convex: a vertex lies {worst:.3g} in front of face {k}")
