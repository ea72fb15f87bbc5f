"""Seeded fuzz test of the command-line contract on bad and hostile input.

Every scene in cases/ (cases/scenes/*.toml, cases/scenes/crossval/*.toml, cases/scenes/studies/*.toml, cases/scenes/studies/scenes/*.toml)
is parsed, and each of its numeric keys (the numeric leaves of the TOML, one key per path with list indices
folded, a random instance of it per value) gets NaN, inf, -inf, 0, a negative value, 1e308 and 1e-300; each
scene also gets strings for numbers, tables for lists, lists of the wrong length, deleted required keys, unknown
keys and TOML syntax errors. Small meshes written here (a single triangle, an open box, an inverted box, garbage
with an .stl name, empty files, NaN or 1e308 vertices, quads, ...) stand where scenes name meshes (excavation
surfaces, cavities, triangulated discontinuities, fill surfaces, DDA blocks); model.npz, run.npz and deck
folders are corrupted; absurd sizes, durations and case counts are asked for; dda wedge, adapters and
cases study options get the same values. The commands: sgim build, sgim dfn, dda run, dda wedge, adapters
export, adapters run, cases study run.

Each case is classified up front: "must fail" (exit status 2, exactly one line on stderr starting
``PROG: error:``, no traceback, no output folder left behind) or "may succeed" (exit 0 with its output, or the
same clean refusal; `dda run` may also end in a blow-up, status 3, with its folder).

How the cases run: the commands' ``main(argv)`` in worker processes forked from this one (after a warm-up that
pays for imports and numba's kernels once), file descriptors 1 and 2 captured as capfd does, an uncaught
exception printed as the interpreter prints it, the warning filters of a fresh interpreter, a memory limit, and
a time limit per case (a must-fail input accepted by mistake runs into it, is killed and reported instead of
hanging the suite); two workers, one per core. The refusals happen in validation, before any kernel runs. A
may-succeed case first runs its reader (scene, DDA scene or study): when the reader refuses, the command runs;
when it accepts, a seeded sample of FUZZ_RUN_VALID such cases of cheap scenes runs for real (the scenes are
shrunk first: a coarser lattice, fewer excavation points, a 0.02 s run with npz output), the rest are counted
as accepted. Valid `dda run` cases run only when numba's cache already holds the engines (FUZZ_DDA_RUNS). A
sample of the cases also runs through the real executables (.venv/bin/sgim, ...) as subprocesses.

Environment: FUZZ_SEED (default 20251125) picks the mutations; FUZZ_ONLY=TEXT runs only the cases whose id
contains TEXT (ids are stable for a seed: FUZZ_ONLY=0123- reproduces case 123); FUZZ_TIMEOUT (s, default 30)
per case; FUZZ_RUN_VALID (default 40) accepted may-succeed cases run for real; FUZZ_SUBPROCESS (default 10)
cases run as subprocesses; FUZZ_DDA_RUNS (auto, 1, 0). ``pytest -s tests/test_fuzz.py`` prints the seed, the
cases per command, how they ran and the wall time; a failure names each broken case with its input.
"""
from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import os
import pickle
import random
import re
import resource
import select
import shutil
import signal
import struct
import subprocess
import sys
import time
import tomllib
import traceback
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
SEED = int(os.environ.get("FUZZ_SEED", "20251125"))
ONLY = os.environ.get("FUZZ_ONLY", "")
TIMEOUT = float(os.environ.get("FUZZ_TIMEOUT", "30"))
RUN_VALID = int(os.environ.get("FUZZ_RUN_VALID", "40"))
N_SUBPROCESS = int(os.environ.get("FUZZ_SUBPROCESS", "10"))
JOBS = 2
SCENE_GLOBS = ("cases/scenes/*.toml", "cases/scenes/crossval/*.toml", "cases/scenes/studies/*.toml", "cases/scenes/studies/scenes/*.toml")

PROG = {"sgim build": "sgim", "sgim dfn": "sgim", "dda run": "dda", "dda wedge": "dda wedge",
        "adapters export": "adapters", "adapters run": "adapters", "cases study run": "cases study"}
# the file a successful run writes into its output folder
DONE_FILE = {"sgim build": "model.npz", "sgim dfn": "network.csv", "dda run": "summary.json",
             "adapters export": "deck.json", "adapters run": "result.json", "cases study run": "results.csv"}


def _main(command):
    if command.startswith("sgim"):
        from sgim.cli import main
    elif command.startswith("dda"):
        from dda.cli import main
    elif command.startswith("adapters"):
        from adapters.cli import main
    else:
        from cases.cli import main
    return main


def _argv_prefix(command):
    return {"sgim build": ["build"], "sgim dfn": ["dfn"], "dda run": ["run"], "dda wedge": ["wedge"],
            "adapters export": ["export"], "adapters run": ["run"], "cases study run": ["study", "run"]}[command]


# --------------------------------------------------------------------------------------------- cases
@dataclass
class Case:
    cid: str  # stable id: number, command, scene, mutation
    command: str
    args: list  # after the subcommand; "{d}" is the case folder
    expect: str  # "fail" or "may"
    desc: str  # what was done to the input (mutation path and value, or the file's contents)
    files: dict = field(default_factory=dict)  # name in the case folder -> str or bytes
    out: str | None = "out"  # the output path the command is given (relative to the case folder)
    reader: tuple | None = None  # ("sgim" | "dda" | "study", file name): the reader a may-succeed case checks first
    cheap: bool = True  # an accepted may-succeed case may run for real
    engine: bool = False  # a may-succeed case that steps the DDA engine (dda wedge): run only with FUZZ_DDA_RUNS
    owner: str = ""  # whose validation the case exercises (for the report)

    @property
    def num(self):
        """The case's number: its folder's name."""
        return self.cid.split("-")[0]

    def argv(self, d):
        return _argv_prefix(self.command) + [a.replace("{d}", str(d)) for a in self.args]


