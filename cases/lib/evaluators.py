"""Evaluators of batch studies: one case's scene -> a dict of scalar results.

``EVALUATORS[name]`` is an :class:`Evaluator`; a study names one as its ``evaluator``. The runner (cases/lib/_batch.py)
calls ``fn(scene_path, case_dir, params)`` with the case's scene (the study's base scene with the case's values
substituted), the case's own folder (an evaluator may write files there) and the case's parameters
``{path: value}``; the evaluator returns ``{name: float | int | bool}`` and raises on failure (the runner records
the exception's first line). ``needs`` names the external programs a case runs (checked before a study starts).

================  =============================================================================================
name              what it does / the scalars it returns
================  =============================================================================================
``wedge-hb``      Hoek & Bray factor of safety of the wedge of a DDA wedge scene (``[[generate]] kind = "wedge"``:
                  joint_a, joint_b, face, top, height; ``[contact]`` friction and cohesion (Pa); the density of
                  the wedge's material and the gravity give the unit weight). Analytical, about 0.1 ms.
                  ``fs``, ``phi_crit`` (deg, cohesion 0), ``wedge`` (1: the joints form a wedge that daylights
                  in the face; 0: no wedge can slide out, every other value NaN), ``two_planes`` (1: sliding on
                  both joints, 0: on one), ``plunge`` / ``trend`` of the line of intersection (deg), ``volume``
                  (m^3).
``wedge-dda``     the in-house DDA critical friction of the same wedge (``dda.wedge.dda_critical_friction``:
                  bracket and bisect the joint friction to 0.05 deg; trial length ``[simulation] duration``,
                  ``[simulation] safety``, ``[contact]`` kn and damping from the scene; cohesion must be 0) next to
                  Hoek & Bray in the same row: ``fs_dda`` = tan(phi) / tan(phi_crit_dda), ``phi_crit_dda``,
                  ``fs_hb``, ``phi_crit_hb``, ``error_fs`` = fs_dda / fs_hb - 1, ``error_phi`` = phi_crit_dda /
                  phi_crit_hb - 1, ``wedge``, ``trials``, ``steps_per_trial``, ``run_s`` (wall time of the
                  search). A case whose joints form no wedge returns ``wedge`` = 0 and NaN elsewhere.
``sgim-build``    builds the sgim scene (``sgim.builder.build_model``): ``spheres``, ``red``, ``green``, ``blue``,
                  ``red_fraction``, ``fractures`` (discontinuities incl. the sampled network), ``bonded``,
                  ``packing_density`` (random packings; NaN for lattices), ``detached_clusters``,
                  ``detached_spheres``, ``largest_detached`` (see :func:`detached_clusters`), ``build_s``.
``sgim-volume``   excavation volume of an sgim scene with one excavation surface covering the domain's plan
                  (a height surface): ``spheres`` kept, ``kept_volume`` (kept sites x domain volume / lattice
                  sites), ``exact_volume`` (below the triangulated surface, exact), ``error_volume`` = kept /
                  exact - 1, ``excavate_s`` (lattice + excavation).
``dda-run``       runs a DDA scene (``dda.scene.load_scene(...).build()``, ``Simulation.run`` for ``[simulation]
                  duration``): ``displacement`` (m) of the tracked block (param ``track`` = a block name, else the
                  first moving block named block / wedge / projectile / column, else the first moving block),
                  ``moved`` (moving blocks whose centroid moved more than 1 % of their size), ``error_energy``
                  (max |energy balance error| over the run / the largest mechanical energy in play, see
                  :func:`energy_error`), ``steps``, ``dt``, ``dt_ratio`` (dt / critical), ``run_s``, and against
                  the analytical reference of a standard case, ``reference`` (m) and ``error_disp`` (relative):
                  incline (``kind = "incline"``): s = 1/2 g (sin a - tan phi cos a) t^2 down the slope;
                  wedge (``kind = "wedge"``, sliding on both joints, cohesion 0): s = 1/2 g sin(psi5)
                  (1 - tan phi / tan phi_c) t^2 along the line of intersection. A block that must hold (s = 0)
                  gives error_disp = displacement / block size. Other scenes: reference and error_disp NaN.
``yade``          exports a sphere scene (DDA scene with [spheres], sgim scene or model) with
``liggghts``      ``adapters.deck.export`` and runs it with ``adapters.deck.run`` (a subprocess on one core);
``dda-spheres``   the same run in the in-house engine (``adapters.inhouse.run_inhouse``):
                  ``n``, ``detached`` (spheres that moved more than half the smallest radius), ``reference_detached``
                  (spheres that no bond path ties to a fixed sphere: the cross-validation reference of
                  cases/lib/crossval.py; NaN without fixed spheres), ``error_detached`` (spheres whose state differs
                  from the reference / n), ``max_displacement``, ``mean_displacement``, ``bonds_broken``,
                  ``steps``, ``engine_s``. An incomplete run raises.
================  =============================================================================================

Error columns are named ``error_*`` (the report draws speed against error for each; the results table's own
``error`` column holds a failed case's message). Timing columns an evaluator returns (``run_s``, ``build_s``,
``excavate_s``, ``engine_s``) time the computation proper: the first DDA (or excavation) case of a process first
runs a few steps of the same model (a coarse lattice), so that the one-off compilation of the kernels does not
fall on it (the runner's ``wall_s`` includes it). The runner calls the evaluator's ``warm`` once in the case
server of each rank, before the cases are forked from it, so every case finds the kernels compiled.

Every evaluator declares its ``units`` (the report's axes and tables) and a ``check`` of the base scene, run once
before any case. The registry: :func:`registry` (the framework's noop / sleep / spin and EVALUATORS) and
:func:`resolve_evaluator` (a registry name or ``module:function``).
"""
from __future__ import annotations

