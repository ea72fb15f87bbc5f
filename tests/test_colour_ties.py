"""Ties of the paper's eq. 13-16 and of the bond rules on lattices, against exact arithmetic.

A joint at a round coordinate through a regular lattice puts sphere centres exactly on its plane, exactly 2r
from it and exactly R from its axis. The paper's inequalities are closed there ("<= R", "<= 2r", "<= d/2",
green where S.(M - O) >= 0), and sgim decides such ties as they are written (sgim/_cut.py: the tie allowance),
not by the rounding of the lattice coordinates or of the normal.

The reference here is a brute-force transcription of eq. 13-16 and of both bond rules in exact arithmetic:
every lattice site is rebuilt from its indices as an exact number a + b sqrt2 + c sqrt3 + d sqrt6 with
``fractions.Fraction`` coefficients (close-packed rows are r sqrt3 apart, layers 2r sqrt(2/3)), the radius,
the domain and the disc from their decimal text, the normal exactly (integers for dips and dip directions
that are multiples of 90 degrees; (1, 1, 0), (0, 1, 1), (-1, -1, sqrt2) ... for the 45 degree ones), and
lengths are compared squared, so that no square root is taken.
"""
from __future__ import annotations

import copy
import math
from fractions import Fraction as Fr
from pathlib import Path

import numpy as np
import pytest

from sgim.builder import build_model
from sgim.scene import load_scene, scene_from_dict

# ---------------------------------------------------------------------------
# exact numbers a + b sqrt2 + c sqrt3 + d sqrt6 (a, b, c, d rational)


class Q:
    __slots__ = ("a", "b", "c", "d")

    def __init__(self, a=0, b=0, c=0, d=0):  # int or Fraction coefficients
        self.a, self.b, self.c, self.d = a, b, c, d

    def scaled(self, L):
        """L x self with integer coefficients (asserted exact): the comparisons below are homogeneous in
        the lengths, so they can run on integers, which is much faster than on Fractions."""
        out = []
        for v in (self.a, self.b, self.c, self.d):
            v = Fr(v) * L
            assert v.denominator == 1
            out.append(v.numerator)
        return Q(*out)

    def denominators(self):
        return [Fr(v).denominator for v in (self.a, self.b, self.c, self.d)]

    @staticmethod
    def of(v):
        return v if isinstance(v, Q) else Q(v)

    def __add__(self, o):
        o = Q.of(o)
        return Q(self.a + o.a, self.b + o.b, self.c + o.c, self.d + o.d)

    __radd__ = __add__

    def __neg__(self):
        return Q(-self.a, -self.b, -self.c, -self.d)

    def __sub__(self, o):
        return self + (-Q.of(o))

    def __rsub__(self, o):
        return Q.of(o) - self

    def __mul__(self, o):
        o = Q.of(o)
        a1, b1, c1, d1 = self.a, self.b, self.c, self.d
        a2, b2, c2, d2 = o.a, o.b, o.c, o.d
        # sqrt2 sqrt3 = sqrt6, sqrt2 sqrt6 = 2 sqrt3, sqrt3 sqrt6 = 3 sqrt2
        return Q(a1 * a2 + 2 * b1 * b2 + 3 * c1 * c2 + 6 * d1 * d2,
                 a1 * b2 + b1 * a2 + 3 * (c1 * d2 + d1 * c2),
                 a1 * c2 + c1 * a2 + 2 * (b1 * d2 + d1 * b2),
                 a1 * d2 + d1 * a2 + b1 * c2 + c1 * b2)

    __rmul__ = __mul__

    def sign(self):
        """Exact sign: x = p + q sqrt2 with p = a + c sqrt3, q = b + d sqrt3."""
        def sign3(u, v):  # sign of u + v sqrt3
            su, sv = (u > 0) - (u < 0), (v > 0) - (v < 0)
            if su == 0 or sv == 0 or su == sv:
                return su or sv
            w = u * u - 3 * v * v
            return su * ((w > 0) - (w < 0))

        sp, sq = sign3(self.a, self.c), sign3(self.b, self.d)
        if sp == 0 or sq == 0 or sp == sq:
            return sp or sq
        # p^2 - 2 q^2 = (a^2 + 3c^2 - 2b^2 - 6d^2) + (2ac - 4bd) sqrt3
        a, b, c, d = self.a, self.b, self.c, self.d
        return sp * sign3(a * a + 3 * c * c - 2 * b * b - 6 * d * d, 2 * a * c - 4 * b * d)

    def __float__(self):
        return float(self.a) + float(self.b) * 2 ** 0.5 + float(self.c) * 3 ** 0.5 + float(self.d) * 6 ** 0.5


