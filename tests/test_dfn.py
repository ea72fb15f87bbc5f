"""Monte-Carlo fracture networks (sgim.dfn) against independent references.

References written here, apart from the code under test:
* the area of a disc inside a box by a polar midpoint quadrature of the disc (and closed forms for
  half, quarter and circular-segment cases);
* the Fisher distribution's cumulative distribution of the angle to the mean pole, and the
  Fisher concentration estimate kappa = (N - 1) / (N - R);
* maximum-likelihood fits of the radius laws with normalising constants by numerical quadrature
  (scipy.integrate.quad), and Kolmogorov-Smirnov tests against the laws' distribution functions;
* brute-force membership, colours and bonds (tests/sgim_ref.py via sgim_check.check_model) of the
  network written out by hand as [[discontinuity]] tables.
"""
from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, optimize, stats

from sgim.builder import build_model
from sgim.cli import main as sgim_main
from sgim.dfn import clipped_areas, network_for
from sgim.scene import SceneError, scene_from_dict
from sgim_check import build as build_checked
from sgim_check import check_model

_SCRIPT = Path(sys.executable).parent / "sgim"
SGIM = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "sgim.cli"]


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def pole(dip, dd):
    d, a = math.radians(dip), math.radians(dd)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def scene_dict(sets, lo=(0.0, 0.0, 0.0), hi=(60.0, 50.0, 40.0), seed=7, r=0.5, **dfn):
    return {"domain": {"min": list(lo), "max": list(hi)}, "packing": {"radius": r},
            "dfn": {"seed": seed, **dfn}, "joint_set": copy.deepcopy(sets)}


def network(sets, **kw):
    sc = scene_from_dict(scene_dict(sets, **kw), "dfn.toml")
    return network_for(sc)


def of_set(net, name):
    s = net.set_names.index(name)
    return net.set_index == s


# ---------------------------------------------------------------------------
# area of a disc inside a box

def quad_area(M, n, R, lo, hi, nr=48, nphi=192):
    """Polar midpoint quadrature on equal-area rings: area of the disc inside the box."""
    n = unit(n)
    helper = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.5 else np.array([1.0, 0.0, 0.0])
    u = unit(np.cross(n, helper))
    v = np.cross(n, u)
    rho = R * np.sqrt((np.arange(nr) + 0.5) / nr)
    phi = 2 * np.pi * (np.arange(nphi) + 0.5) / nphi
    P = M + (rho[:, None, None] * (np.cos(phi)[None, :, None] * u + np.sin(phi)[None, :, None] * v))
    inside = np.all((P >= lo) & (P <= hi), axis=-1)
    return math.pi * R * R * inside.mean()


def segment_area(R, h):
    """Area of the circle of radius R beyond a chord at distance h from the centre (0 <= h <= R)."""
    return R * R * math.acos(h / R) - h * math.sqrt(R * R - h * h)


