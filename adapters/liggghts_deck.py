"""LIGGGHTS-PUBLIC decks of bonded-sphere runs (adapters.spec.SphereRun): the ``data`` and ``in`` files.

``write_deck(run, folder, variant="bonds")`` writes ``data`` + ``in`` into `folder` (the caller saves
``run.npz`` beside them) and returns the extra deck.json keys. The runner is adapters/liggghts_run.py.

Common to every variant: ``units si``, ``atom_style hybrid granular molecular``, ``newton off``,
``communicate single vel yes``, fixed boundaries around the model (``deck_box``: four radii, plus the
free-fall distance over the run along gravity; ``liggghts_box_margin`` in run.extra for one margin on every
side), one time step run.dt, gravity by ``fix gravity``. Atom type = colour + 1 (1 intact, 2 red, 3 green,
4 blue), + 4 for fixed and prescribed spheres (group ``fixed``: never integrated; zero velocity unless
prescribed). Contacts:
``pair_style gran model hooke/stiffness tangential history`` with absolute (constant) stiffness kn = run.kn
and kt = run.ks [N/m] (``fix property/global kn / kt peratomtypepair``), Coulomb friction tan(run.friction_deg)
(green-blue pairs: tan(run.joint_friction_deg)), normal viscous damping gamman_abs = 2 run.damping
sqrt(kn m_eff) (m_eff of the mean sphere: m/2 free-free, m
free-fixed) and ``limitForce on``; no tangential damping (as the in-house contact law).

Loads (run.force, run.prescribed / run.velocity): the spheres of one distinct force vector form a group
``ldK`` with ``fix afK ldK addforce fx fy fz`` (added to gravity every step); the spheres of one distinct
prescribed velocity form a group ``pvK`` (typed like fixed spheres, so they are not integrated and their
contacts damp with the free sphere's mass, as in-house) with ``velocity pvK set`` and ``fix mvK pvK move linear
vx vy vz`` (position x0 + v t exactly, no rotation). Groups list atom ids as ranges ``a:b``; LIGGGHTS holds at
most 32 groups, so a deck takes at most MAX_LOAD_GROUPS distinct force and velocity vectors. The box covers the
prescribed spheres' paths and the travel of forced spheres over the run.

Variants:

- ``bonds`` (primary): ``bond_style harmonic`` and a ``Bonds`` section with exactly the run's bonds
  (run.bond_i/j), bond k of type k + 1 with r0 = bond_len0 and K = bond_kn / 2 (LIGGGHTS' harmonic force is
  2 K (r - r0)). LIGGGHTS-PUBLIC cannot break bonds: the runner (``run_deck``) runs the deck in chunks through
  the engine's input, reads a full-precision dump after each chunk, finds the bonds whose tension
  kn (r - r0) exceeds bond_ft and removes exactly those with ``delete_bonds all bond T remove``.
- ``sjkr``: type-pair adhesion instead of bonds, ``pair_style gran model hertz tangential history cohesion
  sjkr`` with ``cohesionEnergyDensity peratomtypepair`` encoding the colour rule: every type pair is cohesive
  except red with anything and green with blue. What it can represent: which colour pairs stick. What it cannot:
  bonds. SJKR is an adhesion proportional to the overlap area of two spheres: it acts only while they overlap,
  holds nothing in tension once they separate, re-forms on every new contact (a fallen piece sticks where it
  lands) and has no breakage state; it does not know which joint cut a pair (a green sphere of one joint and a
  blue sphere of another are not cohesive either); contacts are Hertzian (a youngsModulus giving the Hertz
  tangent stiffness run.kn at the overlap d*, ``hard_particles yes``), not linear. Since adhesion needs an
  overlap, radii are changed by a fraction of d* per colour (``SJKR_GROW``; d* = run.extra
  ``liggghts_sjkr_overlap`` x mean radius, default 2e-3; densities scaled to keep the masses): touching
  intact pairs start at their adhesive equilibrium overlap d*, intact-green/blue pairs at d*/2, green-blue
  and red-intact pairs just touching (no push between non-cohesive pairs); green-green and blue-blue pairs start
  touching, so they only stick once pressed together, and red spheres start d*/2 off green/blue ones. The
  cohesion energy density makes d* the equilibrium (``sjkr_parameters``): pull-off force 8/81 kn d* per pair,
  not bond_ft.
- ``clumps``: rigid bodies, ``fix rigid molecule`` with molecule id = connected component of the run's bond
  graph; spheres without bonds stay free granular atoms (one-atom rigid bodies are an error); a component with a
  fixed sphere is fixed as a whole, one with a prescribed sphere moves at its velocity as a whole; contacts
  inside a body are excluded (``neigh_modify exclude molecule``). Bodies never break and never deform.

What LIGGGHTS-PUBLIC cannot do exactly (listed per run in RunResult.extra["approximations"]):

- harmonic bonds are central springs: no shear spring and no bending, so shear breakage (bond_fs) is not
  applied (a simple-cubic lattice is a mechanism: use FCC/HCP or random packings); bonds have no damping;
- bonded pairs also get the granular contact when they overlap (compression stiffness kn_bond + kn): the bonds
  variant shrinks the contact radii by ``bond_gap`` (1e-3 by default, masses kept), so touching bonded
  neighbours get it only beyond a compressive strain of about 2e-3, and unbonded pairs start 2e-3 r apart;
- bond breakage is checked by the runner between chunks of run.record_steps steps (run.extra
  ``liggghts_check_steps`` for a shorter check), not every step;
- no smooth joint: joint pairs are plain contacts along the centre line (with the joint friction), unless
  run.liggghts_joints = "open" ([spheres] liggghts_joints, ``adapters export --liggghts-joints open``): then
  ``neigh_modify exclude type`` drops every contact between a green and a blue atom type (the two sides of a
  joint), which is a smooth joint's behaviour while it is open (no force) and wrong when it closes in
  compression (the spheres pass through each other). A run whose touching green-blue pairs are not exactly its
  joint pairs (a joint pair of one colour, e.g. the geometric bond rule; a green sphere of one joint touching a
  blue one of another) is refused (``open_joint_problem``). The notes list it, also that green-blue pairs that
  first meet during the run get no contact either; the runner reports the
  largest closure of a joint pair along its joint normal (extra ``joint_closure_max`` [m],
  ``joint_pairs_closed_max``), the error the option makes;
- Cundall's local damping does not exist in LIGGGHTS-PUBLIC: runs are undamped unless run.viscous_damping
  ([simulation] viscous_damping: a ratio of critical damping of the model's first mode, or "critical";
  ``adapters export --viscous-damping``) or run.extra ``liggghts_viscous`` = gamma [kg/s] adds ``fix viscous``
  (force -gamma v on absolute velocities, so it also slows free flight; deck.json ``viscous_gamma_equivalent``
  gives the gamma with the same loss per cycle at the mean sphere's frequency);
- bonds have no damping (run.bond_zeta, [spheres] bond_damping, is listed as not represented);
- the Coulomb limit uses the damped normal force (in-house: the elastic one).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._liggghts_io import DUMP_COLUMNS, write_data
from .liggghts_joints import joint_exclusions, open_joint_notes, open_joint_problem, open_joints
from . import liggghts_walls as jw
from .spec import SpecError, SphereRun

VARIANTS = ("bonds", "sjkr", "clumps")
N_TYPES = 8  # colour (4) x fixed (2)
MAX_LOAD_GROUPS = 24  # LIGGGHTS holds 32 groups: all, fixed, single, movable, clump and the load groups


def atom_types(run: SphereRun, fixed=None):
    """LIGGGHTS atom type of each sphere: colour + 1, + 4 when fixed."""
    fixed = run.fixed if fixed is None else fixed
    return np.asarray(run.colour, np.int64) + 1 + 4 * np.asarray(fixed, bool)


def components(run: SphereRun):
    """Connected components of the bond graph: (labels (n,), size of each sphere's component)."""
    from scipy.sparse import coo_matrix  # lazy: scipy.sparse takes a second to load, for clumps decks only
    from scipy.sparse.csgraph import connected_components

    n = run.n
    g = coo_matrix((np.ones(run.n_bonds), (run.bond_i, run.bond_j)), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    size = np.bincount(lab)[lab]
    return lab, size


def clump_molecules(run: SphereRun):
    """(molecule id (n,), fixed (n,), number of rigid bodies K) for the clumps variant: ids 1..K are the free
    multi-sphere components (the rigid bodies), then the rest (single spheres, fixed components)."""
    lab, size = components(run)
    fixed_comp = np.zeros(lab.max() + 1, bool)
    fixed_comp[lab[np.asarray(run.fixed, bool)]] = True
    fixed = fixed_comp[lab]
    body = (size > 1) & ~fixed & ~clump_prescribed(run)[0]
    order = np.r_[np.unique(lab[body]), np.setdiff1d(np.unique(lab), np.unique(lab[body]))]
    new_id = np.empty(lab.max() + 1, np.int64)
    new_id[order] = np.arange(1, len(order) + 1)
    return new_id[lab], fixed, int(len(np.unique(lab[body])))


def clump_prescribed(run: SphereRun):
    """(prescribed (n,), velocity (n, 3)) of the clumps variant: every sphere of a bonded component that holds a
    prescribed sphere moves at that sphere's velocity (SpecError when a component holds two velocities, or a
    fixed and a prescribed sphere)."""
    n = run.n
    p = np.asarray(run.prescribed, bool) & ~np.asarray(run.fixed, bool)
    if not p.any():
        return np.zeros(n, bool), np.zeros((n, 3))
    lab, _ = components(run)
    k = lab.max() + 1
    comp_p = np.zeros(k, bool)
    comp_p[lab[p]] = True
    vel = np.zeros((k, 3))
    vel[lab[p]] = run.velocity[p]
    if np.any(vel[lab[p]] != run.velocity[p]):
        raise SpecError(f"{run.source or run.name}: clumps variant: a bonded component holds spheres with different "
                        "prescribed velocities (it moves as one rigid body)")
    comp_f = np.zeros(k, bool)
    comp_f[lab[np.asarray(run.fixed, bool)]] = True
    if np.any(comp_f & comp_p):
        raise SpecError(f"{run.source or run.name}: clumps variant: a bonded component holds a fixed and a "
                        "prescribed sphere (it moves as one rigid body)")
    return comp_p[lab], np.where(comp_p[lab][:, None], vel[lab], 0.0)


def _id_lines(group, idx, per_line=400):
    """``group NAME id ...`` commands for the 0-based sphere indices `idx` (atom ids as ranges a:b, several
    lines for long lists: a repeated group command adds to the group)."""
    ids = np.sort(np.asarray(idx, np.int64)) + 1
    if not len(ids):
        return []
    runs = np.split(ids, np.flatnonzero(np.diff(ids) != 1) + 1)
    tokens = [f"{r[0]}" if len(r) == 1 else f"{r[0]}:{r[-1]}" for r in runs]
    return [f"group {group} id " + " ".join(tokens[s:s + per_line]) for s in range(0, len(tokens), per_line)]


def load_groups(run: SphereRun, variant="bonds"):
    """(prescribed (n,), velocity (n, 3), [(vector, indices)] of the distinct prescribed velocities,
    [(vector, indices)] of the distinct forces on free spheres) of a deck; SpecError beyond MAX_LOAD_GROUPS."""
    fixed = np.asarray(run.fixed, bool)
    if variant == "clumps":
        pres, vel = clump_prescribed(run)
        fixed = clump_molecules(run)[1]
    else:
        pres = np.asarray(run.prescribed, bool) & ~fixed
        vel = np.where(pres[:, None], run.velocity, 0.0)

    def distinct(mask, values):
        idx = np.flatnonzero(mask)
        if not len(idx):
            return []
        u, inv = np.unique(values[idx], axis=0, return_inverse=True)
        inv = np.asarray(inv).reshape(-1)
        return [(u[k], idx[inv == k]) for k in range(len(u))]

    force = np.asarray(run.force, float)
    vgroups = distinct(pres, vel)
    fgroups = distinct(np.any(force != 0.0, axis=1) & ~fixed & ~pres, force)
    if len(vgroups) + len(fgroups) > MAX_LOAD_GROUPS:
        raise SpecError(f"{run.source or run.name}: {len(fgroups)} distinct sphere forces and {len(vgroups)} "
                        f"distinct prescribed velocities: a LIGGGHTS deck takes at most {MAX_LOAD_GROUPS} "
                        "(one group each)")
    return pres, vel, vgroups, fgroups


def _mean_mass(run):
    r = float(np.mean(run.radii))
    return run.density * 4.0 / 3.0 * math.pi * r ** 3, r


def _matrix(values):
    return " ".join(f"{v:.17g}" for v in np.asarray(values, float).ravel())


def _type_pairs(n_types=N_TYPES):
    """(colour_a, colour_b, fixed_a, fixed_b) of the n_types x n_types matrix, row-major (types beyond N_TYPES,
    the joint walls' (adapters/liggghts_walls.py), count as fixed)."""
    t = np.arange(n_types)
    a, b = np.meshgrid(t, t, indexing="ij")
    return np.where(a < N_TYPES, a % 4, -1), np.where(b < N_TYPES, b % 4, -1), a >= 4, b >= 4


def cohesion_matrix():
    """Colour rule as a type-pair mask: True where the pair is cohesive (intact/green/blue with each other,
    except green-blue; red with nothing)."""
    ca, cb, _, _ = _type_pairs()
    red = (ca == 1) | (cb == 1)
    across = ((ca == 2) & (cb == 3)) | ((ca == 3) & (cb == 2))
    return ~(red | across)


MAX_BINS = 10_000_000


def deck_box(run: SphereRun):
    """(lo, hi) of the fixed-boundary box: the model's bounding box plus four radii, extended along gravity by
    1.1 times the free-fall distance over the run (capped so that the neighbour bins of the box stay below
    MAX_BINS: LIGGGHTS bins the whole box), and likewise along the acceleration of spheres under a constant
    force (gravity + force / mass); the box holds the prescribed spheres' whole paths. run.extra
    ``liggghts_box_margin`` [m] sets one margin for every side instead. Particles leaving the box are lost (the
    runner stops with an error)."""
    rmax = float(np.max(run.radii))
    pres = np.asarray(run.prescribed, bool) & ~np.asarray(run.fixed, bool)
    ends = np.asarray(run.centers, float)[pres] + np.asarray(run.velocity, float)[pres] * run.duration
    pts = np.r_[np.asarray(run.centers, float), ends]
    lo = pts.min(0) - rmax
    hi = pts.max(0) + rmax
    if "liggghts_box_margin" in run.extra:
        m = float(run.extra["liggghts_box_margin"])
        return lo - m, hi + m
    lo, hi = lo - 4.0 * rmax, hi + 4.0 * rmax
    acc = np.asarray(run.gravity, float).reshape(1, 3)
    loaded = np.any(np.asarray(run.force) != 0.0, axis=1) & ~np.asarray(run.fixed, bool) & ~pres
    if loaded.any():  # spheres under a constant force: their own acceleration (free, the fastest they can go)
        m = run.density * 4.0 / 3.0 * math.pi * np.asarray(run.radii, float)[loaded] ** 3
        acc = np.r_[acc, acc + np.asarray(run.force, float)[loaded] / m[:, None]]
    b = max(rmax, 0.5 * (2.0 * rmax + 0.3 * float(np.min(run.radii))))  # about LIGGGHTS' bin size
    for a in range(3):
        for sign in (-1.0, 1.0):
            fall = 0.55 * max(0.0, float((sign * acc[:, a]).max())) * run.duration ** 2
            if fall <= 0:
                continue
            others = [k for k in range(3) if k != a]
            lateral = float(np.prod([(hi[k] - lo[k]) / b for k in others]))
            cap = MAX_BINS / lateral * b - (hi[a] - lo[a])
            ext = min(fall, max(cap, 0.0))
            if sign < 0:
                lo[a] -= ext
            else:
                hi[a] += ext
    return lo, hi


def check_steps(run: SphereRun):
    c = int(run.extra.get("liggghts_check_steps", run.record_steps))
    return max(1, min(c, run.record_steps))


# the bond keys of a DDA scene's [spheres] table: what the sjkr and clumps variants do not use
BOND_KEYS = ("spheres.bond_young, spheres.bond_kn, spheres.bond_ks, spheres.bond_shear_ratio, spheres.bond_tensile, "
             "spheres.bond_shear, spheres.bond_damping, spheres.bond_radius_factor")
# run.npz fields the runner reads besides the deck's data and in files, per variant (bond breakage)
RUNNER_FIELDS = {"bonds": ("bond_ft",), "sjkr": (), "clumps": ()}


def viscous(run: SphereRun):
    """The fix viscous coefficient [kg/s] of the deck: run.viscous_damping ([simulation] viscous_damping), else
    run.extra ``liggghts_viscous`` (a stand-in for the local damping of the other engines), else 0."""
    if run.viscous_damping > 0:
        return float(run.viscous_damping)
    return float(run.extra.get("liggghts_viscous", 0.0))


def approximations(run: SphereRun, variant):
    """What this deck cannot represent exactly (strings for RunResult.extra["approximations"]), naming the scene
    keys they concern."""
    out = []
    if variant == "bonds" and run.n_bonds:
        out.append("bonds are central springs (bond_style harmonic): no shear spring (spheres.bond_ks, "
                   "spheres.bond_shear_ratio not represented), no bending")
        zeta = np.asarray(run.bond_zeta, float)
        if np.any(zeta > 0):
            out.append(f"spheres.bond_damping = {float(zeta.max()):g} not represented: harmonic bonds have no "
                       "damping")
        if np.any(np.isfinite(run.bond_fs)):
            out.append("spheres.bond_shear (bond_fs) not applied: harmonic bonds carry no shear force")
        if np.any(np.isfinite(run.bond_ft)):
            out.append(f"bond tension breakage checked by the runner every {check_steps(run)} steps "
                       "(delete_bonds between chunks), not every step")
        out.append("bonded pairs also get the granular contact when they overlap (compression: kn_bond + kn)")
    if variant == "sjkr":
        out.append("no bonds: SJKR adhesion per colour type pair (acts only while spheres overlap, re-forms on "
                   "new contacts, never breaks); Hertzian contacts instead of linear springs")
        out.append(f"not used without bonds: {BOND_KEYS}")
        out.append("green-blue pairs are non-cohesive whichever joint they belong to")
    if variant == "clumps":
        out.append("bonded components are rigid bodies (fix rigid molecule): no bond deformation or breakage")
        out.append(f"not used by rigid bodies: {BOND_KEYS}")
        if np.any(np.asarray(run.fixed, bool)):
            out.append("components with a fixed sphere are fixed as a whole (spheres.fixed, spheres.fixed_below)")
        if np.any(np.asarray(run.prescribed, bool) & ~np.asarray(run.fixed, bool)):
            out.append("a bonded component with a prescribed sphere moves at its velocity as a whole")
    if variant == "bonds" and bond_gap(run) > 0:
        out.append(f"contact radius r (1 - {bond_gap(run):g}) (masses kept): bonded pairs get the granular "
                   f"contact only beyond a compressive strain of about {2 * bond_gap(run):g}")
    out += jw.wall_notes(run)
    if jw.joint_walls(run) and variant != "clumps":
        out.append(f"{jw.mode(run)[1]} with the {variant} variant: a sphere turns freely (central bonds, adhesion), "
                   "so it rolls on a wall like a ball bearing and the wall's friction barely holds a block of spheres "
                   "(the clumps variant makes it one rigid body)")
    if open_joints(run):
        out += open_joint_notes(run)
    elif len(run.joint_i) and run.smooth_joints and not jw.all_walled(run):
        out.append("spheres.smooth_joints not represented (LIGGGHTS-PUBLIC has no smooth joint): joint pairs are "
                   "plain contacts along the centre line (joint friction on green-blue type pairs); "
                   "spheres.liggghts_joints = \"open\" drops their contact instead")
    if run.damping > 0:
        out.append("contact damping with the effective mass of the mean sphere; Coulomb limit on the damped "
                   "normal force")
    c = viscous(run)
    if run.local_damping > 0:
        out.append(f"simulation.local_damping = {run.local_damping:g} (Cundall) not represented: LIGGGHTS-PUBLIC "
                   "has none; " + (f"fix viscous {c:g} kg/s damps the run instead" if c > 0 else
                                   "the run is undamped (simulation.viscous_damping adds fix viscous)"))
    if c > 0:
        out.append(f"viscous damping fix viscous {c:g} kg/s acts on absolute velocities (also slows free fall: "
                   "terminal velocity m g / c)")
    return out


def bond_gap(run):
    """Relative radius reduction of the bonds variant (run.extra ``liggghts_bond_gap``, default 1e-3): LIGGGHTS
    adds the granular contact to a bonded pair that overlaps, so touching bonded neighbours under compression
    would be stiffer (kn_bond + kn) than in YADE or in-house; the contact radius r (1 - gap) leaves them a gap of
    2 gap r (masses kept by the density), so the contact acts only beyond a compressive strain of about 2 gap."""
    return float(run.extra.get("liggghts_bond_gap", 1e-3)) if run.n_bonds else 0.0


def viscous_gamma(run):
    """A fix viscous gamma [kg/s] with the energy loss per cycle of Cundall local damping alpha (4 alpha =
    4 pi zeta, so zeta = alpha / pi) at the frequency of a mean sphere on its springs (reported in deck.json as
    a suggestion for run.extra ``liggghts_viscous``; lower modes and free flight are damped far more)."""
    m, _ = _mean_mass(run)
    k_sphere = 2.0 * float(np.sum(run.bond_kn)) / run.n if run.n_bonds else 0.0
    k_sphere = max(k_sphere, 4.0 * run.kn)
    omega = math.sqrt(k_sphere / m)
    return 2.0 * (run.local_damping / math.pi) * m * omega


SJKR_NU = 0.25
# radius change of the sjkr variant per colour (intact, red, green, blue), in units of the overlap d*: touching
# intact pairs start at d* (their adhesive equilibrium), intact-green/blue at d*/2 (inside the adhesive range),
# green-blue and red-intact just touching (no push between non-cohesive pairs), red-green/blue and red-red
# with a gap of d*/2 and d*
SJKR_GROW = np.array([0.5, -0.5, 0.0, 0.0])


def sjkr_overlap(run: SphereRun):
    """Equilibrium overlap d* of the sjkr variant [m] (run.extra ``liggghts_sjkr_overlap``, a fraction of the
    mean radius, default 2e-3)."""
    return float(run.extra.get("liggghts_sjkr_overlap", 2e-3)) * float(np.mean(run.radii))


def sjkr_parameters(run: SphereRun):
    """(youngsModulus, cohesionEnergyDensity, coefficientRestitution) of the sjkr variant.

    Two mean spheres (radius r, R* = r / 2) overlapping by d feel the Hertz repulsion c d^1.5 (c = 4/3 E*
    sqrt(R*), E* = E / (2 (1 - nu^2))) and the SJKR attraction k_c pi a^2 ~ k_c pi r d. E* is chosen so that
    the Hertz tangent stiffness 1.5 c sqrt(d*) equals run.kn at the overlap d* (sjkr_overlap), and k_c so that
    d* is the equilibrium (k_c pi r = c sqrt(d*) = 2 kn / 3): the pair then has the stiffness kn / 3 and a
    pull-off force 8 / 81 kn d*. run.extra ``liggghts_cohesion`` overrides k_c."""
    r = float(np.mean(run.radii))
    d = sjkr_overlap(run)
    e_star = run.kn / (2.0 * math.sqrt(0.5 * r * d))
    young = e_star * 2.0 * (1.0 - SJKR_NU ** 2)
    coh = float(run.extra.get("liggghts_cohesion", (2.0 / 3.0) * run.kn / (math.pi * r)))
    z = min(run.damping, 0.99)
    e_rest = float(run.extra.get("liggghts_restitution", math.exp(-math.pi * z / math.sqrt(1.0 - z * z))))
    return young, coh, e_rest


def write_deck(run: SphereRun, folder, variant="bonds"):
    """Write ``data`` and ``in`` for `run` into `folder`; returns the extra deck.json keys."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown LIGGGHTS variant {variant!r} (choose from {', '.join(VARIANTS)})")
    folder = Path(folder)
    n = run.n
    m_mean, r_mean = _mean_mass(run)
    fixed = np.asarray(run.fixed, bool)
    mol = np.ones(n, np.int64)
    n_bodies = 0
    if variant == "clumps":
        mol, fixed, n_bodies = clump_molecules(run)
    pres, _, vgroups, fgroups = load_groups(run, variant)
    types = atom_types(run, fixed | pres)  # prescribed spheres: typed as fixed (not integrated)
    planes = jw.wall_planes(run)  # run.extra joint_walls: rigid-side joints as mesh walls
    types[jw.dropped(run, planes)] = jw.DROPPED_TYPE
    n_types = jw.WALL_TYPES if planes else N_TYPES
    box = deck_box(run)
    if planes:  # the box holds the walls
        corners = jw.wall_triangles(run, planes).reshape(-1, 3)
        box = (np.minimum(box[0], corners.min(0) - r_mean), np.maximum(box[1], corners.max(0) + r_mean))
        for k, (p, tri) in enumerate(zip(planes, jw.wall_triangles(run, planes)), 1):
            jw.write_stl(folder / f"wall_{k}.stl", tri, p["normal"], f"joint{p['disc']}")
    bonds = None
    if variant == "bonds":
        bonds = (run.bond_i, run.bond_j, 0.5 * np.asarray(run.bond_kn, float), run.bond_len0)
    radii, density = run.radii, np.full(n, float(run.density))
    if variant == "sjkr":  # adhesion needs overlap: radii changed by SJKR_GROW[colour] d* (masses kept)
        radii = run.radii + SJKR_GROW[np.asarray(run.colour, np.int64)] * sjkr_overlap(run)
        density = run.density * (run.radii / radii) ** 3
    elif variant == "bonds" and bond_gap(run) > 0:  # bonded pairs keep clear of the granular contact
        radii = run.radii * (1.0 - bond_gap(run))
        density = run.density * (run.radii / radii) ** 3
    if planes and jw.mode(run)[0] == "pairs":  # every sphere of a walled joint pair touches the wall
        if variant != "clumps":
            raise SpecError(f"{run.source or run.name}: run.extra {jw.mode(run)[1]} (\"pairs\") grows the radii of the "
                            "spheres on the walls, which needs the clumps variant (no contacts inside a body), not "
                            f"{variant}")
        radii = jw.wall_radii(run, planes)
        density = run.density * (run.radii / radii) ** 3
    write_data(folder / "data", run.centers, radii, density, types, mol, n_types, box, bonds=bonds,
               title=f"{run.name} ({variant})")

    ca, cb, fa, fb = _type_pairs(n_types)
    joint = ((ca == 2) & (cb == 3)) | ((ca == 3) & (cb == 2))
    t = np.arange(1, n_types + 1)
    joint |= (t[:, None] == jw.WALL_TYPE) | (t[None, :] == jw.WALL_TYPE)  # a wall is the joint's fixed side
    mu = np.where(joint & run.smooth_joints, math.tan(math.radians(run.joint_friction_deg)),
                  math.tan(math.radians(run.friction_deg)))
    meff = np.where(fa | fb, m_mean, 0.5 * m_mean)
    gamma_n = 2.0 * run.damping * np.sqrt(run.kn * meff)
    skin = 0.3 * float(np.min(run.radii))
    g = np.asarray(run.gravity, float)
    gnorm = float(np.linalg.norm(g))
    L = [f"# rockdem LIGGGHTS deck '{run.name}', variant {variant}: {n} spheres, "
         f"{run.n_bonds if variant == 'bonds' else 0} bonds, {run.steps} steps of {run.dt:.6g} s",
         "# run with `adapters run DECK` (bond breakage between chunks) or by hand: liggghts -in in",
         "variable driven index 0",
         "atom_style hybrid granular molecular", "atom_modify map array sort 0 0.0", "units si", "boundary f f f",
         "newton off", "communicate single vel yes"]
    if variant == "sjkr":
        L.append("hard_particles yes")
    if variant == "bonds":
        L.append("bond_style harmonic")
    L += ["read_data data", f"neighbor {skin:.17g} bin", "neigh_modify delay 0"]
    if open_joint_problem(run):
        raise SpecError(f"{run.source or run.name}: spheres.liggghts_joints = open: {open_joint_problem(run)}")
    for a, b in joint_exclusions(run):  # spheres.liggghts_joints = "open": no contact across a joint
        L.append(f"neigh_modify exclude type {a} {b}")
    for a, b in jw.exclusions() if planes else []:  # the fixed spheres the walls stand for: no contact
        L.append(f"neigh_modify exclude type {a} {b}")
    if variant == "clumps" and n_bodies:
        L.append(f"group clump molecule 1:{n_bodies}")
        L.append("neigh_modify exclude molecule clump")
    fx = "fix"
    if variant == "sjkr":
        young, coh, e_rest = sjkr_parameters(run)
        L += [f"{fx} m1 all property/global youngsModulus peratomtype {_matrix(np.full(n_types, young))}",
              f"{fx} m2 all property/global poissonsRatio peratomtype {_matrix(np.full(n_types, SJKR_NU))}",
              f"{fx} m3 all property/global coefficientRestitution peratomtypepair {n_types} "
              f"{_matrix(np.full((n_types, n_types), e_rest))}",
              f"{fx} m4 all property/global coefficientFriction peratomtypepair {n_types} {_matrix(mu)}",
              f"{fx} m5 all property/global cohesionEnergyDensity peratomtypepair {n_types} "
              f"{_matrix(np.pad(np.where(cohesion_matrix(), coh, 0.0), (0, n_types - N_TYPES)))}",
              "pair_style gran model hertz tangential history cohesion sjkr"]
    else:
        L += [f"{fx} m1 all property/global kn peratomtypepair {n_types} "
              f"{_matrix(np.full((n_types, n_types), run.kn))}",
              f"{fx} m2 all property/global kt peratomtypepair {n_types} "
              f"{_matrix(np.full((n_types, n_types), run.ks))}",
              f"{fx} m3 all property/global gamman_abs peratomtypepair {n_types} {_matrix(gamma_n)}",
              f"{fx} m4 all property/global gammat_abs peratomtypepair {n_types} "
              f"{_matrix(np.zeros((n_types, n_types)))}",
              f"{fx} m5 all property/global coefficientFriction peratomtypepair {n_types} {_matrix(mu)}",
              "pair_style gran model hooke/stiffness tangential history absolute_damping on "
              "tangential_damping off limitForce on"]
    L += ["pair_coeff * *", "group fixed type 5 6 7 8" + (f" {jw.DROPPED_TYPE}" if planes else ""),
          "velocity fixed set 0 0 0"]
    for k, (v, idx) in enumerate(vgroups, 1):  # prescribed velocities: x = x0 + v t, whatever the forces
        L += _id_lines(f"pv{k}", idx)
        L += [f"velocity pv{k} set {_matrix(v)}", f"fix mv{k} pv{k} move linear {_matrix(v)}"]
    for k, (f, idx) in enumerate(fgroups, 1):  # constant forces on each sphere
        L += _id_lines(f"ld{k}", idx)
        L.append(f"fix af{k} ld{k} addforce {_matrix(f)}")
    if variant == "clumps" and n_bodies:
        L += ["group movable subtract all fixed", "group single subtract movable clump"]
    else:
        L += ["group single subtract all fixed"]
    if gnorm > 0:
        L.append(f"fix grav all gravity {gnorm:.17g} vector {g[0] / gnorm:.17g} {g[1] / gnorm:.17g} "
                 f"{g[2] / gnorm:.17g}")
    if planes:  # the fixed sides of the joints as mesh walls, on every sphere that moves
        L += ["group onwall subtract all fixed"]
        L += jw.wall_commands(planes, "onwall", "hertz tangential history" if variant == "sjkr" else
                              "hooke/stiffness tangential history", "" if variant == "sjkr" else
                              "absolute_damping on tangential_damping off limitForce on")
    L.append("fix integrate single nve/sphere")
    if variant == "clumps" and n_bodies:
        L.append("fix bodies clump rigid molecule")
    if viscous(run) > 0:
        L.append(f"fix viscous all viscous {viscous(run):.17g}")
    L += [f"timestep {run.dt:.17g}", "variable natoms equal atoms",
          "thermo_style custom step atoms ke", f"thermo {max(run.record_steps, 1)}",
          "thermo_modify lost ignore norm no",
          'if "${driven} == 0" then &',
          f'  "dump rec all custom {run.record_steps} dump.*.txt {" ".join(DUMP_COLUMNS)}" &',
          '  "dump_modify rec sort id" &',
          f'  "run {run.steps}"']
    (folder / "in").write_text("\n".join(L) + "\n")
    return {"variant": variant, "atom_types": n_types, "joint_walls": len(planes),
            "bond_types": int(run.n_bonds) if variant == "bonds" else 0,
            "rigid_bodies": int(n_bodies), "box": [list(map(float, box[0])), list(map(float, box[1]))],
            "check_steps": check_steps(run), "approximations": approximations(run, variant),
            "liggghts_joints": run.liggghts_joints if open_joints(run) else "contact",
            "excluded_type_pairs": [list(p) for p in joint_exclusions(run)],
            "viscous_gamma_equivalent": viscous_gamma(run) if run.local_damping > 0 else 0.0}


__all__ = ["write_deck", "VARIANTS", "N_TYPES", "MAX_LOAD_GROUPS", "RUNNER_FIELDS", "BOND_KEYS", "atom_types",
           "components", "clump_molecules", "clump_prescribed", "load_groups", "cohesion_matrix", "deck_box",
           "check_steps", "viscous", "approximations", "bond_gap", "viscous_gamma", "sjkr_overlap", "sjkr_parameters"]
