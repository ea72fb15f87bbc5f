"""The answers a run states: the quantities a scene declares in ``[[report]]`` tables, with the error against a
reference where the scene gives one.

``dda run`` prints them as its last lines and writes them to ``summary.json`` (``"answers"``)::

    [[report]]
    quantity = "displacement"   # see QUANTITIES
    block = "block"             # the block it is measured on (block quantities)
    component = "x"             # x, y, z or "magnitude" (the default; shortening: z)
    reference = 0.9064          # optional: the run states value, reference and relative error
    label = "slide distance"    # optional: the name printed (default: the quantity and its block)

A scene without ``[[report]]`` states the largest displacement and how many bodies moved (and, with spheres, the
broken bonds and the detached spheres).
"""
from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass

import numpy as np

from .regions import read_region_cuts, region_mask

# quantity -> (unit, what it is, where it applies: "block" needs a named block, "any" a block or sphere run,
# "spheres" a sphere run)
QUANTITIES = {
    "displacement": ("m", "final minus initial centroid of the block (or mean of a sphere region)", "body"),
    "velocity": ("m/s", "final velocity of the block (or mean of a sphere region)", "body"),
    "rotation": ("deg", "angle of the block's rotation from its initial orientation", "block"),
    "shortening": ("m", "decrease of the block's extent along the component (default z): deformable blocks",
                   "block"),
    "max_displacement": ("m", "largest displacement of a moving block or free sphere", "any"),
    "moved": ("", "blocks (or free spheres) that moved more than `above` m (default 1e-3)", "any"),
    "bonds_broken": ("", "bonds broken during the run", "spheres"),
    "detached": ("", "free spheres that no path of intact bonds joins to a fixed sphere", "spheres"),
    "energy_error": ("J", "energy balance error at the end of the run", "any"),
}
REPORT_KEYS = {"quantity", "block", "region", "component", "reference", "label", "above"}
COMPONENTS = ("x", "y", "z", "magnitude")


@dataclass
class Report:
    quantity: str
    label: str
    block: str | None = None  # a block name, or a pattern (fnmatch) for max_displacement / moved
    region: object = None  # sphere runs: cuts like "x>1.1" (all must hold)
    component: str = "magnitude"
    reference: float | None = None
    above: float = 1e-3

    @property
    def unit(self):
        return QUANTITIES[self.quantity][0]


def read_reports(rd, data, block_names, spheres):
    """The [[report]] tables of a scene (SceneError on a bad one); `block_names` the scene's blocks,
    `spheres` whether the scene has [spheres]."""
    out = []
    tabs = rd.list_of_tables(data, "report")
    for k, t in enumerate(tabs):
        key = f"report[{k}]"
        rd.known(t, REPORT_KEYS, key)
        q = rd.string(t, "quantity", f"{key}.quantity", "")
        if q not in QUANTITIES:
            rd.err(f"{key}.quantity", q, f"must be one of {', '.join(QUANTITIES)}")
        where = QUANTITIES[q][2]
        if where == "spheres" and not spheres:
            rd.err(f"{key}.quantity", q, "applies to runs with [spheres] only")
        block = rd.string(t, "block", f"{key}.block", "") or None
        region = t.get("region")
        if region is not None:
            if not spheres or where not in ("body", "any"):
                rd.err(f"{key}.region", region, "a sphere region applies to displacement, velocity, "
                                                "max_displacement and moved of runs with [spheres]")
            region = read_region_cuts(rd, region, f"{key}.region")
        if where in ("block", "body") and region is None:
            if block is None:
                rd.err(f"{key}.block", None, f"{q} is measured on a block: name it (block = \"...\")"
                       + (" or a sphere region (region = \"x>1\")" if where == "body" and spheres else ""))
            if block not in block_names:
                rd.err(f"{key}.block", block, f"no block of that name (have: {_names(block_names)})")
        elif block is not None and where == "any":
            if not fnmatch.filter(block_names, block):
                rd.err(f"{key}.block", block, f"matches no block (have: {_names(block_names)})")
        elif block is not None:
            rd.err(f"{key}.block", block, f"{q} is not measured on a block")
        component = rd.string(t, "component", f"{key}.component", "z" if q == "shortening" else "magnitude")
        if component not in COMPONENTS or (component != "magnitude" and q not in
                                           ("displacement", "velocity", "shortening")):
            rd.err(f"{key}.component", component, f"must be one of {', '.join(COMPONENTS)} (displacement and "
                                                  "velocity), x, y or z (shortening)")
        if q == "shortening" and component == "magnitude":
            rd.err(f"{key}.component", component, "shortening is along x, y or z")
        ref = rd.number(t, "reference", f"{key}.reference") if "reference" in t else None
        above = rd.number(t, "above", f"{key}.above", default=1e-3, positive=True, unit=" m")
        label = rd.string(t, "label", f"{key}.label", "") or _label(q, block, region, component, above)
        out.append(Report(q, label, block, region, component, ref, above))
    return out


NAMES = {"max_displacement": "largest displacement", "bonds_broken": "bonds broken",
         "detached": "detached spheres", "energy_error": "energy balance error"}


def _label(q, block, region, component, above):
    """The default name of an answer: 'displacement x of cube', 'bodies moved more than 0.01 m', ..."""
    where = block or ("region " + " & ".join(region_text(region)) if region else "")
    if q == "moved":
        return f"{'bodies' if not where else where} moved more than {above:g} m"
    name = NAMES.get(q, q)
    if component != "magnitude" and q != "shortening":
        name += f" {component}"
    return f"{name} of {where}" if where else name


