"""Every physical key of a DDA scene's [simulation] and [spheres] tables reaches every deck writer that can express
it, or that writer names it in its ``extra["approximations"]``; notes true for the variant written; non-finite
model values refused at export; viscous damping computed from the model.

The keys come from the scene reader (dda.scene.SIMULATION_KEYS, SPHERE_KEYS): a new key fails the walk until it
has a test value here and every writer carries it or lists it. Keys that no deck carries by design are declared,
with their reason, in adapters.spec.NOT_RUN_KEYS. Writers: the in-house engine (the SphereSet and SphereSimulation
it builds), YADE (run.npz entries its script reads, yade.json) and LIGGGHTS bonds / sjkr / clumps (data, in, and
the run.npz fields its runner reads). pfc-text and vtu exports are model files, not runs: they carry no run keys.
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import re
from pathlib import Path

import numpy as np
import pytest

from adapters import inhouse, liggghts, yade
from adapters.spec import NOT_RUN_KEYS, from_scene
from dda.scene import SIMULATION_KEYS, SPHERE_KEYS

# a value different from the base scene's for every key (a key without one fails the walk)
VALUES = {
    "simulation.duration": 0.004, "simulation.dt": 2e-6, "simulation.safety": 0.3,
    "simulation.gravity": [0.0, -9.81, 0.0], "simulation.local_damping": 0.3, "simulation.record_every": 0.0005,
    "simulation.viscous_damping": 0.5, "simulation.frames": 5, "simulation.sleep": True,
    "simulation.sleep_velocity": 0.1, "simulation.sleep_accel": 0.1, "simulation.sleep_steps": 50,
    "simulation.max_steps": 1e7,
    "spheres.model": "model2.npz", "spheres.density": 3000.0, "spheres.fixed": ["x<0.04"],
    "spheres.bond_young": 5e8, "spheres.bond_kn": 1e6, "spheres.bond_ks": 2e5, "spheres.bond_shear_ratio": 0.2,
    "spheres.bond_tensile": 1e6, "spheres.bond_shear": 1e6, "spheres.bond_damping": 0.2,
    "spheres.bond_radius_factor": 0.7, "spheres.joint_friction": 10.0, "spheres.smooth_joints": False,
    "spheres.fixed_below": [[0.0, 0.0, 0.0, 0.0, 0.02]],
    "spheres.load": [{"region": "x>0.1", "force": [0.0, 0.0, -1.0]}],
    "spheres.liggghts_joints": "open",
}
BASE = {"simulation": {"duration": 0.002, "record_every": 0.001},
        "contact": {"kn": 1e6, "friction": 30.0},
        "spheres": {"model": "model.npz", "fixed": ["x<0.02"]}}
WRITERS = ("in-house", "yade", "liggghts-bonds", "liggghts-sjkr", "liggghts-clumps")


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def write_scene(path, tables):
    lines = ['name = "keys"']
    for name, tab in tables.items():
        lines.append(f"[{name}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in tab.items() if k != "load"]
    for load in tables["spheres"].get("load", []):
        lines.append("[[spheres.load]]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in load.items()]
    Path(path).write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    folder = tmp_path_factory.mktemp("keys")
    for name, length in (("model.npz", 0.12), ("model2.npz", 0.15)):
        d = {"name": "m", "domain": {"min": [0, 0, 0], "max": [length, 0.06, 0.06]},
             "packing": {"kind": "fcc", "radius": 0.015}, "bonds": {"rule": "colour"},
             "discontinuity": [{"name": "j", "centre": [0.0675, 0.03, 0.03], "dip": 90.0, "dip_direction": 90.0,
                                "radius": 1.0}]}
        build_model(scene_from_dict(d, "m.toml")).save(folder / name)
    return folder


def _digest(h, value):
    if isinstance(value, np.ndarray):
        h.update(str(value.dtype).encode() + str(value.shape).encode() + np.ascontiguousarray(value).tobytes())
    elif dataclasses.is_dataclass(value):
        h.update(repr(value).encode())
    elif isinstance(value, (bool, int, float, str, tuple)) or value is None:
        h.update(repr(value).encode())


def inputs(writer, run, folder):
    """A digest of everything `writer` runs from `run`."""
    h = hashlib.sha256()
    if writer == "in-house":
        ss, sim = run.in_house()
        for obj in (ss, sim):
            for k, v in sorted(vars(obj).items()):
                h.update(k.encode())
                _digest(h, v)
        _digest(h, (run.steps, run.record_steps))
        return h.hexdigest()
    folder.mkdir(parents=True, exist_ok=True)
    if writer == "yade":
        yade.write_deck(run, folder)
        script = (folder / "script.py").read_text()
        z = np.load(folder / "run.npz", allow_pickle=False)
        head = __import__("json").loads(str(z["header"]))
        for name in sorted(set(re.findall(r'\bz\["(\w+)"\]', script))):
            if name in z.files and name != "header":  # the header: the head[...] entries below
                _digest(h, np.asarray(z[name]))
        for name in sorted(set(re.findall(r'\bhead\["(\w+)"\]', script))):
            _digest(h, head[name])
        h.update((folder / "yade.json").read_bytes())
        return h.hexdigest()
    variant = writer.split("-")[1]
    liggghts.write_deck(run, folder, variant=variant)
    h.update((folder / "data").read_bytes() + (folder / "in").read_bytes())
    for name in liggghts.RUNNER_FIELDS[variant]:
        _digest(h, np.asarray(getattr(run, name)))
    return h.hexdigest()


def approximations(writer, run):
    if writer == "in-house":
        return inhouse.approximations(run)
    if writer == "yade":
        return yade.approximations(run)
    return liggghts.approximations(run, writer.split("-")[1])


def test_every_scene_key_reaches_every_deck_or_is_listed(models):
    keys = sorted([f"simulation.{k}" for k in SIMULATION_KEYS] + [f"spheres.{k}" for k in SPHERE_KEYS])
    assert set(NOT_RUN_KEYS) <= set(keys), "NOT_RUN_KEYS names a key the scene reader does not have"
    missing = [k for k in keys if k not in VALUES]
    assert not missing, f"scene keys without a test value (add one, and carry or list them in every deck): {missing}"
    base_run = from_scene(write_scene(models / "base.toml", BASE))
    base = {w: inputs(w, base_run, models / "base" / w) for w in WRITERS}
    base_notes = {w: approximations(w, base_run) for w in WRITERS}
    table, silent = {}, []
    for key in keys:
        if key in NOT_RUN_KEYS:
            assert NOT_RUN_KEYS[key]
            continue
        tab, name = key.split(".")
        tables = {t: dict(v) for t, v in BASE.items()}
        tables[tab][name] = VALUES[key]
        run = from_scene(write_scene(models / f"{key}.toml", tables))
        if key not in ("simulation.dt", "simulation.safety"):
            run.dt = base_run.dt  # the key's own effect, not the automatic time step it shifts (bond_damping does)
        for w in WRITERS:
            carried = inputs(w, run, models / key / w) != base[w]
            # listed for the changed value, or for the base value (an engine that cannot express the default)
            listed = any(key in a for a in approximations(w, run) + base_notes[w])
            table[key, w] = "carried" if carried else ("listed" if listed else "DROPPED")
            if not (carried or listed):
                silent.append(f"{key} in {w}")
    assert not silent, f"keys neither carried nor listed in extra.approximations: {silent}"
    # what an engine cannot express, it lists: the expected gaps (so a carried-by-accident key shows up too)
    assert table["simulation.viscous_damping", "in-house"] == "carried"
    assert table["simulation.viscous_damping", "yade"] == "listed"
    assert table["simulation.viscous_damping", "liggghts-bonds"] == "carried"
    assert table["spheres.bond_damping", "in-house"] == "carried"
    assert table["spheres.bond_damping", "yade"] == "listed"
    assert table["spheres.bond_damping", "liggghts-bonds"] == "listed"
    assert table["simulation.local_damping", "liggghts-bonds"] == "listed"
    assert table["spheres.bond_ks", "liggghts-bonds"] == "listed"
    assert all(table[k, w] == "carried" for k in ("spheres.load", "simulation.gravity", "spheres.density")
               for w in WRITERS)
    # LIGGGHTS-only: the decks drop the contact across the joint, the engines with smooth joints say they ignore it
    assert all(table["spheres.liggghts_joints", f"liggghts-{v}"] == "carried" for v in liggghts.VARIANTS)
    assert table["spheres.liggghts_joints", "in-house"] == table["spheres.liggghts_joints", "yade"] == "listed"


def test_liggghts_notes_are_those_of_the_variant(models):
    run = from_scene(write_scene(models / "notes.toml", BASE))
    assert run.fixed.any() and run.n_bonds
    whole = "components with a fixed sphere are fixed as a whole"
    assert not any(whole in a for a in liggghts.approximations(run, "bonds"))
    assert not any(whole in a for a in liggghts.approximations(run, "sjkr"))
    assert any(whole in a for a in liggghts.approximations(run, "clumps"))
    # and in the deck.json the export writes
    import json

    from adapters.deck import export

    for variant, expect in (("bonds", False), ("clumps", True)):
        export(models / "notes.toml", "liggghts", models / f"notes_{variant}", variant=variant)
        notes = json.loads((models / f"notes_{variant}" / "deck.json").read_text())["approximations"]
        assert any(whole in a for a in notes) == expect


@pytest.mark.parametrize("what", ["centers", "radii"])
def test_non_finite_model_values_are_refused_at_export(models, tmp_path, capsys, what):
    from adapters.cli import main

    z = dict(np.load(models / "model.npz", allow_pickle=False))
    bad = z[what].astype(float).copy()
    bad.flat[4] = np.nan
    z[what] = bad
    np.savez(tmp_path / "model.npz", **z)
    run = from_scene(write_scene(models / "ok.toml", BASE))
    run.save(tmp_path / "run_ok.npz")
    r = dict(np.load(tmp_path / "run_ok.npz", allow_pickle=False))
    r[what] = r[what].astype(float)
    r[what].flat[4] = np.inf
    np.savez(tmp_path / "run.npz", **r)
    for src, value in ((tmp_path / "model.npz", "nan"), (tmp_path / "run.npz", "inf")):
        for to in ("yade", "liggghts", "pfc-text"):
            out = tmp_path / f"out_{to}"
            capsys.readouterr()
            assert main(["export", str(src), "--to", to, "-o", str(out)]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1, err
            assert str(src) in err[0] and what in err[0] and value in err[0], err[0]
            assert not out.exists()


def test_critical_viscous_damping_of_a_sphere_on_one_bond(tmp_path):
    # a sphere hung from a fixed one by one bond of stiffness k: first mode omega = sqrt(k / m) exactly, so
    # "critical" is c = 2 sqrt(k m) (the free sphere's mass), and 0.5 half of it
    from adapters.spec import from_model, viscous_coefficient
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    r = 0.05
    model = build_model(scene_from_dict({"name": "pair", "domain": {"min": [0, 0, 0], "max": [0.1, 0.1, 0.2]},
                                         "packing": {"kind": "cubic", "radius": r}, "bonds": {"rule": "colour"}},
                                        "pair.toml"))
    assert len(model.radii) == 2 and np.asarray(model.bonded).sum() == 1
    run = from_model(model, fixed=model.centers[:, 2] > 0.1, viscous_damping="critical")
    m = run.density * 4.0 / 3.0 * math.pi * r ** 3
    k = float(run.bond_kn[0])
    assert run.viscous_damping == pytest.approx(2.0 * math.sqrt(k * m), rel=1e-12)
    assert viscous_coefficient(run, 0.5) == pytest.approx(math.sqrt(k * m), rel=1e-12)
    for bad in ("nan", -1.0, float("nan"), "sometimes"):
        with pytest.raises(ValueError):
            viscous_coefficient(run, bad)
    # nothing tied to a fixed sphere: no first mode, refused
    free = from_model(model)
    with pytest.raises(ValueError, match="first mode"):
        viscous_coefficient(free, "critical")


def test_in_house_viscous_damping_critical_on_one_bond():
    # the sphere hung from a fixed one by one bond, released at the bond's rest length under gravity, with
    # c = 2 sqrt(k m): the critically damped response u(t) = u_s (1 - (1 + w t) e^(-w t)), u_s = m g / k
    from adapters.spec import from_model
    from sgim.builder import build_model
    from sgim.scene import scene_from_dict

    model = build_model(scene_from_dict({"name": "pair", "domain": {"min": [0, 0, 0], "max": [0.1, 0.1, 0.2]},
                                         "packing": {"kind": "cubic", "radius": 0.05}, "bonds": {"rule": "colour"}},
                                        "pair.toml"))
    run = from_model(model, fixed=model.centers[:, 2] > 0.1, viscous_damping="critical", safety=0.05)
    ss, sim = run.in_house()
    free = int(np.flatnonzero(~run.fixed)[0])
    m, k = float(ss.mass[free]), float(run.bond_kn[0])
    w = math.sqrt(k / m)
    u_s = m * 9.81 / k
    for t in (1.0 / w, 3.0 / w, 8.0 / w):
        sim.run(t - sim.time)
        u = run.centers[free, 2] - sim.x[free, 2]
        assert u == pytest.approx(u_s * (1.0 - (1.0 + w * t) * math.exp(-w * t)), rel=2e-2)
    # undamped, the same sphere overshoots to twice the static stretch
    ss2, sim2 = from_model(model, fixed=model.centers[:, 2] > 0.1, safety=0.05).in_house()
    sim2.run(math.pi / w)
    assert run.centers[free, 2] - sim2.x[free, 2] == pytest.approx(2.0 * u_s, rel=2e-2)


def test_critical_damping_without_a_first_mode_is_one_line(models, tmp_path, capsys):
    # nothing fixed: no sphere is tied to a fixed one, so "critical" has no first mode to refer to
    from adapters.cli import main
    from dda.scene import load_scene
    from sgim.scene import SceneError

    tables = {t: dict(v) for t, v in BASE.items()}
    tables["spheres"]["fixed"] = []
    tables["simulation"]["viscous_damping"] = "critical"
    path = write_scene(models / "unheld.toml", tables)
    assert main(["export", str(path), "--to", "liggghts", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "simulation.viscous_damping = 'critical'" in err[0] and "first mode" in err[0]
    assert not (tmp_path / "out").exists()
    with pytest.raises(SceneError, match="first mode"):
        load_scene(path).build_spheres()
    tables["simulation"]["viscous_damping"] = "sometimes"
    with pytest.raises(SceneError, match="viscous_damping"):
        load_scene(write_scene(models / "bad.toml", tables))


def test_liggghts_joints_open_is_refused_where_the_type_exclusion_is_not_the_joint_pairs(tmp_path, capsys):
    # the wedge's model uses the geometric bond rule: some joint pairs join spheres of one colour and some touching
    # green-blue pairs are no joint pairs, so dropping green-blue contacts is not "the joint pairs open": refused,
    # one line naming the file, the key and the value (and for the CLI option); bad values likewise; nothing written
    import shutil

    from adapters.cli import main
    from cases.lib.crossval import CV

    shutil.copy(CV / "wedge_model.toml", tmp_path)
    text = (CV / "wedge.toml").read_text()
    run = from_scene(CV / "wedge.toml")
    c = run.colour
    gb = ((c[run.joint_i] == 2) & (c[run.joint_j] == 3)) | ((c[run.joint_i] == 3) & (c[run.joint_j] == 2))
    assert not gb.all()  # the premise: joint pairs of one colour
    beam = (CV / "beam_joint.toml").read_text()
    key_line = re.compile(r'^liggghts_joints = "open"$', re.M)
    shutil.copy(CV / "beam_joint_model.toml", tmp_path)
    cases = [(text.replace("[spheres]", '[spheres]\nliggghts_joints = "open"'), [], "spheres.liggghts_joints",
              "open"),
             (text, ["--liggghts-joints", "open"], "--liggghts-joints", "open"),
             (key_line.sub('liggghts_joints = "shut"', beam), [], "spheres.liggghts_joints", "shut"),
             (key_line.sub('liggghts_joints = "open"\nsmooth_joints = false', beam), [], "spheres.liggghts_joints",
              "smooth_joints"),
             (beam, ["--liggghts-joints", "ajar"], "--liggghts-joints", "ajar")]
    assert key_line.search(beam)
    for k, (scene, opts, key, value) in enumerate(cases):
        src = tmp_path / f"s{k}.toml"
        src.write_text(scene)
        out = tmp_path / f"out{k}"
        capsys.readouterr()
        assert main(["export", str(src), "--to", "liggghts", "-o", str(out), *opts]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert str(src) in err[0] and key in err[0] and value in err[0], err[0]
        assert not out.exists()
    assert main(["export", str(tmp_path / "s4.toml"), "--to", "yade", "-o", str(tmp_path / "y"),
                 "--liggghts-joints", "open"]) == 2
    assert not (tmp_path / "y").exists()


def test_liggghts_joints_values_agree_with_the_scene_reader():
    from adapters.spec import LIGGGHTS_JOINTS
    from dda.scene import LIGGGHTS_JOINTS as SCENE

    assert LIGGGHTS_JOINTS == SCENE
