"""RunResult: one result format for a bonded-sphere run, whichever engine ran it (in-house, YADE, LIGGGHTS).

A result folder holds ``result.npz`` (arrays) and ``result.json`` (status and scalars, human readable):

==============  ===========  ===============================================================
key             shape        meaning
==============  ===========  ===============================================================
time            (r,)         record times [s]
pos             (r, n, 3)    positions at the records (may be (0, n, 3): not recorded)
x0              (n, 3)       initial positions
final_pos       (n, 3)       positions at the end of the run (or at the last good record)
final_vel       (n, 3)       velocities there
bond_intact     (m,) bool    state of each bond of the run's bond list (SphereRun.bond_i/j order)
series_<name>   (r,)         scalar time series (kinetic energy, intact bonds, atom count, ...)
==============  ===========  ===============================================================

``result.json``: engine, status ("complete", or "incomplete" with ``message`` saying why: time limit,
engine error, lost particles), steps, dt, wall_s, n, n_bonds and ``extra`` (engine-specific facts).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sgim.common import atomic_npz, atomic_path
from sgim.readback import Arrays, Fields, read_json, read_npz

COMPLETE, INCOMPLETE = "complete", "incomplete"


@dataclass
class RunResult:
    """One engine's result of a SphereRun, the same for YADE, LIGGGHTS and the in-house engine: initial and
    final positions, recorded positions and times, bond states, scalar series, completion status (the
    module docstring lists the arrays of result.npz)."""

    engine: str
    x0: np.ndarray
    final_pos: np.ndarray
    final_vel: np.ndarray
    bond_intact: np.ndarray
    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pos: np.ndarray | None = None
    series: dict = field(default_factory=dict)
    status: str = COMPLETE
    message: str = ""
    steps: int = 0
    dt: float = 0.0
    wall_s: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def n(self):
        return len(self.x0)

    @property
    def complete(self):
        return self.status == COMPLETE

    def displacement(self):
        return self.final_pos - self.x0

    def moved(self, threshold):
        """Spheres whose final displacement exceeds `threshold` [m] (bool mask)."""
        return np.linalg.norm(self.displacement(), axis=1) > threshold

    def save(self, folder):
        """Write result.npz and result.json into `folder` (each written under a temporary name first)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        pos = self.pos if self.pos is not None else np.zeros((0, self.n, 3))
        data = {"time": np.asarray(self.time, float), "pos": np.asarray(pos, float), "x0": self.x0,
                "final_pos": self.final_pos, "final_vel": self.final_vel,
                "bond_intact": np.asarray(self.bond_intact, bool)}
        data.update({f"series_{k}": np.asarray(v) for k, v in self.series.items()})
        atomic_npz(folder / "result.npz", data)
        head = {"engine": self.engine, "status": self.status, "message": self.message, "steps": int(self.steps),
                "dt": float(self.dt), "wall_s": float(self.wall_s), "n": int(self.n),
                "n_bonds": int(len(self.bond_intact)), "bonds_intact": int(np.sum(self.bond_intact)),
                "records": int(len(self.time)), "series": sorted(self.series), "extra": self.extra}
        with atomic_path(folder / "result.json") as tmp:
            Path(tmp).write_text(json.dumps(head, indent=2))
        return folder

    @classmethod
    def load(cls, folder):
        """The result in `folder` (result.json + result.npz), validated: result.json a JSON object with the engine,
        a known status and non-negative counts and times; result.npz with every array of the table above, shapes
        agreeing with each other and with result.json (n, n_bonds, records, series), record times finite, and
        positions and velocities finite in a complete result (an incomplete one may hold the NaN of a blow-up).
        Raises sgim.readback.BadFile naming the file and the first defect."""
        folder = Path(folder)
        jpath, npath = folder / "result.json", folder / "result.npz"
        F = Fields(jpath, read_json(jpath, "a result.json"))
        head = {"engine": F.string("engine"), "status": F.string("status", choices=(COMPLETE, INCOMPLETE)),
                "message": F.string("message", ""), "steps": F.number("steps", 0, integer=True, nonneg=True),
                "dt": F.number("dt", 0.0, nonneg=True), "wall_s": F.number("wall_s", 0.0, nonneg=True),
                "extra": F.obj("extra", {})}
        A = Arrays(npath, read_npz(npath, "a result.npz"), "a result.npz")
        A.missing(("time", "pos", "x0", "final_pos", "final_vel", "bond_intact"))
        done = head["status"] == COMPLETE
        x0 = A.real("x0", (None, 3), finite=done)
        n = len(x0)
        t = A.real("time", (None,))
        r = len(t)
        pos = A.real("pos", None, finite=False)
        if pos.ndim != 3 or pos.shape[1:] != (n, 3) or pos.shape[0] not in (0, r):
            A.fail(f"pos: shape {tuple(pos.shape)}, expected ({r}, {n}, 3) or (0, {n}, 3) (records x spheres of x0)")
        series = {}
        for k in A.arrays:
            if k.startswith("series_"):
                series[k[len("series_"):]] = A.real(k, (r,), finite=False, per="one per record of time",
                                                    dtype=A.arrays[k].dtype)
        one = "one per sphere of x0"
        res = cls(engine=head["engine"], x0=x0, final_pos=A.real("final_pos", (n, 3), finite=done, per=one),
                  final_vel=A.real("final_vel", (n, 3), finite=done, per=one),
                  bond_intact=A.boolean("bond_intact", (None,)), time=t, pos=pos if pos.size else None,
                  series=series, status=head["status"], message=head["message"], steps=head["steps"], dt=head["dt"],
                  wall_s=head["wall_s"], extra=head["extra"])
        for key, have in (("n", n), ("n_bonds", len(res.bond_intact)), ("records", r)):
            if key in F.doc and F.number(key, integer=True, nonneg=True) != have:
                F.fail(key, F.doc[key], f"does not match {npath.name}, which holds {have}")
        if "series" in F.doc and sorted(F.strings("series")) != sorted(series):
            F.fail("series", F.doc["series"], f"does not match {npath.name}, which holds {sorted(series)}")
        return res


__all__ = ["RunResult", "COMPLETE", "INCOMPLETE"]
