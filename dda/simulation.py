"""Explicit 3D DDA simulation: contact law, time step, the run loop in numba chunks, energy balance.

Usage::

    from dda.system import BlockSystem
    from dda.simulation import Simulation, ContactLaw
    bs = BlockSystem(); i = bs.add_block(spec, density=2600.0)
    law = ContactLaw(kn=1e9, ks=5e8, friction_deg=30.0)
    sim = Simulation(bs, law, gravity=(0, 0, -9.81), dt=None, safety=0.5)
    res = sim.run(duration=1.0, record_every=0.01)
    sim.displacement(i), sim.velocity(i)

Per material-pair contact properties: ``Simulation(bs, law, pair_laws={("rock", "joint"): ContactLaw(...)})``;
the material names are the blocks' ``material`` fields, pairs are unordered, and ``law`` applies to every pair
not listed.

Contact law (per contact point; see dda/_contact.py): ``kn`` and ``ks`` [N/m] are the penalty springs of one
contact point (a block resting on a face has four points, so its normal stiffness is 4 kn); ``cohesion`` and
``tensile`` [Pa] act on the point's share of the contact polygon's area and only on contacts present at the
start of the run (bonded until they first fail); ``damping`` is the ratio of critical viscous damping of the
normal spring (0 for elastic impacts). ``local_damping`` (Cundall's non-viscous damping, a fraction of the
out-of-balance force opposing each velocity component) is for quasi-static runs only.

Loads and prescribed motion (see dda/system.py): ``bs.add_body_load(i, force)``, ``bs.add_point_load(i, point,
force)``, ``bs.add_block(spec, prescribed=True)``. Their energy: the constant loads' potential -F.x is part of
the potential column, and so is minus the work the prescribed blocks do on the others (the driver's input).

Sleeping (``sleep=True``): a free block whose mean speed over ``sleep_steps`` steps (centroid speed plus angular
speed times its size) is below ``sleep_velocity`` and whose mean acceleration over them (the least-squares slope of
that velocity) is below ``sleep_accel`` -- means, so that the ringing of a block resting on stiff contacts averages
out; no step's speed may exceed ten times sleep_velocity -- and that touches no moving block (one whose last step
or window failed the test), is no longer integrated nor searched for contacts (its resting contacts are kept as
they are); it wakes when a moving block comes near, at rest, and counts as moving (waking its sleeping neighbours
in turn) only once it fails a test itself, a step's speed above sleep_velocity failing it until its first window
ends. Defaults:
sleep_velocity = 1e-4 sqrt(g d50), sleep_accel = 1e-3 g (d50 the median block size; g = 9.81 without
gravity). ``sim.active`` lists the awake moving blocks, ``sim.asleep`` flags the sleeping ones;
``sim.fall_asleep(blocks)`` puts free blocks to sleep at once (a run that starts from a settled state).

Deformable blocks (``dof = 12`` in the BlockSpec, E and nu of the block's material): the state adds six
body-frame strains (``sim.strain(i)``, engineering shear strains, the constant strain of DDA's first-order
displacement function) in a co-rotational form, x = x0 + R (I + E) X (see dda/_deform.py), so a large rotation
gives no strain; contact and load forces enter through T^T f and the strain energy V/2 e.C e counts with the
elastic energy. ``sim.set_strain(i, e)`` imposes an initial strain, ``sim.volume(i)`` is the deformed volume.
The time step then also resolves the fastest strain mode. Deformable blocks never sleep.

Time step: ``dt=None`` takes ``safety * 2 / omega_max`` with omega_max from the stiffest contact (NPOINT
points of the largest kn in parallel: a block held between two faces) on the smallest moving mass, and for
rotation from the same springs at the block's worst vertex (``rotation_bound``: the largest eigenvalue of the
vertex's point inertia against the block's, so a long thin block is not held to its length over its smallest
moment of inertia). With local damping alpha the bound is divided by sqrt(1 + alpha): in the fastest mode the
velocity turns at every step, the damping force (against the velocity before the step) then points along the new
one and the springs act as (1 + alpha) times as stiff.
"""
from __future__ import annotations

import math
import time

import numpy as np

from sgim.portable import det3, matmul, norm

