"""Command line: ``sgim build | show | info | dfn``.

Bad input prints one line naming the file, key and value, exits with status 2 and
leaves no output behind (the output is assembled in a temporary folder and moved into place
only when everything is written). An output folder is written only when it is new, empty or
holds the command's own earlier output (replaced with --force; files the user added stay):
sgim/outdir.py.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

# absolute imports: the same classes also under `python -m sgim.cli` (sgim/common.py)
from sgim.common import FORCE_HELP, CliError, add_version, positive_int, progress_printer, run_command
from sgim.outdir import output_folder

# The commands import the package's other modules inside their functions: `sgim --help`, --version and the refusal
# of a bad command line load neither numpy nor numba, and a bad scene is refused before the build's kernels load.


def cmd_build(args):
    from .scene import OUTPUT_FORMATS, load_scene

    t0 = time.perf_counter()
    say = progress_printer(args.quiet)
    scene = load_scene(args.scene)  # SceneError before anything is created
    formats = args.formats.split(",") if args.formats else list(scene.formats)
    bad = [f for f in formats if f not in OUTPUT_FORMATS]
    if bad:
        raise CliError(f"--formats: unknown format {bad[0]!r} (choose from {', '.join(OUTPUT_FORMATS)})")
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CliError(f"{out}: output exists and is not a folder")
    dest = output_folder(out, "sgim build", force=args.force, say=say)  # refused before any work
    from .limits import check_build

    # spheres and memory estimated before any progress line (a refused build prints its one line only) and
    # before the build's modules are imported (a refusal takes the interpreter's start and the scene's reading)
    t_parse = time.perf_counter() - t0
    est = check_build(scene, max_spheres=positive_int(args.max_spheres, "--max-spheres"))
    from .builder import Timer, build_model, summary

    timer = Timer(say)
    timer.t["parse"] = t_parse
    timer.t["estimate"] = time.perf_counter() - t0 - t_parse
    if say:
        say(f"parse      {timer.t['parse']:7.2f} s  {args.scene}")
        say(f"{est.line()} ({timer.t['estimate']:.2f} s)")
    model = build_model(scene, timer=timer, estimate=est)
    with dest.assemble() as tmp:
        model.save(tmp / "model.npz")
        timer.lap("write npz", str(out / "model.npz"))
        if "vtu" in formats:
            model.save_vtu(tmp / "model.vtu")
            timer.lap("write vtu")
        if "txt" in formats:
            model.save_text(tmp / "balls.txt", tmp / "bonds.txt")
            timer.lap("write txt")
        if "png" in formats:
            from .render import render

            rs = scene.render
            picture = render(model, tmp / "model.png", hide_intact=rs.hide_intact, translucent=rs.translucent,
                             cut_away=rs.cut_away, width=rs.width, height=rs.height, title=scene.name)
            timer.lap("render", f"{out / 'model.png'} ({picture['drawn']} spheres drawn, {picture['hidden']} hidden)")
        if getattr(scene, "dfn", None) is not None:
            from .dfn import network_for, write_network

            write_network(network_for(scene), tmp)
            timer.lap("write dfn", str(out / "network.csv"))
        info = summary(model, timer.t)
        if "png" in formats:
            info["picture"] = {k: picture[k] for k in ("selected", "drawn", "hidden")}
        info["timings_s"]["total"] = round(time.perf_counter() - t0, 4)
        (tmp / "summary.json").write_text(json.dumps(info, indent=2))
    if args.json:
        print(json.dumps(info, indent=2))
    elif not args.quiet:
        c = model.counts()
        print(f"{out}: {c['spheres']} spheres ({c['intact']} intact, {c['red']} red, {c['green']} green, "
              f"{c['blue']} blue), {c['bonds']} contacts ({c['bonded']} bonded, {c['cut']} cut) "
              f"in {info['timings_s']['total']:.2f} s")
    return 0


def cmd_dfn(args):
    from .dfn import format_statistics, network_for, write_network
    from .scene import load_scene

    t0 = time.perf_counter()
    say = progress_printer(args.quiet)
    scene = load_scene(args.scene)  # SceneError before anything is created
    if scene.dfn is None:
        raise CliError(f"{scene.path}: joint_set = None: the scene defines no fracture network "
                       "(add [[joint_set]] tables or [dfn] file)")
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CliError(f"{out}: output exists and is not a folder")
    dest = output_folder(out, "sgim dfn", force=args.force, say=say)
    net = network_for(scene, progress=say)
    with dest.assemble() as tmp:
        write_network(net, tmp)
        info = {"scene": scene.name, "scene_path": str(scene.path), **net.summary(),
                "seconds": round(time.perf_counter() - t0, 4)}
        (tmp / "summary.json").write_text(json.dumps(info, indent=2))
    if args.json:
        print(json.dumps(info, indent=2))
    elif not args.quiet:
        print(f"{out}: {len(net)} fractures, P32 {info['p32']:.4g} 1/m in the domain, {info['seconds']:.2f} s")
        for line in format_statistics(net):
            print("  " + line)
    return 0


def _load_model(path):
    from .model import SphereModel

    p = Path(path)
    if not p.is_file():
        raise CliError(f"{p}: MODEL = {str(path)!r}: file not found")
    return SphereModel.load(p)  # a broken, foreign or inconsistent file: BadFile (one line)


def cmd_show(args):
    from .render import render
    from .scene import parse_cut

    for c in args.cut_away:
        try:
            parse_cut(c)
        except ValueError as exc:
            raise CliError(f"--cut-away = {c!r}: {exc}") from None
    model = _load_model(args.model)
    out = Path(args.output)
    if out.parent and not out.parent.exists():
        raise CliError(f"{out}: -o = {str(out)!r}: folder {out.parent} does not exist")
    title = model.meta.get("scene")
    res = render(model, out, hide_intact=args.hide_intact, translucent=args.translucent, cut_away=args.cut_away,
                 width=args.width, height=args.height, title=None if title is None else str(title))
    if not args.quiet:
        print(f"{out}: {res['drawn']} spheres drawn of {res['selected']} selected")
    return 0


def cmd_info(args):
    model = _load_model(args.model)
    c = model.counts()
    if args.json:
        print(json.dumps({**c, "meta": model.meta}, indent=2))
        return 0
    m = model.meta
    pk = _table(m, "packing")
    print(f"model      {args.model}")
    print(f"scene      {m.get('scene', '?')}  ({m.get('generator', '?')})")
    if pk.get("kind") == "random":  # sgim/rpack.py statistics
        st = _table(pk, "statistics")
        les = _table(st, "largest_empty_sphere")
        print(f"packing    random  r = {_num(st.get('radius_min'), '.6g')} .. {_num(st.get('radius_max'), '.6g')} m  "
              f"density "
              f"{_num(st.get('density'), '.4f')}  coordination {_num(st.get('coordination'), '.3f')}  "
              f"max overlap {_num(st.get('max_overlap'), '.1e')}  largest empty sphere "
              f"{_num(les.get('radius'), '.4g')} m ({_num(les.get('relative_max'), '.3f')} x local r)")
    else:
        print(f"packing    {pk.get('kind', '?')}  r = {_num(pk.get('radius'), '.6g')} m  lattice sites "
              f"{pk.get('lattice_sites', '?')}")
    print(f"spheres    {c['spheres']}  intact {c['intact']}  red {c['red']}  green {c['green']}  blue {c['blue']}")
    print(f"contacts   {c['bonds']}  bonded {c['bonded']}  cut {c['cut']}  (rule {_table(m, 'bonds').get('rule', '?')})")
    print(f"discs      {c['discontinuities']}  memberships {c['memberships']}")
    for k, name in enumerate(model.disc_name):
        kind = "fault" if model.disc_thickness[k] > 0 else "joint"
        print(f"  [{k}] {name} ({kind}, radius {model.disc_radius[k]:g} m"
              + (f", thickness {model.disc_thickness[k]:g} m)" if kind == "fault" else ", zero thickness)"))
    srf = model.surfaces
    for q, k in enumerate(srf.get("surf_index", [])):
        d = float(srf["surf_thickness"][q])
        nf = int(srf["surf_face_start"][q + 1] - srf["surf_face_start"][q])
        print(f"  [{k}] {srf['surf_name'][q]} ({'fault' if d > 0 else 'joint'}, surface of {nf} triangles, "
              + (f"thickness {d:g} m)" if d > 0 else "zero thickness)"))
    cavities = m.get("cavities")
    for c in cavities if isinstance(cavities, list) else []:
        c = c if isinstance(c, dict) else {}
        print(f"cavity     {c.get('name', '?')} ({c.get('source', '?')}, {c.get('faces', '?')} triangles): "
              f"{c.get('spheres_removed', '?')} spheres removed")
    return 0


def _table(d, key):
    """d[key] when it is a dict (model.meta is free-form JSON: a missing or odd entry shows as '?')."""
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, dict) else {}


def _num(v, fmt):
    return format(v, fmt) if isinstance(v, (int, float)) and not isinstance(v, bool) else "nan" if v is None else "?"


def make_parser():
    p = add_version(argparse.ArgumentParser(prog="sgim", description="Sphere generator for irregular geological "
                                                                     "models"))
    sub = p.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="build a sphere model from a scene file")
    b.add_argument("scene", help="the scene file (TOML; docs/scenes.md lists its keys)")
    b.add_argument("-o", "--output", required=True, help="output folder")
    b.add_argument("--quiet", action="store_true", help="no progress lines")
    b.add_argument("--json", action="store_true", help="print a JSON summary (counts, bonds, timings)")
    b.add_argument("--formats", help="comma list of npz,vtu,txt,png (default: the scene's [output] formats)")
    b.add_argument("--force", action="store_true", help=FORCE_HELP)
    b.add_argument("--max-spheres", metavar="N", help="refuse a build estimated past N spheres (overrides the "
                                                      "scene's [limits] max_spheres; default: see sgim/limits.py)")
    b.set_defaults(func=cmd_build)
    s = sub.add_parser("show", help="render a model to PNG")
    s.add_argument("model", help="a model.npz written by sgim build")
    s.add_argument("-o", "--output", required=True, help="the picture to write (PNG)")
    s.add_argument("--hide-intact", action="store_true", help="draw only the spheres a discontinuity coloured")
    s.add_argument("--translucent", action="store_true", help="draw intact spheres translucent")
    s.add_argument("--cut-away", action="append", default=[], metavar="EXPR",
                   help="remove the spheres where EXPR holds, e.g. 'y<0'; repeated, the spheres "
                        "where all of them hold (--cut-away 'y<0' --cut-away 'z>50' removes that corner)")
    s.add_argument("--width", type=int, default=1600, help="picture width in pixels (default 1600)")
    s.add_argument("--height", type=int, default=1100, help="picture height in pixels (default 1100)")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=cmd_show)
    i = sub.add_parser("info", help="summarise a model")
    i.add_argument("model", help="a model.npz written by sgim build")
    i.add_argument("--json", action="store_true", help="print the counts and the model's metadata as JSON")
    i.set_defaults(func=cmd_info)
    f = sub.add_parser("dfn", help="sample (or read) the scene's fracture network and write it with statistics")
    f.add_argument("scene", help="the scene file (TOML) with [dfn] and [[joint_set]] tables")
    f.add_argument("-o", "--output", required=True, help="output folder (network.csv, .json, .vtu, summary.json)")
    f.add_argument("--quiet", action="store_true", help="no progress lines")
    f.add_argument("--json", action="store_true", help="print the JSON summary (per-set statistics)")
    f.add_argument("--force", action="store_true", help=FORCE_HELP)
    f.set_defaults(func=cmd_dfn)
    return p


def main(argv=None):
    return run_command("sgim", make_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
