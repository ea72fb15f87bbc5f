"""Time-series plot of a run (``series.png``): displacement, speed and energy terms against time, with units.

Three panels sharing the time axis (s): the mean and the largest displacement of the moving bodies (m), their
mean and largest speed (m/s), and the energy terms (J) with the balance error. Blocks and spheres are drawn
apart when a run has both. Values that span more than three decades are drawn on a symmetric log scale.
"""
from __future__ import annotations

import numpy as np

from .results import ENERGY_COLUMNS

ENERGY_LABELS = {"kinetic": "kinetic", "potential": "potential (change from start)", "elastic": "elastic (springs)",
                 "friction": "friction (dissipated)", "damping": "contact damping (dissipated)",
                 "local_damping": "local damping (dissipated)",
                 "point_turnover": "point turnover (released - created)", "balance_error": "balance error"}


def _moves(pos, vel, moving):
    """(mean, max displacement, mean, max speed) per record of the bodies `moving` (r,) each."""
    if pos.ndim != 3 or not moving.any() or not len(pos):
        z = np.zeros(len(pos))
        return z, z, z, z
    d = np.linalg.norm(pos[:, moving] - pos[:1, moving], axis=2)
    s = np.linalg.norm(vel[:, moving], axis=2) if vel.ndim == 3 and len(vel) == len(pos) else np.zeros_like(d)
    return d.mean(axis=1), d.max(axis=1), s.mean(axis=1), s.max(axis=1)


def plot_series(path, title, time, energy, bodies):
    """Write the PNG. `bodies`: list of (name, pos (r, n, 3), vel (r, n, 3) or None (then the time derivative of
    the positions), moving (n,) bool)."""
    import matplotlib  # not at the top: seconds to load, for the PNG only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(time, float)
    fig, axes = plt.subplots(3, 1, figsize=(8.0, 9.0), sharex=True, constrained_layout=True)
    fig.suptitle(f"{title}: time series")
    for name, pos, vel, moving in bodies:
        pos = np.asarray(pos, float)
        if vel is None:  # not recorded (moving blocks of a sphere run): the rate of the recorded positions
            vel = np.gradient(pos, t, axis=0) if pos.ndim == 3 and len(pos) == len(t) > 1 else np.zeros_like(pos)
        vel = np.asarray(vel, float)
        dm, dx, sm, sx = _moves(pos, vel, np.asarray(moving, bool))
        if len(dm) != len(t):
            continue
        axes[0].plot(t, dm, label=f"{name}: mean")
        axes[0].plot(t, dx, "--", label=f"{name}: largest")
        axes[1].plot(t, sm, label=f"{name}: mean")
        axes[1].plot(t, sx, "--", label=f"{name}: largest")
    axes[0].set_ylabel("displacement (m)")
    axes[1].set_ylabel("speed (m/s)")
    e = np.asarray(energy, float).reshape(len(t), -1) if len(t) else np.zeros((0, len(ENERGY_COLUMNS)))
    span = []
    for k, col in enumerate(ENERGY_COLUMNS):
        if k >= e.shape[1] or not np.any(np.isfinite(e[:, k])):
            continue
        y = e[:, k] - e[0, k] if col == "potential" else e[:, k]  # the potential energy from its start value
        if np.nanmax(np.abs(y)) > 0:
            axes[2].plot(t, y, ":" if col == "balance_error" else "-", label=ENERGY_LABELS[col])
            span.append(np.nanmax(np.abs(y)))
    if span and max(span) > 1e3 * min(span):
        axes[2].set_yscale("symlog", linthresh=max(span) * 1e-6)
    axes[2].set_ylabel("energy (J)")
    axes[2].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize="small", loc="best")
    fig.savefig(path, dpi=100)
    plt.close(fig)