SQRT2, SQRT3, SQRT6 = Q(0, 1), Q(0, 0, 1), Q(0, 0, 0, 1)


def le(x, y):
    return (Q.of(x) - y).sign() <= 0


def dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def sub(u, v):
    return tuple(x - y for x, y in zip(u, v))


# ---------------------------------------------------------------------------
# the lattices rebuilt exactly (the construction of sgim/packing.py, from each site's indices)

def exact_sites(kind, lo, r, centres):
    """Exact coordinates of the lattice sites nearest to the given float centres (each must be one)."""
    x1, y1, z1 = lo
    out = []
    for x, y, z in centres:
        if kind == "cubic":  # eq. 1-2: x = x1 + r (2k - 1)
            k, j, i = (round((float(v - o) / float(r) + 1) / 2) for v, o in ((x, x1), (y, y1), (z, z1)))
            site = (Q(x1 + r * (2 * k - 1)), Q(y1 + r * (2 * j - 1)), Q(z1 + r * (2 * i - 1)))
        else:  # close-packed layers, stacked AB (hcp) or ABC (fcc)
            stacking = "AB" if kind == "hexagonal" else "ABC"
            h = Q(0, 0, 0, 2 * r / 3)  # 2r sqrt(2/3) = 2r sqrt6 / 3
            layer = round((z - float(z1) - float(r)) / float(h))
            letter = stacking[layer % len(stacking)]
            sx, sy = {"A": (Fr(0), Q()), "B": (r, Q(0, 0, r / 3)), "C": (Fr(0), Q(0, 0, 2 * r / 3))}[letter]
            row = round((y - float(y1) - float(r) - float(sy)) / (float(r) * 3 ** 0.5))
            off = (sx + (r if row % 2 else 0)) % (2 * r)
            col = round((x - float(x1) - float(r) - float(off)) / float(2 * r))
            site = (Q(x1 + r + off + 2 * r * col), y1 + r + sy + r * row * SQRT3, z1 + r + layer * h)
        assert max(abs(float(s) - v) for s, v in zip(site, (x, y, z))) < 1e-9, ((x, y, z), [float(s) for s in site])
        out.append(site)
    return out


# ---------------------------------------------------------------------------
# eq. 13-16 and the bond rules, exactly

class Exact:
    """A lattice and a disc (M, S, R) in exact numbers, every length scaled by one integer L so that all
    coefficients are integers (the inequalities are homogeneous in the lengths)."""

    def __init__(self, sites, M, S, R, r):
        dens = [r.denominator, R.denominator] + [q for v in M for q in Q.of(v).denominators()]
        dens += [q for O in sites for v in O for q in v.denominators()]
        L = math.lcm(*dens)
        sc = lambda v: Q.of(v).scaled(L)  # noqa: E731
        self.sites = [tuple(sc(v) for v in O) for O in sites]
        self.M = tuple(sc(v) for v in M)
        self.S = S
        self.R, self.r, self.L = sc(R).a, sc(r).a, L
        S2 = dot(S, S)
        self.S2 = S2
        self.rho = []  # |MO x S|^2 - R^2 |S|^2 (eq. 13)
        self.dots = []  # S.(M - O)
        for O in self.sites:
            c = cross(sub(O, self.M), S)
            self.rho.append(dot(c, c) - Q.of(self.R * self.R) * S2)
            self.dots.append(dot(S, sub(self.M, O)))

    def disc(self, d):
        """Per site: kind (0 / 1 red / 2 green / 3 blue) and the ties met, for thickness d.

        Squared: |MO x S|^2 <= R^2 |S|^2 (eq. 13), S.(M - O)^2 <= (d/2)^2 |S|^2 (eq. 14) or (2r)^2 |S|^2
        (eq. 15 / 16), green where S.(M - O) >= 0."""
        half = Q.of(d / 2).scaled(self.L).a if d else 2 * self.r
        lim = Q.of(half * half) * self.S2
        kinds = []
        ties = {"plane": 0, "band": 0, "radius": 0}
        for rho, s in zip(self.rho, self.dots):
            off = s * s - lim
            ties["plane"] += s.sign() == 0
            ties["band"] += off.sign() == 0
            ties["radius"] += rho.sign() == 0
            if rho.sign() > 0 or off.sign() > 0:
                kinds.append(0)
            elif d:
                kinds.append(1)
            else:
                kinds.append(2 if s.sign() >= 0 else 3)
        return np.array(kinds, np.int8), ties


