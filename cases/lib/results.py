"""A study's outputs read back for its report (cases/lib/report.py): OUTDIR/results.csv and OUTDIR/study.json,
the readable names and units of its columns (:class:`Names`), one number format per column, the classification of
a study (Monte Carlo or sweep, its result columns) and the statistics of the report: probability of failure with
its Wilson interval, exceedance curves, the Pareto front of speed against error.
"""
from __future__ import annotations

import json
import math
import re
import textwrap
from pathlib import Path

import numpy as np

from sgim.readback import BadFile, read_json

from .table import FIXED_COLUMNS as FIXED
from .table import check_table, csv_records

# -- names and units: the evaluator's declaration (study.json "units", with the study's own `units` table)
# first, then these tables of the keys the project's scenes and evaluators use (matched on the last segment of
# a parameter path)
PARAM_NAMES = {
    "friction": ("joint friction angle", "deg"), "cohesion": ("cohesion", "Pa"), "kn": ("normal stiffness kn", "N/m"),
    "ks": ("shear stiffness ks", "N/m"), "damping": ("damping ratio", "-"), "safety": ("time-step safety factor", "-"),
    "dt": ("time step", "s"), "duration": ("simulated time", "s"), "height": ("height", "m"),
    "joint_a": ("joint A orientation", "deg"), "joint_b": ("joint B orientation", "deg"),
    "face": ("slope face orientation", "deg"), "top": ("top face orientation", "deg"), "dip": ("dip", "deg"),
    "dip_direction": ("dip direction", "deg"), "seed": ("random seed", "-"), "radius": ("sphere radius", "m"),
    "r": ("sphere radius", "m"), "density": ("density", "kg/m^3"), "angle": ("slope angle", "deg"),
    "bond_young": ("bond Young's modulus", "Pa"), "young": ("Young's modulus", "Pa"), "kappa": ("Fisher kappa", "-"),
    "tensile": ("tensile strength", "Pa"), "gravity": ("gravity", "m/s^2"), "size": ("size", "m"),
}
RESULT_NAMES = {
    "fs": "factor of safety", "fs_hb": "factor of safety (Hoek & Bray)", "fs_dda": "factor of safety (DDA)",
    "phi_crit": "critical friction angle", "phi_crit_hb": "critical friction angle (Hoek & Bray)",
    "phi_crit_dda": "critical friction angle (DDA)", "wedge": "wedge forms (1) or not (0)",
    "two_planes": "sliding on both joints (1) or one (0)", "plunge": "plunge of the line of intersection",
    "trend": "trend of the line of intersection", "volume": "wedge volume", "displacement": "displacement of the "
    "tracked block", "moved": "blocks that moved", "steps": "time steps", "dt": "time step", "dt_ratio":
    "time step / critical time step", "reference": "analytical displacement", "spheres": "spheres",
    "red_fraction": "fraction of spheres in faults (red)", "packing_density": "packing density",
    "detached_clusters": "detached clusters", "detached_spheres": "spheres in detached clusters",
    "largest_detached": "largest detached cluster", "kept_volume": "kept volume", "exact_volume": "exact volume",
    "detached": "detached spheres", "max_displacement": "largest sphere displacement",
    "mean_displacement": "mean sphere displacement", "bonds_broken": "broken bonds", "trials": "DDA trials",
    "steps_per_trial": "steps per trial", "n": "spheres", "value": "value",
}
# what each error column means: (short formula for axes, sentence for titles and the text)
ERRORS = {
    "error_fs": ("FS_DDA / FS_HB - 1", "relative error of the DDA factor of safety against Hoek & Bray"),
    "error_phi": ("phi_DDA / phi_HB - 1", "relative error of the DDA critical friction angle against Hoek & Bray"),
    "error_disp": ("s / s_ref - 1", "relative error of the displacement against the analytical reference"),
    "error_energy": ("energy balance error / energy in play", "energy balance error relative to the mechanical "
                     "energy in play"),
    "error_volume": ("V_kept / V_exact - 1", "relative error of the excavated volume against the exact volume"),
    "error_detached": ("wrong spheres / spheres", "fraction of spheres whose state differs from the reference"),
}
NO_UNIT = ("", "-", "count")
MC_METHODS = ("random", "lhs", "realisations", "monte-carlo", "montecarlo")
MC_SPECS = ("uniform", "normal", "fisher", "realisations", "lognormal")
TIME_COLUMNS = ("run_s", "build_s", "excavate_s", "engine_s")


def is_timing(col, units=None):
    """Timing columns (the runner's wall_s, an evaluator's run_s, build_s, ...): reported apart from results."""
    return col == "wall_s" or col in TIME_COLUMNS or (col.endswith("_s") and (units or {}).get(col, "s") == "s")


