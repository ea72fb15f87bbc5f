"""The stable time step's rotation bound (dda.simulation.rotation_bound) against brute-force eigenvalues, and runs
of thin blocks at the step it gives."""
import math

import numpy as np
import pytest

from dda.blockspec import BlockSpec
from dda.simulation import NPOINT, ContactLaw, Simulation, rotation_bound
from dda.system import BlockSystem
from blocks import box  # independent of dda.shapes


def _hull_block(rng, scale):
    """A random convex block: the hull of points in a box of half-sides `scale`, as a BlockSpec."""
    from scipy.spatial import ConvexHull

    p = rng.uniform(-1, 1, (30, 3)) * scale
    h = ConvexHull(p)
    keep = np.unique(h.simplices)
    remap = -np.ones(len(p), int)
    remap[keep] = np.arange(len(keep))
    faces = []
    for s, eq in zip(h.simplices, h.equations):
        a, b, c = p[s]
        faces.append(list(remap[s]) if np.dot(np.cross(b - a, c - a), eq[:3]) > 0 else list(remap[s[::-1]]))
    return BlockSpec(p[keep], faces)


def _system(specs):
    bs = BlockSystem()
    for s in specs:
        bs.add_block(s, density=2700.0)
    return bs.arrays()


@pytest.mark.parametrize("seed", range(4))
def test_rotation_bound_is_the_worst_single_spring_and_no_spring_set_exceeds_it(seed):
    rng = np.random.default_rng(seed)
    scales = [(1, 1, 1), (8, 0.5, 0.5), (5, 5, 0.3), (3, 1, 0.2)]
    A = _system([_hull_block(rng, np.array(s, float)) for s in scales])
    which = np.arange(len(scales))
    lam = rotation_bound(A.vloc, A.vert_start, A.inertia, A.radius, which)
    for b in which:
        v = A.vloc[A.vert_start[b]:A.vert_start[b + 1]]
        I = A.inertia[b]
        # brute force: one spring at vertex r with normal n turns the block with w^2 / k = (r x n).I^-1.(r x n);
        # its largest over n, by dense sampling of n, and by LAPACK's eigenvalues of the same 3 x 3 matrices
        n = rng.normal(size=(20000, 3))
        n /= np.linalg.norm(n, axis=1)[:, None]
        sampled = max(float(((np.cross(r, n) ** 2) / I).sum(1).max()) for r in v)
        exact = max(np.linalg.eigvalsh((r @ r * np.eye(3) - np.outer(r, r)) / np.sqrt(np.outer(I, I)))[-1]
                    for r in v)
        assert sampled <= lam[b] * (1 + 1e-12)
        assert lam[b] <= exact * (1 + 1e-9) or lam[b] == A.radius[b] ** 2 / I.min()
        assert lam[b] <= A.radius[b] ** 2 / I.min() * (1 + 1e-15)
        # NPOINT springs anywhere on the surface (points on random faces, random normals): the largest
        # rotational eigenvalue of the whole set stays below NPOINT times the bound
        for _ in range(200):
            w = rng.dirichlet(np.ones(len(v)), NPOINT)
            pts = w @ v
            nn = rng.normal(size=(NPOINT, 3))
            nn /= np.linalg.norm(nn, axis=1)[:, None]
            g = np.cross(pts, nn) / np.sqrt(I)
            assert np.linalg.eigvalsh(g.T @ g)[-1] <= NPOINT * lam[b] * (1 + 1e-12)


def test_rotation_bound_of_a_needle_is_its_arm_not_its_length():
    # a 10 x 0.2 x 0.2 needle, its inertia from the box formula m (b^2 + c^2) / 12: the bound is the largest
    # eigenvalue of I^-1/2 (|r|^2 E - r r^T) I^-1/2 at a tip vertex (all eight alike), about 6 / m (a tip spring
    # turns it about an axis between its length and a cross axis), against the old r_max^2 / I_min = 3753 / m
    A = _system([box((-5, -0.1, -0.1), (5, 0.1, 0.1))])
    m = A.mass[0]
    I = m * np.array([0.2 ** 2 + 0.2 ** 2, 10 ** 2 + 0.2 ** 2, 10 ** 2 + 0.2 ** 2]) / 12
    r = np.array([5.0, 0.1, 0.1])
    exact = np.linalg.eigvalsh((r @ r * np.eye(3) - np.outer(r, r)) / np.sqrt(np.outer(I, I)))[-1]
    lam = rotation_bound(A.vloc, A.vert_start, A.inertia, A.radius, np.array([0]))[0]
    assert lam == pytest.approx(exact, rel=1e-9)
    assert 5.9 < lam * m < 6.0
    assert A.radius[0] ** 2 / A.inertia[0].min() * m == pytest.approx(25.02 * 12 / 0.08, rel=1e-9)


def test_cube_keeps_the_old_bound_to_the_bit():
    A = _system([box((0, 0, 0), (1, 1, 1))])
    lam = rotation_bound(A.vloc, A.vert_start, A.inertia, A.radius, np.array([0]))
    assert lam[0] == A.radius[0] ** 2 / A.inertia[0].min()


@pytest.mark.parametrize("dims", [(10.0, 0.2, 0.2), (10.0, 1.0, 0.2)])
def test_thin_block_rocking_on_a_base_is_stable_at_the_step_the_bound_gives(dims):
    # a needle and a plank dropped tilted onto a fixed base, no damping: at the automatic step (more than 3 x the
    # old one) the run neither blows up nor gains energy (balance within 1 % of the weight times the drop)
    a, b, c = (x / 2 for x in dims)
    bs = BlockSystem()
    bs.add_block(box((-8, -8, -1), (8, 8, 0)), fixed=True)
    t = math.radians(3.0)
    R = np.array([[math.cos(t), 0, -math.sin(t)], [0, 1, 0], [math.sin(t), 0, math.cos(t)]])
    spec = box((-a, -b, -c), (a, b, c))
    v = spec.vertices @ R.T
    v[:, 2] += 0.01 - v[:, 2].min()
    i = bs.add_block(BlockSpec(v, spec.faces), density=2700.0)
    sim = Simulation(bs, ContactLaw(kn=1e10, ks=5e9, friction_deg=30.0, damping=0.0))
    lam_old = sim.A.radius[i] ** 2 / sim.A.inertia[i].min()
    k = NPOINT * 1e10
    old_dt = sim.safety * 2.0 / math.sqrt(k * lam_old)
    assert sim.dt > 3.0 * old_dt
    z0 = sim.pos[i, 2]
    res = sim.run(0.2, record_every=0.01)
    drop = sim.A.mass[i] * 9.81 * 0.02
    assert abs(res.energy_column("balance_error")[-1]) < 0.01 * drop
    assert sim.pos[i, 2] < z0 - 0.005  # it fell onto the base and tips over its low corner
    assert sim.vertices(i)[:, 2].min() > -1e-3  # and rests on it (the overlap of a 0.1 mm spring, not a pass)
