"""The bonded-sphere step on several cores gives the same bits for any number of threads.

The bond pass, the gather of the bond forces per sphere and the integration run in prange over chunks of spheres
(dda/_bondlaw.py ``bond_forces``, dda/_spheres.py ``integrate``); every sum has a fixed order. The same deck
(more than two chunks of spheres; full bonds and central bonds in one list that is not sorted by sphere; bonds
breaking; fixed, prescribed and damped spheres) runs in two processes, with NUMBA_NUM_THREADS=1 and 2, and the
final states must agree to the bit. A one-step check compares the forces on the spheres with a plain Python
transcription of the serial bond loop over the bond list sorted by its first sphere.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
R = 0.01

CHILD = r"""
import sys
import numba
import numpy as np
sys.path.insert(0, sys.argv[2])
from test_dda_sphere_threads import deck
sim = deck()
sim.run(60 * sim.dt, record_every=20 * sim.dt)
np.savez(sys.argv[1], threads=numba.get_num_threads(), x=sim.x, v=sim.v, w=sim.w, rows=sim.bond_rows,
         intact=sim.bond_intact, brk=sim.bond_break_time, energy=sim.energy, stats=sim.stats, acc=sim.acc)
"""


def deck(shape=(17, 17, 18), seed=3):
    """A cubic lattice of spheres: full bonds (shear springs) along the axes, central bonds across the face
    diagonals, both in one shuffled list; bottom layer fixed, top layer prescribed, random velocities that break
    some bonds."""
    from dda.simulation import ContactLaw
    from dda.spheres import BondLaw, SphereSet, SphereSimulation

    nx, ny, nz = shape
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 3)
    ss = SphereSet(2.0 * R * g.astype(float), np.full(len(g), R), 2600.0)
    idx = np.arange(len(g)).reshape(shape)
    axis, diag = [], []
    for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1)):
        a = idx[:nx - d[0], :ny - d[1], :nz - d[2]].ravel()
        b = idx[d[0]:, d[1]:, d[2]:].ravel()
        (axis if sum(d) == 1 else diag).append(np.c_[a, b])
    rng = np.random.default_rng(seed)
    axis, diag = np.concatenate(axis), np.concatenate(diag)
    ss.add_bonds(axis[rng.permutation(len(axis))], BondLaw(kn=1e6, ks=4e5, tensile=3e5, shear=3e5, damping=0.05))
    ss.add_bonds(diag[rng.permutation(len(diag))][:, ::-1], BondLaw(kn=5e5, ks=0.0, tensile=5e4, damping=0.02))
    z = ss.centers[:, 2]
    ss.fixed[z < R] = True
    ss.prescribed[z > z.max() - R] = True
    ss.velocity[:] = rng.normal(0.0, 0.05, (ss.n, 3))
    ss.angular_velocity[:] = rng.normal(0.0, 2.0, (ss.n, 3))
    return SphereSimulation(ss, ContactLaw(kn=1e6, ks=4e5, friction_deg=30.0), local_damping=0.05)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("threads")
    out = {}
    for nt in (1, 2):
        env = dict(os.environ, NUMBA_NUM_THREADS=str(nt))
        p = subprocess.run([sys.executable, "-c", CHILD, str(tmp / f"t{nt}.npz"), str(ROOT / "tests")], cwd=ROOT,
                           env=env, capture_output=True, text=True)
        assert p.returncode == 0, p.stderr[-2000:]
        out[nt] = dict(np.load(tmp / f"t{nt}.npz"))
    return out


def test_one_and_two_threads_give_the_same_bits(runs):
    from dda._sphere_state import SCHUNK

    one, two = runs[1], runs[2]
    assert int(one["threads"]) == 1 and int(two["threads"]) == 2
    assert len(one["x"]) > 2 * SCHUNK  # several chunks of the parallel passes
    broken = ~one["intact"]
    full = one["rows"][:, 2] > 0.0
    assert (broken & full).sum() > 10 and (broken & ~full).sum() > 10  # both bond loops broke bonds
    for key in ("x", "v", "w", "rows", "intact", "brk", "energy", "stats", "acc"):
        assert one[key].shape == two[key].shape
        assert one[key].tobytes() == two[key].tobytes(), key


def _meff(sim, i, j):
    """The effective mass of a pair: the free sphere's when the other one is held, else m_i m_j / (m_i + m_j)."""
    si, sj = sim.fixed[i] or sim.kin[i], sim.fixed[j] or sim.kin[j]
    if si and not sj:
        return sim.m[j]
    if sj and not si:
        return sim.m[i]
    return sim.m[i] * sim.m[j] / (sim.m[i] + sim.m[j])


