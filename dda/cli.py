"""Command line: ``dda run SCENE -o OUTDIR [--quiet]``, ``dda wedge ...`` and ``dda blocks SCENE -o OUTDIR``.

Bad input prints one line naming the file, key and value, exits with status 2 and leaves no output behind
(the output is assembled in a temporary folder and moved into place at the end). The output folder is written
only when it is new, empty or holds an earlier `dda run` output (replaced with --force; files added by hand
stay): sgim/outdir.py. A run that blows
up writes the folder with the last good state and a summary saying so, and exits with status 3.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sgim.common import FORCE_HELP, add_version, positive_int, progress_printer, run_command  # the CLI conventions

from .answers import format_answer
from .blockout import add_blocks_parser
from .wedge import add_wedge_parser

EXIT_BLOWUP = 3


def cmd_run(args):
    from .runner import run  # not at the top: the engine's numba kernels load when a run starts (fast --help)

    r = run(args.scene, Path(args.output), force=args.force, progress=progress_printer(args.quiet),
            max_steps=positive_int(args.max_steps, "--max-steps"))
    if args.json:
        print(json.dumps(r.summary, indent=2))
    if r.status != "ok":
        print(f"dda: error: {r.summary['message']} (last good state written to {args.output})", file=sys.stderr)
        return EXIT_BLOWUP
    if not args.json and not args.quiet:
        print(f"{args.output}: {r.headline}")
        for a in r.answers:
            print(f"  {format_answer(a)}")
    return 0


def make_parser():
    p = add_version(argparse.ArgumentParser(prog="dda", description="Explicit 3D DDA for convex blocks"))
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a DDA scene")
    r.add_argument("scene", help="the DDA scene file (TOML: blocks, generators and / or [spheres]; dda/scene.py)")
    r.add_argument("-o", "--output", required=True, help="output folder")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    r.add_argument("--json", action="store_true", help="print summary.json (with the answers) to stdout")
    r.add_argument("--force", action="store_true", help=FORCE_HELP)
    r.add_argument("--max-steps", metavar="N", help="refuse a run of more than N steps (duration / dt; overrides "
                                                    "the scene's [simulation] max_steps, default 1e8)")
    r.set_defaults(func=cmd_run)
    add_wedge_parser(sub)
    add_blocks_parser(sub)
    return p


def main(argv=None):
    return run_command("dda", make_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
