"""Smooth joints of the bonded-sphere engine (dda.spheres SphereSet.add_joints) against analytical motion."""
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from dda.simulation import ContactLaw
from dda.spheres import BondLaw, SphereSet, SphereSimulation

G = 9.81


def fcc(lo, hi, r):
    """FCC lattice (nearest neighbours at 2 r) filling the box lo..hi (plain numpy)."""
    a = 2.0 * math.sqrt(2.0) * r
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]) * a
    ranges = [np.arange(lo[k], hi[k], a) for k in range(3)]
    cells = np.stack(np.meshgrid(*ranges, indexing="ij"), -1).reshape(-1, 3)
    c = (cells[:, None, :] + basis[None]).reshape(-1, 3)
    return c[np.all((c >= lo) & (c <= hi), axis=1)]


def two_blocks(alpha_deg, r=0.05, joint_reach=3.0):
    """A fixed slab under an inclined plane (dip alpha, dipping towards -x) and a bonded block above it.

    Returns (centres, upper mask, bonded pairs, cross pairs, their normals i -> j, down-dip unit vector).
    Cross pairs: every pair across the plane closer than `joint_reach` r whose centres are less than 2 r
    apart normal to the plane (the pairs that can touch while the block slides along the plane)."""
    a = math.radians(alpha_deg)
    n = np.array([-math.sin(a), 0.0, math.cos(a)])
    down = np.array([-math.cos(a), 0.0, -math.sin(a)])
    c = fcc((0.0, 0.0, 0.0), (1.6, 0.45, 1.2), r)
    p0 = np.array([0.8, 0.0, 0.6])
    h = (c - p0) @ n
    along = (c - p0) @ np.array([math.cos(a), 0.0, math.sin(a)])
    upper = (h > 0) & (h < 0.25) & (np.abs(along) < 0.35)
    lower = (h <= 0) & (h > -3.5 * r)
    c = c[upper | lower]
    upper = upper[upper | lower]
    tree = cKDTree(c)
    touch = tree.query_pairs(2 * r * (1 + 1e-9), output_type="ndarray")
    bonded = touch[upper[touch[:, 0]] & upper[touch[:, 1]]]
    near = tree.query_pairs(joint_reach * r, output_type="ndarray")
    cross = near[upper[near[:, 0]] != upper[near[:, 1]]]
    dn = (c[cross[:, 1]] - c[cross[:, 0]]) @ n
    cross = cross[np.abs(dn) < 2 * r]
    normals = np.where(((c[cross[:, 1]] - c[cross[:, 0]]) @ n)[:, None] >= 0, n, -n)
    return c, upper, bonded, cross, normals, down


def slide(alpha, phi, duration, smooth=True):
    r = 0.05
    c, upper, bonded, cross, normals, down = two_blocks(alpha, r)
    ss = SphereSet(c, np.full(len(c), r), density=2600.0)
    ss.add_bonds(bonded, BondLaw(kn=2e6, ks=1e6))
    ss.fixed[:] = ~upper
    if smooth:
        ss.add_joints(cross, normals, phi)
    sim = SphereSimulation(ss, ContactLaw(kn=2e6, ks=1e6, friction_deg=phi, damping=0.3), gravity=(0, 0, -G))
    res = sim.run(duration, record_every=duration / 20)
    s = (np.asarray(res.pos)[:, upper] - c[upper]).mean(1) @ down
    return sim, res, s, upper


