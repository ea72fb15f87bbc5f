"""Central-spring bonds (ks = 0, as LIGGGHTS' harmonic bonds) in the sphere engine, against independent references:
a linear solve of the spring network, the two-body oscillation, spin conservation, breakage by stretch."""
import math

import numpy as np
import pytest

from dda.blockspec import BlockSpec
from dda.simulation import ContactLaw
from dda.spheres import BondLaw, SphereSet, SphereSimulation

G = 9.81


def fcc_block(nx, ny, nz, r):
    """Centres of an FCC lattice (nearest distance 2r) in nx x ny x nz cubic cells, and its touching pairs."""
    a = 2.0 * r * math.sqrt(2.0)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]) * a
    pts = []
    for i in range(nx + 1):
        for j in range(ny + 1):
            for k in range(nz + 1):
                for b in basis:
                    p = np.array([i, j, k]) * a + b
                    if np.all(p <= np.array([nx, ny, nz]) * a + 1e-9):
                        pts.append(p)
    c = np.array(pts)
    d = np.linalg.norm(c[:, None] - c[None], axis=2)
    i, j = np.nonzero(np.triu(np.abs(d - 2 * r) < 1e-9 * r, 1))
    return c, np.c_[i, j]


def network_displacement(c, pairs, kn, free, load):
    """Small-displacement solution of a network of central springs: K u = f with K = sum kn n n^T per spring
    (assembled densely), the fixed nodes' rows and columns removed."""
    n = len(c)
    K = np.zeros((3 * n, 3 * n))
    for (i, j) in pairs:
        e = c[j] - c[i]
        e = e / np.linalg.norm(e)
        k = kn * np.outer(e, e)
        for a, b, s in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[3 * a:3 * a + 3, 3 * b:3 * b + 3] += s * k
    dof = np.repeat(free, 3)
    u = np.zeros(3 * n)
    u[dof] = np.linalg.solve(K[np.ix_(dof, dof)], load.reshape(-1)[dof])
    return u.reshape(n, 3)


def test_hanging_fcc_block_of_central_bonds_reaches_the_static_solution_of_its_spring_network():
    r, rho, kn = 0.01, 2600.0, 1e6
    c, pairs = fcc_block(2, 2, 3, r)
    ss = SphereSet(c, np.full(len(c), r), density=rho)
    ss.add_bonds(pairs, BondLaw(kn=kn, shear_ratio=0.0))
    assert np.all(ss.bond_ks == 0.0)
    ss.fixed[c[:, 2] > c[:, 2].max() - 1e-9] = True
    m = ss.mass[0]
    side = np.array([0.4 * m * G, -0.2 * m * G, 0.0])  # a sideways load as well: the network carries it by stretch
    ss.body_force[:] = side
    sim = SphereSimulation(ss, ContactLaw(kn=kn), gravity=(0, 0, -G), local_damping=0.8)
    assert math.isfinite(sim.dt_crit) and sim.dt_crit > 0
    sim.run(6000 * sim.dt, record_every=3000 * sim.dt)
    load = np.tile(side + m * np.array([0.0, 0.0, -G]), (len(c), 1))
    u_ref = network_displacement(c, pairs, kn, ~ss.fixed, load)
    u = sim.displacement()
    assert np.abs(u_ref).max() > 1e-6  # a strain of about 1e-4: linear theory holds to that order
    assert np.linalg.norm(u - u_ref) < 3e-3 * np.linalg.norm(u_ref)
    # central bonds exert no torque: nothing turns
    assert np.all(sim.w == 0.0)
    # the static bond forces balance the loads of the spheres below the fixed layer
    assert -sim.bond_fn.sum() != 0.0 and sim.bond_intact.all()


def test_hanging_chain_of_central_bonds_stretches_by_the_weight_below_each_bond():
    # a vertical chain: bond k (from the top) carries the weight of the N - 1 - k spheres below it
    N, r, rho, kn = 8, 0.05, 2000.0, 2e5
    c = np.c_[np.zeros(N), np.zeros(N), -2 * r * np.arange(N)]
    ss = SphereSet(c, np.full(N, r), density=rho)
    ss.add_bonds(np.c_[np.arange(N - 1), np.arange(1, N)], BondLaw(kn=kn, ks=0.0))
    ss.fixed[0] = True
    sim = SphereSimulation(ss, ContactLaw(kn=kn), gravity=(0, 0, -G), local_damping=0.8)
    sim.run(4000 * sim.dt, record_every=2000 * sim.dt)
    m = ss.mass[0]
    gaps = -np.diff(sim.x[:, 2]) - 2 * r
    assert gaps == pytest.approx((N - 1 - np.arange(N - 1)) * m * G / kn, rel=1e-4)
    assert sim.bond_fn == pytest.approx((N - 1 - np.arange(N - 1)) * m * G, rel=1e-4)


