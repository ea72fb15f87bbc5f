"""Step limits: a run whose step count (duration / dt) passes a limit is refused before it starts.

The limit: ``--max-steps N`` on the command (``dda run``, ``dda wedge``, ``adapters export``), else the scene's
``[simulation] max_steps`` (or ``[limits] max_steps``: the same key in the table sgim scenes use), else
``DEFAULT_MAX_STEPS`` = 1e8. The scenes of cases/ need at most 3.6e5 steps (cases/scenes/dda_toppling.toml; the
crossval and study scenes 2e3 - 2e4), and 1e8 steps of one block take about a day at the engine's speed.

The refusal is one SceneError line naming what caused the count, the dt and the numbers:

* the duration (``simulation.duration = 1e9: 1e9 s at dt = 1.78e-05 s is 5.6e+13 steps, past max_steps = 1e+08
  (...)``) when the time step would allow a second of simulated time within the limit;
* otherwise the key that set the time step: ``simulation.dt`` when the scene gives it, else the stiffness that
  sets the critical step (``contact.kn``, ``contact_pair[k].kn``, ``contact.ks``, ``spheres.bond_young`` /
  ``spheres.bond_kn``): ``contact.kn = 1e+30: sets dt = 5.6e-15 s (...)``.

The block run of an sgim scene (dda/georun.py) names its own keys: ``blocks.run.duration``, ``blocks.run.dt``,
``blocks.kn`` or ``blocks.law[k].kn``, and only ``--max-steps`` to raise the limit (such a scene has no max_steps).
"""
from __future__ import annotations

import math

import numpy as np

from sgim.common import SceneError

DEFAULT_MAX_STEPS = 100_000_000


def run_steps(duration, dt):
    """The steps Simulation.run takes for `duration` at `dt` (at least 1; inf when dt underflows)."""
    q = float(duration) / float(dt)
    return max(1, round(q)) if math.isfinite(q) else math.inf


def limit_for(scene=None, max_steps=None):
    """(limit, key, origin) of a run: --max-steps, else the scene's max_steps, else the default."""
    if max_steps is not None:
        return int(max_steps), "--max-steps", "--max-steps"
    lim = getattr(scene, "max_steps", None)
    if lim is not None:
        return int(lim), getattr(scene, "max_steps_key", "simulation.max_steps"), "the scene's"
    return DEFAULT_MAX_STEPS, "simulation.max_steps", "the default"


def block_dt_source(scene):
    """(key, value) of the stiffness that sets a block scene's critical step: the largest of the scene's
    ``stiffness_keys()`` ([contact] kn and the [[contact_pair]] laws; the block run of an sgim scene: [blocks] kn and
    the [[blocks.law]] kn, dda/georun.py)."""
    pairs = scene.stiffness_keys()
    key, kn = pairs[0]
    for k, v in pairs[1:]:
        if v > kn:
            key, kn = k, v
    return key, kn


def sphere_dt_source(kn, ks, n, bond_i=(), bond_j=(), bond_kn=(), bond_ks=(), bond_key="spheres.bond_young",
                     bond_value=None, kn_key="contact.kn", ks_key="contact.ks"):
    """(key, value) of the stiffness that sets a sphere run's critical step (dda.spheres.SphereSimulation.
    critical_dt: four contacts of stiffness max(kn, 3.5 ks) plus the sphere's bonds, the stiffest sphere):
    the bonds when their largest sum on one sphere exceeds the contacts' part, else kn or ks."""
    contact = 4.0 * max(float(kn), 3.5 * float(ks))
    bond = 0.0
    if len(bond_i):
        kb = np.maximum(np.asarray(bond_kn, float), 3.5 * np.asarray(bond_ks, float))
        s = np.bincount(np.asarray(bond_i, np.int64), kb, n) + np.bincount(np.asarray(bond_j, np.int64), kb, n)
        bond = float(s.max())
    if bond > contact:
        return bond_key, bond_value
    return (kn_key, float(kn)) if float(kn) >= 3.5 * float(ks) else (ks_key, float(ks))


