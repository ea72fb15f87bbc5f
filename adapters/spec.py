"""SphereRun: the engine-neutral description of one bonded-sphere run, the common input of every deck.

A SphereRun holds, as plain arrays, everything an engine needs to run an sgim model (model.npz) the same way
in-house (dda.spheres), in YADE or in LIGGGHTS:

- spheres: ``centers`` (n, 3), ``radii``, ``colour`` (sgim colour code), ``fixed`` (n,) bool, ``density``;
- bonds: only the pairs the model marks ``bonded``: ``bond_i < bond_j``, rest length ``bond_len0``, normal and
  shear stiffness ``bond_kn`` / ``bond_ks`` [N/m], breaking forces ``bond_ft`` (tension) / ``bond_fs`` (shear)
  [N] (inf: unbreakable), ``bond_zeta`` viscous bond damping (ratio of critical, [spheres] bond_damping); the
  stiffness and strength follow dda.spheres.BondLaw (bond area pi (f min r)^2, kn = E A / L0);
- joints: the touching pairs the model marks cut by a zero-thickness discontinuity (a disc or a triangulated
  surface without thickness): ``joint_i < joint_j``, ``joint_disc`` (the discontinuity index) and
  ``joint_normal`` (n, 3): the discontinuity's unit normal at the pair, signed to point from sphere i to
  sphere j. With ``smooth_joints`` these pairs are smooth joints (contact normal = joint normal, friction
  ``joint_friction_deg``); pairs cut by a fault (thickness > 0) are plain frictional contacts;
  ``liggghts_joints`` ([spheres] liggghts_joints, LIGGGHTS decks only, which have no smooth joint): "contact"
  (the joint pairs are plain contacts) or "open" (no contact between the two sides of a joint, adapters/liggghts.py);
- the contact law of every unbonded contact: ``kn``, ``ks`` [N/m], ``friction_deg``, ``damping`` (ratio of
  critical, viscous), and the run: ``gravity``, ``dt`` (one step for every engine), ``duration``,
  ``record_every``, ``local_damping`` (Cundall's non-viscous damping, as YADE's NewtonIntegrator.damping),
  ``viscous_damping`` (a force -c v on every free sphere, c [N s/m] the same for all: LIGGGHTS' ``fix
  viscous``, the in-house SphereSimulation's viscous_damping; [simulation] viscous_damping gives it as a ratio
  of critical damping of the model's first mode, :func:`viscous_coefficient`);
- loads: ``force`` (n, 3) a constant force on each sphere [N] (added to its weight; no effect on fixed or
  prescribed spheres), ``prescribed`` (n,) bool and ``velocity`` (n, 3) [m/s]: prescribed spheres move at
  their velocity whatever the forces and do not turn (a platen; ``velocity`` is ignored elsewhere). A sphere
  cannot be both fixed and prescribed. Runs saved before these arrays existed load with no loads.

Build one from a DDA scene with [spheres] (``from_scene``) or from a model with run settings
(``from_model``); ``save`` / ``load`` write the arrays to one npz (``run.npz`` of a deck folder) and the
scalars to its JSON header.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from dda.contactlaw import ContactLaw
from dda.limits import check, sphere_bond_key, sphere_dt_source
from dda.timestep import sphere_critical_dt, sphere_mass
from sgim.common import SceneError, atomic_npz
from sgim.model import SphereModel
from sgim.readback import Arrays, Fields, parse_json, read_npz

from .liggghts_joints import open_joint_problem

# The in-house engine's modules (dda.spheres, dda.simulation, dda.scene) load numba: the functions below that need
# them import them when called, so that reading or writing a run.npz (every `adapters run`) does not load it.

ARRAYS = ("centers", "radii", "colour", "fixed", "bond_i", "bond_j", "bond_len0", "bond_kn", "bond_ks", "bond_ft",
          "bond_fs", "joint_i", "joint_j", "joint_disc", "joint_normal", "cut_i", "cut_j", "gravity")
ARRAYS += ("force", "prescribed", "velocity")  # loads; optional in run.npz files (absent: none)
ARRAYS += ("bond_zeta",)  # viscous bond damping; optional in run.npz files (absent: undamped bonds)
OPTIONAL_ARRAYS = ("force", "prescribed", "velocity", "bond_zeta")

# Scene keys that no deck carries, and why (every other [simulation] and [spheres] key of dda/scene.py reaches
# every engine that can express it, or is named in that engine's extra["approximations"]; tests/test_scene_keys.py)
# [spheres] liggghts_joints: how a LIGGGHTS deck (no smooth joint) writes the joint pairs (adapters/liggghts.py);
# the values of dda.scene.LIGGGHTS_JOINTS (not imported here: dda.scene is slow to import)
LIGGGHTS_JOINTS = ("contact", "open")

NOT_RUN_KEYS = {
    "simulation.frames": "the number of VTU frames `dda run` writes (output, not physics)",
    "simulation.max_steps": "a limit checked when the deck is written (a longer run is refused), not physics",
    "simulation.sleep": "resting blocks stop being integrated: blocks only (sphere decks have no blocks)",
    "simulation.sleep_velocity": "see simulation.sleep", "simulation.sleep_accel": "see simulation.sleep",
    "simulation.sleep_steps": "see simulation.sleep",
}


def liggghts_only(run):
    """The note of an engine with smooth joints when the run asks LIGGGHTS to drop the joint contacts."""
    if run.liggghts_joints == "open":
        return ['spheres.liggghts_joints = "open" concerns LIGGGHTS decks only: here the joint pairs are smooth '
                "joints (spheres.smooth_joints)"]
    return []


class SpecError(ValueError):
    """A model or scene that no engine can run (one line for the user)."""


@dataclass
class SphereRun:
    """The engine-neutral description of a bonded-sphere run (run.npz): spheres, fixed and loaded ones, the
    per-pair bonds and smooth joints, contact law, time step and duration, written to every engine's deck."""

    name: str
    centers: np.ndarray
    radii: np.ndarray
    colour: np.ndarray
    fixed: np.ndarray
    density: float
    bond_i: np.ndarray
    bond_j: np.ndarray
    bond_len0: np.ndarray
    bond_kn: np.ndarray
    bond_ks: np.ndarray
    bond_ft: np.ndarray
    bond_fs: np.ndarray
    joint_i: np.ndarray
    joint_j: np.ndarray
    joint_disc: np.ndarray
    joint_normal: np.ndarray
    cut_i: np.ndarray
    cut_j: np.ndarray
    kn: float
    ks: float
    friction_deg: float
    damping: float
    joint_friction_deg: float
    smooth_joints: bool
    gravity: np.ndarray
    dt: float
    duration: float
    record_every: float
    local_damping: float
    source: str = ""
    extra: dict = field(default_factory=dict)  # engine-specific settings (e.g. liggghts bond breakage check)
    force: np.ndarray | None = None       # (n, 3) constant force on each sphere [N] (None: zeros)
    prescribed: np.ndarray | None = None  # (n,) bool: moves at `velocity` whatever the forces (None: none)
    velocity: np.ndarray | None = None    # (n, 3) velocity of the prescribed spheres [m/s] (None: zeros)
    bond_zeta: np.ndarray | None = None   # (m,) viscous bond damping, ratio of critical (None: zeros)
    viscous_damping: float = 0.0          # c [N s/m]: a force -c v on every free sphere (LIGGGHTS fix viscous)
    liggghts_joints: str = "contact"      # LIGGGHTS decks: joint pairs as plain contacts, or "open" (no contact)

    def __post_init__(self):
        n = len(np.asarray(self.radii).reshape(-1))
        m = len(np.asarray(self.bond_i).reshape(-1))
        self.bond_zeta = np.zeros(m) if self.bond_zeta is None else np.asarray(self.bond_zeta, float).reshape(-1)
        self.force = np.zeros((n, 3)) if self.force is None else np.asarray(self.force, float).reshape(-1, 3)
        self.prescribed = (np.zeros(n, bool) if self.prescribed is None
                           else np.asarray(self.prescribed, bool).reshape(-1))
        self.velocity = np.zeros((n, 3)) if self.velocity is None else np.asarray(self.velocity, float).reshape(-1, 3)

    @property
    def loaded(self):
        """True when some sphere carries a constant force or a prescribed velocity."""
        return bool(np.any(self.prescribed) or np.any(self.force != 0))

    @property
    def n(self):
        return len(self.radii)

    @property
    def n_bonds(self):
        return len(self.bond_i)

    @property
    def steps(self):
        return max(1, int(round(self.duration / self.dt)))

    @property
    def record_steps(self):
        return max(1, int(round(self.record_every / self.dt)))

    def scalars(self):
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ARRAYS}

    # -- files ---------------------------------------------------------------
    def save(self, path):
        """One npz: the arrays plus a JSON string ``header`` with the scalars."""
        data = {k: np.asarray(getattr(self, k)) for k in ARRAYS}
        data["header"] = np.array(json.dumps(self.scalars()))
        atomic_npz(path, data)

    @classmethod
    def load(cls, path):
        """The run in the npz `path` (a deck's run.npz), validated (:func:`check_run`): a file that is not a
        usable run raises sgim.readback.BadFile (a CliError: ``FILE: what is wrong``)."""
        return cls(**check_run(path, read_npz(path, "a run.npz")))

    def in_house(self, walls=None, wall_friction_deg=None):
        """(SphereSet, SphereSimulation) of the in-house engine for this run (dda.spheres); `walls`: fixed convex
        polyhedra (BlockSpecs) with the run's contact law at `wall_friction_deg` (default friction_deg)."""
        from dda.spheres import SphereSimulation

        ss = _sphere_set(self)
        law = ContactLaw(kn=self.kn, ks=self.ks, friction_deg=self.friction_deg, damping=self.damping)
        wall_law = None if wall_friction_deg is None else ContactLaw(
            kn=self.kn, ks=self.ks, friction_deg=float(wall_friction_deg), damping=self.damping)
        sim = SphereSimulation(ss, law, walls=walls, wall_law=wall_law, gravity=self.gravity, dt=self.dt,
                               local_damping=self.local_damping, viscous_damping=self.viscous_damping)
        return ss, sim

    def subset(self, keep):
        """A copy of this run with the spheres `keep` ((n,) bool) alone, and the bonds, joints and cut pairs
        between them (their order kept, sphere indices renumbered)."""
        keep = np.asarray(keep, bool)
        new = np.full(self.n, -1, np.int64)
        new[keep] = np.arange(int(keep.sum()))
        bond = keep[self.bond_i] & keep[self.bond_j]
        joint = keep[self.joint_i] & keep[self.joint_j]
        cut = keep[self.cut_i] & keep[self.cut_j]
        per_bond = ("bond_len0", "bond_kn", "bond_ks", "bond_ft", "bond_fs", "bond_zeta")
        return replace(
            self, centers=np.asarray(self.centers)[keep], radii=np.asarray(self.radii)[keep],
            colour=np.asarray(self.colour)[keep], fixed=np.asarray(self.fixed, bool)[keep],
            bond_i=new[self.bond_i[bond]], bond_j=new[self.bond_j[bond]],
            **{k: np.asarray(getattr(self, k))[bond] for k in per_bond},
            joint_i=new[self.joint_i[joint]], joint_j=new[self.joint_j[joint]],
            joint_disc=np.asarray(self.joint_disc)[joint],
            joint_normal=np.asarray(self.joint_normal).reshape(-1, 3)[joint], cut_i=new[self.cut_i[cut]],
            cut_j=new[self.cut_j[cut]], force=np.asarray(self.force)[keep],
            prescribed=np.asarray(self.prescribed)[keep], velocity=np.asarray(self.velocity)[keep])


