"""Excavation of the block model: a triangulated terrain removes everything above it, a closed cavity removes
everything inside it, both exactly (dda/geoblocks.py calls them block by block).

Terrain (an ``[[excavation]]`` surface, a height field: every vertical line meets it at most once). Let h(x, y)
be the surface's height; the kept region is z <= h where the surface covers the plan, everything elsewhere.
For a block P with plan footprint F (the convex hull of its vertices' (x, y)):

- the facets whose plan triangle overlaps F with positive area are the only ones that matter;
- where the surface bends upward across an edge (a *valley* edge: the kept region is reflex there) or ends (a
  boundary edge), and that edge crosses the interior of F, P is split by the vertical plane through the edge
  and each half is treated again with the remaining edges (the split faces are intact rock);
- with no such edge left, h is concave on F (a piecewise-linear function concave across every interior edge of a
  convex domain is the minimum of its pieces), so P below the surface is P clipped below every facet plane over
  F: one convex piece, whose faces on the facet planes are the excavation's free faces;
- two halves both kept whole are given back as their parent, so only blocks the surface actually crosses are
  split.

Cavity (``[[cavity]]``, a closed triangulated surface): every facet whose triangle reaches a piece of the block
(exact test in the facet's plane) splits that piece by its plane; the surface then crosses no piece's interior,
so each piece lies wholly inside or outside and its centroid decides (``TriMesh.inside``). A block with no
piece inside is kept whole. Once the model is cut through, ``label_walls`` makes the caps wholly on the wall
free faces; the others (between two kept pieces, or partly so) stay intact rock.
"""
from __future__ import annotations

import numpy as np

from ._geocut import overlap_mask
from .blockcut import REL, TBlock, convex_polygon_2d, face_planes, split, triangle_reaches
from .shapes import GeometryError


class Terrain:
    """The facets of one excavation surface as plan triangles with planes z = a x + b y + c, and its valley and
    boundary edges."""

    def __init__(self, vertices, faces, name="excavation"):
        v = np.asarray(vertices, float)
        f = np.asarray(faces, np.int64)
        xy = v[f][:, :, :2]
        area2 = ((xy[:, 1, 0] - xy[:, 0, 0]) * (xy[:, 2, 1] - xy[:, 0, 1])
                 - (xy[:, 1, 1] - xy[:, 0, 1]) * (xy[:, 2, 0] - xy[:, 0, 0]))
        scale = float(np.ptp(v[:, :2], axis=0).max()) or 1.0
        keep = np.abs(area2) > 1e-12 * scale * scale  # vertical facets remove nothing
        f = np.where((area2 < 0)[:, None], f[:, [0, 2, 1]], f)[keep]  # counter-clockwise in plan
        self.name = name
        self.v, self.f = v, f
        self.tri = v[f]
        self.xy = np.ascontiguousarray(self.tri[:, :, :2])
        self.box = np.column_stack([self.xy[:, :, 0].min(1), self.xy[:, :, 0].max(1),
                                    self.xy[:, :, 1].min(1), self.xy[:, :, 1].max(1)])
        self.zlo, self.zhi = self.tri[:, :, 2].min(1), self.tri[:, :, 2].max(1)
        # plane z = a x + b y + c through each facet
        p0, e1, e2 = self.tri[:, 0], self.tri[:, 1] - self.tri[:, 0], self.tri[:, 2] - self.tri[:, 0]
        nrm = np.cross(e1, e2)
        self.a, self.b = -nrm[:, 0] / nrm[:, 2], -nrm[:, 1] / nrm[:, 2]
        self.c = p0[:, 2] - self.a * p0[:, 0] - self.b * p0[:, 1]
        self._edges(scale)

    def _edges(self, scale):
        owner = {}
        for k, t in enumerate(self.f.tolist()):
            for i in range(3):
                a, b, o = t[i], t[(i + 1) % 3], t[(i + 2) % 3]
                owner.setdefault((min(a, b), max(a, b)), []).append((k, o))
        ends, bad = [], []
        tol = 1e-9 * max(scale, float(np.ptp(self.v[:, 2])))
        for (a, b), fs in owner.items():
            if len(fs) > 2:
                raise GeometryError(f"{self.name}: edge {a}-{b} is shared by {len(fs)} facets (not a height field)")
            if len(fs) == 1:
                ends.append((a, b))
                continue
            (f, _), (g, og) = fs
            q = self.v[og]
            # the far vertex of g against the side of the edge in plan: both facets on one side = a fold
            pa, pb = self.v[a, :2], self.v[b, :2]
            side = lambda p: (pb[0] - pa[0]) * (p[1] - pa[1]) - (pb[1] - pa[1]) * (p[0] - pa[0])  # noqa: E731
            if side(self.v[fs[0][1], :2]) * side(q[:2]) >= 0:
                raise GeometryError(f"{self.name}: the surface folds over at edge {a}-{b} (not a height field)")
            if q[2] > self.a[f] * q[0] + self.b[f] * q[1] + self.c[f] + tol:
                ends.append((a, b))  # valley: the surface bends upward across the edge
        e = np.array(ends, np.int64).reshape(-1, 2)
        self.seg = np.ascontiguousarray(self.v[e][:, :, :2]) if len(e) else np.zeros((0, 2, 2))
        self.seg_box = np.column_stack([self.seg[:, :, 0].min(1), self.seg[:, :, 0].max(1),
                                        self.seg[:, :, 1].min(1), self.seg[:, :, 1].max(1)])

    def facets_near(self, lo, hi):
        b = self.box
        return np.nonzero((b[:, 0] < hi[0]) & (b[:, 1] > lo[0]) & (b[:, 2] < hi[1]) & (b[:, 3] > lo[1]))[0]

    def edges_near(self, lo, hi):
        b = self.seg_box
        return np.nonzero((b[:, 0] <= hi[0]) & (b[:, 1] >= lo[0]) & (b[:, 2] <= hi[1]) & (b[:, 3] >= lo[1]))[0]


