"""Spheres together with moving polyhedral blocks (dda/_coupled.py), against analytical references:
static equilibrium (total weight), springs in series, elastic collision laws and momentum conservation, the
5/7 rolling law, and an all-pairs sphere-box distance test for the broad phase."""
import math

import numpy as np
import pytest

from dda.simulation import ContactLaw
from dda.spheres import BondLaw, SphereSet, SphereSimulation
from dda.system import BlockSystem
from blocks import box  # independent of dda.shapes

G = 9.81


def test_sphere_dropped_on_a_free_block_comes_to_rest_on_the_total_weight():
    rho_b, rho_s, r = 2600.0, 2000.0, 0.1
    bs = BlockSystem()
    bs.add_block(box((-2, -2, -1), (2, 2, 0), fixed=True), density=rho_b)
    ib = bs.add_block(box((-0.5, -0.4, 0), (0.5, 0.4, 0.5)), density=rho_b)
    ss = SphereSet([[0.13, -0.07, 0.9]], [r], density=rho_s)
    kn = 1e8
    sim = SphereSimulation(ss, ContactLaw(kn=kn, friction_deg=30, damping=0.3), walls=bs, gravity=(0, 0, -G))
    res = sim.run(0.8, record_every=0.01)
    mb = rho_b * 0.4
    ms = rho_s * 4 / 3 * math.pi * r ** 3
    # the impact pushed the block into the floor: its lowest point is reached after the sphere arrives
    zb = np.asarray(res.block_pos)[:, ib, 2]
    t_hit = math.sqrt(2 * (0.9 - r - 0.5) / G)
    assert res.times[np.argmin(zb)] > t_hit
    # rest: the floor carries block + sphere, the block carries the sphere (at the point under its centre)
    fb = sim.blocks.contacts()
    floor = fb["fn"][(fb["a"] == 0) | (fb["b"] == 0)].sum()
    assert floor == pytest.approx((mb + ms) * G, rel=2e-3)
    c = sim.contacts()
    assert list(c["i"]) == [-1 - ib] and c["fn"].sum() == pytest.approx(ms * G, rel=2e-3)
    assert sim.x[0, :2] == pytest.approx([0.13, -0.07], abs=2e-3)  # (the off-centre impact rocks the block)
    nz = sim.blocks.rotation(ib)[:, 2]  # the block's top face normal (it may have tilted a little)
    gap = sim.x[0] @ nz - (sim.blocks.vertices(ib) @ nz).max()
    assert gap == pytest.approx(r - ms * G / kn, abs=2e-8)
    assert np.abs(sim.v).max() < 1e-3 and np.abs(sim.blocks.vel[ib]).max() < 1e-3


@pytest.mark.parametrize("offset", [0.0, 0.06])
def test_elastic_frictionless_sphere_block_impact_conserves_momentum_and_energy(offset):
    # zero gravity: a sphere flies into a free cube (head-on, then off-centre); no friction, no damping.
    # Linear momentum and angular momentum about the origin are conserved; head-on, the velocities after the
    # impact follow the 1D elastic collision law; energy drift within 0.5 %
    r, a = 0.1, 0.1
    bs = BlockSystem()
    bs.add_block(box((-5, -5, -6), (5, 5, -5), fixed=True), density=2600.0)  # far away
    ib = bs.add_block(box((-a, -a, -a), (a, a, a)), density=1000.0)
    ss = SphereSet([[0.0, offset, 0.35]], [r], density=2000.0)
    v0 = np.array([0.0, 0.0, -1.0])
    ss.velocity[0] = v0
    sim = SphereSimulation(ss, ContactLaw(kn=1e6, friction_deg=0.0), walls=bs, gravity=(0, 0, 0), safety=0.1)
    ms = sim.m[0]
    mb = 1000.0 * (2 * a) ** 3
    E0 = 0.5 * ms * v0 @ v0
    res = sim.run(0.4, record_every=0.002)
    b = sim.blocks
    # momentum
    p = ms * sim.v[0] + mb * b.vel[ib]
    assert p == pytest.approx(ms * v0, abs=1e-9 * ms)
    L = ms * np.cross(sim.x[0], sim.v[0]) + sim.inertia[0] * sim.w[0] + mb * np.cross(b.pos[ib], b.vel[ib]) \
        + b.angmom[ib]
    L0 = ms * np.cross(np.array([0.0, offset, 0.35]), v0)
    assert L == pytest.approx(L0, abs=2e-3 * ms * 0.35)
    if offset == 0.0:
        assert sim.v[0, 2] == pytest.approx(-(ms - mb) / (ms + mb), abs=5e-3)
        assert b.vel[ib, 2] == pytest.approx(-2 * ms / (ms + mb), abs=5e-3)
        assert np.abs(b.angmom[ib]).max() < 1e-9
    else:
        assert abs(b.angmom[ib, 0]) > 1e-3 * ms * offset  # the off-centre push turned the block
    bal = res.energy_column("balance_error")
    assert np.abs(bal).max() <= 5e-3 * E0
    ke = 0.5 * ms * sim.v[0] @ sim.v[0] + 0.5 * sim.inertia[0] * sim.w[0] @ sim.w[0] \
        + 0.5 * mb * b.vel[ib] @ b.vel[ib] + 0.5 * b.angmom[ib] @ (np.linalg.solve(
            b.rotation(ib) @ np.diag(b.A.inertia[ib]) @ b.rotation(ib).T, b.angmom[ib]))
    assert ke == pytest.approx(E0, rel=5e-3)


