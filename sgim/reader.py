"""The one validating reader of the project's TOML files: sgim scenes (sgim/scene.py), dda scenes (dda/scene.py)
and study files (cases/lib/study.py).

``read_toml(path)`` reads and parses a file (SceneError ``(file)`` / ``(toml)`` when it cannot);
:class:`SceneReader` reads each value of the parsed tables by its key path, checking its type and range, and
raises SceneError (sgim/common.py) naming the file, the key path, the value and what is wrong, a bound with its
unit. The recording reader of docs/scenes.md (sgim/scenedoc.py) is a subclass: whatever is read through these
methods is documented with its type, default, range and unit.

    from sgim.reader import SIZE, SceneReader, read_toml
    data, text = read_toml("scene.toml")
    rd = SceneReader("scene.toml")
    pk = rd.table(data, "packing", "packing", required=True)        # {} when absent and not required
    rd.known(pk, {"kind", "radius", "seed"}, "packing")               # unknown keys refused, the allowed listed
    r = rd.number(pk, "radius", "packing.radius", positive=True, **SIZE)            # required (no default)
    tol = rd.number(pk, "tolerance", "bonds.tolerance", default=1e-3, nonneg=True, hi=0.2)
    seed = rd.integer(pk, "seed", "packing.seed", default=0, lo=0, hi=2**63 - 1)
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from .common import SceneError
from .geometry import MAX_COORD, MIN_LENGTH

# ranges and units of the common quantities (keyword arguments of SceneReader.number / vector / matrix)
COORD = {"lo": -MAX_COORD, "hi": MAX_COORD, "unit": " m"}  # a coordinate (x, y or z)
LENGTH = {"hi": MAX_COORD, "unit": " m"}  # a length that may be 0 (thickness)
SIZE = {"lo": MIN_LENGTH, "hi": MAX_COORD, "unit": " m"}  # a length > 0 (radius, width, depth, ...)


def read_toml(path, what="scene file"):
    """(data, text) of the TOML file `path`; SceneError (key ``(file)``: ``cannot read {what} (...)``, or
    ``(toml)``: ``not valid TOML``) when it cannot be read or parsed."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(path, "(file)", str(path), f"cannot read {what} ({exc.__class__.__name__})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "(toml)", str(exc).split("\n")[0], "not valid TOML") from None
    return data, text


class SceneReader:
    """The validating value reader of every scene-like TOML file (sgim and dda scenes, study files).

    ``SceneReader(path)``; each method reads one value of a parsed table, named by its key path for the
    messages, and raises SceneError(path, key, value, what is wrong) on a missing value (when no default is
    given), a wrong type or a value out of range; a bound is shown with its `unit` (e.g. " m")."""

    def __init__(self, path):
        self.path = path

    def err(self, key, value, message):
        raise SceneError(self.path, key, value, message)

    def table(self, parent, name, key, required=False):
        if name not in parent:
            if required:
                self.err(key, None, "missing table")
            return {}
        value = parent[name]
        if not isinstance(value, dict):
            self.err(key, value, "must be a table")
        return value

    def known(self, tab, allowed, key):
        for k in tab:
            if k not in allowed:
                where = f"{key}.{k}" if key else k
                self.err(where, tab[k], f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def number(self, tab, name, key, default=None, positive=False, nonneg=False, lo=None, hi=None, unit=""):
        if name not in tab:
            if default is None:
                self.err(key, None, "missing value")
            return float(default)
        return self.check_number(tab[name], key, positive, nonneg, lo, hi, unit)

    def check_number(self, v, key, positive=False, nonneg=False, lo=None, hi=None, unit=""):
        """`v` as a float: a finite number within the bounds (`unit`, e.g. " m", is named with a bound)."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.err(key, v, "must be a number")
        v = float(v)
        if not math.isfinite(v):
            self.err(key, v, "must be finite")
        if positive and v <= 0:
            self.err(key, v, "must be > 0")
        if nonneg and v < 0:
            self.err(key, v, "must be >= 0")
        if lo is not None and v < lo:
            self.err(key, v, f"must be >= {lo:g}{unit}" if unit else f"must be >= {lo}")
        if hi is not None and v > hi:
            self.err(key, v, f"must be <= {hi:g}{unit}" if unit else f"must be <= {hi}")
        return v

    def vector(self, tab, name, key, n=3, default=None, lo=None, hi=None, unit=""):
        if name not in tab:
            if default is None:
                self.err(key, None, "missing value")
            return np.asarray(default, float)
        v = tab[name]
        if not isinstance(v, list) or len(v) != n:
            self.err(key, v, f"must be a list of {n} numbers")
        return np.array([self.check_number(x, f"{key}[{i}]", lo=lo, hi=hi, unit=unit) for i, x in enumerate(v)],
                        float)

    def matrix(self, tab, name, key, ncol, integer=False, lo=None, hi=None, unit=""):
        v = tab[name]
        if not isinstance(v, list) or not v:
            self.err(key, v, f"must be a non-empty list of [{', '.join('abc'[:ncol])}] rows")
        out = np.empty((len(v), ncol), np.int64 if integer else float)
        for i, row in enumerate(v):
            if not isinstance(row, list) or len(row) != ncol:
                self.err(f"{key}[{i}]", row, f"must be a list of {ncol} numbers")
            for c, x in enumerate(row):
                if integer:
                    if isinstance(x, bool) or not isinstance(x, int):
                        self.err(f"{key}[{i}]", row, "indices must be integers")
                    out[i, c] = x
                else:
                    out[i, c] = self.check_number(x, f"{key}[{i}]", lo=lo, hi=hi, unit=unit)
        return out

    def choice(self, tab, name, key, choices, default):
        v = tab.get(name, default)
        if v not in choices:
            self.err(key, v, f"must be one of {', '.join(repr(c) for c in choices)}")
        return v

    def boolean(self, tab, name, key, default):
        v = tab.get(name, default)
        if not isinstance(v, bool):
            self.err(key, v, "must be true or false")
        return v

    def string(self, tab, name, key, default):
        v = tab.get(name, default)
        if not isinstance(v, str):
            self.err(key, v, "must be a string")
        return v

    def value(self, tab, name, key, default, kind="value"):
        """`tab[name]` or `default`, checked by the caller (`kind` names what it must be, for docs/scenes.md)."""
        return tab.get(name, default)

    def integer(self, tab, name, key, default, lo, hi):
        """`tab[name]` (or `default`) as an int: a number within [lo, hi] with no fractional part."""
        v = self.number(tab, name, key, default=default, lo=lo, hi=hi)
        if not float(v).is_integer():
            self.err(key, tab.get(name), "must be an integer")
        return int(v)

    def list_of_tables(self, data, name):
        """``data[name]`` (default []) when it is an array of tables ([[name]]); SceneError otherwise."""
        v = data.get(name, [])
        if not isinstance(v, list) or any(not isinstance(t, dict) for t in v):
            self.err(name, v, f"must be an array of tables ([[{name}]])")
        return v
