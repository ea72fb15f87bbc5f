"""Loads on sphere regions through every engine: the DDA scene keys ([[spheres.load]]: a constant force on each
sphere of a region, or a prescribed velocity), their one-line errors, the SphereRun arrays, and real in-house,
YADE and LIGGGHTS runs against analytical motion (a sphere under a constant force plus gravity, a sphere held
up by a force equal to its weight, a prescribed sphere dragging a bonded neighbour: x(t) = v t - (v / w) sin(w t))."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from adapters.inhouse import run_inhouse
from adapters.spec import SpecError, SphereRun, from_model, from_scene
from engine_runs import G, hand_run, require_engine
from sgim.scene import SceneError

ENGINES = ("dda", "yade", "liggghts")
R = 0.05
RHO = 2600.0
MASS = RHO * 4.0 / 3.0 * math.pi * R ** 3


def run_engine(engine, run, folder):
    """RunResult of `run` in `engine` (decks written into `folder`)."""
    if engine == "dda":
        return run_inhouse(run)
    require_engine(engine)
    from adapters import liggghts, yade

    deck = folder / f"{engine}_deck"
    deck.mkdir(parents=True)
    run.save(deck / "run.npz")
    mod = yade if engine == "yade" else liggghts
    info = mod.write_deck(run, deck)
    (deck / "deck.json").write_text(json.dumps({"engine": engine, **info}))
    res = mod.run_deck(deck, folder / f"{engine}_out")
    assert res.complete, res.message
    return res


# -- a constant force on each sphere ------------------------------------------------------------------------
F0 = np.array([3.0, -2.0, 5.0])
DT_F, T_F = 1e-4, 0.2


@pytest.fixture(scope="module")
def force_runs(tmp_path_factory):
    """Four spheres 1 m apart under gravity: 0 with the force F0, 1 held up by a force equal to its weight,
    2 fixed under a large force, 3 free without a force (free fall); every engine."""
    centers = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]
    force = [F0, [0, 0, MASS * G], [50.0, 50.0, 50.0], [0, 0, 0]]
    run = hand_run(centers, R, fixed=(2,), dt=DT_F, duration=T_F, record_every=0.02, force=force)
    folder = tmp_path_factory.mktemp("force")
    return run, {e: run_engine(e, run, folder) for e in ENGINES}


@pytest.mark.parametrize("engine", ENGINES)
def test_constant_force_moves_a_free_sphere_f_t2_over_2m(force_runs, engine):
    run, results = force_runs
    res = results[engine]
    t = res.time
    assert len(t) == 11 and np.allclose(t, np.linspace(0, T_F, 11))
    acc = F0 / MASS + np.array([0, 0, -G])  # x and y: F t^2 / (2 m) alone; z: with gravity
    d = res.pos[:, 0] - run.centers[0]
    exact = 0.5 * acc * t[:, None] ** 2
    if engine == "yade":
        # YADE's leapfrog starts with a full velocity step: x_n = a dt^2 n (n + 1) / 2, within 1 / n of a t^2 / 2
        n = np.rint(t / DT_F)
        np.testing.assert_allclose(d, 0.5 * acc * DT_F ** 2 * (n * (n + 1))[:, None], rtol=1e-9, atol=1e-13)
        np.testing.assert_allclose(d[-1], exact[-1], rtol=1.5 * DT_F / T_F)
    else:  # central difference started with a half step, velocity Verlet: exact for a constant force
        np.testing.assert_allclose(d, exact, rtol=1e-9, atol=1e-13)
    assert np.allclose(res.final_vel[0], acc * T_F, rtol=1e-3)
    # the force equal to the weight holds sphere 1 where it is; the fixed sphere never moves whatever its force
    assert np.abs(res.pos[:, 1] - run.centers[1]).max() < 1e-12
    assert np.array_equal(res.final_pos[2], run.centers[2])
    # sphere 3 without a force falls freely: the force of the others is not applied to it
    assert res.final_pos[3, 2] == pytest.approx(-0.5 * G * T_F ** 2, rel=1.5 * DT_F / T_F)
    assert np.allclose(res.final_pos[3, :2], run.centers[3, :2], atol=1e-14)


# -- a prescribed velocity ----------------------------------------------------------------------------------
V0 = np.array([0.2, 0.0, 0.0])
V2 = np.array([0.1, -0.05, 0.3])
KB = 1e6
DT_P, T_P = 1e-5, 0.02


@pytest.fixture(scope="module")
def drag_runs(tmp_path_factory):
    """No gravity. Sphere 0 moves at V0 along +x and drags sphere 1, bonded behind it (the bond stretches and
    shortens by up to V0 / w); sphere 2 moves alone at the oblique V2; every engine. LIGGGHTS' contact radii
    leave the bonded pair a gap of 2e-2 r, well beyond that: the bond alone acts, as in the other engines."""
    centers = [[0, 0, 0], [-2 * R, 0, 0], [0, 1, 0]]
    run = hand_run(centers, R, bonds=[(0, 1)], kn=KB, dt=DT_P, duration=T_P, record_every=0.002, gravity=(0, 0, 0),
                   prescribed=(0, 2), velocity=[V0, [0, 0, 0], V2], liggghts_bond_gap=1e-2)
    assert V0[0] / math.sqrt(KB / MASS) < 0.5 * 2e-2 * R  # half the gap
    folder = tmp_path_factory.mktemp("drag")
    return run, {e: run_engine(e, run, folder) for e in ENGINES}


@pytest.mark.parametrize("engine", ENGINES)
def test_prescribed_sphere_moves_at_its_velocity_and_drags_its_bonded_neighbour(drag_runs, engine):
    run, results = drag_runs
    res = results[engine]
    t = res.time
    assert len(t) == 11
    # prescribed: x0 + v t exactly, velocity v, whatever the bond pulls
    for k, v in ((0, V0), (2, V2)):
        np.testing.assert_allclose(res.pos[:, k], run.centers[k] + v * t[:, None], rtol=0, atol=1e-12)
        np.testing.assert_allclose(res.final_vel[k], v, rtol=1e-12)
    # the bonded sphere (the prescribed one has no finite mass): extension e = (v / w) sin(w t), w = sqrt(kn / m)
    w = math.sqrt(KB / MASS)
    amp = V0[0] / w
    ext = (res.pos[:, 0, 0] - res.pos[:, 1, 0]) - 2 * R
    np.testing.assert_allclose(ext, amp * np.sin(w * t), rtol=0, atol=2e-4 * amp)
    assert np.abs(res.pos[:, 1, 1:]).max() < 1e-12
    # rigid translation to within the bond's stretch: the sphere followed at v
    assert abs(res.final_pos[1, 0] - (-2 * R + V0[0] * T_P)) <= 1.0001 * amp
    # kinetic energy: the free sphere only (prescribed spheres are not free), v1 = v (1 - cos w t)
    v1 = V0[0] * (1 - math.cos(w * T_P))
    assert res.series["kinetic"][-1] == pytest.approx(0.5 * MASS * v1 ** 2, rel=2e-2)
    assert res.series["kinetic"][0] == 0.0
    assert res.bond_intact.all()


def test_engines_agree_on_the_dragged_sphere(drag_runs):
    """The same discrete motion in the three engines (the bond starts unloaded: no initial acceleration, so the
    half-step and full-step starts coincide): the bond extension at every record within 1e-6 of its
    amplitude, the final position within 1e-6 of the travel."""
    run, results = drag_runs
    w = math.sqrt(KB / MASS)
    amp = V0[0] / w
    ref = results["dda"]
    for engine in ("yade", "liggghts"):
        res = results[engine]
        e_ref = ref.pos[:, 0, 0] - ref.pos[:, 1, 0]
        e = res.pos[:, 0, 0] - res.pos[:, 1, 0]
        assert np.abs(e - e_ref).max() <= 1e-6 * amp, engine
        travel = V0[0] * T_P
        assert abs(res.final_pos[1, 0] - ref.final_pos[1, 0]) <= 1e-6 * travel, engine


# -- SphereRun arrays ---------------------------------------------------------------------------------------
def test_run_file_round_trip_and_older_files_without_loads(tmp_path):
    run = hand_run([[0, 0, 0], [1, 0, 0], [2, 0, 0]], R, fixed=(1,), force=[[1, 2, 3], [0, 0, 0], [0, 0, 0]],
                   prescribed=(2,), velocity=[[0, 0, 0], [0, 0, 0], [4, 5, 6]])
    run.save(tmp_path / "run.npz")
    back = SphereRun.load(tmp_path / "run.npz")
    assert np.array_equal(back.force, run.force) and back.force.dtype == float
    assert back.prescribed.tolist() == [False, False, True]
    assert np.array_equal(back.velocity, [[0, 0, 0], [0, 0, 0], [4, 5, 6]])
    # a run.npz written before the loads existed: the same file without the three arrays loads with none
    with np.load(tmp_path / "run.npz") as z:
        old = {k: z[k] for k in z.files if k not in ("force", "prescribed", "velocity")}
    np.savez(tmp_path / "old.npz", **old)
    back = SphereRun.load(tmp_path / "old.npz")
    assert back.force.shape == (3, 3) and not back.force.any()
    assert back.prescribed.shape == (3,) and not back.prescribed.any() and not back.velocity.any()
    assert not back.loaded and run.loaded


def test_in_house_sphere_set_gets_the_loads():
    run = hand_run([[0, 0, 0], [1, 0, 0], [2, 0, 0]], R, force=[[1, 2, 3], [0, 0, 0], [0, 0, 0]], prescribed=(2,),
                   velocity=[4, 5, 6])
    ss, sim = run.in_house()
    assert np.array_equal(ss.body_force, run.force)
    assert ss.prescribed.tolist() == [False, False, True]
    assert np.array_equal(ss.velocity, [[0, 0, 0], [0, 0, 0], [4, 5, 6]])  # velocity only where prescribed


def sgim_model():
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    d = {"name": "loads", "domain": {"min": [0, 0, 0], "max": [0.3, 0.3, 0.6]}, "packing": {"kind": "fcc",
                                                                                            "radius": R}}
    return build_model(scene_from_dict(d, "loads.toml"))


BASE = 'name = "s"\n[simulation]\nduration = 0.002\ndt = 1e-5\ngravity = [0, 0, 0]\n[contact]\nkn = 1e6\n' \
       '[spheres]\nmodel = "model.npz"\nbond_kn = 1e6\n'


LOADS = ('[[spheres.load]]\nregion = "z>0.5"\nvelocity = [0.0, 0.0, 0.5]\n'
         '[[spheres.load]]\nregion = ["x>0.2", "z<0.5", "z>0.1"]\nforce = [10.0, 0.0, 0.0]\n'
         '[[spheres.load]]\nbelow = [20, 90, 0.0, 0.0, 0.3]\nforce = [0.0, 20.0, 0.0]\n')


def scene_regions(c):
    """The regions of LOADS written out by hand: (top, side, below); the plane of dip 20 towards 090 has the
    upward normal (sin 20, 0, cos 20)."""
    n = np.array([math.sin(math.radians(20)), 0.0, math.cos(math.radians(20))])
    top = c[:, 2] > 0.5
    side = (c[:, 0] > 0.2) & (c[:, 2] < 0.5) & (c[:, 2] > 0.1)
    below = (c - [0, 0, 0.3]) @ n < 0
    return top, side, below


def test_scene_load_keys_fill_the_run_and_the_sphere_set(tmp_path):
    from dda.scene import load_scene

    model = sgim_model()
    model.save(tmp_path / "model.npz")
    c = model.centers
    top, side, below = scene_regions(c)
    assert top.any() and (side & below).any() and (side & ~below).any() and (below & ~side).any()
    # the fixed spheres (z < 0.06) lie below the plane: a loaded region must not hold them
    assert (below & (c[:, 2] < 0.06)).any()
    (tmp_path / "f.toml").write_text(BASE + 'fixed = ["z<0.06"]\n' + LOADS)
    with pytest.raises(SceneError, match=r"spheres\.load\[2\]\.below.*both fixed and loaded"):
        load_scene(tmp_path / "f.toml")
    (tmp_path / "s.toml").write_text(BASE + LOADS)
    run = from_scene(tmp_path / "s.toml")
    want_f = np.zeros((len(c), 3))
    want_f[side, 0] += 10.0
    want_f[below, 1] += 20.0  # overlapping force loads add up
    assert np.array_equal(run.force, want_f)
    assert np.array_equal(run.prescribed, top)
    assert np.array_equal(run.velocity, np.where(top[:, None], [0.0, 0.0, 0.5], 0.0))
    assert not run.fixed.any()
    ss, _ = load_scene(tmp_path / "s.toml").build_spheres()
    assert np.array_equal(ss.body_force, want_f) and np.array_equal(ss.prescribed, top)
    assert np.array_equal(ss.velocity[top], np.tile([0.0, 0.0, 0.5], (top.sum(), 1)))


def liggghts_groups(text):
    """Independent reader of a LIGGGHTS input: {group: set of 0-based sphere indices} from ``group NAME id``
    lines (ranges a:b), and the addforce / move linear vectors per group."""
    groups, force, move = {}, {}, {}
    for line in text.splitlines():
        w = line.split()
        if len(w) > 3 and w[0] == "group" and w[2] == "id":
            ids = groups.setdefault(w[1], set())
            for tok in w[3:]:
                lo, _, hi = tok.partition(":")
                ids.update(range(int(lo) - 1, int(hi or lo)))
        elif len(w) == 7 and w[0] == "fix" and w[3] == "addforce":
            force[w[2]] = np.array(w[4:7], float)
        elif len(w) == 8 and w[0] == "fix" and w[3:5] == ["move", "linear"]:
            move[w[2]] = np.array(w[5:8], float)
    return groups, force, move


def test_scene_loads_reach_every_engine(tmp_path):
    """The scene's platen and forces through the decks: prescribed spheres at x0 + v t exactly in every engine;
    the LIGGGHTS input's groups hold exactly the loaded spheres; YADE follows the in-house run (the same bond
    law) within 1 % of the largest displacement, LIGGGHTS (central bonds: no shear spring) within 30 %."""
    model = sgim_model()
    model.save(tmp_path / "model.npz")
    (tmp_path / "s.toml").write_text(BASE + LOADS)
    run = from_scene(tmp_path / "s.toml")
    res = {e: run_engine(e, run, tmp_path) for e in ENGINES}
    top = run.prescribed
    for e, r in res.items():
        np.testing.assert_allclose(r.final_pos[top], run.centers[top] + [0, 0, 0.5 * run.duration], rtol=0,
                                   atol=1e-12, err_msg=e)
    groups, force, move = liggghts_groups((tmp_path / "liggghts_deck" / "in").read_text())
    got_f = np.zeros((run.n, 3))
    for g, f in force.items():
        got_f[sorted(groups[g])] += f
    assert np.array_equal(got_f, run.force)
    assert len(move) == 1 and sorted(groups[next(iter(move))]) == np.flatnonzero(top).tolist()
    assert np.array_equal(next(iter(move.values())), [0.0, 0.0, 0.5])
    d = {e: r.final_pos - run.centers for e, r in res.items()}
    scale = np.abs(d["dda"][~top]).max()
    assert scale > 1e-4
    assert np.abs(d["yade"] - d["dda"]).max() <= 1e-2 * scale
    assert np.abs(d["liggghts"] - d["dda"]).max() <= 0.3 * scale


def test_liggghts_clump_with_a_prescribed_sphere_moves_as_a_whole(tmp_path):
    """Clumps variant: a bonded pair with one prescribed sphere is one rigid body moving at its velocity; a free
    sphere beside it falls."""
    require_engine("liggghts")
    from adapters import liggghts

    run = hand_run([[0, 0, 0], [2 * R, 0, 0], [1, 0, 0]], R, bonds=[(0, 1)], dt=1e-4, duration=0.05,
                   record_every=0.01, prescribed=(0,), velocity=[0.1, 0.2, 0.3])
    assert liggghts.clump_prescribed(run)[0].tolist() == [True, True, False]
    deck = tmp_path / "d"
    deck.mkdir()
    run.save(deck / "run.npz")
    info = liggghts.write_deck(run, deck, variant="clumps")
    (deck / "deck.json").write_text(json.dumps({"engine": "liggghts", **info}))
    res = liggghts.run_deck(deck, tmp_path / "out")
    np.testing.assert_allclose(res.final_pos[:2], run.centers[:2] + np.array([0.1, 0.2, 0.3]) * 0.05, rtol=0,
                               atol=1e-12)
    assert res.final_pos[2, 2] == pytest.approx(-0.5 * G * 0.05 ** 2, rel=1e-9)
    assert any("prescribed" in a for a in res.extra["approximations"])


def test_liggghts_deck_refuses_more_load_groups_than_it_holds(tmp_path):
    from adapters import liggghts

    n = liggghts.MAX_LOAD_GROUPS + 1
    run = hand_run([[3 * R * k, 0, 0] for k in range(n)], R, force=[[k + 1.0, 0, 0] for k in range(n)])
    with pytest.raises(SpecError, match=f"at most {liggghts.MAX_LOAD_GROUPS}"):
        liggghts.write_deck(run, tmp_path)
    run.force[-1] = run.force[0]  # one group fewer: accepted
    liggghts.write_deck(run, tmp_path)


@pytest.mark.parametrize("load, key, message", [
    ('region = "z>0.5"\nforce = [1, 0, 0]\nvelocity = [0, 0, 1]\n', "spheres.load[0]", "exactly one of: force"),
    ('region = "z>0.5"\n', "spheres.load[0]", "exactly one of: force"),
    ('force = [1, 0, 0]\n', "spheres.load[0]", "exactly one of: region"),
    ('region = "z>0.5"\nbelow = [0, 0, 0, 0, 0.2]\nforce = [1, 0, 0]\n', "spheres.load[0]", "exactly one of: region"),
    ('region = "z>0.5"\nforce = [1, 0, 0]\nspeed = 3\n', "spheres.load[0].speed", "unknown key"),
    ('region = "z>9"\nforce = [1, 0, 0]\n', "spheres.load[0].region", "no sphere in region"),
    ('region = ["z>0.5", "z<0.4"]\nforce = [1, 0, 0]\n', "spheres.load[0].region", "no sphere in region"),
    ('region = "q>0.5"\nforce = [1, 0, 0]\n', "spheres.load[0].region", "must look like"),
    ('region = []\nforce = [1, 0, 0]\n', "spheres.load[0].region", "must be a string"),
    ('region = "z>0.5"\nforce = [1, 0]\n', "spheres.load[0].force", "list of 3 numbers"),
    ('region = "z>0.5"\nvelocity = [1, 0, "a"]\n', "spheres.load[0].velocity[2]", "must be a number"),
    ('below = [95, 0, 0, 0, 0.2]\nforce = [1, 0, 0]\n', "spheres.load[0].below", "dip must be"),
    ('region = "z<0.1"\nforce = [1, 0, 0]\n', "spheres.load[0].region", "both fixed and loaded"),
    ('region = "z>0.5"\nvelocity = [0, 0, 1]\n[[spheres.load]]\nregion = "z>0.4"\nforce = [1, 0, 0]\n',
     "spheres.load[1].region", "also loaded by spheres.load[0]"),
    ('region = "z>0.4"\nforce = [1, 0, 0]\n[[spheres.load]]\nregion = "z>0.5"\nvelocity = [0, 0, 1]\n',
     "spheres.load[1].region", "also loaded by spheres.load[0]"),
])
def test_bad_load_tables_give_one_line(tmp_path, load, key, message):
    from dda.scene import load_scene

    sgim_model().save(tmp_path / "model.npz")
    (tmp_path / "s.toml").write_text(BASE + 'fixed = ["z<0.06"]\n[[spheres.load]]\n' + load)
    with pytest.raises(SceneError) as exc:
        load_scene(tmp_path / "s.toml")
    text = str(exc.value)
    assert "\n" not in text and key in text and message in text, text


def test_load_must_be_an_array_of_tables(tmp_path):
    from dda.scene import load_scene

    sgim_model().save(tmp_path / "model.npz")
    (tmp_path / "s.toml").write_text(BASE + 'load = "z>0.5"\n')
    with pytest.raises(SceneError, match=r"spheres\.load.*array of tables"):
        load_scene(tmp_path / "s.toml")


def test_from_model_refuses_bad_loads():
    model = sgim_model()
    n = len(model.radii)
    fixed = np.zeros(n, bool)
    fixed[0] = True
    with pytest.raises(SpecError, match="both fixed and prescribed"):
        from_model(model, fixed=fixed, prescribed=fixed, dt=1e-5)
    with pytest.raises(SpecError, match="must be"):
        from_model(model, force=np.zeros((n + 1, 3)), dt=1e-5)
    with pytest.raises(SpecError, match="finite"):
        from_model(model, velocity=[np.nan, 0, 0], dt=1e-5)
    run = from_model(model, force=[0, 0, 1.0], dt=1e-5)  # one vector: every sphere
    assert run.force.shape == (n, 3) and np.all(run.force[:, 2] == 1.0)
