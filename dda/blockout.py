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

import numpy as np

from sgim.common import FORCE_HELP, CliError, progress_printer
from sgim.outdir import output_folder
from sgim.scene import load_scene, parse_cut

from .shapes import GeometryError


def cmd_blocks(args):
    # not at the top: the cutting kernels load when a model is built (a fast --help)
    from .geoblocks import build_blocks, stage_line, write_blocks

    scene = load_scene(args.scene)
    cut_away = scene.render.cut_away if args.cut_away is None else args.cut_away
    for c in cut_away:
        try:
            parse_cut(c)
        except ValueError as exc:
            raise CliError(f"--cut-away = {c!r}: {exc}") from None
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CliError(f"{out}: -o = {str(out)!r}: output exists and is not a folder")
    say = progress_printer(args.quiet)
    dest = output_folder(out, "dda blocks", force=args.force, say=say)
    try:
        model = build_blocks(scene, progress=lambda *a: say and say(stage_line(*a)))
    except GeometryError as exc:
        raise CliError(f"{args.scene}: {exc}") from None
    with dest.assemble() as tmp:
        summary = write_blocks(model, tmp)
        if args.png:
            render_blocks(model, tmp / "blocks.png", title=f"{scene.name}: {summary['blocks']} blocks",
                          cut_away=cut_away)
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
    b.add_argument("--png", action="store_true", help="also blocks.png: the faces in the sphere picture's colours")
    b.add_argument("--cut-away", action="append", default=None, metavar="EXPR",
                   help="blocks.png leaves out the blocks whose centroid meets every condition, like 'y<0' (repeat "
                        "for a corner; default the scene's [render] cut_away)")
    b.add_argument("--force", action="store_true", help=FORCE_HELP)
    b.set_defaults(func=cmd_blocks)
    return b


# the sphere picture's colours (sgim/render.py COLOURS): rock, fault red, joint faces green / blue by source
ROCK, FAULT_RGB, GREEN, BLUE = (0.80, 0.74, 0.60), (0.86, 0.08, 0.08), (0.10, 0.68, 0.18), (0.12, 0.30, 0.92)
INTACT_RGB = (0.60, 0.60, 0.62)


def face_colours(model, tris_owner_block, tris_owner_face, centroids):
    """RGB per triangle of the block mesh: a fault's face red, a joint's face green or blue (by its source's
    index, so that neighbouring sets differ), intact rock grey, the domain's and excavation faces the rock's
    colour; a disc's (triangle's) face takes its kind at the triangle's centroid (joint inside, intact outside)."""
    from .geoblocks import DOMAIN, EXCAVATION, FAULT, INTACT  # not at the top: loads the cutting kernels

    rgb = np.empty((len(centroids), 3))
    for t, (i, f, c) in enumerate(zip(tris_owner_block, tris_owner_face, centroids)):
        src = int(model.blocks[i].src[f])
        kind = int(model.point_kinds(int(i), int(f), c)[0])
        rgb[t] = {DOMAIN: ROCK, EXCAVATION: ROCK, INTACT: INTACT_RGB, FAULT: FAULT_RGB}.get(
            kind, GREEN if src % 2 == 0 else BLUE)
    return rgb


def render_blocks(model, path, width=1600, height=1100, title=None, cut_away=()):
    """blocks.png: the block model's faces in the sphere picture's colours (face_colours), edges drawn; the blocks
    whose centroid meets every condition of ``cut_away`` (the scene's [render] cut_away, as in sgim's picture:
    ``["y<6"]``) are left out, so that the inside shows."""
    import pyvista as pv  # not at the top: pyvista loads only when a picture is drawn

    from sgim.render import Frame, cut_mask

    from .geoblocks import block_mesh

    pts, tris, data, _ = block_mesh(model)
    if len(cut_away) and len(tris):
        gone = cut_mask(np.array([b.volume_centroid()[1] for b in model.blocks]), cut_away)
        keep = ~gone[data["block"]]
        tris, data = tris[keep], {k: v[keep] for k, v in data.items()}
    cen = pts[tris].mean(1)
    rgb = face_colours(model, data["block"], data["face"], cen)
    mesh = pv.PolyData(pts, np.hstack([np.full((len(tris), 1), 3), tris]).astype(np.int64))
    mesh.cell_data["rgb"] = (rgb * 255).astype(np.uint8)
    frame = Frame(width, height, title)
    frame.fit(model.lo, model.hi, azimuth=-60.0, elevation=25.0)
    frame.axes(model.lo, model.hi)
    frame.pl.add_mesh(mesh, scalars="rgb", rgb=True, show_edges=True, edge_color="black", line_width=0.3)
    for label, c in (("joint faces", GREEN), ("joint faces (next set)", BLUE), ("fault", FAULT_RGB),
                     ("intact rock", INTACT_RGB), ("free surface / domain", ROCK)):
        frame.add_legend_entry(label, c)
    frame.save(path)
    frame.close()
