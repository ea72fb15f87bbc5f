"""numba kernels: spheres and bonds (the bonded-sphere models of sgim) in the explicit time loop.

Bodies: spheres with 6 DOF (centre velocity ``v`` and angular velocity ``w``; the inertia of a solid sphere,
2/5 m r^2, is isotropic, so no orientation is needed). Fixed spheres never move; prescribed spheres move at
their given velocity whatever the forces. Fixed convex polyhedra (walls: a floor, an incline, a box) are given
by their world vertices, face planes and face vertex loops.

One step (central difference exactly as the block engine, dt(0) = 0 so the first step is a half step):

Each stage is a kernel of its own, on the bundles of dda/_sphere_state.py (``run_spheres`` calls them in turn;
dda/_coupled.py runs the same contact, joint, bond and integration kernels with the blocks):

1. ``refresh_pairs``, the pair list (Verlet list): the pairs i < j closer than r_i + r_j + skin, found on a hashed grid of cells
   2 r_max + skin (counting sort: cost linear in the sphere count), without the pairs of an intact bond, the
   smooth-joint pairs and the pairs of two fixed spheres; rebuilt only when a sphere has moved more than
   skin / 2 since the last build (a bond that breaks joins the list at once);
2. ``pair_contacts``, ``wall_contacts``: sphere-sphere contacts (overlap r_i + r_j - |x_j - x_i|) of the listed pairs, sphere-wall contacts (closest
   point of the convex polyhedron: a face, an edge or a vertex; a centre inside the wall bears on the face it
   is nearest to), both with the block engine's contact law (dda/_contact.py) at one contact point; the shear
   history of each contact is kept between steps (``History``, one hash on the pair key: ``history_hash``,
   ``carry_shear``, ``record_contact``);
3. smooth joints (``_joints``, YADE JCFpm's smoothJoint with neverErase): the pairs cut by a joint act along
   the joint normal with the joint friction and keep their reference gap while open, see ``_joints``;
4. bonds (``bond_forces``, dda/_bondlaw.py, the one bond law): a normal spring kn_b on the change of the centre distance from its initial value (tension and
   compression) and a shear spring ks_b on the incremental tangential displacement at the bond point; a bond
   breaks when its tensile force would exceed its tensile strength or its shear force its shear strength;
   the energy left in its springs is released (counted as dissipated); the step it broke is recorded.
   Central bonds (ks_b = 0, as LIGGGHTS' harmonic bonds) carry the normal spring alone (no shear force, no
   torque, no shear breakage) and have a loop of their own over compact rows (``Bonds.cij``, ``crows``), so that a model
   of central bonds costs one normal spring per bond;
5. ``integrate``: central difference for the free spheres (viscous damping -c v of every sphere and Cundall's local damping as
   options; the work of both goes to the local damping term).
Energy = [kinetic (product form), potential, elastic (contacts, joints and bonds), friction (+ released),
damping, local damping]; the last three cumulative.

Memory layout of the hot loop: the sphere state is copied into rows for the duration of a call: ``PA``
(position, force: 8 doubles), ``PB`` (velocity, angular velocity: 8 doubles), ``TQ`` (torque: 4 doubles), rows
aligned to their size by the caller (a stage sees them as a ``Motion`` bundle of views); the bond constants
and state live in one row per bond (``Bonds.rows``, B_* columns: rest length, kn, ks, tensile and shear force,
damping ratio, shear displacement, normal force, r_i / (r_i + r_j)). A central bond touches one 64-byte row
PA of each sphere, two sphere indices and one 24-byte row of ``Bonds.crows`` (rest
length, kn, tensile force): its loop runs over half the memory that whole sphere rows would take, which
matters more than its arithmetic (the spheres a bond joins lie far apart in memory for a part of the bonds).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._bondlaw import _blank_key, _hkey, bond_forces, bond_lookup, pair_meff, sync_central
from ._contact import local_damping, point_force
from ._sphere_state import (E_DAMPING, E_ELASTIC, E_FRICTION, E_KIN, E_LOCAL, E_POT, LAW_KN, LAW_KS, LAW_TANPHI,
                            LAW_ZETA, ST_BONDS, ST_BROKEN, ST_BUILDS, ST_CONTACTS, ST_JOINTS, ST_NEED,
                            ST_NEED_PAIRS, ST_WALL, Motion)

OK, NEED_CAPACITY, BLOWUP, NEED_PAIRS = 0, 1, 2, 3


@njit(cache=True)
def history_hash(hist):
    """Start a step's contact history: the hash ``hist.htab`` of last step's keys (buffer cur[0]). Returns
    hc = (old buffer, new buffer, hash mask) for ``carry_shear`` and ``record_contact``."""
    old = hist.cur[0]
    new = 1 - old
    nold = hist.n[old]
    hsize = 16
    while hsize < 2 * nold + 16:
        hsize *= 2
    hmask = hsize - 1
    htab = hist.htab
    htab[:hsize] = -1
    for s in range(nold):
        h = _hkey(hist.key[old, s], hmask)
        while htab[h] >= 0:
            h = (h + 1) & hmask
        htab[h] = s
    return old, new, hmask


@njit(cache=True)
def carry_shear(hist, hc, key, n, us):
    """us = last step's shear displacement of contact `key`, turned into the plane normal to n with its length
    kept (zeros for a new contact)."""
    old = hc[0]
    hmask = hc[2]
    us[0] = 0.0
    us[1] = 0.0
    us[2] = 0.0
    h = _hkey(key, hmask)
    while hist.htab[h] >= 0:
        s = hist.htab[h]
        if hist.key[old, s] == key:
            ous = hist.us[old]
            l0 = np.sqrt(ous[s, 0] ** 2 + ous[s, 1] ** 2 + ous[s, 2] ** 2)
            un = ous[s, 0] * n[0] + ous[s, 1] * n[1] + ous[s, 2] * n[2]
            for a in range(3):
                us[a] = ous[s, a] - un * n[a]
            l1 = np.sqrt(us[0] ** 2 + us[1] ** 2 + us[2] ** 2)
            if l1 > 0.0:
                for a in range(3):
                    us[a] *= l0 / l1
            return
        h = (h + 1) & hmask


@njit(cache=True, inline="always")
def record_contact(hist, hc, nnew, key, fn_el, a, j, us):
    """Contact nnew of this step (bodies a, j) into the new buffer (when it fits); returns nnew + 1."""
    new = hc[1]
    if nnew < hist.key.shape[1]:
        hist.key[new, nnew] = key
        hist.fn[new, nnew] = fn_el
        hist.ij[new, nnew, 0] = a
        hist.ij[new, nnew, 1] = j
        for c in range(3):
            hist.us[new, nnew, c] = us[c]
    return nnew + 1


@njit(cache=True, inline="always")
def contact_normal(c, cpt, sd, r, f0, f1, fnw, fdw, nrm):
    """Normal of a sphere (centre c, radius r) against a convex polyhedron (faces f0:f1) whose closest point is
    cpt at signed distance sd: from cpt to c, or, a centre on or inside it, the nearest face's normal."""
    if sd > 1e-12 * r:
        for a in range(3):
            nrm[a] = (c[a] - cpt[a]) / sd
    else:
        # centre on or inside the body: push out along the nearest face's normal
        best = -1e300
        fb = f0
        for f in range(f0, f1):
            s = fnw[f, 0] * c[0] + fnw[f, 1] * c[1] + fnw[f, 2] * c[2] - fdw[f]
            if s > best:
                best = s
                fb = f
        for a in range(3):
            nrm[a] = fnw[fb, a]


