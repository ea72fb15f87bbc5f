"""Batch studies: a base scene, parameters to vary, one evaluator per case, one results table.

    cases study run STUDY -o OUTDIR [--timeout S] [--memory-limit MB] [--retry-failed] [--force]
                                    [--new-version] [--reuse-process] [--quiet] [--json]         (serial)
    mpirun -n N cases study run STUDY -o OUTDIR [...]                                            (MPI, mpi4py)
    cases study list STUDY [--json] | --evaluators                                  (the cases, nothing run)
    cases study report OUTDIR [--json]                                              (cases/lib/report.py)

A study file (TOML)::

    name = "wedge_friction"
    base = "../dda_wedge.toml"        # the scene every case starts from (relative to the study file's folder,
                                      # wherever the study file is and whatever the working folder)
    evaluator = "wedge-hb"            # a name in the registry, or "module:function" (`engine` is its former name)
    results = ["fs", "phi_crit"]      # the scalars to collect (the evaluator must return them; not the table's
                                      # own columns case_id, status, error, wall_s, rank, ...)
    units = { phi_crit = "deg" }      # optional: units for the report (the evaluator declares its own)
    seed = 1                          # every random choice comes from numpy's Generator seeded here
    timeout = 600                     # per case [s] (optional; `--timeout` overrides)

    [parameters]                      # dotted paths into the base scene; list items by index
    "contact.friction" = { grid = [15.0, 20.0, 25.0] }          # an axis (grid and list are the same)
    "generate.0.height" = { list = [5.0, 10.0] }
    "contact.kn" = { uniform = [1e9, 1e10] }                     # sampled (random or lhs)
    "contact.damping" = { normal = [0.1, 0.01] }
    "generate.0.joint_a" = { fisher = { dip = 45.0, dip_direction = 5.0, kappa = 40.0 } }
    "dfn.seed" = { realisations = 20 }                           # an axis of 20 fracture-network seeds

    [sampling]
    method = "lhs"                    # "grid" | "random" | "lhs" | "realisations"
    samples = 100                     # random / lhs

The cases are the product of the axes (grid, list, realisations; the first parameter varies slowest) and, for
random / lhs sampling, `samples` draws of the sampled parameters (the same draws at every point of the axes).
Case ids are ``c00000``, ``c00001``, ... in that order: the same study file gives the same cases.
A Fisher parameter points at an orientation: a [dip, dip_direction] pair or a table with `dip` and
`dip_direction` keys. Latin hypercube: one sample per stratum in every dimension (a Fisher orientation is two
dimensions: the angle from the mean pole through its distribution function, and the azimuth).

Evaluators: ``fn(scene_path, case_dir, params) -> {name: scalar}``. The registry (cases/lib/evaluators.py) holds
the framework's ``noop`` / ``sleep`` / ``spin`` (checks and benchmarks) and ``EVALUATORS``.
``evaluator = "module:function"`` loads a user's evaluator (the study file's folder is on the import path); a
module that cannot be imported (missing, a syntax error, an exception while it runs) or a name that is not a
function is refused with one line. Before any case runs, the base scene goes through the evaluator's ``check``
(one line and exit status 2 when it is invalid).
"""
from __future__ import annotations

import argparse
import copy
import hashlib
import itertools
import json
import math
import os
import re
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from statistics import NormalDist

import numpy as np

from adapters.process import EngineError, find_engine
from sgim.common import EXIT_BAD_INPUT, CliError, SceneError, run_command
from sgim.common import progress_printer as _progress
from sgim.geometry import dip_to_normal, normal_to_dip
from sgim.reader import SceneReader, read_toml

from ._batch import Terminated, run_study, world
from .evaluators import BUILTIN, Evaluator, _as_evaluator, _noop, _sleep, _spin, module_file, registry, \
    resolve_evaluator  # noqa: F401 - re-exported
from .report import write_report

STUDY_KEYS = {"name", "description", "base", "evaluator", "engine", "results", "units", "seed", "timeout",
              "parameters", "sampling"}
