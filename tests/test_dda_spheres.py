"""Spheres and bonds in the explicit engine, against analytical motion and brute-force references."""
import math

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial import ConvexHull

from dda import _spheres
from dda.blockspec import BlockSpec
from dda.simulation import ContactLaw
from dda.spheres import BondLaw, SphereSet, SphereSimulation, load_model

G = 9.81


def box(lo, hi, R=None, **kw):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    if R is not None:
        v = v @ np.asarray(R).T
    f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return BlockSpec(v, f, fixed=True, **kw)


def test_bonded_pair_oscillates_at_the_analytical_frequency():
    # two free spheres of different sizes on one bond: omega = sqrt(kn (1/m1 + 1/m2)), the stretch stays
    # a cosine of amplitude s0 (the leapfrog's frequency error is (omega dt)^2 / 24, here 4e-6)
    rho, kn = 1000.0, 2e5
    ss = SphereSet([[0, 0, 0], [0.5, 0.3, 0.0]], [0.3, 0.283], density=rho)
    ss.add_bonds([[0, 1]], BondLaw(kn=kn, ks=kn / 2))
    L0 = math.hypot(0.5, 0.3)
    s0 = 0.004
    ss.centers[1] += s0 * np.array([0.5, 0.3, 0.0]) / L0
    m1, m2 = rho * 4 / 3 * math.pi * 0.3 ** 3, rho * 4 / 3 * math.pi * 0.283 ** 3
    om = math.sqrt(kn * (1 / m1 + 1 / m2))
    sim = SphereSimulation(ss, ContactLaw(kn=1e5), gravity=(0, 0, 0), dt=0.01 / om)
    T = 4 * 2 * math.pi / om
    res = sim.run(T, record_every=sim.dt)
    pos = np.asarray(res.pos)
    s = np.linalg.norm(pos[:, 1] - pos[:, 0], axis=1) - L0
    t = res.times
    assert np.max(np.abs(s - s0 * np.cos(om * t))) < 2e-3 * s0
    # the centre of mass stays put
    com = (m1 * pos[:, 0] + m2 * pos[:, 1]) / (m1 + m2)
    assert np.max(np.abs(com - com[0])) < 1e-12
    assert abs(res.energy_column("balance_error")[-1]) < 1e-3 * 0.5 * kn * s0 * s0
    assert sim.bond_intact.all()


def _pull(tensile, shear, direction, duration):
    r, E, v = 0.2, 1e8, 0.05
    ss = SphereSet([[0, 0, 0], [2 * r, 0, 0]], [r, r], density=2000.0)
    ss.add_bonds([[0, 1]], BondLaw(young=E, shear_ratio=0.5, tensile=tensile, shear=shear))
    ss.fixed[0] = True
    ss.prescribed[1] = True
    ss.velocity[1] = v * np.asarray(direction, float)
    sim = SphereSimulation(ss, ContactLaw(kn=1e6), gravity=(0, 0, 0), dt=1e-4)
    sim.run(duration, record_every=duration)
    area = math.pi * r * r
    kn = E * area / (2 * r)  # the bond modulus over the bond area and length
    return sim, kn, area, v


def test_bond_breaks_exactly_at_its_tensile_strength():
    ft = 2e5
    sim, kn, area, v = _pull(ft, 1e12, (1, 0, 0), 0.2)
    t_break = ft * area / (kn * v)  # stretch v t reaches the strength over the stiffness
    assert not sim.bond_intact[0]
    assert t_break * (1 - 1e-9) <= sim.bond_break_time[0] <= t_break + sim.dt * 1.0001
    # just before: intact, and the bond force below the strength
    sim2, *_ = _pull(ft, 1e12, (1, 0, 0), t_break - 2 * sim.dt)
    assert sim2.bond_intact[0]
    assert sim2.bond_fn[0] <= ft * area
    # the force of the last step (position at t - dt): within a few steps' stretch of the strength
    assert sim2.bond_fn[0] > ft * area * (1 - 4 * sim.dt / t_break)


def test_bond_breaks_at_its_shear_strength():
    fs = 1e5
    sim, kn, area, v = _pull(1e12, fs, (0, 1, 0), 0.2)
    t_break = fs * area / (0.5 * kn * v)
    assert not sim.bond_intact[0]
    # the bond turns by at most v t / L (< 2 degrees): the shear increment is v cos(angle)
    assert t_break * (1 - 1e-9) <= sim.bond_break_time[0] <= t_break * 1.001 + sim.dt


def test_broad_phase_finds_every_overlapping_pair():
    rng = np.random.default_rng(7)
    n = 3000
    x = rng.uniform(0, 6, (n, 3))
    r = rng.uniform(0.05, 0.2, n)
    ss = SphereSet(x, r)
    sim = SphereSimulation(ss, ContactLaw(kn=1e3), gravity=(0, 0, 0), dt=1e-6)
    sim.run(sim.dt, record_every=sim.dt)
    c = sim.contacts()
    got = set(zip(c["i"].tolist(), c["j"].tolist()))
    # brute force over all pairs
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    i, j = np.nonzero(np.triu(d < r[:, None] + r[None], 1))
    assert got == set(zip(i.tolist(), j.tolist()))
    assert len(got) > 100