def test_clipped_area_closed_forms():
    lo, hi = np.zeros(3), np.array([10.0, 8.0, 6.0])
    R = 2.0
    cases = [
        ((5.0, 4.0, 3.0), (0.3, -0.2, 0.9), math.pi * R * R),  # inside
        ((0.0, 4.0, 3.0), (0.0, 0.0, 1.0), 0.5 * math.pi * R * R),  # centred on the face x = 0
        ((0.0, 0.0, 3.0), (0.0, 0.0, 1.0), 0.25 * math.pi * R * R),  # centred on the vertical edge
        ((0.7, 4.0, 3.0), (0.0, 0.0, 1.0), math.pi * R * R - segment_area(R, 0.7)),  # a chord cut off
        ((-0.7, 4.0, 3.0), (0.0, 1.0, 0.0), segment_area(R, 0.7)),  # mostly outside
        ((-3.0, 4.0, 3.0), (0.0, 0.0, 1.0), 0.0),  # outside
        ((5.0, 4.0, 7.0), (0.0, 0.0, 1.0), 0.0),  # parallel above the box
    ]
    M = np.array([c[0] for c in cases], float)
    N = unit(np.array([c[1] for c in cases], float))
    got = clipped_areas(M, N, np.full(len(cases), R), lo, hi)
    want = np.array([c[2] for c in cases])
    assert np.allclose(got, want, rtol=1e-12, atol=1e-12), (got, want)
    # discs larger than the box: the section of the box by the disc's plane
    big = clipped_areas(np.array([[5.0, 4.0, 3.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([50.0]), lo, hi)
    assert big[0] == pytest.approx(80.0, rel=1e-12)  # the whole 10 x 8 section
    tilted = clipped_areas(np.array([[5.0, 4.0, 3.0]]), unit(np.array([[1.0, 0.0, 1.0]])), np.array([50.0]), lo, hi)
    # plane x + z = 8 through the box: section is a rectangle 8 (in y) by the chord length in x-z
    # from (2, 6) to (8, 0): 6 sqrt(2)
    assert tilted[0] == pytest.approx(8.0 * 6.0 * math.sqrt(2.0), rel=1e-12)


def test_clipped_area_random_discs_against_quadrature():
    rng = np.random.default_rng(11)
    lo, hi = np.array([-3.0, 1.0, 0.0]), np.array([7.0, 9.0, 9.0])
    n = 400
    M = rng.uniform(lo - 3, hi + 3, (n, 3))
    N = unit(rng.normal(size=(n, 3)))
    R = rng.uniform(0.2, 6.0, n)
    got = clipped_areas(M, N, R, lo, hi)
    want = np.array([quad_area(M[k], N[k], R[k], lo, hi) for k in range(n)])
    full = np.pi * R * R
    assert np.all(np.abs(got - want) <= 0.01 * full + 1e-12), np.max(np.abs(got - want) / full)
    assert np.all((got >= 0) & (got <= full * (1 + 1e-12)))
    assert abs(got.sum() - want.sum()) <= 2e-3 * want.sum()
    whole = np.isclose(got, full, rtol=1e-12, atol=0)
    assert (got == 0).sum() > 10 and whole.sum() > 5 and ((got > 0) & ~whole).sum() > 100


# ---------------------------------------------------------------------------
# intensity

POWER = {"law": "power", "exponent": 2.6, "min": 1.5, "max": 12.0}


def test_realised_p32_meets_the_target():
    lo, hi = np.zeros(3), np.array([60.0, 50.0, 40.0])
    target = 0.3
    net = network([{"name": "J1", "dip": 60.0, "dip_direction": 130.0, "kappa": 15.0, "p32": target,
                    "radius": POWER}], lo=lo, hi=hi)
    assert len(net) > 1000
    V = float(np.prod(hi - lo))
    area = np.array([quad_area(net.centres[k], net.normals[k], net.radii[k], lo, hi) for k in range(len(net))])
    assert np.all(area > 0) or (area == 0).sum() <= 0.002 * len(net)  # grazing discs may miss the nodes
    p32 = area.sum() / V
    assert abs(p32 - target) <= 0.05 * target, p32
    assert abs(p32 - target) <= 0.01 * target, p32  # in fact closer: the set stops at the target
    st = net.statistics()[0]
    assert st["p32"] == pytest.approx(net.area.sum() / V)
    assert st["p32_target"] == target


def test_p32_stops_at_the_closest_count():
    """The P32 set holds the number of fractures whose area comes closest to the target; its
    fractures are the first ones of the same set given by count (one more, one fewer)."""
    lo, hi = np.zeros(3), np.array([30.0, 30.0, 30.0])
    js = {"name": "A", "dip": 30.0, "dip_direction": 10.0, "kappa": 8.0, "radius": POWER}
    net = network([{**js, "p32": 0.2}], lo=lo, hi=hi)
    k = len(net)
    more = network([{**js, "count": k + 1}], lo=lo, hi=hi)
    fewer = network([{**js, "count": k - 1}], lo=lo, hi=hi)
    assert np.array_equal(more.centres[:k], net.centres) and np.array_equal(fewer.centres, net.centres[:k - 1])
    T = 0.2 * 27000.0
    a = np.array([quad_area(more.centres[q], more.normals[q], more.radii[q], lo, hi, 64, 256) for q in range(k + 1)])
    s_k, s_more, s_fewer = a[:k].sum(), a.sum(), a[:k - 1].sum()
    slack = 0.01 * a[k - 1:].max()  # quadrature error
    assert abs(s_k - T) <= abs(s_more - T) + slack and abs(s_k - T) <= abs(s_fewer - T) + slack


# ---------------------------------------------------------------------------
# orientation

def fisher_cdf(theta, kappa):
    """P(angle to the mean pole <= theta) for the Fisher distribution."""
    return -np.expm1(-kappa * (1 - np.cos(theta))) / -math.expm1(-2 * kappa)


@pytest.mark.parametrize("kappa,dip,dd", [(5.0, 40.0, 200.0), (40.0, 75.0, 40.0), (300.0, 10.0, 320.0)])
def test_fisher_orientations(kappa, dip, dd):
    lo, hi = np.zeros(3), np.full(3, 100.0)
    net = network([{"name": "F", "dip": dip, "dip_direction": dd, "kappa": kappa, "count": 12000,
                    "radius": 1.0}], lo=lo, hi=hi)
    inside = np.all((net.centres >= lo) & (net.centres <= hi), axis=1)
    n = net.normals[inside]
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert np.all(n[:, 2] >= 0)  # upward normals
    p = pole(dip, dd)
    # the stored normals are axial after turning them upward: align to the given pole
    al = np.where((n @ p)[:, None] < 0, -n, n)
    N = len(al)
    Rlen = np.linalg.norm(al.sum(0))
    k_est = (N - 1) / (N - Rlen)
    assert abs(k_est - kappa) <= 0.10 * kappa, k_est
    mean = al.sum(0) / Rlen
    assert math.degrees(math.acos(min(1.0, float(mean @ p)))) < 3.0 / math.sqrt(kappa) * 3
    # the angle to the pole, folded into [0, pi/2] by the axial alignment
    psi = np.arccos(np.clip(al @ p, -1, 1))
    assert stats.kstest(psi, lambda t: fisher_cdf(t, kappa) + 1.0 - fisher_cdf(np.pi - t, kappa)).pvalue > 1e-3
    # azimuth about the pole: uniform
    e1 = unit(np.cross(p, [0.0, 0.0, 1.0] if abs(p[2]) < 0.9 else [1.0, 0.0, 0.0]))
    e2 = np.cross(p, e1)
    az = np.mod(np.arctan2(al @ e2, al @ e1), 2 * np.pi)
    assert stats.kstest(az / (2 * np.pi), "uniform").pvalue > 1e-3
    st = net.statistics()[0]
    assert st["kappa_estimate"] == pytest.approx(k_est, rel=0.02)
    sp = pole(st["mean_pole"]["dip"], st["mean_pole"]["dip_direction"])
    assert abs(float(sp @ p)) > math.cos(math.radians(3.0))


# ---------------------------------------------------------------------------
# radius laws: the fractures whose centre lies in the domain sample the law without bias

def mle_1d(logpdf_unnorm, r, a, b, lo_t, hi_t):
    def nll(t):
        z = integrate.quad(lambda x: math.exp(logpdf_unnorm(x, t)), a, b, limit=200)[0]
        return -(sum_log(logpdf_unnorm, r, t)) + len(r) * math.log(z)
    return optimize.minimize_scalar(nll, bounds=(lo_t, hi_t), method="bounded", options={"xatol": 1e-7}).x


def sum_log(f, r, t):
    return float(np.sum(f(r, t)))


def radii_inside(net, lo, hi):
    inside = np.all((net.centres >= lo) & (net.centres <= hi), axis=1)
    return net.radii[inside]


LO_R, HI_R = np.zeros(3), np.full(3, 160.0)


def sample_radii(radius, count=9000):
    net = network([{"name": "R", "dip": 45.0, "dip_direction": 90.0, "kappa": 10.0, "count": count,
                    "radius": radius}], lo=LO_R, hi=HI_R)
    return net, radii_inside(net, LO_R, HI_R)


def ks_against(r, pdf, a, b):
    z = integrate.quad(pdf, a, b, limit=200)[0]
    xs = np.sort(r)
    grid = np.concatenate([[a], xs])
    steps = np.array([integrate.quad(pdf, grid[i], grid[i + 1], limit=100)[0] for i in range(len(xs))])
    cdf = np.cumsum(steps) / z
    n = len(xs)
    D = max(np.max(np.arange(1, n + 1) / n - cdf), np.max(cdf - np.arange(n) / n))
    return stats.kstwo.sf(D, n)


@pytest.mark.parametrize("exponent,rmin,rmax", [(2.7, 2.0, 30.0), (1.0, 1.0, 20.0), (4.5, 1.0, None)])
def test_power_law_radius_recovered(exponent, rmin, rmax):
    law = {"law": "power", "exponent": exponent, "min": rmin}
    if rmax:
        law["max"] = rmax
    net, r = sample_radii(law)
    assert len(r) > 3000 and r.min() >= rmin and (rmax is None or r.max() <= rmax)
    b = rmax or math.inf
    if rmax:
        a_hat = mle_1d(lambda x, a: -a * np.log(x), r, rmin, b, -5.0, 10.0)
    else:  # closed form (Pareto) written independently
        a_hat = 1.0 + len(r) / float(np.sum(np.log(r / rmin)))
    assert abs(a_hat - exponent) <= 0.1, a_hat
    fit = net.statistics()[0]["radius_fit"]
    assert fit["exponent"] == pytest.approx(a_hat, abs=2e-3)
    pdf = (lambda x: x ** -exponent)
    if rmax:
        assert ks_against(r[:1500], pdf, rmin, rmax) > 1e-3
    else:
        assert stats.kstest(r, lambda x: 1 - (x / rmin) ** (1 - exponent)).pvalue > 1e-3


@pytest.mark.parametrize("rmin,rmax", [(1.0, None), (1.0, 12.0)])
def test_exponential_radius_recovered(rmin, rmax):
    law = {"law": "exponential", "mean": 4.0, "min": rmin}
    if rmax:
        law["max"] = rmax
    net, r = sample_radii(law)
    b = rmax or 400.0
    mu_hat = mle_1d(lambda x, m: -x / m, r, rmin, b, 0.5, 20.0)
    assert abs(mu_hat - 4.0) <= 0.05 * 4.0, mu_hat
    assert net.statistics()[0]["radius_fit"]["mean"] == pytest.approx(mu_hat, rel=2e-3)
    assert ks_against(r[:1500], lambda x: math.exp(-x / 4.0), rmin, b) > 1e-3


@pytest.mark.parametrize("given", [{"mean": 5.0, "sd": 2.0}, {"mu": 1.5, "sigma": 0.5, "min": 2.0, "max": 12.0}])
def test_lognormal_radius_recovered(given):
    net, r = sample_radii({"law": "lognormal", **given})
    if "mean" in given:
        s2 = math.log(1 + (given["sd"] / given["mean"]) ** 2)
        mu, sigma = math.log(given["mean"]) - s2 / 2, math.sqrt(s2)
    else:
        mu, sigma = given["mu"], given["sigma"]
    a, b = given.get("min", 1e-9), given.get("max", 1e4)

    def nll(p):
        m, s = p[0], math.exp(p[1])
        z = integrate.quad(lambda x: stats.norm.pdf((math.log(x) - m) / s) / (x * s), a, b, limit=200)[0]
        return -float(np.sum(stats.norm.logpdf((np.log(r) - m) / s) - np.log(r * s))) + len(r) * math.log(z)

    res = optimize.minimize(nll, [float(np.log(r).mean()), math.log(float(np.log(r).std()))], method="Nelder-Mead",
                            options={"xatol": 1e-6, "fatol": 1e-6})
    mu_hat, s_hat = res.x[0], math.exp(res.x[1])
    assert abs(mu_hat - mu) <= 0.05 and abs(s_hat - sigma) <= 0.05 * sigma, (mu_hat, s_hat)
    fit = net.statistics()[0]["radius_fit"]
    assert fit["mu"] == pytest.approx(mu_hat, abs=2e-3) and fit["sigma"] == pytest.approx(s_hat, rel=5e-3)
    assert ks_against(r[:1500], lambda x: stats.norm.pdf((math.log(x) - mu) / sigma) / x, a, b) > 1e-3


def test_constant_radius():
    net, r = sample_radii(3.5, count=500)
    assert np.all(net.radii == 3.5)
    assert net.statistics()[0]["radius_fit"]["value"] == 3.5


def test_discs_reaching_in_from_outside_are_represented():
    """For a homogeneous Poisson process of discs (intensity lambda per volume), the expected area
    inside the domain is lambda V pi E[R^2] (Fubini), while lambda V discs are centred in it.  With
    radii as large as the domain most of the area comes from discs centred outside: the ratio
    area / (count centred inside x pi E[R^2]) is 1 only if they are all there."""
    lo, hi = np.zeros(3), np.array([20.0, 10.0, 5.0])
    law = {"law": "power", "exponent": 2.0, "min": 1.0, "max": 15.0}
    net = network([{"name": "B", "dip": 80.0, "dip_direction": 0.0, "kappa": 3.0, "count": 40000,
                    "radius": law}], lo=lo, hi=hi)
    d_out = np.max(np.maximum(lo - net.centres, net.centres - hi), axis=1)
    assert np.all(d_out <= net.radii)  # a centre farther than R from the box cannot reach it
    n_in = int((d_out <= 0).sum())
    assert n_in < 0.4 * len(net)  # most reach in from outside
    z = integrate.quad(lambda x: x ** -2.0, 1.0, 15.0)[0]
    er2 = integrate.quad(lambda x: x ** 2 * x ** -2.0, 1.0, 15.0)[0] / z
    sub = np.arange(0, len(net), 10)
    area = np.array([quad_area(net.centres[k], net.normals[k], net.radii[k], lo, hi, 24, 96) for k in sub])
    ratio = area.sum() * 10 / (n_in * math.pi * er2)
    assert abs(ratio - 1.0) < 0.06, ratio
    assert abs(net.area.sum() / area.sum() / 10 - 1.0) < 0.03


# ---------------------------------------------------------------------------
# reproducibility and stable ids

SETS = [
    {"name": "J1", "dip": 75.0, "dip_direction": 40.0, "kappa": 40.0, "p32": 0.08, "radius": POWER},
    {"name": "J2", "dip": 15.0, "dip_direction": 220.0, "kappa": 20.0, "count": 300, "thickness": 0.3,
     "radius": {"law": "lognormal", "mean": 3.0, "sd": 1.0}},
]


def same(a, b, sel_a=None, sel_b=None):
    sa = slice(None) if sel_a is None else sel_a
    sb = slice(None) if sel_b is None else sel_b
    return (np.array_equal(a.centres[sa], b.centres[sb]) and np.array_equal(a.normals[sa], b.normals[sb])
            and np.array_equal(a.radii[sa], b.radii[sb]) and np.array_equal(a.thickness[sa], b.thickness[sb])
            and list(np.array(a.ids)[sa]) == list(np.array(b.ids)[sb]))


def test_same_seed_same_network_and_ids():
    a, b = network(SETS), network(SETS)
    assert len(a) > 300 and same(a, b)
    c = network(SETS, seed=8)
    assert not np.array_equal(a.centres[:10], c.centres[:10])
    j1 = [i for i in a.ids if i.startswith("J1-")]
    assert j1 == [f"J1-{k:06d}" for k in range(1, len(j1) + 1)]
    assert len(set(a.ids)) == len(a.ids)
    assert np.all(a.thickness[of_set(a, "J2")] == 0.3) and np.all(a.thickness[of_set(a, "J1")] == 0.0)


def test_sets_do_not_disturb_each_other():
    both = network(SETS)
    j1 = network(SETS[:1])
    j2 = network(SETS[1:])
    rev = network(SETS[::-1])
    assert same(both, j1, of_set(both, "J1"))
    assert same(both, j2, of_set(both, "J2"))
    assert same(both, rev, of_set(both, "J1"), of_set(rev, "J1"))


def test_intensity_only_appends():
    lo_net = network([{**SETS[0], "p32": 0.05}])
    hi_net = network([{**SETS[0], "p32": 0.1}])
    k = len(lo_net)
    assert len(hi_net) > 1.5 * k and same(lo_net, hi_net, None, slice(0, k))
    c1 = network([{**SETS[1], "count": 100}])
    c2 = network([{**SETS[1], "count": 300}])
    assert same(c1, c2, None, slice(0, 100))
    # a different orientation law keeps the candidates' radii and centres: the fractures centred
    # in the domain (kept whatever their orientation) are the same
    k2 = network([{**SETS[1], "kappa": 5.0, "dip": 60.0}])
    lo, hi = np.zeros(3), np.array([60.0, 50.0, 40.0])
    a_in = {tuple(c) + (r,) for c, r in zip(c2.centres, c2.radii) if np.all((c >= lo) & (c <= hi))}
    b_in = {tuple(c) + (r,) for c, r in zip(k2.centres, k2.radii) if np.all((c >= lo) & (c <= hi))}
    assert len(a_in & b_in) > 0.95 * min(len(a_in), len(b_in)) > 100


# ---------------------------------------------------------------------------
# the network applied in a build

SMALL = {"domain": {"min": [0.0, 0.0, 0.0], "max": [8.0, 7.0, 6.0]}, "packing": {"kind": "cubic", "radius": 0.3},
         "discontinuity": [{"name": "hand", "centre": [4.0, 3.0, 3.0], "dip": 50.0, "dip_direction": 10.0,
                            "radius": 3.0}]}
SMALL_SETS = [
    {"name": "S1", "dip": 70.0, "dip_direction": 120.0, "kappa": 15.0, "count": 25,
     "radius": {"law": "power", "exponent": 2.5, "min": 0.8, "max": 4.0}},
    {"name": "S2", "dip": 20.0, "dip_direction": 300.0, "kappa": 10.0, "count": 6, "thickness": 0.5,
     "radius": {"law": "lognormal", "mean": 2.0, "sd": 0.5}},
]


def by_hand(net, d):
    """The scene dictionary with the network written out as [[discontinuity]] tables."""
    h = copy.deepcopy(d)
    h.pop("dfn", None)
    h.pop("joint_set", None)
    for k in range(len(net)):
        h["discontinuity"].append({"name": net.ids[k], "centre": net.centres[k].tolist(),
                                   "normal": net.normals[k].tolist(), "radius": float(net.radii[k]),
                                   "thickness": float(net.thickness[k])})
    return h


def models_equal(a, b, exact=True):
    for k in ("centers", "radii", "colour", "colour_source", "bonds", "bonded", "cut_by", "member_sphere",
              "member_disc", "member_kind", "disc_centre", "disc_radius", "disc_thickness"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    for k in ("member_offset", "disc_normal"):
        if exact:
            assert np.array_equal(getattr(a, k), getattr(b, k)), k
        else:
            assert np.allclose(getattr(a, k), getattr(b, k), rtol=0, atol=1e-12), k
    assert list(a.disc_name) == list(b.disc_name)


@pytest.mark.parametrize("rule", ["colour", "geometric"])
def test_network_build_equals_hand_written_discs(rule):
    d = {**copy.deepcopy(SMALL), "bonds": {"rule": rule, "tolerance": 1e-3}, "dfn": {"seed": 3},
         "joint_set": copy.deepcopy(SMALL_SETS)}
    scene = scene_from_dict(copy.deepcopy(d), "net.toml")
    m = build_model(scene)
    net = network_for(scene)
    assert len(net) == 31 and m.disc_name[0] == "hand" and list(m.disc_name[1:]) == net.ids
    h = by_hand(net, d)
    hscene, hm = build_checked(h)
    models_equal(m, hm, exact=False)
    check_model(h, hscene, hm)  # brute-force membership, colours, bonds and bond rule
    assert (m.colour == 1).sum() > 0 and (m.colour == 2).sum() > 0 and (~m.bonded).sum() > 0
    assert m.meta["dfn"]["fractures"] == 31


@pytest.mark.parametrize("rule", ["colour", "geometric"])
def test_many_fractures_against_brute_force(rule):
    """Hundreds of fractures of every orientation (the cutting stage visits only the grid cells near
    each disc's plane) in a box with an awkward origin: membership, colours and bonds by brute force."""
    d = {"domain": {"min": [-13.37, 4.1, -2.2], "max": [-4.0, 12.3, 4.9]},
         "packing": {"kind": "hexagonal", "radius": 0.27}, "discontinuity": [],
         "bonds": {"rule": rule, "tolerance": 1e-3}, "dfn": {"seed": 99},
         "joint_set": [
             {"name": "A", "dip": 88.0, "dip_direction": 45.0, "kappa": 2.0, "count": 150,
              "radius": {"law": "exponential", "mean": 1.5, "min": 0.3}},
             {"name": "B", "dip": 3.0, "dip_direction": 0.0, "kappa": 1.0, "count": 150,
              "radius": {"law": "power", "exponent": 3.0, "min": 0.5, "max": 9.0}},
             {"name": "C", "dip": 45.0, "dip_direction": 300.0, "kappa": 50.0, "count": 20, "thickness": 0.35,
              "radius": 2.0}]}
    scene = scene_from_dict(copy.deepcopy(d), "many.toml")
    m = build_model(scene)
    net = network_for(scene)
    h = by_hand(net, d)
    hscene, hm = build_checked(h)
    models_equal(m, hm, exact=False)
    check_model(h, hscene, hm)
    assert len(np.unique(m.member_disc)) > 250


@pytest.mark.parametrize("suffix", ["csv", "json"])
def test_network_file_applies_exactly(tmp_path, suffix):
    d = {**copy.deepcopy(SMALL), "dfn": {"seed": 3}, "joint_set": copy.deepcopy(SMALL_SETS)}
    scene = scene_from_dict(copy.deepcopy(d), tmp_path / "net.toml")
    m = build_model(scene)
    net = network_for(scene)
    getattr(net, f"save_{suffix}")(tmp_path / f"network.{suffix}")
    f = copy.deepcopy(SMALL)
    f["dfn"] = {"file": f"network.{suffix}"}
    fscene = scene_from_dict(f, tmp_path / "file.toml")
    models_equal(m, build_model(fscene), exact=True)
    loaded = network_for(fscene)
    assert loaded.ids == net.ids and loaded.set_names == net.set_names
    assert np.array_equal(loaded.area, net.area)


def test_file_rows_outside_the_domain_are_dropped(tmp_path):
    rows = ["id,set,cx,cy,cz,nx,ny,nz,radius",
            "a,X,4,3,3,0,0,1,1.0",
            "b,X,40,3,3,0,0,1,1.0",  # far outside
            "c,Y,-0.5,3,3,1,0,0,2.0"]  # parallel to the face x = 0, outside
    (tmp_path / "n.csv").write_text("\n".join(rows) + "\n")
    f = copy.deepcopy(SMALL)
    f["dfn"] = {"file": "n.csv"}
    net = network_for(scene_from_dict(f, tmp_path / "s.toml"))
    assert net.ids == ["a"] and net.dropped == 2 and net.area[0] == pytest.approx(math.pi)


def test_vtu_discs(tmp_path):
    import meshio

    net = network(SETS)
    net.save_vtu(tmp_path / "n.vtu")
    mesh = meshio.read(tmp_path / "n.vtu")
    cells = mesh.cells[0].data
    assert mesh.cells[0].type == "polygon" and len(cells) == len(net)
    P = mesh.points[cells].astype(float)  # (n, segments, 3), single precision
    rel = P - net.centres[:, None, :]
    tol = 1e-6 * (1.0 + np.abs(net.centres).max() + net.radii.max())
    assert np.allclose(np.linalg.norm(rel, axis=2), net.radii[:, None], rtol=0, atol=tol)
    assert np.allclose(np.einsum("nsk,nk->ns", rel, net.normals), 0.0, atol=tol)
    assert cells.shape[1] >= 16
    assert np.allclose(mesh.cell_data["radius"][0], net.radii)


# ---------------------------------------------------------------------------
# command line

SCENE = """\
name = "dfn_small"
[domain]
min = [0.0, 0.0, 0.0]
max = [8.0, 7.0, 6.0]
[packing]
radius = 0.3
[dfn]
seed = 5
[[joint_set]]
name = "J1"
dip = 70.0
dip_direction = 120.0
kappa = 15.0
p32 = 0.3
[joint_set.radius]
law = "power"
exponent = 2.5
min = 0.8
max = 4.0
"""


def run(*args, cwd):
    return subprocess.run([*SGIM, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=240)


def test_cli_dfn_and_build(tmp_path):
    (tmp_path / "s.toml").write_text(SCENE)
    p = run("dfn", "s.toml", "-o", "net", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    info = json.loads(p.stdout)
    files = sorted(x.name for x in (tmp_path / "net").iterdir())
    assert files == [".rockdem-output", "network.csv", "network.json", "network.vtu", "summary.json"]
    doc = json.loads((tmp_path / "net" / "network.json").read_text())
    assert len(doc["fractures"]) == info["fractures"] > 10
    csv_rows = (tmp_path / "net" / "network.csv").read_text().splitlines()
    assert csv_rows[0].split(",") == ["id", "set", "cx", "cy", "cz", "nx", "ny", "nz", "dip", "dip_direction",
                                      "radius", "thickness", "area_in_domain"]
    assert len(csv_rows) == info["fractures"] + 1
    # dip / dip direction agree with the normal; area column sums to P32 V
    row = doc["fractures"][0]
    assert np.allclose(pole(row["dip"], row["dip_direction"]), row["normal"], atol=1e-12)
    assert sum(f["area_in_domain"] for f in doc["fractures"]) / (8 * 7 * 6) == pytest.approx(info["p32"])
    assert info["sets"][0]["p32_target"] == 0.3
    q = run("build", "s.toml", "-o", "model", "--quiet", "--formats", "npz", cwd=tmp_path)
    assert q.returncode == 0, q.stderr
    assert (tmp_path / "model" / "network.csv").read_text() == (tmp_path / "net" / "network.csv").read_text()
    summ = json.loads((tmp_path / "model" / "summary.json").read_text())
    assert summ["meta"]["dfn"]["fractures"] == info["fractures"]
    assert summ["discontinuities"] == info["fractures"]
    t = run("dfn", "s.toml", "-o", "net", "--force", cwd=tmp_path)  # replaces its output, prints the table
    assert t.returncode == 0 and "J1" in t.stdout and "P32" in t.stdout


# ---------------------------------------------------------------------------
# bad input: one line, exit status 2, nothing written

def with_set(**kw):
    js = {"name": "J1", "dip": 70.0, "dip_direction": 120.0, "kappa": 15.0, "p32": 0.3,
          "radius": {"law": "power", "exponent": 2.5, "min": 0.8, "max": 4.0}}
    for k, v in kw.items():
        if v is None:
            js.pop(k, None)
        else:
            js[k] = v
    return js


def toml_of(d):
    """A tiny TOML writer for the scene dictionaries used here."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    lines = []
    for k, v in d.items():
        if isinstance(v, dict):
            lines += [f"[{k}]", *(f"{a} = {val(b)}" for a, b in v.items())]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for t in v:
                lines += [f"[[{k}]]", *(f"{a} = {val(b)}" for a, b in t.items())]
        else:
            lines.append(f"{k} = {val(v)}")
    return "\n".join(lines) + "\n"


BASE = {"domain": {"min": [0.0, 0.0, 0.0], "max": [8.0, 7.0, 6.0]}, "packing": {"radius": 0.3}}

BAD = [
    ("kappa zero", [with_set(kappa=0.0)], {}, "joint_set[0].kappa", "must be > 0"),
    ("kappa negative", [with_set(kappa=-3)], {}, "joint_set[0].kappa", "must be > 0"),
    ("power exponent <= 1 unbounded", [with_set(radius={"law": "power", "exponent": 0.8, "min": 1.0})], {},
     "joint_set[0].radius.exponent", "upper bound"),
    ("power exponent 1 unbounded", [with_set(radius={"law": "power", "exponent": 1.0, "min": 1.0})], {},
     "joint_set[0].radius.exponent", "upper bound"),
    ("inverted bounds", [with_set(radius={"law": "power", "exponent": 2.5, "min": 4.0, "max": 0.8})], {},
     "joint_set[0].radius.max", "inverted"),
    ("inverted lognormal bounds", [with_set(radius={"law": "lognormal", "mu": 1.0, "sigma": 0.3, "min": 5.0,
                                                    "max": 5.0})], {}, "joint_set[0].radius.max", "inverted"),
    ("count and p32", [with_set(count=10)], {}, "joint_set[0]", "exactly one of p32"),
    ("neither count nor p32", [with_set(p32=None)], {}, "joint_set[0]", "exactly one of p32"),
    ("p32 beyond max_fractures", [with_set(p32=50.0)], {"max_fractures": 1000}, "joint_set[0].p32", "needs about"),
    ("count beyond max_fractures", [with_set(p32=None, count=5000)], {"max_fractures": 1000},
     "joint_set[0].count", "max_fractures"),
    ("unknown law", [with_set(radius={"law": "weibull", "k": 2})], {}, "joint_set[0].radius.law", "must be one of"),
    ("repeated name", [with_set(), with_set()], {}, "joint_set[1].name", "repeats"),
    ("negative seed", [with_set()], {"seed": -1}, "dfn.seed", ">= 0"),
    ("file and sets", [with_set()], {"file": "x.csv"}, "dfn.file", "not both"),
    ("missing file", [], {"file": "nowhere.csv"}, "dfn.file", "cannot read"),
]


@pytest.mark.parametrize("case", BAD, ids=[b[0] for b in BAD])
@pytest.mark.parametrize("cmd", ["dfn", "build"])
def test_bad_input_one_line(tmp_path, capsys, case, cmd):
    _, sets, dfn, key, words = case
    d = {**copy.deepcopy(BASE), "dfn": {"seed": 1, **dfn}}
    if sets:
        d["joint_set"] = sets
    (tmp_path / "s.toml").write_text(toml_of(d))
    out = tmp_path / "out"
    rc = sgim_main([cmd, str(tmp_path / "s.toml"), "-o", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and words in lines[0], err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_p32_refusal_names_the_count_needed():
    """Constant radius R = 1 in a 200 m cube: P32 V / (pi R^2) discs, plus the few per cent that reach
    in from outside with less than their full area."""
    d = {"domain": {"min": [0.0, 0.0, 0.0], "max": [200.0, 200.0, 200.0]}, "packing": {"radius": 0.5},
         "joint_set": [{"name": "D", "dip": 30.0, "dip_direction": 0.0, "kappa": 10.0, "p32": 5.0, "radius": 1.0}]}
    with pytest.raises(SceneError) as ei:
        scene_from_dict(d, "big.toml")
    msg = str(ei.value)
    assert "joint_set[0].p32" in msg and "200000" in msg
    need = int(msg.split("needs about ")[1].split()[0])
    ref = 5.0 * 8e6 / math.pi
    assert ref <= need <= 1.05 * ref, (need, ref)


def test_max_fractures_counts_all_sets():
    sets = [with_set(name="A", p32=None, count=600), with_set(name="B", p32=None, count=600)]
    with pytest.raises(SceneError, match=r"dfn\.max_fractures.*1200"):
        scene_from_dict({**copy.deepcopy(BASE), "dfn": {"max_fractures": 1000}, "joint_set": sets}, "s.toml")


def test_bad_network_file_rows(tmp_path):
    (tmp_path / "n.csv").write_text("id,set,cx,cy,cz,nx,ny,nz,radius\na,X,4,3,3,0,0,1,-1.0\n")
    d = {**copy.deepcopy(BASE), "dfn": {"file": "n.csv"}}
    with pytest.raises(SceneError, match=r"row 1\)\.radius"):
        scene_from_dict(d, tmp_path / "s.toml")
    (tmp_path / "m.csv").write_text("id,set,cx,cy,cz,nx,ny,nz,radius\na,X,4,3,3,0,0,0,1.0\n")
    d["dfn"]["file"] = "m.csv"
    with pytest.raises(SceneError, match="zero vector"):
        scene_from_dict(d, tmp_path / "s.toml")
    (tmp_path / "k.csv").write_text("id,set,cx,cy,cz,nx,ny,nz,radius\na,X,4,3,3,0,0,1,1.0\na,X,4,3,3,0,1,0,1.0\n")
    d["dfn"]["file"] = "k.csv"
    with pytest.raises(SceneError, match="repeats the id"):
        scene_from_dict(d, tmp_path / "s.toml")


def test_no_network_in_scene(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(toml_of(BASE))
    rc = sgim_main(["dfn", str(tmp_path / "s.toml"), "-o", str(tmp_path / "o")])
    assert rc == 2 and "no fracture network" in capsys.readouterr().err and not (tmp_path / "o").exists()