# the runner's own columns of results.csv (and the prefix of parameter columns): no result may take these names
RESERVED = ("case_id", "status", "error", "wall_s", "rank", "attempt", "version")
METHODS = ("grid", "random", "lhs", "realisations")
AXIS_KINDS = ("grid", "list", "realisations")
SAMPLED_KINDS = ("uniform", "normal", "fisher")
PARAM_KINDS = AXIS_KINDS + SAMPLED_KINDS
MAX_CASES = 1_000_000  # cases per study: each is a row of the table and usually an engine run
MAX_TIMEOUT = 1e9  # s per case (30 years): a deadline beyond the platform's time_t overflowed the runner
MAX_MEMORY_MB = 1e9  # --memory-limit [MB]


# --------------------------------------------------------------------------------------------- evaluators
# the registry lives in cases/lib/evaluators.py (Evaluator, registry, resolve_evaluator; re-exported here)
# --------------------------------------------------------------------------------------------- the study
@dataclass
class Param:
    path: str
    kind: str
    spec: object
    target: str  # "number", "int", "pair", "table-orientation", "string", "bool", "list"


@dataclass
class Case:
    case_id: str
    params: dict  # path -> value (JSON types)


@dataclass
class Study:
    path: Path
    name: str
    base: Path
    base_scene: dict
    engine: str
    results: list
    seed: int
    timeout: float | None
    method: str
    samples: int | None
    params: list
    cases: list = field(default_factory=list)
    needs: tuple = ()
    units: dict = field(default_factory=dict)  # result or parameter -> unit (the evaluator's, then the study's)
    files: list = field(default_factory=list)  # the files the base scene and the parameters name (absolute)
    value_files: dict = field(default_factory=dict)  # a parameter's text value -> the file it names
    description: str = ""

    def to_json(self):
        return {"name": self.name, "description": self.description, "study": str(self.path),
                "base": str(self.base), "evaluator": self.engine, "results": list(self.results), "seed": self.seed,
                "timeout": self.timeout, "method": self.method, "samples": self.samples,
                "parameters": {p.path: {p.kind: p.spec} for p in self.params}, "units": dict(self.units),
                "fingerprint": self.fingerprint(),
                "cases": [{"case_id": c.case_id, "params": c.params} for c in self.cases]}

    def fingerprint(self):
        """{what: sha256 of its bytes}: the study file, the base scene, every file the base scene names and the
        evaluator's module source. A restart compares it with the one in OUTDIR/study.json."""
        def digest(p):
            try:
                return hashlib.sha256(Path(p).read_bytes()).hexdigest()
            except OSError:
                return "unreadable"

        out = {"study file": digest(self.path), "base scene": digest(self.base)}
        for f in self.files:  # named relative to the study file's folder, else the base scene's, else absolute
            rel = str(f)
            for folder in (self.path.parent, self.base.parent):
                try:
                    rel = Path(f).relative_to(folder).as_posix()
                    break
                except ValueError:
                    pass
            out[f"file {rel}"] = digest(f)
        try:
            mod = module_file(resolve_evaluator(self.engine, self.path.parent.resolve()))
        except LookupError:
            mod = None
        if mod is not None:
            out[f"evaluator module {mod.name}"] = digest(mod)
        return out

    def case_scene(self, case):
        """The base scene with the case's values substituted (a dict); a text value naming a file (relative to the
        study file's folder, else to the base scene's) becomes its absolute path."""
        scene = copy.deepcopy(self.base_scene)
        for path, value in case.params.items():
            if isinstance(value, str) and value in self.value_files:
                value = str(self.value_files[value])
            _set_path(scene, path, value)
        return scene

    def case_scene_text(self, case):
        head = f"# study {self.name}, case {case.case_id}: {json.dumps(case.params)}\n"
        return head + dump_toml(self.case_scene(case))


def _segments(path):
    return path.split(".")


def _walk(scene, path):
    """(found, node or (where, segment, keys) for the error)."""
    node, where = scene, "the top level"
    for seg in _segments(path):
        if isinstance(node, dict):
            if seg not in node:
                return False, (where, seg, ", ".join(node) or "nothing")
            node, where = node[seg], f"table {seg!r}"
        elif isinstance(node, list):
            if not re.fullmatch(r"\d+", seg) or int(seg) >= len(node):
                return False, (where, seg, f"indices 0..{len(node) - 1}")
            node, where = node[int(seg)], f"item {seg}"
        else:
            return False, (where, seg, "nothing (a value, not a table)")
    return True, node