def test_block_slides_on_a_smooth_joint_as_the_analytical_block_on_an_incline():
    alpha, phi = 30.0, 20.0
    acc = G * (math.sin(math.radians(alpha)) - math.tan(math.radians(phi)) * math.cos(math.radians(alpha)))
    T = 0.25  # slides about 1.1 r: within the 2 r a smooth joint contact lasts
    sim, res, s, upper = slide(alpha, phi, T)
    t = res.times
    assert s[-1] == pytest.approx(0.5 * acc * T * T, rel=0.03)
    late = t > 0.4 * T
    assert np.allclose(s[late], 0.5 * acc * t[late] ** 2, rtol=0.05)
    assert sim.bond_intact.all()
    # it slides as a block: no sphere of it moves apart from the others by more than the elastic strain
    d = sim.x[upper] - sim.x0[upper]
    assert np.abs(d - d.mean(0)).max() < 0.02 * s[-1]
    # energy balance (kinetic + potential + elastic + dissipated) to a small fraction of the work of gravity
    w = sim.spheres.mass[upper].sum() * G * math.sin(math.radians(alpha)) * s[-1]
    assert abs(res.energy_column("balance_error")[-1]) < 0.01 * w


def test_block_holds_on_a_smooth_joint_when_friction_exceeds_the_dip():
    _, _, s, _ = slide(30.0, 35.0, 0.15)
    assert abs(s[-1]) < 2e-4  # elastic creep only (0.4 % of the radius)


def test_without_smooth_joints_the_sphere_roughness_changes_the_sliding():
    alpha, phi = 30.0, 20.0
    acc = G * (math.sin(math.radians(alpha)) - math.tan(math.radians(phi)) * math.cos(math.radians(alpha)))
    _, _, s, _ = slide(alpha, phi, 0.25, smooth=False)
    assert abs(s[-1] - 0.5 * acc * 0.25 ** 2) > 0.2 * 0.5 * acc * 0.25 ** 2


@pytest.mark.parametrize("beta", [0.0, 25.0])
def test_sphere_on_a_frictionless_joint_feels_only_the_joint_normal(beta):
    # a free sphere resting on a fixed one, their centre line 35 deg from the vertical; the joint between them
    # is tilted by beta: the force on the free sphere is along the joint normal only, so it slides down the
    # joint plane at g sin(beta) and settles kn-compressed by m g cos(beta) / kn along the normal (a
    # centre-line contact would push it off sideways)
    r, rho, kn = 0.1, 2000.0, 1e6
    th = math.radians(35.0)
    c = np.array([[0.0, 0.0, 0.0], [2 * r * math.sin(th), 0.0, 2 * r * math.cos(th)]])
    b = math.radians(beta)
    n = np.array([math.sin(b), 0.0, math.cos(b)])
    down = np.array([math.cos(b), 0.0, -math.sin(b)])  # in the joint plane, downhill
    ss = SphereSet(c, [r, r], density=rho)
    ss.fixed[0] = True
    ss.add_joints([[0, 1]], [n], 0.0)
    m = ss.mass[1]
    sim = SphereSimulation(ss, ContactLaw(kn=kn, ks=kn / 2, friction_deg=0.0, damping=0.5), gravity=(0, 0, -G),
                           dt=2e-4)
    T = 0.12
    res = sim.run(T, record_every=T / 12)
    d = sim.x[1] - c[1]
    assert d @ down == pytest.approx(0.5 * G * math.sin(b) * T * T, abs=1e-3 * r)
    assert d @ n == pytest.approx(-m * G * math.cos(b) / kn, rel=1e-3)
    assert abs(d[1]) < 1e-12
    # no torque from a smooth joint: the sphere does not spin
    assert np.abs(sim.w[1]).max() == 0.0
    # energy balance with the damping dissipation
    assert abs(res.energy_column("balance_error")[-1]) < 1e-3 * m * G * (m * G / kn + abs(d @ down)) + 1e-9


