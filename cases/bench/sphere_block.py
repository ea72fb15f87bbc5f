"""Benchmark: spheres and moving blocks in one loop (dda/_coupled.py); a table on stdout, never a test.

    .venv/bin/python -m cases.bench.sphere_block [--steps 400]

Scene of size k: a fixed floor, k x k free cubes resting on it and, above each cube, a 3 x 3 x 3 lump of
spheres falling onto it (27 k^2 spheres, k^2 + 1 blocks). For each k, microseconds per step (median of three
runs after a warm-up) of
  coupled   spheres + moving blocks (SphereSimulation with the BlockSystem),
  spheres   the same spheres with the cubes turned into fixed walls (the sphere-only loop),
  blocks    the same blocks without spheres (dda.simulation),
and coupled / (spheres + blocks): the coupled loop costs about what its two parts cost alone, and the cost per
body stays flat as k grows (cost follows the contents).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from cases.bench.dda import _box
from sgim.machine import machine_line

# The DDA engine (spheres, system, simulation: numba kernels) is imported inside the functions that time it.


def _scene(k, fixed_cubes=False):
    from dda.spheres import SphereSet
    from dda.system import BlockSystem

    bs = BlockSystem()
    span = 1.0 * k
    bs.add_block(_box((-0.5, -0.5, -0.5), (span + 0.5, span + 0.5, 0.0), fixed=True), density=2600.0)
    centers = []
    for i in range(k):
        for j in range(k):
            x, y = i * 1.0 + 0.3, j * 1.0 + 0.3
            bs.add_block(_box((x - 0.2, y - 0.2, 0.0), (x + 0.2, y + 0.2, 0.4), fixed=fixed_cubes), density=2600.0)
            for a in range(3):
                for b in range(3):
                    for c in range(3):
                        centers.append((x + 0.1 * (a - 1), y + 0.1 * (b - 1), 0.5 + 0.1 * c))
    return bs, SphereSet(np.array(centers), np.full(len(centers), 0.045), density=2600.0)


def _time(sim, steps):
    sim.run(20 * sim.dt, record_every=20 * sim.dt)  # compile / warm up
    out = []
    for _ in range(3):
        n0 = sim.steps
        t = time.perf_counter()
        sim.run(steps * sim.dt, record_every=steps * sim.dt)
        out.append((time.perf_counter() - t) / (sim.steps - n0))
    return statistics.median(out) * 1e6


def main(argv=None):
    from dda.simulation import ContactLaw, Simulation
    from dda.spheres import SphereSimulation

    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--sizes", default="2,4,8,16")
    args = ap.parse_args(argv)
    law = ContactLaw(kn=1e7, friction_deg=30.0, damping=0.2)
    print(machine_line())
    print(f"{'k':>3} {'spheres':>8} {'blocks':>7} {'coupled us':>11} {'spheres us':>11} {'blocks us':>10} "
          f"{'ratio':>6} {'us/body':>8}")
    for k in [int(s) for s in args.sizes.split(",")]:
        bs, ss = _scene(k)
        sim = SphereSimulation(ss, law, walls=bs, gravity=(0, 0, -9.81))
        dt = sim.dt
        tc = _time(sim, args.steps)
        bs2, ss2 = _scene(k, fixed_cubes=True)
        ts = _time(SphereSimulation(ss2, law, walls=bs2, gravity=(0, 0, -9.81), dt=dt), args.steps)
        bs3, _ = _scene(k)
        tb = _time(Simulation(bs3, law, gravity=(0, 0, -9.81), dt=dt), args.steps)
        nbody = ss.n + k * k
        print(f"{k:3d} {ss.n:8d} {k * k + 1:7d} {tc:11.1f} {ts:11.1f} {tb:10.1f} {tc / (ts + tb):6.2f} "
              f"{tc / nbody:8.3f}")


if __name__ == "__main__":
    main()
