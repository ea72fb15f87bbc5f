"""``dda run`` of an sgim scene: its block model (dda/geoblocks.py) run under gravity by the block engine.

    from dda.georun import load_geo_scene
    from dda.runner import run
    outcome = run(load_geo_scene("cases/scenes/open_pit_blocks.toml"), "out/pit")   # or run("....toml", ...)

``dda run SCENE.toml`` takes an sgim scene (a file with ``[domain]``) as it takes a DDA scene: the scene is cut
into blocks, the blocks with a face on the domain's sides or bottom are fixed (the model's boundary, ``[blocks.run] fixed``; the top is
the ground; with ``[blocks.run] free_within`` the blocks farther than that from the free surfaces are fixed too, the
far field), and the others move under gravity with the run settings of ``[blocks.run]`` (duration required),
sleeping when at rest (``[blocks.run] sleep``, default true: a resting block is neither integrated nor searched
for contacts). The outputs are those of a DDA block run (dda/runner.py) plus ``blocks_moved`` in summary.json.

Contact laws by face kind (dda/_kinds.py). The law table gets one row per law: ``law:intact`` (``[blocks]``
cohesion, tensile, friction: a cemented contact present at the start, which breaks for good when its strength is
passed), ``law:NAME`` for every joint set, disc, DFN set, triangulated discontinuity and fault that made a face
(its ``[[blocks.law]]``, else the joint law of ``[blocks]``). A face made by a joint set plane or an intact split
has its row over the whole face; a face made by a disc (a triangle) has its row inside the disc (the triangle)
and the intact row outside; domain and excavation faces have none (two blocks meeting there later take the
blocks' material law: ``[blocks]`` friction, no cohesion). kn, ks and damping are ``[blocks]``'s unless a law
gives its own kn, ks.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from sgim.blocktable import DEFAULTS as BLOCK_DEFAULTS
from sgim.common import SceneError
from sgim.grading import NearObjects
from sgim.reader import read_toml
from sgim.scene import load_scene as load_sgim_scene

from .blockcut import face_planes
from .contactlaw import ContactLaw
from .geoblocks import DOMAIN, EXCAVATION, INTACT, build_blocks, default_spec, stage_line
from .keyblocks import key_blocks
from .limits import check_block_run
from .polyhedra import PolyhedronError, check_convex
from .shapes import GeometryError, convex_hull
from .polyhedra import face_planes as poly_planes
from .scene import OUTPUT_FORMATS, DDAScene, Material
from .simulation import Simulation, block_dt_bounds
from .system import quat_to_matrix

INTACT_ROW = "law:intact"
SHAPES = {"plane": 0, "surface": 0, "disc": 1, "triangle": 2}


def is_sgim_scene(path):
    """True when the TOML file `path` is an sgim scene (it has a [domain] table and no [simulation])."""
    data, _ = read_toml(path)
    return "domain" in data and "simulation" not in data


def _law_name(model, src, spec):
    """The [[blocks.law]] name that applies to source `src`: its own name, or the set of a DFN fracture id."""
    name = model.sources[src].name
    if name in spec.laws:
        return name
    base = name.rsplit("-", 1)[0]
    return base if base in spec.laws else name


def _contact_law(spec, law):
    kn = law.kn if law.kn is not None else spec.kn
    ks = law.ks if law.ks is not None else (spec.ks if spec.ks is not None and law.kn is None else kn / 2)
    return ContactLaw(kn=kn, ks=ks, friction_deg=law.friction, cohesion=law.cohesion, tensile=law.tensile,
                      damping=spec.damping)


class GeoScene(DDAScene):
    """A DDAScene made from an sgim scene's block model; ``build()`` gives the Simulation its face kinds."""

    model = None
    spec = None
    face_src = None  # per block, its faces' sources (the model's; a hulled block's matched by plane)
    left_out = (0, 0.0)  # (blocks, m3) left out of the run: needles the engine's convexity check refuses even as hulls
    small = None  # per block: below [blocks] min_volume and free (its inertia scaled, scale_small_blocks)
    small_scaled = (0, 1.0)  # (blocks whose inertia was scaled, the largest factor)
    far_fixed = 0  # blocks fixed as the far field: farther than [blocks.run] free_within from the free surfaces
    hulled = 0  # blocks replaced by their convex hull (not convex within the engine's tolerance after snapping)
    # the keys the step limit's message names (dda/limits.py): the run settings are [blocks.run]'s, and an sgim
    # scene has no max_steps key (only --max-steps raises the limit)
    run_keys = {"duration": "blocks.run.duration", "dt": "blocks.run.dt", "raise_limit": "raise --max-steps"}

    def stiffness_keys(self):
        """[(key, kn)] of the stiffnesses in the run: [blocks] kn and every [[blocks.law]] kn of a law that made a
        face (dda/limits.py names the largest when it sets a time step past the step limit)."""
        rows = self.law_rows()
        out = [("blocks.kn", float(self.spec.kn))]
        for k, (name, law) in enumerate(self.spec.laws.items()):
            if law.kn is not None and f"law:{name}" in rows:
                out.append((f"blocks.law[{k}].kn", float(law.kn)))
        return out

    def law_rows(self):
        """{row name: ContactLaw}: the intact row and one per law name that made a face."""
        sp = self.spec
        rows = {INTACT_ROW: ContactLaw(kn=sp.kn, ks=sp.ks, friction_deg=sp.friction, cohesion=sp.cohesion,
                                       tensile=sp.tensile, damping=sp.damping)}
        for src in self.face_src:
            for s in set(np.asarray(src).tolist()):
                kind = self.model.sources[s].kind
                if kind in (DOMAIN, EXCAVATION, INTACT):
                    continue
                name = _law_name(self.model, s, sp)
                rows.setdefault(f"law:{name}", _contact_law(sp, sp.law_of(name)))
        return rows

    def face_laws(self, bs, names):
        """(face_row, face_shape, face_geo, intact_row) of the system's faces (dda/_kinds.py), the rows indexed
        in `names` (the law table's materials)."""
        A = bs.arrays()
        nf = int(A.face_start[-1])
        row = np.full(nf, -1, np.int64)
        shape = np.zeros(nf, np.int64)
        geo = np.zeros((nf, 9))
        intact = names.index(INTACT_ROW)
        for i, src_i in enumerate(self.face_src):
            R = quat_to_matrix(A.quat[i])
            f0 = int(A.face_start[i])
            for k, s in enumerate(np.asarray(src_i).tolist()):
                src = self.model.sources[s]
                if src.kind in (DOMAIN, EXCAVATION):
                    continue
                if src.kind == INTACT:
                    row[f0 + k] = intact
                    continue
                row[f0 + k] = names.index(f"law:{_law_name(self.model, s, self.spec)}")
                shape[f0 + k] = SHAPES[src.shape]
                if src.shape == "disc":
                    geo[f0 + k, :3] = (np.asarray(src.centre) - A.pos[i]) @ R
                    geo[f0 + k, 3:6] = np.asarray(src.normal) @ R
                    geo[f0 + k, 6] = src.radius
                elif src.shape == "triangle":
                    geo[f0 + k] = ((np.asarray(src.tri) - A.pos[i]) @ R).reshape(9)
        return row, shape, geo, intact

    def build(self, max_steps=None, duration=None, check=True):
        bs = self.block_system()
        rows = self.law_rows()
        for name in rows:
            if name not in bs.materials:
                bs.materials.append(name)
        pair_laws = dict(self.pair_laws)
        pair_laws.update({(n, n): law for n, law in rows.items()})
        face_laws = self.face_laws(bs, bs.materials)
        if self.small is not None and self.small.any():
            laws = [self.law, *pair_laws.values()]
            self.small_scaled = scale_small_blocks(bs.arrays(), self.small, max(law.kn for law in laws),
                                                   max(law.damping for law in laws), self.gravity)

        def step_check(sim):
            check_block_run(self, sim, max_steps=max_steps, duration=duration)

        sim = Simulation(bs, self.law, gravity=self.gravity, dt=self.dt, safety=self.safety,
                         local_damping=self.local_damping, pair_laws=pair_laws,
                         on_dt=step_check if check else None, face_laws=face_laws, **self.sleep)
        # touching faces of cut blocks meet at a gap of rounding size: the cemented (intact) contacts must be
        # found at the first step, so the kept gap is at least a millionth of the median block
        sim.keep_gap = max(sim.keep_gap, 1e-6 * sim.d50)
        sim.gap = max(sim.gap, 0.02 * sim.d50 + sim.keep_gap)
        self.key = None

        # faces with nothing across them: the excavations', cavities' and domain's
        free_face = np.concatenate([[self.model.sources[k].kind in (DOMAIN, EXCAVATION) for k in src]
                                    for src in self.face_src]) if self.face_src else np.zeros(0, bool)

        def screen(s):  # the key blocks, once the first step has found the cemented contacts (dda/keyblocks.py):
            # with the cement holding, and with it broken
            self.key = {"cemented": key_blocks(s, free_face), "uncemented": key_blocks(s, free_face, cemented=False)}

        sim.after_first_step = screen
        return bs, sim

    def run_summary(self, sim, moved=None):
        """blocks_moved: free blocks displaced by more than `moved` (default a hundredth of the median block);
        key_blocks: the clusters that could not stand at the first step (dda/keyblocks.py) with the cement holding
        ("cemented") and with every block on its own ("uncemented"), their blocks and volume, how many of their
        blocks moved and how many other blocks moved; the run's cost: block-steps integrated (the
        awake blocks of each step) against every moving block at every step, and CPU time per integrated
        block-step."""
        moved = 0.01 * sim.d50 if moved is None else moved
        d = np.linalg.norm(sim.pos - sim.pos0, axis=1)
        free = ~np.asarray(sim.A.fixed, bool)
        key = None
        if getattr(self, "key", None) is not None:
            key = {}
            for name, kb in self.key.items():
                key[name] = kb.summary(sim.A.volume)
                is_key = np.zeros(len(d), bool)
                is_key[kb.blocks] = True
                key[name]["key_blocks_moved"] = int((is_key & (d > moved)).sum())
                key[name]["other_blocks_moved"] = int((free & ~is_key & (d > moved)).sum())
        cost = {"block_steps": sim.block_steps, "block_steps_all_awake": sim.steps * len(sim.movable),
                "cpu_s": round(sim.cpu_s, 3),
                "cpu_us_per_block_step": round(1e6 * sim.cpu_s / sim.block_steps, 2) if sim.block_steps else None}
        return {"blocks_moved": int((d[free] > moved).sum()), "moved_threshold_m": moved, "key_blocks": key,
                "cost": cost,
                "fixed_blocks": int((~free).sum()), "max_displacement_m": float(d[free].max()) if free.any() else 0.0,
                "blocks_hulled": self.hulled, "small_blocks_scaled": self.small_scaled[0],
                "small_blocks_largest_scale": self.small_scaled[1],
                "far_blocks_fixed": self.far_fixed, "blocks_left_out": self.left_out[0],
                "volume_left_out_m3": self.left_out[1],
                "cut": {k: v for k, v in self.model.summary().items() if k != "seconds"}}


