"""Deck folders: export a model or scene for an engine, and run a deck with the engine that wrote it.

``export(source, to, out)`` reads `source`:

- a DDA scene (.toml with [simulation]) with [spheres]: the run's settings come from the scene
  (adapters.spec.from_scene); a DDA scene with blocks only: a YADE Polyhedra deck (``to="yade"``);
- an sgim scene (.toml with [domain]): the model is built in memory and run with default settings;
- an sgim ``model.npz``: run with default settings;
- a ``run.npz`` (a deck's SphereRun): as it is.

``overrides`` (duration, dt, record_every, viscous_damping, liggghts_joints, joint_walls or its older spelling
liggghts_joint_walls) shorten or change the run. ``to`` is a target of adapters/registry.py (yade, liggghts, pfc-text, vtu; a block scene: yade,
the YADE Polyhedra deck): the target's writer writes the deck, what the target cannot take (a variant, an
option, a run.npz without a model) is refused first in one line naming the choices.

Every deck has ``deck.json`` (engine, variant, source, counts, steps, dt, the files). The folder is assembled
under a temporary name and renamed into place: a failed export leaves nothing behind.
``run(deck, out)`` runs a deck with the runner of its deck.json engine (yade, yade-polyhedra, liggghts), after the
engine's reader has checked every file the run reads, and returns the RunResult it saved into `out` (default
DECK/result).
"""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

from sgim.model import SphereModel, check_model
from sgim.outdir import output_folder
from sgim.readback import Fields, read_json, read_npz

from . import registry
from .frames import write_result_frames
from .joint_walls import MODES
from .liggghts_joints import open_joint_problem
from .process import EngineError
from .spec import (LIGGGHTS_JOINTS, SpecError, SphereRun, check_run, check_steps, from_model, from_scene,
                   viscous_coefficient)

TARGETS = registry.export_names()  # the --to names: yade, liggghts, pfc-text, vtu
RUNNABLE = registry.runnable_names()  # deck.json engines `adapters run` runs: yade, yade-polyhedra, liggghts


class DeckError(ValueError):
    """A source, target or deck that cannot be exported or run (one line for the user)."""


def _toml_kind(path):
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return "dda"  # let the scene loader report the problem with its own line
    if "simulation" in data:
        return "dda-spheres" if "spheres" in data else "dda-blocks"
    return "sgim"


def load_source(source, overrides=None, max_steps=None, limit_steps=True):
    """(kind, SphereRun or None, SphereModel or None) of `source`; kind: "spheres" or "blocks". With
    `limit_steps`, a sphere run whose steps pass the step limit (`max_steps`, the --max-steps value, else the
    scene's; spec.check_steps) is refused."""
    path = Path(source)
    if not path.is_file():
        raise DeckError(f"{path}: no such file")
    ov = {k: v for k, v in (overrides or {}).items() if v is not None}
    model = None
    if path.suffix.lower() == ".toml":
        kind = _toml_kind(path)
        if kind == "dda-blocks":
            return "blocks", None, None
        if kind == "dda-spheres":
            run = from_scene(path, max_steps=max_steps, duration=ov.get("duration"), dt=ov.get("dt"),
                             limit_steps=limit_steps)
            model = _scene_model(path)
        else:
            from sgim.builder import build_model  # lazy: the sgim builder loads numba (an sgim scene source only)
            from sgim.scene import load_scene

            model = build_model(load_scene(path))
            run = from_model(model, source=str(path), **_run_kw(ov))
    else:  # an npz: a run.npz (it has a JSON header) or a model.npz, validated (sgim.readback.BadFile)
        arrays = read_npz(path, "a model.npz or run.npz")
        if "header" in arrays or "bond_i" in arrays:
            run = SphereRun(**check_run(path, arrays))
        else:
            model = SphereModel(**check_model(path, arrays, "a model.npz or run.npz"))
            run = from_model(model, source=str(path), **_run_kw(ov))
    _apply_overrides(run, ov, path)
    if limit_steps and not (path.suffix.lower() == ".toml" and kind == "dda-spheres"):  # from_scene checked it
        check_steps(run, path, max_steps)
    return "spheres", run, model


def _scene_model(path):
    from dda.scene import load_scene  # lazy: dda.scene loads numba

    return load_scene(path).spheres["model"]


def _run_kw(ov):
    return {k: ov[k] for k in ("duration", "dt", "record_every") if k in ov}


