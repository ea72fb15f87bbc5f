"""Batch studies: a base scene, parameters to vary, one evaluator per case, one results table.

    cases study run STUDY -o OUTDIR [--timeout S] [--retry-failed] [--quiet]     (serial)
    mpirun -n N cases study run STUDY -o OUTDIR [...]                              (MPI, mpi4py)
    cases study list STUDY [--json]                                                (the cases, nothing run)
    cases study report OUTDIR                                                      (cases/report.py)

A study file (TOML)::

    name = "wedge_friction"
    base = "../dda_wedge.toml"        # the scene every case starts from (relative to the study file)
    engine = "wedge-hb"               # an evaluator: a name in the registry, or "module:function"
    results = ["fs", "phi_crit"]      # the scalars to collect (the evaluator must return them)
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

Evaluators: ``fn(scene_path, case_dir, params) -> {name: scalar}``. The registry is this module's built-in
``noop`` / ``sleep`` / ``spin`` (framework checks and benchmarks) merged with ``cases.evaluators.EVALUATORS``.
``engine = "module:function"`` loads a user's evaluator (the study file's folder is on the import path).
"""
from __future__ import annotations

import argparse
import copy
import importlib
import itertools
import json
import math
import re
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sgim.cli import EXIT_BAD_INPUT, CliError, _progress, run_command
from sgim.scene import SceneError

STUDY_KEYS = {"name", "description", "base", "engine", "results", "seed", "timeout", "parameters", "sampling"}
METHODS = ("grid", "random", "lhs", "realisations")
AXIS_KINDS = ("grid", "list", "realisations")
SAMPLED_KINDS = ("uniform", "normal", "fisher")
PARAM_KINDS = AXIS_KINDS + SAMPLED_KINDS
MAX_CASES = 1_000_000  # cases per study: each is a row of the table and usually an engine run
MAX_TIMEOUT = 1e9  # s per case (30 years): a deadline beyond the platform's time_t overflowed the runner


# --------------------------------------------------------------------------------------------- evaluators
@dataclass(frozen=True)
class Evaluator:
    """fn(scene_path: Path, case_dir: Path, params: dict) -> dict of scalars; needs: engine executables."""

    fn: object
    needs: tuple = ()
    description: str = ""


def _work(scene_path):
    with open(scene_path, "rb") as fh:
        return tomllib.load(fh).get("work", {})


def _noop(scene_path, case_dir, params):
    """Reads the scene, returns the sum of the numeric parameters (framework overhead)."""
    _work(scene_path)
    total = 0.0
    for v in params.values():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            total += v
    return {"value": total}


def _sleep(scene_path, case_dir, params):
    """Sleeps [work] seconds."""
    s = float(_work(scene_path).get("seconds", 0.1))
    time.sleep(s)
    return {"value": s}


def _spin(scene_path, case_dir, params):
    """A fixed single-core numpy workload: [work] iterations x size elementwise steps (deterministic)."""
    w = _work(scene_path)
    n, size = int(w.get("iterations", 200)), int(w.get("size", 100_000))
    x = np.linspace(0.0, 1.0, size) + float(w.get("offset", 0.0))
    for _ in range(n):
        x = np.sin(x) * 0.999 + 0.01 * np.cos(3.0 * x)
    return {"value": float(x.sum())}


BUILTIN = {
    "noop": Evaluator(_noop, (), "no work: framework overhead"),
    "sleep": Evaluator(_sleep, (), "sleeps [work] seconds"),
    "spin": Evaluator(_spin, (), "fixed CPU workload ([work] iterations, size): scaling benchmark"),
}


def registry():
    """Built-in evaluators merged with cases/evaluators.py EVALUATORS (when that module exists)."""
    reg = dict(BUILTIN)
    try:
        mod = importlib.import_module("cases.evaluators")
    except ModuleNotFoundError as exc:
        if exc.name not in ("cases.evaluators",):
            raise
        return reg
    reg.update(getattr(mod, "EVALUATORS", {}))
    return reg


def _as_evaluator(obj):
    if callable(obj) and not hasattr(obj, "fn"):
        return Evaluator(obj)
    return Evaluator(obj.fn, tuple(getattr(obj, "needs", ()) or ()), getattr(obj, "description", ""))


