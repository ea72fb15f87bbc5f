"""numba kernels: the explicit time loop (central difference) for chunks of steps.

``run_chunk`` is a loop over the stages of a step; the state travels in the named bundles of dda/_state.py.
One step i, for the moving (active) blocks only:

1. world vertices, face planes and bounding boxes from the pose (x_i, q_i); blocks whose box left their
   cells are re-mapped (the moving-block grid is rebuilt only then);
2. candidate pairs from the grid (dda/_broad.py); then, in dda/_narrow.py, the cached common plane of the pair
   is checked first (a positive gap along it proves the blocks apart, so the FCP search runs only for pairs that
   may touch); contact points; law;
3. central difference exactly as the explicit 3D-DDA paper gives it:
       v(i+1/2) = v(i-1/2) + 0.5 (dt(i+1) + dt(i)) a(i),   x(i+1) = x(i) + dt(i+1) v(i+1/2);
   rotations: the world angular momentum L is advanced the same way with the torque (dL/dt = T holds in the
   world frame, so the gyroscopic term needs no separate treatment); the half-step angular velocity
   w = R I^-1 R^T L is taken at the mid-step orientation (one predictor) and the quaternion is turned by
   exp(w dt).
Energy: kinetic energy at step i in the product form 1/2 m v(i-1/2).v(i+1/2) (conserved exactly by the
leapfrog for a linear spring), gravitational potential, elastic contact energy, and the cumulative work
dissipated by friction, contact damping and local damping.

4. sleeping blocks fall asleep or wake (``sleep_stage``).
Contacts are kept in two buffers (last step's and this step's); a hash table on the pair key finds last
step's common plane and the shear history of each contact point (matched by the point's feature id).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._broad import build_grid, buckets_for, find_pairs, inside_cells, map_cells, n_cells
from ._contact import dashpot_scale, local_damping
from ._deform import deform_geometry, deform_step
from ._fcp import MAXP
from ._kinematics import ang_vel, place_vertices, quat_matrix, turn, turned
from ._narrow import carry_resting, hash_pairs, narrow_phase
from ._state import (ACC_DRIVER, ACC_SLEEPING, C_CONTACTS, C_FIT, C_NEW, C_POINTS, C_SAT, C_SLIDING, C_WAKE,
                     E_DAMPING, E_ELASTIC, E_FRICTION, E_KIN, E_LOCAL, E_POT, E_TURNOVER, NCOUNT, NTALLY,
                     ST_AWAKE, ST_BLOCK_STEPS, ST_CONTACTS, ST_FCP_ITER, ST_MAXDEPTH, ST_NEED, ST_PAIRS,
                     ST_POINTS, ST_SAT, ST_SLIDING, ST_STATUS, ST_STEPS, T_DAMPING, T_ELASTIC, T_FRICTION, T_KIN,
                     T_LOCAL, T_MAXDEPTH, T_POT, T_TURNOVER, Lists, Work)

OK, NEED_CAPACITY, BLOWUP = 0, 1, 2


@njit(cache=True)
def update_geometry(i, pos, quat, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb):
    R = np.empty((3, 3))
    quat_matrix(quat[i], R)
    place_vertices(i, pos, R, vs, vloc, vert, aabb)
    for f in range(fs[i], fs[i + 1]):
        d = dloc[f]
        for a in range(3):
            nn = R[a, 0] * nloc[f, 0] + R[a, 1] * nloc[f, 1] + R[a, 2] * nloc[f, 2]
            fnw[f, a] = nn
            d += nn * pos[i, a]
        fdw[f] = d


@njit(cache=True)
def _load_potential(i, blocks, loads):
    """-(m g + F_body).x - sum F_p.(x + R r_p): potential of gravity and the constant loads of block i."""
    pos, quat, mass = blocks.pos, blocks.quat, blocks.mass
    gravity, bforce, pl_start, pl_r, pl_f = loads.gravity, loads.bforce, loads.pl_start, loads.pl_r, loads.pl_f
    pe = 0.0
    for a in range(3):
        pe -= (mass[i] * gravity[a] + bforce[i, a]) * pos[i, a]
    if pl_start[i + 1] > pl_start[i]:
        R = np.empty((3, 3))
        quat_matrix(quat[i], R)
        for p in range(pl_start[i], pl_start[i + 1]):
            for a in range(3):
                x = pos[i, a] + R[a, 0] * pl_r[p, 0] + R[a, 1] * pl_r[p, 1] + R[a, 2] * pl_r[p, 2]
                pe -= pl_f[p, a] * x
    return pe


@njit(cache=True)
def regrid(active, static, cellbox, large):
    """Static grid (fixed and sleeping blocks), moving grid (awake blocks) and the list of large blocks."""
    nb = static.shape[0]
    ns = 0
    nl = 0
    for i in range(nb):
        if static[i]:
            ns += 1
        if large[i]:
            nl += 1
    sidx = np.empty(ns, np.int64)
    lidx = np.empty(nl, np.int64)
    ns = 0
    nl = 0
    nent = 0
    for i in range(nb):
        if static[i]:
            sidx[ns] = i
            ns += 1
            if not large[i]:
                nent += n_cells(cellbox, i)
        if large[i]:
            lidx[nl] = i
            nl += 1
    fstart, fentries = build_grid(sidx, cellbox, large, buckets_for(nent))
    nent = 0
    for k in range(active.shape[0]):
        if not large[active[k]]:
            nent += n_cells(cellbox, active[k])
    mstart, mentries = build_grid(active, cellbox, large, buckets_for(nent))
    return mstart, mentries, fstart, fentries, lidx


@njit(cache=True)
def make_work(blocks, geom, asleep):
    """run_chunk's scratch arrays (dda._state.Work), sized for the largest block."""
    nbody = blocks.pos.shape[0]
    vs, es = geom.vs, geom.es
    maxv = 0
    maxe = 0
    for i in range(nbody):
        maxv = max(maxv, vs[i + 1] - vs[i])
        maxe = max(maxe, es[i + 1] - es[i])
    static = np.empty(nbody, np.bool_)
    for i in range(nbody):
        static[i] = blocks.fixed[i] or asleep[i]
    return Work(np.empty((3, 3)), np.empty(3), np.empty(3), np.empty(3), np.empty(4), np.empty(3), np.empty(3),
                np.empty(3), np.empty(3), np.empty((MAXP, 3)), np.empty(MAXP), np.empty(MAXP, np.int64),
                np.zeros(MAXP, np.bool_), np.empty(3), np.empty((2 * maxv, 3)), np.empty(2 * maxe, np.int64),
                static, np.zeros(nbody, np.bool_), np.empty(nbody, np.int64))


