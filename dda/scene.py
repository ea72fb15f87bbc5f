"""DDA scene files (TOML): parsing and validation into blocks, materials, contact laws and run settings.

Every problem raises :class:`sgim.common.SceneError` (one line naming file, key and value; read through
sgim/reader.py) before anything is written. Keys::

    name = "incline"
    [simulation]   duration (s, required), dt (0 or absent: automatic), safety = 0.5, gravity = [0, 0, -9.81],
                   local_damping = 0.0, viscous_damping = 0.0 (sphere decks: a force -c v on every sphere, c
                   for this ratio of critical damping of the model's first mode, or "critical"; LIGGGHTS' fix
                   viscous, the in-house engine's too; YADE lists it as not represented), record_every (default
                   duration / 100), frames = 20 (VTU frames),
                   sleep = false (resting blocks stop being integrated), sleep_velocity (m/s), sleep_accel
                   (m/s2), sleep_steps = 200 (see dda/simulation.py for the defaults), max_steps = 1e8 (a run
                   whose duration / dt passes it is refused before it starts; dda/limits.py)
    [limits]       max_steps: the same limit in the table sgim scenes use for theirs (give one of the two)
    [contact]      default law: kn (N/m per contact point, required), ks (default kn / 2), friction (deg),
                   cohesion (Pa), tensile (Pa), damping (ratio of critical)
    [[material]]   name, density (kg/m3) = 2600, E = 1e10, nu = 0.25
    [[contact_pair]]  materials = ["a", "b"] and any [contact] key: the law between those two materials
    [[block]]      one of: shape = "cube" + size (+ center, rotation_axis, rotation_angle, width, height, sides);
                   vertices + faces (0-based, counter-clockwise seen from outside); file = "mesh.stl" (convex);
                   and name, fixed, material, velocity, angular_velocity, prescribed = false (move at the
                   given velocity / angular velocity whatever the forces), force = [fx, fy, fz] (constant
                   body load at the centroid, N), dof = 6 (rigid) or 12 (deformable: six constant strains,
                   E and nu of its material; see dda/_deform.py)
    [[load]]       block = "name", force = [fx, fy, fz] (N, world), point = [x, y, z] (world, initial pose;
                   absent: the centroid): a constant point load
    [[generate]]   kind = one of dda.generate.GENERATORS, the other keys are its parameters
    [spheres]      model = "model.npz" (an sgim model) or "beam.toml" (an sgim scene, built in memory),
                   relative to the scene; density = 2600, fixed = ["z>2.6"]
                   (regions of fixed spheres), bond_young (Pa) = 1e9 or bond_kn / bond_ks (N/m), bond_shear_ratio
                   = 0.4 (0, or bond_ks = 0: central bonds, the normal spring only), bond_tensile / bond_shear
                   (Pa, default unbreakable), bond_damping, bond_radius_factor = 1;
                   fixed_below = [[dip, dip_direction, x, y, z], ...] (spheres below any of these planes are
                   fixed), smooth_joints = true (pairs the model cuts by a zero-thickness joint slide on the joint
                   plane: contact normal = joint normal), joint_friction (deg, default [contact] friction),
                   liggghts_joints = "contact" (LIGGGHTS decks only, which have no smooth joint: the joint pairs
                   are plain contacts) or "open" (no contact between the two sides of a joint: exact while the
                   joints stay open; see adapters/liggghts.py);
                   [[spheres.load]] tables load a region of spheres: region = "z>2.6" (or a list of such cuts,
                   all of which must hold) or below = [dip, dip_direction, x, y, z], and exactly one of
                   force = [fx, fy, fz] (a constant force on EACH sphere of the region, N; the forces of
                   overlapping force loads add up) or velocity = [vx, vy, vz] (m/s: the region's spheres move
                   at this velocity whatever the forces, without turning, e.g. a platen); a region without a
                   sphere, a fixed sphere in a loaded region, or a prescribed sphere under a second load is an
                   error; only the model's bonded pairs get bonds; [contact] is the sphere contact law (sphere-sphere,
                   sphere-block and, with [[contact_pair]], block-block); blocks are fixed walls or moving
                   blocks stepped in one loop with the spheres (see dda/spheres.py, dda/_coupled.py)
    [[report]]     quantity (displacement, velocity, rotation, shortening, max_displacement, moved,
                   bonds_broken, detached, energy_error), block or region, component, reference, label: the
                   answers the run states at its end and in summary.json (dda/answers.py)
    [output]       formats = ["npz", "csv", "vtu", "png"]
    [render]       width = 1600, height = 1100
"""
from __future__ import annotations

import difflib
import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sgim.common import SceneError
from sgim.geometry import MAX_COORD, MIN_LENGTH, dip_to_normal
from sgim.model import SphereModel
from sgim.readback import BadFile
from sgim.reader import COORD, SIZE, SceneReader, read_toml
from sgim.scene import load_scene as load_sgim_scene
from sgim.scene import parse_cut, read_limits

