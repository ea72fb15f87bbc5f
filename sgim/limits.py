"""Resource estimates before work: how many spheres a build makes and how much memory it needs.

``check_build(scene)`` runs first in ``sgim.builder.build_model`` (so ``sgim build``, the in-memory builds of
``dda`` sphere scenes and ``adapters export``, and the ``cases study`` evaluators all go through it). It counts
the spheres without allocating them and refuses with one SceneError line, naming the key to change and the
numbers, when the count passes the scene's limit or the memory estimate passes the memory available now.

Sphere counts
-------------
* lattices (cubic, hexagonal, fcc): the lattice sites in the domain box, exactly as ``sgim.packing`` places
  them (``lattice_counts``: closed form, no arrays). Excavations and cavities remove sites later, so for a
  scene with them the count is an upper bound (the messages say so).
* random packings: ``DENSITY`` (0.64, above the packer's 0.60-0.63 bulk densities) x the region volume / the
  mean sphere volume x the wall factor. The region volume is exact for a box; with excavation surfaces,
  cavities or a fill shape it is the box volume times the fraction of 2^15 Sobol points of the region's
  bounding box that lie in the region. Mean sphere volume: 4/3 pi r^3 for a constant radius, the radius
  law's mean of 4/3 pi r^3 for a [packing.distribution]; for a [packing.grading] the same Sobol points give
  the mean of 1 / (4/3 pi r(d)^3) over the region, r(d) the grading law at each point (times the mean of
  f^-3 over the spread factor f), i.e. the expected number of spheres per unit volume point by point (the
  grading's smallest radius alone would count 17.8 x too many on the graded open pit). The wall factor takes
  a layer r/2 thick off each face of the box (r: the radius, the law's cube-root mean of r^3, the grading's
  fine radius): spheres against a flat wall leave about that much empty. Measured: +3 to +7 % on boxes 20 -
  40 radii across (with and without a cavity), +5.7 % on 983 011 spheres (60 x 60 x 30 m, r = 0.25), -4 % for
  a uniform law 0.06 - 0.12, +10 % on the graded open pit (4.14 M for 3.77 M packed).

Memory
------
``BYTES_PER_SPHERE`` is the peak resident memory of a whole `sgim build` (packing or lattice and excavation,
cutting, bonds, model.npz and model.vtu written; the picture does not raise the peak) above the interpreter,
per sphere, measured with /usr/bin/time -v on box scenes without excavation and rounded up by about 12 %:

=========== ===================================== =========== ================== ===========
kind        measured build                        spheres     peak RSS           bytes/sphere
=========== ===================================== =========== ================== ===========
cubic       200 x 200 x 100 m, r = 0.5, npz + vtu  4 000 000   1.16 GB (0.72 npz)  266 -> 300
fcc         200 x 200 x 100 m, r = 0.5, npz + vtu  5 597 970   1.86 GB (1.31 npz)  315 -> 350
random      60 x 60 x 30 m, r = 0.25, npz + vtu      983 011   0.45 GB (0.39 npz)  358 -> 400
=========== ===================================== =========== ================== ===========

(the interpreter with numpy, numba and sgim: 0.10 GB; a 64-sphere build with every format, the picture's
off-screen renderer included: 0.53 GB). Contacts are the largest part: 3 per sphere for cubic and random
packings, 6 for the close-packed lattices, 16 bytes of pair plus flags and cut records each; the hexagonal
lattice uses the fcc figure. A lattice adds ``BYTES_PER_COLUMN`` per lattice column (the column arrays of
the excavation kernel), and every build ``BASE_BYTES`` (0.5 GB).

Limits
------
``[limits] max_spheres`` in the scene, overridden by ``sgim build --max-spheres N``. The default is the
number of spheres whose estimated memory fills half of this machine's physical memory (MemTotal in
/proc/meminfo): ``(MemTotal / 2 - BASE_BYTES) / BYTES_PER_SPHERE[kind]`` (on this 25.3 GB machine: 40.5 M
sites of a cubic lattice, 34.7 M of a close-packed one, 30.4 M spheres of a random packing). Independently of the limit, a build whose estimated
memory exceeds the memory available now (MemAvailable) is refused.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from .common import SceneError
from .packing import lattice_counts

# Random packings only: the packer's and grading's modules (numba kernels) and scipy.stats are imported inside
# _estimate_random, so that the estimate of a lattice scene (and a refused build) stays fast.

DENSITY = 0.64  # random packings: solid fraction assumed for the estimate (packer: 0.60 - 0.63 in bulk)
BYTES_PER_SPHERE = {"cubic": 300, "hexagonal": 350, "fcc": 350, "random": 400}
BYTES_PER_COLUMN = 32  # lattices: column x, y and the kernel's per-column counts and offsets
BASE_BYTES = 500_000_000  # the interpreter with numpy and numba (0.10 GB) and the picture's renderer (0.43 GB)
SAMPLES_LOG2 = 15  # Sobol points for region volumes and graded densities


def meminfo():
    """(MemTotal, MemAvailable) in bytes from /proc/meminfo; None for what cannot be read."""
    total = avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                key, _, rest = line.partition(":")
                if key in ("MemTotal", "MemAvailable"):
                    val = int(rest.split()[0]) * 1024
                    if key == "MemTotal":
                        total = val
                    else:
                        avail = val
    except (OSError, ValueError, IndexError):
        pass
    if total is None:
        try:
            total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        except (ValueError, OSError, AttributeError):
            total = None
    return total, avail


def default_max_spheres(kind, total=None):
    """The spheres of `kind` whose estimated build memory fills half of MemTotal (at least 1000)."""
    if total is None:
        total = meminfo()[0]
    if not total:
        return 50_000_000
    return max(1000, int((0.5 * total - BASE_BYTES) / BYTES_PER_SPHERE[kind]))


def fmt_bytes(b):
    b = float(b)
    for unit, scale in (("EB", 1e18), ("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= scale:
            return f"{b / scale:.1f} {unit}" if b < 100 * scale else f"{b / scale:.3g} {unit}"
    return f"{b / 1e6:.2f} MB"


def fmt_count(n):
    """1 866 586 below a billion, 8.0e+12 above."""
    return f"{int(n):,}".replace(",", " ") if n < 1e9 else f"{float(n):.1e}"


@dataclass
class Estimate:
    kind: str
    spheres: float  # expected (random) or upper bound (lattice with excavation / cavities) or exact
    bytes: float
    what: str  # how the count was obtained, for messages
    upper_bound: bool = False
    radius_key: str = "packing.radius"
    radius_value: object = None
    region: object = None  # random packings: the sgim.rpack.Region built for the estimate (reused)
    near: object = None  # graded packings: the sgim.grading.NearObjects (reused)
    extra: dict = field(default_factory=dict)

    def line(self):
        """The progress line: `estimate   1 866 586 spheres, 0.9 GB`."""
        bound = " (at most: before excavation and cavities)" if self.upper_bound else ""
        return f"{'estimate':<10s} {fmt_count(self.spheres)} spheres{bound}, {fmt_bytes(self.bytes)}"


def estimate(scene) -> Estimate:
    """Spheres and memory of building `scene`, computed without allocating them (see the module docstring)."""
    kind = scene.packing.kind
    if kind != "random":
        sites, columns = lattice_counts(kind, scene.domain.min, scene.domain.max, scene.packing.radius)
        carved = bool(scene.excavations or getattr(scene, "cavities", None))
        nbytes = BASE_BYTES + float(sites) * BYTES_PER_SPHERE[kind] + float(columns) * BYTES_PER_COLUMN
        return Estimate(kind, float(sites), nbytes, f"the {kind} lattice of [domain] holds {fmt_count(sites)} sites",
                        upper_bound=carved, radius_key="packing.radius", radius_value=scene.packing.radius)
    return _estimate_random(scene)


def _estimate_random(scene):
    from .rpack import Region

    spec = scene.packing.random
    lo, hi = np.asarray(scene.domain.min, float), np.asarray(scene.domain.max, float)
    region = near = None
    meshes = bool(scene.excavations or getattr(scene, "cavities", None) or spec.fill is not None)
    pts = inside = None
    box = float(np.prod(hi - lo))
    if meshes or spec.grading is not None:
        from scipy.stats import qmc

        region = Region.from_scene(scene, fill=spec.fill)
        blo, bhi = region.bounds()
        box = float(np.prod(np.maximum(bhi - blo, 0.0)))
        u = qmc.Sobol(3, scramble=True, seed=0).random_base2(SAMPLES_LOG2)
        pts = blo + u * (bhi - blo)
        inside = region.contains(pts) if meshes else np.ones(len(pts), bool)
    volume = box if inside is None else box * float(inside.mean())
    blo, bhi = (lo, hi) if region is None else region.bounds()
    if spec.grading is not None:
        from .grading import NearObjects

        gr = spec.grading
        near = NearObjects(scene, gr)
        r = gr.radius(near.distance(pts[inside], gr.coarse_distance)) if inside.any() else np.zeros(0)
        s = float(gr.spread)
        fmean = ((1.0 - s) ** -2 - (1.0 + s) ** -2) / (4.0 * s) if s > 0 else 1.0  # mean of f^-3
        per_volume = float(np.sum(1.0 / (4.0 / 3.0 * math.pi * r ** 3))) / len(pts) * fmean  # over the box
        n = DENSITY * box * per_volume * _wall_factor(blo, bhi, gr.fine_radius)
        what = (f"the graded random packing of the region ({volume:.3g} m3, radius {gr.fine_radius:g} to "
                f"{gr.coarse_radius:g}) holds about {fmt_count(n)} spheres at density {DENSITY}")
        key, value = "packing.grading.fine_radius", gr.fine_radius
    else:
        law = spec.law
        if law.law == "constant":
            vmean = 4.0 / 3.0 * math.pi * law.params["radius"] ** 3
            key, value = "packing.radius", law.params["radius"]
            size = f"radius {law.params['radius']:g}"
        else:
            vmean = law.mean_volume()
            key, value = "packing.distribution", law.law
            size = f"{law.law} radii, mean sphere volume {vmean:.3g} m3"
        n = DENSITY * volume / vmean * _wall_factor(blo, bhi, (3.0 / (4.0 * math.pi) * vmean) ** (1.0 / 3.0))
        what = (f"the random packing of the region ({volume:.3g} m3, {size}) holds about {fmt_count(n)} spheres "
                f"at density {DENSITY}")
    nbytes = BASE_BYTES + n * BYTES_PER_SPHERE["random"]
    return Estimate("random", n, nbytes, what, radius_key=key, radius_value=value, region=region, near=near)


def _wall_factor(lo, hi, r):
    """The share of the box lo..hi left when a layer r / 2 thick is taken off each face: the walls' density
    deficit (spheres against a flat wall leave about that much empty; 17-20 % of a box 20 - 40 radii across
    without it, 3-5 % with it)."""
    ext = np.asarray(hi, float) - np.asarray(lo, float)
    return float(np.prod(np.clip((ext - r) / np.maximum(ext, 1e-300), 0.0, 1.0)))


def check_build(scene, max_spheres=None, progress=None, mem=None) -> Estimate:
    """Estimate the build of `scene` and refuse it (SceneError, one line) past the sphere limit or the memory
    available. `max_spheres`: the --max-spheres value (overrides the scene's [limits] max_spheres); `mem`:
    (MemTotal, MemAvailable) in bytes, for tests (default: this machine's)."""
    est = estimate(scene)
    total, avail = meminfo() if mem is None else mem
    lim = getattr(scene, "limits", None) or {}
    if max_spheres is not None:
        key, limit, origin = "--max-spheres", int(max_spheres), "--max-spheres"
    elif lim.get("max_spheres") is not None:
        key, limit, origin = "limits.max_spheres", int(lim["max_spheres"]), "the scene's"
    else:
        limit = default_max_spheres(est.kind, total)
        key = "limits.max_spheres"
        per = BYTES_PER_SPHERE[est.kind]
        origin = (f"the default: half of this machine's {fmt_bytes(total)} of memory at {per} B per sphere"
                  if total else "the default")
    bound = " (an upper bound: before excavation and cavities)" if est.upper_bound else ""
    if est.spheres > limit:
        raise SceneError(scene.path, key, limit,
                         f"{est.what}{bound}, about {fmt_bytes(est.bytes)}; past max_spheres ({origin}): raise "
                         f"limits.max_spheres or --max-spheres, or enlarge {est.radius_key} = "
                         f"{est.radius_value!r}")
    if avail is not None and est.bytes > avail:
        raise SceneError(scene.path, est.radius_key, est.radius_value,
                         f"the build needs about {fmt_bytes(est.bytes)} for {fmt_count(est.spheres)} spheres"
                         f"{bound} but {fmt_bytes(avail)} of memory are available now (MemAvailable): enlarge "
                         f"{est.radius_key}, shrink [domain], or free memory")
    if progress:
        progress(est.line())
    return est
