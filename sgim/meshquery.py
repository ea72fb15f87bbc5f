"""Triangle-mesh queries: closest point, signed distance, inside, segment crossings.

API stable.

:class:`TriMesh` cleans a triangle surface once and answers vectorised, numba-backed
queries over many points.  Cost of a query follows the triangles near the point
(bounding-volume hierarchy over the faces, median split, 4 faces a leaf).

Construction (``TriMesh(vertices, faces, weld=1e-7, orient=True)``):

1. vertices closer than ``weld`` x (bounding-box diagonal) are merged;
2. degenerate triangles (repeated vertex, zero area) and exact duplicates (same three
   vertices in any order; the first is kept) are dropped;
3. with ``orient`` every edge-connected patch is made consistent (flipped triangles are
   reversed); a patch without holes, or whose boundary is short next to its size (total
   boundary length <= 0.1 sqrt(area)), is then oriented outward (positive enclosed volume);
   any other patch keeps the orientation of most of its input area;
4. faces are stored in BVH order: ``mesh.faces[i]`` came from input face
   ``mesh.face_source[i]``.  Every face index returned by a query refers to ``mesh.faces``.

Attributes: ``vertices (nv,3)``, ``faces (m,3)``, ``face_source (m,)``, ``normals (m,3)`` unit,
``areas (m,)``, ``edges (ne,2)``, ``edge_count (ne,)`` faces per edge, ``boundary_edges (nb,2)``
(vertex pairs of edges used by one face), ``closed`` (no boundary edge), ``lo``/``hi``
(bounding box), ``report`` (dict: welded vertices, dropped degenerate / duplicate faces,
flipped faces, patches, boundary and non-manifold edges).

Queries (``points`` is (k,3); every result is a numpy array of length k):

- ``closest(points, max_dist=inf) -> (dist, foot (k,3), face, on_boundary)``: distance to the
  nearest point of the surface, that point, its face, and whether it lies on the surface's
  boundary (a boundary edge or a boundary vertex: for an open surface, the point's
  projection falls outside it).  Points farther than ``max_dist`` stop early and get
  ``dist = inf``, ``foot = nan``, ``face = -1``, ``on_boundary = False`` (fast band queries).
- ``signed_distance(points, max_dist=inf)``: distance with the sign of
  ``(p - foot) . pseudo-normal`` (angle-weighted vertex normals, edge normals as the sum of
  the two face normals; Baerentzen & Aanaes 2005): positive on the side the face normals
  point to, so negative inside a closed, outward-oriented mesh.  ``inf`` beyond ``max_dist``.
- ``signed_closest(points, max_dist=inf) -> (sdist, face, on_boundary)``: both at once.
- ``inside(points)``: ray-parity vote (two rays in fixed oblique directions, a third one
  when they disagree).  Meant for closed meshes; robust to small holes, flipped or
  duplicated triangles and slivers (a defect can mislead one ray, rarely two).
- ``overlaps(points, r)``: the centre of a sphere of radius ``r`` (scalar or per point) is
  inside the closed mesh or closer than ``r`` to its surface (the cavity rule).
- ``segment_crossings(a, b)``: a face crossed by each segment ``a[i] -> b[i]`` or -1.

Closure: ``closed`` is strict; ``holes()`` lists the boundary loops (vertex ids) and
``nearly_closed(max_hole=None)`` says whether every loop is smaller (bounding-box diagonal)
than ``max_hole`` (default 0.25 x the mesh thickness 3V/A, i.e. a quarter of a sphere's
radius or 0.375 of a long cylinder's).

Kernel level (for numba code): ``D = mesh.kernel_data()`` is a tuple of arrays (layout in
sgim/_meshq.py); ``sgim._meshq.closest_point(D, 0, x, y, z, maxd2)``,
``signed_point(D, 0, x, y, z, maxd)``, ``inside_point(D, 0, x, y, z)`` are ``@njit``
functions.  :class:`MeshSet` joins several meshes (for example every cavity of a scene)
into one ``D``; ``sgim._meshq.clearance_point(D, x, y, z, maxd)`` then gives the signed
clearance to their union (min over meshes of the signed distance; +inf / -inf beyond
``maxd`` outside / inside), and ``MeshSet.clearance(points, max_dist)`` the same vectorised.
"""
from __future__ import annotations

import numpy as np

from . import _meshq as K
from .portable import norm

__all__ = ["TriMesh", "MeshSet"]