from .answers import read_reports
from .blockspec import BlockSpec
from .generate import GENERATORS
from .limits import check_block_run, check_sphere_run
from .polyhedra import PolyhedronError, check_convex, half_edges
from .regions import SphereLoadError, fixed_mask, load_region, read_region_cuts, sphere_load_arrays
from .shapes import SHAPES, GeometryError, load_convex_mesh, rotation_about, shape
from .simulation import ContactLaw, Simulation
from .spheres import BondLaw, SphereSimulation, load_model, viscous_coefficient
from .system import BlockSystem

OUTPUT_FORMATS = ("npz", "csv", "vtu", "png")
TOP_KEYS = {"name", "description", "simulation", "contact", "material", "contact_pair", "block", "generate",
            "output", "render", "load", "spheres"}
TOP_KEYS |= {"limits"}  # [limits] max_steps: the same as [simulation] max_steps (dda/limits.py)
TOP_KEYS |= {"report"}  # [[report]]: the answers the run states (dda/answers.py)
SPHERE_KEYS = {"model", "density", "fixed", "bond_young", "bond_kn", "bond_ks", "bond_shear_ratio", "bond_tensile",
               "bond_shear", "bond_damping", "bond_radius_factor", "joint_friction", "smooth_joints", "fixed_below"}
SPHERE_KEYS |= {"load"}  # [[spheres.load]]: loaded regions (constant force or prescribed velocity)
SPHERE_KEYS |= {"liggghts_joints"}  # LIGGGHTS decks only: joint pairs as plain contacts or without contact
LIGGGHTS_JOINTS = ("contact", "open")
SIMULATION_KEYS = {"duration", "dt", "safety", "gravity", "local_damping", "record_every", "frames", "sleep",
                   "sleep_velocity", "sleep_accel", "sleep_steps", "max_steps"}
SIMULATION_KEYS |= {"viscous_damping"}  # sphere decks: -c v on every sphere (LIGGGHTS fix viscous; adapters/spec.py)
SPHERE_LOAD_KEYS = {"region", "below", "force", "velocity"}
LAW_KEYS = {"kn", "ks", "friction", "cohesion", "tensile", "damping"}
# Numerical guards far beyond any rock or engine setting (the resource limits refuse the long runs that stiff or
# light settings ask for, dda/limits.py): beyond these the critical time step, masses and energies over- or
# underflow.
STIFFNESS = {"lo": 1e-20, "hi": 1e40, "unit": " N/m"}  # contact and bond stiffness
MODULUS = {"lo": 1e-20, "hi": 1e40, "unit": " Pa"}  # Young's modulus of blocks and bonds
DENSITY = {"lo": 1e-20, "hi": 1e40, "unit": " kg/m3"}
DURATION = {"hi": 1e12, "unit": " s"}  # 30 000 years: steps = duration / dt stay finite
RATIO = {"hi": 1e3, "unit": ""}  # dimensionless factors (bond shear / normal stiffness, bond radius)

# The defaults of the optional keys, in one table (key path -> value; docs/scenes.md lists them, dda/scenedoc.py).
# Scene-dependent defaults stay in the reader: simulation.record_every = duration / 100, [contact] ks = kn / 2,
# spheres.joint_friction = [contact] friction; [contact] (kn required) and [[contact_pair]] take the defaults of
# dda.simulation.ContactLaw (friction 30 deg, no cohesion, tensile strength or damping) resp. of [contact].
DEFAULTS = {
    "simulation.dt": 0.0,  # s; 0: automatic
    "simulation.safety": 0.5,
    "simulation.gravity": (0.0, 0.0, -9.81),  # m/s2
    "simulation.local_damping": 0.0,
    "simulation.viscous_damping": 0.0,
    "simulation.frames": 20,
    "simulation.sleep": False,
    "material[].density": 2600.0,  # kg/m3
    "material[].E": 1e10,  # Pa
    "material[].nu": 0.25,
    "block[].fixed": False,
    "block[].material": "rock",
    "block[].velocity": (0.0, 0.0, 0.0),  # m/s
    "block[].angular_velocity": (0.0, 0.0, 0.0),  # rad/s
    "block[].prescribed": False,
    "block[].force": (0.0, 0.0, 0.0),  # N
    "block[].center": (0.0, 0.0, 0.0),  # m
    "block[].rotation_axis": (0.0, 0.0, 1.0),
    "spheres.density": 2600.0,  # kg/m3
    "spheres.bond_young": 1e9,  # Pa
    "spheres.bond_shear_ratio": 0.4,
    "spheres.bond_tensile": float("inf"),  # Pa: unbreakable
    "spheres.bond_shear": float("inf"),  # Pa: unbreakable
    "spheres.bond_damping": 0.0,
    "spheres.bond_radius_factor": 1.0,
    "render.width": 1600,  # pixels
    "render.height": 1100,  # pixels
}
D = DEFAULTS  # the short name the reader below uses


@dataclass
class Material:
    name: str
    density: float = DEFAULTS["material[].density"]
    E: float = DEFAULTS["material[].E"]
    nu: float = DEFAULTS["material[].nu"]


