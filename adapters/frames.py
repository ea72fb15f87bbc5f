"""ParaView files of a run's result, whichever engine ran it (in-house, YADE, LIGGGHTS, YADE Polyhedra).

``write_frames(result, folder, run)`` writes into `folder`:

=====================  =====================================================================================
frames/frame_NNNNN.vtu the spheres at each record of the result (result.pos; without records: the start and
                       the end): vertex cells, point data id, displacement (vector from x0) and
                       displacement_magnitude [m], and from the run (when given) radius, colour, fixed
result.pvd             the frames with their times [s] (ParaView: File > Open result.pvd)
final.vtu              the end state: the spheres (as above, plus velocity [m/s]) and the run's bonds as line
                       cells (after the vertex cells) with cell data cell_kind (0 sphere, 1 bond) and intact
                       (1 intact at the end, 0 broken, -1 on sphere cells)
=====================  =====================================================================================

The run (adapters.spec.SphereRun, a deck's run.npz) gives radii, colours and the bond list; a result without
one (a Polyhedra run: the "spheres" are block centroids) gets the positions and displacements only.
``adapters.run`` (deck.run) and ``run_inhouse(run, out)`` write them beside every result they save (a partial
one included); ``export_result(source, out)`` is ``adapters export RESULT --to vtu``: the same files in a new
output folder.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dda.render import write_pvd
from sgim.common import atomic_path
from sgim.outdir import output_folder
from sgim.vtu import array, constant, pieces, points_and_lines

from .result import RunResult
from .spec import SphereRun

FRAME = "frames/frame_{:05d}.vtu"


def is_result(source):
    """True when `source` is a result folder or its result.npz (arrays final_pos and bond_intact)."""
    p = Path(source)
    if p.is_dir():
        p = p / "result.npz"
    if not p.is_file() or p.suffix.lower() != ".npz":
        return False
    try:
        with np.load(p, allow_pickle=False) as z:
            return {"final_pos", "bond_intact", "x0"} <= set(z.files)
    except Exception:  # noqa: BLE001 - not a readable npz: not a result; the caller's reader says what is wrong
        return False


def find_run(result_folder, n):
    """(SphereRun, path) of the deck a result folder belongs to: run.npz in the folder or in its parent
    (DECK/result and DECK/result-dda); (None, None) when there is none or it has not `n` spheres."""
    for cand in (Path(result_folder) / "run.npz", Path(result_folder).resolve().parent / "run.npz"):
        if cand.is_file():
            try:
                run = SphereRun.load(cand)
            except Exception:  # noqa: BLE001 - a broken run.npz: frames without it
                continue
            if run.n == n:
                return run, cand
    return None, None


def _frames(result: RunResult):
    """[(time, positions)] of the frames."""
    if result.pos is not None and len(result.pos):
        return [(float(t), result.pos[k]) for k, t in enumerate(result.time)]
    end = float(result.steps * result.dt) if result.steps else (float(result.time[-1]) if len(result.time) else 1.0)
    return [(0.0, result.x0), (end, result.final_pos)]


def _point_data(result: RunResult, run, pos, velocity=None):
    n = result.n
    disp = np.asarray(pos, float) - np.asarray(result.x0, float)
    data = [array("id", np.arange(n, dtype=np.int64)), array("displacement", disp),
            array("displacement_magnitude", np.linalg.norm(disp, axis=1))]
    if run is not None:
        data += [array("radius", np.asarray(run.radii, float)), array("colour", np.asarray(run.colour, np.int32)),
                 array("fixed", np.asarray(run.fixed, bool).astype(np.uint8))]
    if velocity is not None:
        data.append(array("velocity", np.asarray(velocity, float)))
    return data


def write_frames(result: RunResult, folder, run=None):
    """Write frames/*.vtu, result.pvd and final.vtu of `result` into `folder` (see the module docstring); frames
    of an earlier run in the folder are removed first. Returns {"frames": count, "files": [...]}."""

    folder = Path(folder)
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    for old in (folder / "frames").glob("frame_*.vtu"):
        old.unlink()
    if run is not None and run.n != result.n:
        run = None
    entries = []
    for k, (t, pos) in enumerate(_frames(result)):
        name = FRAME.format(k)
        with atomic_path(folder / name) as tmp:
            points_and_lines(tmp, pos, np.zeros((0, 2), np.int64), _point_data(result, run, pos))
        entries.append((t, name))
    write_pvd(entries, folder / "result.pvd")
    n = result.n
    if run is not None:
        lines = np.column_stack([run.bond_i, run.bond_j]).astype(np.int64)
        intact = np.asarray(result.bond_intact, bool)
        if len(intact) != len(lines):
            intact = np.ones(len(lines), bool)  # a result of another bond list: state unknown, drawn intact
    else:
        lines, intact = np.zeros((0, 2), np.int64), np.zeros(0, bool)
    m = len(lines)
    cells = [pieces("cell_kind", np.uint8, [(n, constant(0)), (m, constant(1))]),
             pieces("intact", np.int8, [(n, constant(-1)), (m, lambda s, e: intact[s:e])])]
    with atomic_path(folder / "final.vtu") as tmp:
        points_and_lines(tmp, result.final_pos, lines,
                         _point_data(result, run, result.final_pos, result.final_vel), cells)
    return {"frames": len(entries), "files": ["result.pvd", "final.vtu"] + [e[1] for e in entries]}


def write_result_frames(result: RunResult, folder, run=None, progress=None):
    """`write_frames` for a run's result folder: `run` a SphereRun, or the path of a run.npz (used when it
    holds the result's spheres); a progress line names result.pvd. Called by adapters.run (deck.run) and
    run_inhouse for every result they save, a partial one included."""
    if run is not None and not hasattr(run, "radii"):
        try:
            run = SphereRun.load(run) if Path(run).is_file() else None
        except Exception:  # noqa: BLE001 - the deck was checked before the run; frames without it otherwise
            run = None
    info = write_frames(result, folder, run)
    if progress:
        progress(f"paraview   {Path(folder) / 'result.pvd'} ({info['frames']} frames), "
                 f"{Path(folder) / 'final.vtu'}")
    return info


def export_result(source, out, force=False, progress=None):
    """``adapters export RESULT --to vtu -o OUT``: the result folder (or its result.npz) `source` as ParaView
    files in the output folder `out` (sgim/outdir.py rules): frames/*.vtu, result.pvd, final.vtu and
    export.json. The bonds, radii and colours come from the deck's run.npz beside or above the result."""

    src = Path(source)
    folder = src if src.is_dir() else src.parent
    dest = output_folder(out, "adapters export", force=force, say=progress)
    res = RunResult.load(folder)
    run, run_path = find_run(folder, res.n)
    with dest.assemble() as tmp:
        info = write_frames(res, tmp, run)
        info = {"engine": "vtu", "source": str(source), "result_engine": res.engine, "status": res.status,
                "n": int(res.n), "bonds": 0 if run is None else int(run.n_bonds), "frames": info["frames"],
                "run": None if run is None else str(run_path),
                "files": ["result.pvd", "final.vtu", "frames/frame_*.vtu"]}
        (tmp / "export.json").write_text(json.dumps(info, indent=2))
    if progress:
        progress(f"vtu        {out}: {info['frames']} frames of the {res.engine} result + final.vtu"
                 + ("" if run is not None else " (no run.npz beside the result: no radii or bonds)")
                 + "; open result.pvd in ParaView")
    return info


__all__ = ["write_frames", "write_result_frames", "export_result", "is_result", "find_run"]
