"""Study report (cases/lib/report.py): Pareto front and probability of failure against brute-force transcriptions of
their definitions, and write_report on synthetic study folders laid out as the runner writes them."""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from cases.lib.report import exceedance, pareto_front, probability_of_failure, wilson_interval, write_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _pareto_brute(cost, err):
    """Definition: i is on the front unless some j is no worse in both and better in one."""
    out = []
    for i in range(len(cost)):
        if not (math.isfinite(cost[i]) and math.isfinite(err[i])):
            out.append(False)
            continue
        dominated = False
        for j in range(len(cost)):
            if j == i or not (math.isfinite(cost[j]) and math.isfinite(err[j])):
                continue
            if cost[j] <= cost[i] and err[j] <= err[i] and (cost[j] < cost[i] or err[j] < err[i]):
                dominated = True
                break
        out.append(not dominated)
    return out


def test_pareto_front_against_brute_force():
    rng = np.random.default_rng(3)
    for trial in range(300):
        n = int(rng.integers(1, 25))
        # small integer ranges give many ties in cost, in error and in both
        cost = rng.integers(0, 6, n).astype(float)
        err = rng.integers(0, 6, n).astype(float)
        if trial % 3 == 0:
            cost = rng.random(n)
            err = rng.random(n)
        if trial % 5 == 0:
            k = rng.integers(0, n, 2)
            cost[k[0]] = np.nan
            err[k[1]] = np.inf
        got = pareto_front(cost, err)
        assert got.tolist() == _pareto_brute(cost.tolist(), err.tolist()), (cost, err)


def test_pareto_front_simple_cases():
    assert pareto_front([], []).tolist() == []
    assert pareto_front([1, 2, 3], [3, 2, 1]).all()  # a trade-off: every point on the front
    assert pareto_front([1, 2, 3], [1, 2, 3]).tolist() == [True, False, False]
    assert pareto_front([1, 1], [2, 2]).tolist() == [True, True]  # identical points do not dominate each other


def test_probability_of_failure_and_interval():
    fs = [0.8, 1.2, 0.99, 1.0, np.nan, 3.0, 0.5, 1.01]
    pof, k, n = probability_of_failure(fs)
    assert (k, n) == (3, 8) and pof == 3 / 8  # 0.8, 0.99, 0.5 below 1; FS = 1 holds; NaN stable
    rng = np.random.default_rng(0)
    x = rng.normal(1.2, 0.3, 1000)
    assert probability_of_failure(x)[0] == sum(1 for v in x if v < 1.0) / 1000
    # Wilson score interval, textbook value for 5 of 10 at 95 %: 0.2366 .. 0.7634
    lo, hi = wilson_interval(5, 10)
    assert lo == pytest.approx(0.2366, abs=1e-4) and hi == pytest.approx(0.7634, abs=1e-4)
    lo, hi = wilson_interval(0, 20)
    assert lo == 0.0 and hi == pytest.approx(0.1611, abs=1e-4)


def test_exceedance_curve():
    x, p = exceedance([3.0, 1.0, 2.0, 2.0, np.nan])
    assert x.tolist() == [1.0, 2.0, 2.0, 3.0]
    assert p.tolist() == [0.75, 0.25, 0.25, 0.0]  # P(X > x) over the four finite values


