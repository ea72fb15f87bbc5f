"""Deformable DDA blocks (12 DOF): block matrices against an independent quadrature and analytical modes."""
import math

import numpy as np
import pytest
from scipy.linalg import eigh

from dda._deform import mass_matrix, stiffness_matrix, t_matrix
from dda.polyhedra import mass_properties

# tetrahedron quadrature exact for polynomials of degree 2 (4 points, weights 1/4)
_A, _B = 0.5854101966249685, 0.1381966011250105


def _quad_mass(v, faces, rho):
    """rho int T^T T dV by splitting into tetrahedra (centroid + face triangles) with a degree-2 rule."""
    c = mass_properties(v, faces).centroid
    M = np.zeros((12, 12))
    for f in faces:
        for a, b in zip(f[1:-1], f[2:]):
            P = np.array([c, v[f[0]], v[a], v[b]])
            vol = abs(np.linalg.det(np.array([P[1] - P[0], P[2] - P[0], P[3] - P[0]]))) / 6
            for k in range(4):
                bary = np.full(4, _B)
                bary[k] = _A
                x = bary @ P - c
                T = t_matrix(x)
                M += rho * vol / 4 * T.T @ T
    return M


def _cube(a):
    v = np.array([[0, 0, 0], [a, 0, 0], [a, a, 0], [0, a, 0], [0, 0, a], [a, 0, a], [a, a, a], [0, a, a]], float)
    f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return v, f


def _tetra():
    v = np.array([[0.1, 0.2, 0.0], [1.3, 0.1, 0.2], [0.4, 1.1, 0.3], [0.5, 0.4, 1.7]], float)
    f = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    return v, f


@pytest.mark.parametrize("shape", [_cube(0.7), _tetra()])
def test_mass_matrix_matches_an_independent_quadrature(shape):
    v, f = shape
    M = mass_matrix(v, f, 2500.0)
    Q = _quad_mass(v, f, 2500.0)
    assert np.allclose(M, Q, rtol=1e-10, atol=1e-10 * np.abs(Q).max())
    assert np.allclose(M, M.T)
    assert np.all(np.linalg.eigvalsh(M) > 0)


def test_free_cube_modes_have_the_analytical_frequencies():
    # constant-strain modes of a free cube of side a: omega^2 = 36 K / (rho a^2) (volumetric, K the bulk
    # modulus) once and 24 G / (rho a^2) five times (two deviatoric normal, three shear); six rigid modes at 0
    a, rho, E, nu = 0.8, 2600.0, 1e9, 0.25
    v, f = _cube(a)
    M = mass_matrix(v, f, rho)
    K = stiffness_matrix(a ** 3, E, nu)
    w2 = np.sort(eigh(K, M, eigvals_only=True))
    Kb = E / (3 * (1 - 2 * nu))
    G = E / (2 * (1 + nu))
    ref = np.sort([0.0] * 6 + [24 * G / (rho * a * a)] * 5 + [36 * Kb / (rho * a * a)])
    assert np.allclose(w2, ref, rtol=1e-10, atol=1e-6 * ref.max())
    assert math.isclose(w2[-1], 36 * Kb / (rho * a * a), rel_tol=1e-10)