import importlib
import inspect
import json
import math
import sys
import time
import tomllib
from dataclasses import dataclass, field
from importlib.machinery import PathFinder
from pathlib import Path
from typing import Callable

import numpy as np

# Each evaluator imports its engine (sgim, dda, adapters: numba kernels; scipy) inside its own functions: the
# case server imports this registry once, and a study then loads only the engine of its evaluator (noop, sleep
# and spin load none), which keeps the fork of every case small and `cases study list` fast.

G = 9.81
NAN = float("nan")


@dataclass(frozen=True)
class Evaluator:
    """fn(scene_path, case_dir, params) -> {name: scalar}. needs: external programs; results: the scalars fn
    returns; units: {result: unit} for reports; check(scene_path): validates a scene before any case runs
    (raises with a one-line reason); warm(scene_path): one-off work (kernel compilation) done once in the case
    server of each rank before the cases are forked from it."""

    fn: Callable
    needs: tuple = ()
    description: str = ""
    results: tuple = field(default=())  # the scalars fn returns (every case returns all of them)
    units: dict = field(default_factory=dict)
    check: Callable | None = None
    warm: Callable | None = None


# ---------------------------------------------------------------------------------------------------------
# scene helpers


def _read_toml(path):
    from sgim.common import SceneError

    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(path, "(file)", str(path), f"cannot read scene file ({exc.__class__.__name__})") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "(toml)", str(exc).split("\n")[0], "not valid TOML") from None


def orientation(value):
    """(dip, dip direction) with dip in [0, 90] and dip direction in [0, 360) for any pair of angles: a dip
    outside [0, 90] (a sampled pole below the horizon) is the same plane seen from the other side."""
    dip, dd = float(value[0]), float(value[1])
    dip %= 360.0
    if dip > 180.0:
        dip -= 360.0
    if dip < 0.0:
        dip, dd = -dip, dd + 180.0
    if dip > 90.0:
        dip, dd = 180.0 - dip, dd + 180.0
    return dip, dd % 360.0


def wedge_inputs(path):
    """The wedge of a DDA scene with ``[[generate]] kind = "wedge"``: a dict of joint_a, joint_b, face, top
    (dip, dip direction), height (m), friction (deg), cohesion (Pa), density (kg/m^3), g (m/s^2),
    unit_weight (N/m^3), kn, damping, safety, duration (None where the scene does not say)."""
    from sgim.common import SceneError

    data = _read_toml(path)
    gens = [(k, g) for k, g in enumerate(data.get("generate", []) or []) if isinstance(g, dict)
            and g.get("kind") == "wedge"]
    if not gens:
        raise SceneError(path, "generate", None, 'no [[generate]] table with kind = "wedge"')
    k, gt = gens[0]
    ct = data.get("contact", {}) or {}
    st = data.get("simulation", {}) or {}
    mname = gt.get("material", "rock")
    density = 2600.0
    for m in data.get("material", []) or []:
        if isinstance(m, dict) and m.get("name") == mname:
            density = float(m.get("density", density))
    grav = st.get("gravity", (0.0, 0.0, -G))
    g = float(np.linalg.norm(np.asarray(grav, float)))
    out = dict(joint_a=orientation(gt.get("joint_a", (45.0, 5.0))),
               joint_b=orientation(gt.get("joint_b", (55.0, 135.0))),
               face=orientation(gt.get("face", (65.0, 65.0))), top=orientation(gt.get("top", (0.0, 0.0))),
               height=float(gt.get("height", 10.0)), friction=float(ct.get("friction", 0.0)),
               cohesion=float(ct.get("cohesion", 0.0)), density=density, g=g, unit_weight=density * g,
               kn=ct.get("kn"), damping=ct.get("damping"), safety=st.get("safety"), duration=st.get("duration"))
    if not (0.0 <= out["friction"] < 90.0):
        raise SceneError(path, "contact.friction", out["friction"], "must be in [0, 90) degrees")
    return out


