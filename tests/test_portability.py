"""The same bits on every CPU: membership, contact features and whole runs do not depend on the code paths a
machine's CPU selects.

Each job of tests/portable_jobs.py (Fast Common-Plane and contact points of 40 hull pairs; an sgim build with
a seeded random packing, cavities, a listric fault, a joint through lattice-round coordinates and a Fisher
fracture network; DDA runs of blocks and of bonded spheres with a block) runs in a subprocess under
environments that switch what differs between x86-64 CPUs:

- "another CPU": OPENBLAS_CORETYPE=Prescott (OpenBLAS's oldest x86-64 kernels in place of the ones this CPU
  selects: no FMA, other blocking, i.e. the BLAS / LAPACK round-off of another machine), NPY_DISABLE_CPU_FEATURES
  (numpy's SIMD dispatch, AVX2 / AVX-512, switched off: its element-wise and transcendental loops run the
  baseline code) and NUMBA_NUM_THREADS=1 (the parallel kernels on one thread), all at once;
- a fresh NUMBA_CACHE_DIR (the FCP job): its kernels compiled anew (results must not depend on a warm cache).

Every output array must hash the same as in the plain environment, and a second plain sgim build repeats the
first byte for byte. Jobs run two at a time (the cold compile overlaps the others).
"""
from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
JOBS = ("fcp", "sgim", "dda")


