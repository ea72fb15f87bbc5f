"""The report of a batch study: ``write_report(OUTDIR)`` -> OUTDIR/report.md with PNG plots in OUTDIR/report/.

It reads what the runner wrote (cases/study.py): OUTDIR/study.json (name, engine, results, seed, sampling, the
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
MC_METHODS = ("random", "lhs", "realisations", "monte-carlo", "montecarlo")
MC_SPECS = ("uniform", "normal", "fisher", "realisations", "lognormal")
TIME_COLUMNS = ("run_s", "build_s", "excavate_s", "engine_s")
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
    return t


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
    return str(v).replace("|", "\\|").replace("\n", " ")


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


def plot_distribution(path, cols, data, fs=False):
    """Histogram (left) and, right, the exceedance curve P(X > x), or P(FS < x) for factors of safety with the
    line FS = 1; `cols` drawn on the same axes (same samples)."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    finite = [data[c][np.isfinite(data[c])] for c in cols]
    allv = np.concatenate(finite) if finite else np.zeros(0)
    bins = np.histogram_bin_edges(allv, bins=min(30, max(5, int(np.sqrt(max(len(allv), 1)))))) if len(allv) else 10
    styles = ["-", "--", ":", "-."]
    for m, (c, v) in enumerate(zip(cols, finite)):
        label = c
        if fs:
            pof, k, n = probability_of_failure(data[c])
            label = f"{c}: PoF = {pof:.3f} ({k}/{n})"
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
            a2.step(np.r_[x[0], x], np.r_[1.0, p], where="post", label=c, ls=styles[m % 4], color=f"C{m}")
    if fs:
        for ax in (a1, a2):
            ax.axvline(1.0, color="k", lw=0.8, ls="--")
        a2.set_ylabel("P(FS < x)")
        a2.set_title("probability of failure against the FS threshold x")
    else:
        a2.set_ylabel("P(X > x)")
        a2.set_title("exceedance")
    a1.set_title("histogram")
    a1.set_ylabel("cases")
    for ax in (a1, a2):
        ax.set_xlabel(", ".join(cols))
        ax.grid(alpha=0.3)
    if fs or len(cols) > 1:
        a1.legend(fontsize=8)
        a2.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _save(fig, path)


def plot_response(path, col, params, data, rows):
    """Response of result `col` over one numeric parameter (line per value of a second, if any) or two
    (colour map on the full grid, else a coloured scatter)."""
    plt = _plt()
    from matplotlib.colors import LogNorm

    y = data[col]
    label = col
    if col.startswith("error_"):  # errors: their size, on a log scale when it spans decades
        y, label = np.abs(y), f"|{col}|"
    fy = y[np.isfinite(y)]
    logscale = len(fy) > 1 and fy.min() > 0 and fy.max() / fy.min() > 100
    if len(params) == 1:
        fig, ax = plt.subplots(figsize=(6, 4))
        x = _numeric(rows, params[0])
        o = np.argsort(x)
        ax.plot(x[o], y[o], "o-")
        ax.set_xlabel(params[0])
        if np.all(x[np.isfinite(x)] > 0) and np.nanmax(x) / max(np.nanmin(x), 1e-300) > 50:
            ax.set_xscale("log")
        if logscale:
            ax.set_yscale("log")
    else:
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        px, py = params[0], params[1]
        x, yy = _numeric(rows, px), _numeric(rows, py)
        xs, ys = np.unique(x[np.isfinite(x)]), np.unique(yy[np.isfinite(yy)])
        grid = np.full((len(ys), len(xs)), np.nan)
        full = len(xs) * len(ys) == len(rows) and len(xs) > 1 and len(ys) > 1
        if full:
            for xv, yv, v in zip(x, yy, y):
                grid[np.searchsorted(ys, yv), np.searchsorted(xs, xv)] = v
            full = bool(np.isfinite(grid).sum() >= 2)
        if full:
            # cells centred on the grid values (index space: uneven and logarithmic grids stay readable)
            m = ax.pcolormesh(np.arange(len(xs) + 1) - 0.5, np.arange(len(ys) + 1) - 0.5, grid, shading="flat",
                              norm=LogNorm() if logscale else None)
            ax.set_xticks(range(len(xs)), [_fmt(v, 3) for v in xs])
            ax.set_yticks(range(len(ys)), [_fmt(v, 3) for v in ys])
            for i in range(len(ys)):
                for j in range(len(xs)):
                    if np.isfinite(grid[i, j]):
                        ax.text(j, i, _fmt(float(grid[i, j]), 3), ha="center", va="center", fontsize=7,
                                bbox=dict(boxstyle="round,pad=0.15", fc="w", ec="none", alpha=0.7))
        else:
            m = ax.scatter(x, yy, c=y, s=40, norm=LogNorm() if logscale else None)
        fig.colorbar(m, ax=ax, label=label)
        ax.set_xlabel(px)
        ax.set_ylabel(py)
    ax.set_title(label)
    if len(params) == 1:
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def plot_speed_error(path, col, t, err, front, labels, tname):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    e = np.abs(err)
    ok = np.isfinite(t) & np.isfinite(e)
    ax.scatter(t[ok & ~front], e[ok & ~front], c="0.5", s=30, label="case")
    o = np.flatnonzero(front)
    o = o[np.argsort(t[o])]
    ax.plot(t[o], e[o], "o-", c="C3", ms=7, label="Pareto front")
    for k in o:  # the front's points carry their parameters (every case is in the report's table)
        ax.annotate(labels[k], (t[k], e[k]), fontsize=6, xytext=(4, 4), textcoords="offset points", color="C3")
    if np.all(t[ok] > 0):
        ax.set_xscale("log")
    if np.all(e[ok] > 0):
        ax.set_yscale("log")
    ax.set_xlabel(f"{tname} [s]")
    ax.set_ylabel(f"|{col}|")
    ax.set_title(f"speed against error: {col}")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


