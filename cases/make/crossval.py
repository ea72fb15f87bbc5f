"""Author the cross-validation scenes in cases/scenes/crossval/ (sgim models and the DDA scenes that run them).

    python -m cases.make.crossval        # rewrites cases/scenes/crossval/*.toml

- hang_{intact,fault,joint,small_joint}: a 1.0 x 0.6 x 1.2 m block of bonded FCC spheres (r = 0.05) hanging
  from its fixed top layer under gravity; a 0.12 m fault layer, a through-going joint, or a small interior joint.
- column: a 0.3 x 0.3 x 1.5 m FCC column (r = 0.05) hanging from its top, bonds as central springs (shear ratio
  0), heavily damped: the static elongation against the exact solution of the spring network.
- rocking: a 0.12 x 0.12 x 0.2 m block of FCC spheres (r = 0.015, central bonds) cut by a horizontal
  zero-thickness joint at z = 0.07, its base fixed, pushed sideways at its top: the heel of the smooth joint
  opens in the first swing and closes again as local damping brings the block to rest.
- beam_joint, beam_settle: a 1.2 x 0.12 x 0.12 m FCC cantilever (r = 0.015, central bonds) fixed at x < 0.04:
  cut by a vertical joint through the lattice's centres at x = 0.6 (the part beyond it detaches; LIGGGHTS decks
  drop the contact across the joint, [spheres] liggghts_joints = "open"), and intact,
  damped by [simulation] viscous_damping = "critical" alone (LIGGGHTS' fix viscous, in-house -c v): its static
  sag.
- shear_beam: a 0.36 x 0.12 x 0.12 m simple-cubic cantilever (r = 0.015, normal + shear bonds, ks = 0.1 kn) fixed
  at x < 0.03, heavily damped: its static tip sag against the 6-DOF solution of the network (a mechanism with
  central bonds alone).
- wedge: the paper's wedge (joints 45/005 and 55/135, face 65/065, height 10 m) as FCC spheres (r = 0.5): the
  wedge's spheres bonded, the rock behind the joints fixed, the joints smooth: the friction at which it starts to
  slide against Hoek & Bray and the DDA block wedge.
- planar: a 1.2 x 0.4 m block of bonded FCC spheres (r = 0.05), 0.3 m thick, on one joint dipping 35 deg (no
  cohesion, no water), the rock below it fixed, the joint smooth: the friction at which it starts to slide
  against Hoek & Bray's tan phi_c = tan psi.
"""
from __future__ import annotations

import numpy as np

from cases import SCENES

# dda is imported inside half_spaces() and wedge_cavities() only: the other generators and the modules that read
# this one's constants (cases/lib/crossval.py) load no DDA engine.

HERE = SCENES / "crossval"

HANG_VARIANTS = {
    "intact": [],
    "fault": [dict(name="fault", centre=[0.5, 0.3, 0.5], dip=10.0, dip_direction=90.0, radius=2.0,
                   thickness=0.12)],
    "joint": [dict(name="joint", centre=[0.5, 0.3, 0.6], dip=30.0, dip_direction=90.0, radius=2.0,
                   thickness=0.0)],
    "small_joint": [dict(name="small joint", centre=[0.5, 0.3, 0.6], dip=30.0, dip_direction=90.0,
                         radius=0.15, thickness=0.0)],
}
ROCKING_JOINT = [dict(name="joint", centre=[0.06, 0.06, 0.07], dip=0.0, dip_direction=0.0, radius=1.0,
                      thickness=0.0)]
BEAM_JOINT = [dict(name="joint", centre=[0.6, 0.06, 0.06], dip=90.0, dip_direction=90.0, radius=1.0,
                   thickness=0.0)]
WEDGE = dict(joint_a=(45.0, 5.0), joint_b=(55.0, 135.0), face=(65.0, 65.0), height=10.0, radius=0.5, margin=1.6,
             rock=1.5)
