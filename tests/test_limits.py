"""Resource estimates before work (sgim/limits.py) and step limits (dda/limits.py): absurd builds and runs are
refused at once with one line naming the key to change, the estimates match real builds, and the limits are
exact thresholds."""
from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dda.cli import main as dda_main
from sgim.cli import main as sgim_main

ROOT = Path(__file__).resolve().parents[1]


def _write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _refused(capsys, rc, out, *keys):
    """Exit status 2, exactly one stderr line naming every key in `keys`, no output folder (nor its
    temporary .part folder) left behind."""
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert rc == 2, captured.err
    assert len(lines) == 1, captured.err
    for key in keys:
        assert key in lines[0], lines[0]
    assert "Traceback" not in captured.err
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]
    return lines[0]


def _box(kind, lo, hi, r, extra=""):
    return f"""name = "box"
[domain]
min = {list(map(float, lo))}
max = {list(map(float, hi))}
[packing]
kind = "{kind}"
radius = {r}
[output]
formats = ["npz"]
{extra}"""


def _spheres_in(path):
    with np.load(path) as z:
        return len(z["radii"])


# ---------------------------------------------------------------------------------------------------------
# the reproducers


def test_lattice_of_a_10_km_cube_is_refused_before_any_allocation(tmp_path, capsys):
    scene = _write(tmp_path, _box("cubic", [0, 0, 0], [10000, 10000, 10000], 0.5))
    out = tmp_path / "out"
    rc = sgim_main(["build", str(scene), "-o", str(out)])
    line = _refused(capsys, rc, out, "limits.max_spheres", "packing.radius", "--max-spheres", "1.0e+12")
    assert line.startswith(f"sgim: error: {scene}: limits.max_spheres = ")


def test_random_packing_of_a_100_m_cube_at_1_cm_is_refused(tmp_path, capsys):
    scene = _write(tmp_path, _box("random", [0, 0, 0], [100, 100, 100], 0.01))
    out = tmp_path / "out"
    rc = sgim_main(["build", str(scene), "-o", str(out)])
    _refused(capsys, rc, out, "limits.max_spheres", "packing.radius", "1.5e+11")


def _incline(tmp_path, old, new):
    text = (ROOT / "cases" / "scenes" / "dda_incline.toml").read_text()
    assert old in text
    return _write(tmp_path, text.replace(old, new))


def test_incline_with_absurd_stiffness_is_refused_naming_kn_and_dt(tmp_path, capsys):
    scene = _incline(tmp_path, "kn = 1e11 ", "kn = 1e30 ")
    out = tmp_path / "out"
    rc = dda_main(["run", str(scene), "-o", str(out)])
    line = _refused(capsys, rc, out, "contact.kn = 1e+30", "dt = 5.6e-15 s", "max_steps", "--max-steps")
    assert line.startswith(f"dda: error: {scene}: contact.kn = ")


def test_incline_with_absurd_duration_is_refused_naming_the_duration(tmp_path, capsys):
    scene = _incline(tmp_path, "duration = 1.0", "duration = 1e9")
    out = tmp_path / "out"
    rc = dda_main(["run", str(scene), "-o", str(out)])
    line = _refused(capsys, rc, out, "simulation.duration", "dt = 1.8e-05 s", "5.6e+13 steps", "contact.kn")
    assert line.startswith(f"dda: error: {scene}: simulation.duration = ")


def test_10_km_cube_refusal_takes_well_under_two_seconds(tmp_path):
    """Interpreter start included (0.4 s on an idle 2-core machine); the best of up to three runs, so that a
    moment of contention on a shared machine does not fail it (the old build took 8.7 s to fail)."""
    scene = _write(tmp_path, _box("cubic", [0, 0, 0], [10000, 10000, 10000], 0.5))
    walls = []
    for _ in range(3):
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "sgim.cli", "build", str(scene), "-o", str(tmp_path / "out")],
                           capture_output=True, text=True, timeout=60)
        walls.append(time.perf_counter() - t0)
        assert p.returncode == 2, p.stderr
        assert len(p.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "out").exists()
        if walls[-1] < 2.0:
            break
    assert min(walls) < 2.0, walls


