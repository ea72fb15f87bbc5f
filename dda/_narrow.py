"""numba kernels: narrow phase and contact law, the middle stages of a step of dda/_integrate.py's run_chunk.

For each candidate pair (i, j) of the broad phase (``narrow_phase``):

1. last step's record of the pair (a hash table on the pair key, ``hash_pairs``), or of the pair with its
   roles swapped (a block fell asleep or woke), turned round;
2. the common plane: last step's plane (or the centroids' line) is checked first (a positive gap along it proves
   the blocks apart); else the Fast Common-Plane search from it, confirmed by the separating-axis search for a new
   or deep overlap;
3. the contact points on that plane (dda/_fcp.py's contact_points, plus the support points' midpoint when no
   point represents the plane's overlap);
4. the contact law at each point: shear history of the same feature from last step, relative velocity,
   dda/_contact.py's point_force, the force and torque on both blocks, the point's new record.

Reference counts: numba increments the count of an array when a variable takes it (an inlined helper's
parameter, a view such as ``pos[i]``, an array taken out of a bundle) and decrements it after the variable's
last use; its pruning pass removes such pairs only within one basic block or when no other decrement lies between
them. A helper with array parameters and branches, or a bundle handed on, thus cost about 100 atomic count
changes per touching pair. So narrow_phase takes its arrays out of the bundles once per step and writes the
per-pair and per-point steps out in its own loops; the helpers it inlines there take scalars or are straight-line
code, and the kernels it calls per pair take plain arrays (a non-inlined call borrows its arguments). The one
helper left with array parameters and branches per point is point_force (4 arrays); a cut block model's face
kinds add dda/_kinds.py's per point (their own runs only).

Contacts between two resting blocks are carried over unchanged while sleeping is on (``carry_resting``).
The step's sums (elastic energy, friction and damping work, deepest point) go to ``tally`` and its counts to
``count`` (slots T_* and C_* of dda/_state.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._contact import add_dashpots, point_force
from ._deform import add_strain_force, body_point, point_velocity
from ._fcp import MAXP, clip_line, contact_points, fcp, gap_along, polygon_area, sat_search
from ._kinds import intact_share, law_face, point_row
from ._kinematics import quat_matrix, spin
from ._state import (C_CONTACTS, C_FIT, C_NEW, C_POINTS, C_SAT, C_SLIDING, C_WAKE, LAW_COH, LAW_KN, LAW_KS,
                     LAW_TANPHI, LAW_TEN, LAW_ZETA, T_DAMPING, T_ELASTIC, T_FRICTION, T_MAXDEPTH, T_TURNOVER)


@njit(cache=True, inline="always")
def _book_gone(tally, e_n, kt, us, v0, v1, v2, nrm, dt, fd0, fd1, fd2):
    """The energy of last step's point that is gone this step (found open: depth <= 0 and no bond; or without a
    successor), v its relative velocity this step: its normal spring's state 1/2 fn d_last goes with the half of
    its last force that the product-form kinetic energy pairs with this step's increment, together
    1/2 fn d_now = e_n (point turnover, released; <= 0 for a point that opened); likewise its shear spring's
    1/2 ks u.(u + du) (released with friction, du = the tangential increment of this step), and the second half
    of its last damping force fd (contact damping)."""
    vn = v0 * nrm[0] + v1 * nrm[1] + v2 * nrm[2]
    us_du = (us[0] * (v0 - vn * nrm[0]) * dt + us[1] * (v1 - vn * nrm[1]) * dt
             + us[2] * (v2 - vn * nrm[2]) * dt)
    uu = us[0] * us[0] + us[1] * us[1] + us[2] * us[2]
    tally[T_TURNOVER] += e_n
    tally[T_FRICTION] += 0.5 * kt * (uu + us_du)
    tally[T_DAMPING] -= 0.5 * dt * (fd0 * v0 + fd1 * v1 + fd2 * v2)


@njit(cache=True)
def _body_point_velocity(b, still, x, blocks):
    """Velocity of body b's material point at x (half-step; a deformable block's rigid part only) as three
    scalars; 0 for a body that does not move (`still`)."""
    if still:
        return 0.0, 0.0, 0.0
    pos, vel = blocks.pos, blocks.vel
    if blocks.kin[b]:
        w0, w1, w2 = blocks.wpres[b, 0], blocks.wpres[b, 1], blocks.wpres[b, 2]
    else:
        w0, w1, w2 = spin(b, blocks.quat, blocks.inertia, blocks.angmom)
    c0, c1, c2 = _cross(w0, w1, w2, x[0] - pos[b, 0], x[1] - pos[b, 1], x[2] - pos[b, 2])
    return vel[b, 0] + c0, vel[b, 1] + c1, vel[b, 2] + c2


@njit(cache=True)
def _book_vanished(tally, i, j, still_i, still_j, x, depth, fn, u, fd, ks, nrm, dt, blocks):
    """The energy of last step's point (at x, depth, normal force fn, shear displacement u, damping force fd)
    that has no successor this step (_book_gone), its depth now d_after = depth - vn dt from the blocks'
    velocities at x: 1/2 fn d_after is <= 0 for a point that opened, about 1/2 kn depth^2 for one that a change
    of the contact polygon dropped while loaded."""
    a0, a1, a2 = _body_point_velocity(i, still_i, x, blocks)
    b0, b1, b2 = _body_point_velocity(j, still_j, x, blocks)
    v0, v1, v2 = b0 - a0, b1 - a1, b2 - a2
    vn = v0 * nrm[0] + v1 * nrm[1] + v2 * nrm[2]
    _book_gone(tally, 0.5 * fn * (depth - vn * dt), ks, u, v0, v1, v2, nrm, dt, fd[0], fd[1], fd[2])


@njit(cache=True)
def _pierce_point(vert, fnw, fdw, he_origin, he_next, edge_he, e0, e1, g0, g1, n, sgn, tol, out):
    """The deepest point where an edge of block X (edges e0..e1) runs through block Y (faces g0..g1): the middle
    of the edge's part inside Y, written into `out`; its depth is Y's extent behind it along the normal n (A -> B):
    along -n for X = A (sgn = -1), along +n for X = B (sgn = 1), as contact_points measures its points. Returns the
    depth, or -1 when no edge runs through Y."""
    best = -1.0
    d = np.empty(3)
    P = np.empty(3)
    for e in range(e0, e1):
        h = edge_he[e]
        a = he_origin[h]
        b = he_origin[he_next[h]]
        ln = 0.0
        for c in range(3):
            d[c] = vert[b, c] - vert[a, c]
            ln += d[c] * d[c]
        ln = np.sqrt(ln)
        if ln == 0.0:
            continue
        for c in range(3):
            d[c] /= ln
        lo, hi = clip_line(vert[a], d, fnw, fdw, g0, g1, tol, 0.0, sgn)
        lo = max(lo, 0.0)
        hi = min(hi, ln)
        if lo >= hi:
            continue
        for c in range(3):
            P[c] = vert[a, c] + 0.5 * (lo + hi) * d[c]
        lo, hi = clip_line(P, n, fnw, fdw, g0, g1, tol, 0.0, sgn)
        depth = -lo if sgn < 0.0 else hi
        if lo <= hi and depth > best:
            best = depth
            for c in range(3):
                out[c] = P[c]
    return best


@njit(cache=True, inline="always")
def _unshown(p_depth, k, g):
    """True when the k contact points (k = -1: none inside the other block) do not show the plane's overlap -g:
    none reaches half of it."""
    if k < 0:
        return True
    maxd = 0.0
    for q in range(k):
        if p_depth[q] > maxd:
            maxd = p_depth[q]
    return maxd < -0.5 * g


@njit(cache=True, inline="always")
def _hash_key(key, mask):
    h = key * np.int64(0x9E3779B97F4A7C15 & 0x7FFFFFFFFFFFFFFF)
    h ^= h >> 29
    return h & mask


@njit(cache=True, inline="always")
def _find_slot(key, hmask, htab, key_old):
    """Last step's slot of the pair `key` (the hash table of hash_pairs), or -1."""
    h = _hash_key(key, hmask)
    while htab[h] >= 0:
        if key_old[htab[h]] == key:
            return htab[h]
        h = (h + 1) & hmask
    return -1


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