@njit(cache=True)
def _rebuild_moving(grid, lists, static):
    """The moving-block grid anew (a block left its cells); large moving blocks join the large list."""
    active, large = lists.active, grid.large
    nent = 0
    for k in range(active.shape[0]):
        i = active[k]
        if not large[i]:
            nent += n_cells(grid.cellbox, i)
    mstart, mentries = build_grid(active, grid.cellbox, large, buckets_for(nent))
    large_list = lists.large_list
    nl = 0
    for k in range(active.shape[0]):
        if large[active[k]]:
            nl += 1
    if nl > 0:
        cnt = 0
        for e in range(large_list.shape[0]):
            if static[large_list[e]]:
                cnt += 1
        nll = np.empty(cnt + nl, np.int64)
        cnt = 0
        for e in range(large_list.shape[0]):
            if static[large_list[e]]:
                nll[cnt] = large_list[e]
                cnt += 1
        for k in range(active.shape[0]):
            if large[active[k]]:
                nll[cnt] = active[k]
                cnt += 1
        large_list = nll
    return Lists(active, mstart, mentries, lists.fstart, lists.fentries, large_list, lists.pa, lists.pb)


@njit(cache=True)
def move_geometry(blocks, deform, geom, grid, lists, static, R):
    """Stage 1: world vertices, face planes and boxes of the moving blocks; blocks whose box left their cells
    are re-mapped and the moving grid rebuilt. Returns the lists (new grids after a rebuild). The arrays the
    loop uses are taken out of their bundles once, before it."""
    rebuild = False
    pos, quat, dof12, strain, large = blocks.pos, blocks.quat, blocks.dof12, deform.strain, grid.large
    vs, fs, vloc, nloc, dloc, vert, fnw, fdw = geom.vs, geom.fs, geom.vloc, geom.nloc, geom.dloc, geom.vert, \
        geom.fnw, geom.fdw
    aabb, cellbox, S, margin, active = geom.aabb, grid.cellbox, grid.S, grid.margin, lists.active
    for k in range(active.shape[0]):
        i = active[k]
        if dof12[i]:
            quat_matrix(quat[i], R)
            deform_geometry(i, pos, R, strain, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb)
        else:
            update_geometry(i, pos, quat, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb)
        if not inside_cells(aabb, i, S, cellbox):
            map_cells(aabb, i, S, margin, cellbox)
            if n_cells(cellbox, i) > 64:
                if not large[i]:
                    large[i] = True
            rebuild = True
    if rebuild:
        return _rebuild_moving(grid, lists, static)
    return lists