@njit(cache=True, inline="always")
def sphere_point(j, p, mo, r, vrel):
    """The lever r = p - x_j of sphere j's point p and the point's velocity v_j + w_j x r (into vrel)."""
    x = mo.x
    v = mo.v
    w = mo.w
    r[0] = p[0] - x[j, 0]
    r[1] = p[1] - x[j, 1]
    r[2] = p[2] - x[j, 2]
    vrel[0] = v[j, 0] + w[j, 1] * r[2] - w[j, 2] * r[1]
    vrel[1] = v[j, 1] + w[j, 2] * r[0] - w[j, 0] * r[2]
    vrel[2] = v[j, 2] + w[j, 0] * r[1] - w[j, 1] * r[0]


@njit(cache=True, inline="always")
def sphere_point_force(j, r, meff, depth, n, vrel, us, lawrow, dt, mo, res, f):
    """The contact law (dda/_contact.py point_force, no cohesion) at a point of sphere j with lever r: its
    energy terms added to res, the force f (on j, along n) and its torque added to sphere j when the point is in
    contact. Returns (status, elastic normal force)."""
    st, bnd, fn_el, ee, df, dd = point_force(lawrow[LAW_KN], lawrow[LAW_KS], lawrow[LAW_TANPHI], 0.0, 0.0,
                                             lawrow[LAW_ZETA], meff, depth, n, vrel, dt, us, False, f)
    res[0] += ee
    res[1] += df
    res[2] += dd
    if st != 0:
        for a in range(3):
            mo.force[j, a] += f[a]
        mo.torque[j, 0] += r[1] * f[2] - r[2] * f[1]
        mo.torque[j, 1] += r[2] * f[0] - r[0] * f[2]
        mo.torque[j, 2] += r[0] * f[1] - r[1] * f[0]
    return st, fn_el