class Names:
    """Readable names, units and labels of a study's columns (parameters as ``p:<path>``)."""

    def __init__(self, study):
        u = study.get("units")
        self.units = dict(u) if isinstance(u, dict) else {}
        self.study = str(study.get("name") or "study")

    def unit(self, col):
        key = col[2:] if col.startswith("p:") else col
        if key in self.units:
            return str(self.units[key])
        if col.startswith("p:"):
            seg = [x for x in key.split(".") if not x.isdigit()]
            return PARAM_NAMES.get(seg[-1] if seg else key, ("", ""))[1]
        if col in ERRORS or col.startswith("error_"):
            return "relative"
        if is_timing(col, self.units):
            return "s"
        return ""

    def name(self, col):
        if col.startswith("p:"):
            path = col[2:]
            seg = path.split(".")
            last = [x for x in seg if not x.isdigit()]
            base = PARAM_NAMES.get(last[-1], (None,))[0] if last else None
            return f"{base} ({path})" if base else path
        if col in ERRORS:
            return ERRORS[col][1]
        if col == "wall_s":
            return "wall time per case (runner)"
        if col in TIME_COLUMNS:
            return {"run_s": "run time", "build_s": "build time", "excavate_s": "excavation time",
                    "engine_s": "engine time"}[col] + " (evaluator)"
        return RESULT_NAMES.get(col, col.replace("_", " "))

    def label(self, col, absolute=False):
        """Axis label: readable name [unit]; an error as |formula| [relative]."""
        u = self.unit(col)
        tail = "" if u in NO_UNIT else f" [{u}]"
        if col in ERRORS:
            f = ERRORS[col][0]
            return (f"|{f}|" if absolute else f) + tail
        if col.startswith("error_"):
            return (f"|{col}|" if absolute else col) + tail
        return self.name(col) + tail

    def title(self, what, width=64):
        """The study's name and what is drawn, wrapped so that it never runs off the figure."""
        return textwrap.fill(f"{self.study}: {what}", width)


def integer_columns(outdir):
    """The columns of OUTDIR/results.csv whose every non-empty cell is written as an integer (counts)."""
    path = Path(outdir) / "results.csv"
    try:
        data = path.read_bytes()
    except OSError:
        return set()
    recs = csv_records(path, data[:data.rfind(b"\n") + 1])
    if not recs:
        return set()
    header = recs[0][1]
    out = set()
    for k, col in enumerate(header):
        cells = [c[k] for _, c in recs[1:] if len(c) == len(header) and c[k] != ""]
        if cells and all(re.fullmatch(r"-?\d+", c) for c in cells):
            out.add(col)
    return out


def column_format(values, integer=False):
    """One format for every number of a column: integers as integers; otherwise fixed decimals enough for four
    significant digits of the column's smallest magnitude, or scientific when the column spans beyond 1e-3..1e5."""
    v = np.asarray([x for x in values if isinstance(x, (int, float)) and math.isfinite(x)], float)
    if not len(v):
        return lambda x: _fmt(x)
    if np.all(v == np.round(v)) and (integer or np.all(np.abs(v) < 1e5)):
        return lambda x: f"{int(x)}" if isinstance(x, (int, float)) and math.isfinite(x) else _fmt(x)
    a = np.abs(v[v != 0])
    if len(a) and (a.max() >= 1e5 or a.min() < 1e-3):
        return lambda x: f"{x:.3e}" if isinstance(x, (int, float)) and math.isfinite(x) else _fmt(x)
    lo = a.min() if len(a) else 1.0
    dec = int(min(6, max(0, 3 - math.floor(math.log10(lo)))))
    return lambda x: f"{x:.{dec}f}" if isinstance(x, (int, float)) and math.isfinite(x) else _fmt(x)
FS_RE = re.compile(r"^fs($|_)")
MAX_TABLE_ROWS = 40
MAX_PLOTS = 24


# ---------------------------------------------------------------------------------------------------------
# statistics


def pareto_front(cost, error):
    """Boolean mask of the non-dominated points: no other point has cost <= and error <= with one of them
    strictly smaller. Points with a non-finite cost or error are never on the front. O(n log n): sort by cost
    (then error) and sweep, keeping the best error of the strictly cheaper points."""
    cost = np.asarray(cost, float)
    error = np.asarray(error, float)
    n = len(cost)
    front = np.zeros(n, bool)
    ok = np.flatnonzero(np.isfinite(cost) & np.isfinite(error))
    if not len(ok):
        return front
    order = ok[np.lexsort((error[ok], cost[ok]))]
    best = math.inf  # best error among strictly cheaper points
    k = 0
    while k < len(order):
        j = k
        while j < len(order) and cost[order[j]] == cost[order[k]]:
            j += 1
        group = order[k:j]  # equal cost, sorted by error
        e_min = error[group[0]]
        if e_min < best:
            front[group[error[group] == e_min]] = True
        best = min(best, e_min)
        k = j
    return front


