"""adapters.inhouse.run_inhouse: the in-house engine on a SphereRun, against analytical motion."""
import math

import numpy as np
import pytest

from adapters.inhouse import run_inhouse
from adapters.process import EngineError
from adapters.result import RunResult
from adapters.spec import SphereRun

G = 9.81


def make_run(centers, radii, fixed=None, bonds=(), bond_kn=1e5, bond_ft=math.inf, dt=1e-4, duration=0.1,
             record_every=0.01, kn=1e5):
    c = np.asarray(centers, float).reshape(-1, 3)
    n = len(c)
    b = np.asarray(bonds, np.int64).reshape(-1, 2)
    m = len(b)
    return SphereRun(
        name="t", centers=c, radii=np.asarray(radii, float), colour=np.zeros(n, np.int8),
        fixed=np.zeros(n, bool) if fixed is None else np.asarray(fixed, bool), density=2000.0,
        bond_i=b[:, 0].copy(), bond_j=b[:, 1].copy(), bond_len0=np.linalg.norm(c[b[:, 1]] - c[b[:, 0]], axis=1),
        bond_kn=np.full(m, bond_kn), bond_ks=np.full(m, bond_kn / 2), bond_ft=np.full(m, bond_ft),
        bond_fs=np.full(m, math.inf), joint_i=np.zeros(0, np.int64), joint_j=np.zeros(0, np.int64),
        joint_disc=np.zeros(0, np.int32), joint_normal=np.zeros((0, 3)), cut_i=np.zeros(0, np.int64),
        cut_j=np.zeros(0, np.int64), kn=kn, ks=kn / 2, friction_deg=30.0, damping=0.0, joint_friction_deg=30.0,
        smooth_joints=True, gravity=np.array([0.0, 0.0, -G]), dt=dt, duration=duration, record_every=record_every,
        local_damping=0.0)


def test_free_fall_matches_the_analytical_trajectory_and_kinetic_energy(tmp_path):
    # three separate spheres (one fixed): x(t) = x0 - g t^2 / 2 exactly for the central difference started with
    # a half step; the recorded velocity is the mid-step one, v(t - dt/2) = g (t - dt/2)
    c = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    r = [0.1, 0.2, 0.15]
    run = make_run(c, r, fixed=[False, False, True], dt=1e-3, duration=0.2, record_every=0.02)
    res = run_inhouse(run, out=tmp_path / "res")
    assert res.complete and res.engine == "dda" and res.steps == 200
    t = res.time
    assert np.allclose(t, np.arange(11) * 0.02)
    assert res.pos.shape == (11, 3, 3)
    z = res.pos[:, :2, 2]
    assert np.allclose(z, -0.5 * G * t[:, None] ** 2, atol=1e-12)
    assert np.allclose(res.pos[:, 2], [0, 1, 0])
    m = 2000.0 * 4 / 3 * math.pi * np.array(r[:2]) ** 3
    v = np.where(t > 0, G * (t - 0.5e-3), 0.0)
    assert np.allclose(res.series["kinetic"], 0.5 * m.sum() * v ** 2, rtol=1e-9)
    assert np.allclose(res.final_vel[:2, 2], -G * (0.2 - 0.5e-3))
    back = RunResult.load(tmp_path / "res")
    assert np.array_equal(back.final_pos, res.final_pos) and back.complete


def test_hanging_bond_breaks_at_its_tensile_force():
    # a sphere hanging from a fixed one on a bond released from its rest length: the tension kn s(t) with
    # s = (m g / kn)(1 - cos(omega t)), omega = sqrt(kn / m), reaches ft = 1.5 m g at omega t = 2 pi / 3
    r, kn = 0.1, 1e5
    m = 2000.0 * 4 / 3 * math.pi * r ** 3
    om = math.sqrt(kn / m)
    dt = 2e-3 / om
    t_break = (2 * math.pi / 3) / om
    run = make_run([[0, 0, 0], [0, 0, -2 * r], [5, 0, 0]], [r, r, r], fixed=[True, False, False],
                   bonds=[[0, 1]], bond_kn=kn, bond_ft=1.5 * m * G, dt=dt, duration=2 * t_break,
                   record_every=dt)
    res = run_inhouse(run)
    intact = res.series["bonds_intact"]
    t = res.time
    assert intact[t < t_break - 2 * dt].min() == 1
    assert intact[t > t_break + 2 * dt].max() == 0
    assert not res.bond_intact[0]
    # an unbreakable bond holds, oscillating about the static stretch
    run2 = make_run([[0, 0, 0], [0, 0, -2 * r]], [r, r], fixed=[True, False], bonds=[[0, 1]], bond_kn=kn,
                    bond_ft=2.5 * m * G, dt=dt, duration=2 * t_break, record_every=dt)
    res2 = run_inhouse(run2)
    assert res2.bond_intact.all()
    s = -(res2.pos[:, 1, 2] + 2 * r)
    assert np.allclose(s, m * G / kn * (1 - np.cos(om * res2.time)), atol=1e-3 * m * G / kn)


