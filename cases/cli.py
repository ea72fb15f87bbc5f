"""Command line: ``cases crossval [...]`` (the cross-validation table, cases/crossval.py), ``cases study [...]``
(batch studies, cases/study.py)."""
from __future__ import annotations

import sys

COMMANDS = {"crossval": "cases.crossval", "study": "cases.study"}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in COMMANDS:
        print(f"usage: cases {{{','.join(COMMANDS)}}} [options]   (cases COMMAND --help)", file=sys.stderr)
        return 2
    import importlib

    return importlib.import_module(COMMANDS[argv[0]]).main(argv[1:])


if __name__ == "__main__":
    sys.exit(main())
