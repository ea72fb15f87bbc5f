"""numba kernels: the bond law of the sphere engine (one law for sphere-only and coupled sphere-block runs).

A bond is a normal spring kn_b on the change of the centre distance from its initial value (tension and
compression) and a shear spring ks_b on the incremental tangential displacement at the bond point; it breaks
when its tensile force would exceed its tensile strength or its shear force its shear strength; the energy
left in its springs is released (counted as dissipated) and the step it broke is recorded. Central bonds
(ks_b = 0, as LIGGGHTS' harmonic bonds) carry the normal spring alone (no shear force, no torque, no shear
breakage) and have a loop of their own over compact rows, so that a model of central bonds costs one normal
spring per bond. The bond state is one ``Bonds`` bundle (dda/_sphere_state.py). A bond that breaks joins the
pair list of a sphere-only run (``PairList``; a coupled run searches its pairs on a grid each step and passes
an empty list). The bonds run on all of numba's threads with results independent of their number: a pass
over the bonds writes each bond's force into a row of its own, a gather adds them to each sphere in a fixed
order (``bond_forces``).

Also here, for every sphere kernel: the hash of pair keys (bonds and smooth joints look their pairs up in it)
and the effective mass of a pair.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._sphere_state import B_FN, B_FS, B_FT, B_KN, B_KS, B_LEN, B_RATIO, B_US, B_ZETA, C_FT, C_KN, C_LEN, SCHUNK


@njit(cache=True)
def _hkey(key, mask):
    h = key * np.int64(0x9E3779B97F4A7C15 & 0x7FFFFFFFFFFFFFFF)
    h ^= h >> 29
    return h & mask


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


@njit(cache=True, inline="always")
def _list_broken(i, j, sp, pl):
    """A bond that broke: its pair joins the pair list as a contact (unless neither sphere moves; a full list
    raises the flag, and the caller rebuilds the list)."""
    if (sp.fixed[i] or sp.kin[i]) and (sp.fixed[j] or sp.kin[j]):
        return
    if pl.n[0] < pl.pairs.shape[0]:
        pl.pairs[pl.n[0], 0] = i
        pl.pairs[pl.n[0], 1] = j
        pl.n[0] += 1
    else:
        pl.flag[0] = 1


@njit(cache=True)
def sync_central(bonds):
    """Central bonds: the sign flag of ``cij`` (i stored as -1 - i while broken) from ``intact``."""
    CI = bonds.cij
    for q in range(bonds.cidx.shape[0]):
        i = CI[q, 0]
        if (i >= 0) != bonds.intact[bonds.cidx[q]]:
            CI[q, 0] = -1 - i
            bonds.cfn[q] = 0.0


@njit(cache=True)
def bond_forces(mo, sp, bonds, pl, dt, t, last, res):
    """The bonds' forces of one step on ``mo`` (Motion), breakage (into ``pl``); res[1] += released energy,
    res[2] += damping work. ``last``: write the central bonds' normal forces ``cfn``. Returns (elastic energy
    of the bonds, intact bonds, bonds broken).

    Both cores, the same bits for any number of threads and no atomics: ``bond_pass`` computes every bond once,
    chunk by chunk of SCHUNK spheres, the bonds of a sphere i in order: the force (and torque) each puts on its
    j into a row of its own (``fwork``, ``cwork``), their sums on i into the sphere's row (``fsum``, ``csum``);
    ``bond_gather`` then adds to each sphere's force, in a fixed order: its full bonds as j one by one
    (ascending), minus the sum of its own full bonds, its central bonds as j, minus the sum of its own central
    bonds. That is the order the serial loop over the bond list sorted by i (i < j) added them in, so the forces
    are those of that loop to the bit. The sums over bonds (energy, damping work) add the chunks' partial sums
    in chunk order; the broken bonds join the pair list and release their energy in bond order (``_broken``)."""
    if bonds.fwork.shape[0] == 0 and bonds.cwork.shape[0] == 0:
        return 0.0, 0, 0
    n = mo.x.shape[0]
    nch = (n + SCHUNK - 1) // SCHUNK
    part = np.zeros((nch, 4))
    bond_pass(mo, sp, bonds, dt, t, last, res[2], part)
    bond_gather(mo, bonds)
    e_bond = 0.0
    nint = 0
    nbroken = 0
    d = 0.0
    for c in range(nch):
        e_bond += part[c, 0]
        d += part[c, 1]
        nint += np.int64(part[c, 2])
        nbroken += np.int64(part[c, 3])
    res[2] = d
    if nbroken > 0:
        _broken(sp, bonds, pl, t, part, res)
    return e_bond, nint, nbroken


@njit(cache=True)
def _broken(sp, bonds, pl, t, part, res):
    """The bonds broken at time t, in the order of the full then the central list: their released energy into
    res[1], their pairs into the pair list (only the chunks that broke one are looked at)."""
    bi, bj, brk, intact, rel = bonds.i, bonds.j, bonds.brk, bonds.intact, bonds.rel
    n = sp.x.shape[0]
    for lst, start in ((bonds.full, bonds.fstart), (bonds.cidx, bonds.cstart)):
        for c in range(part.shape[0]):
            if part[c, 3] == 0.0:
                continue
            s0 = c * SCHUNK
            for p in range(start[s0], start[min(n, s0 + SCHUNK)]):
                k = lst[p]
                if brk[k] == t and not intact[k]:
                    res[1] += rel[k]
                    _list_broken(bi[k], bj[k], sp, pl)


@njit(cache=True, parallel=True)
def bond_pass(mo, sp, bonds, dt, t, last, d0, part):
    """Every bond once, in prange over chunks of SCHUNK spheres (the bonds whose i lies in the chunk):
    part[c] = (elastic energy, damping work (chunk 0 starting from d0), intact, broken) of chunk c."""
    n = mo.x.shape[0]
    for c in prange(part.shape[0]):
        s0 = c * SCHUNK
        s1 = min(n, s0 + SCHUNK)
        e, d, nint, nbroken = full_chunk(s0, s1, mo, sp, bonds, dt, t, d0 if c == 0 else 0.0)
        e, d, nint, nbroken = central_chunk(s0, s1, mo, sp, bonds, t, last, dt, e, d, nint, nbroken)
        part[c, 0] = e
        part[c, 1] = d
        part[c, 2] = nint
        part[c, 3] = nbroken


@njit(cache=True, parallel=True)
def bond_gather(mo, bonds):
    """Each sphere's bond forces and torques added to mo.force / mo.torque in the fixed order of bond_forces."""
    force, torque = mo.force, mo.torque
    fin_start, fin, fwork, fsum = bonds.fin_start, bonds.fin, bonds.fwork, bonds.fsum
    cin_start, cin, cwork, csum = bonds.cin_start, bonds.cin, bonds.cwork, bonds.csum
    nfull = fwork.shape[0]
    ncen = cwork.shape[0]
    for s in prange(force.shape[0]):
        f0 = force[s, 0]
        f1 = force[s, 1]
        f2 = force[s, 2]
        if nfull > 0:
            f0, f1, f2 = _gather(fin_start[s], fin_start[s + 1], fin, fwork, 0, f0, f1, f2, fsum, s)
            torque[s, 0], torque[s, 1], torque[s, 2] = _gather(fin_start[s], fin_start[s + 1], fin, fwork, 3,
                                                               torque[s, 0], torque[s, 1], torque[s, 2], fsum, s)
        if ncen > 0:
            f0, f1, f2 = _gather(cin_start[s], cin_start[s + 1], cin, cwork, 0, f0, f1, f2, csum, s)
        force[s, 0] = f0
        force[s, 1] = f1
        force[s, 2] = f2