from . import _integrate as _it
from ._broad import LARGE, build_grid, buckets_for, map_cells, n_cells
from ._deform import critical_omega2, deform_geometry
from ._fcp import MAXP
from ._state import (ACC_SLEEPING, E_DAMPING, LAW_KN, LAW_TEN, LAW_ZETA, NENERGY, NLAW, NSTATS, ST_BLOCK_STEPS,
                     ST_CONTACTS, ST_FCP_ITER, ST_NEED, ST_POINTS, Blocks, Books, Contacts, Deform, Forces, Geometry,
                     Grid, Law, Lists, Loads, Sleep, State)
from .contactlaw import ContactLaw
from ._kinds import no_kinds
from .progress import tracker
from .results import Results
from .system import quat_to_matrix


def block_dt_bounds(A, which, kn, zeta):
    """(dt_t, dt_r) of the blocks `which` of the system arrays A: 2 / omega for contact springs kn (NPOINT of
    them) on the block in translation and in rotation (at its worst vertex, rotation_bound), shortened by the
    viscous damping ratio zeta. Both scale as the square root of the block's density."""
    k = NPOINT * kn
    m = A.mass[which]
    lam = rotation_bound(A.vloc, A.vert_start, A.inertia, A.radius, which)
    # viscous damping shortens the stable step: dt < 2 / w (sqrt(1 + z^2) - z). The point dampers are sized on
    # the translational mass (c / k = 2 zeta sqrt(m / k)), so the rotational mode w^2 = k lam sees the ratio
    # z sqrt(m lam).
    zr = zeta * np.sqrt(m * lam)
    dt_t = 2.0 / np.sqrt(k / m) * (np.sqrt(1.0 + zeta * zeta) - zeta)
    dt_r = 2.0 / np.sqrt(k * lam) * (np.sqrt(1.0 + zr * zr) - zr)
    return dt_t, dt_r


def rotation_bound(vloc, vert_start, inertia, radius, which):
    """Per block of `which`: an upper bound of omega^2 / k for a spring of stiffness k acting anywhere on the
    block in rotation, the largest over its vertices r (body frame, principal axes) of the largest eigenvalue of
    I^-1/2 (|r|^2 E - r r^T) I^-1/2 (the moment arm |u x r| of the spring's normal about any axis u is at most
    the distance of the point from that axis, largest at a vertex). The eigenvalue, of diag(d) - w w^T with
    d = |r|^2 / I, w = r / sqrt(I), is the secular equation's root in [d_2, d_1], bisected to its upper end
    with correctly rounded arithmetic only (the same bits on every CPU). It is never above the older bound
    r_max^2 / I_min, which it keeps where it gives no gain (cubes, spheres of inertia), and it is much lower for
    needles and slabs: a long thin block turning about its length has small inertia but short arms."""
    which = np.asarray(which, np.int64)
    old = radius[which] ** 2 / inertia[which].min(1)
    if len(which) == 0:
        return old
    cnt = vert_start[which + 1] - vert_start[which]
    idx = np.repeat(vert_start[which] - np.cumsum(cnt) + cnt, cnt) + np.arange(int(cnt.sum()))
    r = vloc[idx]
    ii = inertia[np.repeat(which, cnt)]
    r2 = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1] + r[:, 2] * r[:, 2]
    d = r2[:, None] / ii
    w2 = r * r / ii
    order = np.argsort(-d, axis=1, kind="stable")
    d = np.take_along_axis(d, order, 1)
    w2 = np.take_along_axis(w2, order, 1)
    lo, hi = d[:, 1].copy(), d[:, 0].copy()
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        g = np.zeros_like(mid)
        for a in range(3):
            den = d[:, a] - mid
            g = g + np.where(den != 0.0, w2[:, a] / np.where(den != 0.0, den, 1.0), -np.inf)
        above = g > 1.0  # g rises on (d_2, d_1): the root lies below mid
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    lam = np.maximum.reduceat(hi, np.cumsum(cnt) - cnt)
    return np.where(lam < old * (1.0 - 1e-9), lam, old)


def _strain_tensor(e):
    return np.array([[e[0], e[5] / 2, e[4] / 2], [e[5] / 2, e[1], e[3] / 2], [e[4] / 2, e[3] / 2, e[2]]])


NPOINT = 8  # contact points assumed in parallel on one block (a block held between two faces) for the critical step


class BlowUpError(RuntimeError):
    """The run became unstable (non-finite state or an energy jump); `.results` holds the last good state."""

    def __init__(self, message, results=None):
        super().__init__(message)
        self.results = results


