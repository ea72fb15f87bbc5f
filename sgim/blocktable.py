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
}
BLOCK_KEYS = {"min_volume", "cut_by", "cohesion", "tensile", "friction", "seed", "joint_set"}
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
class BlocksSpec:
    min_volume: float
    cut_by: list | None  # names; None: every discontinuity and joint set of the scene
    cohesion: float
    tensile: float
    friction: float
    seed: int
    joint_sets: list = field(default_factory=list)


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
    return spec


def discontinuity_names(scene):
    """Names cut_by may give: [[discontinuity]] discs and surfaces, and the fracture network's sets."""
    names = {d.name for d in scene.discontinuities} | {s.name for s in scene.surfaces}
    dfn = getattr(scene, "dfn", None)
    if dfn is not None:
        names |= {s.name for s in dfn.sets}
        if dfn.network is not None:
            names |= set(dfn.network.set_names)
    return names