@njit(cache=True, inline="always")
def _gather(lo, hi, rows, work, col, a0, a1, a2, sums, s):
    """(a0, a1, a2) plus the columns col:col + 3 of work's rows rows[lo:hi] one by one, minus sums[s, col:col + 3]."""
    for p in range(lo, hi):
        r = rows[p]
        a0 += work[r, col]
        a1 += work[r, col + 1]
        a2 += work[r, col + 2]
    return a0 - sums[s, col], a1 - sums[s, col + 1], a2 - sums[s, col + 2]


@njit(cache=True)
def full_chunk(s0, s1, mo, sp, bonds, dt, t, d):
    """The bonds with a shear spring whose i is one of the spheres s0:s1: their force and torque on j into
    ``fwork``, the sums over each sphere's own bonds into ``fsum`` (a bond not intact puts zeros); returns
    (elastic energy, damping work from d, intact, broken)."""
    X, V, W = mo.x, mo.v, mo.w
    BB, full, fstart, intact, bj = bonds.rows, bonds.full, bonds.fstart, bonds.intact, bonds.j
    fwork, fsum, brk, rel = bonds.fwork, bonds.fsum, bonds.brk, bonds.rel
    m, fixed, kin = sp.m, sp.fixed, sp.kin
    e_bond = 0.0
    nint = 0
    nbroken = 0
    for i in range(s0, s1):
        if fstart[i] == fstart[i + 1]:
            continue
        g0 = g1 = g2 = h0 = h1 = h2 = 0.0
        for kk in range(fstart[i], fstart[i + 1]):
            k = full[kk]
            if not intact[k]:
                for a in range(6):
                    fwork[kk, a] = 0.0
                continue
            j = bj[k]
            d0 = X[j, 0] - X[i, 0]
            d1 = X[j, 1] - X[i, 1]
            d2 = X[j, 2] - X[i, 2]
            dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            inv = 1.0 / dl
            nx = d0 * inv
            ny = d1 * inv
            nz = d2 * inv
            # bond point: between the surfaces, in proportion to the radii (B_RATIO = r_i / (r_i + r_j))
            # (arms: r_i = a0 n from i, r_j = aj n from j): relative velocity there
            # v_j + w_j x r_j - v_i - w_i x r_i = dv + (aj w_j - a0 w_i) x n, whose normal part is dv.n
            a0 = dl * BB[k, B_RATIO]
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
            u0 = BB[k, B_US]
            u1 = BB[k, B_US + 1]
            u2 = BB[k, B_US + 2]
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
            stretch = dl - BB[k, B_LEN]
            fn = BB[k, B_KN] * stretch  # tension > 0
            uu = u0 * u0 + u1 * u1 + u2 * u2
            if fn > BB[k, B_FT] or BB[k, B_KS] * BB[k, B_KS] * uu > BB[k, B_FS] * BB[k, B_FS]:  # ks |u| > fs
                # breaks: its spring energy (last step's) leaves the system (bond_forces books it and lists
                # the pair)
                intact[k] = False
                brk[k] = t
                BB[k, B_FN] = 0.0
                rel[k] = 0.5 * BB[k, B_KN] * stretch * stretch + 0.5 * BB[k, B_KS] * uu
                BB[k, B_US] = 0.0
                BB[k, B_US + 1] = 0.0
                BB[k, B_US + 2] = 0.0
                for a in range(6):
                    fwork[kk, a] = 0.0
                nbroken += 1
                continue
            nint += 1
            BB[k, B_US] = u0
            BB[k, B_US + 1] = u1
            BB[k, B_US + 2] = u2
            BB[k, B_FN] = fn
            e_bond += 0.5 * BB[k, B_KN] * stretch * stretch + 0.5 * BB[k, B_KS] * uu
            # force on j: -fn n - ks u (+ viscous damping on the normal and shear relative velocity)
            cdn = 0.0
            if BB[k, B_ZETA] > 0.0:
                meff = pair_meff(i, j, m, fixed, kin)
                cdn = 2.0 * BB[k, B_ZETA] * np.sqrt(BB[k, B_KN] * meff)
                cds = 2.0 * BB[k, B_ZETA] * np.sqrt(BB[k, B_KS] * meff)
                d += (cdn * vn * vn + cds * ((vr0 - vn * nx) ** 2 + (vr1 - vn * ny) ** 2
                                             + (vr2 - vn * nz) ** 2)) * dt
            else:
                cds = 0.0
            f0 = -(fn + cdn * vn) * nx - BB[k, B_KS] * u0 - cds * (vr0 - vn * nx)
            f1 = -(fn + cdn * vn) * ny - BB[k, B_KS] * u1 - cds * (vr1 - vn * ny)
            f2 = -(fn + cdn * vn) * nz - BB[k, B_KS] * u2 - cds * (vr2 - vn * nz)
            # torques: r_j x f = aj (n x f) on j, r_i x f = a0 (n x f) against i
            q0 = ny * f2 - nz * f1
            q1 = nz * f0 - nx * f2
            q2 = nx * f1 - ny * f0
            fwork[kk, 0] = f0
            fwork[kk, 1] = f1
            fwork[kk, 2] = f2
            fwork[kk, 3] = aj * q0
            fwork[kk, 4] = aj * q1
            fwork[kk, 5] = aj * q2
            g0 += f0
            g1 += f1
            g2 += f2
            h0 += a0 * q0
            h1 += a0 * q1
            h2 += a0 * q2
        fsum[i, 0] = g0
        fsum[i, 1] = g1
        fsum[i, 2] = g2
        fsum[i, 3] = h0
        fsum[i, 4] = h1
        fsum[i, 5] = h2
    return e_bond, d, nint, nbroken


