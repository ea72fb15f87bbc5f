"""Spheres and bonds in the explicit engine: sgim's bonded-sphere models (model.npz) under gravity and loads.

Usage::

    from dda.spheres import SphereSet, BondLaw, SphereSimulation, load_model
    ss = load_model("model.npz", density=2600.0, bonds=BondLaw(young=1e9, tensile=1e6, shear=1e6))
    ss.fixed[ss.centers[:, 2] > 9.5] = True                 # or SphereSet(centers, radii, ...) + add_bonds
    sim = SphereSimulation(ss, ContactLaw(kn=1e7, friction_deg=30), walls=[floor_spec], gravity=(0, 0, -9.81))
    res = sim.run(1.0, record_every=0.01)                  # SphereResults: time, pos, energy, bonds intact
    sim.bond_intact, sim.bond_break_time, sim.displacement()

Bodies are spheres with 6 DOF (solid-sphere inertia 2/5 m r^2); ``fixed`` spheres never move, ``prescribed``
ones move at their velocity / angular velocity whatever the forces; ``body_force`` adds a constant force.
Walls are fixed convex polyhedra (BlockSpec-like: ``vertices``, ``faces``): a sphere touches a wall at the
polyhedron's closest point (face, edge or vertex).

Spheres with moving blocks: pass a BlockSystem with free, prescribed or deformable blocks as ``walls``::

    bs = BlockSystem(); bs.add_block(floor_spec); ib = bs.add_block(cube_spec)    # fixed and free blocks
    sim = SphereSimulation(ss, law, walls=bs, wall_law=None, block_law=None, pair_laws=None)
    sim.run(1.0); sim.blocks.pos[ib], sim.blocks.contacts(), sim.contacts()   # sim.blocks: a dda Simulation

Both run in one numba loop (dda/_coupled.py): each step computes the sphere forces (sphere-block contacts at
the polyhedron's closest point with ``wall_law``, default ``law``; the block takes the reaction at that point),
then advances the blocks one step with the block engine's own kernel (block-block contacts with ``block_law``,
default ``wall_law``, and ``pair_laws``), then the spheres. The time step is common: ``safety`` times the
smallest of the spheres' critical step, the blocks' (dda.simulation) and the blocks' under NPOINT sphere-block
springs. Energies (``total_energy()``, the records) are the sums of both; blocks do not sleep in such runs.
``contacts()`` lists sphere-block contacts with i = -1 - block index.

Contacts (sphere-sphere without an intact bond, sphere-wall) follow the block engine's law at one point
(dda/_contact.py: kn, ks per contact, friction, damping; no cohesion). Bonds (only the pairs of the model's
bond list whose ``bonded`` flag is set): a normal spring on the change of centre distance and a shear spring
on the tangential displacement at the bond point; ``BondLaw`` gives them from a bond modulus over the bond
area A = pi (radius_factor min(r_i, r_j))^2 and length L0 = initial centre distance (kn = E A / L0, ks =
shear_ratio kn) or directly as ``kn`` / ``ks`` [N/m]; the tensile and shear strengths [Pa] times A are the
forces at which the bond breaks (for good). Bonds with ks = 0 (``shear_ratio=0`` or ``ks=0``) are central
springs, as LIGGGHTS' harmonic bonds: the normal spring alone, no shear force, no torque, no shear breakage
(a loop of their own in the kernel, about the cost of one spring per bond); their spheres still turn under
contact friction. Bond states are reported per record (``SphereResults.bonds``)
and the time each bond broke in ``bond_break_time`` (-1: intact).

Smooth joints (``SphereSet.add_joints(pairs, normals, friction_deg)``, the pairs a joint cuts; a DDA scene adds
the model's joint pairs with [spheres] smooth_joints = true): such a pair does not touch along its centre
line but across the joint plane, as YADE's JCFpm smoothJoint: normal overlap D = initD - |(x_j - x_i).n|
measured along the joint's unit normal n from the gap initD the pair had when its contact formed (at the
start for pairs within (1 + ``joint_touch``) (r_i + r_j), later when the spheres overlap), force kn D along n
while D >= 0, a shear spring ks on the centre velocity difference in the joint plane with Coulomb friction
tan(joint friction), no torque. The pair keeps its reference gap for good (YADE's JCFpm with neverErase, as
the YADE adapter sets it up): a joint that opens (D < 0) carries no force and loses its shear spring, and
pushes again as soon as D >= 0 (a joint's two faces stay where they are; re-forming it at a new gap when the
centres come within r_i + r_j would let a closed joint sink by the opening). Once the pair has slid
2 min(r_i, r_j) the spheres are no longer neighbours across the joint: the joint is retired and the pair is a
plain contact (``sim.joint_on`` False, ``joint_init`` -1; ``joint_slide``), with fixed walls and with moving
blocks alike.

Contacts are searched in a pair list (dda/_spheres.py) rebuilt when a sphere has moved half its margin
``skin`` (0.2 r_min): ``sim.stats[7]`` counts the builds.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from sgim.model import SphereModel
from sgim.portable import matmul

from . import _spheres as _sp
from ._bondlaw import build_bond_hash
from ._sphere_state import (B_FN, NBOND_COLS, ST_NEED_PAIRS, Bonds, Books, Env, History, Joints, Link, Motion,
                            PairList, Spheres, Walls)
from ._state import NENERGY  # the block engine's energy columns (coupled runs add the two)
from .progress import tracker
from .results import ENERGY_COLUMNS  # one column order for blocks and spheres
from .polyhedra import check_convex, face_planes, half_edges
from .simulation import NPOINT, BlowUpError, ContactLaw, Simulation
from .timestep import sphere_critical_dt, sphere_mass


@dataclass
class BondLaw:
    """Bonds between sphere pairs: stiffness from a bond modulus (or kn / ks directly), the shear ratio,
    tensile and shear strengths [Pa] (a bond breaks past either), damping and the bond radius factor."""

    young: float | None = 1e9      # bond modulus [Pa] (kn = young A / L0), unless kn is given
    shear_ratio: float = 0.4       # ks / kn, unless ks is given; 0: central bonds (normal spring only)
    tensile: float = math.inf      # tensile strength [Pa] on the bond area
    shear: float = math.inf        # shear strength [Pa] on the bond area
    damping: float = 0.0           # ratio of critical viscous damping of the bond springs
    radius_factor: float = 1.0     # bond radius = radius_factor min(r_i, r_j)
    kn: float | None = None        # [N/m], overrides young
    ks: float | None = None        # [N/m], overrides shear_ratio

    def check(self):
        if self.kn is None and not (self.young is not None and self.young > 0):
            raise ValueError(f"bond modulus must be > 0 (got {self.young!r})")
        if self.kn is not None and not self.kn > 0:
            raise ValueError(f"bond kn must be > 0 (got {self.kn!r})")
        if self.ks is not None and not self.ks >= 0:
            raise ValueError(f"bond ks must be >= 0 (got {self.ks!r})")
        if not (self.shear_ratio >= 0 and self.radius_factor > 0):
            raise ValueError("bond shear_ratio must be >= 0 and radius_factor > 0")
        if not (self.tensile >= 0 and self.shear >= 0 and self.damping >= 0):
            raise ValueError("bond strengths and damping must be >= 0")


class SphereSet:
    """Spheres (centres, radii, density) with per-sphere flags, loads and a bond list."""

    def __init__(self, centers, radii, density=2600.0):
        self.centers = np.ascontiguousarray(np.asarray(centers, float).reshape(-1, 3))
        self.radii = np.ascontiguousarray(np.asarray(radii, float).reshape(-1))
        n = len(self.radii)
        if len(self.centers) != n:
            raise ValueError("centers and radii differ in length")
        if n == 0:
            raise ValueError("no spheres")
        if not (np.all(self.radii > 0) and np.all(np.isfinite(self.centers))):
            raise ValueError("radii must be > 0 and centres finite")
        if not density > 0:
            raise ValueError(f"density must be > 0 (got {density!r})")
        self.density = float(density)
        self.mass = sphere_mass(self.radii, density)
        self.fixed = np.zeros(n, bool)
        self.prescribed = np.zeros(n, bool)
        self.velocity = np.zeros((n, 3))
        self.angular_velocity = np.zeros((n, 3))
        self.body_force = np.zeros((n, 3))
        self.bond_i = np.zeros(0, np.int64)
        self.bond_j = np.zeros(0, np.int64)
        self.bond_len0 = np.zeros(0)
        self.bond_kn = np.zeros(0)
        self.bond_ks = np.zeros(0)
        self.bond_ft = np.zeros(0)
        self.bond_fs = np.zeros(0)
        self.bond_zeta = np.zeros(0)
        self.joint_i = np.zeros(0, np.int64)
        self.joint_j = np.zeros(0, np.int64)
        self.joint_normal = np.zeros((0, 3))
        self.joint_tanphi = np.zeros(0)
        self.joint_touch = 0.05

    @property
    def n(self):
        return len(self.radii)

    @property
    def n_joints(self):
        return len(self.joint_i)

    @property
    def n_bonds(self):
        return len(self.bond_i)

    def add_bonds(self, pairs, law: BondLaw):
        """Bond the sphere pairs (m, 2) with `law`; returns the bond indices."""
        law.check()
        p = np.asarray(pairs, np.int64).reshape(-1, 2)
        if len(p) and (p.min() < 0 or p.max() >= self.n or np.any(p[:, 0] == p[:, 1])):
            raise ValueError("bond pairs must name two different spheres of the set")
        i = np.minimum(p[:, 0], p[:, 1])
        j = np.maximum(p[:, 0], p[:, 1])
        L0 = np.linalg.norm(self.centers[j] - self.centers[i], axis=1)
        rb = law.radius_factor * np.minimum(self.radii[i], self.radii[j])
        area = np.pi * rb * rb
        kn = np.full(len(p), float(law.kn)) if law.kn is not None else law.young * area / L0
        ks = np.full(len(p), float(law.ks)) if law.ks is not None else law.shear_ratio * kn
        first = self.n_bonds
        self.bond_i = np.r_[self.bond_i, i]
        self.bond_j = np.r_[self.bond_j, j]
        self.bond_len0 = np.r_[self.bond_len0, L0]
        self.bond_kn = np.r_[self.bond_kn, kn]
        self.bond_ks = np.r_[self.bond_ks, ks]
        self.bond_ft = np.r_[self.bond_ft, law.tensile * area]
        self.bond_fs = np.r_[self.bond_fs, law.shear * area]
        self.bond_zeta = np.r_[self.bond_zeta, np.full(len(p), float(law.damping))]
        keys = self.bond_i * self.n + self.bond_j
        if len(np.unique(keys)) != len(keys):
            raise ValueError("a sphere pair is bonded twice")
        if self.n_joints and np.isin(keys, self.joint_i * self.n + self.joint_j).any():
            raise ValueError("a sphere pair is both bonded and a smooth joint")
        return np.arange(first, self.n_bonds)

    def add_joints(self, pairs, normals, friction_deg):
        """Smooth joints on the sphere pairs (k, 2) (the pairs a joint cuts): their contact acts along the joint's
        unit normal (k, 3) (signed from the pair's lower index to the higher; given for a pair (j, i) with
        j > i it is flipped) instead of the centre line, with Coulomb friction `friction_deg` (a number or one
        per pair), as YADE's JCFpm smoothJoint (dda/_spheres.py ``_joints``). Pairs within (1 + joint_touch)
        (r_i + r_j) at the start of a run are in contact there, at the gap they have. Returns the indices."""
        p = np.asarray(pairs, np.int64).reshape(-1, 2)
        nrm = np.asarray(normals, float).reshape(-1, 3)
        if len(nrm) != len(p):
            raise ValueError("one joint normal per pair")
        if len(p) and (p.min() < 0 or p.max() >= self.n or np.any(p[:, 0] == p[:, 1])):
            raise ValueError("joint pairs must name two different spheres of the set")
        ln = np.linalg.norm(nrm, axis=1)
        if not np.all(np.isfinite(ln) & (ln > 0)):
            raise ValueError("joint normals must be finite and non-zero")
        tanphi = np.tan(np.radians(np.broadcast_to(np.asarray(friction_deg, float), (len(p),))))
        if not np.all((tanphi >= 0) & np.isfinite(tanphi)):
            raise ValueError(f"joint friction must be in [0, 90) degrees (got {friction_deg!r})")
        sign = np.where(p[:, 0] < p[:, 1], 1.0, -1.0)
        i = np.minimum(p[:, 0], p[:, 1])
        j = np.maximum(p[:, 0], p[:, 1])
        keys = np.r_[self.joint_i * self.n + self.joint_j, i * self.n + j]
        if len(np.unique(keys)) != len(keys):
            raise ValueError("a sphere pair is a smooth joint twice")
        if self.n_bonds and np.isin(i * self.n + j, self.bond_i * self.n + self.bond_j).any():
            raise ValueError("a sphere pair is both bonded and a smooth joint")
        first = self.n_joints
        self.joint_i = np.r_[self.joint_i, i]
        self.joint_j = np.r_[self.joint_j, j]
        self.joint_normal = np.r_[self.joint_normal, nrm / ln[:, None] * sign[:, None]]
        self.joint_tanphi = np.r_[self.joint_tanphi, tanphi]
        return np.arange(first, self.n_joints)


def load_model(model, density=2600.0, bonds: BondLaw | None = None) -> SphereSet:
    """SphereSet from an sgim model (a SphereModel or the path of a model.npz): its spheres, and bonds (with
    `bonds`, default BondLaw()) on the pairs of its bond list whose ``bonded`` flag is set."""
    if not hasattr(model, "centers"):
        model = SphereModel.load(model)
    ss = SphereSet(model.centers, model.radii, density)
    pairs = np.asarray(model.bonds, np.int64).reshape(-1, 2)[np.asarray(model.bonded, bool)]
    ss.add_bonds(pairs, bonds or BondLaw())
    return ss


@dataclass
class SphereResults:
    time: list = field(default_factory=list)
    pos: list = field(default_factory=list)
    vel: list = field(default_factory=list)
    energy: list = field(default_factory=list)
    contacts: list = field(default_factory=list)
    wall_contacts: list = field(default_factory=list)
    bonds: list = field(default_factory=list)  # intact bonds at each record
    block_pos: list = field(default_factory=list)   # block centroids at each record (runs with moving blocks)
    block_quat: list = field(default_factory=list)  # block orientations (unit quaternions w, x, y, z)
    wall_s: float = 0.0
    dt: float = 0.0

    @property
    def times(self):
        return np.asarray(self.time)

    def energy_column(self, name):
        return np.asarray(self.energy)[:, ENERGY_COLUMNS.index(name)]

    def save(self, path, sim):
        """series npz: time, pos (r, n, 3), vel, energy, contacts, wall_contacts, bonds; and the final bond state
        (bond_i, bond_j, bond_intact, bond_break_time); with moving blocks block_pos (r, nb, 3), block_quat."""
        np.savez_compressed(path, time=self.times, pos=np.asarray(self.pos), vel=np.asarray(self.vel),
                            energy=np.asarray(self.energy), energy_columns=np.array(ENERGY_COLUMNS),
                            contacts=np.asarray(self.contacts), wall_contacts=np.asarray(self.wall_contacts),
                            bonds=np.asarray(self.bonds), radii=sim.spheres.radii, fixed=sim.spheres.fixed,
                            bond_i=sim.spheres.bond_i, bond_j=sim.spheres.bond_j, bond_intact=sim.bond_intact,
                            bond_break_time=sim.bond_break_time,
                            **({"block_pos": np.asarray(self.block_pos), "block_quat": np.asarray(self.block_quat)}
                               if self.block_pos else {}))


def _wall_arrays(walls):
    """World geometry of fixed convex polyhedra: vertices, face planes, face loops, per-wall ranges, boxes."""
    verts, fn, fd, fvs, fv, fstart, boxes = [], [], [], [0], [], [0], []
    nv = 0
    for s in walls or []:
        v = np.asarray(s.vertices, float).reshape(-1, 3)
        faces = [list(map(int, f)) for f in s.faces]
        half_edges(len(v), faces)
        check_convex(v, faces)
        n_, d_ = face_planes(v, faces)
        verts.append(v)
        fn.append(n_)
        fd.append(d_)
        for f in faces:
            fv.extend(x + nv for x in f)
            fvs.append(len(fv))
        nv += len(v)
        fstart.append(fstart[-1] + len(faces))
        boxes.append(np.r_[v.min(0), v.max(0)])
    cat = (lambda a, sh: np.ascontiguousarray(np.concatenate(a)) if a else np.zeros(sh))
    return (cat(verts, (0, 3)), cat(fn, (0, 3)), cat(fd, (0,)), np.array(fvs, np.int64), np.array(fv, np.int64),
            np.array(fstart, np.int64), np.array(boxes, float).reshape(-1, 6))


def _aligned_rows(n, width, align=64):
    """Zeroed (n, width) float array whose rows start on `align`-byte boundaries (width * 8 a multiple of it)."""
    buf = np.zeros(n * width + align // 8)
    off = (-buf.ctypes.data % align) // 8
    return buf[off:off + n * width].reshape(n, width)


class SphereSimulation:
    """Explicit run of a SphereSet (and fixed polyhedral walls): the sphere counterpart of dda.Simulation.

    `walls`: BlockSpecs (fixed walls), or a BlockSystem (all fixed: walls; some moving: blocks stepped with
    the spheres, see the module docstring), `wall_law`: the sphere-block ContactLaw (default `law`),
    `block_law` / `pair_laws`: the block-block laws of a moving BlockSystem. dt None: `safety` times the critical step (2 / omega for the stiffest sphere: its bonds plus four
    contacts, shear springs counted with the rotational factor 1 + 1 / (2/5))."""

    def __init__(self, spheres: SphereSet, law: ContactLaw | None = None, walls=None, wall_law=None,
                 gravity=(0.0, 0.0, -9.81), dt=None, safety=0.5, local_damping=0.0, record_positions=True,
                 block_law=None, pair_laws=None, viscous_damping=0.0):
        self.spheres = ss = spheres
        self.law = law or ContactLaw()
        self.gravity = np.asarray(gravity, float).reshape(3)
        self.local_damping = float(local_damping)
        self.viscous_damping = float(viscous_damping)  # c [N s/m]: a force -c v on every free sphere
        if not (math.isfinite(self.viscous_damping) and self.viscous_damping >= 0.0):
            raise ValueError(f"viscous damping must be a finite c >= 0 N s/m (got {viscous_damping!r})")
        self.record_positions = bool(record_positions)
        if ss.n_bonds and not np.all(np.isfinite(ss.bond_kn)):
            raise ValueError("bond stiffness must be finite")
        self.blocks = None
        if hasattr(walls, "arrays") and not np.all(walls.arrays().fixed):
            self._init_coupled(walls, wall_law, block_law, pair_laws, dt, safety)
            return
        if hasattr(walls, "arrays"):
            A = walls.arrays()
            from .blockspec import BlockSpec
            from .system import quat_to_matrix

            specs = []
            for i in range(A.n):
                v = A.pos[i] + matmul(A.vloc[A.vert_start[i]:A.vert_start[i + 1]], quat_to_matrix(A.quat[i]).T)
                faces = [list(A.face_verts[A.face_vert_start[f]:A.face_vert_start[f + 1]] - A.vert_start[i])
                         for f in range(A.face_start[i], A.face_start[i + 1])]
                specs.append(BlockSpec(v, faces))
            walls = specs
        walls = list(walls or [])
        self.wvert, self.wfn, self.wfd, self.wfv_start, self.wfv, self.wface_start, self.waabb = _wall_arrays(walls)
        row = np.array(self.law.row(), float)
        wrow = np.array((wall_law or self.law).row(), float)
        self.lawrow = row
        self.wall_lawrow = np.ascontiguousarray(np.tile(wrow, (len(walls), 1)).reshape(-1, 6))
        self._init_sphere_state()
        self.dt_crit = self.critical_dt()
        self.dt = float(dt) if dt is not None else float(safety) * self.dt_crit
        if not self.dt > 0:
            raise ValueError(f"time step must be > 0 (got {dt!r})")
        self.dt_prev = 0.0
        self.time = 0.0
        self.steps = 0
        self.E0 = None

    def _init_sphere_state(self):
        ss = self.spheres
        n = ss.n
        self.x = ss.centers.copy()
        self.x0 = ss.centers.copy()
        self.v = np.where(ss.fixed[:, None], 0.0, ss.velocity).astype(float)
        self.w = np.where(ss.fixed[:, None], 0.0, ss.angular_velocity).astype(float)
        self.m = ss.mass.copy()
        self.inertia = 0.4 * ss.mass * ss.radii ** 2
        self.fixed = ss.fixed.copy()
        self.kin = ss.prescribed & ~ss.fixed
        self.bforce = np.ascontiguousarray(ss.body_force, float)
        # bond constants and state in one row per bond (dda/_spheres.py): bond_us and bond_fn are views of it
        self.bond_rows = np.zeros((ss.n_bonds, NBOND_COLS))
        for col, arr in enumerate((ss.bond_len0, ss.bond_kn, ss.bond_ks, ss.bond_ft, ss.bond_fs, ss.bond_zeta)):
            self.bond_rows[:, col] = arr
        self.bond_rows[:, 10] = ss.radii[ss.bond_i] / (ss.radii[ss.bond_i] + ss.radii[ss.bond_j])
        self.bond_us = self.bond_rows[:, 6:9]
        self.bond_intact = np.ones(ss.n_bonds, bool)
        self.bond_fn = self.bond_rows[:, 9]
        # central bonds (ks = 0): their own compact rows (dda/_spheres.py); bond_fn gets their normal force back
        # after each call
        central = ss.bond_ks == 0.0
        self.bond_full = np.flatnonzero(~central).astype(np.int64)
        self.cbond_idx = np.flatnonzero(central).astype(np.int64)
        self.cbond_ij = np.ascontiguousarray(np.c_[ss.bond_i[central], ss.bond_j[central]].astype(np.int32))
        self.cbond_rows = np.zeros((len(self.cbond_idx), 3))
        self.cbond_fn = np.zeros(len(self.cbond_idx))
        self.cbond_rows[:, 0] = ss.bond_len0[central]
        self.cbond_rows[:, 1] = ss.bond_kn[central]
        self.cbond_rows[:, 2] = ss.bond_ft[central]
        zc = ss.bond_zeta[central]
        self.cbond_zeta = np.ascontiguousarray(zc, float) if np.any(zc > 0) else np.zeros(0)
        self.sphere_rows = (_aligned_rows(n, 8), _aligned_rows(n, 8), _aligned_rows(n, 4, 32))
        self.bond_break_time = np.full(ss.n_bonds, -1.0)
        self.bkey_tab, self.bkey_slot = build_bond_hash(ss.bond_i, ss.bond_j, n)
        # bonds per sphere (CSR on the lower index): the pair-list build skips bonded pairs with it
        lo, hi = np.minimum(ss.bond_i, ss.bond_j), np.maximum(ss.bond_i, ss.bond_j)
        order = np.lexsort((hi, lo))
        self.bond_start = np.searchsorted(lo[order], np.arange(n + 1)).astype(np.int64)
        self.bond_nbr = np.ascontiguousarray(hi[order], np.int64)
        self.bond_idx = np.ascontiguousarray(order, np.int64)
        # smooth joints: in contact at the start when touching (reference gap: the projected distance now)
        nj = ss.n_joints
        self.joint_i = ss.joint_i.copy()
        self.joint_j = ss.joint_j.copy()
        self.joint_normal = np.ascontiguousarray(ss.joint_normal, float).reshape(-1, 3)
        self.joint_tanphi = ss.joint_tanphi.astype(float)
        d = self.x[self.joint_j] - self.x[self.joint_i]
        dn = np.einsum("ij,ij->i", d, self.joint_normal)
        self.joint_on = np.linalg.norm(d, axis=1) <= (1.0 + ss.joint_touch) * (ss.radii[self.joint_i]
                                                                                + ss.radii[self.joint_j])
        self.joint_init = np.abs(dn)
        self.joint_slide = np.zeros(nj)
        self.joint_us = np.zeros((nj, 3))
        self.joint_sign = np.where(dn >= 0, 1.0, -1.0)
        self.jkey_tab, self.jkey_slot = build_bond_hash(self.joint_i, self.joint_j, n)
        # Verlet pair list of the sphere-sphere contacts (margin skin; rebuilt when a sphere moved skin / 2)
        self.skin = 0.2 * float(ss.radii.min())
        self.nl_pairs = np.zeros((max(64, 2 * n), 2), np.int64)
        self.nl_n = np.zeros(1, np.int64)
        self.nl_flag = np.ones(1, np.int64)
        self.x_ref = self.x.copy()
        self._alloc(max(64, 8 * n))
        self.energy = np.zeros(NENERGY)
        self.acc = np.zeros(1)
        self.stats = np.zeros(8)

    def _init_coupled(self, system, wall_law, block_law, pair_laws, dt, safety):
        """Spheres with moving blocks: a block Simulation stepped inside the coupled loop (dda/_coupled.py)."""
        ss = self.spheres
        self.lawrow = np.array(self.law.row(), float)
        wl = wall_law or self.law
        self.blocks = bsim = Simulation(system, block_law or wl, gravity=self.gravity, dt=1.0,
                                        local_damping=self.local_damping, pair_laws=pair_laws)
        A = bsim.A
        nb = A.n
        self.wall_lawrow = np.ascontiguousarray(np.tile(np.array(wl.row(), float), (nb, 1)))
        self.wvert = np.zeros((0, 3))  # walls are blocks of the block system here
        self.waabb = np.zeros((0, 6))
        self._init_sphere_state()
        bsim.fext = np.zeros((nb, 3))
        bsim.text = np.zeros((nb, 3))
        bsim.qext = np.zeros((nb, 6))
        self.bstamp = np.full(nb, -1, np.int64)
        self.btag = np.zeros(1, np.int64)
        self.sforce = np.zeros((ss.n, 3))
        self.storque = np.zeros((ss.n, 3))
        self.sres = np.zeros(4)  # R_* slots (dda/_sphere_state.py)
        # the coupled loop searches its sphere pairs on a grid each step: no pair list (a broken bond has none to join)
        self.no_pairs = PairList(np.zeros((0, 2), np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64),
                                 np.zeros((0, 3)), 0.0)
        self.resume = False
        # common critical step: the spheres' (their springs with the sphere-block kn), the blocks' (their own
        # law), and the blocks under NPOINT sphere-block springs
        dts = self.critical_dt()
        dtb = bsim.dt_crit
        free = bsim.free
        if len(free):
            k = NPOINT * float(self.wall_lawrow[:, 0].max())
            m = A.mass[free]
            imin = A.inertia[free].min(1)
            rr = A.radius[free]
            z = float(self.wall_lawrow[:, 5].max())
            dtb = min(dtb, float((2.0 / np.sqrt(k / m) * (np.sqrt(1 + z * z) - z)).min()),
                      float((2.0 / np.sqrt(k * rr * rr / imin)).min()))
        self.dt_crit = min(dts, dtb)
        self.dt = float(dt) if dt is not None else float(safety) * self.dt_crit
        if not self.dt > 0:
            raise ValueError(f"time step must be > 0 (got {dt!r})")
        bsim.dt = self.dt
        self.dt_prev = 0.0
        self.time = 0.0
        self.steps = 0
        self.E0 = None

    def _chunk_coupled(self, nsteps):
        from . import _coupled as _cp  # lazy: the coupled kernels load (or compile) only for runs with blocks

        b = self.blocks
        A = b.A
        link = Link(A.face_vert_start, A.face_verts, self.bstamp, self.btag, self.wall_lawrow)
        mo = Motion(self.x, self.v, self.w, self.sforce, self.storque)
        while True:
            sp, env, bonds, joints, hist, books = self.bundles()
            status, done, fit, lists = _cp.run_coupled(nsteps, self.resume, self.dt, self.dt_prev, self.time,
                                                       b.first_step, env, sp, mo, bonds, joints, hist, books,
                                                       self.sres, link, self.no_pairs, b.bundles())
            b.set_lists(lists)
            self._central_fn()
            self.resume = False
            if done:
                self.dt_prev = self.dt
                b.dt_prev = self.dt
                b.first_step = False
            self.steps += done
            self.time += done * self.dt
            b.steps = self.steps
            b.time = self.time
            b.fcp_iterations += int(fit)
            nsteps -= done
            if status == _cp.NEED_BLOCK_CAPACITY:
                b._grow_contacts(int(b.stats[2]))
                self.resume = True  # this step's sphere forces are computed already
                continue
            if status == _cp.NEED_CAPACITY:
                self._grow_sphere_contacts()
                continue
            return _sp.BLOWUP if status == _cp.BLOWUP else _sp.OK

    def _grow_sphere_contacts(self):
        old = (self.cur.copy(), self.c_n.copy(), self.c_key, self.c_us, self.c_fn, self.c_ij)
        cap = self.c_key.shape[1]
        self._alloc(max(2 * cap, int(1.5 * self.stats[4])))
        self.cur[:], self.c_n[:] = old[0], old[1]
        self.c_key[:, :cap], self.c_us[:, :cap], self.c_fn[:, :cap], self.c_ij[:, :cap] = old[2:]

    def total_energy(self):
        """Energy terms (kinetic, potential, elastic, friction, damping, local damping) of spheres and blocks."""
        return self.energy + (self.blocks.energy if self.blocks is not None else 0.0)

    def _alloc(self, cap):
        self.cur = np.zeros(1, np.int64)
        self.c_n = np.zeros(2, np.int64)
        self.c_key = np.zeros((2, cap), np.int64)
        self.c_us = np.zeros((2, cap, 3))
        self.c_fn = np.zeros((2, cap))
        self.c_ij = np.zeros((2, cap, 2), np.int64)
        hs = 16
        while hs < 2 * cap + 16:
            hs *= 2
        self.htab = np.full(hs, -1, np.int64)

    def critical_dt(self):
        """The stable step of dda/timestep.py, with the walls' stiffness counted into the contact law's."""
        ss = self.spheres
        kn, ks = self.lawrow[0], self.lawrow[1]
        if len(self.wall_lawrow):
            kn = max(kn, self.wall_lawrow[:, 0].max())
            ks = max(ks, self.wall_lawrow[:, 1].max())
        return sphere_critical_dt(self.m, ~(self.fixed | self.kin), kn, ks, self.lawrow[5], ss.bond_i, ss.bond_j,
                                  ss.bond_kn, ss.bond_ks, ss.bond_zeta)

    def _chunk(self, nsteps):
        if self.blocks is not None:
            return self._chunk_coupled(nsteps)
        walls = Walls(self.wvert, self.wfn, self.wfd, self.wfv_start, self.wfv, self.wface_start, self.waabb,
                      self.wall_lawrow)
        while True:
            sp, env, bonds, joints, hist, books = self.bundles()
            pl = PairList(self.nl_pairs, self.nl_n, self.nl_flag, self.x_ref, self.skin)
            status, done = _sp.run_spheres(nsteps, self.dt, self.dt_prev, self.time, env, sp, self.sphere_rows,
                                           walls, bonds, joints, pl, hist, books)
            if done:
                self.dt_prev = self.dt
            self._central_fn()
            self.steps += done
            self.time += done * self.dt
            nsteps -= done
            if status == _sp.NEED_CAPACITY:
                self._grow_sphere_contacts()
                continue
            if status == _sp.NEED_PAIRS:
                self.nl_pairs = np.zeros((int(1.5 * self.stats[ST_NEED_PAIRS]) + 64, 2), np.int64)
                self.nl_flag[0] = 1
                continue
            return status

    def bundles(self):
        """The sphere state as the kernels' bundles (dda/_sphere_state.py): (Spheres, Env, Bonds, Joints,
        History, Books), views of this object's arrays (built anew after the contact buffers grow)."""
        ss = self.spheres
        sp = Spheres(self.x, self.v, self.w, ss.radii, self.m, self.inertia, self.fixed, self.kin, self.bforce)
        env = Env(self.gravity, self.local_damping, self.viscous_damping, self.lawrow)
        bonds = Bonds(ss.bond_i, ss.bond_j, self.bond_rows, self.bond_intact, self.bond_break_time, self.bond_start,
                      self.bond_nbr, self.bond_idx, self.bond_full, self.cbond_idx, self.cbond_ij, self.cbond_rows,
                      self.cbond_fn, self.cbond_zeta, self.bkey_tab, self.bkey_slot)
        joints = Joints(self.joint_i, self.joint_j, self.joint_normal, self.joint_tanphi, self.joint_on,
                        self.joint_init, self.joint_slide, self.joint_us, self.joint_sign, self.jkey_tab,
                        self.jkey_slot)
        hist = History(self.cur, self.c_n, self.c_key, self.c_us, self.c_fn, self.c_ij, self.htab)
        return sp, env, bonds, joints, hist, Books(self.energy, self.acc, self.stats)

    def _central_fn(self):
        """The central bonds' normal forces (written by the kernel in the last step of a call) into bond_fn."""
        if len(self.cbond_idx):
            self.bond_rows[self.cbond_idx, B_FN] = self.cbond_fn

    def _record(self, res):
        res.time.append(self.time)
        if self.record_positions:
            res.pos.append(self.x.copy())
            res.vel.append(self.v.copy())
        e = self.total_energy()
        total = float(e.sum())
        if self.blocks is not None:
            res.block_pos.append(self.blocks.pos.copy())
            res.block_quat.append(self.blocks.quat.copy())
        res.energy.append(np.r_[e, total - self.E0 if self.E0 is not None else 0.0])
        res.contacts.append(int(self.stats[0]))
        res.wall_contacts.append(int(self.stats[1]))
        res.bonds.append(int(self.bond_intact.sum()))

    def run(self, duration, record_every=None, progress=None) -> SphereResults:
        """Advance by `duration` seconds, recording every `record_every` seconds (default duration / 100);
        `progress` as for dda.simulation.Simulation.run.

        Raises BlowUpError (with the results so far) on a non-finite state."""
        nsteps = max(1, int(round(duration / self.dt)))
        rec = max(1, int(round((record_every or duration / 100) / self.dt)))
        res = SphereResults(dt=self.dt)
        if self.E0 is None:
            self._record(res)
        t_wall = time.perf_counter()
        clock = tracker(progress, self, duration)
        left = nsteps
        while left > 0:
            n = 1 if self.E0 is None else min(rec - (self.steps % rec), left)
            status = self._chunk(n)
            left -= n
            if self.E0 is None:
                self.E0 = float(self.total_energy().sum())
                res.energy[0] = np.r_[self.total_energy(), 0.0]
                if left > 0 and self.steps % rec:
                    continue
            if status == _sp.BLOWUP or not np.all(np.isfinite(self.total_energy())):
                raise BlowUpError(f"blow-up near t = {self.time:.6g} s (step {self.steps}): non-finite state; "
                                  f"dt = {self.dt:.3g} s (critical {self.dt_crit:.3g} s)", res)
            self._record(res)
            clock.update(self.time, self.steps, f"contacts {int(self.stats[0])}  "
                         f"{'block' if self.blocks is not None else 'wall'} {int(self.stats[1])}  "
                         f"bonds {int(self.stats[2])}", end=left == 0)
        res.wall_s = time.perf_counter() - t_wall
        return res

    def displacement(self):
        return self.x - self.x0

    def contacts(self):
        """Current contacts: i (sphere, or -1 - wall), j (sphere), normal force, shear displacement."""
        c = int(self.cur[0])
        k = int(self.c_n[c])
        return {"i": self.c_ij[c, :k, 0].copy(), "j": self.c_ij[c, :k, 1].copy(), "fn": self.c_fn[c, :k].copy(),
                "shear": self.c_us[c, :k].copy()}