@pytest.mark.parametrize("alpha", [0.3, 0.8])
def test_hanging_chain_with_local_damping_closes_its_energy_balance(alpha):
    """The chain above settling from unstretched bonds with local damping alpha: its balance (kinetic, potential,
    bond and contact springs, the damping's work) stays within 1e-3 of the potential energy's drop. The damping's
    work pairs with the mean of the half-step velocities on either side of the step (the product-form kinetic
    energy's); with the velocity before the step alone it was -2.3e-3 (alpha 0.3) and -5.1e-3 (0.8)."""
    N, r, rho, kn = 8, 0.05, 2000.0, 2e5
    c = np.c_[np.zeros(N), np.zeros(N), -2 * r * np.arange(N)]
    ss = SphereSet(c, np.full(N, r), density=rho)
    ss.add_bonds(np.c_[np.arange(N - 1), np.arange(1, N)], BondLaw(kn=kn, ks=0.0))
    ss.fixed[0] = True
    sim = SphereSimulation(ss, ContactLaw(kn=kn), gravity=(0, 0, -G), local_damping=alpha)
    res = sim.run(2000 * sim.dt, record_every=500 * sim.dt)
    drop = res.energy_column("potential")[0] - res.energy_column("potential")[-1]
    assert res.energy_column("local_damping")[-1] > 0.3 * drop
    assert abs(res.energy_column("balance_error")[-1]) < 1e-3 * drop


@pytest.mark.parametrize("radii", [(0.1, 0.1), (0.1, 0.07)])
def test_central_bond_pair_oscillates_at_the_two_body_frequency_and_keeps_its_spin(radii):
    rho, kn, s0 = 1000.0, 2e5, 0.002
    e = np.array([1.0, 2.0, 2.0]) / 3.0
    L0 = radii[0] + radii[1]
    w0 = np.array([[3.0, -1.0, 2.0], [-2.0, 4.0, 1.0]])

    def run(law, T_periods):
        ss = SphereSet([[0, 0, 0], L0 * e], radii, density=rho)
        ss.add_bonds([[0, 1]], law)
        ss.centers[1] += s0 * e
        ss.angular_velocity[:] = w0
        m1, m2 = ss.mass
        om = math.sqrt(kn * (1 / m1 + 1 / m2))
        sim = SphereSimulation(ss, ContactLaw(kn=kn), gravity=(0, 0, 0), dt=0.01 / om)
        res = sim.run(T_periods * 2 * math.pi / om, record_every=sim.dt)
        return sim, res, om

    sim, res, om = run(BondLaw(kn=kn, shear_ratio=0.0), 4)
    if radii[0] == radii[1]:
        assert om == pytest.approx(math.sqrt(2 * kn / sim.m[0]))
    pos = np.asarray(res.pos)
    s = np.linalg.norm(pos[:, 1] - pos[:, 0], axis=1) - L0
    assert np.max(np.abs(s - s0 * np.cos(om * res.times))) < 2e-3 * s0
    # the motion stays on the bond axis and the spins are untouched
    lateral = (pos[:, 1] - pos[:, 0]) - np.outer((pos[:, 1] - pos[:, 0]) @ e, e)
    assert np.abs(lateral).max() < 1e-12
    assert np.array_equal(sim.w, w0)
    assert abs(res.energy_column("balance_error")[-1]) < 1e-3 * 0.5 * kn * s0 * s0
    # with a shear spring the same spins load the bond: the check above can tell the two apart
    sim_s, _, _ = run(BondLaw(kn=kn, shear_ratio=0.5), 1)
    assert np.abs(sim_s.w - w0).max() > 1e-2 * np.abs(w0).max()


def _pull(direction, tensile, shear, shear_ratio, steps):
    r, kn, v = 0.2, 1e6, 0.05
    ss = SphereSet([[0, 0, 0], [2 * r, 0, 0]], [r, r], density=2000.0)
    ss.add_bonds([[0, 1]], BondLaw(kn=kn, shear_ratio=shear_ratio, tensile=tensile, shear=shear))
    ss.fixed[0] = True
    ss.prescribed[1] = True
    ss.velocity[1] = v * np.asarray(direction, float)
    sim = SphereSimulation(ss, ContactLaw(kn=1e6), gravity=(0, 0, 0), dt=1e-4)
    sim.run(steps * sim.dt, record_every=sim.dt)
    return sim, r, kn, v, math.pi * r * r


