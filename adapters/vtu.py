"""The ``vtu`` export target: a SphereRun as two ParaView files, nothing to run.

``write_deck(run, folder)`` writes ``spheres.vtu`` (vertex cells with point data radius, colour, fixed and the
count of intact bonds of each sphere) and ``bonds.vtu`` (one line cell per bond with cell data kn and
tensile_force, -1 for an unbreakable bond). A run's result folder exports to ParaView frames instead
(adapters/frames.py).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from sgim.common import atomic_vtu


def write_vtu(run, folder):
    """spheres.vtu (vertex cells: radius, colour, fixed, intact-bond count) and bonds.vtu (one line per bond)."""
    import meshio  # lazy: meshio takes half a second to load, for this export only

    n = run.n
    nb = np.bincount(np.r_[run.bond_i, run.bond_j].astype(np.int64), minlength=n)
    pts = meshio.Mesh(run.centers, [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))],
                      point_data={"radius": run.radii, "colour": run.colour.astype(np.int32),
                                  "fixed": run.fixed.astype(np.int32), "bonds": nb.astype(np.int32)})
    lines = meshio.Mesh(run.centers, [("line", np.c_[run.bond_i, run.bond_j].astype(np.int64))],
                        cell_data={"kn": [run.bond_kn], "tensile_force": [np.where(np.isfinite(run.bond_ft),
                                                                                    run.bond_ft, -1.0)]})
    for name, mesh in (("spheres.vtu", pts), ("bonds.vtu", lines)):
        atomic_vtu(Path(folder) / name, mesh)


def write_deck(run, folder, variant=None):
    """The registry's writer (adapters/registry.py): write_vtu; no extra deck.json keys."""
    write_vtu(run, folder)
    return {}


__all__ = ["write_vtu", "write_deck"]