def _set_path(scene, path, value):
    node = scene
    segs = _segments(path)
    for seg in segs[:-1]:
        node = node[int(seg)] if isinstance(node, list) else node[seg]
    last = segs[-1]
    key = int(last) if isinstance(node, list) else last
    if isinstance(value, dict) and isinstance(node[key], dict):  # an orientation table
        node[key].update(value)
    else:
        node[key] = value


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _target(value):
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "list"
    if isinstance(value, dict):
        return "table"
    return "other"


def _absolutise(scene, base_dir, found=None):
    """String values naming a file next to the base scene become absolute paths (the case scene lives in
    its own folder); the files go to `found`."""
    found = [] if found is None else found
    if isinstance(scene, dict):
        items = scene.items()
    elif isinstance(scene, list):
        items = enumerate(scene)
    else:
        return found
    for k, v in list(items):
        if isinstance(v, (dict, list)):
            _absolutise(v, base_dir, found)
        elif isinstance(v, str) and v and len(v) < 4096:
            cand = Path(v) if Path(v).is_absolute() else base_dir / v
            try:
                if cand.is_file():
                    scene[k] = str(cand.resolve())
                    if cand.resolve() not in found:
                        found.append(cand.resolve())
            except (OSError, ValueError):
                pass
    return found


def load_study(path, check_engine=True) -> Study:
    """Read and validate a study file; raise SceneError (one line) on any problem. Nothing is run."""
    path = Path(path)
    data, _ = read_toml(path, what="study file")
    rd = SceneReader(path)  # every message: SceneError(path, key, value, message), as in the scene readers
    err = rd.err
    rd.known(data, STUDY_KEYS, "")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name:
        err("name", name, "must be a non-empty string")
    base, base_scene, files = _read_base(path, data, err)
    engine, ev, needs = _read_evaluator(path, data, err, check_engine)
    results, units, seed, timeout = _read_outputs(data, err)

    ptab = data.get("parameters", {})
    if not isinstance(ptab, dict):
        err("parameters", ptab, "must be a table of parameter paths")
    params = []
    for ppath, spec in ptab.items():
        key = f'parameters."{ppath}"'
        params.append(_read_param(err, key, ppath, spec, base_scene, base))
    method, samples = _read_sampling(data, rd, params)

    description = data.get("description", "")
    if not isinstance(description, str):
        err("description", description, "must be a string")
    all_units = {**(dict(ev.units) if ev is not None else {}), **units}
    study = Study(path=path.resolve(), name=name, base=base, base_scene=base_scene, engine=engine, results=results,
                  seed=seed, timeout=float(timeout) if timeout is not None else None, method=method,
                  samples=samples, params=params, needs=tuple(needs), units=all_units, files=files,
                  description=description)
    _find_value_files(study, params, [path.resolve().parent, base.parent], files)
    study.cases = make_cases(study)
    return study


