"""``dda wedge``: the wedge's factor of safety by DDA next to Hoek & Bray's analytical value.

    dda wedge --joint 45/005 --joint 55/135 --face 65/065 --height 10 --friction 25 [--unit-weight 25.506]
              [--top 0/000] [--json] [--analytical-only] [--quiet]

Blocks: ``dda.generate.wedge`` (the free wedge and three fixed blocks of the rock mass). The critical friction
angle is found as the explicit 3D-DDA paper does, by lowering the friction angle (the same on both joints,
cohesion 0) step by step from the given value until the wedge slides, then bisecting between the last angle
that held and the first that slid until the bracket is narrower than ``--tolerance`` (default 0.05 deg); the
critical angle is the bracket's middle. The DDA factor of safety is FS = tan(phi) / tan(phi_crit).

Sliding test for one friction angle: the wedge starts at rest and is run for ``--duration`` simulated seconds
(default 1.5 s); its displacement s(t) along the line of intersection is sampled at 1/2, 3/4 and all of the
run. It slides when the last quarter's advance exceeds the advance of a wedge accelerating at
``a_min = g sin(plunge) * resolution`` (resolution 1e-3, that is FS = 0.999) and the advance grows (the
wedge accelerates). A wedge that holds only settles elastically, by less than that.

Contact stiffness: ``kn`` per contact point is chosen so that the wedge's weight shared by three points
compresses the springs by ``--penetration`` (default 1e-5) times the wedge's size, unless ``--kn`` is given;
``ks = kn / 2``; contact damping ratio 0.3 (normal springs) settles the initial elastic response.

``--unit-weight`` is in kN/m^3 (default 2.6 t/m^3 x 9.81 = 25.506), giving the block density; with cohesion
0 the factor of safety does not depend on it. ``--json`` prints ``{"fs_dda", "fs_hoek_bray", "phi_crit_dda",
"phi_crit_hoek_bray", ...}`` as numbers.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time

import numpy as np

from sgim.common import EXIT_BAD_INPUT, SceneError
from sgim.portable import matmul, norm

from . import hoekbray
from .limits import check

G = 9.81


class WedgeInputError(ValueError):
    """Bad command-line value: one line, exit status 2."""


def _short(value):
    return f"{value:g}" if isinstance(value, float) else repr(value)


def parse_orientation(text, what):
    """``"45/005"`` -> (45.0, 5.0); dip in [0, 90], dip direction in [0, 360)."""
    parts = str(text).split("/")
    try:
        if len(parts) != 2:
            raise ValueError
        dip, dd = float(parts[0]), float(parts[1])
    except ValueError:
        raise WedgeInputError(f"{what} = {text!r}: expected DIP/DIPDIR in degrees, e.g. 45/005") from None
    if not (0.0 <= dip <= 90.0) or not (0.0 <= dd <= 360.0) or not (math.isfinite(dip) and math.isfinite(dd)):
        raise WedgeInputError(f"{what} = {text!r}: dip must be in [0, 90] and dip direction in [0, 360]")
    return dip, dd % 360.0


# ---------------------------------------------------------------------------------------------------------
# the search


def bracket_and_bisect(slides, start, step=2.0, tol=0.05, floor=0.5, progress=None):
    """Lower the friction angle from ``start`` by ``step`` until ``slides(phi)``; then bisect between the
    last angle that held and the first that slid until they are closer than ``tol``.

    Returns ``(phi_crit, trials)`` with phi_crit the middle of the final bracket and trials a list of
    ``(phi, slid)``. If the wedge slides at ``start`` the bracket is searched upward instead (up to 89 deg);
    if it holds down to ``floor`` degrees, phi_crit is ``floor``'s bracket middle with 0.
    """
    trials = []

    def test(phi):
        s = bool(slides(phi))
        trials.append((phi, s))
        if progress:
            progress(f"friction {phi:8.4f} deg: {'slides' if s else 'holds'}")
        return s

    hi = float(start)
    if test(hi):  # slides already: go up until it holds
        lo = hi
        while True:
            hi = min(lo + step, 89.0)
            if not test(hi):
                break
            if hi >= 89.0:
                return 89.0, trials
            lo = hi
    else:
        while True:
            lo = max(hi - step, floor)
            if test(lo):
                break
            if lo <= floor:
                return 0.5 * lo, trials
            hi = lo
    # lo slides, hi holds
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if test(mid):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi), trials


class WedgeModel:
    """The DDA wedge: blocks from ``dda.generate.wedge`` and one sliding test per friction angle."""

    def __init__(self, joint_a, joint_b, face, top=(0.0, 0.0), height=10.0, unit_weight=25.506, kn=None,
                 penetration=1e-5, duration=1.5, resolution=1e-3, damping=0.3, safety=0.25, settle=0.5,
                 settle_friction=60.0):
        # lazy: dda.generate (scipy) and the block engine (numba) load only when a wedge is modelled, so that
        # `dda wedge --help` and the analytical-only answer start fast
        from .generate import wedge as wedge_blocks

        self.geom = hoekbray.wedge_fs(joint_a, joint_b, face, top=top, friction=30.0, unit_weight=unit_weight,
                                      height=height)
        self.specs = wedge_blocks(joint_a=joint_a, joint_b=joint_b, face=face, top=top, height=height)
        self.density = unit_weight * 1000.0 / G
        o, p5 = self.geom.vertices[0], self.geom.vertices[1]
        self.line = (o - p5) / norm(o - p5)
        size = float(np.ptp(self.geom.vertices, axis=0).max())
        weight = self.density * self.geom.volume * G
        self.kn = float(kn) if kn is not None else weight / (3.0 * penetration * size)
        self.penetration = float(penetration)
        self.duration = float(duration)
        self.damping = float(damping)
        self.safety = float(safety)
        self.threshold = 7.0 / 32.0 * G * math.sin(math.radians(self.geom.line_plunge)) * resolution * duration ** 2
        self.settle = float(settle)
        self.settle_friction = float(settle_friction)
        self._settled = None
        self.runs = []

    def settled(self):
        """The simulation after the wedge has settled into its groove at ``settle_friction`` (built once).

        Starting a trial from rest with the joints already loaded is what the paper does when it lowers the
        friction step by step: a wedge released at its trial friction would first slip while its normal forces
        build up, and a wedge near its limit (FS close to 1) would carry that slip on at nearly constant speed,
        which hides whether it accelerates."""
        if self._settled is None:
            sim = self._fresh()
            sim.run(self.settle, record_every=self.settle)
            self._settled = sim
        return self._settled

    def _fresh(self):
        """The wedge's Simulation before settling."""
        from .simulation import ContactLaw, Simulation  # lazy (numba), as above
        from .system import BlockSystem

        bs = BlockSystem()
        for s in self.specs:
            bs.add_block(s, density=self.density)
        law = ContactLaw(kn=self.kn, ks=self.kn / 2, friction_deg=self.settle_friction, damping=self.damping)
        return Simulation(bs, law, gravity=(0.0, 0.0, -G), safety=self.safety)

    def check_steps(self, max_steps=None, kn_given=True):
        """Refuse (WedgeInputError, one line) a trial or the settling run whose steps pass the limit
        (`max_steps`, the --max-steps value, default dda.limits.DEFAULT_MAX_STEPS), before anything runs.
        `kn_given`: kn came from --kn (else from --penetration, which the message then names)."""
        sim = self._fresh()
        key, value, fix = ("--kn", self.kn, None) if kn_given else ("--penetration", self.penetration,
                                                                     "raise --penetration")
        try:
            for dur, dkey in ((self.duration, "--duration"), (self.settle, "settle")):
                check("dda wedge", dur, sim.dt, dt_key=key, dt_value=value, auto_dt=True, dt_crit=sim.dt_crit,
                      safety=self.safety, max_steps=max_steps, duration_key=dkey,
                      raise_limit="raise --max-steps", dt_fix=fix)
        except SceneError as exc:
            raise WedgeInputError(f"{exc.key} = {_short(exc.value)}: {exc.message}") from None

    def run(self, phi):
        """Displacements along the line of intersection at 1/2, 3/4 and 1 of the duration, counted from the
        settled state, after the friction of every contact is lowered to ``phi``."""
        sim = copy.deepcopy(self.settled())
        sim.lawtab[:, :, 2] = math.tan(math.radians(float(phi)))
        s0 = matmul(sim.displacement(0), self.line)
        marks = []
        t = 0.0
        for frac in (0.5, 0.75, 1.0):
            sim.run(frac * self.duration - t, record_every=self.duration)
            t = frac * self.duration
            marks.append(matmul(sim.displacement(0), self.line) - s0)
        self.runs.append((phi, marks, sim.steps))
        return marks

    def slides(self, phi):
        s_half, s_3q, s_end = self.run(phi)
        last, before = s_end - s_3q, s_3q - s_half
        return last > self.threshold and last > before


