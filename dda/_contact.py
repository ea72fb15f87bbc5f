"""numba kernel: the contact law at one contact point.

Penalty normal spring kn and shear spring ks (per contact point), Mohr-Coulomb strength with cohesion and
tensile strength (given here as forces: the material values times the point's share of the contact area),
viscous contact damping on the normal relative velocity (ratio `zeta` of critical for kn and the pair's
effective mass) and, on locked points, on the shear relative velocity (the same ratio for ks). The elastic shear displacement ``us`` is stored per point and updated incrementally.

States: 0 open (no force), 1 locked (elastic shear), 2 sliding (shear at the Coulomb limit).
A point is ``bonded`` while its cohesion and tensile strength are intact; the first failure (tension beyond
the tensile strength or shear beyond the cohesive limit) breaks it for good. When a point opens, the energy
left in its shear spring is released and counted with the friction dissipation (it leaves the system).
``point_force`` is inlined where it is called, as dda/_kinematics.py's kernels are (see there why).

An explicit dashpot turns a velocity back when dt c / m > 1 and blows up past 2 (with local damping alpha the
step's force acts as (1 + alpha) of it in that mode). The dashpots of a block add up: a thin slab on twenty points
turning about its length, where its inertia is small, met dt c / I ~ 1.5 at zeta = 0.1 and, with local damping
0.5, rang at the step's own frequency (its velocity turned each step, the dashpots' clamp at zero normal force
bounding the cycle). So each step adds every point's dashpots to its blocks' rate matrices M^-1/2 C M^-1/2
(add_dashpots, 6 x 6 in the body frame), and where dt (1 + alpha) times the largest eigenvalue exceeds 1 the
block's dashpots are scaled down to 1 the next step (dashpot_scale): they may stop a block's motion in one step,
never turn it back. Elsewhere they stay as they are (the scale is exactly 1).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._kinematics import rotation

OPEN, LOCKED, SLIDING = 0, 1, 2


@njit(cache=True, inline="always")
def local_damping(alpha, f, v):
    """Cundall's local damping of a force (torque) component f on a body moving at v along it: alpha |f| with
    the sign of v (0 for v = 0), to be taken from f."""
    if v == 0.0:
        return 0.0
    return alpha * abs(f) * (1.0 if v > 0 else -1.0)


@njit(cache=True, inline="always")
def _rank1(S, i, c, b0, b1, b2, b3, b4, b5):
    """S[i] += c b b^T, S[i] the upper triangle of a symmetric 6 x 6 matrix, row by row (21 entries)."""
    S[i, 0] += c * b0 * b0
    S[i, 1] += c * b0 * b1
    S[i, 2] += c * b0 * b2
    S[i, 3] += c * b0 * b3
    S[i, 4] += c * b0 * b4
    S[i, 5] += c * b0 * b5
    S[i, 6] += c * b1 * b1
    S[i, 7] += c * b1 * b2
    S[i, 8] += c * b1 * b3
    S[i, 9] += c * b1 * b4
    S[i, 10] += c * b1 * b5
    S[i, 11] += c * b2 * b2
    S[i, 12] += c * b2 * b3
    S[i, 13] += c * b2 * b4
    S[i, 14] += c * b2 * b5
    S[i, 15] += c * b3 * b3
    S[i, 16] += c * b3 * b4
    S[i, 17] += c * b3 * b5
    S[i, 18] += c * b4 * b4
    S[i, 19] += c * b4 * b5
    S[i, 20] += c * b5 * b5


@njit(cache=True, inline="always")
def _direction(S, i, c, u0, u1, u2, x0, x1, x2, sm, s0, s1, s2):
    """A dashpot c along the body-frame unit vector u at the body-frame arm x: S[i] += c b b^T, b = M^-1/2 [u; x
    cross u] (sm = m^-1/2, s = I^-1/2 per principal axis)."""
    _rank1(S, i, c, u0 * sm, u1 * sm, u2 * sm, (x1 * u2 - x2 * u1) * s0, (x2 * u0 - x0 * u2) * s1,
           (x0 * u1 - x1 * u0) * s2)


@njit(cache=True, inline="always")
def add_dashpots(S, i, cn, cs, m, inertia, q, r0, r1, r2, n0, n1, n2):
    """Add a point's dashpots (cn along the normal n, cs across it; world arm r from block i's centroid, block
    orientation q, mass m, principal inertia `inertia`) to S[i], the rate M^-1/2 C M^-1/2 of block i's dashpots
    in its body frame (6 x 6, upper triangle)."""
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = rotation(q[0], q[1], q[2], q[3])
    # body-frame arm and normal (R^T x)
    x0 = R00 * r0 + R10 * r1 + R20 * r2
    x1 = R01 * r0 + R11 * r1 + R21 * r2
    x2 = R02 * r0 + R12 * r1 + R22 * r2
    m0 = R00 * n0 + R10 * n1 + R20 * n2
    m1 = R01 * n0 + R11 * n1 + R21 * n2
    m2 = R02 * n0 + R12 * n1 + R22 * n2
    sm = 1.0 / np.sqrt(m)
    s0 = 1.0 / np.sqrt(inertia[0])
    s1 = 1.0 / np.sqrt(inertia[1])
    s2 = 1.0 / np.sqrt(inertia[2])
    # cs in every direction (the three body axes), cn - cs more along the normal
    if cs > 0.0:
        _direction(S, i, cs, 1.0, 0.0, 0.0, x0, x1, x2, sm, s0, s1, s2)
        _direction(S, i, cs, 0.0, 1.0, 0.0, x0, x1, x2, sm, s0, s1, s2)
        _direction(S, i, cs, 0.0, 0.0, 1.0, x0, x1, x2, sm, s0, s1, s2)
    _direction(S, i, cn - cs, m0, m1, m2, x0, x1, x2, sm, s0, s1, s2)


@njit(cache=True)
def _largest_eigenvalue(S, i):
    """The largest eigenvalue of the symmetric positive semi-definite 6 x 6 matrix S[i] (upper triangle): power
    iteration from a vector with no symmetry (not orthogonal to the modes of symmetric blocks), its Rayleigh
    quotient (from below; additions, products, divisions and square roots only, the same bits on every CPU)."""
    A = np.empty((6, 6))
    k = 0
    for a in range(6):
        for b in range(a, 6):
            A[a, b] = S[i, k]
            A[b, a] = S[i, k]
            k += 1
    v = np.array([1.0, 0.83, 0.71, 0.59, 0.47, 0.37])
    w = np.empty(6)
    lam = 0.0
    for _ in range(100):
        nv = 0.0
        for a in range(6):
            t = 0.0
            for b in range(6):
                t += A[a, b] * v[b]
            w[a] = t
            nv += t * t
        if nv == 0.0:
            return 0.0
        vv = 0.0
        vw = 0.0
        for a in range(6):
            vv += v[a] * v[a]
            vw += v[a] * w[a]
        lam = vw / vv
        nv = np.sqrt(nv)
        for a in range(6):
            v[a] = w[a] / nv
    return lam


@njit(cache=True, inline="always")
def dashpot_scale(S, i, dt, alpha):
    """The scale of block i's dashpots for the next step from this step's sums S[i] (add_dashpots), which it
    clears: 1, or 1 / (dt (1 + alpha) lambda_max) where that exceeds 1 (the module docstring). lambda_max is bounded
    first by the smaller of the trace and the largest absolute row sum; only where that bound exceeds
    1 / (dt (1 + alpha)) is it found (_largest_eigenvalue)."""
    tr = S[i, 0] + S[i, 6] + S[i, 11] + S[i, 15] + S[i, 18] + S[i, 20]
    lim = 1.0 / (dt * (1.0 + alpha))
    x = 1.0
    if tr > lim:
        g = 0.0
        for a in range(6):
            row = 0.0
            for b in range(6):
                lo, hi = (a, b) if a <= b else (b, a)
                row += abs(S[i, lo * 6 - lo * (lo - 1) // 2 + hi - lo])
            g = max(g, row)
        if g > lim:
            lam = _largest_eigenvalue(S, i)
            if lam > lim:
                x = lim / lam
    for a in range(21):
        S[i, a] = 0.0
    return x


@njit(cache=True, inline="always")
def point_force(kn, ks, tanphi, coh_force, ten_force, zeta, meff, depth, n, vrel, dt, us, bonded, out_f):
    """Force on block B (A -> B normal n) at one point. Updates us in place.

    Returns (state, bonded, fn_elastic, elastic_energy, friction_dissipation, damping_dissipation)."""
    fn_el = kn * depth
    if fn_el < 0.0:
        if not bonded or -fn_el > ten_force:
            # the point opens: the energy left in its shear spring is released (counted as dissipated)
            rel = 0.5 * ks * (us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
            us[0] = 0.0
            us[1] = 0.0
            us[2] = 0.0
            out_f[0] = 0.0
            out_f[1] = 0.0
            out_f[2] = 0.0
            return OPEN, False, 0.0, 0.0, rel, 0.0
    vn = vrel[0] * n[0] + vrel[1] * n[1] + vrel[2] * n[2]
    fd = -2.0 * zeta * np.sqrt(kn * meff) * vn if zeta > 0.0 else 0.0
    if not bonded and fn_el + fd < 0.0:
        fd = -fn_el
    # shear: elastic shear displacement of B relative to A (u0: last step's)
    u00, u01, u02 = us[0], us[1], us[2]
    for a in range(3):
        us[a] += (vrel[a] - vn * n[a]) * dt
    fs0 = -ks * us[0]
    fs1 = -ks * us[1]
    fs2 = -ks * us[2]
    fsm = np.sqrt(fs0 * fs0 + fs1 * fs1 + fs2 * fs2)
    fmax = tanphi * max(fn_el, 0.0)
    if bonded:
        fmax += coh_force
    state = LOCKED
    diss = 0.0
    if fsm > fmax:
        if bonded:
            bonded = False
            fmax = tanphi * max(fn_el, 0.0)
            if fn_el < 0.0:
                rel = 0.5 * ks * (us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
                us[0] = 0.0
                us[1] = 0.0
                us[2] = 0.0
                out_f[0] = 0.0
                out_f[1] = 0.0
                out_f[2] = 0.0
                return OPEN, False, 0.0, 0.0, rel, 0.0
        state = SLIDING
        scale = fmax / fsm
        # the trial displacement t = us is cut back to scale t: the spring took the work of its mean force over
        # the increment, 1/2 ks (u0 + scale t).(t - u0), and keeps 1/2 ks scale^2 t^2 of it (the same
        # product-form pairing of forces and half-step velocities as the kinetic energy's; fmax (fsm - fmax) / ks
        # holds only while the limit stays put, and misses what a falling limit takes, e.g. as a point unloads)
        tu = us[0] * u00 + us[1] * u01 + us[2] * u02
        diss = 0.5 * ks * (1.0 - scale) * (scale * (us[0] * us[0] + us[1] * us[1] + us[2] * us[2]) + tu)
        fs0 *= scale
        fs1 *= scale
        fs2 *= scale
        us[0] *= scale
        us[1] *= scale
        us[2] *= scale
    fnt = fn_el + fd
    d_damp = -fd * vn * dt
    if state == LOCKED and zeta > 0.0:
        # shear damping on locked points (a sliding point is held at the Coulomb limit)
        cs = 2.0 * zeta * np.sqrt(ks * meff)
        for a in range(3):
            vt = vrel[a] - vn * n[a]
            d_damp += cs * vt * vt * dt
        fs0 -= cs * (vrel[0] - vn * n[0])
        fs1 -= cs * (vrel[1] - vn * n[1])
        fs2 -= cs * (vrel[2] - vn * n[2])
    out_f[0] = fnt * n[0] + fs0
    out_f[1] = fnt * n[1] + fs1
    out_f[2] = fnt * n[2] + fs2
    e_el = 0.5 * kn * depth * depth + 0.5 * ks * (us[0] * us[0] + us[1] * us[1] + us[2] * us[2])
    return state, bonded, fn_el, e_el, diss, d_damp
