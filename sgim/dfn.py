"""Monte-Carlo discrete fracture network (DFN): joint sets -> discs with stable ids.

Scene keys
----------
::

    [dfn]
    seed = 42                 # integer >= 0 (default 0)
    max_fractures = 200000    # refuse a network that would need more fractures
    # file = "network.csv"    # apply a network written by `sgim dfn` (CSV or JSON) instead of sampling

    [[joint_set]]
    name = "J1"               # ids are NAME-000001, NAME-000002, ...
    dip = 75.0                # mean pole, as the mean plane's dip / dip direction (degrees)
    dip_direction = 40.0
    kappa = 40.0              # Fisher concentration, > 0
    p32 = 0.08                # fracture area inside the domain per domain volume (1/m), or
    # count = 300             # the number of fractures that reach the domain (exactly one of the two)
    thickness = 0.0           # > 0: faults (red inside), as for [[discontinuity]]
    [joint_set.radius]        # or radius = 5.0 for a constant radius
    law = "power"             # "constant" | "power" | "lognormal" | "exponential"
    exponent = 2.7
    min = 2.0
    max = 30.0

Radius laws (density f(r) of the disc radius r, each optionally truncated to [min, max]):

* ``constant``: ``value``.
* ``power``: f(r) ~ r^-exponent on [min, max]; ``min`` > 0 is required.  Without ``max`` the
  law must have a finite third moment (exponent > 4; the Poisson sampling region grows with the
  radius, see below); with ``max`` any exponent is accepted (exponent = 1: log-uniform).
* ``lognormal``: ln r normal with ``mu`` and ``sigma`` (of ln r), or with ``mean`` and ``sd`` of the
  untruncated radius (sigma^2 = ln(1 + sd^2/mean^2), mu = ln mean - sigma^2/2); ``min`` (default 0)
  and ``max`` (default none) truncate it.
* ``exponential``: f(r) ~ exp(-r / mean) on [min, max] (``min`` default 0, ``max`` default none);
  ``mean`` is the scale of the untruncated law.

Model
-----
Each joint set is a homogeneous Poisson process of discs: centres uniform in space, radii
independent from the radius law, unit normals from the Fisher distribution about the mean pole
(sampled exactly by inverting its cumulative distribution: 1 - cos(theta) =
-ln(e^-2kappa + u (1 - e^-2kappa)) / kappa, azimuth uniform).  Only discs that can reach the domain
are drawn: a disc of radius R can reach the domain box only if its centre lies in the box enlarged by
R on every side, E(R), of volume V(R) = (Lx + 2R)(Ly + 2R)(Lz + 2R).  The Poisson process restricted to
those centres has independent candidates whose radius density is f(r) V(r) / E_f[V(R)] (a mixture of the
moment-weighted laws f(r) r^j, j = 0..3, each sampled exactly by inversion) and whose centre is uniform
in E(R).  A candidate is kept when its area inside the domain is positive; the others cannot reach the
domain and are dropped.

P32 is the fracture area inside the domain per domain volume, P32 = sum_k area(disc_k inside box) / V.
The domain is the scene's [domain] box (before excavation).  With a ``p32`` target, kept fractures are
added in candidate order until the realised P32 is as close to the target as one more or one fewer
fracture can make it; with ``count`` the first ``count`` kept fractures form the set.

Reproducibility and stable ids
------------------------------
Candidates are drawn in blocks of CHUNK; block b of set NAME uses its own numpy Generators (PCG64)
seeded by SeedSequence(seed, spawn_key=(hash(NAME), b, stream)) with separate streams for radius,
centre and orientation, and every block draws a fixed number of uniforms per candidate.  Hence the
same seed gives the identical network, a set's fractures do not change when other sets are added,
removed or reordered, raising the intensity only appends fractures (the lower-intensity network is a
prefix of the higher one), and changing the orientation law leaves the candidates' centres and radii
unchanged.  Kept fractures are numbered in candidate order: id NAME-000001, NAME-000002, ...

Statistics
----------
Per set: count, realised P32 (and its target), the mean pole and the Fisher concentration estimate
kappa = (N - 1) / (N - R) (R the length of the resultant of the unit normals, each turned into the
hemisphere of the principal axis), and the maximum-likelihood fit of the radius law's parameters with
its bounds held.  Orientation and radius statistics use the fractures whose centre lies inside the
domain: the discs reaching the domain from outside are biased towards large radii and towards
orientations that cut the box more easily, while the centres inside the domain sample the set's laws
without bias.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _dfn as K
from .common import SceneError, atomic_path, atomic_vtu
from .cutting import Discs
from .dfnlaw import RadiusLaw
from .geometry import MAX_COORD, dip_to_normal
from .portable import each, norm

CHUNK = 4096  # candidates per block; part of the reproducibility contract, never change
LAWS = ("constant", "power", "lognormal", "exponential")
DEFAULT_MAX_FRACTURES = 200_000
MAX_P32 = 1e6  # fracture area per volume [m2/m3]: a fracture every micrometre
VTU_SEGMENTS = 24
CSV_COLUMNS = ("id", "set", "cx", "cy", "cz", "nx", "ny", "nz", "dip", "dip_direction", "radius", "thickness",
               "area_in_domain")


# ---------------------------------------------------------------------------
# scene specification

@dataclass
class JointSet:
    name: str
    key: str  # key path in the scene, for messages
    dip: float
    dip_direction: float
    kappa: float
    radius: RadiusLaw
    p32: float | None = None
    count: int | None = None
    thickness: float = 0.0

    @property
    def pole(self):
        return dip_to_normal(self.dip, self.dip_direction)

    def describe(self):
        out = {"name": self.name, "dip": self.dip, "dip_direction": self.dip_direction, "kappa": self.kappa,
               "radius": self.radius.params(), "thickness": self.thickness}
        if self.p32 is not None:
            out["p32"] = self.p32
        else:
            out["count"] = self.count
        return out


@dataclass
class DfnSpec:
    seed: int
    max_fractures: int
    sets: list
    lo: np.ndarray
    hi: np.ndarray
    file: str | None = None
    scene_path: str = "<scene>"
    network: object = None  # Network, once sampled or loaded (loaded networks are read while validating)


def _int(rd, tab, name, key, default, lo):
    v = rd.value(tab, name, key, default, "integer")
    if isinstance(v, bool) or not isinstance(v, int):
        rd.err(key, v, "must be an integer")
    if v < lo:
        rd.err(key, v, f"must be >= {lo}")
    return int(v)


def _read_radius(rd, js, key):
    if "radius" not in js:
        rd.err(key, None, "missing value (a number for a constant radius, or a table with law = ...)")
    rt = js["radius"]
    if isinstance(rt, (int, float)) and not isinstance(rt, bool):
        return RadiusLaw("constant", value=rd.check_number(rt, key, positive=True, hi=MAX_COORD, unit=" m"))
    if not isinstance(rt, dict):
        rd.err(key, rt, "must be a number (constant radius) or a table with law = ...")
    law = rd.choice(rt, "law", f"{key}.law", LAWS, None)
    if law == "constant":
        rd.known(rt, {"law", "value"}, key)
        return RadiusLaw(law, value=rd.number(rt, "value", f"{key}.value", positive=True, hi=MAX_COORD, unit=" m"))
    allowed = {"law", "min", "max", {"power": "exponent", "exponential": "mean"}.get(law, "mu")}
    if law == "lognormal":
        allowed |= {"sigma", "mean", "sd"}
    rd.known(rt, allowed, key)
    if law == "power":
        lo = rd.number(rt, "min", f"{key}.min", positive=True, hi=MAX_COORD, unit=" m")
    else:
        lo = rd.number(rt, "min", f"{key}.min", default=0.0, nonneg=True, hi=MAX_COORD, unit=" m")
    hi = math.inf
    if "max" in rt:
        hi = rd.check_number(rt["max"], f"{key}.max", positive=True, hi=MAX_COORD, unit=" m")
        if hi <= lo:
            rd.err(f"{key}.max", hi, f"must exceed {key}.min = {lo:g} (inverted radius bounds)")
    if law == "power":
        a = rd.number(rt, "exponent", f"{key}.exponent", lo=-50.0, hi=50.0)
        if math.isinf(hi):
            if a <= 1:
                rd.err(f"{key}.exponent", a, "a power law with exponent <= 1 has no finite probability without "
                                             f"an upper bound: give {key}.max")
            if a <= 4:
                rd.err(f"{key}.exponent", a, "without an upper bound the radius needs a finite third moment "
                                             f"(exponent > 4) to sample the domain's neighbourhood: give {key}.max")
        law_obj = RadiusLaw(law, exponent=a, min=lo, max=hi)
    elif law == "exponential":
        mean = rd.number(rt, "mean", f"{key}.mean", positive=True, hi=MAX_COORD, unit=" m")
        if lo / mean > 200.0:
            rd.err(f"{key}.min", lo, f"lies {lo / mean:.3g} means into the exponential tail (at most 200)")
        law_obj = RadiusLaw(law, mean=mean, min=lo, max=hi)
    else:
        pairs = [p for p in (("mu", "sigma"), ("mean", "sd")) if p[0] in rt or p[1] in rt]
        if len(pairs) != 1:
            rd.err(key, sorted(rt), "give exactly one of: mu + sigma (of ln r), mean + sd (of r)")
        if pairs[0][0] == "mu":
            mu = rd.number(rt, "mu", f"{key}.mu", lo=-50.0, hi=50.0)
            sigma = rd.number(rt, "sigma", f"{key}.sigma", positive=True, hi=10.0)
        else:
            mean = rd.number(rt, "mean", f"{key}.mean", positive=True, hi=MAX_COORD, unit=" m")
            sd = rd.number(rt, "sd", f"{key}.sd", positive=True, hi=MAX_COORD, unit=" m")
            s2 = math.log1p((sd / mean) ** 2)
            if s2 > 100.0:
                rd.err(f"{key}.sd", sd, "too wide for a lognormal radius (sigma of ln r must be <= 10)")
            sigma, mu = math.sqrt(s2), math.log(mean) - 0.5 * s2
        law_obj = RadiusLaw(law, mu=mu, sigma=sigma, min=lo, max=hi)
    if not law_obj.mass() > 1e-300 or not all(math.isfinite(law_obj.moment(j)) and law_obj.moment(j) > 0
                                              for j in range(4)):
        rd.err(key, law_obj.params(), "the law puts no usable probability between min and max")
    return law_obj


def _read_joint_set(rd, js, key, k):
    if not isinstance(js, dict):
        rd.err(key, js, "must be a table")
    rd.known(js, {"name", "dip", "dip_direction", "kappa", "p32", "count", "thickness", "radius"}, key)
    name = rd.string(js, "name", f"{key}.name", f"J{k + 1}")
    if not name.strip() or any(ch in name for ch in ",\"\n\r\t"):
        rd.err(f"{key}.name", name, "must be non-empty, without commas, quotes or line breaks")
    dip = rd.number(js, "dip", f"{key}.dip", lo=0.0, hi=90.0)
    dd = rd.number(js, "dip_direction", f"{key}.dip_direction", lo=0.0, hi=360.0)
    kappa = rd.number(js, "kappa", f"{key}.kappa")
    if kappa <= 0:
        rd.err(f"{key}.kappa", kappa, "must be > 0 (Fisher concentration)")
    if kappa > 1e8:
        rd.err(f"{key}.kappa", kappa, "must be <= 1e8")
    has = [w for w in ("p32", "count") if w in js]
    if len(has) != 1:
        rd.err(key, sorted(js), "give exactly one of p32 (area per volume) and count (number of fractures)"
               + (", not both" if has else ""))
    p32 = count = None
    if has[0] == "p32":
        p32 = rd.number(js, "p32", f"{key}.p32", positive=True, hi=MAX_P32, unit=" m2/m3")
    else:
        count = _int(rd, js, "count", f"{key}.count", 0, 1)
    thick = rd.number(js, "thickness", f"{key}.thickness", default=0.0, nonneg=True, hi=MAX_COORD, unit=" m")
    radius = _read_radius(rd, js, f"{key}.radius")
    return JointSet(name, key, dip, dd, kappa, radius, p32, count, thick)


def read_dfn(rd, data, domain, scene_path):
    """The scene's [dfn] table and [[joint_set]] tables -> DfnSpec (or None when neither is given).

    Raises SceneError on any problem, including a network that would need more than
    dfn.max_fractures fractures (estimated from the first block of candidates).
    """
    dt = rd.table(data, "dfn", "dfn")
    rd.known(dt, {"seed", "max_fractures", "file"}, "dfn")
    sets_raw = data.get("joint_set", [])
    if not isinstance(sets_raw, list):
        rd.err("joint_set", sets_raw, "must be an array of tables ([[joint_set]])")
    if not dt and not sets_raw:
        return None
    seed = _int(rd, dt, "seed", "dfn.seed", 0, 0)
    mx = _int(rd, dt, "max_fractures", "dfn.max_fractures", DEFAULT_MAX_FRACTURES, 1)
    lo, hi = np.asarray(domain.min, float), np.asarray(domain.max, float)
    spec = DfnSpec(seed, mx, [], lo, hi, scene_path=str(scene_path))
    if "file" in dt:
        fname = rd.string(dt, "file", "dfn.file", "")
        if sets_raw:
            rd.err("dfn.file", fname, "give either [dfn] file or [[joint_set]] tables, not both")
        fpath = Path(fname)
        if not fpath.is_absolute():
            fpath = Path(scene_path).parent / fpath
        spec.file = fname
        spec.network = load_network(fpath, lo, hi, scene_path=scene_path, key=f"dfn.file {fname}")
        if len(spec.network) > mx:
            rd.err("dfn.file", fname, f"holds {len(spec.network)} fractures reaching the domain, more than "
                                      f"dfn.max_fractures = {mx}")
        return spec
    if not sets_raw:
        return None
    names = {}
    for k, js in enumerate(sets_raw):
        s = _read_joint_set(rd, js, f"joint_set[{k}]", k)
        if s.name in names:
            rd.err(f"joint_set[{k}].name", s.name, f"repeats the name of joint_set[{names[s.name]}]")
        names[s.name] = k
        spec.sets.append(s)
    total, parts = 0, []
    for s in spec.sets:
        need = s.count if s.count is not None else estimate_count(s, seed, lo, hi)
        if need > mx:
            what = f"count = {s.count}" if s.count is not None else f"p32 = {s.p32:g} needs about {need} fractures"
            rd.err(f"{s.key}.{'count' if s.count is not None else 'p32'}", s.count if s.count is not None
                   else s.p32, f"{what} in the domain, more than dfn.max_fractures = {mx}")
        total += need
        parts.append(f"{s.name} {need}")
    if total > mx:
        rd.err("dfn.max_fractures", mx, f"the joint sets need about {total} fractures in all ({', '.join(parts)})")
    return spec


# ---------------------------------------------------------------------------
# sampling

def _name_key(name):
    h = hashlib.sha256(name.encode("utf-8")).digest()
    return int.from_bytes(h[:4], "little"), int.from_bytes(h[4:8], "little")


def _generators(seed, name, block):
    k1, k2 = _name_key(name)
    return [np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(k1, k2, block, s))))
            for s in range(3)]


def fisher_normals(pole, kappa, u):
    """Unit vectors from the Fisher distribution about ``pole``; u is (n, 2) uniforms in [0, 1)."""
    e = math.exp(-2.0 * kappa)
    up = 1.0 - u[:, 0]  # in (0, 1]
    t = np.minimum(-each(math.log, e + up * (-math.expm1(-2.0 * kappa))) / kappa, 2.0)  # 1 - cos(theta)
    st = np.sqrt(t * (2.0 - t))
    phi = 2.0 * math.pi * u[:, 1]
    p = np.asarray(pole, float) / norm(pole)
    ux, uy, uz, vx, vy, vz = K.plane_basis(p)
    a, b, w = st * each(math.cos, phi), st * each(math.sin, phi), 1.0 - t
    return np.column_stack([a * ux + b * vx + w * p[0], a * uy + b * vy + w * p[1], a * uz + b * vz + w * p[2]])


def upward(n):
    """Unit normals turned to point up (z >= 0), the convention of dip / dip direction."""
    n = n / np.linalg.norm(n, axis=1)[:, None]
    return np.where(n[:, 2:3] < 0, -n, n)


def candidates(js: JointSet, seed, lo, hi, block):
    """Block ``block`` of the set's candidate discs: (centres, upward normals, radii)."""
    gr, gc, go = _generators(seed, js.name, block)
    ur, uc, uo = gr.random((CHUNK, 2)), gc.random((CHUNK, 3)), go.random((CHUNK, 2))
    ext = hi - lo
    r = js.radius.sample_biased(ur, ext)
    centres = lo[None, :] - r[:, None] + uc * (ext[None, :] + 2.0 * r[:, None])
    normals = upward(fisher_normals(js.pole, js.kappa, uo))
    return centres, normals, r