def _numpy_dispatch():
    """numpy's dispatch targets this CPU has (those are what NPY_DISABLE_CPU_FEATURES can switch off)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]


def _environments(tmp):
    """name -> (environment, jobs run in it). "another CPU" switches every CPU-dependent path at once (a
    difference there is then bisected by hand with the single variables)."""
    base = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")}
    other = {**base, "OPENBLAS_CORETYPE": "Prescott", "NUMBA_NUM_THREADS": "1"}
    off = _numpy_dispatch()
    if off:
        other["NPY_DISABLE_CPU_FEATURES"] = ",".join(off)
    return {
        "plain": (base, JOBS),
        "plain again": (base, ("sgim",)),  # the same scene and seed: byte-identical model.npz
        "another CPU (" + ", ".join(f"{k}={other[k]}" for k in sorted(set(other) - set(base))) + ")": (other, JOBS),
        # (a cold compile of the whole block and sphere engine costs one to two minutes of the suite: the FCP
        # job's kernels, which decide contact features, stand for the others; numba writes and reads every
        # kernel's cache the same way)
        "cold numba cache": ({**base, "NUMBA_CACHE_DIR": str(tmp / "numba-cold")}, ("fcp",)),
    }


def _run(job, env_name, env, tmp):
    work = tmp / f"{job}-{env_name.replace('=', '_').replace(' ', '_')}"
    work.mkdir()
    p = subprocess.run([sys.executable, str(HERE / "portable_jobs.py"), job, str(work)], env=env, cwd=work,
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, f"{job} under {env_name}: exit {p.returncode}\n{p.stderr[-3000:]}"
    lines = [ln for ln in p.stdout.splitlines() if ln.strip()]
    assert lines, f"{job} under {env_name}: no output"
    return dict(ln.split() for ln in lines)


def test_the_same_bits_under_every_cpu_code_path(tmp_path):
    envs = _environments(tmp_path)
    pairs = [(j, name) for name, (env, jobs) in envs.items() for j in jobs]
    order = sorted(pairs, key=lambda je: je[1] != "cold numba cache")  # the cold compile overlaps the rest
    with ThreadPoolExecutor(2) as pool:
        futures = {je: pool.submit(_run, je[0], je[1], envs[je[1]][0], tmp_path) for je in order}
        results = {je: f.result() for je, f in futures.items()}
    moved = []
    for (job, name), got in results.items():
        ref = results[(job, "plain")]
        assert ref and got.keys() == ref.keys(), (job, name)
        moved += [f"{job}: {out} differs under {name}" for out in ref if got[out] != ref[out]]
    assert not moved, "\n".join(moved)


@pytest.mark.parametrize("dip_direction, normal", [(0.0, (0.0, 1.0, 0.0)), (90.0, (1.0, 0.0, 0.0)),
                                                   (180.0, (0.0, -1.0, 0.0)), (270.0, (-1.0, 0.0, 0.0))])
def test_vertical_planes_of_round_orientation_have_exact_normals(dip_direction, normal):
    from sgim.geometry import dip_to_normal

    assert tuple(dip_to_normal(90.0, dip_direction)) == normal
    assert tuple(dip_to_normal(0.0, dip_direction)) == (0.0, 0.0, 1.0)


def test_portable_linear_algebra_against_references():
    """det3 against exact rational arithmetic, matmul against the definition summed in index order, eigh3
    against LAPACK (to round-off) and its own definition (A V = V diag(w), V orthonormal, right-handed)."""
    from fractions import Fraction

    import numpy as np

    from sgim.portable import det3, eigh3, matmul, norm

    rng = np.random.default_rng(5)
    for _ in range(200):
        a = rng.normal(size=(3, 3))
        q = [[Fraction(float(x)) for x in row] for row in a]
        exact = (q[0][0] * (q[1][1] * q[2][2] - q[1][2] * q[2][1]) - q[0][1] * (q[1][0] * q[2][2] - q[1][2] * q[2][0])
                 + q[0][2] * (q[1][0] * q[2][1] - q[1][1] * q[2][0]))
        assert abs(det3(a) - float(exact)) <= 1e-14 * max(1.0, abs(float(exact)))
        b = rng.normal(size=(3, 4))
        want = np.array([[sum((a[i, k] * b[k, j] for k in range(3)), 0.0) for j in range(4)] for i in range(3)])
        assert np.array_equal(matmul(a, b), want)
        assert matmul(a[0], b[:, 0]) == want[0, 0]
        assert norm(a[0]) == (a[0, 0] ** 2 + a[0, 1] ** 2 + a[0, 2] ** 2) ** 0.5
        s = a + a.T
        w, v = eigh3(s)
        assert np.allclose(w, np.linalg.eigh(s)[0], atol=1e-12)
        assert np.allclose(s @ v, v * w, atol=1e-12) and np.allclose(v.T @ v, np.eye(3), atol=1e-14)
        assert abs(det3(v) - 1.0) < 1e-12


def test_sines_of_degrees():
    import math

    from sgim.portable import sin_cos_deg

    exact = {0: (0.0, 1.0), 30: (0.5, math.sqrt(3) / 2), 45: (math.sqrt(0.5), math.sqrt(0.5)),
             60: (math.sqrt(3) / 2, 0.5), 90: (1.0, 0.0)}
    for k in range(-8, 9):  # every quadrant, both signs, past a full turn
        for a, (s, c) in exact.items():
            got = sin_cos_deg(a + 90.0 * k)
            want = [(s, c), (c, -s), (-s, -c), (-c, s)][k % 4]
            assert got == (want[0] + 0.0, want[1] + 0.0), (a + 90.0 * k, got, want)
    for a in (1.0, 10.0, 37.5, 44.9, 45.1, 89.0, 123.4, 271.0, 359.5, -17.0):
        s, c = sin_cos_deg(a)
        assert abs(s - math.sin(math.radians(a))) < 4e-16 and abs(c - math.cos(math.radians(a))) < 4e-16


def test_portable_inverse_cholesky_and_eigenvalues():
    """inv, cholesky and eigvalsh (used for the deformable blocks' mass matrices and critical time step)
    against their definitions and LAPACK."""
    import numpy as np

    from sgim.portable import cholesky, eigvalsh, inv

    rng = np.random.default_rng(8)
    for n in (3, 9, 12):
        a = rng.normal(size=(n, n))
        s = a @ a.T + n * np.eye(n)
        assert np.allclose(inv(s) @ s, np.eye(n), atol=1e-12) and np.allclose(inv(a) @ a, np.eye(n), atol=1e-9)
        low = cholesky(s)
        assert np.array_equal(low, np.tril(low)) and np.allclose(low @ low.T, s, atol=1e-12)
        w = eigvalsh(s)
        assert np.allclose(w, np.linalg.eigvalsh(s), rtol=1e-13, atol=1e-12) and np.all(np.diff(w) >= 0)
