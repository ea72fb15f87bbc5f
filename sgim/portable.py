"""Arithmetic that gives the same bits on every x86-64 CPU.

The project's kernels that decide topology or membership (which side of a plane a sphere centre lies on,
which features of two blocks touch, which blocks a cut makes) must give the same answer on every machine.
IEEE-754 makes +, -, *, / and sqrt correctly rounded everywhere (numpy's element-wise operations too), and
numba kernels compiled without fast-math keep the order of operations as written (no fused multiply-add, no
reassociation), so such code is bit-reproducible. Three things are not, and are kept out of every value that
feeds a decision:

- BLAS and LAPACK (numpy's ``@``, ``np.dot``, ``np.linalg.det`` / ``eigh`` / ``inv``, and
  ``np.linalg.norm`` of a 1-D array, which calls ``dot``): OpenBLAS picks a kernel per CPU (with or
  without FMA, other blockings), so the last bits differ between machines;
- numpy's transcendental functions (``np.sin``, ``np.exp``, ...), which use other SIMD code paths on CPUs
  with AVX-512;
- numba kernels compiled with fast-math (``contract`` allows FMA where the CPU has it, ``reassoc`` lets
  the vectoriser reorder sums by the CPU's vector width).

This module holds the small pieces of linear algebra and trigonometry that the geometry needs, written so
that only correctly rounded operations (and, for the angles, the C library's ``sin`` / ``cos`` of a reduced
argument, with exact values at multiples of 30 and 45 degrees) decide their results. docs/ARCHITECTURE.md
("Same answer on every CPU") lists which kernels may use fast-math and why.
"""
from __future__ import annotations

import math

import numpy as np


def det3(a) -> float:
    """Determinant of a 3 x 3 matrix (cofactor expansion along the first row)."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = (tuple(map(float, row)) for row in np.asarray(a))
    return (a00 * (a11 * a22 - a12 * a21)
            - a01 * (a10 * a22 - a12 * a20)
            + a02 * (a10 * a21 - a11 * a20))


def matmul(a, b):
    """a @ b for 1-D or 2-D float arrays without BLAS: the products of each inner index are added in index
    order with numpy's element-wise operations (correctly rounded on every CPU)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    a2 = a.reshape(1, -1) if a.ndim == 1 else a
    b2 = b.reshape(-1, 1) if b.ndim == 1 else b
    if a2.shape[1] != b2.shape[0]:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not match")
    out = np.zeros((a2.shape[0], b2.shape[1]))
    for k in range(a2.shape[1]):
        out += a2[:, k, None] * b2[None, k, :]
    if a.ndim == 1 and b.ndim == 1:
        return float(out[0, 0])
    if a.ndim == 1:
        return out[0]
    if b.ndim == 1:
        return out[:, 0]
    return out


def norm(x) -> float:
    """Euclidean length of a vector, summed in index order (np.linalg.norm of a 1-D array calls BLAS dot)."""
    s = 0.0
    for c in np.asarray(x, float).ravel():
        s += float(c) * float(c)
    return math.sqrt(s)


def each(f, x) -> np.ndarray:
    """f (a function of the math module: the C library's, whatever numpy's SIMD dispatch would pick) applied
    to every element of x; for the small arrays of geometry set-up (mesh sections, profiles)."""
    x = np.asarray(x, float)
    return np.array([f(float(v)) for v in x.ravel()], float).reshape(x.shape)


def each2(f, x, y) -> np.ndarray:
    """f(x, y) of the math module element by element (``each`` for two arguments, e.g. math.atan2)."""
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    return np.array([f(float(a), float(b)) for a, b in zip(x.ravel(), y.ravel())], float).reshape(x.shape)


