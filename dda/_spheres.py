"""numba kernels: spheres and bonds (the bonded-sphere models of sgim) in the explicit time loop.

Bodies: spheres with 6 DOF (centre velocity ``v`` and angular velocity ``w``; the inertia of a solid sphere,
2/5 m r^2, is isotropic, so no orientation is needed). Fixed spheres never move; prescribed spheres move at
their given velocity whatever the forces. Fixed convex polyhedra (walls: a floor, an incline, a box) are given
by their world vertices, face planes and face vertex loops.

One step (central difference exactly as the block engine, dt(0) = 0 so the first step is a half step):

1. grid: cubic cells of the largest sphere diameter, hashed into 2^k buckets (counting sort, rebuilt each step:
   cost linear in the sphere count); each sphere looks at the 27 cells around it, pairs i < j;
2. sphere-sphere contacts (overlap r_i + r_j - |x_j - x_i|) of pairs without an intact bond, sphere-wall
   contacts (closest point of the convex polyhedron: a face, an edge or a vertex; a centre inside the wall
   bears on the face it is nearest to), both with the block engine's contact law (dda/_contact.py) at one
   contact point; the shear history of each contact is kept between steps (hash on the pair key);
3. bonds: a normal spring kn_b on the change of the centre distance from its initial value (tension and
   compression) and a shear spring ks_b on the incremental tangential displacement at the bond point; a bond
   breaks when its tensile force would exceed its tensile strength or its shear force its shear strength;
   the energy left in its springs is released (counted as dissipated); the step it broke is recorded;
4. central difference for the free spheres (Cundall's local damping as an option).
Energy = [kinetic (product form), potential, elastic (contacts and bonds), friction (+ released), damping,
local damping]; the last three cumulative.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._contact import point_force

OK, NEED_CAPACITY, BLOWUP = 0, 1, 2


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
        si = fixed[i] or kin[i]
        sj = fixed[j] or kin[j]
        if si and not sj:
            meff = m[j]
        elif sj and not si:
            meff = m[i]
        else:
            meff = m[i] * m[j] / (m[i] + m[j])
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
def run_spheres(nsteps, dt, dt_prev, gravity, local_damp, t0,
                x, v, w, r, m, inertia, fixed, kin, bforce, lawrow, wall_lawrow,
                bi, bj, b_len0, b_kn, b_ks, b_ft, b_fs, b_zeta, b_us, b_intact, b_fn, b_break, bkey_tab, bkey_slot,
                wvert, wfn, wfd, wfv_start, wfv, wface_start, waabb,
                cur, c_n, c_key, c_us, c_fn, c_ij, htab, energy, acc, stats):
    """Advance `nsteps` steps. Returns (status, steps done). See the module docstring.

    Contact buffers c_* are (2, cap, ...) double buffers, ``cur[0]`` the one holding last step's contacts.
    ``acc = [work of the prescribed spheres]``; ``stats = [contacts, wall contacts, intact bonds, broken this
    chunk, pairs needed]``; ``b_break`` gets the time a bond broke."""
    n = x.shape[0]
    nbond = bi.shape[0]
    nwall = waabb.shape[0]
    cap = c_key.shape[1]
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    res = np.zeros(3)
    cpt = np.empty(3)
    c = np.empty(3)
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    S = 2.0 * rmax * 1.0001
    nbk = 16
    while nbk < 2 * n:
        nbk *= 2
    cmask = nbk - 1
    count = np.zeros(nbk + 1, np.int64)
    entries = np.empty(n, np.int64)
    fill = np.empty(nbk, np.int64)
    cell = np.empty(n, np.int64)
    cix = np.empty((n, 3), np.int64)
    seen = np.empty(27, np.int64)
    bmask = bkey_tab.shape[0] - 1
    status = OK
    done = 0
    nbroken = 0
    t = t0
    for step in range(nsteps):
        # 1. grid (counting sort into hashed buckets)
        count[:] = 0
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
        # 2. sphere-sphere contacts
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
                            if j <= i:
                                continue
                            if (fixed[i] or kin[i]) and (fixed[j] or kin[j]):
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
                            dl = np.sqrt(dd)
                            depth = rs - dl
                            nx = d0 / dl
                            ny = d1 / dl
                            nz = d2 / dl
                            a0 = r[i] - 0.5 * depth
                            nnew = _contact(i, j, False, key, depth, nx, ny, nz, x[i, 0] + a0 * nx,
                                            x[i, 1] + a0 * ny, x[i, 2] + a0 * nz, x, v, w, m, fixed, kin, lawrow,
                                            dt, c_key[old], c_us[old], htab, hmask, nold, c_key[new], c_us[new],
                                            c_fn[new], c_ij[new], nnew, force, torque, res)
        # sphere-wall contacts (walls are few: each tested by its box)
        for j in range(n):
            if fixed[j] or kin[j]:
                continue
            for k in range(nwall):
                if (x[j, 0] + r[j] < waabb[k, 0] or x[j, 0] - r[j] > waabb[k, 3] or x[j, 1] + r[j] < waabb[k, 1]
                        or x[j, 1] - r[j] > waabb[k, 4] or x[j, 2] + r[j] < waabb[k, 2]
                        or x[j, 2] - r[j] > waabb[k, 5]):
                    continue
                for a in range(3):
                    c[a] = x[j, a]
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
                nnew = _contact(k, j, True, key, depth, nx, ny, nz, cpt[0], cpt[1], cpt[2], x, v, w, m, fixed,
                                kin, wall_lawrow[k], dt, c_key[old], c_us[old], htab, hmask, nold, c_key[new],
                                c_us[new], c_fn[new], c_ij[new], nnew, force, torque, res)
                nwc += nnew - nc0
        if nnew > cap:
            status = NEED_CAPACITY
            stats[4] = nnew
            break
        c_n[new] = nnew
        cur[0] = new
        # 3. bonds
        e_bond = 0.0
        nint = 0
        for k in range(nbond):
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
            # bond point: between the surfaces, in proportion to the radii
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
            # shear displacement: onto the current tangent plane (length kept), then the increment
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
            fn = b_kn[k] * stretch  # tension > 0
            fs = b_ks[k] * np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            if fn > b_ft[k] or fs > b_fs[k]:
                # breaks: its spring energy (last step's) leaves the system
                b_intact[k] = False
                b_break[k] = t
                b_fn[k] = 0.0
                res[1] += 0.5 * b_kn[k] * stretch * stretch + 0.5 * b_ks[k] * (u0 * u0 + u1 * u1 + u2 * u2)
                b_us[k, 0] = 0.0
                b_us[k, 1] = 0.0
                b_us[k, 2] = 0.0
                nbroken += 1
                continue
            nint += 1
            b_us[k, 0] = u0
            b_us[k, 1] = u1
            b_us[k, 2] = u2
            b_fn[k] = fn
            e_bond += 0.5 * b_kn[k] * stretch * stretch + 0.5 * b_ks[k] * (u0 * u0 + u1 * u1 + u2 * u2)
            # force on j: -fn n - ks u (+ viscous damping on the normal and shear relative velocity)
            cdn = 0.0
            if b_zeta[k] > 0.0:
                si = fixed[i] or kin[i]
                sj = fixed[j] or kin[j]
                meff = m[j] if si and not sj else (m[i] if sj and not si else m[i] * m[j] / (m[i] + m[j]))
                cdn = 2.0 * b_zeta[k] * np.sqrt(b_kn[k] * meff)
                cds = 2.0 * b_zeta[k] * np.sqrt(b_ks[k] * meff)
                res[2] += (cdn * vn * vn + cds * ((vr0 - vn * nx) ** 2 + (vr1 - vn * ny) ** 2
                                                  + (vr2 - vn * nz) ** 2)) * dt
            else:
                cds = 0.0
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
        # 4. central difference
        dtavg = 0.5 * (dt + dt_prev)
        ke = 0.0
        pe = 0.0
        d_loc = 0.0
        blown = False
        for i in range(n):
            if fixed[i]:
                continue
            if kin[i]:
                acc[0] -= dt * (force[i, 0] * v[i, 0] + force[i, 1] * v[i, 1] + force[i, 2] * v[i, 2]
                                + torque[i, 0] * w[i, 0] + torque[i, 1] * w[i, 1] + torque[i, 2] * w[i, 2])
                for a in range(3):
                    x[i, a] += dt * v[i, a]
                continue
            for a in range(3):
                f = force[i, a] + m[i] * gravity[a] + bforce[i, a]
                tq = torque[i, a]
                if local_damp > 0.0:
                    if v[i, a] != 0.0:
                        fd = local_damp * abs(f) * (1.0 if v[i, a] > 0 else -1.0)
                        f -= fd
                        d_loc += fd * v[i, a] * dtavg
                    if w[i, a] != 0.0:
                        td = local_damp * abs(tq) * (1.0 if w[i, a] > 0 else -1.0)
                        tq -= td
                        d_loc += td * w[i, a] * dtavg
                vn_ = v[i, a] + dtavg * f / m[i]
                wn_ = w[i, a] + dtavg * tq / inertia[i]
                ke += 0.5 * m[i] * v[i, a] * vn_ + 0.5 * inertia[i] * w[i, a] * wn_
                pe -= (m[i] * gravity[a] + bforce[i, a]) * x[i, a]
                v[i, a] = vn_
                w[i, a] = wn_
                x[i, a] += dt * vn_
                if not np.isfinite(x[i, a]) or not np.isfinite(vn_) or not np.isfinite(wn_):
                    blown = True
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
    return status, done
