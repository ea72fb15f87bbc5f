"""Benchmark of random dense packing (sgim/rpack.py): speed, quality, a YADE peer, a graded open pit.

What is measured
----------------
1. Equal spheres in a box: about one million spheres (r = 0.5 in a 96 m cube; --quick: a 48 m
   cube, about 125 000).  A constant radius in a region this wide is packed in zones by two
   threads (sgim/rpack.py, _zones); the same box packed in one zone, one thread, is the peer in
   the same run (speed ratio; seam check: the solid fraction of 1 m slabs across the cut axis,
   centres 2 m or more from the other walls, min / max / standard deviation for both).  The
   packer's time (seeds + pocket filling, warm numba kernels, median of the repeats) gives
   spheres/s, and its CPU time (the process's, both threads) spheres per CPU second; then the
   statistics of sgim/rpack.py: density (sphere volume / box volume), bulk density (spheres
   whose centre lies 4 r or more inside the box, over that inner box), mean coordination number
   at the bond tolerance 1e-3 (contact when |ci - cj| <= (ri + rj) (1 + 1e-3)), maximum overlap
   (fraction of the smaller radius) and the largest empty sphere (radius, and relative to the
   local sphere radius); the time of the statistics is listed apart.
2. Radius ratio 2: radius uniform between r and 2 r (r = 0.5) in the same box.
3. Peer: YADE 2023.02a ``pack.randomDensePack(pack.inAlignedBox(...), radius=0.5)`` in a
   ``yade -n -x`` subprocess with a time limit, in its default (aperiodic: triaxial compression,
   10 m cube) and periodic (``spheresInCell=2000``, 20 m cube) forms; sgim packs the same boxes
   with the same radius in the same run.  Spheres/s counts the spheres returned over the time of
   the call inside yade; density = their volume / box volume (every returned sphere lies inside).
4. Graded open pit: cases/scenes/open_pit_graded.toml (radius 0.25 m within 1 m of the pit and terrain
   surface, 2 m beyond 16 m) against the uniform fine packing (radius 0.25 m everywhere).  The
   uniform fine packing of the whole pit (about 70 million spheres) does not fit this machine's
   time budget: it is built on a 30 m x 30 m column through the pit wall (the same surface, from
   the bottom to the surface) and scaled by the ratio of the region volumes; the column's four
   side walls lower its density a little, so the estimate is low and the ratio conservative.
   --quick builds both packings whole on that column.

Run
---
    .venv/bin/python -m cases.bench.pack            # full run, about 4 minutes
    .venv/bin/python -m cases.bench.pack --quick    # smaller sizes, about 2 minutes
    .venv/bin/python -m cases.bench.pack --json out.json

Markdown tables go to stdout, progress lines to stderr.  The machine has 2 cores shared with other
work: timings are medians of repeats and the load average is recorded in the JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from cases import SCENES
from sgim.machine import machine_info, machine_line

# sgim's packing code (numba kernels) is imported inside the functions of each part, so that `--help` loads none
# of it and each part loads only what it times.

REPO = Path(__file__).resolve().parents[2]
GRADED_PIT = SCENES / "open_pit_graded.toml"
T0 = time.perf_counter()


def say(msg):
    print(f"[bench_pack {time.perf_counter() - T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


def md_table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def fint(n):
    return f"{int(n):,}".replace(",", " ")


# ---------------------------------------------------------------------------
# 1-2: boxes

def bulk_density(X, R, lo, hi, margin):
    inner = np.all((X > lo + margin) & (X < hi - margin), axis=1)
    return float(np.sum(4 / 3 * np.pi * R[inner] ** 3) / np.prod(hi - lo - 2 * margin))


def slab_profile(X, R, lo, hi, axis=0, width=1.0, margin=2.0):
    """Solid fraction of slabs across axis (exact sphere volume between two planes), centres at
    least margin from the other walls, slabs at least margin from the walls across axis."""
    other = [a for a in range(3) if a != axis]
    keep = np.all((X[:, other] > lo[other] + margin) & (X[:, other] < hi[other] - margin), axis=1)
    x, r = X[keep, axis], R[keep]
    edges = np.arange(lo[axis] + margin, hi[axis] - margin + 1e-9, width)

    def below(h):
        t = np.clip(h - (x - r), 0.0, 2.0 * r)
        return np.pi * t * t * (3.0 * r - t) / 3.0

    area = float(np.prod(hi[other] - lo[other] - 2.0 * margin))
    d = np.array([(below(b) - below(a)).sum() / ((b - a) * area) for a, b in zip(edges[:-1], edges[1:])])
    return {"min": float(d.min()), "max": float(d.max()), "sd": float(d.std()), "mean": float(d.mean())}


def box_case(L, law, repeats, seed=1, stats=True, parallel=True):
    from sgim.rpack import RandomSpec, Region, pack_region, pack_statistics

    reg = Region(np.zeros(3), np.full(3, float(L)))
    spec = RandomSpec(seed=seed, law=law)
    times, cpu = [], []
    res = None
    for k in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        res = pack_region(reg, spec, parallel=parallel)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
        say(f"  box {L:g} m, {law.law}, {res.stats['counters']['zones']} zone(s): {len(res.radii)} spheres in "
            f"{times[-1]:.2f} s (cpu {cpu[-1]:.2f} s)")
    X, R = res.centres, res.radii
    out = {"box_m": L, "law": law.meta(), "zones": res.stats["counters"]["zones"], "spheres": int(len(R)),
           "slabs": slab_profile(X, R, reg.lo, reg.hi), "pack_s": times,
           "pack_s_median": statistics.median(times), "pack_cpu_s": cpu, "pack_cpu_s_median": statistics.median(cpu)}
    out["spheres_per_s"] = out["spheres"] / out["pack_s_median"]
    out["spheres_per_cpu_s"] = out["spheres"] / out["pack_cpu_s_median"]
    out["bulk_density"] = bulk_density(X, R, reg.lo, reg.hi, 4 * float(R.max()))
    if stats:
        t = time.perf_counter()
        st = pack_statistics(X, R, reg, reg.volume(), 1e-3, seed=seed)
        out["stats_s"] = time.perf_counter() - t
        out["statistics"] = st
    return out


def table_boxes(rows):
    hdr = ["case", "zones", "spheres", "pack time (s, median)", "spheres/s", "spheres per CPU s", "density",
           "bulk density", "1 m slabs min / max / sd", "coordination (gap 1e-3)", "max overlap",
           "largest empty sphere r (x local r)", "statistics (s)"]
    out = []
    for name, c in rows:
        st = c.get("statistics", {})
        les = st.get("largest_empty_sphere") or {}
        sl = c["slabs"]
        out.append([name, str(c["zones"]), fint(c["spheres"]), f"{c['pack_s_median']:.2f}", fint(c["spheres_per_s"]),
                    fint(c["spheres_per_cpu_s"]),
                    f"{st.get('density', float('nan')):.4f}", f"{c['bulk_density']:.4f}",
                    f"{sl['min']:.4f} / {sl['max']:.4f} / {sl['sd']:.4f}",
                    f"{st.get('coordination', float('nan')):.3f}", f"{st.get('max_overlap', float('nan')):.1e}",
                    f"{les.get('radius', float('nan')):.3f} ({les.get('relative_max', float('nan')):.3f})",
                    f"{c.get('stats_s', float('nan')):.1f}"])
    return md_table(hdr, out)


# ---------------------------------------------------------------------------
# 3: YADE peer

YADE_SCRIPT = r'''
import sys, time
import numpy as np
from yade import pack
L, r, cells, seed, out = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
t0 = time.time()
sp = pack.randomDensePack(pack.inAlignedBox((0, 0, 0), (L, L, L)), radius=r, spheresInCell=cells,
                          returnSpherePack=True, seed=seed)
t = time.time() - t0
c = np.array([s[0] for s in sp]).reshape(-1, 3)
rad = np.array([s[1] for s in sp])
np.savez(out, centres=c, radii=rad, seconds=t)
'''


def yade_case(work, L, r, cells, timeout):
    yade = shutil.which("yade")
    if yade is None:
        return {"status": "yade not installed"}
    script = work / "yade_rdp.py"
    script.write_text(YADE_SCRIPT)
    out = work / f"yade_{L:g}_{cells}.npz"
    say(f"  yade randomDensePack: {L:g} m cube, radius {r}, spheresInCell {cells} (limit {timeout} s)")
    t = time.perf_counter()
    try:
        p = subprocess.run([yade, "-n", "-x", str(script), str(L), str(r), str(cells), "1", str(out)], cwd=work,
                           capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": f"timed out after {timeout} s"}
    wall = time.perf_counter() - t
    if p.returncode != 0 or not out.exists():
        return {"status": "yade failed", "log_tail": (p.stdout + p.stderr)[-800:]}
    z = np.load(out, allow_pickle=False)
    X, R, sec = z["centres"], z["radii"], float(z["seconds"])
    inside = bool(np.all(X - R[:, None] >= -1e-9) and np.all(X + R[:, None] <= L + 1e-9))
    return {"status": "ok", "box_m": L, "radius_asked": r, "spheres_in_cell": cells, "spheres": int(len(R)),
            "seconds_in_yade": sec, "wall_s": wall, "spheres_per_s": len(R) / sec,
            "density": float(np.sum(4 / 3 * np.pi * R ** 3) / L ** 3), "radius_min": float(R.min()),
            "radius_max": float(R.max()), "all_inside_box": inside,
            "bulk_density": bulk_density(X, R, np.zeros(3), np.full(3, L), 4 * float(R.max()))}


def bench_yade(work, quick):
    from sgim.rpack import RadiusLaw

    out = []
    for L, cells in ((10.0, 0), (20.0, 2000)):
        y = yade_case(work, L, 0.5, cells, timeout=600)
        s = box_case(L, RadiusLaw("constant", {"radius": 0.5}), 3, stats=False)
        out.append({"box_m": L, "spheres_in_cell": cells, "yade": y, "sgim": s})
    return out


def table_yade(rows):
    hdr = ["box", "packer", "spheres", "radius", "time (s)", "spheres/s", "density", "bulk density"]
    out = []
    for c in rows:
        y, s = c["yade"], c["sgim"]
        form = "default (aperiodic)" if c["spheres_in_cell"] == 0 else f"periodic, spheresInCell={c['spheres_in_cell']}"
        if y.get("status") == "ok":
            rr = f"{y['radius_min']:.3f}" if y["radius_min"] == y["radius_max"] else \
                f"{y['radius_min']:.3f}..{y['radius_max']:.3f}"
            out.append([f"{c['box_m']:g} m cube", f"YADE randomDensePack, {form}", fint(y["spheres"]), rr,
                        f"{y['seconds_in_yade']:.1f}", fint(y["spheres_per_s"]), f"{y['density']:.4f}",
                        f"{y['bulk_density']:.4f}"])
        else:
            out.append([f"{c['box_m']:g} m cube", f"YADE randomDensePack, {form}", y.get("status"), "", "", "", "",
                        ""])
        out.append([f"{c['box_m']:g} m cube", "sgim pocket filling", fint(s["spheres"]), "0.500",
                    f"{s['pack_s_median']:.3f}", fint(s["spheres_per_s"]),
                    f"{np.sum(4 / 3 * np.pi * 0.5 ** 3) * s['spheres'] / c['box_m'] ** 3:.4f}",
                    f"{s['bulk_density']:.4f}"])
        if y.get("status") == "ok":
            out.append([f"{c['box_m']:g} m cube", "ratio sgim / YADE (spheres/s)", "", "", "",
                        f"{s['spheres_per_s'] / y['spheres_per_s']:.0f} x", "", ""])
    return md_table(hdr, out)


# ---------------------------------------------------------------------------
# 4: graded open pit

def pit_scene(box=None, uniform_r=None, drop_discs=False):
    from sgim.scene import scene_from_dict

    text = GRADED_PIT.read_text()
    data = tomllib.loads(text)
    if box is not None:
        data["domain"] = {"min": list(box[0]), "max": list(box[1])}
        drop_discs = True
    if drop_discs:
        data.pop("discontinuity", None)
    if uniform_r is not None:
        data["packing"] = {"kind": "random", "seed": 1, "radius": uniform_r}
    return scene_from_dict(data, GRADED_PIT, text)


def pack_scene(scene, label):
    """The build's packing step (sgim.rpack.pack_and_measure: pack, statistics, seeding of holes)."""
    from sgim.rpack import NearObjects, Region, pack_and_measure

    spec = scene.packing.random
    reg = Region.from_scene(scene)
    near = NearObjects(scene, spec.grading) if spec.grading is not None else None
    local = None
    if near is not None:
        def local(p):
            return spec.grading.radius(near.distance(p, spec.grading.coarse_distance))
    t = time.perf_counter()
    res, st, vol = pack_and_measure(reg, spec, near, 1e-3, local)
    total = time.perf_counter() - t
    tp = res.timings["pack"] + res.timings["seeds"]
    say(f"  {label}: {len(res.radii)} spheres, packing {tp:.1f} s, all {total:.1f} s")
    return {"spheres": int(len(res.radii)), "pack_s": tp, "spheres_per_s": len(res.radii) / tp,
            "stats_s": total - tp, "region_volume": vol, "statistics": st}


