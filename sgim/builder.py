"""The SGIM pipeline: scene -> lattice -> excavation -> cutting -> bonds -> SphereModel."""
from __future__ import annotations

import json
import time

import numpy as np

from .common import __version__
from .cavities import carve
from .cutting import Discs, SphereGrid, apply_bond_rule, colours, membership, touching_pairs
from .excavate import FacetSet, kept_sites
from .limits import check_build
from .machine import machine_info
from .model import SphereModel
from .packing import lattice_for
from .surfdisc import membership_with_surfaces, surface_arrays, surface_geometric_cuts


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


def build_model(scene, progress=None, timer=None, max_spheres=None, estimate=None) -> SphereModel:
    """Build the bonded sphere model of a validated scene.

    The spheres and memory are estimated first (sgim/limits.py): past the scene's [limits] max_spheres (or
    `max_spheres`, the --max-spheres value) or the memory available, SceneError before anything is allocated.
    `estimate`: the Estimate of a check_build the caller has already made (the check is not repeated)."""
    tm = timer or Timer(progress)
    est = estimate if estimate is not None else check_build(scene, max_spheres=max_spheres, progress=tm.progress)
    if scene.packing.kind == "random":  # random dense packing of the kept region (sgim/rpack.py)
        from .rpack import build_random  # random packings only: the packer's kernels load when needed

        centres, radii, pack_meta, cavity_meta = build_random(scene, tm, region=est.region, near=est.near)
        n = len(centres)
    else:
        lat = lattice_for(scene)
        facets = FacetSet(scene.excavations)
        centres = kept_sites(lat, facets, scene.domain.min, scene.domain.max)
        centres, cavity_meta = carve(scene.cavities, centres, lat.radius)  # inner excavations
        n = len(centres)
        radii = np.full(n, lat.radius)
        tm.lap("excavate", f"{n} of {lat.n_sites} lattice sites kept ({len(lat.families)} column families, "
                           f"{facets.n} facets)")
        pack_meta = {"kind": lat.kind, "radius": lat.radius, "lattice_sites": lat.n_sites,
                     "coordination": lat.coordination}

    tol = scene.bonds.tolerance
    rmax = float(radii.max()) if n else 1.0
    grid = SphereGrid.build(centres, 2.0 * rmax * (1.0 + tol) * (1 + 1e-12))
    discs, network = _with_network(scene, Discs.from_scene(scene.discontinuities), tm)
    mem = membership(centres, radii, grid, discs)
    mem = membership_with_surfaces(mem, scene.surfaces, len(discs), centres, radii, grid)
    colour, source = colours(n, mem)
    tm.lap("cut", f"{len(discs) + len(scene.surfaces)} discontinuities, {len(mem.sphere)} memberships")

    bonds, bond_start = touching_pairs(centres, radii, grid, tol)
    bonded, cut_by = apply_bond_rule(scene.bonds.rule, centres, radii, grid, bonds, bond_start, colour, source,
                                     mem, discs, tol)
    if scene.bonds.rule == "geometric" and scene.surfaces:
        cut_by = surface_geometric_cuts(cut_by, scene.surfaces, len(discs), centres, radii, grid, bonds, bond_start,
                                        tol)
        bonded = cut_by < 0
    tm.lap("bonds", f"{len(bonds)} touching pairs, {int(bonded.sum())} bonded ({scene.bonds.rule} rule)")

    meta = {
        "generator": f"sgim {__version__}",
        "scene": scene.name,
        "scene_path": str(scene.path),
        "domain": [scene.domain.min.tolist(), scene.domain.max.tolist()],
        "packing": pack_meta,
        "excavation": [{"name": s.name, "rule": s.rule, "facets": int(len(s.faces))} for s in scene.excavations],
        "bonds": {"rule": scene.bonds.rule, "tolerance": tol},
    }
    if network is not None:
        meta["dfn"] = network.summary()
    if cavity_meta:
        meta["cavities"] = cavity_meta
    if scene.surfaces:
        meta["surfaces"] = [{"name": s.name, "index": len(discs) + k, "source": s.source, "thickness": s.thickness,
                             "faces": int(s.mesh.n_faces), **s.params} for k, s in enumerate(scene.surfaces)]
    return SphereModel(
        centers=centres, radii=radii, colour=colour, colour_source=source,
        bonds=bonds, bonded=bonded, cut_by=cut_by,
        member_sphere=mem.sphere, member_disc=mem.disc, member_kind=mem.kind, member_offset=mem.offset,
        disc_centre=discs.centres, disc_normal=discs.normals, disc_radius=discs.radii,
        disc_thickness=discs.thickness, disc_name=discs.names, meta=meta, scene_toml=scene.text,
        surfaces=surface_arrays(scene.surfaces, len(discs)) if scene.surfaces else {},
    )


def _with_network(scene, discs, tm):
    """Append the scene's fracture network (sampled from its joint sets or read from its file) to the
    hand-written discs; the network is kept on the scene for the output files."""
    if getattr(scene, "dfn", None) is None:
        return discs, None
    from .dfn import append_discs, network_for  # scenes with a fracture network only

    t0 = time.perf_counter()
    network = network_for(scene, progress=tm.progress)
    tm.t["dfn"] = time.perf_counter() - t0
    tm._last += tm.t["dfn"]  # the "cut" lap leaves the network's time out
    if tm.progress:
        tm.progress(f"{'dfn':<10s} {tm.t['dfn']:7.2f} s  {len(network)} fractures ({network.source})")
    return append_discs(discs, network), network


def summary(model: SphereModel, timings: dict) -> dict:
    """Counts, the model's meta, the stage timings and the machine they were measured on."""
    return {**model.counts(), "meta": model.meta, "timings_s": {k: round(v, 4) for k, v in timings.items()},
            "machine": machine_info()}


def summary_json(model, timings):
    return json.dumps(summary(model, timings), indent=2)
