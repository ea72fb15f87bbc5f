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

These matrices are built once per block (numpy). In the time loop (dda/_integrate.py, taken only for blocks with
dof = 12) the rotation is not the small rotation of D: a block's state is its centroid, its exact orientation R
(quaternion, as for rigid blocks) and its six strains e in the body frame, a point at undeformed body offset X
being at x = x0 + R (I + E) X (E the symmetric strain tensor of e). This co-rotational (rotation-corrected) form
keeps the strains free of any contribution of the rotation, however large it grows. Per step the body-frame
rates (angular velocity, strain rates) are advanced by central difference with the exact 9 x 9 rotation-strain
block of M (translation decouples: int x dV = 0), generalized forces from T^T f with f in the body frame, the
elastic force -V C e and the rigid gyroscopic torque; the velocity-dependent terms of the strains (centrifugal
stretching) are left out (first-order DDA neglects them too).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from sgim.portable import cholesky, eigvalsh, inv, matmul

from ._contact import local_damping
from ._kinematics import place_vertices, quat_matrix
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
    M = vol * matmul(T0.T, T0)
    for k in range(3):
        for l in range(3):
            M += S[k, l] * matmul(Tk[k].T, Tk[l])
    return density * M


def stiffness_matrix(volume, E, nu):
    """12 x 12 elastic stiffness of a block (V C in the strain block)."""
    K = np.zeros((12, 12))
    K[6:, 6:] = volume * elastic_matrix(E, nu)
    return K


def block_matrices(vloc, faces, density, E, nu):
    """(M9, M9^-1, V C) of a block in its body frame: the rotation-strain part of the mass matrix and its
    inverse (the translation part is m I), and the strain stiffness V C."""
    M = mass_matrix(vloc, faces, density)
    vol = second_moments(vloc, faces)[0]
    M9 = np.ascontiguousarray(M[3:, 3:])
    return M9, inv(M9), vol * elastic_matrix(E, nu)


def critical_omega2(vloc, faces, density, E, nu, k_contact):
    """Largest omega^2 of a free block with a contact spring k_contact at its farthest vertex (all 12 DOF)."""
    M = mass_matrix(vloc, faces, density)
    vol, c, _ = second_moments(vloc, faces)
    K = stiffness_matrix(vol, E, nu)
    r = np.asarray(vloc, float) - c
    v = r[int(np.argmax(np.einsum("ij,ij->i", r, r)))]
    T = t_matrix(v)
    K = K + k_contact * matmul(T.T, T)
    Li = inv(cholesky(M))
    return float(eigvalsh(matmul(matmul(Li, K), Li.T)).max())


@njit(cache=True)
def strain_tensor(e, Et):
    """Symmetric 3 x 3 strain tensor of (ex, ey, ez, gyz, gzx, gxy)."""
    Et[0, 0] = e[0]
    Et[1, 1] = e[1]
    Et[2, 2] = e[2]
    Et[1, 2] = Et[2, 1] = 0.5 * e[3]
    Et[0, 2] = Et[2, 0] = 0.5 * e[4]
    Et[0, 1] = Et[1, 0] = 0.5 * e[5]


@njit(cache=True, inline="always")
def stretch_inverse(strain, i):
    """(I + E)^-1 of block i's strains (E the strain tensor of strain[i]) as nine scalars, row by row: no array
    is made or called with, so it costs nothing in reference counts where it is inlined per contact point."""
    a00 = strain[i, 0] + 1.0
    a11 = strain[i, 1] + 1.0
    a22 = strain[i, 2] + 1.0
    a12 = 0.5 * strain[i, 3]
    a02 = 0.5 * strain[i, 4]
    a01 = 0.5 * strain[i, 5]
    a21, a20, a10 = a12, a02, a01
    d = (a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20))
    return ((a11 * a22 - a12 * a21) / d, (a02 * a21 - a01 * a22) / d, (a01 * a12 - a02 * a11) / d,
            (a12 * a20 - a10 * a22) / d, (a00 * a22 - a02 * a20) / d, (a02 * a10 - a00 * a12) / d,
            (a10 * a21 - a11 * a20) / d, (a01 * a20 - a00 * a21) / d, (a00 * a11 - a01 * a10) / d)