def exact_colour_rule_cut(bonds, kind):
    ki, kj = kind[bonds[:, 0]], kind[bonds[:, 1]]
    return (ki == 1) | (kj == 1) | ((ki == 2) & (kj == 3)) | ((ki == 3) & (kj == 2))


def exact_geometric_cut(bonds, ex: Exact):
    """The segment O_i O_j crosses the joint plane (its ends on the two sides of eq. 15 / 16) at P with
    |MP x S| <= R |S|; with D = s_i - s_j, D (P - M) = D (O_i - M) + s_i (O_j - O_i), so that
    |(D (O_i - M) + s_i (O_j - O_i)) x S|^2 <= R^2 |S|^2 D^2 needs no division."""
    out = np.zeros(len(bonds), bool)
    for b, (i, j) in enumerate(bonds):
        si, sj = ex.dots[i], ex.dots[j]
        if (si.sign() >= 0) == (sj.sign() >= 0):
            continue
        D = si - sj
        w = tuple(D * u + si * v for u, v in zip(sub(ex.sites[i], ex.M), sub(ex.sites[j], ex.sites[i])))
        c = cross(w, ex.S)
        out[b] = le(dot(c, c), Q.of(ex.R * ex.R) * ex.S2 * D * D)
    return out


# ---------------------------------------------------------------------------
# joints through lattice centres: every lattice, every orientation family

R_TEXT = "0.015"
LO_TEXT = ("-0.21", "0.33", "1.05")  # decimal coordinates: the float lattice is rounded, the exact one is not
SIZE = Fr("0.3")
ORIENTATIONS = {  # (dip, dip direction): the exact upward normal, up to a positive factor
    (0.0, 0.0): (0, 0, 1),
    (0.0, 270.0): (0, 0, 1),
    (90.0, 0.0): (0, 1, 0),
    (90.0, 90.0): (1, 0, 0),
    (90.0, 180.0): (0, -1, 0),
    (90.0, 270.0): (-1, 0, 0),
    (90.0, 45.0): (1, 1, 0),
    (90.0, 135.0): (1, -1, 0),
    (45.0, 0.0): (0, 1, 1),
    (45.0, 90.0): (1, 0, 1),
    (45.0, 225.0): (-1, -1, SQRT2),
}


def lattice_scene(kind, disc, rule):
    lo = [float(Fr(v)) for v in LO_TEXT]
    return {"domain": {"min": lo, "max": [float(Fr(v) + SIZE) for v in LO_TEXT]},
            "packing": {"kind": kind, "radius": float(Fr(R_TEXT))},
            "discontinuity": [disc], "bonds": {"rule": rule, "tolerance": 1e-3}}


def build(d):
    return build_model(scene_from_dict(copy.deepcopy(d), "ties.toml"))


def lattice_centres(kind):
    """The sphere centres sgim builds for the domain (no discontinuity)."""
    d = lattice_scene(kind, None, "colour")
    d.pop("discontinuity")
    return build(d).centers