def scale_small_blocks(A, small, kn, zeta, gravity):
    """Mass scaling of the small free blocks (flags `small`) of the system arrays A, in place: each block's mass
    and inertia times f = (dt_0 / dt_i)^2, where dt_i is its own stable step (block_dt_bounds, contact springs
    kn, damping ratio zeta) and dt_0 the smallest of the other free blocks', so that it no longer sets the time
    step; a body force (1 - f) m g keeps its weight m g. Such a block answers forces f times more slowly (alone
    it would fall at g / f); joined to its neighbours by intact rock it adds at most about the critical block's
    inertia to theirs. Returns (blocks scaled, the largest factor)."""
    small = np.asarray(small, bool)
    free = np.flatnonzero(~np.asarray(A.fixed, bool) & ~small)
    tiny = np.flatnonzero(small & ~np.asarray(A.fixed, bool))
    if len(tiny) == 0 or len(free) == 0:
        return 0, 1.0
    dt0 = float(np.minimum(*block_dt_bounds(A, free, kn, zeta)).min())
    dt = np.minimum(*block_dt_bounds(A, tiny, kn, zeta))
    f = np.maximum((dt0 / dt) ** 2, 1.0)
    g = np.asarray(gravity, float)
    A.bforce[tiny] += (1.0 - f)[:, None] * A.mass[tiny, None] * g
    A.mass[tiny] *= f
    A.inertia[tiny] *= f[:, None]
    return int((f > 1.0).sum()), float(f.max())