class Simulation:
    """Explicit DDA run of a BlockSystem: central differences, the uniform-grid broad phase, Fast Common-Plane
    contacts with the ContactLaw (per material pair with `pair_laws`), gravity, local damping and sleeping
    blocks. ``run(duration)`` advances it and returns the recorded Results (dda/results.py)."""

    def __init__(self, system, law: ContactLaw | None = None, gravity=(0.0, 0.0, -9.81), dt=None, safety=0.5,
                 local_damping=0.0, pair_laws=None, cell_factor=1.5, blowup_ratio=0.5, sleep=False,
                 sleep_velocity=None, sleep_accel=None, sleep_steps=200, on_dt=None, face_laws=None):
        """`on_dt(sim)`, if given, is called as soon as the time step is known, before any kernel is loaded
        (the step limit of dda/limits.py refuses an endless run at once). `face_laws`: (face_row, face_shape,
        face_geo, intact_row), the law row of each face of a cut block model (dda/_kinds.py; dda/georun.py
        makes them); None: the blocks' materials decide every law."""
        self.face_laws = no_kinds() if face_laws is None else face_laws
        self.system = system
        self.law = law or ContactLaw()
        self.gravity = np.asarray(gravity, float)
        self.local_damping = float(local_damping)
        self.safety = float(safety)
        self.blowup_ratio = float(blowup_ratio)
        A = system.arrays()
        self.A = A
        nb = A.n
        if nb == 0:
            raise ValueError("the block system is empty")
        mats = system.materials
        nm = len(mats)
        tab = np.empty((nm, nm, NLAW))
        tab[:, :] = self.law.row()
        for (m1, m2), lw in (pair_laws or {}).items():
            if m1 not in mats or m2 not in mats:
                continue
            a, b = mats.index(m1), mats.index(m2)
            tab[a, b] = tab[b, a] = lw.row()
        self.lawtab = tab
        # state (copies: the BlockSystem stays the initial state)
        self.pos = A.pos.copy()
        self.pos0 = A.pos.copy()
        self.quat = A.quat.copy()
        self.vel = A.vel.copy()
        self.angmom = A.angmom.copy()
        # deformable blocks: body-frame angular velocity, strains and strain rates (see dda/_deform.py)
        self.dof12 = (A.dof == 12) & ~A.fixed
        self.strain_ = np.zeros((nb, 6))
        self.srate = np.zeros((nb, 6))
        self.wb = np.zeros((nb, 3))
        self.qs = np.zeros((nb, 6))
        for i in np.nonzero(self.dof12)[0]:
            R = quat_to_matrix(self.quat[i])
            self.wb[i] = matmul(R.T, self.angmom[i]) / A.inertia[i]
            self.angmom[i] = 0.0
        self.active = np.nonzero(~A.fixed)[0].astype(np.int64)
        self.movable = self.active.copy()
        self.free = np.nonzero(~A.fixed & ~A.kin)[0].astype(np.int64)
        # time step
        self.dt_crit = self.critical_dt()
        self.dt = float(dt) if dt is not None else self.safety * self.dt_crit
        if not self.dt > 0:
            raise ValueError(f"time step must be > 0 (got {dt!r})")
        if on_dt is not None:
            on_dt(self)
        # called once, after the first step of the first run (its contacts are then found): dda/georun.py's key
        # block screening
        self.after_first_step = None
        self.asleep = np.zeros(nb, bool)
        self.calm = np.zeros(nb, np.int64)
        self.sw = np.zeros((nb, 12))
        self.ke_step = np.zeros(nb)
        self.woke = np.zeros(nb, np.bool_)
        self.pe_sl = np.zeros(nb)
        self.acc = np.zeros(2)  # [work of the prescribed blocks, potential energy of the sleeping blocks]
        self.vert = np.zeros_like(A.vloc)
        self.fnw = np.zeros_like(A.nloc)
        self.fdw = np.zeros_like(A.dloc)
        self.aabb = np.zeros((nb, 6))
        for i in range(nb):
            _it.update_geometry(i, self.pos, self.quat, A.vert_start, A.face_start, A.vloc, A.nloc, A.dloc,
                                self.vert, self.fnw, self.fdw, self.aabb)
        ext = self.aabb[:, 3:] - self.aabb[:, :3]
        self.size_b = ext.max(1)
        self.d50 = float(np.median(self.size_b))
        self.S = cell_factor * self.d50
        self.margin = 0.05 * self.S
        kn_max = float(tab[:, :, LAW_KN].max())
        area = self.d50 ** 2
        ten = tab[:, :, LAW_TEN]
        self.keep_gap = float(np.max(ten) * area / kn_max) if np.any(ten > 0) else 0.0
        self.gap = 0.02 * self.d50 + self.keep_gap
        # grids
        self.cellbox = np.zeros((nb, 6), np.int64)
        self.large = np.zeros(nb, bool)
        for i in range(nb):
            map_cells(self.aabb, i, self.S, self.margin, self.cellbox)
            self.large[i] = n_cells(self.cellbox, i) > LARGE
        fixed_idx = np.nonzero(A.fixed)[0].astype(np.int64)
        nent = int(sum(n_cells(self.cellbox, i) for i in fixed_idx if not self.large[i]))
        self.fstart, self.fentries = build_grid(fixed_idx, self.cellbox, self.large, buckets_for(nent))
        nent = int(sum(n_cells(self.cellbox, i) for i in self.active if not self.large[i]))
        self.mstart, self.mentries = build_grid(self.active, self.cellbox, self.large, buckets_for(nent))
        self.large_list = np.nonzero(self.large)[0].astype(np.int64)
        self.stamp = np.full(nb, -1, np.int64)
        self.tag = np.zeros(1, np.int64)
        self.pa = np.zeros(1024, np.int64)
        self.pb = np.zeros(1024, np.int64)
        self._alloc_contacts(max(256, 4 * nb))
        self.force = np.zeros((nb, 3))
        self.torque = np.zeros((nb, 3))
        self.dsum = np.zeros((nb, 21))
        self.dscale = np.ones(nb)
        # external force / torque / strain force per block at each step (spheres' reactions; empty: none)
        self.fext = np.zeros((0, 3))
        self.text = np.zeros((0, 3))
        self.qext = np.zeros((0, 6))
        self.energy = np.zeros(NENERGY)
        self.stats = np.zeros(NSTATS)
        g0 = norm(self.gravity) or 9.81
        v_s = 1e-4 * math.sqrt(g0 * self.d50) if sleep_velocity is None else float(sleep_velocity)
        a_s = 1e-3 * g0 if sleep_accel is None else float(sleep_accel)
        if sleep and not (v_s > 0 and a_s > 0 and sleep_steps >= 2):
            raise ValueError("sleep thresholds must be > 0 and sleep_steps >= 2")
        self.sleep_par = np.array([1.0 if sleep else 0.0, v_s, a_s, float(int(sleep_steps))])
        self.first_step = True
        # dt(0) = 0: the first step is a half step, v(1/2) = v(0) + dt/2 a(0), so the given initial
        # velocities are those at t = 0 (free fall then follows x = x0 + v0 t + g t^2 / 2 exactly)
        self.dt_prev = 0.0
        self.time = 0.0
        self.steps = 0
        self.E0 = None
        self.fcp_iterations = 0
        self.block_steps = 0  # block-steps integrated (each step's awake moving blocks, summed)
        self.cpu_s = 0.0  # CPU seconds spent in run()
        # energies below the moving weight over a thousandth of the median block size never count as a blow-up
        g = norm(self.gravity)
        self.energy_floor = max(1e-3 * self.d50 * g * float(A.mass[self.active].sum()), 1e-300)
        self.pair_tests = 0

    # ------------------------------------------------------------------
    def block_dts(self):
        """(dt_t, dt_r) of each free block (sim.free's order): block_dt_bounds with the stiffest contact law."""
        return block_dt_bounds(self.A, self.free, float(self.lawtab[:, :, LAW_KN].max()),
                               float(self.lawtab[:, :, LAW_ZETA].max()))

    def critical_dt(self):
        """2 / omega_max for the stiffest contact on the lightest moving block (translation and rotation)."""
        if len(self.free) == 0:
            return 1.0
        k = NPOINT * float(self.lawtab[:, :, LAW_KN].max())
        zeta = float(self.lawtab[:, :, LAW_ZETA].max())
        dt_t, dt_r = self.block_dts()
        dt_c = float(min(dt_t.min(), dt_r.min()))
        for i in np.nonzero(self.dof12)[0]:
            # all 12 modes of the block with the contact springs at its farthest vertex
            b = self.system.block(int(i))
            w = math.sqrt(critical_omega2(b.vloc, b.faces, b.density, b.E, b.nu, k))
            dt_c = min(dt_c, 2.0 / w * (math.sqrt(1.0 + zeta * zeta) - zeta))
        # local damping alpha |f| against the velocity before the step: in the fastest mode the velocity turns
        # each step, so the damping force points along the new velocity and the spring acts as (1 + alpha) kn
        return dt_c / math.sqrt(1.0 + self.local_damping)

    def _alloc_contacts(self, cap):
        self.cur = np.zeros(1, np.int64)
        self.c_n_pair = np.zeros(2, np.int64)
        self.c_key = np.full((2, cap), -1, np.int64)
        self.c_a = np.zeros((2, cap), np.int64)
        self.c_b = np.zeros((2, cap), np.int64)
        self.c_nrm = np.zeros((2, cap, 3))
        self.c_np = np.zeros((2, cap), np.int64)
        self.c_pid = np.zeros((2, cap, MAXP), np.int64)
        self.c_us = np.zeros((2, cap, MAXP, 3))
        self.c_state = np.zeros((2, cap, MAXP), np.int8)
        self.c_bond = np.zeros((2, cap, MAXP), np.bool_)
        self.c_pos = np.zeros((2, cap, MAXP, 3))
        self.c_fn = np.zeros((2, cap, MAXP))
        self.c_depth = np.zeros((2, cap, MAXP))
        self.c_fd = np.zeros((2, cap, MAXP, 3))  # the point's damping force last step (energy booking)
        hs = 16
        while hs < 2 * cap + 16:
            hs *= 2
        self.htab = np.full(hs, -1, np.int64)

    def _grow_contacts(self, need):
        old = {k: getattr(self, k) for k in ("cur", "c_n_pair", "c_key", "c_a", "c_b", "c_nrm", "c_np", "c_pid",
                                              "c_us", "c_state", "c_bond", "c_pos", "c_fn", "c_depth", "c_fd")}
        cap = old["c_key"].shape[1]
        self._alloc_contacts(max(2 * cap, int(need * 1.5)))
        self.cur[:] = old["cur"]
        self.c_n_pair[:] = old["c_n_pair"]
        for k, v in old.items():
            if k in ("cur", "c_n_pair"):
                continue
            getattr(self, k)[:, :cap] = v

    def bundles(self):
        """The state as the named bundles of dda/_state.py that the step kernels take (views of this Simulation's
        arrays, so the kernels advance it): a dda._state.State (blocks, deform, loads, forces, geometry, grid,
        lists, sleep, contacts, law, books), the order of dda._integrate.run_chunk's arguments after the step
        parameters."""
        A = self.A
        return State(
            Blocks(self.pos, self.vel, self.quat, self.angmom, A.mass, A.inertia, A.fixed, A.kin, A.wpres,
                   A.material, self.size_b, self.dof12),
            Deform(self.strain_, self.srate, self.wb, A.m9, A.m9inv, A.vc),
            Loads(self.gravity, A.bforce, A.pl_start, A.pl_r, A.pl_f, self.fext, self.text, self.qext),
            Forces(self.force, self.torque, self.qs, self.dsum, self.dscale),
            Geometry(A.vert_start, A.face_start, A.edge_start, A.vloc, A.nloc, A.dloc, self.vert, self.fnw,
                     self.fdw, self.aabb, A.he_origin, A.he_next, A.he_pair, A.he_face, A.vert_he, A.edge_he),
            Grid(self.S, self.margin, self.gap, self.cellbox, self.large, self.stamp, self.tag),
            Lists(self.active, self.mstart, self.mentries, self.fstart, self.fentries, self.large_list,
                  self.pa, self.pb),
            Sleep(self.movable, self.asleep, self.calm, self.pe_sl, self.sleep_par, self.sw, self.ke_step, self.woke),
            Contacts(self.cur, self.c_n_pair, self.c_key, self.c_a, self.c_b, self.c_nrm, self.c_np,
                     self.c_pid, self.c_us, self.c_state, self.c_bond, self.c_pos, self.c_fn, self.c_depth,
                     self.c_fd, self.htab),
            Law(self.lawtab, self.keep_gap, *self.face_laws),
            Books(self.energy, self.acc, self.stats),
        )

    def set_lists(self, lists):
        """Take the grids and lists a chunk of steps returns (dda._state.Lists)."""
        (self.active, self.mstart, self.mentries, self.fstart, self.fentries, self.large_list, self.pa,
         self.pb) = lists

    def _chunk(self, nsteps):
        while True:
            status, done, lists = _it.run_chunk(nsteps, self.dt, self.dt_prev, self.local_damping, self.first_step,
                                                *self.bundles())
            self.set_lists(lists)
            if done:
                self.first_step = False
                self.dt_prev = self.dt
            self.steps += done
            self.time += done * self.dt
            self.fcp_iterations += int(self.stats[ST_FCP_ITER])
            self.block_steps += int(self.stats[ST_BLOCK_STEPS])
            nsteps -= done
            if status == _it.NEED_CAPACITY:
                self._grow_contacts(int(self.stats[ST_NEED]))
                continue
            return status

    def _snapshot(self):
        return (self.pos.copy(), self.quat.copy(), self.vel.copy(), self.angmom.copy(), self.time, self.steps,
                self.strain_.copy(), self.srate.copy(), self.wb.copy())

    def _restore(self, snap):
        # the state of the last good record (the sleep flags stay as they are: a blow-up ends the run)
        self.pos[:], self.quat[:], self.vel[:], self.angmom[:] = snap[0], snap[1], snap[2], snap[3]
        self.time, self.steps = snap[4], snap[5]
        self.strain_[:], self.srate[:], self.wb[:] = snap[6], snap[7], snap[8]

    @property
    def n_asleep(self):
        return int(self.asleep.sum())

    def fall_asleep(self, which):
        """Put the free rigid blocks `which` (indices) to sleep now, as a calm block falls asleep in a run
        (dda/_integrate.py sleep_stage): at rest where they are, neither integrated nor searched; their contacts
        with fixed and sleeping blocks are carried over, and a moving block that comes near wakes them. Their kinetic
        energy, if any, is counted as damped. For a run that starts from a settled state (and for benchmarks of
        half-asleep scenes); needs sleep=True."""
        if self.sleep_par[0] <= 0:
            raise ValueError("fall_asleep needs a run with sleep=True")
        A = self.A
        which = np.unique(np.asarray(which, np.int64))
        if np.any(A.fixed[which] | A.kin[which] | self.dof12[which]):
            raise ValueError("only free rigid blocks fall asleep")
        st = self.bundles()
        for i in which[~self.asleep[which]]:
            R = quat_to_matrix(self.quat[i])
            w = R @ ((R.T @ self.angmom[i]) / A.inertia[i])
            self.energy[E_DAMPING] += 0.5 * A.mass[i] * float(self.vel[i] @ self.vel[i]) \
                + 0.5 * float(self.angmom[i] @ w)
            self.vel[i] = 0.0
            self.angmom[i] = 0.0
            self.asleep[i] = True
            self.calm[i] = int(self.sleep_par[3])
            self.pe_sl[i] = _it._load_potential(i, st.blocks, st.loads)
            self.acc[ACC_SLEEPING] += self.pe_sl[i]
        self.active = self.movable[~self.asleep[self.movable]]
        self.mstart, self.mentries, self.fstart, self.fentries, self.large_list = _it.regrid(
            self.active, A.fixed | self.asleep, self.cellbox, self.large)

    def run(self, duration, record_every=None, progress=None) -> Results:
        """Advance by `duration` seconds; record every `record_every` seconds (default duration / 100).

        `progress`: a line printer (`progress(msg)`, at most about one line a second: simulated time, steps/s,
        ETA, contacts, energy) or the dda.progress.RunProgress of a run made of several calls.
        Raises BlowUpError (with the results up to the last good state) when the run becomes unstable."""
        nsteps = max(1, int(round(duration / self.dt)))
        rec_steps = max(1, int(round((record_every or duration / 100) / self.dt)))
        res = Results.empty(self)
        res.record(self)  # state before the first step (its energy is known after the first step)
        left = nsteps
        t_wall, t_cpu = time.perf_counter(), time.process_time()
        clock = tracker(progress, self, duration)
        scale = 0.0
        first = self.E0 is None
        while left > 0:
            n = 1 if first else min(rec_steps - (self.steps % rec_steps), left)
            snap = self._snapshot()
            status = self._chunk(n)
            left -= n
            e = self.energy
            total = e[0] + e[1] + e[2] + e[3] + e[4] + e[5] + e[6]
            if first:
                # energies of step 0 (kinetic in the product form over the first step)
                self.E0 = total
                self.PE0 = e[1]
                res.energy[0] = np.r_[e, 0.0]
            err = total - self.E0
            # an unstable run makes its energy where contact points appear deep and vanish, which the point
            # turnover books: the blow-up test takes the balance without it
            jump = err - e[6]
            ref = max(scale, abs(e[1] - self.PE0) + e[3] + e[4] + e[5], self.energy_floor)
            bad = status == _it.BLOWUP or not np.all(np.isfinite(e))
            if not bad and jump > self.blowup_ratio * ref and jump > 1e-9 * (abs(self.E0) + 1.0) and self.steps > n:
                bad = True
            if bad:
                self._restore(snap)
                why = "non-finite state" if status == _it.BLOWUP or not np.all(np.isfinite(e)) else \
                    f"energy jump ({jump:.3g} J made against {ref:.3g} J in play)"
                raise BlowUpError(
                    f"blow-up near t = {snap[4]:.6g} s (step {snap[5]}): {why}; dt = {self.dt:.3g} s "
                    f"(critical {self.dt_crit:.3g} s): reduce dt or the safety factor, or soften kn", res)
            scale = max(scale, e[0] + e[2] + abs(e[1] - self.PE0) + e[3] + e[4] + e[5])
            if first:
                first = False
                if self.after_first_step is not None:
                    self.after_first_step(self)
                if left > 0 and self.steps % rec_steps:
                    continue
            res.record(self)
            asleep = f"asleep {self.n_asleep} of {len(self.movable)}  " if self.sleep_par[0] > 0 else ""
            clock.update(self.time, self.steps, f"contacts {int(self.stats[ST_CONTACTS])}  "
                         f"points {int(self.stats[ST_POINTS])}  {asleep}KE {e[0]:.4g} J  balance error {err:.3g} J",
                         end=left == 0)
        res.wall_s = time.perf_counter() - t_wall
        self.cpu_s += time.process_time() - t_cpu
        return res

    # ------------------------------------------------------------------
    def displacement(self, i):
        return self.pos[i] - self.pos0[i]

    def velocity(self, i):
        return self.vel[i].copy()

    def rotation(self, i):
        return quat_to_matrix(self.quat[i])

    def vertices(self, i):
        """World vertices of block i in the current state."""
        A = self.A
        R = self.rotation(i)
        if self.dof12[i]:
            R = matmul(R, np.eye(3) + _strain_tensor(self.strain_[i]))
        return self.pos[i] + matmul(A.vloc[A.vert_start[i]:A.vert_start[i + 1]], R.T)

    def strain(self, i):
        """Body-frame strains (ex, ey, ez, gyz, gzx, gxy) of block i (zero for a rigid block)."""
        return self.strain_[i].copy()

    def set_strain(self, i, e):
        """Impose the strains of deformable block i (e.g. an initial strain before the run)."""
        if not self.dof12[i]:
            raise ValueError(f"block {i} is not a free deformable block (dof = 12)")
        self.strain_[i] = np.asarray(e, float).reshape(6)
        deform_geometry(int(i), self.pos, self.rotation(i), self.strain_, self.A.vert_start, self.A.face_start,
                        self.A.vloc, self.A.nloc, self.A.dloc, self.vert, self.fnw, self.fdw, self.aabb)

    def volume(self, i):
        """Current volume of block i: V0 det(I + E) for a deformable block."""
        v0 = float(self.A.volume[i])
        return v0 * float(det3(np.eye(3) + _strain_tensor(self.strain_[i]))) if self.dof12[i] else v0

    def contacts(self):
        """Current contact points: dict of arrays (a, b, position, normal, normal force, depth, state)."""
        c = int(self.cur[0])
        n = int(self.c_n_pair[c])
        out = {k: [] for k in ("a", "b", "position", "normal", "fn", "depth", "state", "shear")}
        for s in range(n):
            for q in range(int(self.c_np[c, s])):
                out["a"].append(self.c_a[c, s])
                out["b"].append(self.c_b[c, s])
                out["position"].append(self.c_pos[c, s, q])
                out["normal"].append(self.c_nrm[c, s])
                out["fn"].append(self.c_fn[c, s, q])
                out["depth"].append(self.c_depth[c, s, q])
                out["state"].append(self.c_state[c, s, q])
                out["shear"].append(self.c_us[c, s, q])
        return {k: np.array(v) for k, v in out.items()}
