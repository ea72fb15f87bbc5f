"""numba kernel: the explicit time loop (central difference) for chunks of steps.

One step i, for the moving (active) blocks only:

1. world vertices, face planes and bounding boxes from the pose (x_i, q_i); blocks whose box left their
   cells are re-mapped (the moving-block grid is rebuilt only then);
2. candidate pairs from the grid; the cached common plane of the pair is checked first (a positive gap along
   it proves the blocks apart, so the FCP search runs only for pairs that may touch); contact points; law;
3. central difference exactly as the explicit 3D-DDA paper gives it:
       v(i+1/2) = v(i-1/2) + 0.5 (dt(i+1) + dt(i)) a(i),   x(i+1) = x(i) + dt(i+1) v(i+1/2);
   rotations: the world angular momentum L is advanced the same way with the torque (dL/dt = T holds in the
   world frame, so the gyroscopic term needs no separate treatment); the half-step angular velocity
   w = R I^-1 R^T L is taken at the mid-step orientation (one predictor) and the quaternion is turned by
   exp(w dt).
Energy: kinetic energy at step i in the product form 1/2 m v(i-1/2).v(i+1/2) (conserved exactly by the
leapfrog for a linear spring), gravitational potential, elastic contact energy, and the cumulative work
dissipated by friction, contact damping and local damping.

Contacts are kept in two buffers (last step's and this step's); a hash table on the pair key finds last
step's common plane and the shear history of each contact point (matched by the point's feature id).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._broad import build_grid, buckets_for, find_pairs, inside_cells, map_cells, n_cells
from ._contact import point_force
from ._deform import add_strain_force, body_point, deform_geometry, deform_step, point_velocity
from ._fcp import MAXP, contact_points, fcp, gap_along, polygon_area, sat_search

OK, NEED_CAPACITY, BLOWUP = 0, 1, 2


@njit(cache=True)
def quat_matrix(q, R):
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True)
def update_geometry(i, pos, quat, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb):
    R = np.empty((3, 3))
    quat_matrix(quat[i], R)
    for a in range(3):
        aabb[i, a] = 1e300
        aabb[i, 3 + a] = -1e300
    for v in range(vs[i], vs[i + 1]):
        for a in range(3):
            x = pos[i, a] + R[a, 0] * vloc[v, 0] + R[a, 1] * vloc[v, 1] + R[a, 2] * vloc[v, 2]
            vert[v, a] = x
            if x < aabb[i, a]:
                aabb[i, a] = x
            if x > aabb[i, 3 + a]:
                aabb[i, 3 + a] = x
    for f in range(fs[i], fs[i + 1]):
        d = dloc[f]
        for a in range(3):
            nn = R[a, 0] * nloc[f, 0] + R[a, 1] * nloc[f, 1] + R[a, 2] * nloc[f, 2]
            fnw[f, a] = nn
            d += nn * pos[i, a]
        fdw[f] = d


@njit(cache=True)
def _ang_vel(R, inertia_i, L, out):
    # w = R I^-1 R^T L
    b0 = R[0, 0] * L[0] + R[1, 0] * L[1] + R[2, 0] * L[2]
    b1 = R[0, 1] * L[0] + R[1, 1] * L[1] + R[2, 1] * L[2]
    b2 = R[0, 2] * L[0] + R[1, 2] * L[1] + R[2, 2] * L[2]
    b0 /= inertia_i[0]
    b1 /= inertia_i[1]
    b2 /= inertia_i[2]
    for a in range(3):
        out[a] = R[a, 0] * b0 + R[a, 1] * b1 + R[a, 2] * b2


@njit(cache=True)
def _turn(q, w, h, out):
    """out = exp(w h) * q (w in the world frame), normalised."""
    wl = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    th = wl * h
    if wl > 0.0:
        s = np.sin(0.5 * th) / wl
        c = np.cos(0.5 * th)
    else:
        s = 0.5 * h
        c = 1.0
    p0, p1, p2, p3 = c, s * w[0], s * w[1], s * w[2]
    o0 = p0 * q[0] - p1 * q[1] - p2 * q[2] - p3 * q[3]
    o1 = p0 * q[1] + p1 * q[0] + p2 * q[3] - p3 * q[2]
    o2 = p0 * q[2] - p1 * q[3] + p2 * q[0] + p3 * q[1]
    o3 = p0 * q[3] + p1 * q[2] - p2 * q[1] + p3 * q[0]
    ln = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    out[0] = o0 / ln
    out[1] = o1 / ln
    out[2] = o2 / ln
    out[3] = o3 / ln


@njit(cache=True)
def _hash_key(key, mask):
    h = key * np.int64(0x9E3779B97F4A7C15 & 0x7FFFFFFFFFFFFFFF)
    h ^= h >> 29
    return h & mask


@njit(cache=True)
def _released(c_np, c_us, old, slot, matched, ks):
    """Shear-spring energy of last step's points of this pair that have no successor (they opened)."""
    if slot < 0:
        return 0.0
    e = 0.0
    for r in range(c_np[old, slot]):
        if not matched[r]:
            e += 0.5 * ks * (c_us[old, slot, r, 0] ** 2 + c_us[old, slot, r, 1] ** 2 + c_us[old, slot, r, 2] ** 2)
    return e


