"""Results of a DDA run: time series of the block states and the energy balance, and their files.

``series.npz`` keys: ``time`` (r,), ``pos`` (r, n, 3) centroids, ``quat`` (r, n, 4) orientations (w, x, y, z,
body principal frame -> world), ``vel`` (r, n, 3), ``energy`` (r, 8) with columns ``ENERGY_COLUMNS``,
``contacts`` / ``points`` / ``sliding`` (r,) counts, ``names`` (n,), ``fixed`` (n,), ``mass`` (n,); with
deformable blocks also ``strain`` (r, n, 6) body-frame strains (ex, ey, ez, gyz, gzx, gxy).
``series.csv``: one row per record with time, the energy columns, the counts, and the mean displacement of
the moving blocks, each column name ending in its unit (``time_s``, ``kinetic_J``, ``mean_displacement_m``) (``save_sphere_csv``: the columns of a run with spheres). ``final.npz``: the final state (pos, quat, vel, angmom, world vertices, contact points;
``strain`` (n, 6) and ``dof`` with deformable blocks).
"""
from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field

import numpy as np

ENERGY_COLUMNS = ("kinetic", "potential", "elastic", "friction", "damping", "local_damping", "point_turnover",
                  "balance_error")
# series.csv: the unit of each column as a suffix of its name (counts have none)
CSV_UNITS = {"time": "s", **{c: "J" for c in ENERGY_COLUMNS}, "mean_displacement": "m",
             "mean_block_displacement": "m"}


def csv_header(columns):
    """Column names with their units: time_s, kinetic_J, ..., mean_displacement_m; counts stay bare."""
    return [f"{c}_{CSV_UNITS[c]}" if c in CSV_UNITS else c for c in columns]


@dataclass
class Results:
    names: list
    fixed: np.ndarray
    mass: np.ndarray
    time: list = field(default_factory=list)
    pos: list = field(default_factory=list)
    quat: list = field(default_factory=list)
    vel: list = field(default_factory=list)
    energy: list = field(default_factory=list)
    contacts: list = field(default_factory=list)
    points: list = field(default_factory=list)
    sliding: list = field(default_factory=list)
    wall_s: float = 0.0
    dt: float = 0.0
    steps: int = 0
    strain: list = field(default_factory=list)  # only with deformable blocks

    @staticmethod
    def empty(sim):
        return Results(names=list(sim.A.names), fixed=sim.A.fixed.copy(), mass=sim.A.mass.copy(), dt=sim.dt)

    def record(self, sim):
        self.time.append(sim.time)
        self.pos.append(sim.pos.copy())
        self.quat.append(sim.quat.copy())
        self.vel.append(sim.vel.copy())
        e = sim.energy
        err = (e.sum() - sim.E0) if sim.E0 is not None else np.nan
        self.energy.append(np.r_[e, err] if sim.E0 is not None else np.full(7, np.nan))
        self.contacts.append(int(sim.stats[5]))
        self.points.append(int(sim.stats[6]))
        self.sliding.append(int(sim.stats[7]))
        self.steps = sim.steps
        d12 = getattr(sim, "dof12", None)
        if d12 is not None and d12.any():
            self.strain.append(sim.strain_.copy())

    # arrays ----------------------------------------------------------
    @property
    def times(self):
        return np.asarray(self.time)

    @property
    def positions(self):
        return np.asarray(self.pos)

    @property
    def velocities(self):
        return np.asarray(self.vel)

    @property
    def energies(self):
        return np.asarray(self.energy)

    def energy_column(self, name):
        return self.energies[:, ENERGY_COLUMNS.index(name)]

    def arrays(self):
        return {
            "time": self.times, "pos": self.positions, "quat": np.asarray(self.quat), "vel": self.velocities,
            "energy": self.energies, "energy_columns": np.array(ENERGY_COLUMNS),
            "contacts": np.asarray(self.contacts), "points": np.asarray(self.points),
            "sliding": np.asarray(self.sliding), "names": np.array(self.names), "fixed": self.fixed,
            "mass": self.mass, "dt": self.dt, "steps": self.steps, "wall_s": self.wall_s,
            **({"strain": np.asarray(self.strain)} if self.strain else {}),
        }

    def save_npz(self, path):
        tmp = f"{path}.tmp{os.getpid()}.npz"
        np.savez_compressed(tmp, **self.arrays())
        os.replace(tmp, path)

    def save_csv(self, path):
        tmp = f"{path}.tmp{os.getpid()}"
        pos = self.positions
        moving = ~self.fixed
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(csv_header(["time", *ENERGY_COLUMNS, "contacts", "points", "sliding", "mean_displacement"]))
            for r in range(len(self.time)):
                disp = float(np.linalg.norm(pos[r, moving] - pos[0, moving], axis=1).mean()) if moving.any() else 0.0
                w.writerow([repr(float(self.time[r])), *[repr(float(x)) for x in self.energy[r]],
                            self.contacts[r], self.points[r], self.sliding[r], repr(disp)])
        os.replace(tmp, path)


def _mean_displacement(pos, moving):
    """Mean distance of the moving bodies from their first recorded position, per record (r,)."""
    if pos.ndim != 3 or not moving.any():
        return np.zeros(len(pos))
    return np.linalg.norm(pos[:, moving] - pos[:1, moving], axis=2).mean(axis=1)


def save_sphere_csv(res, path, fixed, block_fixed=None):
    """series.csv of a sphere run (a SphereResults): one row per record with time, the energy columns, the
    sphere-sphere and sphere-wall/block contact counts, the intact bonds, the mean displacement of the free
    spheres and (with moving blocks) of the moving blocks (`block_fixed`: the blocks' fixed flags)."""
    tmp = f"{path}.tmp{os.getpid()}"
    n = len(res.time)
    sdisp = _mean_displacement(np.asarray(res.pos), ~np.asarray(fixed, bool)) if res.pos else np.zeros(n)
    bpos = np.asarray(res.block_pos)
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(csv_header(["time", *ENERGY_COLUMNS, "contacts", "wall_contacts", "bonds", "mean_displacement",
                               *(["mean_block_displacement"] if res.block_pos else [])]))
        bdisp = None
        if res.block_pos:
            moving = np.ones(bpos.shape[1], bool) if block_fixed is None else ~np.asarray(block_fixed, bool)
            bdisp = _mean_displacement(bpos, moving)
        for r in range(n):
            w.writerow([repr(float(res.time[r])), *[repr(float(x)) for x in res.energy[r]], res.contacts[r],
                        res.wall_contacts[r], res.bonds[r], repr(float(sdisp[r])),
                        *([repr(float(bdisp[r]))] if bdisp is not None else [])])
    os.replace(tmp, path)


def save_final(sim, path):
    """Final state of a simulation (npz)."""
    tmp = f"{path}.tmp{os.getpid()}.npz"
    A = sim.A
    verts = np.concatenate([sim.vertices(i) for i in range(A.n)])
    c = sim.contacts()
    np.savez_compressed(
        tmp, time=sim.time, steps=sim.steps, pos=sim.pos, quat=sim.quat, vel=sim.vel, angmom=sim.angmom,
        vertices=verts, vert_start=A.vert_start, face_vert_start=A.face_vert_start, face_verts=A.face_verts,
        face_start=A.face_start, names=np.array(A.names), fixed=A.fixed,
        **{f"contact_{k}": v for k, v in c.items()},
        **({"strain": sim.strain_, "dof": A.dof} if getattr(sim, "dof12", None) is not None and sim.dof12.any()
           else {}))
    os.replace(tmp, path)
