"""The Python API in one walk, notebook style (docs/api.md): build a sphere model, run a DDA scene and read its
answer, export a bonded-sphere run to YADE, run it there and in-house, and compare.

    python -m cases.make.example_api OUTDIR   # about half a minute; YADE must be installed (./go sets it up)

Each step prints what it got; tests/test_api.py runs this script and checks the numbers against their
references.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

import adapters
import dda
import sgim
from cases import SCENES


def main(out):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    # --- 1. A sphere model from a scene given as a dict (the tables of a TOML file) ------------------------
    scene = {
        "name": "jointed_block",
        "domain": {"min": [0.0, 0.0, 0.0], "max": [2.0, 1.0, 1.0]},
        "packing": {"kind": "cubic", "radius": 0.05},
        "bonds": {"rule": "colour"},
        "discontinuity": [{"name": "joint", "centre": [1.0, 0.5, 0.5], "dip": 60.0, "dip_direction": 90.0,
                           "radius": 5.0, "thickness": 0.0}],
    }
    model = sgim.build(scene)
    c = model.counts()
    print(f"[1] sgim.build: {c['spheres']} spheres ({c['green']} green, {c['blue']} blue beside the joint), "
          f"{c['bonds']} contacts, {c['bonded']} bonded, {c['cut']} cut by the joint")
    model.save(out / "model.npz")
    again = sgim.load(out / "model.npz")
    assert np.array_equal(again.centers, model.centers) and np.array_equal(again.bonded, model.bonded)
    print(f"[1] sgim.load: {out / 'model.npz'} read back, {len(again.radii)} spheres")

    # --- 2. A DDA scene run in memory, and its answer ----------------------------------------------------------
    r = dda.run(SCENES / "dda_incline.toml")  # with out="folder" it writes what `dda run` writes
    (a,) = r.answers
    g, alpha, phi = 9.81, math.radians(30.0), math.radians(20.0)
    exact = 0.5 * g * (math.sin(alpha) - math.tan(phi) * math.cos(alpha)) * r.summary["time"] ** 2
    print(f"[2] dda.run: {r.headline}")
    print(f"[2] {a['label']}: {a['value']:.5f} m, analytical {exact:.5f} m ({100 * (a['value'] / exact - 1):+.3f} %)")

    # --- 3. The hanging column in YADE and in-house ------------------------------------------------------------
    info = adapters.export(SCENES / "crossval" / "column.toml", "yade", out / "deck", force=True)
    print(f"[3] adapters.export: {info['n']} spheres, {info['n_bonds']} bonds, {info['steps']} steps -> {out / 'deck'}")
    yade = adapters.run(out / "deck")
    mine = adapters.run_inhouse(adapters.SphereRun.load(out / "deck" / "run.npz"))
    dz_yade = float(np.mean(yade.displacement()[:, 2]))
    dz_mine = float(np.mean(mine.displacement()[:, 2]))
    print(f"[3] mean vertical displacement: YADE {dz_yade * 1e6:.3f} um, in-house {dz_mine * 1e6:.3f} um "
          f"({100 * (dz_mine / dz_yade - 1):+.3f} %)")
    same = adapters.load_result(out / "deck" / "result")
    assert np.array_equal(same.final_pos, yade.final_pos)
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1]))
