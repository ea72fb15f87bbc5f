"""The DDA part of the scene-key reference (docs/scenes.md): what dda/scene.py's reader allows and reads
(recorded as in sgim/scenedoc.py), the hand-written unit and meaning of each key, and the [[generate]] kinds with
their parameters and defaults (from the signatures of ``dda.generate.GENERATORS``).
"""
from __future__ import annotations

import copy
import inspect
import tomllib
from pathlib import Path

from sgim.scenedoc import K, show, write_scene_files

from .generate import GENERATORS
from .scene import generator_parameters, scene_from_dict

_LAW = {
    "kn": K("N/m", "normal stiffness per contact point"),
    "ks": K("N/m", "shear stiffness per contact point"),
    "friction": K("deg", "friction angle"),
    "cohesion": K("Pa", "cohesion on the point's share of the contact area; contacts present at t = 0 only"),
    "tensile": K("Pa", "tensile strength on the point's share of the contact area; contacts present at t = 0 only"),
    "damping": K("-", "contact damping, ratio of critical (normal; shear on locked points)"),
}

DDA_KEYS = {
    "name": K("", "name of the scene (output titles and summary)", default="the file name without .toml"),
    "description": K("", "free text, not read (documentation of the scene)", type="string", absent="none"),
    "simulation": K("", "run settings (required)"),
    "simulation.duration": K("s", "simulated time"),
    "simulation.dt": K("s", "time step; 0: safety x the critical step (8 points of the stiffest kn on the "
                            "lightest block)"),
    "simulation.safety": K("-", "fraction of the critical time step used when dt = 0"),
    "simulation.gravity": K("m/s2", "gravity vector [gx, gy, gz]"),
    "simulation.local_damping": K("-", "Cundall's non-viscous local damping (quasi-static runs only)"),
    "simulation.viscous_damping": K("-", "sphere decks: a force -c v on every sphere, c for this ratio of critical "
                                         "damping of the model's first mode, or \"critical\" (= 1)",
                                    type="number or \"critical\"", default="0"),
    "simulation.record_every": K("s", "time-series interval", default="duration / 100"),
    "simulation.frames": K("-", "VTU frames written over the run"),
    "simulation.sleep": K("", "resting blocks stop being integrated"),
    "simulation.sleep_velocity": K("m/s", "sleep: mean speed over the window below which a block may rest "
                                          "(no step above ten times it)",
                                   absent="1e-4 sqrt(g d50), d50 the median block size (dda/simulation.py)"),
    "simulation.sleep_accel": K("m/s2", "sleep: mean acceleration over the window below which a block may rest",
                                absent="1e-3 g (dda/simulation.py)"),
    "simulation.sleep_steps": K("-", "sleep: the window of the mean speed and acceleration, steps",
                                absent="200 (dda/simulation.py)"),
    "simulation.max_steps": K("-", "refuse a run of more steps (duration / dt) before it starts (a positive "
                                   "integer; or [limits] max_steps, not both)", type="integer",
                              absent="1e8 (dda/limits.py)"),
    "limits": K("", "resource limits (dda/limits.py)"),
    "limits.max_steps": K("-", "the same as [simulation] max_steps (give one of the two)", type="integer",
                          absent="1e8 (dda/limits.py)"),
    "contact": K("", "the default contact law, per contact point (required; with [spheres] also the sphere law)"),
    **{f"contact.{k}": v for k, v in _LAW.items()},
    "contact.ks": K("N/m", "shear stiffness per contact point", default="kn / 2"),
    "material": K("", "[[material]]: block materials (a block's material \"rock\" needs no table)"),
    "material[].name": K("", "material name, named by blocks and contact pairs"),
    "material[].density": K("kg/m3", "density"),
    "material[].E": K("Pa", "Young's modulus (deformable blocks, dof = 12)"),
    "material[].nu": K("-", "Poisson's ratio (deformable blocks)"),
    "contact_pair": K("", "[[contact_pair]]: the law between two materials (other keys as [contact], defaults "
                          "from it)"),
    "contact_pair[].materials": K("", "the two material names", type="list of 2 strings"),
    **{f"contact_pair[].{k}": K(v["unit"], v["meaning"], default=f"[contact] {k}") for k, v in _LAW.items()},
    "block": K("", "[[block]]: one block: shape + size, vertices + faces, or file"),
    "block[].name": K("", "block name ([[load]], [[report]])", default='"block[k]"'),
    "block[].fixed": K("", "the block does not move"),
    "block[].material": K("", "[[material]] name (\"rock\": the defaults 2600 kg/m3, E = 1e10 Pa, nu = 0.25)"),
    "block[].velocity": K("m/s", "initial velocity (prescribed: the velocity it keeps)"),
    "block[].angular_velocity": K("rad/s", "initial angular velocity"),
    "block[].prescribed": K("", "move at the given velocity / angular velocity whatever the forces"),
    "block[].force": K("N", "constant body load [fx, fy, fz] at the centroid"),
    "block[].dof": K("-", "6: rigid; 12: deformable (six constant strains, E and nu of its material)",
                     absent="6"),
    "block[].shape": K("", "library shape (dda/shapes.py), with size (one of shape, vertices + faces, file)"),
    "block[].size": K("m", "shape: edge length (the shape's characteristic size)"),
    "block[].center": K("m", "shape: centroid [x, y, z]"),
    "block[].rotation_axis": K("-", "shape: rotation axis (any length), with rotation_angle"),
    "block[].rotation_angle": K("deg", "shape: rotation about rotation_axis", absent="no rotation"),
    "block[].width": K("m", "brick: width", absent="the shape's own (dda/shapes.py)"),
    "block[].height": K("m", "brick, prism: height", absent="the shape's own (dda/shapes.py)"),
    "block[].sides": K("-", "prism: number of sides (3 .. 64)", absent="the shape's own (dda/shapes.py)"),
    "block[].vertices": K("m", "vertices, with faces"),
    "block[].faces": K("-", "0-based vertex indices of each face (>= 3), counter-clockwise seen from outside",
                       type="list of integer lists"),
    "block[].file": K("", "convex mesh file (any meshio format), relative to the scene"),
    "generate": K("", "[[generate]]: blocks made by a generator: kind and its parameters (see below)",
                  type="array of tables"),
    "load": K("", "[[load]]: a constant point load on a block"),
    "load[].block": K("", "name of the loaded block"),
    "load[].force": K("N", "force [fx, fy, fz] in world axes"),
    "load[].point": K("m", "point of application (world, initial pose)", absent="the centroid"),
    "spheres": K("", "bonded spheres of an sgim model, stepped with the blocks (dda/spheres.py)"),
    "spheres.model": K("", "an sgim model.npz or an sgim scene .toml (built in memory), relative to the scene"),
    "spheres.density": K("kg/m3", "sphere density"),
    "spheres.fixed": K("", "regions of fixed spheres, e.g. [\"z>2.6\"]"),
    "spheres.fixed_below": K("deg, deg, m, m, m", "[dip, dip_direction, x, y, z] rows: spheres below any of these "
                                                  "planes are fixed", absent="none"),
    "spheres.bond_young": K("Pa", "bond Young's modulus (normal stiffness E A / L); or bond_kn / bond_ks"),
    "spheres.bond_kn": K("N/m", "bond normal stiffness, instead of bond_young", absent="from bond_young"),
    "spheres.bond_ks": K("N/m", "bond shear stiffness (0: central bonds)", absent="bond_shear_ratio x normal"),
    "spheres.bond_shear_ratio": K("-", "bond shear / normal stiffness (0: central bonds, the normal spring only)"),
    "spheres.bond_tensile": K("Pa", "bond tensile strength (inf: unbreakable)"),
    "spheres.bond_shear": K("Pa", "bond shear strength (inf: unbreakable)"),
    "spheres.bond_damping": K("-", "bond damping, ratio of critical"),
    "spheres.bond_radius_factor": K("-", "bond radius as a factor of the smaller sphere radius"),
    "spheres.smooth_joints": K("", "pairs the model cuts by a zero-thickness joint slide on the joint plane"),
    "spheres.joint_friction": K("deg", "friction of the smooth joints", absent="[contact] friction"),
    "spheres.liggghts_joints": K("", "LIGGGHTS decks only (no smooth joint there): \"contact\" = joint pairs are "
                                     "plain contacts, \"open\" = no contact between green and blue spheres (exact "
                                     "while the joints stay open; closing joints pass through)"),
    "spheres.load": K("", "[[spheres.load]]: loaded regions of spheres"),
    "spheres.load[].region": K("", "\"z>2.6\" or a list of such cuts, all of which must hold (or below)",
                               type="string or list of strings"),
    "spheres.load[].below": K("deg, deg, m, m, m", "[dip, dip_direction, x, y, z]: the spheres below this plane "
                                                   "(or region)"),
    "spheres.load[].force": K("N", "constant force [fx, fy, fz] on EACH sphere of the region (or velocity)"),
    "spheres.load[].velocity": K("m/s", "prescribed velocity [vx, vy, vz] of the region's spheres (or force)"),
    "report": K("", "[[report]]: the answers the run states at its end and in summary.json (dda/answers.py)"),
    "report[].quantity": K("", "displacement, velocity, rotation, shortening, max_displacement, moved, "
                               "bonds_broken, detached, energy_error (units m, m/s, deg, m, m, -, -, -, J)"),
    "report[].block": K("", "block name (block quantities); a pattern such as \"brick_*\" for max_displacement "
                            "and moved", absent="none"),
    "report[].region": K("", "sphere runs: cuts like \"x>1.8\" (all must hold) whose spheres are measured",
                         type="string or list of strings", absent="none"),
    "report[].component": K("", "x, y, z or magnitude (displacement, velocity); x, y or z (shortening)",
                            default='"magnitude" (shortening: "z")'),
    "report[].reference": K("unit of the quantity", "the run states the error against it", absent="none"),
    "report[].label": K("", "the name printed", default="the quantity and its block"),
    "report[].above": K("m", "moved: count bodies that moved more than this"),
    "output": K("", "the files dda run writes"),
    "output.formats": K("", "drawn from npz, csv, vtu, png"),
    "render": K("", "the picture final.png"),
    "render.width": K("px", "picture width"),
    "render.height": K("px", "picture height"),
}

