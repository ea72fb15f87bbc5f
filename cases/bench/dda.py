"""Benchmarks of the explicit 3D DDA engine (tables on stdout; timing never goes into a test).

    .venv/bin/python -m cases.bench.dda                   # every part but pit
    .venv/bin/python -m cases.bench.dda scaling fixed     # some parts
    parts: scaling, fall1500, fixed, yade, error, pit

scaling   cost per step against block count (100 .. 10 000): falling polyhedra (no contacts yet) and
          resting columns of cubes (every block in contact), microseconds per block-step
fall1500  the paper's scene: 1500 polyhedra falling onto a floor for 1 s simulated (cases/scenes/dda_falling_polyhedra.toml),
          and its energy balance against the potential energy's drop
fixed     10 000 fixed blocks + 10 moving ones against the 10 moving ones alone (ms per step)
yade      YADE Polyhedra (Debian yade, CGAL) on the same falling scene, same dt and steps: block-steps per second
error     speed against error: incline (dt x kn, against the analytical solution), second-order convergence in
          dt, undamped impact (energy balance error), wedge (critical friction against Hoek & Bray)
pit       the open pit's block run (cases/scenes/open_pit_blocks.toml as `dda run` builds it): ms per step, us per
          block-step and per awake block-step, all awake (the run from its start), the free blocks west of x = 0
          asleep, and all asleep (Simulation.fall_asleep): sleeping blocks cost no integration (not in `every part`:
          the cut alone takes a minute; `python -m cases.bench.dda pit`)
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cases import SCENES
from dda.shapes import box as _box
from sgim.machine import machine_line

# The DDA engine (simulation, system, generators: numba kernels) is imported inside the functions of each part, so
# that `--help` loads none of it and a part run alone loads only what it times.

G = 9.81


def _falling(n, seed=1, size=0.2, **kw):
    from dda.generate import GENERATORS
    from dda.simulation import ContactLaw, Simulation
    from dda.system import BlockSystem

    bs = BlockSystem()
    for spec in GENERATORS["falling_polyhedra"](n=n, size=size, seed=seed, **kw):
        bs.add_block(spec, density=2600.0)
    return bs, Simulation(bs, ContactLaw(kn=1e7, friction_deg=30.0, damping=0.1))


def _columns(n, height=5):
    """n cubes in columns `height` tall resting on a floor (every block touches the one below)."""
    from dda.simulation import ContactLaw, Simulation
    from dda.system import BlockSystem

    kn = 1e8
    side = int(math.ceil(math.sqrt(n / height)))
    bs = BlockSystem()
    bs.add_block(_box((-0.5, -0.5, -1.0), (side * 1.2, side * 1.2, 0.0)), fixed=True)
    k = 0
    for ix in range(side):
        for iy in range(side):
            z = 0.0
            for h in range(height):
                if k == n:
                    break
                load = (height - h) * 2600 * G / (4 * kn)
                z -= load
                bs.add_block(_box((ix * 1.2, iy * 1.2, z), (ix * 1.2 + 1, iy * 1.2 + 1, z + 1)))
                z += 1.0
                k += 1
    return bs, Simulation(bs, ContactLaw(kn=kn, friction_deg=30.0, damping=0.1))


def _time_steps(sim, nsteps):
    sim.run(5 * sim.dt, record_every=5 * sim.dt)  # compile / warm up, state settles
    t = time.perf_counter()
    sim.run(nsteps * sim.dt, record_every=nsteps * sim.dt)
    return time.perf_counter() - t


def part_scaling():
    print("\n## Cost per step against block count")
    print("| blocks | falling: ms/step | us/block-step | resting columns: ms/step | us/block-step | contacts |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in (100, 300, 1000, 3000, 10000):
        bs, sim = _falling(n)
        steps = max(20, int(200 * 1000 / n))
        w = _time_steps(sim, steps)
        bs2, sim2 = _columns(n)
        w2 = _time_steps(sim2, steps)
        print(f"| {n} | {1e3 * w / steps:.3f} | {1e6 * w / steps / n:.2f} | {1e3 * w2 / steps:.3f} | "
              f"{1e6 * w2 / steps / n:.2f} | {int(sim2.stats[5])} |", flush=True)


def part_fall1500():
    from dda.results import ENERGY_COLUMNS
    from dda.scene import load_scene

    print("\n## 1500 falling polyhedra, 1 s simulated (cases/scenes/dda_falling_polyhedra.toml)")
    sc = load_scene(SCENES / "dda_falling_polyhedra.toml")
    bs, sim = sc.build()
    sim.run(2 * sim.dt, record_every=2 * sim.dt)  # compile
    t = time.perf_counter()
    res = sim.run(sc.duration - sim.time, record_every=0.05)
    w = time.perf_counter() - t
    E = res.energies
    drop = float(np.max(np.abs(E[:, 1] - E[0, 1])))
    col = {c: E[-1, k] for k, c in enumerate(ENERGY_COLUMNS)}
    print("| blocks | dt (s) | steps | wall (s) | ms/step | contacts at end | points | paper |")
    print("|---:|---:|---:|---:|---:|---:|---:|---|")
    print(f"| {bs.n_blocks} | {sim.dt:.3g} | {sim.steps} | {w:.1f} | {1e3 * w / sim.steps:.2f} | "
          f"{int(sim.stats[5])} | {int(sim.stats[6])} | about 1200 s (C++, 2.4 GHz) |", flush=True)
    print("\nIts energy at t = 1 s (J) and the balance against the potential energy's drop:\n")
    print("| PE drop | kinetic | elastic | friction | damping | point turnover | balance error at the end | "
          "largest over the run |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    print(f"| {drop:.0f} | {col['kinetic']:.0f} | {col['elastic']:.1f} | {col['friction']:.0f} | "
          f"{col['damping']:.0f} | {col['point_turnover']:.0f} | {col['balance_error']:+.0f} "
          f"({100 * col['balance_error'] / drop:+.2f} %) | {100 * np.max(np.abs(E[1:, -1])) / drop:.2f} % |",
          flush=True)


def part_fixed():
    from dda.simulation import ContactLaw, Simulation
    from dda.system import BlockSystem

    print("\n## Fixed blocks cost no integration: 10 moving blocks on 10 000 fixed ones")
    print("| scene | blocks | moving | ms/step |")
    print("|---|---:|---:|---:|")
    rows = []
    for tiles in (True, False):
        bs = BlockSystem()
        if tiles:
            for ix in range(100):
                for iy in range(100):
                    bs.add_block(_box((ix, iy, -1.0), (ix + 1.0, iy + 1.0, 0.0)), fixed=True)
        else:
            bs.add_block(_box((0, 0, -1.0), (100.0, 100.0, 0.0)), fixed=True)
        for k in range(10):
            x = 10.3 + 8 * k
            d0 = 2600 * G * 0.216 / (4e8)
            bs.add_block(_box((x, 50.2, -d0), (x + 0.6, 50.8, 0.6 - d0)))
        sim = Simulation(bs, ContactLaw(kn=1e8, friction_deg=30.0, damping=0.1))
        w = _time_steps(sim, 2000)
        rows.append(1e3 * w / 2000)
        print(f"| {'10 000 fixed tiles' if tiles else 'one fixed floor'} | {bs.n_blocks} | {len(sim.active)} | "
              f"{rows[-1]:.4f} |", flush=True)
    print(f"ratio (10 000 fixed / 1 fixed): {rows[0] / rows[1]:.2f}")


YADE_SCRIPT = r"""
import sys, json, time, math
import numpy as np
from yade import polyhedra_utils
d = np.load(sys.argv[1], allow_pickle=False)
verts, starts, fixed = d['verts'], d['starts'], d['fixed']
nsteps, dt, out = int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
mat = PolyhedraMat(young=float(d['young']), poisson=0.25, density=2600.0, frictionAngle=math.radians(30.0))
O.materials.append(mat)
bodies = []
for k in range(len(starts) - 1):
    v = [Vector3(*p) for p in verts[starts[k]:starts[k + 1]]]
    bodies.append(polyhedra_utils.polyhedra(mat, v=v, fixed=bool(fixed[k])))
