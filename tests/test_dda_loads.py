"""DDA loads and prescribed motion: body loads, point loads, prescribed velocities against analytical motion."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dda.scene import scene_from_dict
from dda.simulation import BlowUpError, ContactLaw, Simulation
from dda.blockspec import BlockSpec
from dda.system import BlockSystem, quat_to_matrix
from blocks import box  # independent of dda.shapes
from sgim.scene import SceneError

G = 9.81


def test_body_load_gives_uniform_acceleration():
    bs = BlockSystem()
    i = bs.add_block(box((0, 0, 0), (1, 2, 0.5)), density=1000.0)
    m = 1000.0 * 1.0
    F = np.array([300.0, -200.0, 50.0])
    bs.add_body_load(i, F)
    bs.add_body_load(i, F)  # loads add up
    sim = Simulation(bs, ContactLaw(kn=1e8), gravity=(0, 0, 0), dt=1e-3)
    res = sim.run(0.5, record_every=0.1)
    t = res.times[-1]
    expect = 0.5 * (2 * F / m) * t * t
    assert np.allclose(sim.displacement(i), expect, rtol=1e-9, atol=1e-12)
    assert np.allclose(sim.velocity(i), 2 * F / m * (t - 0.5 * sim.dt), rtol=1e-9)  # the half-step velocity
    # the load's potential -F.x keeps the balance closed
    KE = res.energy_column("kinetic")[-1]  # the energy of the last step, taken at t - dt
    te = t - sim.dt
    assert abs(KE - 0.5 * m * np.dot(2 * F / m * te, 2 * F / m * te)) < 1e-5 * KE
    assert abs(res.energy_column("balance_error")[-1]) < 1e-5 * KE


def test_point_load_couple_turns_the_block_like_the_pendulum_equation():
    # cube of side a, two opposite loads +-F (along y) at +-d (along x): the torque about z is 2 d F cos(theta)
    # as the points turn with the block, so I theta'' = 2 d F cos(theta), theta(0) = 0 (solved by scipy)
    a, rho, d, F = 1.0, 1000.0, 0.4, 1000.0
    bs = BlockSystem()
    i = bs.add_block(box((-a / 2, -a / 2, -a / 2), (a / 2, a / 2, a / 2)), density=rho)
    bs.add_point_load(i, (d, 0, 0), (0, F, 0))
    bs.add_point_load(i, (-d, 0, 0), (0, -F, 0))
    m = rho * a ** 3
    inertia = m * a * a / 6
    sim = Simulation(bs, ContactLaw(kn=1e8), gravity=(0, 0, 0), dt=2e-4)
    R0 = sim.rotation(i)  # body principal frame at t = 0
    T = 0.8
    res = sim.run(T, record_every=0.2)
    sol = solve_ivp(lambda t, y: [y[1], 2 * d * F * math.cos(y[0]) / inertia], (0, T), [0.0, 0.0],
                    rtol=1e-11, atol=1e-12)
    theta_ref = sol.y[0, -1]
    R = sim.rotation(i) @ R0.T
    theta = math.atan2(R[1, 0], R[0, 0])
    assert theta_ref > 1.0  # a large turn, so the load really follows the block
    assert abs(theta - theta_ref) < 1e-3 * theta_ref
    assert np.allclose(sim.displacement(i), 0.0, atol=1e-12)  # the couple has no net force
    # energy: the loads' potential balances the kinetic energy
    KE = res.energy_column("kinetic")[-1]
    assert abs(KE - 0.5 * inertia * sol.y[1, -1] ** 2) < 2e-3 * KE
    assert abs(res.energy_column("balance_error")[-1]) < 2e-3 * KE


def test_point_load_on_a_free_block_accelerates_the_centroid_by_f_over_m():
    bs = BlockSystem()
    i = bs.add_block(box((0, 0, 0), (2, 1, 1)), density=500.0)
    F = np.array([0.0, 0.0, 2000.0])
    bs.add_point_load(i, (2.0, 0.5, 0.5), F)  # off the centroid: it also turns the block
    sim = Simulation(bs, ContactLaw(kn=1e8), gravity=(0, 0, 0), dt=1e-4)
    R0 = sim.rotation(i)
    sim.run(0.3, record_every=0.1)
    m = 500.0 * 2.0
    assert np.allclose(sim.displacement(i), 0.5 * F / m * sim.time ** 2, rtol=1e-9, atol=1e-12)
    assert np.linalg.norm(sim.rotation(i) - R0) > 0.1


def test_prescribed_block_moves_exactly_and_pushes_a_block_along_a_frictional_floor():
    # a frictionless plate moving at v pushes a block lying on a fixed floor with friction mu: after the start the
    # block moves with the plate, the plate does work mu m g v per second against friction
    v, mu = 0.5, math.tan(math.radians(20.0))
    bs = BlockSystem()
    bs.add_block(box((-5, -2, -1), (5, 2, 0)), fixed=True)
    b = bs.add_block(box((0, -0.5, 0), (1, 0.5, 1)), density=1000.0)
    p = bs.add_block(box((-0.3, -0.6, 0.05), (-0.01, 0.6, 1.2), velocity=(v, 0, 0), angular_velocity=(0, 0, 0)),
                     prescribed=True, material="plate")
    sim = Simulation(bs, ContactLaw(kn=1e8, friction_deg=20.0, damping=0.3), dt=None,
                     pair_laws={("rock", "plate"): ContactLaw(kn=1e8, friction_deg=0.0, damping=0.3)})
    R0 = sim.rotation(p)
    res = sim.run(2.0, record_every=0.1)
    assert np.allclose(sim.displacement(p), (v * sim.time, 0, 0), rtol=1e-12, atol=1e-12)
    assert np.allclose(sim.rotation(p), R0, atol=1e-12)
    vb = res.velocities[-5:, b, 0]
    assert np.all(np.abs(vb - v) < 1e-3 * v)
    # the block's travel: the plate's travel less the initial gap and the contact overlap
    gap = 0.01
    assert abs(sim.displacement(b)[0] - (v * sim.time - gap)) < 5e-3
    # driver work: mu m g v per second while pushing (energy balance closed by the potential column)
    m = 1000.0
    fr = res.energy_column("friction")
    k0, k1 = len(res.times) // 2, len(res.times) - 1
    rate = (fr[k1] - fr[k0]) / (res.times[k1] - res.times[k0])
    assert abs(rate - mu * m * G * v) < 0.02 * mu * m * G * v
    assert abs(res.energy_column("balance_error")[-1]) < 0.02 * fr[-1]


def test_prescribed_rotation_turns_at_the_given_rate():
    bs = BlockSystem()
    bs.add_block(box((-1, -1, -1), (1, 1, 1)), fixed=True)
    p = bs.add_block(box((3, -0.5, -0.5), (4, 0.5, 0.5), angular_velocity=(0, 0, 2.0)), prescribed=True)
    bs.add_block(box((-0.5, -0.5, 5), (0.5, 0.5, 6)))
    sim = Simulation(bs, ContactLaw(kn=1e8), gravity=(0, 0, -G))
    R0 = sim.rotation(p)
    sim.run(0.5, record_every=0.1)
    R = sim.rotation(p) @ R0.T
    assert abs(math.atan2(R[1, 0], R[0, 0]) - 2.0 * sim.time) < 1e-9
    assert np.allclose(sim.displacement(p), 0, atol=1e-12)


def _scene(**extra):
    d = {
        "simulation": {"duration": 0.2, "dt": 1e-3, "gravity": [0, 0, 0]},
        "contact": {"kn": 1e8},
        "block": [
            {"name": "free", "shape": "cube", "size": 1.0, "center": [0, 0, 0], "force": [100.0, 0, 0]},
            {"name": "plate", "shape": "cube", "size": 1.0, "center": [10, 0, 0], "prescribed": True,
             "velocity": [0, 1.0, 0]},
        ],
        "load": [{"block": "free", "force": [0, 0, 300.0]},
                 {"block": "free", "force": [0, 50.0, 0], "point": [0, 0, 0]}],
    }
    d.update(extra)
    return d


def test_scene_keys_for_loads_and_prescribed_blocks():
    sc = scene_from_dict(_scene())
    bs, sim = sc.build()
    sim.run(0.2, record_every=0.1)
    m = 2600.0
    t = sim.time
    assert np.allclose(sim.displacement(0), 0.5 * np.array([100.0, 50.0, 300.0]) / m * t * t, rtol=1e-9)
    assert np.allclose(sim.displacement(1), (0, t, 0), rtol=1e-12)


@pytest.mark.parametrize("patch,key", [
    ({"load": [{"block": "nope", "force": [1, 0, 0]}]}, "load[0].block"),
    ({"load": [{"block": "free", "force": [1, 0]}]}, "load[0].force"),
    ({"load": [{"block": "free", "force": [1, 0, 0], "where": 1}]}, "load[0]"),
])
def test_bad_load_keys_are_scene_errors(patch, key):
    with pytest.raises(SceneError) as ei:
        scene_from_dict(_scene(**patch))
    assert key in str(ei.value)


def test_fixed_and_prescribed_is_a_scene_error():
    d = _scene()
    d["block"][1]["fixed"] = True
    with pytest.raises(SceneError) as ei:
        scene_from_dict(d)
    assert "prescribed" in str(ei.value)


# ---------------------------------------------------------------- local damping's energy
@pytest.mark.parametrize("plunge, alpha", [(40.0, 0.3), (40.0, 0.8), (0.0, 0.8)])
def test_local_damping_closes_the_energy_balance(plunge, alpha):
    """A cube dropped 0.2 m onto a plane (gravity tilted `plunge` degrees: it lands and slides on 30 degrees of
    friction) with local damping alpha and no contact damping: kinetic + potential + elastic + friction + local
    damping stays its initial value within 1e-3 of the potential energy's drop. Local damping acts within the
    block's step, so its work pairs with the mean of the half-step velocities before and after it, as the
    product-form kinetic energy does; booked with the velocity before the step alone it was off by 2.4 to 4.5 %."""
    psi = math.radians(plunge)
    bs = BlockSystem()
    bs.add_block(box((-20, -2, -1), (20, 2, 0)), fixed=True)
    bs.add_block(box((-0.5, -0.5, 0.2), (0.5, 0.5, 1.2)))
    sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, damping=0.0),
                     gravity=(G * math.sin(psi), 0.0, -G * math.cos(psi)), local_damping=alpha)
    res = sim.run(0.6, record_every=0.1)
    drop = res.energy_column("potential")[0] - res.energy_column("potential")[-1]
    assert res.energy_column("local_damping")[-1] > 0.5 * drop
    assert abs(res.energy_column("balance_error")[-1]) < 1e-3 * drop


@pytest.mark.parametrize("alpha", [0.3, 0.8])
def test_local_damping_slows_a_sliding_block_to_one_minus_alpha_of_its_acceleration(alpha):
    """Cundall's local damping takes alpha |F| against the velocity: a block that slides under a constant net
    force F (a plane tilted 40 degrees, friction 30) accelerates at (1 - alpha) F / m, so it moves
    (1 - alpha) a t^2 / 2 with a = g (sin 40 - cos 40 tan 30) (within 2 %: the block seats on its springs first)."""
    psi = math.radians(40.0)
    bs = BlockSystem()
    bs.add_block(box((-20, -2, -1), (20, 2, 0)), fixed=True)
    i = bs.add_block(box((-0.5, -0.5, 0.0), (0.5, 0.5, 1.0)))
    sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, damping=0.2),
                     gravity=(G * math.sin(psi), 0.0, -G * math.cos(psi)), local_damping=alpha)
    t = 0.5
    sim.run(t, record_every=0.1)
    a = G * (math.sin(psi) - math.cos(psi) * math.tan(math.radians(30.0)))
    assert sim.displacement(i)[0] == pytest.approx(0.5 * (1.0 - alpha) * a * t * t, rel=0.02)


def _cube_on_springs_omega_max(kn, ks, m):
    """The fastest mode of a unit cube (mass m, I = m / 6) on four corner springs (normal kn, shear ks): the
    largest eigenvalue of M^-1 K, K = sum over the corners of B^T diag(ks, ks, kn) B, B = [I, -[r]x]."""
    K = np.zeros((6, 6))
    for x in (-0.5, 0.5):
        for y in (-0.5, 0.5):
            r = np.array([x, y, -0.5])
            rx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
            B = np.hstack([np.eye(3), -rx])
            K += B.T @ np.diag([ks, ks, kn]) @ B
    M = np.diag([m, m, m, m / 6, m / 6, m / 6])
    return math.sqrt(np.linalg.eigvals(np.linalg.solve(M, K)).real.max())


@pytest.mark.parametrize("alpha, frac, stable", [(0.8, 0.95, True), (0.8, 1.05, False), (0.0, 1.05, True)])
def test_local_damping_lowers_the_stable_step_by_sqrt_one_plus_alpha(alpha, frac, stable):
    """Local damping alpha |f| acts against the velocity before the step: in the fastest mode the velocity turns at
    every step, so it points along the new velocity and the springs act as (1 + alpha) times as stiff; the
    central difference is stable for omega_max dt < 2 / sqrt(1 + alpha). A cube ringing on its four corner springs
    (omega_max from the eigenvalues of its 6 x 6 stiffness and mass) at frac x that step, alpha = 0.8: stable at
    0.95, blows up at 1.05; without local damping the same step (omega_max dt = 1.57 < 2) is stable. The engine's
    own step (dt_crit) carries the factor."""
    kn, ks, m = 1e9, 5e8, 2600.0
    w = _cube_on_springs_omega_max(kn, ks, m)
    dt = frac * 2.0 / (w * math.sqrt(1.8))
    bs = BlockSystem()
    bs.add_block(box((-2, -2, -1), (2, 2, 0)), fixed=True)
    i = bs.add_block(box((-0.5, -0.5, 0), (0.5, 0.5, 1)))
    law = ContactLaw(kn=kn, ks=ks, friction_deg=45.0)
    sim = Simulation(bs, law, dt=dt, local_damping=alpha)
    sim.vel[i] = (1e-4, -2e-4, 0.0)
    sim.angmom[i] = np.array([1e-4, -2e-4, 1.5e-4]) * m / 6
    try:
        sim.run(3000 * dt, record_every=100 * dt)
        grew = np.linalg.norm(sim.vel[i]) > 1e-2
    except BlowUpError:
        grew = True
    assert grew != stable
    assert Simulation(bs, law, local_damping=0.8).dt_crit == pytest.approx(Simulation(bs, law).dt_crit / math.sqrt(1.8))


def _cube_on_dashpots_rate(zeta, kn, ks, m):
    """The largest eigenvalue of M^-1 C for the cube of _cube_on_springs_omega_max on four corner dashpots
    cn = 2 zeta sqrt(kn m), cs = 2 zeta sqrt(ks m) (the point dashpots of dda/_contact.py on a fixed floor)."""
    cn, cs = 2 * zeta * math.sqrt(kn * m), 2 * zeta * math.sqrt(ks * m)
    return _cube_on_springs_omega_max(cn, cs, m) ** 2


@pytest.mark.parametrize("zeta, frac", [(0.5, 0.8), (0.1, None)])
def test_overshooting_dashpots_are_scaled_to_stop_a_block_in_one_step_not_turn_it_back(zeta, frac):
    """An explicit dashpot c on a mass m multiplies the velocity by 1 - dt c / m each step: past 1 it turns the
    velocity back, past 2 it blows up. A cube on its four corner dashpots at zeta = 0.5 and omega_max dt = 0.8
    (springs stable) has dt lambda_max(M^-1 C) = 2.97 (the eigenvalues of its 6 x 6 damping and mass): unscaled,
    its rocking would grow at every step (it did: 3.7 mm/s after 400 steps from 2.4, the dashpots making energy).
    The engine scales the block's dashpots so that dt times that rate is 1: the cube comes to rest and the books
    stay closed. At zeta = 0.1 and the engine's own step the dashpots stay exactly as they are (scale 1)."""
    kn, ks, m = 1e9, 5e8, 2600.0
    w = _cube_on_springs_omega_max(kn, ks, m)
    rate = _cube_on_dashpots_rate(zeta, kn, ks, m)
    bs = BlockSystem()
    bs.add_block(box((-2, -2, -1), (2, 2, 0)), fixed=True)
    i = bs.add_block(box((-0.5, -0.5, 0), (0.5, 0.5, 1)))
    law = ContactLaw(kn=kn, ks=ks, friction_deg=45.0, damping=zeta)
    sim = Simulation(bs, law, dt=frac / w if frac else None)
    if frac:
        assert sim.dt * rate == pytest.approx(2.97, abs=0.01)
    else:
        assert sim.dt * rate < 1.0
    sim.vel[i] = (1e-3, -2e-3, 1e-3)
    sim.angmom[i] = np.array([1e-3, -2e-3, 1.5e-3]) * m / 6
    first = sim.run(2 * sim.dt, record_every=sim.dt).energy_column("balance_error")[-1]
    res = sim.run(400 * sim.dt, record_every=50 * sim.dt)
    if frac:
        assert 0.0 < sim.dscale[i] < 1.0
        # scaled to dt lambda_max = 1 exactly (the engine's eigenvalue against numpy's)
        assert sim.dt * rate * sim.dscale[i] == pytest.approx(1.0, rel=1e-4)
    else:
        assert sim.dscale[i] == 1.0
    assert np.linalg.norm(sim.vel[i]) < 1e-6
    damped = res.energy_column("damping")[-1]
    assert damped > 0.9 * (0.5 * m * 6e-6 + 0.5 * (m / 6) * 7.25e-6)  # the initial kinetic energy, and its settling
    # the books after the first two steps (the first starts from the given velocities at t = 0, and its dashpot
    # forces are booked half in the second) stay closed
    assert abs(res.energy_column("balance_error")[-1] - first) < 1e-6 * damped


