"""The stable time step of a sphere run, as a pure function of the spheres, their bonds and the contact law.

``sphere_critical_dt`` is the computation of ``dda.spheres.SphereSimulation.critical_dt`` for spheres without
walls, written on plain arrays so that a run description (adapters.spec.SphereRun) gets its time step without
building the engine: the same operations in the same order, so the step is the same to the last bit.

The stiffest sphere decides: each sphere is held by four contacts of stiffness max(kn, 3.5 ks) (the shear spring
counted with the rotational factor 1 + 1 / (2/5); four contacts also bound the rotation of spheres on central
bonds, ks = 0) plus its bonds, max(bond_kn, 3.5 bond_ks) each; two bodies on one spring give omega^2 = 2 K / m;
viscous damping zeta (the largest of the contact law's and the bonds') shortens the step:
dt = 2 / omega (sqrt(1 + zeta^2) - zeta). A run without free spheres has dt_crit = 1.
"""
from __future__ import annotations

import numpy as np


def sphere_mass(radii, density):
    """Mass of each sphere [kg] (the expression of dda.spheres.SphereSet, for identical bits)."""
    return density * 4.0 / 3.0 * np.pi * np.asarray(radii, float) ** 3


def sphere_critical_dt(mass, free, kn, ks, zeta, bond_i, bond_j, bond_kn, bond_ks, bond_zeta):
    """Critical time step [s] of spheres of `mass` (n,) of which `free` (n,) bool move, under the contact law
    (`kn`, `ks` [N/m], viscous damping ratio `zeta`) and the bonds (`bond_i`, `bond_j` int arrays, `bond_kn`,
    `bond_ks` [N/m], `bond_zeta`); 1.0 when no sphere is free."""
    free = np.asarray(free, bool)
    if not free.any():
        return 1.0
    n = len(mass)
    K = np.full(n, 4.0 * max(kn, 3.5 * ks))
    if len(bond_i):
        kb = np.maximum(bond_kn, 3.5 * bond_ks)
        K += np.bincount(bond_i, kb, n) + np.bincount(bond_j, kb, n)
    zeta = max(float(zeta), float(np.max(bond_zeta)) if len(bond_i) else 0.0)
    om = np.sqrt(2.0 * K[free] / mass[free])
    return float((2.0 / om * (np.sqrt(1.0 + zeta * zeta) - zeta)).min())


__all__ = ["sphere_critical_dt", "sphere_mass"]