# ---------------------------------------------------------------------------------------------------------
# wedge-hb, wedge-dda

WEDGE_HB_RESULTS = ("fs", "phi_crit", "wedge", "two_planes", "plunge", "trend", "volume")


def wedge_hb(scene_path, case_dir, params):
    """Hoek & Bray factor of safety of the scene's wedge (see the module docstring)."""
    from dda import hoekbray

    w = wedge_inputs(scene_path)
    try:
        r = hoekbray.wedge_fs(w["joint_a"], w["joint_b"], w["face"], top=w["top"], friction=w["friction"],
                              cohesion=w["cohesion"], unit_weight=w["unit_weight"], height=w["height"])
    except hoekbray.WedgeError:
        return {k: (0 if k == "wedge" else NAN) for k in WEDGE_HB_RESULTS}
    return dict(fs=r.fs, phi_crit=r.critical_friction, wedge=1, two_planes=int(r.mode == "both planes"),
                plunge=r.line_plunge, trend=r.line_trend, volume=r.volume)


WEDGE_DDA_RESULTS = ("fs_dda", "phi_crit_dda", "fs_hb", "phi_crit_hb", "error_fs", "error_phi", "wedge", "trials",
                     "steps_per_trial", "run_s")
_WARM = set()


def _wedge_model_kw(w):
    kw = {}
    if w["kn"] is not None:
        kw["kn"] = float(w["kn"])
    for key in ("damping", "safety", "duration"):
        if w[key] is not None:
            kw[key] = float(w[key])
    return kw


def warm_wedge_dda(scene_path):
    """Compile the DDA kernels on a few steps of the scene's wedge (outside the timed search)."""
    from dda import hoekbray
    from dda.wedge import WedgeModel

    w = wedge_inputs(scene_path)
    geo = (w["joint_a"], w["joint_b"], w["face"], w["top"], w["height"])
    try:
        hoekbray.wedge_fs(*geo[:3], top=geo[3], height=geo[4], friction=w["friction"], unit_weight=w["unit_weight"])
    except hoekbray.WedgeError:
        return
    kw = _wedge_model_kw(w)
    WedgeModel(*geo, w["density"] * G / 1000.0, **{**kw, "duration": 0.002, "settle": 0.002}).run(w["friction"])
    _WARM.add("wedge-dda")


def wedge_dda(scene_path, case_dir, params):
    """DDA critical friction and factor of safety of the scene's wedge next to Hoek & Bray's."""
    from dda import hoekbray
    from dda.wedge import WedgeModel, dda_critical_friction
    from sgim.common import SceneError

    w = wedge_inputs(scene_path)
    if w["cohesion"] != 0.0:
        raise SceneError(scene_path, "contact.cohesion", w["cohesion"], "wedge-dda searches the friction angle "
                         "of cohesionless joints: cohesion must be 0")
    if abs(w["g"] - G) > 1e-9 * G:
        raise SceneError(scene_path, "simulation.gravity", w["g"], f"wedge-dda runs with g = {G}")
    geo = dict(joint_a=w["joint_a"], joint_b=w["joint_b"], face=w["face"], top=w["top"], height=w["height"])
    try:
        hb = hoekbray.wedge_fs(**geo, friction=w["friction"], unit_weight=w["unit_weight"])
    except hoekbray.WedgeError:
        return {k: (0 if k in ("wedge", "trials", "steps_per_trial") else NAN) for k in WEDGE_DDA_RESULTS}
    unit_kn = w["density"] * G / 1000.0  # WedgeModel takes kN/m^3
    kw = _wedge_model_kw(w)
    if "wedge-dda" not in _WARM:  # compile the kernels outside the timed search (results do not change)
        warm_wedge_dda(scene_path)
    r = dda_critical_friction(geo["joint_a"], geo["joint_b"], geo["face"], geo["top"], geo["height"],
                              w["friction"], unit_kn, tol=0.05, step=2.0, **kw)
    if case_dir is not None:
        Path(case_dir).mkdir(parents=True, exist_ok=True)
        (Path(case_dir) / "wedge_dda.json").write_text(json.dumps(r, indent=1))
    fs_dda = float(r["fs_dda"])
    return dict(fs_dda=fs_dda, phi_crit_dda=float(r["phi_crit_dda"]), fs_hb=hb.fs, phi_crit_hb=hb.critical_friction,
                error_fs=fs_dda / hb.fs - 1.0, error_phi=float(r["phi_crit_dda"]) / hb.critical_friction - 1.0,
                wedge=1, trials=len(r["trials"]), steps_per_trial=int(r["steps_per_trial"]), run_s=float(r["wall_s"]))


# ---------------------------------------------------------------------------------------------------------
# sgim-build

SUPPORTED_FACES = ("x-", "x+", "y-", "y+", "z-")


