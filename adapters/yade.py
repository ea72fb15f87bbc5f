"""YADE adapter: a bonded-sphere run (SphereRun) as a deck folder that ``yade -n -x`` runs headless.

Deck (written by ``write_deck(run, folder)``; the deck writer saves ``run.npz`` beside it)::

    DECK/run.npz     the SphereRun (arrays; no per-sphere code lines anywhere)
    DECK/script.py   adapters/yade_script.py, run on YADE's own Python (numpy + json + yade only)
    DECK/yade.json   deck settings: detection_factor (bonding-step detection, default 1.01, raised to
                     cover the bond list's widest gap, at most 1.2), record_positions (default: when
                     n x records <= 5e6), dump_bonds (write YADE's cohesive and smooth-joint pairs after the
                     bonding step to OUT/yade_bonds.npz); the keywords of write_deck

``run_deck(folder, out, np=1, timeout=None, progress=None)`` runs ``yade -n -f2 -x script.py DECK OUT``
(``-j np`` for OpenMP threads), surfaces YADE's error line (or the script's ``FATAL:`` line) as an EngineError
carrying the partial result (marked incomplete), and returns / saves the RunResult (engine "yade").

Model: JCFpm (JCFpmMat, Ip2_JCFpmMat_JCFpmMat_JCFpmPhys, Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM
with smoothJoint). JCFpm rather than CohFrict because it is the YADE law with a joint concept: a pair cut by a
zero-thickness joint becomes a smooth joint (normal force along the joint normal, sliding on the joint plane,
joint friction), which CohFrict cannot express; its bonds are per-pair normal/shear springs with force
limits, as the project's bond law. Bonds are created at the first step (detection enlarged by a factor
slightly above 1, then reset), and then the exact per-pair rule of the run is applied from Python to every
interaction: bond-list pairs keep a bond with their own kn, ks, tensile limit FnMax = bond_ft and shear limit
FsMax = bond_fs (inf: 1e300); joint pairs (SphereRun.joint_i/j, with smooth_joints) are unbonded and become
smooth joints with the run's per-pair normal (signed like the interaction normal id1 -> id2) and
joint_friction_deg (one normal per pair: no three-joint limit); every other interaction is unbonded (a plain
frictional contact). A bond-list pair without an interaction fails the run loudly.

Loads: a constant sphere force (run.force) is a permanent force (``O.forces.setPermF``: NewtonIntegrator adds
it to the weight every step); a prescribed sphere (run.prescribed) gets blockedDOFs xyzXYZ and state.vel =
run.velocity: YADE moves it at that velocity whatever the forces, and it does not turn (not counted in the
kinetic energy, as the in-house engine).

Unbonded contacts take kn, ks and friction from materials made per distinct radius with young = kn / r and
poisson = ks / kn, so that JCFpm's kn = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2) equals run.kn for every pair of radii
and ks = poisson kn equals run.ks (exact, also for unequal radii). Fixed spheres have blockedDOFs xyzXYZ;
gravity and Cundall's local damping by NewtonIntegrator (damping = run.local_damping); O.dt = run.dt.

Approximations (also listed in RunResult.extra["approximations"]):
- bond shear failure is Mohr-Coulomb in JCFpm: |Fs| > FsMax + Fn tan(friction) (Fn < 0 in tension lowers the
  limit), where the in-house law breaks at |Fs| > bond_fs;
- no viscous damping: neither at contacts (run.damping), nor on bonds (run.bond_zeta), nor on the spheres
  (run.viscous_damping);
- bonds carry no bending or twisting moment (the shear force gives the torque at the contact point);
- smooth joints exist for the model's joint pairs only (the pairs touching at the start). Interactions are
  kept while their spheres are apart (neverErase), so that a joint pair that opens stays a joint pair with its
  reference gap and pushes again as soon as it closes: the rule the in-house engine follows too
  (dda/_spheres.py ``_joints``). JCFpm switches a joint pair off once it slid 2 min(r_i, r_j) along the
  joint; the script erases it at the next record, and the two spheres meet later as a plain frictional
  contact (in-house: from the next step);
- a bond broken in shear under compression stays a frictional contact whose zero-force distance is the
  bond's rest distance (equal to touching for lattice packings).

Several YADE processes may run at once: each opens its local servers (TCP 9000+, XMLRPC 21000+) by trying
successive ports until a bind succeeds, so parallel runs do not clash.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from sgim.readback import Arrays, BadFile, Fields, read_json, read_npz

from . import joint_walls as jw

from .process import EngineError, describe_failure, find_engine, run_process, unbuffered
from .result import COMPLETE, INCOMPLETE, RunResult
from .spec import SpecError, SphereRun, liggghts_only

SCRIPT = Path(__file__).with_name("yade_script.py")
POS_LIMIT = 5_000_000  # record positions when n * records <= POS_LIMIT
OUTPUTS = ("yade_setup.json", "yade_series.npz", "yade_snapshot.npz", "yade_pos.bin", "yade_final.npz",
           "yade_bonds.npz")


def approximations(run: SphereRun):
    """What this deck cannot represent exactly: strings naming the scene key they concern (RunResult.extra)."""
    out = ["bond shear failure is Mohr-Coulomb in JCFpm: |Fs| > bond_fs + Fn tan(friction), Fn < 0 in tension",
           "bonds carry no bending or twisting moment"] + liggghts_only(run)
    zeta = np.asarray(run.bond_zeta, float)
    if np.any(zeta > 0):
        out.append(f"spheres.bond_damping = {float(zeta.max()):g} not represented: JCFpm bonds have no viscous "
                   "damping (the bonds run undamped)")
    if run.damping > 0:
        out.append(f"contact.damping = {run.damping:g} not represented: JCFpm has no viscous contact damping")
    if run.viscous_damping > 0:
        out.append(f"simulation.viscous_damping (c = {run.viscous_damping:g} N s/m on every sphere) not "
                   "represented: YADE's NewtonIntegrator has Cundall's local damping only "
                   "(simulation.local_damping)")
    if run.smooth_joints and len(run.joint_i):
        out.append("a smooth joint slid 2 min(r) along the joint is switched off at once, and erased (a plain "
                   "contact from then on) at the next record; in-house it is a plain contact from the next step")
    planes = jw.wall_planes(run)
    out += jw.notes(run, "a YADE facet (Ig2_Facet_Sphere_ScGeom, the JCFpm law at the run's kn and ks)", planes)
    if planes and run.joint_friction_deg > run.friction_deg:
        out.append(f"spheres.joint_friction = {run.joint_friction_deg:g} deg on the joint walls is "
                   f"{run.friction_deg:g} deg (contact.friction): JCFpm's Ip2 takes the smaller friction angle of "
                   "the two materials")
    if planes and np.ptp(np.asarray(run.radii, float)[~jw.dropped(run, planes)]) > 0:
        out.append("a joint wall's facet stiffness is exact for the mean radius r of the free spheres of its pairs "
                   "(JCFpm's Ip2 counts a facet as a sphere of twice the sphere's radius): a sphere of radius r' "
                   "touches it with kn 2 r' / (r + r')")
    return out


def wall_facets(run, planes):
    """(triangles (walls, 3, 3), young (walls,)) of the joint walls (adapters/joint_walls.py) as YADE facets:
    one triangle per wall holding its rectangle (two facets would give a sphere on their shared edge two
    contacts), counter-clockwise about the wall normal; young = kn / (2 r) of the mean radius r of the free
    spheres of its pairs, so that JCFpm's kn of the facet (taken as a sphere of radius 2 r) and a sphere of
    young kn / r is run.kn."""
    q = jw.wall_rectangles(run, planes)
    tri = np.stack([q[:, 0] - 0.5 * (q[:, 1] - q[:, 0]), q[:, 1] + 0.5 * (q[:, 1] - q[:, 0]),
                    0.5 * (q[:, 2] + q[:, 3]) + (q[:, 3] - q[:, 0])], axis=1)
    mid = tri.mean(axis=1, keepdims=True)
    tri = mid + 1.001 * (tri - mid)  # the rectangle's corners strictly inside
    fixed = np.asarray(run.fixed, bool)
    young = []
    for p in planes:
        k = (np.asarray(run.joint_disc) == p["disc"]) & (fixed[run.joint_i] != fixed[run.joint_j])
        free = np.where(fixed[run.joint_i[k]], run.joint_j[k], run.joint_i[k])
        young.append(run.kn / (2.0 * float(np.mean(np.asarray(run.radii, float)[free]))))
    return tri, np.asarray(young)


def write_deck(run: SphereRun, folder, *, dump_bonds=False, detection_factor=1.01, record_positions=None):
    """Write script.py and yade.json into `folder` (and run.npz when the caller has not); returns the extra
    deck.json keys."""
    folder = Path(folder)
    if run.n == 0:
        raise SpecError(f"{run.source or run.name}: the model has no spheres")
    if not (np.isfinite(detection_factor) and 1.0 < detection_factor < 1.2):
        raise ValueError(f"detection_factor must be in (1, 1.2) (got {detection_factor!r})")
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "run.npz").exists():
        run.save(folder / "run.npz")
    records = run.steps // run.record_steps + 1
    if record_positions is None:
        record_positions = run.n * records <= POS_LIMIT
    shutil.copyfile(SCRIPT, folder / "script.py")
    planes = jw.wall_planes(run)  # run.extra joint_walls: the fixed sides of joints as facets
    cfg = {"detection_factor": float(detection_factor), "record_positions": bool(record_positions),
           "dump_bonds": bool(dump_bonds), "joint_walls": len(planes)}
    files = ["run.npz", "script.py", "yade.json"]
    if planes:
        jw.only_nearest(run, "YADE")
        tri, young = wall_facets(run, planes)
        np.savez(folder / "walls.npz", triangles=tri, young=young, dropped=jw.dropped(run, planes))
        files.append("walls.npz")
    (folder / "yade.json").write_text(json.dumps(cfg, indent=1))
    return {"files": files, "yade": cfg, "joint_walls": len(planes), "approximations": approximations(run)}


def export_deck(run: SphereRun, folder, variant=None):
    """The deck writer of the registry (adapters/registry.py): write_deck with its defaults (one variant, JCFpm)."""
    return write_deck(run, folder)


def check_deck(deck):
    """The deck reader of the registry: the deck's run.npz and yade.json read back and checked (BadFile for a
    broken file) before YADE starts; returns the SphereRun."""
    run = SphereRun.load(Path(deck) / "run.npz")
    cfg = read_config(Path(deck) / "yade.json")
    if cfg.get("joint_walls", 0):  # the facets of run.extra joint_walls, as the script reads them
        path = Path(deck) / "walls.npz"
        if not path.is_file():
            raise BadFile(path, "missing: the deck's joint walls (run.extra joint_walls), written by `adapters export`")
        A = Arrays(path, read_npz(path, "a walls.npz"), "a walls.npz")
        A.missing(["triangles", "young", "dropped"])
        A.real("triangles", (cfg["joint_walls"], 3, 3))
        A.real("young", (cfg["joint_walls"],), positive=True)
        A.boolean("dropped", (run.n,), per="one per sphere of run.npz")
    return run


def read_config(path):
    """yade.json of a YADE sphere deck (the keys yade_script.py reads), validated: BadFile for a broken file."""
    F = Fields(path, read_json(path, "a yade.json"))
    if "detection_factor" in F.doc:
        F.number("detection_factor", lo=1.0, hi=1.2)
    if "max_detection_factor" in F.doc:
        F.number("max_detection_factor", lo=1.0, hi=1.2)
    F.boolean("record_positions", True)
    F.boolean("dump_bonds", False)
    if "joint_walls" in F.doc:
        F.number("joint_walls", nonneg=True, integer=True)
    return F.doc


def load_output(path, keys=(), engine="yade"):
    """The arrays of an npz the YADE script wrote; a broken one (or one without `keys`) is an EngineError."""
    try:
        arrays = read_npz(path, "an npz written by the YADE script")
    except BadFile as exc:
        raise EngineError(f"{engine}: {exc}") from None
    gone = [k for k in keys if k not in arrays]
    if gone:
        raise EngineError(f"{engine}: {path}: missing array(s) {', '.join(gone)} (not written by the YADE script)")
    return arrays


def _result(folder, out, outcome, np_):
    """RunResult from what the script wrote into `out` (complete when yade_final.npz is there and the
    process ended well)."""
    run = SphereRun.load(folder / "run.npz")
    n, m = run.n, run.n_bonds
    x0 = np.asarray(run.centers, float)
    series = load_output(out / "yade_series.npz", ("time", "kinetic", "bonds_intact")) \
        if (out / "yade_series.npz").exists() else None
    t = np.asarray(series["time"], float) if series else np.zeros(0)
    ser = {"kinetic": np.asarray(series["kinetic"], float),
           "bonds_intact": np.asarray(series["bonds_intact"], np.int64)} if series else {}
    pos = None
    pb = out / "yade_pos.bin"
    if pb.exists() and n:
        raw = np.fromfile(pb, "<f8")
        r = min(len(t), raw.size // (3 * n))
        pos = raw[:r * 3 * n].reshape(r, n, 3)
        t = t[:r] if pos is not None and len(t) > r else t
        ser = {k: v[:len(t)] for k, v in ser.items()}
    setup = {}
    if (out / "yade_setup.json").exists():
        try:
            setup = read_json(out / "yade_setup.json", "a yade_setup.json")
        except BadFile as exc:
            raise EngineError(f"yade: {exc}") from None
    extra = {"approximations": approximations(run), "setup": setup, "threads": int(np_),
             "log": str(out / "yade.log")}
    final = out / "yade_final.npz"
    if outcome.ok and final.exists():
        f = load_output(final, ("wall_run", "tens_cracks", "shear_cracks", "final_pos", "final_vel", "bond_intact",
                                "steps"))
        extra["wall_run_s"] = float(f["wall_run"])
        extra["cracks"] = {"tension": int(f["tens_cracks"]), "shear": int(f["shear_cracks"])}
        return RunResult(engine="yade", x0=x0, final_pos=f["final_pos"], final_vel=f["final_vel"],
                         bond_intact=f["bond_intact"].astype(bool), time=t, pos=pos, series=ser, status=COMPLETE,
                         steps=int(f["steps"]), dt=run.dt, wall_s=outcome.wall_s, extra=extra)
    # incomplete: the last snapshot (or the last recorded positions, or the initial state)
    fp, fv, bi, steps = x0.copy(), np.zeros_like(x0), np.ones(m, bool), 0
    snap = out / "yade_snapshot.npz"
    if snap.exists():
        s = load_output(snap, ("pos", "vel", "bond_intact", "steps"))
        fp, fv, bi, steps = s["pos"], s["vel"], s["bond_intact"].astype(bool), int(s["steps"])
        extra["final_from"] = f"snapshot at step {steps}"
    if pos is not None and len(pos) and len(t) and t[-1] > steps * run.dt:
        fp, steps = pos[-1].copy(), int(round(t[-1] / run.dt))
        extra["final_from"] = f"record at step {steps} (velocities and bond states from the last snapshot)"
    return RunResult(engine="yade", x0=x0, final_pos=fp, final_vel=fv, bond_intact=bi, time=t, pos=pos,
                     series=ser, status=INCOMPLETE, steps=steps, dt=run.dt, wall_s=outcome.wall_s, extra=extra)


def _on_line(progress, tag="yade"):
    if progress is None:
        return None

    def cb(line):
        if line.startswith("PROGRESS "):
            progress(f"{tag}: " + line[len("PROGRESS "):])
    return cb


def run_script(exe, folder, out, outputs, np=1, timeout=None, progress=None, tag="yade"):
    """Run ``yade -n -f2 [-j np] -x DECK/script.py DECK OUT`` (output files of an earlier run removed first);
    returns (ProcessOutcome, log path). -f2: YADE's own logging shows errors only (CGAL polyhedra runs
    otherwise print hundreds of thousands of warning lines)."""
    out.mkdir(parents=True, exist_ok=True)
    for name in outputs:
        (out / name).unlink(missing_ok=True)
    cmd = [exe, "-n", "-f2"] + (["-j", str(int(np))] if int(np) > 1 else []) + \
          ["-x", str(folder / "script.py"), str(folder), str(out)]
    log = out / f"{tag}.log"
    outcome = run_process(unbuffered(cmd), cwd=out, log=log, timeout=timeout, on_line=_on_line(progress, tag))
    return outcome, log


def run_deck(folder, out, np=1, timeout=None, progress=None) -> RunResult:
    """Run a YADE sphere deck; returns the RunResult (also saved into `out`). EngineError on failure (with
    the partial result, marked incomplete and saved into `out`)."""
    exe = find_engine("yade")
    folder, out = Path(folder).resolve(), Path(out).resolve()
    for need in ("script.py", "run.npz", "yade.json"):
        if not (folder / need).exists():
            raise EngineError(f"yade: {folder}: not a YADE sphere deck (missing {need})")
    outcome, log = run_script(exe, folder, out, OUTPUTS, np=np, timeout=timeout, progress=progress)
    return finish(_result(folder, out, outcome, np), "yade", outcome, log, out)


def finish(res, engine, outcome, log, out):
    """Save the RunResult `res` of a YADE run into `out` and return it; an incomplete one (the engine failed,
    or its script ended without its final results) is saved and raised as an EngineError."""
    if not res.complete:
        res.message = describe_failure(engine, outcome, log) if not outcome.ok else \
            f"{engine}: the script ended without writing its final results (log {log})"
        res.save(out)
        raise EngineError(res.message, result=res)
    res.save(out)
    return res


__all__ = ["write_deck", "export_deck", "check_deck", "read_config", "run_deck", "run_script", "finish", "load_output",
           "approximations"]