def check_membership(m, kind_ref, dots):
    """Membership rows and colours equal the exact ones; a centre on the plane has offset 0."""
    want = np.nonzero(kind_ref)[0]
    assert np.array_equal(m.member_sphere, want)
    assert np.array_equal(m.member_kind, kind_ref[want])
    assert np.array_equal(m.colour, kind_ref)
    on = np.array([dots[i].sign() == 0 for i in want], bool)
    assert np.all(m.member_offset[on] == 0.0)
    assert np.all(np.sign(m.member_offset[~on]) == [-dots[i].sign() for i in want[~on]])


@pytest.mark.parametrize("orientation", list(ORIENTATIONS), ids=lambda o: f"dip{o[0]:g}-dd{o[1]:g}")
@pytest.mark.parametrize("kind", ["cubic", "hexagonal", "fcc"])
def test_joint_through_lattice_centres_against_exact_arithmetic(kind, orientation):
    r = Fr(R_TEXT)
    lo = tuple(Fr(v) for v in LO_TEXT)
    dip, dd = orientation
    S = tuple(Q.of(v) for v in ORIENTATIONS[orientation])
    R = 8 * r  # 0.12: lattice sites lie at exactly R from the axis in several of the families
    # the lattice as sgim builds it, and the site nearest the domain's centre as M
    c = lattice_centres(kind)
    mid = np.array([float(v + SIZE / 2) for v in lo])
    M = exact_sites(kind, lo, r, [c[int(np.argmin(((c - mid) ** 2).sum(1)))]])[0]
    sites = exact_sites(kind, lo, r, c)
    joint = {"centre": [float(v) for v in M], "dip": dip, "dip_direction": dd, "radius": float(R)}

    ex = Exact(sites, M, S, R, r)
    kind_ref, ties = ex.disc(0)
    assert ties["plane"] >= 1 and (kind_ref == 2).sum() > 20 and (kind_ref == 3).sum() > 20, ties
    mc = build(lattice_scene(kind, joint, "colour"))
    assert np.array_equal(mc.centers, c)
    check_membership(mc, kind_ref, ex.dots)
    cut = exact_colour_rule_cut(mc.bonds, kind_ref)
    assert np.array_equal(mc.bonded, ~cut) and np.all(mc.cut_by[cut] == 0)

    mg = build(lattice_scene(kind, joint, "geometric"))
    assert np.array_equal(mg.bonds, mc.bonds)
    cut = exact_geometric_cut(mg.bonds, ex)
    assert cut.sum() > 10
    assert np.array_equal(mg.bonded, ~cut) and np.all(mg.cut_by[cut] == 0)

    # a fault of thickness 4r on the same disc: red within d/2 = 2r, the same ties as the joint's band
    fault = {**joint, "thickness": float(4 * r)}
    kind_f, _ = ex.disc(4 * r)
    mf = build(lattice_scene(kind, fault, "colour"))
    check_membership(mf, kind_f, ex.dots)
    assert np.array_equal(mf.bonded, ~exact_colour_rule_cut(mf.bonds, kind_f))


def test_the_lattice_cases_meet_every_kind_of_tie():
    """The orientations above do put sites exactly at 2r from the plane and exactly at R from the axis."""
    r = Fr(R_TEXT)
    lo = tuple(Fr(v) for v in LO_TEXT)
    for kind, orientation, want in (("cubic", (90.0, 90.0), ("band", "radius")),
                                    ("fcc", (90.0, 90.0), ("band", "radius")),
                                    ("hexagonal", (0.0, 0.0), ("radius",)),
                                    ("cubic", (0.0, 0.0), ("band", "radius"))):
        c = lattice_centres(kind)
        mid = np.array([float(v + SIZE / 2) for v in lo])
        M = exact_sites(kind, lo, r, [c[int(np.argmin(((c - mid) ** 2).sum(1)))]])[0]
        S = tuple(Q.of(v) for v in ORIENTATIONS[orientation])
        _, ties = Exact(exact_sites(kind, lo, r, c), M, S, 8 * r, r).disc(0)
        for t in want:
            assert ties[t] > 0, (kind, orientation, ties)


