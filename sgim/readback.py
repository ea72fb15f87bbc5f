"""Reading back the files the tools wrote: every decoding or consistency problem is one line.

Every reader of a file that a tool wrote earlier (model.npz, a deck's run.npz / deck.json / blocks.npz,
result.npz / result.json, ...) goes through these helpers. A file that is missing, empty, truncated, of another
format (a PNG renamed, a single .npy, a zip of something else), of another kind (an npz without the arrays
expected), or inconsistent (an array of the wrong dtype or shape, lengths that disagree, NaN or inf where a
finite number is needed, an index out of range) raises :class:`BadFile`, a :class:`sgim.common.CliError` whose
text is ``FILE: what is wrong``: every command prints it as its one ``PROG: error: ...`` line with exit status
2, before anything is written. ``allow_pickle`` is always False: nothing in a file is ever executed.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .common import CliError

ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip with members, an empty zip
NPY_MAGIC = b"\x93NUMPY"


class BadFile(CliError):
    """A file read back is unreadable or inconsistent: ``str(err)`` is ``FILE: what is wrong`` (one line)."""

    def __init__(self, path, what):
        self.path, self.what = str(path), str(what)
        super().__init__(f"{self.path}: {self.what}")


def _reason(exc):
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    msg = msg if len(msg) <= 100 else msg[:97] + "..."
    return f"{exc.__class__.__name__}: {msg}" if msg else exc.__class__.__name__


def _head(path, n=8):
    with open(path, "rb") as fh:
        return fh.read(n)


def _readable_file(path, kind):
    path = Path(path)
    if not path.exists():
        raise BadFile(path, "no such file")
    if not path.is_file():
        raise BadFile(path, "not a file")
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise BadFile(path, f"cannot read ({_reason(exc)})") from None
    if size == 0:
        raise BadFile(path, f"empty file (expected {kind})")
    return path


def read_npz(path, kind="an npz archive"):
    """All arrays of the npz archive `path` as a dict (read eagerly, allow_pickle=False). BadFile when the file is
    missing, empty, not a zip archive (e.g. a PNG renamed), a single .npy array, truncated, corrupt, or holds a
    member that is not an array; `kind` names what was expected ("a model.npz")."""
    path = _readable_file(path, kind)
    try:
        head = _head(path)
    except OSError as exc:
        raise BadFile(path, f"cannot read ({_reason(exc)})") from None
    if head.startswith(NPY_MAGIC):
        raise BadFile(path, f"not {kind}: a single .npy array, not an npz archive")
    if not head.startswith(ZIP_MAGIC):
        raise BadFile(path, f"not {kind}: not an npz (zip) archive (the file starts with {head!r})")
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any failure to decode is a bad file
        raise BadFile(path, f"not {kind}: unreadable archive ({_reason(exc)})") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise BadFile(path, f"not {kind}: not an npz archive")
    out, key = {}, None
    try:
        with z:
            for key in z.files:
                a = z[key]
                if not isinstance(a, np.ndarray):
                    raise BadFile(path, f"not {kind}: member {key!r} is not a numpy array")
                out[key] = a
    except BadFile:
        raise
    except Exception as exc:  # noqa: BLE001 - truncated members, bad CRC, object arrays, huge headers
        raise BadFile(path, f"not {kind}: array {key!r} cannot be read ({_reason(exc)})") from None
    return out


def parse_json(path, text, where="", kind="a JSON object"):
    """The JSON object in `text` (read from `path`; `where` names the part of the file, e.g. "header"). BadFile
    for invalid JSON or a JSON value that is not an object."""
    pre = f"{where}: " if where else ""
    try:
        doc = json.loads(text)
    except ValueError as exc:  # JSONDecodeError, or a number too large
        pos = f" at line {exc.lineno} column {exc.colno}" if isinstance(exc, json.JSONDecodeError) else ""
        msg = exc.msg if isinstance(exc, json.JSONDecodeError) else _reason(exc)
        raise BadFile(path, f"{pre}not valid JSON ({msg}{pos})") from None
    except RecursionError:
        raise BadFile(path, f"{pre}not valid JSON (nested too deeply)") from None
    if not isinstance(doc, dict):
        raise BadFile(path, f"{pre}expected {kind}, found a JSON {_json_type(doc)}")
    return doc


def _json_type(v):
    return {dict: "object", list: "array", str: "string", bool: "boolean", type(None): "null"}.get(
        type(v), "number")


def read_json(path, kind="a JSON object"):
    """The JSON object in the file `path` (BadFile: missing, empty, not UTF-8, not JSON, not an object)."""
    path = _readable_file(path, kind)
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise BadFile(path, f"cannot read ({_reason(exc)})") from None
    except UnicodeDecodeError as exc:
        raise BadFile(path, f"not {kind}: not UTF-8 text (byte {exc.start})") from None
    return parse_json(path, text, kind=kind)


def read_text(path, kind="a text file"):
    """The UTF-8 text of `path` (BadFile: missing, empty, not UTF-8)."""
    path = _readable_file(path, kind)
    try:
        return path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise BadFile(path, f"cannot read ({_reason(exc)})") from None
    except UnicodeDecodeError as exc:
        raise BadFile(path, f"not {kind}: not UTF-8 text (byte {exc.start})") from None


def _shape_text(shape):
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _where(key, a, flat):
    """``key[i, j]`` of the flat index `flat` into `a`."""
    if a.ndim == 0:
        return key
    idx = np.unravel_index(int(flat), a.shape)
    return f"{key}[{', '.join(str(int(i)) for i in idx)}]"


class Arrays:
    """Checks on the arrays of one file (`arrays` from :func:`read_npz`). Each method returns the array
    converted to its canonical dtype, or raises BadFile naming the file, the array and the defect."""

    def __init__(self, path, arrays, kind="file"):
        self.path, self.arrays, self.kind = str(path), arrays, kind

    def fail(self, what):
        raise BadFile(self.path, what)

    def has(self, key):
        return key in self.arrays

    def missing(self, keys):
        """Fail when any of `keys` is absent (one message listing them: "not a model.npz (missing ...)")."""
        gone = [k for k in keys if k not in self.arrays]
        if gone:
            names = ", ".join(gone[:6]) + (f" and {len(gone) - 6} more" if len(gone) > 6 else "")
            self.fail(f"not {self.kind}: missing array{'s' if len(gone) > 1 else ''} {names}")

    def get(self, key):
        if key not in self.arrays:
            self.fail(f"not {self.kind}: missing array {key}")
        return self.arrays[key]

    def _shape(self, key, a, shape, per):
        if shape is None:
            return
        ok = a.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, a.shape))
        if not ok:
            self.fail(f"{key}: shape {tuple(a.shape)}, expected {_shape_text(shape)}" + (f" ({per})" if per else ""))

    def real(self, key, shape=None, *, finite=True, allow_inf=False, positive=False, nonneg=False, lo=None,
             hi=None, per="", dtype=np.float64):
        """Real numbers (float or integer dtype) of `shape` (None entries: any length); `finite`: no NaN or inf
        (`allow_inf`: +-inf allowed, NaN not); bounds: positive (> 0), nonneg (>= 0), lo / hi (inclusive)."""
        a = self.get(key)
        if a.dtype.kind not in "fiu":
            self.fail(f"{key}: dtype {a.dtype}, expected real numbers")
        self._shape(key, a, shape, per)
        a = a.astype(dtype, copy=False)
        if finite:
            bad = np.isnan(a) if allow_inf else ~np.isfinite(a)
            if bad.any():
                k = int(np.argmax(bad.ravel()))
                self.fail(f"{_where(key, a, k)} = {float(a.ravel()[k])!r}: must be a finite number"
                          if not allow_inf else f"{_where(key, a, k)} = nan: must be a number")
        tests = []
        if positive:
            tests.append(("> 0", lambda x: x <= 0))
        if nonneg:
            tests.append((">= 0", lambda x: x < 0))
        if lo is not None:
            tests.append((f">= {lo}", lambda x: x < lo))
        if hi is not None:
            tests.append((f"<= {hi}", lambda x: x > hi))
        for text, below in tests:
            with np.errstate(invalid="ignore"):
                bad = below(a)
            if bad.any():
                k = int(np.argmax(bad.ravel()))
                self.fail(f"{_where(key, a, k)} = {float(a.ravel()[k])!r}: must be {text}")
        return a

    def integer(self, key, shape=None, *, lo=None, hi=None, why="", per="", dtype=np.int64):
        """Integers of `shape` in [lo, hi) (`why` says what the range is, e.g. "the model has 12 spheres")."""
        a = self.get(key)
        if a.dtype.kind not in "iu":
            self.fail(f"{key}: dtype {a.dtype}, expected integers")
        self._shape(key, a, shape, per)
        if a.size:
            bad = np.zeros(a.shape, bool)
            if lo is not None:
                bad |= a < lo
            if hi is not None:
                bad |= a >= hi
            if bad.any():
                k = int(np.argmax(bad.ravel()))
                rng = f"{lo} .. {hi - 1}" if lo is not None and hi is not None and hi > lo else \
                    (f">= {lo}" if hi is None else (f"< {hi}" if lo is None else "none allowed"))
                self.fail(f"{_where(key, a, k)} = {int(a.ravel()[k])}: out of range ({rng}"
                          + (f"; {why}" if why else "") + ")")
        return a.astype(dtype, copy=False)

    def boolean(self, key, shape=None, *, per=""):
        """Booleans (bool dtype, or integers 0 / 1)."""
        a = self.get(key)
        if a.dtype.kind in "iu":
            bad = (a != 0) & (a != 1)
            if bad.any():
                k = int(np.argmax(bad.ravel()))
                self.fail(f"{_where(key, a, k)} = {int(a.ravel()[k])}: expected a boolean (0 / 1)")
        elif a.dtype.kind != "b":
            self.fail(f"{key}: dtype {a.dtype}, expected booleans")
        self._shape(key, a, shape, per)
        return a.astype(bool, copy=False)

    def text(self, key):
        """One string (a 0-d unicode array)."""
        a = self.get(key)
        if a.dtype.kind != "U" or a.ndim != 0:
            self.fail(f"{key}: expected one string, found {a.dtype} of shape {tuple(a.shape)}")
        return str(a)

    def strings(self, key, shape=None, *, per=""):
        a = self.get(key)
        if a.dtype.kind != "U":
            self.fail(f"{key}: dtype {a.dtype}, expected strings")
        self._shape(key, a, shape, per)
        return [str(s) for s in a.reshape(-1)]


_MISSING = object()


class Fields:
    """Checks on the values of one JSON object (`doc`) read from `path`; `where` prefixes the key names
    (e.g. "header."). Each method returns the value or raises BadFile."""

    def __init__(self, path, doc, where=""):
        self.path, self.doc, self.where = str(path), doc, where

    def fail(self, key, value, what):
        shown = repr(value)
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        raise BadFile(self.path, f"{self.where}{key} = {shown}: {what}")

    def _get(self, key, default):
        """(True, value) of a key present, (False, default) of an absent one with a default."""
        if key in self.doc:
            return True, self.doc[key]
        if default is _MISSING:
            raise BadFile(self.path, f"missing key {self.where}{key}")
        return False, default

    def number(self, key, default=_MISSING, *, positive=False, nonneg=False, lo=None, hi=None, integer=False,
               allow_inf=False):
        present, v = self._get(key, default)
        if not present:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(key, v, "must be an integer" if integer else "must be a number")
        if integer and not isinstance(v, int):
            if not (isinstance(v, float) and math.isfinite(v) and v == int(v)):
                self.fail(key, v, "must be an integer")
            v = int(v)
        if math.isnan(v) or (math.isinf(v) and not allow_inf):
            self.fail(key, v, "must be a finite number")
        for cond, ok, text in ((positive, v > 0, "> 0"), (nonneg, v >= 0, ">= 0"),
                               (lo is not None, lo is None or v >= lo, f">= {lo}"),
                               (hi is not None, hi is None or v <= hi, f"<= {hi}")):
            if cond and not ok:
                self.fail(key, v, f"must be {text}")
        return v

    def string(self, key, default=_MISSING, *, choices=None):
        present, v = self._get(key, default)
        if not present:
            return v
        if not isinstance(v, str):
            self.fail(key, v, "must be a string")
        if choices is not None and v not in choices:
            self.fail(key, v, f"must be one of {', '.join(choices)}")
        return v

    def boolean(self, key, default=_MISSING):
        present, v = self._get(key, default)
        if not present:
            return v
        if not isinstance(v, bool):
            self.fail(key, v, "must be true or false")
        return v

    def obj(self, key, default=_MISSING):
        present, v = self._get(key, default)
        if not present:
            return v
        if not isinstance(v, dict):
            self.fail(key, v, "must be a JSON object")
        return v

    def strings(self, key, default=_MISSING):
        present, v = self._get(key, default)
        if not present:
            return v
        if not isinstance(v, list) or any(not isinstance(s, str) for s in v):
            self.fail(key, v, "must be a list of strings")
        return v

    def vector(self, key, length, default=_MISSING):
        present, v = self._get(key, default)
        if not present:
            return v
        if not (isinstance(v, list) and len(v) == length and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            self.fail(key, v, f"must be a list of {length} finite numbers")
        return [float(x) for x in v]

    def only(self, keys):
        """Fail on a key not in `keys` (a header of another kind or version)."""
        extra = [k for k in self.doc if k not in keys]
        if extra:
            raise BadFile(self.path, f"unknown key {self.where}{extra[0]}")


__all__ = ["BadFile", "read_npz", "read_json", "read_text", "parse_json", "Arrays", "Fields"]
