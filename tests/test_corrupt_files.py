"""Every file a tool reads back is validated: a corrupt, truncated, empty, foreign or inconsistent file is one line
``PROG: error: FILE: what is wrong`` with exit status 2, no traceback and nothing written.

The valid files are made once by the real tools (sgim build / dfn, adapters export / run --in-house, cases study
run) from small scenes; each test copies one, corrupts it (cut in half, emptied, random bytes with a fixed seed,
a PNG or another kind of npz in its place, an array or key removed, a wrong shape or dtype, NaN, an index out of
range) and runs the command that reads it through its ``main(argv)`` in this process. No engine is started: the
files are checked before YADE or LIGGGHTS would be.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from adapters.cli import main as adapters_main
from adapters.result import RunResult
from cases.lib.report import main as report_main
from cases.lib.study import main as study_main
from dda.cli import main as dda_main
from sgim.cli import CliError, run_command
from sgim.cli import main as sgim_main

ROOT = Path(__file__).resolve().parents[1]
HANG = ROOT / "cases" / "scenes" / "crossval" / "hang_joint.toml"
HANG_MODEL = ROOT / "cases" / "scenes" / "crossval" / "hang_joint_model.toml"
INCLINE = ROOT / "cases" / "scenes" / "dda_incline.toml"

RANDOM = np.random.default_rng(20240611).bytes(3000)
PNG = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + RANDOM[:300]

DFN_SCENE = """\
name = "dfn_small"
[domain]
min = [0.0, 0.0, 0.0]
max = [8.0, 7.0, 6.0]
[packing]
radius = 0.5
[dfn]
seed = 5
[[joint_set]]
name = "J1"
dip = 70.0
dip_direction = 120.0
kappa = 15.0
p32 = 0.3
radius = 1.5
"""

STUDY_BASE = """\
name = "base"
[contact]
kn = 1e10
friction = 18.0
[[generate]]
kind = "wedge"
joint_a = [45.0, 5.0]
height = 10.0
"""

STUDY = """\
base = "base.toml"
engine = "noop"
results = ["value"]
[parameters]
"contact.friction" = { grid = [1.0, 2.0, 3.0, 4.0] }
"""


# ------------------------------------------------------------------------------------------------ valid files
@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """The valid files, written by the tools themselves."""
    d = tmp_path_factory.mktemp("made")
    assert sgim_main(["build", str(HANG_MODEL), "-o", str(d / "model"), "--formats", "npz", "--quiet"]) == 0
    for engine in ("yade", "liggghts"):
        assert adapters_main(["export", str(HANG), "--to", engine, "-o", str(d / engine), "--duration", "0.0005",
                              "--quiet"]) == 0
    assert adapters_main(["export", str(INCLINE), "--to", "yade", "-o", str(d / "poly"), "--duration", "0.01",
                          "--quiet"]) == 0
    assert adapters_main(["run", str(d / "yade"), "--in-house", "-o", str(d / "result"), "--quiet"]) == 0
    (d / "dfn.toml").write_text(DFN_SCENE)
    assert sgim_main(["dfn", str(d / "dfn.toml"), "-o", str(d / "net"), "--quiet"]) == 0
    (d / "study").mkdir()
    (d / "study" / "base.toml").write_text(STUDY_BASE)
    (d / "study" / "study.toml").write_text(STUDY)
    assert study_main(["run", str(d / "study" / "study.toml"), "-o", str(d / "study" / "out"), "--quiet"]) == 0
    return d


# ------------------------------------------------------------------------------------------------ helpers
def listing(folder):
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*"))


def one_line(capsys, rc, *words):
    """The command ended in exactly one line on stderr with exit status 2, no traceback; returns the line."""
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, (rc, err)
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def npy_bytes():
    buf = io.BytesIO()
    np.save(buf, np.arange(5.0))
    return buf.getvalue()


def zip_of_text():
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("readme.txt", "not arrays")
    return buf.getvalue()


BYTES = {  # name -> (bytes of the valid file) -> bytes written instead, words expected in the line
    "half": (lambda b: b[:len(b) // 2], "unreadable archive"),
    "empty": (lambda b: b"", "empty file"),
    "random": (lambda b: RANDOM, "not an npz (zip) archive"),
    "png": (lambda b: PNG, "PNG"),
    "npy": (lambda b: npy_bytes(), "a single .npy array"),
    "zip of text": (lambda b: zip_of_text(), "not a numpy array"),
}


def write_bytes(src, dst, how):
    fn, words = BYTES[how]
    Path(dst).write_bytes(fn(Path(src).read_bytes()))
    return words


def edit_npz(src, dst, fn):
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k].copy() for k in z.files}
    fn(arrays)
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)


def setter(key, fn):
    def edit(a):
        a[key] = fn(a[key])
    return edit


def at(index, value):
    def fn(x):
        x = x.copy()
        x[index] = value
        return x
    return fn


def drop(key):
    return lambda a: a.pop(key)


def header(change):
    """Edit the JSON header of a run.npz: `change(dict)` mutates it, or returns a replacement text."""
    def edit(a):
        head = json.loads(str(a["header"]))
        out = change(head)
        a["header"] = np.array(out if isinstance(out, str) else json.dumps(head))
    return edit


# ------------------------------------------------------------------------------------------------ model.npz
MODEL_EDITS = [
    ("missing array", drop("bonds"), "missing array bonds"),
    ("radii one short", setter("radii", lambda x: x[:-1]), "radii: shape"),
    ("centre NaN", setter("centers", at((3, 1), np.nan)), "centers[3, 1] = nan"),
    ("radius inf", setter("radii", at(4, np.inf)), "radii[4] = inf"),
    ("radius zero", setter("radii", at(0, 0.0)), "must be > 0"),
    ("bond past the spheres", setter("bonds", at((5, 1), 10 ** 6)), "bonds[5, 1] = 1000000: out of range"),
    ("bond to itself", lambda a: a["bonds"].__setitem__((2, 1), a["bonds"][2, 0]), "paired with itself"),
    ("membership sphere negative", setter("member_sphere", at(0, -1)), "member_sphere[0] = -1"),
    ("colour code", setter("colour", at(2, 9)), "colour[2] = 9"),
    ("cut by an unknown disc", setter("cut_by", at(0, 99)), "cut_by[0] = 99"),
    ("bonded length", setter("bonded", lambda x: x[:-1]), "bonded: shape"),
    ("centres as text", setter("centers", lambda x: x.astype(str)), "centers: dtype"),
    ("bonds as floats", setter("bonds", lambda x: x.astype(float)), "expected integers"),
    ("member kind", setter("member_kind", at(0, 0)), "member_kind[0] = 0"),
    ("disc normal not unit", setter("disc_normal", lambda x: 2.0 * x), "unit vector"),
    ("meta a JSON array", setter("meta", lambda x: np.array("[1, 2]")), "meta: expected a JSON object"),
    ("meta not JSON", setter("meta", lambda x: np.array("{scene")), "meta: not valid JSON"),
    ("object array", setter("centers", lambda x: np.array([None] * len(x), dtype=object)), "cannot be read"),
]


def bad_model(made, tmp_path, how):
    """A corrupted copy of the valid model.npz in tmp_path (returns its path and the words to expect)."""
    src, dst = made / "model" / "model.npz", tmp_path / "model.npz"
    if how in BYTES:
        return dst, write_bytes(src, dst, how)
    if how == "run.npz":  # an npz of another kind
        shutil.copyfile(made / "yade" / "run.npz", dst)
        return dst, "missing arrays"
    _, fn, words = next(e for e in MODEL_EDITS if e[0] == how)
    edit_npz(src, dst, fn)
    return dst, words


MODEL_CASES = [*BYTES, "run.npz", *(e[0] for e in MODEL_EDITS)]


def model_command(kind, path, tmp_path):
    out = tmp_path / "out"
    if kind == "sgim info":
        return sgim_main(["info", str(path)])
    if kind == "sgim show":
        return sgim_main(["show", str(path), "-o", str(tmp_path / "pic.png"), "--quiet"])
    if kind == "adapters export":
        return adapters_main(["export", str(path), "--to", "vtu", "-o", str(out), "--quiet"])
    scene = tmp_path / "scene.toml"
    scene.write_text(HANG.read_text().replace('model = "hang_joint_model.toml"', f'model = "{path.name}"'))
    return dda_main(["run", str(scene), "-o", str(out), "--quiet"])


@pytest.mark.parametrize("kind,how", [(k, h) for k in ("sgim info", "sgim show", "adapters export", "dda run")
                                      for h in MODEL_CASES if not (k == "adapters export" and h == "run.npz")])
def test_model_npz(made, tmp_path, capsys, kind, how):  # (a run.npz is a valid source of `adapters export`)
    path, words = bad_model(made, tmp_path, how)
    before = listing(tmp_path)
    if kind == "dda run":
        before.append("scene.toml")
    line = one_line(capsys, model_command(kind, path, tmp_path), "model.npz", *([words] if words else []))
    if kind == "dda run":
        assert "spheres.model = 'model.npz'" in line  # the scene, its key and the model's problem
    assert listing(tmp_path) == sorted(before)


def test_a_valid_model_still_loads(made, tmp_path, capsys):
    assert sgim_main(["info", str(made / "model" / "model.npz"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["spheres"] > 0 and info["bonded"] > 0


# ------------------------------------------------------------------------------------------------ decks
RUN_EDITS = [
    ("header removed", drop("header"), "missing array header"),
    ("header a JSON array", lambda a: a.__setitem__("header", np.array("[1, 2]")), "header: expected a JSON object"),
    ("header not JSON", lambda a: a.__setitem__("header", np.array("{dt: 1")), "header: not valid JSON"),
    ("header without dt", header(lambda h: h.pop("dt")), "missing key header.dt"),
    ("dt negative", header(lambda h: h.__setitem__("dt", -1.0)), "header.dt = -1.0: must be > 0"),
    ("dt NaN", header(lambda h: h.__setitem__("dt", float("nan"))), "header.dt = nan"),
    ("kn a string", header(lambda h: h.__setitem__("kn", "stiff")), "header.kn = 'stiff': must be a number"),
    ("unknown header key", header(lambda h: h.__setitem__("colour_rule", 1)), "unknown key header.colour_rule"),
    ("bond past the spheres", setter("bond_j", at(0, 10 ** 6)), "bond_j[0] = 1000000: out of range"),
    ("bond lengths disagree", setter("bond_kn", lambda x: x[:-3]), "bond_kn: shape"),
    ("radii one short", setter("radii", lambda x: x[:-1]), "radii: shape"),
    ("centre NaN", setter("centers", at((0, 2), np.nan)), "centers[0, 2] = nan"),
    ("bond stiffness inf", setter("bond_kn", at(1, np.inf)), "bond_kn[1] = inf"),
    ("strength NaN", setter("bond_ft", at(1, np.nan)), "bond_ft[1] = nan"),
    ("joint normal shape", setter("joint_normal", lambda x: x[:, :2]), "joint_normal: shape"),
    ("gravity of two", setter("gravity", lambda x: x[:2]), "gravity: shape"),
    ("fixed as text", setter("fixed", lambda x: x.astype(str)), "fixed: dtype"),
    ("fixed and prescribed", lambda a: (a.__setitem__("prescribed", a["fixed"].copy())), "both fixed and prescribed"),
]


def bad_run(made, tmp_path, how, engine="yade"):
    """A copy of a valid deck in tmp_path/deck with its run.npz corrupted."""
    deck = tmp_path / "deck"
    shutil.copytree(made / engine, deck)
    src, dst = made / engine / "run.npz", deck / "run.npz"
    if how in BYTES:
        return deck, write_bytes(src, dst, how)
    if how == "model.npz":
        shutil.copyfile(made / "model" / "model.npz", dst)
        return deck, "not a run.npz: missing arrays header"
    _, fn, words = next(e for e in RUN_EDITS if e[0] == how)
    edit_npz(src, dst, fn)
    return deck, words


RUN_CASES = [*BYTES, "model.npz", *(e[0] for e in RUN_EDITS)]


@pytest.mark.parametrize("kind,how", [(k, h) for k in ("run", "run --in-house", "export") for h in RUN_CASES
                                      if not (k == "export" and h == "model.npz")])
def test_run_npz(made, tmp_path, capsys, kind, how):  # (a model.npz is a valid source of `adapters export`)
    deck, words = bad_run(made, tmp_path, how)
    before = listing(tmp_path)
    if kind == "export":  # a run.npz as the source of a deck
        rc = adapters_main(["export", str(deck / "run.npz"), "--to", "vtu", "-o", str(tmp_path / "v"), "--quiet"])
    else:
        rc = adapters_main(["run", str(deck), "--quiet", *(["--in-house"] if "in-house" in kind else [])])
    words = words.replace("not a run.npz", "not a model.npz or run.npz") if kind == "export" else words
    one_line(capsys, rc, "run.npz", words)
    assert listing(tmp_path) == before  # no result folder, no deck


@pytest.mark.parametrize("how", ["random", "bond past the spheres", "header without dt"])
def test_run_npz_of_a_liggghts_deck(made, tmp_path, capsys, how):
    deck, words = bad_run(made, tmp_path, how, engine="liggghts")
    before = listing(tmp_path)
    one_line(capsys, adapters_main(["run", str(deck), "--quiet"]), "run.npz", words)
    assert listing(tmp_path) == before


DECK_FILES = [  # (engine, file, text written, words)
    ("yade", "deck.json", "", "empty file"),
    ("yade", "deck.json", "{\"engine\": \"yade\"", "not valid JSON"),
    ("yade", "deck.json", "[\"yade\"]", "expected a deck.json, found a JSON array"),
    ("yade", "deck.json", RANDOM, "not UTF-8"),
    ("yade", "deck.json", "{\"engine\": \"abaqus\"}", "not runnable"),
    ("liggghts", "deck.json", "{\"engine\": \"liggghts\", \"variant\": \"glue\"}", "variant = 'glue'"),
    ("yade", "yade.json", "[]", "found a JSON array"),
    ("yade", "yade.json", "{\"detection_factor\": 5}", "detection_factor = 5: must be <= 1.2"),
    ("yade", "yade.json", "{\"record_positions\": \"yes\"}", "record_positions = 'yes'"),
    ("yade", "yade.json", PNG, "not UTF-8"),
    ("yade", "script.py", None, "missing script.py"),
    ("liggghts", "data", "", "no 'LIGGGHTS data file' title"),
    ("liggghts", "data", PNG, "not a LIGGGHTS data file"),
    ("liggghts", "data", "atoms-", "atoms, but run.npz has"),
    ("liggghts", "data", "bonds-", "bonds, but run.npz has"),
    ("liggghts", "in", None, "missing in"),
    ("yade-polyhedra", "poly.json", "[1]", "found a JSON array"),
    ("yade-polyhedra", "poly.json", "dt=-1", "dt = -1: must be > 0"),
    ("yade-polyhedra", "poly.json", "steps=2.5", "steps = 2.5: must be an integer"),
    ("yade-polyhedra", "poly.json", "gravity=[0, 0]", "gravity = [0, 0]"),
    ("yade-polyhedra", "poly.json", "-young", "missing key young"),
]


def _deck_text(old, how):
    """Text of a deck file: an edit of its JSON / LIGGGHTS header, or `how` as it is."""
    if how in ("atoms-", "bonds-"):
        word = how[:-1]
        lines = old.splitlines(keepends=True)
        k = next(i for i, ln in enumerate(lines) if ln.strip().endswith(f" {word}"))
        lines[k] = f"{int(lines[k].split()[0]) - 1} {word}\n"
        return "".join(lines)
    if how.startswith("-"):
        doc = json.loads(old)
        doc.pop(how[1:])
        return json.dumps(doc)
    if "=" in how and not how.startswith("{"):
        key, value = how.split("=", 1)
        doc = json.loads(old)
        doc[key] = json.loads(value)
        return json.dumps(doc)
    return how


@pytest.mark.parametrize("engine,name,how,words", DECK_FILES,
                         ids=[f"{e}-{n}-{i}" for i, (e, n, _, _) in enumerate(DECK_FILES)])
def test_deck_files(made, tmp_path, capsys, engine, name, how, words):
    deck = tmp_path / "deck"
    shutil.copytree(made / ("poly" if engine == "yade-polyhedra" else engine), deck)
    path = deck / name
    if how is None:
        path.unlink()
    elif isinstance(how, bytes):
        path.write_bytes(how)
    else:
        path.write_text(_deck_text(path.read_text(), how))
    before = listing(tmp_path)
    one_line(capsys, adapters_main(["run", str(deck), "--quiet"]), name, words)
    assert listing(tmp_path) == before


BLOCK_EDITS = [
    ("missing array", drop("vert_start"), "missing array vert_start"),
    ("vertex block past the end", setter("vert_start", at(-1, 10 ** 4)), "vert_start"),
    ("density NaN", setter("density", at(0, np.nan)), "density[0] = nan"),
    ("velocity shape", setter("velocity", lambda x: x[:, :2]), "velocity: shape"),
    ("names one short", setter("names", lambda x: x[:-1]), "names: shape"),
    ("no blocks", lambda a: a.update(fixed=np.zeros(0, bool)), "no blocks"),
    ("vertices inf", setter("vertices", at((0, 0), np.inf)), "vertices[0, 0] = inf"),
]


@pytest.mark.parametrize("how", [*BYTES, "model.npz", *(e[0] for e in BLOCK_EDITS)])
def test_blocks_npz(made, tmp_path, capsys, how):
    deck = tmp_path / "deck"
    shutil.copytree(made / "poly", deck)
    src, dst = made / "poly" / "blocks.npz", deck / "blocks.npz"
    if how in BYTES:
        words = write_bytes(src, dst, how)
    elif how == "model.npz":
        shutil.copyfile(made / "model" / "model.npz", dst)
        words = "not a blocks.npz: missing arrays"
    else:
        _, fn, words = next(e for e in BLOCK_EDITS if e[0] == how)
        edit_npz(src, dst, fn)
    before = listing(tmp_path)
    one_line(capsys, adapters_main(["run", str(deck), "--quiet"]), "blocks.npz", words)
    assert listing(tmp_path) == before


def test_garbage_run_npz_in_a_real_process(made, tmp_path):
    """`adapters run DECK` as a user runs it: one line, exit status 2, within 2 s, no result folder."""
    deck = tmp_path / "deck"
    shutil.copytree(made / "yade", deck)
    (deck / "run.npz").write_bytes(RANDOM)
    exe = Path(sys.executable).with_name("adapters")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "adapters.cli"]
    t0 = time.perf_counter()
    r = subprocess.run([*cmd, "run", str(deck)], capture_output=True, text=True, timeout=60)
    wall = time.perf_counter() - t0
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith("adapters: error: ") and "run.npz" in lines[0]
    assert not (deck / "result").exists()
    assert wall < 2.0, wall


# ------------------------------------------------------------------------------------------------ results
RESULT_EDITS = [
    ("result.json", lambda t: "[]", "found a JSON array"),
    ("result.json", lambda t: "", "empty file"),
    ("result.json", lambda t: t[:len(t) // 2], "not valid JSON"),
    ("result.json", lambda t: t.replace('"complete"', '"finished"', 1), "status = 'finished'"),
    ("result.json", lambda t: t.replace('"n": ', '"n": 1', 1), "does not match result.npz"),
    ("result.json", lambda t: t.replace('"engine": "dda",', '', 1), "missing key engine"),
    ("result.npz", "half", "unreadable archive"),
    ("result.npz", "random", "not an npz (zip) archive"),
    ("result.npz", drop("x0"), "missing array x0"),
    ("result.npz", setter("pos", lambda x: x[:, :-1]), "pos: shape"),
    ("result.npz", setter("time", at(0, np.nan)), "time[0] = nan"),
    ("result.npz", setter("series_kinetic", lambda x: x[:-1]), "series_kinetic: shape"),
    ("result.npz", setter("bond_intact", lambda x: x.astype(float)), "bond_intact: dtype"),
    ("result.npz", setter("final_pos", at((0, 0), np.nan)), "final_pos[0, 0] = nan"),
    ("result.npz", setter("x0", lambda x: x[:-1]), "shape"),
]


@pytest.mark.parametrize("name,how,words", RESULT_EDITS, ids=[f"{n}-{i}" for i, (n, _, _) in enumerate(RESULT_EDITS)])
def test_result_files(made, tmp_path, capsys, name, how, words):
    """No command reads a result folder back; RunResult.load (tests, studies) gives the same one line, through
    the CLI convention of every command (run_command)."""
    folder = tmp_path / "result"
    shutil.copytree(made / "result", folder)
    path = folder / name
    if name == "result.json":
        path.write_text(how(path.read_text()))
    elif isinstance(how, str):
        write_bytes(made / "result" / name, path, how)
    else:
        edit_npz(made / "result" / name, path, how)
    with pytest.raises(CliError):
        RunResult.load(folder)
    rc = run_command("adapters", argparse.Namespace(func=lambda a: RunResult.load(folder)))
    one_line(capsys, rc, name, words)


def test_a_valid_result_still_loads(made):
    res = RunResult.load(made / "result")
    assert res.complete and res.n > 0 and len(res.time) == len(res.series["kinetic"])


# ------------------------------------------------------------------------------------------------ DFN files
def _net_scene(tmp_path, name):
    scene = tmp_path / "s.toml"
    scene.write_text(DFN_SCENE.split("[dfn]")[0] + f'[dfn]\nfile = "{name}"\n')
    return scene


def _cut_mid_row(text):
    cut = len(text) // 2
    while text[cut - 1] in "\n,":
        cut += 1
    return text[:cut]


NETWORK_EDITS = [
    ("network.csv", lambda t: "", "CSV lacks the column"),
    ("network.csv", RANDOM, "cannot read network file"),
    ("network.csv", PNG, "cannot read network file"),
    ("network.csv", _cut_mid_row, "must be a finite number"),
    ("network.csv", lambda t: t.replace("\n", ",9,9\n", 2).replace(",9,9\n", "\n", 1), "more cells than"),
    ("network.csv", lambda t: t.replace("J1-00001", "J1-00002", 1), "repeats the id"),
    ("network.csv", lambda t: t.replace(",1.5,", ",nan,", 1), "radius"),
    ("network.csv", lambda t: "\n".join(t.splitlines()[:1] + ["x," * 12 + "x"]), "must be a finite number"),
    ("network.json", lambda t: "[1, 2]", "'fractures' list"),
    ("network.json", lambda t: t[:len(t) // 2], "not valid JSON"),
    ("network.json", lambda t: '{"fractures": 3}', "'fractures' list"),
    ("network.json", lambda t: '{"fractures": [7]}', "must be an object"),
    ("network.json", lambda t: '{"fractures": [{"id": "a", "normal": [0, 0, 1], "radius": 1}]}', "'centre'"),
    ("network.json", lambda t: '{"fractures": [{"id": "a", "centre": [1, 1, 1], "normal": [0, 0, 1], '
                               '"radius": Infinity}]}', "must be a finite number"),
]


@pytest.mark.parametrize("name,how,words", NETWORK_EDITS,
                         ids=[f"{n}-{i}" for i, (n, _, _) in enumerate(NETWORK_EDITS)])
@pytest.mark.parametrize("cmd", ["dfn", "build"])
def test_network_files(made, tmp_path, capsys, cmd, name, how, words):
    path = tmp_path / name
    text = (made / "net" / name).read_text()
    if isinstance(how, bytes):
        path.write_bytes(how)
    else:
        path.write_text(how(text))
    scene = _net_scene(tmp_path, name)
    before = listing(tmp_path)
    rc = sgim_main([cmd, str(scene), "-o", str(tmp_path / "out"), "--quiet"])
    one_line(capsys, rc, "s.toml", f"dfn.file {name}", words)
    assert listing(tmp_path) == before


def test_a_valid_network_still_reads(made, tmp_path, capsys):
    for name in ("network.csv", "network.json"):
        shutil.copyfile(made / "net" / name, tmp_path / name)
        assert sgim_main(["dfn", str(_net_scene(tmp_path, name)), "-o", str(tmp_path / name[-4:]), "--json",
                          "--quiet"]) == 0
        assert json.loads(capsys.readouterr().out)["fractures"] > 3


# ------------------------------------------------------------------------------------------------ study tables
def _study(made, tmp_path):
    shutil.copytree(made / "study", tmp_path / "study")
    return tmp_path / "study" / "study.toml", tmp_path / "study" / "out"


def _lines(path):
    return path.read_bytes().splitlines(keepends=True)


def _replace_line(path, k, new):
    lines = _lines(path)
    lines[k] = new
    path.write_bytes(b"".join(lines))


TABLE_EDITS = [  # (file, edit of the file, words; "line N" where the defect is)
    ("results.csv", lambda p: _replace_line(p, 2, b"c00001,ok,,0.1\n"), "line 3: 4 cells, expected 7"),
    ("results.csv", lambda p: _replace_line(p, 2, b"c00001,fine,,0.1,0,2.0,2.0\n"), "line 3: status = 'fine'"),
    ("results.csv", lambda p: _replace_line(p, 3, _lines(p)[1]), "line 4: case c00000 repeats line 2"),
    ("results.csv", lambda p: _replace_line(p, 2, b"c00001,ok,,\xff\xfe,0,2.0,2.0\n"), "line 3: not UTF-8"),
    ("results.csv", lambda p: _replace_line(p, 2, b"\n"), "line 3: 0 cells"),
    ("results.csv", lambda p: _replace_line(p, 1, b"c00000,ok,,fast,0,1.0,1.0\n"), "line 2: wall_s = 'fast'"),
    ("results.csv", lambda p: _replace_line(p, 1, b'c00000,ok,"unclosed,0.1,0,1.0,1.0\n'), "line 2"),
    ("results.jsonl", lambda p: _replace_line(p, 1, b"{not json\n"), "line 2: not a JSON line"),
    ("results.jsonl", lambda p: _replace_line(p, 0, b"[1, 2]\n"), "line 1: not a row of the results table"),
    ("results.jsonl", lambda p: _replace_line(p, 2, _lines(p)[0]), "line 3: case c00000 repeats line 1"),
    ("study.json", lambda p: p.write_text("{\"cases\": "), "not valid JSON"),
    ("study.json", lambda p: p.write_text("[]"), "found a JSON array"),
]


@pytest.mark.parametrize("name,edit,words", TABLE_EDITS, ids=[f"{n}-{i}" for i, (n, _, _) in enumerate(TABLE_EDITS)])
def test_study_resume_reads_the_table_back(made, tmp_path, capsys, name, edit, words):
    study, out = _study(made, tmp_path)
    edit(out / name)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != ".lock"}
    rc = study_main(["run", str(study), "-o", str(out), "--quiet"])
    one_line(capsys, rc, name, words)
    after = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != ".lock"}
    assert after == before  # nothing run, nothing rewritten


@pytest.mark.parametrize("name,edit,words", [e for e in TABLE_EDITS if e[0] != "results.jsonl"],
                         ids=[f"{n}-{i}" for i, (n, _, _) in enumerate(TABLE_EDITS) if n != "results.jsonl"])
def test_study_report_reads_the_table_back(made, tmp_path, capsys, name, edit, words):
    _, out = _study(made, tmp_path)
    edit(out / name)
    before = listing(out)
    one_line(capsys, study_main(["report", str(out)]), name, words)
    assert listing(out) == before  # no report.md, no report/
    one_line(capsys, report_main([str(out)]), name, words)


def test_table_with_rows_of_another_study(made, tmp_path, capsys):
    study, out = _study(made, tmp_path)
    p = out / "results.csv"
    _replace_line(p, 2, b"c99999,ok,,0.1,0,2.0,2.0\n")
    one_line(capsys, study_main(["run", str(study), "-o", str(out), "--quiet"]), "results.csv",
             "line 3: case c99999 is not a case of this study")
    _replace_line(p, 0, b"case_id,status,error,wall_s,rank,p:contact.kn,value\n")
    one_line(capsys, study_main(["run", str(study), "-o", str(out), "--quiet"]), "results.csv", "columns differ")
    _replace_line(p, 0, b"id,state,error,wall_s,rank,p:contact.friction,value\n")
    one_line(capsys, study_main(["report", str(out)]), "results.csv", "line 1: not a results table")


def test_a_torn_last_line_is_still_dropped(made, tmp_path, capsys):
    """A crash inside a write leaves a last line without its end: the design drops it (the case runs again),
    in the runner and in the report; it is not an error."""
    study, out = _study(made, tmp_path)
    lines = _lines(out / "results.csv")
    (out / "results.csv").write_bytes(b"".join(lines[:-1]) + lines[-1][:9])
    assert study_main(["report", str(out)]) == 0
    assert "| not run | 1 |" in (out / "report.md").read_text()
    assert study_main(["run", str(study), "-o", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(io.StringIO((out / "results.csv").read_text())))
    assert [(r["case_id"], r["status"], r["value"]) for r in rows] == \
        [(f"c0000{k}", "ok", f"{k + 1:.1f}") for k in range(4)]
    assert (out / "results.csv").read_bytes().startswith(b"".join(lines[:-1]))  # the finished rows kept