def _footprint_overlaps(fp, polys, ids, eps):
    ids = np.asarray(ids, np.int64)
    return ids[overlap_mask(np.ascontiguousarray(fp), polys, ids, eps)].tolist()


def excavate_block(blk: TBlock, ter: Terrain, wall_src, split_src):
    """The pieces of ``blk`` below the terrain ([] when all of it is above)."""
    lo, hi = blk.v.min(0), blk.v.max(0)
    facets = ter.facets_near(lo, hi)
    if len(facets) == 0:
        return [blk]
    if hi[2] <= ter.zlo[facets].min():
        return [blk]
    return _below(blk, ter, facets, ter.edges_near(lo, hi), wall_src, split_src)[1]


def _below(blk, ter, facets, edges, wall_src, split_src):
    """("whole" | "empty" | "cut", pieces) of ``blk`` below the terrain, using only ``facets`` and ``edges``."""
    fp = convex_polygon_2d(blk.v[:, :2])
    eps = REL * blk.diag()
    if len(fp) < 3:
        return "whole", [blk]
    facets = _footprint_overlaps(fp, ter.xy, facets, eps)
    if not facets:
        return "whole", [blk]
    # below (above) the plane of every facet over the footprint: below (above) the surface, which is one of
    # those planes at every point of the footprint
    f = np.asarray(facets)
    gap = blk.v[:, 2:3] - (blk.v[:, :1] * ter.a[f] + blk.v[:, 1:2] * ter.b[f] + ter.c[f])
    if gap.max() <= eps:
        return "whole", [blk]
    cross = _footprint_overlaps(fp, ter.seg, edges, eps)
    if not cross:
        if gap.min() >= -eps:
            return "empty", []
        return _clip_concave(blk, ter, facets, wall_src)
    # split by the vertical plane of the crossing edge whose line passes nearest the footprint's centre
    c = fp.mean(0)
    seg = ter.seg[cross]
    t = seg[:, 1] - seg[:, 0]
    nrm = np.column_stack([-t[:, 1], t[:, 0]]) / np.linalg.norm(t, axis=1)[:, None]
    dist = np.abs(np.einsum("ij,ij->i", nrm, c - seg[:, 0]))
    k = int(np.argmin(dist))
    n3 = np.array([nrm[k, 0], nrm[k, 1], 0.0])
    rest = [e for j, e in enumerate(cross) if j != k]
    halves = split(blk, n3, float(n3[:2] @ seg[k, 0]), split_src)
    if halves[0] is None or halves[1] is None:
        return _below(blk, ter, facets, rest, wall_src, split_src)
    res = [_below(h, ter, facets, rest, wall_src, split_src) for h in halves]
    states = {r[0] for r in res}
    if states == {"whole"}:
        return "whole", [blk]
    if states == {"empty"}:
        return "empty", []
    return "cut", res[0][1] + res[1][1]


