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


# ---------------------------------------------------------------------------------------------------------
# deformable blocks in a run (dof = 12)

from dda.blockspec import BlockSpec  # noqa: E402
from dda.simulation import ContactLaw, Simulation  # noqa: E402
from dda.system import BlockSystem  # noqa: E402


def _box(x0, x1, y0, y1, z0, z1):
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return v, f


def test_column_under_its_own_weight_shortens_by_the_elastic_solution():
    # column of height h, side b, on a fixed frictionless base: the reference is the uniaxial solution with free
    # lateral expansion, total shortening int_0^h rho g (h - z) / E dz = rho g h^2 / (2 E) and lateral strain
    # nu times the mean axial strain, so a width change of nu rho g h b / (2 E)
    b, h, rho, E, nu, g = 0.5, 2.0, 2600.0, 1e8, 0.25, 9.81
    bs = BlockSystem()
    v, f = _box(-1, 1, -1, 1, -0.5, 0)
    bs.add_block(BlockSpec(v, f, fixed=True), density=rho)
    v, f = _box(-b / 2, b / 2, -b / 2, b / 2, 0, h)
    i = bs.add_block(BlockSpec(v, f, dof=12), density=rho, E=E, nu=nu)
    sim = Simulation(bs, ContactLaw(kn=1e8, friction_deg=0.0, damping=0.2), gravity=(0, 0, -g), local_damping=0.5)
    sim.run(0.6, record_every=0.1)
    V = sim.vertices(i)
    top, bot = V[V[:, 2] > h / 2], V[V[:, 2] < h / 2]
    shortening = h - (top[:, 2].mean() - bot[:, 2].mean())
    ref = rho * g * h * h / (2 * E)
    assert shortening == pytest.approx(ref, rel=0.01)
    widening = (top[:, 0].max() - top[:, 0].min()) - b
    assert widening == pytest.approx(nu * rho * g * h * b / (2 * E), rel=0.01)
    assert np.ptp(top[:, 2]) < 1e-3 * ref  # no tilt, no shear
    # a rigid column on the same base does not shorten (the strain comes from the 12-DOF path only)
    assert abs(sim.strain(i)).max() > 0


@pytest.mark.parametrize("mode", ["volumetric", "shear"])
def test_free_block_with_an_initial_strain_oscillates_at_the_analytical_frequency(mode):
    # free cube of side a: the constant-strain modes have omega^2 = 36 K / (rho a^2) (volumetric) and
    # 24 G / (rho a^2) (shear, deviatoric); a strain imposed at rest oscillates as e0 cos(omega t)
    a, rho, E, nu = 0.8, 2600.0, 1e8, 0.25
    v, f = _cube(a)
    bs = BlockSystem()
    i = bs.add_block(BlockSpec(v, f, dof=12), density=rho, E=E, nu=nu)
    Kb, G = E / (3 * (1 - 2 * nu)), E / (2 * (1 + nu))
    if mode == "volumetric":
        w, e0 = math.sqrt(36 * Kb / (rho * a * a)), np.array([1e-4, 1e-4, 1e-4, 0, 0, 0])
    else:
        w, e0 = math.sqrt(24 * G / (rho * a * a)), np.array([0, 0, 0, 0, 0, 2e-4])
    period = 2 * math.pi / w
    sim = Simulation(bs, ContactLaw(), gravity=(0, 0, 0), dt=period / 400)
    sim.set_strain(i, e0)
    res = sim.run(3.2 * period, record_every=sim.dt)
    k = int(np.argmax(np.abs(e0)))
    s = np.asarray(res.strain)[:, i, k] / e0[k]
    t = res.times
    # zero crossings (linear interpolation) give the period
    z = np.nonzero((s[1:] < 0) != (s[:-1] < 0))[0]
    tz = t[z] - s[z] * (t[z + 1] - t[z]) / (s[z + 1] - s[z])
    measured = 2 * np.mean(np.diff(tz))
    assert measured == pytest.approx(period, rel=2e-3)
    assert np.abs(s).max() == pytest.approx(1.0, rel=1e-3)  # no energy gain or loss
    assert np.allclose(sim.pos[i], mass_properties(v, f).centroid, atol=1e-12)  # no rigid motion


def test_rotating_deformable_block_keeps_its_volume_and_shape():
    # a brick spinning about a principal axis through several turns: rotation must give no strain (a small
    # rotation update would inflate the block by about theta^2 / 2 per step); the vertices must be the initial
    # ones turned by the analytical angle omega t
    v, f = _box(0, 1.2, 0, 0.6, 0, 0.3)
    bs = BlockSystem()
    w = 15.0
    i = bs.add_block(BlockSpec(v, f, dof=12, angular_velocity=(0.0, 0.0, w)), density=2600.0, E=1e8, nu=0.3)
    sim = Simulation(bs, ContactLaw(), gravity=(0, 0, 0), dt=2e-3)
    sim.run(2.0, record_every=0.5)
    assert sim.volume(i) == pytest.approx(1.2 * 0.6 * 0.3, rel=1e-12)
    assert np.abs(sim.strain(i)).max() < 1e-12
    th = w * sim.time
    Rz = np.array([[math.cos(th), -math.sin(th), 0], [math.sin(th), math.cos(th), 0], [0, 0, 1]])
    c = v.mean(0)
    assert np.allclose(sim.vertices(i), (v - c) @ Rz.T + c, atol=1e-9)