def test_local_damping_does_not_spin_a_needle_about_its_axis():
    """A free needle (5 m x 25 mm x 25 mm, axial inertia 2e-5 of the transverse one, axis tilted out of the world
    axes) under a couple about a transverse axis, turning about the transverse axes, local damping 0.5: torque
    and angular velocity have no part about its axis and, by Euler's equations for I2 = I3, it never turns about
    it. Damping about the principal axes keeps that (axial speed at rounding); damped about the world axes it
    spun up to 0.1 rad/s."""
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    cy, sy = math.cos(math.radians(20)), math.sin(math.radians(20))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    a, e1, e2 = R[:, 0], R[:, 1], R[:, 2]
    b = box((-2.5, -0.0125, -0.0125), (2.5, 0.0125, 0.0125))
    bs = BlockSystem()
    i = bs.add_block(BlockSpec(b.vertices @ R.T, b.faces))
    f = 10.0 * (e1 + 0.7 * e2)
    bs.add_point_load(i, a, f)
    bs.add_point_load(i, -a, -f)
    sim = Simulation(bs, ContactLaw(kn=1e9), gravity=(0.0, 0.0, 0.0), local_damping=0.5)
    I = sim.A.inertia[i]
    Rb = quat_to_matrix(sim.quat[i])
    assert abs(abs(Rb[:, np.argmin(I)] @ a) - 1.0) < 1e-12
    sim.angmom[i] = Rb @ (I * (Rb.T @ (0.3 * e1 + 0.2 * e2)))
    sim.run(1000 * sim.dt, record_every=200 * sim.dt)
    Rb = quat_to_matrix(sim.quat[i])
    w_axial = (Rb.T @ sim.angmom[i])[np.argmin(I)] / I.min()
    assert abs(w_axial) < 1e-8
    assert np.linalg.norm(sim.angmom[i]) > 1.0  # it turns about the transverse axes


