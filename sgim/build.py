"""The SGIM pipeline: scene -> lattice -> excavation -> cutting -> bonds -> SphereModel."""
from __future__ import annotations

import json
import time

import numpy as np

from . import __version__
from .cutting import Discs, SphereGrid, apply_bond_rule, colours, membership, touching_pairs
from .excavate import FacetSet, kept_sites
from .model import SphereModel
from .packing import lattice_for


class Timer:
    def __init__(self, progress=None):
        self.t = {}
        self.progress = progress
        self._t0 = time.perf_counter()
        self._last = self._t0

    def lap(self, name, detail=""):
        now = time.perf_counter()
        self.t[name] = now - self._last
        self._last = now
        if self.progress:
            self.progress(f"{name:<10s} {self.t[name]:7.2f} s  {detail}")

    @property
    def total(self):
        return time.perf_counter() - self._t0


def build_model(scene, progress=None, timer=None) -> SphereModel:
    """Build the bonded sphere model of a validated scene."""
    tm = timer or Timer(progress)
    lat = lattice_for(scene)
    facets = FacetSet(scene.excavations)
    centres = kept_sites(lat, facets, scene.domain.min, scene.domain.max)
    n = len(centres)
    radii = np.full(n, lat.radius)
    tm.lap("excavate", f"{n} of {lat.n_sites} lattice sites kept ({len(lat.families)} column families, "
                       f"{facets.n} facets)")

    tol = scene.bonds.tolerance
    grid = SphereGrid.build(centres, 2.0 * lat.radius * (1.0 + tol) * (1 + 1e-12))
    discs = Discs.from_scene(scene.discontinuities)
    mem = membership(centres, radii, grid, discs)
    colour, source = colours(n, mem)
    tm.lap("cut", f"{len(discs)} discontinuities, {len(mem.sphere)} memberships")

    bonds, bond_start = touching_pairs(centres, radii, grid, tol)
    bonded, cut_by = apply_bond_rule(scene.bonds.rule, centres, radii, grid, bonds, bond_start, colour, source,
                                     mem, discs, tol)
    tm.lap("bonds", f"{len(bonds)} touching pairs, {int(bonded.sum())} bonded ({scene.bonds.rule} rule)")

    meta = {
        "generator": f"sgim {__version__}",
        "scene": scene.name,
        "scene_path": str(scene.path),
        "domain": [scene.domain.min.tolist(), scene.domain.max.tolist()],
        "packing": {"kind": lat.kind, "radius": lat.radius, "lattice_sites": lat.n_sites,
                    "coordination": lat.coordination},
        "excavation": [{"name": s.name, "rule": s.rule, "facets": int(len(s.faces))} for s in scene.excavations],
        "bonds": {"rule": scene.bonds.rule, "tolerance": tol},
    }
    return SphereModel(
        centers=centres, radii=radii, colour=colour, colour_source=source,
        bonds=bonds, bonded=bonded, cut_by=cut_by,
        member_sphere=mem.sphere, member_disc=mem.disc, member_kind=mem.kind, member_offset=mem.offset,
        disc_centre=discs.centres, disc_normal=discs.normals, disc_radius=discs.radii,
        disc_thickness=discs.thickness, disc_name=discs.names, meta=meta, scene_toml=scene.text,
    )


def summary(model: SphereModel, timings: dict) -> dict:
    return {**model.counts(), "meta": model.meta, "timings_s": {k: round(v, 4) for k, v in timings.items()}}


def summary_json(model, timings):
    return json.dumps(summary(model, timings), indent=2)