# planar sliding: a joint dipping 35 deg towards +x through `point`; the block is the rock within `thickness` above
# it (measured along its normal), the fixed rock a layer `rock` thick below it; the domain's vertical faces at
# x = lo and x = hi are the dry tension crack and the slope face where the joint daylights
PLANAR = dict(dip=35.0, dip_direction=90.0, point=(0.5, 0.0, 0.64), thickness=0.3, rock=0.2, radius=0.05,
              lo=(0.0, 0.0, 0.0), hi=(1.2, 0.4, 1.4))


def _fmt(v):
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)


def _table(name, d, array=False):
    head = f"[[{name}]]" if array else f"[{name}]"
    return "\n".join([head] + [f"{k} = {_fmt(v)}" for k, v in d.items()]) + "\n"


def sgim_scene(name, comment, lo, hi, radius, discs=(), cavities=(), rule="colour", kind="fcc"):
    parts = [f"# {comment}\n# Written by cases/make/crossval.py.\n", f'name = "{name}"\n',
             _table("domain", {"min": list(lo), "max": list(hi)}),
             _table("packing", {"kind": kind, "radius": radius}), _table("bonds", {"rule": rule})]
    parts += [_table("discontinuity", d, True) for d in discs]
    parts += [_table("cavity", c, True) for c in cavities]
    return "\n".join(parts)


def dda_scene(name, comment, model, simulation, contact, spheres):
    return "\n".join([f"# {comment}\n# Written by cases/make/crossval.py.\n", f'name = "{name}"\n',
                      _table("simulation", simulation), _table("contact", contact),
                      _table("spheres", {"model": model, **spheres})])


def half_spaces(lo, hi, planes):
    """[[cavity]] tables of half-spaces: each (name, (normal, offset)) is the part of a box 5 m larger than the
    domain (lo, hi) where normal . x <= offset, triangulated."""
    from dda.cut import clip
    from dda.shapes import box

    big = box(np.asarray(lo) - 5.0, np.asarray(hi) + 5.0)
    out = []
    for name, plane in planes:
        piece = clip(big, plane)
        tri = [[p[0], p[k], p[k + 1]] for p in piece.faces for k in range(1, len(p) - 1)]
        out.append(dict(name=name, vertices=np.round(piece.vertices, 9).tolist(), faces=tri))
    return out


def wedge_cavities():
    """Closed surfaces of what the wedge model leaves out: the air in front of the slope face, and the rock
    deeper than ``rock`` below either joint (the fixed rock is a layer under the joints)."""
    from dda import hoekbray

    w = WEDGE
    a, b, f, t, dt, verts = hoekbray.wedge_geometry(w["joint_a"], w["joint_b"], w["face"], None, w["height"])
    lo = verts.min(0) - w["margin"]
    hi = verts.max(0) + w["margin"]
    hi[2] = verts[:, 2].max()
    return lo, hi, half_spaces(lo, hi, (("air", (-f, 0.0)), ("deep rock A", (a, -w["rock"])),
                                        ("deep rock B", (b, -w["rock"]))))


def planar_normal():
    """The planar case's joint: its upward unit normal and its down-dip unit vector."""
    d, a = np.radians(PLANAR["dip"]), np.radians(PLANAR["dip_direction"])
    normal = np.array([np.sin(d) * np.sin(a), np.sin(d) * np.cos(a), np.cos(d)])
    down = np.array([np.cos(d) * np.sin(a), np.cos(d) * np.cos(a), -np.sin(d)])
    return normal, down


def planar_cavities():
    """The planar case's domain (lo, hi) and the closed surfaces it leaves out: the air more than ``thickness``
    above the joint (measured along its normal) and the rock deeper than ``rock`` below it."""
    p = PLANAR
    n, _ = planar_normal()
    lo, hi = np.array(p["lo"], float), np.array(p["hi"], float)
    d = float(n @ np.asarray(p["point"], float))
    return lo, hi, half_spaces(lo, hi, (("air", (-n, -(d + p["thickness"]))), ("deep rock", (n, d - p["rock"]))))


