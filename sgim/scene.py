"""Scene files (TOML): parsing and validation.

Every problem found in a scene raises :class:`SceneError` whose message is one
line naming the file, the key path and the offending value.  Nothing in this
module writes files; validation is complete before any output is created.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import shapes
from .blocktable import read_blocks
from .common import SceneError  # noqa: F401  (also the scene API's name: sgim.scene.SceneError)
from .geometry import MeshError, dip_to_normal, facet_degeneracies, load_mesh_file, triangulate_plan
from .packing import lattice_counts
from .portable import norm
from .reader import COORD, LENGTH, SIZE, SceneReader, read_toml
from .shapes import ShapeError

# The readers of random packings (sgim/rpack.py), fracture networks (sgim/dfn.py), cavities and triangulated
# surfaces (sgim/meshquery.py) are imported inside the functions that need them: their numba kernels load only
# for the scenes that use them (a lattice scene, and `sgim build`'s refusals, stay fast).


PACKING_KINDS = ("cubic", "hexagonal", "fcc", "random")  # random: sgim/rpack.py
EXCAVATION_RULES = ("paper", "exact")
BOND_RULES = ("colour", "geometric")
OUTPUT_FORMATS = ("npz", "vtu", "txt", "png")

# The defaults of the optional keys this module reads, in one table (key path -> value; docs/scenes.md lists
# them with every other key, sgim/scenedoc.py). The tables of random packings, grading and fracture networks
# are read, with their defaults, by sgim/rpack.py, sgim/grading.py and sgim/dfn.py.
DEFAULTS = {
    "packing.kind": "cubic",
    "excavation[].rule": "paper",
    "discontinuity[].thickness": 0.0,  # m: a joint (> 0: a fault)
    "cavity[].segments": 48,  # facets around a swept or ellipsoid cavity (a box has its own 12 triangles)
    "bonds.rule": "colour",
    "bonds.tolerance": 1e-3,  # relative to ri + rj
    "output.formats": ("npz", "vtu", "png"),  # npz is always written; the PFC-style text ("txt") when asked for
    "render.hide_intact": False,
    "render.translucent": False,
    "render.cut_away": (),
    "render.width": 1600,  # pixels
    "render.height": 1100,  # pixels
}


@dataclass
class Domain:
    min: np.ndarray
    max: np.ndarray


@dataclass
class Packing:
    kind: str
    radius: float  # random packing: the largest radius
    random: object = None  # sgim.rpack.RandomSpec when kind == "random"


@dataclass
class Surface:
    """A triangulated excavating surface."""

    name: str
    vertices: np.ndarray  # (nv, 3) float64
    faces: np.ndarray  # (nf, 3) int64
    rule: str
    key: str  # key path in the scene, for messages


@dataclass
class Disc:
    """A disc discontinuity (joint when thickness == 0, fault otherwise)."""

    name: str
    centre: np.ndarray  # (3,)
    normal: np.ndarray  # (3,) unit
    radius: float
    thickness: float


@dataclass
class Bonds:
    rule: str = DEFAULTS["bonds.rule"]
    tolerance: float = DEFAULTS["bonds.tolerance"]  # relative to ri + rj


@dataclass
class Render:
    hide_intact: bool = DEFAULTS["render.hide_intact"]
    translucent: bool = DEFAULTS["render.translucent"]
    cut_away: list = field(default_factory=list)  # ["x>0", ...]
    width: int = DEFAULTS["render.width"]
    height: int = DEFAULTS["render.height"]


@dataclass
class Scene:
    path: Path
    text: str
    name: str
    domain: Domain
    packing: Packing
    excavations: list
    discontinuities: list
    bonds: Bonds
    formats: tuple
    render: Render
    dfn: object = None  # sgim.dfn.DfnSpec when the scene names joint sets or a network file
    cavities: list = field(default_factory=list)  # sgim.cavities.Cavity, from [[cavity]]
    surfaces: list = field(default_factory=list)  # SurfaceDiscontinuity; indices follow every disc
    limits: dict = field(default_factory=dict)  # [limits]: max_spheres (sgim/limits.py)
    blocks: object = None  # sgim.blocktable.BlocksSpec from [blocks] (the block model, dda/geoblocks.py)

    @property
    def n_lattice_sites(self) -> int:
        return lattice_counts(self.packing.kind, self.domain.min, self.domain.max, self.packing.radius)[0]


TOP_KEYS = {"name", "description", "domain", "packing", "excavation", "discontinuity", "bonds", "output", "render"}
TOP_KEYS |= {"dfn", "joint_set"}  # Monte-Carlo fracture network (sgim/dfn.py)
TOP_KEYS |= {"cavity"}  # inner excavations (sgim/cavities.py)
TOP_KEYS |= {"limits"}  # resource limits checked before the build (sgim/limits.py)
TOP_KEYS |= {"blocks"}  # the block model's own keys (sgim/blocktable.py), read and validated, unused by sgim build
LIMIT_KEYS = {"max_spheres"}


def read_limits(rd, data, allowed=LIMIT_KEYS):
    """The [limits] table: each key a positive integer (TOML integer or an integral float such as 1.2e7)."""
    lt = rd.table(data, "limits", "limits")
    rd.known(lt, allowed, "limits")
    out = {}
    for k, v in lt.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v) or v < 1:
            rd.err(f"limits.{k}", v, "must be a positive integer")
        out[k] = int(v)
    return out


def load_scene(path) -> Scene:
    """Read and validate a scene file; raise SceneError on any problem."""
    path = Path(path)
    data, text = read_toml(path)
    return scene_from_dict(data, path, text)


def scene_from_dict(data: dict, path="<scene>", text="", reader=None) -> Scene:
    """The validated Scene of a parsed scene file; `reader(path)` makes the value reader (default
    sgim.reader.SceneReader; sgim/scenedoc.py passes one that records what is read)."""
    path = Path(path)
    rd = (reader or SceneReader)(path)
    rd.known(data, TOP_KEYS, "")
    name = rd.string(data, "name", "name", path.stem)

    dom = rd.table(data, "domain", "domain", required=True)
    rd.known(dom, {"min", "max"}, "domain")
    lo = rd.vector(dom, "min", "domain.min", **COORD)
    hi = rd.vector(dom, "max", "domain.max", **COORD)
    for a in range(3):
        if hi[a] <= lo[a]:
            rd.err(f"domain.max[{a}]", float(hi[a]), f"must exceed domain.min[{a}] = {lo[a]:g} (empty or inverted box)")
    domain = Domain(lo, hi)

    pk = rd.table(data, "packing", "packing", required=True)
    if pk.get("kind") == "random":
        from .rpack import read_random

        spec, radius = read_random(rd, pk, domain, path)
        packing = Packing("random", radius, spec)
    else:
        rd.known(pk, {"kind", "radius"}, "packing")
        kind = rd.choice(pk, "kind", "packing.kind", PACKING_KINDS, DEFAULTS["packing.kind"])
        radius = rd.number(pk, "radius", "packing.radius", positive=True, **SIZE)
        if 2 * radius > float(np.min(hi - lo)):
            rd.err("packing.radius", radius, f"spheres of diameter {2 * radius:g} do not fit in the domain")
        packing = Packing(kind, radius)

    excavations = []
    exc_list = data.get("excavation", [])
    if not isinstance(exc_list, list):
        rd.err("excavation", exc_list, "must be an array of tables ([[excavation]])")
    for k, ex in enumerate(exc_list):
        excavations.append(_read_surface(rd, ex, f"excavation[{k}]", domain, path))

    discs = []
    d_list = data.get("discontinuity", [])
    if not isinstance(d_list, list):
        rd.err("discontinuity", d_list, "must be an array of tables ([[discontinuity]])")
    surfaces = []
    for k, dt in enumerate(d_list):
        if isinstance(dt, dict) and any(f in dt for f in SURFACE_FORMS):
            surfaces.append(_read_surface_discontinuity(rd, dt, f"discontinuity[{k}]", domain, radius, path))
            continue
        discs.append(_read_disc(rd, dt, f"discontinuity[{k}]", domain, radius))

    bt = rd.table(data, "bonds", "bonds")
    rd.known(bt, {"rule", "tolerance"}, "bonds")
    bonds = Bonds(
        rule=rd.choice(bt, "rule", "bonds.rule", BOND_RULES, DEFAULTS["bonds.rule"]),
        tolerance=rd.number(bt, "tolerance", "bonds.tolerance", default=DEFAULTS["bonds.tolerance"], nonneg=True,
                            hi=0.2),
    )

    ot = rd.table(data, "output", "output")
    rd.known(ot, {"formats"}, "output")
    formats = rd.value(ot, "formats", "output.formats", list(DEFAULTS["output.formats"]), "list of strings")
    if not isinstance(formats, list) or any(f not in OUTPUT_FORMATS for f in formats):
        rd.err("output.formats", formats, f"must be a list drawn from {', '.join(OUTPUT_FORMATS)}")
    if "npz" not in formats:
        formats = ["npz", *formats]

    rt = rd.table(data, "render", "render")
    rd.known(rt, {"hide_intact", "translucent", "cut_away", "width", "height"}, "render")
    cut = rd.value(rt, "cut_away", "render.cut_away", list(DEFAULTS["render.cut_away"]), "string or list of strings")
    if isinstance(cut, str):
        cut = [cut]
    if not isinstance(cut, list):
        rd.err("render.cut_away", cut, "must be a string like 'y>0' or a list of them")
    for c in cut:
        try:
            parse_cut(c)
        except ValueError as exc:
            rd.err("render.cut_away", c, str(exc))
    render = Render(
        hide_intact=rd.boolean(rt, "hide_intact", "render.hide_intact", DEFAULTS["render.hide_intact"]),
        translucent=rd.boolean(rt, "translucent", "render.translucent", DEFAULTS["render.translucent"]),
        cut_away=cut,
        width=int(rd.number(rt, "width", "render.width", default=DEFAULTS["render.width"], lo=64, hi=8000)),
        height=int(rd.number(rt, "height", "render.height", default=DEFAULTS["render.height"], lo=64, hi=8000)),
    )
    scene = Scene(path, text, name, domain, packing, excavations, discs, bonds, tuple(formats), render)
    scene.limits = read_limits(rd, data)
    if "dfn" in data or "joint_set" in data:
        from .dfn import read_dfn

        scene.dfn = read_dfn(rd, data, domain, path)
    scene.surfaces = surfaces
    cav_list = data.get("cavity", [])
    if not isinstance(cav_list, list):
        rd.err("cavity", cav_list, "must be an array of tables ([[cavity]])")
    scene.cavities = [_read_cavity(rd, ct, f"cavity[{k}]", domain, path) for k, ct in enumerate(cav_list)]
    scene.blocks = read_blocks(rd, data, scene)
    if packing.random is not None:  # grading names refer to everything above
        from .rpack import check_scene

        check_scene(rd, scene)
    return scene


def parse_cut(expr):
    """'x>0' / 'z<=40' -> (axis, sign, value): spheres with sign*(c[axis]-value) > 0 are cut away."""
    if not isinstance(expr, str):
        raise ValueError("must be a string like 'y>0'")
    e = expr.replace(" ", "").replace("=", "")
    if len(e) < 3 or e[0] not in "xyz" or e[1] not in "<>":
        raise ValueError("must look like 'x>0', 'y<10' or 'z>100'")
    try:
        value = float(e[2:])
    except ValueError:
        raise ValueError("must look like 'x>0', 'y<10' or 'z>100'") from None
    if not math.isfinite(value):
        raise ValueError("the value must be finite")
    return "xyz".index(e[0]), (1.0 if e[1] == ">" else -1.0), value


def _vertices_faces(rd, tab, key):
    """The `vertices` and `faces` of table `key` (faces required, every index a vertex's)."""
    if "faces" not in tab:
        rd.err(f"{key}.faces", None, "missing value (vertices need faces)")
    verts = rd.matrix(tab, "vertices", f"{key}.vertices", 3, **COORD)
    faces = rd.matrix(tab, "faces", f"{key}.faces", 3, integer=True)
    bad = np.nonzero((faces < 0) | (faces >= len(verts)))[0]
    if bad.size:
        i = int(bad[0])
        rd.err(f"{key}.faces[{i}]", faces[i].tolist(), f"vertex index out of range 0..{len(verts) - 1}")
    return verts, faces


def _read_surface(rd, ex, key, domain, scene_path):
    if not isinstance(ex, dict):
        rd.err(key, ex, "must be a table")
    rd.known(ex, {"name", "vertices", "faces", "points", "file", "rule"}, key)
    name = rd.string(ex, "name", f"{key}.name", key)
    rule = rd.choice(ex, "rule", f"{key}.rule", EXCAVATION_RULES, DEFAULTS["excavation[].rule"])
    forms = [f for f in ("vertices", "points", "file") if f in ex]
    if len(forms) != 1:
        rd.err(key, sorted(ex), "give exactly one of: vertices+faces, points, file")
    form = forms[0]
    if form == "vertices":
        verts, faces = _vertices_faces(rd, ex, key)
        face_key = f"{key}.faces"
    elif form == "points":
        if "faces" in ex:
            rd.err(f"{key}.faces", ex["faces"], "faces go with vertices, not with points")
        pts = rd.matrix(ex, "points", f"{key}.points", 3, **COORD)
        try:
            verts, faces = triangulate_plan(pts)
        except MeshError as exc:
            rd.err(f"{key}.points{exc.where}", exc.value, exc.message)
        face_key = f"{key}.points (triangle"
    else:
        if "faces" in ex:
            rd.err(f"{key}.faces", ex["faces"], "faces go with vertices, not with file")
        fname = rd.string(ex, "file", f"{key}.file", "")
        fpath = Path(fname)
        if not fpath.is_absolute():
            fpath = Path(scene_path).parent / fpath
        try:
            verts, faces = load_mesh_file(fpath)
        except MeshError as exc:
            rd.err(f"{key}.file", fname, exc.message)
        face_key = f"{key}.file {fname} (face"
    bad = facet_degeneracies(verts, faces)
    if bad.size:
        i = int(bad[0])
        where = f"{face_key}[{i}]" + (")" if "(" in face_key else "")
        rd.err(where, verts[faces[i]].tolist(), "facet points are repeated or collinear")
    vmin, vmax = verts.min(0), verts.max(0)
    if np.any(vmax[:2] < domain.min[:2]) or np.any(vmin[:2] > domain.max[:2]) or vmin[2] > domain.max[2] \
            or vmax[2] < domain.min[2]:
        rd.err(key, [vmin.tolist(), vmax.tolist()], "surface lies entirely outside the domain box")
    return Surface(name, verts, faces, rule, key)


def _read_disc(rd, dt, key, domain, r):
    if not isinstance(dt, dict):
        rd.err(key, dt, "must be a table")
    rd.known(dt, {"name", "centre", "center", "dip", "dip_direction", "normal", "radius", "thickness"}, key)
    name = rd.string(dt, "name", f"{key}.name", key)
    cname = "centre" if "centre" in dt or "center" not in dt else "center"
    centre = rd.vector(dt, cname, f"{key}.{cname}", **COORD)
    has_dip = "dip" in dt or "dip_direction" in dt
    if has_dip and "normal" in dt:
        rd.err(f"{key}.normal", dt["normal"], "give either dip + dip_direction or normal, not both")
    if "normal" in dt:
        n = rd.vector(dt, "normal", f"{key}.normal")
        n = n / max(float(np.abs(n).max()), 1e-300)  # a direction: scaled first, so that its length cannot overflow
        length = norm(n)
        if not length > 1e-12 * max(1.0, float(np.abs(n).max())):
            rd.err(f"{key}.normal", n.tolist(), "normal must not be the zero vector")
        normal = n / length
    else:
        dip = rd.number(dt, "dip", f"{key}.dip", lo=0.0, hi=90.0)
        dd = rd.number(dt, "dip_direction", f"{key}.dip_direction", lo=0.0, hi=360.0)
        normal = dip_to_normal(dip, dd)
    radius = rd.number(dt, "radius", f"{key}.radius", positive=True, **SIZE)
    thick = rd.number(dt, "thickness", f"{key}.thickness", default=DEFAULTS["discontinuity[].thickness"], nonneg=True,
                      **LENGTH)
    band = max(thick / 2, 2 * r) + radius
    if np.any(centre + band < domain.min) or np.any(centre - band > domain.max):
        rd.err(f"{key}.centre", centre.tolist(), "discontinuity lies entirely outside the domain box")
    return Disc(name, centre, normal, radius, thick)


# --------------------------------------------------------------------------
# triangulated surfaces: cavities ([[cavity]]) and surface discontinuities

SURFACE_FORMS = ("file", "vertices", "shape")
_CAVITY_SHAPE_KEYS = {
    "circular_tunnel": {"path", "radius", "segments"},
    "horseshoe_tunnel": {"path", "width", "height", "segments"},
    "ellipsoid": {"centre", "center", "radii", "radius", "segments"},
    "box": {"min", "max"},
}
_SURFACE_SHAPE_KEYS = {
    "listric": {"trace", "dip_direction", "dip_top", "dip_bottom", "depth", "length", "resolution"},
}


@dataclass
class SurfaceDiscontinuity:
    """A triangulated discontinuity: fault (thickness > 0, red inside |signed distance| <= t/2)
    or joint (green / blue by side within 2r).  The mesh's normals point upward on average."""

    name: str
    mesh: object  # sgim.meshquery.TriMesh
    thickness: float
    key: str
    source: str
    params: dict = field(default_factory=dict)


def _mesh_from_table(rd, tab, key, scene_path, shape_keys, build_shape):
    """Vertices and faces from exactly one of: shape (+ its keys), file, vertices + faces.

    Returns (vertices, faces, source, face_key, params); face_key names faces in messages.
    """
    forms = [f for f in SURFACE_FORMS if f in tab]
    if len(forms) != 1:
        rd.err(key, sorted(tab), "give exactly one of: shape, file, vertices+faces")
    form = forms[0]
    extra = set().union(*shape_keys.values())
    if form != "shape":
        for k in tab:
            if k in extra:
                rd.err(f"{key}.{k}", tab[k], f"goes with a shape, not with {form}")
    if form == "vertices":
        verts, faces = _vertices_faces(rd, tab, key)
        return verts, faces, "vertices", (f"{key}.faces", None), {}
    if "faces" in tab:
        rd.err(f"{key}.faces", tab["faces"], f"faces go with vertices, not with {form}")
    if form == "file":
        fname = rd.string(tab, "file", f"{key}.file", "")
        fpath = Path(fname)
        if not fpath.is_absolute():
            fpath = Path(scene_path).parent / fpath
        try:
            verts, faces = load_mesh_file(fpath)
        except MeshError as exc:
            rd.err(f"{key}.file", fname, exc.message)
        return verts, faces, f"file {fname}", (f"{key}.file", fname), {"file": fname}
    shape = rd.choice(tab, "shape", f"{key}.shape", tuple(shape_keys), None)
    for k in tab:
        if k in extra and k not in shape_keys[shape]:
            rd.err(f"{key}.{k}", tab[k], f"not a parameter of shape {shape!r} "
                                         f"(allowed: {', '.join(sorted(shape_keys[shape]))})")
    try:
        verts, faces, params = build_shape(shape)
    except ShapeError as exc:
        rd.err(f"{key}.{exc.where}" if exc.where else key, exc.value, exc.message)
    return verts, faces, shape, (f"{key}.shape", shape), {"shape": shape, **params}


def _read_path(rd, tab, key):
    if "path" not in tab:
        rd.err(key, None, "missing value")
    v = tab["path"]
    if not isinstance(v, list) or len(v) < 2:
        rd.err(key, v, "must be a list of at least two [x, y, z] points")
    return rd.matrix(tab, "path", key, 3, **COORD)


def _trimesh_or_error(rd, verts, faces, face_key):
    from .meshquery import TriMesh

    try:
        return TriMesh(verts, faces)
    except ValueError as exc:
        rd.err(face_key[0], face_key[1], str(exc))


def _read_cavity(rd, ct, key, domain, scene_path):
    from .cavities import Cavity

    if not isinstance(ct, dict):
        rd.err(key, ct, "must be a table")
    allowed = {"name", "faces", *SURFACE_FORMS, *set().union(*_CAVITY_SHAPE_KEYS.values())}
    rd.known(ct, allowed, key)
    name = rd.string(ct, "name", f"{key}.name", key)

    def build(shape):
        seg = DEFAULTS["cavity[].segments"] if shape == "box" else \
            rd.integer(ct, "segments", f"{key}.segments", DEFAULTS["cavity[].segments"], 8, 4096)
        if shape in ("circular_tunnel", "horseshoe_tunnel"):
            path = _read_path(rd, ct, f"{key}.path")
            if shape == "circular_tunnel":
                r = rd.number(ct, "radius", f"{key}.radius", positive=True, **SIZE)
                v, f = shapes.circular_tunnel(path, r, seg)
                return v, f, {"path": path.tolist(), "radius": r, "segments": seg}
            w = rd.number(ct, "width", f"{key}.width", positive=True, **SIZE)
            h = rd.number(ct, "height", f"{key}.height", positive=True, **SIZE)
            v, f = shapes.horseshoe_tunnel(path, w, h, seg)
            return v, f, {"path": path.tolist(), "width": w, "height": h, "segments": seg}
        if shape == "ellipsoid":
            cname = "centre" if "centre" in ct or "center" not in ct else "center"
            c = rd.vector(ct, cname, f"{key}.{cname}", **COORD)
            if "radii" in ct and "radius" in ct:
                rd.err(f"{key}.radius", ct["radius"], "give either radius (a sphere) or radii, not both")
            if "radius" in ct:
                radii = np.full(3, rd.number(ct, "radius", f"{key}.radius", positive=True, **SIZE))
            else:
                radii = rd.vector(ct, "radii", f"{key}.radii", **LENGTH)
                for a in range(3):
                    rd.check_number(float(radii[a]), f"{key}.radii[{a}]", positive=True, **SIZE)
            v, f = shapes.ellipsoid(c, radii, seg)
            return v, f, {"centre": c.tolist(), "radii": radii.tolist(), "segments": seg}
        lo = rd.vector(ct, "min", f"{key}.min", **COORD)
        hi = rd.vector(ct, "max", f"{key}.max", **COORD)
        for a in range(3):
            if hi[a] <= lo[a]:
                rd.err(f"{key}.max[{a}]", float(hi[a]), f"must exceed {key}.min[{a}] = {lo[a]:g}")
        v, f = shapes.box(lo, hi)
        return v, f, {"min": lo.tolist(), "max": hi.tolist()}

    verts, faces, source, face_key, params = _mesh_from_table(rd, ct, key, scene_path, _CAVITY_SHAPE_KEYS, build)
    mesh = _trimesh_or_error(rd, verts, faces, face_key)
    if not mesh.nearly_closed():
        sizes = mesh.hole_sizes()
        rd.err(face_key[0], face_key[1] if face_key[1] is not None else f"{len(faces)} faces",
               f"surface is not closed: {len(mesh.boundary_edges)} boundary edges in {len(sizes)} holes, "
               f"the largest {sizes.max():.4g} across (small defects up to {0.25 * mesh.thickness:.4g} are "
               f"tolerated); a cavity needs a closed surface")
    if np.any(mesh.hi < domain.min) or np.any(mesh.lo > domain.max):
        rd.err(key, [mesh.lo.tolist(), mesh.hi.tolist()], "cavity lies entirely outside the domain box")
    return Cavity(name, mesh, key, source, params)


def _read_surface_discontinuity(rd, dt, key, domain, r, scene_path):
    from .meshquery import TriMesh

    allowed = {"name", "thickness", "faces", *SURFACE_FORMS, *set().union(*_SURFACE_SHAPE_KEYS.values())}
    rd.known(dt, allowed, key)
    name = rd.string(dt, "name", f"{key}.name", key)
    thick = rd.number(dt, "thickness", f"{key}.thickness", default=DEFAULTS["discontinuity[].thickness"], nonneg=True,
                      **LENGTH)

    def build(shape):
        trace = rd.vector(dt, "trace", f"{key}.trace", **COORD)
        p = {"trace": trace.tolist()}
        p["dip_direction"] = rd.number(dt, "dip_direction", f"{key}.dip_direction", lo=0.0, hi=360.0)
        for k in ("dip_top", "dip_bottom"):
            p[k] = rd.number(dt, k, f"{key}.{k}", lo=0.0, hi=90.0)
            if p[k] < 0.1:
                rd.err(f"{key}.{k}", p[k], "must be >= 0.1 degrees (a listric fault dips; flatter, its horizontal "
                                           "offset runs off to infinity)")
        for k in ("depth", "length", "resolution"):
            p[k] = rd.number(dt, k, f"{key}.{k}", positive=True, **SIZE)
        v, f = shapes.listric(trace, p["dip_direction"], p["dip_top"], p["dip_bottom"], p["depth"], p["length"],
                              p["resolution"])
        return v, f, p

    verts, faces, source, face_key, params = _mesh_from_table(rd, dt, key, scene_path, _SURFACE_SHAPE_KEYS, build)
    mesh = _trimesh_or_error(rd, verts, faces, face_key)
    if float((mesh.areas * mesh.normals[:, 2]).sum()) < 0:  # normals upward on average
        mesh = TriMesh(mesh.vertices, mesh.faces[:, [0, 2, 1]])
    band = max(thick / 2, 2 * r)
    if np.any(mesh.hi + band < domain.min) or np.any(mesh.lo - band > domain.max):
        rd.err(key, [mesh.lo.tolist(), mesh.hi.tolist()], "discontinuity lies entirely outside the domain box")
    return SurfaceDiscontinuity(name, mesh, thick, key, source, params)