def _apply_overrides(run, ov, path):
    for key in ("duration", "dt", "record_every"):
        if key in ov:
            val = float(ov[key])
            if not val > 0:
                raise DeckError(f"{path}: --{key.replace('_', '-')} must be > 0 (got {ov[key]!r})")
            setattr(run, key, val)
    if "duration" in ov and "record_every" not in ov:
        run.record_every = run.duration / 100 if run.record_every > run.duration else run.record_every
    run.record_every = min(run.record_every, run.duration)
    if "liggghts_joints" in ov:  # --liggghts-joints: how a LIGGGHTS deck writes the joint pairs
        raw = ov["liggghts_joints"]
        if raw not in LIGGGHTS_JOINTS:
            raise DeckError(f"{path}: --liggghts-joints = {raw!r}: must be one of {', '.join(LIGGGHTS_JOINTS)}")
        if raw == "open" and not run.smooth_joints:
            raise DeckError(f"{path}: --liggghts-joints = 'open': stands in for smooth joints, but the run has "
                            "smooth_joints = false")
        run.liggghts_joints = raw
        if open_joint_problem(run):
            raise DeckError(f"{path}: --liggghts-joints = 'open': {open_joint_problem(run)}")
    for key in ("liggghts_joint_walls", "joint_walls"):  # --joint-walls (and its older LIGGGHTS spelling)
        if key in ov:  # the fixed side of a joint as a wall (adapters/joint_walls.py)
            raw = ov[key]
            if raw not in MODES:
                raise DeckError(f"{path}: --{key.replace('_', '-')} = {raw!r}: must be one of {', '.join(MODES)}")
            for old in ("liggghts_joint_walls", "liggghts_wall_radii"):
                run.extra.pop(old, None)
            run.extra["joint_walls"] = raw
    if "viscous_damping" in ov:  # --viscous-damping: a ratio of critical damping of the first mode, or critical
        raw = ov["viscous_damping"]
        try:
            value = raw if str(raw).strip().lower() == "critical" else float(raw)
            run.viscous_damping = viscous_coefficient(run, value)
        except ValueError as exc:
            msg = str(exc) if "damping" in str(exc) or "mode" in str(exc) else \
                'must be a ratio of critical damping or "critical"'
            raise DeckError(f"{path}: --viscous-damping = {raw!r}: {msg}") from None


def export(source, to, out, variant=None, overrides=None, progress=None, max_steps=None, force=False, blocks=False):
    """Write the deck folder `out` for engine/format `to` from `source`; returns its deck.json dict. `blocks`: the
    source is an sgim scene whose block model (dda/georun.py) is exported, not its spheres.

    `out` must be new, empty or hold an earlier `adapters export` deck, which `force` replaces (only the files
    that export wrote; files added by hand stay): sgim/outdir.py. Anything else is refused before any work.

    A yade or liggghts deck whose steps (duration / dt) pass the step limit (`max_steps`, the --max-steps
    value, else the DDA scene's [simulation] max_steps, else 1e8; dda/limits.py) is refused before the folder
    is made."""
    if blocks:
        if not (Path(source).suffix.lower() == ".toml" and Path(source).is_file() and _toml_kind(source) == "sgim"):
            raise DeckError(f"{source}: --blocks takes an sgim scene (.toml with [domain])")
        target = registry.for_export(to, "blocks")
        if target is None:
            names = ", ".join(t.to for t in registry.TARGETS if t.source == "blocks")
            raise DeckError(f"{source}: --blocks exports to {names} (Polyhedra) only, not {to}")
    else:
        target = _export_target(to, variant, overrides)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DeckError(f"{out}: output exists and is not a folder")
    dest = output_folder(out, "adapters export", force=force, say=progress)
    if blocks:
        kind, run, model = "blocks", None, None  # an sgim scene's block model (dda/georun.py), not its spheres
    else:
        try:
            kind, run, model = load_source(source, overrides, max_steps=max_steps, limit_steps=target.runnable)
        except SpecError as exc:
            raise DeckError(str(exc)) from None
    if kind != target.source:  # a block scene: the target of `to` for blocks, if there is one
        target = registry.for_export(to, kind)
        if target is None:
            names = ", ".join(t.to for t in registry.TARGETS if t.source == kind)
            raise DeckError(f"{source}: a block scene (no [spheres]) exports to {names} (Polyhedra) only, not {to}")
    prepared = target.function("prepare")(source, overrides, max_steps) if target.prepare else None  # steps
    if kind == "spheres" and run.n == 0:
        raise DeckError(f"{source}: the model has no spheres")
    if target.needs_model and model is None:
        raise DeckError(f"{source}: {to} needs an sgim model or scene (a run.npz has no model)")
    variant = variant or target.default_variant
    with dest.assemble() as tmp:
        info = {"engine": target.name, "variant": variant, "source": str(source)}
        if kind == "blocks":
            info.update(target.write(source, tmp, prepared) or {})
        else:
            info.update(name=run.name, n=int(run.n), n_bonds=int(run.n_bonds), n_joints=int(len(run.joint_i)),
                        steps=int(run.steps), dt=float(run.dt), record_steps=int(run.record_steps),
                        duration=float(run.duration))
            if target.saves_run:
                run.save(tmp / "run.npz")
            info.update(target.write(run, tmp, variant, **({"model": model} if target.needs_model else {})) or {})
            info["variant"] = variant
        info["files"] = sorted(p.name for p in tmp.iterdir())
        (tmp / "deck.json").write_text(json.dumps(info, indent=2))
    if progress:
        progress(f"deck       {out}: {info['engine']} ({', '.join(info['files'])})")
    return info


