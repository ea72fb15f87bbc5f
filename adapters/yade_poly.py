"""YADE Polyhedra deck from a DDA block scene: the same blocks run by YADE's CGAL polyhedra.

Deck (``write_polyhedra_deck(scene_path, folder)``)::

    DECK/blocks.npz  world vertices of every block (concatenated, vert_start), fixed flags, densities,
                     initial velocities / angular velocities, names
    DECK/poly.json   contact material, gravity, local damping, dt, steps, record_steps
    DECK/script.py   adapters/yade_poly_script.py (YADE's own Python: numpy + json + yade only)

``run_polyhedra_deck(folder, out, np=1, timeout=None, progress=None)`` runs it (``yade -n -f2 -x``) and returns
a RunResult (engine "yade-polyhedra") whose "spheres" are the blocks: x0 / final_pos = block centroids,
final_vel their velocities, pos the centroids at every record, series "kinetic" (translational + rotational
energy of the free blocks); bond_intact is empty.

Mapping from the DDA scene:
- blocks: the BlockSpec world vertices (dda.scene.load_scene(...).blocks), fixed flags (blockedDOFs xyzXYZ),
  velocity / angular_velocity, density of their [[material]];
- contact: YADE's volumetric law (Law2_PolyhedraGeom_PolyhedraPhys_Volumetric) gives a normal force
  F = kn_v V (V the overlap volume) with kn_v = E1 E2 / (E1 + E2) and a shear spring ks = (E1 nu1)(E2 nu2) /
  (E1 nu1 + E2 nu2) [N/m] on the shear displacement, Coulomb friction. With L = (mean volume of the free
  blocks)^(1/3), we take young = 2 kn / L^2 and poisson = ks L^2 / kn, so that a face contact of area L^2 has
  the normal stiffness kn_v L^2 = kn of one DDA penalty spring and the shear stiffness ks of one DDA shear
  spring ([contact] kn, ks); friction = [contact] friction;
- gravity, local damping (NewtonIntegrator.damping = [simulation] local_damping), run length and records from
  [simulation]; dt: `dt` if given, else the scene's dt, else the in-house DDA Simulation's step (safety x its
  critical step, which counts 8 penalty springs per block and is therefore stable for YADE's softer contact).
  PWaveTimeStep() returns 1.0 in this YADE build: the step is always set by hand.

Approximations (RunResult.extra["approximations"]): the normal force follows the overlap volume, not DDA's
point penalty springs; no viscous contact damping ([contact] damping ignored), no cohesion / tensile strength;
deformable blocks (dof 12) run rigid; per-material-pair laws are not carried over. Known bug of YADE 2023.02a
(Debian): the volumetric law keeps the shear force on the law object, not per contact, so with several
contacts each one starts from the previous contact's shear force; single-contact runs (a block on an incline)
are right, multi-contact runs (the wedge: two or three contacts) are unreliable, especially static ones.
Measured on cases/scenes/dda_incline.toml (one contact): slide after 1 s 0.907031 m against 0.906410 m analytical
(+0.07 %). On cases/scenes/dda_wedge.toml (friction 18 degrees, close to the critical 19.7, sliding on both joints):
0.3268 m along the line of intersection after 1 s against 0.2023 m analytical (+62 %), and +316 % with a ten
times stiffer material: the error follows the shared shear force, not the stiffness mapping. Far from the
limit (cases/scenes/crossval/block_wedge.toml, friction 10 degrees) the same wedge slides 1.1173 m against 1.1056 m
(+1.05 %): there the friction forces are a small part of the motion.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np

from dda.limits import block_dt_source, check
from dda.polyhedra import mass_properties
from sgim.common import SceneError
from sgim.readback import Arrays, Fields, read_json, read_npz

from .process import EngineError, find_engine
from .result import COMPLETE, INCOMPLETE, RunResult
from .yade import finish, load_output, run_script

SCRIPT = Path(__file__).with_name("yade_poly_script.py")
OUTPUTS = ("yade_series.npz", "yade_final.npz")
APPROXIMATIONS = [
    "normal force from the overlap volume (YADE volumetric law), not DDA point penalty springs",
    "no viscous contact damping, no cohesion or tensile strength",
    "YADE 2023.02a keeps the shear force on the law object, not per contact: runs with several contacts at "
    "once are unreliable (single-contact runs are right)",
]


def polyhedra_steps(scene, scene_path, dt=None, duration=None, max_steps=None):
    """(dt, duration) of the polyhedra deck of the DDA block scene `scene`: dt given (--dt), the scene's
    [simulation] dt, or the in-house critical step; SceneError when duration / dt passes the step limit
    (`max_steps`, the --max-steps value, else the scene's; dda/limits.py)."""
    duration = float(duration if duration is not None else scene.duration)
    kw = dict(max_steps=max_steps, scene=scene,
              duration_key="--duration" if duration != scene.duration else "simulation.duration")
    if dt is not None or scene.dt is not None:
        key = "--dt" if dt is not None else "simulation.dt"
        dt = float(dt if dt is not None else scene.dt)
        if dt > 0 and duration > 0:
            check(scene_path, duration, dt, dt_key=key, dt_value=dt, auto_dt=False, **kw)
        return dt, duration
    _, sim = scene.build(check=False)
    if duration > 0:
        key, value = block_dt_source(scene)
        check(scene_path, duration, sim.dt, dt_key=key, dt_value=value, auto_dt=True, dt_crit=sim.dt_crit,
              safety=scene.safety, **kw)
    return sim.dt, duration


def write_polyhedra_deck(scene_path, folder, *, dt=None, duration=None, record_every=None, young=None, scene=None,
                         max_steps=None):
    """Write the polyhedra deck of a DDA block scene into `folder`; returns the extra deck.json keys.
    `dt`, `duration`, `record_every`, `young` override the scene's values (young: the YADE PolyhedraMat
    modulus, default from [contact] kn as in the module docstring). `scene`: the DDAScene of `scene_path` when
    already loaded; `max_steps`: the step limit (polyhedra_steps)."""
    scene_path = Path(scene_path)
    scene = scene if scene is not None else _load_scene(scene_path)
    if scene.spheres:
        raise SceneError(scene_path, "spheres", scene.spheres.get("path"),
                         "a polyhedra deck takes blocks only (use the sphere deck for [spheres])")
    if not scene.blocks:
        raise SceneError(scene_path, "block", None, "a polyhedra deck needs blocks")
    for k, spec in enumerate(scene.blocks):
        if getattr(spec, "prescribed", False):
            raise SceneError(scene_path, f"{scene.sources[k]}.prescribed", True,
                             "prescribed blocks are not supported by the YADE polyhedra deck")
        if np.any(np.asarray(getattr(spec, "body_force", (0, 0, 0))) != 0):
            raise SceneError(scene_path, f"{scene.sources[k]}.force", list(spec.body_force),
                             "body loads are not supported by the YADE polyhedra deck")
    if scene.loads:
        raise SceneError(scene_path, "load", len(scene.loads), "point loads are not supported by the YADE "
                                                                "polyhedra deck")
    folder = Path(folder)
    law = scene.law
    ks = law.kn / 2 if law.ks is None else law.ks
    free = [b for b in scene.blocks if not b.fixed]
    vols = [mass_properties(b.vertices, b.faces).volume for b in (free or scene.blocks)]
    L = float(np.mean(vols)) ** (1.0 / 3.0)
    E = float(young) if young is not None else 2.0 * law.kn / L ** 2
    nu = ks * L ** 2 / law.kn if young is None else ks / law.kn
    dt, duration = polyhedra_steps(scene, scene_path, dt, duration, max_steps)
    dt = float(dt)
    record_every = float(record_every if record_every is not None else scene.record_every)
    if not (dt > 0 and math.isfinite(dt) and duration > 0 and record_every > 0):
        raise SceneError(scene_path, "simulation", {"dt": dt, "duration": duration}, "dt, duration and "
                                                                                     "record_every must be > 0")
    folder.mkdir(parents=True, exist_ok=True)  # after the checks: a refused deck leaves no folder
    steps = max(1, int(round(duration / dt)))
    rec = max(1, int(round(record_every / dt)))
    verts = [np.asarray(b.vertices, float) for b in scene.blocks]
    start = np.r_[0, np.cumsum([len(v) for v in verts])].astype(np.int64)
    dens = [float((scene.materials.get(b.material).density if b.material in scene.materials else 2600.0))
            for b in scene.blocks]
    np.savez(folder / "blocks.npz", vertices=np.concatenate(verts), vert_start=start,
             fixed=np.array([bool(b.fixed) for b in scene.blocks]), density=np.array(dens),
             velocity=np.array([b.velocity for b in scene.blocks], float).reshape(-1, 3),
             angular_velocity=np.array([b.angular_velocity for b in scene.blocks], float).reshape(-1, 3),
             names=np.array([b.name or f"block_{k}" for k, b in enumerate(scene.blocks)]))
    approx = list(APPROXIMATIONS)
    if any(int(getattr(b, "dof", 6)) == 12 for b in scene.blocks):
        approx.append("deformable blocks (dof 12) run rigid")
    if getattr(scene, "model", None) is not None:  # an sgim scene's block model (dda/georun.py)
        approx.append("the face-kind laws (joint, intact rock, fault: [blocks], [[blocks.law]]) are not carried "
                      "over: every contact uses [blocks] kn, ks and the intact friction, without cohesion")
    if scene.pair_laws:
        approx.append("[[contact_pair]] laws are not carried over: every contact uses [contact]")
    if law.damping > 0:
        approx.append(f"[contact] damping = {law.damping:g} ignored")
    cfg = {"young": E, "poisson": nu, "friction_deg": float(law.friction_deg), "gravity": list(map(float,
           scene.gravity)), "local_damping": float(scene.local_damping), "dt": dt, "steps": steps,
           "record_steps": rec, "duration": duration, "length_scale": L, "kn": float(law.kn), "ks": float(ks),
           "scene": str(scene_path), "name": scene.name, "approximations": approx}
    (folder / "poly.json").write_text(json.dumps(cfg, indent=1))
    shutil.copyfile(SCRIPT, folder / "script.py")
    return {"files": ["blocks.npz", "poly.json", "script.py"], "n": len(scene.blocks), "steps": steps, "dt": dt,
            "record_steps": rec, "yade_polyhedra": {"young": E, "poisson": nu, "length_scale": L},
            "approximations": approx}


def _load_scene(scene_path):
    """The DDAScene of a DDA block scene, or of an sgim scene's block model (dda/georun.py: cut into blocks, the
    domain's side and bottom blocks fixed, [blocks.run] the run settings)."""
    # lazy: dda.scene and dda.georun load numba (this module stays light for the registry)
    from dda.georun import is_sgim_scene, load_geo_scene
    from dda.scene import load_scene

    return load_geo_scene(scene_path) if is_sgim_scene(scene_path) else load_scene(scene_path)


def prepare_deck(scene_path, overrides=None, max_steps=None):
    """The registry's check before the deck folder is made (adapters/registry.py): the DDA scene read, and the
    deck's dt and duration (`overrides` duration, dt, record_every; polyhedra_steps refuses a run past the step
    limit). Returns (scene, keywords of write_polyhedra_deck)."""
    scene = _load_scene(scene_path)
    ov = {k: v for k, v in (overrides or {}).items() if k in ("duration", "dt", "record_every") and v is not None}
    ov["dt"], ov["duration"] = polyhedra_steps(scene, scene_path, ov.get("dt"), ov.get("duration"), max_steps)
    return scene, ov


def export_deck(scene_path, folder, prepared):
    """The registry's deck writer: write_polyhedra_deck with what prepare_deck found."""
    scene, ov = prepared
    return write_polyhedra_deck(scene_path, folder, **ov, scene=scene)


def check_deck(deck):
    """The registry's deck reader: check_polyhedra_deck (nothing returned: a block deck has no SphereRun)."""
    check_polyhedra_deck(deck)


def check_polyhedra_deck(folder):
    """(poly.json dict, blocks.npz arrays) of a polyhedra deck, validated before YADE starts (the keys and arrays
    yade_poly_script.py reads): BadFile naming the file and the first defect."""
    folder = Path(folder)
    path = folder / "poly.json"
    F = Fields(path, read_json(path, "a poly.json"))
    cfg = {"young": F.number("young", positive=True), "poisson": F.number("poisson", nonneg=True),
           "friction_deg": F.number("friction_deg", lo=0, hi=90), "gravity": F.vector("gravity", 3),
           "local_damping": F.number("local_damping", lo=0, hi=1), "dt": F.number("dt", positive=True),
           "steps": F.number("steps", integer=True, lo=1), "record_steps": F.number("record_steps", integer=True, lo=1),
           "approximations": F.strings("approximations", [])}
    cfg = {**F.doc, **cfg}
    path = folder / "blocks.npz"
    A = Arrays(path, read_npz(path, "a blocks.npz"), "a blocks.npz")
    A.missing(("vertices", "vert_start", "fixed", "density", "velocity", "angular_velocity", "names"))
    fixed = A.boolean("fixed", (None,))
    nb = len(fixed)
    if nb == 0:
        A.fail("fixed: the deck has no blocks")
    one = "one per block of fixed"
    verts = A.real("vertices", (None, 3))
    start = A.integer("vert_start", (nb + 1,), lo=0, hi=len(verts) + 1, per="one more than the blocks")
    few = np.diff(start) < 4
    if start[0] != 0 or start[-1] != len(verts) or few.any():
        A.fail(f"vert_start = {start.tolist()[:8]}: must rise from 0 to {len(verts)} by at least 4 vertices a block")
    b = {"vertices": verts, "vert_start": start, "fixed": fixed,
         "density": A.real("density", (nb,), positive=True, per=one),
         "velocity": A.real("velocity", (nb, 3), per=one),
         "angular_velocity": A.real("angular_velocity", (nb, 3), per=one),
         "names": np.asarray(A.strings("names", (nb,), per=one))}
    return cfg, b


def _load(path, keys=()):
    return load_output(path, keys, engine="yade-polyhedra")


def _result(folder, out, outcome, np_):
    cfg, b = check_polyhedra_deck(folder)
    nb = len(b["fixed"])
    extra = {"approximations": cfg["approximations"], "names": b["names"].tolist(),
             "fixed": b["fixed"].tolist(), "young": cfg["young"], "poisson": cfg["poisson"],
             "threads": int(np_), "log": str(out / "yade-polyhedra.log")}
    s = _load(out / "yade_series.npz", ("time", "pos", "kinetic")) if (out / "yade_series.npz").exists() else None
    t = np.asarray(s["time"], float) if s else np.zeros(0)
    pos = np.asarray(s["pos"], float).reshape(-1, nb, 3) if s else None
    ser = {"kinetic": np.asarray(s["kinetic"], float)} if s else {}
    x0 = pos[0].copy() if pos is not None and len(pos) else np.full((nb, 3), np.nan)
    final = out / "yade_final.npz"
    if outcome.ok and final.exists():
        f = _load(final, ("wall_run", "final_pos", "final_vel", "steps"))
        extra["wall_run_s"] = float(f["wall_run"])
        return RunResult(engine="yade-polyhedra", x0=x0, final_pos=f["final_pos"], final_vel=f["final_vel"],
                         bond_intact=np.zeros(0, bool), time=t, pos=pos, series=ser, status=COMPLETE,
                         steps=int(f["steps"]), dt=cfg["dt"], wall_s=outcome.wall_s, extra=extra)
    fp = pos[-1].copy() if pos is not None and len(pos) else x0.copy()
    return RunResult(engine="yade-polyhedra", x0=x0, final_pos=fp, final_vel=np.zeros_like(fp),
                     bond_intact=np.zeros(0, bool), time=t, pos=pos, series=ser, status=INCOMPLETE,
                     steps=int(round(t[-1] / cfg["dt"])) if len(t) else 0, dt=cfg["dt"], wall_s=outcome.wall_s,
                     extra=extra)


def run_polyhedra_deck(folder, out, np=1, timeout=None, progress=None) -> RunResult:
    """Run a YADE polyhedra deck; returns the RunResult (also saved into `out`); EngineError on failure,
    with the partial result (marked incomplete, saved into `out`)."""
    exe = find_engine("yade")
    folder, out = Path(folder).resolve(), Path(out).resolve()
    for need in ("script.py", "blocks.npz", "poly.json"):
        if not (folder / need).exists():
            raise EngineError(f"yade-polyhedra: {folder}: not a YADE polyhedra deck (missing {need})")
    outcome, log = run_script(exe, folder, out, OUTPUTS, np=np, timeout=timeout, progress=progress,
                              tag="yade-polyhedra")
    return finish(_result(folder, out, outcome, np), "yade-polyhedra", outcome, log, out)


def main(argv=None):
    """``python -m adapters.yade_poly SCENE [--duration T] [--dt DT] [-o OUT]``: write the polyhedra deck of a
    DDA block scene, run it in YADE and print each free block's displacement."""
    ap = argparse.ArgumentParser(prog="python -m adapters.yade_poly", description=main.__doc__)
    ap.add_argument("scene")
    ap.add_argument("--duration", type=float)
    ap.add_argument("--dt", type=float)
    ap.add_argument("-o", "--out", help="folder for the deck (OUT/deck) and the result (OUT/result)")
    a = ap.parse_args(argv)
    base = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="yade_poly_"))
    try:
        info = write_polyhedra_deck(a.scene, base / "deck", duration=a.duration, dt=a.dt)
        res = run_polyhedra_deck(base / "deck", base / "result", progress=print)
    except (SceneError, EngineError) as exc:
        print(f"error: {exc}")
        return 2
    print(f"{info['steps']} steps of {info['dt']:.6g} s, young {info['yade_polyhedra']['young']:.6g}, "
          f"wall {res.wall_s:.2f} s, result in {base / 'result'}")
    for k, name in enumerate(res.extra["names"]):
        if not res.extra["fixed"][k]:
            d = res.final_pos[k] - res.x0[k]
            print(f"{name}: t = {res.time[-1]:.6g} s  displacement [{d[0]:.6g}, {d[1]:.6g}, {d[2]:.6g}] m  "
                  f"|d| = {np.linalg.norm(d):.6g} m")
    return 0


__all__ = ["write_polyhedra_deck", "run_polyhedra_deck", "check_polyhedra_deck", "polyhedra_steps", "prepare_deck",
           "export_deck", "check_deck"]

if __name__ == "__main__":
    raise SystemExit(main())
