"""The scene-key reference (docs/scenes.md), recorded from the validating reader.

A :class:`Record` reads scenes through a subclass of :class:`sgim.reader.SceneReader` that notes every table the reader
allows (``known``) and, for every key read through the reader's methods, its type, default, range and unit.  Which
keys are required is found by reading each synthetic scene again without the key: a key is required when the reader
then stops at that key.  What the reader cannot say (the unit of a key it reads without one, and a one-line
meaning for every key) is the hand-written :data:`SGIM_KEYS`; :func:`render_tables` merges the two.

The synthetic scenes (:func:`sgim_scenes`) reach every table and key the reader allows, including those no case
scene uses.  dda/scenedoc.py does the same for DDA scenes; cases/make/scene_docs.py writes docs/scenes.md.
Nothing here changes how a scene is read.
"""
from __future__ import annotations

import copy
import math
import re
import tomllib
from pathlib import Path

from .common import SceneError
from .reader import SceneReader
from .scene import scene_from_dict

NODEFAULT = "<none>"  # the reader was given no default


def norm(key):
    """Key path with array indices dropped: excavation[2].name -> excavation[].name."""
    return re.sub(r"\[\d+\]", "[]", key)


def _range(positive=False, nonneg=False, lo=None, hi=None):
    low = []
    if positive:
        low.append("> 0" if lo is None or lo <= 0 else f">= {lo:g}")
    elif lo is not None:
        low.append(f">= {max(lo, 0.0) if nonneg else lo:g}")
    elif nonneg:
        low.append(">= 0")
    if hi is not None:
        low.append(f"<= {hi:g}")
    return ", ".join(low)