def _names(names):
    names = sorted(set(names))
    return ", ".join(names[:8]) + (f", ... ({len(names)} in all)" if len(names) > 8 else "") or "none"


def region_text(cuts):
    return [f"{'xyz'[a]}{'>' if s > 0 else '<'}{v:g}" for a, s, v in cuts]


def default_reports(spheres):
    qs = ("max_displacement", "moved") + (("bonds_broken", "detached") if spheres else ())
    return [Report(q, _label(q, None, None, "magnitude", 1e-3)) for q in qs]


def _component(vec, component):
    return float(np.linalg.norm(vec)) if component == "magnitude" else float(vec["xyz".index(component)])


def _rotation_deg(q0, q1):
    """Angle (degrees) of the rotation taking orientation q0 to q1 (unit quaternions w, x, y, z)."""
    d = abs(float(np.dot(q0, q1)))
    return math.degrees(2.0 * math.acos(min(1.0, d)))


class Answers:
    """Takes the initial state of a simulation when made, the final one in `finish`."""

    def __init__(self, reports, sim, spheres=False):
        self.reports, self.spheres = reports, spheres
        if spheres:
            self.x0 = sim.x.copy()
            self.bonds0 = int(sim.bond_intact.sum())
            self.blocks = sim.blocks
        else:
            self.blocks = sim
        if self.blocks is not None:
            b = self.blocks
            self.names = list(b.A.names)
            self.quat0 = b.quat.copy()
            self.extent0 = {r.block: self._extent(b, r.block) for r in reports if r.quantity == "shortening"}

    def _index(self, name):
        return self.names.index(name)

    def _extent(self, b, name):
        v = b.vertices(self._index(name))
        return v.max(axis=0) - v.min(axis=0)

    def _block_moves(self, pattern):
        b = self.blocks
        if b is None:
            return np.zeros(0)
        moving = ~np.asarray(b.A.fixed, bool)
        if pattern is not None:
            moving &= np.array([fnmatch.fnmatchcase(n, pattern) for n in self.names], bool)
        return np.linalg.norm(b.pos[moving] - b.pos0[moving], axis=1)

    def _sphere_moves(self, sim, region):
        free = ~(sim.spheres.fixed | sim.spheres.prescribed)
        if region is not None:
            free &= region_mask(self.x0, region)
        return np.linalg.norm(sim.x[free] - self.x0[free], axis=1)

    def value(self, r, sim, energy_error):
        q = r.quantity
        b = self.blocks
        if q == "energy_error":
            return float(energy_error)
        if q in ("displacement", "velocity"):
            if r.region is not None:
                sel = region_mask(self.x0, r.region)
                vec = (sim.x[sel] - self.x0[sel] if q == "displacement" else sim.v[sel]).mean(axis=0)
            else:
                i = self._index(r.block)
                vec = b.pos[i] - b.pos0[i] if q == "displacement" else b.vel[i]
            return _component(vec, r.component)
        if q == "rotation":
            i = self._index(r.block)
            return _rotation_deg(self.quat0[i], b.quat[i])
        if q == "shortening":
            axis = "xyz".index(r.component)
            return float(self.extent0[r.block][axis] - self._extent(b, r.block)[axis])
        if q in ("max_displacement", "moved"):
            moves = [self._block_moves(r.block)] if r.block is not None or r.region is None else []
            if self.spheres and r.block is None:
                moves.append(self._sphere_moves(sim, r.region))
            d = np.concatenate(moves) if moves else np.zeros(0)
            if q == "moved":
                return int((d > r.above).sum())
            return float(d.max()) if len(d) else 0.0
        if q == "bonds_broken":
            return int(self.bonds0 - int(sim.bond_intact.sum()))
        if q == "detached":
            return detached_spheres(sim)
        raise AssertionError(q)

    def finish(self, sim, energy_error):
        """The answers as dicts: label, quantity, value, unit, and reference / error (relative) when given."""
        out = []
        for r in self.reports:
            v = self.value(r, sim, energy_error)
            a = {"label": r.label, "quantity": r.quantity, "value": v, "unit": r.unit}
            if r.block is not None:
                a["block"] = r.block
            if r.component != "magnitude":
                a["component"] = r.component
            if r.reference is not None:
                a["reference"] = r.reference
                a["error"] = (v - r.reference) / abs(r.reference) if r.reference != 0 else v - r.reference
                a["error_kind"] = "relative" if r.reference != 0 else "absolute"
            out.append(a)
        return out


def detached_spheres(sim):
    """Free spheres that no path of intact bonds joins to a fixed (or prescribed) sphere."""
    from scipy.sparse import coo_matrix  # not at the top: scipy.sparse only for this answer (fast `dda --help`)
    from scipy.sparse.csgraph import connected_components

    ss = sim.spheres
    n = ss.n
    keep = sim.bond_intact
    g = coo_matrix((np.ones(int(keep.sum())), (ss.bond_i[keep], ss.bond_j[keep])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    held = np.zeros(lab.max() + 1, bool)
    anchor = ss.fixed | ss.prescribed
    held[lab[anchor]] = True
    if not anchor.any():
        return 0
    return int((~held[lab] & ~anchor).sum())


def format_answer(a):
    unit = f" {a['unit']}" if a["unit"] else ""
    v = a["value"]
    text = f"{a['label']}: {v:.6g}{unit}" if isinstance(v, float) else f"{a['label']}: {v}{unit}"
    if "reference" in a:
        err = a["error"]
        text += (f" (reference {a['reference']:.6g}{unit}: error {100.0 * err:+.3g} %)" if a["error_kind"] == "relative"
                 else f" (reference 0: error {err:+.3g}{unit})")
    return text
