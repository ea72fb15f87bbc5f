"""Cross-validation of the full bond law: a cantilever of normal + shear bonds against the exact 6-DOF network.

    cases crossval --cases shear_beam [--engines dda,yade]

The bond law of the in-house engine (dda/_bondlaw.py) and of YADE's JCFpm (the law the YADE decks use) is a
normal spring kn along the centre line and a shear spring ks in the tangent plane, both acting at the contact
point between the two spheres, so that the rotations of both spheres enter the bond's relative displacement and
its force turns both spheres; neither law has a bending or twisting moment spring. The reference here is the
linear static solution of that network with six degrees of freedom per sphere, assembled from this definition
alone (nothing of either engine is imported):

- bond (i, j), unit normal n from i to j, overlap d = r_i + r_j - |x_j - x_i|; the contact point c lies at the
  arm a_i = r_i - d / 2 from x_i along n and a_j = r_j - d / 2 from x_j against it (YADE's ScGeom point, the middle
  of the overlap; the in-house engine puts it at r_i / (r_i + r_j) of the centre distance: the same point for
  touching spheres and for equal radii, as in the model below);
- relative displacement at c: D = u_j + w_j x (c - x_j) - u_i - w_i x (c - x_i) = u_j - u_i + n x (a_i w_i + a_j w_j);
- the force on j at c is f = -(kn n n^T + ks (I - n n^T)) D, on i it is -f; moments (c - x) x force about each
  centre. With B the 3 x 12 matrix of D over (u_i, w_i, u_j, w_j), the bond's stiffness is B^T C B
  (C = kn n n^T + ks (I - n n^T)); the bonds' blocks sum to the sparse 6n x 6n stiffness K;
- K U = F (F: the weights m g on the translations, no moments) over the spheres that are not fixed (fixed spheres
  hold all six degrees of freedom). K may be singular: a mechanism that the load does not work on and that moves
  no sphere's centre (the spins of `shear_beam`, below) leaves the displacements unique, and the solution is the
  one without it; a mechanism that the load works on, or that moves a centre, is an error.

The case, `shear_beam` (cases/scenes/crossval/shear_beam.toml, written by cases/make/crossval.py): a 0.36 x 0.12 x
0.12 m cantilever of simple-cubic spheres (r = 0.015: 12 x 4 x 4 spheres), fixed at its first layer (x < 0.03),
bonds of modulus 1 GPa with ks = 0.1 kn, under gravity, brought to rest by local damping 0.7; result: the mean
vertical displacement of the tip layer. The cubic lattice is chosen because the shear springs carry it: with
central bonds alone it is a mechanism (each bay shears freely), with the spheres' rotations held it is 4.9 times
stiffer, and the shear springs hold 59 % of its elastic energy at rest (the note of the row computes the three
from the reference). K has eleven zero modes: in each free layer the spheres spin about the beam's axis in a
checkerboard of alternate senses (neighbours' spins cancel at every contact point, and bonds along the axis do
not resist a spin about it); gravity does not work on them.

Both engines are this law at first order in the displacements: the in-house engine accumulates the tangential
relative velocity at the bond point (both spins, arms r_i / (r_i + r_j) of the centre distance) into a shear
displacement kept in the current tangent plane, force -kn (stretch) n - ks u_s applied at that point; YADE's
JCFpm (Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM over Ig2_Sphere_Sphere_ScGeom) rotates its shear force
with the contact and adds -ks times ScGeom's shear increment (the tangential relative velocity at the contact
point, arms r - overlap / 2, times dt), and turns both spheres by the arms times n x force; the YADE deck sets
each bond's kn and ks (adapters/yade_script.py, apply_pair_rule). Neither has a moment spring (JCFpm carries no
rolling moment), so the reference has none either.

LIGGGHTS-PUBLIC has only central bonds (bond_style harmonic): it cannot express the shear spring, and this
lattice is a mechanism without it; its row says so and runs nothing.

This module imports nothing of cases/lib/crossval.py (which dispatches to it): the engines' runner and the table's
rows come in as arguments.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.sparse import coo_matrix, identity
from scipy.sparse.linalg import LinearOperator, eigsh, splu

from adapters.spec import from_scene
from cases import SCENES

SCENE = SCENES / "crossval" / "shear_beam.toml"
SHEAR_TOLERANCE = 0.01  # an engine against the 6-DOF network: 1 %
ZERO = 1e-10  # an eigenvalue of K below ZERO x its largest is a zero mode (a mechanism)


# -- the 6-DOF network (independent of every engine) -----------------------------------------------------
def _cross_matrix(n):
    """(m, 3, 3): S v = n x v for each row of n (m, 3)."""
    S = np.zeros((len(n), 3, 3))
    S[:, 0, 1], S[:, 0, 2] = -n[:, 2], n[:, 1]
    S[:, 1, 0], S[:, 1, 2] = n[:, 2], -n[:, 0]
    S[:, 2, 0], S[:, 2, 1] = -n[:, 1], n[:, 0]
    return S


def bond_geometry(centers, radii, bond_i, bond_j):
    """(n (m, 3) unit normals from i to j, arm a_i (m,), arm a_j (m,)): the contact point is x_i + a_i n =
    x_j - a_j n, the middle of the overlap (a_i = r_i - d / 2, d = r_i + r_j - |x_j - x_i|)."""
    c = np.asarray(centers, float).reshape(-1, 3)
    r = np.asarray(radii, float)
    i, j = np.asarray(bond_i, np.int64), np.asarray(bond_j, np.int64)
    d = c[j] - c[i]
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    overlap = r[i] + r[j] - dist
    return d / dist[:, None], r[i] - 0.5 * overlap, r[j] - 0.5 * overlap


def relative_operator(centers, radii, bond_i, bond_j):
    """(m, 3, 12) B: the relative displacement at each bond's contact point, D = B (u_i, w_i, u_j, w_j)."""
    n, ai, aj = bond_geometry(centers, radii, bond_i, bond_j)
    S = _cross_matrix(n)
    eye = np.broadcast_to(np.eye(3), S.shape)
    return np.concatenate([-eye, ai[:, None, None] * S, eye, aj[:, None, None] * S], axis=2)


