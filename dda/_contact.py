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
"""
from __future__ import annotations

import numpy as np
from numba import njit

OPEN, LOCKED, SLIDING = 0, 1, 2


@njit(cache=True, inline="always")
def local_damping(alpha, f, v):
    """Cundall's local damping of a force (torque) component f on a body moving at v along it: alpha |f| with
    the sign of v (0 for v = 0), to be taken from f."""
    if v == 0.0:
        return 0.0
    return alpha * abs(f) * (1.0 if v > 0 else -1.0)


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
