"""`dda run` as a library function: run a DDA scene (blocks, spheres, or both), write its outputs, state its
answers. ``dda.run(scene, out)`` is this module's :func:`run`; dda/cli.py is its command line.

Outputs of a block run: series.npz / series.csv (dda/results.py), series.png (dda/plots.py), final.npz, the
VTU frames indexed by blocks.pvd, final.png and summary.json; of a run with spheres: the same series, the frames
indexed by spheres.pvd, spheres.vtu / blocks.vtu (see _run_spheres). summary.json holds the answers of the
scene's [[report]] tables (dda/answers.py).
"""
from __future__ import annotations

import contextlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sgim.common import CliError
from sgim.machine import machine_info
from sgim.outdir import output_folder

from .answers import Answers, default_reports
from .georun import GeoScene, is_sgim_scene, load_geo_scene
from .plots import plot_series
from .progress import RunProgress
from .render import (block_polydata, faces_polydata, render_meshes, render_png, save_mesh, sphere_polydata,
                     write_pvd, write_vtu)
from .results import ENERGY_COLUMNS, save_final, save_sphere_csv
from .scene import DDAScene, load_scene, scene_from_dict
from .simulation import BlowUpError


@dataclass
class RunOutcome:
    """What a run gives back: the scene, the simulation in its final state (a dda Simulation or
    SphereSimulation), the recorded series (Results or SphereResults), the summary (summary.json's contents)
    and a one-line headline."""
    scene: object
    simulation: object
    results: object
    summary: dict
    headline: str

    @property
    def status(self):
        """"ok", or "blow-up" (the simulation then holds the last good state; summary["message"] says why)."""
        return self.summary["status"]

    @property
    def answers(self):
        """The [[report]] answers: dicts with label, quantity, value, unit (and reference, error)."""
        return self.summary["answers"]


class _Nowhere:
    """The output folder of a run that writes nothing: with no formats nothing is written into it (None)."""

    assemble = staticmethod(contextlib.nullcontext)


def _write_outputs(scene, sim, res, tmp, frames, summary, say, out):
    if "npz" in scene.formats:
        res.save_npz(tmp / "series.npz")
    if "csv" in scene.formats:
        res.save_csv(tmp / "series.csv")
    save_final(sim, tmp / "final.npz")
    if "vtu" in scene.formats and frames:
        write_pvd(frames, tmp / "blocks.pvd")
    if "png" in scene.formats:
        plot_series(tmp / "series.png", scene.name, res.time, res.energy,
                    [("blocks", res.positions, res.velocities, ~np.asarray(res.fixed, bool))])
        render_png(sim, tmp / "final.png", scene.width, scene.height, title=scene.name)
        if say:
            say(f"render     {out / 'final.png'}")
    (tmp / "summary.json").write_text(json.dumps(summary, indent=2))


def _n_moving(scene):
    return sum(not getattr(b, "fixed", False) for b in scene.blocks)


def _run_frames(sim, scene, say, frame, append):
    """Run `sim` for the scene's duration in `scene.frames` pieces, calling `frame()` before the first and after
    each piece; `append(res, r)` merges a piece's results into the run's. Returns (results, status, message):
    on a blow-up the results so far, "blow-up" and its message."""
    frame()
    piece = scene.duration / scene.frames
    clock = RunProgress(say, sim.time + scene.duration, sim.time, sim.steps)  # percent and ETA of the whole run
    status, message, res = "ok", "", None
    for _ in range(scene.frames):
        try:
            r = sim.run(piece, record_every=min(scene.record_every, piece), progress=clock)
        except BlowUpError as exc:
            status, message, r = "blow-up", str(exc), exc.results
        if res is None:
            res = r
        else:
            append(res, r)
        frame()
        if status != "ok":
            break
    return res, status, message


def _append_block_results(res, r):
    # a later piece's first row repeats the previous piece's last state
    for name in ("time", "pos", "quat", "vel", "energy", "contacts", "points", "sliding"):
        getattr(res, name).extend(getattr(r, name)[1:])
    res.wall_s += r.wall_s
    res.steps = r.steps


def _append_sphere_results(res, r):
    # a later piece records no initial row (the energy reference is already set)
    for name in ("time", "pos", "vel", "energy", "contacts", "wall_contacts", "bonds", "block_pos", "block_quat"):
        getattr(res, name).extend(getattr(r, name))
    res.wall_s += r.wall_s


def _model_colour(model, n):
    """The sgim colour of each sphere of a [spheres] model (None when the model has none)."""
    colour = getattr(model, "colour", None)
    if colour is None:
        try:
            with np.load(model, allow_pickle=False) as z:
                colour = z["colour"] if "colour" in z.files else None
        except Exception:  # noqa: BLE001 - the colour is only for the pictures: without it they are plain
            colour = None
    return None if colour is None or len(colour) != n else np.asarray(colour)


