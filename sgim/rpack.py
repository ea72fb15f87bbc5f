"""Random dense packings of equal and unequal spheres (``[packing] kind = "random"``).

Scene keys::

    [packing]
    kind = "random"
    radius = 0.5                 # equal spheres; or a [packing.distribution] or [packing.grading] table
    seed = 1                     # every random choice comes from this seed
    overlap = 1e-6               # largest overlap allowed, as a fraction of the smaller radius
                                 # (and largest penetration of a wall or surface, as a fraction of r)
    fill = "shape.stl"           # optional closed surface: pack the domain intersected with it

    [packing.distribution]       # unequal spheres, one of:
    law = "uniform"              #   radius uniform in [min, max]
    min = 0.5
    max = 1.0
    # law = "lognormal"          #   ln r normal with median radius `median` and standard deviation
    # median = 0.6               #   `sigma` of ln r; optional truncation to [min, max]
    # sigma = 0.25
    # law = "sieve"              #   grading curve: sphere diameters `sizes` (ascending) and the
    # sizes = [0.5, 1.0, 2.0]    #   percent `passing` by mass (non-decreasing, 0 ... 100); mass is
    # passing = [0, 40, 100]     #   spread evenly in diameter within each class

The packed region is what the scene keeps: the domain box, minus the excavation space of
every ``[[excavation]]`` surface (the exact rule: a sphere is kept when its centre is not
above the surface in vertical projection and the sphere does not reach it), minus every
``[[cavity]]``, intersected with the fill shape.

Algorithm: pocket filling, lowest pocket first (sgim/_rpack.py).  Spheres are placed one at a
time, each in the lowest *pocket* (to within the queue's bucket height: 10 % of the radius, of
the smallest grid level's largest radius for unequal spheres) where it touches three supports
(spheres, box walls, the tangent planes of the surfaces), starting from seeds on the floor of
the region.  It is a
geometric analogue of deposition: no overlaps beyond rounding, every sphere rests on three
supports, spheres rest on the floor, walls and surfaces (the packing reaches every face within
one radius; the last layer under a ceiling need not touch it), and the work follows the spheres
placed, not the domain box.  Equal spheres reach a bulk density of about 0.61, radius ratio 2 about 0.63;
the contact fabric is slightly vertical (<n_z^2> about 0.34 against 1/3 for isotropy).

Reported statistics (``pack_statistics``; in the model's ``meta["packing"]["statistics"]`` and in
``summary.json``):

* density: total sphere volume / volume of the region (``Region.volume``: exact for a box, else
  a voxel sum whose voxels near the boundary are integrated by the midpoint rule);
* coordination: 2 x pairs with |ci - cj| <= (ri + rj)(1 + gap) / spheres, gap the scene's
  ``[bonds] tolerance``;
* max overlap: largest (ri + rj - |ci - cj|) / min(ri, rj) over all pairs (0 if none);
* largest empty sphere: the largest sphere inside the region that overlaps no packed sphere.
  Its centre is a local maximum of the clearance (distance to the nearest sphere surface, box
  face or region surface).  Estimated by probing: 6 probe points per sphere, uniform in the
  shell between r and 1.8 r around its centre (drawn from a counter-based generator: the same
  points for any number of threads), scored by their clearance over the nearest sphere's
  radius, one kernel pass keeping each sphere's best; from the 1000 + n/1000 best of those, a
  steepest ascent of the clearance (direction: the point of smallest
  norm in the convex hull of the unit directions away from the nearest constraints; it stops
  at a point equidistant from four constraints, a vertex of the Voronoi diagram for equal
  spheres).  Reported: its radius, the radius relative to the local sphere radius (the radius
  of the nearest sphere, or the grading law at the centre for graded packings), its centre,
  and the largest relative value found.  A lower bound of the true value; on equal-sphere
  packings it matches the largest Delaunay circumsphere (tests/test_rpack.py).
"""
from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit, prange

from . import _excavate as EX
from . import _rpack as K
from . import _rpgrid as RG
from . import _rpprobe as PR
from . import _rpregion as RR
from . import _rpstate as ST
from .cavities import carve
from .excavate import FacetSet
from .geometry import MeshError, load_mesh_file
from .grading import Grading, NearObjects, empty_mesh_data, read_grading, scene_names
from .meshquery import MeshSet, TriMesh
from .portable import norm
from .reader import SIZE

LAWS = ("uniform", "lognormal", "sieve")
POOL = 32  # pooled radii (a law): each pocket takes the largest that fits
SHELL = 1.8  # largest-empty-sphere probes lie in the shell r .. SHELL r around each sphere


# ---------------------------------------------------------------------------
# radius laws