@njit(cache=True)
def broad_phase(geom, grid, lists, static):
    """Stage 2: candidate pairs from the grids; returns (lists with the pair arrays, number of pairs)."""
    pa, pb, npair = find_pairs(lists.active, static, grid.large, geom.aabb, grid.cellbox, grid.gap, lists.mstart,
                               lists.mentries, lists.mstart.shape[0] - 2, lists.fstart, lists.fentries,
                               lists.fstart.shape[0] - 2, lists.large_list, grid.stamp, grid.tag, lists.pa, lists.pb)
    return Lists(lists.active, lists.mstart, lists.mentries, lists.fstart, lists.fentries, lists.large_list,
                 pa, pb), npair


@njit(cache=True)
def reset_forces(active, dof12, forces, loads):
    """Each moving block starts the step with no force, or the external one (fixed blocks take no forces: the
    cost follows the moving blocks)."""
    force, torque, qs = forces.force, forces.torque, forces.qs
    fext, text, qext = loads.fext, loads.text, loads.qext
    for k in range(active.shape[0]):
        i = active[k]
        force[i, 0] = 0.0
        force[i, 1] = 0.0
        force[i, 2] = 0.0
        torque[i, 0] = 0.0
        torque[i, 1] = 0.0
        torque[i, 2] = 0.0
        if dof12[i]:
            for a in range(6):
                qs[i, a] = 0.0
        if fext.shape[0] > 0:
            for a in range(3):
                force[i, a] = fext[i, a]
                torque[i, a] = text[i, a]
            if dof12[i]:
                for a in range(6):
                    qs[i, a] = qext[i, a]


@njit(cache=True, inline="always")
def _prescribed_step(i, dt, pos, vel, quat, wpres, force, torque, acc, qh):
    """Prescribed motion of block i: the driver does the work the contacts do against it."""
    acc[ACC_DRIVER] -= dt * (force[i, 0] * vel[i, 0] + force[i, 1] * vel[i, 1] + force[i, 2] * vel[i, 2]
                             + torque[i, 0] * wpres[i, 0] + torque[i, 1] * wpres[i, 1] + torque[i, 2] * wpres[i, 2])
    turn(quat[i], wpres[i], dt, qh)
    for a in range(4):
        quat[i, a] = qh[a]
    for a in range(3):
        pos[i, a] += dt * vel[i, a]


@njit(cache=True, inline="always")
def _point_loads(i, R, pl_start, pl_r, pl_f, force, torque, pos, tally):
    """Constant point loads of rigid block i (world force at a body point) and their potential."""
    for p in range(pl_start[i], pl_start[i + 1]):
        r0 = R[0, 0] * pl_r[p, 0] + R[0, 1] * pl_r[p, 1] + R[0, 2] * pl_r[p, 2]
        r1 = R[1, 0] * pl_r[p, 0] + R[1, 1] * pl_r[p, 1] + R[1, 2] * pl_r[p, 2]
        r2 = R[2, 0] * pl_r[p, 0] + R[2, 1] * pl_r[p, 1] + R[2, 2] * pl_r[p, 2]
        f0 = pl_f[p, 0]
        f1 = pl_f[p, 1]
        f2 = pl_f[p, 2]
        force[i, 0] += f0
        force[i, 1] += f1
        force[i, 2] += f2
        torque[i, 0] += r1 * f2 - r2 * f1
        torque[i, 1] += r2 * f0 - r0 * f2
        torque[i, 2] += r0 * f1 - r1 * f0
        tally[T_POT] -= f0 * (pos[i, 0] + r0) + f1 * (pos[i, 1] + r1) + f2 * (pos[i, 2] + r2)