def _walk_numbers(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _walk_numbers(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _walk_numbers(v, path + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path, node


def _walk_all(node, path=()):
    """Every (path, value) of a TOML document, containers included."""
    if path:
        yield path, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _walk_all(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _walk_all(v, path + (i,))


def _pattern(path):
    return ".".join("*" if isinstance(s, int) else s for s in path)


def _dotted(path):
    return ".".join(str(s) for s in path)


def _get(doc, path):
    for s in path:
        doc = doc[s]
    return doc


def _set(doc, path, value):
    _get(doc, path[:-1])[path[-1]] = value


def _delete(doc, path):
    parent = _get(doc, path[:-1])
    del parent[path[-1]]


def _absolutise(node, base):
    """String values naming a file next to the scene become absolute paths (the mutated scene lives elsewhere)."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in list(items):
        if isinstance(v, (dict, list)):
            _absolutise(v, base)
        elif isinstance(v, str) and v and not Path(v).is_absolute() and (base / v).is_file():
            node[k] = str((base / v).resolve())


def _dump(doc):
    from cases.lib.study import dump_toml

    return dump_toml(doc)


def _kind(doc):
    if "base" in doc or "engine" in doc:
        return "study"
    return "dda" if "simulation" in doc else "sgim"


# Classification of 0, a negative value and 1e308 per key (NaN and +-inf must always be refused): the first rule
# whose pattern matches the dotted path (list indices as numbers) gives (zero, negative, huge), each "fail" or
# "may". Unlisted keys: "may" (the run decides). 1e308 of a length, coordinate, angle, count, time or stiffness
# is an absurd value that must be refused (at the reader, or by the resource limits before the run).
F, M = "fail", "may"
RULES = [
    # studies
    (r"^seed$", (M, F, F)),
    (r"^timeout$", (F, F, M)),
    (r"^sampling\.samples$", (F, F, F)),
    (r"^parameters\..*\.(grid|list)\.\d+$", (M, M, M)),
    (r"^parameters\..*\.realisations$", (F, F, F)),
    (r"^parameters\..*\.uniform\.\d+$", (M, M, M)),
    (r"^parameters\..*\.normal\.0$", (M, M, M)),
    (r"^parameters\..*\.normal\.1$", (F, F, M)),
    (r"^parameters\..*\.fisher\.dip$", (M, F, F)),
    (r"^parameters\..*\.fisher\.dip_direction$", (M, M, M)),
    (r"^parameters\..*\.fisher\.kappa$", (F, F, M)),
    # sgim scenes
    (r"^domain\.(min|max)\.\d$", (M, M, F)),
    (r"^packing\.radius$", (F, F, F)),
    (r"^packing\.seed$", (M, F, F)),
    (r"^packing\.distribution\.sizes\.\d+$", (F, F, F)),
    (r"^packing\.distribution\.passing\.\d+$", (M, F, F)),
    (r"^packing\.distribution\.(min|max|median|sigma)$", (F, F, F)),
    (r"^packing\.grading\.(fine|coarse)_radius$", (F, F, F)),
    (r"^packing\.grading\.(fine|coarse)_distance$", (M, F, M)),
    (r"^bonds\.tolerance$", (M, F, F)),
    (r"^discontinuity\.\d+\.radius$", (F, F, M)),
    (r"\.thickness$", (M, F, M)),
    (r"\.dip_(top|bottom)$", (F, F, F)),
    (r"^(discontinuity|joint_set)\.\d+\.dip$", (M, F, F)),
    (r"^(discontinuity|joint_set)\.\d+\.dip_direction$", (M, F, F)),
    (r"\.(centre|center)\.\d$", (M, M, F)),
    (r"\.(points|vertices|path)\.\d+\.\d$", (M, M, F)),
    (r"^(excavation|cavity|discontinuity)\.\d+\.faces\.\d+\.\d$", (M, F, F)),
    (r"\.trace\.\d$", (M, M, F)),
    (r"^cavity\.\d+\.(radius|radii\.\d|width|height)$", (F, F, F)),
    (r"\.segments$", (F, F, F)),
    (r"^discontinuity\.\d+\.(depth|length)$", (F, F, F)),
    (r"^discontinuity\.\d+\.resolution$", (F, F, M)),
    (r"^dfn\.seed$", (M, F, F)),
    (r"^dfn\.max_fractures$", (F, F, M)),
    (r"^joint_set\.\d+\.kappa$", (F, F, M)),
    (r"^joint_set\.\d+\.p32$", (M, F, F)),
    (r"^joint_set\.\d+\.radius\.exponent$", (M, M, M)),
    (r"^joint_set\.\d+\.radius\.min$", (F, F, F)),
    (r"^joint_set\.\d+\.radius\.max$", (F, F, M)),
    # dda scenes
    (r"^simulation\.(duration|record_every|safety|frames)$", (F, F, F)),
    (r"^simulation\.local_damping$", (M, F, F)),
    (r"^(contact|contact_pair\.\d+)\.(kn|ks)$", (F, F, F)),
    (r"\.friction$", (M, F, F)),
    (r"\.(cohesion|tensile)$", (M, F, M)),
    (r"\.damping$", (M, F, F)),
    (r"^material\.\d+\.density$", (F, F, F)),
    (r"^material\.\d+\.E$", (F, F, M)),
    (r"^material\.\d+\.nu$", (M, F, F)),
    (r"^spheres\.density$", (F, F, F)),
    (r"^spheres\.bond_young$", (F, F, F)),
    (r"^spheres\.bond_shear_ratio$", (M, F, F)),
    (r"^spheres\.bond_(tensile|shear)$", (M, F, M)),
    (r"^spheres\.joint_friction$", (M, F, F)),
    (r"^spheres\.fixed_below\.\d+\.\d$", (M, M, F)),
    (r"^block\.\d+\.(size|width|height)$", (F, F, F)),
    (r"^block\.\d+\.dof$", (F, F, F)),
    (r"^block\.\d+\.velocity\.\d$", (M, M, M)),
    (r"^block\.\d+\.rotation_angle$", (M, M, M)),
    (r"^block\.\d+\.rotation_axis\.\d$", (M, M, M)),  # a direction: any length
    (r"^generate\.\d+\.(joint_a|joint_b|face)\.\d$", (M, M, F)),
    (r"^generate\.\d+\.(height|size|b|h)$", (F, F, F)),
    (r"^generate\.\d+\.(angle|alpha)$", (M, M, F)),
    (r"^generate\.\d+\.(n|layers|per_layer)$", (M, F, F)),
    (r"^generate\.\d+\.seed$", (M, F, F)),
    (r"^generate\.\d+\.projectile_velocity$", (M, M, M)),
]
VALUES = ("nan", "inf", "-inf", "zero", "neg", "huge", "tiny")


def classify(path, value_class):
    if value_class in ("nan", "inf", "-inf"):
        return F
    if value_class == "tiny":  # 1e-300: within every positive range, but a size or a mass that underflows
        return M
    dotted = _dotted(path)
    for pat, (zero, neg, huge) in RULES:
        if re.search(pat, dotted):
            return {"zero": zero, "neg": neg, "huge": huge}[value_class]
    return M


def mutated_value(orig, value_class):
    if value_class == "nan":
        return math.nan
    if value_class == "inf":
        return math.inf
    if value_class == "-inf":
        return -math.inf
    if value_class == "tiny":
        return 1e-300
    if value_class == "zero":
        return 0 if isinstance(orig, int) else 0.0
    if value_class == "neg":
        v = -abs(orig) if orig != 0 else -1
        return int(v) if isinstance(orig, int) else float(v)
    return 1e308


# scenes whose valid variants are not run even shrunk (random packings, a 60 000-sphere deck, studies that run
# engines): their accepted may-succeed cases are checked by the reader only
NOT_RUN = {"core_sample.toml", "open_pit_graded.toml", "open_pit_deck.toml"}
# lengths of vectors whose length is fixed (a list of the wrong length must be refused)
FREE_LISTS = {"sizes", "passing", "grid", "list", "results", "formats", "cut_away", "fixed", "path", "points",
              "vertices", "faces", "region", "near"}


def _shrink_sgim(doc):
    """A coarser lattice (about 13 000 sites at most) so that a valid build is fast, and at most 200 of an
    excavation's points (every k-th: the open pits give 2 000), so that reading the scene is."""
    changed = False
    for ex in doc.get("excavation", []):
        pts = ex.get("points") if isinstance(ex, dict) else None
        if isinstance(pts, list) and len(pts) > 200:
            ex["points"] = pts[:: -(-len(pts) // 200)]
            changed = True
    pk, dom = doc.get("packing"), doc.get("domain")
    try:
        ext = min(float(b) - float(a) for a, b in zip(dom["min"], dom["max"]))
        r = float(pk["radius"])
    except (TypeError, KeyError, ValueError):
        return changed
    if pk.get("kind", "cubic") != "random" and r < ext / 30:
        pk["radius"] = round(ext / 30, 6)
        return True
    return changed


def _shrink_dda(doc, files):
    """A short run with npz output only (and a coarse in-memory sphere model, few generated blocks)."""
    sim = doc.get("simulation")
    changed = False
    if isinstance(sim, dict):
        dur = sim.get("duration")
        if isinstance(dur, (int, float)) and dur > 0.02:
            sim["duration"] = 0.02
            changed = True
        if isinstance(sim.get("record_every"), (int, float)) and sim["record_every"] > 0.01:
            sim["record_every"] = 0.01
        if isinstance(sim.get("frames"), int) and sim["frames"] > 2:
            sim["frames"] = 2
    doc["output"] = {"formats": ["npz"]}
    for g in doc.get("generate", []):
        if isinstance(g, dict) and isinstance(g.get("n"), int) and g["n"] > 30:
            g["n"] = 20
            changed = True
    sp = doc.get("spheres")
    if isinstance(sp, dict) and isinstance(sp.get("model"), str) and sp["model"].endswith(".toml"):
        mdoc = tomllib.loads(Path(sp["model"]).read_text())
        _absolutise(mdoc, Path(sp["model"]).parent)
        if _shrink_sgim(mdoc):
            files["model_scene.toml"] = _dump(mdoc)
            sp["model"] = "model_scene.toml"
            changed = True
    return changed


class Generator:
    def __init__(self, seed, root_files):
        self.rng = random.Random(seed)
        self.np_rng = np.random.default_rng(seed)
        self.cases = []
        self.files = root_files  # shared valid files: {"model.npz": bytes, "deck": {name: bytes}, ...}

    def add(self, command, args, expect, desc, **kw):
        n = len(self.cases)
        short = re.sub(r"[^A-Za-z0-9_.=+-]+", "_", desc)[:60]
        self.cases.append(Case(f"{n:04d}-{command.replace(' ', '-')}-{short}", command, args, expect, desc, **kw))

    # -- scenes --------------------------------------------------------------------------------------------
    def scene_command(self, kind, doc, name):
        if kind == "study":
            return "cases study run"
        if kind == "sgim":
            if isinstance(doc, dict) and ("joint_set" in doc or "dfn" in doc):
                return "sgim dfn" if self.rng.random() < 0.8 else "sgim build"
            return "adapters export" if self.rng.random() < 0.12 and name not in NOT_RUN else "sgim build"
        return "adapters export" if self.rng.random() < 0.12 and name not in NOT_RUN else "dda run"

    def scene_case(self, kind, name, rel, doc, desc, expect, files=None, shrunk="", cheap=True):
        files = dict(files or {})
        command = self.scene_command(kind, doc, name)
        fname = "study.toml" if kind == "study" else "scene.toml"
        files[fname] = doc if isinstance(doc, (str, bytes)) else _dump(doc)
        src = "{d}/" + fname
        if command == "sgim build":
            args = [src, "-o", "{d}/out", "--quiet", "--formats", "npz"]
        elif command == "sgim dfn":
            args = [src, "-o", "{d}/out", "--quiet"]
        elif command == "dda run":
            args = [src, "-o", "{d}/out", "--quiet"]
        elif command == "cases study run":
            args = [src, "-o", "{d}/out", "--quiet"]
        else:
            to = "yade" if kind == "dda" and isinstance(doc, dict) and "spheres" not in doc else "vtu"
            args = [src, "--to", to, "-o", "{d}/out", "--quiet"]
        reader = ("study" if kind == "study" else kind, fname)
        cheap = cheap and kind != "study" and name not in NOT_RUN
        self.add(command, args, expect, f"{rel}{shrunk}: {desc}", files=files, reader=reader, cheap=cheap,
                 owner="scene readers")

    def scenes(self):
        paths = sorted({p for g in SCENE_GLOBS for p in REPO.glob(g)})
        for p in paths:
            rel = str(p.relative_to(REPO))
            doc0 = tomllib.loads(p.read_text(encoding="utf-8"))
            _absolutise(doc0, p.parent)
            kind = _kind(doc0)
            base_files = {}
            shrunk = ""
            if kind == "sgim" and _shrink_sgim(doc0):
                shrunk = " (shrunk: coarser lattice, fewer excavation points)"
            elif kind == "dda" and _shrink_dda(doc0, base_files):
                shrunk = " (shrunk: duration 0.02 s, npz output, coarse model / few blocks)"
            self.scene_values(kind, p.name, rel, doc0, base_files, shrunk)
            self.scene_structure(kind, p.name, rel, doc0, base_files, shrunk, p.read_text(encoding="utf-8"))

    def scene_values(self, kind, name, rel, doc0, files, shrunk, cheap=True):
        groups = {}
        for path, v in _walk_numbers(doc0):
            groups.setdefault(_pattern(path), []).append((path, v))
        for pat in sorted(groups):
            for vc in VALUES:
                path, orig = self.rng.choice(groups[pat])
                doc = copy.deepcopy(doc0)
                new = mutated_value(orig, vc)
                _set(doc, path, new)
                self.scene_case(kind, name, rel, doc, f"{_dotted(path)} = {orig!r} -> {new!r}",
                                classify(path, vc), files, shrunk, cheap=cheap)

    def scene_structure(self, kind, name, rel, doc0, files, shrunk, text):
        rng = self.rng
        numbers = list(_walk_numbers(doc0))
        every = list(_walk_all(doc0))
        # a string for a number (twice), a number given as a list
        for _ in range(2):
            path, v = rng.choice(numbers)
            doc = copy.deepcopy(doc0)
            s = rng.choice([str(v), "abc", ""])
            _set(doc, path, s)
            self.scene_case(kind, name, rel, doc, f"{_dotted(path)} = {v!r} -> {s!r} (string for a number)", F,
                            files, shrunk)
        path, v = rng.choice(numbers)
        doc = copy.deepcopy(doc0)
        _set(doc, path, [v, v])
        self.scene_case(kind, name, rel, doc, f"{_dotted(path)} = {v!r} -> {[v, v]!r} (list for a number)", F,
                        files, shrunk)
        # a table for a list, a list of the wrong length
        vectors = [(p, v) for p, v in every if isinstance(v, list) and v and len(v) in (2, 3, 5)
                   and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
                   and not any(isinstance(s, str) and s in FREE_LISTS for s in p[-1:])
                   and not (kind == "dda" and "faces" in p)
                   and not (kind == "study" and p[0] == "parameters" and p[-1] in ("grid", "list"))]
        lists = [(p, v) for p, v in every if isinstance(v, list) and v and not all(isinstance(x, dict) for x in v)]
        if lists:
            path, v = rng.choice(lists)
            doc = copy.deepcopy(doc0)
            _set(doc, path, {"x": 1.0})
            self.scene_case(kind, name, rel, doc, f"{_dotted(path)} = {_short(v)} -> {{x = 1.0}} (table for a list)",
                            F, files, shrunk)
        if vectors:
            path, v = rng.choice(vectors)
            doc = copy.deepcopy(doc0)
            new = v[:-1] if rng.random() < 0.5 else v + [v[-1]]
            _set(doc, path, new)
            self.scene_case(kind, name, rel, doc, f"{_dotted(path)} = {v!r} -> {new!r} (list of the wrong length)",
                            F, files, shrunk)
        # a table given as a number, an array of tables given as one table
        tables = [(p, v) for p, v in every if isinstance(v, dict) and len(p) == 1]
        if tables:
            path, v = rng.choice(tables)
            doc = copy.deepcopy(doc0)
            _set(doc, path, 5)
            self.scene_case(kind, name, rel, doc, f"[{_dotted(path)}] -> {_dotted(path)} = 5 (number for a table)",
                            F, files, shrunk)
        aots = [(p, v) for p, v in every if len(p) == 1 and isinstance(v, list) and v
                and all(isinstance(x, dict) for x in v)]
        if aots:
            path, v = rng.choice(aots)
            doc = copy.deepcopy(doc0)
            _set(doc, path, copy.deepcopy(v[0]))
            self.scene_case(kind, name, rel, doc, f"[[{_dotted(path)}]] -> one [{_dotted(path)}] table "
                                                  "(table for an array of tables)", F, files, shrunk)
        # deleted required keys (must fail), a deleted key of any kind (may succeed)
        required = [p for p, _ in every if _required(kind, doc0, p)]
        for path in rng.sample(required, min(2, len(required))):
            doc = copy.deepcopy(doc0)
            _delete(doc, path)
            self.scene_case(kind, name, rel, doc, f"deleted required key {_dotted(path)}", F, files, shrunk)
        keyed = [p for p, _ in every if isinstance(p[-1], str)]
        path = rng.choice(keyed)
        doc = copy.deepcopy(doc0)
        _delete(doc, path)
        self.scene_case(kind, name, rel, doc, f"deleted key {_dotted(path)}", M, files, shrunk)
        # unknown keys: at the top and in a table
        doc = copy.deepcopy(doc0)
        doc["bogus"] = 1.0
        self.scene_case(kind, name, rel, doc, "unknown top-level key bogus = 1.0", F, files, shrunk)
        inner = [p for p, v in every if isinstance(v, dict)]
        if inner:
            path = rng.choice(inner)
            doc = copy.deepcopy(doc0)
            _get(doc, path)["bogus_key"] = 2
            self.scene_case(kind, name, rel, doc, f"unknown key {_dotted(path)}.bogus_key = 2", F, files, shrunk)
        # TOML syntax errors (in the original text, its file references made absolute)
        lines = _dump(doc0).splitlines()
        k = rng.randrange(len(lines))
        broken = [
            ("unclosed table header", lines[:k] + ["[domain"] + lines[k:]),
            ("key without a value", lines[:k] + ["oops ="] + lines[k:]),
            ("unterminated string", lines[:k] + ['name2 = "abc'] + lines[k:]),
            ("stray text", lines[:k] + ["this is not toml"] + lines[k:]),
            ("a key given twice", lines + [lines[0]] if "=" in lines[0] else lines + ["x = 1", "x = 2"]),
        ]
        for what, ls in rng.sample(broken, 2):
            self.scene_case(kind, name, rel, "\n".join(ls) + "\n", f"TOML syntax error: {what} at line {k + 1}", F,
                            files, shrunk)
        head = "\n".join(lines).encode()[: max(1, len(text) // 3)]
        bad = rng.choice([b"\xff\xfe\x00\x00garbage", head + b"\x00\x9c"])
        self.scene_case(kind, name, rel, bad, f"binary bytes ({len(bad)} bytes: {bad[:24]!r}...)", F, files, shrunk)

    def random_packings(self):
        """Random packings in small scenes of their own (the ones in cases/ use only some of the radius laws)."""
        head = ('name = "random"\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [2.0, 2.0, 2.0]\n[output]\nformats = ["npz"]\n'
                '[[excavation]]\nname = "top"\npoints = [[-1.0, -1.0, 1.8], [3.0, -1.0, 1.7], [3.0, 3.0, 1.9], '
                '[-1.0, 3.0, 1.8]]\n[packing]\nkind = "random"\nseed = 1\n')
        for what, body in (
            ("constant radius", "radius = 0.15\n"),
            ("uniform law", '[packing.distribution]\nlaw = "uniform"\nmin = 0.1\nmax = 0.2\n'),
            ("lognormal law", '[packing.distribution]\nlaw = "lognormal"\nmedian = 0.15\nsigma = 0.2\nmin = 0.1\n'
                              'max = 0.3\n'),
            ("sieve curve", '[packing.distribution]\nlaw = "sieve"\nsizes = [0.2, 0.3, 0.4]\n'
                            'passing = [0.0, 50.0, 100.0]\n'),
            ("grading", '[packing.grading]\nnear = ["top"]\nfine_radius = 0.1\ncoarse_radius = 0.3\n'
                        'fine_distance = 0.1\ncoarse_distance = 0.8\n'),
        ):
            doc0 = tomllib.loads(head + body)
            self.scene_values("sgim", "random packing", f"random packing ({what})", doc0, {}, "", cheap=False)

    # -- meshes --------------------------------------------------------------------------------------------
    def meshes(self):
        host_sgim = ('name = "host"\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [2.0, 2.0, 2.0]\n'
                     '[packing]\nkind = "cubic"\nradius = 0.1\n[output]\nformats = ["npz"]\n')
        host_random = ('name = "host"\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [2.0, 2.0, 2.0]\n'
                       '[packing]\nkind = "random"\nradius = 0.12\nfill = "MESH"\n[output]\nformats = ["npz"]\n')
        host_dda = ('name = "host"\n[simulation]\nduration = 0.01\nrecord_every = 0.005\nframes = 1\n'
                    '[contact]\nkn = 1e8\nfriction = 30.0\n[output]\nformats = ["npz"]\n'
                    '[[block]]\nname = "floor"\nshape = "brick"\nsize = 4.0\nwidth = 4.0\nheight = 0.2\n'
                    'center = [1.0, 1.0, 0.4]\nfixed = true\n'
                    '[[block]]\nname = "m"\nfile = "MESH"\n')
        uses = {
            "excavation": (host_sgim + '[[excavation]]\nfile = "MESH"\n', "sgim build", "sgim"),
            "cavity": (host_sgim + '[[cavity]]\nfile = "MESH"\n', "sgim build", "sgim"),
            "discontinuity": (host_sgim + '[[discontinuity]]\nfile = "MESH"\nthickness = 0.0\n', "sgim build", "sgim"),
            "fill": (host_random, "sgim build", "sgim"),
            "block": (host_dda, "dda run", "dda"),
        }
        may = {"excavation": {"triangle", "open_box", "inverted_box", "box"},
               "cavity": {"inverted_box", "box"},
               "discontinuity": {"triangle", "open_box", "inverted_box", "box"},
               "fill": {"inverted_box", "box"},
               "block": {"inverted_box", "box", "outside", "quads"}}  # a block's faces may be polygons
        for mesh, (fname, content) in mesh_files(self.np_rng).items():
            for use, (host, command, reader) in uses.items():
                scene = host.replace("MESH", fname)
                args = ["{d}/scene.toml", "-o", "{d}/out", "--quiet"]
                args += ["--formats", "npz"] if command == "sgim build" else []
                shown = content if isinstance(content, str) and len(content) < 700 else f"{len(content)} bytes"
                self.add(command, args, M if mesh in may[use] else F,
                         f"{use} mesh {mesh} ({fname}): {shown!r}", files={"scene.toml": scene, fname: content},
                         reader=(reader, "scene.toml"), cheap=use != "fill", owner="mesh loading")

    # -- files read back ------------------------------------------------------------------------------------
    def corrupt_files(self):
        model, run = self.files["model.npz"], self.files["run.npz"]
        deck = self.files["deck"]
        for what, data in corrupt_npz(model, "model", self.np_rng):
            self.add("adapters export", ["{d}/model.npz", "--to", "vtu", "-o", "{d}/out", "--quiet"], F,
                     f"model.npz {what}", files={"model.npz": data}, owner="file readers (model.npz)")
        for what, data in self.rng.sample(corrupt_npz(model, "model", self.np_rng), 5):
            scene = ('[simulation]\nduration = 0.01\n[contact]\nkn = 1e7\n[spheres]\nmodel = "model.npz"\n'
                     '[output]\nformats = ["npz"]\n')
            self.add("dda run", ["{d}/scene.toml", "-o", "{d}/out", "--quiet"], F,
                     f"[spheres] model = model.npz {what}", files={"scene.toml": scene, "model.npz": data},
                     reader=("dda", "scene.toml"), owner="file readers (model.npz)")
        for what, data in corrupt_npz(run, "run", self.np_rng):
            self.add("adapters export", ["{d}/run.npz", "--to", "vtu", "-o", "{d}/out", "--quiet"], F,
                     f"run.npz {what}", files={"run.npz": data}, owner="file readers (run.npz)")
        for what, data in self.rng.sample(corrupt_npz(run, "run", self.np_rng), 6):
            files = {f"deck/{k}": v for k, v in deck.items()}
            files["deck/run.npz"] = data
            self.add("adapters run", ["{d}/deck", "--in-house", "-o", "{d}/out", "--quiet"], F,
                     f"deck run.npz {what} (--in-house)", files=files, owner="file readers (run.npz)")
        info = json.loads(deck["deck.json"])
        deck_json = [
            ("missing", None),
            ("empty", b""),
            ("garbage", b"\x89PNG\r\n\x1a\n garbage"),
            ("a JSON list", b"[1, 2, 3]"),
            ("a JSON string", b'"liggghts"'),
            ("engine not runnable", json.dumps({**info, "engine": "pfc-text"}).encode()),
            ("engine null", json.dumps({**info, "engine": None}).encode()),
            ("truncated", deck["deck.json"][: len(deck["deck.json"]) // 2]),
        ]
        for what, data in deck_json:
            files = {f"deck/{k}": v for k, v in deck.items() if k != "deck.json"}
            if data is not None:
                files["deck/deck.json"] = data
            self.add("adapters run", ["{d}/deck", "-o", "{d}/out", "--quiet"], F, f"deck.json {what}: {data!r}"[:200],
                     files=files, owner="file readers (deck.json)")
        files = {f"deck/{k}": v for k, v in deck.items() if k != "run.npz"}
        self.add("adapters run", ["{d}/deck", "--in-house", "-o", "{d}/out", "--quiet"], F, "deck without run.npz "
                 "(--in-house)", files=files, owner="file readers (deck)")
        files = {f"deck/{k}": v for k, v in deck.items() if k not in ("in", "data")}
        self.add("adapters run", ["{d}/deck", "-o", "{d}/out", "--quiet"], F, "liggghts deck without its in and data "
                 "files", files=files, owner="file readers (deck)")
        for flag, v in (("--np", "0"), ("--np", "-3"), ("--timeout", "0"), ("--timeout", "-1"), ("--timeout", "nan"),
                        ("--timeout", "-inf")):
            files = {f"deck/{k}": v2 for k, v2 in deck.items()}
            self.add("adapters run", ["{d}/deck", f"{flag}={v}", "-o", "{d}/out", "--quiet"], F,
                     f"adapters run {flag} {v}", files=files, owner="adapters run options")

    # -- absurd sizes -----------------------------------------------------------------------------------------
    def absurd(self):
        sg = ('name = "big"\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [{L}, {L}, {L}]\n[packing]\nkind = "{kind}"\n'
              'radius = {r}\n[output]\nformats = ["npz"]\n')
        for L, kind, r in ((1e4, "cubic", 0.5), (100.0, "random", 0.01), (2e5, "hexagonal", 1.0), (1e308, "fcc", 1.0)):
            text = sg.format(L=L, kind=kind, r=r)
            self.add("sgim build", ["{d}/scene.toml", "-o", "{d}/out", "--quiet", "--formats", "npz"], F,
                     f"absurd size: a {L:g} m cube, {kind} packing at r = {r:g}", files={"scene.toml": text},
                     reader=("sgim", "scene.toml"), owner="resource limits")
        incline = tomllib.loads((REPO / "cases/scenes/dda_incline.toml").read_text())
        incline["output"] = {"formats": ["npz"]}
        for key, val in (("simulation.duration", 1e9), ("contact.kn", 1e30), ("material.0.density", 1e-30)):
            doc = copy.deepcopy(incline)
            path = tuple(int(s) if s.isdigit() else s for s in key.split("."))
            _set(doc, path, val)
            if key == "simulation.duration":
                doc["simulation"]["record_every"] = 1.0
            self.add("dda run", ["{d}/scene.toml", "-o", "{d}/out", "--quiet"], F,
                     f"absurd run: cases/scenes/dda_incline.toml with {key} = {val:g}", files={"scene.toml": _dump(doc)},
                     reader=("dda", "scene.toml"), owner="resource limits")
        hang = tomllib.loads((REPO / "cases/scenes/crossval/hang_intact.toml").read_text())
        _absolutise(hang, REPO / "cases/scenes/crossval")
        hang["simulation"]["duration"] = 1e9
        hang["simulation"]["record_every"] = 1.0
        hang["output"] = {"formats": ["npz"]}
        self.add("dda run", ["{d}/scene.toml", "-o", "{d}/out", "--quiet"], F,
                 "absurd run: cases/scenes/crossval/hang_intact.toml with simulation.duration = 1e9",
                 files={"scene.toml": _dump(hang)}, reader=("dda", "scene.toml"), owner="resource limits")
        # studies with an absurd number of cases
        base = "[work]\nseconds = 0.0\n[x]\na = 1.0\nb = 2\nc = 3.0\n"
        head = 'name = "absurd"\nbase = "base.toml"\nengine = "noop"\nresults = ["value"]\n'
        grid = ", ".join(str(float(i)) for i in range(1000))
        for what, body in (
            ("samples = 1000000000", '[sampling]\nmethod = "random"\nsamples = 1000000000\n'
                                     '[parameters]\n"x.a" = { uniform = [0.0, 1.0] }\n'),
            ("realisations = 1000000000", '[parameters]\n"x.b" = { realisations = 1000000000 }\n'),
            ("three grids of 1000 values (1e9 cases)", f'[parameters]\n"x.a" = {{ grid = [{grid}] }}\n'
                                                       f'"x.b" = {{ grid = [{", ".join(map(str, range(1000)))}] }}\n'
                                                       f'"x.c" = {{ grid = [{grid}] }}\n'),
        ):
            self.add("cases study run", ["{d}/study.toml", "-o", "{d}/out", "--quiet"], F, f"absurd study: {what}",
                     files={"study.toml": head + body, "base.toml": base}, reader=("study", "study.toml"),
                     owner="study reader")

    # -- a cheap study (engine noop): its values run for real ---------------------------------------------
    def noop_study(self):
        base = "[work]\nseconds = 0.0\n[x]\na = 1.0\nb = 2\n"
        doc0 = {"name": "fuzz", "base": "base.toml", "engine": "noop", "results": ["value"], "seed": 3,
                "timeout": 60.0, "parameters": {"x.a": {"uniform": [0.5, 1.5]}, "x.b": {"grid": [1, 2]}},
                "sampling": {"method": "lhs", "samples": 2}}
        for path, orig in _walk_numbers(doc0):
            for vc in VALUES:
                doc = copy.deepcopy(doc0)
                new = mutated_value(orig, vc)
                _set(doc, path, new)
                self.add("cases study run", ["{d}/study.toml", "-o", "{d}/out", "--quiet"], classify(path, vc),
                         f"noop study: {_dotted(path)} = {orig!r} -> {new!r}",
                         files={"study.toml": _dump(doc), "base.toml": base}, reader=("study", "study.toml"),
                         owner="study reader")

    # -- dda wedge ------------------------------------------------------------------------------------------
    def wedge(self):
        base = ["--joint", "45/5", "--joint", "55/135", "--face", "65/65", "--height", "10", "--friction", "25",
                "--quiet"]
        defaults = {"--height": 10.0, "--friction": 25.0, "--unit-weight": 25.5, "--tolerance": 0.05, "--step": 2.0,
                    "--duration": 1.5, "--kn": 1e9, "--penetration": 1e-5}
        for flag, orig in defaults.items():
            for vc in VALUES:
                v = mutated_value(orig, vc)
                args = _with_flag(base, flag, repr(v) if isinstance(v, float) else str(v))
                if flag in ("--height", "--friction", "--unit-weight"):
                    args = args + ["--analytical-only"]
                self.add("dda wedge", args, M if vc == "tiny" else F, f"dda wedge {flag} {v!r}", out=None,
                         owner="dda wedge options", engine="--analytical-only" not in args)
        for flag, text, expect in (("--joint", "45", F), ("--joint", "a/b", F), ("--joint", "100/5", F),
                                   ("--joint", "nan/5", F), ("--joint", "45/nan", F), ("--joint", "inf/5", F),
                                   ("--joint", "45/1e308", F), ("--joint", "-10/5", F), ("--face", "65/-5", F),
                                   ("--face", "", F), ("--face", "65/65/65", F), ("--top", "1e308/0", F),
                                   ("--face", "0/0", M), ("--top", "10/200", M)):
            args = _with_flag(base, flag, text) + ["--analytical-only"]
            self.add("dda wedge", args, expect, f"dda wedge {flag} {text!r}", out=None, owner="dda wedge options")
        self.add("dda wedge", ["--joint", "45/5", "--face", "65/65", "--height", "10", "--friction", "25",
                               "--analytical-only", "--quiet"], F, "dda wedge with one --joint", out=None,
                 owner="dda wedge options")
        self.add("dda wedge", base + ["--joint", "30/90", "--analytical-only"], F, "dda wedge with three --joint",
                 out=None, owner="dda wedge options")
        self.add("dda wedge", base + ["--analytical-only"], M, "dda wedge, valid (analytical only)", out=None,
                 owner="dda wedge options")

    def other(self):
        # sgim dfn of scenes without a fracture network; adapters export to an unknown target
        for rel in ("cases/scenes/crossval/hang_joint_model.toml", "cases/scenes/studies/scenes/excavation_plane.toml"):
            doc = tomllib.loads((REPO / rel).read_text())
            self.add("sgim dfn", ["{d}/scene.toml", "-o", "{d}/out", "--quiet"], F, f"{rel}: no fracture network",
                     files={"scene.toml": _dump(doc)}, reader=("sgim", "scene.toml"), owner="sgim dfn")
        self.add("adapters export", [str(REPO / "cases/scenes/crossval/hang_joint_model.toml"), "--to", "pfc", "-o",
                                     "{d}/out", "--quiet"], F, "adapters export --to pfc (unknown target)",
                 owner="adapters export options")
        for flag, v in (("--duration", "nan"), ("--duration", "-1"), ("--dt", "0"), ("--dt", "inf"),
                        ("--record-every", "-inf")):
            self.add("adapters export", ["{d}/model.npz", "--to", "vtu", "-o", "{d}/out", "--quiet", f"{flag}={v}"], F,
                     f"adapters export {flag} {v}", files={"model.npz": self.files["model.npz"]},
                     owner="adapters export options")
        noop = ('name = "fuzz"\nbase = "base.toml"\nengine = "noop"\nresults = ["value"]\n'
                '[parameters]\n"x.a" = { grid = [1.0, 2.0] }\n')
        for v in ("0", "-1", "nan", "inf", "1e308"):
            self.add("cases study run", ["{d}/study.toml", "-o", "{d}/out", "--quiet", f"--timeout={v}"], F,
                     f"cases study run --timeout {v}", files={"study.toml": noop, "base.toml": "[x]\na = 1.0\n"},
                     owner="cases study options")
        for what, path in (("a missing scene file", "{d}/nothing.toml"), ("a folder as scene", "{d}")):
            self.add("sgim build", [path, "-o", "{d}/out", "--quiet"], F, f"sgim build of {what}",
                     owner="scene readers")
            self.add("dda run", [path, "-o", "{d}/out", "--quiet"], F, f"dda run of {what}", owner="scene readers")
            self.add("cases study run", [path, "-o", "{d}/out", "--quiet"], F, f"cases study run of {what}",
                     owner="study reader")


def _required(kind, doc, path):
    p = _pattern(path)
    if kind == "sgim":
        req = {"domain", "domain.min", "domain.max", "packing", "discontinuity.*.centre", "discontinuity.*.radius",
               "discontinuity.*.dip", "discontinuity.*.dip_direction", "excavation.*.points", "excavation.*.vertices",
               "excavation.*.faces", "cavity.*.path", "cavity.*.width", "cavity.*.height", "cavity.*.vertices",
               "cavity.*.faces", "cavity.*.shape", "joint_set.*.p32", "joint_set.*.dip", "joint_set.*.radius",
               "packing.distribution.sizes", "packing.distribution.law", "packing.grading.fine_radius"}
        if doc.get("packing", {}).get("kind") != "random":
            req |= {"packing.radius"}
        return p in req
    if kind == "dda":
        return p in {"simulation", "simulation.duration", "contact", "contact.kn", "spheres.model", "block.*.size",
                     "block.*.shape", "generate.*.kind", "material.*.name"}
    return p in {"base", "engine", "sampling.samples"} or (p.startswith("parameters.") and path[-1] in
                                                            ("uniform", "normal", "fisher", "grid", "realisations"))


def _short(v, limit=60):
    t = repr(v)
    return t if len(t) <= limit else t[:limit - 3] + "..."


def _with_flag(args, flag, value):
    """`args` with `flag` set to `value` (as --flag=VALUE, so that a value like -inf is not read as an option)."""
    out = list(args)
    if flag in out:
        i = out.index(flag)
        del out[i:i + 2]
        out[i:i] = [f"{flag}={value}"]
    else:
        out.append(f"{flag}={value}")
    return out


# --------------------------------------------------------------------------------------------- meshes
BOX_FACES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                      [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])


def _box(lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    return np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                     [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)


def _obj(v, f, fmt=repr):
    return "".join(f"v {fmt(a)} {fmt(b)} {fmt(c)}\n" for a, b, c in v) + "".join(
        "f " + " ".join(str(i + 1) for i in row) + "\n" for row in f)


def _stl(v, f):
    out = ["solid s"]
    for a, b, c in f:
        out += ["facet normal 0 0 0", "outer loop", *(f"vertex {x!r} {y!r} {z!r}" for x, y, z in v[[a, b, c]]),
                "endloop", "endfacet"]
    return "\n".join(out + ["endsolid s"]) + "\n"


def mesh_files(np_rng):
    """{mesh name: (file name, contents)}: small meshes inside the host domain [0, 2]^3, and broken ones."""
    v = _box((0.6, 0.6, 0.6), (1.4, 1.4, 1.4))
    tri = np.array([[0.3, 0.3, 1.0], [1.7, 0.3, 1.1], [1.0, 1.7, 0.9]])
    quads = "".join(f"v {a} {b} {c}\n" for a, b, c in v)
    quads += "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n"
    return {
        "triangle": ("triangle.obj", _obj(tri, [[0, 1, 2]])),
        "open_box": ("open_box.obj", _obj(v, BOX_FACES[[0, 1, 4, 5, 6, 7, 8, 9, 10, 11]])),
        "inverted_box": ("inverted_box.stl", _stl(v, BOX_FACES[:, ::-1])),
        "box": ("box.obj", _obj(v, BOX_FACES)),
        "degenerate": ("degenerate.obj", _obj(np.array([[0.2, 0.2, 1.0], [1.0, 1.0, 1.0], [1.8, 1.8, 1.0]]),
                                              [[0, 1, 2]])),
        "garbage": ("garbage.stl", bytes(np_rng.integers(0, 256, 400, dtype=np.uint8))),
        "empty_obj": ("empty.obj", ""),
        "empty_stl": ("empty.stl", b""),
        "nan": ("nan.obj", _obj(v, BOX_FACES).replace("v 0.6 0.6 0.6", "v nan 0.6 0.6", 1)),
        "huge": ("huge.obj", _obj(_box((-1e308, -1e308, -1e308), (1e308, 1e308, 1e308)), BOX_FACES)),
        "tiny": ("tiny.obj", _obj(_box((1.0, 1.0, 1.0), (1.0 + 1e-300, 1.0 + 1e-300, 1.0 + 1e-300)), BOX_FACES)),
        "outside": ("outside.obj", _obj(_box((100.0, 100.0, 100.0), (101.0, 101.0, 101.0)), BOX_FACES)),
        "quads": ("quads.obj", quads),
        "bad_index": ("bad_index.obj", _obj(tri, [[0, 1, 2]]) + "f 1 2 99\n"),
        "broken_stl": ("broken.stl", "solid s\nfacet normal 0 0 1\nouter loop\nvertex 1 2\nvertex 0 0 0\n"),
    }


# --------------------------------------------------------------------------------------------- corrupt npz
def _npz_bytes(arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def corrupt_npz(data, kind, np_rng):
    """(what, bytes) corruptions of a valid model.npz / run.npz."""
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    n = len(arrays["radii"])
    out = [
        ("truncated to half", data[: len(data) // 2]),
        ("truncated to 64 bytes", data[:64]),
        ("empty", b""),
        ("garbage bytes", bytes(np_rng.integers(0, 256, 2000, dtype=np.uint8))),
        ("a text file", b"this is not an npz archive\n"),
        ("a single .npy", (lambda b: (np.save(b, arrays["radii"]), b.getvalue())[1])(io.BytesIO())),
    ]

    def edit(what, **changes):
        a = dict(arrays)
        for k, v in changes.items():
            if v is None:
                a.pop(k, None)
            else:
                a[k] = v
        out.append((what, _npz_bytes(a)))

    c = arrays["centers"].copy()
    c[n // 2, 1] = np.nan
    edit("without radii", radii=None)
    edit("without centers", centers=None)
    edit("with a NaN centre", centers=c)
    edit("with a negative radius", radii=np.where(np.arange(n) == 3, -1.0, arrays["radii"]))
    edit("with radii one short", radii=arrays["radii"][:-1])
    edit("with centers of two columns", centers=arrays["centers"][:, :2])
    edit("with radii as text", radii=np.array(["a"] * n))
    edit("with an object array (pickled)", radii=np.array([1, "x"] * (n // 2) + [1] * (n % 2), dtype=object))
    if kind == "model":
        b = arrays["bonds"].copy()
        if len(b):
            b[0, 1] = n + 5
        edit("with a bond to a sphere out of range", bonds=b)
        edit("with meta not JSON", meta=np.array("{not json"))
    else:
        edit("with a header not JSON", header=np.array("{not json"))
        h = json.loads(str(arrays["header"]))
        edit("with dt = 0 in the header", header=np.array(json.dumps({**h, "dt": 0.0})))
        edit("with duration = NaN in the header", header=np.array(json.dumps({**h, "duration": float("nan")})))
        bi = arrays["bond_i"].copy()
        if len(bi):
            bi[0] = n + 7
        edit("with a bond to a sphere out of range", bond_i=bi)
    return out


# --------------------------------------------------------------------------------------------- running
@dataclass
class Outcome:
    rc: int | None  # None: killed at the time limit
    out: str
    err: str
    how: str  # "in a worker", "in a worker (run)", "subprocess", "accepted (not run)"
    seconds: float = 0.0


def _write_files(case, d):
    if d.exists():
        shutil.rmtree(d)
    d.mkdir(parents=True)
    for name, content in case.files.items():
        p = d / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, str):
            p.write_text(content, encoding="utf-8")
        else:
            p.write_bytes(content)


def _reader_refuses(case, d):
    """True when the case's reader (scene, DDA scene or study) raises on the input: the command then stops in
    validation too. False when it accepts (or the case names no reader)."""
    if case.reader is None:
        return False
    kind, name = case.reader
    path = d / name
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            if kind == "sgim":
                from sgim.scene import load_scene

                load_scene(path)
            elif kind == "dda":
                from dda.scene import load_scene

                load_scene(path)
            else:
                from cases.lib.study import load_study

                load_study(path)
    except Exception:  # noqa: BLE001 - a refusal, or a crash the command will show
        return True
    return False


def _show_warning(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _interpreter_warnings():
    """The warning filters of a fresh interpreter (a new registry version: each case sees its warnings once)."""
    warnings.resetwarnings()
    warnings.filterwarnings("default", category=DeprecationWarning, module="__main__", append=True)
    for cat in (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning):
        warnings.filterwarnings("ignore", category=cat, append=True)
    warnings.showwarning = _show_warning


def run_main_captured(case, d):
    """(exit status, stdout, stderr, seconds) of the command's main(argv) in this process, file descriptors 1 and
    2 captured (what C code writes too), an uncaught exception printed as the interpreter would."""
    main = _main(case.command)
    paths = (d / ".stdout", d / ".stderr")
    saved = (os.dup(1), os.dup(2))
    old = (sys.stdout, sys.stderr)
    for fd, path in zip((1, 2), paths):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(f, fd)
        os.close(f)
    sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), write_through=True)
    sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), write_through=True)
    _interpreter_warnings()
    t0 = time.perf_counter()
    try:
        rc = main(case.argv(d))
    except SystemExit as exc:
        rc = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # noqa: BLE001 - what the interpreter would print
        traceback.print_exc()
        rc = 1
    finally:
        seconds = time.perf_counter() - t0
        sys.stdout.flush()
        sys.stderr.flush()
        sys.stdout, sys.stderr = old
        for fd, s in zip((1, 2), saved):
            os.dup2(s, fd)
            os.close(s)
    out, err = (p.read_text(errors="replace") for p in paths)
    for p in paths:
        p.unlink()
    return rc, out, err, seconds


def _vm_size():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


_MSG = struct.Struct("<I")
_PARENT_FDS = set()  # the parent's ends of the workers' pipes: a worker forked later must not hold them


def _send(fd, obj):
    data = pickle.dumps(obj)
    _write_all(fd, _MSG.pack(len(data)) + data)


def _write_all(fd, data):
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _recv(fd):
    head = _read_exact(fd, _MSG.size)
    if head is None:
        return None
    return pickle.loads(_read_exact(fd, _MSG.unpack(head)[0]))


def _read_exact(fd, n):
    buf = b""
    while len(buf) < n:
        chunk = os.read(fd, n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


class Worker:
    """A forked child (own process group, memory limit) that runs cases on request:
    ("check", i): write the case's files; when its reader refuses, run the command -> ("done", result); when the
    reader accepts -> ("accepted", None); ("run", i): run the command -> ("done", result). The parent kills a
    worker whose case passes the time limit and starts another."""

    def __init__(self, cases, root):
        from_parent, to_child = os.pipe()
        from_child, to_parent = os.pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            for fd in (to_child, from_child, *_PARENT_FDS):
                os.close(fd)
            try:
                os.setpgid(0, 0)
                limit = _vm_size() + (4 << 30)
                resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
                while True:
                    msg = _recv(from_parent)
                    if msg is None:
                        break
                    mode, i = msg
                    case = cases[i]
                    d = root / case.num
                    if not d.exists():
                        _write_files(case, d)
                    if mode == "check":
                        if not _reader_refuses(case, d):
                            _send(to_parent, ("accepted", None))
                            continue
                    _send(to_parent, ("done", run_main_captured(case, d)))
            finally:
                os._exit(0)
        os.close(from_parent)
        os.close(to_parent)
        _PARENT_FDS.update((to_child, from_child))
        self.pid, self.w, self.r = pid, to_child, from_child
        self.task, self.t0 = None, 0.0

    def submit(self, task):
        self.task, self.t0 = task, time.perf_counter()
        _send(self.w, task)

    def kill(self):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(self.pid, 0)
        self._close_fds()

    def close(self):
        os.close(self.w)
        _PARENT_FDS.discard(self.w)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(self.pid, 0)
        os.close(self.r)
        _PARENT_FDS.discard(self.r)

    def _close_fds(self):
        for fd in (self.w, self.r):
            os.close(fd)
            _PARENT_FDS.discard(fd)


TASK_SECONDS = {}


def run_pool(cases, root, tasks, how):
    """Run [(mode, i)] on JOBS workers; returns {i: ("accepted", None) | ("done", Outcome)}."""
    results, queue, workers = {}, list(tasks), []
    try:
        while queue or any(w.task for w in workers):
            while len(workers) < JOBS:
                workers.append(Worker(cases, root))
            for w in workers:
                if w.task is None and queue:
                    w.submit(queue.pop(0))
            busy = [w for w in workers if w.task is not None]
            ready, _, _ = select.select([w.r for w in busy], [], [], 0.05)
            for w in busy:
                mode, i = w.task
                if w.r in ready:
                    msg = _recv(w.r)
                    if msg is None:  # the worker died (a crash of the interpreter)
                        results[i] = ("done", Outcome(-1, "", "(the process died)", how, time.perf_counter() - w.t0))
                        workers.remove(w)
                        w.kill()
                        continue
                    kind, value = msg
                    results[i] = (kind, Outcome(value[0], value[1], value[2], how, value[3]) if value else None)
                    TASK_SECONDS[(mode, i)] = time.perf_counter() - w.t0
                    w.task = None
                elif time.perf_counter() - w.t0 > TIMEOUT:
                    results[i] = ("done", Outcome(None, "", "", how, time.perf_counter() - w.t0))
                    workers.remove(w)
                    w.kill()
    finally:
        for w in workers:
            w.close()
    return results


def leftovers(case, d):
    """Output the command left behind (its output path, temporary .NAME.part* folders)."""
    if case.out is None:
        return []
    out = d / case.out
    found = [out] if out.exists() else []
    found += sorted(out.parent.glob(f".{out.name}.*"))
    return [str(p.relative_to(d)) for p in found]


def judge(case, res, d):
    """Problems with the outcome (empty: as expected)."""
    prog = PROG[case.command]
    if res.rc is None:
        return [f"still running after {TIMEOUT:g} s (killed): the input was accepted and run"]
    lines = res.err.splitlines()
    left = leftovers(case, d)

    def refused_cleanly():
        p = []
        if res.rc != 2:
            p.append(f"exit status {res.rc}, expected 2")
        if "Traceback" in res.err:
            p.append("a traceback on stderr")
        if len(lines) != 1:
            p.append(f"{len(lines)} lines on stderr, expected exactly one")
        elif not lines[0].startswith(prog + ":"):
            p.append(f"the stderr line does not start with {prog + ':'!r}")
        elif case.command != "dda wedge" and not lines[0].startswith(prog + ": error: "):
            p.append(f"the stderr line does not start with {prog + ': error: '!r}")
        if left:
            p.append(f"left behind: {', '.join(left)}")
        return p

    if case.expect == F:
        return refused_cleanly()
    if res.rc == 2:
        return refused_cleanly()
    if "Traceback" in res.err:
        return [f"exit status {res.rc} with a traceback on stderr"]
    if res.rc == 0:
        if case.out is not None and not (d / case.out / DONE_FILE[case.command]).exists():
            return [f"exit status 0 but no {case.out}/{DONE_FILE[case.command]}"]
        if case.out is None and not res.out.strip():
            return ["exit status 0 but nothing on stdout"]
        return []
    if res.rc == 3 and case.command == "dda run" and (d / case.out / "summary.json").exists():
        return []  # a valid run that blew up: the last good state is written, status 3
    return [f"exit status {res.rc} (expected 0, or 2 with one line)"]


def report_case(case, res, problems, d):
    files = []
    for name, content in case.files.items():
        if isinstance(content, str) and len(content) <= 1500:
            files.append(f"    --- {name} ---\n" + "\n".join("    " + ln for ln in content.splitlines()))
        else:
            files.append(f"    --- {name}: {len(content)} bytes (in {d}) ---")
    return (f"[{case.cid}] {case.command} ({'must fail' if case.expect == F else 'may succeed'}; "
            f"{case.owner}): {'; '.join(problems)}\n"
            f"  input: {case.desc}\n"
            f"  argv: {PROG[case.command].split()[0]} {' '.join(case.argv(d))}\n"
            f"  ran {res.how} in {res.seconds:.2f} s; exit {res.rc}\n"
            f"  stderr: {res.err[-1500:]!r}\n  stdout: {res.out[-300:]!r}\n"
            f"  reproduce: FUZZ_SEED={SEED} FUZZ_ONLY={case.num}- pytest -s tests/test_fuzz.py\n"
            + "\n".join(files[:3]))


# --------------------------------------------------------------------------------------------- fixtures
HOST_MODEL = """\
name = "tiny"
[domain]
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
[packing]
kind = "cubic"
radius = 0.1
[[discontinuity]]
centre = [0.5, 0.5, 0.5]
dip = 60.0
dip_direction = 30.0
radius = 2.0
[[excavation]]
points = [[-1.0, -1.0, 0.95], [2.0, -1.0, 0.9], [2.0, 2.0, 0.95], [-1.0, 2.0, 0.85]]
[output]
formats = ["npz"]
"""


WARM_SCENE = """\
name = "warm"
[domain]
min = [0.0, 0.0, 0.0]
max = [2.0, 2.0, 2.0]
[packing]
kind = "cubic"
radius = 0.1
[[excavation]]
points = [[-1.0, -1.0, 1.9], [3.0, -1.0, 1.8], [3.0, 3.0, 1.9], [-1.0, 3.0, 1.7]]
rule = "exact"
[[cavity]]
shape = "ellipsoid"
centre = [1.0, 1.0, 1.0]
radius = 0.4
segments = 12
[[discontinuity]]
vertices = [[-1.0, -1.0, 0.5], [3.0, -1.0, 0.6], [3.0, 3.0, 0.7], [-1.0, 3.0, 0.6]]
faces = [[0, 1, 2], [0, 2, 3]]
thickness = 0.2
[[discontinuity]]
centre = [1.0, 1.0, 1.2]
dip = 60.0
dip_direction = 30.0
radius = 3.0
[output]
formats = ["npz"]
"""


def _dda_engines_cached():
    """Whether accepted may-succeed `dda run` cases run for real: FUZZ_DDA_RUNS=1 / 0, or (auto, the default) when
    numba's cache holds the block, sphere and coupled engines' kernels, as in a run of the whole suite or any run
    after one. From a cold cache they take minutes to compile, which the refusals never need."""
    env = os.environ.get("FUZZ_DDA_RUNS", "auto")
    if env in ("0", "1"):
        return env == "1"
    try:
        from dda import _coupled, _integrate, _spheres

        return all(os.path.exists(f._cache._cache_file._index_path)
                   for f in (_integrate.run_chunk, _spheres.run_spheres, _coupled.run_coupled))
    except Exception:  # noqa: BLE001 - another numba: decide for the cold case
        return False


@pytest.fixture(scope="module")
def valid_files(tmp_path_factory):
    """A valid model.npz, and a LIGGGHTS deck of it (run.npz, deck.json, data, in), written by the commands.

    Also the warm-up of this process, which the workers are forked from: every reader once on every scene in
    cases/, and small builds, DFNs and runs, so that imports and the numba kernels (compiled, or loaded from
    numba's cache) are paid for once, not in every worker."""
    from adapters.cli import main as adapters_main
    from dda.cli import main as dda_main
    from sgim.cli import main as sgim_main

    root = tmp_path_factory.mktemp("fuzz_valid")
    dda_runs = _dda_engines_cached()
    (root / "tiny.toml").write_text(HOST_MODEL)
    (root / "warm.toml").write_text(WARM_SCENE)
    incline = tomllib.loads((REPO / "cases/scenes/dda_incline.toml").read_text())
    _shrink_dda(incline, {})
    (root / "incline.toml").write_text(_dump(incline))
    hang = tomllib.loads((REPO / "cases/scenes/crossval/hang_joint.toml").read_text())
    _absolutise(hang, REPO / "cases/scenes/crossval")
    _shrink_dda(hang, {})
    (root / "hang.toml").write_text(_dump(hang))
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
            warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert sgim_main(["build", str(root / "tiny.toml"), "-o", str(root / "model"), "--quiet"]) == 0
        assert adapters_main(["export", str(root / "model/model.npz"), "--to", "liggghts", "-o", str(root / "deck"),
                              "--quiet", "--duration", "0.001"]) == 0
        assert sgim_main(["build", str(root / "warm.toml"), "-o", str(root / "warm"), "--quiet"]) == 0
        assert sgim_main(["dfn", str(REPO / "cases/scenes/studies/scenes/open_pit_dfn_small.toml"), "-o",
                          str(root / "dfn"), "--quiet"]) == 0
        if dda_runs:
            assert dda_main(["run", str(root / "incline.toml"), "-o", str(root / "incline"), "--quiet"]) == 0
            assert dda_main(["run", str(root / "hang.toml"), "-o", str(root / "hang"), "--quiet"]) == 0
        for name in ("incline", "hang"):  # the step limit's refusal sets the engines up without stepping them
            assert dda_main(["run", str(root / f"{name}.toml"), "-o", str(root / f"{name}_long"), "--quiet",
                             "--max-steps", "1"]) == 2
        for p in sorted({p for g in SCENE_GLOBS for p in REPO.glob(g)}):
            case = Case("warm", "sgim build", [], M, "", reader=(_kind(tomllib.loads(p.read_text())), p.name))
            assert not _reader_refuses(case, p.parent), p
    deck = {p.name: p.read_bytes() for p in (root / "deck").iterdir() if p.is_file()}
    return {"model.npz": (root / "model/model.npz").read_bytes(), "run.npz": deck["run.npz"], "deck": deck,
            "dda_runs": dda_runs}


def generate(valid_files, seed=SEED):
    g = Generator(seed, valid_files)
    g.scenes()
    g.random_packings()
    g.noop_study()
    g.meshes()
    g.corrupt_files()
    g.absurd()
    g.wedge()
    g.other()
    return g.cases


def test_fuzz(valid_files, tmp_path):
    t_start = time.perf_counter()
    cases = generate(valid_files)
    total = len(cases)
    per_command = Counter(c.command for c in cases)
    if ONLY:
        cases = [c for c in cases if ONLY in c.cid]
    rng = random.Random(SEED + 1)
    # 1. must-fail cases run their command (a refusal comes in validation; an input accepted by mistake runs until
    # the time limit); may-succeed cases with a reader run it first, and their command when it refuses
    skipped = [i for i, c in enumerate(cases) if c.expect == M and c.engine and not valid_files["dda_runs"]]
    tasks = [("run" if c.expect == F or c.reader is None else "check", i) for i, c in enumerate(cases)
             if i not in skipped]
    first = run_pool(cases, tmp_path, tasks, "in a worker")
    outcomes = {i: r for i, (kind, r) in first.items() if kind == "done"}
    outcomes.update({i: Outcome(0, "", "", "accepted (not run)") for i in skipped})
    accepted = [i for i, (kind, _) in first.items() if kind == "accepted"]
    # 2. a seeded sample of the accepted may-succeed cases of cheap scenes runs for real
    may = [i for i in accepted if cases[i].cheap]
    chosen = sorted(may if ONLY else rng.sample(may, min(RUN_VALID, len(may))))
    if not valid_files["dda_runs"]:  # a cold numba cache: the engines are not compiled for these
        chosen = [i for i in chosen if cases[i].command != "dda run"]
    second = run_pool(cases, tmp_path, [("run", i) for i in chosen], "in a worker (valid run)")
    outcomes.update({i: r for i, (_, r) in second.items()})
    for i in accepted:
        outcomes.setdefault(i, Outcome(0, "", "", "accepted (not run)"))
    t_pool = time.perf_counter() - t_start
    failures, failed = [], set()
    for i, res in sorted(outcomes.items()):
        if res.how == "accepted (not run)":
            continue
        d = tmp_path / cases[i].num
        problems = judge(cases[i], res, d)
        if problems:
            failures.append(report_case(cases[i], res, problems, d))
            failed.add(cases[i].num)
    # 3. a sample through the real executables
    sub = _subprocess_sample(cases, outcomes, rng, tmp_path)
    sub_failures = []
    for case, res in sub:
        d = tmp_path / case.num
        problems = judge(case, res, d)
        if problems:
            sub_failures.append(report_case(case, res, problems, d))
            failed.add(case.num)
    for case in cases:  # the folders of the failing cases stay for a look
        if case.num not in failed:
            shutil.rmtree(tmp_path / case.num, ignore_errors=True)
    how = Counter(r.how for r in outcomes.values())
    per_owner = Counter(cases[i].owner for i in outcomes)
    summary = (f"fuzz seed {SEED} (FUZZ_SEED): {total} cases generated, {len(cases)} run"
               + (f" (FUZZ_ONLY={ONLY!r})" if ONLY else "") + "; per command: "
               + ", ".join(f"{k} {v}" for k, v in sorted(per_command.items()))
               + f"; must fail {sum(c.expect == F for c in cases)}, may succeed {sum(c.expect == M for c in cases)}"
               + f"; reader accepted {len(accepted)} (valid dda runs "
               + ("on" if valid_files["dda_runs"] else "off: the engines are not in numba's cache, FUZZ_DDA_RUNS=1")
               + "); ran: " + ", ".join(f"{k} {v}" for k, v in sorted(how.items()))
               + f"; {len(sub)} as subprocesses; by area: "
               + ", ".join(f"{k} {v}" for k, v in sorted(per_owner.items()))
               + f"; {t_pool:.1f} s in workers, {time.perf_counter() - t_start:.1f} s in all")
    print("\n" + summary)
    slow = sorted(TASK_SECONDS.items(), key=lambda kv: -kv[1])[:8]
    print("slowest: " + ", ".join(f"{mode} {cases[i].cid} {t:.2f} s" for (mode, i), t in slow))
    if os.environ.get("FUZZ_PROFILE"):
        groups = Counter()
        for (mode, i), t in TASK_SECONDS.items():
            groups[cases[i].desc.split(":")[0][:50] + " / " + mode] += t
        for k, t in groups.most_common(25):
            print(f"  {t:7.2f} s  {k}")
    for f in failures + sub_failures:
        print(f)
    assert not failures and not sub_failures, (
        f"{summary}\n{len(failures)} worker and {len(sub_failures)} subprocess cases broke the contract:\n"
        + "\n".join(failures[:40] + sub_failures))


def _subprocess_sample(cases, outcomes, rng, root):
    """N_SUBPROCESS must-fail cases (one per command first) run through the real executables, two at a time."""
    bindir = Path(sys.executable).parent
    pool = [cases[i] for i, r in sorted(outcomes.items()) if cases[i].expect == F and r.rc is not None
            and r.how != "accepted (not run)"]
    rng.shuffle(pool)
    picked, seen = [], set()
    for c in pool:
        if c.command not in seen:
            picked.append(c)
            seen.add(c.command)
    picked += [c for c in pool if c not in picked][: max(0, N_SUBPROCESS - len(picked))]
    queue, running, results = picked[:N_SUBPROCESS], [], []
    while queue or running:
        while queue and len(running) < JOBS:
            case = queue.pop(0)
            d = root / case.num
            for left in leftovers(case, d):
                shutil.rmtree(d / left, ignore_errors=True)
            prog = PROG[case.command].split()[0]
            exe = bindir / prog
            cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", f"{prog}.cli"]
            p = subprocess.Popen(cmd + case.argv(d), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 start_new_session=True)
            running.append((case, p, time.perf_counter()))
        time.sleep(0.01)
        for item in list(running):
            case, p, t0 = item
            killed = False
            if p.poll() is None:
                if time.perf_counter() - t0 < TIMEOUT * 2:
                    continue
                os.killpg(p.pid, signal.SIGKILL)
                killed = True
            out, err = p.communicate()
            running.remove(item)
            results.append((case, Outcome(None if killed else p.returncode, out, err, "subprocess",
                                          time.perf_counter() - t0)))
    return results