@njit(cache=True)
def _swap_roles(slot, nrm_old, npt_old, pid_old, us_old, fd_old, nhe):
    """Last step's record `slot` of a pair turned round (its B is A now): the normal (A -> B), the shear
    displacement of B relative to A and the damping force on B change sign; an edge crossing's feature id names
    A's half-edge first (dda/_fcp.py contact_points), a vertex's id (its index + 1) and the midpoint's (0) stay."""
    for a in range(3):
        nrm_old[slot, a] = -nrm_old[slot, a]
    for r in range(npt_old[slot]):
        for a in range(3):
            us_old[slot, r, a] = -us_old[slot, r, a]
            fd_old[slot, r, a] = -fd_old[slot, r, a]
        pid = pid_old[slot, r]
        if pid < 0:
            ha = (-pid - 1) // nhe
            pid_old[slot, r] = -(1 + (-pid - 1 - ha * nhe) * nhe + ha)


@njit(cache=True, inline="always")
def _effective_mass(kin_i, kin_j, static_j, m_i, m_j):
    """Mass of the contact's normal mode: the free block's when the other is fixed, asleep or prescribed."""
    inj = static_j or kin_j
    if kin_i and inj:
        return min(m_i, m_j)
    if kin_i:
        return m_j
    if inj:
        return m_i
    return m_i * m_j / (m_i + m_j)


