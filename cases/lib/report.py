"""The report of a batch study: ``write_report(OUTDIR)`` -> OUTDIR/report.md with PNG plots in OUTDIR/report/.

It reads what the runner wrote (cases/lib/study.py): OUTDIR/study.json (name, engine, results, seed, sampling, the
cases with their parameters) and OUTDIR/results.csv (case_id, status, error, wall_s, rank, ``p:<path>`` columns,
then the result columns; a torn last line is dropped). The report has:

* a summary: cases planned / ok / failed / timeout / not run, total and median wall time per case;
* Monte-Carlo studies (sampling random, lhs or realisations, or parameters drawn from uniform / normal / fisher /
  realisations): for every numeric result a histogram and an exceedance curve P(X > x); for every factor of
  safety column (``fs`` or ``fs_*``) the probability of failure PoF = P(FS < 1) over the cases that ran (a case
  whose FS is NaN, e.g. joints that form no wedge, cannot fail and counts as stable) with its 95 % Wilson
  interval, and the curve P(FS < x); columns ``fs_*`` of the same rows are drawn on one plot (e.g. DDA next to
  Hoek & Bray over the same samples);
* sweeps (grid or list parameters): response surfaces, a line per result over one numeric parameter, a
  colour map over two (a scatter with colours when the grid is not full);
* speed against error (sweeps with ``error_*`` result columns): the time of each case (the evaluator's own
  ``run_s`` / ``build_s`` / ``excavate_s`` / ``engine_s`` when it reports one, which leaves out one-off
  compilation; else the runner's ``wall_s``) against |error| over the resolution parameters, with the Pareto
  front marked: the cases that no other case beats on both time and error (:func:`pareto_front`);
* the failed and timed-out cases with their reasons.

Written under temporary names and renamed into place.
"""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np

from sgim.cli import CliError
from sgim.readback import BadFile, read_json

FIXED = ("case_id", "status", "error", "wall_s", "rank")

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
        import textwrap

        return textwrap.fill(f"{self.study}: {what}", width)


def integer_columns(outdir):
    """The columns of OUTDIR/results.csv whose every non-empty cell is written as an integer (counts)."""
    from ._batch import csv_records

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
    from ._batch import check_table, csv_records

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


# ---------------------------------------------------------------------------------------------------------
# plots


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path):
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.png")
    fig.savefig(tmp, dpi=110)
    _plt().close(fig)
    os.replace(tmp, path)
    return path


def spans_decades(v, factor=10.0):
    """True when the finite values are all > 0 and the largest is more than `factor` times the smallest."""
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return bool(len(v) > 1 and v.min() > 0 and v.max() / v.min() > factor)


def _bins(v, n=None):
    n = n or min(30, max(5, int(np.sqrt(max(len(v), 1)))))
    if spans_decades(v):
        return np.geomspace(v.min(), v.max(), n + 1), True
    return np.histogram_bin_edges(v, bins=n), False