# ---------------------------------------------------------------------------------------------------------
# the estimates


def _brute_force_sites(kind, lo, hi, r):
    """Lattice sites with the sphere inside the box, from the lattice vectors (independent of sgim.packing):
    cubic: spacing 2r from lo + r; fcc: a Bravais lattice (2r, 0, 0), (r, r sqrt 3, 0), (r, r / sqrt 3, h);
    hcp: the same net with a two-layer basis (layer B shifted by (r, r / sqrt 3)), h = 2r sqrt(2/3)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    o = lo + r
    span = int(np.max(hi - lo) / r) + 4
    i = np.arange(-span, span + 1)
    if kind == "cubic":
        a = [np.array([2 * r, 0, 0]), np.array([0, 2 * r, 0]), np.array([0, 0, 2 * r])]
        basis = [np.zeros(3)]
    else:
        h = 2 * r * math.sqrt(2 / 3)
        a = [np.array([2 * r, 0, 0]), np.array([r, r * math.sqrt(3), 0])]
        b = np.array([r, r / math.sqrt(3), h])
        if kind == "fcc":
            a.append(b)
            basis = [np.zeros(3)]
        else:
            a.append(np.array([0, 0, 2 * h]))
            basis = [np.zeros(3), b]
    I, J, K = np.meshgrid(i, i, i, indexing="ij")
    count = 0
    eps = 1e-9 * r
    for s in basis:
        p = o + s + I[..., None] * a[0] + J[..., None] * a[1] + K[..., None] * a[2]
        inside = np.all((p >= lo + r - eps) & (p <= hi - r + eps), axis=-1)
        count += int(inside.sum())
    return count


@pytest.mark.parametrize("kind, hi", [("cubic", [4.0, 3.0, 2.0]), ("hexagonal", [4.3, 3.1, 2.7]),
                                      ("fcc", [3.7, 3.3, 2.9])])
def test_lattice_estimate_equals_the_sites_and_the_spheres_built(tmp_path, capsys, kind, hi):
    from sgim.limits import estimate
    from sgim.scene import load_scene

    lo = [-0.3, 0.2, 0.0]
    hi = [lo[k] + hi[k] for k in range(3)]
    scene = _write(tmp_path, _box(kind, lo, hi, 0.25))
    est = estimate(load_scene(scene))
    assert not est.upper_bound  # no excavation, no cavity: the count is exact
    brute = _brute_force_sites(kind, lo, hi, 0.25)
    out = tmp_path / "out"
    assert sgim_main(["build", str(scene), "-o", str(out), "--quiet"]) == 0
    built = _spheres_in(out / "model.npz")
    assert est.spheres == brute == built


def test_lattice_estimate_with_excavation_is_an_upper_bound_and_says_so(tmp_path):
    from sgim.limits import estimate
    from sgim.scene import load_scene

    extra = """[[excavation]]
