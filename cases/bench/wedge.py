"""Benchmark: the sphere wedge's onset against Hoek & Bray over the sphere radius; a table on stdout, never a test.

    .venv/bin/python -m cases.bench.wedge [--radii 0.5,0.4,0.3] [--engines dda] [--iterations 7] [--causes]
                                          [--json OUT]

For each radius r: the wedge of cases/scenes/crossval/wedge.toml with its model's [packing] radius = r (the
same domain, joints, cavities, contact and bond stiffness, local damping 0.1 and 1.2 s per trial), the bisection
of the joint friction that `cases crossval` runs (cases.lib.crossval.wedge_onset: from 0.95-1.05 x the critical
angle, 7 halvings; a trial slides when the wedge has not come to rest and accelerates), in each engine. Columns:
r, spheres (free ones), time steps per trial, trials, the final bracket, its middle, the error against Hoek &
Bray's critical friction, wall time per trial and in all (one warm-up trial first, so no compilation is
counted). The smaller the spheres, the more joint contacts and the finer the wedge's faces; the cost grows about
as r^-4.5 (spheres r^-3, steps r^-1.5 at the same contact stiffness).

--causes: at the scene's radius, where the 1.17 % of the criterion before issue 16 came from: the bisection as
it was (from 0.85-1.15 x, 6 halvings) with the old criterion (a trial slides when its last quarter moved more
than 7/32 x 1 % g sin(plunge) T^2, i.e. an acceleration of 1 % of the driving one) and with the new one
(wedge_slides), each on the model with and without the free spheres that fewer than three bonds hold
(crossval.rigid_core), and the onset the old threshold alone allows (analytical: tan phi = (1 - 0.01 / c)
tan phi_c with c = 1 for the rigid wedge and c = 1 - local damping for the damped slide).
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

from sgim.machine import machine_info, machine_line

# The engines (adapters, dda: numba kernels) are imported by cases.lib.crossval inside the functions that run them.
from cases.lib import crossval as cv

OLD_FRACTION = 0.01  # the old criterion: 1 % of the driving acceleration g sin(plunge)


def scene_at(radius, folder):
    """wedge.toml and its model written into `folder` with [packing] radius = `radius`; the scene's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model = (cv.CV / "wedge_model.toml").read_text()
    old = 'kind = "fcc"\nradius = 0.5\n'
    if old not in model:
        raise RuntimeError(f"{cv.CV / 'wedge_model.toml'}: no [packing] radius = 0.5 to replace")
    (folder / "wedge_model.toml").write_text(model.replace(old, f'kind = "fcc"\nradius = {radius!r}\n'))
    (folder / "wedge.toml").write_text((cv.CV / "wedge.toml").read_text())
    return folder / "wedge.toml"


def old_criterion(s, run, geo):
    """The criterion before issue 16: the last quarter moved more than 7/32 x 1 % g sin(plunge) T^2 and more than
    the quarter before."""
    T = run.duration
    threshold = 7.0 / 32.0 * cv.G * math.sin(math.radians(geo.line_plunge)) * OLD_FRACTION * T * T
    return s[2] - s[1] > threshold and s[2] - s[1] > s[1] - s[0]


def onset(engine, path, work, **kw):
    t0 = time.perf_counter()
    b = cv.wedge_onset(engine, work, path=path, **kw)
    wall = time.perf_counter() - t0
    run = b["run"]
    got = 0.5 * (b["lo"] + b["hi"]) if b["found"] else float("nan")
    return dict(engine=engine, radius=float(run.radii.min()), spheres=int(run.n), free=int((~run.fixed).sum()),
                steps=int(run.steps), trials=len(b["trials"]), lo=b["lo"], hi=b["hi"], found=b["found"], onset=got,
                phi_c=b["phi_c"], error_pct=100.0 * (got / b["phi_c"] - 1.0), wall_s=wall,
                wall_per_trial_s=wall / len(b["trials"]))


def warm_up(engine, path, work):
    run = cv.wedge_run(path)
    run.duration = 20 * run.dt
    run.save(Path(work) / "warm.npz")
    cv.run_engine(engine, Path(work) / "warm.npz", work, run=run)