HEADER = ("name", "density", "kn", "ks", "friction_deg", "damping", "joint_friction_deg", "smooth_joints", "dt",
          "duration", "record_every", "local_damping", "source", "extra", "viscous_damping", "liggghts_joints")


def check_run(path, arrays):
    """The SphereRun keywords of the arrays `arrays` read from the run.npz `path`: the JSON header holds the
    scalars (positive density, stiffness and times, angles 0..90 degrees, ...), every array is present (the loads
    may be absent) with its dtype kind and shape, lengths agree (n spheres, m bonds, k joint pairs, c cut pairs),
    centres / radii / stiffnesses / normals / loads are finite, radii > 0, strengths >= 0 (inf: unbreakable), colour
    codes 0..3, every sphere index in range and no sphere both fixed and prescribed. Raises
    sgim.readback.BadFile naming the file and the first defect."""
    A = Arrays(path, arrays, "a run.npz")
    A.missing(["header", *(k for k in ARRAYS if k not in OPTIONAL_ARRAYS)])
    F = Fields(path, parse_json(path, A.text("header"), where="header"), where="header.")
    F.only(HEADER)
    kw = {"name": F.string("name"), "density": F.number("density", positive=True),
          "kn": F.number("kn", positive=True), "ks": F.number("ks", nonneg=True),
          "friction_deg": F.number("friction_deg", lo=0, hi=90), "damping": F.number("damping", nonneg=True),
          "joint_friction_deg": F.number("joint_friction_deg", lo=0, hi=90),
          "smooth_joints": F.boolean("smooth_joints"), "dt": F.number("dt", positive=True),
          "duration": F.number("duration", positive=True), "record_every": F.number("record_every", positive=True),
          "local_damping": F.number("local_damping", lo=0, hi=1), "source": F.string("source", ""),
          "extra": F.obj("extra", {}), "viscous_damping": F.number("viscous_damping", 0.0, nonneg=True),
          "liggghts_joints": F.string("liggghts_joints", "contact", choices=LIGGGHTS_JOINTS)}
    c = kw["centers"] = A.real("centers", (None, 3))
    n = len(c)
    sph, one = f"the run has {n} spheres", "one per sphere of centers"
    kw["radii"] = A.real("radii", (n,), positive=True, per=one)
    kw["colour"] = A.integer("colour", (n,), lo=0, hi=4, why="colour codes 0 intact, 1 red, 2 green, 3 blue",
                             per=one, dtype=np.int8)
    kw["fixed"] = A.boolean("fixed", (n,), per=one)
    for a, b, what in (("bond_i", "bond_j", "bond"), ("joint_i", "joint_j", "joint pair"),
                       ("cut_i", "cut_j", "cut pair")):
        i = kw[a] = A.integer(a, (None,), lo=0, hi=n, why=sph)
        j = kw[b] = A.integer(b, (len(i),), lo=0, hi=n, why=sph, per=f"one per {what} of {a}")
        same = i == j
        if same.any():
            k = int(np.argmax(same))
            A.fail(f"{a}[{k}] = {b}[{k}] = {int(i[k])}: a {what} of a sphere with itself")
    m, per = len(kw["bond_i"]), "one per bond of bond_i"
    kw["bond_len0"] = A.real("bond_len0", (m,), nonneg=True, per=per)
    kw["bond_kn"] = A.real("bond_kn", (m,), nonneg=True, per=per)
    kw["bond_ks"] = A.real("bond_ks", (m,), nonneg=True, per=per)
    kw["bond_ft"] = A.real("bond_ft", (m,), nonneg=True, allow_inf=True, per=per)
    kw["bond_fs"] = A.real("bond_fs", (m,), nonneg=True, allow_inf=True, per=per)
    if A.has("bond_zeta"):
        kw["bond_zeta"] = A.real("bond_zeta", (m,), nonneg=True, hi=1.0, per=per)
    k, per = len(kw["joint_i"]), "one per joint pair of joint_i"
    kw["joint_disc"] = A.integer("joint_disc", (k,), lo=0, per=per, dtype=np.int32)
    kw["joint_normal"] = A.real("joint_normal", (k, 3), per=per)
    kw["gravity"] = A.real("gravity", (3,))
    if A.has("force"):
        kw["force"] = A.real("force", (n, 3), per=one)
    if A.has("velocity"):
        kw["velocity"] = A.real("velocity", (n, 3), per=one)
    if A.has("prescribed"):
        p = kw["prescribed"] = A.boolean("prescribed", (n,), per=one)
        both = p & kw["fixed"]
        if both.any():
            A.fail(f"prescribed[{int(np.argmax(both))}] = fixed[{int(np.argmax(both))}] = True: a sphere cannot be "
                   "both fixed and prescribed")
    return kw


