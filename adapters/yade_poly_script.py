"""YADE script of a polyhedra deck (copied into the deck as script.py; run by ``yade -n -x``).

Usage (see adapters/yade_poly.py)::

    yade -n -f2 -x DECK/script.py DECK OUT

Runs on YADE's own (system) Python: it imports nothing of this project, only numpy, json and yade. It reads
``DECK/blocks.npz`` (world vertices of every block, fixed flags, densities) and ``DECK/poly.json`` (contact
material, gravity, damping, dt, run length), and writes into ``OUT``:

- ``yade_series.npz``  record times, kinetic energy, block centroids at the records (rewritten at every record);
- ``yade_final.npz``   final centroids and velocities, written last.

Lines starting with ``FATAL:`` carry the reason of a deliberate failure; ``PROGRESS`` lines the advance.
"""
import json
import math
import os
import sys
import time

import numpy as np
from yade import O
from yade.polyhedra_utils import polyhedra
from yade.wrapper import (Bo1_Polyhedra_Aabb, ForceResetter, Ig2_Polyhedra_Polyhedra_PolyhedraGeom,
                          InsertionSortCollider, InteractionLoop, Ip2_PolyhedraMat_PolyhedraMat_PolyhedraPhys,
                          Law2_PolyhedraGeom_PolyhedraPhys_Volumetric, NewtonIntegrator, PolyhedraMat)


def fatal(msg, code=3):
    print("FATAL: " + msg, flush=True)
    sys.exit(code)


def save_npz(path, **arrays):
    tmp = path + ".tmp"
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, path)


def main(deck, out):
    cfg = json.load(open(os.path.join(deck, "poly.json")))
    z = np.load(os.path.join(deck, "blocks.npz"), allow_pickle=False)
    verts = np.asarray(z["vertices"], float)
    start = np.asarray(z["vert_start"], np.int64)
    fixed = np.asarray(z["fixed"], bool)
    dens = np.asarray(z["density"], float)
    vel0 = np.asarray(z["velocity"], float).reshape(-1, 3)
    avel0 = np.asarray(z["angular_velocity"], float).reshape(-1, 3)
    nb = len(fixed)
    dt = float(cfg["dt"])
    steps = int(cfg["steps"])
    rec = int(cfg["record_steps"])
    if nb == 0:
        fatal("the deck has no blocks")
    if not (dt > 0 and math.isfinite(dt)):
        fatal("time step must be > 0")
    mats = {}
    for d in np.unique(dens).tolist():
        mats[d] = PolyhedraMat(young=float(cfg["young"]), poisson=float(cfg["poisson"]),
                               frictionAngle=math.radians(float(cfg["friction_deg"])), density=d)
        O.materials.append(mats[d])
    bodies = []
    for k in range(nb):
        v = [tuple(p) for p in verts[start[k]:start[k + 1]].tolist()]
        b = polyhedra(mats[float(dens[k])], v=v, fixed=bool(fixed[k]))
        if not fixed[k]:
            b.state.vel = tuple(float(x) for x in vel0[k])
            b.state.angVel = tuple(float(x) for x in avel0[k])
        bodies.append(b)
    ids = O.bodies.append(bodies)
    if list(ids) != list(range(nb)):
        fatal("unexpected body ids")
    O.engines = [
        ForceResetter(),
        InsertionSortCollider([Bo1_Polyhedra_Aabb()]),
        InteractionLoop([Ig2_Polyhedra_Polyhedra_PolyhedraGeom()], [Ip2_PolyhedraMat_PolyhedraMat_PolyhedraPhys()],
                        [Law2_PolyhedraGeom_PolyhedraPhys_Volumetric()]),
        NewtonIntegrator(gravity=[float(g) for g in cfg["gravity"]], damping=float(cfg["local_damping"])),
    ]
    O.dt = dt
    free = ~fixed

    def state():
        p = np.array([b.state.pos for b in O.bodies], float).reshape(nb, 3)
        v = np.array([b.state.vel for b in O.bodies], float).reshape(nb, 3)
        return p, v

    def kinetic(v):
        e = 0.0
        for k in np.flatnonzero(free).tolist():
            st = O.bodies[k].state
            w = np.asarray(st.angVel, float)
            R = np.asarray(st.ori.toRotationMatrix(), float).reshape(3, 3)
            Iw = R @ (np.asarray(st.inertia, float) * (R.T @ w))
            e += 0.5 * st.mass * float(v[k] @ v[k]) + 0.5 * float(w @ Iw)
        return e

    times, kins, poss = [], [], []

    def record():
        p, v = state()
        times.append(O.iter * dt)
        kins.append(kinetic(v))
        poss.append(p)
        save_npz(os.path.join(out, "yade_series.npz"), time=np.array(times), kinetic=np.array(kins),
                 pos=np.array(poss), steps=np.array(O.iter))
        return p, v

    record()
    done, last_print, t_run = 0, 0.0, time.time()
    while done < steps:
        nxt = min(steps, (done // rec + 1) * rec)
        O.run(nxt - done, True)
        done = nxt
        p, v = record()
        if not (math.isfinite(kins[-1]) and np.all(np.isfinite(p))):
            fatal(f"blow-up near t = {O.iter * dt:.6g} s (step {O.iter}): non-finite state (dt = {dt:.3g} s)", 4)
        now = time.time()
        if now - last_print > 1.0 or done == steps:
            last_print = now
            print(f"PROGRESS t = {O.iter * dt:.6g} s  step {O.iter}/{steps}  kinetic {kins[-1]:.6g} J  "
                  f"contacts {sum(1 for _ in O.interactions)}", flush=True)
    wall = time.time() - t_run
    p, v = state()
    save_npz(os.path.join(out, "yade_final.npz"), final_pos=p, final_vel=v, steps=np.array(O.iter),
             time=np.array(O.iter * dt), wall_run=np.array(wall))
    print(f"PROGRESS done: {O.iter} steps in {wall:.3f} s", flush=True)


if len(sys.argv) < 3:
    fatal("usage: yade -n -x script.py DECK OUT", 2)
main(os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2]))