@njit(cache=True, inline="always")
def _calm_step(i, sz, vel, w, dtavg, par, calm, sw, woke):
    """The calm-step counter of rigid block i after its step. Over each window of par[3] steps, with the
    velocity v = (velocity, size x angular velocity) summed in sw: the window's mean speed below par[1] and the
    least-squares slope of v (a mean acceleration) below par[2] -- means, in which the ringing of a block resting
    on stiff contacts averages out where one step's speed and acceleration would not -- and no step's speed above
    ten times par[1] (a block just woken, ``woke``: above par[1], until its first window ends, so that a block woken
    and pushed counts as moving at once and wakes the blocks it pushes). A window that fails starts the count anew;
    the windows go on while the block is calm, so a calm block that starts to creep or accelerate is caught at the
    next window's end."""
    spd = np.sqrt(vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2) + sz * np.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2)
    if spd >= (1.0 if woke[i] else 10.0) * par[1]:
        calm[i] = 0
        woke[i] = False
        return
    n = np.int64(par[3])
    c = calm[i]
    k = c % n
    if k == 0:
        for a in range(12):
            sw[i, a] = 0.0
    for a in range(3):
        sw[i, a] += vel[i, a]
        sw[i, 3 + a] += sz * w[a]
        sw[i, 6 + a] += k * vel[i, a]
        sw[i, 9 + a] += k * sz * w[a]
    c += 1
    if k == n - 1:
        # mean of samples k = 0..n-1: sum v / n; slope per step: (sum k v - (n-1)/2 sum v) / (n (n^2 - 1) / 12)
        den = n * (n * n - 1) / 12.0 * dtavg
        kbar = 0.5 * (n - 1)
        ml, ma, sl, sa = 0.0, 0.0, 0.0, 0.0
        for a in range(3):
            ml += sw[i, a] ** 2
            ma += sw[i, 3 + a] ** 2
            sl += ((sw[i, 6 + a] - kbar * sw[i, a]) / den) ** 2
            sa += ((sw[i, 9 + a] - kbar * sw[i, 3 + a]) / den) ** 2
        if (np.sqrt(ml) + np.sqrt(ma)) / n >= par[1] or np.sqrt(sl) + np.sqrt(sa) >= par[2]:
            c = 0
        woke[i] = False
    calm[i] = c