def _sphere_set(run: SphereRun):
    from dda.spheres import SphereSet  # lazy: numba (see the top)

    ss = SphereSet(run.centers, run.radii, run.density)
    ss.fixed[:] = run.fixed
    ss.bond_i, ss.bond_j = run.bond_i.astype(np.int64), run.bond_j.astype(np.int64)
    ss.bond_len0 = run.bond_len0.astype(float)
    ss.bond_kn, ss.bond_ks = run.bond_kn.astype(float), run.bond_ks.astype(float)
    ss.bond_ft, ss.bond_fs = run.bond_ft.astype(float), run.bond_fs.astype(float)
    ss.bond_zeta = np.asarray(run.bond_zeta, float).copy()
    ss.body_force[:] = run.force
    ss.prescribed[:] = run.prescribed
    ss.velocity[:] = np.where(run.prescribed[:, None], run.velocity, 0.0)
    if run.smooth_joints and len(run.joint_i):
        ss.add_joints(np.c_[run.joint_i, run.joint_j], run.joint_normal, run.joint_friction_deg)
    return ss


# -- construction ---------------------------------------------------------------
def joint_pairs(model):
    """(pair index into model.bonds, discontinuity index, unit normal i -> j) of every touching pair that the
    model marks cut by a zero-thickness discontinuity (a joint disc or a triangulated joint surface)."""
    return model.joint_pairs()