def plot_distribution(path, cols, data, names, fs=False):
    """Histogram (left) and, right, the exceedance curve P(X > x), or P(FS < x) for factors of safety with the
    line FS = 1; `cols` drawn on the same axes (same samples). Log x axis when the values span more than 10x."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.2))
    finite = [data[c][np.isfinite(data[c])] for c in cols]
    allv = np.concatenate(finite) if finite else np.zeros(0)
    bins, logx = _bins(allv) if len(allv) else (10, False)
    styles = ["-", "--", ":", "-."]
    for m, (c, v) in enumerate(zip(cols, finite)):
        label = names.name(c)
        if fs:
            pof, k, n = probability_of_failure(data[c])
            label = f"{label}: PoF = {pof:.3f} ({k}/{n})"
        if m == 0:
            a1.hist(v, bins=bins, alpha=0.5 if len(cols) > 1 else 0.9, label=label, color="C0")
        else:  # later columns as outlines: equal distributions stay visible
            a1.hist(v, bins=bins, histtype="step", lw=1.8, ls=styles[m % 4], label=label, color=f"C{m}")
        x, p = exceedance(v)
        if not len(x):
            continue
        if fs:  # P(FS < x): 0 left of the smallest value, NaN (stable) cases in the denominator
            n = len(data[c])
            a2.step(np.r_[x[0], x], np.r_[0.0, np.searchsorted(x, x, side="right") / max(n, 1)], where="post",
                    label=label, ls=styles[m % 4], color=f"C{m}")
        else:  # P(X > x): 1 left of the smallest value
            a2.step(np.r_[x[0], x], np.r_[1.0, p], where="post", label=label, ls=styles[m % 4], color=f"C{m}")
    what = names.name(cols[0]) if len(cols) == 1 else ", ".join(names.name(c) for c in cols)
    xlabel = names.label(cols[0]) if len(cols) == 1 else (
        "factor of safety" if fs else ", ".join(names.label(c) for c in cols))
    if fs:
        for ax in (a1, a2):
            ax.axvline(1.0, color="k", lw=0.8, ls="--")
        a2.set_ylabel("P(FS < x)")
        a2.set_title(names.title("probability of failure P(FS < x)", 52), fontsize=10)
        a1.set_title(names.title("factor of safety, cases per bin", 52), fontsize=10)
    else:
        a2.set_ylabel("P(X > x)")
        a2.set_title(names.title(f"exceedance of {what}", 52), fontsize=10)
        a1.set_title(names.title(f"{what}, cases per bin", 52), fontsize=10)
    a1.set_ylabel("cases")
    for ax in (a1, a2):
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        if logx:
            ax.set_xscale("log")
            _tidy_log(ax)
    if fs or len(cols) > 1:
        a1.legend(fontsize=8)
        a2.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _save(fig, path)


def _tick_labels(values, fmt):
    return [fmt(float(v)) for v in values]


def _tidy_log(ax):
    """Log axes labelled in plain numbers at 1, 2, 5 x 10^k (1 x 10^k only past four decades); no labels on the
    minor ticks (they overlap)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    for axis, scale, lim in ((ax.xaxis, ax.get_xscale(), ax.get_xlim()), (ax.yaxis, ax.get_yscale(), ax.get_ylim())):
        if scale == "log":
            lo, hi = sorted(lim)
            wide = lo > 0 and hi / lo > 1e4
            axis.set_major_locator(LogLocator(base=10.0, subs=(1.0,) if wide else (1.0, 2.0, 5.0)))
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            axis.set_minor_formatter(NullFormatter())


def _value_ticks(ax, x):
    """The x ticks at the (few) values of a swept parameter, in the parameter's one format."""
    xs = np.unique(x[np.isfinite(x)])
    if 1 < len(xs) <= 12:
        from matplotlib.ticker import NullFormatter

        ax.set_xticks(xs, _tick_labels(xs, column_format(list(xs))))
        ax.xaxis.set_minor_formatter(NullFormatter())