def write_all(folder=HERE):
    folder.mkdir(exist_ok=True)
    files = {}
    sim = {"duration": 0.15, "record_every": 0.005, "local_damping": 0.2, "frames": 1}
    for var, discs in HANG_VARIANTS.items():
        files[f"hang_{var}_model.toml"] = sgim_scene(
            f"hang_{var}_model", f"Hanging block ({var.replace('_', ' ')}): bonded FCC spheres, r = 0.05.",
            (0.0, 0.0, 0.0), (1.0, 0.6, 1.2), 0.05, discs)
        files[f"hang_{var}.toml"] = dda_scene(
            f"hang_{var}", "The block hangs from its fixed top layer (z > 1.1) under gravity for 0.15 s: the "
            "spheres that no bond path ties to the top fall (0.11 m), the rest hold.",
            f"hang_{var}_model.toml", sim, {"kn": 1e7, "ks": 5e6, "friction": 30.0},
            {"density": 2600.0, "fixed": ["z>1.1"], "bond_young": 1e8})
    files["column_model.toml"] = sgim_scene("column_model", "A 0.3 x 0.3 x 1.5 m column of bonded FCC spheres.",
                                            (0.0, 0.0, 0.0), (0.3, 0.3, 1.5), 0.05)
    files["column.toml"] = dda_scene(
        "column", "The column hangs from its fixed top (z > 1.4); bonds are central springs (shear ratio "
        "0); local damping 0.7 brings it to rest: its static elongation against the spring network's exact "
        "solution.", "column_model.toml", {"duration": 0.3, "record_every": 0.01, "local_damping": 0.7,
                                            "frames": 1},
        {"kn": 1e7, "ks": 5e6, "friction": 30.0},
        {"density": 2600.0, "fixed": ["z>1.4"], "bond_young": 1e8, "bond_shear_ratio": 0.0})
    files["rocking_model.toml"] = sgim_scene(
        "rocking_model", "A 0.12 x 0.12 x 0.2 m block of bonded FCC spheres (r = 0.015) cut by a horizontal joint "
        "at z = 0.07.", (0.0, 0.0, 0.0), (0.12, 0.12, 0.2), 0.015, ROCKING_JOINT)
    files["rocking.toml"] = dda_scene(
        "rocking", "The block's base (z < 0.03) is fixed, the joint smooth (friction 40 deg), bonds central springs; "
        "0.25 N on each top sphere (z > 0.155) rocks the upper part: the heel of the joint opens in the first "
        "swing and closes again, local damping 0.4 brings it to rest. In-house and YADE keep each joint pair's "
        "reference gap while it is open (the same smooth-joint rule).", "rocking_model.toml",
        {"duration": 0.06, "record_every": 0.001, "local_damping": 0.4, "frames": 1},
        {"kn": 1e6, "ks": 5e5, "friction": 30.0},
        {"density": 2600.0, "fixed": ["z<0.03"], "bond_young": 1e8, "bond_shear_ratio": 0.0, "smooth_joints": True,
         "joint_friction": 40.0}) + "\n" + _table("spheres.load", {"region": "z>0.155", "force": [0.25, 0.0, 0.0]},
                                                  True)
    beam_sim = {"kn": 1e6, "ks": 5e5, "friction": 30.0}
    beam_spheres = {"density": 2600.0, "fixed": ["x<0.04"], "bond_shear_ratio": 0.0}
    files["beam_model.toml"] = sgim_scene("beam_model", "A 1.2 x 0.12 x 0.12 m beam of bonded FCC spheres, r = 0.015.",
                                          (0.0, 0.0, 0.0), (1.2, 0.12, 0.12), 0.015)
    files["beam_joint_model.toml"] = sgim_scene(
        "beam_joint_model", "The beam cut by a vertical joint at x = 0.6, through lattice centres (they are green: "
        "on the joint).", (0.0, 0.0, 0.0), (1.2, 0.12, 0.12), 0.015, BEAM_JOINT)
    files["beam_joint.toml"] = dda_scene(
        "beam_joint", "The jointed beam, fixed at x < 0.04, under gravity for 0.06 s: the 293 spheres beyond the "
        "joint fall (no bond ties them to the fixed end), the rest hold. LIGGGHTS (no smooth joint) drops the "
        "contact across the joint (liggghts_joints = \"open\"): as plain contacts the spheres beyond it nest in "
        "the lattice pockets across it and hang.", "beam_joint_model.toml",
        {"duration": 0.06, "record_every": 0.002, "frames": 1}, beam_sim, {**beam_spheres, "liggghts_joints": "open"})
    files["beam_settle.toml"] = dda_scene(
        "beam_settle", "The intact beam damped by viscous damping at the critical ratio of its first mode "
        "(LIGGGHTS' fix viscous, the in-house engine's force -c v; YADE has no such damping and lists it): after "
        "0.3 s (16 / omega_1) its sag is the static one.", "beam_model.toml",
        {"duration": 0.3, "record_every": 0.01, "viscous_damping": "critical", "frames": 1}, beam_sim,
        beam_spheres)
    files["shear_beam_model.toml"] = sgim_scene(
        "shear_beam_model", "A 0.36 x 0.12 x 0.12 m cantilever of bonded simple-cubic spheres, r = 0.015 (12 x 4 x 4).",
        (0.0, 0.0, 0.0), (0.36, 0.12, 0.12), 0.015, kind="cubic")
    files["shear_beam.toml"] = dda_scene(
        "shear_beam", "The cubic cantilever fixed at its first layer (x < 0.03), normal + shear bonds (ks = 0.1 kn), "
        "under gravity; local damping 0.7 brings it to rest: its tip sag against the static solution of the network "
        "with six degrees of freedom per sphere (cases/lib/crossval_shear.py). With central bonds alone the lattice "
        "is a mechanism: the shear springs and the rotations they couple carry it.", "shear_beam_model.toml",
        {"duration": 0.15, "record_every": 0.005, "local_damping": 0.7, "frames": 1},
        {"kn": 1e7, "ks": 5e6, "friction": 30.0},
        {"density": 2600.0, "fixed": ["x<0.03"], "bond_young": 1e9, "bond_shear_ratio": 0.1})
    lo, hi, cavities = wedge_cavities()
    w = WEDGE
    discs = [dict(name=f"joint {n}", centre=[0.0, 0.0, 0.0], dip=d[0], dip_direction=d[1], radius=60.0,
                  thickness=0.0) for n, d in (("A", w["joint_a"]), ("B", w["joint_b"]))]
    files["wedge_model.toml"] = sgim_scene(
        "wedge_model", "The paper's wedge (joints A 45/005, B 55/135, face 65/065, height 10 m) in FCC spheres, "
        "r = 0.5; the air in front of the face and the rock deeper than 1.5 m below the joints are cavities. "
        "Geometric bond rule: near the line of intersection a sphere is on one side of each joint, and only the "
        "pair's own crossing decides (with the colour rule, a single colour per sphere keeps 31 bonds across A "
        "where both spheres lie on the same side of B).", np.round(lo, 6).tolist(), np.round(hi, 6).tolist(),
        w["radius"], discs, cavities, rule="geometric")
    files["wedge.toml"] = dda_scene(
        "wedge", "The wedge's spheres are bonded; the rock below either joint is fixed; the joints are smooth. "
        "At joint friction 18 deg (below the critical 19.7 deg) it slides; `cases crossval` finds the onset.",
        "wedge_model.toml", {"duration": 1.2, "record_every": 0.02, "local_damping": 0.1, "frames": 1},
        {"kn": 1e9, "ks": 5e8, "friction": 30.0},
        {"density": 2600.0, "bond_young": 1e9, "fixed_below": [[*w["joint_a"], 0.0, 0.0, 0.0],
                                                               [*w["joint_b"], 0.0, 0.0, 0.0]],
         "smooth_joints": True, "joint_friction": 18.0})
    lo, hi, cavities = planar_cavities()
    p = PLANAR
    files["planar_model.toml"] = sgim_scene(
        "planar_model", f"Planar sliding: a block of FCC spheres (r = {p['radius']:g}) on one joint dipping "
        f"{p['dip']:g} deg towards +x ({p['dip']:g}/{p['dip_direction']:03.0f}) through {list(p['point'])}. The joint "
        "crosses the lattice, not along a lattice plane: the block's spheres on it sit 0.08 r to 1.8 r above it (a "
        "stepped face); a smooth joint acts along the joint's normal all the same. The block is the rock within "
        f"{p['thickness']:g} m "
        f"above the joint (along its normal), the rock deeper than {p['rock']:g} m below it is a cavity, and so "
        f"is the air above the block. The domain's vertical faces at x = {lo[0]:g} and x = {hi[0]:g} are a dry tension "
        "crack and the slope face in which the joint daylights. The block's base along the dip is about five times "
        "its thickness (b / h > tan psi: it slides, it cannot topple).", lo.tolist(), hi.tolist(), p["radius"],
        [dict(name="joint", centre=list(p["point"]), dip=p["dip"], dip_direction=p["dip_direction"], radius=10.0,
              thickness=0.0)], cavities, rule="geometric")
    files["planar.toml"] = dda_scene(
        "planar", f"The block's spheres are bonded; the rock below the joint is fixed; the joint is smooth, with no "
        f"cohesion and no water: Hoek & Bray's FS = tan(phi) / tan(psi), so the block starts to slide where the "
        f"joint friction equals the dip, {p['dip']:g} deg; `cases crossval` finds the onset (here it slides, at "
        "30 deg). The block lands on the joint with its springs unloaded and bounces; local damping 0.7 stills it "
        "(at 0.1 the bouncing let it creep down at 37 deg, above the dip), 0.3 s per trial.", "planar_model.toml",
        {"duration": 0.3, "record_every": 0.01, "local_damping": 0.7, "frames": 1},
        {"kn": 1e7, "ks": 5e6, "friction": 30.0},
        {"density": 2600.0, "bond_young": 1e8, "fixed_below": [[p["dip"], p["dip_direction"], *p["point"]]],
         "smooth_joints": True, "joint_friction": 30.0})
    files["block_wedge.toml"] = "\n".join([
        "# The paper's wedge as one DDA block on three fixed blocks at friction 10 deg, well below the critical\n"
        "# 19.7 deg: it slides 1/2 g sin(psi5) (1 - tan(phi) / tan(phi_c)) t^2 along the line of intersection.\n"
        "# (At 18 deg the distance is ill-conditioned: 1 % on tan(phi_c) is 10 % on the acceleration.)\n"
        "# Written by cases/make/crossval.py.\n", 'name = "block_wedge"\n',
        _table("simulation", {"duration": 1.0, "safety": 0.5, "record_every": 0.01, "frames": 1}),
        _table("contact", {"kn": 1e10, "friction": 10.0, "damping": 0.1}),
        _table("material", {"name": "rock", "density": 2600.0}, True),
        _table("generate", {"kind": "wedge", "joint_a": list(w["joint_a"]), "joint_b": list(w["joint_b"]),
                            "face": list(w["face"]), "height": w["height"]}, True)])
    for name, text in files.items():
        (folder / name).write_text(text)
    return sorted(files)


if __name__ == "__main__":
    for name in write_all():
        print(HERE / name)
