"""Command line: ``adapters export SOURCE --to yade|liggghts|pfc-text|vtu -o DECK`` and
``adapters run DECK [--np N] [--timeout S] [-o RESULT] [--in-house]``.

Bad input (a scene, model, deck or option) prints one line and exits with status 2, leaving no deck behind.
An engine that is missing, fails or runs out of time prints its one-line reason and exits with status 3;
what the run wrote before it stopped is kept in the result folder, marked incomplete in result.json.
"""
from __future__ import annotations

import argparse
import json
import sys

from sgim.common import FORCE_HELP, CliError, add_version, positive_int, run_command
from sgim.common import progress_printer as _progress

from . import registry

# The commands import the deck, frames and engine modules when they run, not here: `adapters --help` stays quick
# (they load numpy, and the in-house engine numba).

EXIT_ENGINE = 3


def cmd_export(args):
    from .deck import export
    from .frames import export_result, is_result

    say = _progress(args.quiet)
    if is_result(args.source):  # a run's result folder or result.npz: ParaView frames
        if args.to != "vtu":
            raise CliError(f"{args.source}: a run's result exports to vtu only (ParaView frames), not {args.to}")
        info = export_result(args.source, args.output, force=args.force, progress=say)
        if args.json:
            print(json.dumps(info, indent=2))
        return 0
    overrides = {"duration": args.duration, "dt": args.dt, "record_every": args.record_every,
                 "viscous_damping": args.viscous_damping, "liggghts_joints": args.liggghts_joints,
                 "liggghts_joint_walls": args.liggghts_joint_walls, "joint_walls": args.joint_walls}
    info = export(args.source, args.to, args.output, variant=args.variant, overrides=overrides, progress=say,
                  max_steps=positive_int(args.max_steps, "--max-steps"), force=args.force, blocks=args.blocks)
    if args.json:
        print(json.dumps(info, indent=2))
    return 0


def cmd_run(args):
    from .deck import run

    say = _progress(args.quiet)
    if args.in_house:  # the in-house engine's runner (registry target "dda") on the deck's run.npz
        res = registry.target("dda").run(args.deck, out=args.output, progress=say)
    else:
        res = run(args.deck, out=args.output, np=args.np, timeout=args.timeout, progress=say)
    summary = {"engine": res.engine, "status": res.status, "steps": res.steps, "wall_s": round(res.wall_s, 3),
               "bodies": res.n, "bonds_intact": int(res.bond_intact.sum()), "bonds": int(len(res.bond_intact)),
               "particle_steps_per_s": round(res.n * res.steps / res.wall_s) if res.wall_s > 0 else None}
    print(json.dumps(summary) if args.json else
          "  ".join(f"{k} {v}" for k, v in summary.items()))
    return 0


def main(argv=None):
    ap = add_version(argparse.ArgumentParser(prog="adapters", description="Export sphere models and block scenes to "
                                             "YADE and LIGGGHTS decks, run them, read their results back."))
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("export", help="write a deck folder for an engine (or a text / VTU export)")
    p.add_argument("source", help="DDA scene (.toml with [spheres], or blocks for yade), sgim scene .toml, "
                                  "model.npz or run.npz")
    p.add_argument("--to", required=True, help=" | ".join(registry.export_names()))
    p.add_argument("-o", "--output", required=True, help="deck folder (new, empty, or an earlier export's "
                                                         "with --force)")
    p.add_argument("--variant", help="; ".join(
        f"{t.to}: " + " | ".join(v + (" (default)" if v == t.default_variant else "") for v in t.variants)
        for t in registry.TARGETS if t.default_variant))
    p.add_argument("--duration", type=float, help="run length [s] (overrides the scene)")
    p.add_argument("--dt", type=float, help="time step [s] (overrides the scene)")
    p.add_argument("--record-every", type=float, help="record interval [s]")
    p.add_argument("--viscous-damping", metavar="ZETA", help="a force -c v on every sphere (LIGGGHTS fix viscous), "
                                                            "c for this ratio of critical damping of the model's "
                                                            "first mode, or 'critical' (overrides [simulation] "
                                                            "viscous_damping)")
    p.add_argument("--liggghts-joints", metavar="HOW", help="liggghts: contact (joint pairs are plain contacts) | "
                                                            "open (no contact between green and blue spheres: exact "
                                                            "while the joints stay open; overrides [spheres] "
                                                            "liggghts_joints)")
    p.add_argument("--joint-walls", metavar="HOW", help="yade, liggghts (and adapters run --in-house): the fixed "
                                                        "side of each joint as a plane wall with the joint friction "
                                                        "(YADE facet, LIGGGHTS mesh wall, in-house slab), touching "
                                                        "the nearest free sphere (nearest) or every free sphere of "
                                                        "the joint's pairs (pairs: grown contact radii, liggghts "
                                                        "--variant clumps only)")
    p.add_argument("--liggghts-joint-walls", metavar="HOW", help="liggghts: the older spelling of --joint-walls")
    p.add_argument("--max-steps", metavar="N", help="refuse a deck of more than N steps (duration / dt; overrides "
                                                    "the scene's [simulation] max_steps, default 1e8)")
    p.add_argument("--blocks", action="store_true", help="an sgim scene's block model (dda blocks / dda run of the "
                                                         "scene) instead of its spheres: yade writes Polyhedra")
    p.add_argument("--json", action="store_true", help="print deck.json")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=cmd_export)
    p = sub.add_parser("run", help="run a deck folder with its engine")
    p.add_argument("deck", help="a deck folder written by adapters export")
    p.add_argument("--np", type=int, default=1, help="MPI ranks (liggghts) or threads (yade -j)")
    p.add_argument("--timeout", type=float, help="time limit [s]; partial results are kept, marked incomplete")
    p.add_argument("-o", "--output", help="result folder (default DECK/result)")
    p.add_argument("--in-house", action="store_true", help="run the deck's run.npz with the in-house engine")
    p.add_argument("--json", action="store_true", help="print the run's summary as JSON on stdout")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_run)
    args = ap.parse_args(argv)
    from .deck import DeckError
    from .process import EngineError
    from .spec import SpecError

    try:
        return run_command("adapters", args, bad_input=(DeckError, SpecError))
    except EngineError as exc:
        print(f"adapters: error: {exc}", file=sys.stderr)
        if exc.result is not None:
            print(f"adapters: partial results kept ({exc.result.status}, {len(exc.result.time)} records)",
                  file=sys.stderr)
        return EXIT_ENGINE


if __name__ == "__main__":
    sys.exit(main())
