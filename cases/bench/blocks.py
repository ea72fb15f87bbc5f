"""The block model of the open pit (dda/geoblocks.py): block count, cutting time per stage, peak memory, and the
model's volume against the exact polyhedral volume under the terrain inside the domain (each terrain triangle
clipped to the domain's plan rectangle, the linear height integrated over the clipped polygon).

    python -m cases.bench.blocks              # open_pit_blocks (three joint sets at 10 m) and open_pit_dfn
    python -m cases.bench.blocks --only pit --runs 1

Scenes: cases/scenes/open_pit_blocks.toml (the pit's discs and fault, its three persistent sets at 10 m spacing,
min_volume 5 m3); cases/scenes/open_pit_dfn.toml (its 6114 sampled fractures and the fault) with min_volume 5 m3.
A table on stdout, never a test. Each cut runs in a fresh process so that the peak memory (ru_maxrss) is its own;
the cutting time is the median of ``--runs`` cuts (3), with the load average before and after them.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cases import SCENES
from sgim.machine import machine_line

WARM = {"domain": {"min": [0, 0, 0], "max": [10, 10, 10]}, "packing": {"kind": "cubic", "radius": 0.5},
        "excavation": [{"points": [[0, 0, 8], [10, 0, 7], [10, 10, 9], [0, 10, 8], [5, 5, 6]]}],
        "discontinuity": [{"centre": [5, 5, 4], "dip": 30, "dip_direction": 10, "radius": 3}],
        "blocks": {"joint_set": [{"dip": 70, "dip_direction": 40, "spacing": 3}]}}
CASES = {"pit": ("open_pit_blocks.toml", ""), "dfn": ("open_pit_dfn.toml", "\n[blocks]\nmin_volume = 5.0\n")}


def _clip(poly, axis, val, keep_ge):
    out = []
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        ia = a[axis] >= val if keep_ge else a[axis] <= val
        ib = b[axis] >= val if keep_ge else b[axis] <= val
        if ia:
            out.append(a)
        if ia != ib:
            out.append(a + (val - a[axis]) / (b[axis] - a[axis]) * (b - a))
    return out


def terrain_volume(scene):
    """Exact volume between the domain's floor and the (single) excavation surface, inside the domain's plan."""
    lo, hi = scene.domain.min, scene.domain.max
    ex = scene.excavations[0]
    total = 0.0
    for t in ex.vertices[ex.faces]:
        poly = [p.copy() for p in t]
        for axis, val, ge in ((0, lo[0], True), (0, hi[0], False), (1, lo[1], True), (1, hi[1], False)):
            poly = _clip(poly, axis, val, ge) if poly else poly
        if len(poly) < 3:
            continue
        p = np.array(poly)
        x, y = p[:, 0], p[:, 1]
        a2 = x * np.roll(y, -1) - np.roll(x, -1) * y
        area = a2.sum() / 2
        if area == 0:
            continue
        cx, cy = ((x + np.roll(x, -1)) * a2).sum() / (6 * area), ((y + np.roll(y, -1)) * a2).sum() / (6 * area)
        n = np.cross(t[1] - t[0], t[2] - t[0])
        z = t[0, 2] - (n[0] * (cx - t[0, 0]) + n[1] * (cy - t[0, 1])) / n[2]
        if not lo[2] <= z <= hi[2]:
            raise SystemExit("the terrain leaves the domain's height: the reference needs it inside")
        total += abs(area) * (z - lo[2])
    return total


def one(name):
    """Cut one case in this process; its line as JSON on stdout."""
    # not at the top: only the child process builds (the peak memory is the cutting's own)
    from dda.geoblocks import build_blocks
    from sgim.scene import load_scene, scene_from_dict

    file, extra = CASES[name]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / file
        path.write_text((SCENES / file).read_text() + extra)
        scene = load_scene(path)
    build_blocks(scene_from_dict(WARM, "warm.toml"))  # the kernels compiled or loaded before the clock starts
    t0 = time.perf_counter()
    model = build_blocks(scene)
    wall = time.perf_counter() - t0
    s = model.summary()
    ref = terrain_volume(scene)
    print(json.dumps({"case": name, "blocks": s["blocks"], "wall_s": wall, "stages": s["seconds"],
                      "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "volume": s["volume"], "reference": ref, "rel_error": (s["volume"] - ref) / ref,
                      "smallest": s["smallest"], "median": s["median"], "largest": s["largest"],
                      "below_min_volume": s["small_blocks"]}))


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m cases.bench.blocks", description=__doc__.split("\n\n")[0])
    p.add_argument("--only", choices=sorted(CASES), help="one case")
    p.add_argument("--runs", type=int, default=3, help="cuts per case; the table gives the median time (3)")
    p.add_argument("--child", choices=sorted(CASES), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        return one(args.child)
    print(machine_line())
    print()
    print("| case | blocks | cutting s (median) | runs s | peak MB | volume rel. error | smallest / median / largest m3 "
          "| < min_volume | load average |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in [args.only] if args.only else sorted(CASES, reverse=True):
        load0 = os.getloadavg()[0]
        runs = []
        for _ in range(max(1, args.runs)):
            r = subprocess.run([sys.executable, "-m", "cases.bench.blocks", "--child", name], capture_output=True,
                               text=True, check=True)
            runs.append(json.loads(r.stdout.strip().splitlines()[-1]))
        d = sorted(runs, key=lambda x: x["wall_s"])[len(runs) // 2]  # the median run (its stages and memory)
        each = " ".join(f"{x['wall_s']:.1f}" for x in runs)
        print(f"| {name} | {d['blocks']} | {d['wall_s']:.1f} | {each} | "
              f"{d['peak_mb']:.0f} | {d['rel_error']:.1e} | {d['smallest']:.2g} / {d['median']:.3g} / "
              f"{d['largest']:.4g} | {d['below_min_volume']} | {load0:.1f} - {os.getloadavg()[0]:.1f} |")
        print("  stages of the median run: " + ", ".join(f"{k} {v:.1f} s" for k, v in d["stages"].items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