points = [[-1.0, -1.0, 1.5], [5.0, -1.0, 1.0], [5.0, 5.0, 2.0], [-1.0, 5.0, 1.2]]
"""
    scene = load_scene(_write(tmp_path, _box("cubic", [0, 0, 0], [4, 4, 3], 0.25, extra)))
    est = estimate(scene)
    assert est.upper_bound and "before excavation" in est.line()
    from sgim.builder import build_model

    assert len(build_model(scene).radii) < est.spheres == scene.n_lattice_sites


@pytest.mark.parametrize("extra", ["", """[[cavity]]
shape = "ellipsoid"
centre = [2.0, 2.0, 1.0]
radius = 0.8
""", """[packing.distribution]
law = "uniform"
min = 0.06
max = 0.12
"""])
def test_random_estimate_is_within_ten_percent_of_a_real_packing(tmp_path, capsys, extra):
    from sgim.limits import estimate
    from sgim.scene import load_scene

    text = _box("random", [0, 0, 0], [4, 4, 2], 0.1, extra)
    if "distribution" in extra:
        text = text.replace("radius = 0.1\n", "")
    scene = _write(tmp_path, text)
    est = estimate(load_scene(scene))
    out = tmp_path / "out"
    assert sgim_main(["build", str(scene), "-o", str(out), "--quiet"]) == 0
    built = _spheres_in(out / "model.npz")
    assert abs(est.spheres / built - 1.0) < 0.10, (est.spheres, built)


def test_the_build_prints_its_estimate_as_a_progress_line(tmp_path, capsys):
    scene = _write(tmp_path, _box("cubic", [0, 0, 0], [4, 4, 4], 0.25))
    assert sgim_main(["build", str(scene), "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "estimate   512 spheres, " in err


# ---------------------------------------------------------------------------------------------------------
# the limits are thresholds


def test_max_spheres_flag_just_below_refuses_and_at_or_above_builds(tmp_path, capsys):
    scene = _write(tmp_path, _box("fcc", [0, 0, 0], [3.1, 2.9, 2.3], 0.25))
    from sgim.packing import lattice_counts

    n = lattice_counts("fcc", [0, 0, 0], [3.1, 2.9, 2.3], 0.25)[0]
    out = tmp_path / "out"
    rc = sgim_main(["build", str(scene), "-o", str(out), "--max-spheres", str(n - 1)])
    line = _refused(capsys, rc, out, f"--max-spheres = {n - 1}", "packing.radius")
    assert f"holds {n} sites" in line
    for limit in (n, n + 1):  # the second replaces the first's output (--force)
        assert sgim_main(["build", str(scene), "-o", str(out), "--quiet", "--force", "--max-spheres", str(limit)]) == 0
        assert _spheres_in(out / "model.npz") == n


def test_scene_limits_table_sets_the_limit_and_is_validated(tmp_path, capsys):
    base = _box("cubic", [0, 0, 0], [4, 4, 4], 0.25)  # 512 sites
    out = tmp_path / "out"
    rc = sgim_main(["build", str(_write(tmp_path, base + "[limits]\nmax_spheres = 511\n")), "-o", str(out)])
    _refused(capsys, rc, out, "limits.max_spheres = 511", "the scene's")
    # the flag overrides the scene
    assert sgim_main(["build", str(tmp_path / "scene.toml"), "-o", str(out), "--quiet", "--max-spheres", "512"]) == 0
    import shutil

    shutil.rmtree(out)
    assert sgim_main(["build", str(_write(tmp_path, base + "[limits]\nmax_spheres = 5.12e2\n")), "-o", str(out),
                      "--quiet"]) == 0
    shutil.rmtree(out)
    for bad, key in (("max_spheres = 0", "limits.max_spheres"), ("max_spheres = 1.5", "limits.max_spheres"),
                     ('max_spheres = "many"', "limits.max_spheres"), ("max_rocks = 5", "limits.max_rocks")):
        rc = sgim_main(["build", str(_write(tmp_path, base + f"[limits]\n{bad}\n")), "-o", str(out)])
        _refused(capsys, rc, out, key)
    rc = sgim_main(["build", str(_write(tmp_path, base)), "-o", str(out), "--max-spheres", "lots"])
    _refused(capsys, rc, out, "--max-spheres = 'lots'")


def test_memory_past_what_is_available_is_refused_under_the_limit(tmp_path):
    from sgim.limits import check_build
    from sgim.scene import SceneError, load_scene

    scene = load_scene(_write(tmp_path, _box("cubic", [0, 0, 0], [20, 20, 20], 0.25)))  # 64 000 sites
    check_build(scene, mem=(16e9, 8e9))
    with pytest.raises(SceneError) as err:
        check_build(scene, mem=(16e9, 1e8))  # 100 MB available
    assert err.value.key == "packing.radius"
    assert "MemAvailable" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(SceneError) as err:
        check_build(scene, mem=(20e6, None))  # a machine with 20 MB: the default limit is 1000 spheres
    assert err.value.key == "limits.max_spheres" and err.value.value == 1000


def test_every_path_that_builds_a_model_goes_through_the_check(tmp_path, capsys):
    """build_model itself (studies, adapters), the in-memory build of a dda [spheres] scene, and adapters
    export of an sgim scene refuse the 10 km cube at once."""
    from sgim.builder import build_model
    from sgim.scene import SceneError, load_scene

    huge = _write(tmp_path, _box("cubic", [0, 0, 0], [10000, 10000, 10000], 0.5), "huge.toml")
    t0 = time.perf_counter()
    with pytest.raises(SceneError) as err:
        build_model(load_scene(huge))
    assert err.value.key == "limits.max_spheres"
    from cases.lib.evaluators import sgim_build, sgim_volume

    with pytest.raises(SceneError, match="limits.max_spheres"):
        sgim_build(huge, None, {})
    with pytest.raises(SceneError, match="limits.max_spheres"):
        sgim_volume(_write(tmp_path, _box("cubic", [0, 0, 0], [10000, 10000, 10000], 0.5, """[[excavation]]