@njit(cache=True)
def integrate(dt, dt_prev, local_damp, blocks, deform, loads, forces, active, sleep, acc, work, tally):
    """Stage 4: central difference of the moving blocks (prescribed, deformable, rigid). Returns True when the
    state became non-finite. The arrays the loop uses are taken out of their bundles once, before it (numba's
    reference counts: dda/_narrow.py's docstring)."""
    dtavg = 0.5 * (dt + dt_prev)
    blown = False
    pos, vel, quat, angmom, inertia, mass = blocks.pos, blocks.vel, blocks.quat, blocks.angmom, blocks.inertia, \
        blocks.mass
    kin, dof12, wpres, size_b = blocks.kin, blocks.dof12, blocks.wpres, blocks.size_b
    force, torque, gravity, bforce = forces.force, forces.torque, loads.gravity, loads.bforce
    dsum, dscale = forces.dsum, forces.dscale
    pl_start, pl_r, pl_f = loads.pl_start, loads.pl_r, loads.pl_f
    R, w_old, w_new, Lnew, qh = work.R, work.w_old, work.w_new, work.Lnew, work.qh
    par, calm, sw, ke_step, woke = sleep.par, sleep.calm, sleep.sw, sleep.ke, sleep.woke
    sleep_on = par[0] > 0.0
    for k in range(active.shape[0]):
        i = active[k]
        if kin[i]:
            _prescribed_step(i, dt, pos, vel, quat, wpres, force, torque, acc, qh)
            continue
        dscale[i] = dashpot_scale(dsum, i, dt, local_damp)
        if dof12[i]:
            ke_i, pe_i, es_i, dl_i, bl_i = deform_step(i, dt, dtavg, local_damp, blocks, deform, loads, forces)
            tally[T_KIN] += ke_i
            tally[T_POT] += pe_i
            tally[T_ELASTIC] += es_i
            tally[T_LOCAL] += dl_i
            if bl_i:
                blown = True
            continue
        # rigid block: central difference (module docstring), written out here rather than in helpers: the
        # arrays a helper takes as parameters would be counted in and out per block
        m = mass[i]
        quat_matrix(quat[i], R)
        _point_loads(i, R, pl_start, pl_r, pl_f, force, torque, pos, tally)
        ang_vel(R, inertia[i], angmom[i], w_old)
        # local damping: alpha |f| against each component of the velocity; for the torque, about each principal
        # axis (body frame): taken about the world axes, a long thin block's damping torque, alpha |T| in size,
        # has a part about its axis of least inertia much larger than the torque there, and spins it up
        td0, td1, td2 = 0.0, 0.0, 0.0
        if local_damp > 0.0:
            for a in range(3):
                tb = R[0, a] * torque[i, 0] + R[1, a] * torque[i, 1] + R[2, a] * torque[i, 2]
                wb = R[0, a] * w_old[0] + R[1, a] * w_old[1] + R[2, a] * w_old[2]
                d = local_damping(local_damp, tb, wb)
                td0 += R[0, a] * d
                td1 += R[1, a] * d
                td2 += R[2, a] * d
        ke_i = 0.0
        for a in range(3):
            f = force[i, a] + m * gravity[a] + bforce[i, a]
            fd = 0.0
            if local_damp > 0.0:
                fd = local_damping(local_damp, f, vel[i, a])
                f -= fd
            vnew = vel[i, a] + dtavg * f / m
            # a force's work in the product-form kinetic energy pairs it with the mean of the half-step velocities
            # on either side of its step
            tally[T_LOCAL] += fd * 0.5 * (vel[i, a] + vnew) * dtavg
            ke_i += 0.5 * m * vel[i, a] * vnew
            vel[i, a] = vnew
            Lnew[a] = angmom[i, a] + dtavg * (torque[i, a] - (td0 if a == 0 else (td1 if a == 1 else td2)))
            tally[T_POT] -= (m * gravity[a] + bforce[i, a]) * pos[i, a]
        ang_vel(R, inertia[i], Lnew, w_new)
        if local_damp > 0.0:
            tally[T_LOCAL] += 0.5 * dtavg * (td0 * (w_old[0] + w_new[0]) + td1 * (w_old[1] + w_new[1])
                                             + td2 * (w_old[2] + w_new[2]))
        ke_i += 0.5 * (angmom[i, 0] * w_new[0] + angmom[i, 1] * w_new[1] + angmom[i, 2] * w_new[2])
        tally[T_KIN] += ke_i
        if sleep_on:
            ke_step[i] = ke_i
            _calm_step(i, size_b[i], vel, w_new, dtavg, par, calm, sw, woke)
        # mid-step orientation predictor, then the full turn (turned: scalars, so that no array is counted in
        # and out per block around its branch)
        qh[0], qh[1], qh[2], qh[3] = turned(quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3], w_new[0], w_new[1],
                                            w_new[2], 0.5 * dt)
        quat_matrix(qh, R)
        ang_vel(R, inertia[i], Lnew, w_new)
        quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3] = turned(quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3],
                                                                w_new[0], w_new[1], w_new[2], dt)
        for a in range(3):
            angmom[i, a] = Lnew[a]
            pos[i, a] += dt * vel[i, a]
            if not np.isfinite(pos[i, a]) or not np.isfinite(vel[i, a]) or not np.isfinite(Lnew[a]):
                blown = True
    return blown