@dataclass
class RadiusLaw:
    """Distribution of the radius (by number of spheres)."""

    law: str  # "constant", "uniform", "lognormal", "sieve"
    params: dict

    @property
    def bounds(self):
        p = self.params
        if self.law == "constant":
            return p["radius"], p["radius"]
        if self.law == "uniform":
            return p["min"], p["max"]
        if self.law == "lognormal":
            lo = p.get("min") or p["median"] * math.exp(-6.0 * p["sigma"])
            hi = p.get("max") or p["median"] * math.exp(6.0 * p["sigma"])
            return lo, hi
        s = np.asarray(p["sizes"], float)
        q = np.asarray(p["passing"], float)
        first = int(np.nonzero(q > 0)[0][0])  # the first class with mass
        return float(s[max(first - 1, 0)]) / 2.0, float(s[-1]) / 2.0

    def sample(self, rng, n):
        """n radii (prefix-consistent: a longer draw from the same generator state extends a shorter one)."""
        p = self.params
        if self.law == "constant":
            return np.full(n, p["radius"])
        if self.law == "uniform":
            return p["min"] + (p["max"] - p["min"]) * rng.random(n)
        if self.law == "lognormal":
            from scipy.special import ndtr, ndtri  # scipy loaded only for a lognormal law (start-up time)

            mu, sg = math.log(p["median"]), p["sigma"]
            a = ndtr((math.log(p["min"]) - mu) / sg) if p.get("min") else 0.0
            b = ndtr((math.log(p["max"]) - mu) / sg) if p.get("max") else 1.0
            u = a + (b - a) * rng.random(n)
            u = np.clip(u, 1e-300, 1.0 - 1e-16)
            r = np.exp(mu + sg * ndtri(u))
            if p.get("min"):
                r = np.maximum(r, p["min"])
            if p.get("max"):
                r = np.minimum(r, p["max"])
            return r
        # sieve: class by number weight, then d ~ d^-3 within the class (mass even in d)
        s = np.asarray(p["sizes"], float)
        q = np.asarray(p["passing"], float) / 100.0
        a, b = s[:-1], s[1:]
        dm = np.diff(q)
        w = dm * (a ** -2 - b ** -2) / (2.0 * (b - a))
        cw = np.cumsum(w) / w.sum()
        u = rng.random((n, 2))
        k = np.minimum(np.searchsorted(cw, u[:, 0], side="right"), len(w) - 1)
        ia, ib = a[k] ** -2, b[k] ** -2
        d = (ia - u[:, 1] * (ia - ib)) ** -0.5
        return d / 2.0

    def mean_volume(self):
        r = self.sample(np.random.default_rng(12345), 200_000)
        return float(np.mean(4.0 / 3.0 * np.pi * r ** 3))

    def meta(self):
        return {"law": self.law, **{k: (list(v) if isinstance(v, (list, tuple)) else v) for k, v in self.params.items()}}


@dataclass
class RandomSpec:
    """The random-packing part of a scene's [packing] table."""

    seed: int = 0
    overlap: float = 1e-6
    law: RadiusLaw = None  # equal spheres: law "constant"
    grading: Grading = None
    fill: object = None  # sgim.meshquery.TriMesh (closed) or None
    fill_name: str = ""

    @property
    def rmin(self):
        return self.grading.rmin if self.grading else self.law.bounds[0]

    @property
    def rmax(self):
        return self.grading.rmax if self.grading else self.law.bounds[1]

    def meta(self):
        out = {"seed": self.seed, "overlap_tolerance": self.overlap}
        if self.grading:
            out["grading"] = self.grading.meta()
        else:
            out["distribution"] = self.law.meta()
        if self.fill is not None:
            out["fill"] = self.fill_name
        return out


def check_scene(rd, scene):
    """Checks that need the whole scene: grading names."""
    spec = scene.packing.random
    if spec.grading is not None:
        names = scene_names(scene.excavations, getattr(scene, "cavities", []), scene.discontinuities,
                            getattr(scene, "surfaces", []))
        for nm in spec.grading.near:
            if nm not in names:
                known = ", ".join(sorted(names)) or "none"
                rd.err("packing.grading.near", nm, f"no excavation surface, cavity or discontinuity has this name "
                                                   f"(known: {known})")


def read_random(rd, pk, domain, scene_path):
    """Parse the random-packing keys of [packing] (kind = "random").  Returns (RandomSpec, rmax)."""
    rd.known(pk, {"kind", "radius", "seed", "overlap", "fill", "distribution", "grading"}, "packing")
    seed = rd.number(pk, "seed", "packing.seed", default=0, nonneg=True)
    if not float(seed).is_integer() or isinstance(pk.get("seed"), float):
        rd.err("packing.seed", pk.get("seed"), "must be a non-negative integer")
    overlap = rd.number(pk, "overlap", "packing.overlap", default=1e-6, positive=True, hi=0.1)
    forms = [f for f in ("radius", "distribution", "grading") if f in pk]
    if len(forms) != 1:
        rd.err("packing", sorted(pk), "random packing needs exactly one of: radius, [packing.distribution], "
                                      "[packing.grading]")
    spec = RandomSpec(seed=int(seed), overlap=overlap)
    if forms[0] == "radius":
        r = rd.number(pk, "radius", "packing.radius", positive=True, **SIZE)
        spec.law = RadiusLaw("constant", {"radius": r})
    elif forms[0] == "distribution":
        spec.law = _read_law(rd, rd.table(pk, "distribution", "packing.distribution"))
    else:
        spec.grading = read_grading(rd, rd.table(pk, "grading", "packing.grading"), "packing.grading")
    rmax = spec.rmax
    if 2 * rmax > float(np.min(domain.max - domain.min)):
        rd.err("packing", rmax, f"spheres of diameter {2 * rmax:g} do not fit in the domain")
    if "fill" in pk:
        fname = rd.string(pk, "fill", "packing.fill", "")
        fpath = Path(fname)
        if not fpath.is_absolute():
            fpath = Path(scene_path).parent / fpath
        try:
            v, f = load_mesh_file(fpath)
            mesh = TriMesh(v, f)
        except MeshError as exc:
            rd.err("packing.fill", fname, exc.message)
        except ValueError as exc:
            rd.err("packing.fill", fname, str(exc))
        if not mesh.nearly_closed():
            rd.err("packing.fill", fname, f"the fill surface is not closed ({len(mesh.boundary_edges)} boundary "
                                          f"edges): a fill shape must enclose a volume")
        if np.any(mesh.hi < domain.min) or np.any(mesh.lo > domain.max):
            rd.err("packing.fill", fname, "the fill surface lies entirely outside the domain box")
        spec.fill, spec.fill_name = mesh, fname
    return spec, rmax


