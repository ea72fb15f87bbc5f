"""Benchmark of the SGIM sphere generator (sgim): speed, memory, a YADE peer and excavation accuracy.

What is measured
----------------
1. End to end: ``sgim build SCENE -o DIR --formats npz --quiet --json`` run as a subprocess
   (parse, lattice + excavation, cutting, bonds, model.npz) for cases/scenes/open_pit.toml and for a
   pit in the same box (same r, same discontinuities) whose surface lies low in the box so that
   about 90 % of the lattice sites are removed.  Each case gets a fresh, empty numba cache
   (NUMBA_CACHE_DIR): its first run compiles every kernel and is reported as "cold"; the warm
   figures are medians of the following runs.  Wall time is taken around the child process (so it
   includes interpreter start and imports); peak memory is the child's ru_maxrss from os.wait4;
   stage times come from the JSON the build prints.  A third case, the open pit at r = 5 (10 500
   sites), measures the fixed cost (interpreter start, imports, loading kernels from the cache,
   parsing the 3 434-facet surface); the marginal cost per kept sphere is taken above it.
2. Peer: YADE's ``pack.regularOrtho(predicate, radius=r, gap=0)`` in a ``yade -n -x`` subprocess,
   with a Python ``pack.Predicate`` for the open pit's excavating surface under sgim's "exact"
   excavation rule (keep a site inside the box and at least r below the surface).  The predicate
   looks up, per lattice column, the highest z that keeps a ball of radius r under the surface; that
   table is computed here with numpy/matplotlib from sgim's facets (sampling the surface over a
   disc of radius r around each column), independently of sgim's kernels.  sgim runs on the same
   box, radius, surface and rule; the two sets of kept centres are compared site by site.
3. Rules: on the open pit, the sites kept by the paper's rule (eq. 3-12) and by the exact rule
   (removed when above the surface in plan projection or closer than r to a facet), and their
   symmetric difference.
4. Speed against error: two surfaces in a 100 x 80 x 40 box whose solid volume below the surface
   has a closed form (each cross-checked here by a fine midpoint-rule integration of the facet
   surface): an inclined plane, and a rectangular pit with three benches (planar faces and berms)
   sheared onto a 4 degree incline (the shear keeps every facet planar and the closed form simple,
   and stops flat berms from lining up with lattice layers, which would make the error depend on
   alignment rather than on r).  r halves from 2 to 0.125 (cubic packing), both rules; kept volume
   = spheres x (2r)^3.  For the coarser radii the kept set is also checked against a brute-force
   evaluation of the rule at every lattice site.

Timings are medians of repeats (the machine has 2 cores shared with other work).  In-process timings
(parts 2-4) are warm: numba kernels loaded and the process's memory already mapped; the first touch
of fresh memory, which every real ``sgim build`` pays once, is inside the end-to-end figures of part 1.

Run
---
    .venv/bin/python -m cases.bench.sgim                 # full run, a few minutes
    .venv/bin/python -m cases.bench.sgim --quick         # smoke run, under a minute: r = 1 for the
                                                         # end-to-end scenes and the rules, r = 2.5 for
                                                         # YADE, r down to 0.25, one warm repeat
    .venv/bin/python -m cases.bench.sgim --json out.json # also write the results as JSON

Markdown tables go to stdout, progress lines to stderr.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
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
from cases.bench.surfaces import BenchPit, integrate_solid, keep_heights, low_pit_points, surface_interpolator, \
    tie_split
from cases.make.open_pit import BOX
from sgim.machine import machine_info, machine_line

REPO = Path(__file__).resolve().parents[2]
OPEN_PIT = SCENES / "open_pit.toml"
GB = 1e9
T_START = time.perf_counter()


def say(msg):
    print(f"[{time.perf_counter() - T_START:6.1f} s] {msg}", file=sys.stderr, flush=True)


def median(xs):
    return float(statistics.median(xs))


# ---------------------------------------------------------------------------------------------
# small helpers: Markdown tables, TOML writing, sgim subprocess runs

def md_table(headers, rows):
    cells = [[str(c) for c in r] for r in rows]
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in cells]
    return "\n".join(lines)


def fmt_int(n):
    return f"{int(n):,}".replace(",", " ")


def fmt_s(t):
    return "-" if t is None else (f"{t:.3f}" if t < 10 else f"{t:.1f}")


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"cannot write {v} to TOML")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def toml_dumps(data: dict) -> str:
    """TOML text for the scene layout: scalars, tables of scalars, arrays of tables of scalars."""
    head, tables, arrays = [], [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables.append((k, v))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            arrays.append((k, v))
        else:
            head.append(f"{k} = {_toml_value(v)}")
    out = head + [""]
    for k, tab in tables:
        out += [f"[{k}]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in tab.items()] + [""]
    for k, items in arrays:
        for tab in items:
            out += [f"[[{k}]]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in tab.items()] + [""]
    return "\n".join(out)


def run_build(scene, outdir, cache_dir):
    """One ``sgim build`` child process: (summary JSON, wall s, peak RSS bytes)."""
    cmd = [sys.executable, "-m", "sgim.cli", "build", str(scene), "-o", str(outdir), "--formats", "npz",
           "--quiet", "--json"]
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    log_out = Path(str(outdir) + ".stdout")
    log_err = Path(str(outdir) + ".stderr")
    with open(log_out, "wb") as fo, open(log_err, "wb") as fe:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=fo, stderr=fe, cwd=REPO, env=env)
        _, status, ru = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    shutil.rmtree(outdir, ignore_errors=True)
    if proc.returncode != 0:
        raise RuntimeError(f"sgim build {scene} failed (exit {proc.returncode}): "
                           f"{log_err.read_text(errors='replace')[-2000:]}")
    info = json.loads(log_out.read_text())
    log_out.unlink()
    log_err.unlink()
    return info, wall, ru.ru_maxrss * 1024


# ---------------------------------------------------------------------------------------------
# 1. end to end

def bench_end_to_end(work, quick, repeats):
    scene_open = OPEN_PIT
    data = tomllib.loads(OPEN_PIT.read_text())
    low = {k: v for k, v in data.items() if k != "excavation"}
    low["name"] = "low_pit_90pct_removed"
    low["excavation"] = [{"name": "low terrain and small pit", "rule": "paper",
                          "points": low_pit_points(BOX).tolist()}]
    scene_low = work / "low_pit.toml"
    scene_low.write_text(toml_dumps(low))
    cases = [("open pit (cases/scenes/open_pit.toml)", scene_open), ("low pit, ~90 % removed", scene_low)]
    if quick:  # same geometry, r = 1.0 (8x fewer sites)
        for i, (name, path) in enumerate(cases):
            d = tomllib.loads(path.read_text())
            d["packing"]["radius"] = 1.0
            q = work / f"quick_{i}.toml"
            q.write_text(toml_dumps(d))
            cases[i] = (name + " [quick: r = 1.0]", q)
    # fixed-cost probe: the open pit at r = 5 (interpreter start, imports, kernel loading, parse)
    d = tomllib.loads(OPEN_PIT.read_text())
    d["packing"]["radius"] = 5.0
    probe = work / "probe_r5.toml"
    probe.write_text(toml_dumps(d))
    cases.append(("fixed-cost probe: open pit at r = 5", probe))
    rows = []
    for ci, (name, path) in enumerate(cases):
        if ci < (1 if quick else 2):  # (--quick: only the first case gets a cold run)
            cache = work / f"numba_cache_case{ci}"
            cache.mkdir()
            say(f"end to end: {name}: cold run (fresh numba cache)")
            info_c, wall_c, rss_c = run_build(path, work / f"out{ci}", cache)
        else:  # reuse the open pit's warm cache
            cache = work / "numba_cache_case0"
            info_c, wall_c, rss_c = {"timings_s": None}, None, None
        runs = []
        for k in range(repeats):
            say(f"end to end: {name}: warm run {k + 1}/{repeats}")
            runs.append(run_build(path, work / f"out{ci}", cache))
        walls = [w for _, w, _ in runs]
        stages = {}
        for key in ("parse", "excavate", "cut", "bonds", "write npz", "total"):
            stages[key] = median([i["timings_s"].get(key, float("nan")) for i, _, _ in runs])
        info = runs[0][0]
        kept = info["spheres"]
        sites = info["meta"]["packing"]["lattice_sites"]
        wall = median(walls)
        rows.append({
            "case": name, "scene": str(path), "radius": info["meta"]["packing"]["radius"],
            "lattice_sites": sites, "spheres_kept": kept, "kept_fraction": kept / sites,
            "bonds": info["bonds"], "bonded": info["bonded"],
            "wall_s_median": wall, "wall_s_runs": walls, "wall_s_cold": wall_c,
            "cold_stage_s": info_c["timings_s"], "stage_s_median": stages,
            "spheres_per_s": kept / wall, "us_per_kept_sphere_wall": wall / kept * 1e6,
            "us_per_kept_sphere_stages": (stages["total"] - stages["parse"]) / kept * 1e6,
            "peak_rss_bytes": max(r for _, _, r in runs), "peak_rss_bytes_cold": rss_c,
        })
    pr = rows[-1]
    for row in rows[:-1]:  # marginal cost per kept sphere above the fixed-cost probe
        dn = row["spheres_kept"] - pr["spheres_kept"]
        row["marginal_us_per_kept_sphere_wall"] = (row["wall_s_median"] - pr["wall_s_median"]) / dn * 1e6
        row["marginal_us_per_kept_sphere_stages"] = ((row["stage_s_median"]["total"] - row["stage_s_median"]["parse"])
                                                     - (pr["stage_s_median"]["total"] - pr["stage_s_median"]["parse"])) / dn * 1e6
    return rows


def table_end_to_end(rows):
    hdr = ["case", "lattice sites", "spheres kept", "wall s (median)", "cold wall s", "spheres kept/s",
           "parse s", "excavate s", "cut s", "bonds s", "write npz s", "µs/kept sphere (wall)",
           "µs/kept sphere (stages w/o parse)", "marginal µs/kept sphere over the probe (wall / stages)",
           "peak RSS GB (warm / cold)"]
    out = []
    for r in rows:
        st = r["stage_s_median"]
        marg = (f"{r['marginal_us_per_kept_sphere_wall']:.2f} / {r['marginal_us_per_kept_sphere_stages']:.2f}"
                if "marginal_us_per_kept_sphere_wall" in r else "-")
        cold_rss = "-" if r["peak_rss_bytes_cold"] is None else f"{r['peak_rss_bytes_cold'] / GB:.2f}"
        out.append([r["case"], fmt_int(r["lattice_sites"]), f"{fmt_int(r['spheres_kept'])} ({100 * r['kept_fraction']:.1f} %)",
                    fmt_s(r["wall_s_median"]), fmt_s(r["wall_s_cold"]), fmt_int(r["spheres_per_s"]),
                    fmt_s(st["parse"]), fmt_s(st["excavate"]), fmt_s(st["cut"]), fmt_s(st["bonds"]),
                    fmt_s(st["write npz"]), f"{r['us_per_kept_sphere_wall']:.2f}",
                    f"{r['us_per_kept_sphere_stages']:.2f}", marg,
                    f"{r['peak_rss_bytes'] / GB:.2f} / {cold_rss}"])
    return md_table(hdr, out)


# ---------------------------------------------------------------------------------------------
# 2. YADE peer

YADE_SCRIPT = r'''
import json, sys, time
import numpy as np
from yade import pack
try:
    from yade import Vector3
except ImportError:
    from minieigen import Vector3

heff_path, par_path, out_path = sys.argv[1:4]
P = json.load(open(par_path))
LO, HI, R = P["lo"], P["hi"], P["r"]
H = np.load(heff_path, allow_pickle=False)
NX, NY = H.shape
HL = H.tolist()
STEP = 2.0 * R
X0, Y0 = LO[0] + R, LO[1] + R
TOL = 1e-9 * max(HI[a] - LO[a] for a in range(3))


class BelowSurface(pack.Predicate):
    """Inside the box and at least r below the excavating surface (per-column keep height)."""

    def __init__(self):
        pack.Predicate.__init__(self)

    def aabb(self):
        # regularOrtho places centres at arange(min + r, max - r, 2r): arange drops its end point,
        # so the upper corner is nudged by 1e-6 r to get the full lattice of the box
        e = 1e-6 * R
        return Vector3(LO[0], LO[1], LO[2]), Vector3(HI[0] + e, HI[1] + e, HI[2] + e)

    def center(self):
        return Vector3(*[(LO[a] + HI[a]) / 2 for a in range(3)])

    def dim(self):
        return Vector3(*[HI[a] - LO[a] for a in range(3)])

    def __call__(self, pt, pad, lo=LO, hi=HI, hl=HL, tol=TOL):
        x, y, z = pt[0], pt[1], pt[2]
        if (x - pad < lo[0] - tol or x + pad > hi[0] + tol or y - pad < lo[1] - tol or y + pad > hi[1] + tol
                or z - pad < lo[2] - tol or z + pad > hi[2] + tol):
            return False
        i = int(round((x - X0) / STEP))
        j = int(round((y - Y0) / STEP))
        if i < 0 or j < 0 or i >= NX or j >= NY:
            return False
        return z <= hl[i][j]


pred = BelowSurface()
t0 = time.perf_counter()
spheres = pack.regularOrtho(pred, radius=R, gap=0)
t1 = time.perf_counter()
pos = np.array([tuple(b.state.pos) for b in spheres], dtype=float).reshape(-1, 3)
np.savez(out_path, pos=pos, t_regular_ortho=t1 - t0, n=len(spheres))
print("YADE_DONE", len(spheres), t1 - t0)
sys.exit(0)
'''


def site_index(c, lo, r, dims):
    """Linear index of cubic-lattice centres (x = lo + r(2i+1))."""
    ijk = np.rint((c - np.asarray(lo)) / (2 * r) - 0.5).astype(np.int64)
    return (ijk[:, 2] * dims[1] + ijk[:, 1]) * dims[0] + ijk[:, 0]


def bench_yade(work, quick, cache):
    # lazy: part 1 times fresh `sgim build` processes; this process loads sgim's kernels only for parts 2-4
    from sgim.excavate import FacetSet, kept_sites
    from sgim.packing import make_lattice
    from sgim.scene import load_scene

    r = 2.5 if quick else 1.0
    scene = load_scene(OPEN_PIT)
    lo, hi = scene.domain.min, scene.domain.max
    dims = [int(round((hi[a] - lo[a]) / (2 * r))) for a in range(3)]
    assert all(abs(dims[a] * 2 * r - (hi[a] - lo[a])) < 1e-9 for a in range(3)), "box must be a multiple of 2r"
    surf = dataclasses.replace(scene.excavations[0], rule="exact")
    say(f"yade peer: keep heights for r = {r} from sgim's {len(surf.faces)} facets")
    t0 = time.perf_counter()
    heff = keep_heights(surface_interpolator(surf.vertices, surf.faces), lo, hi, r)
    t_heff = time.perf_counter() - t0
    np.save(work / "heff.npy", heff)
    (work / "yade_params.json").write_text(json.dumps({"lo": lo.tolist(), "hi": hi.tolist(), "r": r}))
    (work / "yade_regular_ortho.py").write_text(YADE_SCRIPT)

    # sgim on the identical geometry: lattice + excavation, in process (warm), median of 5
    # (results are dropped between calls, so repeats reuse memory the process already has mapped)
    def sgim_once():
        t = time.perf_counter()
        lat = make_lattice("cubic", lo, hi, r)
        c = kept_sites(lat, FacetSet([surf]), lo, hi)
        return c, time.perf_counter() - t

    centres = sgim_once()[0]
    t_sgim = median([sgim_once()[1] for _ in range(5)])

    # sgim build (whole pipeline, child process) on the open pit scene at this r with the exact rule
    data = tomllib.loads(OPEN_PIT.read_text())
    data["packing"]["radius"] = r
    data["excavation"][0]["rule"] = "exact"
    scene_r = work / "open_pit_exact_r.toml"
    scene_r.write_text(toml_dumps(data))
    run_build(scene_r, work / "outy", cache)  # warm-up
    b = [run_build(scene_r, work / "outy", cache) for _ in range(3)]
    t_build = median([w for _, w, _ in b])
    n_build = b[0][0]["spheres"]

    res = {"radius": r, "box": [lo.tolist(), hi.tolist()], "lattice_sites": int(np.prod(dims)),
           "keep_height_table_s": t_heff,
           "sgim_kept_sites": {"spheres": int(len(centres)), "s_median": t_sgim,
                               "spheres_per_s": len(centres) / t_sgim},
           "sgim_build_cli": {"spheres": int(n_build), "wall_s_median": t_build, "spheres_per_s": n_build / t_build,
                              "discontinuities": len(scene.discontinuities),
                              "note": "whole pipeline incl. interpreter start, discontinuities, bonds, npz"}}
    yade = shutil.which("yade")
    if yade is None:
        res["yade"] = {"status": "yade not installed"}
        return res
    say(f"yade peer: yade -n -x regularOrtho at r = {r} ({fmt_int(np.prod(dims))} lattice sites)")
    out = work / "yade_out.npz"
    t0 = time.perf_counter()
    try:
        p = subprocess.run([yade, "-n", "-x", str(work / "yade_regular_ortho.py"), str(work / "heff.npy"),
                            str(work / "yade_params.json"), str(out)], cwd=work, capture_output=True, text=True,
                           timeout=300)
        wall = time.perf_counter() - t0
        ok = p.returncode == 0 and out.exists()
        tail = (p.stdout + p.stderr)[-1500:]
    except subprocess.TimeoutExpired:
        wall, ok, tail = time.perf_counter() - t0, False, "timed out after 300 s"
    if not ok:
        res["yade"] = {"status": "yade failed", "log_tail": tail}
        return res
    with np.load(out, allow_pickle=False) as z:
        pos, t_ro, n_y = z["pos"], float(z["t_regular_ortho"]), int(z["n"])
    iy = site_index(pos, lo, r, dims)
    isg = site_index(centres, lo, r, dims)
    y_only = pos[~np.isin(iy, isg)]
    s_only = centres[~np.isin(isg, iy)]
    yt, yn, ymin = tie_split(y_only, surf.vertices, surf.faces, r)
    st, sn, smin = tie_split(s_only, surf.vertices, surf.faces, r)
    res["yade"] = {"status": "ok", "version": "2023.02a (Debian)", "spheres": n_y, "regular_ortho_s": t_ro,
                   "process_wall_s": wall, "spheres_per_s": n_y / t_ro,
                   "yade_only_sites": int(len(y_only)), "yade_only_ties": yt, "yade_only_other": yn,
                   "yade_only_other_min_dist_over_r": ymin,
                   "sgim_only_sites": int(len(s_only)), "sgim_only_ties": st, "sgim_only_other": sn,
                   "sgim_only_other_min_dist_over_r": smin}
    return res


def table_yade(res):
    r = res["radius"]
    hdr = ["generator (open pit surface, exact rule, cubic r = %g, %s sites)" % (r, fmt_int(res["lattice_sites"])),
           "spheres", "time s", "spheres/s", "sgim / YADE"]
    y = res["yade"]
    rows = []
    ys = y.get("spheres_per_s")
    if y["status"] == "ok":
        rows.append(["YADE pack.regularOrtho + Python predicate (time inside yade)", fmt_int(y["spheres"]),
                     fmt_s(y["regular_ortho_s"]), fmt_int(ys), "1"])
        rows.append(["YADE process (start, script, saving positions)", fmt_int(y["spheres"]),
                     fmt_s(y["process_wall_s"]), fmt_int(y["spheres"] / y["process_wall_s"]), "-"])
    else:
        rows.append([f"YADE: {y['status']}", "-", "-", "-", "-"])
    s = res["sgim_kept_sites"]
    rows.append(["sgim lattice + excavation (kept_sites, in process, median of 5)", fmt_int(s["spheres"]),
                 f"{s['s_median']:.3f}", fmt_int(s["spheres_per_s"]),
                 f"{s['spheres_per_s'] / ys:.0f}" if ys else "-"])
    b = res["sgim_build_cli"]
    rows.append([f"sgim build (child process: start, parse, excavate, {b['discontinuities']} discs, bonds, npz; "
                 "median of 3)",
                 fmt_int(b["spheres"]), fmt_s(b["wall_s_median"]), fmt_int(b["spheres_per_s"]),
                 f"{b['spheres_per_s'] / ys:.0f}" if ys else "-"])
    text = md_table(hdr, rows)
    if y["status"] == "ok":
        def part(k):
            m = y[f"{k}_other_min_dist_over_r"]
            return (f"{y[k + '_sites']} ({y[k + '_ties']} at distance exactly r, {y[k + '_other']} others"
                    + (f", nearest at {m:.4f} r" if m is not None else "") + ")")

        text += (f"\n\nSame kept set? Sites kept by YADE only: {part('yade_only')}; by sgim only: {part('sgim_only')}. "
                 f"YADE's per-column keep heights were sampled from sgim's facets in {res['keep_height_table_s']:.1f} s "
                 f"(not counted above); distances by an independent numpy point-to-triangle test.")
    return text


# ---------------------------------------------------------------------------------------------
# 3. rules

def bench_rules(quick):
    # lazy: part 1 times fresh `sgim build` processes; this process loads sgim's kernels only for parts 2-4
    from sgim.excavate import FacetSet, kept_sites
    from sgim.packing import lattice_for, make_lattice
    from sgim.scene import load_scene

    scene = load_scene(OPEN_PIT)
    lo, hi = scene.domain.min, scene.domain.max
    lat = make_lattice("cubic", lo, hi, 1.0) if quick else lattice_for(scene)
    r = lat.radius
    dims = [int(round((hi[a] - lo[a]) / (2 * r))) for a in range(3)]
    out = {"radius": r, "lattice_sites": lat.n_sites}
    masks = {}
    for rule in ("paper", "exact"):
        fs = FacetSet([dataclasses.replace(s, rule=rule) for s in scene.excavations])
        kept_sites(lat, fs, lo, hi)  # warm
        ts, c = [], None
        for _ in range(3):
            t = time.perf_counter()
            c = kept_sites(lat, fs, lo, hi)
            ts.append(time.perf_counter() - t)
        m = np.zeros(int(np.prod(dims)), bool)
        m[site_index(c, lo, r, dims)] = True
        masks[rule] = m
        out[rule] = {"kept": int(len(c)), "excavate_s_median": median(ts)}
        say(f"rules: {rule}: {len(c)} kept")
    p, e = masks["paper"], masks["exact"]
    out["paper_keeps_exact_removes"] = int((p & ~e).sum())
    out["exact_keeps_paper_removes"] = int((e & ~p).sum())
    out["symmetric_difference"] = out["paper_keeps_exact_removes"] + out["exact_keeps_paper_removes"]
    verts = np.concatenate([s_.vertices for s_ in scene.excavations])
    faces, base = [], 0
    for s_ in scene.excavations:
        faces.append(s_.faces + base)
        base += len(s_.vertices)
    faces = np.concatenate(faces)
    for key, m in (("paper_keeps_exact_removes", p & ~e), ("exact_keeps_paper_removes", e & ~p)):
        idx = np.nonzero(m)[0]
        ijk = np.column_stack([idx % dims[0], (idx // dims[0]) % dims[1], idx // (dims[0] * dims[1])])
        pts = lo + r * (2 * ijk + 1)
        ties, other, dmin = tie_split(pts, verts, faces, r)
        out[key + "_detail"] = {"at_distance_r": ties, "closer_than_r": other, "min_distance_over_r": dmin}
    return out


def table_rules(res):
    r = res["radius"]
    v = (2 * r) ** 3
    hdr = ["rule", "spheres kept", "excavation s (median of 3)"]
    rows = [[k, fmt_int(res[k]["kept"]), f"{res[k]['excavate_s_median']:.3f}"] for k in ("paper", "exact")]
    t = md_table(hdr, rows)

    def row(label, key):
        d = res[key + "_detail"]
        m = d["min_distance_over_r"]
        return [label, fmt_int(res[key]), f"{100 * res[key] / res['paper']['kept']:.3f}", f"{res[key] * v:.0f}",
                fmt_int(d["at_distance_r"]), fmt_int(d["closer_than_r"]), "-" if m is None else f"{m:.4f}"]

    t += "\n\n" + md_table(
        ["symmetric difference", "sites", "% of paper's kept", "volume m³ (sites x (2r)³)",
         "at distance exactly r (tie)", "closer than r", "nearest of those (/ r)"],
        [row("paper keeps, exact removes", "paper_keeps_exact_removes"),
         row("exact keeps, paper removes", "exact_keeps_paper_removes"),
         ["total", fmt_int(res["symmetric_difference"]),
          f"{100 * res['symmetric_difference'] / res['paper']['kept']:.3f}", f"{res['symmetric_difference'] * v:.0f}",
          "", "", ""]])
    return t


# ---------------------------------------------------------------------------------------------
# 4. speed against error

def inclined_plane():
    """A plane z = 20 + 0.27 x + 0.11 y (dip about 16 degrees) over the benched pit's box."""
    pit = BenchPit()
    lo, hi = np.array(pit.lo), np.array(pit.hi)

    def height(x, y):
        return 20.0 + 0.27 * x + 0.11 * y

    pad = 5.0
    xy = np.array([(lo[0] - pad, lo[1] - pad), (hi[0] + pad, lo[1] - pad), (hi[0] + pad, hi[1] + pad),
                   (lo[0] - pad, hi[1] + pad)])
    verts = np.column_stack([xy, height(xy[:, 0], xy[:, 1])])
    faces = np.array([(0, 1, 2), (0, 2, 3)], np.int64)
    corners = height(np.array([lo[0], hi[0], hi[0], lo[0]]), np.array([lo[1], lo[1], hi[1], hi[1]]))
    assert corners.min() > lo[2] and corners.max() < hi[2]
    # closed form: the plane stays inside the box's z range, so the volume is area x height at the centre
    v_exact = (hi[0] - lo[0]) * (hi[1] - lo[1]) * (height((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2) - lo[2])
    return lo, hi, verts, faces, height, v_exact


def bench_convergence(quick):
    # lazy: part 1 times fresh `sgim build` processes; this process loads sgim's kernels only for parts 2-4
    from sgim.excavate import FacetSet, kept_sites
    from sgim.packing import make_lattice
    from sgim.scene import Surface

    pit = BenchPit()
    plo, phi = np.array(pit.lo), np.array(pit.hi)
    pverts, pfaces = pit.mesh()
    surfaces = [("inclined plane", *inclined_plane()),
                ("benched pit on a 4° incline", plo, phi, pverts, pfaces, pit.height, pit.exact_volume())]
    n_int = 1000 if quick else 4000
    radii = [2.0, 1.0, 0.5, 0.25] if quick else [2.0, 1.0, 0.5, 0.25, 0.125]
    rng = np.random.default_rng(7)
    res = {"benched_pit": dataclasses.asdict(pit), "surfaces": [], "rows": []}
    for name, lo, hi, verts, faces, height, v_exact in surfaces:
        t0 = time.perf_counter()
        interp = surface_interpolator(verts, faces)
        v_num = integrate_solid(interp, lo, hi, n_int)
        t_int = time.perf_counter() - t0
        P = rng.uniform(lo[:2], hi[:2], size=(20000, 2))  # the facets reproduce the analytic height
        mesh_err = float(np.max(np.abs(np.asarray(interp(P[:, 0], P[:, 1])) - height(P[:, 0], P[:, 1]))))
        res["surfaces"].append({"surface": name, "box": [lo.tolist(), hi.tolist()], "facets": int(len(faces)),
                                "exact_volume": v_exact, "numerical_volume": v_num, "numerical_cells_x": n_int,
                                "numerical_s": t_int, "numerical_vs_exact_rel": (v_num - v_exact) / v_exact,
                                "mesh_vs_height_function_max_abs": mesh_err})
        for rule in ("paper", "exact"):
            surf = Surface(name, verts, faces, rule, name)
            for r in radii:
                def once():
                    t = time.perf_counter()
                    lat = make_lattice("cubic", lo, hi, r)
                    c = kept_sites(lat, FacetSet([surf]), lo, hi)
                    return c, lat, time.perf_counter() - t

                # warm-ups; results are dropped between calls so that the repeats reuse memory the process
                # already has mapped (first touch of fresh pages costs ~2 us per 4 KiB page on this VM)
                c, lat, _ = once()
                n = len(c)
                del c
                once()
                t = median([once()[2] for _ in range(5)])
                vk = n * (2 * r) ** 3
                check = None
                if lat.n_sites <= 400_000:  # brute force: every site against every facet
                    c = once()[0]
                    allc = lat.all_centres()
                    removed = FacetSet([surf]).removed(allc, r)
                    dims = [int(round((hi[a] - lo[a]) / (2 * r))) for a in range(3)]
                    check = bool(np.array_equal(np.sort(site_index(allc[~removed], lo, r, dims)),
                                                np.sort(site_index(c, lo, r, dims))))
                res["rows"].append({"surface": name, "rule": rule, "radius": r, "lattice_sites": lat.n_sites,
                                    "spheres": n, "wall_s_median": t, "kept_volume": vk, "exact_volume": v_exact,
                                    "rel_error": (vk - v_exact) / v_exact, "matches_brute_force": check})
                say(f"convergence: {name}, {rule}, r = {r}: {n} spheres, {t:.3f} s")
                c = None
    return res


def table_convergence(res):
    hdr = ["surface", "rule", "r", "lattice sites", "spheres", "wall s (lattice + excavation, median of 5)", "kept volume m³",
           "exact volume m³", "rel. error", "order", "= brute force"]
    out = []
    prev = {}
    for row in res["rows"]:
        e = row["rel_error"]
        key = (row["surface"], row["rule"])
        p = prev.get(key)
        order = f"{math.log2(abs(p / e)):.2f}" if p not in (None, 0.0) and e != 0 else "-"
        prev[key] = e
        chk = "-" if row["matches_brute_force"] is None else ("yes" if row["matches_brute_force"] else "NO")
        out.append([row["surface"], row["rule"], f"{row['radius']:g}", fmt_int(row["lattice_sites"]),
                    fmt_int(row["spheres"]), f"{row['wall_s_median']:.3f}", f"{row['kept_volume']:.1f}",
                    f"{row['exact_volume']:.1f}", f"{e:+.3%}", order, chk])
    t = md_table(hdr, out)
    t += "\n\n" + md_table(
        ["surface", "box", "facets", "exact volume m³ (closed form)", "midpoint rule on the facets m³",
         "rel. difference", "max abs(facet height - analytic height) m"],
        [[s["surface"], f"{s['box'][0]} .. {s['box'][1]}", s["facets"], f"{s['exact_volume']:.4f}",
          f"{s['numerical_volume']:.4f} ({s['numerical_cells_x']} cells along x)",
          f"{s['numerical_vs_exact_rel']:+.2e}", f"{s['mesh_vs_height_function_max_abs']:.1e}"]
         for s in res["surfaces"]])
    return t



# ---------------------------------------------------------------------------------------------

def sgim_sources():
    """(path, mtime_ns, size) of sgim's sources: a change during the run means kernels were recompiled."""
    return [(p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in sorted((REPO / "sgim").glob("*.py"))]


def git_head():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m cases.bench.sgim", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, one warm repeat (smoke run, < 60 s)")
    ap.add_argument("--json", metavar="OUT.json", help="also write the results as JSON")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else 3
    work = Path(tempfile.mkdtemp(prefix="bench_sgim_"))
    results = {"quick": args.quick, "git_head": git_head(),
               "machine": {**machine_info(), "load_avg_start": os.getloadavg()}}
    print(f"# sgim benchmarks: {machine_line(results['machine'])}\n", flush=True)
    sources0 = sgim_sources()
    try:
        # the in-process parts use the numba cache that the open pit's cold run fills
        cache0 = work / "numba_cache_case0"
        os.environ["NUMBA_CACHE_DIR"] = str(cache0)

        e2e = bench_end_to_end(work, args.quick, repeats)
        results["end_to_end"] = e2e
        print("## 1. End to end: `sgim build SCENE -o DIR --formats npz --quiet --json` (child process)\n")
        print(table_end_to_end(e2e))
        a, b = e2e[0], e2e[1]
        ok_t = "met" if a["wall_s_median"] <= 15 else "MISSED"
        ok_m = "met" if a["peak_rss_bytes"] <= 4 * GB else "MISSED"
        print(f"\nLow pit / open pit, time per kept sphere: {b['us_per_kept_sphere_wall'] / a['us_per_kept_sphere_wall']:.2f}x "
              f"(wall), {b['us_per_kept_sphere_stages'] / a['us_per_kept_sphere_stages']:.2f}x (stages without parse), "
              f"{b['marginal_us_per_kept_sphere_wall'] / a['marginal_us_per_kept_sphere_wall']:.2f}x (marginal wall over "
              f"the probe). Targets for the open pit: <= 15 s wall ({ok_t}: {a['wall_s_median']:.1f} s), <= 4 GB "
              f"peak RSS ({ok_m}: {a['peak_rss_bytes'] / GB:.2f} GB warm, "
              f"{a['peak_rss_bytes_cold'] / GB:.2f} GB cold). GB = 1e9 bytes; cold = first run with an empty numba "
              f"cache (compiles every kernel).\n", flush=True)

        yres = bench_yade(work, args.quick, cache0)
        results["yade_peer"] = yres
        print("## 2. Peer: YADE pack.regularOrtho on the same geometry\n")
        print(table_yade(yres) + "\n", flush=True)

        rres = bench_rules(args.quick)
        results["rules"] = rres
        print(f"## 3. Excavation rules on the open pit (cubic r = {rres['radius']:g}, "
              f"{fmt_int(rres['lattice_sites'])} sites)\n")
        print(table_rules(rres) + "\n", flush=True)

        cres = bench_convergence(args.quick)
        results["convergence"] = cres
        print("## 4. Speed against error: inclined plane and benched pit, closed-form solid volumes\n")
        print(table_convergence(cres) + "\n", flush=True)
        results["total_s"] = time.perf_counter() - T_START
        results["machine"]["load_avg_end"] = os.getloadavg()
        changed = sorted({a[0] for a, b in zip(sources0, sgim_sources()) if a != b}
                         | ({"(files added or removed)"} if len(sources0) != len(sgim_sources()) else set()))
        results["sgim_sources_changed_during_run"] = changed
        if changed:
            print(f"WARNING: sgim sources changed during the run ({', '.join(changed)}): numba recompiled "
                  f"kernels in some runs and the timings above are not trustworthy; run again.\n")
        say(f"done in {results['total_s']:.0f} s")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