# ---------------------------------------------------------------- resting blocks sleep
def _stack_and_projectile(arrive=0.75):
    bs = BlockSystem()
    bs.add_block(box((-6, -2, -1), (3, 2, 0)), fixed=True)
    ids = [bs.add_block(box((-0.5, -0.5, k * 1.0), (0.5, 0.5, k * 1.0 + 1.0))) for k in range(3)]
    # ballistic projectile reaching the top block's face (x = -0.5) at height 2.5 at t = arrive
    p = bs.add_block(box((-4.75, -0.25, 2.25), (-4.25, 0.25, 2.75), velocity=(3.75 / arrive, 0, G * arrive / 2)))
    return bs, ids, p


def _run(sleep, t1, t2):
    bs, ids, p = _stack_and_projectile()
    sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, damping=0.2), sleep=sleep)
    sim.run(t1, record_every=0.1)
    before = (sim.asleep.copy(), len(sim.active), sim.pos.copy())
    res = sim.run(t2, record_every=0.05)
    return sim, res, ids, p, before


def test_resting_stack_sleeps_wakes_when_hit_and_matches_the_run_without_sleeping():
    a, ra, ids, p, (asleep_a, nact_a, pos_a) = _run(True, 0.6, 0.25)
    b, rb, _, _, (_, _, pos_b) = _run(False, 0.6, 0.25)
    # before the impact the stack rests: every stack block sleeps, only the projectile is integrated
    assert asleep_a[ids].all() and not asleep_a[p]
    assert nact_a == 1
    assert np.abs(pos_a - pos_b).max() < 1e-6
    # the projectile struck the top block (it moved by centimetres) and woke the stack
    assert np.linalg.norm(b.displacement(ids[2])) > 0.01
    assert not a.asleep[ids[2]]
    # 0.1 s after the impact both runs agree (an impact amplifies differences of 1e-6 in the initial
    # velocity to about 1e-5 m here). The blocks under the struck one wake one step after the block above them
    # starts to move (a block woken at rest wakes no others until it moves), not before the strike: the two
    # steps (1.3e-4 s) the lowest block stays put during the impact make 9.4e-5 m of its 6.2 mm
    assert np.abs(a.pos - b.pos).max() < 2e-4
    assert np.abs(a.vel - b.vel).max() < 1e-3