def test_central_bond_breaks_in_tension_at_its_tensile_force():
    sim, r, kn, v, area = _pull([1, 0, 0], tensile=2e3, shear=0.0, shear_ratio=0.0, steps=8000)
    ft = 2e3 * area
    t_break = ft / (kn * v)  # stretch v t reaches ft / kn
    assert not sim.bond_intact[0]
    assert abs(sim.bond_break_time[0] - t_break) <= 1.01 * sim.dt
    assert sim.bond_fn[0] == 0.0
    # just before: intact, its force at most ft (zero shear strength does not matter: no shear force)
    steps = int(t_break / 1e-4) - 1
    sim2, *_ = _pull([1, 0, 0], tensile=2e3, shear=0.0, shear_ratio=0.0, steps=steps)
    # (the force of the last step, at the positions it started from: (steps - 1) dt v of stretch)
    assert sim2.bond_intact[0] and sim2.bond_fn[0] == pytest.approx(kn * v * (steps - 1) * 1e-4, rel=1e-9)
    assert sim2.bond_fn[0] <= ft


def test_central_bond_pulled_sideways_breaks_only_when_the_geometric_stretch_reaches_its_tensile_force():
    # sideways motion y = v t stretches the bond by sqrt(L0^2 + y^2) - L0; a shear strength of 1 Pa would break a
    # bond with a shear spring at once
    tensile = 50.0
    sim, r, kn, v, area = _pull([0, 1, 0], tensile=tensile, shear=1.0, shear_ratio=0.0, steps=6000)
    L0, ft = 2 * r, tensile * area
    y = math.sqrt((L0 + ft / kn) ** 2 - L0 ** 2)
    assert not sim.bond_intact[0]
    assert abs(sim.bond_break_time[0] - y / v) <= 1.01 * sim.dt
    sim_s, *_ = _pull([0, 1, 0], tensile=tensile, shear=1.0, shear_ratio=0.5, steps=100)
    assert not sim_s.bond_intact[0] and sim_s.bond_break_time[0] < 10 * sim_s.dt


def test_spheres_on_central_bonds_roll_under_contact_friction():
    # a bonded pair sliding along a floor: friction spins each sphere up until it rolls at 5/7 of the initial speed
    r, v0, phi = 0.05, 1.0, 30.0
    ss = SphereSet([[0, 0, r], [2 * r, 0, r]], [r, r], density=2600.0)
    ss.add_bonds([[0, 1]], BondLaw(kn=1e6, ks=0.0))
    ss.velocity[:] = [v0, 0, 0]
    floor = BlockSpec(np.array([[-1, -1, -1], [2, -1, -1], [2, 1, -1], [-1, 1, -1], [-1, -1, 0], [2, -1, 0],
                                [2, 1, 0], [-1, 1, 0]], float),
                      [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]], fixed=True)
    sim = SphereSimulation(ss, ContactLaw(kn=1e6, ks=4e5, friction_deg=phi, damping=0.3), walls=[floor],
                           gravity=(0, 0, -G))
    assert math.isfinite(sim.dt_crit) and sim.dt_crit > 0
    t_roll = 2 * v0 / (7 * math.tan(math.radians(phi)) * G)
    sim.run(3 * t_roll)
    assert sim.v[:, 0] == pytest.approx(np.full(2, 5 / 7 * v0), rel=1e-2)
    assert sim.w[:, 1] == pytest.approx(sim.v[:, 0] / r, rel=1e-2)
    assert sim.bond_intact.all()