# [[generate]] parameters: unit and meaning (defaults come from the generator's signature)
_MAT = K("", "material of the blocks")
GENERATOR_PARAMS = {
    "incline": {
        "angle": K("deg", "slope angle; the slope descends toward +x"),
        "size": K("m", "block edge along and across the slope"),
        "height": K("m", "block height (none: size / 2)"),
        "base_length": K("m", "length of the fixed base"),
        "base_thickness": K("m", "thickness of the fixed base"),
        "position": K("m", "block centre along the slope, from the base's middle"),
        "material": _MAT,
        "base_material": K("", "material of the base (none: material)"),
    },
    "wedge": {
        "joint_a": K("deg", "[dip, dip_direction] of joint A"),
        "joint_b": K("deg", "[dip, dip_direction] of joint B"),
        "face": K("deg", "[dip, dip_direction] of the slope face"),
        "top": K("deg", "[dip, dip_direction] of the top surface"),
        "height": K("m", "wedge height"),
        "margin": K("-", "box around the wedge for the fixed blocks, as a factor of the wedge size"),
        "material": _MAT,
        "crease": K("-", "thin void between below_ab and the line of intersection, as a factor of the wedge size"),
    },
    "toppling": {
        "b": K("m", "column width down the slope"),
        "h": K("m", "column height"),
        "alpha": K("deg", "base inclination (descending toward +x)"),
        "depth": K("m", "column depth across the slope (none: b)"),
        "base_length": K("m", "base length (none: 4 (b + h))"),
        "base_thickness": K("m", "base thickness (none: max(b, h) / 2)"),
        "material": _MAT,
    },
    "brick_wall": {
        "layers": K("-", "brick layers"),
        "per_layer": K("-", "bricks per layer (along y)"),
        "brick": K("m", "[length, thickness, height] of a brick"),
        "ramp_angle": K("deg", "inclination of the fixed ramp"),
        "gap": K("m", "gap between the ramp's lower end and the wall"),
        "run": K("m", "slope length from the ramp's lower end to the projectile"),
        "projectile": K("m", "edge of the cube projectile"),
        "projectile_velocity": K("m/s", "initial speed of the projectile down the ramp"),
        "hit_height": K("m", "height of the ramp's lower end (none: 0.6 x the wall height)"),
        "material": _MAT,
        "brick_material": K("", "material of the bricks (none: material)"),
        "projectile_material": K("", "material of the projectile (none: material)"),
    },
    "falling_polyhedra": {
        "n": K("-", "number of falling blocks"),
        "size": K("m", "edge of the shapes"),
        "seed": K("-", "random seed (shapes, orientations, jitter)"),
        "spacing": K("-", "cell size 2 R (1 + spacing), R the largest circumradius"),
        "jitter": K("-", "random shift of each cell, fraction of the free space (0 .. 1)"),
        "clearance": K("m", "height of the lowest layer above the floor"),
        "side": K("-", "columns per side of the grid (none: ceil(n^(1/3)))"),
        "shapes": K("", "shapes drawn from (dda/shapes.py)"),
        "material": _MAT,
        "floor_margin": K("m", "floor margin around the grid (none: a quarter of the grid's span)"),
    },
    "stack": {
        "n": K("-", "number of stacked boxes"),
        "size": K("m", "box width"),
        "height": K("m", "box height (none: size / 2)"),
        "offset": K("-", "shift of each box along x, fraction of size (alternating sign)"),
        "material": _MAT,
    },
    "box_cut": {
        "lo": K("m", "lower corner of the box"),
        "hi": K("m", "upper corner of the box"),
        "joint_sets": K("deg, m", "tables {dip, dip_direction, spacing, origin = [0, 0, 0], extent = none, name}"),
        "planes": K("-, m", "tables {normal, point} or {dip, dip_direction, point}"),
        "floor": K("", "add a fixed floor under the box"),
        "sliver": K("", "what becomes of sliver pieces (dda/cut.py)"),
        "material": _MAT,
    },
}


