"""Benchmark of numba's compilation on the default build path (issue 15, point 3).

What is measured
----------------
``sgim build SCENE --formats npz`` (default: the built-in open pit, cases/scenes/open_pit.toml) in a child process
with an empty numba cache of its own (a newcomer's first run: every kernel compiled), then again with that cache
filled (every kernel loaded). numba's compile events are recorded in the cold child: the seconds spent compiling
each kernel the build calls (a kernel's own compilation with the callees it compiles on the way; the sum is the
compilation's share of the cold run) and every kernel compiled for more than one signature (each signature is a
compilation of its own). The table gives the medians of the repeats, cold and warm wall time, the compilation
seconds, and the top kernels.

``--repo PATH`` runs the sgim of another checkout (``git worktree add --detach /tmp/before REV``): the figures
before a change, in the same run conditions. Compilation is CPU work in one thread: the load average printed with
the table says how much the machine's other work slowed it.

Run
---
    .venv/bin/python -m cases.bench.compile                     # the open pit, 3 cold and 3 warm runs
    .venv/bin/python -m cases.bench.compile --repo /tmp/before  # another checkout
    .venv/bin/python -m cases.bench.compile --repeats 1 --scene cases/scenes/tunnel_jointed.toml
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sgim.machine import machine_info, machine_line

REPO = Path(__file__).resolve().parents[2]
T0 = time.perf_counter()

# run in the child: the build with numba's compile events recorded; prints one JSON line
CHILD = r"""
import json, sys, time
from numba.core import event
from numba.core.registry import CPUDispatcher
from sgim.cli import main

spans, stack = {}, []
with event.install_recorder("numba:compile") as rec:
    t0 = time.perf_counter()
    code = main(["build", sys.argv[1], "-o", sys.argv[2], "--force", "--quiet", "--formats", "npz"])
    wall = time.perf_counter() - t0
for ts, e in rec.buffer:
    d = (e.data or {}).get("dispatcher")
    key = f"{d.py_func.__module__}.{d.py_func.__qualname__}" if d is not None else "other"
    if e.is_start:
        stack.append((key, ts))
    else:
        k, t = stack.pop()
        if not stack:  # a kernel the build itself called: its compilation with that of its callees
            spans[k] = spans.get(k, 0.0) + ts - t
multi = {}
for name, mod in list(sys.modules.items()):
    if name.split(".")[0] in ("sgim", "dda"):
        for attr, f in vars(mod).items():
            if isinstance(f, CPUDispatcher) and len(f.signatures) > 1:
                multi[f"{name}.{attr}"] = len(f.signatures)
print(json.dumps({"code": code, "wall": wall, "compile": spans, "signatures": multi}))
"""


def say(msg):
    print(f"[bench_compile {time.perf_counter() - T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


def child(repo, scene, out, cache):
    """One build in a child process with NUMBA_CACHE_DIR = cache: (its JSON record, wall seconds of the child)."""
    env = dict(os.environ, PYTHONPATH=str(repo), NUMBA_CACHE_DIR=str(cache))
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(out)], cwd=repo, env=env,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode:
        raise SystemExit(f"sgim build {scene} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1]), wall


def measure(repo, scene, repeats):
    """Cold and warm builds, each cold one with a fresh cache: the rows of the table."""
    cold, warm = [], []
    with tempfile.TemporaryDirectory(prefix="bench_compile_") as d:
        for k in range(repeats):
            cache = Path(d) / f"cache{k}"
            rec, wall = child(repo, scene, Path(d) / "out", cache)
            cold.append((rec, wall))
            say(f"cold {k + 1}/{repeats}: {wall:.1f} s, {sum(rec['compile'].values()):.1f} s compiling")
            rec, wall = child(repo, scene, Path(d) / "out", cache)
            warm.append((rec, wall))
            say(f"warm {k + 1}/{repeats}: {wall:.1f} s")
    kernels = sorted({k for rec, _ in cold for k in rec["compile"]})
    per = {k: statistics.median(rec["compile"].get(k, 0.0) for rec, _ in cold) for k in kernels}
    return {"cold_wall_s": statistics.median(w for _, w in cold), "warm_wall_s": statistics.median(w for _, w in warm),
            "compile_s": statistics.median(sum(rec["compile"].values()) for rec, _ in cold),
            "kernels": per, "signatures": cold[0][0]["signatures"]}


def table(res, top):
    lines = ["| measurement | seconds |", "|---|---|",
             f"| whole child process, empty numba cache (cold) | {res['cold_wall_s']:.2f} |",
             f"| whole child process, cache filled (warm) | {res['warm_wall_s']:.2f} |",
             f"| compiling (numba's compile events, cold) | {res['compile_s']:.2f} |"]
    lines += ["", "| kernel the build calls (with the callees it compiles) | compile s |", "|---|---|"]
    for k, v in sorted(res["kernels"].items(), key=lambda kv: -kv[1])[:top]:
        lines.append(f"| {k} | {v:.2f} |")
    if res["signatures"]:
        lines += ["", "kernels compiled for more than one signature: "
                  + ", ".join(f"{k} ({n})" for k, n in sorted(res["signatures"].items()))]
    else:
        lines += ["", "every kernel compiled for one signature"]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=str(REPO / "cases" / "scenes" / "open_pit.toml"),
                    help="the scene built (default: the open pit)")
    ap.add_argument("--repeats", type=int, default=3, help="cold and warm builds (default 3; medians)")
    ap.add_argument("--repo", default=str(REPO), help="the checkout whose sgim is run (default: this one)")
    ap.add_argument("--top", type=int, default=10, help="kernels listed (default 10)")
    ap.add_argument("--json", help="also write the results to this JSON file")
    args = ap.parse_args(argv)
    repo = Path(args.repo).resolve()
    if not (repo / "sgim" / "cli.py").is_file():
        raise SystemExit(f"--repo = {args.repo!r}: no sgim/cli.py there")
    if args.repeats < 1:
        raise SystemExit(f"--repeats = {args.repeats}: must be at least 1")
    scene = Path(args.scene).resolve()
    if not scene.is_file():
        raise SystemExit(f"--scene = {args.scene!r}: no such file")
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True).stdout
    res = measure(repo, scene, args.repeats)
    print(f"`sgim build {scene.name} --formats npz` at {rev.strip() or repo}, medians of {args.repeats}; load "
          f"average {os.getloadavg()[0]:.1f}")
    print(machine_line())
    print()
    print(table(res, args.top))
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": machine_info(), "load_average": os.getloadavg(),
                                               "revision": rev.strip(), **res}, indent=2))


if __name__ == "__main__":
    main()