def test_settled_stack_costs_no_integration_and_keeps_its_energy_balance():
    bs = BlockSystem()
    bs.add_block(box((-3, -2, -1), (3, 2, 0)), fixed=True)
    ids = [bs.add_block(box((-0.5, -0.5, k * 1.0), (0.5, 0.5, k * 1.0 + 1.0))) for k in range(3)]
    sims = {}
    for sleep in (False, True):
        sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, damping=0.2), sleep=sleep)
        res = sim.run(1.0, record_every=0.1)
        sims[sleep] = (sim, res)
    s1, r1 = sims[True]
    s0, r0 = sims[False]
    assert s1.n_asleep == 3 and len(s1.active) == 0 and s0.n_asleep == 0
    assert np.abs(s1.pos - s0.pos).max() < 1e-7
    # the carried contacts keep the elastic energy of the sleeping stack; the balance stays closed
    e1 = r1.energy_column("elastic")[-1]
    e0 = r0.energy_column("elastic")[-1]
    assert abs(e1 - e0) < 1e-3 * e0
    scale = 3 * 2600.0 * G * 1e-3
    assert abs(r1.energy_column("balance_error")[-1]) < 1e-3 * scale
    # resting contacts are still reported
    assert len(s1.contacts()["a"]) == len(s0.contacts()["a"])