@njit(cache=True, inline="always")
def _dist2(pos_old, slot, r, p_pos, q):
    """Squared distance between last step's point r of pair slot `slot` and the point q."""
    d0 = pos_old[slot, r, 0] - p_pos[q, 0]
    d1 = pos_old[slot, r, 1] - p_pos[q, 1]
    d2 = pos_old[slot, r, 2] - p_pos[q, 2]
    return d0 * d0 + d1 * d1 + d2 * d2


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    """a x b."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, inline="always")
def _onto_plane(u0, u1, u2, n0, n1, n2):
    """The shear displacement u turned onto the plane of unit normal n, keeping its length."""
    l0 = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    un = u0 * n0 + u1 * n1 + u2 * n2
    u0 -= un * n0
    u1 -= un * n1
    u2 -= un * n2
    l1 = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if l1 > 0.0:
        u0 *= l0 / l1
        u1 *= l0 / l1
        u2 *= l0 / l1
    return u0, u1, u2


@njit(cache=True, inline="always")
def _store_point(pid_new, us_new, state_new, bond_new, pos_new, fn_new, depth_new, s, kept, us, st, bonded, fn_el,
                 p_pos, p_depth, p_id, q):
    """Record point q of the pair's points (p_pos, p_depth, p_id) as point `kept` of pair slot s in this step's
    buffer (rows pid_new ... depth_new). Straight-line code: the counts of the arrays it takes cancel within one
    basic block, where numba removes them."""
    pid_new[s, kept] = p_id[q]
    us_new[s, kept, 0] = us[0]
    us_new[s, kept, 1] = us[1]
    us_new[s, kept, 2] = us[2]
    state_new[s, kept] = st
    bond_new[s, kept] = bonded
    pos_new[s, kept, 0] = p_pos[q, 0]
    pos_new[s, kept, 1] = p_pos[q, 1]
    pos_new[s, kept, 2] = p_pos[q, 2]
    fn_new[s, kept] = fn_el
    depth_new[s, kept] = p_depth[q]


# written out as one loop over the pairs with the loop over their points inside it (over 150 lines): numba counts
# every array a helper takes in and out at each call unless the counts cancel in straight-line code, so the
# per-pair and per-point steps use this kernel's own arrays (taken out of the bundles once per step) and call only
# kernels that take plain arrays (dda/_fcp.py) or scalar and straight-line helpers; a helper taking arrays with
# branches, or a bundle, cost about 100 count changes per touching pair (the module docstring)
@njit(cache=True)
def narrow_phase(npair, pa, pb, hmask, first_step, dt, law, gap, blocks, deform, forces, geom, sleep, con, work,
                 tally, count):
    """Common plane, contact points and contact law of the npair candidate pairs (pa[p], pb[p])."""
    nbody = blocks.pos.shape[0]
    old = con.cur[0]
    new = 1 - old
    sleep_on = sleep.par[0] > 0.0
    static, veto, matched, nrm, wake_list = work.static, work.veto, work.matched, work.nrm, work.wake_list
    kin, calm, asleep = blocks.kin, sleep.calm, sleep.asleep
    pos, size_b, material, lawtab, keep_gap = blocks.pos, blocks.size_b, blocks.material, law.tab, law.keep_gap
    vert, fnw, fdw, vs, fs, es = geom.vert, geom.fnw, geom.fdw, geom.vs, geom.fs, geom.es
    he_origin, he_next, he_pair, he_face = geom.he_origin, geom.he_next, geom.he_pair, geom.he_face
    vert_he, edge_he, n_sat = geom.vert_he, geom.edge_he, work.n_sat
    p_pos, p_depth, p_id, scr, iscr, mass = work.p_pos, work.p_depth, work.p_id, work.scr, work.iscr, blocks.mass
    htab, key_old, nrm_old, npt_old, us_old = con.htab, con.key[old], con.nrm[old], con.npt[old], con.us[old]
    key_new, a_new, b_new, nrm_new, npt_new = con.key[new], con.a[new], con.b[new], con.nrm[new], con.npt[new]
    pid_old, bond_old, fn_old, depth_old = con.pid[old], con.bond[old], con.fn[old], con.depth[old]
    pid_new, us_new, state_new, bond_new = con.pid[new], con.us[new], con.state[new], con.bond[new]
    pos_new, fn_new, depth_new, fd_old, fd_new = con.pos[new], con.fn[new], con.depth[new], con.fd[old], con.fd[new]
    R, w, X, us, fpt, vrel = work.R, work.w_old, work.w_old, work.us, work.fpt, work.vrel
    vel, quat, fixed, dof12 = blocks.vel, blocks.quat, blocks.fixed, blocks.dof12
    wpres, inertia, angmom = blocks.wpres, blocks.inertia, blocks.angmom
    strain, srate, wb = deform.strain, deform.srate, deform.wb
    force, torque, qs, dsum, dscale = forces.force, forces.torque, forces.qs, forces.dsum, forces.dscale
    face_row, face_shape, face_geo, intact_row = law.face_row, law.face_shape, law.face_geo, law.intact_row
    kinds = len(face_row) > 0
    pos_old, a_old, b_old, nhe = con.pos[old], con.a[old], con.b[old], he_origin.shape[0]
    rec = np.empty(MAXP + 1, np.int64)  # each point's record of last step (the pair loop)
    for p in range(npair):
        i = pa[p]
        j = pb[p]
        key = i * nbody + j
        # 1. last step's slot of the pair; else its slot with the roles swapped (one of the blocks fell asleep or
        # woke: a pair's A is an awake block), turned round and taken over, so that a cemented point keeps its
        # bond and every point its shear history
        slot = _find_slot(key, hmask, htab, key_old)
        if slot < 0 and not first_step:
            slot = _find_slot(j * nbody + i, hmask, htab, key_old)
            if slot >= 0:
                _swap_roles(slot, nrm_old, npt_old, pid_old, us_old, fd_old, nhe)
                key_old[slot] = key
                a_old[slot] = i
                b_old[slot] = j
        size = min(size_b[i], size_b[j])
        # a cut block model's neighbours meet face to face within rounding (the cutter's 1e-9 of a block): an
        # overlap below contact_points' tolerance is none to confirm by the separating axes nor to represent by a
        # point (the open pit: 45 000 of 223 000 pairs a step, overlaps of 1e-15 of their size, most of a step's
        # cost); the blocks of every other scene keep the exact test (and their results' bits)
        tol = 1e-9 * size if kinds else 0.0
        mi = material[i]
        mj = material[j]
        ks = lawtab[mi, mj, LAW_KS]
        kg = 0.0
        if kinds or lawtab[mi, mj, LAW_TEN] > 0.0 or lawtab[mi, mj, LAW_COH] > 0.0:
            kg = keep_gap
        # 2. last step's plane, or the centroids' line; a positive gap along it proves the blocks apart
        if slot >= 0:
            for a in range(3):
                nrm[a] = nrm_old[slot, a]
        else:
            for a in range(3):
                nrm[a] = pos[j, a] - pos[i, a]
            if nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2] == 0.0:
                nrm[2] = 1.0
        nl = np.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
        nrm[0] /= nl
        nrm[1] /= nl
        nrm[2] /= nl
        g, ia, ib, sa, sb = gap_along(vert, vs[i], vs[i + 1], vs[j], vs[j + 1], nrm[0], nrm[1], nrm[2])
        k = 0
        if g <= kg:
            # else the Fast Common-Plane search from it, and (3.) the contact points on its plane (geom: this
            # kernel's own argument, handed on as it came); the separating-axis search confirms the plane of a new
            # overlap (no points last step), a deep one (more than 1 % of the smaller block) and one whose points
            # do not show its overlap (none inside the other block, or none half as deep: the blocks may not touch
            # at all): FCP's local search can stop on a poor plane, and last step's plane is where it starts
            g, ia, ib, sa, sb, its = fcp(vert, fnw, vs[i], vs[i + 1], vs[j], vs[j + 1], he_origin, he_next, he_pair,
                                         he_face, vert_he, nrm, 1e-13 * size, 50, nrm)
            count[C_FIT] += its
            k = contact_points(geom, i, j, nrm, sa, sb, kg, size, p_pos, p_depth, p_id, scr, iscr)
            if g < -tol and (slot < 0 or npt_old[slot] == 0 or g < -0.01 * size or _unshown(p_depth, k, g)):
                for a in range(3):
                    n_sat[a] = nrm[a]
                g2 = sat_search(vert, fnw, vs[i], vs[i + 1], fs[i], fs[i + 1], es[i], es[i + 1], vs[j], vs[j + 1],
                                fs[j], fs[j + 1], es[j], es[j + 1], he_origin, he_next, edge_he, nrm, g, n_sat)
                if g2 > g:
                    count[C_SAT] += 1
                    for a in range(3):
                        nrm[a] = n_sat[a]
                    g, ia, ib, sa, sb = gap_along(vert, vs[i], vs[i + 1], vs[j], vs[j + 1], nrm[0], nrm[1], nrm[2])
                    k = 0
                    if g <= kg:
                        k = contact_points(geom, i, j, nrm, sa, sb, kg, size, p_pos, p_depth, p_id, scr, iscr)
            k = max(k, 0)
        s = count[C_NEW]
        count[C_NEW] += 1
        key_new[s] = key
        a_new[s] = i
        b_new[s] = j
        for a in range(3):
            nrm_new[s, a] = nrm[a]
        npt_new[s] = 0
        matched[:] = False
        if sleep_on and asleep[j] and not veto[j] and g < gap and (kin[i] or calm[i] == 0):
            # a moving block (calm count 0: it failed its last step or window) comes within the search gap of a
            # sleeping one: wake it before they touch
            # (veto marks a sleeping block already on the wake list)
            veto[j] = True
            wake_list[count[C_WAKE]] = j
            count[C_WAKE] += 1
        kept = 0
        if g <= kg:
            # 3. the contact points (above), plus one more when the plane's overlap sa - sb is not represented: when
            # no point found reaches half of it (tip against tip, or an edge that pierces a face, which the
            # candidates do not include)
            if sa - sb > tol and _unshown(p_depth, k, sb - sa) and k < MAXP:
                # the deepest point where an edge of one block runs through the other: a point of the overlap
                # whose depth changes with the blocks' relative velocity there; else the support points' own
                # overlap at their midpoint (that depth changes with the support points' velocities, up to a
                # block's width away, and the force at the midpoint does work its springs do not book)
                d_a = _pierce_point(vert, fnw, fdw, he_origin, he_next, edge_he, es[i], es[i + 1], fs[j],
                                    fs[j + 1], nrm, -1.0, 1e-9 * size, p_pos[k])
                d_b = _pierce_point(vert, fnw, fdw, he_origin, he_next, edge_he, es[j], es[j + 1], fs[i],
                                    fs[i + 1], nrm, 1.0, 1e-9 * size, scr[0])
                p_id[k] = 0
                if d_b > d_a:
                    for a in range(3):
                        p_pos[k, a] = scr[0, a]
                    d_a = d_b
                if d_a > 0.0:
                    p_depth[k] = min(d_a, sa - sb)
                else:
                    p_depth[k] = sa - sb
                    for a in range(3):
                        p_pos[k, a] = 0.5 * (vert[ia, a] + vert[ib, a])
                k += 1
        if k > 0:
            # 4. the contact law at each point
            apt = polygon_area(p_pos, k, nrm) / k
            meff = _effective_mass(kin[i], kin[j], static[j], mass[i], mass[j])
            dsc = dscale[i] if static[j] else min(dscale[i], dscale[j])
            count[C_CONTACTS] += 1
            kn, kt, tanphi = lawtab[mi, mj, LAW_KN], ks, lawtab[mi, mj, LAW_TANPHI]
            coh, ten, zeta = lawtab[mi, mj, LAW_COH], lawtab[mi, mj, LAW_TEN], lawtab[mi, mj, LAW_ZETA]
            lf, lo = -1, -1
            a_int, a_jnt = -1.0, -1.0
            if kinds:
                # face lf of block lo decides each point's law row (dda/_kinds.py); a disc's face: the intact and
                # joint points share their own areas
                lf, lo = law_face(i, j, nrm, fnw, fs, face_row)
                if lf >= 0 and face_shape[lf] == 1:
                    rows = np.empty(k, np.int64)
                    for q in range(k):
                        rows[q] = point_row(lf, lo, p_pos[q], pos, quat, face_row, face_shape, face_geo, intact_row, R)
                    a_int, a_jnt = intact_share(lf, lo, p_pos, k, rows, nrm, pos, quat, face_geo, intact_row, R)
            # last step's record of each point (rec[q], -1: none): the record of the same feature id; in a cut block
            # model (lf >= 0) only while it lies at the point's place (within tolp: a feature id can come to
            # stand for another place, e.g. the crossing of two near-parallel edges, or a merged candidate whose
            # id and place come from different vertices), else the nearest unclaimed record at its place
            # (coincident vertices of cut blocks: which one stands for a corner may change), nearest pairs
            # first; a point that opens takes a record by place only to keep a bond (else the record is booked
            # as released at its own place below, and the opening point has nothing to book)
            for q in range(k):
                rec[q] = -1
            if slot >= 0:
                tolp2 = (1e-3 * size) ** 2
                for q in range(k):
                    for r in range(npt_old[slot]):
                        if pid_old[slot, r] == p_id[q]:
                            if lf < 0 or _dist2(pos_old, slot, r, p_pos, q) <= tolp2:
                                rec[q] = r
                                matched[r] = True
                            break
                if lf >= 0:
                    while True:
                        bq = -1
                        br = -1
                        bd = tolp2
                        for q in range(k):
                            if rec[q] >= 0:
                                continue
                            for r in range(npt_old[slot]):
                                if matched[r] or (p_depth[q] <= 0.0 and not bond_old[slot, r]):
                                    continue
                                d2 = _dist2(pos_old, slot, r, p_pos, q)
                                if d2 <= bd:
                                    bd = d2
                                    bq = q
                                    br = r
                        if bq < 0:
                            break
                        rec[bq] = br
                        matched[br] = True
            for q in range(k):
                if lf >= 0:  # the law of the face's kind at this point (joint inside its disc, intact rock outside)
                    r = point_row(lf, lo, p_pos[q], pos, quat, face_row, face_shape, face_geo, intact_row, R)
                    if a_int >= 0.0:
                        apt = a_int if r == intact_row else a_jnt
                    kn, kt, tanphi = lawtab[r, r, LAW_KN], lawtab[r, r, LAW_KS], lawtab[r, r, LAW_TANPHI]
                    coh, ten, zeta = lawtab[r, r, LAW_COH], lawtab[r, r, LAW_TEN], lawtab[r, r, LAW_ZETA]
                # shear history of the point's record (above), turned onto the current plane
                found = rec[q]
                fd0, fd1, fd2 = 0.0, 0.0, 0.0  # the point's damping force last step
                e_open = 0.0  # its normal spring's energy if it opens now (_book_gone)
                if found >= 0:
                    us[0], us[1], us[2] = _onto_plane(us_old[slot, found, 0], us_old[slot, found, 1],
                                                      us_old[slot, found, 2], nrm[0], nrm[1], nrm[2])
                    bonded = bond_old[slot, found]
                    fd0, fd1, fd2 = fd_old[slot, found, 0], fd_old[slot, found, 1], fd_old[slot, found, 2]
                    e_open = 0.5 * fn_old[slot, found] * p_depth[q]
                else:
                    us[0] = 0.0
                    us[1] = 0.0
                    us[2] = 0.0
                    bonded = first_step and (coh > 0.0 or ten > 0.0)
                opens = p_depth[q] <= 0.0 and not bonded
                if opens and found < 0:
                    continue
                # velocity of B (= j) relative to A (= i) at the point (half-step velocities)
                for a in range(3):
                    vrel[a] = vel[j, a] - vel[i, a]
                if not static[j] and dof12[j]:
                    quat_matrix(quat[j], R)
                    point_velocity(j, p_pos[q], pos, R, strain, srate, wb, w)
                    for a in range(3):
                        vrel[a] += w[a]
                elif not static[j]:
                    if kin[j]:
                        w0, w1, w2 = wpres[j, 0], wpres[j, 1], wpres[j, 2]
                    else:
                        w0, w1, w2 = spin(j, quat, inertia, angmom)
                    c0, c1, c2 = _cross(w0, w1, w2, p_pos[q, 0] - pos[j, 0], p_pos[q, 1] - pos[j, 1],
                                        p_pos[q, 2] - pos[j, 2])
                    vrel[0] += c0
                    vrel[1] += c1
                    vrel[2] += c2
                if dof12[i]:
                    quat_matrix(quat[i], R)
                    point_velocity(i, p_pos[q], pos, R, strain, srate, wb, w)
                    for a in range(3):
                        vrel[a] -= w[a]
                elif not fixed[i]:
                    if kin[i]:
                        w0, w1, w2 = wpres[i, 0], wpres[i, 1], wpres[i, 2]
                    else:  # i is awake (pairs come from the moving blocks)
                        w0, w1, w2 = spin(i, quat, inertia, angmom)
                    c0, c1, c2 = _cross(w0, w1, w2, p_pos[q, 0] - pos[i, 0], p_pos[q, 1] - pos[i, 1],
                                        p_pos[q, 2] - pos[i, 2])
                    vrel[0] -= c0
                    vrel[1] -= c1
                    vrel[2] -= c2
                if opens:
                    # last step's point opens; its springs' and damping force's second halves (see below)
                    _book_gone(tally, e_open, kt, us, vrel[0], vrel[1], vrel[2], nrm, dt, fd0, fd1, fd2)
                    continue
                st, bonded, fn_el, ee, df, dd = point_force(kn, kt, tanphi, coh * apt, ten * apt, zeta * dsc, meff,
                                                            p_depth[q], nrm, vrel, dt, us, bonded, fpt)
                if zeta > 0.0 and st != 0:
                    # this point's nominal dashpots in its blocks' rates (dda/_contact.py: dashpot_scale)
                    cn = 2.0 * zeta * np.sqrt(kn * meff)
                    cs = 2.0 * zeta * np.sqrt(kt * meff) if st == 1 else 0.0
                    if not kin[i]:
                        add_dashpots(dsum, i, cn, cs, mass[i], inertia[i], quat[i], p_pos[q, 0] - pos[i, 0],
                                     p_pos[q, 1] - pos[i, 1], p_pos[q, 2] - pos[i, 2], nrm[0], nrm[1], nrm[2])
                    if not static[j] and not kin[j]:
                        add_dashpots(dsum, j, cn, cs, mass[j], inertia[j], quat[j], p_pos[q, 0] - pos[j, 0],
                                     p_pos[q, 1] - pos[j, 1], p_pos[q, 2] - pos[j, 2], nrm[0], nrm[1], nrm[2])
                tally[T_ELASTIC] += ee
                tally[T_FRICTION] += df
                # the work of a force in the product-form kinetic energy takes the half-step velocities on both
                # sides of its step, so each damping force is booked half with this step's velocity (dd / 2) and
                # half with the next one's (last step's force here)
                tally[T_DAMPING] += 0.5 * dd - 0.5 * dt * (fd0 * vrel[0] + fd1 * vrel[1] + fd2 * vrel[2])
                if st == 0:
                    if found >= 0:
                        # a bonded point that point_force found broken in tension: its normal spring's second half,
                        # as for a point that opens (_book_gone; its shear spring went with the friction)
                        tally[T_TURNOVER] += e_open
                    continue
                if found < 0 and not first_step:
                    # a new point: its normal spring holds 1/2 kn d^2 but took the work of half its force over this
                    # step's approach (d - d_before) only, the product-form pairing: the difference 1/2 fn d_before,
                    # d_before = d + vn dt, is booked as point turnover (created); for a natural first touch d_before
                    # <= 0, for a point that the contact polygon's change made (already deep) about 1/2 kn d^2
                    vn = vrel[0] * nrm[0] + vrel[1] * nrm[1] + vrel[2] * nrm[2]
                    tally[T_TURNOVER] -= 0.5 * fn_el * (p_depth[q] + vn * dt)
                if st == 2:
                    count[C_SLIDING] += 1
                if p_depth[q] > tally[T_MAXDEPTH]:
                    tally[T_MAXDEPTH] = p_depth[q]
                # the point force fpt on B, minus on A: forces, torques about the centroids, strain forces
                for a in range(3):
                    force[i, a] -= fpt[a]
                if not static[j]:
                    for a in range(3):
                        force[j, a] += fpt[a]
                    c0, c1, c2 = _cross(p_pos[q, 0] - pos[j, 0], p_pos[q, 1] - pos[j, 1], p_pos[q, 2] - pos[j, 2],
                                        fpt[0], fpt[1], fpt[2])
                    torque[j, 0] += c0
                    torque[j, 1] += c1
                    torque[j, 2] += c2
                c0, c1, c2 = _cross(p_pos[q, 0] - pos[i, 0], p_pos[q, 1] - pos[i, 1], p_pos[q, 2] - pos[i, 2],
                                    fpt[0], fpt[1], fpt[2])
                torque[i, 0] -= c0
                torque[i, 1] -= c1
                torque[i, 2] -= c2
                if dof12[i]:
                    quat_matrix(quat[i], R)
                    body_point(i, p_pos[q], pos, R, strain, X)
                    add_strain_force(i, X, R, fpt, -1.0, qs)
                if dof12[j] and not static[j]:
                    quat_matrix(quat[j], R)
                    body_point(j, p_pos[q], pos, R, strain, X)
                    add_strain_force(j, X, R, fpt, 1.0, qs)
                # this step's damping force at the point: the force less its springs' parts
                fd_new[s, kept, 0] = fpt[0] - fn_el * nrm[0] + kt * us[0]
                fd_new[s, kept, 1] = fpt[1] - fn_el * nrm[1] + kt * us[1]
                fd_new[s, kept, 2] = fpt[2] - fn_el * nrm[2] + kt * us[2]
                _store_point(pid_new, us_new, state_new, bond_new, pos_new, fn_new, depth_new, s, kept, us, st,
                             bonded, fn_el, p_pos, p_depth, p_id, q)
                kept += 1
        npt_new[s] = kept
        count[C_POINTS] += kept
        # last step's points of this pair that have no successor: they opened, or the contact polygon changed
        if slot >= 0:
            for r in range(npt_old[slot]):
                if not matched[r]:
                    _book_vanished(tally, i, j, fixed[i], static[j], pos_old[slot, r], depth_old[slot, r],
                                   fn_old[slot, r], us_old[slot, r], fd_old[slot, r], ks, nrm, dt, blocks)
        if sleep_on and kept > 0:
            moving_i = kin[i] or calm[i] == 0
            if not asleep[j]:
                if moving_i:
                    veto[j] = True
                if not static[j] and (kin[j] or calm[j] == 0):
                    veto[i] = True


@njit(cache=True)
def carry_resting(law, material, asleep, con, static, tally, count):
    """Contacts between resting bodies are carried over unchanged (shear history and elastic energy kept)."""
    old = con.cur[0]
    new = 1 - old
    kinds = len(law.face_row) > 0
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
                con.fd[new, s, q, a] = con.fd[old, s0, q, a]
                u2 += con.us[old, s0, q, a] ** 2
            if kinds:  # the point's own kn (its kind's row): fn = kn depth
                tally[T_ELASTIC] += 0.5 * con.fn[old, s0, q] * d0
            else:
                tally[T_ELASTIC] += 0.5 * kn0 * d0 * d0
            tally[T_ELASTIC] += 0.5 * ks0 * u2
        count[C_CONTACTS] += 1
        count[C_POINTS] += con.npt[old, s0]