def plot_response(path, col, params, data, rows, names):
    """Response of result `col` over one numeric parameter (a line) or two (colour map on the full grid, else a
    coloured scatter). Errors are drawn as their size; log scales where values span more than 10x."""
    plt = _plt()
    from matplotlib.colors import LogNorm

    y = data[col]
    is_err = col.startswith("error_")
    if is_err:
        y = np.abs(y)
    label = names.label(col, absolute=is_err)
    logscale = spans_decades(y)
    fmt_y = column_format(list(y))
    what = names.name(col)
    if len(params) == 1:
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        x = _numeric(rows, params[0])
        o = np.argsort(x)
        ax.plot(x[o], y[o], "o-")
        ax.set_xlabel(names.label(params[0]))
        if spans_decades(x):
            ax.set_xscale("log")
        if logscale:
            ax.set_yscale("log")
        _tidy_log(ax)
        _value_ticks(ax, x)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
        ax.set_title(names.title(f"{what} against {names.name(params[0])}"), fontsize=10)
    else:
        fig, ax = plt.subplots(figsize=(7.5, 5.2))
        px, py = params[0], params[1]
        x, yy = _numeric(rows, px), _numeric(rows, py)
        xs, ys = np.unique(x[np.isfinite(x)]), np.unique(yy[np.isfinite(yy)])
        grid = np.full((len(ys), len(xs)), np.nan)
        full = len(xs) * len(ys) == len(rows) and len(xs) > 1 and len(ys) > 1
        if full:
            for xv, yv, v in zip(x, yy, y):
                grid[np.searchsorted(ys, yv), np.searchsorted(xs, xv)] = v
            full = bool(np.isfinite(grid).sum() >= 2)
        norm = LogNorm() if logscale else None
        if full:
            # cells centred on the grid values (index space: uneven and logarithmic grids stay readable)
            m = ax.pcolormesh(np.arange(len(xs) + 1) - 0.5, np.arange(len(ys) + 1) - 0.5, grid, shading="flat",
                              norm=norm, cmap="viridis")
            ax.set_xticks(range(len(xs)), _tick_labels(xs, column_format(list(xs))))
            ax.set_yticks(range(len(ys)), _tick_labels(ys, column_format(list(ys))))
            for i in range(len(ys)):
                for j in range(len(xs)):
                    if np.isfinite(grid[i, j]):
                        ax.text(j, i, fmt_y(float(grid[i, j])), ha="center", va="center", fontsize=7,
                                bbox=dict(boxstyle="round,pad=0.15", fc="w", ec="none", alpha=0.7))
        else:
            m = ax.scatter(x, yy, c=y, s=40, norm=norm, cmap="viridis")
            if spans_decades(x):
                ax.set_xscale("log")
            if spans_decades(yy):
                ax.set_yscale("log")
        _tidy_log(ax)
        fig.colorbar(m, ax=ax, label=label + (" (log scale)" if logscale else ""))
        ax.set_xlabel(names.label(px))
        ax.set_ylabel(names.label(py))
        ax.set_title(names.title(what), fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_speed_error(path, col, t, err, front, labels, tname, names):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.8))
    e = np.abs(err)
    ok = np.isfinite(t) & np.isfinite(e)
    ax.scatter(t[ok & ~front], e[ok & ~front], c="0.5", s=30, label="case")
    o = np.flatnonzero(front)
    o = o[np.argsort(t[o])]
    ax.plot(t[o], e[o], "o-", c="C3", ms=7, label="Pareto front (no case is both faster and more accurate)")
    for k in o:  # the front's points carry their parameters (every case is in the report's table)
        ax.annotate(labels[k], (t[k], e[k]), fontsize=6, xytext=(4, 4), textcoords="offset points", color="C3")
    if np.all(t[ok] > 0) and spans_decades(t[ok], 3.0):
        ax.set_xscale("log")
    if np.all(e[ok] > 0) and spans_decades(e[ok], 3.0):
        ax.set_yscale("log")
    _tidy_log(ax)
    ax.set_xlabel(names.label(tname))
    ax.set_ylabel(names.label(col, absolute=True))
    ax.set_title(names.title(f"speed against {names.name(col)}"), fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def _orientation(v):
    """(dip, dip direction) of a sampled orientation cell: [dip, dd] or {"dip": .., "dip_direction": ..}."""
    if isinstance(v, dict) and "dip" in v and "dip_direction" in v:
        v = [v["dip"], v["dip_direction"]]
    if isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v):
        dip, dd = float(v[0]), float(v[1])
        if dip < 0:
            dip, dd = -dip, dd + 180.0
        if dip > 90:
            dip, dd = 180.0 - dip, dd + 180.0
        return dip, dd % 360.0
    return None


def pole_projection(dip, dip_direction):
    """(x east, y north) of the pole of a plane on the lower-hemisphere equal-area (Schmidt) net of radius 1: the
    pole plunges 90 - dip towards dip direction + 180, at distance sqrt(2) sin((90 - plunge) / 2) = sqrt(2)
    sin(dip / 2) from the centre (a vertical plane's pole on the circle)."""
    d, a = np.radians(np.asarray(dip, float)), np.radians(np.asarray(dip_direction, float) + 180.0)
    r = np.sqrt(2.0) * np.sin(d / 2.0)
    return r * np.sin(a), r * np.cos(a)