def _edge_table(F, nv):
    """Undirected edges of faces F: (edges (ne,2), fedge (m,3), count (ne,), twin (3m,), he_dir (3m,))."""
    m = len(F)
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * np.int64(nv) + hi
    uniq, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    edges = np.column_stack([uniq // nv, uniq % nv]).astype(np.int64)
    twin = np.full(3 * m, -1, np.int64)
    order = np.argsort(inv, kind="stable")
    first = np.zeros(len(uniq) + 1, np.int64)
    np.cumsum(count, out=first[1:])
    pair = np.nonzero(count == 2)[0]
    h0, h1 = order[first[pair]], order[first[pair] + 1]
    twin[h0], twin[h1] = h1, h0
    he_dir = np.where(a < b, 1, -1).astype(np.int64)
    return edges, inv.reshape(m, 3), count, twin, he_dir


def _components(n, pairs):
    """Connected components of n nodes joined by index pairs (k,2): labels (n,)."""
    # scipy loaded only when a mesh is cleaned (start-up time), here and in TriMesh
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(pairs) == 0:
        return np.arange(n)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1]


class TriMesh:
    """A cleaned triangle surface with spatial queries (see the module docstring)."""

    def __init__(self, vertices, faces, weld=1e-7, orient=True):
        V = np.asarray(vertices, dtype=float)
        F = np.asarray(faces)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
            raise ValueError("vertices must be (n, 3) and faces (m, 3)")
        if not np.all(np.isfinite(V)):
            raise ValueError("vertices must be finite")
        if F.size and (F.min() < 0 or F.max() >= len(V)):
            raise ValueError(f"face vertex index out of range 0..{len(V) - 1}")
        F = F.astype(np.int64)
        src = np.arange(len(F))
        rep = {"input_vertices": int(len(V)), "input_faces": int(len(F))}

        # 1. weld near-duplicate vertices
        diag = norm(np.ptp(V, axis=0)) if len(V) else 0.0
        tol = weld * diag
        if tol > 0 and len(V) > 1:
            from scipy.spatial import cKDTree  # scipy only for meshes that need welding (start-up time)

            pairs = cKDTree(V).query_pairs(tol, output_type="ndarray")
            lab = _components(len(V), pairs)
        else:
            lab = np.unique(V, axis=0, return_inverse=True)[1].ravel()
        _, first, lab = np.unique(lab, return_index=True, return_inverse=True)
        F = lab.ravel()[F]
        rep["welded_vertices"] = int(len(V) - len(first))

        # 2. degenerate and duplicate triangles
        ok = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])
        P = V[first]
        if len(F):
            t = P[F]
            cr = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
            e2 = np.maximum.reduce([((t[:, 1] - t[:, 0]) ** 2).sum(1), ((t[:, 2] - t[:, 1]) ** 2).sum(1),
                                    ((t[:, 0] - t[:, 2]) ** 2).sum(1)])
            ok &= cr > 1e-10 * e2
        rep["degenerate_faces"] = int((~ok).sum())
        F, src = F[ok], src[ok]
        _, keep = np.unique(np.sort(F, axis=1), axis=0, return_index=True)
        keep = np.sort(keep)
        rep["duplicate_faces"] = int(len(F) - len(keep))
        F, src = F[keep], src[keep]
        if len(F) == 0:
            raise ValueError("no triangles left after removing degenerate ones")
        used, F = np.unique(F, return_inverse=True)
        F = F.reshape(-1, 3).astype(np.int64)
        P = np.ascontiguousarray(P[used])

        # 3. orientation
        edges, fedge, count, twin, he_dir = _edge_table(F, len(P))
        flip, comp = K.orient_faces(twin, he_dir, len(F))
        ncomp = int(comp.max()) + 1
        self.vertices = P
        self._set_faces(F, src)
        rep["patches"] = ncomp
        rep["flipped_faces"] = 0
        if orient:
            Fo = F.copy()
            Fo[flip] = Fo[flip][:, [0, 2, 1]]
            area = self._face_area(Fo)
            vol, closedish = self._patch_volumes(Fo, comp, ncomp)
            against = np.bincount(comp, weights=area * flip, minlength=ncomp)
            total = np.bincount(comp, weights=area, minlength=ncomp)
            whole = np.where(closedish, vol < 0, against > 0.5 * total)
            flip = flip ^ whole[comp]
            rep["flipped_faces"] = int(flip.sum())
            F = F.copy()
            F[flip] = F[flip][:, [0, 2, 1]]

        # 4. BVH, then the per-face / per-edge / per-vertex tables in BVH order
        tri = np.ascontiguousarray(P[F].reshape(-1, 9))
        order, self._lo, self._hi, self._kid, self._rng = K.build_bvh(tri, K.LEAF)
        F, src = F[order], src[order]
        self._set_faces(F, src)
        self.edges, self._fedge, self.edge_count, _, _ = _edge_table(F, len(P))
        self.report = rep
        rep["boundary_edges"] = int((self.edge_count == 1).sum())
        rep["nonmanifold_edges"] = int((self.edge_count > 2).sum())
        self._tables()

    # -- construction helpers ---------------------------------------------------
    def _set_faces(self, F, src):
        self.faces = np.ascontiguousarray(F, dtype=np.int64)
        self.face_source = np.asarray(src, dtype=np.int64)

    def _face_area(self, F):
        t = self.vertices[F]
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)

    def _patch_volumes(self, F, comp, ncomp):
        """Signed volume of each patch (about its centroid) and whether it is closed or nearly so."""
        t = self.vertices[F]
        cen = np.stack([np.bincount(comp, weights=t[:, :, a].mean(1), minlength=ncomp) for a in range(3)], 1)
        cen /= np.bincount(comp, minlength=ncomp)[:, None]
        q = t - cen[comp][:, None, :]
        vol = np.bincount(comp, weights=np.einsum("ij,ij->i", q[:, 0], np.cross(q[:, 1], q[:, 2])) / 6.0,
                          minlength=ncomp)
        area = np.bincount(comp, weights=self._face_area(F), minlength=ncomp)
        edges, fedge, count, _, _ = _edge_table(F, len(self.vertices))
        ecomp = np.zeros(len(edges), np.int64)
        ecomp[fedge.ravel()] = np.repeat(comp, 3)
        blen = np.linalg.norm(self.vertices[edges[:, 0]] - self.vertices[edges[:, 1]], axis=1) * (count == 1)
        bsum = np.bincount(ecomp, weights=blen, minlength=ncomp)
        # closed, or open only along boundary loops that are short next to the patch's size
        closedish = bsum <= 0.1 * np.sqrt(area)
        return vol, closedish

    def _tables(self):
        P, F = self.vertices, self.faces
        t = P[F]
        cr = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        ln = np.linalg.norm(cr, axis=1)
        self.areas = 0.5 * ln
        self.normals = cr / ln[:, None]
        # angle-weighted vertex pseudo-normals
        vpn = np.zeros_like(P)
        for c in range(3):
            u = t[:, (c + 1) % 3] - t[:, c]
            w = t[:, (c + 2) % 3] - t[:, c]
            cosang = np.einsum("ij,ij->i", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
            ang = np.arccos(np.clip(cosang, -1.0, 1.0))
            np.add.at(vpn, F[:, c], ang[:, None] * self.normals)
        epn = np.zeros((len(self.edges), 3))
        for c in range(3):
            np.add.at(epn, self._fedge[:, c], self.normals)
        for arr in (vpn, epn):
            nrm = np.linalg.norm(arr, axis=1)
            arr /= np.where(nrm > 0, nrm, 1.0)[:, None]
        ebnd = (self.edge_count == 1).astype(np.uint8)
        vbnd = np.zeros(len(P), np.uint8)
        vbnd[self.edges[ebnd == 1].ravel()] = 1
        self.boundary_edges = self.edges[ebnd == 1]
        self.closed = bool(len(self.boundary_edges) == 0)
        self.lo, self.hi = P.min(0), P.max(0)
        self._D = (
            np.ascontiguousarray(self._lo), np.ascontiguousarray(self._hi), np.ascontiguousarray(self._kid),
            np.ascontiguousarray(self._rng), np.ascontiguousarray(t.reshape(-1, 9)),
            np.ascontiguousarray(self.normals), np.ascontiguousarray(self._fedge), self.faces,
            np.ascontiguousarray(epn), np.ascontiguousarray(vpn), ebnd, vbnd,
            np.zeros(1, np.int64), np.array([0, len(F)], np.int64),
        )

    # -- properties ----------------------------------------------------------------
    @property
    def n_faces(self):
        return len(self.faces)

    def kernel_data(self):
        """The tuple of arrays the numba kernels of sgim._meshq take (mesh index 0)."""
        return self._D

    @property
    def area(self):
        return float(self.areas.sum())

    @property
    def volume(self):
        """Signed enclosed volume (divergence theorem; meaningful for closed meshes)."""
        t = self.vertices[self.faces] - self.vertices.mean(0)
        return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)

    @property
    def thickness(self):
        """3 |V| / A: a sphere's radius, 1.5 x a long cylinder's radius."""
        return 3.0 * abs(self.volume) / self.area

    def holes(self):
        """Boundary loops (or chains) as arrays of vertex ids."""
        be = self.boundary_edges
        if len(be) == 0:
            return []
        vids, inv = np.unique(be.ravel(), return_inverse=True)
        lab = _components(len(vids), inv.reshape(-1, 2))
        return [vids[lab == c] for c in range(int(lab.max()) + 1)]

    def hole_sizes(self):
        """Bounding-box diagonal of each boundary loop."""
        return np.array([norm(np.ptp(self.vertices[h], axis=0)) for h in self.holes()])

    def nearly_closed(self, max_hole=None):
        """True when the mesh is closed up to small defects: every hole no larger than max_hole."""
        if self.closed:
            return True
        if max_hole is None:
            max_hole = 0.25 * self.thickness
        return bool(np.all(self.hole_sizes() <= max_hole))

    # -- queries ---------------------------------------------------------------------
    @staticmethod
    def _pts(points):
        p = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
        return p

    def closest(self, points, max_dist=np.inf):
        """(dist, foot (k,3), face, on_boundary) of the nearest surface point within max_dist."""
        return K.closest_many(self._D, 0, self._pts(points), float(max_dist))

    def signed_distance(self, points, max_dist=np.inf):
        """Pseudo-normal signed distance (negative inside an outward closed mesh), inf beyond max_dist."""
        return K.signed_many(self._D, 0, self._pts(points), float(max_dist))

    def signed_closest(self, points, max_dist=np.inf):
        """(signed distance, face, on_boundary) within max_dist (inf, -1, False beyond)."""
        return K.signed_full_many(self._D, 0, self._pts(points), float(max_dist))

    def inside(self, points):
        """Ray-parity vote: True inside the (nearly) closed mesh."""
        return K.inside_many(self._D, 0, self._pts(points))

    def overlaps(self, points, r):
        """True where a sphere of radius r (scalar or one per point) centred at the point has its
        centre inside the closed mesh or is closer than r to its surface."""
        p = self._pts(points)
        rad = np.ascontiguousarray(np.broadcast_to(np.asarray(r, dtype=float), (len(p),)))
        return K.removed_by_cavity(self._D, 0, p, rad)

    def segment_crossings(self, a, b, eps=1e-9):
        """A face crossed by each segment a[i] -> b[i], or -1 (barycentric slack eps)."""
        return K.segments_cross(self._D, 0, self._pts(a), self._pts(b), float(eps))