def _sphere_meshes(sim, colour):
    """(spheres, blocks) pyvista meshes of the current state of a SphereSimulation (blocks None: no walls)."""
    ss = sim.spheres
    spheres = sphere_polydata(sim.x, ss.radii, fixed=ss.fixed, velocity=sim.v, displacement=sim.displacement(),
                              colour=colour)
    if sim.blocks is not None:
        blocks = block_polydata(sim.blocks)
    elif len(sim.wface_start) > 1:
        blocks = faces_polydata(sim.wvert, sim.wfv_start, sim.wfv, sim.wface_start,
                                np.ones(len(sim.wface_start) - 1, bool))
    else:
        blocks = None
    return spheres, blocks


def _run_spheres(scene, out, dest, formats, max_steps, say, t0):
    """`dda run` of a scene with [spheres]: series.npz (positions, energies, intact bonds per record, the final
    bond state; block_pos / block_quat per record when blocks move), series.csv, a VTU frame series
    (frames/spheres_*.vtu: points with radius, fixed, velocity, displacement, colour; frames/blocks_*.vtu, or one
    frames/walls.vtu when no block moves) indexed with their times in spheres.pvd (part 0 spheres, part 1
    blocks), the final spheres.vtu / blocks.vtu, final.png and summary.json."""
    ss, sim = scene.build_spheres(max_steps=max_steps)  # step limit: SceneError
    colour = _model_colour(scene.spheres["model"], ss.n)
    answers = Answers(scene.reports or default_reports(True), sim, spheres=True)
    if say:
        say(f"scene      {scene.name}: {ss.n} spheres ({int(ss.fixed.sum())} fixed), {ss.n_bonds} bonds, "
            f"{ss.n_joints} smooth joints, {len(scene.blocks)} blocks ({_n_moving(scene)} moving), dt = {sim.dt:.3g} s "
            f"(critical {sim.dt_crit:.3g} s)")
    with dest.assemble() as tmp:
        want_vtu = "vtu" in formats
        entries = []
        if want_vtu:
            (tmp / "frames").mkdir()

        def frame():
            if not want_vtu:
                return
            k = len(entries) // 2
            spheres, blocks = _sphere_meshes(sim, colour)
            save_mesh(spheres, tmp / f"frames/spheres_{k:05d}.vtu")
            entries.append((sim.time, f"frames/spheres_{k:05d}.vtu", 0))
            if blocks is None:
                name = None
            elif sim.blocks is not None:
                name = f"frames/blocks_{k:05d}.vtu"
                save_mesh(blocks, tmp / name)
            else:  # fixed walls do not move: one file for every time
                name = "frames/walls.vtu"
                if k == 0:
                    save_mesh(blocks, tmp / name)
            entries.append((sim.time, name, 1))

        res, status, message = _run_frames(sim, scene, say, frame, _append_sphere_results)
        if out is not None:
            res.save(tmp / "series.npz", sim)
        if "csv" in formats:
            save_sphere_csv(res, tmp / "series.csv", ss.fixed,
                            None if sim.blocks is None else sim.blocks.A.fixed)
        spheres, blocks = _sphere_meshes(sim, colour) if formats else (None, None)
        if want_vtu:
            write_pvd([e for e in entries if e[1] is not None], tmp / "spheres.pvd")
            save_mesh(spheres, tmp / "spheres.vtu")
            if blocks is not None:
                save_mesh(blocks, tmp / "blocks.vtu")
        if "png" in formats:
            render_meshes(tmp / "final.png", blocks=blocks, spheres=spheres, width=scene.width,
                          height=scene.height, title=scene.name, time=sim.time)
            if say:
                say(f"render     {out / 'final.png'}")
        e = res.energy[-1]
        summary = {
            "scene": scene.name, "scene_path": str(scene.path), "status": status, "message": message,
            "spheres": ss.n, "fixed": int(ss.fixed.sum()), "bonds": ss.n_bonds,
            "bonds_intact": int(sim.bond_intact.sum()), "walls": len(scene.blocks) - _n_moving(scene),
            "moving_blocks": _n_moving(scene), "dt": sim.dt,
            "dt_critical": sim.dt_crit, "steps": sim.steps, "time": sim.time,
            "wall_s": round(time.perf_counter() - t0, 3),
            "energy_final": dict(zip(ENERGY_COLUMNS, [float(x) for x in e])),
            "answers": answers.finish(sim, e[-1]),
            "machine": machine_info(),
        }
        if "png" in formats:
            bodies = [("spheres", res.pos, res.vel, ~(ss.fixed | ss.prescribed))]
            if res.block_pos:
                bodies.append(("blocks", res.block_pos, None, ~np.asarray(sim.blocks.A.fixed, bool)))
            plot_series(tmp / "series.png", scene.name, res.time, res.energy, bodies)
        if out is not None:
            (tmp / "summary.json").write_text(json.dumps(summary, indent=2))
    headline = (f"{ss.n} spheres, {sim.steps} steps to t = {sim.time:.4g} s in {summary['wall_s']:.2f} s, "
                f"{summary['bonds_intact']} of {ss.n_bonds} bonds intact")
    return RunOutcome(scene, sim, res, summary, headline)