def held_by_bonds(n, bond_i, bond_j, anchored):
    """(n,) bool: the spheres not `anchored` (fixed or prescribed) that a path of bonds ties to an anchored one:
    the part of a model that has a static equilibrium under its bonds."""
    from scipy.sparse import coo_matrix  # scipy only for the static solves (start-up time)
    from scipy.sparse.csgraph import connected_components

    anchored = np.asarray(anchored, bool)
    if n == 0:
        return np.zeros(0, bool)
    g = coo_matrix((np.ones(len(bond_i)), (np.asarray(bond_i), np.asarray(bond_j))), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    tied = np.zeros(lab.max() + 1, bool)
    tied[lab[anchored]] = True
    return tied[lab] & ~anchored


def bond_network_static(centers, mass, anchored, bond_i, bond_j, bond_kn, bond_ks, gravity):
    """Static displacement (n, 3) of a bond network under the weights m g: the sparse linear solve of K u = m g
    over the spheres held by bonds (held_by_bonds; the others stay 0). Each bond is a normal spring kn along its
    centre line plus a shear spring ks across it (central bonds: ks = 0; rotations left out). ValueError when
    the network is a mechanism (no finite solution)."""
    from scipy.sparse import coo_matrix  # scipy only for the static solves (start-up time)
    from scipy.sparse.linalg import spsolve

    c = np.asarray(centers, float).reshape(-1, 3)
    n = len(c)
    i, j = np.asarray(bond_i, np.int64), np.asarray(bond_j, np.int64)
    d = c[j] - c[i]
    e = d / np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
    ee = e[:, :, None] * e[:, None, :]
    kn, ks = np.asarray(bond_kn, float), np.asarray(bond_ks, float)
    blocks = kn[:, None, None] * ee + ks[:, None, None] * (np.eye(3)[None] - ee)  # (m, 3, 3)
    rows, cols, vals = [], [], []
    for a, b, s in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
        for p in range(3):
            for q in range(3):
                rows.append(3 * a + p)
                cols.append(3 * b + q)
                vals.append(s * blocks[:, p, q])
    K = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))
    K = K.tocsr()
    f = (np.asarray(mass, float)[:, None] * np.asarray(gravity, float)[None, :]).ravel()
    free = np.repeat(held_by_bonds(n, i, j, anchored), 3)
    u = np.zeros(3 * n)
    if free.any():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            u[free] = spsolve(K[free][:, free].tocsc(), f[free])
        if not np.all(np.isfinite(u)):
            raise ValueError("the bond network is a mechanism (no static solution)")
    return u.reshape(n, 3)


