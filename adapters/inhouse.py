"""The in-house engine (dda.spheres) on a SphereRun: the same run as a YADE or LIGGGHTS deck, one RunResult.

``run_inhouse(run, out=None, progress=None)`` builds the SphereSet and SphereSimulation of the run
(``run.in_house()``: bonds in run.bond_i/j order with their kn, ks, ft, fs and rest lengths, the cut pairs on
joints as smooth joints with run.joint_normal and run.joint_friction_deg when run.smooth_joints, the contact
law, gravity, run.dt, Cundall local damping, the viscous damping of the spheres run.viscous_damping, viscous
bond damping run.bond_zeta, the constant sphere forces run.force and the prescribed velocities run.velocity of
run.prescribed), steps it run.steps times and records every run.record_steps
steps (first record at t = 0): series ``kinetic`` (translational + rotational energy of the free spheres [J])
and ``bonds_intact``, positions when n * records <= 5e6, and the final positions, velocities and bond states.
The in-house engine does every feature of the run exactly (it is the reference the decks are compared with),
so ``extra["approximations"]`` is empty; ``extra`` also holds the set-up time, the stepping CPU time (``cpu_s``)
and the pair-list rebuilds.

The engine's cost depends on how its arrays are laid out in memory: the run is stepped with its spheres
renumbered in a spatial order (columns of grid cells, ``spatial_order``) and its bonds sorted by their new
first sphere, so that the spheres a bond touches lie close together in memory; every array of the result is
mapped back to the run's own numbering (spheres and bond list).

A blow-up (non-finite state) raises adapters.process.EngineError with the partial result (status
"incomplete", positions of the last good record) saved into `out`.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from sgim.common import CliError

from .deck import read_deck
from .frames import write_result_frames
from .process import EngineError
from .result import COMPLETE, INCOMPLETE, RunResult
from . import joint_walls as jw
from .spec import SphereRun, liggghts_only

POS_LIMIT = 5_000_000  # record positions when n * records <= POS_LIMIT


def spatial_order(centers, radii):
    """Sphere order for memory locality: by grid column (cells of the largest diameter, x then y), then height."""
    c = np.asarray(centers, float)
    if not len(c):
        return np.zeros(0, np.int64)
    cell = np.floor((c - c.min(0)) / (2.2 * float(np.max(radii)))).astype(np.int64)
    return np.lexsort((c[:, 2], cell[:, 1], cell[:, 0]))


def reordered(run, perm):
    """(run with sphere p = run's sphere perm[p] and its bonds sorted by new index, bond order: new bond q is
    the run's bond order[q])."""
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))

    def pairs(i, j):
        a, b = inv[np.asarray(i, np.int64)], inv[np.asarray(j, np.int64)]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        order = np.lexsort((hi, lo))
        return lo[order], hi[order], order, (a > b)[order]

    bi, bj, border, _ = pairs(run.bond_i, run.bond_j)
    ji, jj, jorder, flip = pairs(run.joint_i, run.joint_j)
    ci, cj, _, _ = pairs(run.cut_i, run.cut_j)
    normal = np.asarray(run.joint_normal, float).reshape(-1, 3)[jorder] * np.where(flip, -1.0, 1.0)[:, None]
    new = replace(run, centers=np.asarray(run.centers, float)[perm], radii=np.asarray(run.radii)[perm],
                  colour=np.asarray(run.colour)[perm], fixed=np.asarray(run.fixed, bool)[perm], bond_i=bi, bond_j=bj,
                  bond_len0=np.asarray(run.bond_len0)[border], bond_kn=np.asarray(run.bond_kn)[border],
                  bond_ks=np.asarray(run.bond_ks)[border], bond_ft=np.asarray(run.bond_ft)[border],
                  bond_fs=np.asarray(run.bond_fs)[border], bond_zeta=np.asarray(run.bond_zeta, float)[border],
                  joint_i=ji, joint_j=jj,
                  joint_disc=np.asarray(run.joint_disc)[jorder], joint_normal=normal, cut_i=ci, cut_j=cj,
                  force=np.asarray(run.force, float)[perm], prescribed=np.asarray(run.prescribed, bool)[perm],
                  velocity=np.asarray(run.velocity, float)[perm])
    return new, border


def approximations(run):
    """What the in-house engine does not represent of `run`: strings naming the scene key (RunResult.extra):
    every key of a run (bonds, joints, loads, contact, local, viscous and bond damping), and the joint walls when
    run.extra joint_walls asks for them."""
    return liggghts_only(run) + jw.notes(run, "a fixed convex slab (the spheres' contact law at "
                                              "its closest point)")


def wall_slabs(run, planes=None):
    """(kept (n,) bool, BlockSpecs) of run.extra joint_walls (adapters/joint_walls.py) in-house: each wall's
    rectangle as the top face of a fixed convex slab 2 r_max thick behind it; kept: the spheres the engine runs
    (not the rock the walls stand for). Mode "pairs" is refused (the spheres keep their radii here)."""
    from dda.blockspec import BlockSpec  # lazy: dda's package top loads numba

    planes = jw.wall_planes(run) if planes is None else planes
    if not planes:
        return np.ones(run.n, bool), []
    jw.only_nearest(run, "the in-house engine")
    t = 2.0 * float(np.max(run.radii))
    specs = []
    for p, q in zip(planes, jw.wall_rectangles(run, planes)):
        v = np.r_[q, q - t * p["normal"]]
        specs.append(BlockSpec(v, [[0, 1, 2, 3], [7, 6, 5, 4], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3],
                                   [3, 7, 4, 0]], name=f"joint{p['disc']}", fixed=True))
    return ~jw.dropped(run, planes), specs