def _export_target(to, variant, overrides):
    """The registry's target of `--to to` for a sphere source, with `variant` and the overrides checked against
    what it takes (DeckError: one line naming the choices)."""
    target = registry.for_export(to)
    if target is None:
        raise DeckError(f"--to: unknown target {to!r} (choose from {', '.join(TARGETS)})")
    if variant is not None and variant not in target.variants:
        raise DeckError(f"--variant: {variant!r} is not a {to} variant "
                        f"(choose from {', '.join(target.variants) or 'none'})")
    for key, value in (overrides or {}).items():
        takers = [t.to for t in registry.TARGETS if key in t.options]
        if value is not None and takers and key not in target.options:
            raise DeckError(f"--{key.replace('_', '-')}: for --to {' | '.join(takers)} only, not {to}")
    return target


def read_deck(deck):
    """deck.json of the deck folder `deck` (a JSON object naming a runnable engine; a liggghts deck's variant, when
    given, one of its variants). DeckError for a folder without deck.json, BadFile for a broken one."""
    deck = Path(deck)
    path = deck / "deck.json"
    if not path.is_file():
        raise DeckError(f"{deck}: not a deck folder (no deck.json; write one with `adapters export`)")
    info = read_json(path, "a deck.json")
    F = Fields(path, info)
    if info.get("engine") not in RUNNABLE:
        raise DeckError(f"{path}: engine {info.get('engine')!r} is not runnable "
                        f"(runnable decks: {', '.join(RUNNABLE)})")
    target = registry.target(info["engine"])
    if target.checks_variant and info.get("variant") is not None:
        F.string("variant", choices=target.variants)
    F.strings("approximations", None)
    return info


def check_deck(deck, info):
    """Read back and validate every file of the deck folder `deck` that its engine's runner or script will read
    (run.npz, yade.json, the LIGGGHTS data header, blocks.npz, poly.json, script files), before the engine is
    started: a broken file is one BadFile / DeckError line, and nothing is run or written."""
    deck = Path(deck)
    engine = info["engine"]
    target = registry.target(engine)
    for name in target.deck_files:
        if not (deck / name).is_file():
            raise DeckError(f"{deck}: not a complete {engine} deck (missing {name}; write it with `adapters export`)")
    run = target.read(deck)  # the target's reader: every file its runner reads, back and checked
    if run is not None and run.n == 0:
        raise DeckError(f"{deck / 'run.npz'}: the run has no spheres")


def run(deck, out=None, np=1, timeout=None, progress=None):
    """Run the deck folder with its engine; the RunResult is saved into `out` (default DECK/result), with its
    ParaView files (adapters/frames.py: frames/*.vtu, result.pvd, final.vtu), also for a partial result."""
    deck = Path(deck)
    info = read_deck(deck)
    if not (isinstance(np, int) and np >= 1):
        raise DeckError(f"--np must be a positive integer (got {np!r})")
    if timeout is not None and not timeout > 0:
        raise DeckError(f"--timeout must be > 0 seconds (got {timeout!r})")
    check_deck(deck, info)  # every file the run will read, before the engine starts
    out = Path(out) if out is not None else deck / "result"
    try:  # ParaView files beside the result (adapters/frames.py), whatever the engine
        res = registry.target(info["engine"]).run(deck, out, np=np, timeout=timeout, progress=progress)
    except EngineError as exc:
        if exc.result is not None:
            write_result_frames(exc.result, out, deck / "run.npz", progress)
        raise
    write_result_frames(res, out, deck / "run.npz", progress)
    return res


__all__ = ["export", "run", "load_source", "read_deck", "check_deck", "DeckError", "EngineError", "TARGETS",
           "RUNNABLE"]