def test_sphere_pressed_onto_a_joint_settles_at_the_joint_normal_compression():
    # centre line 35 deg off the joint normal, friction high, damped: the static force is m g along the joint
    # normal (vertical), the compression m g / kn measured along it, no sideways drift
    r, rho, kn = 0.1, 2000.0, 1e6
    th = math.radians(35.0)
    c = np.array([[0.0, 0.0, 0.0], [2 * r * math.sin(th), 0.0, 2 * r * math.cos(th)]])
    ss = SphereSet(c, [r, r], density=rho)
    ss.fixed[0] = True
    ss.add_joints([[1, 0]], [[0.0, 0.0, -1.0]], 30.0)  # given from sphere 1 to 0: flipped to 0 -> 1
    assert np.allclose(ss.joint_normal, [[0, 0, 1]])
    sim = SphereSimulation(ss, ContactLaw(kn=kn, ks=kn / 2, friction_deg=30.0, damping=0.7), gravity=(0, 0, -G))
    sim.run(0.3)
    m = ss.mass[1]
    assert sim.x[1, 2] - c[1, 2] == pytest.approx(-m * G / kn, rel=1e-3)
    assert np.abs(sim.x[1, :2] - c[1, :2]).max() < 1e-9
    # without the joint the same pair rolls and slides off
    ss2 = SphereSet(c, [r, r], density=rho)
    ss2.fixed[0] = True
    sim2 = SphereSimulation(ss2, ContactLaw(kn=kn, ks=kn / 2, friction_deg=30.0, damping=0.7), gravity=(0, 0, -G))
    sim2.run(0.3)
    assert sim2.x[1, 0] - c[1, 0] > 0.2 * r


def test_smooth_joint_contact_is_lost_after_sliding_two_radii():
    # frictionless horizontal joint, the free sphere launched along it at v0: it glides at height while the
    # joint contact lasts (JCFpm: until the cumulative sliding exceeds 2 min(r_i, r_j)), then falls freely
    r, v0 = 0.1, 1.0
    c = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2 * r]])
    ss = SphereSet(c, [r, r], density=2000.0)
    ss.fixed[0] = True
    ss.velocity[1] = (v0, 0.0, 0.0)
    ss.add_joints([[0, 1]], [[0.0, 0.0, 1.0]], 0.0)
    sim = SphereSimulation(ss, ContactLaw(kn=1e7, ks=5e6, friction_deg=0.0, damping=0.5), gravity=(0, 0, -G),
                           dt=1e-5)
    t_loss = 2 * r / v0
    sim.run(t_loss - 0.01)
    assert sim.joint_on[0]
    assert sim.x[1, 2] == pytest.approx(2 * r, abs=1e-5)
    sim.run(0.01 + 0.05)
    assert not sim.joint_on[0]
    assert sim.x[1, 0] == pytest.approx(v0 * (t_loss + 0.05), rel=1e-6)
    assert sim.x[1, 2] - 2 * r == pytest.approx(-0.5 * G * 0.05 ** 2, rel=0.02)


def test_joint_input_errors():
    ss = SphereSet([[0, 0, 0], [0.2, 0, 0], [0.4, 0, 0]], [0.1, 0.1, 0.1])
    ss.add_bonds([[0, 1]], BondLaw())
    with pytest.raises(ValueError, match="both bonded and a smooth joint"):
        ss.add_joints([[1, 0]], [[1, 0, 0]], 30.0)
    with pytest.raises(ValueError, match="non-zero"):
        ss.add_joints([[1, 2]], [[0, 0, 0]], 30.0)
    with pytest.raises(ValueError, match="one joint normal per pair"):
        ss.add_joints([[1, 2]], np.zeros((0, 3)), 30.0)
    ss.add_joints([[1, 2]], [[2, 0, 0]], 30.0)
    assert np.allclose(ss.joint_normal, [[1, 0, 0]])
    with pytest.raises(ValueError, match="twice"):
        ss.add_joints([[2, 1]], [[-1, 0, 0]], 30.0)