# ---------------------------------------------------------------------------
# the reported cantilever: FCC beam 1.2 x 0.12 x 0.12 m, r = 0.015, joint at x = 0.6

BEAM = """name = "beam"
[domain]
min = [0.0, 0.0, 0.0]
max = [1.2, 0.12, 0.12]
[packing]
kind = "fcc"
radius = 0.015
[bonds]
rule = "colour"
[[discontinuity]]
name = "joint"
centre = [{x}, 0.06, 0.06]
dip = 90
dip_direction = 90
radius = 1
thickness = 0.0
"""


def components(n, pairs):
    """Union-find over the bonded pairs: a component label per sphere."""
    parent = list(range(n))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in pairs:
        a, b = find(int(i)), find(int(j))
        if a != b:
            parent[max(a, b)] = min(a, b)
    return np.array([find(i) for i in range(n)])


@pytest.mark.parametrize("x", ["0.6", "0.6075"])
def test_beam_joint_at_a_round_coordinate_detaches_the_far_part(tmp_path, x):
    path = Path(tmp_path) / "beam.toml"
    path.write_text(BEAM.format(x=x))
    m = build_model(load_scene(path))
    c = m.centers
    xj = float(x)
    on = c[:, 0] == xj
    assert on.sum() == (7 if x == "0.6" else 0)
    assert np.all(m.colour[on] == 2)  # on the plane: green (S.(M - O) = 0 >= 0)
    # the 2r band is the same on both sides: x = 0.57 green, x = 0.63 blue (at 2r, rounded either way)
    if x == "0.6":
        assert np.all(m.colour[np.isclose(c[:, 0], 0.57, rtol=0, atol=1e-9)] == 2)
        assert np.all(m.colour[np.isclose(c[:, 0], 0.63, rtol=0, atol=1e-9)] == 3)
    beyond = c[:, 0] > xj
    b = m.bonds
    across = beyond[b[:, 0]] != beyond[b[:, 1]]
    assert across.sum() > 0 and not m.bonded[across].any()
    lab = components(len(c), b[m.bonded])
    assert not set(lab[beyond]) & set(lab[~beyond])  # no component holds spheres of both sides
    assert beyond.sum() == 293
    assert len(set(lab[beyond])) == 1 and len(set(lab[~beyond])) == 1  # each side stays one piece


# ---------------------------------------------------------------------------
# fracture networks and triangulated discontinuities take the same tie rule

def _plane_x_scene(kind, xm):
    lo = [float(Fr(v)) for v in LO_TEXT]
    return lo, {"domain": {"min": lo, "max": [float(Fr(v) + SIZE) for v in LO_TEXT]},
                "packing": {"kind": kind, "radius": float(Fr(R_TEXT))}, "bonds": {"rule": "colour", "tolerance": 1e-3}}


@pytest.mark.parametrize("kind", ["cubic", "fcc"])
def test_network_disc_through_lattice_centres_colours_like_the_disc(tmp_path, kind):
    r = Fr(R_TEXT)
    lo = tuple(Fr(v) for v in LO_TEXT)
    xm = lo[0] + (r if kind == "cubic" else 2 * r) + 10 * r  # a column of sites
    _, base = _plane_x_scene(kind, xm)
    centre = [float(xm), float(lo[1] + SIZE / 2), float(lo[2] + SIZE / 2)]
    disc = build({**base, "discontinuity": [{"centre": centre, "dip": 90.0, "dip_direction": 90.0, "radius": 1.0}]})
    (Path(tmp_path) / "network.csv").write_text(
        "id,set,cx,cy,cz,nx,ny,nz,radius,thickness\n" + f"J-000001,J,{centre[0]!r},{centre[1]!r},{centre[2]!r},"
        "1.0,0.0,0.0,1.0,0.0\n")
    sc = scene_from_dict({**copy.deepcopy(base), "dfn": {"file": "network.csv"}}, str(Path(tmp_path) / "s.toml"))
    net = build_model(sc)
    on = np.abs(disc.centers[:, 0] - centre[0]) < 1e-9
    assert on.sum() > 10 and np.all(disc.colour[on] == 2)
    assert np.array_equal(net.colour, disc.colour) and np.array_equal(net.bonded, disc.bonded)
    assert np.array_equal(net.member_offset, disc.member_offset)


