"""numba kernels: spheres and bonds (the bonded-sphere models of sgim) in the explicit time loop.

Bodies: spheres with 6 DOF (centre velocity ``v`` and angular velocity ``w``; the inertia of a solid sphere,
2/5 m r^2, is isotropic, so no orientation is needed). Fixed spheres never move; prescribed spheres move at
their given velocity whatever the forces. Fixed convex polyhedra (walls: a floor, an incline, a box) are given
by their world vertices, face planes and face vertex loops.

One step (central difference exactly as the block engine, dt(0) = 0 so the first step is a half step):

1. pair list (Verlet list): the pairs i < j closer than r_i + r_j + skin, found on a hashed grid of cells
   2 r_max + skin (counting sort: cost linear in the sphere count), without the pairs of an intact bond, the
   smooth-joint pairs and the pairs of two fixed spheres; rebuilt only when a sphere has moved more than
   skin / 2 since the last build (a bond that breaks joins the list at once);
2. sphere-sphere contacts (overlap r_i + r_j - |x_j - x_i|) of the listed pairs, sphere-wall contacts (closest
   point of the convex polyhedron: a face, an edge or a vertex; a centre inside the wall bears on the face it
   is nearest to), both with the block engine's contact law (dda/_contact.py) at one contact point; the shear
   history of each contact is kept between steps (hash on the pair key);
3. smooth joints (``_joints``, YADE JCFpm's smoothJoint with neverErase): the pairs cut by a joint act along
   the joint normal with the joint friction and keep their reference gap while open, see ``_joints``;
4. bonds: a normal spring kn_b on the change of the centre distance from its initial value (tension and
   compression) and a shear spring ks_b on the incremental tangential displacement at the bond point; a bond
   breaks when its tensile force would exceed its tensile strength or its shear force its shear strength;
   the energy left in its springs is released (counted as dissipated); the step it broke is recorded.
   Central bonds (ks_b = 0, as LIGGGHTS' harmonic bonds) carry the normal spring alone (no shear force, no
   torque, no shear breakage) and have a loop of their own over compact rows (``CI``, ``CB``), so that a model
   of central bonds costs one normal spring per bond;
5. central difference for the free spheres (viscous damping -c v of every sphere and Cundall's local damping as
   options; the work of both goes to the local damping term).
Energy = [kinetic (product form), potential, elastic (contacts, joints and bonds), friction (+ released),
damping, local damping]; the last three cumulative.

Memory layout of the hot loop: the sphere state is copied into rows for the duration of a call: ``PA``
(position, force: 8 doubles), ``PB`` (velocity, angular velocity: 8 doubles), ``TQ`` (torque: 4 doubles), rows
aligned to their size by the caller; the bond constants and state live in one row per bond (``BB``: rest
length, kn, ks, tensile and shear force, damping ratio, shear displacement, normal force, r_i / (r_i + r_j)).
A central bond touches one 64-byte row PA of each sphere, two sphere indices and one 24-byte row ``CB`` (rest
length, kn, tensile force): its loop runs over half the memory that whole sphere rows would take, which
matters more than its arithmetic (the spheres a bond joins lie far apart in memory for a part of the bonds).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._contact import point_force

OK, NEED_CAPACITY, BLOWUP, NEED_PAIRS = 0, 1, 2, 3


@njit(cache=True, inline="always")
def pair_meff(i, j, m, fixed, kin):
    """Effective mass of the pair (i, j) for viscous damping: the free sphere's mass when the other
    is fixed or kinematic, else m_i m_j / (m_i + m_j)."""
    si = fixed[i] or kin[i]
    sj = fixed[j] or kin[j]
    if si and not sj:
        return m[j]
    if sj and not si:
        return m[i]
    return m[i] * m[j] / (m[i] + m[j])


@njit(cache=True)
def _hkey(key, mask):
    h = key * np.int64(0x9E3779B97F4A7C15 & 0x7FFFFFFFFFFFFFFF)
    h ^= h >> 29
    return h & mask


@njit(cache=True, inline="always")
def _cell_hash(ix, iy, iz, mask):
    return ((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)) & mask


@njit(cache=True)
def closest_on_polyhedron(c, fv_start, fv, f0, f1, vert, fnw, fdw, out):
    """Closest point `out` of the convex polyhedron with faces f0:f1 to the point c.

    Returns the signed distance (negative inside: then `out` is the projection on the nearest face plane)."""
    best = 1e300
    smax = -1e300
    fmax = f0
    for f in range(f0, f1):
        s = fnw[f, 0] * c[0] + fnw[f, 1] * c[1] + fnw[f, 2] * c[2] - fdw[f]
        if s > smax:
            smax = s
            fmax = f
        if s <= 0.0:
            continue
        # projection on the face plane, inside the face polygon?
        p0 = c[0] - s * fnw[f, 0]
        p1 = c[1] - s * fnw[f, 1]
        p2 = c[2] - s * fnw[f, 2]
        inside = True
        a = fv_start[f]
        b = fv_start[f + 1]
        for k in range(a, b):
            u = fv[k]
            v = fv[k + 1] if k + 1 < b else fv[a]
            e0 = vert[v, 0] - vert[u, 0]
            e1 = vert[v, 1] - vert[u, 1]
            e2 = vert[v, 2] - vert[u, 2]
            # (e x (p - u)) . n < 0: p outside this edge (faces counter-clockwise seen from outside)
            q0 = p0 - vert[u, 0]
            q1 = p1 - vert[u, 1]
            q2 = p2 - vert[u, 2]
            cx = e1 * q2 - e2 * q1
            cy = e2 * q0 - e0 * q2
            cz = e0 * q1 - e1 * q0
            if cx * fnw[f, 0] + cy * fnw[f, 1] + cz * fnw[f, 2] < 0.0:
                inside = False
                break
        if inside:
            if s < best:
                best = s
                out[0] = p0
                out[1] = p1
                out[2] = p2
            continue
        for k in range(a, b):
            u = fv[k]
            v = fv[k + 1] if k + 1 < b else fv[a]
            e0 = vert[v, 0] - vert[u, 0]
            e1 = vert[v, 1] - vert[u, 1]
            e2 = vert[v, 2] - vert[u, 2]
            ee = e0 * e0 + e1 * e1 + e2 * e2
            t = ((c[0] - vert[u, 0]) * e0 + (c[1] - vert[u, 1]) * e1 + (c[2] - vert[u, 2]) * e2) / ee
            t = min(1.0, max(0.0, t))
            x0 = vert[u, 0] + t * e0
            x1 = vert[u, 1] + t * e1
            x2 = vert[u, 2] + t * e2
            d = np.sqrt((c[0] - x0) ** 2 + (c[1] - x1) ** 2 + (c[2] - x2) ** 2)
            if d < best:
                best = d
                out[0] = x0
                out[1] = x1
                out[2] = x2
    if smax <= 0.0:
        out[0] = c[0] - smax * fnw[fmax, 0]
        out[1] = c[1] - smax * fnw[fmax, 1]
        out[2] = c[2] - smax * fnw[fmax, 2]
        return smax
    return best


@njit(cache=True)
def bond_lookup(bkey_tab, bkey_slot, key, mask):
    h = _hkey(key, mask)
    while bkey_slot[h] >= 0:
        if bkey_tab[h] == key:
            return bkey_slot[h]
        h = (h + 1) & mask
    return -1


@njit(cache=True)
def build_bond_hash(bi, bj, n):
    nb = bi.shape[0]
    hs = 16
    while hs < 2 * nb + 16:
        hs *= 2
    tab = np.zeros(hs, np.int64)
    slot = np.full(hs, -1, np.int64)
    for k in range(nb):
        key = bi[k] * n + bj[k]
        h = _hkey(key, hs - 1)
        while slot[h] >= 0:
            h = (h + 1) & (hs - 1)
        tab[h] = key
        slot[h] = k
    return tab, slot


@njit(cache=True)
def _contact(i, j, is_wall, key, depth, nx, ny, nz, px, py, pz, x, v, w, m, fixed, kin, lawrow, dt,
             old_key, old_us, htab, hmask, nold, new_key, new_us, new_fn, new_ij, nnew, force, torque, res):
    """Contact of sphere j against body i (a sphere, or wall i when is_wall): force on j along n (i -> j)."""
    us = np.zeros(3)
    slot = -1
    h = _hkey(key, hmask)
    while htab[h] >= 0:
        if old_key[htab[h]] == key:
            slot = htab[h]
            break
        h = (h + 1) & hmask
    n = np.empty(3)
    n[0] = nx
    n[1] = ny
    n[2] = nz
    if slot >= 0:
        l0 = np.sqrt(old_us[slot, 0] ** 2 + old_us[slot, 1] ** 2 + old_us[slot, 2] ** 2)
        un = old_us[slot, 0] * nx + old_us[slot, 1] * ny + old_us[slot, 2] * nz
        for a in range(3):
            us[a] = old_us[slot, a] - un * n[a]
        l1 = np.sqrt(us[0] ** 2 + us[1] ** 2 + us[2] ** 2)
        if l1 > 0.0:
            for a in range(3):
                us[a] *= l0 / l1
    vrel = np.empty(3)
    rj0 = px - x[j, 0]
    rj1 = py - x[j, 1]
    rj2 = pz - x[j, 2]
    vrel[0] = v[j, 0] + w[j, 1] * rj2 - w[j, 2] * rj1
    vrel[1] = v[j, 1] + w[j, 2] * rj0 - w[j, 0] * rj2
    vrel[2] = v[j, 2] + w[j, 0] * rj1 - w[j, 1] * rj0
    if is_wall:
        meff = m[j]
    else:
        ri0 = px - x[i, 0]
        ri1 = py - x[i, 1]
        ri2 = pz - x[i, 2]
        vrel[0] -= v[i, 0] + w[i, 1] * ri2 - w[i, 2] * ri1
        vrel[1] -= v[i, 1] + w[i, 2] * ri0 - w[i, 0] * ri2
        vrel[2] -= v[i, 2] + w[i, 0] * ri1 - w[i, 1] * ri0
        meff = pair_meff(i, j, m, fixed, kin)
    f = np.empty(3)
    st, bnd, fn_el, ee, df, dd = point_force(lawrow[0], lawrow[1], lawrow[2], 0.0, 0.0, lawrow[5], meff, depth, n,
                                             vrel, dt, us, False, f)
    res[0] += ee
    res[1] += df
    res[2] += dd
    if st == 0:
        return nnew
    for a in range(3):
        force[j, a] += f[a]
    torque[j, 0] += rj1 * f[2] - rj2 * f[1]
    torque[j, 1] += rj2 * f[0] - rj0 * f[2]
    torque[j, 2] += rj0 * f[1] - rj1 * f[0]
    if not is_wall:
        for a in range(3):
            force[i, a] -= f[a]
        torque[i, 0] -= ri1 * f[2] - ri2 * f[1]
        torque[i, 1] -= ri2 * f[0] - ri0 * f[2]
        torque[i, 2] -= ri0 * f[1] - ri1 * f[0]
    if nnew < new_key.shape[0]:
        new_key[nnew] = key
        new_fn[nnew] = fn_el
        new_ij[nnew, 0] = i if not is_wall else -1 - i
        new_ij[nnew, 1] = j
        for a in range(3):
            new_us[nnew, a] = us[a]
    return nnew + 1


@njit(cache=True)
def hashed_cells(x, S):
    """Counting sort of the spheres into hashed cells of size S (twice as many buckets as spheres,
    a power of two): (mask of the hash, bucket starts count (nbk + 1), entries (the spheres bucket
    by bucket), cix (the integer cell of each sphere))."""
    n = x.shape[0]
    nbk = 16
    while nbk < 2 * n:
        nbk *= 2
    cmask = nbk - 1
    count = np.zeros(nbk + 1, np.int64)
    entries = np.empty(n, np.int64)
    fill = np.empty(nbk, np.int64)
    cell = np.empty(n, np.int64)
    cix = np.empty((n, 3), np.int64)
    for i in range(n):
        for a in range(3):
            cix[i, a] = np.int64(np.floor(x[i, a] / S))
        cell[i] = _cell_hash(cix[i, 0], cix[i, 1], cix[i, 2], cmask)
        count[cell[i] + 1] += 1
    for b in range(nbk):
        count[b + 1] += count[b]
    for b in range(nbk):
        fill[b] = count[b]
    for i in range(n):
        entries[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return cmask, count, entries, cix


@njit(cache=True)
def build_pairs(x, r, fixed, kin, skin, bstart, bnbr, bidx, b_intact, jkey_tab, jkey_slot, njoint, out):
    """Verlet pair list: every pair i < j closer than r_i + r_j + skin, except pairs of two fixed or prescribed
    spheres, pairs with an intact bond and smooth-joint pairs (both handled by their own loops). Hashed grid of
    cells 2 r_max + skin (counting sort, linear in the spheres; a candidate counts only from its own cell, so
    buckets shared by several cells need no bookkeeping). Bonds of sphere i: bnbr[bstart[i]:bstart[i + 1]]
    (partners j > i, bond indices bidx). Writes up to len(out) pairs; returns the number of pairs found (more
    than len(out): the caller grows `out` and calls again)."""
    n = x.shape[0]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    S = (2.0 * rmax + skin) * 1.0001
    cmask, count, entries, cix = hashed_cells(x, S)
    jmask = jkey_tab.shape[0] - 1
    cap = out.shape[0]
    npair = 0
    for i in range(n):
        si = fixed[i] or kin[i]
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    cx = cix[i, 0] + dx
                    cy = cix[i, 1] + dy
                    cz = cix[i, 2] + dz
                    hb = _cell_hash(cx, cy, cz, cmask)
                    for e in range(count[hb], count[hb + 1]):
                        j = entries[e]
                        if j <= i:
                            continue
                        if cix[j, 0] != cx or cix[j, 1] != cy or cix[j, 2] != cz:
                            continue
                        if si and (fixed[j] or kin[j]):
                            continue
                        d0 = x[j, 0] - x[i, 0]
                        d1 = x[j, 1] - x[i, 1]
                        d2 = x[j, 2] - x[i, 2]
                        rs = r[i] + r[j] + skin
                        if d0 * d0 + d1 * d1 + d2 * d2 >= rs * rs:
                            continue
                        bonded = False
                        for q in range(bstart[i], bstart[i + 1]):
                            if bnbr[q] == j:
                                bonded = b_intact[bidx[q]]
                                break
                        if bonded:
                            continue
                        if njoint > 0:
                            if bond_lookup(jkey_tab, jkey_slot, i * n + j, jmask) >= 0:
                                continue
                        if npair < cap:
                            out[npair, 0] = i
                            out[npair, 1] = j
                        npair += 1
    return npair


@njit(cache=True)
def _joints(dt, x, v, r, m, fixed, kin, lawrow, ji, jj, j_nrm, j_tan, j_on, j_init, j_slide, j_us, j_sgn,
            jkey_tab, jkey_slot, force, res):
    """Smooth joints (as YADE's JCFpm smoothJoint with neverErase): the pair's contact acts along the joint
    normal n, not the centre line. A joint contact forms at t = 0 for touching pairs (set by the caller), else
    when the spheres first overlap, with the reference gap initD = |(x_j - x_i).n|; the pair then keeps that
    gap for good: D = initD - |(x_j - x_i).n| is its normal overlap (force kn D along +-n while D >= 0, the sign
    that n had at formation). A joint that opens (D < 0) carries no force and its shear spring is emptied, but
    it stays a joint with the same reference gap and pushes again as soon as D >= 0: the two faces of a joint
    stay where they are. The shear spring takes the centre velocity difference in the joint plane (no
    rotation, no torque), Coulomb friction tan(phi_joint). After a cumulative sliding (in contact) of
    2 min(r_i, r_j) the spheres are no longer neighbours across the joint: the joint is retired (j_on False,
    j_init = -1, its key blanked in the joint hash ``jkey_tab``) and the pair is a plain contact from then on.
    Returns (joints in contact, joints retired in this call); a caller with a pair list rebuilds it when the
    second is positive."""
    nact = 0
    nret = 0
    n = np.empty(3)
    vrel = np.empty(3)
    f = np.empty(3)
    us = np.empty(3)
    for k in range(ji.shape[0]):
        i = ji[k]
        j = jj[k]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        dn = d0 * j_nrm[k, 0] + d1 * j_nrm[k, 1] + d2 * j_nrm[k, 2]
        if j_on[k]:
            if j_slide[k] > 2.0 * min(r[i], r[j]):
                # slid past its neighbour: lost, its shear energy released
                res[1] += 0.5 * lawrow[1] * (j_us[k, 0] ** 2 + j_us[k, 1] ** 2 + j_us[k, 2] ** 2)
                j_on[k] = False
                j_init[k] = -1.0
                j_us[k, 0] = 0.0
                j_us[k, 1] = 0.0
                j_us[k, 2] = 0.0
                _blank_key(jkey_tab, jkey_slot, i * x.shape[0] + j)
                nret += 1
                continue
        else:
            if j_init[k] < 0.0:
                continue  # retired: a plain contact now
            rs = r[i] + r[j]
            if d0 * d0 + d1 * d1 + d2 * d2 >= rs * rs:
                continue
            j_on[k] = True
            j_init[k] = abs(dn)
            j_slide[k] = 0.0
            j_sgn[k] = 1.0 if dn >= 0.0 else -1.0
            j_us[k, 0] = 0.0
            j_us[k, 1] = 0.0
            j_us[k, 2] = 0.0
        depth = j_init[k] - abs(dn)
        for a in range(3):
            n[a] = j_sgn[k] * j_nrm[k, a]
            vrel[a] = v[j, a] - v[i, a]
            us[a] = j_us[k, a]
        vn = vrel[0] * n[0] + vrel[1] * n[1] + vrel[2] * n[2]
        meff = pair_meff(i, j, m, fixed, kin)
        st, bnd, fn_el, ee, df, dd = point_force(lawrow[0], lawrow[1], j_tan[k], 0.0, 0.0, lawrow[5], meff, depth,
                                                 n, vrel, dt, us, False, f)
        res[0] += ee
        res[1] += df
        res[2] += dd
        for a in range(3):
            j_us[k, a] = us[a]
        if st == 0:
            continue  # open: no force, the pair and its reference gap stay
        j_slide[k] += np.sqrt((vrel[0] - vn * n[0]) ** 2 + (vrel[1] - vn * n[1]) ** 2
                              + (vrel[2] - vn * n[2]) ** 2) * dt
        nact += 1
        for a in range(3):
            force[j, a] += f[a]
            force[i, a] -= f[a]
    return nact, nret


@njit(cache=True)
def _blank_key(tab, slot, key):
    """Blank `key` in the open-addressing hash (tab, slot) of build_bond_hash: its entry keeps its slot (the
    probe chains through it stay intact) but no key matches it any more (keys are >= 0)."""
    mask = tab.shape[0] - 1
    h = _hkey(key, mask)
    while slot[h] >= 0:
        if tab[h] == key:
            tab[h] = -1
            return
        h = (h + 1) & mask


@njit(cache=True, inline="always")
def _list_broken(i, j, fixed, kin, nl_pairs, nl_n, ncap, nl_flag):
    """A bond that broke: its pair joins the pair list as a contact (unless neither sphere moves; a full list
    raises the flag, and the caller rebuilds the list)."""
    if (fixed[i] or kin[i]) and (fixed[j] or kin[j]):
        return
    if nl_n[0] < ncap:
        nl_pairs[nl_n[0], 0] = i
        nl_pairs[nl_n[0], 1] = j
        nl_n[0] += 1
    else:
        nl_flag[0] = 1


@njit(cache=True, inline="always")
def advance_sphere(i, dt, dtavg, gravity, local_damp, visc, X, V, W, m, inertia, kin, bforce, force, torque, acc,
                   ke, pe, d_loc):
    """Central difference of sphere i (not fixed): a kinematic sphere moves at its prescribed
    velocity and the work of the forces on it goes to acc[0]; otherwise force + gravity + body
    force, with viscous damping -visc v (v of the last half step) and local (Cundall) damping, updates
    its velocities (dtavg, the mean of the last two steps) and its position (dt).  Adds its kinetic and
    potential energy and the damping work to ke, pe, d_loc; returns them and False on a non-finite state."""
    ok = True
    if kin[i]:
        acc[0] -= dt * (force[i, 0] * V[i, 0] + force[i, 1] * V[i, 1] + force[i, 2] * V[i, 2]
                        + torque[i, 0] * W[i, 0] + torque[i, 1] * W[i, 1] + torque[i, 2] * W[i, 2])
        for a in range(3):
            X[i, a] += dt * V[i, a]
        return ke, pe, d_loc, ok
    for a in range(3):
        f = force[i, a] + m[i] * gravity[a] + bforce[i, a]
        tq = torque[i, a]
        if visc > 0.0:
            fv = visc * V[i, a]
            f -= fv
            d_loc += fv * V[i, a] * dtavg
        if local_damp > 0.0:
            if V[i, a] != 0.0:
                fd = local_damp * abs(f) * (1.0 if V[i, a] > 0 else -1.0)
                f -= fd
                d_loc += fd * V[i, a] * dtavg
            if W[i, a] != 0.0:
                td = local_damp * abs(tq) * (1.0 if W[i, a] > 0 else -1.0)
                tq -= td
                d_loc += td * W[i, a] * dtavg
        vn_ = V[i, a] + dtavg * f / m[i]
        wn_ = W[i, a] + dtavg * tq / inertia[i]
        ke += 0.5 * m[i] * V[i, a] * vn_ + 0.5 * inertia[i] * W[i, a] * wn_
        pe -= (m[i] * gravity[a] + bforce[i, a]) * X[i, a]
        V[i, a] = vn_
        W[i, a] = wn_
        X[i, a] += dt * vn_
        if not np.isfinite(X[i, a]) or not np.isfinite(vn_) or not np.isfinite(wn_):
            ok = False
    return ke, pe, d_loc, ok


@njit(cache=True)
def run_spheres(nsteps, dt, dt_prev, gravity, local_damp, visc, t0,
                x, v, w, r, m, inertia, fixed, kin, bforce, lawrow, wall_lawrow,
                bi, bj, BB, b_intact, b_break, bstart, bnbr, bidx, bfull, cidx, CI, CB, cfn, czeta,
                ji, jj, j_nrm, j_tan, j_on, j_init, j_slide, j_us, j_sgn, jkey_tab, jkey_slot,
                wvert, wfn, wfd, wfv_start, wfv, wface_start, waabb,
                nl_pairs, nl_n, nl_flag, x_ref, skin, PA, PB, TQ,
                cur, c_n, c_key, c_us, c_fn, c_ij, htab, energy, acc, stats):
    """Advance `nsteps` steps. Returns (status, steps done). See the module docstring.

    Contact buffers c_* are (2, cap, ...) double buffers, ``cur[0]`` the one holding last step's contacts.
    Pair list: ``nl_pairs[:nl_n[0]]`` built at ``x_ref`` with margin ``skin``; ``nl_flag[0] = 1`` asks for a
    rebuild (set when a sphere has moved by more than skin / 2 since, or a broken bond does not fit the list).
    ``acc = [work of the prescribed spheres]``; ``stats = [contacts, wall contacts, intact bonds, broken this
    chunk, contacts needed, pairs needed, active joints, pair-list builds]``; ``b_break`` gets the time a
    bond broke. Bonds with a shear spring: ``bfull`` (indices into the bond arrays, in order); central bonds
    (ks = 0): ``cidx`` (their bond indices), ``CI`` their spheres (i, j; i stored as -1 - i while the bond is
    broken, set from ``b_intact`` on entry), ``CB`` one row each (rest length, kn, tensile force), ``cfn`` their
    normal force (written in the last step of the call), ``czeta`` their damping ratios (read only when it has
    entries: an empty array stands for undamped central bonds)."""
    n = x.shape[0]
    nbond = bfull.shape[0]
    ncen = cidx.shape[0]
    cdamped = czeta.shape[0] > 0
    for q in range(ncen):
        i = CI[q, 0]
        if (i >= 0) != b_intact[cidx[q]]:
            CI[q, 0] = -1 - i
            cfn[q] = 0.0
    njoint = ji.shape[0]
    nwall = waabb.shape[0]
    cap = c_key.shape[1]
    ncap = nl_pairs.shape[0]
    # sphere state in rows (copied in here and out at the end): PA (position, force: the 64 bytes a central bond
    # touches), PB (velocity, angular velocity), TQ (torque); bond constants and state in one row per bond in BB
    # (length, kn, ks, ft, fs, damping ratio, shear displacement (3), normal force, r_i / (r_i + r_j))
    for i in range(n):
        for a in range(3):
            PA[i, a] = x[i, a]
            PB[i, a] = v[i, a]
            PB[i, 3 + a] = w[i, a]
    X = PA[:, 0:3]
    force = PA[:, 3:6]
    V = PB[:, 0:3]
    W = PB[:, 3:6]
    torque = TQ[:, 0:3]
    res = np.zeros(3)
    cpt = np.empty(3)
    c = np.empty(3)
    half2 = 0.25 * skin * skin
    status = OK
    done = 0
    nbroken = 0
    t = t0
    for step in range(nsteps):
        # 1. pair list (rebuilt only when a sphere may have come within reach of a new neighbour)
        if nl_flag[0] != 0:
            npair = build_pairs(X, r, fixed, kin, skin, bstart, bnbr, bidx, b_intact, jkey_tab, jkey_slot, njoint,
                                nl_pairs)
            if npair > ncap:
                status = NEED_PAIRS
                stats[5] = npair
                break
            nl_n[0] = npair
            for i in range(n):
                for a in range(3):
                    x_ref[i, a] = X[i, a]
            nl_flag[0] = 0
            stats[7] += 1
        old = cur[0]
        new = 1 - old
        nold = c_n[old]
        hsize = 16
        while hsize < 2 * nold + 16:
            hsize *= 2
        hmask = hsize - 1
        htab[:hsize] = -1
        for s in range(nold):
            h = _hkey(c_key[old, s], hmask)
            while htab[h] >= 0:
                h = (h + 1) & hmask
            htab[h] = s
        for i in range(n):
            for a in range(3):
                force[i, a] = 0.0
                torque[i, a] = 0.0
        res[:] = 0.0
        nnew = 0
        nwc = 0
        # 2. sphere-sphere contacts over the pair list
        for p in range(nl_n[0]):
            i = nl_pairs[p, 0]
            j = nl_pairs[p, 1]
            d0 = X[j, 0] - X[i, 0]
            d1 = X[j, 1] - X[i, 1]
            d2 = X[j, 2] - X[i, 2]
            dd = d0 * d0 + d1 * d1 + d2 * d2
            rs = r[i] + r[j]
            if dd >= rs * rs or dd == 0.0:
                continue
            key = i * n + j
            dl = np.sqrt(dd)
            depth = rs - dl
            nx = d0 / dl
            ny = d1 / dl
            nz = d2 / dl
            a0 = r[i] - 0.5 * depth
            nnew = _contact(i, j, False, key, depth, nx, ny, nz, X[i, 0] + a0 * nx,
                            X[i, 1] + a0 * ny, X[i, 2] + a0 * nz, X, V, W, m, fixed, kin, lawrow,
                            dt, c_key[old], c_us[old], htab, hmask, nold, c_key[new], c_us[new],
                            c_fn[new], c_ij[new], nnew, force, torque, res)
        # sphere-wall contacts (walls are few: each tested by its box)
        for j in range(n):
            if nwall == 0:
                break
            if fixed[j] or kin[j]:
                continue
            for k in range(nwall):
                if (X[j, 0] + r[j] < waabb[k, 0] or X[j, 0] - r[j] > waabb[k, 3] or X[j, 1] + r[j] < waabb[k, 1]
                        or X[j, 1] - r[j] > waabb[k, 4] or X[j, 2] + r[j] < waabb[k, 2]
                        or X[j, 2] - r[j] > waabb[k, 5]):
                    continue
                for a in range(3):
                    c[a] = X[j, a]
                sd = closest_on_polyhedron(c, wfv_start, wfv, wface_start[k], wface_start[k + 1], wvert, wfn, wfd,
                                           cpt)
                if sd >= r[j]:
                    continue
                if sd > 1e-12 * r[j]:
                    nx = (c[0] - cpt[0]) / sd
                    ny = (c[1] - cpt[1]) / sd
                    nz = (c[2] - cpt[2]) / sd
                else:
                    # centre on or inside the wall: push out along the nearest face's normal
                    best = -1e300
                    fb = wface_start[k]
                    for f in range(wface_start[k], wface_start[k + 1]):
                        s = wfn[f, 0] * c[0] + wfn[f, 1] * c[1] + wfn[f, 2] * c[2] - wfd[f]
                        if s > best:
                            best = s
                            fb = f
                    nx = wfn[fb, 0]
                    ny = wfn[fb, 1]
                    nz = wfn[fb, 2]
                depth = r[j] - sd
                key = -1 - (j * nwall + k)
                nc0 = nnew
                nnew = _contact(k, j, True, key, depth, nx, ny, nz, cpt[0], cpt[1], cpt[2], X, V, W, m, fixed,
                                kin, wall_lawrow[k], dt, c_key[old], c_us[old], htab, hmask, nold, c_key[new],
                                c_us[new], c_fn[new], c_ij[new], nnew, force, torque, res)
                nwc += nnew - nc0
        if nnew > cap:
            status = NEED_CAPACITY
            stats[4] = nnew
            break
        c_n[new] = nnew
        cur[0] = new
        # smooth joints
        if njoint > 0:
            stats[6], nret = _joints(dt, X, V, r, m, fixed, kin, lawrow, ji, jj, j_nrm, j_tan, j_on, j_init,
                                     j_slide, j_us, j_sgn, jkey_tab, jkey_slot, force, res)
            if nret > 0:
                nl_flag[0] = 1  # retired joints are plain contacts: into the pair list
        # 3. bonds
        e_bond = 0.0
        nint = 0
        # the reaction on sphere i is summed over its consecutive bonds (the list is sorted by i) before it is
        # added to its row
        ci = -1
        g0 = g1 = g2 = h0 = h1 = h2 = 0.0
        for kk in range(nbond):
            k = bfull[kk]
            if not b_intact[k]:
                continue
            i = bi[k]
            j = bj[k]
            if i != ci:
                if ci >= 0:
                    force[ci, 0] -= g0
                    force[ci, 1] -= g1
                    force[ci, 2] -= g2
                    torque[ci, 0] -= h0
                    torque[ci, 1] -= h1
                    torque[ci, 2] -= h2
                ci = i
                g0 = g1 = g2 = h0 = h1 = h2 = 0.0
            d0 = X[j, 0] - X[i, 0]
            d1 = X[j, 1] - X[i, 1]
            d2 = X[j, 2] - X[i, 2]
            dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            inv = 1.0 / dl
            nx = d0 * inv
            ny = d1 * inv
            nz = d2 * inv
            # bond point: between the surfaces, in proportion to the radii (BB[k, 10] = r_i / (r_i + r_j))
            # (arms: r_i = a0 n from i, r_j = aj n from j): relative velocity there
            # v_j + w_j x r_j - v_i - w_i x r_i = dv + (aj w_j - a0 w_i) x n, whose normal part is dv.n
            a0 = dl * BB[k, 10]
            aj = a0 - dl
            dv0 = V[j, 0] - V[i, 0]
            dv1 = V[j, 1] - V[i, 1]
            dv2 = V[j, 2] - V[i, 2]
            vn = dv0 * nx + dv1 * ny + dv2 * nz
            c0 = aj * W[j, 0] - a0 * W[i, 0]
            c1 = aj * W[j, 1] - a0 * W[i, 1]
            c2 = aj * W[j, 2] - a0 * W[i, 2]
            vr0 = dv0 + c1 * nz - c2 * ny
            vr1 = dv1 + c2 * nx - c0 * nz
            vr2 = dv2 + c0 * ny - c1 * nx
            # shear displacement: onto the current tangent plane (length kept), then the increment
            u0 = BB[k, 6]
            u1 = BB[k, 7]
            u2 = BB[k, 8]
            uu = u0 * u0 + u1 * u1 + u2 * u2
            if uu > 0.0:
                un = u0 * nx + u1 * ny + u2 * nz
                u0 -= un * nx
                u1 -= un * ny
                u2 -= un * nz
                l1 = u0 * u0 + u1 * u1 + u2 * u2
                if l1 > 0.0:
                    sc = np.sqrt(uu / l1)
                    u0 *= sc
                    u1 *= sc
                    u2 *= sc
            u0 += (vr0 - vn * nx) * dt
            u1 += (vr1 - vn * ny) * dt
            u2 += (vr2 - vn * nz) * dt
            stretch = dl - BB[k, 0]
            fn = BB[k, 1] * stretch  # tension > 0
            uu = u0 * u0 + u1 * u1 + u2 * u2
            if fn > BB[k, 3] or BB[k, 2] * BB[k, 2] * uu > BB[k, 4] * BB[k, 4]:  # shear force ks |u| > fs
                # breaks: its spring energy (last step's) leaves the system; the pair joins the pair list
                b_intact[k] = False
                b_break[k] = t
                BB[k, 9] = 0.0
                res[1] += 0.5 * BB[k, 1] * stretch * stretch + 0.5 * BB[k, 2] * uu
                BB[k, 6] = 0.0
                BB[k, 7] = 0.0
                BB[k, 8] = 0.0
                nbroken += 1
                _list_broken(i, j, fixed, kin, nl_pairs, nl_n, ncap, nl_flag)
                continue
            nint += 1
            BB[k, 6] = u0
            BB[k, 7] = u1
            BB[k, 8] = u2
            BB[k, 9] = fn
            e_bond += 0.5 * BB[k, 1] * stretch * stretch + 0.5 * BB[k, 2] * uu
            # force on j: -fn n - ks u (+ viscous damping on the normal and shear relative velocity)
            cdn = 0.0
            if BB[k, 5] > 0.0:
                meff = pair_meff(i, j, m, fixed, kin)
                cdn = 2.0 * BB[k, 5] * np.sqrt(BB[k, 1] * meff)
                cds = 2.0 * BB[k, 5] * np.sqrt(BB[k, 2] * meff)
                res[2] += (cdn * vn * vn + cds * ((vr0 - vn * nx) ** 2 + (vr1 - vn * ny) ** 2
                                                  + (vr2 - vn * nz) ** 2)) * dt
            else:
                cds = 0.0
            f0 = -(fn + cdn * vn) * nx - BB[k, 2] * u0 - cds * (vr0 - vn * nx)
            f1 = -(fn + cdn * vn) * ny - BB[k, 2] * u1 - cds * (vr1 - vn * ny)
            f2 = -(fn + cdn * vn) * nz - BB[k, 2] * u2 - cds * (vr2 - vn * nz)
            # torques: r_j x f = aj (n x f) on j, r_i x f = a0 (n x f) against i
            q0 = ny * f2 - nz * f1
            q1 = nz * f0 - nx * f2
            q2 = nx * f1 - ny * f0
            force[j, 0] += f0
            force[j, 1] += f1
            force[j, 2] += f2
            torque[j, 0] += aj * q0
            torque[j, 1] += aj * q1
            torque[j, 2] += aj * q2
            g0 += f0
            g1 += f1
            g2 += f2
            h0 += a0 * q0
            h1 += a0 * q1
            h2 += a0 * q2
        if ci >= 0:
            force[ci, 0] -= g0
            force[ci, 1] -= g1
            force[ci, 2] -= g2
            torque[ci, 0] -= h0
            torque[ci, 1] -= h1
            torque[ci, 2] -= h2
        # central bonds (ks = 0): the normal spring alone, force along the centre line, no torque
        ci = -1
        g0 = g1 = g2 = 0.0
        last = step == nsteps - 1
        for q in range(ncen):
            i = CI[q, 0]
            if i < 0:
                continue
            j = CI[q, 1]
            if i != ci:
                if ci >= 0:
                    force[ci, 0] -= g0
                    force[ci, 1] -= g1
                    force[ci, 2] -= g2
                ci = i
                g0 = g1 = g2 = 0.0
            d0 = X[j, 0] - X[i, 0]
            d1 = X[j, 1] - X[i, 1]
            d2 = X[j, 2] - X[i, 2]
            dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            stretch = dl - CB[q, 0]
            fn = CB[q, 1] * stretch  # tension > 0
            if fn > CB[q, 2]:
                k = cidx[q]
                CI[q, 0] = -1 - i
                b_intact[k] = False
                b_break[k] = t
                BB[k, 9] = 0.0
                cfn[q] = 0.0
                res[1] += 0.5 * CB[q, 1] * stretch * stretch
                nbroken += 1
                _list_broken(i, j, fixed, kin, nl_pairs, nl_n, ncap, nl_flag)
                continue
            nint += 1
            if last:
                cfn[q] = fn
            e_bond += 0.5 * CB[q, 1] * stretch * stretch
            # force on j: -(fn + cdn vn) n, n = d / dl
            s = fn
            if cdamped and czeta[q] > 0.0:
                inv = 1.0 / dl
                vn = ((V[j, 0] - V[i, 0]) * d0 + (V[j, 1] - V[i, 1]) * d1 + (V[j, 2] - V[i, 2]) * d2) * inv
                meff = pair_meff(i, j, m, fixed, kin)
                cdn = 2.0 * czeta[q] * np.sqrt(CB[q, 1] * meff)
                res[2] += cdn * vn * vn * dt
                s += cdn * vn
            s = -s / dl
            f0 = s * d0
            f1 = s * d1
            f2 = s * d2
            force[j, 0] += f0
            force[j, 1] += f1
            force[j, 2] += f2
            g0 += f0
            g1 += f1
            g2 += f2
        if ci >= 0:
            force[ci, 0] -= g0
            force[ci, 1] -= g1
            force[ci, 2] -= g2
        # 4. central difference (and the largest move since the pair list was built)
        dtavg = 0.5 * (dt + dt_prev)
        ke = 0.0
        pe = 0.0
        d_loc = 0.0
        blown = False
        moved = 0.0
        for i in range(n):
            if fixed[i]:
                continue
            ke, pe, d_loc, ok = advance_sphere(i, dt, dtavg, gravity, local_damp, visc, X, V, W, m, inertia, kin,
                                               bforce, force, torque, acc, ke, pe, d_loc)
            blown |= not ok
            e0 = X[i, 0] - x_ref[i, 0]
            e1 = X[i, 1] - x_ref[i, 1]
            e2 = X[i, 2] - x_ref[i, 2]
            moved = max(moved, e0 * e0 + e1 * e1 + e2 * e2)
        if not moved <= half2:
            nl_flag[0] = 1
        dt_prev = dt
        t += dt
        energy[0] = ke
        energy[1] = pe - acc[0]
        energy[2] = res[0] + e_bond
        energy[3] += res[1]
        energy[4] += res[2]
        energy[5] += d_loc
        stats[0] = nnew - nwc
        stats[1] = nwc
        stats[2] = nint
        done += 1
        if blown:
            status = BLOWUP
            break
    stats[3] = nbroken
    for i in range(n):
        for a in range(3):
            x[i, a] = X[i, a]
            v[i, a] = V[i, a]
            w[i, a] = W[i, a]
    return status, done