# ---------------------------------------------------------------------------------------------------------
# the report


def _summary_lines(study, rows, outdir):
    planned = study.get("cases")
    n_planned = len(planned) if isinstance(planned, (list, dict)) else None
    status = [r.get("status") for r in rows]
    wall = _numeric(rows, "wall_s")
    ranks = {r.get("rank") for r in rows if r.get("rank") is not None}
    lines = ["| | |", "|---|---|"]
    lines.append(f"| study | {study.get('name', Path(outdir).name)} |")
    lines.append(f"| engine | {study.get('engine', '?')} |")
    if _method(study):
        lines.append(f"| sampling | {_method(study)} |")
    if study.get("seed") is not None:
        lines.append(f"| seed | {study.get('seed')} |")
    lines.append(f"| cases planned | {n_planned if n_planned is not None else '?'} |")
    for s in ("ok", "failed", "timeout"):
        lines.append(f"| {s} | {status.count(s)} |")
    other = len(status) - sum(status.count(s) for s in ("ok", "failed", "timeout"))
    if other:
        lines.append(f"| other status | {other} |")
    if n_planned is not None:
        lines.append(f"| not run | {max(n_planned - len(rows), 0)} |")
    if np.isfinite(wall).any():
        lines.append(f"| total wall time of the cases | {np.nansum(wall):.1f} s |")
        lines.append(f"| median / max per case | {np.nanmedian(wall):.3g} s / {np.nanmax(wall):.3g} s |")
    if ranks:
        lines.append(f"| ranks that ran cases | {len(ranks)} |")
    return lines