def run(scene, out=None, force=False, progress=None, max_steps=None) -> RunOutcome:
    """Run a DDA scene: `scene` a scene file (a DDA scene, with blocks and / or [spheres]), a dict of its tables
    or a loaded dda.scene.DDAScene. With `out`, the outputs of `dda run` are written there (the scene's [output] formats:
    series.npz / .csv / .png, final.npz, VTU frames and their PVD index, final.png, summary.json; an existing
    folder only when it holds an earlier `dda run` output and `force`, see sgim/outdir.py); without, nothing
    is written. `progress(line)` receives progress lines; `max_steps` overrides the scene's step limit.

    Returns a RunOutcome: the simulation in its final state, the recorded series, the summary (the contents of
    summary.json) and the answers the scene declares ([[report]]). Bad input raises sgim.scene.SceneError (or
    sgim.common.CliError for the output folder) before anything is written; a blow-up returns the last good
    state with status "blow-up"."""
    t0 = time.perf_counter()
    say = progress
    if isinstance(scene, dict):  # the tables of a scene file
        scene = scene_from_dict(scene, f"{scene.get('name', 'scene')}.toml")
    elif not isinstance(scene, DDAScene):
        # SceneError before anything is created; an sgim scene ([domain]) runs its block model (dda/georun.py)
        scene = load_geo_scene(scene, progress=say) if is_sgim_scene(scene) else load_scene(scene)
    if out is not None:
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise CliError(f"{out}: -o = {str(out)!r}: output exists and is not a folder")
        dest = output_folder(out, "dda run", force=force, say=say)  # refused before the run
    else:
        dest = _Nowhere()
    formats = scene.formats if out is not None else ()  # a run in memory writes nothing
    if scene.spheres:
        return _run_spheres(scene, out, dest, formats, max_steps, say, t0)
    bs, sim = scene.build(max_steps=max_steps)  # step limit: SceneError
    if say:
        say(f"scene      {scene.name}: {bs.n_blocks} blocks ({len(sim.active)} moving), dt = {sim.dt:.3g} s "
            f"(critical {sim.dt_crit:.3g} s), {int(round(scene.duration / sim.dt))} steps")
    answers = Answers(scene.reports or default_reports(False), sim)  # the initial state the answers start from
    with dest.assemble() as tmp:
        frames = []
        want_vtu = "vtu" in formats
        if want_vtu:
            (tmp / "frames").mkdir()
        def frame():
            if want_vtu:
                name = f"frames/frame_{len(frames):05d}.vtu"
                write_vtu(sim, tmp / name)
                frames.append((sim.time, name))

        res, status, message = _run_frames(sim, scene, say, frame, _append_block_results)
        summary = {
            "scene": scene.name, "scene_path": str(scene.path), "status": status, "message": message,
            "blocks": bs.n_blocks, "moving": int(len(sim.active)), "dt": sim.dt, "dt_critical": sim.dt_crit,
            "steps": sim.steps, "time": sim.time, "wall_s": round(time.perf_counter() - t0, 3),
            "energy_final": dict(zip(ENERGY_COLUMNS, [float(x) for x in res.energies[-1]])),
            "contacts_final": int(sim.stats[5]), "points_final": int(sim.stats[6]),
            "answers": answers.finish(sim, res.energies[-1][-1]),
            "machine": machine_info(),
        }
        if isinstance(scene, GeoScene):  # the block model of an sgim scene: blocks moved, the cut's summary
            summary.update(scene.run_summary(sim))
        if out is not None:
            _write_outputs(scene, sim, res, tmp, frames, summary, say, out)
    headline = (f"{bs.n_blocks} blocks, {sim.steps} steps to t = {sim.time:.4g} s in {summary['wall_s']:.2f} s "
                f"(energy balance error {summary['energy_final']['balance_error']:.3g} J)")
    return RunOutcome(scene, sim, res, summary, headline)
