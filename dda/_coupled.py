"""numba kernels: spheres together with moving polyhedral blocks (one time loop, one time step).

Design: the block engine's step (dda/_integrate.py ``run_chunk``) is left as it is and called for one step at
a time from ``run_coupled``, a numba loop that wraps it (so the blocks keep their own broad phase, FCP
narrow phase, sleeping-free fast path and bit-identical results when no sphere is present, and the loop
never returns to Python between steps). One coupled step i:

1. world geometry of the moving blocks at x(i) (as run_chunk computes it);
2. ``sphere_forces``: hashed sphere grid (cells of the largest sphere diameter, counting sort, linear in the
   spheres), sphere-sphere contacts without an intact bond, smooth joints (dda/_spheres.py ``_joints``),
   sphere-block contacts and bonds. Sphere-block candidates come from the block engine's own grids (moving blocks, static blocks, short list of large
   blocks): each sphere looks up the cells its box covers, so the cost follows the spheres and the blocks
   near them, never spheres x blocks. A sphere touches a block at the closest point of the convex polyhedron
   (face, edge or vertex); the block contact law acts at that point; the block takes the reaction there
   (force, torque about its centroid and, for a deformable block, the strain part T^T f) in ``fext``,
   ``text``, ``qext``;
3. ``run_chunk(1 step)``: block-block contacts plus the reactions, central difference of the blocks;
4. ``sphere_update``: central difference of the spheres (the same half-step scheme).
Energy: the spheres' terms (kinetic, potential, elastic of sphere contacts and bonds, dissipated) here, the
blocks' in the block engine's array; their sum is the balance.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._broad import _hash
from ._contact import point_force
from ._deform import add_strain_force, body_point, deform_geometry, point_velocity
from ._integrate import _omega, quat_matrix, run_chunk, update_geometry
from ._spheres import (_cell_hash, _contact, _hkey, _joints, advance_sphere, bond_lookup, closest_on_polyhedron,
                       hashed_cells, pair_meff)

OK, NEED_CAPACITY, BLOWUP, NEED_BLOCK_CAPACITY = 0, 1, 2, 3


@njit(cache=True)
def _block_contact(b, j, key, depth, n, p, x, v, w, m, sstatic, lawrow, dt,
                   bpos, bvel, bquat, bangmom, bmass, binertia, bstatic, bkin, bwpres, bdof12, bstrain, bsrate, bwb,
                   old_key, old_us, htab, hmask, new_key, new_us, new_fn, new_ij, nnew,
                   force, torque, fext, text, qext, res):
    """Sphere j against block b (normal n from the block to the sphere, contact point p)."""
    us = np.zeros(3)
    h = _hkey(key, hmask)
    while htab[h] >= 0:
        s = htab[h]
        if old_key[s] == key:
            l0 = np.sqrt(old_us[s, 0] ** 2 + old_us[s, 1] ** 2 + old_us[s, 2] ** 2)
            un = old_us[s, 0] * n[0] + old_us[s, 1] * n[1] + old_us[s, 2] * n[2]
            for a in range(3):
                us[a] = old_us[s, a] - un * n[a]
            l1 = np.sqrt(us[0] ** 2 + us[1] ** 2 + us[2] ** 2)
            if l1 > 0.0:
                for a in range(3):
                    us[a] *= l0 / l1
            break
        h = (h + 1) & hmask
    rj0 = p[0] - x[j, 0]
    rj1 = p[1] - x[j, 1]
    rj2 = p[2] - x[j, 2]
    vrel = np.empty(3)
    vrel[0] = v[j, 0] + w[j, 1] * rj2 - w[j, 2] * rj1
    vrel[1] = v[j, 1] + w[j, 2] * rj0 - w[j, 0] * rj2
    vrel[2] = v[j, 2] + w[j, 0] * rj1 - w[j, 1] * rj0
    R = np.empty((3, 3))
    wb_ = np.empty(3)
    X = np.empty(3)
    rb0 = p[0] - bpos[b, 0]
    rb1 = p[1] - bpos[b, 1]
    rb2 = p[2] - bpos[b, 2]
    if not bstatic[b]:
        for a in range(3):
            vrel[a] -= bvel[b, a]
        if bdof12[b]:
            quat_matrix(bquat[b], R)
            point_velocity(b, p, bpos, R, bstrain, bsrate, bwb, wb_)
            for a in range(3):
                vrel[a] -= wb_[a]
        else:
            _omega(b, bkin, bstatic, bwpres, bquat, binertia, bangmom, R, wb_)
            vrel[0] -= wb_[1] * rb2 - wb_[2] * rb1
            vrel[1] -= wb_[2] * rb0 - wb_[0] * rb2
            vrel[2] -= wb_[0] * rb1 - wb_[1] * rb0
    bs = bstatic[b] or bkin[b]
    if bs and not sstatic[j]:
        meff = m[j]
    elif sstatic[j] and not bs:
        meff = bmass[b]
    else:
        meff = m[j] * bmass[b] / (m[j] + bmass[b])
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
    if not bstatic[b]:
        for a in range(3):
            fext[b, a] -= f[a]
        text[b, 0] -= rb1 * f[2] - rb2 * f[1]
        text[b, 1] -= rb2 * f[0] - rb0 * f[2]
        text[b, 2] -= rb0 * f[1] - rb1 * f[0]
        if bdof12[b]:
            quat_matrix(bquat[b], R)
            body_point(b, p, bpos, R, bstrain, X)
            add_strain_force(b, X, R, f, -1.0, qext)
    if nnew < new_key.shape[0]:
        new_key[nnew] = key
        new_fn[nnew] = fn_el
        new_ij[nnew, 0] = -1 - b
        new_ij[nnew, 1] = j
        for a in range(3):
            new_us[nnew, a] = us[a]
    return nnew + 1


@njit(cache=True)
def _bonds(dt, t, x, v, w, r, m, fixed, kin, bi, bj, b_len0, b_kn, b_ks, b_ft, b_fs, b_zeta, b_us, b_intact, b_fn,
           b_break, force, torque, res, cnt):
    """Bond springs (as dda/_spheres.py). Returns their elastic energy; cnt = [intact, broken]."""
    e_bond = 0.0
    for k in range(bi.shape[0]):
        if not b_intact[k]:
            continue
        i = bi[k]
        j = bj[k]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        nx = d0 / dl
        ny = d1 / dl
        nz = d2 / dl
        a0 = dl * r[i] / (r[i] + r[j])
        ri0 = a0 * nx
        ri1 = a0 * ny
        ri2 = a0 * nz
        rj0 = ri0 - d0
        rj1 = ri1 - d1
        rj2 = ri2 - d2
        vr0 = v[j, 0] + w[j, 1] * rj2 - w[j, 2] * rj1 - v[i, 0] - (w[i, 1] * ri2 - w[i, 2] * ri1)
        vr1 = v[j, 1] + w[j, 2] * rj0 - w[j, 0] * rj2 - v[i, 1] - (w[i, 2] * ri0 - w[i, 0] * ri2)
        vr2 = v[j, 2] + w[j, 0] * rj1 - w[j, 1] * rj0 - v[i, 2] - (w[i, 0] * ri1 - w[i, 1] * ri0)
        vn = vr0 * nx + vr1 * ny + vr2 * nz
        u0 = b_us[k, 0]
        u1 = b_us[k, 1]
        u2 = b_us[k, 2]
        l0 = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        un = u0 * nx + u1 * ny + u2 * nz
        u0 -= un * nx
        u1 -= un * ny
        u2 -= un * nz
        l1 = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if l1 > 0.0:
            u0 *= l0 / l1
            u1 *= l0 / l1
            u2 *= l0 / l1
        u0 += (vr0 - vn * nx) * dt
        u1 += (vr1 - vn * ny) * dt
        u2 += (vr2 - vn * nz) * dt
        stretch = dl - b_len0[k]
        fn = b_kn[k] * stretch
        fs = b_ks[k] * np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if fn > b_ft[k] or fs > b_fs[k]:
            b_intact[k] = False
            b_break[k] = t
            b_fn[k] = 0.0
            res[1] += 0.5 * b_kn[k] * stretch * stretch + 0.5 * b_ks[k] * (u0 * u0 + u1 * u1 + u2 * u2)
            b_us[k, 0] = 0.0
            b_us[k, 1] = 0.0
            b_us[k, 2] = 0.0
            cnt[1] += 1
            continue
        cnt[0] += 1
        b_us[k, 0] = u0
        b_us[k, 1] = u1
        b_us[k, 2] = u2
        b_fn[k] = fn
        e_bond += 0.5 * b_kn[k] * stretch * stretch + 0.5 * b_ks[k] * (u0 * u0 + u1 * u1 + u2 * u2)
        cdn = 0.0
        cds = 0.0
        if b_zeta[k] > 0.0:
            meff = pair_meff(i, j, m, fixed, kin)
            cdn = 2.0 * b_zeta[k] * np.sqrt(b_kn[k] * meff)
            cds = 2.0 * b_zeta[k] * np.sqrt(b_ks[k] * meff)
            res[2] += (cdn * vn * vn + cds * ((vr0 - vn * nx) ** 2 + (vr1 - vn * ny) ** 2
                                              + (vr2 - vn * nz) ** 2)) * dt
        f0 = -(fn + cdn * vn) * nx - b_ks[k] * u0 - cds * (vr0 - vn * nx)
        f1 = -(fn + cdn * vn) * ny - b_ks[k] * u1 - cds * (vr1 - vn * ny)
        f2 = -(fn + cdn * vn) * nz - b_ks[k] * u2 - cds * (vr2 - vn * nz)
        force[j, 0] += f0
        force[j, 1] += f1
        force[j, 2] += f2
        torque[j, 0] += rj1 * f2 - rj2 * f1
        torque[j, 1] += rj2 * f0 - rj0 * f2
        torque[j, 2] += rj0 * f1 - rj1 * f0
        force[i, 0] -= f0
        force[i, 1] -= f1
        force[i, 2] -= f2
        torque[i, 0] -= ri1 * f2 - ri2 * f1
        torque[i, 1] -= ri2 * f0 - ri0 * f2
        torque[i, 2] -= ri0 * f1 - ri1 * f0
    return e_bond


@njit(cache=True)
def sphere_forces(dt, t, x, v, w, r, m, fixed, kin, lawrow, blawrow,
                  bi, bj, b_len0, b_kn, b_ks, b_ft, b_fs, b_zeta, b_us, b_intact, b_fn, b_break, bkey_tab, bkey_slot,
                  ji, jj, j_nrm, j_tan, j_on, j_init, j_slide, j_us, j_sgn, jkey_tab, jkey_slot,
                  active, bpos, bvel, bquat, bangmom, bmass, binertia, bfixed, bkin, bwpres, bdof12, bstrain, bsrate,
                  bwb, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb, fvs, fv,
                  S_b, margin, mstart, mentries, fstart, fentries, large_list, bstamp, btag,
                  cur, c_n, c_key, c_us, c_fn, c_ij, htab, force, torque, fext, text, qext, res, stats):
    """Forces of one step at the current state (see the module docstring). res = [elastic, friction, damping,
    bond energy]; stats = [sphere contacts, block contacts, intact bonds, broken (cumulative), pairs needed].
    Returns OK or NEED_CAPACITY (then nothing persistent changed)."""
    n = x.shape[0]
    nb = bpos.shape[0]
    cap = c_key.shape[1]
    R = np.empty((3, 3))
    for k in range(active.shape[0]):
        i = active[k]
        if bdof12[i]:
            quat_matrix(bquat[i], R)
            deform_geometry(i, bpos, R, bstrain, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb)
        else:
            update_geometry(i, bpos, bquat, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb)
        for a in range(3):
            fext[i, a] = 0.0
            text[i, a] = 0.0
        for a in range(6):
            qext[i, a] = 0.0
    sstatic = np.empty(n, np.bool_)
    for i in range(n):
        sstatic[i] = fixed[i] or kin[i]
    bstatic = bfixed  # no sleeping in coupled runs
    for i in range(n):
        for a in range(3):
            force[i, a] = 0.0
            torque[i, a] = 0.0
    for a in range(4):
        res[a] = 0.0
    # sphere grid (counting sort into hashed buckets)
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    S = 2.0 * rmax * 1.0001
    cmask, count, entries, cix = hashed_cells(x, S)
    seen = np.empty(27, np.int64)
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
    bmask = bkey_tab.shape[0] - 1
    nbond = bi.shape[0]
    jmask = jkey_tab.shape[0] - 1
    njoint = ji.shape[0]
    nnew = 0
    rs3 = np.zeros(3)
    # sphere-sphere
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
                            kb = bond_lookup(bkey_tab, bkey_slot, key, bmask)
                            if kb >= 0 and b_intact[kb]:
                                continue
                        if njoint > 0 and bond_lookup(jkey_tab, jkey_slot, key, jmask) >= 0:
                            continue  # a smooth joint (below)
                        dl = np.sqrt(dd)
                        depth = rs - dl
                        nx = d0 / dl
                        ny = d1 / dl
                        nz = d2 / dl
                        a0 = r[i] - 0.5 * depth
                        nnew = _contact(i, j, False, key, depth, nx, ny, nz, x[i, 0] + a0 * nx,
                                        x[i, 1] + a0 * ny, x[i, 2] + a0 * nz, x, v, w, m, fixed, kin, lawrow,
                                        dt, c_key[old], c_us[old], htab, hmask, nold, c_key[new], c_us[new],
                                        c_fn[new], c_ij[new], nnew, force, torque, rs3)
    nss = nnew
    # sphere-block: candidates from the block grids (moving, static, large list)
    mmask = mstart.shape[0] - 2
    fmask = fstart.shape[0] - 2
    c = np.empty(3)
    cpt = np.empty(3)
    nrm = np.empty(3)
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for j in range(n):
        for a in range(3):
            c[a] = x[j, a]
            lo[a] = np.int64(np.floor((x[j, a] - r[j] - margin) / S_b))
            hi[a] = np.int64(np.floor((x[j, a] + r[j] + margin) / S_b))
        btag[0] += 1
        tg = btag[0]
        for pass_ in range(3):
            if pass_ == 1 and sstatic[j]:
                continue  # static spheres meet only moving blocks
            if pass_ < 2:
                ncell = (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1)
            else:
                ncell = 1
            for ci in range(ncell):
                if pass_ < 2:
                    iz = lo[2] + ci % (hi[2] - lo[2] + 1)
                    rest = ci // (hi[2] - lo[2] + 1)
                    iy = lo[1] + rest % (hi[1] - lo[1] + 1)
                    ix = lo[0] + rest // (hi[1] - lo[1] + 1)
                    if pass_ == 0:
                        hh = _hash(ix, iy, iz, mmask)
                        e0 = mstart[hh]
                        e1 = mstart[hh + 1]
                    else:
                        if fentries.shape[0] == 0:
                            continue
                        hh = _hash(ix, iy, iz, fmask)
                        e0 = fstart[hh]
                        e1 = fstart[hh + 1]
                else:
                    e0 = 0
                    e1 = large_list.shape[0]
                for e in range(e0, e1):
                    if pass_ == 0:
                        bb = mentries[e]
                    elif pass_ == 1:
                        bb = fentries[e]
                    else:
                        bb = large_list[e]
                    if bstamp[bb] == tg:
                        continue
                    bstamp[bb] = tg
                    if sstatic[j] and (bstatic[bb] or bkin[bb]):
                        continue
                    if (c[0] + r[j] < aabb[bb, 0] or c[0] - r[j] > aabb[bb, 3] or c[1] + r[j] < aabb[bb, 1]
                            or c[1] - r[j] > aabb[bb, 4] or c[2] + r[j] < aabb[bb, 2] or c[2] - r[j] > aabb[bb, 5]):
                        continue
                    sd = closest_on_polyhedron(c, fvs, fv, fs[bb], fs[bb + 1], vert, fnw, fdw, cpt)
                    if sd >= r[j]:
                        continue
                    if sd > 1e-12 * r[j]:
                        for a in range(3):
                            nrm[a] = (c[a] - cpt[a]) / sd
                    else:
                        best = -1e300
                        fb = fs[bb]
                        for f in range(fs[bb], fs[bb + 1]):
                            s_ = fnw[f, 0] * c[0] + fnw[f, 1] * c[1] + fnw[f, 2] * c[2] - fdw[f]
                            if s_ > best:
                                best = s_
                                fb = f
                        for a in range(3):
                            nrm[a] = fnw[fb, a]
                    key = -1 - (j * nb + bb)
                    nnew = _block_contact(bb, j, key, r[j] - sd, nrm, cpt, x, v, w, m, sstatic, blawrow[bb], dt,
                                          bpos, bvel, bquat, bangmom, bmass, binertia, bstatic, bkin, bwpres,
                                          bdof12, bstrain, bsrate, bwb, c_key[old], c_us[old], htab, hmask,
                                          c_key[new], c_us[new], c_fn[new], c_ij[new], nnew, force, torque,
                                          fext, text, qext, rs3)
    if nnew > cap:
        stats[4] = nnew
        return NEED_CAPACITY
    c_n[new] = nnew
    cur[0] = new
    if njoint > 0:
        # a retired joint's key is blanked: the search above finds it as a plain contact from the next step
        stats[6], _ = _joints(dt, x, v, r, m, fixed, kin, lawrow, ji, jj, j_nrm, j_tan, j_on, j_init, j_slide,
                              j_us, j_sgn, jkey_tab, jkey_slot, force, rs3)
    res[0] = rs3[0]
    res[1] = rs3[1]
    res[2] = rs3[2]
    cnt = np.zeros(2, np.int64)
    res[3] = _bonds(dt, t, x, v, w, r, m, fixed, kin, bi, bj, b_len0, b_kn, b_ks, b_ft, b_fs, b_zeta, b_us,
                    b_intact, b_fn, b_break, force, torque, res, cnt)
    stats[0] = nss
    stats[1] = nnew - nss
    stats[2] = cnt[0]
    stats[3] += cnt[1]
    return OK


@njit(cache=True)
def sphere_update(dt, dt_prev, gravity, local_damp, visc, x, v, w, m, inertia, fixed, kin, bforce, force, torque,
                  acc, energy, res):
    """Central difference of the spheres (as dda/_spheres.py) and their energy terms. Returns False on a
    non-finite state."""
    n = x.shape[0]
    dtavg = 0.5 * (dt + dt_prev)
    ke = 0.0
    pe = 0.0
    d_loc = 0.0
    ok = True
    for i in range(n):
        if fixed[i]:
            continue
        ke, pe, d_loc, step_ok = advance_sphere(i, dt, dtavg, gravity, local_damp, visc, x, v, w, m, inertia, kin,
                                                bforce, force, torque, acc, ke, pe, d_loc)
        ok &= step_ok
    energy[0] = ke
    energy[1] = pe - acc[0]
    energy[2] = res[0] + res[3]
    energy[3] += res[1]
    energy[4] += res[2]
    energy[5] += d_loc
    return ok


@njit(cache=True)
def run_coupled(nsteps, resume, dt, dt_prev, t0, gravity, local_damp, visc, first_step,
                x, v, w, r, m, sinertia, sfixed, skin, sbforce, lawrow, blawrow,
                bi, bj, b_len0, b_kn, b_ks, b_ft, b_fs, b_zeta, b_us, b_intact, b_fn, b_break, bkey_tab, bkey_slot,
                ji, jj, j_nrm, j_tan, j_on, j_init, j_slide, j_us, j_sgn, jkey_tab, jkey_slot,
                scur, sc_n, sc_key, sc_us, sc_fn, sc_ij, shtab, sforce, storque, sacc, senergy, sres, sstats,
                fvs, fv, bstamp, btag,
                pos, vel, quat, angmom, mass, inertia, fixed, material, active,
                movable, kin, wpres, bforce, pl_start, pl_r, pl_f, asleep, calm, pe_sl, sleep_par, acc,
                vs, fs, es, vloc, nloc, dloc, vert, fnw, fdw, aabb, size_b,
                he_origin, he_next, he_pair, he_face, vert_he, edge_he,
                S, cellbox, large, mstart, mentries, fstart, fentries, large_list, stamp, tag, gap, margin,
                lawtab, keep_gap,
                cur, c_n_pair, c_key, c_a, c_b, c_nrm, c_np, c_pid, c_us, c_state, c_bond, c_pos, c_fn, c_depth,
                htab, pa, pb, force, torque, energy, stats,
                dof12, strain, srate, wb, qs, m9, m9inv, vc, fext, text, qext):
    """`nsteps` coupled steps (module docstring). `resume`: the first step's sphere forces are already in
    sforce / fext (a NEED_BLOCK_CAPACITY return before). Returns (status, steps done, fcp iterations, and
    run_chunk's grids and lists)."""
    status = OK
    done = 0
    fit = 0
    for step in range(nsteps):
        t = t0 + done * dt
        if not (resume and step == 0):
            st = sphere_forces(dt, t, x, v, w, r, m, sfixed, skin, lawrow, blawrow,
                               bi, bj, b_len0, b_kn, b_ks, b_ft, b_fs, b_zeta, b_us, b_intact, b_fn, b_break,
                               bkey_tab, bkey_slot, ji, jj, j_nrm, j_tan, j_on, j_init, j_slide, j_us, j_sgn,
                               jkey_tab, jkey_slot, active, pos, vel, quat, angmom, mass, inertia, fixed, kin, wpres,
                               dof12, strain, srate, wb, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb, fvs, fv,
                               S, margin, mstart, mentries, fstart, fentries, large_list, bstamp, btag,
                               scur, sc_n, sc_key, sc_us, sc_fn, sc_ij, shtab, sforce, storque, fext, text, qext,
                               sres, sstats)
            if st != OK:
                status = NEED_CAPACITY
                break
        (st, d, mstart, mentries, pa, pb, large_list, active, fstart, fentries) = run_chunk(
            1, dt, dt_prev, gravity, local_damp, first_step,
            pos, vel, quat, angmom, mass, inertia, fixed, material, active,
            movable, kin, wpres, bforce, pl_start, pl_r, pl_f, asleep, calm, pe_sl, sleep_par, acc,
            vs, fs, es, vloc, nloc, dloc, vert, fnw, fdw, aabb, size_b,
            he_origin, he_next, he_pair, he_face, vert_he, edge_he,
            S, cellbox, large, mstart, mentries, fstart, fentries, large_list, stamp, tag, gap, margin,
            lawtab, keep_gap,
            cur, c_n_pair, c_key, c_a, c_b, c_nrm, c_np, c_pid, c_us, c_state, c_bond, c_pos, c_fn, c_depth,
            htab, pa, pb, force, torque, energy, stats,
            dof12, strain, srate, wb, qs, m9, m9inv, vc, fext, text, qext)
        fit += np.int64(stats[3])
        if st == NEED_CAPACITY:
            status = NEED_BLOCK_CAPACITY
            break
        resume = False
        first_step = False
        ok = sphere_update(dt, dt_prev, gravity, local_damp, visc, x, v, w, m, sinertia, sfixed, skin, sbforce,
                           sforce, storque, sacc, senergy, sres)
        dt_prev = dt
        done += 1
        if st == BLOWUP or not ok:
            status = BLOWUP
            break
    return status, done, fit, mstart, mentries, pa, pb, large_list, active, fstart, fentries