def _read_law(rd, dt):
    key = "packing.distribution"
    law = rd.choice(dt, "law", f"{key}.law", LAWS, None)
    if law == "uniform":
        rd.known(dt, {"law", "min", "max"}, key)
        lo = rd.number(dt, "min", f"{key}.min", positive=True, **SIZE)
        hi = rd.number(dt, "max", f"{key}.max", positive=True, **SIZE)
        if hi < lo:
            rd.err(f"{key}.max", hi, f"must be >= min = {lo:g}")
        _ratio(rd, f"{key}.max", hi, lo)
        return RadiusLaw("uniform", {"min": lo, "max": hi})
    if law == "lognormal":
        rd.known(dt, {"law", "median", "sigma", "min", "max"}, key)
        med = rd.number(dt, "median", f"{key}.median", positive=True, **SIZE)
        sg = rd.number(dt, "sigma", f"{key}.sigma", positive=True, hi=2.0)
        p = {"median": med, "sigma": sg}
        if "min" in dt:
            p["min"] = rd.number(dt, "min", f"{key}.min", positive=True, **SIZE)
        if "max" in dt:
            p["max"] = rd.number(dt, "max", f"{key}.max", positive=True, **SIZE)
        if "min" in p and "max" in p and p["max"] <= p["min"]:
            rd.err(f"{key}.max", p["max"], f"must exceed min = {p['min']:g}")
        lo = p.get("min", med * math.exp(-6 * sg))
        hi = p.get("max", med * math.exp(6 * sg))
        if "min" in p and p["min"] >= med * math.exp(8 * sg) or "max" in p and p["max"] <= med * math.exp(-8 * sg):
            rd.err(key, [p.get("min"), p.get("max")], "the truncation leaves no probability mass")
        _ratio(rd, key, hi, lo, "the law spans more than a factor 64 in radius: give min and max")
        return RadiusLaw("lognormal", p)
    rd.known(dt, {"law", "sizes", "passing"}, key)
    for name in ("sizes", "passing"):
        v = dt.get(name)
        if not isinstance(v, list) or len(v) < 2:
            rd.err(f"{key}.{name}", v, "must be a list of at least two numbers")
    sizes = [rd.check_number(x, f"{key}.sizes[{i}]", positive=True, **SIZE) for i, x in enumerate(dt["sizes"])]
    passing = [rd.check_number(x, f"{key}.passing[{i}]", lo=0.0, hi=100.0) for i, x in enumerate(dt["passing"])]
    if len(sizes) != len(passing):
        rd.err(f"{key}.passing", dt["passing"], f"needs one value per size ({len(sizes)})")
    for i in range(1, len(sizes)):
        if sizes[i] <= sizes[i - 1]:
            rd.err(f"{key}.sizes[{i}]", sizes[i], f"sizes must increase (previous {sizes[i - 1]:g})")
        if passing[i] < passing[i - 1]:
            rd.err(f"{key}.passing[{i}]", passing[i], f"percent passing must not decrease (previous "
                                                      f"{passing[i - 1]:g}): the sieve curve is not monotone")
    if passing[0] != 0.0:
        rd.err(f"{key}.passing[0]", passing[0], "must be 0 (no mass below the smallest size)")
    if passing[-1] != 100.0:
        rd.err(f"{key}.passing[{len(passing) - 1}]", passing[-1], "must be 100 (all mass below the largest size)")
    law = RadiusLaw("sieve", {"sizes": sizes, "passing": passing})
    lo, hi = law.bounds
    _ratio(rd, f"{key}.sizes", hi, lo)
    return law


def _ratio(rd, key, hi, lo, msg=None):
    if hi > 64 * lo:
        rd.err(key, hi, msg or f"radius range wider than a factor 64 ({lo:g} .. {hi:g})")


# ---------------------------------------------------------------------------
# the region

