"""What every package shares: the conventions of the project's commands and files, on the lowest floor.

sgim, dda, adapters and cases all import these names from here (nothing in this module imports another
module of the project, so any module may import it without a circle; it loads the standard library only):

* ``SceneError``: a bad scene, study or deck file, one line ``FILE: KEY = VALUE: what is wrong``;
* ``CliError``: a bad command line or input file, one line; both exit with ``EXIT_BAD_INPUT`` (2);
* ``run_command``: ``args.func(args)`` under those conventions; ``add_version`` (``--version`` of every tool),
  ``progress_printer`` (the ``[  1.23 s] ...`` lines on stderr), ``positive_int`` (count flags), ``FORCE_HELP``,
  ``reader_gone`` (a reader closed the pipe);
* ``atomic_path``, ``atomic_npz``, ``atomic_vtu``: files written under a temporary name, renamed into place;
* ``__version__``: the package version written into models and summaries.

The geology conventions (dip / dip direction -> unit normal, ``MAX_COORD``, ``MIN_LENGTH``) live in
sgim/geometry.py; the scene readers' value checks (key paths, types, ranges, units) in sgim/reader.py.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

__version__ = "0.1.0"
EXIT_BAD_INPUT = 2
FORCE_HELP = ("replace the command's earlier output in the folder (only the files it wrote there; files "
              "added by hand stay)")


class CliError(Exception):
    """One-line error for the user (exit status 2).

    Defined here, not in sgim/cli.py: the class is the same whether sgim.cli is imported or run as
    ``python -m sgim.cli`` (a class defined in a module run as __main__ would be a second class)."""


class SceneError(ValueError):
    """A scene file (or a value in it) is invalid.  ``str(err)`` is one line."""

    def __init__(self, file, key, value, message):
        self.file, self.key, self.value, self.message = str(file), key, value, message
        shown = _short(value)
        super().__init__(f"{self.file}: {key} = {shown}: {message}")


def _short(value, limit=80):
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


# --------------------------------------------------------------------------
# command-line conventions
def reader_gone():
    """After a BrokenPipeError on stdout (the reader, e.g. `head`, closed the pipe): point stdout at devnull so
    that the interpreter's final flush does not fail too; the command then ends quietly with status 0."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    return 0


def progress_printer(quiet):
    """None when `quiet`; else ``say(msg)`` printing ``[elapsed s] msg`` on stderr (time since this call)."""
    if quiet:
        return None
    t0 = time.perf_counter()

    def say(msg):
        print(f"[{time.perf_counter() - t0:7.2f} s] {msg}", file=sys.stderr, flush=True)

    return say


def positive_int(text, flag):
    """The value of a count flag (`--max-spheres 12000000` or `1.2e7`), None when not given; CliError otherwise."""
    if text is None:
        return None
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (v >= 1 and v < 2 ** 63 and v == int(v)):
        raise CliError(f"{flag} = {text!r}: must be a positive integer (e.g. 12000000 or 1.2e7)")
    return int(v)


def add_version(parser):
    """``--version`` on every tool of the project: the rockdem distribution's version."""
    from importlib.metadata import PackageNotFoundError, version  # read only when a parser is made

    try:
        v = version("rockdem")
    except PackageNotFoundError:  # run from a source tree that was never installed
        v = "(not installed)"
    parser.add_argument("--version", action="version", version=f"%(prog)s (rockdem {v})")
    return parser


def run_command(prog, args, bad_input=()):
    """``args.func(args)`` under the CLI conventions of every command of the project: bad input (SceneError,
    CliError and the `bad_input` exception types) prints one line ``PROG: error: ...`` and gives exit status 2;
    a reader closing the pipe (e.g. ``head``) ends the command quietly with status 0."""
    try:
        return args.func(args)
    except BrokenPipeError:
        return reader_gone()
    except (CliError, SceneError, *bad_input) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


# --------------------------------------------------------------------------
# atomic writers
class atomic_path:
    """Context manager yielding a temporary name that is renamed to ``path`` on success."""

    def __init__(self, path):
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.part{os.getpid()}")

    def __enter__(self):
        return str(self.tmp)

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            os.replace(self.tmp, self.path)
        else:
            try:
                os.unlink(self.tmp)
            except FileNotFoundError:
                pass
        return False


def atomic_npz(path, data):
    """np.savez of the dict `data` to `path`, written under a temporary name and renamed into place."""
    import numpy as np  # not at the top: this module stays standard-library only (fast `--help`, refusals)

    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **data)


def atomic_vtu(path, mesh):
    """A meshio Mesh written as binary VTU to `path` under a temporary name and renamed into place."""
    import meshio  # not at the top: loaded only by the commands that write VTU (meshio takes a while to import)

    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression=None)