@njit(cache=True)
def _contact(i, j, is_wall, key, depth, n, p, mo, sp, lawrow, dt, hist, hc, nnew, res):
    """Contact of sphere j against body i (a sphere, or wall i when is_wall): force on j along n (i -> j) at the
    point p, the shear history from ``hist`` (hc of ``history_hash``). Returns the contact count."""
    x = mo.x
    v = mo.v
    w = mo.w
    us = np.empty(3)
    carry_shear(hist, hc, key, n, us)
    rj = np.empty(3)
    vrel = np.empty(3)
    sphere_point(j, p, mo, rj, vrel)
    if is_wall:
        meff = sp.m[j]
    else:
        ri0 = p[0] - x[i, 0]
        ri1 = p[1] - x[i, 1]
        ri2 = p[2] - x[i, 2]
        vrel[0] -= v[i, 0] + w[i, 1] * ri2 - w[i, 2] * ri1
        vrel[1] -= v[i, 1] + w[i, 2] * ri0 - w[i, 0] * ri2
        vrel[2] -= v[i, 2] + w[i, 0] * ri1 - w[i, 1] * ri0
        meff = pair_meff(i, j, sp.m, sp.fixed, sp.kin)
    f = np.empty(3)
    st, fn_el = sphere_point_force(j, rj, meff, depth, n, vrel, us, lawrow, dt, mo, res, f)
    if st == 0:
        return nnew
    if not is_wall:
        for a in range(3):
            mo.force[i, a] -= f[a]
        mo.torque[i, 0] -= ri1 * f[2] - ri2 * f[1]
        mo.torque[i, 1] -= ri2 * f[0] - ri0 * f[2]
        mo.torque[i, 2] -= ri0 * f[1] - ri1 * f[0]
    return record_contact(hist, hc, nnew, key, fn_el, i if not is_wall else -1 - i, j, us)


@njit(cache=True)
def sphere_pair(i, j, key, mo, sp, lawrow, dt, hist, hc, nnew, res, nrm, pt):
    """Contact of the overlapping spheres i and j (overlap r_i + r_j - |x_j - x_i|; the point in the middle of
    the overlap); nrm, pt: scratch. Returns the contact count."""
    X = mo.x
    r = sp.r
    d0 = X[j, 0] - X[i, 0]
    d1 = X[j, 1] - X[i, 1]
    d2 = X[j, 2] - X[i, 2]
    dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    depth = r[i] + r[j] - dl
    nrm[0] = d0 / dl
    nrm[1] = d1 / dl
    nrm[2] = d2 / dl
    a0 = r[i] - 0.5 * depth
    for a in range(3):
        pt[a] = X[i, a] + a0 * nrm[a]
    return _contact(i, j, False, key, depth, nrm, pt, mo, sp, lawrow, dt, hist, hc, nnew, res)