class Region:
    """The part of the domain a scene keeps, for the packer and for tests.

    ``constraint`` meshes bound the region (excavation surfaces, cavities, the fill shape);
    ``excavation`` holds the exact rule's "above" test.
    """

    def __init__(self, lo, hi, excavations=(), cavities=(), fill=None):
        self.lo = np.asarray(lo, float)
        self.hi = np.asarray(hi, float)
        self.exc_meshes = [TriMesh(s.vertices, s.faces, orient=False) for s in excavations]
        self.cavities = list(cavities)
        self.fill = fill
        meshes = self.exc_meshes + self.cavities + ([fill] if fill is not None else [])
        self.n_meshes = len(meshes)
        self.Dc = MeshSet(meshes).kernel_data() if meshes else empty_mesh_data()
        if excavations:
            exact = [type(s)(s.name, s.vertices, s.faces, "exact", s.key) for s in excavations]
            fs = FacetSet(exact)
            span = float(np.max(self.hi - self.lo))
            sizes = np.maximum(fs.fb[:, 1] - fs.fb[:, 0], fs.fb[:, 3] - fs.fb[:, 2])
            gs = max(float(np.median(sizes)), span / 2000.0)
            gnx = int((self.hi[0] - self.lo[0]) / gs) + 1
            gny = int((self.hi[1] - self.lo[1]) / gs) + 1
            cst, cfa = EX.bin_facets(fs.fb, self.lo[0], self.lo[1], gs, gnx, gny, 1e-9 * span)
            self.exc = RR.Exc(fs.ec, cst, cfa, float(self.lo[0]), float(self.lo[1]), float(gs), int(gnx), int(gny))
        else:
            self.exc = _NO_EXC

    def bounds(self):
        """Box of the region: the domain, cut to the fill shape's bounding box."""
        if self.fill is None:
            return self.lo, self.hi
        return np.maximum(self.lo, self.fill.lo), np.minimum(self.hi, self.fill.hi)

    @classmethod
    def from_scene(cls, scene, fill=None):
        return cls(scene.domain.min, scene.domain.max, scene.excavations,
                   [c.mesh for c in getattr(scene, "cavities", [])], fill)

    def admissible(self, pts, r, tol=0.0):
        """Centres where a sphere of radius r (scalar or per point) lies in the region."""
        pts = np.ascontiguousarray(np.asarray(pts, float).reshape(-1, 3))
        r = np.broadcast_to(np.asarray(r, float), (len(pts),))
        ok = np.all((pts >= self.lo + r[:, None] * (1 - tol)) & (pts <= self.hi - r[:, None] * (1 - tol)), axis=1)
        if self.exc[6] > 0:
            ok &= ~_above_many(self.exc, pts)
        for m in self.exc_meshes:
            d = m.closest(pts, max_dist=float(r.max()))[0]
            ok &= ~(d < r * (1 - tol))
        for m in self.cavities:
            ok &= ~m.overlaps(pts, r * (1 - tol))
        if self.fill is not None:
            d = self.fill.closest(pts, max_dist=float(r.max()))[0]
            ok &= ~(d < r * (1 - tol)) & self.fill.inside(pts)
        return ok

    def contains(self, pts):
        return self.admissible(pts, 0.0)

    def volume(self, h=None, sub=4):
        """Volume of the region: exact for a box, otherwise a voxel sum (size h) whose voxels near the
        boundary are integrated by the midpoint rule on sub^3 points (kept once computed)."""
        if h is None and getattr(self, "_volume", None) is not None:
            return self._volume
        lo, hi = self.bounds()
        ext = hi - lo
        if self.n_meshes == 0:
            return float(np.prod(ext))
        if h is None:
            h = float((np.prod(ext) / 2e5) ** (1 / 3))
            self._volume = self.volume(h, sub)
            return self._volume
        n = np.maximum(np.ceil(ext / h).astype(int), 1)
        hs = ext / n
        g = [lo[a] + hs[a] * (np.arange(n[a]) + 0.5) for a in range(3)]
        cen = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 3)
        half = 0.5 * norm(hs)
        ins = self.contains(cen)
        near = self._near_boundary(cen, half)
        vol = float((ins & ~near).sum()) * float(np.prod(hs))
        idx = np.nonzero(near)[0]
        off = (np.arange(sub) + 0.5) / sub - 0.5
        so = np.stack(np.meshgrid(off, off, off, indexing="ij"), -1).reshape(-1, 3) * hs
        for s in range(0, len(idx), 20000):
            blk = cen[idx[s:s + 20000]]
            pts = (blk[:, None, :] + so[None]).reshape(-1, 3)
            vol += float(self.contains(pts).sum()) * float(np.prod(hs)) / len(so)
        return vol

    def _near_boundary(self, pts, dist):
        """Points within dist of a constraint surface (box faces included)."""
        near = np.any((pts - self.lo < dist) | (self.hi - pts < dist), axis=1)
        for m in self.exc_meshes + self.cavities + ([self.fill] if self.fill is not None else []):
            near |= np.isfinite(m.closest(pts, max_dist=dist)[0])
        if self.exc[6] > 0:
            # vertical walls of the excavated prisms (the surface's plan boundary)
            for dx, dy in ((dist, 0), (-dist, 0), (0, dist), (0, -dist)):
                q = pts + np.array([dx, dy, 0.0])
                near |= _above_many(self.exc, q) != _above_many(self.exc, pts)
        return near


_NO_EXC = RR.Exc(np.zeros((1, 12)), np.zeros(2, np.int64), np.zeros(0, np.int64), 0.0, 0.0, 1.0, 0, 0)


def _above_many(exc, pts):
    return _above_kernel(exc, np.ascontiguousarray(pts))


@njit(cache=True, parallel=True)
def _above_kernel(exc, pts):
    out = np.zeros(pts.shape[0], np.bool_)
    for i in prange(pts.shape[0]):
        out[i] = RR.above_excavation(exc, pts[i, 0], pts[i, 1], pts[i, 2])
    return out


# ---------------------------------------------------------------------------
# grid geometry (multi-level)