def generator_params():
    """{kind: [(parameter, default shown)]} from the signatures of GENERATORS."""
    out = {}
    for kind, fn in GENERATORS.items():
        sig = inspect.signature(fn).parameters
        out[kind] = [(p, show(sig[p].default) if sig[p].default is not sig[p].empty else "required")
                     for p in generator_parameters(fn)]
    return out


def render_generators(level="###"):
    lines = []
    for kind, params in generator_params().items():
        doc = (GENERATORS[kind].__doc__ or "").strip().split("\n")[0].rstrip(".").replace(" (see module docstring)",
                                                                                           "")
        lines += [f"{level} [[generate]] kind = \"{kind}\"", "", doc + ".", "",
                  "| parameter | default | unit | meaning |", "|---|---|---|---|"]
        for p, default in params:
            m = GENERATOR_PARAMS[kind][p]
            lines.append(f"| `{p}` | {default} | {m['unit']} | {m['meaning']} |")
        lines.append("")
    return "\n".join(lines)


_BEAM = """[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 0.2, 0.2]\n[packing]\nkind = "cubic"\nradius = 0.05\n"""


def dda_scenes():
    """Small valid DDA scenes that, together, give every key the reader allows (files: write_scene_files and
    beam.toml)."""
    sim = {"duration": 0.1, "dt": 1e-4, "safety": 0.5, "gravity": [0, 0, -9.81], "local_damping": 0.0,
           "record_every": 0.01, "frames": 2, "sleep": True, "sleep_velocity": 1e-4, "sleep_accel": 1e-3,
           "sleep_steps": 100, "max_steps": 100000}
    law = {"kn": 1e9, "ks": 5e8, "friction": 30.0, "cohesion": 0.0, "tensile": 0.0, "damping": 0.1}
    blocks = {
        "name": "all block keys", "description": "every block key", "simulation": sim, "contact": law,
        "material": [{"name": "granite", "density": 2700.0, "E": 5e10, "nu": 0.2},
                     {"name": "joint", "density": 2600.0}],
        "contact_pair": [{"materials": ["granite", "joint"], **law}],
        "block": [{"name": "floor", "shape": "brick", "size": 4.0, "width": 4.0, "height": 0.5,
                   "center": [0, 0, -0.25], "fixed": True},
                  {"name": "cube", "shape": "cube", "size": 1.0, "center": [0, 0, 1], "rotation_axis": [0, 0, 1],
                   "rotation_angle": 10.0, "velocity": [0, 0, -1], "angular_velocity": [0, 0, 0.1],
                   "force": [0, 0, -10.0], "material": "granite", "dof": 12},
                  {"name": "tet", "vertices": [[5, 5, 0], [6, 5, 0], [5, 6, 0], [5, 5, 1]],
                   "faces": [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], "material": "joint"}],
        "load": [{"block": "cube", "force": [1.0, 0, 0], "point": [0, 0, 1.5]}, {"block": "tet", "force": [0, 0, 1]}],
        "report": [{"quantity": "displacement", "block": "cube", "component": "z", "reference": 0.1,
                    "label": "drop"},
                   {"quantity": "moved", "block": "t*", "above": 0.01}],
        "output": {"formats": ["npz", "csv"]}, "render": {"width": 640, "height": 480},
    }
    spheres = {
        "simulation": {"duration": 0.1, "viscous_damping": "critical"}, "limits": {"max_steps": 100000},
        "contact": {"kn": 1e7, "friction": 30.0},
        "spheres": {"model": "beam.toml", "density": 2600.0, "fixed": ["x<0.1"], "bond_young": 1e9,
                    "bond_kn": 1e6, "bond_ks": 5e5, "bond_shear_ratio": 0.4, "bond_tensile": 1e6, "bond_shear": 1e6,
                    "bond_damping": 0.1, "bond_radius_factor": 1.0, "smooth_joints": True, "joint_friction": 20.0,
                    "liggghts_joints": "open",
                    "fixed_below": [[0, 0, 0, 0, -1]],
                    "load": [{"region": ["x>0.1", "x<0.4"], "force": [0, 0, -1.0]},
                             {"below": [90, 270, 0.6, 0, 0], "velocity": [0, 0, -0.1]}]},
        "block": [{"name": "cube", "shape": "cube", "size": 0.2, "center": [0.5, 0.1, 0.5]}],
        "report": [{"quantity": "displacement", "region": "x>0.9", "component": "z"},
                   {"quantity": "bonds_broken"}],
    }
    forms = {"simulation": {"duration": 0.1}, "contact": {"kn": 1e9},
             "block": [{"name": "prism", "shape": "prism", "size": 0.5, "sides": 6, "center": [3, 3, 3],
                        "prescribed": True, "velocity": [0, 0, -1]},
                       {"name": "box", "file": "box.obj", "fixed": True}],
             "generate": [{"kind": "stack", "n": 1}]}
    viscous = copy.deepcopy(spheres)
    viscous["simulation"]["viscous_damping"] = 0.5
    del viscous["limits"]
    return {"blocks": blocks, "block_forms": forms, "spheres": spheres, "spheres_viscous": viscous}


def record_dda(record, folder, case_files=(), synthetic=True):
    """Record the DDA reader over the synthetic scenes (files written into `folder`; each also read without each
    of its keys; not when `synthetic` is false) and over `case_files` (DDA scene files)."""
    write_scene_files(folder)
    (Path(folder) / "beam.toml").write_text(_BEAM)
    for name, data in (dda_scenes() if synthetic else {}).items():
        record.read(scene_from_dict, data, Path(folder) / f"{name}.toml", required=True)
    for f in case_files:
        record.read(scene_from_dict, tomllib.loads(Path(f).read_text(encoding="utf-8")), f)
