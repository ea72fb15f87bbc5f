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

import os
import sys
from pathlib import Path

import numpy as np

from sgim.common import CliError

from .figures import plot_distribution, plot_inputs, plot_response, plot_speed_error
from .results import ERRORS, FS_RE, MAX_PLOTS, MAX_TABLE_ROWS, NO_UNIT, TIME_COLUMNS, Names, _fmt, _method, \
    _numeric, _result_columns, _slug, column_format, exceedance, integer_columns, is_monte_carlo, is_timing, \
    pareto_front, probability_of_failure, read_results, read_study, wilson_interval


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
