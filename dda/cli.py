"""Command line: ``dda run SCENE -o OUTDIR [--quiet]`` and ``dda wedge ...``.

Bad input prints one line naming the file, key and value, exits with status 2 and leaves no output behind
(the output folder is assembled under a temporary name and renamed into place at the end). A run that blows
up writes the folder with the last good state and a summary saying so, and exits with status 3.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

EXIT_BAD_INPUT = 2
EXIT_BLOWUP = 3


class CliError(Exception):
    """One-line error for the user (exit status 2)."""


def _progress(quiet):
    if quiet:
        return None
    t0 = time.perf_counter()

    def say(msg):
        print(f"[{time.perf_counter() - t0:7.2f} s] {msg}", file=sys.stderr, flush=True)

    return say


def _write_outputs(scene, sim, res, tmp, frames, summary, say):
    from .render import render_png, write_pvd
    from .results import save_final

    if "npz" in scene.formats:
        res.save_npz(tmp / "series.npz")
    if "csv" in scene.formats:
        res.save_csv(tmp / "series.csv")
    save_final(sim, tmp / "final.npz")
    if "vtu" in scene.formats and frames:
        write_pvd(frames, tmp / "blocks.pvd")
    if "png" in scene.formats:
        render_png(sim, tmp / "final.png", scene.width, scene.height, title=scene.name)
        if say:
            say(f"render     {tmp.name}/final.png")
    (tmp / "summary.json").write_text(json.dumps(summary, indent=2))


def _write_block_mesh(bsim, path):
    """Final block surfaces (polygons) of a block Simulation as one VTU."""
    import meshio

    A = bsim.A
    pts, polys, bid = [], [], []
    nv = 0
    for i in range(A.n):
        v = bsim.vertices(i)
        pts.append(v)
        for f in range(A.face_start[i], A.face_start[i + 1]):
            loop = A.face_verts[A.face_vert_start[f]:A.face_vert_start[f + 1]] - A.vert_start[i] + nv
            for k in range(1, len(loop) - 1):  # fan triangles of the convex face
                polys.append([loop[0], loop[k], loop[k + 1]])
                bid.append(i)
        nv += len(v)
    meshio.write(str(path), meshio.Mesh(np.concatenate(pts), [("triangle", np.array(polys, np.int64))],
                                        cell_data={"block": [np.array(bid, np.int32)]}))


def _n_moving(scene):
    return sum(not getattr(b, "fixed", False) for b in scene.blocks)


def _run_spheres(scene, out, args, say, t0):
    """`dda run` of a scene with [spheres]: series.npz (positions, energies, intact bonds per record, the final
    bond state; block_pos / block_quat per record when blocks move), spheres.vtu (final state), blocks.vtu (final
    block meshes, when blocks move) and summary.json."""
    from .simulation import BlowUpError

    ss, sim = scene.build_spheres()
    if say:
        say(f"scene      {scene.name}: {ss.n} spheres ({int(ss.fixed.sum())} fixed), {ss.n_bonds} bonds, "
            f"{len(scene.blocks)} blocks ({_n_moving(scene)} moving), dt = {sim.dt:.3g} s "
            f"(critical {sim.dt_crit:.3g} s)")
    tmp = out.with_name(f".{out.name}.part{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        status, message = "ok", ""
        try:
            res = sim.run(scene.duration, record_every=scene.record_every, progress=say)
        except BlowUpError as exc:
            status, message, res = "blow-up", str(exc), exc.results
        res.save(tmp / "series.npz", sim)
        if "vtu" in scene.formats:
            import meshio

            meshio.write(str(tmp / "spheres.vtu"), meshio.Mesh(
                sim.x, [("vertex", np.arange(ss.n).reshape(-1, 1))],
                point_data={"radius": ss.radii, "fixed": ss.fixed.astype(np.int32),
                            "displacement": sim.displacement(), "velocity": sim.v}))
            if sim.blocks is not None:
                _write_block_mesh(sim.blocks, tmp / "blocks.vtu")
        e = res.energy[-1]
        summary = {
            "scene": scene.name, "scene_path": str(scene.path), "status": status, "message": message,
            "spheres": ss.n, "fixed": int(ss.fixed.sum()), "bonds": ss.n_bonds,
            "bonds_intact": int(sim.bond_intact.sum()), "walls": len(scene.blocks) - _n_moving(scene),
            "moving_blocks": _n_moving(scene), "dt": sim.dt,
            "dt_critical": sim.dt_crit, "steps": sim.steps, "time": sim.time,
            "wall_s": round(time.perf_counter() - t0, 3),
            "energy_final": dict(zip(("kinetic", "potential", "elastic", "friction", "damping", "local_damping",
                                      "balance_error"), [float(x) for x in e])),
        }
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2))
        if out.exists():
            old = out.with_name(f".{out.name}.old{os.getpid()}")
            os.replace(out, old)
            os.replace(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if status != "ok":
        print(f"dda: error: {message} (last good state written to {out})", file=sys.stderr)
        return EXIT_BLOWUP
    if not args.quiet:
        print(f"{out}: {ss.n} spheres, {sim.steps} steps to t = {sim.time:.4g} s in {summary['wall_s']:.2f} s, "
              f"{summary['bonds_intact']} of {ss.n_bonds} bonds intact")
    return 0


def cmd_run(args):
    from .scene import load_scene
    from .simulation import BlowUpError

    t0 = time.perf_counter()
    say = _progress(args.quiet)
    scene = load_scene(args.scene)  # SceneError before anything is created
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CliError(f"{out}: -o = {str(out)!r}: output exists and is not a folder")
    if scene.spheres:
        return _run_spheres(scene, out, args, say, t0)
    bs, sim = scene.build()
    if say:
        say(f"scene      {scene.name}: {bs.n_blocks} blocks ({len(sim.active)} moving), dt = {sim.dt:.3g} s "
            f"(critical {sim.dt_crit:.3g} s), {int(round(scene.duration / sim.dt))} steps")
    tmp = out.with_name(f".{out.name}.part{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        frames = []
        want_vtu = "vtu" in scene.formats
        if want_vtu:
            (tmp / "frames").mkdir()
        from .render import write_vtu

        def frame():
            if want_vtu:
                name = f"frames/frame_{len(frames):05d}.vtu"
                write_vtu(sim, tmp / name)
                frames.append((sim.time, name))

        frame()
        n_frames = scene.frames
        piece = scene.duration / n_frames
        status = "ok"
        message = ""
        res = None
        for k in range(n_frames):
            try:
                r = sim.run(piece, record_every=min(scene.record_every, piece), progress=say)
            except BlowUpError as exc:
                status, message, r = "blow-up", str(exc), exc.results
            if res is None:
                res = r
            else:
                # append this piece's records (skip its first row: the previous piece's last state)
                for name in ("time", "pos", "quat", "vel", "energy", "contacts", "points", "sliding"):
                    getattr(res, name).extend(getattr(r, name)[1:])
                res.wall_s += r.wall_s
                res.steps = r.steps
            frame()
            if status != "ok":
                break
        summary = {
            "scene": scene.name, "scene_path": str(scene.path), "status": status, "message": message,
            "blocks": bs.n_blocks, "moving": int(len(sim.active)), "dt": sim.dt, "dt_critical": sim.dt_crit,
            "steps": sim.steps, "time": sim.time, "wall_s": round(time.perf_counter() - t0, 3),
            "energy_final": dict(zip(("kinetic", "potential", "elastic", "friction", "damping", "local_damping",
                                      "balance_error"), [float(x) for x in res.energies[-1]])),
            "contacts_final": int(sim.stats[5]), "points_final": int(sim.stats[6]),
        }
        _write_outputs(scene, sim, res, tmp, frames, summary, say)
        if out.exists():
            old = out.with_name(f".{out.name}.old{os.getpid()}")
            os.replace(out, old)
            os.replace(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if status != "ok":
        print(f"dda: error: {message} (last good state written to {out})", file=sys.stderr)
        return EXIT_BLOWUP
    if not args.quiet:
        print(f"{out}: {bs.n_blocks} blocks, {sim.steps} steps to t = {sim.time:.4g} s in {summary['wall_s']:.2f} s "
              f"(energy balance error {summary['energy_final']['balance_error']:.3g} J)")
    return 0


def make_parser():
    p = argparse.ArgumentParser(prog="dda", description="Explicit 3D DDA for convex blocks")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a DDA scene")
    r.add_argument("scene")
    r.add_argument("-o", "--output", required=True, help="output folder")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    r.set_defaults(func=cmd_run)
    try:
        from .wedge import add_wedge_parser
    except ImportError:  # the wedge command lives in its own module
        add_wedge_parser = None
    if add_wedge_parser is not None:
        add_wedge_parser(sub)
    return p


def main(argv=None):
    from sgim.scene import SceneError

    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except (SceneError, CliError) as exc:
        print(f"dda: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