def probability_of_failure(fs, threshold=1.0):
    """(PoF, failures, n): PoF = #(fs < threshold) / n over all n values; NaN counts as not failing."""
    fs = np.asarray(fs, float)
    n = len(fs)
    k = int(np.sum(fs < threshold))  # NaN < x is False
    return (k / n if n else math.nan), k, n


def wilson_interval(k, n, z=1.96):
    """Wilson score interval of a binomial proportion k / n."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    den = 1.0 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, mid - half), min(1.0, mid + half)


def exceedance(values):
    """(x sorted, P(X > x)) of the finite values: the empirical exceedance curve at each sample."""
    x = np.sort(np.asarray(values, float)[np.isfinite(values)])
    n = len(x)
    return x, (n - np.searchsorted(x, x, side="right")) / max(n, 1)


# ---------------------------------------------------------------------------------------------------------
# reading


def _value(text):
    """A CSV cell as a float, a list (JSON) or the text."""
    if text is None:
        return None
    t = text.strip()
    if t == "":
        return None
    if t in ("True", "False"):  # a boolean result
        return 1.0 if t == "True" else 0.0
    try:
        return float(t)
    except ValueError:
        pass
    if t[:1] in "[{":
        try:
            return json.loads(t)
        except ValueError:
            pass
    return text  # text as written, every character kept


def read_results(outdir):
    """(header, rows) of OUTDIR/results.csv; rows are dicts keyed by column (results under their own name,
    parameters as ``p:<path>``). A torn last line (no line end: a crash inside a write) is left out; any other
    defect (a line that is not UTF-8 or CSV, the wrong number of cells, an unknown status, a case twice) raises
    sgim.readback.BadFile naming the file and the line. The status message (``error``) is kept as ``_message``."""
    path = Path(outdir) / "results.csv"
    if not path.is_file():
        return [], []
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise BadFile(path, f"cannot read ({exc.__class__.__name__})") from None
    records = check_table(path, csv_records(path, data[:data.rfind(b"\n") + 1]))
    if not records:
        return [], []
    header = records[0][1]
    rows, seen = [], set()
    for _, cells in records[1:]:
        row = {}
        for k, (name, cell) in enumerate(zip(header, cells)):
            if name == "error" and k < len(FIXED) + 1 and "_message" not in row:
                row["_message"] = cell
                continue
            key = name[2:] if name.startswith("r:") else name
            row[key] = cell if name in ("case_id", "status") else _value(cell)
        cid = row.get("case_id")
        if cid in seen:
            continue
        seen.add(cid)
        rows.append(row)
    return header, rows


def read_study(outdir):
    """OUTDIR/study.json ({} when there is none; BadFile for one that is not a JSON object)."""
    path = Path(outdir) / "study.json"
    if not path.exists():
        return {}
    return read_json(path, "a study.json")


# ---------------------------------------------------------------------------------------------------------
# classification


def _param_specs(study):
    p = study.get("parameters") or {}
    return p if isinstance(p, dict) else {}


def _method(study):
    s = study.get("sampling")
    if isinstance(s, dict) and s.get("method"):
        return str(s["method"])
    if isinstance(s, str):
        return s
    return str(study.get("method") or "")


def is_monte_carlo(study, rows, params):
    m = _method(study).lower()
    if m:
        return m in MC_METHODS
    for spec in _param_specs(study).values():
        if isinstance(spec, dict) and any(k in spec for k in MC_SPECS):
            return True
    if len(rows) >= 20 and params:  # no description: every case has its own values
        return all(len({json.dumps(r.get(p)) for r in rows}) == len(rows) for p in params)
    return False


def _numeric(rows, col):
    return np.array([r[col] if isinstance(r.get(col), float) else math.nan for r in rows], float)


def _result_columns(study, header, rows):
    names = [c[2:] if c.startswith("r:") else c for c in header]
    cols = [c for k, c in enumerate(names) if not (c in FIXED and k < len(FIXED) + 1) and not c.startswith("p:")]
    wanted = study.get("results")
    if isinstance(wanted, list) and wanted:
        cols = [c for c in wanted if c in cols] + [c for c in cols if c not in wanted]
    return cols


def _fmt(v, digits=4):
    if v is None:
        return ""
    if isinstance(v, float):
        if math.isnan(v):
            return "NaN"
        if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
            return f"{v:.{digits - 1}e}"
        if v == int(v) and abs(v) < 1e5:
            return str(int(v))
        return f"{v:.{digits}g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x, 4) for x in v) + "]"
    return " ".join(str(v).replace("|", "\\|").splitlines())


def _slug(text):
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"