def test_block_pushed_by_a_plate_into_a_row_of_bonded_spheres():
    # zero gravity: a prescribed plate pushes a free block against a row of N bonded spheres whose last sphere is
    # fixed. At rest, the force through the row is delta / (1/(4 kn) + 1/kn_sb + (N-1)/kb): springs in series
    # (the plate-block face contact has four points, the block touches the first sphere at one point)
    r, N = 0.05, 5
    kn, kb = 2e6, 5e5
    bs = BlockSystem()
    ip = bs.add_block(box((-0.4, -0.15, -0.15), (-0.2, 0.15, 0.15), velocity=(0.05, 0.0, 0.0)), density=2600.0,
                      prescribed=True)
    ib = bs.add_block(box((-0.2, -0.1, -0.1), (0.0, 0.1, 0.1)), density=2600.0)
    ss = SphereSet([[r + 2 * r * k, 0.0, 0.0] for k in range(N)], [r] * N, density=2600.0)
    ss.add_bonds([[k, k + 1] for k in range(N - 1)], BondLaw(kn=kb, ks=kb / 2))
    ss.fixed[N - 1] = True
    sim = SphereSimulation(ss, ContactLaw(kn=kn, friction_deg=0.0, damping=0.5), walls=bs, gravity=(0, 0, 0),
                           local_damping=0.3)
    sim.run(0.04, record_every=0.01)
    b = sim.blocks
    b.vel[ip] = 0.0  # stop the plate and let everything settle
    delta = float(b.displacement(ip)[0])
    assert delta == pytest.approx(0.002, rel=2e-3)
    # (a compressed row of bonds without bending stiffness buckles in the end, from round-off: the settled
    # state is read well before; lateral motion stays below 1e-4 of a radius)
    sim.run(0.12, record_every=0.04)
    assert np.abs(sim.x[:, 1:]).max() < 1e-4 * r
    F = delta / (1 / (4 * kn) + 1 / kn + (N - 1) / kb)
    assert -sim.bond_fn == pytest.approx(np.full(N - 1, F), rel=3e-3)
    assert sim.bond_intact.all()
    c = sim.contacts()
    assert list(c["i"]) == [-1 - ib] and c["fn"][0] == pytest.approx(F, rel=3e-3)
    fb = b.contacts()
    assert len(fb["fn"]) == 4 and fb["fn"].sum() == pytest.approx(F, rel=3e-3)
    # each sphere moved by the compression of the bonds beyond it
    ux = sim.displacement()[:, 0]
    assert ux == pytest.approx([(N - 1 - k) * F / kb for k in range(N)], abs=1e-3 * F / kb + 1e-12)


