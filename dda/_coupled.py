"""numba kernels: spheres together with moving polyhedral blocks (one time loop, one time step).

Design: the block engine's step (dda/_integrate.py ``run_chunk``) is left as it is and called for one step at
a time from ``run_coupled``, a numba loop that wraps it (so the blocks keep their own broad phase, FCP
narrow phase, sleeping-free fast path and bit-identical results when no sphere is present, and the loop
never returns to Python between steps). One coupled step i:

1. world geometry of the moving blocks at x(i) (as run_chunk computes it);
2. ``sphere_forces``: ``grid_contacts``, a hashed sphere grid (cells of the largest sphere diameter,
   counting sort, linear in the spheres) and the sphere-sphere contacts without an intact bond, the
   sphere-block contacts (``block_contacts``), smooth joints and bonds (dda/_spheres.py ``_joints``, the one
   bond law of dda/_bondlaw.py, as in sphere-only runs). Sphere-block candidates come from the block engine's
   own grids (moving blocks, static blocks, short list of large blocks): each sphere looks up the cells its box covers, so the cost follows the spheres and the blocks
   near them, never spheres x blocks. A sphere touches a block at the closest point of the convex polyhedron
   (face, edge or vertex); the block contact law acts at that point; the block takes the reaction there
   (force, torque about its centroid and, for a deformable block, the strain part T^T f) in ``fext``,
   ``text``, ``qext``;
3. ``run_chunk(1 step)``: block-block contacts plus the reactions, central difference of the blocks;
4. dda/_spheres.py ``integrate``: central difference of the spheres (the same half-step scheme).
The spheres travel in the bundles of dda/_sphere_state.py, the blocks in the block engine's (dda/_state.py).
The sphere grid is searched every step here (no Verlet list: the blocks' grids move with the blocks).
Energy: the spheres' terms (kinetic, potential, elastic of sphere contacts and bonds, dissipated) here, the
blocks' in the block engine's array; their sum is the balance.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._bondlaw import bond_forces, bond_lookup, sync_central
from ._broad import _hash
from ._deform import add_strain_force, body_point, deform_geometry, point_velocity
from ._integrate import run_chunk, update_geometry
from ._kinematics import omega as _omega
from ._kinematics import quat_matrix
from ._sphere_state import R_BOND, ST_BONDS, ST_BROKEN, ST_CONTACTS, ST_JOINTS, ST_NEED, ST_WALL
from ._spheres import (_cell_hash, _joints, book_energy, carry_shear, clear_forces, closest_on_polyhedron,
                       contact_normal, hashed_cells, history_hash, integrate, record_contact, sphere_pair,
                       sphere_point, sphere_point_force)
from ._state import ST_FCP_ITER

OK, NEED_CAPACITY, BLOWUP, NEED_BLOCK_CAPACITY = 0, 1, 2, 3


@njit(cache=True)
def _block_contact(b, j, key, depth, n, p, mo, sp, blocks, deform, loads, lawrow, dt, hist, hc, nnew, res):
    """Sphere j against block b (normal n from the block to the sphere, contact point p); the block takes the
    reaction in ``loads.fext``, ``text``, ``qext``. Returns the contact count."""
    bpos = blocks.pos
    bstatic = blocks.fixed  # no sleeping in coupled runs
    us = np.empty(3)
    carry_shear(hist, hc, key, n, us)
    rj = np.empty(3)
    vrel = np.empty(3)
    sphere_point(j, p, mo, rj, vrel)
    R = np.empty((3, 3))
    wb_ = np.empty(3)
    X = np.empty(3)
    rb0 = p[0] - bpos[b, 0]
    rb1 = p[1] - bpos[b, 1]
    rb2 = p[2] - bpos[b, 2]
    if not bstatic[b]:
        for a in range(3):
            vrel[a] -= blocks.vel[b, a]
        if blocks.dof12[b]:
            quat_matrix(blocks.quat[b], R)
            point_velocity(b, p, bpos, R, deform.strain, deform.srate, deform.wb, wb_)
            for a in range(3):
                vrel[a] -= wb_[a]
        else:
            _omega(b, blocks.kin, bstatic, blocks.wpres, blocks.quat, blocks.inertia, blocks.angmom, R, wb_)
            vrel[0] -= wb_[1] * rb2 - wb_[2] * rb1
            vrel[1] -= wb_[2] * rb0 - wb_[0] * rb2
            vrel[2] -= wb_[0] * rb1 - wb_[1] * rb0
    bs = bstatic[b] or blocks.kin[b]
    ss = sp.fixed[j] or sp.kin[j]
    if bs and not ss:
        meff = sp.m[j]
    elif ss and not bs:
        meff = blocks.mass[b]
    else:
        meff = sp.m[j] * blocks.mass[b] / (sp.m[j] + blocks.mass[b])
    f = np.empty(3)
    st, fn_el = sphere_point_force(j, rj, meff, depth, n, vrel, us, lawrow, dt, mo, res, f)
    if st == 0:
        return nnew
    if not bstatic[b]:
        for a in range(3):
            loads.fext[b, a] -= f[a]
        loads.text[b, 0] -= rb1 * f[2] - rb2 * f[1]
        loads.text[b, 1] -= rb2 * f[0] - rb0 * f[2]
        loads.text[b, 2] -= rb0 * f[1] - rb1 * f[0]
        if blocks.dof12[b]:
            quat_matrix(blocks.quat[b], R)
            body_point(b, p, bpos, R, deform.strain, X)
            add_strain_force(b, X, R, f, -1.0, loads.qext)
    return record_contact(hist, hc, nnew, key, fn_el, -1 - b, j, us)


@njit(cache=True)
def block_geometry(blocks, deform, loads, geom, lists):
    """World geometry of the awake moving blocks at the current state (as run_chunk computes it); their
    external forces (the spheres' reactions) cleared."""
    R = np.empty((3, 3))
    for k in range(lists.active.shape[0]):
        i = lists.active[k]
        if blocks.dof12[i]:
            quat_matrix(blocks.quat[i], R)
            deform_geometry(i, blocks.pos, R, deform.strain, geom.vs, geom.fs, geom.vloc, geom.nloc, geom.dloc,
                            geom.vert, geom.fnw, geom.fdw, geom.aabb)
        else:
            update_geometry(i, blocks.pos, blocks.quat, geom.vs, geom.fs, geom.vloc, geom.nloc, geom.dloc,
                            geom.vert, geom.fnw, geom.fdw, geom.aabb)
        for a in range(3):
            loads.fext[i, a] = 0.0
            loads.text[i, a] = 0.0
        for a in range(6):
            loads.qext[i, a] = 0.0


@njit(cache=True)
def grid_contacts(mo, sp, bonds, joints, lawrow, dt, hist, hc, res):
    """Sphere-sphere contacts found on a hashed sphere grid (cells of the largest sphere diameter, counting
    sort), without the pairs of an intact bond and the smooth-joint pairs; returns their count."""
    x = mo.x
    r = sp.r
    n = x.shape[0]
    sstatic = np.empty(n, np.bool_)
    for i in range(n):
        sstatic[i] = sp.fixed[i] or sp.kin[i]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    S = 2.0 * rmax * 1.0001
    cmask, count, entries, cix = hashed_cells(x, S)
    seen = np.empty(27, np.int64)
    bmask = bonds.key_tab.shape[0] - 1
    nbond = bonds.i.shape[0]
    jmask = joints.key_tab.shape[0] - 1
    njoint = joints.i.shape[0]
    nrm = np.empty(3)
    pt = np.empty(3)
    nnew = 0
    for i in range(n):
        ns = 0
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    hb = _cell_hash(cix[i, 0] + dx, cix[i, 1] + dy, cix[i, 2] + dz, cmask)
                    dup = False
                    for q in range(ns):
                        if seen[q] == hb:
                            dup = True
                            break
                    if dup:
                        continue
                    seen[ns] = hb
                    ns += 1
                    for e in range(count[hb], count[hb + 1]):
                        j = entries[e]
                        if j <= i or (sstatic[i] and sstatic[j]):
                            continue
                        d0 = x[j, 0] - x[i, 0]
                        d1 = x[j, 1] - x[i, 1]
                        d2 = x[j, 2] - x[i, 2]
                        dd = d0 * d0 + d1 * d1 + d2 * d2
                        rs = r[i] + r[j]
                        if dd >= rs * rs or dd == 0.0:
                            continue
                        key = i * n + j
                        if nbond > 0:
                            kb = bond_lookup(bonds.key_tab, bonds.key_slot, key, bmask)
                            if kb >= 0 and bonds.intact[kb]:
                                continue
                        if njoint > 0 and bond_lookup(joints.key_tab, joints.key_slot, key, jmask) >= 0:
                            continue  # a smooth joint (_joints)
                        nnew = sphere_pair(i, j, key, mo, sp, lawrow, dt, hist, hc, nnew, res, nrm, pt)
    return nnew


@njit(cache=True)
def _cell_range(ci, lo, hi):
    """The cell (ix, iy, iz) number ci of the box of cells lo..hi (z fastest)."""
    iz = lo[2] + ci % (hi[2] - lo[2] + 1)
    rest = ci // (hi[2] - lo[2] + 1)
    iy = lo[1] + rest % (hi[1] - lo[1] + 1)
    ix = lo[0] + rest // (hi[1] - lo[1] + 1)
    return ix, iy, iz


@njit(cache=True)
def block_contacts(mo, sp, link, dt, hist, hc, nnew, res, blocks, deform, loads, geom, grid, lists):
    """Sphere-block contacts, after the nnew sphere-sphere contacts: candidates from the block engine's grids
    (moving blocks, static blocks, the large blocks' list); each sphere looks up the cells its box covers, each
    block once (``link.stamp``). Returns the contact count."""
    x = mo.x
    r = sp.r
    fs = geom.fs
    bstatic = blocks.fixed  # no sleeping in coupled runs
    mstart = lists.mstart
    fstart = lists.fstart
    mmask = mstart.shape[0] - 2
    fmask = fstart.shape[0] - 2
    c = np.empty(3)
    cpt = np.empty(3)
    nrm = np.empty(3)
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for j in range(x.shape[0]):
        sstatic = sp.fixed[j] or sp.kin[j]
        for a in range(3):
            c[a] = x[j, a]
            lo[a] = np.int64(np.floor((x[j, a] - r[j] - grid.margin) / grid.S))
            hi[a] = np.int64(np.floor((x[j, a] + r[j] + grid.margin) / grid.S))
        link.tag[0] += 1
        tg = link.tag[0]
        for pass_ in range(3):
            if pass_ == 1 and sstatic:
                continue  # static spheres meet only moving blocks
            ncell = (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1) if pass_ < 2 else 1
            for ci in range(ncell):
                if pass_ < 2:
                    ix, iy, iz = _cell_range(ci, lo, hi)
                    if pass_ == 0:
                        hh = _hash(ix, iy, iz, mmask)
                        e0 = mstart[hh]
                        e1 = mstart[hh + 1]
                    else:
                        if lists.fentries.shape[0] == 0:
                            continue
                        hh = _hash(ix, iy, iz, fmask)
                        e0 = fstart[hh]
                        e1 = fstart[hh + 1]
                else:
                    e0 = 0
                    e1 = lists.large_list.shape[0]
                for e in range(e0, e1):
                    if pass_ == 0:
                        bb = lists.mentries[e]
                    elif pass_ == 1:
                        bb = lists.fentries[e]
                    else:
                        bb = lists.large_list[e]
                    if link.stamp[bb] == tg:
                        continue
                    link.stamp[bb] = tg
                    if sstatic and (bstatic[bb] or blocks.kin[bb]):
                        continue
                    bx = geom.aabb
                    if (c[0] + r[j] < bx[bb, 0] or c[0] - r[j] > bx[bb, 3] or c[1] + r[j] < bx[bb, 1]
                            or c[1] - r[j] > bx[bb, 4] or c[2] + r[j] < bx[bb, 2] or c[2] - r[j] > bx[bb, 5]):
                        continue
                    sd = closest_on_polyhedron(c, link.fvs, link.fv, fs[bb], fs[bb + 1], geom.vert, geom.fnw,
                                               geom.fdw, cpt)
                    if sd >= r[j]:
                        continue
                    contact_normal(c, cpt, sd, r[j], fs[bb], fs[bb + 1], geom.fnw, geom.fdw, nrm)
                    nnew = _block_contact(bb, j, -1 - (j * bstatic.shape[0] + bb), r[j] - sd, nrm, cpt, mo, sp,
                                          blocks, deform, loads, link.lawrow[bb], dt, hist, hc, nnew, res)
    return nnew


@njit(cache=True)
def sphere_forces(dt, t, mo, sp, env, bonds, joints, link, pl, hist, res, stats, blocks, deform, loads, geom, grid,
                  lists):
    """Forces of one step at the current state (see the module docstring). res = [elastic, friction, damping,
    bond energy] (R_* slots); stats: the ST_* slots (bonds broken cumulative). ``pl``: an empty pair list (a
    coupled run searches its pairs on the grid each step). Returns OK or NEED_CAPACITY (then nothing
    persistent changed)."""
    block_geometry(blocks, deform, loads, geom, lists)
    clear_forces(mo)
    for a in range(4):
        res[a] = 0.0
    rs3 = np.zeros(3)
    hc = history_hash(hist)
    nss = grid_contacts(mo, sp, bonds, joints, env.lawrow, dt, hist, hc, rs3)
    nnew = block_contacts(mo, sp, link, dt, hist, hc, nss, rs3, blocks, deform, loads, geom, grid, lists)
    if nnew > hist.key.shape[1]:
        stats[ST_NEED] = nnew
        return NEED_CAPACITY
    hist.n[hc[1]] = nnew
    hist.cur[0] = hc[1]
    if joints.i.shape[0] > 0:
        # a retired joint's key is blanked: the grid search finds it as a plain contact from the next step
        stats[ST_JOINTS], _ = _joints(dt, mo, sp, env.lawrow, joints, rs3)
    res[0] = rs3[0]
    res[1] = rs3[1]
    res[2] = rs3[2]
    res[R_BOND], nint, nbroken = bond_forces(mo, sp, bonds, pl, dt, t, True, res)
    stats[ST_CONTACTS] = nss
    stats[ST_WALL] = nnew - nss
    stats[ST_BONDS] = nint
    stats[ST_BROKEN] += nbroken
    return OK


@njit(cache=True)
def run_coupled(nsteps, resume, dt, dt_prev, t0, first_step, env, sp, mo, bonds, joints, hist, sbooks, sres, link,
                pl, state):
    """`nsteps` coupled steps (module docstring): the spheres in the bundles of dda/_sphere_state.py (``mo``:
    their Motion with the force and torque of a step, ``sres`` the R_* sums of the last sphere forces), the
    blocks in the block engine's State (dda/_state.py). `resume`: the first step's sphere forces are already
    in mo.force / fext (a NEED_BLOCK_CAPACITY return before). Returns (status, steps done, fcp iterations, and
    run_chunk's Lists)."""
    blocks, deform, loads, forces, geom, grid, lists, sleep, con, law, books = state
    sync_central(bonds)
    status = OK
    done = 0
    fit = 0
    for step in range(nsteps):
        t = t0 + done * dt
        if not (resume and step == 0):
            st = sphere_forces(dt, t, mo, sp, env, bonds, joints, link, pl, hist, sres, sbooks.stats, blocks,
                               deform, loads, geom, grid, lists)
            if st != OK:
                status = NEED_CAPACITY
                break
        st, d, lists = run_chunk(1, dt, dt_prev, env.local_damp, first_step, blocks, deform, loads, forces, geom,
                                 grid, lists, sleep, con, law, books)
        fit += np.int64(books.stats[ST_FCP_ITER])
        if st == NEED_CAPACITY:
            status = NEED_BLOCK_CAPACITY
            break
        resume = False
        first_step = False
        ke, pe, d_loc, ok, _ = integrate(mo, sp, env, dt, dt_prev, sbooks.acc, pl.x_ref)  # no move tracking
        book_energy(sbooks.energy, sbooks.acc, ke, pe, d_loc, sres, sres[R_BOND])
        dt_prev = dt
        done += 1
        if st == BLOWUP or not ok:
            status = BLOWUP
            break
    return status, done, fit, lists