@njit(cache=True)
def deform_geometry(i, pos, R, strain, vs, fs, vloc, nloc, dloc, vert, fnw, fdw, aabb):
    """World vertices x = x0 + R (I + E) X, face planes (normal (I + E)^-1 n, turned by R) and box of block i."""
    F = np.empty((3, 3))
    strain_tensor(strain[i], F)
    for a in range(3):
        F[a, a] += 1.0
    i00, i01, i02, i10, i11, i12, i20, i21, i22 = stretch_inverse(strain, i)
    G = np.empty((3, 3))  # R F
    for a in range(3):
        for b in range(3):
            G[a, b] = R[a, 0] * F[0, b] + R[a, 1] * F[1, b] + R[a, 2] * F[2, b]
    place_vertices(i, pos, G, vs, vloc, vert, aabb)
    for f in range(fs[i], fs[i + 1]):
        # F^-T n = F^-1 n (F symmetric); n' . F X = n . X on the face, so d' = dloc / |F^-1 n|
        nb0 = i00 * nloc[f, 0] + i01 * nloc[f, 1] + i02 * nloc[f, 2]
        nb1 = i10 * nloc[f, 0] + i11 * nloc[f, 1] + i12 * nloc[f, 2]
        nb2 = i20 * nloc[f, 0] + i21 * nloc[f, 1] + i22 * nloc[f, 2]
        ln = nb0 * nb0 + nb1 * nb1 + nb2 * nb2
        ln = np.sqrt(ln)
        d = dloc[f] / ln
        for a in range(3):
            nn = (R[a, 0] * nb0 + R[a, 1] * nb1 + R[a, 2] * nb2) / ln
            fnw[f, a] = nn
            d += nn * pos[i, a]
        fdw[f] = d


# inlined: called per contact point, without arrays of its own or calls (dda/_kinematics.py says why)
@njit(cache=True, inline="always")
def body_offset(i, p, pos, R, strain):
    """Undeformed body offset X = (I + E)^-1 R^T (p - x0) of the world point p of block i, as three scalars."""
    i00, i01, i02, i10, i11, i12, i20, i21, i22 = stretch_inverse(strain, i)
    y0 = p[0] - pos[i, 0]
    y1 = p[1] - pos[i, 1]
    y2 = p[2] - pos[i, 2]
    b0 = R[0, 0] * y0 + R[1, 0] * y1 + R[2, 0] * y2
    b1 = R[0, 1] * y0 + R[1, 1] * y1 + R[2, 1] * y2
    b2 = R[0, 2] * y0 + R[1, 2] * y1 + R[2, 2] * y2
    return i00 * b0 + i01 * b1 + i02 * b2, i10 * b0 + i11 * b1 + i12 * b2, i20 * b0 + i21 * b1 + i22 * b2


# inlined: called per contact point (dda/_kinematics.py says why)
@njit(cache=True, inline="always")
def body_point(i, p, pos, R, strain, X):
    """body_offset into X."""
    X[0], X[1], X[2] = body_offset(i, p, pos, R, strain)


# inlined: called per contact point, without arrays of its own or calls (dda/_kinematics.py says why)
@njit(cache=True, inline="always")
def point_velocity(i, p, pos, R, strain, srate, wb, out):
    """Velocity of the world point p of deformable block i relative to its centroid: w x (p - x0) + R Edot X."""
    X0, X1, X2 = body_offset(i, p, pos, R, strain)
    # Edot X, Edot the strain-rate tensor of srate[i] (engineering shear rates halved)
    h3 = 0.5 * srate[i, 3]
    h4 = 0.5 * srate[i, 4]
    h5 = 0.5 * srate[i, 5]
    w0 = R[0, 0] * wb[i, 0] + R[0, 1] * wb[i, 1] + R[0, 2] * wb[i, 2]
    w1 = R[1, 0] * wb[i, 0] + R[1, 1] * wb[i, 1] + R[1, 2] * wb[i, 2]
    w2 = R[2, 0] * wb[i, 0] + R[2, 1] * wb[i, 1] + R[2, 2] * wb[i, 2]
    rx = p[0] - pos[i, 0]
    ry = p[1] - pos[i, 1]
    rz = p[2] - pos[i, 2]
    u0 = srate[i, 0] * X0 + h5 * X1 + h4 * X2
    u1 = h5 * X0 + srate[i, 1] * X1 + h3 * X2
    u2 = h4 * X0 + h3 * X1 + srate[i, 2] * X2
    out[0] = w1 * rz - w2 * ry + R[0, 0] * u0 + R[0, 1] * u1 + R[0, 2] * u2
    out[1] = w2 * rx - w0 * rz + R[1, 0] * u0 + R[1, 1] * u1 + R[1, 2] * u2
    out[2] = w0 * ry - w1 * rx + R[2, 0] * u0 + R[2, 1] * u1 + R[2, 2] * u2