def bond_stiffness(centers, radii, bond_i, bond_j, kn, ks):
    """The sparse (6n, 6n) stiffness of the bond network, degrees of freedom (u_x, u_y, u_z, w_x, w_y, w_z) per
    sphere: the sum over the bonds of B^T (kn n n^T + ks (I - n n^T)) B."""
    n_spheres = len(np.asarray(radii))
    i, j = np.asarray(bond_i, np.int64), np.asarray(bond_j, np.int64)
    n, _, _ = bond_geometry(centers, radii, i, j)
    B = relative_operator(centers, radii, i, j)
    nn = n[:, :, None] * n[:, None, :]
    C = (np.asarray(kn, float)[:, None, None] * nn
         + np.asarray(ks, float)[:, None, None] * (np.eye(3)[None] - nn))
    blocks = np.einsum("mai,mab,mbj->mij", B, C, B)  # (m, 12, 12)
    dof = np.concatenate([6 * i[:, None] + np.arange(6), 6 * j[:, None] + np.arange(6)], axis=1)
    rows = np.broadcast_to(dof[:, :, None], blocks.shape)
    cols = np.broadcast_to(dof[:, None, :], blocks.shape)
    return coo_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(6 * n_spheres, 6 * n_spheres)).tocsr()


def weights(run):
    """(n, 6) the load of gravity: m g on the translations, no moments."""
    mass = run.density * 4.0 / 3.0 * np.pi * run.radii ** 3
    load = np.zeros((run.n, 6))
    load[:, :3] = mass[:, None] * np.asarray(run.gravity, float)[None, :]
    return load


def _zero_modes(Kf, solve, shift):
    """The eigenvectors of Kf (sparse, symmetric, positive semi-definite) whose eigenvalues lie below ZERO x its
    largest diagonal entry: by shift-invert Lanczos about -shift (`solve` applies (Kf + shift I)^-1), asking
    for more until one of those found is not a zero mode; dense when they would be a quarter of the spectrum."""
    size = Kf.shape[0]
    limit = ZERO * Kf.diagonal().max()
    k = min(16, size - 1)
    while 4 * k < size:
        lam, V = eigsh(Kf, k=k, sigma=-shift, OPinv=LinearOperator(Kf.shape, matvec=solve), which="LM")
        if np.sum(lam <= limit) < k:
            return V[:, lam <= limit]
        k *= 2
    lam, V = np.linalg.eigh(Kf.toarray())
    return V[:, lam <= limit]


def static_solution(K, load, held):
    """(U (n, d), zero modes): the static displacements (and rotations, d = 6) of K U = load ((n, d); K of d
    degrees of freedom per sphere, translations first) over the spheres not `held` ((n,) bool: every degree of
    freedom held). Zero modes (_zero_modes) are left out of U; one that the load works on, or that moves a
    sphere's centre, raises ValueError (no unique static displacement). Sparse: a factorisation of K + shift I
    (shift = ZERO x 10 its largest diagonal entry) and iterative refinement to the exact K U = load (each step
    cuts the residual by shift / (lambda + shift) on the mode of eigenvalue lambda)."""
    load = np.asarray(load, float)
    n, d = load.shape
    free = np.repeat(~np.asarray(held, bool), d)
    U = np.zeros(n * d)
    if not free.any():
        return U.reshape(n, d), 0
    Kf = K[free][:, free].tocsc()
    f = load.ravel()[free]
    shift = 10.0 * ZERO * Kf.diagonal().max()
    lu = splu((Kf + shift * identity(Kf.shape[0], format="csc")).tocsc())
    null = _zero_modes(Kf, lu.solve, shift)
    scale = float(np.abs(f).max()) or 1.0
    if null.size and np.abs(f @ null).max() > 1e-9 * scale:
        raise ValueError(f"the load works on the {null.shape[1]} zero modes of the bond network (a mechanism)")
    if null.size and np.abs(null.reshape(-1, d, null.shape[1])[:, :3]).max() > 1e-6:
        raise ValueError("a zero mode of the bond network moves a sphere's centre (a mechanism)")
    x = np.zeros_like(f)
    for _ in range(100):
        r = f - Kf @ x
        if np.abs(r).max() <= 1e-10 * scale:
            break
        x += lu.solve(r)
    else:
        raise ValueError("the static solution of the bond network did not converge")
    U[free] = x - null @ (null.T @ x)
    return U.reshape(n, d), int(null.shape[1])