def test_point_loads_stretch_a_free_block_through_t_transpose_f():
    # two opposite forces F at the centres of opposite faces of a free cube: uniaxial stress F / a^2, so the
    # constant strain is F / (E a^2) along the load and -nu F / (E a^2) across it (static, damped run)
    a, rho, E, nu, F = 0.5, 2600.0, 1e7, 0.2, 2000.0
    v, f = _cube(a)
    bs = BlockSystem()
    i = bs.add_block(BlockSpec(v, f, dof=12), density=rho, E=E, nu=nu)
    bs.add_point_load(i, (a, a / 2, a / 2), (F, 0, 0))
    bs.add_point_load(i, (0, a / 2, a / 2), (-F, 0, 0))
    sim = Simulation(bs, ContactLaw(), gravity=(0, 0, 0), local_damping=0.3)
    sim.run(0.2, record_every=0.1)
    V = sim.vertices(i)
    ex = (V[:, 0].max() - V[:, 0].min()) / a - 1
    ey = (V[:, 1].max() - V[:, 1].min()) / a - 1
    assert ex == pytest.approx(F / (E * a * a), rel=1e-3)
    assert ey == pytest.approx(-nu * F / (E * a * a), rel=1e-3)


def test_scene_reads_dof_and_refuses_bad_values(tmp_path):
    from dda.scene import SceneError, load_scene

    base = ('[simulation]\nduration = 0.01\n[contact]\nkn = 1e8\n[[material]]\nname = "rock"\nE = 1e8\nnu = 0.2\n'
            '[[block]]\nshape = "cube"\nsize = 4\ncenter = [0, 0, -2]\nfixed = true\n'
            '[[block]]\nshape = "cube"\nsize = 1\ncenter = [0, 0, 0.5]\ndof = {dof}\n')
    p = tmp_path / "s.toml"
    p.write_text(base.format(dof=12))
    sc = load_scene(p)
    assert [int(getattr(b, "dof", 6)) for b in sc.blocks] == [6, 12]
    bs, sim = sc.build()
    assert sim.dof12.tolist() == [False, True]
    p.write_text(base.format(dof=7))
    with pytest.raises(SceneError):
        load_scene(p)
    p.write_text(base.format(dof=12) + 'prescribed = true\nvelocity = [1, 0, 0]\n')
    with pytest.raises(SceneError):
        load_scene(p)


def test_column_on_a_free_rigid_slab_and_elastic_bounce_energy():
    # the same column on a free rigid slab resting on the fixed base: the slab's reaction reaches the column
    # through the deformable-rigid contact (both bodies moving), the shortening is again rho g h^2 / (2 E)
    b, h, rho, E, nu, g = 0.5, 2.0, 2600.0, 1e8, 0.25, 9.81
    bs = BlockSystem()
    v, f = _box(-1, 1, -1, 1, -0.5, 0)
    bs.add_block(BlockSpec(v, f, fixed=True), density=rho)
    v, f = _box(-0.6, 0.6, -0.6, 0.6, 0, 0.3)
    bs.add_block(BlockSpec(v, f), density=rho)
    v, f = _box(-b / 2, b / 2, -b / 2, b / 2, 0.3, 0.3 + h)
    i = bs.add_block(BlockSpec(v, f, dof=12), density=rho, E=E, nu=nu)
    sim = Simulation(bs, ContactLaw(kn=1e8, friction_deg=0.0, damping=0.2), gravity=(0, 0, -g), local_damping=0.5)
    sim.run(0.6, record_every=0.1)
    V = sim.vertices(i)
    zc = sim.pos[i, 2]
    shortening = h - (V[V[:, 2] > zc, 2].mean() - V[V[:, 2] < zc, 2].mean())
    assert shortening == pytest.approx(rho * g * h * h / (2 * E), rel=0.01)

    # a soft deformable tetrahedron dropped on the base without friction or damping: the energy balance (kinetic,
    # potential, contact and strain energy) holds to a small fraction of the kinetic energy at impact
    from dda.shapes import shape

    bs = BlockSystem()
    v, f = _box(-2, 2, -2, 2, -0.5, 0)
    bs.add_block(BlockSpec(v, f, fixed=True), density=rho)
    s = shape("tetrahedron", 0.8, center=(0.1, 0.0, 0.6))
    s.dof = 12
    k = bs.add_block(s, density=rho, E=1e7, nu=0.25)
    sim = Simulation(bs, ContactLaw(kn=1e8, friction_deg=0.0, damping=0.0), gravity=(0, 0, -g), dt=5e-5)
    res = sim.run(0.5, record_every=0.01)
    en = res.energies
    assert np.asarray(res.strain)[:, k].max() > 1e-4  # the impact strains the block
    assert np.abs(en[1:, -1]).max() < 0.01 * en[:, 0].max()