def boundary_fixed(model, sides=("x-", "x+", "y-", "y+", "z-")):
    """Per block: True when it has a face on one of the domain's faces `sides` ("x-": outward normal -x, ...)."""
    want = np.array([[(1.0 if s[1] == "+" else -1.0) * (a == "xyz".index(s[0])) for a in range(3)] for s in sides])
    out = np.zeros(len(model.blocks), bool)
    for i, b in enumerate(model.blocks):
        dom = np.array([model.sources[s].kind == DOMAIN for s in b.src])
        if dom.any() and len(want):
            n, _ = face_planes(b)
            out[i] = bool(((n[dom] @ want.T) > 1 - 1e-9).any())
    return out


def far_field(scene, model, names, within):
    """Per block: True when no point of it comes within `within` of the scene's [[excavation]] and [[cavity]]
    surfaces `names` (its bounding sphere about the vertices' centre stays farther): the far field that
    [blocks.run] free_within fixes, as a model's boundary is fixed, so that only the rock near the free surfaces
    moves and costs time steps."""
    centre = np.array([b.v.mean(0) for b in model.blocks]).reshape(-1, 3)
    radius = np.array([np.sqrt(((b.v - c) ** 2).sum(1).max()) for b, c in zip(model.blocks, centre)])
    near = NearObjects(scene, SimpleNamespace(near=list(names)))
    dist = near.distance(centre, float(within + radius.max()) * 1.01 + 1.0)
    return dist - radius > within