def test_blocks_put_to_sleep_at_once_cost_nothing_until_a_moving_block_hits_them():
    """Simulation.fall_asleep: the stack put to sleep where it stands is not integrated (only the projectile is),
    does not move, keeps the energy balance closed, and wakes when the projectile strikes it (t = 0.75 s)."""
    bs, ids, p = _stack_and_projectile()
    sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, damping=0.2), sleep=True)
    sim.fall_asleep(ids)
    assert list(sim.active) == [p] and sim.asleep[ids].all()
    res = sim.run(0.7, record_every=0.05)
    assert np.array_equal(sim.pos[ids], sim.pos0[ids]) and sim.asleep[ids].all()
    # the balance stays what the projectile's first step makes of it (0.18 J of its 5715 J, as without sleeping)
    err, ke = res.energy_column("balance_error")[1:], res.energy_column("kinetic")[1]
    assert np.ptp(err) < 1e-9 * ke and abs(err[0]) < 1e-4 * ke
    sim.run(0.15, record_every=0.05)
    assert not sim.asleep[ids[2]] and np.linalg.norm(sim.displacement(ids[2])) > 0.01
    with pytest.raises(ValueError):
        sim.fall_asleep([0])  # the fixed floor


def test_two_calm_blocks_touching_fall_asleep_together_and_stay_still():
    # each block touches the other, which is awake but calm: the pair must fall asleep together
    bs = BlockSystem()
    bs.add_block(box((-3, -2, -1), (3, 2, 0)), fixed=True)
    bs.add_block(box((-0.5, -0.5, 0), (0.5, 0.5, 1)))
    bs.add_block(box((-0.4, -0.4, 1.0), (0.4, 0.4, 1.5)))
    sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, damping=0.2), sleep=True, sleep_steps=50)
    sim.run(1.0, record_every=0.5)
    assert sim.n_asleep == 2
    p = sim.pos.copy()
    sim.run(0.5, record_every=0.5)
    assert np.array_equal(sim.pos, p)


