"""Deformable DDA blocks: the first-order displacement function and its block matrices (12 DOF).

Unknowns of block i: D = (u0, v0, w0, rx, ry, rz, ex, ey, ez, gyz, gzx, gxy): the centroid translation, the
small rotation about the centroid and the six constant strains (engineering shear strains). A point x of the
block (x0 the centroid, (x, y, z) = x - x0) moves by u = T(x) D with

    T = [[1, 0, 0,  0,  z, -y,  x, 0, 0,  0,   z/2, y/2],
         [0, 1, 0, -z,  0,  x,  0, y, 0,  z/2, 0,   x/2],
         [0, 0, 1,  y, -x,  0,  0, 0, z,  y/2, x/2, 0  ]]

Mass matrix M = rho int T^T T dV, exact for a polyhedron from its volume and second moments about the centroid
(T is linear in x, so only int 1 and int x_k x_l appear; int x_k = 0 about the centroid). Elastic stiffness:
the strain energy V/2 e^T C e with C the isotropic elastic matrix (E, nu) for engineering strains, so K has
V C in its strain block. A point force f at x adds T(x)^T f to the generalized force.

These matrices are built once per block (numpy); the time loop's use of them is not written yet.
"""
from __future__ import annotations

import numpy as np

from .polyhedra import mass_properties


def t_matrix(x):
    """T(x) (3 x 12) for a point at offset x from the centroid."""
    x, y, z = (float(c) for c in x)
    return np.array([
        [1, 0, 0, 0, z, -y, x, 0, 0, 0, z / 2, y / 2],
        [0, 1, 0, -z, 0, x, 0, y, 0, z / 2, 0, x / 2],
        [0, 0, 1, y, -x, 0, 0, 0, z, y / 2, x / 2, 0],
    ], float)


def elastic_matrix(E, nu):
    """Isotropic 6 x 6 stress-strain matrix for (ex, ey, ez, gyz, gzx, gxy) (engineering shear strains)."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    G = E / (2 * (1 + nu))
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[:3, :3] += 2 * G * np.eye(3)
    C[3:, 3:] = G * np.eye(3)
    return C


def second_moments(vertices, faces):
    """(volume, centroid, S) with S_kl = int (x_k - c_k)(x_l - c_l) dV (exact)."""
    mp = mass_properties(vertices, faces)
    Ic = mp.inertia  # unit density: I = tr(S) 1 - S, so tr(I) = 2 tr(S)
    S = 0.5 * np.trace(Ic) * np.eye(3) - Ic
    return mp.volume, mp.centroid, S


def mass_matrix(vertices, faces, density):
    """12 x 12 mass matrix rho int T^T T dV of a polyhedral block (exact)."""
    vol, _, S = second_moments(vertices, faces)
    T0 = t_matrix((0.0, 0.0, 0.0))
    Tk = [t_matrix(e) - T0 for e in np.eye(3)]  # T(x) = T0 + sum_k x_k Tk
    M = vol * T0.T @ T0
    for k in range(3):
        for l in range(3):
            M += S[k, l] * Tk[k].T @ Tk[l]
    return density * M


def stiffness_matrix(volume, E, nu):
    """12 x 12 elastic stiffness of a block (V C in the strain block)."""
    K = np.zeros((12, 12))
    K[6:, 6:] = volume * elastic_matrix(E, nu)
    return K


__all__ = ["t_matrix", "elastic_matrix", "second_moments", "mass_matrix", "stiffness_matrix"]
