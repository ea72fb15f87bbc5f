"""Lattice packings described as column families.

A lattice is a union of *families*; a family is a set of vertical columns at
plan positions (x, y) whose spheres sit at z = za + zb * (c0 + c1 * m),
m = 0 .. nz-1.  Excavation works column by column, so only the spheres that are
kept are ever produced (see sgim/_excavate.py).

* cubic: the paper's equations (1)-(2): I, J, K = round(extent / 2r) and
  x = x1 + r (2k - 1), y = y1 + r (2j - 1), z = z1 + r (2i - 1).
* hexagonal: hexagonal close packing (ABAB...), density 0.7405.
* fcc: face-centred cubic as close-packed ABC layers, density 0.7405.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Family:
    cx: np.ndarray  # (ncol,) column x
    cy: np.ndarray  # (ncol,) column y
    za: float
    zb: float
    c0: int
    c1: int
    nz: int

    def z(self, m):
        return self.za + self.zb * (self.c0 + self.c1 * np.asarray(m))


@dataclass
class Lattice:
    kind: str
    radius: float
    families: list
    coordination: int  # neighbours of an interior sphere

    @property
    def n_sites(self) -> int:
        return int(sum(len(f.cx) * f.nz for f in self.families))

    def all_centres(self) -> np.ndarray:
        """Every lattice site (the full cuboid): for tests and small scenes only."""
        out = []
        for f in self.families:
            z = f.z(np.arange(f.nz))
            out.append(np.column_stack([np.repeat(f.cx, f.nz), np.repeat(f.cy, f.nz), np.tile(z, len(f.cx))]))
        return np.concatenate(out) if out else np.empty((0, 3))


def round_half_up(v: float) -> int:
    return int(math.floor(v + 0.5))


def _count(length, first, step):
    """Number of sites first, first+step, ... that stay <= length (sphere inside the box)."""
    if length < first - 1e-9 * step:
        return 0
    return int(math.floor((length - first) / step + 1e-9)) + 1


def cubic_lattice(lo, hi, r) -> Lattice:
    x1, y1, z1 = lo
    x2, y2, z2 = hi
    I = round_half_up((z2 - z1) / (2 * r))  # noqa: E741  (paper's names)
    J = round_half_up((y2 - y1) / (2 * r))
    K = round_half_up((x2 - x1) / (2 * r))
    k = np.arange(1, K + 1)
    j = np.arange(1, J + 1)
    xs = x1 + r * (2 * k - 1)
    ys = y1 + r * (2 * j - 1)
    cx = np.tile(xs, J)
    cy = np.repeat(ys, K)
    fam = Family(cx, cy, float(z1), float(r), 1, 2, int(I))
    return Lattice("cubic", r, [fam], 6)


def close_packed_lattice(lo, hi, r, stacking: str) -> Lattice:
    """Close-packed layers (triangular nets) stacked as 'AB' (hcp) or 'ABC' (fcc)."""
    x1, y1, z1 = lo
    x2, y2, z2 = hi
    dx, dy, h = 2 * r, r * math.sqrt(3.0), 2 * r * math.sqrt(2.0 / 3.0)
    nlay = _count(z2 - z1 - r, r, h)
    shifts = {"A": (0.0, 0.0), "B": (r, r / math.sqrt(3.0)), "C": (0.0, 2 * r / math.sqrt(3.0))}
    period = len(stacking)
    fams = []
    for s, letter in enumerate(stacking):
        nz = len(range(s, nlay, period))
        if nz == 0:
            continue
        sx, sy = shifts[letter]
        cxs, cys = [], []
        nrow = _count(y2 - y1 - r - sy, r, dy)
        for row in range(nrow):
            off = sx + (r if row % 2 else 0.0)
            off = off % dx
            ncol = _count(x2 - x1 - r - off, r, dx)
            cxs.append(x1 + r + off + dx * np.arange(ncol))
            cys.append(np.full(ncol, y1 + r + sy + dy * row))
        if not cxs:
            continue
        fams.append(Family(np.concatenate(cxs), np.concatenate(cys), float(z1 + r), float(h), s, period, nz))
    return Lattice("hexagonal" if stacking == "AB" else "fcc", r, fams, 12)


def make_lattice(kind, lo, hi, r) -> Lattice:
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    if kind == "cubic":
        return cubic_lattice(lo, hi, r)
    if kind == "hexagonal":
        return close_packed_lattice(lo, hi, r, "AB")
    if kind == "fcc":
        return close_packed_lattice(lo, hi, r, "ABC")
    raise ValueError(f"unknown packing kind {kind!r}")


def lattice_counts(kind, lo, hi, r):
    """(sites, columns) of make_lattice(kind, lo, hi, r) without building it: the same counting rules in
    closed form (a close-packed family has two row kinds, even and odd, each with its own column count), so
    that a domain of 10^12 sites is counted in microseconds (sgim/limits.py)."""
    x1, y1, z1 = (float(v) for v in lo)
    x2, y2, z2 = (float(v) for v in hi)
    r = float(r)
    if kind == "cubic":
        nz = round_half_up((z2 - z1) / (2 * r))
        ncol = round_half_up((y2 - y1) / (2 * r)) * round_half_up((x2 - x1) / (2 * r))
        return ncol * nz, ncol
    if kind not in ("hexagonal", "fcc"):
        raise ValueError(f"unknown packing kind {kind!r}")
    stacking = "AB" if kind == "hexagonal" else "ABC"
    dx, dy, h = 2 * r, r * math.sqrt(3.0), 2 * r * math.sqrt(2.0 / 3.0)
    nlay = _count(z2 - z1 - r, r, h)
    shifts = {"A": (0.0, 0.0), "B": (r, r / math.sqrt(3.0)), "C": (0.0, 2 * r / math.sqrt(3.0))}
    period = len(stacking)
    sites = columns = 0
    for s, letter in enumerate(stacking):
        nz = len(range(s, nlay, period))
        if nz == 0:
            continue
        sx, sy = shifts[letter]
        nrow = _count(y2 - y1 - r - sy, r, dy)
        ncol = 0
        for parity, rows in ((0, (nrow + 1) // 2), (1, nrow // 2)):
            off = (sx + (r if parity else 0.0)) % dx
            ncol += rows * _count(x2 - x1 - r - off, r, dx)
        columns += ncol
        sites += ncol * nz
    return sites, columns


def lattice_for(scene) -> Lattice:
    return make_lattice(scene.packing.kind, scene.domain.min, scene.domain.max, scene.packing.radius)