def detached_clusters(centers, radii, pairs, colour, lo, hi, faces=SUPPORTED_FACES):
    """Clusters of rock that no bond ties to the supported boundary of the domain.

    The graph: the spheres that are not red (red spheres lie inside a fault; the colour rule cuts all their
    bonds) with an edge for every bonded pair in ``pairs`` ((m, 2) indices). A sphere is on the supported
    boundary when its centre lies within one diameter (2 r) of one of ``faces`` of the domain box ``lo``..``hi``
    (by default the bottom and the four sides, where the rock mass continues; the top is free). A connected
    component with no sphere on the supported boundary is a detached cluster (a lone sphere with no bond is one).

    Returns ``dict(detached_clusters, detached_spheres, largest_detached, components)``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    c = np.asarray(centers, float).reshape(-1, 3)
    r = np.asarray(radii, float)
    n = len(c)
    keep = np.asarray(colour) != 1
    p = np.asarray(pairs, np.int64).reshape(-1, 2)
    p = p[keep[p[:, 0]] & keep[p[:, 1]]]
    g = coo_matrix((np.ones(len(p), np.int8), (p[:, 0], p[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    on = np.zeros(n, bool)
    for f in faces:
        ax = "xyz".index(f[0])
        on |= (c[:, ax] - lo[ax] <= 2 * r) if f[1] == "-" else (hi[ax] - c[:, ax] <= 2 * r)
    lab = lab[keep]
    held = np.zeros(lab.max() + 1 if len(lab) else 0, bool)
    held[lab[on[keep]]] = True
    comps = np.unique(lab)
    free = comps[~held[comps]]
    sizes = np.bincount(lab, minlength=len(held))[free]
    return dict(detached_clusters=int(len(free)), detached_spheres=int(sizes.sum()),
                largest_detached=int(sizes.max()) if len(sizes) else 0, components=int(len(comps)))


SGIM_RESULTS = ("spheres", "red", "green", "blue", "red_fraction", "fractures", "bonded", "packing_density",
                "detached_clusters", "detached_spheres", "largest_detached", "build_s")


def sgim_build(scene_path, case_dir, params):
    """Build the sgim scene and count colours and detached clusters (see the module docstring)."""
    from sgim.builder import build_model
    from sgim.scene import load_scene

    scene = load_scene(scene_path)
    t0 = time.perf_counter()
    model = build_model(scene)
    build_s = time.perf_counter() - t0
    cnt = model.counts()
    n = max(cnt["spheres"], 1)
    stats = (model.meta.get("packing") or {}).get("statistics") or {}
    cl = detached_clusters(model.centers, model.radii, np.asarray(model.bonds).reshape(-1, 2)[model.bonded],
                           model.colour, scene.domain.min, scene.domain.max)
    return dict(spheres=cnt["spheres"], red=cnt["red"], green=cnt["green"], blue=cnt["blue"],
                red_fraction=cnt["red"] / n, fractures=cnt["discontinuities"], bonded=cnt["bonded"],
                packing_density=float(stats.get("density", NAN)), detached_clusters=cl["detached_clusters"],
                detached_spheres=cl["detached_spheres"], largest_detached=cl["largest_detached"], build_s=build_s)


# ---------------------------------------------------------------------------------------------------------
# sgim-volume (excavation volume)


def volume_below_surface(vertices, faces, lo, hi):
    """Exact volume of the box lo..hi below a triangulated height surface z = h(x, y) that covers the box's
    plan exactly once and stays within its height range: sum over triangles of plan area x (mean vertex height
    - lo_z) (the volume under a planar triangle is its plan area times its mean height). Raises ValueError when
    the surface does not meet these conditions."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    tol = 1e-9 * float(np.max(hi - lo))
    if np.any(v < lo - tol) or np.any(v > hi + tol):
        raise ValueError("the excavation surface leaves the domain box (its vertices must lie inside it)")
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    plan = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    area = np.abs(plan)
    box = (hi[0] - lo[0]) * (hi[1] - lo[1])
    if abs(area.sum() - box) > 1e-9 * box or abs(abs(plan.sum()) - box) > 1e-9 * box:
        raise ValueError("the excavation surface must cover the domain's plan exactly once (a height surface)")
    return float(np.sum(area * ((a[:, 2] + b[:, 2] + c[:, 2]) / 3.0 - lo[2])))


SGIM_VOLUME_RESULTS = ("spheres", "kept_volume", "exact_volume", "error_volume", "excavate_s")


def _warm_volume(scene):
    from sgim.excavate import FacetSet, kept_sites
    from sgim.packing import make_lattice

    lo = scene.domain.min
    r0 = float(np.max(scene.domain.max - lo)) / 8
    kept_sites(make_lattice(scene.packing.kind, lo, scene.domain.max, r0), FacetSet(scene.excavations), lo,
               scene.domain.max)
    _WARM.add("sgim-volume")


