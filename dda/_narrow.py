"""numba kernels: narrow phase and contact law, the middle stages of a step of dda/_integrate.py's run_chunk.

For each candidate pair (i, j) of the broad phase:

1. last step's record of the pair (a hash table on the pair key, ``hash_pairs`` / ``_slot_of``);
2. the common plane (``common_plane``): last step's plane is checked first (a positive gap along it proves the
   blocks apart); else the Fast Common-Plane search, confirmed by the separating-axis search for a new or deep
   overlap;
3. the contact points on that plane (``pair_points``: dda/_fcp.py's contact_points plus the support points'
   midpoint when no point represents the plane's overlap);
4. the contact law at each point (``pair_forces``): shear history of the same feature from last step, relative
   velocity, dda/_contact.py's point_force, the force and torque on both blocks, the point's new record.

Contacts between two resting blocks are carried over unchanged while sleeping is on (``carry_resting``).
The step's sums (elastic energy, friction and damping work, deepest point) go to ``tally`` and its counts to
``count`` (slots T_* and C_* of dda/_state.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._contact import point_force
from ._deform import add_strain_force, body_point, point_velocity
from ._fcp import MAXP, contact_points, fcp, gap_along, polygon_area, sat_search
from ._kinematics import omega, quat_matrix
from ._state import (C_CONTACTS, C_FIT, C_NEW, C_POINTS, C_SAT, C_SLIDING, C_WAKE, LAW_COH, LAW_KN, LAW_KS,
                     LAW_TANPHI, LAW_TEN, LAW_ZETA, T_DAMPING, T_ELASTIC, T_FRICTION, T_MAXDEPTH)


@njit(cache=True, inline="always")
def _hash_key(key, mask):
    h = key * np.int64(0x9E3779B97F4A7C15 & 0x7FFFFFFFFFFFFFFF)
    h ^= h >> 29
    return h & mask


@njit(cache=True)
def hash_pairs(con, old):
    """Hash table of last step's pairs (buffer `old`) on their key; returns its mask."""
    nold = con.n_pair[old]
    htab = con.htab
    hsize = 16
    while hsize < 2 * nold + 16:
        hsize *= 2
    hmask = hsize - 1
    htab[:hsize] = -1  # only the part in use: the cost follows the pairs, not the capacity
    for s in range(nold):
        h = _hash_key(con.key[old, s], hmask)
        while htab[h] >= 0:
            h = (h + 1) & hmask
        htab[h] = s
    return hmask


@njit(cache=True, inline="always")
def _slot_of(con, old, key, hmask):
    """Last step's slot of the pair `key`, or -1."""
    htab = con.htab
    h = _hash_key(key, hmask)
    while htab[h] >= 0:
        if con.key[old, htab[h]] == key:
            return htab[h]
        h = (h + 1) & hmask
    return -1


@njit(cache=True, inline="always")
def _released(con, old, slot, matched, ks):
    """Shear-spring energy of last step's points of this pair that have no successor (they opened)."""
    if slot < 0:
        return 0.0
    e = 0.0
    for r in range(con.npt[old, slot]):
        if not matched[r]:
            e += 0.5 * ks * (con.us[old, slot, r, 0] ** 2 + con.us[old, slot, r, 1] ** 2
                             + con.us[old, slot, r, 2] ** 2)
    return e