@dataclass
class DDAScene:
    path: Path
    text: str
    name: str
    blocks: list  # BlockSpec
    materials: dict
    law: ContactLaw
    pair_laws: dict
    duration: float
    dt: float | None
    safety: float
    gravity: np.ndarray
    local_damping: float
    record_every: float
    frames: int
    formats: tuple
    width: int = DEFAULTS["render.width"]
    height: int = DEFAULTS["render.height"]
    sources: list = field(default_factory=list)  # scene key that produced each block
    loads: list = field(default_factory=list)  # (block index, world point or None, force)
    sleep: dict = field(default_factory=dict)  # Simulation sleep keywords
    spheres: dict = field(default_factory=dict)  # [spheres]: model path, density, BondLaw, fixed regions
    max_steps: int | None = None  # [simulation] max_steps or [limits] max_steps (None: dda.limits default)
    max_steps_key: str = "simulation.max_steps"
    reports: list = field(default_factory=list)  # [[report]]: dda.answers.Report (empty: the default answers)
    viscous_damping: float | str = 0.0  # [simulation] viscous_damping: ratio of critical of the first mode, or
    # "critical" (sphere runs)
    # the keys of the run settings that the step limit's message names (dda/limits.py check_block_run) where they
    # are not [simulation]'s: "duration", "dt", and "raise_limit" (the remedy's wording); dda/georun.py's own
    run_keys = {}

    def stiffness_keys(self):
        """[(key, kn)] of the block stiffnesses in the run: [contact] kn and each [[contact_pair]] kn (dda/limits.py
        names the largest when it sets a time step past the step limit)."""
        return [("contact.kn", float(self.law.kn))] + [
            (f"contact_pair[{k}].kn", float(law.kn)) for k, law in enumerate(self.pair_laws.values())]

    def build_spheres(self, max_steps=None, duration=None):
        """SphereSet and SphereSimulation of a scene with [spheres] (its blocks are fixed walls).

        SceneError when `duration` (default the scene's) at the run's dt passes the step limit (`max_steps`,
        the --max-steps value, else the scene's; dda/limits.py)."""
        sp = self.spheres
        ss = load_model(sp["model"], density=sp["density"], bonds=sp["bonds"])
        ss.fixed |= self.fixed_spheres(ss.centers)
        if sp.get("loads"):  # [[spheres.load]]: constant forces and prescribed velocities
            force, prescribed, velocity = self.sphere_loads(ss.centers)
            ss.body_force += force
            ss.prescribed |= prescribed
            ss.velocity[prescribed] = velocity[prescribed]
        moving = not all(getattr(b, "fixed", False) for b in self.blocks)
        if sp.get("smooth_joints", True) and hasattr(sp["model"], "joint_pairs"):
            # pairs cut by a zero-thickness joint slide on the joint plane (smooth joints)
            cut, _, normal = sp["model"].joint_pairs()
            if len(cut):
                pairs = np.asarray(sp["model"].bonds, np.int64).reshape(-1, 2)[cut]
                ss.add_joints(pairs, normal, sp.get("joint_friction", self.law.friction_deg))
        walls = self.blocks
        if moving:
            walls = self.block_system()  # moving blocks: one coupled loop with the spheres
        visc = 0.0
        if self.viscous_damping:  # a ratio of critical damping of the first mode -> c [N s/m]
            try:
                zeta = 1.0 if self.viscous_damping == "critical" else float(self.viscous_damping)
                visc = viscous_coefficient(zeta, ss.centers, ss.mass, ss.fixed | ss.prescribed, ss.bond_i,
                                           ss.bond_j, ss.bond_kn, ss.bond_ks, self.gravity)
            except ValueError as exc:
                raise SceneError(self.path, "simulation.viscous_damping", self.viscous_damping, str(exc)) from None
        sim = SphereSimulation(ss, self.law, walls=walls, gravity=self.gravity, dt=self.dt, safety=self.safety,
                               local_damping=self.local_damping, pair_laws=self.pair_laws, viscous_damping=visc)
        check_sphere_run(self, ss, sim, max_steps=max_steps, duration=duration)
        return ss, sim

    def fixed_spheres(self, centers):
        """The [spheres] fixed flags of spheres at `centers`: inside a fixed region ("z>2.6") or below a
        fixed_below plane (dip, dip direction, a point of the plane)."""
        return fixed_mask(centers, self.spheres["fixed"], self.spheres.get("fixed_below", ()))

    def sphere_loads(self, centers):
        """(force (n, 3) [N], prescribed (n,) bool, velocity (n, 3) [m/s]) of the [[spheres.load]] tables for
        spheres at `centers`: the summed constant force of the force loads whose region holds a sphere, and the
        prescribed flag and velocity of the velocity loads (zero elsewhere)."""
        return sphere_load_arrays(self.spheres.get("loads", ()), centers, self.fixed_spheres(centers))

    def block_system(self):
        """BlockSystem of the scene's blocks (materials, body and point loads)."""
        bs = BlockSystem()
        for spec in self.blocks:
            m = self.materials.get(spec.material) or Material(spec.material)
            i = bs.add_block(spec, density=m.density, E=m.E, nu=m.nu)
            f = getattr(spec, "body_force", None)
            if f is not None and np.any(np.asarray(f) != 0):
                bs.add_body_load(i, f)
        for i, point, force in self.loads:
            if point is None:
                bs.add_body_load(i, force)
            else:
                bs.add_point_load(i, point, force)
        return bs

    def build(self, max_steps=None, duration=None, check=True):
        """BlockSystem and Simulation of the scene.

        SceneError when `duration` (default the scene's) at the run's dt passes the step limit (`max_steps`,
        the --max-steps value, else the scene's; dda/limits.py); `check` false: no step check (the caller
        makes its own)."""
        bs = self.block_system()

        def step_check(sim):
            check_block_run(self, sim, max_steps=max_steps, duration=duration)

        sim = Simulation(bs, self.law, gravity=self.gravity, dt=self.dt, safety=self.safety,
                         local_damping=self.local_damping, pair_laws=self.pair_laws,
                         on_dt=step_check if check else None, **self.sleep)
        return bs, sim