def warm_sgim_volume(scene_path):
    """Compile the excavation kernels on a coarse lattice of the scene."""
    from sgim.scene import load_scene

    scene = load_scene(scene_path)
    if scene.packing.kind != "random" and len(scene.excavations) == 1:
        _warm_volume(scene)


def sgim_volume(scene_path, case_dir, params):
    """Excavation volume: the lattice sites an sgim scene keeps below its one excavation surface (a height
    surface over the whole domain plan), each standing for its share of the domain volume (domain volume /
    lattice sites: exact for a cubic lattice that fills the box), against the exact volume below the surface
    (:func:`volume_below_surface`); error_volume = kept / exact - 1."""
    from sgim.excavate import FacetSet, kept_sites
    from sgim.limits import check_build
    from sgim.packing import lattice_for
    from sgim.scene import SceneError, load_scene

    scene = load_scene(scene_path)
    if scene.packing.kind == "random" or len(scene.excavations) != 1 or scene.cavities:
        raise SceneError(scene_path, "excavation", len(scene.excavations), "sgim-volume needs a lattice packing "
                         "and exactly one excavation surface (no cavities)")
    check_build(scene)  # the sphere and memory limits of sgim build (sgim/limits.py), before the lattice
    surf = scene.excavations[0]
    try:
        exact = volume_below_surface(surf.vertices, surf.faces, scene.domain.min, scene.domain.max)
    except ValueError as exc:
        raise SceneError(scene_path, "excavation[0]", surf.name, str(exc)) from None
    if "sgim-volume" not in _WARM:  # compile the kernels outside the timed part
        _warm_volume(scene)
    t0 = time.perf_counter()
    lat = lattice_for(scene)
    kept = kept_sites(lat, FacetSet(scene.excavations), scene.domain.min, scene.domain.max)
    excavate_s = time.perf_counter() - t0
    box = float(np.prod(scene.domain.max - scene.domain.min))
    vol = len(kept) * box / lat.n_sites
    return dict(spheres=int(len(kept)), kept_volume=vol, exact_volume=exact, error_volume=vol / exact - 1.0,
                excavate_s=excavate_s)


# ---------------------------------------------------------------------------------------------------------
# dda-run

DDA_RESULTS = ("displacement", "moved", "error_energy", "steps", "dt", "dt_ratio", "reference", "error_disp", "run_s")
TRACK_NAMES = ("block", "wedge", "projectile", "column")


def energy_error(res):
    """max_t |balance error(t)| / max_t E_play(t), E_play = kinetic + |potential - potential(0)| + elastic
    (the mechanical energy in play: the energy balance error of a run relative to the energy it moved)."""
    from dda.results import ENERGY_COLUMNS

    e = res.energies
    if len(e) < 2:
        return NAN
    e = e[1:]
    col = {k: e[:, ENERGY_COLUMNS.index(k)] for k in ("kinetic", "potential", "elastic", "balance_error")}
    play = col["kinetic"] + np.abs(col["potential"] - col["potential"][0]) + col["elastic"]
    scale = float(np.nanmax(play))
    err = float(np.nanmax(np.abs(col["balance_error"])))
    return err / scale if scale > 0 else NAN


def _track(names, fixed, want=None):
    moving = [i for i, f in enumerate(fixed) if not f]
    if want:
        if want not in names:
            raise ValueError(f"track = {want!r}: no block of that name")
        return names.index(want)
    for nm in TRACK_NAMES:
        for i in moving:
            if names[i] == nm:
                return i
    if not moving:
        raise ValueError("the scene has no moving block to track")
    return moving[0]


def _reference(scene, sim, i):
    """(reference displacement, unit direction) of block i for the standard cases, or (None, None)."""
    data = tomllib.loads(scene.text) if scene.text else {}
    gens = [g for g in data.get("generate", []) or [] if isinstance(g, dict)]
    if len(gens) != 1 or data.get("block") or data.get("spheres") or scene.pair_laws or scene.loads:
        return None, None
    gt = gens[0]
    g = float(np.linalg.norm(scene.gravity))
    if not np.allclose(scene.gravity / max(g, 1e-300), (0.0, 0.0, -1.0)) or scene.law.cohesion > 0:
        return None, None
    t = sim.time
    tphi = math.tan(math.radians(scene.law.friction_deg))
    if gt.get("kind") == "incline" and scene.blocks[i].name == "block":
        a = math.radians(float(gt.get("angle", 30.0)))
        acc = g * (math.sin(a) - tphi * math.cos(a))
        return 0.5 * max(acc, 0.0) * t * t, np.array([math.cos(a), 0.0, -math.sin(a)])
    if gt.get("kind") == "wedge" and scene.blocks[i].name == "wedge":
        from dda import hoekbray

        hb = hoekbray.wedge_fs(orientation(gt.get("joint_a", (45.0, 5.0))),
                               orientation(gt.get("joint_b", (55.0, 135.0))),
                               orientation(gt.get("face", (65.0, 65.0))), top=orientation(gt.get("top", (0.0, 0.0))),
                               friction=scene.law.friction_deg, height=float(gt.get("height", 10.0)))
        if hb.mode != "both planes":
            return None, None
        o, p5 = hb.vertices[0], hb.vertices[1]
        line = (o - p5) / np.linalg.norm(o - p5)
        acc = g * math.sin(math.radians(hb.line_plunge)) * (1.0 - tphi / math.tan(math.radians(hb.critical_friction)))
        return 0.5 * max(acc, 0.0) * t * t, line
    return None, None