@njit(cache=True)
def central_chunk(s0, s1, mo, sp, bonds, t, last, dt, e_bond, d, nint, nbroken):
    """The central bonds (ks = 0: the normal spring alone, force along the centre line, no torque) whose i is
    one of the spheres s0:s1: their force on j into ``cwork``, the sums over each sphere's own bonds into
    ``csum``. Adds to the running (elastic energy, damping work, intact, broken) and returns them."""
    X = mo.x
    V = mo.v
    CI = bonds.cij
    CB = bonds.crows
    cstart, cwork, csum, cfn, cidx = bonds.cstart, bonds.cwork, bonds.csum, bonds.cfn, bonds.cidx
    czeta = bonds.czeta
    cdamped = czeta.shape[0] > 0
    m, fixed, kin = sp.m, sp.fixed, sp.kin
    for s in range(s0, s1):
        if cstart[s] == cstart[s + 1]:
            continue
        g0 = g1 = g2 = 0.0
        for q in range(cstart[s], cstart[s + 1]):
            i = CI[q, 0]
            if i < 0:
                cwork[q, 0] = 0.0
                cwork[q, 1] = 0.0
                cwork[q, 2] = 0.0
                continue
            j = CI[q, 1]
            d0 = X[j, 0] - X[i, 0]
            d1 = X[j, 1] - X[i, 1]
            d2 = X[j, 2] - X[i, 2]
            dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            stretch = dl - CB[q, C_LEN]
            fn = CB[q, C_KN] * stretch  # tension > 0
            if fn > CB[q, C_FT]:
                k = cidx[q]
                CI[q, 0] = -1 - i
                bonds.intact[k] = False
                bonds.brk[k] = t
                bonds.rows[k, B_FN] = 0.0
                cfn[q] = 0.0
                bonds.rel[k] = 0.5 * CB[q, C_KN] * stretch * stretch
                cwork[q, 0] = 0.0
                cwork[q, 1] = 0.0
                cwork[q, 2] = 0.0
                nbroken += 1
                continue
            nint += 1
            if last:
                cfn[q] = fn
            e_bond += 0.5 * CB[q, C_KN] * stretch * stretch
            # force on j: -(fn + cdn vn) n, n = d / dl
            sf = fn
            if cdamped and czeta[q] > 0.0:
                inv = 1.0 / dl
                vn = ((V[j, 0] - V[i, 0]) * d0 + (V[j, 1] - V[i, 1]) * d1 + (V[j, 2] - V[i, 2]) * d2) * inv
                meff = pair_meff(i, j, m, fixed, kin)
                cdn = 2.0 * czeta[q] * np.sqrt(CB[q, C_KN] * meff)
                d += cdn * vn * vn * dt
                sf += cdn * vn
            sf = -sf / dl
            f0 = sf * d0
            f1 = sf * d1
            f2 = sf * d2
            cwork[q, 0] = f0
            cwork[q, 1] = f1
            cwork[q, 2] = f2
            g0 += f0
            g1 += f1
            g2 += f2
        csum[s, 0] = g0
        csum[s, 1] = g1
        csum[s, 2] = g2
    return e_bond, d, nint, nbroken
