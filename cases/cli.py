"""Command line: ``cases crossval [...]`` (the cross-validation table, cases/lib/crossval.py), ``cases study [...]``
(batch studies, cases/lib/study.py)."""
from __future__ import annotations

import argparse
import importlib
import sys

# command -> (module with main(argv), one line of help)
COMMANDS = {
    "crossval": ("cases.lib.crossval", "the cross-validation table: every case in every engine against its reference"),
    "study": ("cases.lib.study", "batch studies (parameter sweeps, Monte Carlo), serial or under mpirun"),
}


def _usage():


    lines = [f"usage: cases {{{','.join(COMMANDS)}}} [options]", "", "commands:"]
    lines += [f"  {name:<10} {text}" for name, (_, text) in COMMANDS.items()]
    lines += ["", "options:", "  -h, --help  show this help and exit", "  --version   show the version and exit",
              "", "cases COMMAND --help shows the options of a command."]
    return "\n".join(lines)


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    if argv and argv[0] == "--version":
        from sgim.common import add_version  # lazy: `cases --help` answers without importing sgim

        add_version(argparse.ArgumentParser(prog="cases")).parse_args(["--version"])
    if not argv or argv[0] not in COMMANDS:
        print(_usage(), file=sys.stderr)
        return 2
    return importlib.import_module(COMMANDS[argv[0]][0]).main(argv[1:])


if __name__ == "__main__":
    sys.exit(main())