def test_blow_up_is_an_engine_error_with_the_partial_result(tmp_path):
    # a time step far above the critical one of a stiff bond: non-finite state, the last good record kept
    run = make_run([[0, 0, 0], [0, 0, -0.2]], [0.1, 0.1], bonds=[[0, 1]], bond_kn=1e12, dt=1e-2, duration=5.0,
                   record_every=0.02)
    run.centers[1, 2] -= 1e-4
    with pytest.raises(EngineError, match="dda: blow-up") as info:
        run_inhouse(run, out=tmp_path / "res")
    res = info.value.result
    assert res.status == "incomplete" and np.all(np.isfinite(res.final_pos))
    assert 0 < res.steps < run.steps
    assert RunResult.load(tmp_path / "res").status == "incomplete"


def test_renumbered_run_maps_back_to_the_run_order():
    # run_inhouse steps the spheres in its own (spatial) order: the result in the run's order equals a direct
    # dda.spheres run of the same arrays (bonds, a breaking bond, smooth joints) up to round-off
    from dda.simulation import ContactLaw
    from dda.spheres import SphereSet, SphereSimulation

    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.arange(4), np.arange(3), np.arange(3), indexing="ij"), -1).reshape(-1, 3) * 0.2
    order = rng.permutation(len(g))
    c = g[order] + rng.normal(0, 1e-4, g.shape)
    n = len(c)
    d = np.linalg.norm(c[:, None] - c[None], axis=2)
    i, j = np.nonzero(np.triu((d > 0) & (d < 0.21), 1))
    cross = (c[i, 0] < 0.3) != (c[j, 0] < 0.3)  # a joint plane x = 0.3 cuts these pairs
    run = make_run(c, np.full(n, 0.1), fixed=c[:, 2] < 0.05, bonds=np.c_[i, j][~cross], bond_kn=2e5,
                   bond_ft=60.0, dt=2e-4, duration=0.06, record_every=0.02)
    jp = np.c_[j, i][cross]  # given as (higher, lower): the normal must follow the pair's order
    run.joint_i, run.joint_j = jp[:, 0].copy(), jp[:, 1].copy()
    run.joint_normal = np.where((c[jp[:, 1], 0] > c[jp[:, 0], 0])[:, None], [1.0, 0, 0], [-1.0, 0, 0])
    run.joint_disc = np.zeros(len(jp), np.int32)
    run.joint_friction_deg = 10.0
    run.gravity = np.array([3.0, 0.0, -G])
    res = run_inhouse(run)
    ss = SphereSet(c, run.radii, run.density)
    ss.fixed[:] = run.fixed
    ss.bond_i, ss.bond_j = run.bond_i, run.bond_j
    ss.bond_len0, ss.bond_kn, ss.bond_ks = run.bond_len0, run.bond_kn, run.bond_ks
    ss.bond_ft, ss.bond_fs, ss.bond_zeta = run.bond_ft, run.bond_fs, np.zeros(run.n_bonds)
    ss.add_joints(jp, run.joint_normal, 10.0)
    sim = SphereSimulation(ss, ContactLaw(kn=run.kn, ks=run.ks, friction_deg=run.friction_deg),
                           gravity=run.gravity, dt=run.dt)
    sim.run(run.duration)
    assert 0 < (~sim.bond_intact).sum() < run.n_bonds  # some bonds broke
    assert np.array_equal(res.bond_intact, sim.bond_intact)
    assert np.allclose(res.final_pos, sim.x, rtol=0, atol=1e-9)
    assert np.allclose(res.final_vel, sim.v, rtol=0, atol=1e-7)
    assert res.extra["smooth_joints"] == len(jp)
