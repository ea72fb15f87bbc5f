"""Explicit 3D DDA engine: convex polyhedral blocks and the spheres of SGIM models (docs/ARCHITECTURE.md).

The Python API (docs/api.md)::

    import dda
    r = dda.run("cases/scenes/dda_incline.toml")     # nothing written; dda.run(scene, out="folder") writes
    r.answers, r.summary, r.results, r.simulation    # what `dda run` prints and writes
    scene = dda.load_scene("cases/scenes/dda_incline.toml")
    bs, sim = scene.build()                          # a BlockSystem and its Simulation, to step by hand
    sim.run(0.5)

Names are imported from their modules when first used: ``import dda`` stays light.
"""
import importlib

import sgim as _sgim  # noqa: F401  (numba's cache folder for this source version: sgim/kernel_cache.py)

__all__ = ["run", "load_scene", "RunOutcome", "BlockSystem", "Simulation", "ContactLaw", "SphereSet",
           "SphereSimulation", "BondLaw", "BlockSpec", "GENERATORS"]
_WHERE = {"run": "runner", "RunOutcome": "runner", "load_scene": "scene", "BlockSystem": "system",
          "Simulation": "simulation", "ContactLaw": "simulation", "SphereSet": "spheres",
          "SphereSimulation": "spheres", "BondLaw": "spheres", "BlockSpec": "blockspec", "GENERATORS": "generate"}


def __getattr__(name):
    if name in _WHERE:
        return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'dda' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