@njit(cache=True, inline="always")
def common_plane(i, j, slot, con, old, pos, geom, kg, size, work):
    """Common plane of pair (i, j) into work.nrm (A = i -> B = j); returns (gap, A's and B's support vertex,
    max_A x.n, min_B x.n, FCP iterations, 1 when the separating-axis search gave the plane else 0)."""
    nrm = work.nrm
    if slot >= 0:
        nrm[0] = con.nrm[old, slot, 0]
        nrm[1] = con.nrm[old, slot, 1]
        nrm[2] = con.nrm[old, slot, 2]
    else:
        nrm[0] = pos[j, 0] - pos[i, 0]
        nrm[1] = pos[j, 1] - pos[i, 1]
        nrm[2] = pos[j, 2] - pos[i, 2]
        if nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2] == 0.0:
            nrm[2] = 1.0
    # any plane with a positive gap proves separation: keep the cached plane and skip the search
    nl = np.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
    nrm[0] /= nl
    nrm[1] /= nl
    nrm[2] /= nl
    vs, fs, es, vert = geom.vs, geom.fs, geom.es, geom.vert
    g, ia, ib, sa, sb = gap_along(vert, vs[i], vs[i + 1], vs[j], vs[j + 1], nrm[0], nrm[1], nrm[2])
    its = 0
    nsat = 0
    if g <= kg:
        g, ia, ib, sa, sb, its = fcp(vert, geom.fnw, vs[i], vs[i + 1], vs[j], vs[j + 1], geom.he_origin,
                                     geom.he_next, geom.he_pair, geom.he_face, geom.vert_he, nrm, 1e-13 * size, 50,
                                     nrm)
        if g < 0.0 and (slot < 0 or con.npt[old, slot] == 0 or g < -0.01 * size):
            # a new or a deep overlap (more than 1 % of the smaller block): confirm the plane with the
            # global separating-axis search (FCP's local search can stop on a poor plane)
            n_sat = work.n_sat
            for a in range(3):
                n_sat[a] = nrm[a]
            g2 = sat_search(vert, geom.fnw, vs[i], vs[i + 1], fs[i], fs[i + 1], es[i], es[i + 1],
                            vs[j], vs[j + 1], fs[j], fs[j + 1], es[j], es[j + 1], geom.he_origin, geom.he_next,
                            geom.edge_he, nrm, g, n_sat)
            if g2 > g:
                nsat = 1
                for a in range(3):
                    nrm[a] = n_sat[a]
                g, ia, ib, sa, sb = gap_along(vert, vs[i], vs[i + 1], vs[j], vs[j + 1], nrm[0], nrm[1], nrm[2])
    return g, ia, ib, sa, sb, its, nsat


@njit(cache=True, inline="always")
def pair_points(i, j, geom, sa, sb, ia, ib, kg, size, work):
    """Contact points of pair (i, j) on the plane work.nrm into work.p_pos / p_depth / p_id; returns their count."""
    p_pos, p_depth, p_id = work.p_pos, work.p_depth, work.p_id
    k = contact_points(geom, i, j, work.nrm, sa, sb, kg, size, p_pos, p_depth, p_id, work.scr, work.iscr)
    if k < 0:
        k = 0
    # the plane's overlap sa - sb must be represented: when no point found reaches half of it (tip
    # against tip, or a penetration through an edge that pierces a face, which the candidates do not
    # include), add the support points' midpoint
    maxd = 0.0
    for q in range(k):
        if p_depth[q] > maxd:
            maxd = p_depth[q]
    if sa - sb > 0.0 and maxd < 0.5 * (sa - sb) and k < MAXP:
        p_depth[k] = sa - sb
        p_id[k] = 0
        for a in range(3):
            p_pos[k, a] = 0.5 * (geom.vert[ia, a] + geom.vert[ib, a])
        k += 1
    return k


@njit(cache=True, inline="always")
def _effective_mass(i, j, blocks, static):
    """Mass of the contact's normal mode: the free block's when the other is fixed, asleep or prescribed."""
    kin, mass = blocks.kin, blocks.mass
    inj = static[j] or kin[j]
    if kin[i] and inj:
        return min(mass[i], mass[j])
    if kin[i]:
        return mass[j]
    if inj:
        return mass[i]
    return mass[i] * mass[j] / (mass[i] + mass[j])