def from_model(model, *, density=2600.0, fixed=None, bonds=None, kn=None, ks=None, friction_deg=None,
               damping=None, joint_friction_deg=None, smooth_joints=True, gravity=(0.0, 0.0, -9.81), dt=None,
               safety=0.5, duration=0.01, record_every=None, local_damping=0.0, name=None, source="",
               force=None, prescribed=None, velocity=None, viscous_damping=0.0):
    """SphereRun of an sgim model (SphereModel or model.npz path). `bonds`: a dda.spheres.BondLaw (default
    BondLaw()); `fixed`: (n,) bool or None; `kn`, `ks`, `friction_deg`, `damping` of the unbonded contacts, unset:
    dda.contactlaw.ContactLaw's defaults; dt None: `safety` times the in-house critical step. Loads: `force`
    (n, 3) or (3,) [N] on each sphere, `prescribed` (n,) bool, `velocity` (n, 3) or (3,) [m/s] (None: none).
    `viscous_damping`: ratio of critical damping of the model's first mode (a number >= 0, or "critical" = 1),
    turned into the coefficient c [N s/m] of SphereRun.viscous_damping by :func:`viscous_coefficient`."""
    from dda.spheres import BondLaw, SphereSet  # lazy: numba (see the top)

    if not hasattr(model, "centers"):
        model = SphereModel.load(model)
    n = len(model.radii)
    if n == 0:
        raise SpecError(f"{source or 'model'}: the model has no spheres")
    law = bonds or BondLaw()
    ss = SphereSet(model.centers, model.radii, density)
    pairs = np.asarray(model.bonds, np.int64).reshape(-1, 2)
    ss.add_bonds(pairs[np.asarray(model.bonded, bool)], law)
    if fixed is not None:
        ss.fixed[:] = np.asarray(fixed, bool)
    law0 = ContactLaw()
    kn = law0.kn if kn is None else kn
    ks = kn / 2 if ks is None else ks
    friction_deg = law0.friction_deg if friction_deg is None else friction_deg
    damping = law0.damping if damping is None else damping
    cut, disc, normal = joint_pairs(model)
    cut_all = pairs[~np.asarray(model.bonded, bool)]
    run = SphereRun(
        name=name or str(model.meta.get("scene", "model")), centers=np.asarray(model.centers, float),
        radii=np.asarray(model.radii, float), colour=np.asarray(model.colour, np.int8), fixed=ss.fixed.copy(),
        density=float(density), bond_i=ss.bond_i, bond_j=ss.bond_j, bond_len0=ss.bond_len0, bond_kn=ss.bond_kn,
        bond_ks=ss.bond_ks, bond_ft=ss.bond_ft, bond_fs=ss.bond_fs, joint_i=pairs[cut, 0], joint_j=pairs[cut, 1],
        joint_disc=disc.astype(np.int32), joint_normal=normal, cut_i=cut_all[:, 0], cut_j=cut_all[:, 1],
        kn=float(kn), ks=float(ks), friction_deg=float(friction_deg), damping=float(damping),
        joint_friction_deg=float(friction_deg if joint_friction_deg is None else joint_friction_deg),
        smooth_joints=bool(smooth_joints), gravity=np.asarray(gravity, float).reshape(3), dt=0.0,
        duration=float(duration), record_every=float(record_every or duration / 100),
        local_damping=float(local_damping), source=str(source), bond_zeta=ss.bond_zeta.copy())
    _set_loads(run, force, prescribed, velocity)
    if dt is None:
        dt = safety * critical_dt(run, ss, safety)
    run.dt = float(dt)
    if not (run.dt > 0 and math.isfinite(run.dt)):
        raise SpecError(f"{source or 'model'}: time step must be > 0 (got {dt!r})")
    if viscous_damping:
        run.viscous_damping = viscous_coefficient(run, viscous_damping)
    return run