def _read_sphere_loads(rd, raw, centers, fixed):
    """[[spheres.load]] tables: parsed, and checked on the model's spheres."""
    if not isinstance(raw, list) or any(not isinstance(t, dict) for t in raw):
        rd.err("spheres.load", raw, "must be an array of tables ([[spheres.load]])")
    loads = []
    for k, lt in enumerate(raw):
        key = f"spheres.load[{k}]"
        rd.known(lt, SPHERE_LOAD_KEYS, key)
        where = [w for w in ("region", "below") if w in lt]
        if len(where) != 1:
            rd.err(key, sorted(lt), 'give exactly one of: region = "z>2.6", below = [dip, dip_direction, x, y, z]')
        what = [w for w in ("force", "velocity") if w in lt]
        if len(what) != 1:
            rd.err(key, sorted(lt), "give exactly one of: force = [fx, fy, fz] (N on each sphere), "
                                    "velocity = [vx, vy, vz] (m/s, prescribed)")
        if where[0] == "region":
            region = ("region", read_region_cuts(rd, lt["region"], f"{key}.region"))
        else:
            row = rd.vector(lt, "below", f"{key}.below", n=5, **COORD)
            if not (0.0 <= row[0] <= 90.0 and -360.0 <= row[1] <= 360.0):
                rd.err(f"{key}.below", row.tolist(), "dip must be 0..90 and dip direction -360..360 deg")
            region = ("below", (np.asarray(dip_to_normal(row[0], row[1]), float), np.asarray(row[2:5], float)))
        vec = rd.vector(lt, what[0], f"{key}.{what[0]}")
        loads.append({"key": key, "kind": what[0], "value": vec, "region": region, "where": where[0],
                      "shown": lt[where[0]]})
    try:
        sphere_load_arrays(loads, centers, fixed)
    except SphereLoadError as exc:
        rd.err(exc.key, exc.value, str(exc))
    return loads


def _read_spheres(rd, data, path):
    """[spheres] model = "model.npz" or an sgim scene "x.toml" (built in memory; relative to the scene), density, fixed = ["z>2.6"], bond_* keys."""
    if "spheres" not in data:
        return {}
    st = rd.table(data, "spheres", "spheres")
    rd.known(st, SPHERE_KEYS, "spheres")
    name = rd.string(st, "model", "spheres.model", "")
    if not name:
        rd.err("spheres.model", name, "missing: the path of an sgim model.npz or scene .toml")
    mp = Path(name) if Path(name).is_absolute() else Path(path).parent / name
    if not mp.is_file():
        rd.err("spheres.model", name, f"no such file ({mp})")
    fixed = rd.value(st, "fixed", "spheres.fixed", [], "list of strings")
    if not isinstance(fixed, list):
        rd.err("spheres.fixed", fixed, 'must be a list like ["z>2.6"]')
    regions = []
    for e in fixed:
        try:
            regions.append(parse_cut(e))
        except ValueError as exc:
            rd.err("spheres.fixed", e, str(exc))
    law = BondLaw(
        young=rd.number(st, "bond_young", "spheres.bond_young", default=D["spheres.bond_young"], positive=True,
                        **MODULUS),
        kn=rd.number(st, "bond_kn", "spheres.bond_kn", positive=True, **STIFFNESS) if "bond_kn" in st else None,
        ks=rd.number(st, "bond_ks", "spheres.bond_ks", nonneg=True, hi=STIFFNESS["hi"], unit=STIFFNESS["unit"])
        if "bond_ks" in st else None,
        shear_ratio=rd.number(st, "bond_shear_ratio", "spheres.bond_shear_ratio",
                              default=D["spheres.bond_shear_ratio"], nonneg=True, **RATIO),
        tensile=rd.number(st, "bond_tensile", "spheres.bond_tensile", default=D["spheres.bond_tensile"], nonneg=True),
        shear=rd.number(st, "bond_shear", "spheres.bond_shear", default=D["spheres.bond_shear"], nonneg=True),
        damping=rd.number(st, "bond_damping", "spheres.bond_damping", default=D["spheres.bond_damping"], nonneg=True,
                          hi=1.0),
        radius_factor=rd.number(st, "bond_radius_factor", "spheres.bond_radius_factor",
                                default=D["spheres.bond_radius_factor"], positive=True, **RATIO),
    )
    if mp.suffix.lower() == ".toml":  # an sgim scene: build its model in memory
        from sgim.builder import build_model  # not at the top: the builder's kernels, for .toml models only

        model = build_model(load_sgim_scene(mp))  # a bad sgim scene raises its own one-line SceneError
    else:
        try:
            model = SphereModel.load(mp)  # validated: a file that is not a usable model is one BadFile line
        except BadFile as exc:
            rd.err("spheres.model", name, exc.what)
    density = rd.number(st, "density", "spheres.density", default=D["spheres.density"], positive=True, **DENSITY)
    below = []
    if "fixed_below" in st:
        rows = rd.matrix(st, "fixed_below", "spheres.fixed_below", 5, **COORD)
        for row in rows:
            if not (0.0 <= row[0] <= 90.0 and -360.0 <= row[1] <= 360.0):
                rd.err("spheres.fixed_below", row.tolist(), "dip must be 0..90 and dip direction -360..360 deg")
            below.append((np.asarray(dip_to_normal(row[0], row[1]), float), np.asarray(row[2:5], float)))
    out = {"model": model, "path": str(mp), "density": density, "bonds": law, "fixed": regions,
           "fixed_below": below,
           "smooth_joints": rd.boolean(st, "smooth_joints", "spheres.smooth_joints", True)}
    if "joint_friction" in st:
        out["joint_friction"] = rd.number(st, "joint_friction", "spheres.joint_friction", lo=0.0, hi=89.9)
    out["liggghts_joints"] = rd.choice(st, "liggghts_joints", "spheres.liggghts_joints", LIGGGHTS_JOINTS, "contact")
    if out["liggghts_joints"] == "open" and not out["smooth_joints"]:
        rd.err("spheres.liggghts_joints", "open", "stands in for smooth joints: needs spheres.smooth_joints = true")
    if "load" in st:
        c = np.asarray(model.centers, float).reshape(-1, 3)
        out["loads"] = _read_sphere_loads(rd, st["load"], c, fixed_mask(c, regions, below))
    return out