def translations(K):
    """The part of a 6-DOF stiffness K on the translations alone (every rotation held)."""
    keep = np.tile(np.r_[np.ones(3, bool), np.zeros(3, bool)], K.shape[0] // 6)
    return K[keep][:, keep]


def network_solution(run, ks_scale=1.0, rotations=True):
    """(U (n, 6), zero modes) of `run`'s bond network under gravity, its shear stiffness times `ks_scale`; with
    `rotations` False every sphere's rotation is held and U is (n, 3)."""
    K = bond_stiffness(run.centers, run.radii, run.bond_i, run.bond_j, run.bond_kn, ks_scale * run.bond_ks)
    if not rotations:
        return static_solution(translations(K), weights(run)[:, :3], run.fixed)
    return static_solution(K, weights(run), run.fixed)


def spring_energies(run, U):
    """(normal, shear) elastic energy [J] of the bonds at the displacements and rotations U (n, 6)."""
    i, j = run.bond_i, run.bond_j
    n, _, _ = bond_geometry(run.centers, run.radii, i, j)
    B = relative_operator(run.centers, run.radii, i, j)
    D = np.einsum("mab,mb->ma", B, np.concatenate([U[i], U[j]], axis=1))
    dn = np.einsum("ij,ij->i", D, n)
    dt = D - dn[:, None] * n
    return (0.5 * float(np.sum(run.bond_kn * dn * dn)),
            0.5 * float(np.sum(run.bond_ks * np.einsum("ij,ij->i", dt, dt))))


def tip_mask(run):
    return run.centers[:, 0] > run.centers[:, 0].max() - 0.5 * float(run.radii.min())


def reference_note(run, U):
    """What carries the cantilever, from the reference: the shear springs' share of the elastic energy, the
    stiffening when rotations are held, and whether central bonds alone hold it."""
    tip = tip_mask(run)
    e_n, e_s = spring_energies(run, U)
    held = float(-network_solution(run, rotations=False)[0][tip, 2].mean())
    try:  # central bonds: no stiffness on any rotation, the translations alone
        network_solution(run, ks_scale=0.0, rotations=False)
        central = "central bonds alone hold it"
    except ValueError:
        central = "central bonds alone: a mechanism"
    return (f"shear springs hold {100 * e_s / (e_n + e_s):.0f} % of the elastic energy; rotations held: "
            f"{float(-U[tip, 2].mean()) / held:.1f} x stiffer; {central}")


# -- the case --------------------------------------------------------------------------------------------
def shear_beam(engines, work, timeout, run_engine, emit):
    """Run the shear-bond cantilever in `engines` (run_engine(engine, source, work, timeout, run=...) -> RunResult)
    and `emit(**fields)` one table row per engine (the fields of cases.lib.crossval.Row)."""
    run = from_scene(SCENE)
    U, _ = network_solution(run)
    tip = tip_mask(run)
    ref = float(-U[tip, 2].mean())
    note = reference_note(run, U)
    reference = f"{ref * 1e6:.3f} um (6-DOF network)"
    for eng in engines:
        if eng == "liggghts":
            emit(case="shear_beam", engine=eng, result="-", reference=reference, error="-", ok=None, wall_s=0.0,
                 note="not run: LIGGGHTS-PUBLIC has central bonds only (bond_style harmonic), no shear spring; "
                      "the cubic lattice is a mechanism without one", ref_value=ref)
            continue
        t0 = time.perf_counter()
        res = run_engine(eng, SCENE, work / "shear_beam", timeout, run=run)
        got = float(-res.displacement()[tip, 2].mean())
        err = got / ref - 1.0
        emit(case="shear_beam", engine=eng, result=f"{got * 1e6:.3f} um", reference=reference,
             error=f"{100 * err:+.1e} %", ok=abs(err) <= SHEAR_TOLERANCE, wall_s=time.perf_counter() - t0,
             note=note, value=got, ref_value=ref, err_value=err)
