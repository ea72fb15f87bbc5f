"""Cross-validation: the same models in-house, in YADE and in LIGGGHTS, against analytical references.

    cases crossval [--cases hang,column,rocking,beam,wedge,planar,blocks,shear_beam] [--engines dda,yade,liggghts]
                   [--json] [--keep DIR]

Each case runs one model (cases/scenes/crossval/*.toml, written by cases/make/crossval.py) in every engine through the
adapters (``adapters.deck.export`` + ``adapters.deck.run``; the in-house engine through ``adapters.inhouse``)
and compares it with a reference computed here, independently of every engine:

- hang_*: which spheres detach when a bonded block hangs from its top layer. Reference: the spheres that no path
  of the model's bonds ties to a fixed sphere (connected components of the bond graph). Result: the spheres that
  moved more than half a radius. Error: the number of spheres whose state differs (0: identical sets).
- column: the static elongation of a hanging column of bonded FCC spheres with central-spring bonds.
  Reference: the linear static solution of the same spring network (sparse stiffness K = sum k n n^T over the
  bonds, load m g, top fixed), mean over the bottom layer. (The column is three spheres wide: its surface
  spheres have fewer bonds, so a continuum modulus of the FCC lattice would not describe it.)
- wedge: the joint friction angle at which the sphere wedge on two smooth joints starts to slide (bisection on
  the joint friction; a trial slides when the wedge has not come to rest: its displacement along the line of
  intersection grew in the last quarter of the run; the free spheres that fewer than three bonds hold are left
  out, they swing for ever). Reference: Hoek & Bray's critical friction (dda.hoekbray); the DDA block wedge
  (dda.wedge) is a row. LIGGGHTS-PUBLIC, which has no smooth joint, runs the wedge on mesh walls in place of the
  fixed rock, as one rigid clump, with fix viscous (liggghts_wedge, adapters/liggghts_walls.py). wedge_walls: the
  same bisection in-house and in YADE with the rock below each joint as a joint wall (run.extra joint_walls =
  "nearest", adapters/joint_walls.py: an in-house slab, a YADE facet; walled_wedge). `python -m cases.bench.wedge`
  gives the error and cost against the sphere radius.
- planar: a bonded block of FCC spheres (r = 0.05) on one smooth joint dipping psi = 35 deg, the rock below it
  fixed, no cohesion, no water: the joint friction at which it starts to slide down the dip, by the same bisection
  (sliding_onset: the onset machinery takes the case's run, its sliding direction and reference angle, a Sliding).
  Reference: Hoek & Bray's planar sliding, FS = tan phi / tan psi, so tan phi_c = tan psi. LIGGGHTS runs it as the
  wedge (mesh wall, rigid clump, fix viscous), its wall contacts damped at PLANAR_LIGGGHTS_DAMPING of critical.
- rocking: a block cut by a horizontal smooth joint rocks under a sideways push at its top; the heel of the
  joint opens in the first swing and closes again, local damping brings it to rest. In-house and YADE only (no
  smooth joint in LIGGGHTS-PUBLIC), each against the other: the upper part's mean vertical displacement at the
  end (the joint's closure, which remembers where each reopened pair closed), and the joint pairs open at every
  record must be the same. Reference: the YADE run (the engines share the rule that a joint pair keeps its
  reference gap while open; re-formed at a new gap, the in-house closure differed by 2.3 %).
- beam: a 1.2 m FCC cantilever cut by a vertical joint through lattice centres at x = 0.6: the spheres beyond
  it fall (reference: the bond graph, as hang_*; LIGGGHTS, which has no smooth joint, runs it with [spheres]
  liggghts_joints = "open": no contact across the joint; the note gives how far joint pairs closed along the joint
  normal, where a smooth joint would have pushed), and the intact cantilever damped from its scene alone
  (viscous_damping = "critical": LIGGGHTS' fix viscous, in-house a force -c v; YADE has no such damping)
  against the static solution of its spring network (tip sag).
- shear_beam: a simple-cubic cantilever of normal + shear bonds (a mechanism with central bonds alone) against the
  linear static solution of its network with six degrees of freedom per sphere (cases/lib/crossval_shear.py).
- incline, block_wedge: a polyhedral block on a 30 degree incline (friction 20) and the paper's wedge at
  friction 18 degrees: distance slid in 1 s, in-house DDA and YADE Polyhedra, against s = 1/2 a t^2 with
  a = g (sin a - tan phi cos a) and a = g sin psi5 (1 - tan phi / tan phi_c).

The table: case, engine, result, reference, error, wall time, and a note where an engine cannot meet the
reference (the reason is in the note and in docs/ARCHITECTURE.md).
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
import tomllib
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from cases import SCENES
from cases.make.crossval import PLANAR, WEDGE, planar_normal

# The engines (adapters, dda, scipy) are imported inside the functions that use them: `cases crossval --help`
# and the evaluators that use a reference of this module (detached_reference) load no engine they do not run.

CV = SCENES / "crossval"
ENGINES = ("dda", "yade", "liggghts")
CASES = ("hang", "column", "rocking", "beam", "wedge", "planar", "blocks", "shear_beam")
SETTLE_TOLERANCE = 1e-3  # the damped beam against its static sag: 0.1 %
ROCKING_TOLERANCE = 1e-3  # in-house against YADE: 0.1 %
HANG = ("intact", "fault", "joint", "small_joint")
G = 9.81
# the agreement the table checks (issue 16): static results 1 %, onset angles 0.5 %; a distance slid in a given
# time (incline, block_wedge) is neither: 2 % (YADE Polyhedra keeps its shear history per law: +1.05 %)
STATIC_TOLERANCE = 0.01
ONSET_TOLERANCE = 0.005
SLIDE_TOLERANCE = 0.02
WEDGE_REST = 1e-4  # a wedge trial that moves less than this many radii in its last quarter has come to rest
WEDGE_LIGGGHTS_TAU = 0.1  # [s] the LIGGGHTS wedge's fix viscous: gamma = sphere mass / tau (liggghts_wedge)
WEDGE_WALL_T = 2.4  # [s] a trial of the wedge on joint walls (walled_wedge): it settles onto them for about 1.5 s
# the LIGGGHTS planar block's wall contacts: normal damping, a ratio of critical (planar_sliding). The clump lands on
# the wall with its normal springs unloaded and bounces; at every unloading friction lets it slip, so undamped
# (fix viscous alone) it crept down at 1.005 x psi as fast as at 0.995 x
PLANAR_LIGGGHTS_DAMPING = 0.3


@dataclass
class Row:
    case: str
    engine: str
    result: str
    reference: str
    error: str
    ok: bool | None
    wall_s: float
    note: str = ""
    value: float | None = None
    ref_value: float | None = None
    err_value: float | None = None


# -- references (independent of every engine) ----------------------------------------------------------
def detached_reference(run):
    """Spheres that no bond path ties to a fixed sphere (bool mask)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = run.n
    g = coo_matrix((np.ones(run.n_bonds), (run.bond_i, run.bond_j)), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    held = np.zeros(lab.max() + 1, bool)
    held[lab[run.fixed]] = True
    return ~held[lab]


def static_displacement(run):
    """Static displacement (n, 3) of the bond network under gravity (bonds as central springs, fixed spheres
    held): the sparse linear solve of K u = m g."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    n = run.n
    i, j = run.bond_i, run.bond_j
    d = run.centers[j] - run.centers[i]
    e = d / np.linalg.norm(d, axis=1)[:, None]
    blocks = run.bond_kn[:, None, None] * e[:, :, None] * e[:, None, :]  # (m, 3, 3)
    rows, cols, vals = [], [], []
    for a, b, s in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
        for p in range(3):
            for q in range(3):
                rows.append(3 * a + p)
                cols.append(3 * b + q)
                vals.append(s * blocks[:, p, q])
    K = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))
    K = K.tocsr()
    mass = run.density * 4.0 / 3.0 * np.pi * run.radii ** 3
    f = (mass[:, None] * run.gravity[None, :]).ravel()
    free = np.repeat(~run.fixed, 3)
    u = np.zeros(3 * n)
    u[free] = spsolve(K[free][:, free].tocsc(), f[free])
    return u.reshape(n, 3)


def wedge_reference(w):
    from dda.hoekbray import wedge_fs

    return wedge_fs(w["joint_a"], w["joint_b"], w["face"], height=w["height"], friction=30.0)


# -- engines ---------------------------------------------------------------------------------------------
def run_engine(engine, source, work, timeout=None, run=None, variant=None):
    """RunResult of `source` (a DDA scene or run.npz) in `engine`; `run` (a SphereRun) for the in-house engine;
    `variant`: the deck variant (None: the engine's default)."""
    from adapters.deck import export
    from adapters.deck import run as run_deck

    if engine == "dda":
        from adapters.inhouse import run_inhouse
        from adapters.spec import from_scene

        return run_inhouse(run if run is not None else from_scene(source))
    deck = Path(work) / engine
    # a deck of an earlier run (--keep): replaced, nothing else is
    export(source, engine, deck, variant=variant, force=True)
    return run_deck(deck, out=deck / "result", timeout=timeout)


def _available(engine):
    from adapters.process import EngineError, find_engine

    if engine == "dda":
        return True
    try:
        find_engine(engine)
        return True
    except EngineError:
        return False


# -- cases -----------------------------------------------------------------------------------------------
def case_hang(engines, work, say, timeout):
    from adapters.spec import from_scene

    rows = []
    for var in HANG:
        path = CV / f"hang_{var}.toml"
        run = from_scene(path)
        ref = detached_reference(run)
        for eng in engines:
            t0 = time.perf_counter()
            res = run_engine(eng, path, Path(work) / f"hang_{var}", timeout, run=run)
            got = res.moved(0.5 * float(run.radii.min()))
            diff = int(np.sum(got != ref))
            rows.append(Row(f"hang_{var}", eng, f"{int(got.sum())} detached", f"{int(ref.sum())} (bond graph)",
                            f"{diff} differ", diff == 0, time.perf_counter() - t0, value=float(got.sum()),
                            ref_value=float(ref.sum()), err_value=float(diff)))
            if say:
                say(_line(rows[-1]))
    return rows


def case_column(engines, work, say, timeout):
    from adapters.spec import from_scene

    path = CV / "column.toml"
    run = from_scene(path)
    u = static_displacement(run)
    bottom = run.centers[:, 2] < run.centers[:, 2].min() + 0.5 * run.radii.min()
    ref = float(-u[bottom, 2].mean())
    # LIGGGHTS has no local damping: fix viscous, critical for the column's first mode (Rayleigh quotient of
    # the static deflection shape) brings it to rest in a few periods
    mass = run.density * 4.0 / 3.0 * np.pi * run.radii ** 3
    omega1 = math.sqrt(float(np.sum(mass * (u @ run.gravity))) / float(np.sum(mass * np.sum(u * u, axis=1))))
    run.extra["liggghts_viscous"] = 2.0 * float(mass.mean()) * omega1
    wk = Path(work) / "column"
    wk.mkdir(parents=True, exist_ok=True)
    run.save(wk / "run.npz")
    rows = []
    for eng in engines:
        t0 = time.perf_counter()
        res = run_engine(eng, wk / "run.npz", wk, timeout, run=run)
        got = float(-res.displacement()[bottom, 2].mean())
        err = got / ref - 1.0
        rows.append(Row("column", eng, f"{got * 1e6:.3f} um", f"{ref * 1e6:.3f} um (static network)",
                        f"{100 * err:+.2f} %", abs(err) <= STATIC_TOLERANCE, time.perf_counter() - t0,
                        value=got, ref_value=ref, err_value=err))
        if say:
            say(_line(rows[-1]))
    return rows


def joint_open(run, pos):
    """(records, joint pairs) bool: the pair's gap along the joint normal is wider than at the start (D < 0)."""
    i, j, n = run.joint_i, run.joint_j, run.joint_normal
    d0 = np.abs(np.einsum("ij,ij->i", run.centers[j] - run.centers[i], n))
    return np.array([np.abs(np.einsum("ij,ij->i", p[j] - p[i], n)) > d0 for p in pos]).reshape(len(pos), len(i))


def case_rocking(engines, work, say, timeout):
    """The rocking block on a smooth joint: in-house against YADE (the joint opens and closes again)."""
    from adapters.spec import from_scene

    path = CV / "rocking.toml"
    run = from_scene(path)
    z_joint = 0.07  # cases/make/crossval.py ROCKING_JOINT
    upper = ~run.fixed & (run.centers[:, 2] > z_joint)
    out = {}
    for eng in [e for e in engines if e in ("dda", "yade")]:
        t0 = time.perf_counter()
        res = run_engine(eng, path, Path(work) / "rocking", timeout, run=run)
        if res.pos is None or len(res.pos) < 3:
            raise RuntimeError(f"{eng}: the rocking run recorded no positions")
        opened = joint_open(run, res.pos)
        out[eng] = (float(res.displacement()[upper, 2].mean()), opened, time.perf_counter() - t0)
    rows = []
    ref = out.get("yade")
    for eng, (got, opened, wall) in out.items():
        cycle = f"{int(opened.any(axis=1).sum())} records open, {int(opened[-1].sum())} open at the end"
        if ref is None or eng == "yade":
            rows.append(Row("rocking", eng, f"{got * 1e6:.4f} um", "-", "-", None, wall, note=cycle, value=got))
        else:
            err = got / ref[0] - 1.0
            same = bool(np.array_equal(opened, ref[1]))
            ok = abs(err) <= ROCKING_TOLERANCE and same and opened.any() and not opened[-1].any()
            note = cycle + ("" if same else "; open pairs differ from YADE's")
            rows.append(Row("rocking", eng, f"{got * 1e6:.4f} um", f"{ref[0] * 1e6:.4f} um (YADE)",
                            f"{100 * err:+.3f} %", ok, wall, note=note, value=got, ref_value=ref[0], err_value=err))
        if say:
            say(_line(rows[-1]))
    return rows


def case_beam(engines, work, say, timeout):
    """The jointed beam's detached spheres in every engine; the damped intact beam's sag in LIGGGHTS."""
    from adapters.spec import from_scene

    rows = []
    path = CV / "beam_joint.toml"
    run = from_scene(path)
    ref = detached_reference(run)
    for eng in engines:
        t0 = time.perf_counter()
        res = run_engine(eng, path, Path(work) / "beam_joint", timeout, run=run)
        got = res.moved(0.5 * float(run.radii.min()))
        diff = int(np.sum(got != ref))
        note = "" if diff == 0 or eng != "liggghts" else (
            "no smooth joint in LIGGGHTS-PUBLIC: spheres beyond the vertical joint nest in the pockets of the "
            "lattice across it and hang")
        if eng == "liggghts" and res.extra.get("liggghts_joints") == "open":  # the error the option makes
            note = "; ".join(filter(None, [
                f"liggghts_joints = open (no contact across the joint): joint pairs closed by up to "
                f"{1e6 * float(res.extra.get('joint_closure_max', 0.0)):.1f} um with no force", note]))
        rows.append(Row("beam_joint", eng, f"{int(got.sum())} detached", f"{int(ref.sum())} (bond graph)",
                        f"{diff} differ", diff == 0, time.perf_counter() - t0, note=note, value=float(got.sum()),
                        ref_value=float(ref.sum()), err_value=float(diff)))
        if say:
            say(_line(rows[-1]))
    for eng in [e for e in engines if e != "yade"]:  # YADE has no viscous damping of the spheres
        rows.append(beam_settle(work, timeout, eng))
        if say:
            say(_line(rows[-1]))
    return rows


def beam_settle(work, timeout=None, engine="liggghts"):
    """The intact beam run in `engine` (liggghts or dda) from its scene alone (viscous_damping = "critical"): its
    tip sag after 0.3 s against the static solution of the spring network."""
    from adapters.spec import from_scene

    path = CV / "beam_settle.toml"
    run = from_scene(path)
    tip = run.centers[:, 0] > run.centers[:, 0].max() - 0.5 * float(run.radii.min())
    ref = float(-static_displacement(run)[tip, 2].mean())  # this module's solve (central bonds), not the adapters'
    t0 = time.perf_counter()
    res = run_engine(engine, path, Path(work) / "beam_settle", timeout, run=run)
    got = float(-res.displacement()[tip, 2].mean())
    err = got / ref - 1.0
    return Row("beam_settle", engine, f"{got * 1e6:.3f} um", f"{ref * 1e6:.3f} um (static network)",
               f"{100 * err:+.4f} %", abs(err) <= SETTLE_TOLERANCE, time.perf_counter() - t0,
               note=f"c = {run.viscous_damping:.4g} kg/s from viscous_damping = critical", value=got,
               ref_value=ref, err_value=err)


def _wedge_line(w):
    geo = wedge_reference(w)
    o, p5 = geo.vertices[0], geo.vertices[1]
    return geo, (o - p5) / np.linalg.norm(o - p5)


def planar_reference(dip):
    """Hoek & Bray's planar sliding without cohesion, water or a loaded tension crack: FS = tan(phi) / tan(psi),
    so the critical friction is phi_c = atan(tan psi) [deg]."""
    return math.degrees(math.atan(math.tan(math.radians(dip))))


@dataclass(frozen=True)
class Sliding:
    """An onset case of the table: its run scene, the direction the body slides in (unit vector), the reference
    angle phi_c [deg] and how the row names it, what slides (the row's note), the joints it slides on as the note
    says them, the reference's geometry (`moving` criteria may read it) and the LIGGGHTS run's contact damping
    ratio (liggghts_wedge)."""
    name: str
    scene: Path
    line: np.ndarray
    phi_c: float
    reference: str
    body: str
    joints: str = "the joint"
    geo: object = None
    liggghts_damping: float = 0.0


def wedge_sliding():
    """The sphere wedge: it slides along the line of intersection of its joints; reference Hoek & Bray."""
    geo, line = _wedge_line(WEDGE)
    return Sliding("wedge", CV / "wedge.toml", line, geo.critical_friction, "Hoek & Bray", "wedge", "each joint",
                   geo)


def planar_sliding():
    """The block on one planar joint: it slides down the joint's dip; reference tan phi_c = tan psi. In LIGGGHTS
    the clump's wall contacts are damped at PLANAR_LIGGGHTS_DAMPING of critical (liggghts_wedge)."""
    _, down = planar_normal()
    return Sliding("planar", CV / "planar.toml", down, planar_reference(PLANAR["dip"]), "tan phi = tan psi", "block",
                   liggghts_damping=PLANAR_LIGGGHTS_DAMPING)


def rigid_core(run, bonds=3):
    """(n,) bool: the spheres a wedge run keeps: the fixed ones and the free spheres that at least `bonds` bonds
    tie to kept spheres (peeled off one layer after another until none has fewer). The bonds carry no moment
    (YADE's JCFpm, the in-house bond law): a free sphere held by one bond rolls round its neighbour and one
    held by two swings about the line through the two bond points, so it never comes to rest and jolts the
    wedge it hangs on (the r = 0.5 wedge has five such spheres; at 19.8 deg, where the wedge holds, the one on a
    single bond moved 0.65 m in 1.2 s, and its jolts let the wedge slip 0.4 mm in the last quarter)."""
    keep = np.ones(run.n, bool)
    fixed = np.asarray(run.fixed, bool)
    while True:
        b = keep[run.bond_i] & keep[run.bond_j]
        held = np.bincount(np.concatenate([run.bond_i[b], run.bond_j[b]]), minlength=run.n)
        drop = keep & ~fixed & (held < bonds)
        if not drop.any():
            return keep
        keep &= ~drop


def without(run, keep):
    """A copy of the SphereRun `run` with the spheres `keep` ((n,) bool) alone, and the bonds, joints and cut pairs
    between them (their order kept, sphere indices renumbered): SphereRun.subset."""
    return run.subset(keep)


def sliding_run(case, path=None, core=True):
    """The SphereRun of an onset case (scene `path`, default the case's), without the free spheres that fewer than
    three bonds hold (rigid_core) unless `core` is false."""
    from adapters.spec import from_scene

    run = from_scene(path or case.scene)
    return without(run, rigid_core(run)) if core else run


def wedge_run(path=None, core=True):
    """The wedge's SphereRun (scene `path`, default cases/scenes/crossval/wedge.toml): sliding_run."""
    return sliding_run(wedge_sliding(), path, core)


def wedge_slides(s, run, geo):
    """A trial slides when the body has not come to rest: its displacement along the sliding direction (s at T/2,
    3T/4, T) grew by more than WEDGE_REST radii in the last quarter (every onset case). A wedge that holds comes
    to rest after the start-up (its last quarter moves by 1e-9 m at r = 0.5 and 19.715 deg); just below the
    critical angle local damping can hold a sliding wedge at a steady creep (at 19.69 deg 0.47 mm in every 0.6 s,
    for 4.8 s), which a test for acceleration calls holding. The criterion before this one asked for an
    acceleration of 1 % of the driving one (the last quarter 7/32 x 1 % g sin(plunge) T^2), which alone puts the
    onset 0.92 % low (tan phi 1 % below tan phi_c), 1.03 % with local damping's slower slide, and 1.17 % with the
    start-up."""
    return s[2] - s[1] > WEDGE_REST * float(np.min(run.radii))


def sliding_trial(case, engine, base, phi, work, timeout=None, moving=wedge_slides, walls=False):
    """One trial of the onset case `case` (a Sliding) on its run `base` (sliding_run) at joint friction `phi`
    [deg] in `engine`: (slides, displacement along the sliding direction at T/2, 3T/4, T) with
    `moving(s, run, case.geo)` deciding. `walls`: the rock below the joints as joint walls (walled_wedge;
    LIGGGHTS always runs on walls, liggghts_wedge)."""
    body = ~base.fixed
    run = replace(base, joint_friction_deg=float(phi))
    variant = None
    if engine == "liggghts":
        run, variant = liggghts_wedge(run, case.liggghts_damping), "clumps"
    elif walls:
        run = walled_wedge(run)
    wk = Path(work) / f"{case.name}_{engine}{'_walls' if walls else ''}_{phi:.4f}"
    wk.mkdir(parents=True, exist_ok=True)
    run.save(wk / "run.npz")
    res = run_engine(engine, wk / "run.npz", wk, timeout, run=run, variant=variant)
    s = _along(res, body, base.radii[body] ** 3, case.line, run.duration)
    return bool(moving(s, run, case.geo)), s


def wedge_trial(engine, base, phi, work, timeout=None, moving=wedge_slides, walls=False):
    """One trial of the wedge run `base` (wedge_run): sliding_trial of wedge_sliding()."""
    return sliding_trial(wedge_sliding(), engine, base, phi, work, timeout, moving, walls)


def liggghts_wedge(run, damping=0.0):
    """An onset case's run as LIGGGHTS runs it (deck variant "clumps"; the wedge and the planar block alike):
    LIGGGHTS-PUBLIC has no smooth joint, and on the fixed spheres' bumps the wedge interlocks (it held at 1.2 deg),
    so the rock below each joint is a plane mesh wall with the joint friction (run.extra liggghts_joint_walls,
    adapters/liggghts_walls.py). The body is one rigid clump: LIGGGHTS' harmonic bonds are central springs, so a
    bonded sphere turns freely and rolls on the wall like a ball bearing (at 18 deg the bonded wedge slid at
    4.1 m/s2, nearly the frictionless 4.4). No local damping in LIGGGHTS: fix viscous gamma = m /
    WEDGE_LIGGGHTS_TAU per sphere takes out the settling onto the walls (the wedge first rests on its lowest
    sphere on each wall and turns by 0.6 deg) and the contact vibrations; below phi_c the wedge then creeps at
    a tau (a its acceleration), 0.13 delta m in the last quarter at tan phi = (1 - delta) tan phi_c, so a trial
    slides from delta = 4e-4 (WEDGE_REST). Measured: the onset's bracket 19.692-19.707 deg at tau = 0.05, 0.1
    and 0.2 s; undamped +0.51 %. `damping` > 0: the contacts' normal damping ratio (run.damping) instead of the
    run's own (the planar block, PLANAR_LIGGGHTS_DAMPING)."""
    m = run.density * 4.0 / 3.0 * math.pi * float(np.mean(np.asarray(run.radii) ** 3))
    out = replace(run, extra={**run.extra, "joint_walls": "pairs", "liggghts_viscous": m / WEDGE_LIGGGHTS_TAU})
    return replace(out, damping=float(damping)) if damping > 0 else out


def walled_wedge(run):
    """The wedge run on joint walls in YADE or in-house (run.extra joint_walls = "nearest", adapters/joint_walls.py):
    the rock below each joint is a plane wall (a YADE facet, an in-house slab) with the joint friction, touching the
    wedge's nearest sphere; the bonded wedge keeps its radii. It first rests on its lowest spheres and settles
    onto the walls (0.14 m along the line of intersection at r = 0.5, 1.5 s; at 1.2 s per trial it was still
    settling and both 0.995 and 1.005 x phi_c moved), so a trial runs WEDGE_WALL_T."""
    return replace(run, duration=WEDGE_WALL_T, record_every=WEDGE_WALL_T / 48,
                   extra={**run.extra, "joint_walls": "nearest"})


def sliding_onset(case, engine, work, timeout=None, path=None, bracket=(0.95, 1.05), iterations=7, core=True,
                  moving=wedge_slides, walls=False):
    """Bisection of the joint friction of the onset case `case` (a Sliding) in `engine`: starts from `bracket` x
    the reference angle case.phi_c (widened while both ends agree), then `iterations` halvings; each trial is
    sliding_trial (`moving` decides). Returns a dict: lo (slides), hi (holds), found (False when no bracket was
    found: lo and hi then name the last two ends tried), trials [(phi, slides, s)], the run (its spheres) and
    phi_c. `path`: another run scene; `walls`: on joint walls (sliding_trial)."""
    base = sliding_run(case, path, core)
    trials = []

    def slides(phi):
        moved, s = sliding_trial(case, engine, base, phi, work, timeout, moving, walls)
        trials.append((float(phi), moved, s))
        return moved

    phi_c = case.phi_c
    lo, hi = bracket[0] * phi_c, bracket[1] * phi_c
    s_lo, s_hi = slides(lo), slides(hi)
    while not s_lo and lo > 2.0:  # holds at both ends: look lower
        hi, lo = lo, 0.5 * lo
        s_lo = slides(lo)
    while s_hi and hi < 60.0:  # slides at both ends: look higher
        lo, hi = hi, min(1.5 * hi, 80.0)
        s_hi = slides(hi)
    found = s_lo and not s_hi
    for _ in range(iterations if found else 0):
        mid = 0.5 * (lo + hi)
        if slides(mid):
            lo = mid
        else:
            hi = mid
    return dict(lo=lo, hi=hi, found=found, where="slides" if s_hi else "holds", trials=trials, run=base,
                phi_c=phi_c)


def wedge_onset(engine, work, timeout=None, path=None, bracket=(0.95, 1.05), iterations=7, core=True,
                moving=wedge_slides, walls=False):
    """Bisection of the sphere wedge's joint friction in `engine` from Hoek & Bray's critical angle:
    sliding_onset of wedge_sliding()."""
    return sliding_onset(wedge_sliding(), engine, work, timeout, path, bracket, iterations, core, moving, walls)


def onset_rows(case, engines, work, say, timeout, iterations=7, walls=("dda", "yade")):
    """The rows of an onset case (a Sliding): its bisection (sliding_onset) in every engine, on smooth joints
    (LIGGGHTS: on walls) and, in the engines of `walls`, also on joint walls (walled_wedge: row NAME_walls)."""
    rows = []
    phi_c = case.phi_c
    runs = [(eng, False) for eng in engines] + [(eng, True) for eng in engines if eng in walls]
    for eng, on_walls in runs:
        t0 = time.perf_counter()
        b = sliding_onset(case, eng, work, timeout, iterations=iterations, walls=on_walls)
        lo, hi, run = b["lo"], b["hi"], b["run"]
        name = f"{case.name}_walls" if on_walls else case.name
        extra = _onset_note(case, eng, on_walls)
        reference = f"{phi_c:.3f} deg ({case.reference})"
        if b["found"]:
            got = 0.5 * (lo + hi)
            err = got / phi_c - 1.0
            note = (f"r = {float(np.min(run.radii)):g} m, {int((~run.fixed).sum())} free spheres, bracket "
                    f"{lo:.3f}-{hi:.3f}, {len(b['trials'])} runs")
            if extra:
                note += "; " + extra
            rows.append(Row(name, eng, f"{got:.3f} deg", reference, f"{100 * err:+.2f} %",
                            abs(err) <= ONSET_TOLERANCE, time.perf_counter() - t0, note=note,
                            value=got, ref_value=phi_c, err_value=err))
        else:
            rows.append(Row(name, eng, f"{b['where']} at {lo:.1f} and {hi:.1f} deg", reference, "no onset found",
                            False, time.perf_counter() - t0, note=extra, ref_value=phi_c))
        if say:
            say(_line(rows[-1]))
    return rows


def case_wedge(engines, work, say, timeout, iterations=7):
    """The sphere wedge's onset by bisection of the joint friction (wedge_onset) in every engine, on smooth joints
    (LIGGGHTS: on walls) and, in-house and in YADE, also on joint walls (walled_wedge: row wedge_walls)."""
    case = wedge_sliding()
    rows = onset_rows(case, engines, work, say, timeout, iterations)
    if "dda" in engines:
        rows.append(_dda_block_wedge(case.phi_c, say))
    return rows


def case_planar(engines, work, say, timeout, iterations=7):
    """Planar sliding of a bonded block on one smooth joint: the onset by bisection of the joint friction in every
    engine (LIGGGHTS: the rock below the joint a mesh wall, the block a rigid clump) against tan phi = tan psi."""
    return onset_rows(planar_sliding(), engines, work, say, timeout, iterations, walls=())


def _onset_note(case, engine, walls=False):
    each = case.joints
    if engine == "liggghts":
        damped = f", wall contacts damped at {case.liggghts_damping:g} of critical" if case.liggghts_damping else ""
        return (f"no smooth joint in LIGGGHTS-PUBLIC: the rock below {each} is a mesh wall (fix wall/gran, joint "
                f"friction), the {case.body} a rigid clump, fix viscous m / {WEDGE_LIGGGHTS_TAU:g} s{damped}")
    if walls:
        return (f"the rock below {each} a {'facet' if engine == 'yade' else 'slab'} with the joint friction "
                f"(joint_walls = nearest), {WEDGE_WALL_T:g} s per run")
    return ""


def _along(res, body, weight, line, T):
    """Mass-weighted mean displacement of the spheres `body` along `line` at T/2, 3T/4 and T."""
    if res.pos is None or len(res.time) < 3:
        raise RuntimeError(f"{res.engine}: the onset run recorded no positions")
    out = []
    for frac in (0.5, 0.75, 1.0):
        k = int(np.argmin(np.abs(res.time - frac * T)))
        d = res.pos[k][body] - res.x0[body]
        out.append(float(np.average(d @ line, weights=weight)))
    return out


def _dda_block_wedge(phi_c, say):
    from dda.wedge import dda_critical_friction

    t0 = time.perf_counter()
    w = WEDGE
    d = dda_critical_friction(w["joint_a"], w["joint_b"], w["face"], height=w["height"], friction=25.0)
    got = d["phi_crit_dda"]
    err = got / phi_c - 1.0
    row = Row("wedge", "dda-blocks", f"{got:.2f} deg", f"{phi_c:.2f} deg (Hoek & Bray)", f"{100 * err:+.2f} %",
              abs(err) <= ONSET_TOLERANCE, time.perf_counter() - t0, note="DDA block wedge (dda wedge)", value=got,
              ref_value=phi_c, err_value=err)
    if say:
        say(_line(row))
    return row


def case_blocks(engines, work, say, timeout):
    """Polyhedral block on an incline and the paper's wedge: in-house DDA and YADE Polyhedra."""
    from dda.hoekbray import wedge_fs
    from dda.scene import load_scene

    rows = []
    for name, path in (("incline", SCENES / "dda_incline.toml"), ("block_wedge", CV / "block_wedge.toml")):
        scene = load_scene(path)
        phi = scene.law.friction_deg
        if name == "incline":
            alpha = 30.0
            acc = G * (math.sin(math.radians(alpha)) - math.tan(math.radians(phi)) * math.cos(math.radians(alpha)))
        else:
            gen = _generate_params(scene)
            geo = wedge_fs(gen["joint_a"], gen["joint_b"], gen["face"], height=gen["height"], friction=30.0)
            acc = G * math.sin(math.radians(geo.line_plunge)) * (
                1.0 - math.tan(math.radians(phi)) / math.tan(math.radians(geo.critical_friction)))
        ref = 0.5 * acc * scene.duration ** 2
        moving = [k for k, b in enumerate(scene.blocks) if not b.fixed]
        for eng in engines:
            if eng == "liggghts":
                continue  # LIGGGHTS has no polyhedra
            t0 = time.perf_counter()
            if eng == "dda":
                bs, sim = scene.build()
                sim.run(scene.duration, record_every=scene.duration)
                got = float(np.linalg.norm(sim.displacement(moving[0])))
                note = ""
            else:
                res = run_engine("yade", path, Path(work) / name, timeout)
                got = float(np.linalg.norm(res.displacement()[moving[0]]))
                note = "" if name == "incline" else "YADE Polyhedra keeps shear history per law, not per contact"
            err = got / ref - 1.0
            eng_name = "dda" if eng == "dda" else "yade-polyhedra"
            rows.append(Row(name, eng_name, f"{got:.4f} m", f"{ref:.4f} m (analytical)", f"{100 * err:+.2f} %",
                            abs(err) <= SLIDE_TOLERANCE, time.perf_counter() - t0, note=note, value=got, ref_value=ref,
                            err_value=err))
            if say:
                say(_line(rows[-1]))
    return rows


def _generate_params(scene):
    data = tomllib.loads(scene.text)
    gen = data["generate"][0]
    return {k: gen[k] for k in ("joint_a", "joint_b", "face", "height")}


def case_shear_beam(engines, work, say, timeout):
    """The cantilever of normal + shear bonds against the network's 6-DOF static solution (crossval_shear.py)."""
    from cases.lib.crossval_shear import shear_beam  # scipy and the adapters: loaded when the case runs

    rows = []

    def emit(**fields):
        rows.append(Row(**fields))
        if say:
            say(_line(rows[-1]))

    shear_beam(engines, Path(work), timeout, run_engine, emit)
    return rows


# -- table -----------------------------------------------------------------------------------------------
COLUMNS = ("case", "engine", "result", "reference", "error", "ok", "wall s", "note")


def _cells(r: Row):
    ok = "-" if r.ok is None else ("yes" if r.ok else "NO")
    return (r.case, r.engine, r.result, r.reference, r.error, ok, f"{r.wall_s:.1f}", r.note)


def _line(r: Row):
    return "  ".join(_cells(r))


def table(rows):
    cells = [COLUMNS] + [_cells(r) for r in rows]
    widths = [max(len(c[k]) for c in cells) for k in range(len(COLUMNS))]
    out = []
    for n, c in enumerate(cells):
        out.append("| " + " | ".join(s.ljust(w) for s, w in zip(c, widths)) + " |")
        if n == 0:
            out.append("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return "\n".join(out)


def crossval(cases=CASES, engines=ENGINES, work=None, say=None, timeout=1800.0):
    missing = [e for e in engines if not _available(e)]
    if missing:
        from adapters.process import find_engine

        find_engine(missing[0])  # raises the one-line EngineError
    own = work is None
    work = Path(tempfile.mkdtemp(prefix="crossval_")) if own else Path(work)
    rows = []
    try:
        for case in cases:
            fn = {"hang": case_hang, "column": case_column, "rocking": case_rocking, "beam": case_beam,
                  "wedge": case_wedge, "planar": case_planar, "blocks": case_blocks,
                  "shear_beam": case_shear_beam}[case]
            rows += fn(engines, work, say, timeout)
    finally:
        if own:
            shutil.rmtree(work, ignore_errors=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(prog="cases crossval", description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma list of {', '.join(CASES)}")
    ap.add_argument("--engines", default=",".join(ENGINES), help=f"comma list of {', '.join(ENGINES)}")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON on stdout (instead of the table)")
    ap.add_argument("--keep", help="keep the decks and results in this folder")
    ap.add_argument("--timeout", type=float, default=1800.0, help="time limit per engine run [s]")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")
    args = ap.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    engines = [e for e in args.engines.split(",") if e]
    bad = [c for c in cases if c not in CASES] + [e for e in engines if e not in ENGINES]
    if bad:
        print(f"cases crossval: error: unknown case or engine {bad[0]!r} (cases: {', '.join(CASES)}; engines: "
              f"{', '.join(ENGINES)})", file=sys.stderr)
        return 2
    from adapters.process import EngineError
    from sgim.common import progress_printer as _progress

    say = _progress(args.quiet)
    try:
        rows = crossval(cases, engines, work=args.keep, say=say, timeout=args.timeout)
    except EngineError as exc:
        print(f"cases crossval: error: {exc}", file=sys.stderr)
        return 3
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2))
    else:
        print(table(rows))
    return 0 if all(r.ok is not False or r.note for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