def critical_dt(run, spheres, safety):
    """The in-house engine's critical time step of `run` (dda.timestep.sphere_critical_dt: the stiffest free
    sphere on its bonds and four contacts), without building the engine. `spheres`: the run's dda SphereSet (its
    spheres and bonds). The run is checked as the engine checks it when it computes the step (ValueError): the
    smooth joints, finite bond stiffness, the contact law, a positive step at `safety`."""

    if run.smooth_joints and len(run.joint_i):
        spheres.add_joints(np.c_[run.joint_i, run.joint_j], run.joint_normal, run.joint_friction_deg)
    if run.n_bonds and not np.all(np.isfinite(run.bond_kn)):
        raise ValueError("bond stiffness must be finite")
    kn, ks, _, _, _, zeta = ContactLaw(kn=run.kn, ks=run.ks, friction_deg=run.friction_deg,
                                       damping=run.damping).row()
    free = ~(np.asarray(run.fixed, bool) | np.asarray(run.prescribed, bool))
    dt_crit = sphere_critical_dt(sphere_mass(run.radii, run.density), free, kn, ks, zeta, run.bond_i, run.bond_j,
                                 run.bond_kn, run.bond_ks, run.bond_zeta)
    if not float(safety) * dt_crit > 0:
        raise ValueError("time step must be > 0 (got None)")  # the engine's own refusal of this step
    return dt_crit


