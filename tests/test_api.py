"""The Python API of the package tops (docs/api.md): the names exist, carry docstrings and do what the command
line does. cases/make/example_api.py, the notebook-style walk, runs in tests/test_readme_walk.py with the README's
other lines, which checks its numbers against their references."""
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_the_package_tops_export_the_api_with_docstrings():
    import adapters
    import dda
    import sgim

    for mod in (sgim, dda, adapters):
        for name in mod.__all__:
            obj = getattr(mod, name)
            if isinstance(obj, dict):  # a table (dda.GENERATORS)
                continue
            doc = obj.__doc__ or ""
            # a dataclass without a docstring gets its signature as __doc__: that is not documentation
            assert len(doc.strip()) > 20 and not doc.startswith(f"{name}("), f"{mod.__name__}.{name} has no docstring"
    from dda import BlockSystem, Simulation  # noqa: F401 - the names a reader of the docs tries first
    with pytest.raises(AttributeError):
        dda.no_such_name  # noqa: B018


def test_the_api_builds_the_model_the_command_line_builds(tmp_path):
    import sgim
    from sgim.cli import main

    scene = ROOT / "cases" / "scenes" / "crossval" / "column_model.toml"
    assert main(["build", str(scene), "-o", str(tmp_path / "cli"), "--formats", "npz", "--quiet"]) == 0
    cli = sgim.load(tmp_path / "cli" / "model.npz")
    api = sgim.build(scene)
    for key in ("centers", "radii", "colour", "bonds", "bonded"):
        assert np.array_equal(getattr(api, key), getattr(cli, key)), key
    with pytest.raises(sgim.SceneError, match="packing.radius"):
        sgim.build({"domain": {"min": [0, 0, 0], "max": [1, 1, 1]}, "packing": {"kind": "cubic", "radius": -1}})


def test_dda_run_in_memory_writes_nothing_and_matches_the_folder_run(tmp_path, monkeypatch):
    import dda

    monkeypatch.chdir(tmp_path)
    scene = ROOT / "cases" / "scenes" / "dda_deformable_column.toml"
    mem = dda.run(scene)
    assert list(tmp_path.iterdir()) == []
    disk = dda.run(scene, out=tmp_path / "run")
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["answers"] == disk.answers
    assert [a["value"] for a in mem.answers] == [a["value"] for a in disk.answers]
    (a,) = mem.answers
    assert a["quantity"] == "shortening" and a["value"] == pytest.approx(2600 * 9.81 * 4 / (2 * 1e8), rel=1e-3)