def resolve_evaluator(name, study_dir=None):
    """The Evaluator for `name`: a registry name or "module:attr" (study_dir on the import path). Raises
    LookupError with a one-line reason."""
    if ":" in name:
        mod_name, _, attr = name.partition(":")
        if study_dir is not None and str(study_dir) not in sys.path:
            sys.path.insert(0, str(study_dir))
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as exc:
            raise LookupError(f"cannot import module {mod_name!r} ({exc})") from None
        if not hasattr(mod, attr):
            raise LookupError(f"module {mod_name!r} has no {attr!r}")
        return _as_evaluator(getattr(mod, attr))
    reg = registry()
    if name not in reg:
        raise LookupError(f"unknown evaluator (known: {', '.join(sorted(reg))}; or 'module:function')")
    return _as_evaluator(reg[name])


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

    def to_json(self):
        return {"name": self.name, "study": str(self.path), "base": str(self.base), "engine": self.engine,
                "results": list(self.results), "seed": self.seed, "timeout": self.timeout, "method": self.method,
                "samples": self.samples, "parameters": {p.path: {p.kind: p.spec} for p in self.params},
                "cases": [{"case_id": c.case_id, "params": c.params} for c in self.cases]}

    def case_scene(self, case):
        """The base scene with the case's values substituted (a dict)."""
        scene = copy.deepcopy(self.base_scene)
        for path, value in case.params.items():
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


def _absolutise(scene, base_dir):
    """String values naming a file next to the base scene become absolute paths (the case scene lives in
    its own folder)."""
    if isinstance(scene, dict):
        items = scene.items()
    elif isinstance(scene, list):
        items = enumerate(scene)
    else:
        return
    for k, v in list(items):
        if isinstance(v, (dict, list)):
            _absolutise(v, base_dir)
        elif isinstance(v, str) and v and not Path(v).is_absolute() and len(v) < 4096:
            cand = base_dir / v
            try:
                if cand.is_file():
                    scene[k] = str(cand.resolve())
            except OSError:
                pass