def run_inhouse(run, out=None, progress=None, chunk_seconds=2.0) -> RunResult:
    """Run `run` (adapters.spec.SphereRun) in-house; RunResult (engine "dda"), saved into `out` when given
    (with its ParaView files: adapters/frames.py)."""
    from dda.simulation import BlowUpError  # lazy: numba, loaded by the run anyway (run.in_house())

    t_setup = time.perf_counter()
    kept, slabs = wall_slabs(run)  # run.extra joint_walls: the rock behind a wall is left out of the engine
    sub = run.subset(kept) if slabs else run
    at, bonds_at = np.flatnonzero(kept), np.flatnonzero(kept[run.bond_i] & kept[run.bond_j])
    perm = spatial_order(sub.centers, sub.radii)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    local, border = reordered(sub, perm)
    ss, sim = local.in_house(slabs, run.joint_friction_deg) if slabs else local.in_house()
    sim.record_positions = False  # recorded here
    setup_s = time.perf_counter() - t_setup
    n = run.n
    x0 = np.asarray(run.centers, float)
    steps, rec = run.steps, run.record_steps
    n_records = 1 + -(-steps // rec)
    keep_pos = n * n_records <= POS_LIMIT
    free = ~(ss.fixed | ss.prescribed)
    mass = ss.mass[free]
    inertia = 0.4 * ss.mass[free] * ss.radii[free] ** 2
    times, kin, nbond, poses = [], [], [], []
    last = {}

    def record():  # in the run's numbering: the spheres behind joint walls stay where they are, bonds intact
        v, w = sim.v[free], sim.w[free]
        times.append(sim.steps * run.dt)
        kin.append(float(0.5 * np.sum(mass * np.einsum("ij,ij->i", v, v))
                         + 0.5 * np.sum(inertia * np.einsum("ij,ij->i", w, w))))
        pos, vel = x0.copy(), np.zeros_like(x0)
        pos[at], vel[at] = sim.x[inv], sim.v[inv]
        if keep_pos:
            poses.append(pos)
        intact = np.ones(run.n_bonds, bool)
        intact[bonds_at[border]] = sim.bond_intact
        nbond.append(int(intact.sum()))
        last.update(pos=pos, vel=vel, intact=intact, step=sim.steps)

    def result(status, message, wall):
        pos = np.asarray(poses) if keep_pos and poses else (np.zeros((0, n, 3)) if keep_pos else None)
        res = RunResult(engine="dda", x0=np.asarray(run.centers, float).copy(), final_pos=last["pos"],
                        final_vel=last["vel"], bond_intact=last["intact"], time=np.asarray(times, float), pos=pos,
                        series={"kinetic": np.asarray(kin, float), "bonds_intact": np.asarray(nbond, np.int64)},
                        status=status, message=message, steps=int(last["step"]), dt=float(run.dt), wall_s=wall,
                        extra={"approximations": approximations(run), "setup_s": setup_s, "joint_walls": len(slabs),
                               "cpu_s": time.process_time() - c0,
                               "pair_list_builds": int(sim.stats[7]),
                               "smooth_joints": int(ss.n_joints), "threads": 1})
        if out is not None:
            res.save(Path(out))
            write_result_frames(res, out, run, progress)  # ParaView files beside the result
        return res

    record()
    t0 = time.perf_counter()
    c0 = time.process_time()
    shown = t0
    done = 0
    while done < steps:
        k = min(rec, steps - done)
        try:
            sim.run(k * sim.dt, record_every=k * sim.dt)
        except BlowUpError as exc:
            msg = f"dda: {exc}"
            raise EngineError(msg, result=result(INCOMPLETE, msg, time.perf_counter() - t0)) from None
        done += k
        record()
        now = time.perf_counter()
        if progress and (now - shown >= chunk_seconds or done == steps):
            shown = now
            progress(f"dda: step {done}/{steps} (t = {done * run.dt:.4g} s), {nbond[-1]} bonds intact, "
                     f"{ss.n * done / max(now - t0, 1e-9) / 1e6:.2f} M particle-steps/s")
    return result(COMPLETE, "", time.perf_counter() - t0)


def run_deck(deck, out=None, np=1, timeout=None, progress=None) -> RunResult:
    """The registry's runner of target "dda" (``adapters run DECK --in-house``): the sphere deck's run.npz run
    in-house; the RunResult is saved into `out` (default DECK/result-dda). `np` and `timeout` are not used."""
    read_deck(deck)
    path = Path(deck) / "run.npz"
    if not path.is_file():
        raise CliError(f"{deck}: no run.npz (a sphere deck is needed for --in-house)")
    return run_inhouse(SphereRun.load(path), out=out or Path(deck) / "result-dda", progress=progress)


__all__ = ["approximations", "run_inhouse", "run_deck"]