O.bodies.append(bodies)
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Polyhedra_Aabb()]),
             InteractionLoop([Ig2_Polyhedra_Polyhedra_PolyhedraGeom()], [Ip2_PolyhedraMat_PolyhedraMat_PolyhedraPhys()],
                             [Law2_PolyhedraGeom_PolyhedraPhys_Volumetric()]),
             NewtonIntegrator(damping=0.1, gravity=(0, 0, -9.81))]
O.dt = dt
O.run(5, True)
t = time.time()
O.run(nsteps, True)
w = time.time() - t
zs = [b.state.pos[2] for b in O.bodies if not b.state.blockedDOFs]
json.dump({"wall": w, "steps": nsteps, "bodies": len(O.bodies), "contacts": len([i for i in O.interactions if i.isReal]),
           "mean_z": float(np.mean(zs))}, open(out, "w"))
"""


def part_yade(n=100, steps=4000, side=10):
    """One layer of polyhedra just above the floor, so that most of the run is in contact."""
    from dda.generate import GENERATORS

    print(f"\n## YADE Polyhedra against this engine: {n} polyhedra dropped from 1 cm in one layer, same dt, "
          f"{steps} steps")
    print("(the Debian build's volumetric law keeps one shear history for all contacts, see shared/REFERENCE.md:"
          " the comparison is of cost, not of results)")
    if not Path("/usr/bin/yade").exists():
        print("yade not installed: skipped")
        return
    geo = dict(side=side, clearance=0.01)
    specs = GENERATORS["falling_polyhedra"](n=n, size=0.2, seed=1, **geo)
    bs, sim = _falling(n, **geo)
    dt = sim.dt
    with tempfile.TemporaryDirectory() as tmp:
        verts = np.concatenate([s.vertices for s in specs])
        starts = np.r_[0, np.cumsum([len(s.vertices) for s in specs])]
        fixed = np.array([s.fixed for s in specs])
        # volumetric law: stiffness from E; E chosen so that a block's static overlap is of the same order
        np.savez(Path(tmp) / "scene.npz", verts=verts, starts=starts, fixed=fixed, young=1e8)
        (Path(tmp) / "run.py").write_text(YADE_SCRIPT)
        t = time.perf_counter()
        p = subprocess.run(["yade", "-n", "-x", str(Path(tmp) / "run.py"), str(Path(tmp) / "scene.npz"), str(steps),
                            repr(dt), str(Path(tmp) / "out.json")], capture_output=True, text=True, cwd=tmp,
                           env={**os.environ, "OMP_NUM_THREADS": "1"})
        total = time.perf_counter() - t
        if p.returncode != 0 or not (Path(tmp) / "out.json").exists():
            print(f"yade failed (exit {p.returncode}): {p.stderr.strip().splitlines()[-1:] }")
            return
        y = json.loads((Path(tmp) / "out.json").read_text())
    w = _time_steps(sim, steps)
    ours = n * steps / w
    theirs = y["bodies"] * y["steps"] / y["wall"]
    mz = float(np.mean(sim.pos[sim.active, 2]))
    print("| engine | bodies | steps | wall (s) | block-steps/s | contacts at end | mean z of moving |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    print(f"| rockdem dda | {bs.n_blocks} | {steps} | {w:.2f} | {ours:,.0f} | {int(sim.stats[5])} | {mz:.3f} |")
    print(f"| YADE Polyhedra | {y['bodies']} | {y['steps']} | {y['wall']:.2f} | {theirs:,.0f} | {y['contacts']} | "
          f"{y['mean_z']:.3f} |")
    print(f"ratio ours / YADE: {ours / theirs:.1f}x  (YADE process wall incl. start-up {total:.1f} s)", flush=True)


def _incline(alpha, phi, kn, safety, duration=1.0, v0=0.0, overlap=1.0, dt=None, damping=0.2):
    from dda.simulation import ContactLaw, Simulation
    from dda.system import BlockSystem

    a = math.radians(alpha)
    c, s = math.cos(-a), math.sin(-a)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    bs = BlockSystem()
    base = _box((-8, -3, -1), (8, 3, 0))
    base.vertices = base.vertices @ R.T
    bs.add_block(base, fixed=True)
    d0 = overlap * 2600 * G * math.cos(a) / (4 * kn)
    blk = _box((1.5, -0.5, -d0), (2.5, 0.5, 1 - d0))
    blk.vertices = blk.vertices @ R.T
    blk.velocity = tuple(R @ np.array([-v0, 0.0, 0.0]))
    i = bs.add_block(blk)
    sim = Simulation(bs, ContactLaw(kn=kn, ks=kn, friction_deg=phi, damping=damping), safety=safety, dt=dt)
    t = time.perf_counter()
    sim.run(duration, record_every=duration)
    w = time.perf_counter() - t
    d = -(R.T @ sim.displacement(i))[0]
    ref = 0.5 * G * (math.sin(a) - math.tan(math.radians(phi)) * math.cos(a)) * sim.time ** 2
    return d, ref, w, sim


def part_error():
    print("\n## Speed against error: block on a 30 deg incline, phi = 20 deg, t = 1 s (analytical 0.9064 m)")
    print("| kn (N/m) | safety | dt (s) | steps | wall (s) | relative error |")
    print("|---:|---:|---:|---:|---:|---:|")
    for kn in (1e9, 1e10, 1e11):
        for safety in (0.5, 0.25, 0.125):
            d, ref, w, sim = _incline(30.0, 20.0, kn, safety)
            print(f"| {kn:.0e} | {safety} | {sim.dt:.3g} | {sim.steps} | {w:.3f} | {d / ref - 1:+.2e} |", flush=True)

    print("\n## Convergence in dt (incline, kn = 1e10, block launched down the slope at 0.5 m/s so that it slides")
    print("from the first step, placed at half its static overlap so that it also oscillates on its contact")
    print("springs without opening: smooth dynamics; no viscous damping (it uses the half-step velocity and is")
    print("first order); dt = 0.3 s / N, against N = 256 000, t = 0.3 s)")
    print("| N | dt (s) | dt / critical | |x - x_ref| (m) | order |")
    print("|---:|---:|---:|---:|---:|")
    kw = dict(duration=0.3, v0=0.5, overlap=0.5, damping=0.0)
    dref, _, _, _ = _incline(30.0, 20.0, 1e10, 0.5, dt=0.3 / 256000, **kw)
    prev = None
    for N in (8000, 16000, 32000, 64000):
        d, ref, w, sim = _incline(30.0, 20.0, 1e10, 0.5, dt=0.3 / N, **kw)
        err = abs(d - dref)
        order = "" if prev is None or err == 0 else f"{math.log2(prev / err):.2f}"
        prev = err
        print(f"| {N} | {sim.dt:.3g} | {sim.dt / sim.dt_crit:.2f} | {err:.3e} | {order} |", flush=True)

    print("\n## Speed against error: undamped frictionless impacts (cube tilted 7 deg, 2 s), energy balance")
    print("| kn (N/m) | safety | dt (s) | steps | wall (s) | max balance error / drop energy |")
    print("|---:|---:|---:|---:|---:|---:|")
    from dda.simulation import ContactLaw, Simulation
    from dda.system import BlockSystem

    for kn in (1e7, 1e8, 1e9):
        for safety in (0.2, 0.1, 0.05, 0.025):
            bs = BlockSystem()
            bs.add_block(_box((-3, -3, -1), (3, 3, 0)), fixed=True)
            cube = _box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
            t7 = math.radians(7.0)
            ax = np.array([1.0, 2.0, 0.0]) / math.sqrt(5.0)
            K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
            Rm = np.eye(3) + math.sin(t7) * K + (1 - math.cos(t7)) * K @ K
            cube.vertices = cube.vertices @ Rm.T + (0, 0, 1.2)
            bs.add_block(cube)
            sim = Simulation(bs, ContactLaw(kn=kn, friction_deg=0.0), safety=safety)
            t = time.perf_counter()
            res = sim.run(2.0, record_every=0.005)
            w = time.perf_counter() - t
            err = np.max(np.abs(res.energy_column("balance_error")[1:])) / (2600 * G * 0.7)
            print(f"| {kn:.0e} | {safety} | {sim.dt:.3g} | {sim.steps} | {w:.3f} | {err:.2e} |", flush=True)

    print("\n## Speed against error: the paper's wedge (A 45/005, B 55/135, face 65/065, H = 10 m, phi = 25 deg)")
    try:
        from dda import hoekbray
        from dda.wedge import dda_critical_friction
    except ImportError as exc:
        print(f"wedge helpers not available ({exc}): skipped")
        return
    hb = hoekbray.wedge_fs((45.0, 5.0), (55.0, 135.0), (65.0, 65.0), friction=25.0, unit_weight=2.6 * G, height=10.0)
    print(f"Hoek & Bray: FS = {hb.fs:.4f}, critical friction {hb.critical_friction:.3f} deg")
    print("| penetration (sets kn) | tolerance (deg) | wall (s) | DDA critical friction | FS | FS error |")
    print("|---:|---:|---:|---:|---:|---:|")
    for pen, tol in ((1e-4, 0.2), (1e-5, 0.1), (1e-5, 0.05)):
        t = time.perf_counter()
        try:
            r = dda_critical_friction((45.0, 5.0), (55.0, 135.0), (65.0, 65.0), (0.0, 0.0), 10.0, 25.0, 2.6 * G,
                                      tol=tol, step=2.0, duration=1.5, kn=None, penetration=pen)
        except Exception as exc:  # report and go on with the next row
            print(f"| {pen:g} | {tol} | {time.perf_counter() - t:.1f} | failed: {str(exc)[:90]} | | |", flush=True)
            continue
        w = time.perf_counter() - t
        print(f"| {pen:g} | {tol} | {w:.1f} | {r['phi_crit_dda']:.3f} | {r['fs_dda']:.4f} | "
              f"{r['fs_dda'] / hb.fs - 1:+.2%} |", flush=True)


def _pit_steps(sim, steps):
    """Time `steps` single steps of sim: per step (wall s, CPU s, awake blocks, sleeping blocks, contacts)."""
    out = []
    for _ in range(steps):
        t, c = time.perf_counter(), time.process_time()
        sim.run(sim.dt, record_every=sim.dt)
        out.append((time.perf_counter() - t, time.process_time() - c, len(sim.active), sim.n_asleep,
                    int(sim.stats[5])))
    return out


def _pit_stages(sim, steps):
    """CPU seconds of each stage of a step (dda/_integrate.py run_chunk's, called one at a time), medians over
    `steps` steps, and the step's pairs, contacts, points and separating-axis searches."""
    from dda import _integrate as it
    from dda._narrow import carry_resting, hash_pairs, narrow_phase
    from dda._state import C_CONTACTS, C_NEW, C_POINTS, C_SAT, NCOUNT, NTALLY

    names = ("geometry", "broad phase", "pair table", "narrow phase", "resting pairs", "integration", "sleeping")
    cpu, last = [], None
    for _ in range(steps):
        blocks, deform, loads, forces, geom, grid, lists, sleep, con, law, books = sim.bundles()
        work = it.make_work(blocks, geom, sleep.asleep)
        tally, count = np.zeros(NTALLY), np.zeros(NCOUNT, np.int64)
        t = [time.process_time()]
        lists = it.move_geometry(blocks, deform, geom, grid, lists, work.static, work.R)
        t.append(time.process_time())
        lists, npair = it.broad_phase(geom, grid, lists, work.static)
        t.append(time.process_time())
        new = 1 - con.cur[0]
        hmask = hash_pairs(con, con.cur[0])
        it.reset_forces(lists.active, blocks.dof12, forces, loads)
        t.append(time.process_time())
        narrow_phase(npair, lists.pa, lists.pb, hmask, False, sim.dt, law, grid.gap, blocks, deform, forces, geom,
                     sleep, con, work, tally, count)
        t.append(time.process_time())
        carry_resting(law, blocks.material, sleep.asleep, con, work.static, tally, count)
        con.n_pair[new] = count[C_NEW]
        con.cur[0] = new
        t.append(time.process_time())
        it.integrate(sim.dt, sim.dt, sim.local_damping, blocks, deform, loads, forces, lists.active, sleep, books.acc,
                     work, tally)
        t.append(time.process_time())
        lists = it.sleep_stage(sim.dt, blocks, loads, grid, lists, sleep, books.acc, work, tally, count)
        t.append(time.process_time())
        sim.set_lists(lists)
        sim.steps += 1
        sim.time += sim.dt
        cpu.append(np.diff(t))
        last = (npair, int(count[C_CONTACTS]), int(count[C_POINTS]), int(count[C_SAT]))
    return dict(zip(names, np.median(cpu, axis=0))), last


def _pit_dt(sim):
    """Why the run's dt is what it is: per free block, its own step by Simulation.block_dts (NPOINT springs kn:
    translation sqrt(k / m), rotation at the block's worst vertex, dda.simulation.rotation_bound). A line of
    text."""
    A, free = sim.A, sim.free
    dt_t, dt_r = (sim.safety * d for d in sim.block_dts())
    own = np.minimum(dt_t, dt_r)
    w = int(np.argmin(own))
    i = free[w]
    v = A.vloc[A.vert_start[i]:A.vert_start[i + 1]]
    thick = min(np.ptp(v @ n) for n in A.nloc[A.face_start[i]:A.face_start[i + 1]])
    return [f"dt {sim.dt:.3g} s ({int(round(2.0 / sim.dt))} steps for 2 s) is set by block {i} "
            f"({A.volume[i]:.3g} m3, {thick:.2f} m thick, {sim.size_b[i]:.1f} m long): its rotation "
            f"bound {dt_r[w]:.3g} s against its translation bound {dt_t[w]:.3g} s; {int((own < 1e-5).sum())} free "
            f"blocks have their own step below 1e-5 s, {int((own < 1e-4).sum())} below 1e-4 s (the median "
            f"{np.median(own):.3g} s)"]


def part_pit(steps=5):
    from dda.georun import load_geo_scene

    print("\n## The open pit's block run (cases/scenes/open_pit_blocks.toml): cost per block-step, awake and asleep")
    t = time.perf_counter()
    gs = load_geo_scene(SCENES / "open_pit_blocks.toml")
    print(f"cut into {len(gs.blocks)} blocks in {time.perf_counter() - t:.0f} s; each state below: the run built "
          f"anew, its first step (every pair new), then {steps} steps timed one by one (medians)\n")
    print("| state | free blocks | awake | asleep | contacts | first step s | ms/step wall | ms/step CPU | "
          "us CPU per block-step | us CPU per awake block-step |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label in ("all awake (the run from its start)", "west half asleep (free blocks with x < 0)", "all asleep"):
        _, sim = gs.build(check=False)
        free = sim.free
        t = time.perf_counter()
        sim.run(sim.dt, record_every=sim.dt)  # the first step: every pair new (and the kernels load)
        first = time.perf_counter() - t
        if label.startswith("west"):
            sim.fall_asleep(free[sim.pos[free, 0] < 0.0])
        elif label == "all asleep":
            sim.fall_asleep(free)
        rows = _pit_steps(sim, steps)
        w, c = float(np.median([r[0] for r in rows])), float(np.median([r[1] for r in rows]))
        awake = int(np.median([r[2] for r in rows]))
        print(f"| {label} | {len(free)} | {awake} | {rows[-1][3]} | {rows[-1][4]} | {first:.1f} | {1e3 * w:.0f} | "
              f"{1e3 * c:.0f} | {1e6 * c / len(free):.1f} | {f'{1e6 * c / awake:.1f}' if awake else '-'} |", flush=True)
        if label.startswith("west"):
            print("|  its steps (a moving block that comes near a sleeping one wakes it): awake, ms CPU | "
                  + ", ".join(f"{r[2]}: {1e3 * r[1]:.0f}" for r in rows) + " | | | | | | | | |")
        if label.startswith("all awake"):
            stages, (npair, ncon, npts, nsat) = _pit_stages(sim, steps)
            why_dt = _pit_dt(sim)
        del sim
    print(f"\nA step of the run with every block awake, stage by stage (CPU ms, medians of {steps} steps): "
          + ", ".join(f"{k} {1e3 * v:.0f}" for k, v in stages.items())
          + f"; {npair} candidate pairs, {ncon} with contact points, {npts} points kept, {nsat} separating-axis "
            f"searches\n")
    print("\n".join(why_dt))


PARTS = {"scaling": part_scaling, "fall1500": part_fall1500, "fixed": part_fixed, "yade": part_yade,
         "error": part_error, "pit": part_pit}
EVERY = ("scaling", "fall1500", "fixed", "yade", "error")  # pit on demand: its cut alone takes a minute


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    parts = argv or list(EVERY)
    bad = [p for p in parts if p not in PARTS]
    if bad:
        print(f"unknown part {bad[0]!r}; choose from {', '.join(PARTS)}", file=sys.stderr)
        return 2
    print(f"# DDA benchmarks: {machine_line()}; load average {os.getloadavg()[0]:.2f}")
    for p in parts:
        PARTS[p]()
    return 0


if __name__ == "__main__":
    sys.exit(main())
