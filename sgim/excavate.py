"""Generate the kept lattice sites of a scene (basic model + excavation in one pass)."""
from __future__ import annotations

import numpy as np

from . import _excavate as K
from .geometry import paper_facets
from .packing import Lattice

RULE_CODES = {"paper": K.RULE_PAPER, "exact": K.RULE_EXACT}


class FacetSet:
    """All excavating facets of a scene as flat arrays for the kernels."""

    def __init__(self, surfaces):
        verts, faces, rules = [], [], []
        base = 0
        for s in surfaces:
            verts.append(s.vertices)
            faces.append(s.faces + base)
            rules.append(np.full(len(s.faces), RULE_CODES[s.rule]))
            base += len(s.vertices)
        if verts:
            v = np.concatenate(verts).astype(float)
            f = np.concatenate(faces).astype(np.int64)
            rule = np.concatenate(rules)
        else:
            v, f, rule = np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0)
        self.n = len(f)
        self.pc = paper_facets(v, f) if self.n else np.zeros((0, 34))
        p0 = v[f[:, 0]]
        e1 = v[f[:, 1]] - p0
        e2 = v[f[:, 2]] - p0
        n = np.cross(e1, e2)
        self.ec = np.ascontiguousarray(np.hstack([p0, e1, e2, n])) if self.n else np.zeros((0, 12))
        tri = v[f]
        fb = np.zeros((self.n, 8))
        if self.n:
            fb[:, 0], fb[:, 1] = tri[:, :, 0].min(1), tri[:, :, 0].max(1)
            fb[:, 2], fb[:, 3] = tri[:, :, 1].min(1), tri[:, :, 1].max(1)
            fb[:, 4], fb[:, 5] = tri[:, :, 2].min(1), tri[:, :, 2].max(1)
            paper = rule == K.RULE_PAPER
            nn = np.where(paper[:, None], self.pc[:, :3], n)
            nz = np.abs(nn[:, 2])
            with np.errstate(divide="ignore"):
                fb[:, 6] = np.where(nz > 0, np.linalg.norm(nn, axis=1) / np.where(nz > 0, nz, 1.0), np.inf)
            fb[:, 7] = rule
        self.fb = np.ascontiguousarray(fb)

    def removed(self, pts, r):
        """Brute force over every facet (small point sets)."""
        if self.n == 0:
            return np.zeros(len(pts), bool)
        return K.removed_mask(self.pc, self.ec, self.fb, np.ascontiguousarray(pts, dtype=float), float(r))


def kept_sites(lattice: Lattice, facets: FacetSet, lo, hi, progress=None):
    """Centres of the lattice sites that survive excavation, in (family, column, z) order."""
    r = lattice.radius
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    span = float(np.max(hi - lo))
    eps = 1e-9 * max(span, 1.0)
    tol = 1e-7
    if facets.n:
        sizes = np.maximum(facets.fb[:, 1] - facets.fb[:, 0], facets.fb[:, 3] - facets.fb[:, 2])
        gs = max(float(np.median(sizes)), 2 * r, span / 2000.0)
    else:
        gs = span
    gnx = int((hi[0] - lo[0]) / gs) + 1
    gny = int((hi[1] - lo[1]) / gs) + 1
    pad = r + 2 * eps + 1e-9 * span
    cell_start, cell_facets = K.bin_facets(facets.fb, lo[0], lo[1], gs, gnx, gny, pad)
    bins = K.Bins(facets.pc, facets.ec, facets.fb, cell_start, cell_facets, lo[0], lo[1], gs, gnx, gny)
    parts = []
    for fam in lattice.families:
        args = (bins, fam.cx, fam.cy, K.Steps(fam.za, fam.zb, fam.c0, fam.c1, fam.nz), r, eps, tol)
        counts = K.column_sites(*args, np.zeros(0, np.int64), np.empty((0, 3)))
        offsets = np.zeros(len(counts) + 1, np.int64)
        np.cumsum(counts, out=offsets[1:])
        out = np.empty((int(offsets[-1]), 3))
        K.column_sites(*args, offsets, out)
        parts.append(out)
        if progress:
            progress(f"family {len(parts)}/{len(lattice.families)}: {len(out)} spheres kept")
    return np.concatenate(parts) if len(parts) > 1 else parts[0]
