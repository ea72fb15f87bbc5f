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

The picture alone (``--picture``): sgim.render.render of n^3 spheres on a cubic grid filling the 10 m cube,
each moved by up to a tenth of the spacing (radius 0.55 spacings: an opaque block), n^3 = 10^5, 10^6 and 10^7, in
this process after one warm-up picture (pyvista and the kernels loaded): medians of the repeats, the spheres
drawn and left out, and the same with every sphere drawn for the first two sizes (the cost before the selection).

``--repo PATH`` runs the sgim of another checkout (``git worktree add --detach /tmp/before REV``) with the same
scenes: the figures before a change, in the same run conditions.

Run
---
    .venv/bin/python -m cases.bench.picture              # both cubes, 3 repeats (several minutes)
    .venv/bin/python -m cases.bench.picture --quick      # the 4.5 m cube only
    .venv/bin/python -m cases.bench.picture --repo /tmp/before --json before.json
    .venv/bin/python -m cases.bench.picture --picture    # the picture alone, 10^5 to 10^7 spheres

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


def grid_model(n, side=10.0, seed=1):
    """n^3 spheres on a cubic grid filling a cube of `side` m, moved by up to a tenth of the spacing, radius 0.55
    spacings (neighbours overlap: an opaque block), as a SphereModel without bonds."""
    # not at the top: the build tables run sgim in child processes; only --picture loads it into this one
    import numpy as np

    from sgim.model import SphereModel

    h = side / n
    g = (np.arange(n) + 0.5) * h
    c = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    c += np.random.default_rng(seed).uniform(-0.1 * h, 0.1 * h, c.shape)
    m = len(c)
    z = np.zeros(0)
    return SphereModel(centers=c, radii=np.full(m, 0.55 * h), colour=np.zeros(m, np.int8),
                       colour_source=np.full(m, -1, np.int32), bonds=np.zeros((0, 2), np.int64),
                       bonded=np.zeros(0, bool), cut_by=np.zeros(0, np.int32), member_sphere=np.zeros(0, np.int64),
                       member_disc=np.zeros(0, np.int32), member_kind=np.zeros(0, np.int8), member_offset=z,
                       disc_centre=np.zeros((0, 3)), disc_normal=np.zeros((0, 3)), disc_radius=z,
                       disc_thickness=z, disc_name=[])


def picture_rows(sizes, repeats, every_up_to):
    """The picture alone of grid_model(n) for each n: (n^3, drawn, hidden, median s, median s drawing every
    sphere or None)."""
    # not at the top: only --picture draws in this process (see grid_model)
    import sgim.render as render_mod

    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_picture_") as d:
        render_mod.render(grid_model(10), Path(d) / "warm.png")
        for n in sizes:
            model = grid_model(n)
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                info = render_mod.render(model, Path(d) / "p.png", title="block")
                times.append(time.perf_counter() - t0)
            every = None
            if n ** 3 <= every_up_to:
                keep = render_mod.in_sight
                render_mod.in_sight = lambda frame, centers, solid, ghost, px: (solid, ghost)
                try:
                    every = []
                    for _ in range(repeats):
                        t0 = time.perf_counter()
                        render_mod.render(model, Path(d) / "e.png", title="block")
                        every.append(time.perf_counter() - t0)
                finally:
                    render_mod.in_sight = keep
                every = statistics.median(every)
            say(f"picture of {n ** 3} spheres: {statistics.median(times):.2f} s, {info['drawn']} drawn")
            rows.append((n ** 3, info["drawn"], info["hidden"], statistics.median(times), every))
    return rows


def picture_table(rows):
    lines = ["| spheres | drawn | left out | picture | every sphere drawn |", "|---|---|---|---|---|"]
    for n, drawn, hidden, t, every in rows:
        lines.append(f"| {n:,} | {drawn:,} | {hidden:,} | {t:.2f} s | "
                     f"{'-' if every is None else f'{every:.2f} s'} |".replace(",", " "))
    return "\n".join(lines)


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
    ap.add_argument("--large", action="store_true", help="the 10 m cube only")
    ap.add_argument("--repeats", type=int, default=3, help="counted builds per case (default 3; medians)")
    ap.add_argument("--repo", default=str(REPO), help="the checkout whose sgim is run (default: this one)")
    ap.add_argument("--json", help="also write the results to this JSON file")
    ap.add_argument("--picture", action="store_true",
                    help="the picture alone of 10^5, 10^6 and 10^7 spheres in this process (instead of the builds)")
    args = ap.parse_args(argv)
    if args.picture:
        sizes = (46, 100) if args.quick else (46, 100, 215)
        rows = picture_rows(sizes, args.repeats, every_up_to=1_100_000)
        report(f"sgim.render.render of an opaque block of n^3 spheres in a 10 m cube, 1600 x 1100, medians of "
               f"{args.repeats}", picture_table(rows), args.json, {"picture": rows})
        return
    repo = Path(args.repo).resolve()
    if not (repo / "sgim" / "cli.py").is_file():
        raise SystemExit(f"--repo = {args.repo!r}: no sgim/cli.py there")
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True).stdout
    cubes = CUBES[:1] if args.quick else CUBES[1:] if args.large else CUBES
    with tempfile.TemporaryDirectory(prefix="bench_picture_") as d:
        rows = [run_case(repo, Path(d), name, side, args.repeats) for name, side in cubes]
    report(f"Default `sgim build` of equal random spheres (r = 0.05 m) at {rev.strip() or repo}, medians of "
           f"{args.repeats} warm runs", table(rows), args.json, {"revision": rev.strip(), "rows": rows})


def report(title, text, json_path, data):
    """The title with the load average, the machine line and the table on stdout; the data, machine and load
    average to `json_path` when given."""
    print(f"{title}; load average {os.getloadavg()[0]:.1f}")
    print(machine_line())
    print()
    print(text)
    if json_path:
        Path(json_path).write_text(json.dumps({"machine": machine_info(), "load_average": os.getloadavg(), **data},
                                              indent=2))


if __name__ == "__main__":
    main()