def _stats_table(cols, data):
    out = ["| result | n | mean | sd | min | 5 % | median | 95 % | max |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for c in cols:
        v = data[c][np.isfinite(data[c])]
        if not len(v):
            out.append(f"| {c} | 0 | | | | | | | |")
            continue
        q = np.percentile(v, [5, 50, 95])
        out.append(f"| {c} | {len(v)} | {_fmt(float(v.mean()))} | {_fmt(float(v.std(ddof=1)) if len(v) > 1 else 0.0)} "
                   f"| {_fmt(float(v.min()))} | {_fmt(float(q[0]))} | {_fmt(float(q[1]))} | {_fmt(float(q[2]))} "
                   f"| {_fmt(float(v.max()))} |")
    return out


def _rows_table(rows, params, cols):
    head = ["case", "status", "wall_s", *params, *cols]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        out.append("| " + " | ".join(_fmt(r.get(h)) if h not in ("case", "status") else
                                     _fmt(r.get("case_id") if h == "case" else r.get("status")) for h in head) + " |")
    return out


def write_report(outdir) -> Path:
    """Write OUTDIR/report.md and the plots in OUTDIR/report/; returns the path of report.md."""
    outdir = Path(outdir)
    study = read_study(outdir)
    header, rows = read_results(outdir)
    if not study and not header:
        raise FileNotFoundError(f"{outdir}: no study.json or results.csv (run `cases study run` first)")
    figdir = outdir / "report"
    figdir.mkdir(parents=True, exist_ok=True)
    params = [c for c in header if c.startswith("p:")]
    cols = _result_columns(study, header, rows)
    ok_rows = [r for r in rows if r.get("status") == "ok"]
    data = {c: _numeric(ok_rows, c) for c in cols}
    numeric = [c for c in cols if np.isfinite(data[c]).any()]
    num_params = [p for p in params if ok_rows and all(isinstance(r.get(p), float) for r in ok_rows)
                  and len({r[p] for r in ok_rows}) > 1]
    mc = is_monte_carlo(study, rows, params)
    name = study.get("name", outdir.name)
    md = [f"# Study report: {name}", ""]
    if study.get("description"):
        md += [str(study["description"]), ""]
    md += ["## Summary", "", *_summary_lines(study, rows, outdir), ""]
    figures = 0

    def fig_line(path, caption):
        return f"![{caption}](report/{path.name})"

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
                md.append(f"| {c} | {k} | {n} | {pof:.4f} | {lo:.4f} - {hi:.4f} | "
                          f"{int(np.sum(~np.isfinite(data[c])))} |")
            if len(fs_cols) > 1:
                both = np.isfinite(data[fs_cols[0]]) & np.isfinite(data[fs_cols[1]])
                a, b = data[fs_cols[0]][both] < 1, data[fs_cols[1]][both] < 1
                md += ["", f"Same verdict (both fail or both hold) in {int(np.sum(a == b))} of {int(both.sum())} "
                           f"cases where {fs_cols[0]} and {fs_cols[1]} are both defined."]
            p = plot_distribution(figdir / "pof.png", fs_cols, data, fs=True)
            figures += 1
            md += ["", fig_line(p, "probability of failure"), ""]
        md += ["### Distributions", "", *_stats_table(numeric, data), ""]
        for c in numeric:
            if c in fs_cols or figures >= MAX_PLOTS:
                continue
            v = data[c][np.isfinite(data[c])]
            if len(v) < 2 or v.min() == v.max():
                continue
            p = plot_distribution(figdir / f"dist_{_slug(c)}.png", [c], data)
            figures += 1
            md += [f"**{c}**", "", fig_line(p, c), ""]
    else:
        md += ["## Results", ""]
        if len(rows) <= MAX_TABLE_ROWS:
            md += [*_rows_table(rows, params, numeric), ""]
        else:
            md += [*_stats_table(numeric, data), ""]
        if num_params and ok_rows:
            md += ["### Response surfaces", ""]
            use = num_params[:2]
            if len(num_params) > 2:
                md += [f"More than two parameters vary; the plots use {', '.join(use)}.", ""]
            for c in numeric:
                v = data[c][np.isfinite(data[c])]
                if c in TIME_COLUMNS or figures >= MAX_PLOTS or v.min() == v.max():
                    continue  # timings are in the speed-against-error plots; a constant needs no plot
                p = plot_response(figdir / f"response_{_slug(c)}.png", c, use, data, ok_rows)
                figures += 1
                md += [fig_line(p, c), ""]
        err_cols = [c for c in numeric if c.startswith("error_")]
        if err_cols and ok_rows:
            tname = next((c for c in TIME_COLUMNS if c in data and np.isfinite(data[c]).all()), "wall_s")
            t = data[tname] if tname in data else _numeric(ok_rows, "wall_s")
            labels = [", ".join(f"{p[2:].split('.')[-1]}={_fmt(r.get(p), 3)}" for p in params) or r.get("case_id", "")
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
                p = plot_speed_error(figdir / f"speed_error_{_slug(c)}.png", c, t, data[c], front, labels, tname)
                figures += 1
                md += [f"**{c}**", "", fig_line(p, f"speed against {c}"), "",
                       f"| case | {' | '.join(params)} | {tname} | {c} | Pareto |",
                       "|" + "---|" * (len(params) + 4)]
                for k in np.argsort(t):
                    r = ok_rows[k]
                    md.append(f"| {r.get('case_id')} | " + " | ".join(_fmt(r.get(q)) for q in params) +
                              f" | {_fmt(float(t[k]))} | {_fmt(float(data[c][k]))} | {'yes' if front[k] else ''} |")
                md.append("")
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
    return path


def main(argv=None):
    import sys

    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) != 1:
        print("usage: python -m cases.report OUTDIR", file=sys.stderr)
        return 2
    try:
        print(write_report(argv[0]))
    except (FileNotFoundError, CliError) as exc:
        print(f"cases.report: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["write_report", "pareto_front", "probability_of_failure", "wilson_interval", "exceedance",
           "read_results", "read_study"]
