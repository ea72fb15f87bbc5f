"""Benchmark of the triangle-mesh queries (sgim/meshquery.py) and of the tunnel case.

    .venv/bin/python -m cases.bench.meshquery [--quick] [--json OUT]

Prints medians of repeated runs (after a warm-up that compiles the numba kernels):

1. TriMesh queries on a closed horseshoe tunnel and on a fine ellipsoid: build, inside,
   signed distance (everywhere and in a band), with VTK measured in the same run as the peer
   (vtkSelectEnclosedPoints for inside, vtkImplicitPolyDataDistance for signed distance),
   and the fraction of points on which the two agree (VTK's inside test works with a
   tolerance of 1e-3 of the bounding diagonal, so points that close to the surface may differ);
2. `sgim build` stages of cases/scenes/tunnel_jointed.toml (no files written).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from cases import SCENES
from sgim import shapes
from sgim.machine import machine_info, machine_line
from sgim.meshquery import TriMesh

# The code it times and its peers (sgim's builder, pyvista, vtk) are imported inside the functions of each part,
# so that `--help` loads none of them and each part loads only what it runs.



def timed(fn, repeat):
    out, ts = None, []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def vtk_poly(V, F):
    import pyvista as pv

    return pv.PolyData(V, np.column_stack([np.full(len(F), 3), F]).ravel())


def vtk_inside(poly, pts):
    import pyvista as pv

    with warnings.catch_warnings():  # vtkSelectEnclosedPoints (ray casting) is the peer on purpose
        warnings.simplefilter("ignore")
        res = pv.PolyData(pts).select_enclosed_points(poly, check_surface=False)
    return np.asarray(res["SelectedPoints"]).astype(bool)


def vtk_signed(poly, pts):
    import vtk

    f = vtk.vtkImplicitPolyDataDistance()
    f.SetInput(poly)
    return np.array([f.EvaluateFunction(p) for p in pts])


def mesh_rows(quick):
    rng = np.random.default_rng(7)
    meshes = {
        "horseshoe tunnel": shapes.horseshoe_tunnel([[-60, -6, 12], [-18, -6, 12], [12, 4, 12], [60, 4, 14]],
                                                    8.0, 7.0, 48),
        "ellipsoid 256": shapes.ellipsoid([0, 0, 0], [9.0, 5.0, 6.0], 256),
    }
    n = 200_000 if quick else 1_000_000
    n_peer = 20_000 if quick else 100_000
    n_peer_sd = 5_000 if quick else 20_000
    rows = []
    for name, (V, F) in meshes.items():
        t_build, mesh = timed(lambda: TriMesh(V, F), 3)
        lo, hi = mesh.lo - 2.0, mesh.hi + 2.0
        pts = rng.uniform(lo, hi, (n, 3))
        mesh.inside(pts[:1000])
        mesh.signed_distance(pts[:1000], 1.0)
        t_in, ins = timed(lambda: mesh.inside(pts), 3)
        t_sd, sd = timed(lambda: mesh.signed_distance(pts), 3)
        t_band, _ = timed(lambda: mesh.signed_distance(pts, max_dist=0.5), 3)
        poly = vtk_poly(mesh.vertices, mesh.faces)
        t_vin, vin = timed(lambda: vtk_inside(poly, pts[:n_peer]), 1)
        t_vsd, vsd = timed(lambda: vtk_signed(poly, pts[:n_peer_sd]), 1)
        rows.append({
            "mesh": name, "faces": int(mesh.n_faces), "build_s": t_build,
            "inside_pts_per_s": n / t_in, "vtk_inside_pts_per_s": n_peer / t_vin,
            "inside_agree": float(np.mean(ins[:n_peer] == vin)),
            "signed_pts_per_s": n / t_sd, "band_pts_per_s": n / t_band,
            "vtk_signed_pts_per_s": n_peer_sd / t_vsd,
            "signed_max_diff": float(np.max(np.abs(sd[:n_peer_sd] - vsd))),
        })
    return rows


def case_rows(quick):
    from sgim.builder import Timer, build_model
    from sgim.scene import load_scene

    scene_path = SCENES / "tunnel_jointed.toml"
    t0 = time.perf_counter()
    scene = load_scene(scene_path)
    t_parse = time.perf_counter() - t0
    build_model(scene)  # warm-up (numba cache)
    runs = []
    for _ in range(1 if quick else 3):
        t0 = time.perf_counter()
        scene = load_scene(scene_path)
        tm = Timer()
        tm.t["parse"] = time.perf_counter() - t0
        tm._last = time.perf_counter()
        model = build_model(scene, timer=tm)
        tm.t["total"] = time.perf_counter() - t0
        runs.append(dict(tm.t))
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    return {"scene": str(scene_path.relative_to(SCENES.parents[1])), "spheres": int(model.n),
            "bonds": int(len(model.bonds)), "first_parse_s": t_parse, **{f"{k}_s": v for k, v in med.items()}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    machine = machine_info()
    print(machine_line(machine), flush=True)
    rows = mesh_rows(args.quick)
    print("mesh queries (points/s, medians; VTK on a subset of the same points)")
    print(f"{'mesh':<18s} {'faces':>7s} {'build s':>8s} {'inside':>10s} {'VTK in':>10s} {'agree':>7s} "
          f"{'signed':>10s} {'band 0.5':>10s} {'VTK sd':>10s} {'max |dsd|':>10s}")
    for r in rows:
        print(f"{r['mesh']:<18s} {r['faces']:>7d} {r['build_s']:>8.3f} {r['inside_pts_per_s']:>10.3g} "
              f"{r['vtk_inside_pts_per_s']:>10.3g} {r['inside_agree']:>7.4f} {r['signed_pts_per_s']:>10.3g} "
              f"{r['band_pts_per_s']:>10.3g} {r['vtk_signed_pts_per_s']:>10.3g} {r['signed_max_diff']:>10.2e}")
    case = case_rows(args.quick)
    print()
    print(f"{case['scene']}: {case['spheres']} spheres, {case['bonds']} contacts (build without writing files)")
    print("  " + "  ".join(f"{k[:-2]} {v:.2f} s" for k, v in case.items() if k.endswith("_s")))
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": machine, "mesh_queries": rows, "tunnel_jointed": case}, indent=2))


if __name__ == "__main__":
    main()
