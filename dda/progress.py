"""Progress lines of a run: the fraction of the run's simulated time, steps per second and the time left.

A run is often made of pieces (`dda run` stops at every VTU frame); one RunProgress spans all of them, so its
percentage is that of the whole run, measured in simulated time (not in the steps of the current piece), and
its ETA extrapolates the wall time per simulated second since the first step (whose wall time includes
loading the kernels) over the simulated time still to go::

    [  12.31 s] t = 0.42 of 1 s (42.0 %)  9875 steps/s  ETA 17 s  contacts 3  points 12  KE 1.2 J ...
"""
from __future__ import annotations

import time


def _eta(seconds):
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds // 60:.0f} min {seconds % 60:02.0f} s"
    return f"{seconds // 3600:.0f} h {(seconds % 3600) // 60:02.0f} min"


class RunProgress:
    """`say(line)` at most every `every` seconds of wall time (and at the end) with the simulated time reached
    out of the run's `t_end`, the steps per second since the start and the estimated time left."""

    def __init__(self, say, t_end, t_start=0.0, steps=0, every=1.0):
        self.say, self.t_start, self.t_end, self.every = say, float(t_start), float(t_end), every
        self.last = time.perf_counter()
        self.base = None  # (t, steps, wall) of the first update: rates leave out the kernels' loading

    def fraction(self, t):
        span = self.t_end - self.t_start
        return 1.0 if span <= 0 else min(1.0, max(0.0, (t - self.t_start) / span))

    def update(self, t, steps, detail="", end=False):
        """Report the state at simulated time `t` after `steps` steps (`end`: the last update of a piece)."""
        if self.say is None:
            return
        now = time.perf_counter()
        f = self.fraction(t)
        if self.base is None:
            self.base = (t, steps, now)
        if now - self.last < self.every and not (end and f >= 1.0 - 1e-12):
            return
        self.last = now
        t0, steps0, wall0 = self.base
        wall = now - wall0
        speed = ""
        if steps > steps0 and wall > 0:
            speed = f"  {(steps - steps0) / wall:.0f} steps/s"
            if f < 1.0 - 1e-12:
                speed += f"  ETA {_eta(wall * (self.t_end - t) / (t - t0))}"
        self.say(f"t = {t:.4g} of {self.t_end:.4g} s ({100.0 * f:5.1f} %){speed}" + (f"  {detail}" if detail else ""))


def tracker(progress, sim, duration):
    """The RunProgress of a `sim.run(duration, progress=...)` call: `progress` itself when it is one (a run in
    pieces), else a new one spanning this call (`progress` a plain line printer or None)."""
    if isinstance(progress, RunProgress):
        return progress
    return RunProgress(progress, sim.time + duration, sim.time, sim.steps)
