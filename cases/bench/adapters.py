"""Benchmark: bonded-sphere decks stepped in-house, in LIGGGHTS and in YADE; a table on stdout, never a test.

    .venv/bin/python -m cases.bench.adapters [--n 100000] [--packing fcc,random] [--steps 200] [--repeats 3]
                                             [--yade-n 10000] [--yade-steps 20] [--skip ENGINES] [--quick]
                                             [--split] [--json OUT]

Each deck (--packing, default both): an sgim packing (radius 1 cm; ``fcc``: FCC lattice, 12 bonds per sphere;
``random``: sgim's random packing, about 6) of about --n spheres in a cube, every touching pair bonded
(unbreakable bonds kn = 1e6 N/m, ks = 4e5 N/m), the bottom layer fixed, gravity, linear contacts kn = 1e6 N/m
with friction 30 deg, dt = half the in-house critical step (adapters.spec.from_model). One SphereRun per deck,
so the engines step the same spheres, bonds, contact law and time step:

  dda       adapters.inhouse.run_inhouse: stepping wall and CPU time (the set-up excluded; the first pair-list
            build and the records included), with the full bond law (row "dda (normal+shear bonds)": normal
            and shear springs and torques);
  dda-central  the same run with bond_ks = 0: central-spring bonds, the physics of LIGGGHTS' harmonic bonds
            (row "dda (central bonds, as LIGGGHTS)", the like-for-like comparison);
  liggghts  adapters.deck.export(--to liggghts) + adapters.deck.run, 1 rank: wall = the sum of LIGGGHTS' own
            "Loop time" lines (stepping only; start-up, reading the data file and dumps excluded); CPU = the
            CPU time of the process minus that of the same deck 5 steps long (start-up and reading excluded);
  yade      the same deck built at --yade-n spheres (10^5 spheres take about 0.3 s per step and a 5-10 s
            bonding step), JCFpm: RunResult.extra["wall_run_s"] (the steps after the bonding step), one run.

The in-house engine and LIGGGHTS alternate, repeat by repeat (medians of --repeats), so that both see the same
machine load; the CPU-time columns are the steadier measure on a shared machine. Particle-steps per second =
spheres x steps / seconds; ratio = engine / LIGGGHTS. Each engine runs one process on one core. The bonds
differ in cost: full in-house bonds carry a normal and a shear spring and torques, LIGGGHTS' harmonic bonds
are central springs (adapters/liggghts.py), as the in-house central bonds (dda.spheres: ks = 0).
--split: for each in-house law, the kernel's time per step split into bonds, sphere contacts and the rest
(pair list, force reset, integration), from extra runs with the bond loops (and then the contact pairs)
left out. --quick: 10^4 spheres, 50 steps, one repeat, YADE at 2000 spheres.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import resource
import shutil
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from sgim.machine import machine_info, machine_line

# The code it times (sgim, dda, adapters: numba kernels) is imported inside the functions of each part, so that
# `--help` loads none of it and each part loads only what it runs.

RADIUS = 0.01
DENSITY = {"fcc": 0.7405, "random": 0.62}  # solid fraction of sgim's packings (random: measured)


def deck_model(n_target, packing="fcc", radius=RADIUS):
    """sgim model of about n_target spheres in a cube (FCC lattice or sgim's random packing), every touching
    pair bonded."""
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    side = (n_target * 4.0 / 3.0 * math.pi * radius ** 3 / DENSITY[packing]) ** (1.0 / 3.0)
    side *= 1.0 + 2.5 * radius / side  # the boundary layer holds fewer spheres
    d = {"name": f"{packing}{n_target}", "domain": {"min": [0.0, 0.0, 0.0], "max": [side, side, side]},
         "packing": {"kind": packing, "radius": radius}, "bonds": {"rule": "colour"}}
    return build_model(scene_from_dict(d, "bench.toml"))


def fcc_run(n_target, steps, packing="fcc"):
    from adapters.spec import from_model
    from dda.spheres import BondLaw

    model = deck_model(n_target, packing)
    z = np.asarray(model.centers)[:, 2]
    fixed = z < z.min() + 0.5 * RADIUS
    run = from_model(model, density=2600.0, fixed=fixed, bonds=BondLaw(kn=1e6, ks=4e5), kn=1e6, ks=4e5,
                     friction_deg=30.0, damping=0.0, gravity=(0.0, 0.0, -9.81), duration=1.0, name=f"fcc{n_target}")
    run.duration = steps * run.dt
    run.record_every = run.duration
    return run


LABELS = {"dda": "dda (normal+shear bonds)", "dda-central": "dda (central bonds, as LIGGGHTS)",
          "liggghts": "liggghts (harmonic bonds)", "yade": "yade (JCFpm)"}


def central_run(run):
    """The same run with central-spring bonds (bond_ks = 0, as LIGGGHTS' harmonic bonds), same time step."""
    return replace(run, bond_ks=np.zeros_like(np.asarray(run.bond_ks, float)))


def inhouse_split(run, steps):
    """Kernel time per step [s] of the in-house run: total, bonds, sphere contacts, rest (pair list, force
    reset, integration): `steps` steps timed on a fresh simulation (after its first step) with everything, without
    the bond loops, and without the bond loops and the listed contact pairs; medians of three rounds."""
    from adapters.inhouse import reordered, spatial_order

    local, _ = reordered(run, spatial_order(run.centers, run.radii))
    none = np.zeros(0, np.int64)
    t = {"total": [], "no_bonds": [], "no_bonds_no_contacts": []}
    for _ in range(3):
        for mode in t:
            _, sim = local.in_house()
            sim.run(sim.dt)
            npair = int(sim.nl_n[0])
            if mode != "total":
                sim.bond_full, sim.cbond_idx = none, none
            if mode == "no_bonds_no_contacts":
                sim.nl_n[0] = 0
            t0 = time.perf_counter()
            sim._chunk(steps)
            t[mode].append((time.perf_counter() - t0) / steps)
    m = {k: statistics.median(v) for k, v in t.items()}
    return {"total": m["total"], "bonds": m["total"] - m["no_bonds"],
            "contacts": m["no_bonds"] - m["no_bonds_no_contacts"], "rest": m["no_bonds_no_contacts"],
            "pairs": npair}


def inhouse_once(run):
    from adapters.inhouse import run_inhouse

    res = run_inhouse(run)
    return res.wall_s, res.extra["cpu_s"], {"pair_list_builds": res.extra["pair_list_builds"]}


def compile_inhouse():
    from adapters.inhouse import run_inhouse

    run_inhouse(fcc_run(500, 5))


_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps")


SHORT = 5  # steps of the short LIGGGHTS deck whose CPU time (start-up, reading the data) is subtracted


def liggghts_decks(run, tmp):
    """The deck of the run and the same deck SHORT steps long."""
    from adapters.deck import export

    decks = []
    for name, r in (("full", run), ("short", replace(run, duration=SHORT * run.dt, record_every=SHORT * run.dt))):
        r.save(tmp / f"run_{name}.npz")
        export(tmp / f"run_{name}.npz", "liggghts", tmp / f"liggghts_{name}")
        decks.append(tmp / f"liggghts_{name}")
    return decks


def _children_cpu():
    u = resource.getrusage(resource.RUSAGE_CHILDREN)
    return u.ru_utime + u.ru_stime


def liggghts_once(run, decks, out):
    """LIGGGHTS' own stepping time (sum of its Loop time lines), its CPU time for the steps (the CPU time of the
    process minus that of the SHORT-step deck, scaled) and the whole process wall time."""
    from adapters.deck import run as run_deck

    cpu = []
    for deck, tag in zip(decks, ("full", "short")):
        c0 = _children_cpu()
        res = run_deck(deck, out / tag, np=1)
        cpu.append(_children_cpu() - c0)
        if tag == "full":
            text = (out / tag / "liggghts.log").read_text(errors="replace")
            hits = [(float(a), int(s)) for a, _, s in _LOOP.findall(text)]
            stepped = sum(s for _, s in hits)
            if stepped != run.steps:
                raise RuntimeError(f"liggghts log: {stepped} steps in its Loop time lines, expected {run.steps}")
            wall, process_wall = sum(a for a, _ in hits), res.wall_s
    cpu_steps = (cpu[0] - cpu[1]) * run.steps / (run.steps - SHORT)
    return wall, cpu_steps, {"process_wall_s": process_wall}


def bench_yade(run, tmp):
    from adapters.deck import export
    from adapters.deck import run as run_deck

    run.save(tmp / "yrun.npz")
    deck = tmp / "yade_deck"
    export(tmp / "yrun.npz", "yade", deck)
    res = run_deck(deck, tmp / "yade_out", np=1)
    return {"wall_s": float(res.extra["wall_run_s"]), "steps": run.steps - 1, "process_wall_s": res.wall_s,
            "setup_s": float(res.extra.get("setup", {}).get("setup_s", float("nan")))}


def bench_deck(packing, args, skip, tmp):
    """Rows (engine, spheres, bonds, timings) of one deck."""
    t = time.perf_counter()
    run = fcc_run(args.n, args.steps, packing)
    print(f"deck {packing}: {run.n} spheres ({int(run.fixed.sum())} fixed), {run.n_bonds} bonds, "
          f"dt = {run.dt:.3g} s, {run.steps} steps (built in {time.perf_counter() - t:.1f} s)", flush=True)
    rows = []
    # in-house and LIGGGHTS alternate, repeat by repeat, so that both see the same machine load
    engines = [e for e in ("dda", "dda-central", "liggghts") if e not in skip]
    crun = central_run(run)
    # the LIGGGHTS decks of each packing in a folder of their own (export refuses a folder holding a deck)
    (tmp / packing).mkdir()
    decks = liggghts_decks(run, tmp / packing) if "liggghts" in engines else None
    walls = {e: [] for e in engines}
    cpus = {e: [] for e in engines}
    info = {}
    for k in range(args.repeats):
        for e in engines:
            if e in ("dda", "dda-central"):
                w, c, info[e] = inhouse_once(run if e == "dda" else crun)
            else:
                w, c, info[e] = liggghts_once(run, decks, tmp / f"liggghts_{packing}_out{k}")
            walls[e].append(w)
            cpus[e].append(c)
            print(f"  {e} repeat {k + 1}: wall {w:.3f} s, cpu {c:.3f} s", flush=True)
    if args.split:
        for e in engines:
            if e in ("dda", "dda-central"):
                info[e]["split_s_per_step"] = sp = inhouse_split(run if e == "dda" else crun, args.steps)
                print(f"  {LABELS[e]}: per step {1e3 * sp['total']:.2f} ms = bonds {1e3 * sp['bonds']:.2f} + "
                      f"contacts {1e3 * sp['contacts']:.2f} ({sp['pairs']} listed pairs) + pair list and "
                      f"integration {1e3 * sp['rest']:.2f} ms", flush=True)
    for e in engines:
        rows.append((e, run.n, run.n_bonds, {"wall_s": statistics.median(walls[e]), "walls": walls[e],
                                             "cpu_s": statistics.median(cpus[e]), "cpus": cpus[e],
                                             "steps": run.steps, **info[e]}))
    if "yade" not in skip:
        yrun = fcc_run(args.yade_n, args.yade_steps, packing)
        rows.append(("yade", yrun.n, yrun.n_bonds, bench_yade(yrun, tmp)))
        print(f"  yade: {rows[-1][3]['wall_s']:.3f} s", flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--yade-n", type=int, default=10_000)
    ap.add_argument("--yade-steps", type=int, default=20)
    ap.add_argument("--packing", default="fcc,random", help="comma-separated decks: fcc, random")
    ap.add_argument("--skip", default="",
                    help="comma-separated engines to leave out (dda, dda-central, liggghts, yade)")
    ap.add_argument("--split", action="store_true", help="in-house time per step: bonds, contacts, the rest")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.steps, args.repeats, args.yade_n, args.yade_steps = 10_000, 50, 1, 2000, 10
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    packings = [p.strip() for p in args.packing.split(",") if p.strip()]
    bad = [p for p in packings if p not in DENSITY]
    if bad:
        ap.error(f"--packing: unknown {', '.join(bad)} (choose from {', '.join(DENSITY)})")
    machine = machine_info()
    print(machine_line(machine), flush=True)
    if not {"dda", "dda-central"} <= skip:
        compile_inhouse()
    table = []
    tmp = Path(tempfile.mkdtemp(prefix="bench_adapters_"))
    try:
        results = [(p, bench_deck(p, args, skip, tmp)) for p in packings]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"\n{'deck':<7} {'engine':<33} {'spheres':>8} {'bonds':>8} {'steps':>6} {'wall s':>8} "
          f"{'particle-steps/s':>17} {'ratio':>6} {'cpu s':>7} {'p-steps/cpu-s':>14} {'ratio':>6}")
    for packing, rows in results:
        rate = {name: n * r["steps"] / r["wall_s"] for name, n, _, r in rows}
        crate = {name: n * r["steps"] / r["cpu_s"] if r.get("cpu_s") else float("nan") for name, n, _, r in rows}
        ref, cref = rate.get("liggghts"), crate.get("liggghts")
        for name, n, nb, r in rows:
            ratio = rate[name] / ref if ref else float("nan")
            cratio = crate[name] / cref if cref else float("nan")
            print(f"{packing:<7} {LABELS.get(name, name):<33} {n:8d} {nb:8d} {r['steps']:6d} {r['wall_s']:8.3f} "
                  f"{rate[name]:17.4g} "
                  f"{ratio:6.2f} {r.get('cpu_s', float('nan')):7.3f} {crate[name]:14.4g} {cratio:6.2f}")
            table.append({"deck": packing, "engine": name, "spheres": n, "bonds": nb, **r,
                          "particle_steps_per_s": rate[name], "ratio": ratio,
                          "particle_steps_per_cpu_s": crate[name], "cpu_ratio": cratio})
    print(f"load average (1, 5, 15 min) at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.json:
        args.json.write_text(json.dumps({"machine": machine, "rows": table}, indent=2))


if __name__ == "__main__":
    main()