def _read_base(path, data, err):
    """(base scene path, its tables, the files it names) of the study's ``base``."""
    if "base" not in data:
        err("base", None, "missing value (the base scene file, relative to the study file)")
    base_rel = data["base"]
    if not isinstance(base_rel, str):
        err("base", base_rel, "must be a file name")
    # relative to the folder of the study file itself (path.parent is absolute after resolve(): a study copied
    # elsewhere, or run from another working folder, finds its scene beside it)
    base = (path.resolve().parent / base_rel).resolve()
    if not base.is_file():
        near = path.resolve().parent / Path(base_rel).name
        hint = f"; {near.name} is beside the study file: base = \"{near.name}\"?" if near.is_file() else ""
        err("base", base_rel, f"no base scene {base} (relative paths are read from the study file's folder "
                              f"{path.resolve().parent}){hint}")
    try:
        base_scene = tomllib.loads(base.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        err("base", base_rel, f"cannot read the base scene {base} ({exc.__class__.__name__})")
    except tomllib.TOMLDecodeError as exc:
        err("base", base_rel, f"base scene is not valid TOML ({str(exc).splitlines()[0]})")
    return base, base_scene, _absolutise(base_scene, base.parent)


def _read_evaluator(path, data, err, check_engine):
    """(evaluator name, Evaluator or None without `check_engine`, the programs it needs) of the study."""
    if "engine" in data and "evaluator" in data:
        err("engine", data["engine"], "give the evaluator once: `evaluator =` (engine is its former name)")
    ekey = "engine" if "engine" in data else "evaluator"
    engine = data.get(ekey)
    if not isinstance(engine, str) or not engine:
        err("evaluator", engine, "missing or not a string (an evaluator name, see `cases study list --evaluators`, "
                                 "or \"module:function\")")
    needs = ()
    ev = None
    if check_engine:
        try:
            ev = resolve_evaluator(engine, path.resolve().parent)
        except LookupError as exc:
            err(ekey, engine, str(exc))
        needs = ev.needs
        for exe in needs:
            try:
                find_engine(exe)
            except EngineError as exc:
                err(ekey, engine, f"needs {exc}")
    return engine, ev, needs


def _read_outputs(data, err):
    """(results, units, seed, timeout) of the study."""
    results = data.get("results", [])
    if not isinstance(results, list) or not all(isinstance(r, str) and r for r in results):
        err("results", results, "must be a list of result names")
    if len(set(results)) != len(results):
        err("results", results, "names must be unique")
    for r in results:
        if r in RESERVED or r.startswith("p:"):
            err("results", r, f"reserved name: the table's own columns are {', '.join(RESERVED)} and p:<parameter> "
                              "(rename the result, e.g. in the evaluator's returned dict)")
        if any(ch in r for ch in ",\"\r\n") or r != r.strip() or len(r.splitlines()) != 1:
            err("results", r, "a result name must be one line without commas or quotes")
    units = data.get("units", {})
    if not isinstance(units, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in units.items()):
        err("units", units, 'must be a table of names and units, e.g. { fs = "-", "contact.kn" = "N/m" }')
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        err("seed", seed, "must be an integer >= 0")
    timeout = data.get("timeout")
    if timeout is not None and (not _is_number(timeout) or not 0 < timeout <= MAX_TIMEOUT):
        err("timeout", timeout, f"must be a number of seconds in (0, {MAX_TIMEOUT:g}]")
    return results, units, seed, timeout


def _read_sampling(data, rd, params):
    """(method, samples) of the study's [sampling] table, checked against its parameters and the case limit."""
    err = rd.err
    samp = data.get("sampling", {})
    if not isinstance(samp, dict):
        err("sampling", samp, "must be a table (method, samples)")
    rd.known(samp, ("method", "samples"), "sampling")
    sampled = [p for p in params if p.kind in SAMPLED_KINDS]
    default_method = "random" if sampled else ("realisations" if any(p.kind == "realisations" for p in params)
                                               else "grid")
    method = samp.get("method", default_method)
    if method not in METHODS:
        err("sampling.method", method, f"must be one of {', '.join(METHODS)}")
    samples = samp.get("samples")
    if method in ("random", "lhs"):
        if samples is None:
            err("sampling.samples", None, f"missing value (the number of {method} samples)")
        if isinstance(samples, bool) or not isinstance(samples, int) or samples <= 0:
            err("sampling.samples", samples, "must be an integer > 0")
        if samples > MAX_CASES:
            err("sampling.samples", samples, f"must be <= {MAX_CASES} (cases)")
        if not sampled:
            err("sampling.method", method, "no sampled parameter (uniform, normal or fisher) to draw")
    else:
        if samples is not None:
            err("sampling.samples", samples, f"only with method random or lhs (method is {method!r})")
        if sampled:
            p = sampled[0]
            err(f'parameters."{p.path}"', {p.kind: p.spec},
                f"a {p.kind} parameter needs [sampling] method = \"random\" or \"lhs\" (method is {method!r})")
        if method == "realisations" and not any(p.kind == "realisations" for p in params):
            err("sampling.method", method, "no { realisations = N } parameter")

    total = math.prod(len(p.spec) if p.kind == "grid" else p.spec for p in params if p.kind in AXIS_KINDS)
    total *= samples if method in ("random", "lhs") else 1
    if total > MAX_CASES:
        err("parameters", f"{total} cases", f"more than {MAX_CASES} cases (the product of the axes"
                                           f"{' and the samples' if method in ('random', 'lhs') else ''})")
    return method, samples


def _find_value_files(study, params, folders, files):
    """Text values of grid / list parameters that name files (in the study's or the base scene's folder): into
    ``study.value_files`` and `files` (the study's inputs)."""
    for p in params:
        for v in (p.spec if p.kind == "grid" else []):
            if isinstance(v, str) and v and len(v) < 4096 and v not in study.value_files:
                for folder in folders:
                    cand = Path(v) if Path(v).is_absolute() else folder / v
                    try:
                        if cand.is_file():
                            study.value_files[v] = cand.resolve()
                            if cand.resolve() not in files:
                                files.append(cand.resolve())
                            break
                    except (OSError, ValueError):
                        pass


def _read_param(err, key, ppath, spec, base_scene, base):
    if not isinstance(ppath, str) or not ppath or any(s == "" for s in _segments(ppath)):
        err(key, spec, "a parameter path must be dotted names (list items by index), e.g. \"contact.friction\"")
    found, node = _walk(base_scene, ppath)
    if not found:
        where, seg, have = node
        err(key, spec, f"unknown parameter path: no {seg!r} in {where} of the base scene {base.name} "
                       f"(has: {have})")
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in PARAM_KINDS:
        err(key, spec, f"must be a table with one of {', '.join(PARAM_KINDS)}")
    kind, val = next(iter(spec.items()))
    target = _target(node)
    if kind in ("grid", "list"):
        if not isinstance(val, list):
            err(key, spec, f"{kind} must be a list of values")
        if not val:
            err(key, spec, f"empty {kind}: give at least one value")
        for v in val:
            if not _compatible(node, v):
                err(key, v, f"does not fit the base scene's value {node!r} ({target})")
            if _is_number(v) and not math.isfinite(v):
                err(key, v, "must be finite (a case with NaN or inf would only fail)")
        if len(val) > MAX_CASES:
            err(key, f"{len(val)} values", f"more than {MAX_CASES} values")
        return Param(ppath, "grid", list(val), target)
    if kind == "realisations":
        if isinstance(val, bool) or not isinstance(val, int) or val <= 0:
            err(key, spec, "realisations must be an integer > 0")
        if val > MAX_CASES:
            err(key, spec, f"realisations must be <= {MAX_CASES} (cases)")
        if target != "int":
            err(key, spec, f"realisations vary a seed: the base scene's value must be an integer, not {node!r}")
        return Param(ppath, "realisations", val, target)
    if kind in ("uniform", "normal"):
        if not (isinstance(val, list) and len(val) == 2 and all(_is_number(x) and math.isfinite(x) for x in val)):
            err(key, spec, f"{kind} must be [{'low, high' if kind == 'uniform' else 'mean, sd'}] (two numbers)")
        if kind == "uniform" and not val[0] < val[1]:
            err(key, spec, "empty range: uniform [low, high] needs low < high")
        if kind == "normal" and not val[1] > 0:
            err(key, spec, "empty range: normal [mean, sd] needs sd > 0")
        if target not in ("number", "int"):
            err(key, spec, f"a {kind} parameter needs a number in the base scene, not {node!r}")
        return Param(ppath, kind, [float(val[0]), float(val[1])], "number")
    # fisher
    if not isinstance(val, dict) or set(val) != {"dip", "dip_direction", "kappa"}:
        err(key, spec, "fisher must be { dip = D, dip_direction = A, kappa = K } (the mean orientation)")
    if not all(_is_number(val[k]) and math.isfinite(val[k]) for k in val):
        err(key, spec, "fisher values must be numbers")
    if not 0 <= val["dip"] <= 90:
        err(key, spec, "fisher dip must be within 0..90 degrees")
    if not val["kappa"] > 0:
        err(key, spec, "fisher kappa must be > 0")
    if isinstance(node, list) and len(node) == 2 and all(_is_number(x) for x in node):
        ftarget = "pair"
    elif isinstance(node, dict) and "dip" in node and "dip_direction" in node:
        ftarget = "table-orientation"
    else:
        err(key, spec, f"a fisher parameter needs an orientation in the base scene ([dip, dip_direction] or a "
                       f"table with dip and dip_direction), not {node!r}")
    return Param(ppath, "fisher", {k: float(val[k]) for k in ("dip", "dip_direction", "kappa")}, ftarget)


def _compatible(base_value, v):
    if _is_number(base_value):
        return _is_number(v)
    if isinstance(base_value, list) and isinstance(v, list):
        return True
    return type(base_value) is type(v)


# --------------------------------------------------------------------------------------------- sampling
def fisher_from_uniform(dip, dip_direction, kappa, u, v):
    """Fisher-distributed orientations from uniform numbers u, v in [0, 1): (dips, dip directions) in degrees.

    The angle θ from the mean pole has P(θ' <= θ) = (1 - exp(-κ (1 - cos θ))) / (1 - exp(-2κ)); the azimuth
    about the pole is uniform. Poles are returned on the upper hemisphere."""
    u, v = np.asarray(u, float), np.asarray(v, float)
    m = dip_to_normal(dip, dip_direction)
    cos_t = 1.0 + np.log1p(-u * (-np.expm1(-2.0 * kappa))) / kappa
    cos_t = np.clip(cos_t, -1.0, 1.0)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    a = np.array([0.0, 0.0, 1.0]) if abs(m[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(m, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(m, e1)
    phi = 2.0 * np.pi * v
    n = (cos_t[:, None] * m[None, :] + sin_t[:, None] * (np.cos(phi)[:, None] * e1[None, :]
                                                           + np.sin(phi)[:, None] * e2[None, :]))
    out = [normal_to_dip(row) for row in n]
    return [d for d, _ in out], [a for _, a in out]


def _unit_draws(rng, method, n, dims):
    """n x dims numbers in [0, 1): plain random, or a Latin hypercube (one per stratum per dimension)."""
    if method == "lhs":
        cols = []
        for _ in range(dims):
            perm = rng.permutation(n)
            cols.append((perm + rng.random(n)) / n)
        return np.column_stack(cols) if cols else np.zeros((n, 0))
    return rng.random((n, dims))


def make_cases(study: Study):
    """The deterministic case list (see the module doc)."""
    rng = np.random.default_rng(study.seed)
    axes = []
    for p in study.params:
        if p.kind == "grid":
            axes.append((p.path, p.spec))
        elif p.kind == "realisations":
            seeds = rng.choice(2**31 - 1, size=p.spec, replace=False) + 1
            axes.append((p.path, [int(s) for s in seeds]))
    draws = [{}]
    sampled = [p for p in study.params if p.kind in SAMPLED_KINDS]
    if study.method in ("random", "lhs"):
        n = study.samples
        dims = sum(2 if p.kind == "fisher" else 1 for p in sampled)
        u = _unit_draws(rng, study.method, n, dims)
        tiny = 2.0**-53
        cols = {}
        j = 0
        for p in sampled:
            if p.kind == "uniform":
                lo, hi = p.spec
                cols[p.path] = [float(lo + (hi - lo) * x) for x in u[:, j]]
                j += 1
            elif p.kind == "normal":
                nd = NormalDist(*p.spec)
                cols[p.path] = [float(nd.inv_cdf(min(max(x, tiny), 1.0 - tiny))) for x in u[:, j]]
                j += 1
            else:
                f = p.spec
                dips, dds = fisher_from_uniform(f["dip"], f["dip_direction"], f["kappa"], u[:, j], u[:, j + 1])
                j += 2
                if p.target == "pair":
                    cols[p.path] = [[float(d), float(a)] for d, a in zip(dips, dds)]
                else:
                    cols[p.path] = [{"dip": float(d), "dip_direction": float(a)} for d, a in zip(dips, dds)]
        draws = [{p.path: cols[p.path][i] for p in sampled} for i in range(n)]
    combos = list(itertools.product(*[vals for _, vals in axes]))
    total = len(combos) * len(draws)
    width = max(5, len(str(total - 1)))
    cases = []
    for combo in combos:
        for d in draws:
            values = {path: v for (path, _), v in zip(axes, combo)}
            values.update(d)
            ordered = {p.path: values[p.path] for p in study.params}
            cases.append(Case(f"c{len(cases):0{width}d}", ordered))
    return cases


# --------------------------------------------------------------------------------------------- TOML writer
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k):
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _is_aot(v):
    return isinstance(v, list) and v and all(isinstance(x, dict) for x in v)


def dump_toml(data: dict) -> str:
    """TOML text for a dict of TOML values (tables, arrays of tables, inline arrays; floats exact)."""
    out = []

    def table(d, prefix):
        for k, v in d.items():
            if not isinstance(v, dict) and not _is_aot(v):
                out.append(f"{_key(k)} = {_value(v)}")
        for k, v in d.items():
            name = prefix + _key(k)
            if isinstance(v, dict):
                out.append("")
                out.append(f"[{name}]")
                table(v, name + ".")
            elif _is_aot(v):
                for item in v:
                    out.append("")
                    out.append(f"[[{name}]]")
                    table(item, name + ".")

    table(data, "")
    return "\n".join(out).lstrip("\n") + "\n"


# --------------------------------------------------------------------------------------------- CLI
def check_base(study):
    """The base scene through the evaluator's own check (once, before any case runs): CliError, one line."""
    ev = resolve_evaluator(study.engine, study.path.parent)
    if ev.check is None:
        return
    try:
        ev.check(study.base)
    except SceneError as exc:
        raise CliError(f"base scene {exc}") from None
    except (CliError, ValueError, KeyError, TypeError, OSError, LookupError) as exc:
        msg = str(exc).strip().splitlines()
        raise CliError(f"base scene {study.base}: {msg[0] if msg else type(exc).__name__} (checked by evaluator "
                       f"{study.engine} before any case runs)") from None


def _options(args):
    """--timeout and --memory-limit checked (CliError, one line): finite positive numbers."""
    t = args.timeout
    if t is not None and not (math.isfinite(t) and 0 < t <= MAX_TIMEOUT):
        raise CliError(f"--timeout: {t!r}: must be a number of seconds in (0, {MAX_TIMEOUT:g}]")
    m = args.memory_limit
    if m is not None and not (math.isfinite(m) and 16 <= m <= MAX_MEMORY_MB):
        raise CliError(f"--memory-limit: {m!r}: must be a number of MB per case in [16, {MAX_MEMORY_MB:g}]")
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CliError(f"{out}: -o = {str(out)!r}: output exists and is not a folder")


def cmd_run(args):
    comm = world()
    rank = comm.rank if comm is not None else 0
    say = _progress(args.quiet or args.json or rank != 0)
    try:
        _options(args)
        study = load_study(args.study)
        check_base(study)
    except (SceneError, CliError) as exc:
        if comm is None:
            raise
        if rank == 0:  # every rank read the same file: rank 0 prints the line, then all stop together
            print(f"cases study: error: {exc}", file=sys.stderr, flush=True)
        comm.Barrier()
        return EXIT_BAD_INPUT
    summary = run_study(study, Path(args.output), timeout=args.timeout, comm=comm, progress=say,
                        retry_failed=args.retry_failed, force=args.force, new_version=args.new_version,
                        memory_mb=args.memory_limit, reuse=args.reuse_process)
    if rank != 0:
        return 0
    f = summary
    if args.json:
        print(json.dumps(summary, indent=1))
    elif not args.quiet:
        print(f"{f['outdir']}/results.csv: {f['done']}/{f['total']} cases ({f['ok']} ok, {f['failed']} failed, "
              f"{f['timeout']} timeout), {f['ran']} run now on {f['ranks']} rank(s) in {f['wall_s']:.2f} s")
    return 0


def cmd_list(args):
    if args.engines:
        for name, ev in sorted(registry().items()):
            needs = f" (needs {', '.join(ev.needs)})" if ev.needs else ""
            print(f"{name:24s} {ev.description}{needs}")
        return 0
    if not args.study:
        raise CliError("study list: give a STUDY file (or --evaluators)")
    study = load_study(args.study)
    if args.json:
        print(json.dumps(study.to_json(), indent=2))
        return 0
    print(f"{study.name}: {len(study.cases)} cases, evaluator {study.engine}, method {study.method}, "
          f"seed {study.seed}")
    for c in study.cases:
        print(f"  {c.case_id}  {json.dumps(c.params)}")
    return 0


def cmd_report(args):
    out = Path(args.outdir)
    if not (out / "study.json").is_file():
        raise CliError(f"{out}: OUTDIR = {str(out)!r}: no study.json (not a study output folder)")
    path, info = write_report(out, with_summary=True)
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        print(path)
    return 0


class _Parser(argparse.ArgumentParser):
    """Bad options in one line (``cases study: error: ...``) and exit status 2."""

    def error(self, message):
        if os.environ.get("OMPI_COMM_WORLD_RANK", os.environ.get("PMI_RANK", "0")) == "0":  # one line under mpirun
            print(f"cases study: error: {self.prog.removeprefix('cases study').strip() or 'study'}: {message} "
                  f"(see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


def make_parser():
    ap = _Parser(prog="cases study", description="Batch studies (serial, or under mpirun).")
    sub = ap.add_subparsers(dest="cmd", required=True, parser_class=_Parser)
    r = sub.add_parser("run", help="run a study (under mpirun: rank 0 hands out cases to all ranks)")
    r.add_argument("study", help="the study file (TOML)")
    r.add_argument("-o", "--output", required=True, help="output folder (a restart skips finished cases)")
    r.add_argument("--timeout", type=float, default=None, help="per-case time limit [s] (overrides the study)")
    r.add_argument("--memory-limit", type=float, default=None, metavar="MB",
                   help="address-space limit of each case [MB] (RLIMIT_AS); a case past it fails with that reason")
    r.add_argument("--retry-failed", action="store_true", help="run failed and timed-out cases again")
    r.add_argument("--reuse-process", action="store_true", help="run the cases one after the other in one process "
                   "per rank instead of a fresh process each (less overhead per case; a case's state, limits and "
                   "crashes then reach the next case)")
    r.add_argument("--force", action="store_true", help="replace a different study's output in the folder (its "
                   "own files only; files added by hand stay); the same study is resumed with or without it")
    r.add_argument("--new-version", action="store_true", help="the study's inputs changed (fingerprint): move the "
                   "earlier tables and cases to OUTDIR/versions/vN/ and run every case again")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    r.add_argument("--json", action="store_true", help="print the run's summary as JSON on stdout")
    r.set_defaults(func=cmd_run)
    ls = sub.add_parser("list", help="the cases of a study (nothing is run)")
    ls.add_argument("study", nargs="?", help="the study file (TOML)")
    ls.add_argument("--json", action="store_true", help="the study and its cases as JSON on stdout")
    ls.add_argument("--evaluators", "--engines", dest="engines", action="store_true", help="list the evaluators")
    ls.set_defaults(func=cmd_list)
    rp = sub.add_parser("report", help="Markdown report with plots of a study's results")
    rp.add_argument("outdir", help="the study's output folder")
    rp.add_argument("--json", action="store_true", help="print the report's summary (files, counts, PoF) as JSON")
    rp.set_defaults(func=cmd_report)
    return ap


def main(argv=None):
    args = make_parser().parse_args(argv)
    try:
        return run_command("cases study", args)
    except KeyboardInterrupt:
        print("cases study: interrupted: the finished cases are in the table (run the same command again to "
              "finish)", file=sys.stderr)
        return 130
    except Terminated:
        print("cases study: terminated (SIGTERM): the finished cases are in the table, the running ones were "
              "stopped (run the same command again to finish)", file=sys.stderr)
        return 143


if __name__ == "__main__":
    sys.exit(main())