def check(path, duration, dt, *, dt_key, dt_value, auto_dt, dt_crit=None, safety=None, max_steps=None,
          scene=None, duration_key="simulation.duration", flag="--max-steps", raise_limit=None, dt_fix=None):
    """Raise SceneError when `duration` / `dt` passes the limit (see the module docstring); return the steps.

    `dt_key` / `dt_value`: what set dt (``simulation.dt`` when given, else the stiffness of the critical step,
    `auto_dt` True); `dt_crit`, `safety`: for the message. `raise_limit` / `dt_fix`: the remedies' wording
    when not the scene keys' (default "raise simulation.max_steps or --max-steps", "lower KEY" / "raise KEY")."""
    steps = run_steps(duration, dt)
    limit, key, origin = limit_for(scene, max_steps)
    if steps <= limit:
        return steps
    shown = f"{steps:.2g}" if math.isfinite(steps) else "infinitely many"
    raise_lim = raise_limit or f"raise {'simulation.max_steps' if key == '--max-steps' else key} or {flag}"
    past = f"past max_steps = {limit:.3g} ({origin})"
    if auto_dt:
        how = f"sets dt = {dt:.2g} s (safety {safety:g} x the critical time step {dt_crit:.2g} s)" \
            if dt_crit is not None and safety is not None else f"sets dt = {dt:.2g} s"
        lower = dt_fix or f"lower {dt_key}"
        lower_with = f"{lower} = {dt_value:g} which sets dt" if dt_value is not None else f"{lower} which sets dt"
    else:
        lower = dt_fix or f"raise {dt_key}"
        lower_with = f"{lower} = {dt:g}"
    if dt * limit >= min(duration, 1.0):  # the step allows a second within the limit: the duration is the cause
        raise SceneError(path, duration_key, duration,
                         f"{duration:g} s at dt = {dt:.2g} s is {shown} steps, {past}: {raise_lim}, shorten "
                         f"{duration_key}, or {lower_with}")
    raise SceneError(path, dt_key, dt_value if dt_value is not None else dt,
                     f"{how}: {duration_key} = {duration:g} s is {shown} steps, {past}: {lower}, {raise_lim}, or "
                     f"shorten {duration_key}" if auto_dt else
                     f"{duration_key} = {duration:g} s at this dt is {shown} steps, {past}: {lower}, {raise_lim}, "
                     f"or shorten {duration_key}")


def check_block_run(scene, sim, max_steps=None, duration=None):
    """The step check of a block scene's Simulation `sim` (DDAScene.build). A scene whose run settings live under
    other keys (the block run of an sgim scene: [blocks.run]) names them in its ``run_keys``: "duration", "dt" and
    "raise_limit" (the remedy's wording for the step limit)."""
    duration = scene.duration if duration is None else duration
    keys = scene.run_keys
    named = dict(duration_key=keys.get("duration", "simulation.duration"), raise_limit=keys.get("raise_limit"))
    if scene.dt is not None:
        return check(scene.path, duration, sim.dt, dt_key=keys.get("dt", "simulation.dt"), dt_value=scene.dt,
                     auto_dt=False, max_steps=max_steps, scene=scene, **named)
    key, value = block_dt_source(scene)
    return check(scene.path, duration, sim.dt, dt_key=key, dt_value=value, auto_dt=True, dt_crit=sim.dt_crit,
                 safety=scene.safety, max_steps=max_steps, scene=scene, **named)


def check_sphere_run(scene, ss, sim, max_steps=None, duration=None):
    """The step check of a sphere scene's SphereSimulation `sim` over SphereSet `ss` (DDAScene.build_spheres)."""
    duration = scene.duration if duration is None else duration
    if scene.dt is not None:
        return check(scene.path, duration, sim.dt, dt_key="simulation.dt", dt_value=scene.dt, auto_dt=False,
                     max_steps=max_steps, scene=scene)
    bkey, bval = sphere_bond_key(scene)
    key, value = sphere_dt_source(scene.law.kn, scene.law.ks if scene.law.ks is not None else scene.law.kn / 2,
                                  ss.n, ss.bond_i, ss.bond_j, ss.bond_kn, ss.bond_ks, bkey, bval)
    if sim.blocks is not None and sim.blocks.dt_crit <= sim.dt_crit * (1 + 1e-12):
        key, value = block_dt_source(scene)  # moving blocks set the common step
    return check(scene.path, duration, sim.dt, dt_key=key, dt_value=value, auto_dt=True, dt_crit=sim.dt_crit,
                 safety=scene.safety, max_steps=max_steps, scene=scene)


def sphere_bond_key(scene):
    """(key, value) of the bond stiffness of a [spheres] scene: bond_kn when given, else bond_young."""
    sp = getattr(scene, "spheres", None) or {}
    law = sp.get("bonds")
    if law is not None and getattr(law, "kn", None) is not None:
        return "spheres.bond_kn", float(law.kn)
    return "spheres.bond_young", float(getattr(law, "young", 1e9)) if law is not None else None
