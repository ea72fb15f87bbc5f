"""Benchmark: the study runner's parallel efficiency and framework overhead; a table on stdout, never a test.

    .venv/bin/python -m cases.bench.study [--cases 32] [--seconds 1.0] [--ranks 2] [--noop 200] [--overhead-only]
                                          [--json]

- scaling: a study of --cases equal cases of the built-in "spin" evaluator (a fixed single-core numpy workload
  calibrated here to about --seconds per case), run serially (`cases study run`) and under
  `mpirun -n --ranks` (`mpirun ... cases study run`). Parallel efficiency = T1 / (ranks x Tn), with T the wall
  time of the whole command (interpreter and mpirun start included) and, in a second column, the runner's own
  time (OUTDIR/runs.jsonl: from the study read to the table closed). The two tables are compared on every
  value (the workload is deterministic: identical to the last bit).
- overhead: the built-in "noop" evaluator, a study of --noop cases against a study of 1 case, serial and under
  mpirun: (T(noop cases) - T(1 case)) / (noop - 1) per case: handing out a case, the fork of its fresh process
  from the rank's case server, its folder and scene file, the round trip and the table rows; next to it the CPU
  time per case of the whole process tree (runner, case servers, cases) and, for scale, the cost of a bare
  os.fork + exit + wait of a process that imported what the case server imports.

The machine's load average (1 min) is printed next to each figure: on a machine with as many cores as ranks,
any other work lowers the efficiency. The median case time under mpirun against serial and the share of the
ranks' time spent inside cases tell contention for cores (cases slower) from the framework (ranks idle).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sgim.machine import machine_info, machine_line

# The evaluator's workload (cases.lib.study) is imported inside calibrate(): the benchmark times the runner in
# fresh processes and `--help` loads nothing of the study runner.

REPO = Path(__file__).resolve().parents[2]
SIZE = 100_000


def _mpirun(n):
    exe = shutil.which("mpirun")
    if exe is None:
        raise SystemExit("bench_study: mpirun not found (install openmpi-bin and pip install mpi4py)")
    cmd = [exe, "--oversubscribe", "-n", str(n)]
    if os.geteuid() == 0:
        cmd.insert(1, "--allow-run-as-root")
    return cmd


def calibrate(seconds):
    """Iterations of the spin workload (SIZE elements) that take about `seconds` on one core."""
    from cases.lib.study import _spin

    folder = Path(tempfile.mkdtemp(prefix="bench_study_cal"))
    try:
        scene = folder / "scene.toml"
        scene.write_text(f"[work]\niterations = 20\nsize = {SIZE}\n")
        _spin(scene, folder, {})
        t0 = time.perf_counter()
        _spin(scene, folder, {})
        per_it = (time.perf_counter() - t0) / 20
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return max(1, round(seconds / per_it))


def write_study(folder, name, engine, n, iterations):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.toml").write_text(f"[work]\niterations = {iterations}\nsize = {SIZE}\noffset = 0.0\n")
    offsets = ", ".join(repr(i / 1000) for i in range(n))
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nbase = "base.toml"\nevaluator = "{engine}"\nresults = ["value"]\n'
                    f'[parameters]\n"work.offset" = {{ grid = [{offsets}] }}\n')
    return path


def _children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def fork_cost(n=200):
    """ms of wall and CPU per os.fork + os._exit + waitpid of a process holding the case server's imports."""
    code = ("import os, time, resource, gc, cases.lib._caseserver, cases.lib.evaluators\n"
            "gc.freeze()\n"
            f"n = {n}\n"
            "c0 = time.process_time(); t0 = time.perf_counter()\n"
            "for _ in range(n):\n"
            "    pid = os.fork()\n"
            "    if pid == 0:\n"
            "        os._exit(0)\n"
            "    os.waitpid(pid, 0)\n"
            "wall = time.perf_counter() - t0\n"
            "ch = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
            "print(1e3 * wall / n, 1e3 * (time.process_time() - c0 + ch.ru_utime + ch.ru_stime) / n)\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    wall, cpu = map(float, r.stdout.split())
    return {"wall_ms": wall, "cpu_ms": cpu}


def timed_run(study, out, ranks, extra=()):
    cmd = [sys.executable, "-m", "cases.cli", "study", "run", str(study), "-o", str(out), "--quiet", *extra]
    if ranks > 1:
        cmd = _mpirun(ranks) + cmd
    load = os.getloadavg()[0]
    c0 = _children_cpu()
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    cpu = _children_cpu() - c0
    if r.returncode != 0:
        raise SystemExit(f"bench_study: {' '.join(cmd)} failed:\n{r.stderr[-2000:]}")
    inner = json.loads((out / "runs.jsonl").read_text().splitlines()[-1])["wall_s"]
    return {"wall_s": wall, "runner_s": inner, "cpu_s": cpu, "load1": load, "load1_after": os.getloadavg()[0]}


def table_values(out):
    with open(out / "results.csv", newline="") as fh:
        return [(r["case_id"], r["status"], r["p:work.offset"], r["value"]) for r in csv.DictReader(fh)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=32, help="cases of the scaling study")
    ap.add_argument("--seconds", type=float, default=1.0, help="target time of one case [s]")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks")
    ap.add_argument("--noop", type=int, default=200, help="cases of the overhead study")
    ap.add_argument("--overhead-only", action="store_true", help="only the framework overhead (no scaling study)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON on stdout (after the table)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the study folders here")
    args = ap.parse_args(argv)

    work = args.keep or Path(tempfile.mkdtemp(prefix="bench_study"))
    if args.keep:
        shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    res = {"ranks": args.ranks, "machine": machine_info()}
    try:
        if not args.overhead_only:
            iters = calibrate(args.seconds)
            spin = write_study(work, "spin", "spin", args.cases, iters)
            s1 = timed_run(spin, work / "spin_1", 1)
            sn = timed_run(spin, work / f"spin_{args.ranks}", args.ranks)
            identical = table_values(work / "spin_1") == table_values(work / f"spin_{args.ranks}")
            with open(work / "spin_1" / "results.csv", newline="") as fh:
                case_s = sorted(float(r["wall_s"]) for r in csv.DictReader(fh))
            with open(work / f"spin_{args.ranks}" / "results.csv", newline="") as fh:
                case_n = sorted(float(r["wall_s"]) for r in csv.DictReader(fh))
            res.update({"cases": args.cases, "spin_iterations": iters, "case_median_s": case_s[len(case_s) // 2],
                        "case_median_mpi_s": case_n[len(case_n) // 2],
                        "busy_mpi": sum(case_n) / (args.ranks * sn["runner_s"]), "serial": s1, "mpi": sn,
                        "efficiency": s1["wall_s"] / (args.ranks * sn["wall_s"]),
                        "efficiency_runner": s1["runner_s"] / (args.ranks * sn["runner_s"]),
                        "identical_tables": identical})
        noop_n = write_study(work, "noop", "noop", args.noop, 1)
        noop_1 = write_study(work, "noop1", "noop", 1, 1)
        over = {}
        for ranks, mode in ((1, "fork"), (args.ranks, "fork"), (1, "reuse"), (args.ranks, "reuse")):
            extra = ("--reuse-process",) if mode == "reuse" else ()
            a = timed_run(noop_1, work / f"noop1_{ranks}_{mode}", ranks, extra)
            b = timed_run(noop_n, work / f"noop_{ranks}_{mode}", ranks, extra)
            over[(ranks, mode)] = {"per_case_ms": 1e3 * (b["wall_s"] - a["wall_s"]) / (args.noop - 1),
                           "runner_per_case_ms": 1e3 * (b["runner_s"] - a["runner_s"]) / (args.noop - 1),
                           "cpu_per_case_ms": 1e3 * (b["cpu_s"] - a["cpu_s"]) / (args.noop - 1),
                           "load1": b["load1"]}
        res["overhead"] = {f"{k[0]} {k[1]}": v for k, v in over.items()}
        res["fork"] = fork_cost()
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    print(machine_line(res["machine"]))
    if not args.overhead_only:
        s1, sn = res["serial"], res["mpi"]
        print(f"study runner benchmark: {args.cases} equal cases (spin, median {res['case_median_s']:.3f} s per case)")
        print(f"{'run':24s} {'wall s':>8s} {'runner s':>9s} {'load1':>6s}")
        print(f"{'serial':24s} {s1['wall_s']:8.2f} {s1['runner_s']:9.2f} {s1['load1']:6.2f}")
        print(f"{'mpirun -n %d' % args.ranks:24s} {sn['wall_s']:8.2f} {sn['runner_s']:9.2f} {sn['load1']:6.2f}")
        print(f"parallel efficiency T1/({args.ranks} T{args.ranks}): {100 * res['efficiency']:.1f} % (whole command), "
              f"{100 * res['efficiency_runner']:.1f} % (runner)   target >= 90 %")
        print(f"cases under mpirun: median {res['case_median_mpi_s']:.3f} s per case (serial "
              f"{res['case_median_s']:.3f} s), ranks busy in cases {100 * res['busy_mpi']:.1f} % of the runner time")
        print(f"serial and MPI tables identical (every value, repr): {res['identical_tables']}")
    print(f"framework overhead per case ({args.noop} noop cases against 1; fork: every case a fresh process, the "
          f"default; reuse: --reuse-process):")
    for (k, mode), v in over.items():
        label = ("serial" if k == 1 else f"mpirun -n {k}") + f", {mode}"
        print(f"  {label:22s} {v['per_case_ms']:7.2f} ms wall (runner {v['runner_per_case_ms']:.2f} ms), "
              f"{v['cpu_per_case_ms']:.2f} ms CPU of all processes  load1 {v['load1']:.2f}   target <= 1 ms")
    f = res["fork"]
    print(f"  for scale: os.fork + exit + wait of the case server's image: {f['wall_ms']:.2f} ms wall, "
          f"{f['cpu_ms']:.2f} ms CPU")
    if args.json:
        print(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