@njit(cache=True)
def sleep_stage(dt, blocks, loads, grid, lists, sleep, acc, work, tally, count):
    """Stage 5: calm blocks without a veto fall asleep, the blocks on the wake list wake; the grids anew when
    that changed the awake blocks. Returns the lists."""
    vel, angmom, static, veto = blocks.vel, blocks.angmom, work.static, work.veto
    asleep, calm = sleep.asleep, sleep.calm
    n_calm = np.int64(sleep.par[3])
    R, w_old = work.R, work.w_old
    changed = False
    d_sleep = 0.0
    for k in range(lists.active.shape[0]):
        i = lists.active[k]
        if not blocks.kin[i] and calm[i] >= n_calm and not veto[i]:
            # falls asleep where this step's contacts and geometry found it (its position before the step): the
            # carried contacts, its world geometry and its potential then agree, and the kinetic energy this step's
            # books gave it there (below the thresholds) counts as damped instead
            q = blocks.quat[i]
            quat_matrix(q, R)
            ang_vel(R, blocks.inertia[i], angmom[i], w_old)
            d_sleep += sleep.ke[i]
            tally[T_KIN] -= sleep.ke[i]
            q[0], q[1], q[2], q[3] = turned(q[0], q[1], q[2], q[3], w_old[0], w_old[1], w_old[2], -dt)
            for a in range(3):
                blocks.pos[i, a] -= dt * vel[i, a]
                vel[i, a] = 0.0
                angmom[i, a] = 0.0
            asleep[i] = True
            static[i] = True
            sleep.pe_sl[i] = _load_potential(i, blocks, loads)
            acc[ACC_SLEEPING] += sleep.pe_sl[i]
            # this step's potential holds the block's already (integrate, at its position before the step):
            # close_step adds acc, which now holds it too (at its position after the step)
            tally[T_POT] -= sleep.pe_sl[i]
            changed = True
        veto[i] = False
    for e in range(count[C_WAKE]):
        j = work.wake_list[e]
        veto[j] = False
        if asleep[j]:
            asleep[j] = False
            static[j] = False
            # woken at rest: the first sample (zero velocity) of a new window, not a moving block (which would
            # wake its sleeping neighbours in turn) until it fails a test (_calm_step)
            calm[j] = 1
            sleep.woke[j] = True
            for a in range(12):
                sleep.sw[j, a] = 0.0
            acc[ACC_SLEEPING] -= sleep.pe_sl[j]
            # it slept through this step's integration: its potential is this step's still (from next step on,
            # integrate's)
            tally[T_POT] += sleep.pe_sl[j]
            changed = True
    tally[T_DAMPING] += d_sleep
    if not changed:
        return lists
    movable = sleep.movable
    na = 0
    for k in range(movable.shape[0]):
        if not asleep[movable[k]]:
            na += 1
    active = np.empty(na, np.int64)
    na = 0
    for k in range(movable.shape[0]):
        if not asleep[movable[k]]:
            active[na] = movable[k]
            na += 1
    mstart, mentries, fstart, fentries, large_list = regrid(active, static, grid.cellbox, grid.large)
    return Lists(active, mstart, mentries, fstart, fentries, large_list, lists.pa, lists.pb)


@njit(cache=True)
def close_step(npair, nactive, acc, books, tally, count):
    """The step's energies (E_* columns) and statistics (ST_* slots)."""
    energy, stats = books.energy, books.stats
    tally[T_POT] += acc[ACC_SLEEPING] - acc[ACC_DRIVER]
    energy[E_KIN] = tally[T_KIN]
    energy[E_POT] = tally[T_POT]
    energy[E_ELASTIC] = tally[T_ELASTIC]
    energy[E_FRICTION] += tally[T_FRICTION]
    energy[E_DAMPING] += tally[T_DAMPING]
    energy[E_LOCAL] += tally[T_LOCAL]
    energy[E_TURNOVER] += tally[T_TURNOVER]
    stats[ST_MAXDEPTH] = tally[T_MAXDEPTH]
    stats[ST_CONTACTS] = count[C_CONTACTS]
    stats[ST_POINTS] = count[C_POINTS]
    stats[ST_SLIDING] = count[C_SLIDING]
    stats[ST_PAIRS] = npair
    stats[ST_SAT] = count[C_SAT]
    stats[ST_AWAKE] = nactive


