"""Compile (or load) numba's cache of the kernels the suite uses, in two halves that run at once.

    python tests/warm_kernels.py sgim|dda WORKDIR

On a fresh machine numba compiles every kernel on its first call, one after the other, in the one process that
runs the tests: several minutes of the suite on one core while the other waits. tests/conftest.py starts both
halves as subprocesses when a whole-suite session begins, so the compilation runs on both cores; the tests then
load the kernels from the cache. A warm cache makes each half a few seconds. Nothing here is checked: the tests
check these code paths.
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
CASES = HERE.parent / "cases" / "scenes"


def warm_sgim(work: Path):
    """Lattice and random packings, excavations, cavities, discs, faults, surfaces, DFN, grading, statistics."""
    import sgim
    from portable_jobs import SGIM_SCENE
    from test_grading import SCENE as GRADED

    for name, text in (("portable", SGIM_SCENE), ("graded", GRADED.format(spread=""))):
        p = work / f"{name}.toml"
        p.write_text(text)
        sgim.build(p)
    for scene in ("open_pit_coarse.toml", "tunnel_jointed.toml", "studies/scenes/open_pit_dfn_small.toml"):
        s = sgim.load_scene(CASES / scene)
        if s.packing.kind != "random":  # a coarser lattice: the same kernels, less work
            s.packing.radius *= 4.0
        sgim.build(s)


def warm_dda(work: Path):
    """Block runs (rigid and deformable, FCP, friction, bonds), sphere runs (bonds, smooth joints, walls, moving
    blocks) and the in-house run of a deck."""
    import dda
    from adapters import SphereRun, export, run_inhouse

    for name in ("dda_wedge", "dda_deformable_column", "dda_toppling", "dda_spheres_block", "crossval/rocking",
                 "crossval/hang_joint"):
        scene = dda.load_scene(CASES / f"{name}.toml")
        scene.duration = scene.record_every = 0.002
        scene.frames = 1
        dda.run(scene)
    export(CASES / "crossval" / "column.toml", "yade", work / "deck", overrides={"duration": 0.002})
    run_inhouse(SphereRun.load(work / "deck" / "run.npz"))


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    {"sgim": warm_sgim, "dda": warm_dda}[sys.argv[1]](Path(sys.argv[2]))
