"""The figures of a study's report (cases/lib/report.py), PNGs drawn off-screen with matplotlib (imported on the
first figure, so that reading a table does not load it): distributions and exceedance curves, response surfaces,
speed against error with the Pareto front, the inputs (stereonet poles of sampled orientations, histograms of
sampled values). Each is written under a temporary name and renamed into place (:func:`_save`).
"""
from __future__ import annotations

import math
import os

import numpy as np

from .results import NO_UNIT, _numeric, _param_specs, column_format, exceedance, probability_of_failure


# ---------------------------------------------------------------------------------------------------------
# plots


def _plt():
    # matplotlib is imported here and in the functions below, at the first figure (see the module doc)
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
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # lazy: see _plt

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
        from matplotlib.ticker import NullFormatter  # lazy: see _plt

        ax.set_xticks(xs, _tick_labels(xs, column_format(list(xs))))
        ax.xaxis.set_minor_formatter(NullFormatter())


def plot_response(path, col, params, data, rows, names):
    """Response of result `col` over one numeric parameter (a line) or two (colour map on the full grid, else a
    coloured scatter). Errors are drawn as their size; log scales where values span more than 10x."""
    plt = _plt()
    from matplotlib.colors import LogNorm  # lazy: see _plt

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
