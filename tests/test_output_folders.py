"""Output folders never lose a user's file (sgim/outdir.py), through the commands' main(argv) in process.

The reported cases: `sgim build mine.toml -o $PWD` wiped the folder (an unrelated important.txt and the scene
itself); `dda run` and `adapters export` deleted a notes.txt placed in their output folders; a rebuild with
`--formats npz` silently removed the earlier VTU and PNG; `-o .` ended in a traceback. The rule: a command writes
into a new or empty folder, or (with --force) over its own earlier output, replacing only the files its marker
lists; anything else is refused with one line, exit status 2, nothing touched.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from sgim.outdir import MARKER

ROOT = Path(__file__).resolve().parents[1]

SCENE = """\
name = "small"
[domain]
min = [0.0, -2.0, 0.0]
max = [5.0, 2.0, 4.0]
[packing]
kind = "cubic"
radius = 0.5
"""


def sgim(*args):
    from sgim.cli import main

    return main([str(a) for a in args])


def dda(*args):
    from dda.cli import main

    return main([str(a) for a in args])


def adapters(*args):
    from adapters.cli import main

    return main([str(a) for a in args])


def snapshot(folder):
    """{relative path: bytes} of every file under `folder` (hidden ones included)."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def one_error_line(capsys, prog):
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error: "), err
    return lines[0]


def marker(folder):
    return json.loads((Path(folder) / MARKER).read_text())


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "mine.toml"
    p.write_text(SCENE)
    return p


@pytest.fixture
def incline(tmp_path):
    text = (ROOT / "cases" / "scenes" / "dda_incline.toml").read_text()
    text = text.replace("duration = 1.0", "duration = 0.02").replace("frames = 10", "frames = 2")
    assert "duration = 0.02" in text and "frames = 2" in text
    p = tmp_path / "incline.toml"
    p.write_text(text)
    return p


# -- sgim build ------------------------------------------------------------------------------------------------
def test_build_into_the_current_folder_holding_user_files_is_refused(tmp_path, scene, monkeypatch, capsys):
    (tmp_path / "important.txt").write_text("do not lose me\n")
    monkeypatch.chdir(tmp_path)
    before = snapshot(tmp_path)
    for target in (str(tmp_path), ".", f"{tmp_path}/", f"{tmp_path}/../{tmp_path.name}"):
        assert sgim("build", "mine.toml", "-o", target, "--formats", "npz") == 2
        line = one_error_line(capsys, "sgim")
        want = f"-o = {str(Path(target))!r}: folder exists and holds files this tool did not write"
        assert f"{want} (important.txt, mine.toml); choose a new folder" in line
        assert snapshot(tmp_path) == before  # both files intact, nothing added (no temporary folder either)
        assert sorted(os.listdir(tmp_path)) == ["important.txt", "mine.toml"]
    # --force does not change that: the files are not the tool's
    assert sgim("build", "mine.toml", "-o", ".", "--force", "--formats", "npz") == 2
    assert "did not write" in one_error_line(capsys, "sgim")
    assert snapshot(tmp_path) == before


def test_build_into_an_empty_current_folder(tmp_path, scene, monkeypatch, capsys):
    here = tmp_path / "empty"
    here.mkdir()
    monkeypatch.chdir(here)
    assert sgim("build", scene, "-o", ".", "--formats", "npz,vtu") == 0
    err = capsys.readouterr().err
    assert ".part" not in err and ".rockdem-part" not in err
    assert "write npz     " in err and "model.npz" in err
    assert sorted(os.listdir(here)) == [MARKER, "model.npz", "model.vtu", "summary.json"]
    m = marker(here)
    assert m["tool"] == "rockdem" and m["command"] == "sgim build" and m["time"]
    assert m["files"] == ["model.npz", "model.vtu", "summary.json"]
    assert here.is_dir() and Path.cwd() == here  # the current folder was written into, never renamed


def test_build_into_its_own_output_needs_force_and_keeps_user_files(tmp_path, scene, capsys):
    out = tmp_path / "out"
    assert sgim("build", scene, "-o", out, "--formats", "npz,vtu,png", "--quiet") == 0
    assert set(marker(out)["files"]) == {"model.npz", "model.vtu", "model.png", "summary.json"}
    (out / "notes.txt").write_text("mine\n")
    before = snapshot(out)
    assert sgim("build", scene, "-o", out, "--formats", "npz", "--quiet") == 2
    line = one_error_line(capsys, "sgim")
    assert "holds an earlier output of sgim build" in line and "--force replaces it" in line
    assert snapshot(out) == before
    # --formats npz --force: the earlier VTU and PNG are the tool's own (listed in the marker) and not written
    # again: removed, so the folder never shows a stale model.vtu beside the new model.npz; notes.txt stays
    assert sgim("build", scene, "-o", out, "--formats", "npz", "--force") == 0
    err = capsys.readouterr().err
    assert "kept       1 file this tool did not write: notes.txt" in err
    assert sorted(os.listdir(out)) == [MARKER, "model.npz", "notes.txt", "summary.json"]
    assert (out / "notes.txt").read_text() == "mine\n"
    assert marker(out)["files"] == ["model.npz", "summary.json"]
    assert json.loads((out / "summary.json").read_text()) != json.loads(before["summary.json"])  # rewritten