def bench_pit(quick):
    column = ((0.0, -40.0, 0.0), (30.0, -10.0, 140.0))  # through the pit wall, from the bottom to the surface
    out = {"column_box": column}
    if quick:
        g = pack_scene(pit_scene(box=column), "graded, column")
        u = pack_scene(pit_scene(box=column, uniform_r=0.25), "uniform r = 0.25, column")
        out.update({"scope": "column", "graded": g, "uniform": u, "uniform_spheres": u["spheres"],
                    "uniform_method": "built"})
    else:
        g = pack_scene(pit_scene(drop_discs=False), "graded, whole pit")
        u = pack_scene(pit_scene(box=column, uniform_r=0.25), "uniform r = 0.25, column")
        est = u["spheres"] * g["region_volume"] / u["region_volume"]
        out.update({"scope": "whole pit", "graded": g, "uniform_column": u, "uniform_spheres": est,
                    "uniform_method": "column x region volume ratio"})
    out["ratio"] = out["uniform_spheres"] / out["graded"]["spheres"]
    return out


def table_pit(p):
    g = p["graded"]
    st = g["statistics"]
    les = st.get("largest_empty_sphere") or {}
    rows = [["graded (0.25 m at the surface, 2 m beyond 16 m)", p["scope"], fint(g["spheres"]), f"{g['pack_s']:.1f}",
             fint(g["spheres_per_s"]), f"{st['density']:.4f}", f"{st['coordination']:.3f}",
             f"{les.get('relative_max', float('nan')):.3f}"]]
    u = p.get("uniform") or p.get("uniform_column")
    su = u["statistics"]
    lu = su.get("largest_empty_sphere") or {}
    rows.append(["uniform r = 0.25 m", "column", fint(u["spheres"]), f"{u['pack_s']:.1f}", fint(u["spheres_per_s"]),
                 f"{su['density']:.4f}", f"{su['coordination']:.3f}", f"{lu.get('relative_max', float('nan')):.3f}"])
    if p["uniform_method"] != "built":
        rows.append(["uniform r = 0.25 m, estimated", p["scope"], fint(p["uniform_spheres"]), "", "", "", "", ""])
    hdr = ["packing", "scope", "spheres", "pack time (s)", "spheres/s", "density", "coordination (gap 1e-3)",
           "largest empty sphere / local r"]
    return md_table(hdr, rows) + (f"\n\nUniform fine / graded: {p['ratio']:.1f} x fewer spheres "
                                  f"(target >= 5 x; uniform count {p['uniform_method']}).")