def dda_critical_friction(joint_a, joint_b, face, top=(0.0, 0.0), height=10.0, friction=25.0, unit_weight=25.506,
                          tol=0.05, step=2.0, progress=None, max_steps=None, **model_kw):
    """DDA critical friction angle and factor of safety; returns a dict of numbers (see run_wedge).
    WedgeInputError before any run when a trial would pass the step limit (`max_steps`, dda/limits.py)."""
    model = WedgeModel(joint_a, joint_b, face, top, height, unit_weight, **model_kw)
    model.check_steps(max_steps, kn_given=model_kw.get("kn") is not None)
    start = time.perf_counter()
    phi_c, trials = bracket_and_bisect(model.slides, friction, step=step, tol=tol, progress=progress)
    return dict(phi_crit_dda=phi_c, fs_dda=math.tan(math.radians(friction)) / math.tan(math.radians(phi_c)),
                trials=[[float(p), bool(s)] for p, s in trials], kn=model.kn, duration=model.duration,
                steps_per_trial=model.runs[-1][2] if model.runs else 0, wall_s=time.perf_counter() - start)


# ---------------------------------------------------------------------------------------------------------
# command line


def add_wedge_parser(subparsers):
    p = subparsers.add_parser("wedge", help="wedge factor of safety: DDA next to Hoek & Bray",
                              description=__doc__.split("\n\n")[0])
    p.add_argument("--joint", action="append", required=True, metavar="DIP/DIPDIR",
                   help="joint plane (give exactly two: A then B)")
    p.add_argument("--face", required=True, metavar="DIP/DIPDIR", help="slope face")
    p.add_argument("--top", default="0/0", metavar="DIP/DIPDIR", help="upper slope surface (default horizontal)")
    p.add_argument("--height", type=float, required=True, help="slope height above the wedge's toe [m]")
    p.add_argument("--friction", type=float, required=True, help="friction angle of both joints [deg]")
    p.add_argument("--unit-weight", type=float, default=2.6 * G, help="unit weight [kN/m^3] (default 25.506)")
    p.add_argument("--tolerance", type=float, default=0.05, help="bracket width of the critical angle [deg]")
    p.add_argument("--step", type=float, default=2.0, help="friction decrement while bracketing [deg]")
    p.add_argument("--duration", type=float, default=1.5, help="simulated time per trial [s]")
    p.add_argument("--kn", type=float, default=None, help="normal penalty stiffness per contact point [N/m]")
    p.add_argument("--penetration", type=float, default=1e-5,
                   help="static contact compression / wedge size that sets kn when --kn is not given")
    p.add_argument("--max-steps", type=float, default=None, metavar="N",
                   help="refuse trials of more than N steps (--duration / dt; default 1e8)")
    p.add_argument("--analytical-only", action="store_true", help="skip the DDA search")
    p.add_argument("--json", action="store_true", help="print the results as JSON numbers")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=run_wedge)
    return p