@njit(cache=True)
def pair_contacts(mo, sp, pl, lawrow, dt, hist, hc, res):
    """Sphere-sphere contacts of the pairs in the pair list; returns their count."""
    X = mo.x
    r = sp.r
    n = X.shape[0]
    nrm = np.empty(3)
    pt = np.empty(3)
    nnew = 0
    for p in range(pl.n[0]):
        i = pl.pairs[p, 0]
        j = pl.pairs[p, 1]
        d0 = X[j, 0] - X[i, 0]
        d1 = X[j, 1] - X[i, 1]
        d2 = X[j, 2] - X[i, 2]
        dd = d0 * d0 + d1 * d1 + d2 * d2
        rs = r[i] + r[j]
        if dd >= rs * rs or dd == 0.0:
            continue
        nnew = sphere_pair(i, j, i * n + j, mo, sp, lawrow, dt, hist, hc, nnew, res, nrm, pt)
    return nnew


@njit(cache=True)
def wall_contacts(mo, sp, walls, dt, hist, hc, nnew, res):
    """Sphere-wall contacts (walls are few: each tested by its box) of the free spheres, after the nnew
    sphere-sphere contacts; returns (contact count, wall contacts)."""
    X = mo.x
    r = sp.r
    n = X.shape[0]
    nwall = walls.aabb.shape[0]
    waabb = walls.aabb
    fstart = walls.face_start
    c = np.empty(3)
    cpt = np.empty(3)
    nrm = np.empty(3)
    nwc = 0
    for j in range(n):
        if nwall == 0:
            break
        if sp.fixed[j] or sp.kin[j]:
            continue
        for k in range(nwall):
            if (X[j, 0] + r[j] < waabb[k, 0] or X[j, 0] - r[j] > waabb[k, 3] or X[j, 1] + r[j] < waabb[k, 1]
                    or X[j, 1] - r[j] > waabb[k, 4] or X[j, 2] + r[j] < waabb[k, 2]
                    or X[j, 2] - r[j] > waabb[k, 5]):
                continue
            for a in range(3):
                c[a] = X[j, a]
            sd = closest_on_polyhedron(c, walls.fv_start, walls.fv, fstart[k], fstart[k + 1], walls.vert, walls.fn,
                                       walls.fd, cpt)
            if sd >= r[j]:
                continue
            contact_normal(c, cpt, sd, r[j], fstart[k], fstart[k + 1], walls.fn, walls.fd, nrm)
            nc0 = nnew
            nnew = _contact(k, j, True, -1 - (j * nwall + k), r[j] - sd, nrm, cpt, mo, sp, walls.lawrow[k], dt,
                            hist, hc, nnew, res)
            nwc += nnew - nc0
    return nnew, nwc


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


@njit(cache=True, inline="always")
def _cell_hash(ix, iy, iz, mask):
    return ((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)) & mask


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
def build_pairs(x, sp, bonds, joints, skin, out):
    """Verlet pair list: every pair i < j closer than r_i + r_j + skin, except pairs of two fixed or prescribed
    spheres, pairs with an intact bond and smooth-joint pairs (both handled by their own loops). Hashed grid of
    cells 2 r_max + skin (counting sort, linear in the spheres; a candidate counts only from its own cell, so
    buckets shared by several cells need no bookkeeping). Bonds of sphere i: bonds.nbr[start[i]:start[i + 1]]
    (partners j > i, bond indices bonds.idx). Writes up to len(out) pairs; returns the number of pairs found
    (more than len(out): the caller grows `out` and calls again)."""
    r = sp.r
    fixed = sp.fixed
    kin = sp.kin
    bstart = bonds.start
    bnbr = bonds.nbr
    njoint = joints.i.shape[0]
    n = x.shape[0]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    S = (2.0 * rmax + skin) * 1.0001
    cmask, count, entries, cix = hashed_cells(x, S)
    jmask = joints.key_tab.shape[0] - 1
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
                                bonded = bonds.intact[bonds.idx[q]]
                                break
                        if bonded:
                            continue
                        if njoint > 0:
                            if bond_lookup(joints.key_tab, joints.key_slot, i * n + j, jmask) >= 0:
                                continue
                        if npair < cap:
                            out[npair, 0] = i
                            out[npair, 1] = j
                        npair += 1
    return npair