# ---------------------------------------------------------------------------

def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m cases.bench.pack", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller boxes, the pit on a column only")
    ap.add_argument("--json", metavar="OUT.json", help="also write the results as JSON")
    ap.add_argument("--skip-yade", action="store_true")
    ap.add_argument("--skip-pit", action="store_true")
    args = ap.parse_args(argv)
    from sgim.rpack import RadiusLaw

    results = {"quick": args.quick, "machine": {**machine_info(), "load_avg_start": os.getloadavg()}}
    print(f"# Packing benchmarks: {machine_line(results['machine'])}\n", flush=True)
    work = Path(tempfile.mkdtemp(prefix="bench_pack_"))
    try:
        say("warm-up (numba kernels)")
        box_case(8.0, RadiusLaw("constant", {"radius": 0.5}), 1)
        box_case(8.0, RadiusLaw("uniform", {"min": 0.5, "max": 1.0}), 1)
        L = 48.0 if args.quick else 96.0
        reps = 3 if args.quick else 2
        say(f"1. equal spheres, {L:g} m cube")
        eq = box_case(L, RadiusLaw("constant", {"radius": 0.5}), reps + 1)
        say(f"1'. equal spheres, {L:g} m cube, one zone (the peer)")
        eq1 = box_case(L, RadiusLaw("constant", {"radius": 0.5}), reps, parallel=False)
        say(f"2. radius ratio 2, {L:g} m cube")
        r2 = box_case(L, RadiusLaw("uniform", {"min": 0.5, "max": 1.0}), reps)
        results["equal"], results["equal_one_zone"], results["ratio2"] = eq, eq1, r2
        print("## 1-2. Random dense packing in a box (r = 0.5; ratio 2: r uniform in [0.5, 1.0])\n")
        print(table_boxes([("equal spheres", eq), ("equal spheres, one zone", eq1), ("radius ratio 2", r2)]))
        print(f"\nZones against one zone: {eq1['pack_s_median'] / eq['pack_s_median']:.2f} x faster; "
              f"density {eq['statistics']['density']:.4f} against {eq1['statistics']['density']:.4f}.")
        print(f"\nTargets: >= 200 000 spheres/s for one million equal spheres ({'met' if eq['spheres_per_s'] >= 2e5 else 'MISSED'}: "
              f"{fint(eq['spheres_per_s'])} spheres/s for {fint(eq['spheres'])}, "
              f"{fint(eq['spheres_per_cpu_s'])} per CPU second); density >= 0.58 for equal spheres "
              f"({eq['statistics']['density']:.4f}), >= 0.60 for ratio 2 ({r2['statistics']['density']:.4f}).\n",
              flush=True)
        if not args.skip_yade:
            say("3. YADE peer")
            y = bench_yade(work, args.quick)
            results["yade"] = y
            print("## 3. Peer: YADE pack.randomDensePack and sgim on the same boxes (radius 0.5)\n")
            print(table_yade(y) + "\n", flush=True)
        if not args.skip_pit:
            say("4. graded open pit")
            p = bench_pit(args.quick)
            results["pit"] = p
            print("## 4. Graded open pit (cases/scenes/open_pit_graded.toml) against the uniform fine packing\n")
            print(table_pit(p) + "\n", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    results["machine"]["load_avg_end"] = os.getloadavg()
    results["total_s"] = time.perf_counter() - T0
    say(f"done in {results['total_s']:.0f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