def _check_args(args):
    if len(args.joint) != 2:
        raise WedgeInputError(f"--joint given {len(args.joint)} times: give exactly two joints (A and B)")
    ja = parse_orientation(args.joint[0], "--joint")
    jb = parse_orientation(args.joint[1], "--joint")
    face = parse_orientation(args.face, "--face")
    top = parse_orientation(args.top, "--top")
    # upper bounds: numerical guards (the wedge's volume, weight and settling threshold overflow beyond them;
    # long or stiff runs are refused by the step limit, dda/limits.py)
    for name, val, lo, hi, unit in (("--height", args.height, 0, 1e9, " m"), ("--friction", args.friction, 0, 90, ""),
                                    ("--unit-weight", args.unit_weight, 0, 1e40, " kN/m3"),
                                    ("--tolerance", args.tolerance, 0, 90, ""), ("--step", args.step, 0, 90, ""),
                                    ("--duration", args.duration, 0, 1e12, " s"),
                                    ("--penetration", args.penetration, 0, 1, "")):
        if not (math.isfinite(val) and lo < val < hi):
            raise WedgeInputError(f"{name} = {val!r}: must be in ({lo:g}, {hi:g}){unit}")
    # lower bounds: a smaller wedge underflows its geometry, a finer search never ends, a softer contact blows up
    for name, val, least, unit in (("--height", args.height, 1e-9, " m"), ("--tolerance", args.tolerance, 1e-3, ""),
                                   ("--step", args.step, 0.1, ""), ("--penetration", args.penetration, 1e-12, "")):
        if val < least:
            raise WedgeInputError(f"{name} = {val!r}: must be at least {least:g}{unit}")
    if args.kn is not None and not (math.isfinite(args.kn) and 1e-20 <= args.kn <= 1e40):
        raise WedgeInputError(f"--kn = {args.kn!r}: must be in [1e-20, 1e+40] N/m")
    m = getattr(args, "max_steps", None)
    if m is not None and not (m >= 1 and m < 2 ** 63 and m == int(m)):
        raise WedgeInputError(f"--max-steps = {m!r}: must be a positive integer")
    return ja, jb, face, top


