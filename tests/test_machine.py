"""The machine line (sgim/machine.py) and the "machine" entry of summary.json."""
from __future__ import annotations

import json
import os
import platform

import numpy
import scipy

from sgim.cli import main
from sgim.machine import PACKAGES, cpu_model, machine_info, machine_line
from test_scene_cli import BASE  # the smallest scene of the CLI tests (80 lattice sites)


def test_machine_info():
    info = machine_info()
    assert set(info) >= {"cpu", "cores", "platform", "python", *PACKAGES}
    assert info["cpu"] == cpu_model() and info["cpu"].strip()
    assert info["cores"] == os.cpu_count()
    assert info["python"] == platform.python_version()
    assert info["numpy"] == numpy.__version__ and info["scipy"] == scipy.__version__
    assert all(isinstance(info[name], str) and info[name] for name in PACKAGES)
    assert json.loads(json.dumps(info)) == info


def test_machine_line():
    info = machine_info()
    line = machine_line()
    assert "\n" not in line
    assert line.startswith(f"{info['cpu']}, {info['cores']} core")
    for part in (f"python {info['python']}", f"numpy {numpy.__version__}", f"numba {info['numba']}",
                 f"llvmlite {info['llvmlite']}", f"scipy {scipy.__version__}"):
        assert part in line
    fake = {"cpu": "Some CPU", "cores": 1, "python": "3.11.7", "numpy": "2.4.6", "numba": None, "llvmlite": "0.50.0",
            "scipy": "1.17.1"}
    assert machine_line(fake) == "Some CPU, 1 core, python 3.11.7, numpy 2.4.6, llvmlite 0.50.0, scipy 1.17.1"


def test_build_summary_records_the_machine(tmp_path, capsys):
    (tmp_path / "scene.toml").write_text(BASE)
    out = tmp_path / "out"
    assert main(["build", str(tmp_path / "scene.toml"), "-o", str(out), "--formats", "npz", "--quiet", "--json"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["machine"]["numpy"] == numpy.__version__
    assert summary["machine"]["cores"] == os.cpu_count() and summary["machine"]["cpu"] == cpu_model()
    assert json.loads(capsys.readouterr().out)["machine"] == summary["machine"]