def _law(kind, spec, unit):
    u = "" if unit in NO_UNIT else f" {unit}"
    if kind == "uniform" and isinstance(spec, list) and len(spec) == 2:
        return f"uniform {spec[0]:g} to {spec[1]:g}{u}"
    if kind == "normal" and isinstance(spec, list) and len(spec) == 2:
        return f"normal, mean {spec[0]:g}{u}, sd {spec[1]:g}{u}"
    return f"{kind} {spec}"


def plot_inputs(path, study, rows, names):
    """The sampled inputs: orientation parameters on an equal-area stereonet of poles (lower hemisphere), the
    others as histograms. Returns the path, or None when no parameter is sampled."""
    specs = _param_specs(study)
    panels = []
    for p, spec in specs.items():
        kind = next(iter(spec)) if isinstance(spec, dict) and spec else None
        if kind not in ("uniform", "normal", "fisher", "lognormal"):
            continue
        vals = [r.get(f"p:{p}") for r in rows]
        if kind == "fisher":
            o = [x for x in (_orientation(v) for v in vals) if x is not None]
            if o:
                panels.append(("stereo", p, np.array(o), spec[kind]))
        else:
            v = np.array([x for x in vals if isinstance(x, float) and math.isfinite(x)])
            if len(v):
                panels.append((kind, p, v, spec[kind]))
    if not panels:
        return None
    plt = _plt()
    n = len(panels)
    cols = min(n, 3)
    nrow = (n + cols - 1) // cols
    fig, axes = plt.subplots(nrow, cols, figsize=(4.4 * cols, 4.3 * nrow), squeeze=False)
    for ax, (kind, p, v, spec) in zip(axes.flat, panels):
        if kind == "stereo":
            t = np.linspace(0, 2 * np.pi, 361)
            ax.plot(np.sin(t), np.cos(t), "k-", lw=1)
            ax.plot([0, 0], [-1, 1], color="0.8", lw=0.6)
            ax.plot([-1, 1], [0, 0], color="0.8", lw=0.6)
            for lab, (x0, y0) in (("N", (0, 1.06)), ("E", (1.08, 0)), ("S", (0, -1.1)), ("W", (-1.1, 0))):
                ax.text(x0, y0, lab, ha="center", va="center", fontsize=9)
            x, y = pole_projection(v[:, 0], v[:, 1])
            ax.plot(x, y, ".", ms=4, color="C0", label=f"{len(v)} sampled poles")
            if isinstance(spec, dict) and "dip" in spec:
                mx, my = pole_projection(spec["dip"], spec["dip_direction"])
                ax.plot(mx, my, "r+", ms=12, mew=2,
                        label=f"mean {spec['dip']:g}/{spec['dip_direction']:03.0f}, kappa {spec.get('kappa', 0):g}")
            ax.set_aspect("equal")
            ax.set_xlim(-1.2, 1.2)
            ax.set_ylim(-1.2, 1.2)
            ax.axis("off")
            ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(-0.05, -0.12))
            ax.set_title(f"{names.name('p:' + p)}\npoles, equal-area lower hemisphere", fontsize=9)
        else:
            bins, logx = _bins(v)
            ax.hist(v, bins=bins, color="C0", alpha=0.85)
            if logx:
                ax.set_xscale("log")
            ax.set_xlabel(names.label("p:" + p))
            ax.set_ylabel("cases")
            ax.grid(alpha=0.3)
            ax.set_title(f"{names.name('p:' + p)}\n{_law(kind, spec, names.unit('p:' + p))}", fontsize=9)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(names.title("sampled inputs"), fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


# ---------------------------------------------------------------------------------------------------------
# the report


def _summary_lines(study, rows, outdir):
    planned = study.get("cases")
    n_planned = len(planned) if isinstance(planned, (list, dict)) else None
    status = [r.get("status") for r in rows]
    ranks = {r.get("rank") for r in rows if r.get("rank") is not None}
    lines = ["| | |", "|---|---|"]
    lines.append(f"| study | {study.get('name', Path(outdir).name)} |")
    lines.append(f"| evaluator | {study.get('evaluator', study.get('engine', '?'))} |")
    if _method(study):
        lines.append(f"| sampling | {_method(study)} |")
    if study.get("seed") is not None:
        lines.append(f"| seed | {study.get('seed')} |")
    if study.get("version") is not None:
        lines.append(f"| version | {study.get('version')} |")
    lines.append(f"| cases planned | {n_planned if n_planned is not None else '?'} |")
    for s in ("ok", "failed", "timeout"):
        lines.append(f"| {s} | {status.count(s)} |")
    other = len(status) - sum(status.count(s) for s in ("ok", "failed", "timeout"))
    if other:
        lines.append(f"| other status | {other} |")
    if n_planned is not None:
        lines.append(f"| not run | {max(n_planned - len(rows), 0)} |")
    if ranks:
        lines.append(f"| ranks that ran cases | {len(ranks)} |")
    return lines


def _timing_lines(rows, ok_rows, tcols, names):
    out = ["| timing | unit | cases | total | median | max |", "|---|---|---:|---:|---:|---:|"]
    for c in ["wall_s", *tcols]:
        v = _numeric(rows if c == "wall_s" else ok_rows, c)
        v = v[np.isfinite(v)]
        if not len(v):
            continue
        f = column_format([float(v.sum()), *v])
        out.append(f"| {names.name(c)} (`{c}`) | s | {len(v)} | {f(float(v.sum()))} | {f(float(np.median(v)))} | "
                   f"{f(float(v.max()))} |")
    return out


def _stats_table(cols, data, names, ints=()):
    out = ["| result | unit | n | mean | sd | min | 5 % | median | 95 % | max |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for c in cols:
        v = data[c][np.isfinite(data[c])]
        u = names.unit(c) or "-"
        if not len(v):
            out.append(f"| {c} | {u} | 0 | | | | | | | |")
            continue
        counts = c in ints
        q = np.percentile(v, [5, 50, 95], method="nearest" if counts else "linear")
        sd = float(v.std(ddof=1)) if len(v) > 1 else 0.0
        stats = [float(v.mean()), sd, float(v.min()), float(q[0]), float(q[1]), float(q[2]), float(v.max())]
        f = column_format(stats if not np.all(v == np.round(v)) else list(v), integer=counts)
        if np.all(v == np.round(v)):  # counts: mean and sd are not integers
            g = column_format([s for s in stats[:2] if s != round(s)] or [0.5])
            cells = [g(stats[0]), g(stats[1])] + [f(x) for x in stats[2:]]
        else:
            cells = [f(x) for x in stats]
        out.append(f"| {c} | {u} | {len(v)} | " + " | ".join(cells) + " |")
    return out


def _rows_table(rows, params, cols, names, ints=()):
    head = ["case", "status", *params, *cols]
    fmts = {h: column_format([r.get(h) for r in rows], integer=h in ints) for h in (*params, *cols)}
    units = [names.unit(h) for h in head[2:]]
    out = ["| " + " | ".join(head[:2] + [f"{h} [{u}]" if u not in NO_UNIT else h for h, u in zip(head[2:], units)])
           + " |", "|" + "---|" * len(head)]
    for r in rows:
        out.append("| " + " | ".join([_fmt(r.get("case_id")), _fmt(r.get("status"))] +
                                     [fmts[h](r.get(h)) if isinstance(r.get(h), float) else _fmt(r.get(h))
                                      for h in head[2:]]) + " |")
    return out


def write_report(outdir, with_summary=False):
    """Write OUTDIR/report.md and the plots in OUTDIR/report/; returns the path of report.md (and, with
    `with_summary`, a dict: files, counts, probabilities of failure)."""
    outdir = Path(outdir)
    study = read_study(outdir)
    header, rows = read_results(outdir)
    if not study and not header:
        raise FileNotFoundError(f"{outdir}: no study.json or results.csv (run `cases study run` first)")
    names = Names({**study, "name": study.get("name", outdir.name)})
    figdir = outdir / "report"
    figdir.mkdir(parents=True, exist_ok=True)
    params = [c for c in header if c.startswith("p:")]
    allcols = _result_columns(study, header, rows)
    ok_rows = [r for r in rows if r.get("status") == "ok"]
    tcols = [c for c in allcols if is_timing(c, names.units)]
    cols = [c for c in allcols if c not in tcols]
    data = {c: _numeric(ok_rows, c) for c in allcols}
    numeric = [c for c in cols if np.isfinite(data[c]).any()]
    num_params = [p for p in params if ok_rows and all(isinstance(r.get(p), float) for r in ok_rows)
                  and len({r[p] for r in ok_rows}) > 1]
    mc = is_monte_carlo(study, rows, params)
    ints = integer_columns(outdir)
    name = names.study
    info = {"report": str(outdir / "report.md"), "study": name, "figures": [],
            "cases": {s: sum(1 for r in rows if r.get("status") == s) for s in ("ok", "failed", "timeout")},
            "pof": {}}
    md = [f"# Study report: {name}", ""]
    if study.get("description"):
        md += [str(study["description"]), ""]
    md += ["## Summary", "", *_summary_lines(study, rows, outdir), ""]
    units = [f"`{c}` {names.unit(c)}" for c in [*params, *numeric] if names.unit(c) not in NO_UNIT]
    if units:
        md += ["Units: " + ", ".join(units) + ".", ""]
    errs = [c for c in numeric if c in ERRORS]
    if errs:
        md += ["Errors: " + "; ".join(f"`{c}` = {ERRORS[c][0]} ({ERRORS[c][1]})" for c in errs) + ".", ""]
    figures = 0

    def fig_line(path, caption):
        info["figures"].append(str(path))
        return f"![{caption}](report/{path.name})"

    p = plot_inputs(figdir / "inputs.png", study, rows, names)
    if p is not None:
        figures += 1
        md += ["## Sampled inputs", "", "Orientations as poles on an equal-area net (lower hemisphere), other sampled "
               "parameters as histograms.", "", fig_line(p, "sampled inputs"), ""]
    if mc:
        md += ["## Monte-Carlo results", "", f"{len(ok_rows)} cases ran (status ok).", ""]
        fs_cols = [c for c in numeric if FS_RE.match(c)]
        if fs_cols:
            md += ["### Probability of failure", "",
                   "PoF = P(FS < 1) over the cases that ran; a NaN factor of safety (no failure mechanism, e.g. "
                   "joints that form no wedge) counts as stable. Columns in the same row share the same samples.",
                   "", "| factor of safety | failures | cases | PoF | 95 % interval (Wilson) | NaN (stable) |",
                   "|---|---:|---:|---:|---|---:|"]
            for c in fs_cols:
                pof, k, n = probability_of_failure(data[c])
                lo, hi = wilson_interval(k, n)
                info["pof"][c] = {"pof": pof, "failures": k, "cases": n, "wilson95": [lo, hi]}
                md.append(f"| {c} | {k} | {n} | {pof:.4f} | {lo:.4f} - {hi:.4f} | "
                          f"{int(np.sum(~np.isfinite(data[c])))} |")
            if len(fs_cols) > 1:
                both = np.isfinite(data[fs_cols[0]]) & np.isfinite(data[fs_cols[1]])
                a, b = data[fs_cols[0]][both] < 1, data[fs_cols[1]][both] < 1
                md += ["", f"Same verdict (both fail or both hold) in {int(np.sum(a == b))} of {int(both.sum())} "
                           f"cases where {fs_cols[0]} and {fs_cols[1]} are both defined."]
            p = plot_distribution(figdir / "pof.png", fs_cols, data, names, fs=True)
            figures += 1
            md += ["", fig_line(p, "probability of failure"), ""]
        md += ["### Distributions", "", *_stats_table(numeric, data, names, ints), ""]
        for c in numeric:
            if c in fs_cols or figures >= MAX_PLOTS:
                continue
            v = data[c][np.isfinite(data[c])]
            if len(v) < 2 or v.min() == v.max():
                continue
            p = plot_distribution(figdir / f"dist_{_slug(c)}.png", [c], data, names)
            figures += 1
            md += [f"**{c}**: {names.name(c)}", "", fig_line(p, c), ""]
    else:
        md += ["## Results", ""]
        if len(rows) <= MAX_TABLE_ROWS:
            md += [*_rows_table(rows, params, numeric, names, ints), ""]
        else:
            md += [*_stats_table(numeric, data, names, ints), ""]
        if num_params and ok_rows:
            md += ["### Response surfaces", ""]
            use = num_params[:2]
            if len(num_params) > 2:
                md += [f"More than two parameters vary; the plots use {', '.join(use)}.", ""]
            for c in numeric:
                v = data[c][np.isfinite(data[c])]
                if figures >= MAX_PLOTS or v.min() == v.max():
                    continue  # a constant needs no plot
                p = plot_response(figdir / f"response_{_slug(c)}.png", c, use, data, ok_rows, names)
                figures += 1
                md += [fig_line(p, c), ""]
        err_cols = [c for c in numeric if c.startswith("error_")]
        if err_cols and ok_rows:
            tname = next((c for c in TIME_COLUMNS if c in data and np.isfinite(data[c]).all()), "wall_s")
            t = data[tname] if tname in data else _numeric(ok_rows, "wall_s")
            labels = [", ".join(f"{p[2:].split('.')[-1]}={column_format(_numeric(ok_rows, p))(r.get(p))}"
                                for p in params if isinstance(r.get(p), float)) or r.get("case_id", "")
                      for r in ok_rows]
            md += ["### Speed against error", "",
                   f"Time: `{tname}`" + (" (the evaluator's own timing of the computation)" if tname != "wall_s"
                                         else " (the runner's wall time per case)") +
                   ". Pareto front: the cases that no other case beats on both time and |error|.", ""]
            for c in err_cols:
                e = np.abs(data[c])
                front = pareto_front(t, e)
                if not np.isfinite(e).any():
                    continue
                p = plot_speed_error(figdir / f"speed_error_{_slug(c)}.png", c, t, data[c], front, labels, tname,
                                     names)
                figures += 1
                ft, fe = column_format(list(t)), column_format(list(data[c]))
                fp = {q: column_format([r.get(q) for r in ok_rows]) for q in params}
                md += [f"**{c}**: {names.name(c)}", "", fig_line(p, f"speed against {c}"), "",
                       f"| case | {' | '.join(params)} | {tname} [s] | {c} | Pareto |",
                       "|" + "---|" * (len(params) + 4)]
                for k in np.argsort(t):
                    r = ok_rows[k]
                    md.append(f"| {r.get('case_id')} | " + " | ".join(
                        fp[q](r.get(q)) if isinstance(r.get(q), float) else _fmt(r.get(q)) for q in params) +
                        f" | {ft(float(t[k]))} | {fe(float(data[c][k]))} | {'yes' if front[k] else ''} |")
                md.append("")
    md += ["## Timing", "", "Kept apart from the results: the runner's wall time of each case (with the process "
           "start and one-off work) and the evaluator's own timings.", "", *_timing_lines(rows, ok_rows, tcols, names),
           ""]
    bad = [r for r in rows if r.get("status") not in ("ok",)]
    md += ["## Failed cases", ""]
    if bad:
        md += ["| case | status | parameters | reason |", "|---|---|---|---|"]
        for r in bad:
            ps = ", ".join(f"{p[2:]}={_fmt(r.get(p))}" for p in params)
            md.append(f"| {r.get('case_id')} | {r.get('status')} | {ps} | {_fmt(r.get('_message') or '')} |")
    else:
        md.append("None.")
    md.append("")
    path = outdir / "report.md"
    tmp = path.with_name(f".report.md.tmp{os.getpid()}")
    tmp.write_text("\n".join(md), encoding="utf-8")
    os.replace(tmp, path)
    return (path, info) if with_summary else path


def main(argv=None):
    import sys

    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) != 1:
        print("usage: python -m cases.lib.report OUTDIR", file=sys.stderr)
        return 2
    try:
        print(write_report(argv[0]))
    except (FileNotFoundError, CliError) as exc:
        print(f"cases.lib.report: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["write_report", "pareto_front", "probability_of_failure", "wilson_interval", "exceedance",
           "read_results", "read_study"]
