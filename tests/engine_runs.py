"""Shared by the adapters' tests: the CI rule for engines, and SphereRuns written out by hand."""
from __future__ import annotations

import math
import os
import shutil

import numpy as np
import pytest

from adapters.spec import SphereRun

G = 9.81
CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require_engine(name, module=False):
    """Skip without `name` on PATH, except on CI (CI=true), where a missing engine fails: the README set-up
    installs it, so the suite must never pass there without running it."""
    if shutil.which(name) is None:
        msg = f"{name} not found on PATH (install the Debian package '{name}', see README)"
        if CI:
            if module:
                raise RuntimeError(msg)
            pytest.fail(msg)
        pytest.skip(f"{name} not installed", allow_module_level=module)


def hand_run(centers, radii, fixed=(), bonds=(), kn=1e6, ft=math.inf, dt=1e-5, duration=0.01, record_every=None,
             colour=None, density=2600.0, gravity=(0.0, 0.0, -G), name="hand", local_damping=0.0,
             contact_kn=None, force=None, prescribed=(), velocity=None, **extra):
    """A SphereRun written out by hand (no sgim model): bonds (i, j) with stiffness kn (shear kn / 2) and
    tensile strength ft; contacts with contact_kn (default kn), shear half of it, friction 30 degrees. Loads:
    `force` (n, 3) or (3,) [N] on each sphere, `prescribed` sphere indices moving at `velocity` ((n, 3) or (3,))."""
    c = np.asarray(centers, float).reshape(-1, 3)
    n = len(c)
    r = np.broadcast_to(np.asarray(radii, float), (n,)).copy()
    fx = np.zeros(n, bool)
    fx[list(fixed)] = True
    b = np.asarray(bonds, np.int64).reshape(-1, 2)
    bi, bj = b.min(1), b.max(1)
    m = len(b)
    ck = float(kn if contact_kn is None else contact_kn)
    pr = np.zeros(n, bool)
    pr[list(prescribed)] = True
    vel = np.where(pr[:, None], np.broadcast_to(np.asarray(0.0 if velocity is None else velocity, float), (n, 3)), 0.0)
    frc = np.broadcast_to(np.asarray(0.0 if force is None else force, float), (n, 3)).copy()
    return SphereRun(
        name=name, centers=c, radii=r, colour=np.zeros(n, np.int8) if colour is None else np.asarray(colour, np.int8),
        fixed=fx, density=density, bond_i=bi, bond_j=bj, bond_len0=np.linalg.norm(c[bj] - c[bi], axis=1),
        bond_kn=np.full(m, float(kn)), bond_ks=np.full(m, kn / 2), bond_ft=np.broadcast_to(ft, (m,)).astype(float),
        bond_fs=np.full(m, math.inf), joint_i=np.zeros(0, np.int64), joint_j=np.zeros(0, np.int64),
        joint_disc=np.zeros(0, np.int32), joint_normal=np.zeros((0, 3)), cut_i=np.zeros(0, np.int64),
        cut_j=np.zeros(0, np.int64), kn=ck, ks=ck / 2, friction_deg=30.0, damping=0.0, joint_friction_deg=30.0,
        smooth_joints=True, gravity=np.asarray(gravity, float), dt=dt, duration=duration,
        record_every=record_every or duration / 10, local_damping=local_damping, extra=dict(extra), force=frc,
        prescribed=pr, velocity=vel)
