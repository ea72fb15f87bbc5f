"""The block model of an sgim scene: the scene's rock mass cut into convex blocks whose faces remember what made
them (issue: one scene, two models).

    from sgim.scene import load_scene
    from dda.geoblocks import build_blocks
    model = build_blocks(load_scene("cases/scenes/open_pit_coarse.toml"))
    model.blocks, model.sources, model.specs(), model.summary()

Stages, in order (each stage cuts the blocks the previous one left):

1. the ``[domain]`` box;
2. the persistent joint sets of ``[[blocks.joint_set]]`` (dip, dip direction, spacing, origin; a plane of a set
   with ``persistence`` p < 1 cuts each block it crosses with chance p; a set with ``extent`` cuts, after the
   unbounded sets, the whole blocks whose section by the plane has its centre in the box);
3. every ``[[excavation]]`` surface removes everything above it, exactly (dda/geoexcavate.py);
4. every ``[[cavity]]`` removes everything inside it, exactly (dda/geoexcavate.py);
5. every ``[[discontinuity]]`` disc and every fracture of the ``[dfn]`` network cuts, along its plane, each whole
   block its disc reaches (exact disc-against-section test, dda/blockcut.py); a disc with thickness t > 0 (a
   fault) cuts along its two faces at +-t/2, and the pieces between them whose centroid lies within the disc's
   radius get the fault as their material; a triangulated ``[[discontinuity]]`` cuts with each facet's plane the
   blocks that facet reaches.

Slivers: a planar cut (stages 2 and 5) that would leave a piece smaller than ``[blocks] min_volume`` is not made
(the block stays whole: volume is conserved, nothing dropped); the pieces of the exact excavations are kept
whatever their size (``summary()["small_blocks"]`` counts those below min_volume).

Faces and contact kinds: every face has a source (``sources[block.src[k]]``) with a kind: ``domain`` (the box),
``joint`` (a joint set plane), ``excavation`` (a free face on a surface or cavity wall), ``intact`` (a vertical
split under a valley of the terrain, a split between two kept pieces of a cavity cut), ``fault``. A face made
by a disc (or a facet of a triangulated discontinuity) is joint (fault) where a point of it lies inside the
disc (triangle) and intact rock outside: :meth:`BlockModel.point_kinds` decides per contact point.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field

import numpy as np

from sgim.blocktable import DEFAULTS as BLOCK_DEFAULTS
from sgim.blocktable import BlocksSpec
from sgim.common import atomic_path, atomic_vtu
from sgim.dfn import network_for
from sgim.geometry import dip_to_normal

from .blockcut import (REL, TBlock, disc_reaches, fan, face_planes, plane_basis, section, signed, split,
                       triangle_reaches)
from .blockspec import BlockSpec
from .geoexcavate import CavityCut, Terrain, carve_block, excavate_block, label_walls

KINDS = ("domain", "joint", "intact", "fault", "excavation")
DOMAIN, JOINT, INTACT, FAULT, EXCAVATION = range(len(KINDS))
BOX_FACES = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]


@dataclass
class Source:
    """What made a face. ``shape``: "box", "plane" (a joint set), "disc" (centre, normal, radius), "triangle"
    (tri), "surface" (an excavation or cavity). ``kind`` is the face kind (KINDS) inside a disc or triangle."""

    name: str
    kind: int
    shape: str = "plane"
    centre: np.ndarray | None = None
    normal: np.ndarray | None = None
    radius: float = 0.0
    tri: np.ndarray | None = None


@dataclass
class BlockModel:
    blocks: list
    sources: list
    lo: np.ndarray
    hi: np.ndarray
    min_volume: float
    stats: dict = field(default_factory=dict)

    def specs(self, prefix="b"):
        """The blocks as dda BlockSpecs (material "rock" or the fault's name)."""
        return [BlockSpec(b.v.copy(), [list(f) for f in b.faces], name=f"{prefix}{i}", material=b.material)
                for i, b in enumerate(self.blocks)]

    def face_kinds(self, i):
        """The nominal kind of every face of block i (a disc's faces: the disc's kind)."""
        return np.array([self.sources[s].kind for s in self.blocks[i].src], np.int64)

    def point_kinds(self, i, face, points):
        """The kind (KINDS index) of each contact point on face ``face`` of block ``i`` (kinds_at)."""
        return kinds_at(self.sources[self.blocks[i].src[face]], points)

    def volumes(self):
        return np.array([b.volume() for b in self.blocks])

    def summary(self):
        vol = self.volumes()
        mat = {}
        for b in self.blocks:
            mat[b.material] = mat.get(b.material, 0) + 1
        some = len(vol) > 0
        return {"blocks": len(self.blocks), "volume": float(vol.sum()),
                "smallest": float(vol.min()) if some else None, "median": float(np.median(vol)) if some else None,
                "largest": float(vol.max()) if some else None, "materials": mat,
                "small_blocks": int((vol < self.min_volume).sum()), "min_volume": self.min_volume, **self.stats}


def kinds_at(src, points):
    """The kind (KINDS index) at each of `points` on a face made by source `src`: a disc's (triangle's) face is its
    kind inside the disc (triangle), intact rock outside; other faces have their source's kind."""
    pts = np.atleast_2d(np.asarray(points, float))
    out = np.full(len(pts), src.kind, np.int64)
    if src.shape == "disc":
        rel = pts - src.centre
        radial = rel - np.outer(rel @ src.normal, src.normal)
        out[np.einsum("ij,ij->i", radial, radial) > src.radius ** 2] = INTACT
    elif src.shape == "triangle":
        out[~_in_triangle(src.tri, pts)] = INTACT
    return out


def _in_triangle(tri, pts):
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    ok = np.ones(len(pts), bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        ok &= np.cross(tri[b] - tri[a], pts - tri[a]) @ n >= 0
    return ok


def default_spec(scene):
    vol = float(np.prod(np.asarray(scene.domain.max, float) - np.asarray(scene.domain.min, float)))
    d = BLOCK_DEFAULTS
    return BlocksSpec(d["blocks.min_volume_fraction"] * vol, None, d["blocks.cohesion"], d["blocks.tensile"],
                      d["blocks.friction"], d["blocks.seed"])


class _Pool:
    """The blocks being cut, with their bounding boxes as arrays for the vectorised candidate search."""

    def __init__(self, blocks):
        self.blocks = list(blocks)
        self._box()

    def _box(self):
        self.lo = np.array([b.v.min(0) for b in self.blocks]).reshape(-1, 3)
        self.hi = np.array([b.v.max(0) for b in self.blocks]).reshape(-1, 3)

    def crossing(self, n, d, lo=None, hi=None):
        """Indices of blocks whose box the plane n . x = d crosses (and that overlap the box lo..hi)."""
        c, h = (self.lo + self.hi) / 2, (self.hi - self.lo) / 2
        sel = np.abs(c @ n - d) < np.abs(h) @ np.abs(n)
        if lo is not None:
            sel &= self.overlaps(lo, hi)
        return np.nonzero(sel)[0]

    def overlaps(self, lo, hi):
        """(n,) bool: the blocks whose box overlaps the box lo..hi."""
        return np.all(self.lo <= hi, axis=1) & np.all(self.hi >= lo, axis=1)

    def near(self, lo, hi):
        """Indices of the blocks whose box overlaps the box lo..hi."""
        return np.nonzero(self.overlaps(lo, hi))[0]

    def replace(self, repl):
        """Replace block i by the list repl[i] for every i in the dict ``repl`` (boxes computed for new blocks only)."""
        if not repl:
            return
        out, lo, hi = [], [], []
        start = 0
        for i in sorted(repl):
            out += self.blocks[start:i] + repl[i]
            lo += [self.lo[start:i], np.array([b.v.min(0) for b in repl[i]]).reshape(-1, 3)]
            hi += [self.hi[start:i], np.array([b.v.max(0) for b in repl[i]]).reshape(-1, 3)]
            start = i + 1
        self.blocks = out + self.blocks[start:]
        self.lo = np.concatenate(lo + [self.lo[start:]])
        self.hi = np.concatenate(hi + [self.hi[start:]])


class _Grid:
    """The pool's blocks in a uniform grid of cells (each block listed in every cell its box overlaps), so that a
    cutter finds the blocks it may reach from the cells its box and plane cross: a DFN's small discs cost what
    they reach, not a scan of every block (the open pit's 6116 discs over up to 54 000 blocks).

    The same interface as _Pool for the cuts (``blocks[i]``, ``crossing``, ``near``, ``replace``), with ids that
    stay valid while other blocks are cut; ``key[i]`` is the block's place in the pool's order (a tuple: the pieces
    of a cut block take its place, as _Pool.replace puts them), so ``to_pool`` gives the order _Pool would have.
    """

    def __init__(self, pool, lo, hi):
        n = len(pool.blocks)
        self.blocks = dict(enumerate(pool.blocks))
        self.key = {i: (i,) for i in range(n)}
        self.lo, self.hi = pool.lo.copy(), pool.hi.copy()
        self.next = n
        ext = np.max(pool.hi - pool.lo, axis=1) if n else np.ones(1)
        self.g0 = np.asarray(lo, float)
        span = np.asarray(hi, float) - self.g0
        # cells of half the median block's size, at most 128 along the domain's longest side
        self.cell = max(0.5 * float(np.median(ext)), float(span.max()) / 128.0)
        self.dims = np.maximum(np.ceil(span / self.cell).astype(np.int64), 1)
        self._g, self._dims, self._top = self.g0.tolist(), self.dims.tolist(), (self.dims - 1).tolist()
        self.cells = {}
        for i in range(n):
            self._file(i)

    def _range(self, lo, hi):
        # floor_divide: the same cell as _file's // for every coordinate (floor(x / h) can round up to the next)
        a = np.clip(np.floor_divide(np.asarray(lo) - self.g0, self.cell).astype(np.int64), 0, self.dims - 1)
        b = np.clip(np.floor_divide(np.asarray(hi) - self.g0, self.cell).astype(np.int64), 0, self.dims - 1)
        return a, b

    def _cell_ids(self, lo, hi):
        a, b = self._range(lo, hi)
        ix, iy, iz = np.meshgrid(*(np.arange(a[k], b[k] + 1) for k in range(3)), indexing="ij")
        return ix.ravel(), iy.ravel(), iz.ravel()

    def _flat(self, ix, iy, iz):
        return ((ix * self.dims[1] + iy) * self.dims[2] + iz).tolist()

    def _file(self, i, add=True):
        """List block i in (add) or take it out of every cell its box overlaps (scalar Python: a few cells)."""
        (gx, gy, gz), h, (_, ny, nz) = self._g, self.cell, self._dims
        (x0, y0, z0), (x1, y1, z1) = self.lo[i].tolist(), self.hi[i].tolist()
        mx, my, mz = self._top
        cells = self.cells
        for x in range(min(max(int((x0 - gx) // h), 0), mx), min(max(int((x1 - gx) // h), 0), mx) + 1):
            for y in range(min(max(int((y0 - gy) // h), 0), my), min(max(int((y1 - gy) // h), 0), my) + 1):
                base = (x * ny + y) * nz
                za, zb = min(max(int((z0 - gz) // h), 0), mz), min(max(int((z1 - gz) // h), 0), mz)
                for c in range(base + za, base + zb + 1):
                    if add:
                        cells.setdefault(c, set()).add(i)
                    else:
                        cells[c].discard(i)

    def _gather(self, cells):
        out = set()
        for c in cells:
            got = self.cells.get(c)
            if got:
                out |= got
        return np.fromiter(out, np.int64, len(out))

    def _ordered(self, ids):
        return np.array(sorted(ids.tolist(), key=self.key.__getitem__), np.int64)

    def near(self, lo, hi):
        """Ids (in pool order) of the blocks whose box overlaps the box lo..hi."""
        ids = self._gather(self._flat(*self._cell_ids(lo, hi)))
        sel = np.all(self.lo[ids] <= hi, axis=1) & np.all(self.hi[ids] >= lo, axis=1)
        return self._ordered(ids[sel])

    def crossing(self, n, d, lo=None, hi=None):
        """Ids (in pool order) of blocks whose box the plane n . x = d crosses and that overlap the box lo..hi."""
        lo = self.g0 if lo is None else lo
        hi = self.g0 + self.dims * self.cell if hi is None else hi
        ix, iy, iz = self._cell_ids(lo, hi)
        centre = self.g0 + (np.column_stack([ix, iy, iz]) + 0.5) * self.cell
        on = np.abs(centre @ n - d) <= 0.5 * self.cell * np.abs(n).sum() * (1 + 1e-9) + 1e-9 * self.cell
        ids = self._gather(self._flat(ix[on], iy[on], iz[on]))
        blo, bhi = self.lo[ids], self.hi[ids]
        c, h = (blo + bhi) / 2, (bhi - blo) / 2
        sel = (np.abs(c @ n - d) < np.abs(h) @ np.abs(n)) & np.all(blo <= hi, axis=1) & np.all(bhi >= lo, axis=1)
        return self._ordered(ids[sel])

    def replace(self, repl):
        """Replace block i by the pieces repl[i] (new ids, in i's place of the order) for every i in ``repl``."""
        for i, pieces in repl.items():
            self._file(i, add=False)
            key = self.key.pop(i)
            del self.blocks[i]
            for j, b in enumerate(pieces):
                k = self.next
                self.next += 1
                if k >= len(self.lo):  # room for as many again (at least 64)
                    more = np.empty((max(len(self.lo), 64), 3))
                    self.lo, self.hi = np.concatenate([self.lo, more]), np.concatenate([self.hi, more])
                self.lo[k], self.hi[k] = b.v.min(0), b.v.max(0)
                self.blocks[k], self.key[k] = b, key + (j,)
                self._file(k)

    def to_pool(self, pool):
        """Write the blocks back into ``pool`` in _Pool's order."""
        order = sorted(self.blocks, key=self.key.__getitem__)
        pool.blocks = [self.blocks[i] for i in order]
        pool.lo, pool.hi = self.lo[order].reshape(-1, 3), self.hi[order].reshape(-1, 3)


def _cut_plane(pool, n, d, src, min_volume, stats, lo=None, hi=None, accept=None):
    """Cut every block of the pool that the plane crosses and ``accept(block, s)`` allows; sliver cuts skipped."""
    repl = {}
    for i in pool.crossing(n, d, lo, hi).tolist():
        b = pool.blocks[i]
        s = signed(b, n, d)
        if not ((s < 0).any() and (s > 0).any()):
            continue
        if accept is not None and not accept(b, s):
            continue
        below, above = split(b, n, d, src, s)
        if below.volume() < min_volume or above.volume() < min_volume:
            stats["sliver_cuts_skipped"] = stats.get("sliver_cuts_skipped", 0) + 1
            continue
        repl[i] = [below, above]
    pool.replace(repl)
    return repl


def _fabric(pool, spec, sources, lo, hi, stats):
    rng = np.random.default_rng(spec.seed)
    for fs in sorted(spec.joint_sets, key=lambda fs: fs.extent is not None):  # bounded sets last
        n = dip_to_normal(fs.dip, fs.dip_direction)
        sources.append(Source(fs.name, JOINT, "plane", normal=n))
        src = len(sources) - 1
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        s = corners @ n
        slo, shi = s.min(), s.max()
        elo = ehi = None
        if fs.extent is not None:
            elo, ehi = fs.extent
            e = np.array([[x, y, z] for x in (elo[0], ehi[0]) for y in (elo[1], ehi[1]) for z in (elo[2], ehi[2])]) @ n
            slo, shi = max(slo, e.min()), min(shi, e.max())
        d0 = float(n @ fs.origin)
        k0, k1 = int(np.ceil((slo - d0) / fs.spacing)), int(np.floor((shi - d0) / fs.spacing))
        for k in range(k0, k1 + 1):
            d = d0 + k * fs.spacing
            if not slo < d < shi:
                continue
            _cut_plane(pool, n, d, src, spec.min_volume, stats, elo, ehi, _fabric_accept(fs, n, d, rng))
        stats["planes"] = stats.get("planes", 0) + max(0, k1 - k0 + 1)


def _fabric_accept(fs, n, d, rng):
    def accept(b, s):
        if fs.extent is not None:  # a bounded set cuts the whole blocks whose section's centre lies in its box
            c = section(b, n, d, s).mean(0)
            if not (np.all(c >= fs.extent[0]) and np.all(c <= fs.extent[1])):
                return False
        return fs.persistence >= 1.0 or rng.random() < fs.persistence

    return accept


def _excavations(pool, scene, sources, stats):
    for ex in scene.excavations:
        ter = Terrain(ex.vertices, ex.faces, f"{ex.key} ({ex.name})")
        sources.append(Source(ex.name, EXCAVATION, "surface"))
        sources.append(Source(f"{ex.name} (split)", INTACT, "surface"))
        wall, cut = len(sources) - 2, len(sources) - 1
        repl = {}
        for i, b in enumerate(pool.blocks):
            out = excavate_block(b, ter, wall, cut)
            if len(out) != 1 or out[0] is not b:
                repl[i] = out
        pool.replace(repl)


def _cavities(pool, scene, sources, walls):
    """Carve every cavity; (cavity, wall source, cap source) of each into ``walls``, for label_walls once the
    model is cut through."""
    for cv in getattr(scene, "cavities", []):
        cav = CavityCut(cv.mesh, cv.name)
        sources.append(Source(cv.name, EXCAVATION, "surface"))
        sources.append(Source(f"{cv.name} (split)", INTACT, "surface"))
        wall, cut = len(sources) - 2, len(sources) - 1
        walls.append((cav, wall, cut))
        repl = {}
        for i in pool.near(cv.mesh.lo, cv.mesh.hi):
            b = pool.blocks[i]
            out = carve_block(b, cav, wall, cut)
            if len(out) != 1 or out[0] is not b:
                repl[int(i)] = out
        pool.replace(repl)


def _disc_list(scene, spec):
    """(name, centre, unit normal, radius, thickness) of every disc and DFN fracture that cuts."""
    chosen = None if spec.cut_by is None else set(spec.cut_by)
    out = [(d.name, d.centre, d.normal, d.radius, d.thickness) for d in scene.discontinuities
           if chosen is None or d.name in chosen]
    net = network_for(scene)
    if net is not None:
        for k in range(len(net)):
            if chosen is None or net.set_names[net.set_index[k]] in chosen:
                out.append((net.ids[k], net.centres[k], net.normals[k], float(net.radii[k]), float(net.thickness[k])))
    return out


def _disc_box(c, n, r, t):
    ext = r * np.sqrt(np.clip(1.0 - n * n, 0.0, 1.0)) + t / 2 * np.abs(n)
    return c - ext, c + ext


def _discs(pool, scene, spec, sources, stats, dlo, dhi):
    discs = _disc_list(scene, spec)
    if not discs:
        return
    grid = _Grid(pool, dlo, dhi)  # a disc finds the blocks it may reach by the grid's cells, not a scan of all
    for name, c, n, r, t in discs:
        c, n = np.asarray(c, float), np.asarray(n, float)
        kind = FAULT if t > 0 else JOINT
        lo, hi = _disc_box(c, n, r, t)
        basis = plane_basis(n)
        for off in ((-t / 2, t / 2) if t > 0 else (0.0,)):
            cc = c + off * n
            sources.append(Source(name, kind, "disc", centre=cc, normal=n, radius=r))
            repl = _cut_plane(grid, n, float(n @ cc), len(sources) - 1, spec.min_volume, stats, lo, hi,
                              lambda b, s, cc=cc: disc_reaches(b, cc, n, r, basis, s))
            stats["disc_cuts"] = stats.get("disc_cuts", 0) + len(repl)
        if t > 0:
            _fault_material(grid, c, n, r, t, name, lo, hi)
    grid.to_pool(pool)


def _fault_material(pool, c, n, r, t, name, lo, hi):
    for i in pool.near(lo, hi).tolist():
        b = pool.blocks[i]
        s = b.v @ n - n @ c
        if s.min() < -t / 2 - REL * b.diag() or s.max() > t / 2 + REL * b.diag():
            continue
        g = b.volume_centroid()[1] - c
        if np.linalg.norm(g - (g @ n) * n) <= r:
            b.material = name


def _surface_discontinuities(pool, scene, spec, sources, stats):
    chosen = None if spec.cut_by is None else set(spec.cut_by)
    for sd in getattr(scene, "surfaces", []):
        if chosen is not None and sd.name not in chosen:
            continue
        kind = FAULT if sd.thickness > 0 else JOINT
        for tri in sd.mesh.vertices[sd.mesh.faces]:
            nrm = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            ln = float(np.linalg.norm(nrm))
            if ln == 0:
                continue
            n = nrm / ln
            sources.append(Source(sd.name, kind, "triangle", normal=n, tri=tri.copy()))
            repl = _cut_plane(pool, n, float(n @ tri[0]), len(sources) - 1, spec.min_volume, stats,
                              tri.min(0), tri.max(0), lambda b, s, tri=tri: triangle_reaches(b, tri))
            stats["facet_cuts"] = stats.get("facet_cuts", 0) + len(repl)


def _hull_block(a, b, na, da):
    """The union of blocks a (face planes na, da) and b as one TBlock when it is convex, each face taking the
    source of the face of a or b on its plane; None otherwise."""
    nb, db = face_planes(b)
    eps = 1e-7 * max(a.diag(), b.diag())
    shared = (na @ nb.T < -1 + 1e-9) & (np.abs(da[:, None] + db[None, :]) <= eps)
    if not shared.any():
        return None
    # a and b on either side of a shared plane: their union is convex exactly when each lies inside the other's
    # remaining face planes (the union is then the intersection of those planes)
    ia, ib = (int(x[0]) for x in np.nonzero(shared))
    oa, ob = np.arange(len(na)) != ia, np.arange(len(nb)) != ib
    if (b.v @ na[oa].T - da[oa] > eps).any() or (a.v @ nb[ob].T - db[ob] > eps).any():
        return None
    lo, hi = np.minimum(a.v.min(0), b.v.min(0)), np.maximum(a.v.max(0), b.v.max(0))
    box = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    h = TBlock(box, [list(f) for f in BOX_FACES], [-1] * 6, a.material if a.volume() >= b.volume() else b.material)
    for n, d, src in ((na[oa], da[oa], a.src[oa]), (nb[ob], db[ob], b.src[ob])):
        for k in range(len(n)):
            h = split(h, n[k], d[k], src[k])[0]
    va, vb = a.volume(), b.volume()
    if abs(h.volume() - va - vb) > 1e-9 * (va + vb):
        return None
    hn, hd = face_planes(h)
    for k in np.nonzero(h.src < 0)[0]:  # box faces on a face plane of a or b: that face's source
        for n, d, src in ((na, da, a.src), (nb, db, b.src)):
            hit = np.nonzero((n @ hn[k] > 1 - 1e-9) & (np.abs(d - hd[k]) <= eps))[0]
            if len(hit):
                h.src[k] = src[hit[0]]
                break
        else:
            return None
    return h


def _joined_by_rock(block, k, sources):
    """True when face k of the block is intact rock throughout: an intact split, or a disc's (triangle's) face
    that lies wholly outside its disc (triangle)."""
    return bool((kinds_at(sources[block.src[k]], block.v[list(block.faces[k])]) == INTACT).all())


def _merge_slivers(pool, min_volume, stats, sources):
    """Each block below min_volume joins a neighbour across a face of intact rock (a piece of the same block of
    the joint fabric) when their union is convex (volume kept, nothing dropped); never across a joint or fault
    face, which would glue two blocks of the fabric together through the sliver's cemented faces. The others
    stay as they are (counted in summary()["small_blocks"]; a run scales their inertia, dda/georun.py)."""
    vol = np.array([b.volume() for b in pool.blocks])
    gone, merged = set(), 0
    for i in np.argsort(vol).tolist():
        if vol[i] >= min_volume or i in gone:
            continue
        eps = REL * pool.blocks[i].diag()
        near = pool.near(pool.lo[i] - eps, pool.hi[i] + eps)
        a = pool.blocks[i]
        na, da = face_planes(a)
        for j in sorted(near.tolist(), key=lambda j: -vol[j]):
            if j == i or j in gone:
                continue
            s = pool.blocks[j].v @ na.T - da  # b must lie on the far side of a face plane of a, touching it
            tol = 1e-7 * max(a.diag(), float(np.linalg.norm(pool.hi[j] - pool.lo[j])))
            touch = np.flatnonzero((s >= -tol).all(0) & ((np.abs(s) <= tol).sum(0) >= 3))
            if not any(_joined_by_rock(a, int(k), sources) for k in touch):
                continue
            h = _hull_block(a, pool.blocks[j], na, da)
            if h is not None:
                pool.blocks[j] = h
                vol[j] = h.volume()
                pool.lo[j], pool.hi[j] = h.v.min(0), h.v.max(0)
                gone.add(i)
                merged += 1
                break
    stats["slivers_merged"] = merged
    pool.replace({i: [] for i in gone})


def stage_line(stage, n, seconds):
    """One progress line of a cutting stage (``build_blocks``' progress callback arguments)."""
    return f"{stage:<13}{n} blocks  {seconds:.2f} s"


def build_blocks(scene, progress=None) -> BlockModel:
    """The block model of an sgim Scene (sgim.scene.load_scene); see the module docstring."""
    spec = scene.blocks if getattr(scene, "blocks", None) is not None else default_spec(scene)
    lo, hi = np.asarray(scene.domain.min, float), np.asarray(scene.domain.max, float)
    v = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    sources = [Source("domain", DOMAIN, "box")]
    pool = _Pool([TBlock(v, [list(f) for f in BOX_FACES], [0] * 6)])
    stats, times, walls = {}, {}, []
    stages = (("joint sets", lambda: _fabric(pool, spec, sources, lo, hi, stats)),
              ("excavation", lambda: _excavations(pool, scene, sources, stats)),
              ("cavities", lambda: _cavities(pool, scene, sources, walls)),
              ("discs", lambda: _discs(pool, scene, spec, sources, stats, lo, hi)),
              ("surfaces", lambda: _surface_discontinuities(pool, scene, spec, sources, stats)),
              ("slivers", lambda: _merge_slivers(pool, spec.min_volume, stats, sources)),
              ("cavity walls", lambda: [label_walls(pool.blocks, *w) for w in walls]))
    for name, run in stages:
        t0 = time.perf_counter()
        run()
        times[name] = time.perf_counter() - t0
        if progress is not None:
            progress(name, len(pool.blocks), times[name])
    stats["seconds"] = times
    return BlockModel(pool.blocks, sources, lo, hi, spec.min_volume, stats)


# ---------------------------------------------------------------------------------------------------------
# files (dda blocks, dda/blockout.py)


def block_mesh(model):
    """(points, triangles, cell data) of every block face of ``model``, one triangle fan per face."""
    pts, tris, cols = [], [], {k: [] for k in ("block", "face", "kind", "source", "volume", "material")}
    mats = sorted({b.material for b in model.blocks})
    base = 0
    for i, b in enumerate(model.blocks):
        t, owner = fan(b.faces)
        pts.append(b.v)
        tris.append(t + base)
        base += len(b.v)
        src = b.src[owner]
        cols["block"].append(np.full(len(t), i, np.int32))
        cols["face"].append(owner.astype(np.int32))
        cols["kind"].append(np.array([model.sources[s].kind for s in src], np.int32).reshape(-1))
        cols["source"].append(src.astype(np.int32))
        cols["volume"].append(np.full(len(t), b.volume()))
        cols["material"].append(np.full(len(t), mats.index(b.material), np.int32))
    cat = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
    return (np.vstack(pts) if pts else np.zeros((0, 3))), (np.vstack(tris) if tris else np.zeros((0, 3), int)), \
        cat, mats


def write_blocks(model, folder):
    """blocks.vtu and summary.json of ``model`` in ``folder``."""
    import meshio  # not at the top: meshio loads only when a VTU is written (it takes a while to import)

    pts, tris, data, mats = block_mesh(model)
    mesh = meshio.Mesh(pts, [("triangle", tris.astype(np.int64))], cell_data={k: [v] for k, v in data.items()})
    atomic_vtu(f"{folder}/blocks.vtu", mesh)
    summary = {"kinds": list(KINDS), **model.summary(), "materials_index": mats,
               "sources": [{"name": s.name, "kind": KINDS[s.kind], "shape": s.shape} for s in model.sources]}
    with atomic_path(f"{folder}/summary.json") as tmp, open(tmp, "w") as fh:
        json.dump(summary, fh, indent=1)
    return summary


__all__ = ["KINDS", "BlockModel", "Source", "build_blocks", "stage_line", "write_blocks"]
