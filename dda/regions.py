"""Sphere regions of DDA scenes: the cuts ("z>2.6", all of which must hold), planes (below = [dip,
dip_direction, x, y, z]) and the masks they select, for [spheres] fixed / fixed_below, [[spheres.load]]
(dda/scene.py) and the [[report]] answers (dda/answers.py).
"""
from __future__ import annotations

import numpy as np

from sgim.portable import matmul
from sgim.scene import parse_cut


class SphereLoadError(ValueError):
    """A [[spheres.load]] table that does not fit the model: ``key``, ``value`` and the message."""

    def __init__(self, key, value, message):
        super().__init__(message)
        self.key, self.value = key, value


def _cut_mask(c, cut):
    """Spheres at `c` on the kept side of one parsed cut ("z>2.6": (axis, sign, value))."""
    axis, sign, value = cut
    return sign * (c[:, axis] - value) > 0


def region_mask(centers, cuts):
    """Mask of the spheres at `centers` inside a sphere region: every cut of `cuts` holds."""
    c = np.asarray(centers, float).reshape(-1, 3)
    mask = np.ones(len(c), bool)
    for cut in cuts:
        mask &= _cut_mask(c, cut)
    return mask


def fixed_mask(centers, cuts, below):
    """[spheres] fixed flags of the spheres at `centers`: inside any fixed cut ("z>2.6") or below any
    fixed_below plane ((normal, point) pairs)."""
    c = np.asarray(centers, float).reshape(-1, 3)
    fixed = np.zeros(len(c), bool)
    for cut in cuts:
        fixed |= _cut_mask(c, cut)
    for normal, point in below:
        fixed |= matmul(c - point, normal) < 0
    return fixed


def load_region(load, centers):
    """Mask of the spheres at `centers` inside the region of one parsed [[spheres.load]] table."""
    kind, spec = load["region"]
    if kind == "below":
        normal, point = spec
        return matmul(np.asarray(centers, float).reshape(-1, 3) - point, normal) < 0
    return region_mask(centers, spec)


def sphere_load_arrays(loads, centers, fixed):
    """(force, prescribed, velocity) of parsed [[spheres.load]] tables on the spheres at `centers` (see
    DDAScene.sphere_loads). SphereLoadError for a region without a sphere, a fixed sphere in a loaded region,
    or a sphere under a velocity load and another load."""
    c = np.asarray(centers, float).reshape(-1, 3)
    n = len(c)
    fixed = np.asarray(fixed, bool)
    force = np.zeros((n, 3))
    velocity = np.zeros((n, 3))
    by = np.full(n, -1, np.int64)  # the first load of each sphere
    prescribed = np.zeros(n, bool)
    for k, load in enumerate(loads):
        key, shown = load["key"], load["shown"]
        mask = load_region(load, c)
        where = f"{key}.{load['where']}"
        if not mask.any():
            raise SphereLoadError(where, shown, "no sphere in region")
        if (mask & fixed).any():
            raise SphereLoadError(where, shown, f"{int((mask & fixed).sum())} of its {int(mask.sum())} spheres are "
                                  "fixed ([spheres] fixed / fixed_below): a sphere cannot be both fixed and loaded")
        clash = mask & (prescribed if load["kind"] == "force" else (by >= 0))
        if clash.any():
            other = loads[int(by[np.flatnonzero(clash)[0]])]["key"]
            raise SphereLoadError(where, shown, f"{int(clash.sum())} of its spheres are also loaded by {other}: a "
                                  "sphere with a prescribed velocity takes no other load")
        by[mask & (by < 0)] = k
        if load["kind"] == "force":
            force[mask] += load["value"]
        else:
            prescribed |= mask
            velocity[mask] = load["value"]
    return force, prescribed, velocity


def read_region_cuts(rd, value, key):
    """A sphere region: "z>2.6" or a list of such cuts, all of which must hold -> [(axis, sign, value), ...]."""
    exprs = [value] if isinstance(value, str) else value
    if not isinstance(exprs, list) or not exprs:
        rd.err(key, value, 'must be a string like "z>2.6" or a list of them (all must hold)')
    cuts = []
    for e in exprs:
        try:
            cuts.append(parse_cut(e))
        except ValueError as exc:
            rd.err(key, e, str(exc))
    return cuts