@njit(cache=True)
def _joints(dt, mo, sp, lawrow, jt, res):
    """Smooth joints (as YADE's JCFpm smoothJoint with neverErase): the pair's contact acts along the joint
    normal n, not the centre line. A joint contact forms at t = 0 for touching pairs (set by the caller), else
    when the spheres first overlap, with the reference gap initD = |(x_j - x_i).n|; the pair then keeps that
    gap for good: D = initD - |(x_j - x_i).n| is its normal overlap (force kn D along +-n while D >= 0, the sign
    that n had at formation). A joint that opens (D < 0) carries no force and its shear spring is emptied, but
    it stays a joint with the same reference gap and pushes again as soon as D >= 0: the two faces of a joint
    stay where they are. The shear spring takes the centre velocity difference in the joint plane (no
    rotation, no torque), Coulomb friction tan(phi_joint). After a cumulative sliding (in contact) of
    2 min(r_i, r_j) the spheres are no longer neighbours across the joint: the joint is retired (on False,
    init = -1, its key blanked in the joint hash ``key_tab``) and the pair is a plain contact from then on.
    Returns (joints in contact, joints retired in this call); a caller with a pair list rebuilds it when the
    second is positive."""
    x = mo.x
    v = mo.v
    force = mo.force
    r = sp.r
    j_us = jt.us
    nact = 0
    nret = 0
    n = np.empty(3)
    vrel = np.empty(3)
    f = np.empty(3)
    us = np.empty(3)
    for k in range(jt.i.shape[0]):
        i = jt.i[k]
        j = jt.j[k]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        dn = d0 * jt.nrm[k, 0] + d1 * jt.nrm[k, 1] + d2 * jt.nrm[k, 2]
        if jt.on[k]:
            if jt.slide[k] > 2.0 * min(r[i], r[j]):
                # slid past its neighbour: lost, its shear energy released
                res[1] += 0.5 * lawrow[LAW_KS] * (j_us[k, 0] ** 2 + j_us[k, 1] ** 2 + j_us[k, 2] ** 2)
                jt.on[k] = False
                jt.init[k] = -1.0
                j_us[k, 0] = 0.0
                j_us[k, 1] = 0.0
                j_us[k, 2] = 0.0
                _blank_key(jt.key_tab, jt.key_slot, i * x.shape[0] + j)
                nret += 1
                continue
        else:
            if jt.init[k] < 0.0:
                continue  # retired: a plain contact now
            rs = r[i] + r[j]
            if d0 * d0 + d1 * d1 + d2 * d2 >= rs * rs:
                continue
            jt.on[k] = True
            jt.init[k] = abs(dn)
            jt.slide[k] = 0.0
            jt.sgn[k] = 1.0 if dn >= 0.0 else -1.0
            j_us[k, 0] = 0.0
            j_us[k, 1] = 0.0
            j_us[k, 2] = 0.0
        depth = jt.init[k] - abs(dn)
        for a in range(3):
            n[a] = jt.sgn[k] * jt.nrm[k, a]
            vrel[a] = v[j, a] - v[i, a]
            us[a] = j_us[k, a]
        vn = vrel[0] * n[0] + vrel[1] * n[1] + vrel[2] * n[2]
        meff = pair_meff(i, j, sp.m, sp.fixed, sp.kin)
        st, bnd, fn_el, ee, df, dd = point_force(lawrow[LAW_KN], lawrow[LAW_KS], jt.tan[k], 0.0, 0.0,
                                                 lawrow[LAW_ZETA], meff, depth, n, vrel, dt, us, False, f)
        res[0] += ee
        res[1] += df
        res[2] += dd
        for a in range(3):
            j_us[k, a] = us[a]
        if st == 0:
            continue  # open: no force, the pair and its reference gap stay
        jt.slide[k] += np.sqrt((vrel[0] - vn * n[0]) ** 2 + (vrel[1] - vn * n[1]) ** 2
                               + (vrel[2] - vn * n[2]) ** 2) * dt
        nact += 1
        for a in range(3):
            force[j, a] += f[a]
            force[i, a] -= f[a]
    return nact, nret