def causes(engine, work, say):
    geo, _ = cv._wedge_line(cv.WEDGE)
    phi_c = geo.critical_friction
    damping = cv.wedge_run().local_damping
    rows = []
    for label, c in (("old threshold alone, rigid slide", 1.0), ("old threshold alone, damped slide", 1 - damping)):
        phi = math.degrees(math.atan((1.0 - OLD_FRACTION / c) * math.tan(math.radians(phi_c))))
        rows.append(dict(case=label, onset=phi, error_pct=100.0 * (phi / phi_c - 1.0), lo=None, hi=None, trials=0,
                         wall_s=0.0))
        say(_cause_line(rows[-1]))
    for crit_name, crit in (("old criterion", old_criterion), ("new criterion", cv.wedge_slides)):
        for core in (False, True):
            label = f"{crit_name}, {'without' if core else 'with'} the spheres < 3 bonds hold"
            r = onset(engine, None, work, bracket=(0.85, 1.15), iterations=6, core=core, moving=crit)
            rows.append(dict(case=label, **{k: r[k] for k in ("onset", "error_pct", "lo", "hi", "trials", "wall_s")}))
            say(_cause_line(rows[-1]))
    return rows


def _cause_line(r):
    br = "-" if r["lo"] is None else f"{r['lo']:.3f}-{r['hi']:.3f}"
    return f"| {r['case']:<54} | {r['onset']:8.3f} | {r['error_pct']:+7.2f} % | {br:>13} | {r['trials']:6d} |"


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m cases.bench.wedge", description=__doc__.split("\n")[0])
    ap.add_argument("--radii", default="0.5,0.4,0.3", help="comma list of sphere radii [m]")
    ap.add_argument("--engines", default="dda", help="comma list of dda, yade")
    ap.add_argument("--iterations", type=int, default=7, help="halvings after the first bracket")
    ap.add_argument("--causes", action="store_true", help="also the old and new criteria, with and without the "
                    "spheres fewer than three bonds hold, at the scene's radius (in-house)")
    ap.add_argument("--json", help="write the rows to this JSON file")
    args = ap.parse_args(argv)
    radii = [float(x) for x in args.radii.split(",") if x]
    engines = [e for e in args.engines.split(",") if e]
    print(machine_line())
    out = {"machine": machine_info(), "rows": [], "causes": []}
    with tempfile.TemporaryDirectory(prefix="bench_wedge_") as tmp:
        if args.causes:
            print("\nwhere the error of the criterion before issue 16 came from (r = 0.5, in-house; the bisection as "
                  "it was, 0.85-1.15 x, 6 halvings: the error is its last bracket's middle):\n")
            print(f"| {'bisection':<54} | {'onset':>8} | {'error':>9} | {'bracket':>13} | {'trials':>6} |")
            print(f"|{'-' * 56}|{'-' * 10}|{'-' * 11}|{'-' * 15}|{'-' * 8}|")
            warm_up("dda", None, tmp)
            out["causes"] = causes("dda", tmp, print)
        print(f"\nonset against sphere radius (Hoek & Bray {cv.wedge_reference(cv.WEDGE).critical_friction:.3f} deg; "
              f"{args.iterations} halvings from 0.95-1.05 x):\n")
        head = ("engine", "r m", "spheres (free)", "steps/trial", "trials", "bracket deg", "onset deg", "error",
                "s/trial", "wall s")
        print("| " + " | ".join(head) + " |")
        print("|" + "|".join("-" * (len(h) + 2) for h in head) + "|")
        for r in radii:
            path = scene_at(r, Path(tmp) / f"r{r:g}")
            for eng in engines:
                warm_up(eng, path, tmp)
                row = onset(eng, path, tmp, iterations=args.iterations)
                out["rows"].append(row)
                print(f"| {eng} | {r:g} | {row['spheres']} ({row['free']}) | {row['steps']} | {row['trials']} | "
                      f"{row['lo']:.3f}-{row['hi']:.3f} | {row['onset']:.3f} | {row['error_pct']:+.2f} % | "
                      f"{row['wall_per_trial_s']:.1f} | {row['wall_s']:.0f} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