def load_study(path, check_engine=True) -> Study:
    """Read and validate a study file; raise SceneError (one line) on any problem. Nothing is run."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(path, "(file)", str(path), f"cannot read study file ({exc.__class__.__name__})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "(toml)", str(exc).split("\n")[0], "not valid TOML") from None

    def err(key, value, message):
        raise SceneError(path, key, value, message)

    for k in data:
        if k not in STUDY_KEYS:
            err(k, data[k], f"unknown key (allowed: {', '.join(sorted(STUDY_KEYS))})")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name:
        err("name", name, "must be a non-empty string")
    if "base" not in data:
        err("base", None, "missing value (the base scene file, relative to the study file)")
    base_rel = data["base"]
    if not isinstance(base_rel, str):
        err("base", base_rel, "must be a file name")
    base = (path.parent / base_rel).resolve()
    try:
        base_scene = tomllib.loads(base.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        err("base", base_rel, f"cannot read the base scene {base} ({exc.__class__.__name__})")
    except tomllib.TOMLDecodeError as exc:
        err("base", base_rel, f"base scene is not valid TOML ({str(exc).splitlines()[0]})")
    _absolutise(base_scene, base.parent)

    engine = data.get("engine")
    if not isinstance(engine, str) or not engine:
        err("engine", engine, "missing or not a string (an evaluator name; see `cases study list --engines`)")
    needs = ()
    if check_engine:
        try:
            ev = resolve_evaluator(engine, path.parent.resolve())
        except LookupError as exc:
            err("engine", engine, str(exc))
        needs = ev.needs
        for exe in needs:
            from adapters.process import EngineError, find_engine

            try:
                find_engine(exe)
            except EngineError as exc:
                err("engine", engine, f"needs {exc}")

    results = data.get("results", [])
    if not isinstance(results, list) or not all(isinstance(r, str) and r for r in results):
        err("results", results, "must be a list of result names")
    if len(set(results)) != len(results):
        err("results", results, "names must be unique")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        err("seed", seed, "must be an integer >= 0")
    timeout = data.get("timeout")
    if timeout is not None and (not _is_number(timeout) or not 0 < timeout <= MAX_TIMEOUT):
        err("timeout", timeout, f"must be a number of seconds in (0, {MAX_TIMEOUT:g}]")

    ptab = data.get("parameters", {})
    if not isinstance(ptab, dict):
        err("parameters", ptab, "must be a table of parameter paths")
    params = []
    for ppath, spec in ptab.items():
        key = f'parameters."{ppath}"'
        params.append(_read_param(err, key, ppath, spec, base_scene, base))

    samp = data.get("sampling", {})
    if not isinstance(samp, dict):
        err("sampling", samp, "must be a table (method, samples)")
    for k in samp:
        if k not in ("method", "samples"):
            err(f"sampling.{k}", samp[k], "unknown key (allowed: method, samples)")
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
    study = Study(path=path, name=name, base=base, base_scene=base_scene, engine=engine, results=results,
                  seed=seed, timeout=float(timeout) if timeout is not None else None, method=method,
                  samples=samples, params=params, needs=tuple(needs))
    study.cases = make_cases(study)
    return study


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
    from sgim.geometry import dip_to_normal, normal_to_dip

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
    from statistics import NormalDist

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
def cmd_run(args):
    from ._batch import run_study, world

    comm = world()
    rank = comm.rank if comm is not None else 0
    say = _progress(args.quiet or rank != 0)
    try:
        study = load_study(args.study)
        if args.timeout is not None and not 0 < args.timeout <= MAX_TIMEOUT:
            raise CliError(f"--timeout: {args.timeout!r}: must be in (0, {MAX_TIMEOUT:g}] seconds")
    except (SceneError, CliError) as exc:
        if comm is None:
            raise
        if rank == 0:  # every rank read the same file: rank 0 prints the line, then all stop together
            print(f"cases study: error: {exc}", file=sys.stderr, flush=True)
        comm.Barrier()
        return EXIT_BAD_INPUT
    summary = run_study(study, Path(args.output), timeout=args.timeout, comm=comm, progress=say,
                        retry_failed=args.retry_failed, force=args.force)
    if rank == 0 and not args.quiet:
        f = summary
        print(f"{f['outdir']}/results.csv: {f['done']}/{f['total']} cases ({f['ok']} ok, {f['failed']} failed, "
              f"{f['timeout']} timeout), {f['ran']} run now on {f['ranks']} rank(s) in {f['wall_s']:.2f} s")
    return 0


def cmd_list(args):
    if args.engines:
        for name, ev in sorted(registry().items()):
            ev = _as_evaluator(ev)
            needs = f" (needs {', '.join(ev.needs)})" if ev.needs else ""
            print(f"{name:24s} {ev.description}{needs}")
        return 0
    if not args.study:
        raise CliError("study list: give a STUDY file (or --engines)")
    study = load_study(args.study)
    if args.json:
        print(json.dumps(study.to_json(), indent=2))
        return 0
    print(f"{study.name}: {len(study.cases)} cases, engine {study.engine}, method {study.method}, seed {study.seed}")
    for c in study.cases:
        print(f"  {c.case_id}  {json.dumps(c.params)}")
    return 0


def cmd_report(args):
    out = Path(args.outdir)
    if not (out / "study.json").is_file():
        raise CliError(f"{out}: OUTDIR = {str(out)!r}: no study.json (not a study output folder)")
    try:
        from .report import write_report
    except ModuleNotFoundError as exc:
        if exc.name != "cases.report":
            raise
        raise CliError("study report: cases/report.py is not available") from None
    path = write_report(out)
    print(path)
    return 0


def make_parser():
    ap = argparse.ArgumentParser(prog="cases study", description="Batch studies (serial, or under mpirun).")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a study (under mpirun: rank 0 hands out cases to all ranks)")
    r.add_argument("study")
    r.add_argument("-o", "--output", required=True, help="output folder (a restart skips finished cases)")
    r.add_argument("--timeout", type=float, default=None, help="per-case time limit [s] (overrides the study)")
    r.add_argument("--retry-failed", action="store_true", help="run failed and timed-out cases again")
    r.add_argument("--force", action="store_true", help="replace a different study's output in the folder (its "
                   "own files only; files added by hand stay); the same study is resumed with or without it")
    r.add_argument("--quiet", action="store_true")
    r.set_defaults(func=cmd_run)
    ls = sub.add_parser("list", help="the cases of a study (nothing is run)")
    ls.add_argument("study", nargs="?")
    ls.add_argument("--json", action="store_true")
    ls.add_argument("--engines", action="store_true", help="list the evaluators")
    ls.set_defaults(func=cmd_list)
    rp = sub.add_parser("report", help="Markdown report with plots of a study's results")
    rp.add_argument("outdir")
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


if __name__ == "__main__":
    sys.exit(main())