@njit(cache=True)
def integrate(mo, sp, env, dt, dt_prev, acc, x_ref):
    """Central difference of the free spheres: a kinematic sphere moves at its prescribed velocity and the work
    of the forces on it goes to acc[0]; otherwise force + gravity + body force, with viscous damping -visc v
    (v of the last half step) and local (Cundall) damping, updates its velocities (dtavg, the mean of the last
    two steps) and its position (dt). Returns (kinetic energy, potential energy, damping work, finite, the
    largest squared move since x_ref: 0 when x_ref is empty).

    One loop over plain arrays taken from the bundles once: a bundle's field read inside the loop (or a helper
    taking the bundles per sphere) costs reference counts per sphere, which made this kernel 6 x slower."""
    X, V, W, force, torque = mo.x, mo.v, mo.w, mo.force, mo.torque
    m, inertia, bforce, fixed, kin = sp.m, sp.inertia, sp.bforce, sp.fixed, sp.kin
    gravity, visc, local_damp = env.gravity, env.visc, env.local_damp
    dtavg = 0.5 * (dt + dt_prev)
    track = x_ref.shape[0] > 0
    ke = 0.0
    pe = 0.0
    d_loc = 0.0
    ok = True
    moved = 0.0
    for i in range(X.shape[0]):
        if fixed[i]:
            continue
        if kin[i]:
            acc[0] -= dt * (force[i, 0] * V[i, 0] + force[i, 1] * V[i, 1] + force[i, 2] * V[i, 2]
                            + torque[i, 0] * W[i, 0] + torque[i, 1] * W[i, 1] + torque[i, 2] * W[i, 2])
            for a in range(3):
                X[i, a] += dt * V[i, a]
        else:
            for a in range(3):
                f = force[i, a] + m[i] * gravity[a] + bforce[i, a]
                tq = torque[i, a]
                fd = 0.0  # the damping force and torque, taken from f and tq
                td = 0.0
                if visc > 0.0:
                    fd = visc * V[i, a]
                    f -= fd
                if local_damp > 0.0:
                    fl = local_damping(local_damp, f, V[i, a])
                    f -= fl
                    fd += fl
                    td = local_damping(local_damp, tq, W[i, a])
                    tq -= td
                vn_ = V[i, a] + dtavg * f / m[i]
                wn_ = W[i, a] + dtavg * tq / inertia[i]
                # their work with the mean of the half-step velocities on either side of the step (the product-form
                # kinetic energy's pairing)
                d_loc += 0.5 * dtavg * (fd * (V[i, a] + vn_) + td * (W[i, a] + wn_))
                ke += 0.5 * m[i] * V[i, a] * vn_ + 0.5 * inertia[i] * W[i, a] * wn_
                pe -= (m[i] * gravity[a] + bforce[i, a]) * X[i, a]
                V[i, a] = vn_
                W[i, a] = wn_
                X[i, a] += dt * vn_
                if not np.isfinite(X[i, a]) or not np.isfinite(vn_) or not np.isfinite(wn_):
                    ok = False
        if track:
            e0 = X[i, 0] - x_ref[i, 0]
            e1 = X[i, 1] - x_ref[i, 1]
            e2 = X[i, 2] - x_ref[i, 2]
            moved = max(moved, e0 * e0 + e1 * e1 + e2 * e2)
    return ke, pe, d_loc, ok, moved


@njit(cache=True, inline="always")
def book_energy(energy, acc, ke, pe, d_loc, res, e_bond):
    """The step's energy terms into ``energy`` (E_* columns; the last three cumulative)."""
    energy[E_KIN] = ke
    energy[E_POT] = pe - acc[0]
    energy[E_ELASTIC] = res[0] + e_bond
    energy[E_FRICTION] += res[1]
    energy[E_DAMPING] += res[2]
    energy[E_LOCAL] += d_loc


@njit(cache=True)
def clear_forces(mo):
    for i in range(mo.force.shape[0]):
        for a in range(3):
            mo.force[i, a] = 0.0
            mo.torque[i, a] = 0.0


@njit(cache=True)
def refresh_pairs(mo, sp, bonds, joints, pl, stats):
    """Rebuild the pair list when asked (pl.flag[0]); False when it does not fit (stats[ST_NEED_PAIRS])."""
    if pl.flag[0] == 0:
        return True
    npair = build_pairs(mo.x, sp, bonds, joints, pl.skin, pl.pairs)
    if npair > pl.pairs.shape[0]:
        stats[ST_NEED_PAIRS] = npair
        return False
    pl.n[0] = npair
    for i in range(mo.x.shape[0]):
        for a in range(3):
            pl.x_ref[i, a] = mo.x[i, a]
    pl.flag[0] = 0
    stats[ST_BUILDS] += 1
    return True