def test_a_user_file_with_an_output_name_is_refused_even_with_force(tmp_path, scene, capsys):
    out = tmp_path / "out"
    assert sgim("build", scene, "-o", out, "--formats", "npz", "--quiet") == 0
    (out / "model.vtu").write_text("the user's own file\n")
    before = snapshot(out)
    assert sgim("build", scene, "-o", out, "--formats", "npz,vtu", "--force", "--quiet") == 2
    line = one_error_line(capsys, "sgim")
    assert "model.vtu would be overwritten, but this tool did not write it" in line
    assert snapshot(out) == before
    assert sorted(os.listdir(out)) == [MARKER, "model.npz", "model.vtu", "summary.json"]


def test_a_failing_build_leaves_the_earlier_output_as_it_was(tmp_path, scene, monkeypatch):
    from sgim.model import SphereModel

    out = tmp_path / "out"
    assert sgim("build", scene, "-o", out, "--formats", "npz,vtu", "--quiet") == 0
    (out / "notes.txt").write_text("mine\n")
    before = snapshot(out)

    def full_disk(self, path):
        Path(path).write_bytes(b"half a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(SphereModel, "save_vtu", full_disk)
    with pytest.raises(OSError, match="No space left"):
        sgim("build", scene, "-o", out, "--formats", "npz,vtu", "--force", "--quiet")
    assert snapshot(out) == before  # the earlier output, its marker and notes.txt, byte for byte
    assert sorted(os.listdir(out)) == [MARKER, "model.npz", "model.vtu", "notes.txt", "summary.json"]
    assert sorted(os.listdir(tmp_path)) == ["mine.toml", "out"]
    # and a failing build into a new folder leaves nothing behind
    with pytest.raises(OSError, match="No space left"):
        sgim("build", scene, "-o", tmp_path / "new", "--formats", "npz,vtu", "--quiet")
    assert sorted(os.listdir(tmp_path)) == ["mine.toml", "out"]


def test_paths_trailing_slash_dotdot_and_symlink(tmp_path, scene, capsys):
    (tmp_path / "sub").mkdir()
    assert sgim("build", scene, "-o", f"{tmp_path}/sub/../out/", "--formats", "npz", "--quiet") == 0
    assert sorted(os.listdir(tmp_path / "out")) == [MARKER, "model.npz", "summary.json"]
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "out")
    (tmp_path / "out" / "notes.txt").write_text("mine\n")
    assert sgim("build", scene, "-o", link, "--formats", "npz", "--quiet") == 2
    assert f"-o = '{link}': folder holds an earlier output" in one_error_line(capsys, "sgim")
    assert sgim("build", scene, "-o", f"{link}/", "--formats", "npz,vtu", "--force", "--quiet") == 0
    assert link.is_symlink() and (tmp_path / "out").is_dir()  # the link stays a link, written through
    assert sorted(os.listdir(tmp_path / "out")) == [MARKER, "model.npz", "model.vtu", "notes.txt", "summary.json"]
    assert sorted(os.listdir(tmp_path)) == ["link", "mine.toml", "out", "sub"]


def test_another_commands_output_is_not_replaced(tmp_path, scene, incline, capsys):
    out = tmp_path / "out"
    assert sgim("build", scene, "-o", out, "--formats", "npz", "--quiet") == 0
    before = snapshot(out)
    assert dda("run", incline, "-o", out, "--force", "--quiet") == 2
    line = one_error_line(capsys, "dda")
    assert "holds an earlier output of sgim build, not of dda run" in line
    assert snapshot(out) == before


def test_a_broken_marker_is_refused(tmp_path, scene, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / MARKER).write_text("not json")
    assert sgim("build", scene, "-o", out, "--force", "--quiet") == 2
    assert "is not an output marker of this tool" in one_error_line(capsys, "sgim")
    assert snapshot(out) == {MARKER: b"not json"}


