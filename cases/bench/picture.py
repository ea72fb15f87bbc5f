"""Benchmark of a whole default ``sgim build`` of equal random spheres in a cube, stage by stage (issue 15).

What is measured
----------------
Equal spheres (r = 0.05 m, [packing] kind = "random", seed 1) fill a cube: 4.5 m (about 104 000 spheres) and
10 m (about 1.14 million). Each case is built by ``sgim build SCENE -o DIR --json --quiet`` in a child process with
the scene's default formats (model.npz, model.vtu, model.png; the PFC-style text only when asked for) and the
user's numba cache: one run first (compiling what is not cached yet, not counted), then the repeats. The table
gives the medians of the repeats: the packing and its statistics (meta.packing.timings_s), cutting, bonds, the
writing of each file, the picture (sgim/render.py: how many spheres it drew, and how many it left out because
they cannot show), and the wall time of the child process (interpreter start and imports included).

``--repo PATH`` runs the sgim of another checkout (``git worktree add --detach /tmp/before REV``) with the same
scenes: the figures before a change, in the same run conditions.

Run
---
    .venv/bin/python -m cases.bench.picture              # both cubes, 3 repeats (several minutes)
    .venv/bin/python -m cases.bench.picture --quick      # the 4.5 m cube only
    .venv/bin/python -m cases.bench.picture --repo /tmp/before --json before.json

Markdown tables go to stdout, progress lines to stderr.
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
from pathlib import Path

from sgim.machine import machine_info, machine_line

REPO = Path(__file__).resolve().parents[2]
T0 = time.perf_counter()
CUBES = (("4.5 m cube", 4.5), ("10 m cube", 10.0))
SCENE = """name = "random_cube_{tag}"
[domain]
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, {side}]
[packing]
kind = "random"
radius = 0.05
seed = 1
"""
# (column, where in the summary JSON: a stage of timings_s, or a path into it)
COLUMNS = (("packing", ("meta", "packing", "timings_s", "pack")),
           ("statistics", ("meta", "packing", "timings_s", "statistics")),
           ("cut", ("timings_s", "cut")), ("bonds", ("timings_s", "bonds")),
           ("write npz", ("timings_s", "write npz")), ("write vtu", ("timings_s", "write vtu")),
           ("write txt", ("timings_s", "write txt")), ("picture", ("timings_s", "render")))


def say(msg):
    print(f"[bench_picture {time.perf_counter() - T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


def _get(d, path):
    for k in path:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def build(repo, scene, out):
    """One default ``sgim build`` child: (summary JSON, wall seconds)."""
    cmd = [sys.executable, "-m", "sgim.cli", "build", str(scene), "-o", str(out), "--json", "--quiet", "--force"]
    env = dict(os.environ, PYTHONPATH=str(repo))
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=repo, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode:
        raise SystemExit(f"sgim build {scene} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout), wall


def run_case(repo, tmp, name, side, repeats):
    scene = tmp / f"cube_{side:g}.toml"
    scene.write_text(SCENE.format(tag=f"{side:g}m".replace(".", "_"), side=side))
    say(f"{name}: first build (compiles what is not cached)")
    build(repo, scene, tmp / "out")
    runs = []
    for k in range(repeats):
        info, wall = build(repo, scene, tmp / "out")
        say(f"{name}: run {k + 1}/{repeats}: {wall:.1f} s, {info['spheres']} spheres")
        runs.append((info, wall))
    shutil.rmtree(tmp / "out", ignore_errors=True)
    row = {"case": name, "spheres": runs[0][0]["spheres"], "wall_s": statistics.median(w for _, w in runs),
           "runs": [{"timings_s": i["timings_s"], "packing_s": _get(i, ("meta", "packing", "timings_s")),
                     "picture": i.get("picture"), "wall_s": w} for i, w in runs]}
    for col, path in COLUMNS:
        vals = [_get(i, path) for i, _ in runs]
        row[col] = statistics.median(vals) if all(v is not None for v in vals) else None
    pic = runs[0][0].get("picture")
    row["drawn"] = pic["drawn"] if pic else None
    return row


def table(rows):
    head = ["case", "spheres", "drawn"] + [c for c, _ in COLUMNS] + ["whole build"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["case"], f"{r['spheres']:,}".replace(",", " "),
                 "all" if r["drawn"] is None else f"{r['drawn']:,}".replace(",", " ")]
        cells += ["-" if r[c] is None else f"{r[c]:.2f} s" for c, _ in COLUMNS]
        cells.append(f"{r['wall_s']:.2f} s")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the 4.5 m cube only")
    ap.add_argument("--repeats", type=int, default=3, help="counted builds per case (default 3; medians)")
    ap.add_argument("--repo", default=str(REPO), help="the checkout whose sgim is run (default: this one)")
    ap.add_argument("--json", help="also write the results to this JSON file")
    args = ap.parse_args(argv)
    repo = Path(args.repo).resolve()
    if not (repo / "sgim" / "cli.py").is_file():
        raise SystemExit(f"--repo = {args.repo!r}: no sgim/cli.py there")
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True).stdout
    cubes = CUBES[:1] if args.quick else CUBES
    with tempfile.TemporaryDirectory(prefix="bench_picture_") as d:
        rows = [run_case(repo, Path(d), name, side, args.repeats) for name, side in cubes]
    print(f"Default `sgim build` of equal random spheres (r = 0.05 m) at {rev.strip() or repo}, medians of "
          f"{args.repeats} warm runs; load average {os.getloadavg()[0]:.1f}")
    print(machine_line())
    print()
    print(table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": machine_info(), "revision": rev.strip(),
                                               "load_average": os.getloadavg(), "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
