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

COMPLETE, INCOMPLETE = "complete", "incomplete"


@dataclass
class RunResult:
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
        from sgim.model import atomic_npz, atomic_path

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
        folder = Path(folder)
        head = json.loads((folder / "result.json").read_text())
        with np.load(folder / "result.npz", allow_pickle=False) as z:
            arr = {k: z[k] for k in z.files}
        series = {k[len("series_"):]: v for k, v in arr.items() if k.startswith("series_")}
        pos = arr["pos"] if arr["pos"].size else None
        return cls(engine=head["engine"], x0=arr["x0"], final_pos=arr["final_pos"], final_vel=arr["final_vel"],
                   bond_intact=arr["bond_intact"], time=arr["time"], pos=pos, series=series, status=head["status"],
                   message=head.get("message", ""), steps=head.get("steps", 0), dt=head.get("dt", 0.0),
                   wall_s=head.get("wall_s", 0.0), extra=head.get("extra", {}))


__all__ = ["RunResult", "COMPLETE", "INCOMPLETE"]