def run_wedge(args) -> int:
    """Run ``dda wedge``; prints the table (or JSON) and returns the exit status (2 on bad input)."""
    try:
        ja, jb, face, top = _check_args(args)
        hb = hoekbray.wedge_fs(ja, jb, face, top=top, friction=args.friction, unit_weight=args.unit_weight,
                               height=args.height)
    except (WedgeInputError, hoekbray.WedgeError) as exc:
        print(f"dda wedge: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = dict(fs_hoek_bray=hb.fs, fs_hoek_bray_friction_only=hb.fs_friction_only,
               phi_crit_hoek_bray=hb.critical_friction, mode=hb.mode, friction=args.friction,
               line_trend=hb.line_trend, line_plunge=hb.line_plunge, volume=hb.volume,
               weight_kN=hb.weight)
    if not args.analytical_only:
        t0 = time.perf_counter()

        def say(msg):
            print(f"[{time.perf_counter() - t0:7.2f} s] {msg}", file=sys.stderr, flush=True)

        from .simulation import BlowUpError  # lazy: loads numba, not needed for the analytical answer

        try:
            out.update(dda_critical_friction(ja, jb, face, top, args.height, args.friction, args.unit_weight,
                                             tol=args.tolerance, step=args.step, duration=args.duration,
                                             kn=args.kn, penetration=args.penetration,
                                             progress=None if args.quiet else say,
                                             max_steps=None if args.max_steps is None else int(args.max_steps)))
        except WedgeInputError as exc:  # the step limit
            print(f"dda wedge: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except BlowUpError as exc:
            print(f"dda wedge: the DDA run failed: {str(exc).splitlines()[0]}", file=sys.stderr)
            return 1
        out["fs_ratio"] = out["fs_dda"] / hb.fs
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"wedge: joint A {ja[0]:g}/{ja[1]:03g}, joint B {jb[0]:g}/{jb[1]:03g}, face {face[0]:g}/{face[1]:03g}, "
          f"top {top[0]:g}/{top[1]:03g}, height {args.height:g} m, friction {args.friction:g} deg")
    print(f"line of intersection {hb.line_plunge:.2f}/{hb.line_trend:03.1f}, volume {hb.volume:.4g} m^3, "
          f"weight {hb.weight:.4g} kN, {hb.mode}")
    print(f"{'':22s}{'phi_crit [deg]':>16s}{'FS':>10s}")
    print(f"{'Hoek & Bray':22s}{hb.critical_friction:16.3f}{hb.fs:10.4f}")
    if not args.analytical_only:
        print(f"{'DDA':22s}{out['phi_crit_dda']:16.3f}{out['fs_dda']:10.4f}")
        print(f"DDA / Hoek & Bray = {out['fs_ratio']:.4f}  ({len(out['trials'])} runs of {args.duration:g} s, "
              f"{out['wall_s']:.1f} s wall)")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="dda")
    sub = parser.add_subparsers(dest="command", required=True)
    add_wedge_parser(sub)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
