"""Cutting by discontinuities (colours, membership) and bonds with their rules."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _cut as K


@dataclass
class SphereGrid:
    """Uniform grid over sphere centres (cell >= the largest bond length)."""

    start: np.ndarray
    order: np.ndarray
    origin: np.ndarray
    cell: float
    dims: np.ndarray

    @classmethod
    def build(cls, centres, cell):
        if len(centres) == 0:
            lo = np.zeros(3)
            dims = np.ones(3, np.int64)
        else:
            lo = centres.min(0)
            dims = (np.floor((centres.max(0) - lo) / cell).astype(np.int64) + 1)
        start, order = K.build_grid(np.ascontiguousarray(centres), lo, float(cell), dims)
        return cls(start, order, lo, float(cell), dims)

    def args(self):
        return self.start, self.order, self.origin, self.cell, self.dims


@dataclass
class Discs:
    centres: np.ndarray  # (k, 3)
    normals: np.ndarray  # (k, 3) unit
    radii: np.ndarray  # (k,)
    thickness: np.ndarray  # (k,)
    names: list

    @classmethod
    def from_scene(cls, discs):
        k = len(discs)
        return cls(
            np.array([d.centre for d in discs], float).reshape(k, 3),
            np.array([d.normal for d in discs], float).reshape(k, 3),
            np.array([d.radius for d in discs], float),
            np.array([d.thickness for d in discs], float),
            [d.name for d in discs],
        )

    def __len__(self):
        return len(self.radii)


@dataclass
class Membership:
    sphere: np.ndarray  # (k,) int64
    disc: np.ndarray  # (k,) int32
    kind: np.ndarray  # (k,) int8: 1 inside (red), 2 green side, 3 blue side
    offset: np.ndarray  # (k,) float64 signed distance S.(O - M), 0 on the plane (sgim/_cut.py: ties)

    def csr(self, n):
        """Rows regrouped by sphere: (start (n+1,), permutation)."""
        perm = np.argsort(self.sphere, kind="stable")
        start = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(self.sphere, minlength=n), out=start[1:])
        return start, perm


def membership(centres, radii, grid: SphereGrid, discs: Discs) -> Membership:
    if len(discs) == 0 or len(centres) == 0:
        return Membership(np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int8), np.zeros(0))
    rmax = float(radii.max())
    args = (centres, radii, *grid.args(), discs.centres, discs.normals, discs.radii, discs.thickness, rmax)
    counts = K.disc_members(*args, np.zeros(0, np.int64), np.empty(0, np.int64), np.empty(0, np.int8), np.empty(0))
    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    tot = int(offsets[-1])
    s = np.empty(tot, np.int64)
    k = np.empty(tot, np.int8)
    o = np.empty(tot)
    K.disc_members(*args, offsets, s, k, o)
    disc = np.repeat(np.arange(len(discs), dtype=np.int32), counts)
    # within a disc, order rows by sphere (the grid walk order is arbitrary)
    perm = np.lexsort((s, disc))
    return Membership(s[perm], disc[perm], k[perm], o[perm])


def colours(n, mem: Membership):
    return K.colours_from_members(n, mem.sphere, mem.disc, mem.kind, mem.offset)


def touching_pairs(centres, radii, grid: SphereGrid, tol):
    if len(radii) and float(radii.max()) > 2.0 * float(radii.min()):
        # unequal radii: a uniform grid of cell 2 r_max holds too many small spheres per cell;
        # the multi-level grid of sgim/rpack.py gives the same pairs in the same order (imported here: the
        # random packer's modules load only when needed, as in sgim/builder.py)
        from .rpack import contact_pairs

        return contact_pairs(centres, radii, tol)
    counts = K.sphere_pairs(centres, radii, *grid.args(), float(tol), np.zeros(0, np.int64), np.empty((0, 2), np.int64))
    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    out = np.empty((int(offsets[-1]), 2), np.int64)
    K.sphere_pairs(centres, radii, *grid.args(), float(tol), offsets, out)
    return out, offsets


def apply_bond_rule(rule, centres, radii, grid, bonds, bond_start, colour, source, mem: Membership, discs: Discs,
                    tol):
    """(bonded, cut_by): cut_by holds the discontinuity index that cut each pair, -1 if bonded."""
    if rule == "colour":
        ci, cj = colour[bonds[:, 0]], colour[bonds[:, 1]]
        cut = (ci == 1) | (cj == 1) | ((ci == 2) & (cj == 3)) | ((ci == 3) & (cj == 2))
        start, perm = mem.csr(len(centres))
        cut_by = K.green_blue_cutter(bonds, cut, colour, source, start, mem.disc[perm], mem.kind[perm],
                                     mem.offset[perm])
    elif rule == "geometric":
        lmax = 2.0 * float(radii.max()) * (1.0 + tol) if len(radii) else 0.0
        cut_by = K.geometric_cuts(centres, radii, *grid.args(), bond_start, bonds, colour, source,
                                  discs.centres, discs.normals, discs.radii, discs.thickness, lmax)
    else:
        raise ValueError(f"unknown bond rule {rule!r}")
    return cut_by < 0, cut_by