def first_mode(centers, mass, anchored, bond_i, bond_j, bond_kn, bond_ks, gravity):
    """(omega [rad/s], mean mass [kg]) of a bond network's first mode: the Rayleigh quotient of its static
    deflection under `gravity` (bond_network_static; straight down when gravity is zero) over the spheres held by
    bonds. ValueError when no sphere is held."""
    g = np.asarray(gravity, float).reshape(3)
    if not np.any(g):
        g = np.array([0.0, 0.0, -9.81])
    mass = np.asarray(mass, float)
    u = bond_network_static(centers, mass, anchored, bond_i, bond_j, bond_kn, bond_ks, g)
    held = held_by_bonds(len(mass), bond_i, bond_j, anchored)
    work = float(np.sum(mass * (u @ g)))
    uu = float(np.sum(mass * np.einsum("ij,ij->i", u, u)))
    if not (held.any() and work > 0 and uu > 0):
        raise ValueError("no sphere is tied by bonds to a fixed sphere: the model has no first mode")
    return math.sqrt(work / uu), float(mass[held].mean())


def viscous_coefficient(zeta, centers, mass, anchored, bond_i, bond_j, bond_kn, bond_ks, gravity):
    """c [N s/m] of a force -c v on every free sphere that damps the network's first mode (first_mode) at the
    ratio of critical damping `zeta`: c = 2 zeta m_mean omega_1 (0 for zeta = 0). ValueError as first_mode."""
    if zeta == 0.0:
        return 0.0
    omega, m = first_mode(centers, mass, anchored, bond_i, bond_j, bond_kn, bond_ks, gravity)
    return 2.0 * float(zeta) * m * omega


__all__ = ["BondLaw", "SphereSet", "SphereSimulation", "SphereResults", "bond_network_static", "first_mode",
           "held_by_bonds", "load_model", "viscous_coefficient"]
