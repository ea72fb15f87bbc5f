"""Jobs whose every output bit must be the same on every x86-64 CPU, for tests/test_portability.py.

    python tests/portable_jobs.py JOB WORKDIR     prints one line per output: NAME SHA1

Each job hashes the arrays it produces. The test runs the jobs in subprocesses under environments that
switch the CPU-dependent code paths a machine may take (OpenBLAS's kernel, numpy's SIMD dispatch, numba's
thread count, a cold numba cache) and asserts that the hashes do not move.
"""
from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# An sgim scene with every kind of membership decision: a random packing (seeded), a tunnel and a cavern,
# a listric fault with a core, a joint disc through round coordinates (dip 90 / dd 90 at x = 3) and a
# Fisher fracture network with power-law radii.
SGIM_SCENE = """\
name = "portable"
[domain]
min = [-12.0, -9.0, 0.0]
max = [12.0, 9.0, 16.0]
[packing]
kind = "random"
radius = 0.55
seed = 7
[[cavity]]
name = "tunnel"
shape = "horseshoe_tunnel"
path = [[-14.0, -1.0, 5.0], [0.0, 1.0, 5.0], [14.0, 0.0, 6.0]]
width = 4.0
height = 3.5
segments = 24
[[cavity]]
name = "cavern"
shape = "ellipsoid"
centre = [6.0, -5.0, 11.0]
radii = [3.0, 2.0, 2.5]
segments = 24
[[discontinuity]]
name = "vertical"
centre = [3.0, 0.0, 8.0]
dip = 90.0
dip_direction = 90.0
radius = 20.0
[[discontinuity]]
name = "listric"
shape = "listric"
trace = [-8.0, 0.0, 16.0]
dip_direction = 100.0
dip_top = 70.0
dip_bottom = 30.0
depth = 16.0
length = 24.0
resolution = 1.5
thickness = 1.0
[bonds]
rule = "colour"
[dfn]
seed = 2013
max_fractures = 5000
[[joint_set]]
name = "J1"
dip = 75.0
dip_direction = 40.0
kappa = 30.0
p32 = 0.08
[joint_set.radius]
law = "power"
exponent = 2.7
min = 1.5
max = 10.0
[[joint_set]]
name = "J2"
dip = 15.0
dip_direction = 220.0
kappa = 20.0
p32 = 0.05
[joint_set.radius]
law = "lognormal"
mean = 3.0
sd = 1.0
[output]
formats = ["npz"]
"""


def _hash(*arrays) -> str:
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def job_fcp(work: Path):
    """Fast Common-Plane and the contact points of 40 random hull pairs, separated and in shallow overlap."""
    sys.path.insert(0, str(HERE))
    from test_dda_fcp import MAXP, _fcp, _pair, contact_points

    from dda.blockspec import BlockSpec
    from dda.simulation import Simulation
    from dda.system import BlockSystem

    out = []
    rng = np.random.default_rng(11)
    for _ in range(40):
        sim, va, fa, vb, fb = _pair(rng, rng.uniform(4.0, 6.0))
        g, nrm, sa, sb, it = _fcp(sim, sim.pos[1] - sim.pos[0])
        out += [sim.vert, sim.fnw, sim.fdw, np.array([g, sa, sb]), nrm]
        bs = BlockSystem()
        bs.add_block(BlockSpec(va, fa))
        bs.add_block(BlockSpec(vb - (g + 0.01) * nrm, fb))
        sim = Simulation(bs, gravity=(0, 0, 0), dt=1e-3)
        g, nrm, sa, sb, it = _fcp(sim, nrm)
        pos, dep, ids = np.zeros((MAXP, 3)), np.zeros(MAXP), np.zeros(MAXP, np.int64)
        k = contact_points(sim.bundles().geometry, 0, 1, nrm, sa, sb, 0.0, 1.0, pos, dep, ids)
        out += [np.array([g, sa, sb, k]), nrm, pos, dep, ids]
    print("fcp", _hash(*out))


def job_sgim(work: Path):
    """`sgim build` of SGIM_SCENE: every array of model.npz."""
    from sgim.cli import main

    scene = work / "portable.toml"
    scene.write_text(SGIM_SCENE)
    out = work / "model"
    rc = main(["build", str(scene), "-o", str(out), "--quiet"])
    assert rc == 0, rc
    with np.load(out / "model.npz", allow_pickle=False) as z:
        for name in sorted(z.files):
            if name != "meta":
                print(f"model.{name}", _hash(z[name]))


def _dda_run(work: Path, name: str, duration: float):
    """`dda run` of cases/scenes/NAME.toml cut to `duration` with npz output only: hashes of its npz files (the wall
    time left out)."""
    src = (HERE.parent / "cases" / "scenes" / f"{name}.toml").read_text()
    lines = []
    for line in src.splitlines():
        key = line.split("=")[0].strip()
        if key == "duration":
            line = f"duration = {duration}"
        elif key == "frames":
            line = "frames = 1"
        elif key == "formats":
            line = 'formats = ["npz"]'
        elif key == "model":  # the sphere model lies beside the scene in cases/scenes/
            line = f"model = {str(HERE.parent / 'cases' / 'scenes' / line.split('=')[1].strip().strip(chr(34)))!r}"
        lines.append(line)
    scene = work / f"{name}.toml"
    scene.write_text("\n".join(lines) + "\n")
    from dda.cli import main

    rc = main(["run", str(scene), "-o", str(work / name), "--quiet"])
    assert rc == 0, rc
    parts = sorted((work / name).glob("*.npz"))
    assert parts, f"{name}: no npz output"
    for part in parts:
        with np.load(part, allow_pickle=False) as z:
            keep = [z[k] for k in sorted(z.files) if z[k].dtype.kind in "fiub" and k != "wall_s"]
            print(f"{name}.{part.name}", _hash(*keep))


def job_dda(work: Path):
    """DDA runs: the paper's wedge sliding on its two joints (blocks, 0.3 s) and bonded spheres hit by a
    falling cube (spheres, blocks and breaking bonds, 0.2 s)."""
    _dda_run(work, "dda_wedge", 0.3)
    _dda_run(work, "dda_spheres_block", 0.2)


JOBS = {"fcp": job_fcp, "sgim": job_sgim, "dda": job_dda}

if __name__ == "__main__":
    JOBS[sys.argv[1]](Path(sys.argv[2]))
