"""The LIGGGHTS-PUBLIC runner: ``run_deck(folder, out, np=1, timeout=None, progress=None)`` runs a deck written
by adapters/liggghts_deck.py and returns the RunResult it saved into `out`; ``check_data`` and ``deck_variant``
read the deck back before the engine starts.

LIGGGHTS-PUBLIC cannot break bonds, so the runner drives the engine through its input (adapters/_liggghts_io.py
Driver): it runs a chunk, has it write a %.17g dump and print a marker with the atom count, reads the dump,
deletes the bonds whose tension passed bond_ft (``delete_bonds all bond T remove``), and goes on.

Results (RunResult, engine "liggghts"): records every run.record_steps steps from t = 0 (series "kinetic":
translational + rotational energy of the free spheres, "bonds_intact", "atoms"), positions at the records
when n x records <= 5e6, final positions and velocities at full precision (%.17g dumps). ``bond_intact``:
bonds variant: not deleted by the runner; sjkr: the pair is in (adhesive) contact; clumps: always intact.
After every chunk the runner compares the atom count with the run's and stops with EngineError (result
incomplete, saved) when LIGGGHTS lost particles (they left the fixed box); a LIGGGHTS "ERROR: ..." line
becomes the EngineError message; ``timeout`` covers the whole run.

Run by hand (no bond breakage, dumps every record): ``cd DECK && liggghts -in in``.
"""
from __future__ import annotations

import math
import os
import re
import time
from pathlib import Path

import numpy as np

from sgim.readback import BadFile, Fields, read_json, read_text

from ._liggghts_io import DUMP_COLUMNS, DUMP_FORMAT, MARK, Driver, DriverError, read_dump
from .liggghts_deck import (SJKR_GROW, VARIANTS, approximations, check_steps, clump_molecules, clump_prescribed,
                            sjkr_overlap)
from .liggghts_joints import joint_closure, open_joints
from .process import EngineError, describe_failure, find_engine, unbuffered
from .result import COMPLETE, INCOMPLETE, RunResult
from .spec import SphereRun

POS_LIMIT = 5_000_000  # record positions when n x records <= POS_LIMIT

def _command(np_, exe):
    cmd = [exe, "-log", "none", "-echo", "none", "-var", "driven", "1"]
    if np_ <= 1:
        return unbuffered(cmd)
    mpirun = find_engine("mpirun")
    pre = [mpirun]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        pre.append("--allow-run-as-root")
    pre += ["--oversubscribe", "-n", str(int(np_))]
    return pre + unbuffered(cmd)


def _boundaries(total, record, check):
    b = set(range(record, total, record)) | set(range(check, total, check)) | {total}
    return sorted(b)


def _delete_commands(types):
    """delete_bonds commands for the (1-based) bond types (this build takes one type per command)."""
    return [f"delete_bonds all bond {int(t)} remove" for t in np.sort(np.asarray(types, np.int64))]


def deck_variant(folder):
    """The variant of a deck folder: deck.json's, else the one named in the first line of ``in`` (BadFile for a
    broken deck.json or ``in``, or an unknown variant)."""
    folder = Path(folder)
    if (folder / "deck.json").is_file():
        F = Fields(folder / "deck.json", read_json(folder / "deck.json", "a deck.json"))
        v = F.string("variant", None) if F.doc.get("variant") is not None else None
        if v:
            F.string("variant", choices=VARIANTS)
            return v
    head = read_text(folder / "in", "a LIGGGHTS input").split("\n", 1)[0]
    for v in VARIANTS:
        if f"variant {v}:" in head:
            return v
    return "bonds"


