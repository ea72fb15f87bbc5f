"""Deck folders: export a model or scene for an engine, and run a deck with the engine that wrote it.

``export(source, to, out)`` reads `source`:

- a DDA scene (.toml with [simulation]) with [spheres]: the run's settings come from the scene
  (adapters.spec.from_scene); a DDA scene with blocks only: a YADE Polyhedra deck (``to="yade"``);
- an sgim scene (.toml with [domain]): the model is built in memory and run with default settings;
- an sgim ``model.npz``: run with default settings;
- a ``run.npz`` (a deck's SphereRun): as it is.

``overrides`` (duration, dt, record_every, viscous_damping, liggghts_joints) shorten or change the run. ``to`` is
one of:

=========  ======================================================================
yade       DECK/script.py + run.npz (JCFpm bonded spheres), or a Polyhedra deck
liggghts   DECK/data + DECK/in + run.npz (variant: bonds, sjkr, clumps)
pfc-text   DECK/balls.txt + DECK/contacts.txt (sgim's PFC-style text lists)
vtu        DECK/spheres.vtu (points: radius, colour, fixed, bond count) + bonds.vtu (lines)
=========  ======================================================================

Every deck has ``deck.json`` (engine, variant, source, counts, steps, dt, the files). The folder is assembled
under a temporary name and renamed into place: a failed export leaves nothing behind.
``run(deck, out)`` runs a yade / liggghts deck (adapters.yade, adapters.liggghts) and returns the RunResult
it saved into `out` (default DECK/result).
"""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np

from .process import EngineError
from .spec import SpecError, SphereRun, check_run, check_steps, from_model, from_scene

TARGETS = ("yade", "liggghts", "pfc-text", "vtu")
RUNNABLE = ("yade", "yade-polyhedra", "liggghts")
VARIANTS = {"liggghts": ("bonds", "sjkr", "clumps"), "yade": ("jcfpm",)}


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
    from sgim.model import SphereModel

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
            from sgim.builder import build_model
            from sgim.scene import load_scene

            model = build_model(load_scene(path))
            run = from_model(model, source=str(path), **_run_kw(ov))
    else:  # an npz: a run.npz (it has a JSON header) or a model.npz, validated (sgim.readback.BadFile)
        from sgim.model import check_model
        from sgim.readback import read_npz

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
    from dda.scene import load_scene

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
        from .spec import LIGGGHTS_JOINTS

        raw = ov["liggghts_joints"]
        if raw not in LIGGGHTS_JOINTS:
            raise DeckError(f"{path}: --liggghts-joints = {raw!r}: must be one of {', '.join(LIGGGHTS_JOINTS)}")
        if raw == "open" and not run.smooth_joints:
            raise DeckError(f"{path}: --liggghts-joints = 'open': stands in for smooth joints, but the run has "
                            "smooth_joints = false")
        run.liggghts_joints = raw
        from .liggghts import open_joint_problem

        if open_joint_problem(run):
            raise DeckError(f"{path}: --liggghts-joints = 'open': {open_joint_problem(run)}")
    if "viscous_damping" in ov:  # --viscous-damping: a ratio of critical damping of the first mode, or critical
        from .spec import viscous_coefficient

        raw = ov["viscous_damping"]
        try:
            value = raw if str(raw).strip().lower() == "critical" else float(raw)
            run.viscous_damping = viscous_coefficient(run, value)
        except ValueError as exc:
            msg = str(exc) if "damping" in str(exc) or "mode" in str(exc) else \
                'must be a ratio of critical damping or "critical"'
            raise DeckError(f"{path}: --viscous-damping = {raw!r}: {msg}") from None