# inlined: called per contact point (dda/_kinematics.py says why)
@njit(cache=True, inline="always")
def add_strain_force(i, X, R, f, sign, qs):
    """qs[i] += sign * T_strain(X)^T R^T f (the strain part of T^T f for a world force f at body offset X)."""
    f0 = sign * (R[0, 0] * f[0] + R[1, 0] * f[1] + R[2, 0] * f[2])
    f1 = sign * (R[0, 1] * f[0] + R[1, 1] * f[1] + R[2, 1] * f[2])
    f2 = sign * (R[0, 2] * f[0] + R[1, 2] * f[1] + R[2, 2] * f[2])
    qs[i, 0] += X[0] * f0
    qs[i, 1] += X[1] * f1
    qs[i, 2] += X[2] * f2
    qs[i, 3] += 0.5 * (X[2] * f1 + X[1] * f2)
    qs[i, 4] += 0.5 * (X[2] * f0 + X[0] * f2)
    qs[i, 5] += 0.5 * (X[1] * f0 + X[0] * f1)


@njit(cache=True)
def deform_step(i, dt, dtavg, local_damp, blocks, deform, loads, forces):
    """Central-difference step of deformable block i (bundles of dda/_state.py; forces of this step in
    forces.force / torque (world) and qs (strain part of T^T f)). Returns (kinetic energy (product form), load
    potential, strain energy, local damping work, blown)."""
    pos, vel, quat, mass, inertia = blocks.pos, blocks.vel, blocks.quat, blocks.mass, blocks.inertia
    force, torque, qs = forces.force, forces.torque, forces.qs
    gravity, bforce, pl_start, pl_r, pl_f = loads.gravity, loads.bforce, loads.pl_start, loads.pl_r, loads.pl_f
    strain, srate, wb, m9, m9inv, vc = deform.strain, deform.srate, deform.wb, deform.m9, deform.m9inv, deform.vc
    R = np.empty((3, 3))
    quat_matrix(quat[i], R)
    F = np.empty((3, 3))
    strain_tensor(strain[i], F)
    for a in range(3):
        F[a, a] += 1.0
    es = 0.0
    for a in range(6):
        for b in range(6):
            es += 0.5 * strain[i, a] * vc[i, a, b] * strain[i, b]
    pe = 0.0
    fp = np.empty(3)
    for p in range(pl_start[i], pl_start[i + 1]):
        X = pl_r[p]
        y0 = F[0, 0] * X[0] + F[0, 1] * X[1] + F[0, 2] * X[2]
        y1 = F[1, 0] * X[0] + F[1, 1] * X[1] + F[1, 2] * X[2]
        y2 = F[2, 0] * X[0] + F[2, 1] * X[1] + F[2, 2] * X[2]
        r0 = R[0, 0] * y0 + R[0, 1] * y1 + R[0, 2] * y2
        r1 = R[1, 0] * y0 + R[1, 1] * y1 + R[1, 2] * y2
        r2 = R[2, 0] * y0 + R[2, 1] * y1 + R[2, 2] * y2
        for a in range(3):
            fp[a] = pl_f[p, a]
            force[i, a] += fp[a]
        torque[i, 0] += r1 * fp[2] - r2 * fp[1]
        torque[i, 1] += r2 * fp[0] - r0 * fp[2]
        torque[i, 2] += r0 * fp[1] - r1 * fp[0]
        add_strain_force(i, X, R, fp, 1.0, qs)
        pe -= fp[0] * (pos[i, 0] + r0) + fp[1] * (pos[i, 1] + r1) + fp[2] * (pos[i, 2] + r2)
    m = mass[i]
    ke = 0.0
    d_loc = 0.0
    for a in range(3):
        f = force[i, a] + m * gravity[a] + bforce[i, a]
        fd = 0.0
        if local_damp > 0.0:
            fd = local_damping(local_damp, f, vel[i, a])
            f -= fd
        vnew = vel[i, a] + dtavg * f / m
        # paired with the mean of the half-step velocities on either side (the product-form kinetic energy's)
        d_loc += fd * 0.5 * (vel[i, a] + vnew) * dtavg
        ke += 0.5 * m * vel[i, a] * vnew
        vel[i, a] = vnew
        pe -= (m * gravity[a] + bforce[i, a]) * pos[i, a]
    # body-frame generalized force of the rotation and strain unknowns
    Q = np.empty(9)
    d0 = np.empty(9)
    for a in range(3):
        Q[a] = R[0, a] * torque[i, 0] + R[1, a] * torque[i, 1] + R[2, a] * torque[i, 2]
        d0[a] = wb[i, a]
    # rigid gyroscopic torque -w x (I w) (principal body frame)
    I0 = inertia[i, 0] * wb[i, 0]
    I1 = inertia[i, 1] * wb[i, 1]
    I2 = inertia[i, 2] * wb[i, 2]
    Q[0] -= wb[i, 1] * I2 - wb[i, 2] * I1
    Q[1] -= wb[i, 2] * I0 - wb[i, 0] * I2
    Q[2] -= wb[i, 0] * I1 - wb[i, 1] * I0
    for a in range(6):
        q = qs[i, a]
        for b in range(6):
            q -= vc[i, a, b] * strain[i, b]
        Q[3 + a] = q
        d0[3 + a] = srate[i, a]
    fdq = np.zeros(9)
    if local_damp > 0.0:
        for a in range(9):
            fdq[a] = local_damping(local_damp, Q[a], d0[a])
            Q[a] -= fdq[a]
    d1 = np.empty(9)
    for a in range(9):
        acc = 0.0
        for b in range(9):
            acc += m9inv[i, a, b] * Q[b]
        d1[a] = d0[a] + dtavg * acc
    for a in range(9):
        d_loc += fdq[a] * 0.5 * (d0[a] + d1[a]) * dtavg
    for a in range(9):
        for b in range(9):
            ke += 0.5 * d0[a] * m9[i, a, b] * d1[b]
    # turn by the world angular velocity R w over dt (exact exponential of the quaternion)
    w0 = R[0, 0] * d1[0] + R[0, 1] * d1[1] + R[0, 2] * d1[2]
    w1 = R[1, 0] * d1[0] + R[1, 1] * d1[1] + R[1, 2] * d1[2]
    w2 = R[2, 0] * d1[0] + R[2, 1] * d1[1] + R[2, 2] * d1[2]
    wl = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if wl > 0.0:
        sn = np.sin(0.5 * wl * dt) / wl
        c = np.cos(0.5 * wl * dt)
    else:
        sn = 0.5 * dt
        c = 1.0
    p0, p1, p2, p3 = c, sn * w0, sn * w1, sn * w2
    q = quat[i]
    o0 = p0 * q[0] - p1 * q[1] - p2 * q[2] - p3 * q[3]
    o1 = p0 * q[1] + p1 * q[0] + p2 * q[3] - p3 * q[2]
    o2 = p0 * q[2] - p1 * q[3] + p2 * q[0] + p3 * q[1]
    o3 = p0 * q[3] + p1 * q[2] - p2 * q[1] + p3 * q[0]
    ln = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    quat[i, 0] = o0 / ln
    quat[i, 1] = o1 / ln
    quat[i, 2] = o2 / ln
    quat[i, 3] = o3 / ln
    blown = False
    for a in range(3):
        wb[i, a] = d1[a]
        pos[i, a] += dt * vel[i, a]
        if not np.isfinite(pos[i, a]) or not np.isfinite(vel[i, a]) or not np.isfinite(d1[a]):
            blown = True
    for a in range(6):
        srate[i, a] = d1[3 + a]
        strain[i, a] += dt * d1[3 + a]
        if not np.isfinite(strain[i, a]):
            blown = True
    return ke, pe, es, d_loc, blown


__all__ = ["t_matrix", "elastic_matrix", "second_moments", "mass_matrix", "stiffness_matrix", "block_matrices",
           "critical_omega2", "deform_geometry", "deform_step", "point_velocity", "body_point", "body_offset",
           "add_strain_force", "strain_tensor", "stretch_inverse"]