@njit(cache=True)
def run_chunk(nsteps, dt, dt_prev, local_damp, first_step, blocks, deform, loads, forces, geom, grid, lists, sleep,
              con, law, books):
    """Advance `nsteps` steps; the state is in the bundles of dda/_state.py (Blocks, Deform, Loads, Forces,
    Geometry, Grid, Lists, Sleep, Contacts, Law, Books). books.energy = [KE, PE, elastic, fric, damp, local,
    turnover] (last four cumulative), books.stats has the ST_* slots.

    Loads and prescribed motion: ``blocks.kin[i]`` blocks move at their velocity ``vel[i]`` and world angular
    velocity ``wpres[i]`` whatever the forces (their contact forces do work counted in ``acc[ACC_DRIVER]``);
    ``loads.bforce[i]`` is a constant force at the centroid; point loads of block i are rows
    ``pl_start[i]:pl_start[i+1]`` of ``pl_f`` (world force) at the body-frame offset ``pl_r`` from the centroid.
    Their potential -F.x enters the potential energy with gravity's, minus the cumulative work of the prescribed
    blocks.

    Sleeping (``sleep.par = [on, velocity, acceleration, steps]``): a free block whose mean speed (centroid plus
    angular speed times its size) and mean acceleration over a window of ``steps`` steps stay below the
    thresholds (``_calm_step``) falls asleep when no block touching it is moving (calm count 0: its last step or
    window failed); a sleeping block is neither integrated nor searched for contacts (its contacts with other
    resting blocks are carried over unchanged, so shear history and elastic energy are kept); it wakes the step
    after a moving block comes within the search gap, at rest and with a count of 1 (the zero first sample of a
    window), so that it does not wake its sleeping neighbours in turn unless it fails a test itself (until its
    first window ends, a step's speed above the threshold fails it).
    ``acc[ACC_SLEEPING]`` holds the potential energy of the sleeping blocks (``sleep.pe_sl`` per block).
    Deformable blocks (``blocks.dof12[i]``, see dda/_deform.py): body-frame strains and strain rates and angular
    velocity (``deform``) replace ``angmom``; ``forces.qs`` collects the strain part of T^T f. They never sleep;
    their strain energy is counted with the elastic energy.
    External forces (the spheres' contact reactions, dda/_coupled.py): when ``loads.fext`` has rows, block i
    starts each step with the force ``fext[i]``, torque ``text[i]`` (world, about the centroid) and strain force
    ``qext[i]`` instead of zero.
    Returns (status, steps_done, lists)."""
    cap = con.key.shape[1]
    acc = books.acc
    work = make_work(blocks, geom, sleep.asleep)
    tally = np.zeros(NTALLY)
    count = np.zeros(NCOUNT, np.int64)
    sleep_on = sleep.par[0] > 0.0
    status = OK
    done = 0
    block_steps = 0
    for step in range(nsteps):
        lists = move_geometry(blocks, deform, geom, grid, lists, work.static, work.R)
        lists, npair = broad_phase(geom, grid, lists, work.static)
        old = con.cur[0]
        new = 1 - old
        nold = con.n_pair[old]
        need = npair + nold if sleep_on else npair  # resting pairs are carried over
        if need > cap:
            status = NEED_CAPACITY
            books.stats[ST_NEED] = need
            break
        hmask = hash_pairs(con, old)
        reset_forces(lists.active, blocks.dof12, forces, loads)
        tally[:] = 0.0
        for c in (C_NEW, C_WAKE, C_CONTACTS, C_POINTS, C_SLIDING):
            count[c] = 0
        narrow_phase(npair, lists.pa, lists.pb, hmask, first_step, dt, law, grid.gap, blocks, deform, forces, geom,
                     sleep, con, work, tally, count)
        if sleep_on:
            carry_resting(law, blocks.material, sleep.asleep, con, work.static, tally, count)
        con.n_pair[new] = count[C_NEW]
        con.cur[0] = new
        first_step = False
        block_steps += lists.active.shape[0]
        blown = integrate(dt, dt_prev, local_damp, blocks, deform, loads, forces, lists.active, sleep, acc, work,
                          tally)
        if sleep_on:
            lists = sleep_stage(dt, blocks, loads, grid, lists, sleep, acc, work, tally, count)
        dt_prev = dt
        close_step(npair, lists.active.shape[0], acc, books, tally, count)
        done += 1
        if blown or not np.isfinite(tally[T_ELASTIC]):
            status = BLOWUP
            break
    books.stats[ST_STEPS] = done
    books.stats[ST_STATUS] = status
    books.stats[ST_FCP_ITER] = count[C_FIT]
    books.stats[ST_BLOCK_STEPS] = block_steps
    return status, done, lists