def check_data(path, run, variant):
    """The header of the deck's LIGGGHTS data file agrees with its run.npz: as many atoms as spheres and, for the
    bonds variant, as many bonds (BadFile otherwise: a data file of another deck, truncated or foreign)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("utf-8", "replace")
    except OSError as exc:
        raise BadFile(path, f"cannot read ({exc.__class__.__name__})") from None
    if not head.startswith("LIGGGHTS data file"):
        raise BadFile(path, "not a LIGGGHTS data file written by `adapters export` (no 'LIGGGHTS data file' title)")
    counts = {m.group(2): int(m.group(1)) for m in re.finditer(r"^\s*(\d+)\s+(atoms|bonds)\s*$", head, re.M)}
    if counts.get("atoms") != run.n:
        raise BadFile(path, f"{counts.get('atoms', 'no')} atoms, but run.npz has {run.n} spheres")
    if variant == "bonds" and counts.get("bonds") != run.n_bonds:
        raise BadFile(path, f"{counts.get('bonds', 'no')} bonds, but run.npz has {run.n_bonds} bonds")


def run_deck(folder, out, np=1, timeout=None, progress=None):
    """Run the LIGGGHTS deck `folder`; the RunResult (engine "liggghts") is saved into `out` and returned.

    Raises EngineError (with the partial result, marked incomplete and saved) when LIGGGHTS is missing, stops
    with an error, runs past `timeout` seconds, or loses particles."""
    return _run_deck(folder, out, int(np), timeout, progress)


def _run_deck(folder, out, nprocs, timeout, progress):
    exe = find_engine("liggghts")
    if nprocs > 1:
        find_engine("mpirun")
    folder, out = Path(folder).resolve(), Path(out).resolve()
    info = {}
    if (folder / "deck.json").is_file():
        info = read_json(folder / "deck.json", "a deck.json")
    run = SphereRun.load(folder / "run.npz")
    variant = deck_variant(folder)
    check_data(folder / "data", run, variant)
    out.mkdir(parents=True, exist_ok=True)
    dump = out / ".liggghts_dump.txt"
    log = out / "liggghts.log"
    rel = os.path.relpath(dump, folder)
    n = run.n
    mass = run.density * 4.0 / 3.0 * math.pi * run.radii ** 3
    inertia = 0.4 * mass * run.radii ** 2
    mobile = ~np.asarray(run.fixed, bool) & ~np.asarray(run.prescribed, bool)
    if variant == "clumps":
        mobile = ~clump_molecules(run)[1] & ~clump_prescribed(run)[0]
    breakable = np.flatnonzero(np.isfinite(run.bond_ft)) if variant == "bonds" else np.zeros(0, np.int64)
    contact_reach = None
    if variant == "sjkr":  # a bond counts as intact while its pair is in (adhesive) contact
        rd = run.radii + SJKR_GROW[np.asarray(run.colour, np.int64)] * sjkr_overlap(run)
        contact_reach = (rd[run.bond_i] + rd[run.bond_j]) * (1.0 + 1e-9)
    intact = np.ones(run.n_bonds, bool)
    steps, rec, chk = run.steps, run.record_steps, check_steps(run)
    bounds = _boundaries(steps, rec, chk)
    n_records = 1 + len([b for b in bounds if b % rec == 0 or b == steps])
    keep_pos = n * n_records <= POS_LIMIT
    times, kin, nbond, natoms, poses = [], [], [], [], []
    state = {"pos": run.centers.copy(), "vel": np.zeros((n, 3)), "step": 0}
    extra = {"variant": variant, "np": nprocs, "approximations": info.get("approximations")
             or approximations(run, variant), "bond_check_steps": chk, "broken_by_runner": 0}
    if open_joints(run):  # the case the exclusion does not represent: a joint pair closing beyond its start gap
        extra.update(liggghts_joints="open", joint_closure_max=0.0, joint_pairs_closed_max=0)
    t0 = time.perf_counter()
    deadline = None if timeout is None else t0 + float(timeout)

    def result(status=COMPLETE, message=""):
        res = RunResult(engine="liggghts", x0=run.centers.copy(), final_pos=state["pos"].copy(),
                        final_vel=state["vel"].copy(), bond_intact=intact.copy(), time=np.asarray(times, float),
                        pos=np.asarray(poses) if keep_pos and poses else (np.zeros((0, n, 3)) if keep_pos else None),
                        series={"kinetic": np.asarray(kin, float), "bonds_intact": np.asarray(nbond, np.int64),
                                "atoms": np.asarray(natoms, np.int64)},
                        status=status, message=message, steps=int(state["step"]), dt=float(run.dt),
                        wall_s=time.perf_counter() - t0, extra=extra)
        res.save(out)
        return res

    def fail(message):
        res = result(INCOMPLETE, message)
        raise EngineError(message, result=res)

    def read_state(k, count):
        ids, vals = read_dump(dump)
        if len(ids) != n or count != n:
            lost = n - min(len(ids), count)
            step = state["step"]
            fail(f"liggghts: lost {lost} of {n} particles by step {step} (t = {step * run.dt:.6g} s): they left "
                 f"the fixed box (deck.json 'box', run.extra 'liggghts_box_margin') (log {log})")
        if not np.array_equal(ids, np.arange(1, n + 1)):
            fail(f"liggghts: dump {dump} does not hold atoms 1..{n} in order (log {log})")
        state["pos"], state["vel"] = vals[:, 0:3].copy(), vals[:, 3:6].copy()
        return vals[:, 6:9]

    def record(omega):
        times.append(state["step"] * run.dt)
        if open_joints(run):
            closure = joint_closure(run, state["pos"])
            extra["joint_closure_max"] = max(extra["joint_closure_max"], float(max(closure.max(), 0.0)))
            extra["joint_pairs_closed_max"] = max(extra["joint_pairs_closed_max"], int(np.sum(closure > 0.0)))
        v, w = state["vel"][mobile], omega[mobile]
        kin.append(float(0.5 * np.sum(mass[mobile] * np.einsum("ij,ij->i", v, v))
                         + 0.5 * np.sum(inertia[mobile] * np.einsum("ij,ij->i", w, w))))
        nbond.append(int(intact.sum()))
        natoms.append(n)
        if keep_pos:
            poses.append(state["pos"].copy())

    write = (f'write_dump all custom "{rel}" {" ".join(DUMP_COLUMNS)} modify sort id format "{DUMP_FORMAT}"')
    if progress:
        progress(f"liggghts: {n} spheres, {run.n_bonds} bonds, {steps} steps on {nprocs} rank(s) (log {log})")
    drv = Driver(_command(nprocs, exe), folder, log)
    try:
        drv.send(["include in", "run 0 post no", write, f'print "{MARK} 0 ${{natoms}}"'])
        k = 0
        count = drv.wait_mark(0, deadline)
        record(read_state(0, count))
        last_msg = time.perf_counter()
        pre = "no"
        for b in bounds:
            k += 1
            drv.send([f"run {b - state['step']} pre {pre} post no", write, f'print "{MARK} {k} ${{natoms}}"'])
            count = drv.wait_mark(k, deadline)
            state["step"] = b
            omega = read_state(k, count)
            pre = "no"
            if len(breakable):
                bi, bj = run.bond_i[breakable], run.bond_j[breakable]
                dist = np.linalg.norm(state["pos"][bj] - state["pos"][bi], axis=1)
                tension = run.bond_kn[breakable] * (dist - run.bond_len0[breakable])
                broke = breakable[intact[breakable] & (tension > run.bond_ft[breakable])]
                if len(broke):
                    intact[broke] = False
                    extra["broken_by_runner"] += int(len(broke))
                    drv.send(_delete_commands(broke + 1))
                    pre = "yes"
            if contact_reach is not None:
                intact[:] = np.linalg.norm(state["pos"][run.bond_j] - state["pos"][run.bond_i], axis=1) \
                    <= contact_reach
            if b % rec == 0 or b == steps:
                record(omega)
            now = time.perf_counter()
            if progress and (now - last_msg >= 1.0 or b == steps):
                last_msg = now
                progress(f"liggghts: t = {b * run.dt:.4g} s  step {b}/{steps} ({100.0 * b / steps:5.1f} %)  "
                         f"bonds {int(intact.sum())}/{run.n_bonds}  atoms {count}")
        outcome = drv.close(deadline)
        if not outcome.ok:
            fail(describe_failure("liggghts", outcome, log))
    except DriverError as exc:
        fail(describe_failure("liggghts", exc.outcome, log))
    except EngineError:
        if drv.proc.poll() is None:
            drv.finish(kill=True)
        raise
    finally:
        if drv.proc.poll() is None:
            drv.finish(kill=True)
        try:
            dump.unlink()
        except OSError:
            pass
    return result()


__all__ = ["run_deck", "check_data", "deck_variant", "POS_LIMIT"]