def show(v):
    """A default as it would be written in TOML."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '""' if v == "" else f'"{v}"'
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:g}"
    if isinstance(v, int):
        return str(v)
    if hasattr(v, "tolist"):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(show(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {show(x)}" for k, x in v.items()) + "}"
    return repr(v)


class Record:
    """What the reader allowed and read over the scenes given to :meth:`read`."""

    def __init__(self):
        self.tables = {}  # normalised table path ("" = top level) -> set of allowed keys
        self.keys = {}  # normalised key path -> {"kinds", "defaults", "ranges", "units"} (sets, insertion order)
        self.order = []  # key paths in the order first read
        self.required = {}  # normalised key path -> set of bool (absent from a scene: does the reader stop there?)
        self.scenes = 0
        self._tried = set()

    def note(self, key, kind, default=NODEFAULT, rng="", unit=""):
        k = norm(key)
        e = self.keys.get(k)
        if e is None:
            e = self.keys[k] = {"kinds": {}, "defaults": {}, "ranges": {}, "units": {}}
            self.order.append(k)
        e["kinds"][kind] = None
        e["defaults"][show(default) if default is not NODEFAULT else NODEFAULT] = None
        if rng:
            e["ranges"][rng] = None
        if unit.strip():
            e["units"][unit.strip()] = None

    def reader(self, path):
        return _Recorder(path, self)

    def allowed(self):
        """Every key path the reader allows (tables included)."""
        out = set()
        for t, ks in self.tables.items():
            out |= {f"{t}.{k}" if t else k for k in ks}
        return out

    def read(self, scene_from_dict, data, path, required=False):
        """Read `data` (a parsed scene) through the recording reader; `required`: also read it again without each
        of its keys in turn, noting whether the reader stops at that key."""
        scene_from_dict(copy.deepcopy(data), path, "", reader=self.reader)
        self.scenes += 1
        if not required:
            return
        for where in _key_paths(data):
            if where[0] == "generate":
                continue  # [[generate]] parameters are the generator's (documented from its signature)
            trimmed = copy.deepcopy(data)
            parent = trimmed
            for part in where[:-1]:
                parent = parent[part]
            name = norm(_join(where))
            context = (name, frozenset(parent))  # the same key among the same keys: the same answer
            if context in self._tried:
                continue
            self._tried.add(context)
            del parent[where[-1]]
            try:
                scene_from_dict(trimmed, path, "", reader=SceneReader)
            except SceneError as exc:
                self.required.setdefault(name, set()).add(norm(exc.key) == name)
            else:
                self.required.setdefault(name, set()).add(False)


def _join(parts):
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def _key_paths(data, prefix=()):
    for k, v in data.items():
        yield prefix + (k,)
        if isinstance(v, dict):
            yield from _key_paths(v, prefix + (k,))
        elif isinstance(v, list) and v and all(isinstance(t, dict) for t in v):
            for i, t in enumerate(v):
                yield from _key_paths(t, prefix + (k, i))


class _Recorder(SceneReader):
    """The scene reader, noting what it allows and reads into a Record."""

    def __init__(self, path, record):
        super().__init__(path)
        self.record, self.depth = record, 0

    def known(self, tab, allowed, key):
        self.record.tables.setdefault(norm(key), set()).update(allowed)
        return super().known(tab, allowed, key)

    def table(self, parent, name, key, required=False):
        self.record.note(key, "table", NODEFAULT if required else {})
        return super().table(parent, name, key, required)

    def _inner(self, fn, *args, **kw):
        self.depth += 1
        try:
            return fn(*args, **kw)
        finally:
            self.depth -= 1

    def number(self, tab, name, key, default=None, positive=False, nonneg=False, lo=None, hi=None, unit=""):
        self.record.note(key, "number", NODEFAULT if default is None else default, _range(positive, nonneg, lo, hi),
                         unit)
        return self._inner(super().number, tab, name, key, default, positive, nonneg, lo, hi, unit)

    def check_number(self, v, key, positive=False, nonneg=False, lo=None, hi=None, unit=""):
        if self.depth == 0 and not key.startswith("generate["):  # read directly (not through number / vector /
            # matrix); [[generate]] parameters are the generator's, documented from its signature
            elem = re.search(r"\[\d+\]$", key)
            base = key[:elem.start()] if elem else key
            kind = "number"
            if elem:  # an element of a list: the list's kind, if the reader named it already
                kinds = self.record.keys.get(norm(base), {}).get("kinds", {})
                kind = next((k for k in kinds if k.startswith("list of")), "list of numbers")
            self.record.note(base, kind, NODEFAULT, _range(positive, nonneg, lo, hi), unit)
        return super().check_number(v, key, positive, nonneg, lo, hi, unit)

    def vector(self, tab, name, key, n=3, default=None, lo=None, hi=None, unit=""):
        self.record.note(key, f"list of {n} numbers", NODEFAULT if default is None else tuple(default),
                         _range(lo=lo, hi=hi), unit)
        return self._inner(super().vector, tab, name, key, n, default, lo, hi, unit)

    def matrix(self, tab, name, key, ncol, integer=False, lo=None, hi=None, unit=""):
        self.record.note(key, f"list of [{ncol} {'integers' if integer else 'numbers'}] rows", NODEFAULT,
                         _range(lo=lo, hi=hi), unit)
        return self._inner(super().matrix, tab, name, key, ncol, integer, lo, hi, unit)

    def choice(self, tab, name, key, choices, default):
        self.record.note(key, "one of " + ", ".join(show(c) for c in choices),
                         NODEFAULT if default is None else default)
        return super().choice(tab, name, key, choices, default)

    def boolean(self, tab, name, key, default):
        self.record.note(key, "true / false", default)
        return super().boolean(tab, name, key, default)

    def string(self, tab, name, key, default):
        self.record.note(key, "string", default)
        return super().string(tab, name, key, default)

    def value(self, tab, name, key, default, kind="value"):
        self.record.note(key, kind, default)
        return super().value(tab, name, key, default, kind)


# --------------------------------------------------------------------------
# what the reader cannot say: unit ("-" dimensionless, "" for text, flags and tables) and meaning of every key.
# Optional: "default" (text replacing a default that depends on the scene, e.g. kn / 2, or that the reader gives
# as a placeholder) and "absent" (what leaving out a key without a default means).

def K(unit, meaning, **extra):
    return {"unit": unit, "meaning": meaning, **extra}


SGIM_KEYS = {
    "name": K("", "name of the scene (output titles and summary)", default="the file name without .toml"),
    "description": K("", "free text, not read (documentation of the scene)", type="string", absent="none"),
    "domain": K("", "the box of the model (required)"),
    "domain.min": K("m", "lower corner [x, y, z] of the box"),
    "domain.max": K("m", "upper corner [x, y, z] of the box; each coordinate > min"),
    "packing": K("", "how the box is filled with spheres (required)"),
    "packing.kind": K("", "cubic: the paper's lattice (eq. 1-2); hexagonal (hcp); fcc; random: dense random "
                          "packing (sgim/rpack.py)"),
    "packing.radius": K("m", "sphere radius (lattices; random: equal spheres, instead of distribution or grading)"),
    "packing.seed": K("-", "random packing: seed (a non-negative integer); the same seed gives the same packing"),
    "packing.overlap": K("-", "random packing: largest overlap, as a fraction of the smaller radius"),
    "packing.fill": K("", "random packing: closed surface file (relative to the scene); the box intersected with it "
                          "is packed", absent="the whole box"),
    "packing.distribution": K("", "random packing: a radius law instead of radius"),
    "packing.distribution.law": K("", "uniform (min, max); lognormal (median, sigma, optional min / max); sieve "
                                      "(sizes, passing)"),
    "packing.distribution.min": K("m", "smallest radius (uniform; lognormal: truncation)",
                                  absent="lognormal: no truncation"),
    "packing.distribution.max": K("m", "largest radius (uniform; lognormal: truncation)",
                                  absent="lognormal: no truncation"),
    "packing.distribution.median": K("m", "lognormal: median radius"),
    "packing.distribution.sigma": K("-", "lognormal: standard deviation of ln r"),
    "packing.distribution.sizes": K("m", "sieve: increasing sieve sizes (diameters)"),
    "packing.distribution.passing": K("%", "sieve: percent passing by mass at each size, from 0 to 100, "
                                           "non-decreasing"),
    "packing.grading": K("", "random packing: radius graded by the distance to named objects, instead of radius"),
    "packing.grading.near": K("", "names of [[excavation]], [[cavity]] or [[discontinuity]] tables the distance is "
                                  "measured to", type="string or list of strings"),
    "packing.grading.fine_radius": K("m", "radius up to fine_distance from the nearest named object"),
    "packing.grading.coarse_radius": K("m", "radius from coarse_distance on (<= 64 x fine_radius)"),
    "packing.grading.fine_distance": K("m", "distance up to which the radius is fine_radius"),
    "packing.grading.coarse_distance": K("m", "distance from which the radius is coarse_radius (> fine_distance); "
                                              "in between r = fine (coarse/fine)^s, s = t^2 (3 - 2t)"),
    "packing.grading.spread": K("-", "radius factor uniform in [1 - spread, 1 + spread]"),
    "excavation": K("", "[[excavation]]: excavating surfaces; a site is removed if any removes it"),
    "excavation[].name": K("", "name (messages, [packing.grading] near)", default='"excavation[k]"'),
    "excavation[].rule": K("", "paper: the paper's spaces I and II per facet; exact: above the surface or within r "
                               "by true distance"),
    "excavation[].points": K("m", "points triangulated in plan view (one of points, vertices + faces, file)"),
    "excavation[].vertices": K("m", "mesh vertices, with faces (one of points, vertices + faces, file)"),
    "excavation[].faces": K("-", "0-based vertex indices of each triangle (with vertices)"),
    "excavation[].file": K("", "triangle mesh file (any meshio format), relative to the scene"),
    "discontinuity": K("", "[[discontinuity]]: discs (centre + orientation + radius) or triangulated surfaces "
                           "(shape, file or vertices + faces)"),
    "discontinuity[].name": K("", "name (messages, [packing.grading] near)", default='"discontinuity[k]"'),
    "discontinuity[].centre": K("m", "disc centre [x, y, z] (or center)"),
    "discontinuity[].center": K("m", "the same as centre (either spelling)"),
    "discontinuity[].dip": K("deg", "disc dip, with dip_direction (or give normal)"),
    "discontinuity[].dip_direction": K("deg", "disc dip direction, clockwise from north (+y); listric: dip "
                                              "direction of the fault"),
    "discontinuity[].normal": K("-", "disc normal [a, b, c] (any length), instead of dip + dip_direction"),
    "discontinuity[].radius": K("m", "disc radius"),
    "discontinuity[].thickness": K("m", "0: joint (green / blue sides within 2r); > 0: fault (red inside)"),
    "discontinuity[].shape": K("", "built-in surface: listric (dip flattening linearly with depth)"),
    "discontinuity[].trace": K("m", "listric: top centre [x, y, z] of the fault"),
    "discontinuity[].dip_top": K("deg", "listric: dip at the trace (>= 0.1)"),
    "discontinuity[].dip_bottom": K("deg", "listric: dip at depth (>= 0.1)"),
    "discontinuity[].depth": K("m", "listric: vertical extent below the trace"),
    "discontinuity[].length": K("m", "listric: length along strike"),
    "discontinuity[].resolution": K("m", "listric: facet size"),
    "discontinuity[].file": K("", "surface: triangle mesh file, relative to the scene"),
    "discontinuity[].vertices": K("m", "surface: mesh vertices, with faces"),
    "discontinuity[].faces": K("-", "surface: 0-based vertex indices of each triangle (with vertices)"),
    "bonds": K("", "which touching pairs are in contact and bonded"),
    "bonds.rule": K("", "colour: the paper's (no bond green-blue, none if either is red); geometric: cut where the "
                        "centre segment crosses a discontinuity"),
    "bonds.tolerance": K("-", "contact when |ci - cj| <= (ri + rj)(1 + tolerance)"),
    "output": K("", "the files sgim build writes"),
    "output.formats": K("", "drawn from npz, vtu, txt, png (npz is always written)"),
    "render": K("", "the picture model.png (sgim build, sgim show)"),
    "render.hide_intact": K("", "leave the intact (uncoloured) spheres out of the picture"),
    "render.translucent": K("", "draw the spheres translucent"),
    "render.cut_away": K("", "conditions like \"y<-10\": spheres meeting every condition are left out of model.png",
                         absent="nothing cut away"),
    "render.width": K("px", "picture width"),
    "render.height": K("px", "picture height"),
    "limits": K("", "resource limits checked before the build (sgim/limits.py)"),
    "limits.max_spheres": K("-", "refuse a build estimated to make more spheres (a positive integer)",
                            type="integer", absent="the spheres that fill half of the machine's memory "
                                                   "(sgim/limits.py)"),
    "blocks": K("", "the block model's own keys (dda/geoblocks.py); sgim build reads and checks them, then ignores "
                    "them", absent="no joint sets, defaults below"),
    "blocks.min_volume": K("m3", "a cut leaving a smaller piece is not made; smaller excavation pieces join a "
                                 "neighbour across intact rock when their union is convex; a run scales the inertia "
                                 "of those left (their weight kept) so that they do not set the time step",
                           default="1e-6 x the domain's volume"),
    "blocks.cut_by": K("", "names of [[discontinuity]] tables and [[joint_set]] sets that cut blocks",
                       absent="all of them"),
    "blocks.cohesion": K("Pa", "intact rock's cohesion (faces outside every disc)"),
    "blocks.tensile": K("Pa", "intact rock's tensile strength"),
    "blocks.friction": K("deg", "intact rock's friction angle"),
    "blocks.seed": K("-", "seed of the joint sets' persistence draws"),
    "blocks.kn": K("N/m", "normal stiffness of every contact point of the block model"),
    "blocks.ks": K("N/m", "shear stiffness of every contact point", absent="kn / 2"),
    "blocks.damping": K("-", "viscous contact damping, ratio of critical (normal and locked shear springs)"),
    "blocks.density": K("kg/m3", "density of every block"),
    "blocks.joint_friction": K("deg", "friction angle of joint and fault faces inside their disc (the default law)"),
    "blocks.joint_cohesion": K("Pa", "cohesion of joint faces (the default law)"),
    "blocks.joint_tensile": K("Pa", "tensile strength of joint faces (the default law)"),
    "blocks.law": K("", "[[blocks.law]]: the contact law of one discontinuity, joint set or fault, by name"),
    "blocks.law[].name": K("", "a [[discontinuity]], [[joint_set]] or [[blocks.joint_set]] name"),
    "blocks.law[].friction": K("deg", "friction angle", default="blocks.joint_friction"),
    "blocks.law[].cohesion": K("Pa", "cohesion", default="blocks.joint_cohesion"),
    "blocks.law[].tensile": K("Pa", "tensile strength", default="blocks.joint_tensile"),
    "blocks.law[].kn": K("N/m", "normal stiffness per contact point", absent="blocks.kn"),
    "blocks.law[].ks": K("N/m", "shear stiffness per contact point", absent="blocks.ks (kn / 2 with its own kn)"),
    "blocks.run": K("", "dda run of the scene: its block model under gravity (dda/georun.py)",
                    absent="dda run refuses the scene"),
    "blocks.run.duration": K("s", "simulated time", absent="dda run refuses the scene"),
    "blocks.run.dt": K("s", "time step; 0: safety x the critical step"),
    "blocks.run.safety": K("-", "fraction of the critical time step"),
    "blocks.run.gravity": K("m/s2", "gravity vector"),
    "blocks.run.local_damping": K("-", "Cundall's local damping (quasi-static runs)"),
    "blocks.run.frames": K("-", "VTU frames of the run"),
    "blocks.run.record_every": K("s", "time between recorded rows", default="duration / 100"),
    "blocks.run.sleep": K("", "resting blocks stop being integrated until a moving block touches them"),
    "blocks.run.fixed": K("", "domain faces (x-, x+, y-, y+, z-, z+) whose blocks are fixed"),
    "blocks.run.free_within": K("m", "only blocks whose bounding sphere comes this near the free_near surfaces "
                                     "move; the others are fixed (the far field)", absent="every block may move"),
    "blocks.run.free_near": K("", "[[excavation]] and [[cavity]] names that free_within measures from",
                              default="every [[excavation]] and [[cavity]] name"),
    "blocks.joint_set": K("", "[[blocks.joint_set]]: a persistent joint set of the block fabric"),
    "blocks.joint_set[].name": K("", "set name (the faces' source)", default='"B1", "B2", ... by position'),
    "blocks.joint_set[].dip": K("deg", "dip of the planes"),
    "blocks.joint_set[].dip_direction": K("deg", "dip direction of the planes"),
    "blocks.joint_set[].spacing": K("m", "distance between neighbouring planes, along the normal"),
    "blocks.joint_set[].origin": K("m", "a point one plane passes through", default="the domain's centre"),
    "blocks.joint_set[].persistence": K("-", "chance that a plane cuts a block it crosses (0 < p <= 1)"),
    "blocks.joint_set[].extent": K("", "box where the set exists: a plane cuts the whole blocks whose section's "
                                       "centre lies in it (bounded sets cut after the others)", absent="everywhere"),
    "blocks.joint_set[].extent.min": K("m", "lower corner of the box"),
    "blocks.joint_set[].extent.max": K("m", "upper corner of the box; each coordinate > min"),
    "dfn": K("", "Monte-Carlo fracture network: seed and limit of the [[joint_set]] sampling, or a network file"),
    "dfn.seed": K("-", "seed of the network; the same seed gives the same network"),
    "dfn.max_fractures": K("-", "refuse a network that would need more fractures"),
    "dfn.file": K("", "network.csv or network.json written before (relative to the scene), instead of "
                      "[[joint_set]] tables", absent="sample the [[joint_set]] tables"),
    "joint_set": K("", "[[joint_set]]: a joint set of Poisson discs (sgim/dfn.py)"),
    "joint_set[].name": K("", "set name (fracture ids NAME-000001, ...)", default='"J1", "J2", ... by position'),
    "joint_set[].dip": K("deg", "dip of the mean plane"),
    "joint_set[].dip_direction": K("deg", "dip direction of the mean plane"),
    "joint_set[].kappa": K("-", "Fisher concentration about the mean pole (> 0, <= 1e8)"),
    "joint_set[].p32": K("m2/m3", "fracture area inside the box per box volume (one of p32, count)"),
    "joint_set[].count": K("-", "fractures reaching the domain, >= 1 (one of p32, count)", default="—"),
    "joint_set[].thickness": K("m", "0: joints; > 0: faults (red)"),
    "joint_set[].radius": K("m", "a number (constant radius) or a table with law = ..."),
    "joint_set[].radius.law": K("", "constant (value); power (exponent, min, max); lognormal (mu + sigma or "
                                    "mean + sd, optional min / max); exponential (mean, optional min / max)"),
    "joint_set[].radius.value": K("m", "constant: the radius"),
    "joint_set[].radius.min": K("m", "smallest radius (power: required, > 0)"),
    "joint_set[].radius.max": K("m", "largest radius (power: needed unless exponent > 4)", absent="unbounded"),
    "joint_set[].radius.exponent": K("-", "power: density ~ r^-exponent"),
    "joint_set[].radius.mu": K("-", "lognormal: mean of ln r (r in m), with sigma"),
    "joint_set[].radius.sigma": K("-", "lognormal: standard deviation of ln r, with mu"),
    "joint_set[].radius.mean": K("m", "exponential: the mean (scale); lognormal: mean of r, with sd"),
    "joint_set[].radius.sd": K("m", "lognormal: standard deviation of r, with mean"),
    "cavity": K("", "[[cavity]]: closed surfaces whose inside (and within r) is excavated (sgim/cavities.py)"),
    "cavity[].name": K("", "name (messages, [packing.grading] near)", default='"cavity[k]"'),
    "cavity[].shape": K("", "built-in closed surface (one of shape, file, vertices + faces)"),
    "cavity[].path": K("m", "tunnels: polyline of at least two [x, y, z] points (axis; horseshoe: the invert)"),
    "cavity[].radius": K("m", "circular_tunnel: radius; ellipsoid: a sphere's radius (instead of radii)"),
    "cavity[].width": K("m", "horseshoe_tunnel: width"),
    "cavity[].height": K("m", "horseshoe_tunnel: height (>= width / 2)"),
    "cavity[].segments": K("-", "facets around a tunnel section or an ellipsoid (8 .. 4096)"),
    "cavity[].centre": K("m", "ellipsoid: centre [x, y, z] (or center)"),
    "cavity[].center": K("m", "the same as centre (either spelling)"),
    "cavity[].radii": K("m", "ellipsoid: semi-axes [a, b, c] along x, y, z"),
    "cavity[].min": K("m", "box: lower corner [x, y, z]"),
    "cavity[].max": K("m", "box: upper corner [x, y, z]"),
    "cavity[].file": K("", "closed triangle mesh file, relative to the scene"),
    "cavity[].vertices": K("m", "closed mesh vertices, with faces"),
    "cavity[].faces": K("-", "0-based vertex indices of each triangle (with vertices)"),
}

# A closed box (the faces' normals point outward) and an open square sheet, for the synthetic scenes' mesh files.
_BOX_OBJ = """v 2 2 2\nv 8 2 2\nv 8 8 2\nv 2 8 2\nv 2 2 8\nv 8 2 8\nv 8 8 8\nv 2 8 8
f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8
"""
_SHEET_OBJ = "v 0 0 5\nv 10 0 5\nv 10 10 6\nv 0 10 6\nf 1 2 3\nf 1 3 4\n"
_NETWORK_CSV = "id,set,cx,cy,cz,nx,ny,nz,radius,thickness\nF-000001,F,5,5,5,0,0,1,3,0\n"


def write_scene_files(folder):
    """The mesh and network files the synthetic scenes name, written into `folder`."""
    folder = Path(folder)
    (folder / "box.obj").write_text(_BOX_OBJ)
    (folder / "sheet.obj").write_text(_SHEET_OBJ)
    (folder / "network.csv").write_text(_NETWORK_CSV)


def sgim_scenes():
    """Small valid sgim scenes that, together, give every key the reader allows (files: write_scene_files)."""
    base = {"domain": {"min": [0, 0, 0], "max": [10, 10, 10]}, "packing": {"kind": "cubic", "radius": 0.5}}
    sq = [[0, 0, 9], [10, 0, 9], [10, 10, 9.5], [0, 10, 9.5]]
    full = copy.deepcopy(base) | {
        "name": "all keys", "description": "every lattice key",
        "excavation": [{"name": "pit", "rule": "exact", "points": sq},
                       {"vertices": sq, "faces": [[0, 1, 2], [0, 2, 3]]},
                       {"rule": "paper", "file": "sheet.obj"}],
        "discontinuity": [
            {"name": "J", "centre": [5, 5, 5], "dip": 60, "dip_direction": 120, "radius": 4, "thickness": 0.0},
            {"center": [5, 5, 5], "normal": [0, 1, 1], "radius": 3, "thickness": 1.0},
            {"name": "L", "shape": "listric", "trace": [5, 5, 9], "dip_direction": 90, "dip_top": 70,
             "dip_bottom": 30, "depth": 6, "length": 8, "resolution": 1.0, "thickness": 0.5},
            {"file": "sheet.obj"},
            {"vertices": [[0, 0, 3], [10, 0, 3], [10, 10, 4]], "faces": [[0, 1, 2]]}],
        "bonds": {"rule": "geometric", "tolerance": 1e-3},
        "output": {"formats": ["npz", "png"]},
        "render": {"hide_intact": True, "translucent": True, "cut_away": ["y<2", "z>8"], "width": 800,
                   "height": 600},
        "limits": {"max_spheres": 100000},
        "blocks": {"min_volume": 0.01, "cut_by": ["J"], "cohesion": 2e6, "tensile": 1e6, "friction": 38.0, "seed": 4,
                   "kn": 1e9, "ks": 4e8, "damping": 0.2, "density": 2700.0, "joint_friction": 32.0,
                   "joint_cohesion": 1e3, "joint_tensile": 1e3,
                   "law": [{"name": "J", "friction": 25.0, "cohesion": 0.0, "tensile": 0.0, "kn": 2e9, "ks": 1e9}],
                   "run": {"duration": 1.0, "dt": 1e-4, "safety": 0.4, "gravity": [0, 0, -9.8], "local_damping": 0.1,
                           "frames": 5, "record_every": 0.1, "sleep": False, "fixed": ["z-"],
                           "free_within": 3.0},
                   "joint_set": [{"name": "B1", "dip": 80, "dip_direction": 130, "spacing": 2.0,
                                  "origin": [1, 1, 1], "persistence": 0.8,
                                  "extent": {"min": [0, 0, 0], "max": [10, 10, 6]}}]},
    }
    cav = copy.deepcopy(base) | {
        "blocks": {"run": {"duration": 1.0, "free_within": 2.0, "free_near": ["T"]}},
        "cavity": [{"name": "T", "shape": "circular_tunnel", "path": [[0, 5, 5], [10, 5, 5]], "radius": 1.0,
                    "segments": 8},
                   {"shape": "horseshoe_tunnel", "path": [[0, 3, 3], [10, 3, 3]], "width": 2.0, "height": 2.0,
                    "segments": 8},
                   {"shape": "ellipsoid", "centre": [5, 5, 5], "radii": [1, 2, 1.5], "segments": 8},
                   {"shape": "ellipsoid", "center": [5, 5, 5], "radius": 1.0, "segments": 8},
                   {"shape": "box", "min": [4, 4, 4], "max": [6, 6, 6]},
                   {"file": "box.obj"},
                   {"vertices": [[4, 4, 4], [6, 4, 4], [5, 6, 4], [5, 5, 6]],
                    "faces": [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]]}],
    }
    dfn = copy.deepcopy(base) | {
        "dfn": {"seed": 3, "max_fractures": 1000},
        "joint_set": [
            {"name": "A", "dip": 70, "dip_direction": 40, "kappa": 20, "p32": 0.05, "thickness": 0.0,
             "radius": {"law": "power", "exponent": 2.5, "min": 1.0, "max": 4.0}},
            {"dip": 20, "dip_direction": 200, "kappa": 20, "count": 3, "radius": 2.0},
            {"dip": 50, "dip_direction": 300, "kappa": 20, "count": 3,
             "radius": {"law": "lognormal", "mu": 0.5, "sigma": 0.3, "min": 0.5, "max": 5.0}},
            {"dip": 50, "dip_direction": 300, "kappa": 20, "count": 3,
             "radius": {"law": "lognormal", "mean": 2.0, "sd": 0.5}},
            {"dip": 50, "dip_direction": 300, "kappa": 20, "count": 3,
             "radius": {"law": "exponential", "mean": 2.0, "min": 0.5}},
            {"dip": 50, "dip_direction": 300, "kappa": 20, "count": 3, "radius": {"law": "constant", "value": 2.0}}],
    }
    rnd = {"domain": base["domain"], "packing": {"kind": "random", "radius": 0.5, "seed": 1, "overlap": 1e-6,
                                                  "fill": "box.obj"}}
    uni = {"domain": base["domain"], "packing": {"kind": "random", "distribution": {"law": "uniform", "min": 0.3,
                                                                                    "max": 0.5}}}
    logn = {"domain": base["domain"], "packing": {"kind": "random", "distribution": {
        "law": "lognormal", "median": 0.4, "sigma": 0.2, "min": 0.3, "max": 0.6}}}
    sieve = {"domain": base["domain"], "packing": {"kind": "random", "distribution": {
        "law": "sieve", "sizes": [0.6, 0.8, 1.0], "passing": [0, 40, 100]}}}
    graded = {"domain": base["domain"], "excavation": [{"name": "pit", "points": sq}],
              "packing": {"kind": "random", "grading": {"near": ["pit"], "fine_radius": 0.3, "coarse_radius": 0.6,
                                                        "fine_distance": 1.0, "coarse_distance": 4.0,
                                                        "spread": 0.1}}}
    netfile = copy.deepcopy(base) | {"dfn": {"file": "network.csv", "max_fractures": 10}}
    return {"lattice": full, "cavities": cav, "joint_sets": dfn, "random_radius": rnd, "random_uniform": uni,
            "random_lognormal": logn, "random_sieve": sieve, "random_graded": graded, "dfn_file": netfile}


def record_sgim(record, folder, case_files=(), synthetic=True):
    """Record the sgim reader over the synthetic scenes (mesh files written into `folder`; each also read
    without each of its keys; not when `synthetic` is false) and over `case_files` (sgim scene files)."""
    write_scene_files(folder)
    for name, data in (sgim_scenes() if synthetic else {}).items():
        record.read(scene_from_dict, data, Path(folder) / f"{name}.toml", required=True)
    for f in case_files:
        record.read(scene_from_dict, tomllib.loads(Path(f).read_text(encoding="utf-8")), f)


# --------------------------------------------------------------------------
# rendering

def key_rows(record, meta):
    """{key path: (type, default, range, unit, meaning)} of every key the reader allows, merged with `meta`.
    Raises KeyError naming the keys `meta` lacks."""
    allowed = record.allowed()
    lacking = sorted(k for k in allowed if k not in meta)
    if lacking:
        raise KeyError(f"no unit and meaning for: {', '.join(lacking)}")
    rows = {}
    for k in sorted(allowed):
        m = meta[k]
        e = record.keys.get(k, {"kinds": {}, "defaults": {}, "ranges": {}, "units": {}})
        kinds = [x for x in e["kinds"] if x != "table"] or list(e["kinds"])
        if k in record.tables and "table" not in kinds:
            kinds.append("table")
        if f"{k}[]" in record.tables:
            kinds = ["array of tables"]
        typ = m.get("type") or " or ".join(kinds) or "?"
        req = record.required.get(k, set())
        defaults = [d for d in e["defaults"] if d not in (NODEFAULT, '""')]  # "": a placeholder, never used
        if "default" in m:
            default = m["default"]
        elif len(defaults) > 1:
            default = "VARIES: " + " / ".join(defaults)  # a scene-dependent default needs meta "default"
        elif defaults and True in req:
            default = f"{defaults[0]} (required in some forms, see meaning)"
        elif defaults:
            default = "empty" if defaults[0] == "{}" else defaults[0]
        elif req == {True}:
            default = "required"
        elif True in req:
            default = "required (see meaning)"
        else:
            default = m.get("absent", "—")
        rows[k] = (typ, default, "; ".join(e["ranges"]), m["unit"], m["meaning"])
    return rows


def table_title(path):
    if not path:
        return "top level"
    if path.endswith("[]"):
        return f"[[{path[:-2]}]]"
    inner = re.sub(r"\[\]", "", path)
    return f"[{inner}]" if "[]" not in path else f"[{inner}] (in each [[{path.split('[]')[0]}]])"


def render_tables(record, meta, level="###"):
    """Markdown: one section per table the reader allows, a row per key."""
    rows = key_rows(record, meta)
    order = {k: i for i, k in enumerate(record.order)}
    out = []
    for t in sorted(record.tables, key=lambda t: t != ""):  # top level first, then in the order first read
        keys = [f"{t}.{k}" if t else k for k in record.tables[t]]
        keys.sort(key=lambda k: (order.get(k, len(order)), k))
        out.append(f"{level} {table_title(t)}")
        if t in meta:
            out.append("")
            out.append(meta[t]["meaning"][0].upper() + meta[t]["meaning"][1:] + ".")
        out.append("")
        out.append("| key | type | default | range | unit | meaning |")
        out.append("|---|---|---|---|---|---|")
        for k in keys:
            typ, default, rng, unit, meaning = rows[k]
            leaf = k[len(t) + 1:] if t else k
            if k in record.tables:
                leaf += f" (table: {table_title(k)})"
            cells = [f"`{leaf}`", typ, default, rng, unit, meaning]
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
    return "\n".join(out)