@njit(cache=True)
def _omega(j, kin, static, wpres, quat, inertia, angmom, R, out):
    """World angular velocity of body j (prescribed, zero when fixed or asleep, else R I^-1 R^T L)."""
    if kin[j]:
        for a in range(3):
            out[a] = wpres[j, a]
    elif static[j]:
        for a in range(3):
            out[a] = 0.0
    else:
        quat_matrix(quat[j], R)
        _ang_vel(R, inertia[j], angmom[j], out)


@njit(cache=True)
def _load_potential(i, pos, quat, mass, gravity, bforce, pl_start, pl_r, pl_f):
    """-(m g + F_body).x - sum F_p.(x + R r_p): potential of gravity and the constant loads of block i."""
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
def run_chunk(nsteps, dt, dt_prev, gravity, local_damp, first_step,
              pos, vel, quat, angmom, mass, inertia, fixed, material, active,
              movable, kin, wpres, bforce, pl_start, pl_r, pl_f, asleep, calm, pe_sl, sleep_par, acc,
              vs, fs, es, vloc, nloc, dloc, vert, fnw, fdw, aabb, size_b,
              he_origin, he_next, he_pair, he_face, vert_he, edge_he,
              S, cellbox, large, mstart, mentries, fstart, fentries, large_list, stamp, tag, gap, margin,
              lawtab, keep_gap,
              cur, c_n_pair, c_key, c_a, c_b, c_nrm, c_np, c_pid, c_us, c_state, c_bond, c_pos, c_fn, c_depth,
              htab, pa, pb, force, torque, energy, stats,
              dof12, strain, srate, wb, qs, m9, m9inv, vc, fext, text, qext):
    """Advance `nsteps` steps. energy = [KE, PE, elastic, fric, damp, local] (last three cumulative).

    stats = [steps done, status, pairs needed, fcp iterations, max depth, contacts, points, sliding points,
    candidate pairs, sat searches, awake blocks].

    Loads and prescribed motion: ``kin[i]`` blocks move at their velocity ``vel[i]`` and world angular velocity
    ``wpres[i]`` whatever the forces (their contact forces do work counted in ``acc[0]``); ``bforce[i]`` is a
    constant force at the centroid; point loads of block i are rows ``pl_start[i]:pl_start[i+1]`` of ``pl_f``
    (world force) at the body-frame offset ``pl_r`` from the centroid. Their potential -F.x enters ``energy[1]``
    with gravity's, minus the cumulative work of the prescribed blocks ``acc[0]``.

    Sleeping (``sleep_par = [on, velocity, acceleration, steps]``): a free block whose speed (centroid plus
    angular speed times its size) and acceleration stay below the thresholds for ``steps`` steps falls asleep
    when every block touching it is fixed, asleep or itself calm that long; a sleeping block is neither
    integrated nor searched for contacts (its contacts with other resting blocks are carried over unchanged, so
    shear history and elastic energy are kept); it wakes the step after a block that is not calm touches it.
    ``acc[1]`` holds the potential energy of the sleeping blocks (``pe_sl`` per block).
    Deformable blocks (``dof12[i]``, see dda/_deform.py): body-frame ``strain`` / ``srate`` (strain rates) and
    ``wb`` (angular velocity) replace ``angmom``; ``qs`` collects the strain part of T^T f, ``m9`` / ``m9inv`` /
    ``vc`` are their rotation-strain mass matrix, its inverse and V C. They never sleep; their strain energy is
    counted with the elastic energy ``energy[2]``.
    External forces (the spheres' contact reactions, dda/_coupled.py): when ``fext`` has rows, block i starts
    each step with the force ``fext[i]``, torque ``text[i]`` (world, about the centroid) and strain force
    ``qext[i]`` instead of zero; empty arrays for block-only runs.
    Returns (status, steps_done, mstart, mentries, pa, pb, large_list, active, fstart, fentries)."""
    nbody = pos.shape[0]
    nhe = he_origin.shape[0]
    cap = c_key.shape[1]
    R = np.empty((3, 3))
    w_old = np.empty(3)
    w_new = np.empty(3)
    Lnew = np.empty(3)
    qh = np.empty(4)
    nrm = np.empty(3)
    fpt = np.empty(3)
    vrel = np.empty(3)
    us = np.empty(3)
    p_pos = np.empty((MAXP, 3))
    p_depth = np.empty(MAXP)
    p_id = np.empty(MAXP, np.int64)
    matched = np.zeros(MAXP, np.bool_)
    n_sat = np.empty(3)
    maxv = 0
    maxe = 0
    for i in range(nbody):
        maxv = max(maxv, vs[i + 1] - vs[i])
        maxe = max(maxe, es[i + 1] - es[i])
    scr = np.empty((2 * maxv, 3))
    iscr = np.empty(2 * maxe, np.int64)
    nsat = 0
    mmask = mstart.shape[0] - 2
    fmask = fstart.shape[0] - 2
    status = OK
    done = 0
    fit = 0
    sleep_on = sleep_par[0] > 0.0
    v_thr = sleep_par[1]
    a_thr = sleep_par[2]
    n_calm = np.int64(sleep_par[3])
    static = np.empty(nbody, np.bool_)
    for i in range(nbody):
        static[i] = fixed[i] or asleep[i]
    veto = np.zeros(nbody, np.bool_)
    wake_list = np.empty(nbody, np.int64)
    w_j = np.empty(3)
    for step in range(nsteps):
        # 1. geometry of the moving blocks, re-mapping
        rebuild = False
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
            nent = 0
            for k in range(active.shape[0]):
                i = active[k]
                if not large[i]:
                    nent += n_cells(cellbox, i)
            nbk = buckets_for(nent)
            mstart, mentries = build_grid(active, cellbox, large, nbk)
            mmask = nbk - 1
            # large moving blocks join the large list
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
        # 2. candidate pairs
        pa, pb, npair = find_pairs(active, static, large, aabb, cellbox, gap, mstart, mentries, mmask,
                                   fstart, fentries, fmask, large_list, stamp, tag, pa, pb)
        old = cur[0]
        new = 1 - old
        nold = c_n_pair[old]
        need = npair + nold if sleep_on else npair  # resting pairs are carried over
        if need > cap:
            status = NEED_CAPACITY
            stats[2] = need
            break
        # hash of last step's pairs
        hsize = 16
        while hsize < 2 * nold + 16:
            hsize *= 2
        hmask = hsize - 1
        htab[:hsize] = -1  # only the part in use: the cost follows the pairs, not the capacity
        for s in range(nold):
            h = _hash_key(c_key[old, s], hmask)
            while htab[h] >= 0:
                h = (h + 1) & hmask
            htab[h] = s
        for k in range(active.shape[0]):  # fixed blocks take no forces: cost follows the moving blocks
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
        e_el = 0.0
        d_fric = 0.0
        d_damp = 0.0
        maxdepth = 0.0
        ncontact = 0
        npoints = 0
        nslide = 0
        nnew = 0
        nwake = 0
        # 3. narrow phase and contact law
        for p in range(npair):
            i = pa[p]
            j = pb[p]
            key = i * nbody + j
            h = _hash_key(key, hmask)
            slot = -1
            while htab[h] >= 0:
                if c_key[old, htab[h]] == key:
                    slot = htab[h]
                    break
                h = (h + 1) & hmask
            if slot >= 0:
                nrm[0] = c_nrm[old, slot, 0]
                nrm[1] = c_nrm[old, slot, 1]
                nrm[2] = c_nrm[old, slot, 2]
            else:
                nrm[0] = pos[j, 0] - pos[i, 0]
                nrm[1] = pos[j, 1] - pos[i, 1]
                nrm[2] = pos[j, 2] - pos[i, 2]
                if nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2] == 0.0:
                    nrm[2] = 1.0
            size = min(size_b[i], size_b[j])
            mi = material[i]
            mj = material[j]
            kn = lawtab[mi, mj, 0]
            ks = lawtab[mi, mj, 1]
            tanphi = lawtab[mi, mj, 2]
            coh = lawtab[mi, mj, 3]
            ten = lawtab[mi, mj, 4]
            zeta = lawtab[mi, mj, 5]
            kg = 0.0
            if ten > 0.0 or coh > 0.0:
                kg = keep_gap
            # any plane with a positive gap proves separation: keep the cached plane and skip the search
            nl = np.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
            nrm[0] /= nl
            nrm[1] /= nl
            nrm[2] /= nl
            g, ia, ib, sa, sb = gap_along(vert, vs[i], vs[i + 1], vs[j], vs[j + 1], nrm[0], nrm[1], nrm[2])
            if g <= kg:
                g, ia, ib, sa, sb, its = fcp(vert, fnw, vs[i], vs[i + 1], vs[j], vs[j + 1], he_origin, he_next,
                                             he_pair, he_face, vert_he, nrm, 1e-13 * size, 50, nrm)
                fit += its
                if g < 0.0 and (slot < 0 or c_np[old, slot] == 0 or g < -0.01 * size):
                    # a new or a deep overlap (more than 1 % of the smaller block): confirm the plane with the
                    # global separating-axis search (FCP's local search can stop on a poor plane)
                    for a in range(3):
                        n_sat[a] = nrm[a]
                    g2 = sat_search(vert, fnw, vs[i], vs[i + 1], fs[i], fs[i + 1], es[i], es[i + 1],
                                    vs[j], vs[j + 1], fs[j], fs[j + 1], es[j], es[j + 1], he_origin, he_next,
                                    edge_he, nrm, g, n_sat)
                    if g2 > g:
                        nsat += 1
                        for a in range(3):
                            nrm[a] = n_sat[a]
                        g, ia, ib, sa, sb = gap_along(vert, vs[i], vs[i + 1], vs[j], vs[j + 1],
                                                      nrm[0], nrm[1], nrm[2])
            s = nnew
            nnew += 1
            c_key[new, s] = key
            c_a[new, s] = i
            c_b[new, s] = j
            c_nrm[new, s, 0] = nrm[0]
            c_nrm[new, s, 1] = nrm[1]
            c_nrm[new, s, 2] = nrm[2]
            c_np[new, s] = 0
            matched[:] = False
            if sleep_on and asleep[j] and not veto[j] and g < gap and (kin[i] or calm[i] < n_calm):
                # a moving block comes within the search gap of a sleeping one: wake it before they touch
                # (veto marks a sleeping block already on the wake list)
                veto[j] = True
                wake_list[nwake] = j
                nwake += 1
            if g > kg:
                d_fric += _released(c_np, c_us, old, slot, matched, ks)
                continue
            k = contact_points(vert, fnw, fdw, he_origin, he_next, edge_he,
                               vs[i], vs[i + 1], fs[i], fs[i + 1], es[i], es[i + 1],
                               vs[j], vs[j + 1], fs[j], fs[j + 1], es[j], es[j + 1],
                               nrm, sa, sb, kg, size, nhe, p_pos, p_depth, p_id, scr, iscr)
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
                    p_pos[k, a] = 0.5 * (vert[ia, a] + vert[ib, a])
                k += 1
            if k == 0:
                d_fric += _released(c_np, c_us, old, slot, matched, ks)
                continue
            area = polygon_area(p_pos, k, nrm)
            apt = area / k
            inj = static[j] or kin[j]
            if kin[i] and inj:
                meff = min(mass[i], mass[j])
            elif kin[i]:
                meff = mass[j]
            elif inj:
                meff = mass[i]
            else:
                meff = mass[i] * mass[j] / (mass[i] + mass[j])
            kept = 0
            ncontact += 1
            for q in range(k):
                # shear history of the same feature in last step's contact
                found = -1
                if slot >= 0:
                    for r in range(c_np[old, slot]):
                        if c_pid[old, slot, r] == p_id[q]:
                            found = r
                            break
                bonded = False
                if found >= 0:
                    matched[found] = True
                    us[0] = c_us[old, slot, found, 0]
                    us[1] = c_us[old, slot, found, 1]
                    us[2] = c_us[old, slot, found, 2]
                    bonded = c_bond[old, slot, found]
                    # rotate onto the current tangent plane, keeping its length
                    l0 = np.sqrt(us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
                    un = us[0] * nrm[0] + us[1] * nrm[1] + us[2] * nrm[2]
                    for a in range(3):
                        us[a] -= un * nrm[a]
                    l1 = np.sqrt(us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
                    if l1 > 0.0:
                        for a in range(3):
                            us[a] *= l0 / l1
                else:
                    us[0] = 0.0
                    us[1] = 0.0
                    us[2] = 0.0
                    bonded = first_step and (coh > 0.0 or ten > 0.0)
                if p_depth[q] <= 0.0 and not bonded:
                    continue
                # relative velocity of B with respect to A at the point (half-step velocities)
                for a in range(3):
                    vrel[a] = vel[j, a] - vel[i, a]
                if not static[j] and dof12[j]:
                    quat_matrix(quat[j], R)
                    point_velocity(j, p_pos[q], pos, R, strain, srate, wb, w_old)
                    for a in range(3):
                        vrel[a] += w_old[a]
                elif not static[j]:
                    _omega(j, kin, static, wpres, quat, inertia, angmom, R, w_old)
                    rx = p_pos[q, 0] - pos[j, 0]
                    ry = p_pos[q, 1] - pos[j, 1]
                    rz = p_pos[q, 2] - pos[j, 2]
                    vrel[0] += w_old[1] * rz - w_old[2] * ry
                    vrel[1] += w_old[2] * rx - w_old[0] * rz
                    vrel[2] += w_old[0] * ry - w_old[1] * rx
                if dof12[i]:
                    quat_matrix(quat[i], R)
                    point_velocity(i, p_pos[q], pos, R, strain, srate, wb, w_old)
                    for a in range(3):
                        vrel[a] -= w_old[a]
                elif not fixed[i]:
                    _omega(i, kin, static, wpres, quat, inertia, angmom, R, w_old)
                    rx = p_pos[q, 0] - pos[i, 0]
                    ry = p_pos[q, 1] - pos[i, 1]
                    rz = p_pos[q, 2] - pos[i, 2]
                    vrel[0] -= w_old[1] * rz - w_old[2] * ry
                    vrel[1] -= w_old[2] * rx - w_old[0] * rz
                    vrel[2] -= w_old[0] * ry - w_old[1] * rx
                st, bonded, fn_el, ee, df, dd = point_force(kn, ks, tanphi, coh * apt, ten * apt, zeta, meff,
                                                            p_depth[q], nrm, vrel, dt, us, bonded, fpt)
                e_el += ee
                d_fric += df
                d_damp += dd
                if st == 0:
                    continue
                if st == 2:
                    nslide += 1
                if p_depth[q] > maxdepth:
                    maxdepth = p_depth[q]
                for a in range(3):
                    force[i, a] -= fpt[a]
                if not static[j]:
                    for a in range(3):
                        force[j, a] += fpt[a]
                    rx = p_pos[q, 0] - pos[j, 0]
                    ry = p_pos[q, 1] - pos[j, 1]
                    rz = p_pos[q, 2] - pos[j, 2]
                    torque[j, 0] += ry * fpt[2] - rz * fpt[1]
                    torque[j, 1] += rz * fpt[0] - rx * fpt[2]
                    torque[j, 2] += rx * fpt[1] - ry * fpt[0]
                rx = p_pos[q, 0] - pos[i, 0]
                ry = p_pos[q, 1] - pos[i, 1]
                rz = p_pos[q, 2] - pos[i, 2]
                torque[i, 0] -= ry * fpt[2] - rz * fpt[1]
                torque[i, 1] -= rz * fpt[0] - rx * fpt[2]
                torque[i, 2] -= rx * fpt[1] - ry * fpt[0]
                if dof12[i]:
                    quat_matrix(quat[i], R)
                    body_point(i, p_pos[q], pos, R, strain, w_old)
                    add_strain_force(i, w_old, R, fpt, -1.0, qs)
                if dof12[j] and not static[j]:
                    quat_matrix(quat[j], R)
                    body_point(j, p_pos[q], pos, R, strain, w_old)
                    add_strain_force(j, w_old, R, fpt, 1.0, qs)
                c_pid[new, s, kept] = p_id[q]
                c_us[new, s, kept, 0] = us[0]
                c_us[new, s, kept, 1] = us[1]
                c_us[new, s, kept, 2] = us[2]
                c_state[new, s, kept] = st
                c_bond[new, s, kept] = bonded
                c_pos[new, s, kept, 0] = p_pos[q, 0]
                c_pos[new, s, kept, 1] = p_pos[q, 1]
                c_pos[new, s, kept, 2] = p_pos[q, 2]
                c_fn[new, s, kept] = fn_el
                c_depth[new, s, kept] = p_depth[q]
                kept += 1
            c_np[new, s] = kept
            npoints += kept
            d_fric += _released(c_np, c_us, old, slot, matched, ks)
            if sleep_on and kept > 0:
                moving_i = kin[i] or calm[i] < n_calm
                if not asleep[j]:
                    if moving_i:
                        veto[j] = True
                    if not static[j] and (kin[j] or calm[j] < n_calm):
                        veto[i] = True
        if sleep_on:
            # contacts between resting bodies are carried over unchanged (shear history and elastic energy kept)
            for s0 in range(nold):
                a0 = c_a[old, s0]
                b0 = c_b[old, s0]
                if c_np[old, s0] == 0 or not (static[a0] and static[b0]) or not (asleep[a0] or asleep[b0]):
                    continue
                s = nnew
                nnew += 1
                c_key[new, s] = c_key[old, s0]
                c_a[new, s] = a0
                c_b[new, s] = b0
                c_np[new, s] = c_np[old, s0]
                for a in range(3):
                    c_nrm[new, s, a] = c_nrm[old, s0, a]
                kn0 = lawtab[material[a0], material[b0], 0]
                ks0 = lawtab[material[a0], material[b0], 1]
                for q in range(c_np[old, s0]):
                    c_pid[new, s, q] = c_pid[old, s0, q]
                    c_state[new, s, q] = c_state[old, s0, q]
                    c_bond[new, s, q] = c_bond[old, s0, q]
                    c_fn[new, s, q] = c_fn[old, s0, q]
                    d0 = c_depth[old, s0, q]
                    c_depth[new, s, q] = d0
                    u2 = 0.0
                    for a in range(3):
                        c_us[new, s, q, a] = c_us[old, s0, q, a]
                        c_pos[new, s, q, a] = c_pos[old, s0, q, a]
                        u2 += c_us[old, s0, q, a] ** 2
                    e_el += 0.5 * kn0 * d0 * d0
                    e_el += 0.5 * ks0 * u2
                ncontact += 1
                npoints += c_np[old, s0]
        c_n_pair[new] = nnew
        cur[0] = new
        first_step = False
        # 4. central difference for the moving blocks
        dtavg = 0.5 * (dt + dt_prev)
        ke = 0.0
        pe = 0.0
        d_loc = 0.0
        blown = False
        for k in range(active.shape[0]):
            i = active[k]
            if kin[i]:
                # prescribed motion: the driver does the work the contacts do against it
                acc[0] -= dt * (force[i, 0] * vel[i, 0] + force[i, 1] * vel[i, 1] + force[i, 2] * vel[i, 2]
                                + torque[i, 0] * wpres[i, 0] + torque[i, 1] * wpres[i, 1] + torque[i, 2] * wpres[i, 2])
                _turn(quat[i], wpres[i], dt, qh)
                for a in range(4):
                    quat[i, a] = qh[a]
                for a in range(3):
                    pos[i, a] += dt * vel[i, a]
                continue
            if dof12[i]:
                ke_i, pe_i, es_i, dl_i, bl_i = deform_step(i, dt, dtavg, gravity, local_damp, pos, vel, quat, mass,
                                                           inertia, force, torque, bforce, pl_start, pl_r, pl_f,
                                                           strain, srate, wb, qs, m9, m9inv, vc)
                ke += ke_i
                pe += pe_i
                e_el += es_i
                d_loc += dl_i
                if bl_i:
                    blown = True
                continue
            m = mass[i]
            quat_matrix(quat[i], R)
            # constant point loads (world force at a body point) and their potential
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
                pe -= f0 * (pos[i, 0] + r0) + f1 * (pos[i, 1] + r1) + f2 * (pos[i, 2] + r2)
            _ang_vel(R, inertia[i], angmom[i], w_old)
            fsq = 0.0
            tsq = 0.0
            for a in range(3):
                f = force[i, a] + m * gravity[a] + bforce[i, a]
                t = torque[i, a]
                fsq += f * f
                tsq += t * t
                if local_damp > 0.0:
                    if vel[i, a] != 0.0:
                        fd = local_damp * abs(f) * (1.0 if vel[i, a] > 0 else -1.0)
                        f -= fd
                        d_loc += fd * vel[i, a] * dtavg
                    if w_old[a] != 0.0:
                        td = local_damp * abs(t) * (1.0 if w_old[a] > 0 else -1.0)
                        t -= td
                        d_loc += td * w_old[a] * dtavg
                vnew = vel[i, a] + dtavg * f / m
                ke += 0.5 * m * vel[i, a] * vnew
                vel[i, a] = vnew
                Lnew[a] = angmom[i, a] + dtavg * t
                pe -= (m * gravity[a] + bforce[i, a]) * pos[i, a]
            _ang_vel(R, inertia[i], Lnew, w_new)
            ke += 0.5 * (angmom[i, 0] * w_new[0] + angmom[i, 1] * w_new[1] + angmom[i, 2] * w_new[2])
            if sleep_on:
                sz = size_b[i]
                spd = np.sqrt(vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2) \
                    + sz * np.sqrt(w_new[0] ** 2 + w_new[1] ** 2 + w_new[2] ** 2)
                imin = min(inertia[i, 0], min(inertia[i, 1], inertia[i, 2]))
                acl = np.sqrt(fsq) / m + sz * np.sqrt(tsq) / imin
                if spd < v_thr and acl < a_thr:
                    calm[i] += 1
                else:
                    calm[i] = 0
            # mid-step orientation predictor, then the full turn
            _turn(quat[i], w_new, 0.5 * dt, qh)
            quat_matrix(qh, R)
            _ang_vel(R, inertia[i], Lnew, w_new)
            _turn(quat[i], w_new, dt, qh)
            for a in range(4):
                quat[i, a] = qh[a]
            for a in range(3):
                angmom[i, a] = Lnew[a]
                pos[i, a] += dt * vel[i, a]
                if not np.isfinite(pos[i, a]) or not np.isfinite(vel[i, a]) or not np.isfinite(Lnew[a]):
                    blown = True
        if sleep_on:
            changed = False
            d_sleep = 0.0
            for k in range(active.shape[0]):
                i = active[k]
                if not kin[i] and calm[i] >= n_calm and not veto[i]:
                    # falls asleep: the kinetic energy left (below the thresholds) counts as damped
                    quat_matrix(quat[i], R)
                    _ang_vel(R, inertia[i], angmom[i], w_old)
                    d_sleep += 0.5 * mass[i] * (vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2) \
                        + 0.5 * (angmom[i, 0] * w_old[0] + angmom[i, 1] * w_old[1] + angmom[i, 2] * w_old[2])
                    for a in range(3):
                        vel[i, a] = 0.0
                        angmom[i, a] = 0.0
                    asleep[i] = True
                    static[i] = True
                    pe_sl[i] = _load_potential(i, pos, quat, mass, gravity, bforce, pl_start, pl_r, pl_f)
                    acc[1] += pe_sl[i]
                    changed = True
                veto[i] = False
            for e in range(nwake):
                j = wake_list[e]
                veto[j] = False
                if asleep[j]:
                    asleep[j] = False
                    static[j] = False
                    calm[j] = 0
                    acc[1] -= pe_sl[j]
                    changed = True
            d_damp += d_sleep
            if changed:
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
                mstart, mentries, fstart, fentries, large_list = regrid(active, static, cellbox, large)
                mmask = mstart.shape[0] - 2
                fmask = fstart.shape[0] - 2
        pe += acc[1] - acc[0]
        dt_prev = dt
        energy[0] = ke
        energy[1] = pe
        energy[2] = e_el
        energy[3] += d_fric
        energy[4] += d_damp
        energy[5] += d_loc
        done += 1
        stats[4] = maxdepth
        stats[5] = ncontact
        stats[6] = npoints
        stats[7] = nslide
        stats[8] = npair
        stats[9] = nsat
        stats[10] = active.shape[0]
        if blown or not np.isfinite(e_el):
            status = BLOWUP
            break
    stats[0] = done
    stats[1] = status
    stats[3] = fit
    return status, done, mstart, mentries, pa, pb, large_list, active, fstart, fentries