@pytest.mark.parametrize("turn", [False, True])
@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_a_block_sleeps_only_when_its_mean_acceleration_is_below_the_threshold(turn, ratio):
    """A free block (no gravity, no contacts) under a constant load whose acceleration is `ratio` x sleep_accel,
    slow enough (far below sleep_velocity) for a window of calm steps: it falls asleep after one window when the
    acceleration is below the threshold and never when above (then it keeps x = a t^2 / 2). With `turn`, a couple
    about z turns the unit cube, whose rim accelerates at size x torque / I_z, I_z = m (1 + 1) / 12."""
    a_s, n, dt, m = 0.01, 500, 2e-4, 1000.0
    bs = BlockSystem()
    i = bs.add_block(box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)), density=m)
    if turn:
        f = ratio * a_s * m / 6.0  # torque f x 1 m; size 1 m
        bs.add_point_load(i, (0.5, 0.0, 0.0), (0.0, f, 0.0))
        bs.add_point_load(i, (-0.5, 0.0, 0.0), (0.0, -f, 0.0))
    else:
        bs.add_body_load(i, (ratio * a_s * m, 0.0, 0.0))
    sim = Simulation(bs, ContactLaw(kn=1e9), gravity=(0.0, 0.0, 0.0), dt=dt, sleep=True, sleep_velocity=1.0,
                     sleep_accel=a_s, sleep_steps=n)
    sim.run(3 * n * dt, record_every=n * dt)
    assert sim.asleep[i] == (ratio < 1.0)
    if ratio > 1.0 and not turn:
        assert sim.pos[i, 0] == pytest.approx(0.5 * ratio * a_s * sim.time ** 2, rel=1e-9)


