"""Output folders that never lose a user's file.

Every command that writes a folder (``sgim build``, ``sgim dfn``, ``dda run``, ``adapters export``; ``cases study
run`` keeps its own restartable layout, see cases/lib/_batch.py) goes through :class:`OutputFolder`:

* A command writes only into a folder it creates, an empty folder, or a folder holding the marker file
  ``.rockdem-output`` of the same command (JSON: tool, command, time and the list of files it wrote). A
  non-empty folder without the marker is refused with one line and left untouched; so is a folder holding
  another command's output.
* A folder holding the command's earlier output is refused unless ``--force``; with ``--force`` the command
  replaces the earlier output, and only it: the files the marker lists are overwritten or, when not written
  again (e.g. ``--formats npz`` after a build with VTU and PNG), removed, so that the folder never shows a
  stale file next to the new ones. Files the marker does not list (added by the user) stay, and a new
  output whose name is taken by such a file is refused.
* Nothing is half-written: the files are assembled in a temporary folder (beside a new target,
  ``.NAME.partPID``; inside an existing one, ``.rockdem-partPID``) and moved into place at the end; a
  failing command removes it and leaves the target as it was. The target is resolved first (``-o .``,
  ``-o $PWD``, trailing slashes, ``..``, symlinks): an existing folder, the current one included, is never
  renamed or removed, only the files in it.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from contextlib import contextmanager
from pathlib import Path

from .common import CliError

MARKER = ".rockdem-output"
TMP_PREFIX = ".rockdem-part"
SHOWN = 3  # names shown in a refusal


def _cli_error(msg):
    return CliError(msg)


def shown_names(paths, shown=SHOWN):
    paths = sorted(paths)
    return ", ".join(paths[:shown]) + (", ..." if len(paths) > shown else "")


def folder_entries(folder):
    """Names in `folder` other than the marker and temporary assembly folders."""
    return sorted(n for n in os.listdir(folder) if n != MARKER and not n.startswith(TMP_PREFIX))


def _files(root, skip_top=True):
    """Relative POSIX paths of every file (anything but a directory; symlinks are not followed) under `root`."""
    out = []
    for d, dirs, files in os.walk(root):
        rel = Path(d).relative_to(root)
        if skip_top and rel == Path("."):
            dirs[:] = [x for x in dirs if not x.startswith(TMP_PREFIX)]
            files = [f for f in files if f != MARKER]
        for x in list(dirs):
            if os.path.islink(os.path.join(d, x)):  # a link to a folder is a file of the folder, not entered
                dirs.remove(x)
                files.append(x)
        out += [(rel / f).as_posix() for f in files]
    return sorted(out)


def read_marker(folder):
    """The marker of `folder` as a dict; None when there is none; {} when it is not a marker this tool wrote."""
    path = Path(folder) / MARKER
    if not path.exists() and not path.is_symlink():
        return None
    try:
        m = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    ok = (isinstance(m, dict) and m.get("tool") == "rockdem" and isinstance(m.get("command"), str)
          and isinstance(m.get("files"), list) and all(isinstance(f, str) for f in m["files"]))
    return m if ok else {}


def write_marker(folder, command, files):
    """Write (atomically) the marker of `folder`: the tool, the command, the time and the files it wrote."""
    info = {"tool": "rockdem", "command": command, "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "files": sorted(files)}
    folder = Path(folder)
    tmp = folder / f"{TMP_PREFIX}{os.getpid()}.marker"
    tmp.write_text(json.dumps(info, indent=1) + "\n")
    os.replace(tmp, folder / MARKER)


def _safe_rel(f):
    """A marker entry that names a file inside the folder (no absolute path, no '..')."""
    p = Path(f)
    return f and not p.is_absolute() and ".." not in p.parts


class OutputFolder:
    """The output folder of one command. Constructing it checks the target (CliError: one line, nothing
    touched); ``assemble()`` yields the temporary folder to write into and moves its files into place."""

    def __init__(self, out, command, force=False, flag="-o", say=None):
        self.out = Path(out)  # as the user gave it: for messages
        self.command = command
        self.force = force
        self.say = say
        self.label = f"{flag} = {str(out)!r}"
        self.target = Path(os.path.realpath(out))  # '.', $PWD, trailing '/', '..', symlinks
        self.owned = set()
        self.check()

    # -- the rule ------------------------------------------------------------------------------------------
    def check(self):
        """Refuse a target this command may not write (CliError); else set `owned`, the files of the earlier
        output that the command replaces."""
        t = self.target
        self.owned = set()
        if not t.exists():
            up = t.parent
            while not up.exists():
                up = up.parent
            if not up.is_dir():
                raise _cli_error(f"{self.label}: {up} is not a folder")
            return
        if not t.is_dir():
            raise _cli_error(f"{self.label}: output exists and is not a folder")
        marker = read_marker(t)
        if marker is None:
            entries = folder_entries(t)
            if entries:
                raise _cli_error(f"{self.label}: folder exists and holds files this tool did not write "
                                 f"({shown_names(entries)}); choose a new folder")
            return
        if not marker:
            raise _cli_error(f"{self.label}: {MARKER} in the folder is not an output marker of this tool; "
                             "choose a new folder")
        if marker["command"] != self.command:
            raise _cli_error(f"{self.label}: folder holds an earlier output of {marker['command']}, not of "
                             f"{self.command}; choose a new folder")
        owned = {f for f in marker["files"] if _safe_rel(f)}
        if not self.force:
            raise _cli_error(f"{self.label}: folder holds an earlier output of {self.command} "
                             f"({shown_names(owned) or 'no files'}); --force replaces it")
        self.owned = owned

    def _clashes(self, new):
        """New files whose place in the target is taken by something the earlier output did not write."""
        t = self.target
        bad = []
        for f in new:
            parts = Path(f).parts
            for k in range(1, len(parts)):  # every folder on the way must be a real folder
                a = Path(*parts[:k])
                p = t / a
                if p.is_symlink() or (p.exists() and not p.is_dir()):
                    bad.append(a.as_posix())
                    break
            else:
                p = t / f
                if (p.exists() or p.is_symlink()) and (f not in self.owned or p.is_dir() and not p.is_symlink()):
                    bad.append(f)
        return sorted(set(bad))

    # -- writing -------------------------------------------------------------------------------------------
    @contextmanager
    def assemble(self):
        """Yield a temporary folder for the command's files; on success its files are moved into the target,
        the earlier output's files not written again are removed and the marker is written; on any error the
        temporary folder is removed and the target is left as it was."""
        t = self.target
        if t.exists():
            tmp = t / f"{TMP_PREFIX}{os.getpid()}"
        else:
            tmp = t.with_name(f".{t.name}.part{os.getpid()}")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        try:
            yield tmp
            self._commit(tmp)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    def _commit(self, tmp):
        t = self.target
        new = _files(tmp, skip_top=False)
        if not t.exists():  # a new folder: the assembled one is renamed into place, marker included
            write_marker(tmp, self.command, new)
            try:
                os.rename(tmp, t)  # onto a folder made meanwhile: only when it is empty
                return
            except OSError:
                if not t.is_dir():
                    raise
                (tmp / MARKER).unlink()
        self.check()  # again: the folder may have changed while the command ran
        clash = self._clashes(new)
        if clash:
            it = "it" if len(clash) == 1 else "them"
            raise _cli_error(f"{self.label}: {shown_names(clash)} would be overwritten, but this tool did not "
                             f"write {it}; move {it} away or choose a new folder")
        stale = sorted(self.owned - set(new))
        write_marker(t, self.command, set(new) | self.owned)  # a crash below leaves every file recognised
        for f in new:
            (t / f).parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / f, t / f)
        for f in stale:
            p = t / f
            if p.is_symlink() or p.is_file():
                p.unlink()
            for d in Path(f).parents:  # folders the earlier output made, once empty
                if d == Path("."):
                    break
                try:
                    (t / d).rmdir()
                except OSError:
                    break
        write_marker(t, self.command, new)
        if self.say:
            kept = [f for f in _files(t) if f not in set(new)]
            if kept:
                self.say(f"kept       {len(kept)} file{'s' if len(kept) != 1 else ''} this tool did not write: "
                         f"{shown_names(kept)}")


def output_folder(out, command, force=False, say=None):
    """The checked output folder of a command: a CliError (one line, nothing touched) when `out` holds files the
    command did not write, or its earlier output without `force`; its ``assemble()`` yields the temporary folder
    to write into."""
    return OutputFolder(out, command, force=force, say=say)