def _write(outdir, study, header, rows, torn=None):
    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / "study.json").write_text(json.dumps(study))
    with open(outdir / "results.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow(r)
        if torn:
            fh.write(torn)  # a line cut short by a crash


def _pngs(outdir):
    files = sorted((outdir / "report").glob("*.png"))
    for f in files:
        assert f.read_bytes()[:8] == PNG_MAGIC
    return [f.name for f in files]


def test_report_monte_carlo(tmp_path):
    rng = np.random.default_rng(5)
    n = 40
    fs_hb = rng.normal(1.25, 0.25, n)
    fs_dda = fs_hb * (1 + rng.normal(0, 0.01, n))
    fs_hb[3] = np.nan  # no wedge: stable
    fs_dda[3] = np.nan
    header = ["case_id", "status", "error", "wall_s", "rank", "p:contact.friction", "p:generate.0.joint_a",
              "fs_dda", "fs_hb", "error_fs"]
    rows = []
    for k in range(n):
        rows.append([f"c{k:05d}", "ok", "", f"{0.5 + 0.01 * k}", k % 2, repr(20 + k * 0.1), json.dumps([45.0, k]),
                     repr(float(fs_dda[k])), repr(float(fs_hb[k])), repr(float(fs_dda[k] / fs_hb[k] - 1))])
    rows.append(["c00040", "failed", "BlowUpError: blow-up near t = 0.1 s | reduce dt", "0.2", 0, "21.0", "[45, 5]",
                 "", "", ""])
    rows.append(["c00041", "timeout", "time limit 600 s", "600.0", 1, "22.0", "[45, 6]", "", "", ""])
    study = {"name": "wedge_mc", "engine": "wedge-dda", "results": ["fs_dda", "fs_hb", "error_fs"], "seed": 1,
             "sampling": {"method": "random", "samples": 45},
             "cases": [{"case_id": f"c{k:05d}", "params": {}} for k in range(45)]}
    _write(tmp_path, study, header, rows, torn="c00042,ok,,0.5,0,2")
    md = write_report(tmp_path)
    assert md == tmp_path / "report.md"
    text = md.read_text()
    ok_hb, ok_dda = fs_hb, fs_dda  # the 40 ok rows
    for col, v in (("fs_dda", ok_dda), ("fs_hb", ok_hb)):
        k = sum(1 for x in v if x < 1.0)
        assert f"| {col} | {k} | {n} | {k / n:.4f} |" in text
    assert "| ok | 40 |" in text and "| failed | 1 |" in text and "| timeout | 1 |" in text
    assert "| not run | 3 |" in text  # 45 planned, 42 rows (the torn line dropped)
    assert "c00042" not in text
    assert "BlowUpError: blow-up near t = 0.1 s \\| reduce dt" in text and "time limit 600 s" in text
    assert "| ranks that ran cases | 2 |" in text
    names = _pngs(tmp_path)
    assert "pof.png" in names and "dist_error_fs.png" in names
    for name in names:
        assert f"(report/{name})" in text


def test_report_grid_sweep_speed_against_error(tmp_path):
    safety = [0.5, 0.25, 0.125]
    kn = [1e9, 1e10]
    header = ["case_id", "status", "error", "wall_s", "rank", "p:simulation.safety", "p:contact.kn", "error_disp",
              "steps"]
    rows, t, e = [], [], []
    k = 0
    for s in safety:
        for q in kn:
            wall = 0.1 * (q / 1e9) ** 0.5 / s
            err = 1e-3 * (1e9 / q) ** 0.5 + 1e-4 * s
            if k == 4:
                err = 5e-3  # a poor case: dominated
            rows.append([f"c{k:05d}", "ok", "", repr(wall), 0, repr(s), repr(q), repr(-err), repr(int(100 / s))])
            t.append(wall)
            e.append(err)
            k += 1
    study = {"name": "incline_res", "engine": "dda-run", "results": ["error_disp", "steps"],
             "sampling": {"method": "grid"}, "cases": [{"case_id": r[0]} for r in rows]}
    _write(tmp_path, study, header, rows)
    text = write_report(tmp_path).read_text()
    names = _pngs(tmp_path)
    assert {"response_error_disp.png", "response_steps.png", "speed_error_error_disp.png"} <= set(names)
    front = _pareto_brute(t, e)
    section = text.split("### Speed against error")[1]
    for k, r in enumerate(rows):
        line = next(x for x in section.splitlines() if x.startswith(f"| {r[0]} |"))
        assert line.rstrip().endswith("| yes |") == front[k], line
    assert "| failed | 0 |" in text and "None." in text


def test_report_one_parameter_sweep(tmp_path):
    header = ["case_id", "status", "error", "wall_s", "rank", "p:contact.friction", "fs"]
    rows = [[f"c{k:05d}", "ok", "", "0.01", 0, repr(f), repr(math.tan(math.radians(f)) / math.tan(math.radians(20)))]
            for k, f in enumerate((15.0, 20.0, 25.0, 30.0))]
    _write(tmp_path, {"name": "fric", "engine": "wedge-hb", "results": ["fs"],
                      "parameters": {"contact.friction": {"grid": [15, 20, 25, 30]}}}, header, rows)
    text = write_report(tmp_path).read_text()
    assert _pngs(tmp_path) == ["response_fs.png"]
    assert "Monte-Carlo" not in text and "| c00003 | ok |" in text


# --------------------------------------------------------------------------------------------- issue 17, point 9
def _capture(monkeypatch):
    """What every saved figure shows: titles, axis labels and scales, colour norms (read from matplotlib)."""
    import cases.lib.figures as rp

    seen = {}
    real = rp._save

    def save(fig, path):
        axes = []
        for ax in fig.axes:
            norms = [type(c.norm).__name__ for c in ax.collections if hasattr(c, "norm")]
            axes.append({"title": ax.get_title(), "xlabel": ax.get_xlabel(), "ylabel": ax.get_ylabel(),
                         "xscale": ax.get_xscale(), "yscale": ax.get_yscale(), "norms": norms})
        seen[path.name] = {"suptitle": fig._suptitle.get_text() if fig._suptitle else "", "axes": axes}
        return real(fig, path)

    monkeypatch.setattr(rp, "_save", save)
    return seen


def test_report_units_names_titles_inputs_and_timing_apart(tmp_path, monkeypatch):
    """The reproducer of the issue: a Monte-Carlo wedge study (Fisher joint, normal friction) whose report had no
    units, raw column names, titles without the study, no picture of the inputs and timing plotted as a result."""
    seen = _capture(monkeypatch)
    rng = np.random.default_rng(2)
    n = 60
    header = ["case_id", "status", "error", "wall_s", "rank", "p:contact.friction", "p:generate.0.joint_a", "fs",
              "volume", "error_fs", "run_s"]
    rows = []
    for k in range(n):
        dip, dd = float(rng.normal(45, 4)), float(rng.normal(5, 4) % 360)
        rows.append([f"c{k:05d}", "ok", "", repr(0.01 + 0.001 * k), 0, repr(float(rng.normal(25, 3))),
                     json.dumps([dip, dd]), repr(float(rng.normal(1.3, 0.3))), repr(float(rng.uniform(100, 900))),
                     repr(float(rng.normal(0, 0.01))), repr(float(rng.uniform(0.5, 1.5)))])
    study = {"name": "wedge_pof", "evaluator": "wedge-dda", "results": ["fs", "volume", "error_fs", "run_s"],
             "units": {"fs": "-", "volume": "m^3", "run_s": "s"}, "sampling": {"method": "random", "samples": n},
             "parameters": {"contact.friction": {"normal": [25.0, 3.0]},
                            "generate.0.joint_a": {"fisher": {"dip": 45.0, "dip_direction": 5.0, "kappa": 100.0}}},
             "cases": [{"case_id": f"c{k:05d}"} for k in range(n)]}
    _write(tmp_path, study, header, rows)
    text = write_report(tmp_path).read_text()
    assert "`p:contact.friction` deg" in text and "`volume` m^3" in text
    assert "`error_fs` = FS_DDA / FS_HB - 1" in text  # what the error means
    assert "inputs.png" in seen and "dist_run_s.png" not in seen  # timing is not drawn as a result
    stats = text.split("### Distributions")[1].split("## Timing")[0]
    assert "| run_s |" not in stats and "run_s" in text.split("## Timing")[1]
    inputs = seen["inputs.png"]
    assert "wedge_pof" in inputs["suptitle"]
    titles = [a["title"] for a in inputs["axes"]]
    assert any("equal-area" in t and "joint A orientation" in t for t in titles)
    hist = next(a for a in inputs["axes"] if "friction" in a["title"])
    assert hist["xlabel"] == "joint friction angle (contact.friction) [deg]"
    for name, fig in seen.items():
        for a in fig["axes"]:
            if a["title"] and not fig["suptitle"]:  # panels under a figure title that names the study
                assert a["title"].startswith("wedge_pof:"), (name, a["title"])
            assert "p:" not in a["xlabel"] + a["ylabel"], (name, a)
    vol = seen["dist_volume.png"]["axes"][0]
    assert vol["xlabel"] == "wedge volume [m^3]"


def test_pole_projection_equal_area_lower_hemisphere():
    from cases.lib.figures import pole_projection

    # a horizontal plane's pole is vertical: the centre; a vertical plane dipping east has a horizontal pole
    # pointing west: on the primitive circle (radius sqrt 2 sin 45 = 1) at the west; dip 60 towards north: the
    # pole plunges 30 towards south, at sqrt(2) sin(30) from the centre
    for (dip, dd), (x, y) in (((0.0, 123.0), (0.0, 0.0)), ((90.0, 90.0), (-1.0, 0.0)),
                              ((60.0, 0.0), (0.0, -math.sqrt(2) * 0.5))):
        px, py = pole_projection(dip, dd)
        assert abs(px - x) < 1e-12 and abs(py - y) < 1e-12
    # equal area: the fraction of poles within angle t of the vertical is 1 - cos t, the area fraction r^2 / 2
    rng = np.random.default_rng(1)
    z = rng.uniform(0, 1, 20000)  # uniform on the lower hemisphere: cos of the pole's angle from vertical
    dip = np.degrees(np.arccos(z))
    x, y = pole_projection(dip, rng.uniform(0, 360, len(z)))
    inner = np.mean(x * x + y * y <= 0.5)  # the circle of radius 1 / sqrt 2: half the net's area, 1 - cos 60
    assert abs(inner - 0.5) < 0.015


def test_one_number_format_per_column_and_log_scales(tmp_path, monkeypatch):
    """The issue's column switched between `29815` and `2.994e+04`; a 65x error range was drawn on a linear colour
    scale."""
    from cases.lib.report import column_format

    col = [29815.0, 29940.3, 31000.25, 30000.0]
    f = column_format(col)
    out = [f(v) for v in col]
    assert len({len(s.split(".")[-1]) if "." in s else 0 for s in out}) == 1 and not any("e" in s for s in out), out
    assert [float(s) for s in out] == pytest.approx(col, rel=1e-4)
    seen = _capture(monkeypatch)
    header = ["case_id", "status", "error", "wall_s", "rank", "p:simulation.safety", "p:contact.kn", "error_disp",
              "steps"]
    rows, k = [], 0
    for s in (0.8, 0.4, 0.2, 0.1):
        for q in (1e8, 1e9, 1e10):
            err = 2e-4 * (1e10 / q) ** 0.5 * (1 + s)  # spans 1.2e-4 .. 3.6e-3: about 30x
            rows.append([f"c{k:05d}", "ok", "", "0.5", 0, repr(s), repr(q), repr(err), repr(1000 + 37 * k)])
            k += 1
    study = {"name": "incline_res", "evaluator": "dda-run", "results": ["error_disp", "steps"],
             "sampling": {"method": "grid"}, "cases": [{"case_id": r[0]} for r in rows]}
    _write(tmp_path, study, header, rows)
    text = write_report(tmp_path).read_text()
    mesh = seen["response_error_disp.png"]["axes"][0]
    assert "LogNorm" in mesh["norms"] and mesh["xlabel"] == "time-step safety factor (simulation.safety)"
    assert seen["response_error_disp.png"]["axes"][1]["ylabel"].startswith("|s / s_ref - 1| [relative]")
    lin = seen["response_steps.png"]["axes"][0]
    assert "LogNorm" not in lin["norms"]  # 1000 .. 1407: less than 10x
    table = [ln.split("|")[1:-1] for ln in text.split("## Results")[1].split("###")[0].splitlines()
             if ln.startswith("| c0")]
    for j in range(2, 6):
        cells = [c.strip() for c in (r[j] for r in table)]
        styles = {("e" in c, len(c.split(".")[-1].split("e")[0]) if "." in c else 0) for c in cells}
        assert len(styles) == 1, cells
