"""``dda blocks SCENE -o OUT``: the block model of an sgim scene (dda/geoblocks.py) written as

- ``blocks.vtu``: every block face as triangles (fans of the polygon faces), with cell data ``block`` (block
  index), ``face`` (face index in its block), ``kind`` (index into KINDS of the face's source: domain, joint,
  intact, fault, excavation; a disc's face shows the disc's kind, intact outside it per contact point),
  ``source`` (index into summary.json's ``sources``), ``volume`` (the block's, m3) and ``material`` (index into
  summary.json's ``materials``);
- ``summary.json``: block count, total volume, the smallest / median / largest block, blocks below
  ``[blocks] min_volume``, cuts skipped as slivers, slivers joined, seconds per stage, the sources (name, kind,
  shape) and materials.

The folder rules of every command hold (sgim/outdir.py): written only when new, empty or an earlier
``dda blocks`` output (``--force`` to replace it), assembled in a temporary folder and moved into place.
"""
from __future__ import annotations

import json
from pathlib import Path

from sgim.common import FORCE_HELP, CliError, progress_printer
from sgim.outdir import output_folder
from sgim.scene import load_scene

from .shapes import GeometryError


def cmd_blocks(args):
    # not at the top: the cutting kernels load when a model is built (a fast --help)
    from .geoblocks import build_blocks, write_blocks

    scene = load_scene(args.scene)
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CliError(f"{out}: -o = {str(out)!r}: output exists and is not a folder")
    say = progress_printer(args.quiet)
    dest = output_folder(out, "dda blocks", force=args.force, say=say)
    try:
        model = build_blocks(scene, progress=lambda stage, n, s: say and say(f"{stage:<11}{n} blocks  {s:.2f} s"))
    except GeometryError as exc:
        raise CliError(f"{args.scene}: {exc}") from None
    with dest.assemble() as tmp:
        summary = write_blocks(model, tmp)
    if args.json:
        print(json.dumps(summary, indent=2))
    elif not args.quiet:
        print(f"{args.output}: {summary['blocks']} blocks, {summary['volume']:.6g} m3 (smallest "
              f"{summary['smallest']:.3g}, median {summary['median']:.3g}, largest {summary['largest']:.3g} m3)")
    return 0


def add_blocks_parser(sub):
    b = sub.add_parser("blocks", help="cut an sgim scene into its block model (blocks.vtu, summary.json)")
    b.add_argument("scene", help="the sgim scene file (TOML with [domain], [[excavation]], [[discontinuity]], "
                                 "[blocks], ...; sgim/scene.py)")
    b.add_argument("-o", "--output", required=True, help="output folder")
    b.add_argument("--quiet", action="store_true", help="no progress lines")
    b.add_argument("--json", action="store_true", help="print summary.json to stdout")
    b.add_argument("--force", action="store_true", help=FORCE_HELP)
    b.set_defaults(func=cmd_blocks)
    return b