def damping_ratio(value, what="viscous damping"):
    """The ratio of critical damping `value` stands for: a number >= 0, or "critical" (1). ValueError otherwise."""
    if isinstance(value, str):
        if value.strip().lower() == "critical":
            return 1.0
        raise ValueError(f"{what} must be a ratio of critical damping >= 0 or \"critical\"")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0.0 <= float(value) <= 1e3):
        raise ValueError(f"{what} must be a ratio of critical damping in 0..1e3 or \"critical\"")
    return float(value)


def _anchored(run):
    return np.asarray(run.fixed, bool) | np.asarray(run.prescribed, bool)


def _mass(run):
    return run.density * 4.0 / 3.0 * np.pi * np.asarray(run.radii, float) ** 3


def held_spheres(run):
    """(n,) bool: the free spheres that a path of bonds ties to a fixed sphere (dda.spheres.held_by_bonds)."""
    from dda.spheres import held_by_bonds  # lazy: numba (see the top)

    return held_by_bonds(run.n, run.bond_i, run.bond_j, _anchored(run))


def static_displacement(run, gravity=None):
    """Static displacement (n, 3) of the run's bond network under its weight (`gravity`, default run.gravity;
    dda.spheres.bond_network_static: normal and shear bond springs, the spheres held by bonds)."""
    from dda.spheres import bond_network_static  # lazy: numba (see the top)

    g = run.gravity if gravity is None else gravity
    return bond_network_static(run.centers, _mass(run), _anchored(run), run.bond_i, run.bond_j, run.bond_kn,
                               run.bond_ks, g)