def test_scene_joint_pairs_become_smooth_joints(tmp_path):
    from dda.scene import load_scene
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    nrm = np.array([0.3, 0.1, 1.0]) / np.linalg.norm([0.3, 0.1, 1.0])
    d = {"name": "j", "domain": {"min": [0, 0, 0], "max": [0.6, 0.6, 0.6]}, "packing": {"kind": "fcc", "radius": 0.05},
         "bonds": {"rule": "colour"},
         "discontinuity": [{"name": "a", "centre": [0.3, 0.3, 0.3], "normal": nrm.tolist(), "radius": 2.0}]}
    model = build_model(scene_from_dict(d, "j.toml"))
    model.save(tmp_path / "model.npz")
    base = ('name = "s"\n[simulation]\nduration = 0.01\n[contact]\nkn = 1e7\nfriction = 30.0\n'
            '[spheres]\nmodel = "model.npz"\nfixed = ["z<0.1"]\n')
    (tmp_path / "a.toml").write_text(base + "joint_friction = 12.0\n")
    (tmp_path / "b.toml").write_text(base + "smooth_joints = false\n")
    ss, sim = load_scene(tmp_path / "a.toml").build_spheres()
    # brute force: every unbonded touching pair whose centres lie on both sides of the disc plane
    c = model.centers
    side = (c - [0.3, 0.3, 0.3]) @ nrm
    p = model.bonds[~model.bonded]
    across = p[np.sign(side[p[:, 0]]) != np.sign(side[p[:, 1]])]
    assert ss.n_joints == len(across) > 0
    assert np.array_equal(np.c_[ss.joint_i, ss.joint_j], across)
    expect = np.where((side[across[:, 1]] > side[across[:, 0]])[:, None], nrm, -nrm)
    assert np.allclose(ss.joint_normal, expect)
    assert np.allclose(ss.joint_tanphi, math.tan(math.radians(12.0)))
    ss2, _ = load_scene(tmp_path / "b.toml").build_spheres()
    assert ss2.n_joints == 0
    # with a moving block (the coupled loop) the same joints
    (tmp_path / "c.toml").write_text(base + '[[block]]\nname = "cube"\nshape = "cube"\nsize = 0.2\n'
                                     'center = [0.3, 0.3, 0.9]\n')
    ss3, sim3 = load_scene(tmp_path / "c.toml").build_spheres()
    assert sim3.blocks is not None and ss3.n_joints == ss.n_joints


def test_smooth_joints_with_moving_blocks_match_the_sphere_loop():
    # the tilted frictionless joint of the test above, once in the sphere loop and once in the coupled loop
    # (a free cube far away, never touched): the same trajectory to round-off, and the analytical slide
    from dda.blockspec import BlockSpec
    from dda.system import BlockSystem

    r, rho, kn = 0.1, 2000.0, 1e6
    th, b = math.radians(35.0), math.radians(25.0)
    c = np.array([[0.0, 0.0, 0.0], [2 * r * math.sin(th), 0.0, 2 * r * math.cos(th)]])
    n = np.array([math.sin(b), 0.0, math.cos(b)])
    out = []
    for coupled in (False, True):
        ss = SphereSet(c, [r, r], density=rho)
        ss.fixed[0] = True
        ss.add_joints([[0, 1]], [n], 0.0)
        walls = None
        if coupled:
            walls = BlockSystem()
            v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                         float) * 0.2 + [5.0, 5.0, 5.0]
            f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
            walls.add_block(BlockSpec(v, f))
        sim = SphereSimulation(ss, ContactLaw(kn=kn, ks=kn / 2, friction_deg=0.0, damping=0.5), walls=walls,
                               gravity=(0, 0, -G), dt=2e-4)
        assert (sim.blocks is not None) == coupled
        sim.run(0.12)
        out.append(sim.x[1].copy())
    assert np.allclose(out[0], out[1], rtol=0, atol=1e-12)
    down = np.array([math.cos(b), 0.0, -math.sin(b)])
    assert (out[1] - c[1]) @ down == pytest.approx(0.5 * G * math.sin(b) * 0.12 ** 2, abs=1e-3 * r)