def test_sphere_rolling_on_a_moving_block_follows_the_five_sevenths_law():
    # a sphere at rest set on a block that moves at u (prescribed): kinetic friction mu g accelerates it until
    # it rolls, at t_r = 2 u / (7 mu g); then its velocity relative to the block is 5/7 of the initial slip
    # (-u) and w r equals it (no slip); in the ground frame the sphere moves at 2/7 u
    r, u, phi = 0.1, 0.4, 25.0
    mu = math.tan(math.radians(phi))
    bs = BlockSystem()
    ib = bs.add_block(box((-1.0, -0.5, -0.2), (3.0, 0.5, 0.0), velocity=(u, 0, 0)), density=2600.0, prescribed=True)
    ss = SphereSet([[0.0, 0.0, r - 2600 * 4 / 3 * math.pi * r ** 3 * G / 1e8]], [r], density=2600.0)
    sim = SphereSimulation(ss, ContactLaw(kn=1e8, ks=1e8, friction_deg=phi, damping=0.2), walls=bs,
                           gravity=(0, 0, -G))
    t_r = 2 * u / (7 * mu * G)
    res = sim.run(1.6 * t_r, record_every=t_r / 20)
    vx = np.asarray(res.vel)[:, 0, 0]
    t = res.times
    slide = (t > 0.1 * t_r) & (t < 0.9 * t_r)
    assert vx[slide] == pytest.approx(mu * G * t[slide], rel=2e-2)
    assert sim.v[0, 0] == pytest.approx(2 / 7 * u, rel=1e-3)
    rel = sim.v[0, 0] - u
    assert rel == pytest.approx(-5 / 7 * u, rel=1e-3)
    # rolling without slip on the block: contact point velocity v + w x (-r e_z) equals the block's
    assert sim.v[0, 0] - r * sim.w[0, 1] == pytest.approx(u, rel=2e-3)
    assert sim.blocks.vel[ib, 0] == u


def _dist_to_box(c, lo, hi):
    # distance from c to an axis-aligned box (0 inside): the nearest point is the clipped centre
    return float(np.linalg.norm(c - np.clip(c, lo, hi)))


def test_sphere_block_broad_phase_finds_every_touching_pair():
    # many spheres among many free blocks (zero gravity, no motion in the first step): the sphere-block contacts
    # found through the block grids are exactly the pairs a brute-force distance test finds
    rng = np.random.default_rng(7)
    bs = BlockSystem()
    boxes = []
    for k in range(40):
        lo = rng.uniform(-2, 2, 3)
        hi = lo + rng.uniform(0.1, 0.5, 3)
        boxes.append((lo, hi))
        bs.add_block(box(lo, hi), density=2600.0)
    boxes.append((np.array([-3.0, -3, -3.5]), np.array([3.0, 3, -2.5])))
    bs.add_block(box(*boxes[-1], fixed=True), density=2600.0)
    c = rng.uniform(-2.5, 2.5, (400, 3))
    rad = rng.uniform(0.03, 0.12, 400)
    ss = SphereSet(c, rad, density=2000.0)
    sim = SphereSimulation(ss, ContactLaw(kn=1e3, friction_deg=0.0), walls=bs, gravity=(0, 0, 0), dt=1e-7)
    sim.run(1e-7, record_every=1e-7)
    cc = sim.contacts()
    got = {(-1 - int(i), int(j)) for i, j in zip(cc["i"], cc["j"]) if i < 0}
    want = set()
    for j in range(len(rad)):
        for k, (lo, hi) in enumerate(boxes):
            if _dist_to_box(c[j], lo, hi) < rad[j] - 1e-9:
                want.add((k, j))
    assert len(want) > 10
    assert got == want