@njit(cache=True)
def run_spheres(nsteps, dt, dt_prev, t0, env, sp, rows, walls, bonds, joints, pl, hist, books):
    """Advance `nsteps` steps. Returns (status, steps done). See the module docstring; the bundles are
    dda/_sphere_state.py's.

    ``hist``: the contact history, double buffers (2, cap, ...), ``cur[0]`` the one holding last step's
    contacts. Pair list ``pl``: ``pairs[:n[0]]`` built at ``x_ref`` with margin ``skin``; ``flag[0] = 1`` asks
    for a rebuild (set when a sphere has moved by more than skin / 2 since, or a broken bond does not fit the
    list). ``books.acc = [work of the prescribed spheres]``; ``books.stats``: ST_* slots (bonds broken in this
    chunk); ``bonds.brk`` gets the time a bond broke. Central bonds: their sign flags are set from
    ``bonds.intact`` on entry, ``bonds.cfn`` is written in the last step of the call. ``rows`` = (PA, PB, TQ):
    the aligned rows of the sphere state for the duration of the call."""
    PA, PB, TQ = rows
    x = sp.x
    n = x.shape[0]
    stats = books.stats
    sync_central(bonds)
    njoint = joints.i.shape[0]
    cap = hist.key.shape[1]
    # sphere state in rows (copied in here and out at the end): PA (position, force: the 64 bytes a central bond
    # touches), PB (velocity, angular velocity), TQ (torque)
    for i in range(n):
        for a in range(3):
            PA[i, a] = x[i, a]
            PB[i, a] = sp.v[i, a]
            PB[i, 3 + a] = sp.w[i, a]
    mo = Motion(PA[:, 0:3], PB[:, 0:3], PB[:, 3:6], PA[:, 3:6], TQ[:, 0:3])
    res = np.zeros(3)
    half2 = 0.25 * pl.skin * pl.skin
    status = OK
    done = 0
    nbroken = 0
    t = t0
    for step in range(nsteps):
        # 1. pair list (rebuilt only when a sphere may have come within reach of a new neighbour)
        if not refresh_pairs(mo, sp, bonds, joints, pl, stats):
            status = NEED_PAIRS
            break
        hc = history_hash(hist)
        clear_forces(mo)
        res[:] = 0.0
        # 2. sphere-sphere contacts over the pair list, sphere-wall contacts
        nnew = pair_contacts(mo, sp, pl, env.lawrow, dt, hist, hc, res)
        nnew, nwc = wall_contacts(mo, sp, walls, dt, hist, hc, nnew, res)
        if nnew > cap:
            status = NEED_CAPACITY
            stats[ST_NEED] = nnew
            break
        hist.n[hc[1]] = nnew
        hist.cur[0] = hc[1]
        # smooth joints
        if njoint > 0:
            stats[ST_JOINTS], nret = _joints(dt, mo, sp, env.lawrow, joints, res)
            if nret > 0:
                pl.flag[0] = 1  # retired joints are plain contacts: into the pair list
        # 3. bonds
        e_bond, nint, nb = bond_forces(mo, sp, bonds, pl, dt, t, step == nsteps - 1, res)
        nbroken += nb
        # 4. central difference (and the largest move since the pair list was built)
        ke, pe, d_loc, ok, moved = integrate(mo, sp, env, dt, dt_prev, books.acc, pl.x_ref)
        if not moved <= half2:
            pl.flag[0] = 1
        dt_prev = dt
        t += dt
        book_energy(books.energy, books.acc, ke, pe, d_loc, res, e_bond)
        stats[ST_CONTACTS] = nnew - nwc
        stats[ST_WALL] = nwc
        stats[ST_BONDS] = nint
        done += 1
        if not ok:
            status = BLOWUP
            break
    stats[ST_BROKEN] = nbroken
    for i in range(n):
        for a in range(3):
            x[i, a] = mo.x[i, a]
            sp.v[i, a] = mo.v[i, a]
            sp.w[i, a] = mo.w[i, a]
    return status, done