def _clip_concave(blk, ter, facets, wall_src):
    piece = blk
    for f in facets:
        n = np.array([-ter.a[f], -ter.b[f], 1.0])
        m = float(np.linalg.norm(n))
        piece = split(piece, n / m, ter.c[f] / m, wall_src)[0]
        if piece is None:
            return "empty", []
    return ("whole", [blk]) if piece is blk else ("cut", [piece])


class CavityCut:
    """The facets of one closed cavity surface (sgim.meshquery.TriMesh) with their planes and boxes."""

    def __init__(self, mesh, name="cavity"):
        self.mesh = mesh
        self.name = name
        self.tri = mesh.vertices[mesh.faces]
        nrm = np.cross(self.tri[:, 1] - self.tri[:, 0], self.tri[:, 2] - self.tri[:, 0])
        ln = np.linalg.norm(nrm, axis=1)
        ok = ln > 0
        self.tri, nrm, ln = self.tri[ok], nrm[ok], ln[ok]
        self.n = nrm / ln[:, None]
        self.d = np.einsum("ij,ij->i", self.n, self.tri[:, 0])
        self.lo, self.hi = self.tri.min(1), self.tri.max(1)
        h = np.where((np.abs(self.n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        self.e1 = np.cross(h, self.n)
        self.e1 /= np.linalg.norm(self.e1, axis=1)[:, None]
        self.e2 = np.cross(self.n, self.e1)  # (e1, e2, n) right-handed, as blockcut.plane_basis

    def facets_near(self, lo, hi):
        return np.nonzero(np.all(self.lo <= hi, axis=1) & np.all(self.hi >= lo, axis=1))[0]


def carve_block(blk: TBlock, cav: CavityCut, wall_src, split_src):
    """The pieces of ``blk`` outside the cavity ([] when all of it is inside)."""
    lo, hi = blk.v.min(0), blk.v.max(0)
    if np.any(hi < cav.mesh.lo) or np.any(lo > cav.mesh.hi):
        return [blk]
    pieces, plo, phi = [blk], [lo], [hi]
    for f in cav.facets_near(lo, hi):
        near = np.all(cav.lo[f] <= np.array(phi), axis=1) & np.all(cav.hi[f] >= np.array(plo), axis=1)
        for k in np.nonzero(near)[0].tolist():
            p = pieces[k]
            if not triangle_reaches(p, cav.tri[f], cav.n[f], (cav.e1[f], cav.e2[f])):
                continue
            below, above = split(p, cav.n[f], cav.d[f], split_src)
            pieces[k] = None
            for q in (below, above):
                if q is not None:
                    pieces.append(q)
                    plo.append(q.v.min(0))
                    phi.append(q.v.max(0))
        keep = [k for k, p in enumerate(pieces) if p is not None]
        pieces, plo, phi = [pieces[k] for k in keep], [plo[k] for k in keep], [phi[k] for k in keep]
    cents = np.array([p.volume_centroid()[1] for p in pieces])
    inside = np.asarray(cav.mesh.inside(cents), bool)
    if not inside.any():
        return [blk]
    return [p for p, i in zip(pieces, inside) if not i]


def label_walls(blocks, cav: CavityCut, wall_src, split_src):
    """The caps (faces of source ``split_src``) of ``blocks`` that lie wholly on the cavity's wall get
    ``wall_src`` (a free face); the others stay intact rock. Run once the model is cut through (a cap that the
    discs cut later is judged by its own pieces): a cap is on the wall when the points just outside it (its
    centre and its corners drawn 1 % towards the centre) all lie in the cavity; a cap with rock beyond a part of
    it keeps the intact law there, where its contacts are."""
    for p in blocks:
        idx = [k for k, s in enumerate(p.src) if s == split_src]
        if not idx:
            continue
        if np.any(p.v.max(0) < cav.mesh.lo) or np.any(p.v.min(0) > cav.mesh.hi):
            continue
        n, _ = face_planes(p)
        probes, owner = [], []
        for k in idx:
            corners = p.v[p.faces[k]]
            c = corners.mean(0)
            pts = np.vstack([c, c + 0.99 * (corners - c)]) + 1e-6 * p.diag() * n[k]
            probes.append(pts)
            owner += [k] * len(pts)
        inside = np.asarray(cav.mesh.inside(np.vstack(probes)), bool)
        owner = np.asarray(owner)
        for k in idx:
            if inside[owner == k].all():
                p.src[k] = wall_src