def _warm_dda(scene):
    _, warm = scene.build()
    warm.run(3 * warm.dt, record_every=warm.dt)
    _WARM.add("dda-run")


def warm_dda_run(scene_path):
    """Compile the DDA kernels on three steps of the scene."""
    from dda.scene import load_scene

    scene = load_scene(scene_path)
    if not scene.spheres:
        _warm_dda(scene)


def dda_run(scene_path, case_dir, params):
    """Run the DDA scene and measure the tracked block (see the module docstring)."""
    from dda.scene import load_scene

    scene = load_scene(scene_path)
    if scene.spheres:
        raise ValueError("dda-run runs block scenes; a scene with [spheres] goes to yade / liggghts or `dda run`")
    if "dda-run" not in _WARM:  # compile the kernels outside the timed run (a few steps of the same model)
        _warm_dda(scene)
    bs, sim = scene.build()
    names = list(sim.A.names)
    i = _track(names, sim.A.fixed, params.get("track") if isinstance(params.get("track"), str) else None)
    t0 = time.perf_counter()
    res = sim.run(scene.duration, record_every=scene.record_every)
    run_s = time.perf_counter() - t0
    d = sim.displacement(i)
    moving = np.flatnonzero(~sim.A.fixed)
    moved = int(sum(np.linalg.norm(sim.displacement(k)) > 0.01 * sim.size_b[k] for k in moving))
    ref, direction = _reference(scene, sim, i)
    out = dict(displacement=float(np.linalg.norm(d)), moved=moved, error_energy=energy_error(res),
               steps=int(sim.steps), dt=float(sim.dt), dt_ratio=float(sim.dt / sim.dt_crit), reference=NAN,
               error_disp=NAN, run_s=run_s)
    if ref is not None:
        along = float(d @ direction)
        out["reference"] = ref
        out["error_disp"] = along / ref - 1.0 if ref > 0 else float(np.linalg.norm(d)) / float(sim.size_b[i])
    return out


# ---------------------------------------------------------------------------------------------------------
# yade / liggghts

DECK_RESULTS = ("n", "detached", "reference_detached", "error_detached", "max_displacement", "mean_displacement",
                "bonds_broken", "steps", "engine_s")


def _sphere_results(sr, res):
    """Scalars of a sphere run: `sr` the SphereRun, `res` its RunResult (any engine)."""
    disp = np.linalg.norm(res.displacement(), axis=1)
    moved = disp > 0.5 * float(sr.radii.min())
    out = dict(n=int(res.n), detached=int(moved.sum()), reference_detached=NAN, error_detached=NAN,
               max_displacement=float(disp.max()) if len(disp) else 0.0,
               mean_displacement=float(disp.mean()) if len(disp) else 0.0,
               bonds_broken=int(len(res.bond_intact) - np.sum(res.bond_intact)), steps=int(res.steps),
               engine_s=float(res.wall_s))
    if np.any(sr.fixed):  # spheres that no bond path ties to a fixed sphere (cases/lib/crossval.py's reference)
        from cases.lib.crossval import detached_reference

        ref = detached_reference(sr)
        out["reference_detached"] = int(ref.sum())
        out["error_detached"] = float(np.sum(ref != moved)) / max(res.n, 1)
    return out


def _deck_evaluator(engine):
    def fn(scene_path, case_dir, params):
        from adapters.deck import export, run
        from adapters.spec import SphereRun

        deck = Path(case_dir) / engine
        export(scene_path, engine, deck)
        res = run(deck, out=deck / "result")
        if not res.complete:
            raise RuntimeError(f"{engine} run incomplete: {res.message.splitlines()[0] if res.message else '?'}")
        return _sphere_results(SphereRun.load(deck / "run.npz"), res)

    fn.__name__ = f"{engine}_deck"
    fn.__doc__ = f"Export the sphere scene to {engine} and run it (see the module docstring)."
    return fn


def dda_spheres(scene_path, case_dir, params):
    """Run a sphere scene in the in-house engine (adapters.inhouse), the same run the decks make."""
    from adapters.deck import load_source
    from adapters.inhouse import run_inhouse

    kind, sr, _ = load_source(scene_path)
    if kind != "spheres":
        raise ValueError("dda-spheres runs sphere scenes (a DDA scene with [spheres], an sgim scene or model)")
    res = run_inhouse(sr)
    if not res.complete:
        raise RuntimeError(f"in-house run incomplete: {res.message.splitlines()[0] if res.message else '?'}")
    return _sphere_results(sr, res)