def test_dda_run_of_a_scene_with_spheres_and_a_moving_block(tmp_path):
    # a cube dropped on a fixed layer of sgim spheres comes to rest on them: the sphere-block contact forces
    # carry its weight; `dda run` writes the block series and meshes
    from dda.cli import main
    from dda.scene import load_scene
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    d = {"name": "layer", "domain": {"min": [0, 0, 0], "max": [1, 1, 0.2]},
         "packing": {"kind": "cubic", "radius": 0.1}, "bonds": {"rule": "colour"}}
    model = build_model(scene_from_dict(d, "layer.toml"))
    model.save(tmp_path / "model.npz")
    (tmp_path / "s.toml").write_text(
        'name = "drop"\n[simulation]\nduration = 0.4\nrecord_every = 0.05\n'
        '[contact]\nkn = 1e7\nfriction = 30.0\ndamping = 0.3\n'
        '[spheres]\nmodel = "model.npz"\nfixed = ["z>-1"]\n'
        '[[block]]\nname = "cube"\nshape = "cube"\nsize = 0.4\ncenter = [0.5, 0.5, 0.45]\n'
        '[output]\nformats = ["npz", "vtu"]\n')
    scene = load_scene(tmp_path / "s.toml")
    ss, sim = scene.build_spheres()
    assert sim.blocks is not None and ss.fixed.all()
    sim.run(0.4, record_every=0.05)
    c = sim.contacts()
    mass = 2600.0 * 0.4 ** 3
    assert np.all(c["i"] == -1) and c["fn"].sum() == pytest.approx(mass * G, rel=2e-3)
    top = model.centers[:, 2].max() + 0.1
    assert sim.blocks.vertices(0)[:, 2].min() == pytest.approx(top, abs=2e-3)
    assert main(["run", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    z = np.load(tmp_path / "out" / "series.npz")
    assert z["block_pos"].shape == (len(z["time"]), 1, 3)
    assert z["block_pos"][-1, 0] == pytest.approx(sim.blocks.pos[0], abs=1e-12)
    assert (tmp_path / "out" / "blocks.vtu").is_file()


def test_energy_drift_of_repeated_elastic_sphere_block_impacts_over_1e5_steps():
    # zero gravity, frictionless, undamped: a sphere and a free cube bounce around inside a closed box of six
    # fixed blocks (many sphere-block, sphere-wall and block-wall impacts); the energy stays within 0.5 %
    bs = BlockSystem()
    L, t = 1.0, 0.2
    for lo, hi in [((-L - t, -L - t, -L - t), (L + t, L + t, -L)), ((-L - t, -L - t, L), (L + t, L + t, L + t)),
                   ((-L - t, -L - t, -L), (-L, L + t, L)), ((L, -L - t, -L), (L + t, L + t, L)),
                   ((-L, -L - t, -L), (L, -L, L)), ((-L, L, -L), (L, L + t, L))]:
        bs.add_block(box(lo, hi, fixed=True), density=2600.0)
    ib = bs.add_block(box((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2), velocity=(0.3, -0.2, 0.1)), density=1000.0)
    ss = SphereSet([[0.6, 0.5, 0.4], [-0.6, 0.55, -0.5]], [0.15, 0.12], density=2000.0)
    ss.velocity[:] = [[-2.0, -1.3, -0.7], [1.5, -0.4, 1.1]]
    sim = SphereSimulation(ss, ContactLaw(kn=1e6, friction_deg=0.0), walls=bs, gravity=(0, 0, 0),
                           block_law=ContactLaw(kn=1e6, friction_deg=0.0), safety=0.1)
    res = sim.run(1e5 * sim.dt, record_every=500 * sim.dt)
    assert sim.steps >= 100000
    ke = res.energy_column("kinetic")
    E0 = ke[0]
    assert np.abs(res.energy_column("balance_error")).max() <= 5e-3 * E0
    assert res.energy_column("friction")[-1] <= 1e-12 * E0 and res.energy_column("damping")[-1] == 0.0
    # the bodies did collide many times: the cube's velocity changed direction
    bp = np.asarray(res.block_pos)[:, ib]
    assert np.ptp(bp[:, 0]) > 0.3 and np.abs(sim.blocks.vel[ib] - [0.3, -0.2, 0.1]).max() > 0.05
    assert np.all(np.abs(sim.x) < L)


def test_deformable_block_carrying_a_sphere_takes_its_load_in_its_strain():
    # a deformable cube (dof 12, E, nu) on a frictionless fixed floor with a sphere resting on its top face.
    # DDA's constant strain balances the virtual work of the forces: V sigma_z = sum X_z f_z
    # = -h/2 (m_b + m_s) g (floor, at X_z = -h/2) - h/2 m_s g (sphere, at +h/2), uniaxial (frictionless
    # contacts): e_z = sigma_z / E, e_x = e_y = -nu e_z; the floor carries the total weight
    E, nu, h, rho = 1e8, 0.25, 1.0, 2600.0
    bs = BlockSystem()
    bs.add_block(box((-2, -2, -1), (2, 2, 0), fixed=True), density=rho)
    ib = bs.add_block(box((-h / 2, -h / 2, 0), (h / 2, h / 2, h), dof=12), density=rho, E=E, nu=nu)
    ss = SphereSet([[0.0, 0.0, h + 0.1]], [0.1], density=2000.0)
    sim = SphereSimulation(ss, ContactLaw(kn=1e9, friction_deg=0.0, damping=0.3), walls=bs, gravity=(0, 0, -G),
                           local_damping=0.5)
    sim.run(0.5, record_every=0.1)
    ms, mb = sim.m[0], rho * h ** 3
    fb = sim.blocks.contacts()
    assert fb["fn"].sum() == pytest.approx((mb + ms) * G, rel=1e-6)
    assert sim.contacts()["fn"].sum() == pytest.approx(ms * G, rel=1e-6)
    ez = -0.5 * h * G * (mb + 2 * ms) / h ** 3 / E
    e = sim.blocks.strain(ib)
    assert e[2] == pytest.approx(ez, rel=1e-4)
    assert e[:2] == pytest.approx([-nu * ez, -nu * ez], rel=1e-4)