def level_grid(lo, hi, rmin, rmax, max_cells=48_000_000):
    """Levels of radii [rmin 2^k, rmin 2^(k+1)) (the last one up to rmax), cell = 2 x level's largest radius."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    nl = max(1, int(math.ceil(math.log2(rmax / rmin) - 1e-9)))
    rlo = rmin * 2.0 ** np.arange(nl)
    rlo[0] = 0.0
    rtop = np.minimum(rmin * 2.0 ** (np.arange(nl) + 1), rmax)
    rtop[-1] = rmax
    ext = hi - lo
    pad = 2.0 * rmax
    org = np.tile(lo - pad, (nl, 1))
    cs = 2.0 * rtop
    dims = np.empty((nl, 3), np.int64)
    for k in range(nl):
        while True:
            d = np.floor((ext + 2 * pad) / cs[k]).astype(np.int64) + 1
            if np.prod(d) <= max_cells:
                break
            cs[k] *= 1.25
        dims[k] = d
    coff = np.zeros(nl + 1, np.int64)
    coff[1:] = np.cumsum(np.prod(dims, axis=1))
    bdims = (dims + RG.BLOCK - 1) // RG.BLOCK
    boff = np.zeros(nl + 1, np.int64)
    boff[1:] = np.cumsum(np.prod(bdims, axis=1))
    return RG.Grid(org, cs, dims, coff, rlo, rtop.astype(float), bdims, boff)


# ---------------------------------------------------------------------------
# seeds

def floor_seeds(region, rng, radius_at, rtyp, count=None, graded=False):
    """Seed centres on the floor of the region: random plan positions (about one per (4 r)^2 of
    floor, r the local typical radius, so that few seeds overlap and the seeds' radii are not
    sifted), each at the lowest height where a sphere fits (scanned upward in steps of its
    radius, then bisected): seeds rest on the domain's bottom or on the lowest surface of the
    region in their column.  The pockets between them fill the rest of the floor.  With a fill
    shape, only its footprint is seeded and the scan starts at its bottom."""
    lo, hi = region.bounds()
    area = float((hi[0] - lo[0]) * (hi[1] - lo[1]))
    if count is None:
        count = int(min(max(area / (16.0 * rtyp * rtyp), 16), 4_000_000))
    xy = lo[:2] + rng.random((count, 2)) * (hi[:2] - lo[:2])
    r = radius_at(np.column_stack([xy, np.full(count, lo[2])]))
    keep = rng.random(count) < (rtyp / r) ** 2  # thinning where the radius is larger (graded)
    xy, r = xy[keep], r[keep]
    z = _lowest(region, xy, r)
    for _ in range(40 if graded else 0):  # a radius that depends on position: fixed point r = r(centre)
        ok = np.isfinite(z)
        if not ok.any():
            break
        r2 = r.copy()
        r2[ok] = radius_at(np.column_stack([xy[ok], z[ok]]))
        moved = ok & (np.abs(r2 - r) > 1e-13 * r)
        if not moved.any():
            break
        r[moved] = r2[moved]
        z[moved] = _lowest(region, xy[moved], r[moved])
    keep = np.isfinite(z)
    return np.column_stack([xy[keep], z[keep]]), r[keep]


def _lowest(region, xy, r):
    """Lowest admissible centre height for spheres of radius r above plan points xy (nan: none)."""
    lo, hi = region.bounds()
    count = len(r)
    xy = np.clip(xy, lo[:2] + r[:, None], hi[:2] - r[:, None])
    z = np.full(count, np.nan)
    zc = lo[2] + r
    todo = np.arange(count)
    below = np.full(count, lo[2])
    while len(todo):
        pts = np.column_stack([xy[todo], zc[todo]])
        ok = region.admissible(pts, r[todo])
        z[todo[ok]] = zc[todo[ok]]
        rest = todo[~ok]
        below[rest] = zc[rest]
        zc[rest] += r[rest]
        todo = rest[zc[rest] <= hi[2] - r[rest]]
    found = np.isfinite(z)
    # bisect between the last height that failed and the first that fitted
    a = np.maximum(below, lo[2] + r)
    b = z.copy()
    redo = found & (b > a)
    for _ in range(60):
        idx = np.nonzero(redo)[0]
        if not len(idx):
            break
        m = 0.5 * (a[idx] + b[idx])
        ok = region.admissible(np.column_stack([xy[idx], m]), r[idx])
        b[idx[ok]] = m[ok]
        a[idx[~ok]] = m[~ok]
        redo[idx[(b[idx] - a[idx]) <= 1e-12 * (r[idx] + np.abs(b[idx]))]] = False
    return np.where(found, b, np.nan)


# ---------------------------------------------------------------------------
# the packer

def _throttled(progress, t0, every=5.0):
    """Progress callback for the kernel: one line at most every few seconds."""
    last = [time.perf_counter()]

    def cb(placed, pending):
        now = time.perf_counter()
        if now - last[0] >= every:
            last[0] = now
            progress(f"rpack: {placed} spheres placed, {pending} pockets pending ({now - t0:.0f} s)")
    return cb


def _zones(region, G, mode, tol, X0, seeds):
    """Zones for a parallel packing (see sgim/_rpstate.py, zone_of), or None where one zone is used:
    a radius law or a grading, spheres given beforehand, or a region too narrow to cut.

    A sphere of radius r placed in half A, at least w from the cut, reads the grid cells (size c)
    within 4 r of its centre, removes or relinks pockets within 6 r of it, puts new ones within
    2 r and counts itself in its block of cells (4 c).  With w >= 6 r, 2 w - 4 r > c and 2 w > 4 c
    none of it reaches a cell, block or pocket that B touches; w has a margin of 2 r.
    Returns (ZG, zone sphere room, zone pocket room)."""
    if mode != 0 or len(X0):
        return None
    r = float(G.rmax[0])  # one grid level, its largest radius: the radius
    c = float(G.cs[0])
    ext = region.hi - region.lo
    axis = 0 if ext[0] >= ext[1] else 1
    w = max(6.0 * r, 2.0 * r + 0.5 * c, 2.0 * c) + 2.0 * r
    if ext[axis] < 6.0 * w:
        return None
    cut = 0.5 * (region.lo[axis] + region.hi[axis])
    zlo, zhi = region.lo[axis], region.hi[axis]
    spans = [(zlo, cut - w), (cut + w, zhi), (cut - w, cut), (cut, cut + w)]
    other = ext[1 - axis] + 2.0 * r
    rho = 0.7405 / (4.0 / 3.0 * np.pi * (r * (1.0 - tol)) ** 3)  # no packing is denser (Kepler, Hales)
    zcap, zccap = np.zeros(4, np.int64), np.zeros(4, np.int64)
    ax_seed = seeds[:, axis]
    for k, (a, b) in enumerate(spans):
        vol = (b - a + 2.0 * r) * other * (ext[2] + 2.0 * r)
        zcap[k] = int(1.1 * rho * vol) + 1024
        nseed = int(np.count_nonzero((ax_seed >= a) & (ax_seed < b)))
        zccap[k] = int(64.0 * (b - a + 2.0 * r) * other / r ** 2) + 4 * nseed + 65536
    ZG = np.array([1.0, float(axis), cut, w])
    return ZG, zcap, zccap


def _pack_kernel(args, seeds, seed_r, X0, R0, cap0, zones, report):
    """Run the pocket filler (sgim/_rpack.py): one zone in one thread, or the zones of a parallel
    packing band by band (one queue bucket, 0.1 r, high: the order of the one-zone packing up to
    the order within a bucket), A and B in two threads, then the strip.  Returns (X, R, Dist,
    counters)."""
    if zones is None:
        ZG, zcap, zccap = np.zeros(4), np.zeros(4, np.int64), np.zeros(4, np.int64)
    else:
        ZG, zcap, zccap = zones
    S, C, head, bcnt, Q, n_initial, W0, W1 = ST.pack_init(args, POOL, seeds, seed_r, X0, R0, cap0, ZG, zcap, zccap)
    ZS, bhead, CNT = Q.ZS, Q.bhead, Q.CNT

    def run(z0, z1, bz, budget, grow, W):
        return K.fill(z0, z1, bz, budget, grow, args, S, C, head, bcnt, Q, W)

    if CNT[0, 8]:  # the seeds do not fit
        pass
    elif zones is None:
        while True:
            status, S, C = run(0, 0, bhead.shape[1], 50000, True, W0)  # fill may grow S and C
            if status == ST.ST_DONE:
                break
            if report:
                report(int(ZS[:, ST.ZSN].sum()), int(ZS[:, ST.ZHN].sum()))
    else:
        with ThreadPoolExecutor(1) as pool_b:
            while True:
                lowest = ST.lowest_bucket(ZS, bhead)
                if lowest < 0:
                    break
                bz = lowest + 1
                fb = pool_b.submit(run, 1, 1, bz, 1 << 62, False, W1)
                sa = run(0, 0, bz, 1 << 62, False, W0)[0]
                sb = fb.result()[0]
                ss = run(2, 3, bz, 1 << 62, False, W0)[0]
                if ST.ST_FULL in (sa, sb, ss):
                    CNT[0, 8] = 1
                    break
                if report:
                    report(int(ZS[:, ST.ZSN].sum()), int(ZS[:, ST.ZHN].sum()))
    return ST.pack_finish(S, Q, n_initial)


@dataclass
class PackResult:
    centres: np.ndarray
    radii: np.ndarray
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)


def pack_region(region, spec, near=None, progress=None, cap=None, extra_seeds=None, X0=None, R0=None, parallel=True):
    """Pack the region; returns PackResult (statistics are added by pack_statistics).

    With X0, R0 the spheres already there are kept and only extra_seeds start new growth.  With
    parallel, a constant radius in a region wide enough is packed in zones, two at a time (see
    _zones); the result depends on the zones, not on the number of threads."""
    t0 = time.perf_counter()
    s_seed, s_rad, s_fac = np.random.SeedSequence(spec.seed).spawn(3)
    rng_seed, rng_rad, rng_fac = (np.random.default_rng(s) for s in (s_seed, s_rad, s_fac))
    tol = float(spec.overlap)
    rmin, rmax = spec.rmin, spec.rmax
    G = level_grid(region.lo, region.hi, rmin, rmax)
    vol_box = float(np.prod(region.hi - region.lo))
    empty_discs = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    if spec.grading is not None:
        gr = spec.grading
        mode, rconst = 2, 0.0
        Dg, goff, discs = near.D, near.goff, near.discs
        grade = gr.params()

        def radius_at(p):
            return gr.radius(near.distance(p, gr.coarse_distance))
        rseq = np.zeros(1)
        fseq = rng_fac.uniform(1.0 - gr.spread, 1.0 + gr.spread, 1 << 16) if gr.spread > 0 else np.ones(1)
    else:
        law = spec.law
        Dg, goff, discs, grade = empty_mesh_data(), np.zeros(0), empty_discs, (1.0, 1.0, 0.0, 1.0, 0.0)
        fseq = np.ones(1)
        if law.law == "constant":
            mode, rconst = 0, float(law.params["radius"])
            rseq = np.zeros(1)

            def radius_at(p):
                return np.full(len(p), rconst)
        else:
            mode, rconst = 1, 0.0
            n_est = int(0.68 * region.volume() / law.mean_volume()) + 1000
            rseq = law.sample(rng_rad, n_est)

            def radius_at(p):  # seeds: their own draws from the law
                return law.sample(rng_seed, len(p))
    if X0 is None:
        rtyp = rmin if spec.grading is not None else float(np.median(spec.law.sample(np.random.default_rng(0), 4001)))
        seeds, seed_r = floor_seeds(region, rng_seed, radius_at, rtyp, graded=spec.grading is not None)
        X0, R0 = np.zeros((0, 3)), np.zeros(0)
    else:
        seeds = np.asarray(extra_seeds, float).reshape(-1, 3)
        seed_r = radius_at(seeds)
        X0, R0 = np.ascontiguousarray(X0, dtype=float), np.ascontiguousarray(R0, dtype=float)
    t_seed = time.perf_counter() - t0
    if progress:
        progress(f"rpack: {len(seeds)} seeds on the floor of the region ({t_seed:.2f} s)")
    cap0 = cap or int(min(0.7 * vol_box / (4.0 / 3.0 * np.pi * rmin ** 3) + 1024, 4_000_000))
    report = _throttled(progress, t0) if progress else None
    zones = _zones(region, G, mode, tol, X0, seeds) if parallel else None
    while True:
        args = ST.PackArgs(region.lo, region.hi, tol, G, region.Dc, region.exc, mode, rconst, rseq, grade, Dg, goff,
                           discs, fseq)
        X, R, DG, cnt = _pack_kernel(args, seeds, seed_r, X0, R0, cap0, zones, report)
        if cnt[8]:  # a zone ran out of room (never seen): pack in one zone
            zones = None
            continue
        if mode == 1 and cnt[6] < POOL and len(rseq) >= POOL:
            # the radius sequence ran out before the region was full: draw a longer one (same prefix)
            rseq = law.sample(np.random.default_rng(s_rad), 2 * len(rseq))
            continue
        break
    t_pack = time.perf_counter() - t0 - t_seed
    counters = {"pockets_pushed": int(cnt[2]), "pops": int(cnt[0]), "pop_rejects": int(cnt[3]),
                "seeds_placed": int(cnt[4]), "seeds": int(len(seeds)),
                "pockets_covered": int(cnt[7]), "zones": 1 if zones is None else 4}
    if mode == 1:
        counters["radii_left_in_pool"] = int(cnt[6])
    res = PackResult(X, R, {"counters": counters}, {"seeds": t_seed, "pack": t_pack})
    if progress:
        progress(f"rpack: {len(X)} spheres placed in {t_pack:.2f} s ({len(X) / max(t_pack, 1e-9):,.0f} spheres/s)")
    return res


# ---------------------------------------------------------------------------
# statistics

def sphere_grid(X, R, lo, hi):
    """Static multi-level grid over finished spheres: (G, head, nxt, bcnt)."""
    rmin, rmax = (float(R.min()), float(R.max())) if len(R) else (1.0, 1.0)
    G = level_grid(lo, hi, rmin, rmax)
    head, nxt, bcnt = RG.grid_build(np.ascontiguousarray(X), np.ascontiguousarray(R), G)
    return G, head, nxt, bcnt


def contact_pairs(X, R, tol, lo=None, hi=None, grid=None):
    """Every pair with |ci - cj| <= (ri + rj)(1 + tol), i < j, sorted; and the row offsets (n+1,)."""
    X = np.ascontiguousarray(X, dtype=float)
    R = np.ascontiguousarray(R, dtype=float)
    if len(X) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(1, np.int64)
    if lo is None:
        lo, hi = X.min(0) - R.max(), X.max(0) + R.max()
    a = grid or sphere_grid(X, R, lo, hi)  # G, head, nxt, bcnt
    counts = RG.count_pairs(X, R, *a, float(tol))
    offsets = np.zeros(len(X) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    out = np.empty((int(offsets[-1]), 2), np.int64)
    RG.fill_pairs(X, R, *a, float(tol), offsets, out)
    return out, offsets


PROBES = 6  # clearance probes per sphere for the largest empty sphere


def largest_empty_sphere(X, R, region, grid=None, probes_per_sphere=PROBES, seed=0, local_radius=None):
    """Largest sphere in the region clear of every packed sphere (see the module docstring).

    Returns dict(radius, relative (to the nearest sphere's radius, or to local_radius(centre)),
    centre, probes, relative_max (largest clearance / local radius over the ascended probes))."""
    n = len(X)
    if n == 0:
        return {"radius": None, "relative": None, "centre": None, "probes": 0}
    a = grid or sphere_grid(X, R, region.lo, region.hi)  # G, head, nxt, bcnt
    k = probes_per_sphere
    near_s = np.zeros(n, np.uint8)
    if region.n_meshes:
        # a probe of a sphere 2 SHELL r or more from every surface is inside the region and nearer to
        # that sphere's surface than to any surface: no surface query for it
        far = (2.0 * SHELL - 1.0) * R
        near_b = np.isfinite(RR.mesh_distance_many(region.Dc, np.ascontiguousarray(X), far))
        if region.exc[6] > 0:
            near_b |= _above_many(region.exc, X + np.array([0.0, 0.0, 1.0]) * far[:, None])
        near_s = near_b.astype(np.uint8)
    role = np.array([0] * len(region.exc_meshes) + [1] * len(region.cavities) + [2] * (region.fill is not None),
                    np.int64)
    search = 4.0 * float(R.max())
    pseed = int(np.random.SeedSequence(seed).generate_state(1, np.uint64)[0] >> np.uint64(1))
    score, pts, near = PR.probe_best(X, R, *a, region.lo, region.hi, region.Dc, region.exc, role, near_s, k, pseed,
                                     SHELL, search, empty_mesh_data(), _NO_EXC)
    ok = np.nonzero(np.isfinite(score))[0]
    if len(ok) == 0:
        return {"radius": 0.0, "relative": 0.0, "centre": None, "probes": int(n * k)}
    m = min(1000 + n // 1000, len(ok))
    top = ok[np.argpartition(-score[ok], m - 1)[:m]]
    top = top[np.lexsort((top, -score[top]))]  # best first, ties by sphere
    loc = R[np.maximum(near[top], 0)]
    cl, pos, nr = PR.ascend_many(X, R, *a, region.lo, region.hi, region.Dc, region.exc,
                                 np.ascontiguousarray(pts[top]), search, loc, 200)
    rl = R[np.maximum(nr, 0)] if local_radius is None else local_radius(pos)
    rel = cl / rl
    b = int(np.argmax(cl))
    br = int(np.argmax(rel))
    return {"radius": float(cl[b]), "relative": float(cl[b] / rl[b]), "centre": pos[b].tolist(),
            "relative_max": float(rel[br]), "relative_max_centre": pos[br].tolist(),
            "probes": int(n * k), "ascended": int(len(top))}


def pack_statistics(X, R, region, volume, gap, seed=0, local_radius=None, les=True):
    """Density, coordination, overlap, boundary contacts and the largest empty sphere."""
    n = len(X)
    out = {"spheres": int(n), "region_volume": float(volume)}
    if n == 0:
        return out
    grid = sphere_grid(X, R, region.lo, region.hi)
    vs = float(np.sum(4.0 / 3.0 * np.pi * R ** 3))
    out["density"] = vs / volume
    pairs, _ = contact_pairs(X, R, gap, grid=grid)
    out["contact_gap"] = float(gap)
    out["contacts"] = int(len(pairs))
    out["coordination"] = 2.0 * len(pairs) / n
    ov = RG.overlap_stats(np.ascontiguousarray(X), np.ascontiguousarray(R), *grid)
    out["max_overlap"] = float(max(ov.max(), 0.0))
    out["radius_min"], out["radius_max"], out["radius_mean"] = float(R.min()), float(R.max()), float(R.mean())
    lo, hi = region.lo, region.hi
    ext_lo = (X - R[:, None]).min(0)
    ext_hi = (X + R[:, None]).max(0)
    out["extent"] = [ext_lo.tolist(), ext_hi.tolist()]
    out["wall_contacts"] = [int(np.sum(X[:, a] - R - lo[a] <= 1e-6 * R)) for a in range(3)] + \
                           [int(np.sum(hi[a] - X[:, a] - R <= 1e-6 * R)) for a in range(3)]
    if les:
        out["largest_empty_sphere"] = largest_empty_sphere(X, R, region, grid=grid, seed=seed,
                                                           local_radius=local_radius)
    return out


# ---------------------------------------------------------------------------
# scene -> spheres (used by sgim/builder.py)

def pack_and_measure(region, spec, near=None, gap=1e-3, local_radius=None, progress=None, rounds=3):
    """Pack, measure (pack_statistics), and seed the holes the growth did not reach.

    A hole is a local maximum of the clearance; when the largest one found holds a sphere of the
    local radius (separate parts of the region that no seed reached, or a spot between curved
    surfaces that no pocket touched), a seed is placed at its centre and the packing grows on
    from it (at most `rounds` times).  Returns (PackResult, statistics, region volume)."""
    res = pack_region(region, spec, near=near, progress=progress)
    X, R = res.centres, res.radii
    volume = region.volume()
    if progress:
        progress(f"rpack: statistics: contacts, overlaps, largest empty sphere ({PROBES * len(R)} probes)")
    stats = pack_statistics(X, R, region, volume, gap, seed=spec.seed, local_radius=local_radius)
    k = 0
    while k < rounds:
        les = stats.get("largest_empty_sphere") or {}
        if not les.get("relative_max") or les["relative_max"] <= 1.0 + 1e-6:
            break
        k += 1
        more = pack_region(region, spec, near=near, extra_seeds=np.array([les["relative_max_centre"]]), X0=X, R0=R)
        if len(more.radii) == len(R):
            break
        X, R = more.centres, more.radii
        res.timings["pack"] += more.timings["pack"]
        if progress:
            progress(f"rpack: a hole the growth did not reach, seeded: {len(R)} spheres; statistics again")
        stats = pack_statistics(X, R, region, volume, gap, seed=spec.seed, local_radius=local_radius)
    res.centres, res.radii = X, R
    stats["reseed_rounds"] = k
    return res, stats, volume


def build_random(scene, tm, region=None, near=None):
    """Pack a scene's kept region.  Returns (centres, radii, packing meta, cavity meta).  `region` / `near`:
    the Region and NearObjects of the scene when already built (sgim/limits.py builds them for its estimate)."""
    spec = scene.packing.random
    if region is None:
        region = Region.from_scene(scene, fill=spec.fill)
    if near is None and spec.grading is not None:
        near = NearObjects(scene, spec.grading)
    local = None
    if near is not None:
        gr = spec.grading

        def local(p):
            return gr.radius(near.distance(p, gr.coarse_distance))
    t0 = time.perf_counter()
    res, stats, volume = pack_and_measure(region, spec, near, scene.bonds.tolerance, local, tm.progress)
    X, R = res.centres, res.radii
    t_stats = time.perf_counter() - t0 - res.timings["pack"] - res.timings["seeds"]
    tm.lap("pack", f"{len(X)} spheres ({len(X) / max(res.timings['pack'], 1e-9):,.0f} spheres/s); statistics "
                   f"{t_stats:.2f} s")
    les = stats.get("largest_empty_sphere") or {}
    if tm.progress:
        tm.progress(f"pack stats density {stats.get('density', 0):.4f}, coordination "
                    f"{stats.get('coordination', 0):.3f} (gap {scene.bonds.tolerance:g}), max overlap "
                    f"{stats.get('max_overlap', 0):.2e}, largest empty sphere r = {les.get('radius') or 0:.4g} "
                    f"({les.get('relative_max') or 0:.3f} x the local radius)")
    X, cav_meta = _carve_check(scene, X, R, carve)
    meta = {"kind": "random", "radius": float(R.max()) if len(R) else 0.0, **spec.meta(),
            "excavation_rule": "exact (every excavation surface, for random packings)",
            "statistics": stats, "counters": res.stats.get("counters", {}),
            "timings_s": {k: round(v, 4) for k, v in res.timings.items()}}
    meta["timings_s"]["statistics"] = round(t_stats, 4)
    return X, R, meta, cav_meta


def _carve_check(scene, X, R, carve):
    """Cavity meta in the lattice path's format (no sphere may be removed: the packer keeps clear)."""
    if not getattr(scene, "cavities", None):
        return X, []
    kept, meta = carve(scene.cavities, X, R * (1.0 - scene.packing.random.overlap))  # the stated tolerance
    if len(kept) != len(X):
        raise RuntimeError(f"random packing: {len(X) - len(kept)} spheres overlap a cavity")
    return X, meta