def check_dda_scene(scene_path):
    """A DDA scene (dda.scene.load_scene) with no [spheres]: the base of dda-run studies."""
    from dda.scene import load_scene

    if load_scene(scene_path).spheres:
        raise ValueError("a scene with [spheres]: dda-run runs block scenes (use dda-spheres, yade or liggghts)")


def check_wedge_scene(scene_path):
    """A DDA scene with a [[generate]] wedge (wedge-hb, wedge-dda)."""
    from dda.scene import load_scene

    load_scene(scene_path)
    wedge_inputs(scene_path)


def check_sgim_scene(scene_path):
    from sgim.scene import load_scene

    load_scene(scene_path)


def check_sphere_scene(scene_path):
    from adapters.deck import load_source

    kind = load_source(scene_path)[0]
    if kind != "spheres":
        raise ValueError("not a sphere scene (a DDA scene with [spheres], an sgim scene or model)")


U_WEDGE = {"fs": "-", "phi_crit": "deg", "plunge": "deg", "trend": "deg", "volume": "m^3", "wedge": "-",
           "two_planes": "-"}
U_WEDGE_DDA = {"fs_dda": "-", "phi_crit_dda": "deg", "fs_hb": "-", "phi_crit_hb": "deg", "error_fs": "relative",
               "error_phi": "relative", "wedge": "-", "trials": "count", "steps_per_trial": "count", "run_s": "s"}
U_SGIM = {"spheres": "count", "red": "count", "green": "count", "blue": "count", "red_fraction": "-",
          "fractures": "count", "bonded": "count", "packing_density": "-", "detached_clusters": "count",
          "detached_spheres": "count", "largest_detached": "spheres", "build_s": "s"}
U_VOLUME = {"spheres": "count", "kept_volume": "m^3", "exact_volume": "m^3", "error_volume": "relative",
            "excavate_s": "s"}
U_DDA = {"displacement": "m", "moved": "blocks", "error_energy": "relative", "steps": "count", "dt": "s",
         "dt_ratio": "-", "reference": "m", "error_disp": "relative", "run_s": "s"}
U_DECK = {"n": "spheres", "detached": "spheres", "reference_detached": "spheres", "error_detached": "fraction",
          "max_displacement": "m", "mean_displacement": "m", "bonds_broken": "bonds", "steps": "count",
          "engine_s": "s"}

EVALUATORS = {
    "wedge-hb": Evaluator(wedge_hb, (), "Hoek & Bray factor of safety of a wedge scene (analytical)",
                          WEDGE_HB_RESULTS, U_WEDGE, check_wedge_scene),
    "wedge-dda": Evaluator(wedge_dda, (), "DDA critical friction and factor of safety of a wedge scene, with "
                           "Hoek & Bray in the same row", WEDGE_DDA_RESULTS, U_WEDGE_DDA, check_wedge_scene,
                           warm_wedge_dda),
    "sgim-build": Evaluator(sgim_build, (), "build an sgim scene: colours, packing density, detached clusters",
                            SGIM_RESULTS, U_SGIM, check_sgim_scene),
    "sgim-volume": Evaluator(sgim_volume, (), "excavation volume: lattice sites kept below one excavation "
                             "surface against the exact volume", SGIM_VOLUME_RESULTS, U_VOLUME, check_sgim_scene,
                             warm_sgim_volume),
    "dda-run": Evaluator(dda_run, (), "run a DDA block scene: tracked displacement, moved blocks, energy "
                         "balance, error against the analytical reference of a standard case", DDA_RESULTS, U_DDA,
                         check_dda_scene, warm_dda_run),
    "dda-spheres": Evaluator(dda_spheres, (), "run a sphere scene in the in-house engine (adapters.inhouse)",
                             DECK_RESULTS, U_DECK, check_sphere_scene),
    "yade": Evaluator(_deck_evaluator("yade"), ("yade",), "run a sphere scene in YADE (adapters.deck)",
                      DECK_RESULTS, U_DECK, check_sphere_scene),
    "liggghts": Evaluator(_deck_evaluator("liggghts"), ("liggghts",), "run a sphere scene in LIGGGHTS "
                          "(adapters.deck)", DECK_RESULTS, U_DECK, check_sphere_scene),
}


# ---------------------------------------------------------------------------------------------------------
# the registry: the framework's own evaluators, the ones above, and "module:function" of a user


def _work(scene_path):
    with open(scene_path, "rb") as fh:
        return tomllib.load(fh).get("work", {})


def _noop(scene_path, case_dir, params):
    """Reads the scene, returns the sum of the numeric parameters (framework overhead)."""
    _work(scene_path)
    total = 0.0
    for v in params.values():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            total += v
    return {"value": total}