def first_mode(run):
    """(omega [rad/s], mean mass [kg]) of the run's first mode (dda.spheres.first_mode)."""
    from dda.spheres import first_mode as network_first_mode  # lazy: numba (see the top)

    return network_first_mode(run.centers, _mass(run), _anchored(run), run.bond_i, run.bond_j, run.bond_kn,
                              run.bond_ks, run.gravity)


def viscous_coefficient(run, value):
    """c [N s/m] of a force -c v on every free sphere that damps the run's first mode (first_mode) at the ratio
    of critical damping `value` (a number, or "critical" = 1): c = 2 zeta m_mean omega_1. ValueError (a message
    for the user) when the value is not a ratio or the model has no first mode."""
    from dda.spheres import viscous_coefficient as network_coefficient  # lazy: numba (see the top)

    return network_coefficient(damping_ratio(value), run.centers, _mass(run), _anchored(run), run.bond_i,
                               run.bond_j, run.bond_kn, run.bond_ks, run.gravity)


def _set_loads(run, force, prescribed, velocity):
    """Check and store the loads of a run (SpecError for wrong shapes, non-finite values, fixed + prescribed)."""
    n, where = run.n, run.source or "model"
    try:
        f = np.broadcast_to(np.asarray(0.0 if force is None else force, float), (n, 3)).copy()
        p = np.broadcast_to(np.asarray(False if prescribed is None else prescribed, bool), (n,)).copy()
        v = np.broadcast_to(np.asarray(0.0 if velocity is None else velocity, float), (n, 3)).copy()
    except ValueError:
        raise SpecError(f"{where}: force and velocity must be (n, 3) or (3,), prescribed (n,) for n = {n} "
                        "spheres") from None
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(v))):
        raise SpecError(f"{where}: sphere forces and velocities must be finite")
    if np.any(p & run.fixed):
        raise SpecError(f"{where}: {int((p & run.fixed).sum())} spheres are both fixed and prescribed")
    run.force, run.prescribed, run.velocity = f, p, np.where(p[:, None], v, 0.0)