@pytest.mark.parametrize("turn", [False, True])
@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_a_block_sleeps_only_when_its_mean_speed_is_below_the_threshold(turn, ratio):
    """A free block (no gravity, no loads) drifting at `ratio` x sleep_velocity -- its centroid, or with `turn`
    the rim of the unit cube spinning about z (size 1 m x angular speed) -- falls asleep after one window when the
    speed is below the threshold and never when above."""
    v_s, n, dt = 0.01, 500, 2e-4
    bs = BlockSystem()
    i = bs.add_block(box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)))
    sim = Simulation(bs, ContactLaw(kn=1e9), gravity=(0.0, 0.0, 0.0), dt=dt, sleep=True, sleep_velocity=v_s,
                     sleep_accel=1.0, sleep_steps=n)
    if turn:
        sim.angmom[i] = (0.0, 0.0, float(sim.A.inertia[i, 2]) * ratio * v_s)
    else:
        sim.vel[i] = (ratio * v_s, 0.0, 0.0)
    sim.run(3 * n * dt, record_every=n * dt)
    assert sim.asleep[i] == (ratio < 1.0)


def test_a_block_vibrating_on_stiff_contacts_falls_asleep():
    """A unit cube set down on a fixed floor without damping rings on its four corner springs (omega^2 = 4 kn / m,
    velocity amplitude g / omega = 7.9 mm/s, acceleration amplitude g, far above sleep_accel = 1e-3 g): its mean
    acceleration over a window of many periods is ~0, so it falls asleep after one window, within the ringing's
    amplitude g / omega^2 of its static rest (where the step's contacts found it), and the energy balance stays as
    it was (the kinetic energy it had counts as damped)."""
    kn, n = 1e9, 500
    bs = BlockSystem()
    bs.add_block(box((-2, -2, -1), (2, 2, 0)), fixed=True)
    i = bs.add_block(box((-0.5, -0.5, 0), (0.5, 0.5, 1)))
    sim = Simulation(bs, ContactLaw(kn=kn, friction_deg=30.0), sleep=True, sleep_velocity=0.05, sleep_steps=n)
    m = float(sim.A.mass[i])
    omega = math.sqrt(4 * kn / m)
    assert n * sim.dt * omega > 100  # many periods in the window
    res = sim.run(1.5 * n * sim.dt, record_every=0.25 * n * sim.dt)
    assert sim.asleep[i] and sim.block_steps == n
    rest = G / omega ** 2
    assert abs(sim.pos[i, 2] - (0.5 - rest)) < 1.05 * rest
    # the balance keeps the value the first contact step gave it (2.3 mJ) through falling asleep
    err = res.energy_column("balance_error")[1:]
    assert np.ptp(err) < 1e-9 * 0.5 * m * (G / omega) ** 2