class MeshSet:
    """Several meshes in one kernel data tuple (mesh k keeps its faces, edges and vertices).

    ``face_start[k]`` offsets mesh k's faces in the joined face numbering.
    """

    def __init__(self, meshes):
        self.meshes = list(meshes)
        if not self.meshes:
            raise ValueError("MeshSet needs at least one mesh")
        parts = [m.kernel_data() for m in self.meshes]
        nodes = np.cumsum([0] + [len(d[0]) for d in parts])
        facs = np.cumsum([0] + [len(d[4]) for d in parts])
        edgs = np.cumsum([0] + [len(d[8]) for d in parts])
        vrts = np.cumsum([0] + [len(d[9]) for d in parts])
        kid = []
        for k, d in enumerate(parts):
            c = d[2].copy()
            c[c >= 0] += nodes[k]
            kid.append(c)
        self._D = (
            np.concatenate([d[0] for d in parts]), np.concatenate([d[1] for d in parts]),
            np.ascontiguousarray(np.concatenate(kid)),
            np.concatenate([d[3] + facs[k] for k, d in enumerate(parts)]),
            np.concatenate([d[4] for d in parts]), np.concatenate([d[5] for d in parts]),
            np.concatenate([d[6] + edgs[k] for k, d in enumerate(parts)]),
            np.concatenate([d[7] + vrts[k] for k, d in enumerate(parts)]),
            np.concatenate([d[8] for d in parts]), np.concatenate([d[9] for d in parts]),
            np.concatenate([d[10] for d in parts]), np.concatenate([d[11] for d in parts]),
            nodes[:-1].astype(np.int64), facs.astype(np.int64),
        )
        self.face_start = facs.astype(np.int64)

    def __len__(self):
        return len(self.meshes)

    def kernel_data(self):
        return self._D

    def clearance(self, points, max_dist=np.inf):
        """Signed clearance to the union of the meshes (see sgim._meshq.clearance_point)."""
        return K.clearance_many(self._D, TriMesh._pts(points), float(max_dist))