def _sleep(scene_path, case_dir, params):
    """Sleeps [work] seconds."""
    s = float(_work(scene_path).get("seconds", 0.1))
    time.sleep(s)
    return {"value": s}


def _spin(scene_path, case_dir, params):
    """A fixed single-core numpy workload: [work] iterations x size elementwise steps (deterministic)."""
    w = _work(scene_path)
    n, size = int(w.get("iterations", 200)), int(w.get("size", 100_000))
    x = np.linspace(0.0, 1.0, size) + float(w.get("offset", 0.0))
    for _ in range(n):
        x = np.sin(x) * 0.999 + 0.01 * np.cos(3.0 * x)
    return {"value": float(x.sum())}


BUILTIN = {
    "noop": Evaluator(_noop, (), "no work: framework overhead", ("value",), check=_work),
    "sleep": Evaluator(_sleep, (), "sleeps [work] seconds", ("value",), {"value": "s"}, _work),
    "spin": Evaluator(_spin, (), "fixed CPU workload ([work] iterations, size): scaling benchmark", ("value",),
                      check=_work),
}


def registry():
    """Every evaluator a study can name without a module: the framework's (noop, sleep, spin) and EVALUATORS."""
    return {**BUILTIN, **EVALUATORS}


def _as_evaluator(obj):
    if isinstance(obj, Evaluator):
        return obj
    if callable(obj) and not hasattr(obj, "fn"):
        return Evaluator(obj, units=dict(getattr(obj, "units", {}) or {}), check=getattr(obj, "check", None),
                         warm=getattr(obj, "warm", None))
    return Evaluator(obj.fn, tuple(getattr(obj, "needs", ()) or ()), getattr(obj, "description", ""),
                     tuple(getattr(obj, "results", ()) or ()), dict(getattr(obj, "units", {}) or {}),
                     getattr(obj, "check", None), getattr(obj, "warm", None))


def _one_line(exc):
    if isinstance(exc, SyntaxError):
        where = f"{Path(exc.filename).name}:{exc.lineno}" if exc.filename else f"line {exc.lineno}"
        return f"SyntaxError at {where}: {exc.msg}"
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def resolve_evaluator(name, study_dir=None):
    """The Evaluator for `name`: a registry name or "module:function" (study_dir first on the import path).
    Raises LookupError with a one-line reason for an unknown name, a module that cannot be imported (missing,
    a syntax error, an exception while it runs) and a name that is not a function."""
    if ":" in name:
        mod_name, _, attr = name.partition(":")
        if not mod_name or not attr:
            raise LookupError("must be 'module:function'")
        if study_dir is not None and str(study_dir) not in sys.path:
            sys.path.insert(0, str(study_dir))
        here = _study_module_file(mod_name, study_dir)
        old = sys.modules.get(mod_name)
        if here is not None and old is not None and getattr(old, "__file__", None) != str(here):
            del sys.modules[mod_name]  # a module of that name from another study's folder: this study's own
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as exc:
            raise LookupError(f"cannot import module {mod_name!r} ({exc})") from None
        except BaseException as exc:  # noqa: BLE001 - a user's module: any failure is one line
            if isinstance(exc, KeyboardInterrupt):
                raise
            raise LookupError(f"module {mod_name!r} fails on import: {_one_line(exc)}") from None
        if not hasattr(mod, attr):
            raise LookupError(f"module {mod_name!r} has no {attr!r}")
        obj = getattr(mod, attr)
        fn = getattr(obj, "fn", obj)
        if not callable(fn) or isinstance(fn, type):
            raise LookupError(f"{mod_name}.{attr} is a {type(fn).__name__}, not a function "
                              "fn(scene_path, case_dir, params)")
        return _as_evaluator(obj)
    reg = registry()
    if name not in reg:
        raise LookupError(f"unknown evaluator (known: {', '.join(sorted(reg))}; or 'module:function')")
    return reg[name]


def _study_module_file(mod_name, study_dir):
    """The file of top-level module `mod_name` in the study's folder (None when it is not there)."""
    if study_dir is None or "." in mod_name:
        return None
    try:
        spec = PathFinder.find_spec(mod_name, [str(study_dir)])
    except (ImportError, ValueError):
        return None
    return Path(spec.origin) if spec is not None and spec.origin and spec.has_location else None


def module_file(ev):
    """The source file of an evaluator's function (None when it has none)."""
    try:
        f = inspect.getsourcefile(ev.fn)
    except TypeError:
        return None
    return Path(f) if f else None


__all__ = ["Evaluator", "EVALUATORS", "BUILTIN", "registry", "resolve_evaluator", "module_file", "detached_clusters", "energy_error", "orientation", "wedge_inputs",
           "volume_below_surface", "wedge_hb", "wedge_dda", "sgim_build", "sgim_volume", "dda_run", "dda_spheres"]
