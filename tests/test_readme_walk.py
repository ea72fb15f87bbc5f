"""The README's first walk works as written: every line of its marked block, pasted into a shell at the top of
a checkout, succeeds, and what the lines say they write is there.

The block runs in a folder that holds the checkout's `cases` and `.venv` (links), so `out/` lands in a temporary
folder; the lines run one after the other, each in bash, as a user pastes them. The Python walk
(cases/make/example_api.py) is checked against its references here: the analytical slide of the incline and YADE's
run of the same column deck."""
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def walk_lines():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("<!-- walk -->", 1)[1].split("<!-- /walk -->", 1)[0]
    body = block.split("```sh\n", 1)[1].rsplit("```", 1)[0]
    return [ln for ln in body.splitlines() if ln.strip()]


def test_the_first_walk_runs_line_by_line(tmp_path):
    lines = walk_lines()
    assert len(lines) >= 10 and all(ln.startswith(".venv/bin/") for ln in lines)
    (tmp_path / "cases").symlink_to(ROOT / "cases")
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    for ln in lines:
        p = subprocess.run(["bash", "-c", ln], cwd=tmp_path, capture_output=True, text=True, timeout=900, env=env)
        assert p.returncode == 0, f"{ln}\n{p.stderr[-2000:]}"
        if "dda run cases/scenes/dda_incline.toml" in ln:
            assert re.search(r"slide distance: [0-9.]+ m \(reference 0.9064 m: error [-+][0-9.e-]+ %\)", p.stdout)
        if "study report" in ln:
            assert (tmp_path / "out/pof/report.md").is_file()
        if "cases.make.example_api" in ln:  # the Python walk's numbers against their references
            slide = re.search(r"slide distance: ([0-9.]+) m, analytical ([0-9.]+) m", p.stdout)
            g, a, f = 9.81, math.radians(30), math.radians(20)
            assert slide and float(slide[1]) == pytest.approx(float(slide[2]), rel=1e-3)
            assert float(slide[2]) == pytest.approx(0.5 * g * (math.sin(a) - math.tan(f) * math.cos(a)), rel=1e-3)
            dz = re.search(r"YADE (-?[0-9.]+) um, in-house (-?[0-9.]+) um", p.stdout)
            assert dz and float(dz[1]) < 0 and float(dz[2]) == pytest.approx(float(dz[1]), rel=1e-3)
    out = tmp_path / "out"
    for f in ("pit/model.npz", "pit/model.png", "pit/corner.png", "incline/summary.json", "incline/series.png",
              "column/result/result.pvd", "column_dda/result.npz", "api/model.npz"):
        assert (out / f).is_file(), f
    answers = json.loads((out / "incline/summary.json").read_text())["answers"]
    assert answers[0]["label"] == "slide distance"