GENERATOR_SIZES = {"size", "height", "b", "h", "depth", "base_length", "base_thickness", "brick", "projectile",
                   "spacing", "side", "clearance", "gap", "run", "margin", "hit_height",
                   "floor_margin"}  # [[generate]] lengths [m]


def generator_parameters(fn):
    """The parameters a scene may give a [[generate]] function (its progress callback is the run's)."""
    return [p for p, s in inspect.signature(fn).parameters.items()
            if s.kind in (s.POSITIONAL_OR_KEYWORD, s.KEYWORD_ONLY) and p != "progress"]


def _generator_types(rd, fn, params, key):
    """A [[generate]] parameter whose default is a number, a string, a flag or a list of numbers must be given as
    one, and an optional length (default None) as a number (the generators would convert "13" to 13 without a
    word)."""
    sig = inspect.signature(fn).parameters
    allowed = generator_parameters(fn)
    for p, v in params.items():
        if p not in allowed:
            near = difflib.get_close_matches(p, allowed, n=1)
            rd.err(f"{key}.{p}", v, (f"unknown parameter (did you mean {near[0]!r}?); " if near else
                                     "unknown parameter; ") + f"{fn.__name__} takes: {', '.join(allowed)}")
        d = sig[p].default
        num = isinstance(v, (int, float)) and not isinstance(v, bool)
        if isinstance(d, bool):
            if not isinstance(v, bool):
                rd.err(f"{key}.{p}", v, "must be true or false")
        elif isinstance(d, (int, float)):
            if not num:
                rd.err(f"{key}.{p}", v, "must be a number")
        elif isinstance(d, str):
            if not isinstance(v, str):
                rd.err(f"{key}.{p}", v, "must be a string")
        elif d is None and p in GENERATOR_SIZES:
            if not num:  # an optional length (None: the generator's own choice)
                rd.err(f"{key}.{p}", v, "must be a number (m)")
        elif d is None and p.endswith("material"):
            if not isinstance(v, str):  # an optional material name (None: the block's own material)
                rd.err(f"{key}.{p}", v, "must be a string (a material name)")
        elif isinstance(d, (tuple, list)) and d and all(isinstance(x, (int, float)) for x in d):
            if not (isinstance(v, list) and len(v) == len(d)
                    and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
                rd.err(f"{key}.{p}", v, f"must be a list of {len(d)} numbers")


def _generator_numbers(rd, value, key, seed=False):
    """Every number of a [[generate]] parameter (lists and tables included) is finite and, but for a seed, within
    +-MAX_COORD: the generators take lengths, coordinates, angles and counts."""
    if isinstance(value, dict):
        for k, v in value.items():
            _generator_numbers(rd, v, f"{key}.{k}", seed)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _generator_numbers(rd, v, f"{key}[{i}]", seed)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        rd.check_number(value, key)
        if not seed and abs(value) > MAX_COORD:
            rd.err(key, value, f"must be within +-{MAX_COORD:g} (lengths and coordinates in m, angles in degrees, "
                               "counts)")
        if key.split(".")[-1].split("[")[0] in GENERATOR_SIZES and 0 < abs(value) < MIN_LENGTH:
            rd.err(key, value, f"must be 0 or at least {MIN_LENGTH:g} m (a size)")


def _law(rd, tab, key, base=None):
    rd.known(tab, LAW_KEYS | ({"materials"} if base is not None else set()), key)
    b = base or ContactLaw(kn=None)
    kn = rd.number(tab, "kn", f"{key}.kn", default=b.kn, positive=True, **STIFFNESS) \
        if (base is not None or "kn" in tab) else rd.number(tab, "kn", f"{key}.kn", positive=True, **STIFFNESS)
    ks_default = b.ks if base is not None and b.ks is not None else kn / 2
    return ContactLaw(
        kn=kn,
        ks=rd.number(tab, "ks", f"{key}.ks", default=ks_default, positive=True, **STIFFNESS),
        friction_deg=rd.number(tab, "friction", f"{key}.friction", default=b.friction_deg, lo=0.0, hi=89.9),
        cohesion=rd.number(tab, "cohesion", f"{key}.cohesion", default=b.cohesion, nonneg=True),
        tensile=rd.number(tab, "tensile", f"{key}.tensile", default=b.tensile, nonneg=True),
        damping=rd.number(tab, "damping", f"{key}.damping", default=b.damping, nonneg=True, hi=1.0),
    )


def load_scene(path) -> DDAScene:
    """The validated DDAScene of the scene file `path` (blocks, materials, contact laws, [spheres], run
    settings); any problem raises SceneError (sgim/common.py) naming the file, key and value."""
    path = Path(path)
    data, text = read_toml(path)
    return scene_from_dict(data, path, text)


def scene_from_dict(data, path="<scene>", text="", reader=None) -> DDAScene:
    """The validated DDAScene of a parsed scene file; `reader(path)` makes the value reader (default
    sgim.reader.SceneReader; dda/scenedoc.py passes one that records what is read)."""
    path = Path(path)
    rd = (reader or SceneReader)(path)
    rd.known(data, TOP_KEYS, "")
    name = rd.string(data, "name", "name", path.stem)

    sim = _read_simulation(rd, data)

    ct = rd.table(data, "contact", "contact", required=True)
    law = _law(rd, ct, "contact")

    materials = {}
    for k, mt in enumerate(rd.list_of_tables(data, "material")):
        key = f"material[{k}]"
        rd.known(mt, {"name", "density", "E", "nu"}, key)
        mname = rd.string(mt, "name", f"{key}.name", "")
        if not mname:
            rd.err(f"{key}.name", mname, "missing material name")
        if mname in materials:
            rd.err(f"{key}.name", mname, "material defined twice")
        materials[mname] = Material(mname, rd.number(mt, "density", f"{key}.density", default=D["material[].density"],
                                                     positive=True, **DENSITY),
                                    rd.number(mt, "E", f"{key}.E", default=D["material[].E"], positive=True, **MODULUS),
                                    rd.number(mt, "nu", f"{key}.nu", default=D["material[].nu"], lo=0.0, hi=0.4999))
    pair_laws = {}
    for k, pt in enumerate(rd.list_of_tables(data, "contact_pair")):
        key = f"contact_pair[{k}]"
        mats = pt.get("materials")
        if not (isinstance(mats, list) and len(mats) == 2 and all(isinstance(m, str) for m in mats)):
            rd.err(f"{key}.materials", mats, 'must be two material names, e.g. ["rock", "joint"]')
        pair_laws[tuple(mats)] = _law(rd, pt, key, base=law)

    blocks, sources = [], []
    for k, bt in enumerate(rd.list_of_tables(data, "block")):
        blocks.append(_read_block(rd, bt, f"block[{k}]", path))
        sources.append(f"block[{k}]")
    for k, gt in enumerate(rd.list_of_tables(data, "generate")):
        key = f"generate[{k}]"
        kind = gt.get("kind")
        if kind not in GENERATORS:
            rd.err(f"{key}.kind", kind, f"must be one of {', '.join(sorted(GENERATORS))}")
        params = {p: v for p, v in gt.items() if p != "kind"}
        _generator_types(rd, GENERATORS[kind], params, key)
        for p, v in params.items():
            _generator_numbers(rd, v, f"{key}.{p}", seed=p == "seed")
        try:
            made = GENERATORS[kind](**params)
        except TypeError as exc:
            rd.err(key, sorted(params), f"bad parameters for {kind!r} ({exc})")
        except (ValueError, ArithmeticError) as exc:
            rd.err(key, sorted(params), str(exc).split("\n")[0])
        blocks.extend(made)
        sources.extend([key] * len(made))
    spheres = _read_spheres(rd, data, path)
    if not blocks and not spheres:
        rd.err("block", None, "the scene has no blocks (give [[block]] or [[generate]] tables)")
    for spec, src in zip(blocks, sources):
        try:
            half_edges(len(spec.vertices), spec.faces)
            check_convex(spec.vertices, spec.faces)
        except PolyhedronError as exc:
            rd.err(src, spec.name or "(block)", str(exc))
        if spec.material not in materials and spec.material != "rock":
            rd.err(f"{src}.material", spec.material, f"no [[material]] named so (have: {', '.join(materials) or 'none'})")
        if int(getattr(spec, "dof", 6)) not in (6, 12):
            rd.err(f"{src}.dof", spec.dof, "must be 6 (rigid) or 12 (deformable)")
        if int(getattr(spec, "dof", 6)) == 12 and getattr(spec, "prescribed", False):
            rd.err(f"{src}.dof", spec.dof, "a deformable block (dof = 12) cannot be prescribed")
    for (m1, m2) in pair_laws:
        for m in (m1, m2):
            if m not in materials and m != "rock":
                rd.err("contact_pair", m, "unknown material")
    if spheres:
        pass  # blocks with spheres: fixed walls, or moving blocks stepped with the spheres (dda/_coupled.py)
    elif all(getattr(b, "fixed", False) for b in blocks):
        rd.err("block", len(blocks), "every block is fixed: nothing would move")
    for spec, src in zip(blocks, sources):
        if getattr(spec, "prescribed", False) and spec.fixed:
            rd.err(f"{src}.prescribed", True, "a block cannot be both fixed and prescribed")
    names = {}
    for k, spec in enumerate(blocks):
        names.setdefault(spec.name, k)
    loads = []
    for k, lt in enumerate(rd.list_of_tables(data, "load")):
        key = f"load[{k}]"
        rd.known(lt, {"block", "force", "point"}, key)
        bname = rd.string(lt, "block", f"{key}.block", "")
        if bname not in names:
            rd.err(f"{key}.block", bname, "no block of that name")
        force = rd.vector(lt, "force", f"{key}.force")
        point = rd.vector(lt, "point", f"{key}.point", **COORD) if "point" in lt else None
        loads.append((names[bname], point, force))

    reports = read_reports(rd, data, [b.name for b in blocks], bool(spheres))
    ot = rd.table(data, "output", "output")
    rd.known(ot, {"formats"}, "output")
    formats = rd.value(ot, "formats", "output.formats", list(OUTPUT_FORMATS), "list of strings")
    if not isinstance(formats, list) or any(f not in OUTPUT_FORMATS for f in formats):
        rd.err("output.formats", formats, f"must be a list drawn from {', '.join(OUTPUT_FORMATS)}")
    rt = rd.table(data, "render", "render")
    rd.known(rt, {"width", "height"}, "render")
    return DDAScene(
        path=path, text=text, name=name, blocks=blocks, materials=materials, law=law, pair_laws=pair_laws,
        formats=tuple(formats),
        width=int(rd.number(rt, "width", "render.width", default=D["render.width"], lo=64, hi=8000)),
        height=int(rd.number(rt, "height", "render.height", default=D["render.height"], lo=64, hi=8000)),
        sources=sources, loads=loads, spheres=spheres, reports=reports, **sim)


def _read_simulation(rd, data):
    """The [simulation] table (and [limits] max_steps): the DDAScene keywords of the run settings."""
    st = rd.table(data, "simulation", "simulation", required=True)
    rd.known(st, SIMULATION_KEYS, "simulation")
    max_steps, max_steps_key = _max_steps(rd, data, st)
    sleep = {"sleep": rd.boolean(st, "sleep", "simulation.sleep", D["simulation.sleep"])}
    for k in ("sleep_velocity", "sleep_accel"):
        if k in st:
            sleep[k] = rd.number(st, k, f"simulation.{k}", positive=True)
    if "sleep_steps" in st:
        sleep["sleep_steps"] = int(rd.number(st, "sleep_steps", "simulation.sleep_steps", lo=2, hi=1e9))
    duration = rd.number(st, "duration", "simulation.duration", positive=True, **DURATION)
    dt = rd.number(st, "dt", "simulation.dt", default=D["simulation.dt"], nonneg=True) or None
    safety = rd.number(st, "safety", "simulation.safety", default=D["simulation.safety"], positive=True, hi=1.0)
    gravity = rd.vector(st, "gravity", "simulation.gravity", default=D["simulation.gravity"])
    local_damping = rd.number(st, "local_damping", "simulation.local_damping", default=D["simulation.local_damping"],
                              nonneg=True, hi=0.99)
    viscous_damping = D["simulation.viscous_damping"]
    if "viscous_damping" in st:
        vd = st["viscous_damping"]
        if isinstance(vd, str):
            if vd != "critical":
                rd.err("simulation.viscous_damping", vd, 'must be a ratio of critical damping or "critical"')
            viscous_damping = vd
        else:
            viscous_damping = rd.number(st, "viscous_damping", "simulation.viscous_damping", nonneg=True, hi=1e3)
    record_every = rd.number(st, "record_every", "simulation.record_every", default=duration / 100, positive=True)
    if record_every > duration:
        rd.err("simulation.record_every", record_every, f"must not exceed simulation.duration = {duration:g}")
    frames = int(rd.number(st, "frames", "simulation.frames", default=D["simulation.frames"], lo=1, hi=100000))
    return dict(duration=duration, dt=dt, safety=safety, gravity=gravity, local_damping=local_damping,
                record_every=record_every, frames=frames, sleep=sleep, max_steps=max_steps,
                max_steps_key=max_steps_key, viscous_damping=viscous_damping)


def _max_steps(rd, data, st):
    """(limit or None, key) from [simulation] max_steps or [limits] max_steps (not both)."""
    lim = read_limits(rd, data, {"max_steps"})
    if "max_steps" in st:
        if "max_steps" in lim:
            rd.err("limits.max_steps", lim["max_steps"], "give either [simulation] max_steps or [limits] "
                                                         "max_steps, not both")
        v = st["max_steps"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v) or v < 1:
            rd.err("simulation.max_steps", v, "must be a positive integer")
        return int(v), "simulation.max_steps"
    if "max_steps" in lim:
        return lim["max_steps"], "limits.max_steps"
    return None, "simulation.max_steps"


BLOCK_KEYS = {"name", "fixed", "material", "velocity", "angular_velocity", "prescribed", "force", "shape", "size", "center", "rotation_axis",
              "rotation_angle", "width", "height", "sides", "vertices", "faces", "file", "dof"}


def _read_block(rd, bt, key, scene_path):
    rd.known(bt, BLOCK_KEYS, key)
    fields = dict(
        name=rd.string(bt, "name", f"{key}.name", key),
        fixed=rd.boolean(bt, "fixed", f"{key}.fixed", D["block[].fixed"]),
        material=rd.string(bt, "material", f"{key}.material", D["block[].material"]),
        velocity=tuple(rd.vector(bt, "velocity", f"{key}.velocity", default=D["block[].velocity"])),
        angular_velocity=tuple(rd.vector(bt, "angular_velocity", f"{key}.angular_velocity",
                                         default=D["block[].angular_velocity"])),
        prescribed=rd.boolean(bt, "prescribed", f"{key}.prescribed", D["block[].prescribed"]),
        body_force=rd.vector(bt, "force", f"{key}.force", default=D["block[].force"]),
    )
    if "dof" in bt:
        dof = rd.number(bt, "dof", f"{key}.dof")
        if dof not in (6, 12):
            rd.err(f"{key}.dof", bt["dof"], "must be 6 (rigid) or 12 (deformable: six constant strains)")
        fields["dof"] = int(dof)
    forms = [f for f in ("shape", "vertices", "file") if f in bt]
    if len(forms) != 1:
        rd.err(key, sorted(bt), "give exactly one of: shape (+ size), vertices + faces, file")
    form = forms[0]
    if form == "shape":
        sname = rd.choice(bt, "shape", f"{key}.shape", SHAPES, None)
        size = rd.number(bt, "size", f"{key}.size", positive=True, **SIZE)
        centre = rd.vector(bt, "center", f"{key}.center", default=D["block[].center"], **COORD)
        kw = {}
        for extra in ("width", "height"):
            if extra in bt:
                kw[extra] = rd.number(bt, extra, f"{key}.{extra}", positive=True, **SIZE)
        if "sides" in bt:
            kw["sides"] = int(rd.number(bt, "sides", f"{key}.sides", lo=3, hi=64))
        rotation = None
        if "rotation_angle" in bt:
            axis = rd.vector(bt, "rotation_axis", f"{key}.rotation_axis", default=D["block[].rotation_axis"])
            if np.abs(axis).max() > 0:
                axis = axis / np.abs(axis).max()  # a direction: scaled first, so that its length cannot overflow
            if not np.linalg.norm(axis) > 0:
                rd.err(f"{key}.rotation_axis", axis.tolist(), "must not be the zero vector")
            rotation = rotation_about(axis, rd.number(bt, "rotation_angle", f"{key}.rotation_angle"))
        try:
            spec = shape(sname, size, center=centre, rotation=rotation, **kw)
        except (GeometryError, TypeError, ValueError) as exc:
            rd.err(f"{key}.shape", sname, str(exc).split("\n")[0])
    elif form == "vertices":
        if "faces" not in bt:
            rd.err(f"{key}.faces", None, "missing value (vertices need faces)")
        verts = rd.matrix(bt, "vertices", f"{key}.vertices", 3, **COORD)
        faces = bt["faces"]
        if not isinstance(faces, list) or not faces:
            rd.err(f"{key}.faces", faces, "must be a non-empty list of vertex-index lists")
        for i, f in enumerate(faces):
            if not isinstance(f, list) or len(f) < 3 or any(isinstance(x, bool) or not isinstance(x, int) for x in f):
                rd.err(f"{key}.faces[{i}]", f, "must be a list of >= 3 integer vertex indices")
            if any(not 0 <= x < len(verts) for x in f):
                rd.err(f"{key}.faces[{i}]", f, f"vertex index out of range 0..{len(verts) - 1}")
        spec = BlockSpec(verts, faces)
    else:
        fname = rd.string(bt, "file", f"{key}.file", "")
        fpath = Path(fname)
        if not fpath.is_absolute():
            fpath = Path(scene_path).parent / fpath
        try:
            spec = load_convex_mesh(fpath)
        except Exception as exc:  # meshio / geometry errors: one line for the user
            rd.err(f"{key}.file", fname, str(exc).split("\n")[0] or exc.__class__.__name__)
    for k, v in fields.items():
        setattr(spec, k, v)
    return spec


__all__ = ["DDAScene", "Material", "SceneError", "load_scene", "scene_from_dict", "OUTPUT_FORMATS", "SphereLoadError",
           "load_region", "sphere_load_arrays"]