points = [[-1.0, -1.0, 50.0], [10001.0, -1.0, 40.0], [10001.0, 10001.0, 60.0], [-1.0, 10001.0, 45.0]]
"""), "huge_pit.toml"), None, {})
    dda_scene = _write(tmp_path, """name = "on_huge"
[simulation]
duration = 0.01
[contact]
kn = 1e7
[spheres]
model = "huge.toml"
""", "dda.toml")
    out = tmp_path / "out"
    rc = dda_main(["run", str(dda_scene), "-o", str(out)])
    line = _refused(capsys, rc, out, "limits.max_spheres")
    assert "huge.toml" in line
    from adapters.cli import main as adapters_main

    rc = adapters_main(["export", str(huge), "--to", "vtu", "-o", str(out)])
    _refused(capsys, rc, out, "limits.max_spheres")
    assert time.perf_counter() - t0 < 20


def test_dfn_with_an_absurd_p32_is_refused_quickly(tmp_path, capsys):
    scene = _write(tmp_path, _box("cubic", [0, 0, 0], [1000, 1000, 1000], 5.0, """[[joint_set]]
name = "J1"
dip = 60.0
dip_direction = 30.0
kappa = 20.0
p32 = 1000.0
radius = 0.5
"""))
    out = tmp_path / "out"
    t0 = time.perf_counter()
    rc = sgim_main(["dfn", str(scene), "-o", str(out)])
    _refused(capsys, rc, out, "joint_set[0].p32", "dfn.max_fractures")
    assert time.perf_counter() - t0 < 10


# ---------------------------------------------------------------------------------------------------------
# step limits


SMALL_DDA = """name = "small_slide"
[simulation]
duration = 0.02
record_every = 0.01
frames = 1
[contact]
kn = 1e9
friction = 20.0
damping = 0.2
[[block]]
name = "base"
fixed = true
vertices = [[-3, -2, -1], [3, -2, -1], [3, 2, -1], [-3, 2, -1], [-3, -2, 0], [3, -2, 0], [3, 2, 0], [-3, 2, 0]]
faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
[[block]]
name = "cube"
shape = "cube"
size = 1.0
center = [0.0, 0.0, 0.5]
velocity = [1.0, 0.0, 0.0]
[output]
formats = ["npz"]
"""


def test_max_steps_flag_just_below_refuses_and_at_the_count_runs(tmp_path, capsys):
    import json

    from dda.limits import run_steps
    from dda.scene import load_scene

    scene = _write(tmp_path, SMALL_DDA)
    _, sim = load_scene(scene).build()
    n = run_steps(0.02, sim.dt)
    out = tmp_path / "out"
    rc = dda_main(["run", str(scene), "-o", str(out), "--max-steps", str(n - 1)])
    line = _refused(capsys, rc, out, f"past max_steps = {n - 1:.3g} (--max-steps)")
    assert f"is {n:.2g} steps" in line
    assert dda_main(["run", str(scene), "-o", str(out), "--quiet", "--max-steps", str(n)]) == 0
    assert json.loads((out / "summary.json").read_text())["steps"] == n


def test_scene_max_steps_keys(tmp_path, capsys):
    out = tmp_path / "out"
    for table in ("[simulation]\nmax_steps = 10\n", "[limits]\nmax_steps = 10\n"):
        text = SMALL_DDA.replace("[simulation]\n", "[simulation]\nmax_steps = 10\n") if "simulation" in table \
            else SMALL_DDA + table
        rc = dda_main(["run", str(_write(tmp_path, text)), "-o", str(out)])
        key = "simulation.max_steps" if "simulation" in table else "limits.max_steps"
        _refused(capsys, rc, out, f"raise {key} or --max-steps", "past max_steps = 10 (the scene's)")
    both = SMALL_DDA.replace("[simulation]\n", "[simulation]\nmax_steps = 10\n") + "[limits]\nmax_steps = 10\n"
    for text, key in ((both, "limits.max_steps"), (SMALL_DDA + "[limits]\nmax_spheres = 10\n", "limits.max_spheres"),
                      (SMALL_DDA.replace("[simulation]\n", "[simulation]\nmax_steps = 0\n"), "simulation.max_steps"),
                      (SMALL_DDA.replace("[simulation]\n", "[simulation]\nmax_step = 9\n"), "simulation.max_step")):
        rc = dda_main(["run", str(_write(tmp_path, text)), "-o", str(out)])
        _refused(capsys, rc, out, key)


def test_every_dda_scene_of_cases_is_within_the_default_step_limit():
    """The DDA scenes of cases/ (blocks and spheres, the crossval and study scenes too) pass the default limit
    with a margin of over 100 (the longest, dda_toppling, takes 1.4e5 steps)."""
    from dda.limits import DEFAULT_MAX_STEPS, run_steps
    from dda.scene import load_scene

    worst = 0
    paths = [*(ROOT / "cases" / "scenes").glob("dda_*.toml"), *(ROOT / "cases" / "scenes" / "crossval").glob("*.toml"),
             *(ROOT / "cases" / "scenes" / "studies" / "scenes").glob("*.toml")]
    for path in sorted(paths):
        if "[simulation]" not in path.read_text():
            continue  # an sgim scene (a model of a sphere scene)
        scene = load_scene(path)
        _, sim = scene.build_spheres() if scene.spheres else scene.build()
        worst = max(worst, run_steps(scene.duration, sim.dt))
    assert 1e5 < worst < DEFAULT_MAX_STEPS / 100


def test_sphere_run_with_absurd_duration_is_refused(tmp_path, capsys):
    _write(tmp_path, _box("cubic", [0, 0, 0], [1, 1, 1], 0.25), "beam.toml")
    scene = _write(tmp_path, """name = "beam_run"