# -- dda run ---------------------------------------------------------------------------------------------------
def test_dda_run_keeps_notes(tmp_path, incline, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")
    assert dda("run", incline, "-o", out, "--quiet") == 2
    line = one_error_line(capsys, "dda")
    assert "folder exists and holds files this tool did not write (notes.txt)" in line
    assert snapshot(out) == {"notes.txt": b"mine\n"}
    (out / "notes.txt").unlink()
    assert dda("run", incline, "-o", out) == 0  # an empty folder is fine
    err = capsys.readouterr().err
    assert f"render     {out / 'final.png'}" in err and ".part" not in err
    own = set(marker(out)["files"])
    assert {"final.npz", "final.png", "summary.json", "frames/frame_00000.vtu"} <= own
    (out / "notes.txt").write_text("mine\n")
    (out / "frames" / "mine.txt").write_text("mine too\n")
    assert dda("run", incline, "-o", out, "--quiet") == 2
    assert "--force replaces it" in one_error_line(capsys, "dda")
    assert dda("run", incline, "-o", out, "--force", "--quiet") == 0
    assert (out / "notes.txt").read_text() == "mine\n" and (out / "frames" / "mine.txt").read_text() == "mine too\n"
    assert set(marker(out)["files"]) == own
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"


def test_dda_run_with_fewer_formats_removes_its_stale_frames_only(tmp_path, incline):
    out = tmp_path / "run"
    assert dda("run", incline, "-o", out, "--quiet") == 0
    (out / "frames" / "mine.txt").write_text("mine\n")
    text = incline.read_text() + '\n[output]\nformats = ["npz"]\n'
    incline.write_text(text)
    assert dda("run", incline, "-o", out, "--force", "--quiet") == 0
    assert sorted(os.listdir(out / "frames")) == ["mine.txt"]  # the tool's frames gone, the user's file kept
    assert not (out / "final.png").exists() and not (out / "blocks.pvd").exists()
    assert "frames/frame_00000.vtu" not in marker(out)["files"]


# -- adapters export -------------------------------------------------------------------------------------------
def test_adapters_export_keeps_notes(tmp_path, scene, capsys):
    deck = tmp_path / "deck"
    deck.mkdir()
    (deck / "notes.txt").write_text("mine\n")
    assert adapters("export", scene, "--to", "vtu", "-o", deck, "--quiet") == 2
    line = one_error_line(capsys, "adapters")
    assert "folder exists and holds files this tool did not write (notes.txt)" in line
    assert snapshot(deck) == {"notes.txt": b"mine\n"}
    (deck / "notes.txt").unlink()
    assert adapters("export", scene, "--to", "vtu", "-o", deck, "--quiet") == 0
    assert marker(deck)["command"] == "adapters export"
    (deck / "notes.txt").write_text("mine\n")
    assert adapters("export", scene, "--to", "vtu", "-o", deck, "--quiet") == 2
    assert "--force replaces it" in one_error_line(capsys, "adapters")
    assert adapters("export", scene, "--to", "pfc-text", "-o", deck, "--force", "--quiet") == 0
    assert sorted(os.listdir(deck)) == [MARKER, "balls.txt", "contacts.txt", "deck.json", "notes.txt"]
    assert json.loads((deck / "deck.json").read_text())["files"] == ["balls.txt", "contacts.txt"]


# -- cases study run -------------------------------------------------------------------------------------------
STUDY = """\
base = "base.toml"
engine = "noop"
results = []
[parameters]
"contact.friction" = {{ grid = [{values}] }}
"""


def _study(folder, values):
    folder.mkdir()
    (folder / "base.toml").write_text('name = "b"\n[contact]\nfriction = 18.0\n')
    p = folder / "study.toml"
    p.write_text(STUDY.format(values=values))
    return p


def test_study_run_refuses_user_files_and_force_replaces_a_different_study(tmp_path, capsys):
    from cases.lib.study import main

    a, b = _study(tmp_path / "a", "1.0, 2.0, 5.0"), _study(tmp_path / "b", "1.0, 3.0")
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")
    assert main(["run", str(a), "-o", str(out), "--quiet"]) == 2
    assert "holds files this tool did not write (notes.txt)" in one_error_line(capsys, "cases study")
    assert snapshot(out) == {"notes.txt": b"mine\n"}
    (out / "notes.txt").unlink()
    assert main(["run", str(a), "-o", str(out), "--quiet"]) == 0
    assert marker(out)["command"] == "cases study run"
    (out / "notes.txt").write_text("mine\n")
    assert main(["run", str(a), "-o", str(out), "--quiet"]) == 0  # the same study: resumed (nothing to run)
    assert main(["run", str(b), "-o", str(out), "--quiet"]) == 2
    line = one_error_line(capsys, "cases study")
    assert "different study" in line and "--force" in line
    assert main(["run", str(b), "-o", str(out), "--quiet", "--force"]) == 0
    assert (out / "notes.txt").read_text() == "mine\n"
    assert sorted(os.listdir(out / "cases")) == ["c00000", "c00001"]  # the earlier study's c00002 removed
    assert len((out / "results.csv").read_text().splitlines()) == 3
    assert json.loads((out / "study.json").read_text())["study"] == str(b)


# -- every command that writes a folder takes --force ----------------------------------------------------------
@pytest.mark.parametrize("run,args", [(sgim, ("build", "--help")), (sgim, ("dfn", "--help")),
                                      (dda, ("run", "--help")), (adapters, ("export", "--help"))])
def test_force_is_documented(run, args, capsys):
    with pytest.raises(SystemExit):
        run(*args)
    assert "--force" in capsys.readouterr().out


def test_study_force_is_documented(capsys):
    from cases.lib.study import main

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "--force" in capsys.readouterr().out