def _serial_bond_forces(sim):
    """The bond forces and torques of one step as the serial loop adds them: the bonds sorted by their first
    sphere i (full bonds, then central bonds), force f on j added bond by bond, the sum of i's bonds subtracted
    once (a plain Python transcription of the bond law for intact bonds that do not break)."""
    ss = sim.spheres
    x, v, w = sim.x, sim.v, sim.w
    force = np.zeros((ss.n, 3))
    torque = np.zeros((ss.n, 3))
    for full in (True, False):
        ks_pos = ss.bond_ks > 0.0
        ks_sel = np.flatnonzero(ks_pos if full else ~ks_pos)
        ks_sel = ks_sel[np.argsort(ss.bond_i[ks_sel], kind="stable")]
        g = {}
        for k in ks_sel:
            i, j = int(ss.bond_i[k]), int(ss.bond_j[k])
            d = x[j] - x[i]
            dl = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            assert sim.bond_intact[k]
            row = sim.bond_rows[k]
            fn = ss.bond_kn[k] * (dl - ss.bond_len0[k])
            if full:
                n = d * (1.0 / dl)
                a0 = dl * row[10]
                aj = a0 - dl
                dv = v[j] - v[i]
                vn = dv[0] * n[0] + dv[1] * n[1] + dv[2] * n[2]
                c = aj * w[j] - a0 * w[i]
                vr = np.array([dv[0] + c[1] * n[2] - c[2] * n[1], dv[1] + c[2] * n[0] - c[0] * n[2],
                               dv[2] + c[0] * n[1] - c[1] * n[0]])
                u = 0.0 + (vr - vn * n) * sim.dt  # a fresh bond: no shear displacement before this step
                meff = _meff(sim, i, j)
                cdn = 2.0 * row[5] * np.sqrt(row[1] * meff)
                cds = 2.0 * row[5] * np.sqrt(row[2] * meff)
                f = -(fn + cdn * vn) * n - row[2] * u - cds * (vr - vn * n)
                q = np.array([n[1] * f[2] - n[2] * f[1], n[2] * f[0] - n[0] * f[2], n[0] * f[1] - n[1] * f[0]])
                tj, ti = aj * q, a0 * q
            else:
                meff = _meff(sim, i, j)
                vn = ((v[j, 0] - v[i, 0]) * d[0] + (v[j, 1] - v[i, 1]) * d[1] + (v[j, 2] - v[i, 2]) * d[2]) * (1.0 / dl)
                cdn = 2.0 * ss.bond_zeta[k] * np.sqrt(ss.bond_kn[k] * meff)
                f = (-(fn + cdn * vn) / dl) * d
                tj = ti = np.zeros(3)
            force[j] += f
            torque[j] += tj
            gi = g.setdefault(i, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            for a in range(3):
                gi[a] += f[a]
                gi[3 + a] += ti[a]
        for i in sorted(g):
            force[i] -= g[i][:3]
            torque[i] -= g[i][3:]
    return force, torque


def test_bond_forces_match_the_serial_loop_bit_for_bit():
    from dda import _bondlaw
    from dda._sphere_state import Motion, PairList

    sim = deck(shape=(9, 8, 7))
    sim.bond_rows[:, 3] = np.inf  # nothing breaks in this step
    sim.bond_rows[:, 4] = np.inf
    sim.cbond_rows[:, 2] = np.inf
    sp, env, bonds, joints, hist, books = sim.bundles()
    _bondlaw.sync_central(bonds)
    mo = Motion(sim.x, sim.v, sim.w, np.zeros((sim.spheres.n, 3)), np.zeros((sim.spheres.n, 3)))
    pl = PairList(np.zeros((0, 2), np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros((0, 3)), 0.0)
    ref_f, ref_t = _serial_bond_forces(sim)
    res = np.zeros(3)
    _bondlaw.bond_forces(mo, sp, bonds, pl, sim.dt, 0.0, True, res)
    assert np.abs(ref_f).max() > 0.0 and np.abs(ref_t).max() > 0.0
    assert mo.force.tobytes() == ref_f.tobytes()
    assert mo.torque.tobytes() == ref_t.tobytes()