def _jacobi(s):
    """Eigenvalues and eigenvectors (columns) of a symmetric n x n matrix by cyclic Jacobi rotations in a
    fixed order (plain floats, correctly rounded operations only)."""
    n = len(s)
    a = [[float(s[i][j]) for j in range(n)] for i in range(n)]
    vec = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    scale = sum(abs(a[i][j]) for i in range(n) for j in range(i, n))
    pairs = [(p, q) for p in range(n - 1) for q in range(p + 1, n)]
    for _sweep in range(64):
        off = sum(abs(a[p][q]) for p, q in pairs)
        if off <= 1e-300 or off <= 1e-18 * scale:
            break
        for p, q in pairs:
            apq = a[p][q]
            if apq == 0.0:
                continue
            theta = (a[q][q] - a[p][p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / math.sqrt(t * t + 1.0)
            sn = t * c
            for k in range(n):  # A <- A J (columns p, q)
                akp, akq = a[k][p], a[k][q]
                a[k][p] = c * akp - sn * akq
                a[k][q] = sn * akp + c * akq
            for k in range(n):  # A <- J^T A (rows p, q)
                apk, aqk = a[p][k], a[q][k]
                a[p][k] = c * apk - sn * aqk
                a[q][k] = sn * apk + c * aqk
            a[p][q] = a[q][p] = 0.0
            for k in range(n):
                vkp, vkq = vec[k][p], vec[k][q]
                vec[k][p] = c * vkp - sn * vkq
                vec[k][q] = sn * vkp + c * vkq
    return np.array([a[i][i] for i in range(n)]), np.array(vec)


def eigvalsh(s) -> np.ndarray:
    """Eigenvalues (ascending) of a symmetric matrix, the same bits on every CPU (np.linalg.eigvalsh calls
    LAPACK)."""
    s = np.asarray(s, float)
    return np.sort(_jacobi(0.5 * (s + s.T))[0])


def cholesky(a) -> np.ndarray:
    """Lower-triangular L with L L^T = a (a symmetric positive definite), summed in index order."""
    a = np.asarray(a, float)
    n = len(a)
    low = np.zeros((n, n))
    for j in range(n):
        d = float(a[j, j])
        for k in range(j):
            d -= float(low[j, k]) * float(low[j, k])
        if not d > 0.0:
            raise ValueError("cholesky: the matrix is not positive definite")
        low[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            x = float(a[i, j])
            for k in range(j):
                x -= float(low[i, k]) * float(low[j, k])
            low[i, j] = x / low[j, j]
    return low


def inv(a) -> np.ndarray:
    """Inverse of a square matrix by Gauss-Jordan elimination with partial pivoting in a fixed order (the
    same bits on every CPU; np.linalg.inv calls LAPACK)."""
    m = [[float(x) for x in row] for row in np.asarray(a, float)]
    n = len(m)
    out = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    for c in range(n):
        piv = max(range(c, n), key=lambda r: (abs(m[r][c]), -r))
        if m[piv][c] == 0.0:
            raise ValueError("inv: the matrix is singular")
        m[c], m[piv] = m[piv], m[c]
        out[c], out[piv] = out[piv], out[c]
        d = m[c][c]
        m[c] = [x / d for x in m[c]]
        out[c] = [x / d for x in out[c]]
        for r in range(n):
            if r != c and m[r][c] != 0.0:
                f = m[r][c]
                m[r] = [x - f * y for x, y in zip(m[r], m[c])]
                out[r] = [x - f * y for x, y in zip(out[r], out[c])]
    return np.array(out)


def eigh3(s):
    """(eigenvalues ascending, unit eigenvectors as columns) of a symmetric 3 x 3 matrix, the same bits on
    every CPU (np.linalg.eigh calls LAPACK). Each eigenvector's largest component is made positive and the
    frame right-handed (the last column flipped when needed)."""
    s = np.asarray(s, float).reshape(3, 3)
    w, vec = _jacobi(0.5 * (s + s.T))
    order = sorted(range(3), key=lambda k: (w[k], k))
    w = w[order]
    vec = vec[:, order]
    for k in range(3):
        big = int(np.argmax(np.abs(vec[:, k])))
        if vec[big, k] < 0.0:
            vec[:, k] = -vec[:, k]
    if det3(vec) < 0.0:
        vec[:, 2] = -vec[:, 2]
    return w, vec


def sin_cos_deg(angle_deg: float) -> tuple[float, float]:
    """(sin, cos) of an angle in degrees: exact 0, +-1/2 and +-1 where the true values are, sqrt(1/2) and
    sqrt(3)/2 correctly rounded at multiples of 45 and 30, and symmetric under the reflections of the circle
    (sin a = cos(90 - a)), so that planes of round orientation have exactly the normals their symmetry gives
    them. The reduction to
    [0, 45] is exact in floating point; only that remainder goes through the C library."""
    a = math.fmod(float(angle_deg), 360.0)
    if a < 0.0:
        a += 360.0
    q = int(a // 90.0)
    r = a - 90.0 * q  # exact: both terms are within a factor of two (Sterbenz) or q = 0
    if q == 4:  # a rounded up to 360
        q, r = 0, 0.0
    swap = r > 45.0
    x = 90.0 - r if swap else r  # in [0, 45], exact (Sterbenz)
    if x == 0.0:
        s, c = 0.0, 1.0
    elif x == 30.0:
        s, c = 0.5, 0.5 * math.sqrt(3.0)
    elif x == 45.0:
        s = c = math.sqrt(0.5)
    else:
        s, c = math.sin(math.radians(x)), math.cos(math.radians(x))
    if swap:
        s, c = c, s
    for _ in range(q):  # rotate by 90 degrees: (s, c) -> (c, -s)
        s, c = c, -s
    return s + 0.0, c + 0.0  # + 0.0 turns -0.0 into 0.0