def test_closest_point_on_a_polyhedron_matches_a_constrained_minimisation():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(14, 3))
    hull = ConvexHull(pts)
    from dda.shapes import convex_hull

    spec = convex_hull(pts)
    A, b = hull.equations[:, :3], -hull.equations[:, 3]
    from dda.spheres import _wall_arrays

    vert, fn, fd, fvs, fv, fstart, _ = _wall_arrays([spec])
    out = np.empty(3)
    for _ in range(40):
        c = rng.normal(size=3) * 2.5
        sd = _spheres.closest_on_polyhedron(c, fvs, fv, 0, fstart[1], vert, fn, fd, out)
        if np.all(A @ c <= b):
            assert sd <= 0
            assert abs(sd - np.max(A @ c - b)) < 1e-9
            continue
        ref = minimize(lambda y: np.sum((y - c) ** 2), pts.mean(0), jac=lambda y: 2 * (y - c),
                       constraints=[{"type": "ineq", "fun": lambda y: b - A @ y, "jac": lambda y: -A}],
                       method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
        assert abs(sd - np.linalg.norm(ref.x - c)) < 1e-6
        assert np.linalg.norm(out - ref.x) < 1e-4


def test_sphere_resting_on_a_polyhedral_face():
    r, rho, kn = 0.1, 2500.0, 1e6
    m = rho * 4 / 3 * math.pi * r ** 3
    ss = SphereSet([[0.3, -0.2, r]], [r], density=rho)
    sim = SphereSimulation(ss, ContactLaw(kn=kn, friction_deg=30, damping=0.3), walls=[box((-1, -1, -1), (1, 1, 0))])
    sim.run(1.0)
    # at rest on the face: overlap m g / kn, contact force m g, no lateral drift
    assert abs(sim.x[0, 2] - (r - m * G / kn)) < 1e-3 * m * G / kn
    c = sim.contacts()
    assert len(c["fn"]) == 1 and c["i"][0] == -1
    assert abs(c["fn"][0] - m * G) < 1e-3 * m * G
    assert np.allclose(sim.x[0, :2], [0.3, -0.2], atol=1e-12)
    assert abs(sim.v[0]).max() < 1e-4


@pytest.mark.parametrize("phi, kind", [(30.0, "roll"), (0.0, "slide"), (3.0, "slip")])
def test_sphere_on_an_incline(phi, kind):
    alpha = math.radians(20.0)
    R = np.array([[math.cos(alpha), 0, math.sin(alpha)], [0, 1, 0], [-math.sin(alpha), 0, math.cos(alpha)]])
    r, rho, kn = 0.1, 2500.0, 1e7
    wall = box((-5, -1, -1), (5, 1, 0), R=R)
    ss = SphereSet([R @ np.array([0, 0, r])], [r], density=rho)
    sim = SphereSimulation(ss, ContactLaw(kn=kn, ks=kn, friction_deg=phi, damping=0.2), walls=[wall])
    T = 1.0
    sim.run(T)
    down = R @ np.array([1.0, 0, 0])
    if down[2] > 0:
        down = -down
    s = float(sim.displacement()[0] @ down)
    mu = math.tan(math.radians(phi))
    if kind == "roll":
        assert mu >= 2 / 7 * math.tan(alpha)
        a = 5 / 7 * G * math.sin(alpha)
    elif kind == "slide":
        a = G * math.sin(alpha)
    else:
        assert mu < 2 / 7 * math.tan(alpha)
        a = G * (math.sin(alpha) - mu * math.cos(alpha))
    t = sim.time
    assert abs(s - 0.5 * a * t * t) < 5e-3 * 0.5 * a * t * t
    w = np.linalg.norm(sim.w[0])
    if kind == "roll":
        assert abs(w * r - np.linalg.norm(sim.v[0])) < 5e-3 * np.linalg.norm(sim.v[0])
    if kind == "slide":
        assert w < 1e-9


def test_sgim_model_with_a_cut_joint_hangs_and_the_far_side_falls():
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    d = {"name": "cut", "domain": {"min": [0, 0, 0], "max": [2, 2, 3]},
         "packing": {"kind": "cubic", "radius": 0.25}, "bonds": {"rule": "colour"},
         "discontinuity": [{"name": "j", "centre": [1, 1, 1.5], "dip": 0.0, "dip_direction": 0.0, "radius": 5.0,
                            "thickness": 0.0}]}
    model = build_model(scene_from_dict(d, "cut.toml"))
    ss = load_model(model, density=2600.0, bonds=BondLaw(young=1e8, tensile=2e6, shear=2e6))
    assert ss.n_bonds == int(model.bonded.sum()) < len(model.bonds)
    z = model.centers[:, 2]
    ss.fixed[z > 2.6] = True
    sim = SphereSimulation(ss, ContactLaw(kn=1e7, friction_deg=30.0))
    res = sim.run(0.3, record_every=0.05)
    dz = sim.displacement()[:, 2]
    below = z < 1.5
    t = sim.time
    assert np.all(np.abs(dz[below] + 0.5 * G * t * t) < 0.02 * 0.5 * G * t * t)
    assert np.all(np.abs(sim.displacement()[~below]) < 1e-3)
    assert sim.bond_intact.all() and res.bonds[-1] == ss.n_bonds


def _cut_model(tmp_path):
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    d = {"name": "cut", "domain": {"min": [0, 0, 0], "max": [2, 2, 3]},
         "packing": {"kind": "cubic", "radius": 0.25}, "bonds": {"rule": "colour"},
         "discontinuity": [{"name": "j", "centre": [1, 1, 1.5], "dip": 0.0, "dip_direction": 0.0, "radius": 5.0,
                            "thickness": 0.0}]}
    model = build_model(scene_from_dict(d, "cut.toml"))
    model.save(tmp_path / "model.npz")
    return model


def test_dda_run_of_a_sphere_scene(tmp_path):
    from dda.cli import main

    model = _cut_model(tmp_path)
    (tmp_path / "s.toml").write_text(
        'name = "hang"\n[simulation]\nduration = 0.2\nrecord_every = 0.05\n'
        '[contact]\nkn = 1e7\nfriction = 30.0\n'
        '[spheres]\nmodel = "model.npz"\nfixed = ["z>2.6"]\nbond_young = 1e8\nbond_tensile = 2e6\n'
        '[[block]]\nshape = "cube"\nsize = 1.0\ncenter = [1.0, 1.0, -5.0]\nfixed = true\n'
        '[output]\nformats = ["npz", "vtu"]\n')
    assert main(["run", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    z = np.load(tmp_path / "out" / "series.npz")
    assert z["bonds"][-1] == int(model.bonded.sum()) and z["bond_intact"].all()
    dz = z["pos"][-1][:, 2] - z["pos"][0][:, 2]
    below = model.centers[:, 2] < 1.5
    t = z["time"][-1]
    assert np.all(np.abs(dz[below] + 0.5 * G * t * t) < 0.02 * 0.5 * G * t * t)
    assert np.all(np.abs(dz[~below]) < 1e-3)
    assert (tmp_path / "out" / "spheres.vtu").is_file()


def test_sphere_scene_errors(tmp_path, capsys):
    from dda.cli import main

    _cut_model(tmp_path)
    base = '[simulation]\nduration = 0.1\n[contact]\nkn = 1e7\n'
    cases = [('[spheres]\nmodel = "nope.npz"\n', "spheres.model"),
             ('[spheres]\nmodel = "model.npz"\nfixed = ["q>1"]\n', "spheres.fixed"),
             ('[spheres]\nmodel = "model.npz"\nbond_young = -1\n', "spheres.bond_young"),
             ('[spheres]\nmodel = "model.npz"\n[[block]]\nshape = "cube"\nsize = 1.0\nfixed = true\nprescribed = true\n', "block[0].prescribed")]
    for k, (text, key) in enumerate(cases):
        (tmp_path / f"e{k}.toml").write_text(base + text)
        assert main(["run", str(tmp_path / f"e{k}.toml"), "-o", str(tmp_path / f"o{k}"), "--quiet"]) == 2
        assert key in capsys.readouterr().err
        assert not (tmp_path / f"o{k}").exists()


def test_spheres_model_may_be_an_sgim_scene_built_in_memory(tmp_path):
    """[spheres] model = "beam.toml" gives the same spheres and bonds as the model.npz that sgim build writes."""
    import subprocess
    import sys

    from dda.scene import load_scene

    (tmp_path / "beam.toml").write_text(
        'name = "beam"\n[domain]\nmin = [0, 0, 0]\nmax = [2, 1, 1]\n[packing]\nkind = "fcc"\nradius = 0.1\n'
        '[[discontinuity]]\nname = "j"\ncentre = [1, 0.5, 0.5]\ndip = 90.0\ndip_direction = 90.0\nradius = 3.0\n')
    subprocess.run([sys.executable, "-m", "sgim.cli", "build", str(tmp_path / "beam.toml"), "-o",
                    str(tmp_path / "beam"), "--formats", "npz", "--quiet"], check=True)
    runs = {}
    for name, ref in (("npz", "beam/model.npz"), ("toml", "beam.toml")):
        (tmp_path / f"{name}.toml").write_text(
            f'name = "{name}"\n[simulation]\nduration = 0.01\n[contact]\nkn = 1e7\n'
            f'[spheres]\nmodel = "{ref}"\n')
        runs[name] = load_scene(tmp_path / f"{name}.toml").spheres["model"]
    a, b = runs["npz"], runs["toml"]
    assert np.array_equal(a.centers, b.centers) and np.array_equal(a.bonds, b.bonds)
    assert np.array_equal(a.bonded, b.bonded) and not a.bonded.all()