def _snap_convex(spec, rel=3e-10, rounds=60):
    """Move each vertex of `spec` that lies in front of a face plane back onto it (the cutter's blocks are convex
    within about 1e-9 of their size, the engine checks 1e-9: dda.polyhedra.check_convex); True when the block then
    passes that check. The face order, and so the faces' sources, stay as they are."""
    v = np.asarray(spec.vertices, float).copy()
    size = float(np.max(np.ptp(v, axis=0))) or 1.0
    for _ in range(rounds):
        n, d = poly_planes(v, spec.faces)
        dist = v @ n.T - d
        if dist.max() <= rel * size:
            spec.vertices = v
            return True
        v -= np.clip(dist, 0.0, None) @ n
    try:
        check_convex(v, spec.faces)
    except PolyhedronError:
        return False
    spec.vertices = v
    return True


def _hull_of(spec, block, path, k):
    """(spec, face sources) of the convex hull of a block that snapping left non-convex (a sliver of an exact
    excavation, e.g. 2e-5 m3 in the open pit): each hull face takes the source of the block's face whose plane is
    nearest (its normal's direction first)."""
    try:
        h = convex_hull(spec.vertices, tol=1e-13, name=spec.name, material=spec.material, fixed=spec.fixed)
    except GeometryError as exc:
        raise SceneError(path, "blocks", f"block {k}", f"a cut block is not convex and has no hull ({exc})") \
            from None
    h.faces = [[f[0], f[j], f[j + 1]] for f in h.faces for j in range(1, len(f) - 1)]  # exact facet planes
    n0, d0 = poly_planes(np.asarray(spec.vertices, float), spec.faces)
    n1, d1 = poly_planes(np.asarray(h.vertices, float), h.faces)
    match = np.argmax(n1 @ n0.T - 1e-3 * np.abs(d1[:, None] - d0[None, :]), axis=1)
    return h, np.asarray(block.src)[match]


