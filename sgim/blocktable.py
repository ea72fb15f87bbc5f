"""The ``[blocks]`` table of an sgim scene: what only the block model of the scene needs (dda/geoblocks.py).

``sgim build`` reads and validates it (unknown keys fail with their key path) and then ignores it; the block
builder ignores the sphere keys ([packing], [bonds], [render], ...).

    [blocks]
    min_volume = 5.0                 # m3: a cut leaving a smaller piece is not made (default 1e-6 x domain volume)
    cut_by = ["fault F1", "J1"]      # [[discontinuity]] names and [[joint_set]] set names that cut (default all)
    cohesion = 1.0e6                 # Pa, intact rock (the contacts of faces outside every disc)
    tensile = 0.5e6                  # Pa, intact rock
    friction = 40.0                  # degrees, intact rock
    seed = 0                         # draws of the joint sets' persistence

    kn = 1.0e10                      # N/m per contact point, every contact of the block model (default)
    ks = 5.0e9                       # N/m (default kn / 2)
    damping = 0.1                    # ratio of critical, normal and locked shear springs
    density = 2600.0                 # kg/m3 of every block
    joint_friction = 30.0            # degrees: every joint and fault face inside its disc (unless a law names it)
    joint_cohesion = 0.0             # Pa
    joint_tensile = 0.0              # Pa

    [[blocks.law]]                   # the law of one discontinuity, joint set or fault, by name
    name = "J1"                      # a [[discontinuity]], [[joint_set]] set or [[blocks.joint_set]] name
    friction = 25.0                  # deg; cohesion, tensile (Pa), kn, ks (N/m): absent ones as the joints'

    [blocks.run]                     # dda run of the scene: the blocks under gravity
    duration = 2.0                   # s (required for dda run)
    dt = 0.0                         # s (0: automatic, safety x critical)
    safety = 0.5
    gravity = [0.0, 0.0, -9.81]
    local_damping = 0.0
    frames = 20                      # VTU frames
    record_every = 0.02              # s (default duration / 100)
    sleep = true                     # resting blocks stop being integrated
    fixed = ["x-", "x+", "y-", "y+", "z-"]   # blocks with a face on these domain faces are fixed (the default)
    free_within = 20.0               # m: only blocks that come this near the free surfaces move, the far field is
    free_near = ["pit"]              #   fixed; the [[excavation]] / [[cavity]] names (default all of them)

    [[blocks.joint_set]]             # a persistent joint set of the block fabric
    name = "B1"
    dip = 75.0
    dip_direction = 40.0
    spacing = 10.0                   # m, along the normal
    origin = [0.0, 0.0, 0.0]         # one plane of the set passes through it (default the domain's centre)
    persistence = 1.0                # chance that a plane cuts a block it crosses (0 < p <= 1)
    extent = {min = [...], max = [...]}   # a plane cuts the blocks whose section's centre is in it (default all)

Standard library and numpy only (no numba): this module is read by every ``sgim build``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .geometry import MAX_COORD
from .reader import COORD, SIZE

# the defaults of the optional keys (docs/scenes.md lists them with every other key)
DEFAULTS = {
    "blocks.min_volume_fraction": 1e-6,  # of the domain's volume, when min_volume is absent
    "blocks.cohesion": 1.0e6,  # Pa
    "blocks.tensile": 0.5e6,  # Pa
    "blocks.friction": 40.0,  # degrees
    "blocks.seed": 0,
    "blocks.joint_set[].persistence": 1.0,
    "blocks.kn": 1.0e10,  # N/m per contact point
    "blocks.damping": 0.1,
    "blocks.density": 2600.0,  # kg/m3
    "blocks.joint_friction": 30.0,  # degrees
    "blocks.joint_cohesion": 0.0,  # Pa
    "blocks.joint_tensile": 0.0,  # Pa
    "blocks.run.dt": 0.0,  # s: automatic
    "blocks.run.safety": 0.5,
    "blocks.run.gravity": (0.0, 0.0, -9.81),  # m/s2
    "blocks.run.local_damping": 0.0,
    "blocks.run.frames": 20,
    "blocks.run.sleep": True,
    "blocks.run.fixed": ("x-", "x+", "y-", "y+", "z-"),  # the blocks on these domain faces are fixed
}
BLOCK_KEYS = {"min_volume", "cut_by", "cohesion", "tensile", "friction", "seed", "joint_set"}
BLOCK_KEYS |= {"kn", "ks", "damping", "density", "joint_friction", "joint_cohesion", "joint_tensile", "law", "run"}
LAW_KEYS = {"name", "friction", "cohesion", "tensile", "kn", "ks"}
RUN_KEYS = {"duration", "dt", "safety", "gravity", "local_damping", "frames", "record_every", "sleep", "fixed",
            "free_within", "free_near"}
SIDES = ("x-", "x+", "y-", "y+", "z-", "z+")  # the domain's faces, by the axis and side of their outward normal
STIFF = {"lo": 1e-20, "hi": 1e40, "unit": " N/m"}
SET_KEYS = {"name", "dip", "dip_direction", "spacing", "origin", "persistence", "extent"}
STRESS = {"hi": 1e12, "unit": " Pa"}


@dataclass
class FabricSet:
    """A persistent joint set of the block fabric."""

    name: str
    key: str
    dip: float
    dip_direction: float
    spacing: float
    origin: np.ndarray
    persistence: float = 1.0
    extent: tuple | None = None  # (lo, hi) arrays


@dataclass
class Law:
    """A contact law of the block model: kn, ks [N/m per point] (None: the [blocks] ones), friction [deg], cohesion
    and tensile strength [Pa]."""

    friction: float
    cohesion: float = 0.0
    tensile: float = 0.0
    kn: float | None = None
    ks: float | None = None


@dataclass
class BlocksSpec:
    min_volume: float
    cut_by: list | None  # names; None: every discontinuity and joint set of the scene
    cohesion: float
    tensile: float
    friction: float
    seed: int
    joint_sets: list = field(default_factory=list)
    kn: float = DEFAULTS["blocks.kn"]
    ks: float | None = None  # None: kn / 2
    damping: float = DEFAULTS["blocks.damping"]
    density: float = DEFAULTS["blocks.density"]
    joint: Law = field(default_factory=lambda: Law(DEFAULTS["blocks.joint_friction"]))
    laws: dict = field(default_factory=dict)  # name -> Law ([[blocks.law]])
    run: dict = field(default_factory=lambda: default_run())  # [blocks.run]: duration (None: absent), dt, ...

    def law_of(self, name):
        """The joint law of the discontinuity, set or fault ``name`` (its [[blocks.law]], else the joints')."""
        return self.laws.get(name, self.joint)


def _read_set(rd, js, key, k, domain):
    if not isinstance(js, dict):
        rd.err(key, js, "must be a table")
    rd.known(js, SET_KEYS, key)
    name = rd.string(js, "name", f"{key}.name", f"B{k + 1}")
    dip = rd.number(js, "dip", f"{key}.dip", lo=0.0, hi=90.0)
    dd = rd.number(js, "dip_direction", f"{key}.dip_direction", lo=0.0, hi=360.0)
    spacing = rd.number(js, "spacing", f"{key}.spacing", positive=True, **SIZE)
    centre = (np.asarray(domain.min, float) + np.asarray(domain.max, float)) / 2
    origin = rd.vector(js, "origin", f"{key}.origin", default=centre, **COORD)
    p = rd.number(js, "persistence", f"{key}.persistence", default=DEFAULTS["blocks.joint_set[].persistence"],
                  positive=True, hi=1.0)
    extent = None
    if "extent" in js:
        et = rd.table(js, "extent", f"{key}.extent")
        rd.known(et, {"min", "max"}, f"{key}.extent")
        lo = rd.vector(et, "min", f"{key}.extent.min", **COORD)
        hi = rd.vector(et, "max", f"{key}.extent.max", **COORD)
        for a in range(3):
            if hi[a] <= lo[a]:
                rd.err(f"{key}.extent.max[{a}]", float(hi[a]), f"must exceed {key}.extent.min[{a}] = {lo[a]:g} m")
        extent = (lo, hi)
    return FabricSet(name, key, dip, dd, spacing, origin, p, extent)


def read_blocks(rd, data, scene):
    """The scene's [blocks] table -> BlocksSpec, or None when the scene has none. ``scene`` is the Scene read so
    far (its discontinuities and joint sets are the names cut_by may give)."""
    if "blocks" not in data:
        return None
    bt = rd.table(data, "blocks", "blocks")
    rd.known(bt, BLOCK_KEYS, "blocks")
    lo, hi = np.asarray(scene.domain.min, float), np.asarray(scene.domain.max, float)
    vol = float(np.prod(hi - lo))
    mv = rd.number(bt, "min_volume", "blocks.min_volume", default=DEFAULTS["blocks.min_volume_fraction"] * vol,
                   nonneg=True, hi=MAX_COORD ** 3, unit=" m3")
    cut_by = None
    if "cut_by" in bt:
        cut_by = rd.value(bt, "cut_by", "blocks.cut_by", None, "list of strings")
        if not isinstance(cut_by, list) or any(not isinstance(c, str) for c in cut_by):
            rd.err("blocks.cut_by", cut_by, "must be a list of discontinuity or joint set names")
        known = discontinuity_names(scene)
        for i, c in enumerate(cut_by):
            if c not in known:
                rd.err(f"blocks.cut_by[{i}]", c, "names no [[discontinuity]] or [[joint_set]] of the scene"
                       + (f" (known: {', '.join(sorted(known)[:12])})" if known else " (the scene has none)"))
    spec = BlocksSpec(
        min_volume=mv, cut_by=cut_by,
        cohesion=rd.number(bt, "cohesion", "blocks.cohesion", default=DEFAULTS["blocks.cohesion"], nonneg=True,
                           **STRESS),
        tensile=rd.number(bt, "tensile", "blocks.tensile", default=DEFAULTS["blocks.tensile"], nonneg=True,
                          **STRESS),
        friction=rd.number(bt, "friction", "blocks.friction", default=DEFAULTS["blocks.friction"], lo=0.0, hi=89.0),
        seed=rd.integer(bt, "seed", "blocks.seed", DEFAULTS["blocks.seed"], 0, 2**63 - 1),
    )
    spec.kn = rd.number(bt, "kn", "blocks.kn", default=DEFAULTS["blocks.kn"], positive=True, **STIFF)
    spec.ks = rd.number(bt, "ks", "blocks.ks", positive=True, **STIFF) if "ks" in bt else None
    spec.damping = rd.number(bt, "damping", "blocks.damping", default=DEFAULTS["blocks.damping"], nonneg=True, hi=1.0)
    spec.density = rd.number(bt, "density", "blocks.density", default=DEFAULTS["blocks.density"], positive=True,
                             hi=1e40, unit=" kg/m3")
    spec.joint = Law(
        rd.number(bt, "joint_friction", "blocks.joint_friction", default=DEFAULTS["blocks.joint_friction"], lo=0.0,
                  hi=89.0),
        rd.number(bt, "joint_cohesion", "blocks.joint_cohesion", default=DEFAULTS["blocks.joint_cohesion"],
                  nonneg=True, **STRESS),
        rd.number(bt, "joint_tensile", "blocks.joint_tensile", default=DEFAULTS["blocks.joint_tensile"],
                  nonneg=True, **STRESS))
    spec.laws = _read_laws(rd, bt, spec)
    spec.run = _read_run(rd, bt, scene)
    sets = bt.get("joint_set", [])
    if not isinstance(sets, list):
        rd.err("blocks.joint_set", sets, "must be an array of tables ([[blocks.joint_set]])")
    seen = {}
    for k, js in enumerate(sets):
        s = _read_set(rd, js, f"blocks.joint_set[{k}]", k, scene.domain)
        if s.name in seen:
            rd.err(f"blocks.joint_set[{k}].name", s.name, f"repeats the name of blocks.joint_set[{seen[s.name]}]")
        seen[s.name] = k
        spec.joint_sets.append(s)
    known = discontinuity_names(scene) | set(seen)
    for k, name in enumerate(spec.laws):
        if name not in known:
            rd.err(f"blocks.law[{k}].name", name, "names no [[discontinuity]], [[joint_set]] or [[blocks.joint_set]] "
                   "of the scene" + (f" (known: {', '.join(sorted(known)[:12])})" if known else " (the scene has none)"))
    return spec


def _read_laws(rd, bt, spec):
    laws = {}
    raw = bt.get("law", [])
    if not isinstance(raw, list) or any(not isinstance(t, dict) for t in raw):
        rd.err("blocks.law", raw, "must be an array of tables ([[blocks.law]])")
    for k, lt in enumerate(raw):
        key = f"blocks.law[{k}]"
        rd.known(lt, LAW_KEYS, key)
        name = rd.string(lt, "name", f"{key}.name", "")
        if not name:
            rd.err(f"{key}.name", name, "missing: the name of a discontinuity, joint set or fault")
        if name in laws:
            rd.err(f"{key}.name", name, "a second law for the same name")
        j = spec.joint
        laws[name] = Law(
            rd.number(lt, "friction", f"{key}.friction", default=j.friction, lo=0.0, hi=89.0),
            rd.number(lt, "cohesion", f"{key}.cohesion", default=j.cohesion, nonneg=True, **STRESS),
            rd.number(lt, "tensile", f"{key}.tensile", default=j.tensile, nonneg=True, **STRESS),
            rd.number(lt, "kn", f"{key}.kn", positive=True, **STIFF) if "kn" in lt else None,
            rd.number(lt, "ks", f"{key}.ks", positive=True, **STIFF) if "ks" in lt else None)
    return laws


def default_run():
    """The [blocks.run] settings of a scene without that table (duration None: dda run needs one)."""
    d = DEFAULTS
    return {"duration": None, "dt": None, "safety": d["blocks.run.safety"], "gravity": np.array(d["blocks.run.gravity"]),
            "local_damping": d["blocks.run.local_damping"], "frames": d["blocks.run.frames"],
            "sleep": d["blocks.run.sleep"], "record_every": None, "fixed": list(d["blocks.run.fixed"]),
            "free_within": None, "free_near": None}


def _read_run(rd, bt, scene):
    rt = rd.table(bt, "run", "blocks.run")
    rd.known(rt, RUN_KEYS, "blocks.run")
    d = DEFAULTS
    run = {"duration": rd.number(rt, "duration", "blocks.run.duration", positive=True, hi=1e12, unit=" s")
           if "duration" in rt else None,
           "dt": rd.number(rt, "dt", "blocks.run.dt", default=d["blocks.run.dt"], nonneg=True, unit=" s") or None,
           "safety": rd.number(rt, "safety", "blocks.run.safety", default=d["blocks.run.safety"], positive=True,
                               hi=1.0),
           "gravity": rd.vector(rt, "gravity", "blocks.run.gravity", default=d["blocks.run.gravity"]),
           "local_damping": rd.number(rt, "local_damping", "blocks.run.local_damping",
                                      default=d["blocks.run.local_damping"], nonneg=True, hi=0.99),
           "frames": rd.integer(rt, "frames", "blocks.run.frames", d["blocks.run.frames"], 1, 100000),
           "sleep": rd.boolean(rt, "sleep", "blocks.run.sleep", d["blocks.run.sleep"])}
    run["fixed"] = rd.value(rt, "fixed", "blocks.run.fixed", list(d["blocks.run.fixed"]), "list of strings")
    if not isinstance(run["fixed"], list) or any(f not in SIDES for f in run["fixed"]):
        rd.err("blocks.run.fixed", run["fixed"], f"must be a list drawn from {', '.join(SIDES)} (domain faces)")
    run["free_within"], run["free_near"] = None, None
    if "free_within" in rt:
        run["free_within"] = rd.number(rt, "free_within", "blocks.run.free_within", positive=True, hi=MAX_COORD,
                                       unit=" m")
        surfaces = [o.name for o in scene.excavations] + [o.name for o in getattr(scene, "cavities", [])]
        near = rd.value(rt, "free_near", "blocks.run.free_near", surfaces, "list of strings")
        if not isinstance(near, list) or not near or any(not isinstance(x, str) for x in near):
            rd.err("blocks.run.free_near", near, "must be a non-empty list of [[excavation]] or [[cavity]] names")
        for i, x in enumerate(near):
            if x not in surfaces:
                rd.err(f"blocks.run.free_near[{i}]", x, "names no [[excavation]] or [[cavity]] of the scene (known: "
                       + (", ".join(surfaces) or "none") + ")")
        run["free_near"] = near
    elif "free_near" in rt:
        rd.err("blocks.run.free_near", rt["free_near"], "needs blocks.run.free_within (the distance, m)")
    run["record_every"] = None
    if "record_every" in rt:
        run["record_every"] = rd.number(rt, "record_every", "blocks.run.record_every", positive=True, unit=" s")
        if run["duration"] is not None and run["record_every"] > run["duration"]:
            rd.err("blocks.run.record_every", run["record_every"],
                   f"must not exceed blocks.run.duration = {run['duration']:g} s")
    return run


def discontinuity_names(scene):
    """Names cut_by may give: [[discontinuity]] discs and surfaces, and the fracture network's sets."""
    names = {d.name for d in scene.discontinuities} | {s.name for s in scene.surfaces}
    dfn = getattr(scene, "dfn", None)
    if dfn is not None:
        names |= {s.name for s in dfn.sets}
        if dfn.network is not None:
            names |= set(dfn.network.set_names)
    return names