def _surface_rectangle(kind, rule):
    """A joint surface: the rectangle x = xm through a column of sites (two triangles, normal +x), its y range
    the whole domain and beyond, its z range ending exactly at lattice layers z0 and z1. The exact reference
    of the documented rule (sgim/surfdisc.py: the surface's boundary in place of the disc radius, a site
    whose closest point lies on the boundary is not a member; green where the offset is <= 0): a member when
    z0 < z < z1 and |x - xm| <= 2r, green when x <= xm."""
    r = Fr(R_TEXT)
    lo = tuple(Fr(v) for v in LO_TEXT)
    c = lattice_centres(kind)
    sites = exact_sites(kind, lo, r, c)
    xs = sorted({s[0].a for s in sites})
    zs = sorted({s[2] for s in sites}, key=float)
    xm = xs[len(xs) // 2]
    z0, z1 = zs[2], zs[-3]  # boundary edges through lattice layers
    y0, y1 = lo[1] - 1, lo[1] + SIZE + 1
    V = [[float(xm), float(y0), float(z0)], [float(xm), float(y1), float(z0)], [float(xm), float(y1), float(z1)],
         [float(xm), float(y0), float(z1)]]
    m = build(lattice_scene(kind, {"vertices": V, "faces": [[0, 1, 2], [0, 2, 3]], "name": "rect"}, rule))
    assert np.array_equal(m.centers, c)
    off = [O[0] - xm for O in sites]  # S.(O - M) with S = (1, 0, 0)
    inside = np.array([(z0 - O[2]).sign() < 0 and (O[2] - z1).sign() < 0 for O in sites])
    near = np.array([le(s * s, Q((2 * r) ** 2)) for s in off])
    green = np.array([s.sign() <= 0 for s in off])
    kinds = np.where(inside & near, np.where(green, 2, 3), 0).astype(np.int8)
    on = np.array([s.sign() == 0 for s in off])
    edge = np.array([(z0 - O[2]).sign() == 0 or (O[2] - z1).sign() == 0 for O in sites])  # feet on the boundary
    assert (edge & near).sum() > 10
    return m, kinds, inside, green, on


@pytest.mark.parametrize("kind", ["cubic", "fcc"])
def test_surface_joint_through_lattice_centres_against_exact_arithmetic(kind):
    m, kinds, inside, _, on = _surface_rectangle(kind, "colour")
    assert (on & inside).sum() > 10 and (on & ~inside).sum() > 5  # sites on the plane, in and beyond the rectangle
    assert np.array_equal(m.colour, kinds)
    assert np.array_equal(m.member_sphere, np.nonzero(kinds)[0])
    assert np.all(m.member_offset[on[m.member_sphere]] == 0.0)
    assert np.array_equal(m.bonded, ~exact_colour_rule_cut(m.bonds, kinds))


@pytest.mark.parametrize("kind", ["cubic", "fcc"])
def test_surface_joint_geometric_rule_with_ends_on_the_surface(kind):
    """Geometric rule: a bond with an end on the surface is cut when the other end is on the blue side, not
    when both ends lie on it or the other end is green (bonds within the rectangle's z range)."""
    m, _, inside, green, on = _surface_rectangle(kind, "geometric")
    b = m.bonds
    sel = inside[b[:, 0]] & inside[b[:, 1]]
    cut = green[b[:, 0]] != green[b[:, 1]]
    assert np.array_equal(m.bonded[sel], ~cut[sel])
    touch = sel & (on[b[:, 0]] | on[b[:, 1]])
    assert (touch & cut).sum() > 10 and (touch & ~cut).sum() > 10
    assert (sel & on[b[:, 0]] & on[b[:, 1]]).sum() > 0 or kind != "cubic"