def from_scene(path, max_steps=None, duration=None, dt=None, limit_steps=True):
    """SphereRun of a DDA scene file with [spheres] (its [simulation], [contact] and [spheres] keys; a scene
    with blocks is refused: decks carry spheres only, fixed regions stand in for walls).

    The run's steps at `duration` and `dt` (the --duration and --dt overrides; default the scene's) are checked
    against the step limit (`max_steps`, the --max-steps value, else the scene's; :func:`check_steps`) unless
    `limit_steps` is false (exports that run nothing: pfc-text, vtu)."""
    from dda.scene import load_scene  # lazy: numba (see the top)

    scene = load_scene(path)
    if not scene.spheres:
        raise SceneError(Path(path), "spheres", None, "a sphere deck needs a scene with [spheres] (a model)")
    if scene.blocks:
        raise SceneError(Path(path), "block", len(scene.blocks),
                         "sphere decks carry spheres only: use [spheres] fixed regions instead of blocks")
    sp = scene.spheres
    model = sp["model"]
    fixed = scene.fixed_spheres(model.centers)
    force, prescribed, velocity = scene.sphere_loads(model.centers)
    law = scene.law
    try:
        run = from_model(model, density=sp["density"], fixed=fixed, bonds=sp["bonds"], kn=law.kn, ks=law.ks,
                         friction_deg=law.friction_deg, damping=law.damping,
                         joint_friction_deg=sp.get("joint_friction"), smooth_joints=sp.get("smooth_joints", True),
                         gravity=scene.gravity, dt=dt or scene.dt, safety=scene.safety, duration=scene.duration,
                         record_every=scene.record_every, local_damping=scene.local_damping, name=scene.name,
                         source=str(path), force=force, prescribed=prescribed, velocity=velocity)
    except SpecError as exc:
        raise SceneError(Path(path), "spheres.model", sp.get("path"), str(exc).split(": ", 1)[-1]) from None
    run.liggghts_joints = sp.get("liggghts_joints", "contact")
    if open_joint_problem(run):
        raise SceneError(Path(path), "spheres.liggghts_joints", "open", open_joint_problem(run))
    vd = getattr(scene, "viscous_damping", 0.0)
    if vd:
        try:
            run.viscous_damping = viscous_coefficient(run, vd)
        except ValueError as exc:
            raise SceneError(Path(path), "simulation.viscous_damping", vd, str(exc)) from None
    if limit_steps and all(v is None or v > 0 for v in (duration, dt)):  # bad overrides: _apply_overrides
        check_steps(run, path, max_steps, scene=scene, duration=duration, dt=dt)
    return run


def check_steps(run, path, max_steps=None, scene=None, duration=None, dt=None):
    """SceneError (one line, dda/limits.py) when the deck's steps, `duration` / `dt` (the --duration / --dt
    overrides, default the run's), pass the step limit: `max_steps` (--max-steps), else the DDA scene's
    [simulation] max_steps, else dda.limits.DEFAULT_MAX_STEPS. With the DDA `scene` the message names its keys
    (simulation.duration, simulation.dt or the stiffness that sets the critical step); otherwise --duration and
    --dt (a model or run.npz has no scene keys). Returns the steps."""
    dur = float(run.duration if duration is None else duration)
    step = float(run.dt if dt is None else dt)
    dkey = "--duration" if duration is not None or scene is None else "simulation.duration"
    kw = dict(max_steps=max_steps, scene=scene, duration_key=dkey, raise_limit=None if scene is not None
              else "raise --max-steps")
    if dt is not None or scene is None:
        return check(path, dur, step, dt_key="--dt", dt_value=step, auto_dt=False, **kw)
    if scene.dt is not None:
        return check(path, dur, step, dt_key="simulation.dt", dt_value=scene.dt, auto_dt=False, **kw)
    bkey, bval = sphere_bond_key(scene)
    key, value = sphere_dt_source(run.kn, run.ks, run.n, run.bond_i, run.bond_j, run.bond_kn, run.bond_ks, bkey, bval)
    return check(path, dur, step, dt_key=key, dt_value=value, auto_dt=True, dt_crit=step / scene.safety,
                 safety=scene.safety, **kw)


__all__ = ["LIGGGHTS_JOINTS", "NOT_RUN_KEYS", "SphereRun", "SpecError", "check_run", "check_steps", "damping_ratio",
           "first_mode", "from_model", "from_scene", "held_spheres", "joint_pairs", "liggghts_only",
           "static_displacement", "viscous_coefficient"]