[simulation]
duration = 1e9
[contact]
kn = 1e7
[spheres]
model = "beam.toml"
fixed = ["z<0.3"]
""")
    out = tmp_path / "out"
    rc = dda_main(["run", str(scene), "-o", str(out)])
    _refused(capsys, rc, out, "simulation.duration", "spheres.bond_young")
    from adapters.cli import main as adapters_main

    rc = adapters_main(["export", str(scene), "--to", "liggghts", "-o", str(out)])
    _refused(capsys, rc, out, "simulation.duration", "max_steps")
    rc = adapters_main(["export", str(scene), "--to", "liggghts", "-o", str(out), "--duration", "0.01", "--dt",
                        "1e-20"])
    _refused(capsys, rc, out, "--dt = 1e-20", "--duration = 0.01 s")


def test_deck_of_a_model_and_block_deck_with_absurd_steps_are_refused(tmp_path, capsys):
    from adapters.cli import main as adapters_main

    out = tmp_path / "out"
    beam = _write(tmp_path, _box("cubic", [0, 0, 0], [1, 1, 1], 0.25), "beam.toml")
    rc = adapters_main(["export", str(beam), "--to", "yade", "-o", str(out), "--duration", "1e9"])
    _refused(capsys, rc, out, "--duration = 1000000000.0", "--max-steps")
    block_scene = _incline(tmp_path, "kn = 1e11 ", "kn = 1e30 ")
    rc = adapters_main(["export", str(block_scene), "--to", "yade", "-o", str(out)])
    _refused(capsys, rc, out, "contact.kn = 1e+30")


def test_wedge_refuses_trials_past_the_step_limit(capsys):
    args = ["wedge", "--joint", "45/005", "--joint", "55/135", "--face", "65/065", "--height", "10", "--friction",
            "25"]
    assert dda_main([*args, "--duration", "1e9"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--duration = 1e+09" in err[0] and "--max-steps" in err[0]
    assert dda_main([*args, "--kn", "1e30"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dda wedge: --kn = 1e+30: sets dt = ")