def test_central_bonds_from_a_scene(tmp_path, capsys):
    from dda.cli import main
    from dda.scene import load_scene

    (tmp_path / "beam.toml").write_text(
        'name = "beam"\n[domain]\nmin = [0, 0, 0]\nmax = [0.6, 0.3, 0.3]\n[packing]\nkind = "fcc"\nradius = 0.05\n')
    base = '[simulation]\nduration = 0.01\n[contact]\nkn = 1e7\n[spheres]\nmodel = "beam.toml"\nfixed = ["x<0.06"]\n'
    (tmp_path / "c.toml").write_text(base + "bond_shear_ratio = 0\n")
    scene = load_scene(tmp_path / "c.toml")
    ss, sim = scene.build_spheres()
    assert ss.n_bonds > 0 and np.all(ss.bond_ks == 0.0) and np.all(ss.bond_kn > 0)
    assert len(sim.cbond_idx) == ss.n_bonds and len(sim.bond_full) == 0
    assert math.isfinite(sim.dt) and sim.dt > 0
    sim.run(20 * sim.dt)
    assert np.all(np.isfinite(sim.x)) and np.all(sim.w == 0.0)
    (tmp_path / "k.toml").write_text(base + "bond_ks = 0.0\n")
    ss2, _ = load_scene(tmp_path / "k.toml").build_spheres()
    assert np.all(ss2.bond_ks == 0.0)
    (tmp_path / "bad.toml").write_text(base + "bond_shear_ratio = -0.1\n")
    assert main(["run", str(tmp_path / "bad.toml"), "-o", str(tmp_path / "o"), "--quiet"]) == 2
    assert "spheres.bond_shear_ratio" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    with pytest.raises(ValueError):
        BondLaw(kn=1.0, ks=-1.0).check()
    BondLaw(shear_ratio=0.0).check()


def test_mixed_bonds_match_the_full_law_where_they_have_a_shear_spring():
    # a model mixing both kinds: the bonds with a shear spring behave exactly as in a model with the same bonds
    # where the central ones carry a vanishing shear spring instead (1e-12 kn: no measurable shear force)
    rng = np.random.default_rng(3)
    c, pairs = fcc_block(1, 1, 2, 0.01)
    c = c + rng.normal(0, 1e-4, c.shape)
    central = rng.random(len(pairs)) < 0.5
    v0 = rng.normal(0, 0.01, c.shape)
    w0 = rng.normal(0, 1.0, c.shape)

    def run(ks_central):
        ss = SphereSet(c, np.full(len(c), 0.01), density=2600.0)
        ss.add_bonds(pairs[~central], BondLaw(kn=1e5, shear_ratio=0.4))
        ss.add_bonds(pairs[central], BondLaw(kn=1e5, ks=ks_central))
        ss.fixed[c[:, 2] < 0.005] = True
        ss.velocity[:] = v0 * ~ss.fixed[:, None]
        ss.angular_velocity[:] = w0 * ~ss.fixed[:, None]
        sim = SphereSimulation(ss, ContactLaw(kn=1e5), gravity=(0, 0, -G), dt=2e-5)
        sim.run(500 * sim.dt)
        return sim

    a, b = run(0.0), run(1e-7)
    assert len(a.cbond_idx) == central.sum() and len(b.cbond_idx) == 0
    assert np.abs(a.x - b.x).max() < 1e-9
    assert np.abs(a.w - b.w).max() < 1e-6 * np.abs(b.w).max()


def test_damped_central_bond_decays_at_the_damped_oscillator_rate():
    # viscous damping c = 2 zeta sqrt(kn m_eff) on the normal relative velocity: the stretch of a free pair decays
    # as exp(-zeta omega t) at the damped frequency omega sqrt(1 - zeta^2); the energy balance holds
    rho, kn, s0, zeta, r = 1000.0, 2e5, 0.002, 0.05, 0.1
    ss = SphereSet([[0, 0, 0], [2 * r, 0, 0]], [r, r], density=rho)
    ss.add_bonds([[0, 1]], BondLaw(kn=kn, shear_ratio=0.0, damping=zeta))
    ss.centers[1, 0] += s0
    m = ss.mass[0]
    om = math.sqrt(2 * kn / m)
    sim = SphereSimulation(ss, ContactLaw(kn=kn), gravity=(0, 0, 0), dt=0.005 / om)
    res = sim.run(3 * 2 * math.pi / om, record_every=sim.dt)
    pos = np.asarray(res.pos)
    s = pos[:, 1, 0] - pos[:, 0, 0] - 2 * r
    t = res.times
    od = om * math.sqrt(1 - zeta ** 2)
    ref = s0 * np.exp(-zeta * om * t) * (np.cos(od * t) + zeta / math.sqrt(1 - zeta ** 2) * np.sin(od * t))
    assert np.max(np.abs(s - ref)) < 5e-3 * s0
    e = res.energy_column("damping")[-1]
    assert e > 0.5 * 0.5 * kn * s0 * s0  # more than half the initial energy went into damping
    assert abs(res.energy_column("balance_error")[-1]) < 1e-2 * 0.5 * kn * s0 * s0