def test_sleep_scene_keys():
    d = _scene()
    d["simulation"].update(sleep=True, sleep_velocity=1e-3, sleep_accel=0.01, sleep_steps=10)
    sc = scene_from_dict(d)
    assert sc.sleep == {"sleep": True, "sleep_velocity": 1e-3, "sleep_accel": 0.01, "sleep_steps": 10}
    _, sim = sc.build()
    assert list(sim.sleep_par) == [1.0, 1e-3, 0.01, 10.0]
    d["simulation"]["sleep_steps"] = 0
    with pytest.raises(SceneError):
        scene_from_dict(d)


def _bonded(sim, a, b):
    """(A, bonded points) of the contact between blocks a and b (either as A)."""
    c = int(sim.cur[0])
    for s in range(int(sim.c_n_pair[c])):
        if {int(sim.c_a[c, s]), int(sim.c_b[c, s])} == {a, b}:
            return int(sim.c_a[c, s]), int(sim.c_bond[c, s, :sim.c_np[c, s]].sum())
    return -1, 0


def test_cemented_hanging_blocks_sleep_and_wake_with_their_bonds_and_closed_balance():
    """Two blocks hanging in tension from a fixed roof 10 m up by cemented contacts (cohesion and tensile
    strength, bonded at the start) settle and fall asleep; a prescribed block sliding past the lower one within the
    search gap, never touching it, wakes it (its contact with the sleeping upper block then has the lower block as
    A) and it alone (woken at rest and not moving, it wakes no others), and it falls asleep again. Every bonded
    point keeps its bond through it, the blocks stay where they settled (stretched W / (4 kn) per contact: 1.3e-5 m
    and 1.9e-5 m), nothing moves once asleep, and the energy balance of every step is closed, the steps where blocks
    fall asleep and wake included (a block falling asleep counted its potential twice in that step, a block waking not
    at all: 2.2e5 J here, taken for a blow-up)."""
    bs = BlockSystem()
    roof = bs.add_block(box((-2, -2, 10), (2, 2, 11)), fixed=True)
    up = bs.add_block(box((-0.5, -0.5, 9), (0.5, 0.5, 10)))
    lo = bs.add_block(box((-0.5, -0.5, 8), (0.5, 0.5, 9)))
    c = 0.01  # the passing block's clearance: within the search gap (0.021 m), beyond the bonds' kept gap (1e-3 m)
    bs.add_block(box((0.5 + c, -3.25, 8.25), (1.0 + c, -2.75, 8.75), velocity=(0, 10.0, 0)), prescribed=True)
    sim = Simulation(bs, ContactLaw(kn=1e9, friction_deg=30.0, cohesion=1e6, tensile=1e6, damping=0.2), sleep=True)
    assert sim.keep_gap < c < sim.gap
    res = [sim.run(0.2, record_every=sim.dt)]
    # asleep before the passing block comes near (y = -0.52 at t = 0.223 s), the contact's A the upper block
    assert sim.asleep[[up, lo]].all() and _bonded(sim, up, lo) == (up, 4)
    states = []
    for _ in range(50):  # it passes the lower block from t = 0.223 to 0.377 s
        res.append(sim.run(0.005, record_every=sim.dt))
        states.append(tuple(sim.asleep[[up, lo]]))
    assert (True, False) in states and (False, False) not in states and states[-1] == (True, True), set(states)
    # the lower block woke first (its contact with the sleeping upper block turned round) and the bonds held
    assert _bonded(sim, up, lo) == (lo, 4) and _bonded(sim, roof, up) == (up, 4)
    W = 2600.0 * G
    d = np.linalg.norm(sim.pos - sim.pos0, axis=1)
    assert d[up] == pytest.approx(2 * W / 4e9, rel=0.05) and d[lo] == pytest.approx(3 * W / 4e9, rel=0.05), d
    p = sim.pos[[up, lo]].copy()
    res.append(sim.run(0.05, record_every=sim.dt))
    assert np.array_equal(sim.pos[[up, lo]], p)
    err = np.concatenate([r.energy_column("balance_error")[1:] for r in res])
    elastic = res[-1].energy_column("elastic")[-1]  # 1/2 (2W) d_up + 1/2 W (d_lo - d_up): 0.33 J
    assert elastic == pytest.approx(0.5 * (2 * W) * d[up] + 0.5 * W * (d[lo] - d[up]), rel=0.05)
    assert np.abs(err).max() < 0.02 * elastic, np.abs(err).max()