def geo_scene(scene, model=None, progress=None, path=None, fixed=None) -> GeoScene:
    """The GeoScene of an sgim Scene (sgim.scene.load_scene): its block model (built unless `model` is given),
    the boundary blocks fixed (or the blocks flagged in `fixed`), [blocks.run] as the run settings."""
    spec = scene.blocks if getattr(scene, "blocks", None) is not None else default_spec(scene)
    path = path or getattr(scene, "path", "<scene>")
    run = spec.run
    if run.get("duration") is None:
        raise SceneError(path, "blocks.run.duration", None, "missing value: dda run of an sgim scene runs its "
                                                            "block model for [blocks.run] duration (s)")
    model = model if model is not None else build_blocks(scene, progress=progress)
    fix = boundary_fixed(model, run["fixed"]) if fixed is None else np.asarray(fixed, bool)
    far = np.zeros(len(fix), bool)
    if fixed is None and run.get("free_within") is not None:
        far = far_field(scene, model, run["free_near"], run["free_within"]) & ~fix
    fix = fix | far
    # blocks below [blocks] min_volume that no neighbour could take (pieces of the exact excavation, down to
    # 1e-5 m3 in the open pit) would set the time step (1e-9 s in the open pit): their inertia is scaled up
    # in build() (scale_small_blocks), their weight kept
    small = (model.volumes() < spec.min_volume) & ~fix
    specs = model.specs()
    face_src = [b.src for b in model.blocks]
    hulled, left_out = 0, []
    for k, (s, f) in enumerate(zip(specs, fix)):
        s.fixed = bool(f)
        if not _snap_convex(s):
            specs[k], face_src[k] = _hull_of(s, model.blocks[k], path, k)
            hulled += 1
            try:
                check_convex(specs[k].vertices, specs[k].faces)
            except PolyhedronError:  # a needle below the engine's convexity tolerance even as a hull
                left_out.append(k)
    if left_out:  # said in the summary (blocks_left_out, their volume), never silently
        keep = np.setdiff1d(np.arange(len(specs)), left_out)
        lost = float(sum(model.blocks[k].volume() for k in left_out))
        specs, face_src, fix, small = [specs[k] for k in keep], [face_src[k] for k in keep], fix[keep], small[keep]
    if fix.all():
        raise SceneError(path, "blocks.run.fixed", run["fixed"], "every block of the block model has a face on "
                                                                  "these domain faces: nothing would move")
    materials = {m: Material(m, spec.density) for m in {s.material for s in specs}}
    duration = run["duration"]
    gs = GeoScene(path=path, text="", name=getattr(scene, "name", "blocks"), blocks=specs, materials=materials,
                  law=ContactLaw(kn=spec.kn, ks=spec.ks, friction_deg=spec.friction, damping=spec.damping),
                  pair_laws={}, duration=duration, dt=run["dt"], safety=run["safety"],
                  gravity=np.asarray(run["gravity"], float), local_damping=run["local_damping"],
                  record_every=run["record_every"] or duration / 100, frames=run["frames"],
                  formats=OUTPUT_FORMATS, sources=["blocks"] * len(specs), sleep={"sleep": run["sleep"]})
    gs.model, gs.spec, gs.face_src, gs.hulled = model, spec, face_src, hulled
    gs.left_out = (len(left_out), lost if left_out else 0.0)
    gs.small = small
    gs.far_fixed = int(far.sum())
    return gs


def load_geo_scene(path, progress=None) -> GeoScene:
    """The GeoScene of the sgim scene file `path` (SceneError on a bad scene, before anything is cut);
    `progress(line)` receives a line per cutting stage."""
    scene = load_sgim_scene(path)
    say = None if progress is None else (lambda *a: progress("cut        " + stage_line(*a)))
    return geo_scene(scene, progress=say, path=path)


__all__ = ["GeoScene", "INTACT_ROW", "boundary_fixed", "far_field", "geo_scene", "is_sgim_scene", "load_geo_scene"]
