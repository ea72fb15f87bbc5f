"""Graded resolution: the sphere radius as a function of the distance to named objects.

``[packing.grading]`` (with ``[packing] kind = "random"``)::

    [packing.grading]
    near = ["pit"]            # names of [[excavation]] surfaces, [[cavity]] solids or [[discontinuity]] entries
    fine_radius = 0.25        # radius within fine_distance of the nearest named object
    coarse_radius = 2.0       # radius beyond coarse_distance
    fine_distance = 1.0
    coarse_distance = 20.0
    spread = 0.0              # optional: each radius times a factor uniform in [1 - spread, 1 + spread]

The law.  With d the distance from a sphere's centre to the nearest named object (for a
discontinuity with thickness t, the distance to its slab: distance to the disc or surface
minus t / 2, at least 0), t = (d - fine_distance) / (coarse_distance - fine_distance) clamped
to [0, 1] and the smoothstep s = t^2 (3 - 2t):

    r(d) = fine_radius * (coarse_radius / fine_radius) ** s

so the radius is fine_radius up to fine_distance, coarse_radius from coarse_distance on, and
changes geometrically in between with zero slope at both ends (a C1 transition).  The largest
relative change per metre is 1.5 ln(coarse/fine) / (coarse_distance - fine_distance).

Distances: to a triangulated surface (excavation, cavity, triangulated discontinuity) the true
point-to-triangle distance (sgim.meshquery); to a disc the distance to the flat disc of its
radius.  The packer evaluates the law at each sphere's final centre (sgim/_rpack.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _rpregion as K
from .meshquery import MeshSet, TriMesh
from .reader import LENGTH, SIZE


@dataclass
class Grading:
    near: list
    fine_radius: float
    coarse_radius: float
    fine_distance: float
    coarse_distance: float
    spread: float = 0.0
    objects: list = field(default_factory=list)  # resolved (kind, object) pairs, see resolve()

    @property
    def rmin(self):
        return self.fine_radius * (1.0 - self.spread)

    @property
    def rmax(self):
        return self.coarse_radius * (1.0 + self.spread)

    def radius(self, d):
        """The law r(d) (vectorised, numpy; without the spread factor)."""
        d = np.asarray(d, float)
        t = np.clip((d - self.fine_distance) / (self.coarse_distance - self.fine_distance), 0.0, 1.0)
        s = t * t * (3.0 - 2.0 * t)
        return self.fine_radius * (self.coarse_radius / self.fine_radius) ** s

    def params(self):
        return (float(self.fine_radius), float(self.coarse_radius), float(self.fine_distance),
                float(self.coarse_distance), float(self.spread))

    def meta(self):
        return {"near": list(self.near), "fine_radius": self.fine_radius, "coarse_radius": self.coarse_radius,
                "fine_distance": self.fine_distance, "coarse_distance": self.coarse_distance,
                "spread": self.spread,
                "law": "r = fine (coarse/fine)^s, s = t^2 (3 - 2t), t = (d - fine_distance)/(coarse_distance - "
                       "fine_distance) clamped to [0, 1]"}


def read_grading(rd, gt, key):
    """Parse a [packing.grading] table (the names are checked against the scene afterwards)."""
    rd.known(gt, {"near", "fine_radius", "coarse_radius", "fine_distance", "coarse_distance", "spread"}, key)
    near = gt.get("near")
    if isinstance(near, str):
        near = [near]
    if not isinstance(near, list) or not near or not all(isinstance(x, str) for x in near):
        rd.err(f"{key}.near", near, "must be a non-empty list of names of excavation surfaces, cavities or "
                                    "discontinuities")
    rf = rd.number(gt, "fine_radius", f"{key}.fine_radius", positive=True, **SIZE)
    rc = rd.number(gt, "coarse_radius", f"{key}.coarse_radius", positive=True, **SIZE)
    if rc < rf:
        rd.err(f"{key}.coarse_radius", rc, f"must be >= fine_radius = {rf:g}")
    if rc > 64 * rf:
        rd.err(f"{key}.coarse_radius", rc, f"at most 64 x fine_radius = {64 * rf:g}")
    df = rd.number(gt, "fine_distance", f"{key}.fine_distance", default=0.0, nonneg=True, **LENGTH)
    dc = rd.number(gt, "coarse_distance", f"{key}.coarse_distance", positive=True, **LENGTH)
    if dc <= df:
        rd.err(f"{key}.coarse_distance", dc, f"must exceed fine_distance = {df:g}")
    spread = rd.number(gt, "spread", f"{key}.spread", default=0.0, nonneg=True, hi=0.5)
    return Grading(list(near), rf, rc, df, dc, spread)


def scene_names(excavations, cavities, discontinuities, surfaces):
    """Names a grading may refer to -> kind."""
    out = {}
    for s in excavations:
        out[s.name] = "excavation"
    for c in cavities:
        out[c.name] = "cavity"
    for d in discontinuities:
        out[d.name] = "discontinuity"
    for s in surfaces:
        out[s.name] = "discontinuity"
    return out


class NearObjects:
    """The named objects of a grading as kernel arrays: meshes (sgim._meshq data + offsets) and discs."""

    def __init__(self, scene, grading):
        names = set(grading.near)
        meshes, offs = [], []
        dc, dn, dr, dh = [], [], [], []
        for s in scene.excavations:
            if s.name in names:
                meshes.append(TriMesh(s.vertices, s.faces, orient=False))
                offs.append(0.0)
        for c in getattr(scene, "cavities", []):
            if c.name in names:
                meshes.append(c.mesh)
                offs.append(0.0)
        for s in getattr(scene, "surfaces", []):
            if s.name in names:
                meshes.append(s.mesh)
                offs.append(s.thickness / 2.0)
        for d in scene.discontinuities:
            if d.name in names:
                dc.append(d.centre)
                dn.append(d.normal)
                dr.append(d.radius)
                dh.append(d.thickness / 2.0)
        self.n_meshes = len(meshes)
        self.D = MeshSet(meshes).kernel_data() if meshes else empty_mesh_data()
        self.goff = np.array(offs, float)
        k = len(dc)
        self.discs = (np.array(dc, float).reshape(k, 3), np.array(dn, float).reshape(k, 3),
                      np.array(dr, float).reshape(k), np.array(dh, float).reshape(k))

    def distance(self, points, dmax):
        """Distance of each point to the nearest named object (capped at dmax)."""
        pts = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
        return K.near_distance_many(self.D, self.goff, *self.discs, pts, float(dmax))


_EMPTY = None


def empty_mesh_data():
    """Mesh data with no mesh (the kernels loop over zero meshes)."""
    global _EMPTY
    if _EMPTY is None:
        D = TriMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])).kernel_data()
        _EMPTY = D[:12] + (np.zeros(0, np.int64), np.zeros(1, np.int64))
    return _EMPTY
