"""Whole-model checks against the references in sgim_ref (used by test_cutting and test_properties)."""
from __future__ import annotations

import copy

import numpy as np

import sgim_ref as ref
from sgim.builder import build_model
from sgim.packing import make_lattice
from sgim.scene import scene_from_dict


def discs_of(d):
    """(M, S, R, d) of every discontinuity, recomputed from the scene dictionary."""
    out = []
    for t in d.get("discontinuity", []):
        if "normal" in t:
            S = ref.unit(t["normal"])
        else:
            S = ref.dip_normal(t["dip"], t["dip_direction"])
        out.append((np.asarray(t.get("centre", t.get("center")), float), S, float(t["radius"]),
                    float(t.get("thickness", 0.0))))
    return out


def reference_sites(scene):
    lo, hi, r = scene.domain.min, scene.domain.max, scene.packing.radius
    if scene.packing.kind == "cubic":
        sites = ref.cubic_sites(lo, hi, r)
    else:
        sites = make_lattice(scene.packing.kind, lo, hi, r).all_centres()
    return ref.kept(sites, [(s.vertices, s.faces, s.rule) for s in scene.excavations], r)


def check_model(d, scene, m):
    """Every reference comparison of a built model; returns the reference colours."""
    r = scene.packing.radius
    n = len(m.centers)
    # --- excavation: the kept set
    want = reference_sites(scene)
    got = ref.as_set(m.centers)
    assert len(got) == n
    assert got == ref.as_set(want), f"kept sets differ: {len(got - ref.as_set(want))} extra, " \
                                    f"{len(ref.as_set(want) - got)} missing"
    assert np.all(m.radii == r)
    # --- discontinuities as stored
    discs = discs_of(d)
    assert len(m.disc_radius) == len(discs)
    for k, (M, S, R, th) in enumerate(discs):
        assert np.array_equal(m.disc_centre[k], M)
        assert np.allclose(m.disc_normal[k], S, rtol=0, atol=1e-12)
        assert m.disc_radius[k] == R and m.disc_thickness[k] == th
    # --- membership table (eq. 13-16), rows sorted by (disc, sphere)
    s, dk, kind, off = ref.membership_table(m.centers, m.radii, discs)
    assert np.array_equal(m.member_disc, dk), "membership: disc column"
    assert np.array_equal(m.member_sphere, s), "membership: sphere column"
    assert np.array_equal(m.member_kind, kind), "membership: kind column"
    scale = 1.0 + float(np.abs(m.centers).max(initial=0.0))
    assert np.allclose(m.member_offset, off, rtol=0, atol=1e-12 * scale)
    # --- colours
    colour, source = ref.colours(n, (s, dk, kind, off))
    assert np.array_equal(m.colour, colour), "colours"
    assert np.array_equal(m.colour_source, source), "colour sources"
    # --- touching pairs
    tol = scene.bonds.tolerance
    bonds = ref.touching_pairs(m.centers, m.radii, tol)
    assert m.bonds.dtype == np.int64 and m.bonds.shape == bonds.shape
    assert np.array_equal(m.bonds, bonds)
    # --- bond rule
    if scene.bonds.rule == "colour":
        bonded = ref.colour_rule_bonded(bonds, colour)
    else:
        bonded = ref.geometric_rule_bonded(m.centers, bonds, colour, discs)
    assert np.array_equal(m.bonded, bonded), f"{scene.bonds.rule} rule: bonded"
    check_cut_by(m, discs, scene.bonds.rule)
    return colour, source


def check_cut_by(m, discs, rule):
    nd = len(discs)
    cut = ~m.bonded
    assert np.all(m.cut_by[m.bonded] == -1)
    assert np.all((m.cut_by[cut] >= 0) & (m.cut_by[cut] < nd))
    if not cut.any():
        return
    mem = {}
    for s, k, kind in zip(m.member_sphere, m.member_disc, m.member_kind):
        mem.setdefault(int(s), {})[int(k)] = int(kind)
    for b in np.nonzero(cut)[0]:
        i, j = (int(v) for v in m.bonds[b])
        k = int(m.cut_by[b])
        red_from_k = mem.get(i, {}).get(k) == 1 or mem.get(j, {}).get(k) == 1
        if rule == "colour":
            # a red sphere's fault, or a joint that one of the two (green / blue) spheres sits by
            joint_member = discs[k][3] == 0 and (k in mem.get(i, {}) or k in mem.get(j, {}))
            assert red_from_k or joint_member, f"bond {i}-{j} cut by unrelated discontinuity {k}"
        else:
            M, S, R, th = discs[k]
            crosses = th == 0 and bool(ref.segment_crosses_disc(m.centers[[i]], m.centers[[j]], M, S, R)[0])
            assert red_from_k or crosses, f"bond {i}-{j} cut by discontinuity {k} that does not cross it"


def build(d):
    scene = scene_from_dict(copy.deepcopy(d), "random.toml")
    return scene, build_model(scene)