@njit(cache=True, inline="always")
def _shear_history(con, old, slot, pid, nrm, matched, us):
    """Shear displacement of the same feature in last step's contact, turned onto the current tangent plane
    keeping its length, into us; returns (found, bonded)."""
    found = -1
    if slot >= 0:
        for r in range(con.npt[old, slot]):
            if con.pid[old, slot, r] == pid:
                found = r
                break
    if found < 0:
        us[0] = 0.0
        us[1] = 0.0
        us[2] = 0.0
        return False, False
    matched[found] = True
    us[0] = con.us[old, slot, found, 0]
    us[1] = con.us[old, slot, found, 1]
    us[2] = con.us[old, slot, found, 2]
    bonded = con.bond[old, slot, found]
    l0 = np.sqrt(us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
    un = us[0] * nrm[0] + us[1] * nrm[1] + us[2] * nrm[2]
    for a in range(3):
        us[a] -= un * nrm[a]
    l1 = np.sqrt(us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
    if l1 > 0.0:
        for a in range(3):
            us[a] *= l0 / l1
    return True, bonded


@njit(cache=True, inline="always")
def _relative_velocity(i, j, P, blocks, deform, static, R, w, vrel):
    """Velocity of B (= j) relative to A (= i) at the point P (half-step velocities) into vrel."""
    pos, vel, dof12 = blocks.pos, blocks.vel, blocks.dof12
    for a in range(3):
        vrel[a] = vel[j, a] - vel[i, a]
    if not static[j] and dof12[j]:
        quat_matrix(blocks.quat[j], R)
        point_velocity(j, P, pos, R, deform.strain, deform.srate, deform.wb, w)
        for a in range(3):
            vrel[a] += w[a]
    elif not static[j]:
        omega(j, blocks.kin, static, blocks.wpres, blocks.quat, blocks.inertia, blocks.angmom, R, w)
        rx = P[0] - pos[j, 0]
        ry = P[1] - pos[j, 1]
        rz = P[2] - pos[j, 2]
        vrel[0] += w[1] * rz - w[2] * ry
        vrel[1] += w[2] * rx - w[0] * rz
        vrel[2] += w[0] * ry - w[1] * rx
    if dof12[i]:
        quat_matrix(blocks.quat[i], R)
        point_velocity(i, P, pos, R, deform.strain, deform.srate, deform.wb, w)
        for a in range(3):
            vrel[a] -= w[a]
    elif not blocks.fixed[i]:
        omega(i, blocks.kin, static, blocks.wpres, blocks.quat, blocks.inertia, blocks.angmom, R, w)
        rx = P[0] - pos[i, 0]
        ry = P[1] - pos[i, 1]
        rz = P[2] - pos[i, 2]
        vrel[0] -= w[1] * rz - w[2] * ry
        vrel[1] -= w[2] * rx - w[0] * rz
        vrel[2] -= w[0] * ry - w[1] * rx


@njit(cache=True, inline="always")
def _apply_point_force(i, j, P, fpt, blocks, deform, forces, static, R, X):
    """The point force fpt (on B = j, minus on A = i) at P: forces, torques about the centroids, strain forces."""
    pos, force, torque = blocks.pos, forces.force, forces.torque
    for a in range(3):
        force[i, a] -= fpt[a]
    if not static[j]:
        for a in range(3):
            force[j, a] += fpt[a]
        rx = P[0] - pos[j, 0]
        ry = P[1] - pos[j, 1]
        rz = P[2] - pos[j, 2]
        torque[j, 0] += ry * fpt[2] - rz * fpt[1]
        torque[j, 1] += rz * fpt[0] - rx * fpt[2]
        torque[j, 2] += rx * fpt[1] - ry * fpt[0]
    rx = P[0] - pos[i, 0]
    ry = P[1] - pos[i, 1]
    rz = P[2] - pos[i, 2]
    torque[i, 0] -= ry * fpt[2] - rz * fpt[1]
    torque[i, 1] -= rz * fpt[0] - rx * fpt[2]
    torque[i, 2] -= rx * fpt[1] - ry * fpt[0]
    if blocks.dof12[i]:
        quat_matrix(blocks.quat[i], R)
        body_point(i, P, pos, R, deform.strain, X)
        add_strain_force(i, X, R, fpt, -1.0, forces.qs)
    if blocks.dof12[j] and not static[j]:
        quat_matrix(blocks.quat[j], R)
        body_point(j, P, pos, R, deform.strain, X)
        add_strain_force(j, X, R, fpt, 1.0, forces.qs)


@njit(cache=True, inline="always")
def _store_point(con, new, s, kept, pid, us, st, bonded, P, fn_el, depth):
    """Record point `kept` of pair slot s in this step's buffer."""
    con.pid[new, s, kept] = pid
    con.us[new, s, kept, 0] = us[0]
    con.us[new, s, kept, 1] = us[1]
    con.us[new, s, kept, 2] = us[2]
    con.state[new, s, kept] = st
    con.bond[new, s, kept] = bonded
    con.pos[new, s, kept, 0] = P[0]
    con.pos[new, s, kept, 1] = P[1]
    con.pos[new, s, kept, 2] = P[2]
    con.fn[new, s, kept] = fn_el
    con.depth[new, s, kept] = depth


@njit(cache=True, inline="always")
def pair_forces(i, j, s, slot, k, apt, meff, first_step, dt, law, blocks, deform, forces, con, work, tally, count):
    """Contact law at the k points of pair (i, j) (slot s of this step, `slot` of last step's, area apt per
    point); returns the number of points kept (bearing or bonded)."""
    old = con.cur[0]
    new = 1 - old
    mi = blocks.material[i]
    mj = blocks.material[j]
    kn = law.tab[mi, mj, LAW_KN]
    ks = law.tab[mi, mj, LAW_KS]
    tanphi = law.tab[mi, mj, LAW_TANPHI]
    coh = law.tab[mi, mj, LAW_COH]
    ten = law.tab[mi, mj, LAW_TEN]
    zeta = law.tab[mi, mj, LAW_ZETA]
    static = work.static
    p_pos, p_depth, p_id = work.p_pos, work.p_depth, work.p_id
    us, fpt, vrel, nrm = work.us, work.fpt, work.vrel, work.nrm
    kept = 0
    for q in range(k):
        found, bonded = _shear_history(con, old, slot, p_id[q], nrm, work.matched, us)
        if not found:
            bonded = first_step and (coh > 0.0 or ten > 0.0)
        if p_depth[q] <= 0.0 and not bonded:
            continue
        _relative_velocity(i, j, p_pos[q], blocks, deform, static, work.R, work.w_old, vrel)
        st, bonded, fn_el, ee, df, dd = point_force(kn, ks, tanphi, coh * apt, ten * apt, zeta, meff,
                                                    p_depth[q], nrm, vrel, dt, us, bonded, fpt)
        tally[T_ELASTIC] += ee
        tally[T_FRICTION] += df
        tally[T_DAMPING] += dd
        if st == 0:
            continue
        if st == 2:
            count[C_SLIDING] += 1
        if p_depth[q] > tally[T_MAXDEPTH]:
            tally[T_MAXDEPTH] = p_depth[q]
        _apply_point_force(i, j, p_pos[q], fpt, blocks, deform, forces, static, work.R, work.w_old)
        _store_point(con, new, s, kept, p_id[q], us, st, bonded, p_pos[q], fn_el, p_depth[q])
        kept += 1
    return kept


@njit(cache=True, inline="always")
def _new_pair(con, new, s, key, i, j, nrm):
    """Open slot s of this step's buffer for pair (i, j) with the plane nrm and no points yet."""
    con.key[new, s] = key
    con.a[new, s] = i
    con.b[new, s] = j
    con.nrm[new, s, 0] = nrm[0]
    con.nrm[new, s, 1] = nrm[1]
    con.nrm[new, s, 2] = nrm[2]
    con.npt[new, s] = 0


@njit(cache=True)
def narrow_phase(npair, pa, pb, hmask, first_step, dt, law, gap, blocks, deform, forces, geom, sleep, con, work,
                 tally, count):
    """Common plane, contact points and contact law of the npair candidate pairs (pa[p], pb[p])."""
    nbody = blocks.pos.shape[0]
    old = con.cur[0]
    new = 1 - old
    sleep_on = sleep.par[0] > 0.0
    n_calm = np.int64(sleep.par[3])
    static, veto, matched = work.static, work.veto, work.matched
    kin, calm, asleep = blocks.kin, sleep.calm, sleep.asleep
    for p in range(npair):
        i = pa[p]
        j = pb[p]
        key = i * nbody + j
        slot = _slot_of(con, old, key, hmask)
        size = min(blocks.size_b[i], blocks.size_b[j])
        mi = blocks.material[i]
        mj = blocks.material[j]
        ks = law.tab[mi, mj, LAW_KS]
        kg = 0.0
        if law.tab[mi, mj, LAW_TEN] > 0.0 or law.tab[mi, mj, LAW_COH] > 0.0:
            kg = law.keep_gap
        g, ia, ib, sa, sb, its, nsat = common_plane(i, j, slot, con, old, blocks.pos, geom, kg, size, work)
        count[C_FIT] += its
        count[C_SAT] += nsat
        s = count[C_NEW]
        count[C_NEW] += 1
        _new_pair(con, new, s, key, i, j, work.nrm)
        matched[:] = False
        if sleep_on and asleep[j] and not veto[j] and g < gap and (kin[i] or calm[i] < n_calm):
            # a moving block comes within the search gap of a sleeping one: wake it before they touch
            # (veto marks a sleeping block already on the wake list)
            veto[j] = True
            work.wake_list[count[C_WAKE]] = j
            count[C_WAKE] += 1
        if g > kg:
            tally[T_FRICTION] += _released(con, old, slot, matched, ks)
            continue
        k = pair_points(i, j, geom, sa, sb, ia, ib, kg, size, work)
        if k == 0:
            tally[T_FRICTION] += _released(con, old, slot, matched, ks)
            continue
        apt = polygon_area(work.p_pos, k, work.nrm) / k
        meff = _effective_mass(i, j, blocks, static)
        count[C_CONTACTS] += 1
        kept = pair_forces(i, j, s, slot, k, apt, meff, first_step, dt, law, blocks, deform, forces, con, work,
                           tally, count)
        con.npt[new, s] = kept
        count[C_POINTS] += kept
        tally[T_FRICTION] += _released(con, old, slot, matched, ks)
        if sleep_on and kept > 0:
            moving_i = kin[i] or calm[i] < n_calm
            if not asleep[j]:
                if moving_i:
                    veto[j] = True
                if not static[j] and (kin[j] or calm[j] < n_calm):
                    veto[i] = True


@njit(cache=True)
def carry_resting(law, material, asleep, con, static, tally, count):
    """Contacts between resting bodies are carried over unchanged (shear history and elastic energy kept)."""
    old = con.cur[0]
    new = 1 - old
    for s0 in range(con.n_pair[old]):
        a0 = con.a[old, s0]
        b0 = con.b[old, s0]
        if con.npt[old, s0] == 0 or not (static[a0] and static[b0]) or not (asleep[a0] or asleep[b0]):
            continue
        s = count[C_NEW]
        count[C_NEW] += 1
        con.key[new, s] = con.key[old, s0]
        con.a[new, s] = a0
        con.b[new, s] = b0
        con.npt[new, s] = con.npt[old, s0]
        for a in range(3):
            con.nrm[new, s, a] = con.nrm[old, s0, a]
        kn0 = law.tab[material[a0], material[b0], LAW_KN]
        ks0 = law.tab[material[a0], material[b0], LAW_KS]
        for q in range(con.npt[old, s0]):
            con.pid[new, s, q] = con.pid[old, s0, q]
            con.state[new, s, q] = con.state[old, s0, q]
            con.bond[new, s, q] = con.bond[old, s0, q]
            con.fn[new, s, q] = con.fn[old, s0, q]
            d0 = con.depth[old, s0, q]
            con.depth[new, s, q] = d0
            u2 = 0.0
            for a in range(3):
                con.us[new, s, q, a] = con.us[old, s0, q, a]
                con.pos[new, s, q, a] = con.pos[old, s0, q, a]
                u2 += con.us[old, s0, q, a] ** 2
            tally[T_ELASTIC] += 0.5 * kn0 * d0 * d0
            tally[T_ELASTIC] += 0.5 * ks0 * u2
        count[C_CONTACTS] += 1
        count[C_POINTS] += con.npt[old, s0]