def clipped_areas(centres, normals, radii, lo, hi):
    """Area of each disc inside the box [lo, hi] (exact)."""
    return K.clipped_areas(np.ascontiguousarray(centres, float), np.ascontiguousarray(normals, float),
                           np.ascontiguousarray(radii, float), np.asarray(lo, float), np.asarray(hi, float))


def estimate_count(js: JointSet, seed, lo, hi):
    """Fractures reaching the domain that the set's P32 target needs (from the first block)."""
    c, n, r = candidates(js, seed, lo, hi, 0)
    a = clipped_areas(c, n, r, lo, hi)
    kept = a[a > 0]
    target = js.p32 * float(np.prod(hi - lo))
    if len(kept) == 0:
        return 0
    return int(math.ceil(target / float(kept.mean())))


def sample_set(js: JointSet, seed, lo, hi, limit, scene_path="<scene>", progress=None):
    """Fractures of one set: (centres, normals, radii, areas, candidates drawn)."""
    target = js.p32 * float(np.prod(hi - lo)) if js.p32 is not None else None
    parts, acc, nk, block = [], 0.0, 0, 0
    max_blocks = max(1, (50 * limit + 10_000_000) // CHUNK)
    done = False
    while not done:
        if block >= max_blocks:
            raise SceneError(scene_path, f"{js.key}.radius", js.radius.params(),
                             f"only {nk} of {block * CHUNK} candidate discs reach the domain: the radii are too "
                             "large for the domain")
        c, n, r = candidates(js, seed, lo, hi, block)
        a = clipped_areas(c, n, r, lo, hi)
        idx = np.nonzero(a > 0)[0]
        if target is None:
            take = min(len(idx), js.count - nk)
            done = nk + take >= js.count
        else:
            cum = acc + np.cumsum(a[idx])
            p = int(np.searchsorted(cum, target, side="left"))
            if p < len(idx):
                before = acc if p == 0 else float(cum[p - 1])
                take = p + 1 if cum[p] - target <= target - before else p
                done = True
            else:
                take = len(idx)
        idx = idx[:take]
        if nk + len(idx) > limit:
            if target is None:
                need = js.count
            else:
                got = acc + float(a[idx].sum())
                need = int(math.ceil((nk + len(idx)) * target / got)) if got > 0 else limit + 1
            what = f"count = {js.count}" if target is None else f"p32 = {js.p32:g} needs about {need} fractures"
            raise SceneError(scene_path, f"{js.key}.{'count' if target is None else 'p32'}",
                             js.count if target is None else js.p32,
                             f"{what} in the domain, more than the {limit} that dfn.max_fractures leaves")
        parts.append((c[idx], n[idx], r[idx], a[idx]))
        acc += float(a[idx].sum())
        nk += len(idx)
        block += 1
        if progress and (done or block % 16 == 0):
            tgt = f"P32 {acc / float(np.prod(hi - lo)):.4g} of {js.p32:g}" if target is not None else \
                f"{nk} of {js.count}"
            progress(f"dfn        {js.name}: {nk} fractures, {tgt}, {block * CHUNK} candidates")
    cs = np.concatenate([p[0] for p in parts])
    ns = np.concatenate([p[1] for p in parts])
    rs = np.concatenate([p[2] for p in parts])
    ars = np.concatenate([p[3] for p in parts])
    return cs, ns, rs, ars, block * CHUNK


# ---------------------------------------------------------------------------
# the network

def fracture_id(set_name, k):
    """Id of the k-th kept fracture of a set (k from 1)."""
    return f"{set_name}-{k:06d}"


@dataclass
class Network:
    ids: list
    set_index: np.ndarray  # (n,) int32 into set_names
    set_names: list
    centres: np.ndarray  # (n, 3)
    normals: np.ndarray  # (n, 3) unit, upward
    radii: np.ndarray
    thickness: np.ndarray
    area: np.ndarray  # area inside the domain
    lo: np.ndarray
    hi: np.ndarray
    seed: int | None = None
    source: str = "sampled"
    sets: list = field(default_factory=list)  # JointSet per set_names entry (sampled networks)
    candidates: list = field(default_factory=list)  # candidates drawn per set
    dropped: int = 0  # rows of a loaded file that do not reach the domain

    def __len__(self):
        return len(self.radii)

    @property
    def volume(self):
        return float(np.prod(self.hi - self.lo))

    def dip_dd(self):
        n = upward(self.normals)
        dip = np.degrees(np.arccos(np.clip(n[:, 2], -1.0, 1.0)))
        dd = np.degrees(np.arctan2(n[:, 0], n[:, 1])) % 360.0
        return dip, dd

    def centre_inside(self):
        return np.all((self.centres >= self.lo) & (self.centres <= self.hi), axis=1)

    def statistics(self):
        """Per-set statistics (see the module notes)."""
        inside = self.centre_inside()
        out = []
        for s, name in enumerate(self.set_names):
            sel = self.set_index == s
            n = int(sel.sum())
            st = {"set": name, "count": n, "count_centre_inside": int((sel & inside).sum()),
                  "area_in_domain": float(self.area[sel].sum()), "p32": float(self.area[sel].sum()) / self.volume}
            js = self.sets[s] if s < len(self.sets) else None
            if s < len(self.candidates):
                st["candidates"] = int(self.candidates[s])
            if js is not None:
                st["given"] = js.describe()
                if js.p32 is not None:
                    st["p32_target"] = js.p32
            use = sel & inside if int((sel & inside).sum()) >= 2 else sel
            st.update(orientation_stats(self.normals[use]))
            r = self.radii[use]
            st["radius"] = {"n": int(len(r)), "min": float(r.min()) if len(r) else None,
                            "mean": float(r.mean()) if len(r) else None, "max": float(r.max()) if len(r) else None}
            if js is not None and len(r):
                st["radius_fit"] = {"law": js.radius.law, **js.radius.fit(r)}
            out.append(st)
        return out

    def summary(self):
        return {"fractures": len(self), "source": self.source, "seed": self.seed, "volume": self.volume,
                "p32": float(self.area.sum()) / self.volume, "dropped_outside": self.dropped,
                "sets": self.statistics()}

    def discs(self):
        """(centres, normals, radii, thickness, names) for the cutting stage."""
        return self.centres, self.normals, self.radii, self.thickness, list(self.ids)

    # -- files
    def save_csv(self, path):
        dip, dd = self.dip_dd()
        names = [self.set_names[s] for s in self.set_index.tolist()]
        cols = [self.ids, names, *self.centres.T.tolist(), *self.normals.T.tolist(), dip.tolist(), dd.tolist(),
                self.radii.tolist(), self.thickness.tolist(), self.area.tolist()]
        plain = not any(ch in t for t in (*self.ids, *self.set_names) for ch in ',"\n\r')
        with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
            fh.write(",".join(CSV_COLUMNS) + "\n")
            if plain:  # repr: the shortest text that reads back to the same float
                line = "%s,%s" + ",%r" * 11 + "\n"
                fh.write("".join(line % row for row in zip(*cols)))
            else:
                csv.writer(fh, lineterminator="\n").writerows(zip(*cols))

    def save_json(self, path):
        dip, dd = self.dip_dd()
        doc = {"format": "sgim-dfn-1", "domain": {"min": self.lo.tolist(), "max": self.hi.tolist()},
               **self.summary()}
        head = json.dumps(doc, indent=1)
        keys = ("id", "set", "centre", "normal", "dip", "dip_direction", "radius", "thickness", "area_in_domain")
        names = [self.set_names[s] for s in self.set_index.tolist()]
        rows = zip(self.ids, names, self.centres.tolist(), self.normals.tolist(), dip.tolist(), dd.tolist(),
                   self.radii.tolist(), self.thickness.tolist(), self.area.tolist())
        with atomic_path(path) as tmp, open(tmp, "w") as fh:
            fh.write(head[:-2] + ',\n "fractures": [\n')  # one fracture per line
            fh.write(",\n".join("  " + json.dumps(dict(zip(keys, row))) for row in rows))
            fh.write("\n ]\n}\n")

    def save_vtu(self, path, segments=VTU_SEGMENTS):
        """The discs as polygons (``segments`` vertices each) with per-disc cell data."""
        import meshio  # loaded only when a .vtu is written (start-up time)

        n = len(self)
        N = self.normals
        helper = np.where((np.abs(N[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        U = np.cross(helper, N)
        U /= np.linalg.norm(U, axis=1)[:, None]
        W = np.cross(N, U)
        phi = 2.0 * np.pi * np.arange(segments) / segments
        cp, sp = np.cos(phi), np.sin(phi)
        pts = (self.centres[:, None, :] + self.radii[:, None, None]
               * (cp[None, :, None] * U[:, None, :] + sp[None, :, None] * W[:, None, :])).reshape(-1, 3)
        pts = pts.astype(np.float32)
        cells = np.arange(n * segments, dtype=np.int64).reshape(n, segments)
        mesh = meshio.Mesh(pts, [("polygon", cells)] if n else [], cell_data={
            "set": [self.set_index.astype(np.int32)], "row": [np.arange(n, dtype=np.int32)],
            "radius": [self.radii], "thickness": [self.thickness], "area_in_domain": [self.area],
        } if n else {})
        atomic_vtu(path, mesh)


def orientation_stats(normals):
    """Mean pole and Fisher concentration estimate of unit normals (axial: each turned into the
    hemisphere of the principal axis of the orientation tensor)."""
    n = len(normals)
    if n == 0:
        return {"mean_pole": None, "kappa_estimate": None}
    T = normals.T @ normals
    e = np.linalg.eigh(T)[1][:, -1]
    al = np.where((normals @ e)[:, None] < 0, -normals, normals)
    res = al.sum(0)
    R = float(np.linalg.norm(res))
    m = res / R
    if m[2] < 0:
        m = -m
    dip = float(np.degrees(np.arccos(np.clip(m[2], -1, 1))))
    dd = float(np.degrees(np.arctan2(m[0], m[1])) % 360.0)
    kappa = (n - 1) / (n - R) if n > 1 and n - R > 0 else None
    return {"mean_pole": {"dip": dip, "dip_direction": dd, "normal": m.tolist()}, "kappa_estimate": kappa,
            "resultant_length": R}


def generate_network(spec: DfnSpec, progress=None) -> Network:
    """Sample every joint set of ``spec`` (or return the network read from its file)."""
    if spec.network is not None:
        return spec.network
    lo, hi = spec.lo, spec.hi
    cols = {k: [] for k in ("c", "n", "r", "a", "t", "s")}
    ids, drawn, left = [], [], spec.max_fractures
    for s, js in enumerate(spec.sets):
        c, n, r, a, nc = sample_set(js, spec.seed, lo, hi, left, spec.scene_path, progress)
        left -= len(r)
        for key, v in zip("cnra", (c, n, r, a)):
            cols[key].append(v)
        cols["t"].append(np.full(len(r), js.thickness))
        cols["s"].append(np.full(len(r), s, np.int32))
        ids += [fracture_id(js.name, k + 1) for k in range(len(r))]
        drawn.append(nc)
    cat = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
    net = Network(ids, cat["s"].astype(np.int32), [js.name for js in spec.sets], cat["c"].reshape(-1, 3),
                  cat["n"].reshape(-1, 3), cat["r"], cat["t"], cat["a"], lo, hi, seed=spec.seed, source="sampled",
                  sets=list(spec.sets), candidates=drawn)
    spec.network = net
    return net


def network_for(scene, progress=None):
    """The scene's network (sampled once and kept on the scene), or None."""
    spec = getattr(scene, "dfn", None)
    if spec is None:
        return None
    net = getattr(scene, "_dfn_network", None)
    if net is None:
        net = scene._dfn_network = generate_network(spec, progress)
    return net


def append_discs(discs, net):
    """Discs (sgim.cutting.Discs) followed by the network's fractures."""

    if net is None or len(net) == 0:
        return discs
    return Discs(np.vstack([discs.centres, net.centres]), np.vstack([discs.normals, net.normals]),
                 np.concatenate([discs.radii, net.radii]), np.concatenate([discs.thickness, net.thickness]),
                 list(discs.names) + list(net.ids))


def write_network(net: Network, folder):
    """network.csv, network.json (with the statistics) and network.vtu in ``folder``."""
    folder = Path(folder)
    net.save_csv(folder / "network.csv")
    net.save_json(folder / "network.json")
    net.save_vtu(folder / "network.vtu")


# ---------------------------------------------------------------------------
# reading a network file

def _bad(scene_path, key, value, message):
    raise SceneError(scene_path, key, value, message)


def load_network(path, lo, hi, scene_path="<scene>", key="dfn.file"):
    """Read a network written by ``sgim dfn`` (network.csv or network.json).

    Fractures whose disc does not reach the box [lo, hi] are dropped (counted in ``dropped``);
    areas inside the box are recomputed.  Raises SceneError naming the row and column of a bad value.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        _bad(scene_path, key, str(path), f"cannot read network file ({exc.__class__.__name__})")
    rows = []
    if path.suffix.lower() == ".json":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            _bad(scene_path, key, str(path), f"not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})")
        except (ValueError, RecursionError) as exc:
            _bad(scene_path, key, str(path), f"not valid JSON ({exc.__class__.__name__})")
        fr = doc.get("fractures") if isinstance(doc, dict) else None
        if not isinstance(fr, list):
            _bad(scene_path, key, str(path), "a network JSON needs a 'fractures' list")
        for i, f in enumerate(fr):
            if not isinstance(f, dict):
                _bad(scene_path, f"{key} (fracture {i + 1})", f, "must be an object")
            c, nrm = f.get("centre"), f.get("normal")
            if not (isinstance(c, list) and len(c) == 3 and isinstance(nrm, list) and len(nrm) == 3):
                _bad(scene_path, f"{key} (fracture {i + 1})", f.get("id"), "needs 'centre' and 'normal' lists of 3")
            rows.append((f.get("id"), f.get("set", ""), *c, *nrm, f.get("radius"), f.get("thickness", 0.0)))
        where = "fracture"
    elif path.suffix.lower() == ".csv":
        reader = csv.DictReader(text.splitlines())
        need = ("id", "cx", "cy", "cz", "nx", "ny", "nz", "radius")
        try:
            missing = [c for c in need if c not in (reader.fieldnames or [])]
            if missing:
                _bad(scene_path, key, str(path), f"CSV lacks the column(s) {', '.join(missing)}")
            for r in reader:
                if any(str(c).strip() for c in r.get(None) or ()):  # more cells than columns: another table
                    _bad(scene_path, f"{key} (row {len(rows) + 1})", r[None], f"more cells than the "
                         f"{len(reader.fieldnames)} columns")
                rows.append((r["id"], r.get("set") or "", r["cx"], r["cy"], r["cz"], r["nx"], r["ny"], r["nz"],
                             r["radius"], r.get("thickness") or 0.0))
        except csv.Error as exc:
            _bad(scene_path, f"{key} (line {reader.line_num})", str(path), f"not a readable CSV table ({exc})")
        where = "row"
    else:
        _bad(scene_path, key, str(path), "network file must end in .csv or .json")
    names = ("id", "set", "cx", "cy", "cz", "nx", "ny", "nz", "radius", "thickness")
    vals = np.empty((len(rows), 8))
    ids, sets, seen = [], [], {}
    for i, row in enumerate(rows):
        fid = row[0]
        if not isinstance(fid, str) or not fid:
            _bad(scene_path, f"{key} ({where} {i + 1}).id", fid, "must be a non-empty string")
        if fid in seen:
            _bad(scene_path, f"{key} ({where} {i + 1}).id", fid, f"repeats the id of {where} {seen[fid] + 1}")
        seen[fid] = i
        ids.append(fid)
        sets.append(str(row[1]))
        for j, v in enumerate(row[2:]):
            col = names[j + 2]
            try:
                x = float(v) if not isinstance(v, bool) else math.nan
            except (TypeError, ValueError):
                x = math.nan
            if not math.isfinite(x):
                _bad(scene_path, f"{key} ({where} {i + 1}).{col}", v, "must be a finite number")
            vals[i, j] = x
        if not vals[i, 6] > 0:
            _bad(scene_path, f"{key} ({where} {i + 1}).radius", vals[i, 6], "must be > 0")
        if vals[i, 7] < 0:
            _bad(scene_path, f"{key} ({where} {i + 1}).thickness", vals[i, 7], "must be >= 0")
        nn = float(np.linalg.norm(vals[i, 3:6]))
        if not nn > 1e-12 * max(1.0, float(np.abs(vals[i, 3:6]).max())):
            _bad(scene_path, f"{key} ({where} {i + 1}).normal", vals[i, 3:6].tolist(), "must not be the zero vector")
    normals = vals[:, 3:6].copy()
    if len(rows):
        # unit normals (as written by sgim) are kept bit for bit, so that a network read back applies exactly
        nrm = np.linalg.norm(normals, axis=1)
        off = np.abs(nrm - 1.0) > 1e-12
        normals[off] /= nrm[off, None]
    centres = vals[:, 0:3]
    area = clipped_areas(centres, normals, vals[:, 6], lo, hi) if len(rows) else np.zeros(0)
    keep = area > 0
    set_names = list(dict.fromkeys(sets))
    index = {s: k for k, s in enumerate(set_names)}
    set_index = np.array([index[s] for s in sets], np.int32)
    ids = [f for f, k in zip(ids, keep) if k]
    return Network(ids, set_index[keep], set_names, centres[keep], normals[keep], vals[keep, 6], vals[keep, 7],
                   area[keep], np.asarray(lo, float), np.asarray(hi, float), seed=None, source=str(path),
                   dropped=int((~keep).sum()))


def format_statistics(net: Network):
    """Lines of a per-set table for the terminal."""
    lines = [f"{'set':<10s} {'count':>7s} {'P32 (target)':>20s} {'mean pole dip/dd':>17s} "
             f"{'kappa est (given)':>19s}  radius fit (given)"]
    for st in net.statistics():
        tgt = f"({st['p32_target']:g})" if "p32_target" in st else ""
        mp = st["mean_pole"]
        pole = f"{mp['dip']:5.1f}/{mp['dip_direction']:05.1f}" if mp else "-"
        given = st.get("given", {})
        ke = st["kappa_estimate"]
        kap = (f"{ke:.3g}" if ke else "-") + (f" ({given['kappa']:g})" if given else "")
        fit = st.get("radius_fit")
        if fit:
            gp = given["radius"]
            fit_s = ", ".join(f"{k} {v:.4g} ({gp.get(k, math.nan):g})" for k, v in fit.items() if k != "law")
            fit_s = f"{fit['law']}: {fit_s}"
        else:
            rr = st["radius"]
            fit_s = f"min {rr['min']:.3g} mean {rr['mean']:.3g} max {rr['max']:.3g}" if rr["n"] else "-"
        lines.append(f"{st['set']:<10s} {st['count']:>7d} {st['p32']:>10.4g} {tgt:>9s} {pole:>17s} {kap:>19s}  "
                     f"{fit_s}")
    return lines