def export(source, to, out, variant=None, overrides=None, progress=None, max_steps=None, force=False):
    """Write the deck folder `out` for engine/format `to` from `source`; returns its deck.json dict.

    `out` must be new, empty or hold an earlier `adapters export` deck, which `force` replaces (only the files
    that export wrote; files added by hand stay): sgim/outdir.py. Anything else is refused before any work.

    A yade or liggghts deck whose steps (duration / dt) pass the step limit (`max_steps`, the --max-steps
    value, else the DDA scene's [simulation] max_steps, else 1e8; dda/limits.py) is refused before the folder
    is made."""
    from sgim.cli import output_folder

    if to not in TARGETS:
        raise DeckError(f"--to: unknown target {to!r} (choose from {', '.join(TARGETS)})")
    if variant is not None and variant not in VARIANTS.get(to, ()):
        raise DeckError(f"--variant: {variant!r} is not a {to} variant "
                        f"(choose from {', '.join(VARIANTS.get(to, ())) or 'none'})")
    if (overrides or {}).get("liggghts_joints") is not None and to != "liggghts":
        raise DeckError(f"--liggghts-joints: for --to liggghts only, not {to}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DeckError(f"{out}: output exists and is not a folder")
    dest = output_folder(out, "adapters export", force=force, say=progress)
    try:
        kind, run, model = load_source(source, overrides, max_steps=max_steps, limit_steps=to in RUNNABLE)
    except SpecError as exc:
        raise DeckError(str(exc)) from None
    blocks_scene = None
    if kind == "blocks" and to == "yade":  # the polyhedra deck's steps, before the folder is made
        from dda.scene import load_scene

        from .yade_poly import polyhedra_steps

        blocks_scene = load_scene(source)
        ov = overrides_for_blocks(overrides)
        ov["dt"], ov["duration"] = polyhedra_steps(blocks_scene, source, ov.get("dt"), ov.get("duration"),
                                                   max_steps)
    if kind == "blocks" and to != "yade":
        raise DeckError(f"{source}: a block scene (no [spheres]) exports to yade (Polyhedra) only, not {to}")
    if kind == "spheres" and run.n == 0:
        raise DeckError(f"{source}: the model has no spheres")
    if to == "pfc-text" and model is None:
        raise DeckError(f"{source}: pfc-text needs an sgim model or scene (a run.npz has no model)")
    with dest.assemble() as tmp:
        info = {"engine": to, "variant": variant, "source": str(source)}
        if kind == "blocks":
            from .yade_poly import write_polyhedra_deck

            info["engine"] = "yade-polyhedra"
            info.update(write_polyhedra_deck(source, tmp, **ov, scene=blocks_scene) or {})
        else:
            info.update(name=run.name, n=int(run.n), n_bonds=int(run.n_bonds), n_joints=int(len(run.joint_i)),
                        steps=int(run.steps), dt=float(run.dt), record_steps=int(run.record_steps),
                        duration=float(run.duration))
            if to in ("yade", "liggghts"):
                run.save(tmp / "run.npz")
                if to == "yade":
                    from .yade import write_deck
                    info.update(write_deck(run, tmp) or {})
                else:
                    from .liggghts import write_deck
                    info.update(write_deck(run, tmp, variant=variant or "bonds") or {})
                    info["variant"] = variant or "bonds"
            elif to == "pfc-text":
                model.save_text(tmp / "balls.txt", tmp / "contacts.txt")
            else:
                write_vtu(run, tmp)
        info["files"] = sorted(p.name for p in tmp.iterdir())
        (tmp / "deck.json").write_text(json.dumps(info, indent=2))
    if progress:
        progress(f"deck       {out}: {info['engine']} ({', '.join(info['files'])})")
    return info


def overrides_for_blocks(overrides):
    return {k: v for k, v in (overrides or {}).items() if k in ("duration", "dt", "record_every") and v is not None}


def write_vtu(run: SphereRun, folder):
    """spheres.vtu (vertex cells: radius, colour, fixed, intact-bond count) and bonds.vtu (one line per bond)."""
    import meshio

    from sgim.model import atomic_vtu

    n = run.n
    nb = np.bincount(np.r_[run.bond_i, run.bond_j].astype(np.int64), minlength=n)
    pts = meshio.Mesh(run.centers, [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))],
                      point_data={"radius": run.radii, "colour": run.colour.astype(np.int32),
                                  "fixed": run.fixed.astype(np.int32), "bonds": nb.astype(np.int32)})
    lines = meshio.Mesh(run.centers, [("line", np.c_[run.bond_i, run.bond_j].astype(np.int64))],
                        cell_data={"kn": [run.bond_kn], "tensile_force": [np.where(np.isfinite(run.bond_ft),
                                                                                    run.bond_ft, -1.0)]})
    for name, mesh in (("spheres.vtu", pts), ("bonds.vtu", lines)):
        atomic_vtu(Path(folder) / name, mesh)


def read_deck(deck):
    """deck.json of the deck folder `deck` (a JSON object naming a runnable engine; a liggghts deck's variant, when
    given, one of its variants). DeckError for a folder without deck.json, BadFile for a broken one."""
    from sgim.readback import Fields, read_json

    deck = Path(deck)
    path = deck / "deck.json"
    if not path.is_file():
        raise DeckError(f"{deck}: not a deck folder (no deck.json; write one with `adapters export`)")
    info = read_json(path, "a deck.json")
    F = Fields(path, info)
    if info.get("engine") not in RUNNABLE:
        raise DeckError(f"{path}: engine {info.get('engine')!r} is not runnable "
                        f"(runnable decks: {', '.join(RUNNABLE)})")
    if info["engine"] == "liggghts" and info.get("variant") is not None:
        F.string("variant", choices=VARIANTS["liggghts"])
    F.strings("approximations", None)
    return info


def check_deck(deck, info):
    """Read back and validate every file of the deck folder `deck` that its engine's runner or script will read
    (run.npz, yade.json, the LIGGGHTS data header, blocks.npz, poly.json, script files), before the engine is
    started: a broken file is one BadFile / DeckError line, and nothing is run or written."""
    deck = Path(deck)
    engine = info["engine"]
    need = {"yade": ("run.npz", "script.py", "yade.json"), "liggghts": ("run.npz", "data", "in"),
            "yade-polyhedra": ("blocks.npz", "poly.json", "script.py")}[engine]
    for name in need:
        if not (deck / name).is_file():
            raise DeckError(f"{deck}: not a complete {engine} deck (missing {name}; write it with `adapters export`)")
    if engine == "yade-polyhedra":
        from .yade_poly import check_polyhedra_deck

        check_polyhedra_deck(deck)
        return
    run = SphereRun.load(deck / "run.npz")
    if engine == "yade":
        from .yade import read_config

        read_config(deck / "yade.json")
    else:
        from .liggghts import check_data, deck_variant

        check_data(deck / "data", run, deck_variant(deck))
    if run.n == 0:
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
    engine = info["engine"]
    if engine == "yade":
        from .yade import run_deck
    elif engine == "yade-polyhedra":
        from .yade_poly import run_polyhedra_deck as run_deck
    else:
        from .liggghts import run_deck
    from .frames import write_result_frames  # ParaView files beside the result, whatever the engine

    try:
        res = run_deck(deck, out, np=np, timeout=timeout, progress=progress)
    except EngineError as exc:
        if exc.result is not None:
            write_result_frames(exc.result, out, deck / "run.npz", progress)
        raise
    write_result_frames(res, out, deck / "run.npz", progress)
    return res


__all__ = ["export", "run", "load_source", "read_deck", "check_deck", "write_vtu", "DeckError", "EngineError",
           "TARGETS"]
