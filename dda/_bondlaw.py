"""numba kernels: the bond law of the sphere engine (one law for sphere-only and coupled sphere-block runs).

A bond is a normal spring kn_b on the change of the centre distance from its initial value (tension and
compression) and a shear spring ks_b on the incremental tangential displacement at the bond point; it breaks
when its tensile force would exceed its tensile strength or its shear force its shear strength; the energy
left in its springs is released (counted as dissipated) and the step it broke is recorded. Central bonds
(ks_b = 0, as LIGGGHTS' harmonic bonds) carry the normal spring alone (no shear force, no torque, no shear
breakage) and have a loop of their own over compact rows, so that a model of central bonds costs one normal
spring per bond. The bond state is one ``Bonds`` bundle (dda/_sphere_state.py). A bond that breaks joins the
pair list of a sphere-only run (``PairList``; a coupled run searches its pairs on a grid each step and passes
an empty list).

Also here, for every sphere kernel: the hash of pair keys (bonds and smooth joints look their pairs up in it)
and the effective mass of a pair.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._sphere_state import B_FN, B_FS, B_FT, B_KN, B_KS, B_LEN, B_RATIO, B_US, B_ZETA, C_FT, C_KN, C_LEN


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
    of the bonds, intact bonds, bonds broken)."""
    e_bond, nint, nbroken = full_bonds(mo, sp, bonds, pl, dt, t, res)
    return central_bonds(mo, sp, bonds, pl, dt, t, last, res, e_bond, nint, nbroken)


@njit(cache=True)
def full_bonds(mo, sp, bonds, pl, dt, t, res):
    """The bonds with a shear spring (``bonds.full``); returns (elastic energy, intact, broken)."""
    X, V, W, force, torque = mo.x, mo.v, mo.w, mo.force, mo.torque
    BB, full, intact, bi, bj = bonds.rows, bonds.full, bonds.intact, bonds.i, bonds.j
    m, fixed, kin = sp.m, sp.fixed, sp.kin
    e_bond = 0.0
    nint = 0
    nbroken = 0
    # the reaction on sphere i is summed over its consecutive bonds (the list is sorted by i) before it is
    # added to its row
    ci = -1
    g0 = g1 = g2 = h0 = h1 = h2 = 0.0
    for kk in range(full.shape[0]):
        k = full[kk]
        if not intact[k]:
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
            # breaks: its spring energy (last step's) leaves the system; the pair joins the pair list
            intact[k] = False
            bonds.brk[k] = t
            BB[k, B_FN] = 0.0
            res[1] += 0.5 * BB[k, B_KN] * stretch * stretch + 0.5 * BB[k, B_KS] * uu
            BB[k, B_US] = 0.0
            BB[k, B_US + 1] = 0.0
            BB[k, B_US + 2] = 0.0
            nbroken += 1
            _list_broken(i, j, sp, pl)
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
            res[2] += (cdn * vn * vn + cds * ((vr0 - vn * nx) ** 2 + (vr1 - vn * ny) ** 2
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
    return e_bond, nint, nbroken


@njit(cache=True)
def central_bonds(mo, sp, bonds, pl, dt, t, last, res, e_bond, nint, nbroken):
    """The central bonds (ks = 0): the normal spring alone, force along the centre line, no torque. Adds to
    the running (elastic energy, intact, broken) and returns them."""
    X = mo.x
    V = mo.v
    force = mo.force
    CI = bonds.cij
    CB = bonds.crows
    czeta = bonds.czeta
    cdamped = czeta.shape[0] > 0
    ci = -1
    g0 = g1 = g2 = 0.0
    for q in range(bonds.cidx.shape[0]):
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
        stretch = dl - CB[q, C_LEN]
        fn = CB[q, C_KN] * stretch  # tension > 0
        if fn > CB[q, C_FT]:
            k = bonds.cidx[q]
            CI[q, 0] = -1 - i
            bonds.intact[k] = False
            bonds.brk[k] = t
            bonds.rows[k, B_FN] = 0.0
            bonds.cfn[q] = 0.0
            res[1] += 0.5 * CB[q, C_KN] * stretch * stretch
            nbroken += 1
            _list_broken(i, j, sp, pl)
            continue
        nint += 1
        if last:
            bonds.cfn[q] = fn
        e_bond += 0.5 * CB[q, C_KN] * stretch * stretch
        # force on j: -(fn + cdn vn) n, n = d / dl
        s = fn
        if cdamped and czeta[q] > 0.0:
            inv = 1.0 / dl
            vn = ((V[j, 0] - V[i, 0]) * d0 + (V[j, 1] - V[i, 1]) * d1 + (V[j, 2] - V[i, 2]) * d2) * inv
            meff = pair_meff(i, j, sp.m, sp.fixed, sp.kin)
            cdn = 2.0 * czeta[q] * np.sqrt(CB[q, C_KN] * meff)
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
    return e_bond, nint, nbroken
