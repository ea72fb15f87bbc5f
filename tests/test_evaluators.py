"""Study evaluators (cases/lib/evaluators.py) against independent references: the Hoek & Bray paper case, a
brute-force breadth-first search of the bond graph, and the analytical sliding block."""
from __future__ import annotations

import math
from collections import deque
from pathlib import Path

import numpy as np
import pytest

from cases.lib.evaluators import EVALUATORS, detached_clusters, orientation
from sgim.geometry import dip_to_normal

STUDY_SCENES = Path(__file__).resolve().parents[1] / "cases" / "scenes" / "studies" / "scenes"
G = 9.81


def _wedge_scene(tmp_path, joint_a=(45.0, 5.0), joint_b=(55.0, 135.0), friction=25.0, name="w.toml"):
    text = (STUDY_SCENES / "wedge.toml").read_text()
    text = text.replace("joint_a = [45.0, 5.0]", f"joint_a = [{joint_a[0]}, {joint_a[1]}]")
    text = text.replace("joint_b = [55.0, 135.0]", f"joint_b = [{joint_b[0]}, {joint_b[1]}]")
    text = text.replace("friction = 25.0", f"friction = {friction}")
    p = tmp_path / name
    p.write_text(text)
    return p


def test_registry_declares_results_and_needs():
    assert {"wedge-hb", "wedge-dda", "sgim-build", "dda-run", "yade", "liggghts"} <= set(EVALUATORS)
    assert EVALUATORS["yade"].needs == ("yade",) and EVALUATORS["liggghts"].needs == ("liggghts",)
    for name, ev in EVALUATORS.items():
        assert callable(ev.fn) and ev.description and ev.results
        assert "error" not in ev.results  # the results table's own error column holds the failure message


def test_wedge_hb_paper_case(tmp_path):
    # Hoek & Bray's worked example (the explicit 3D-DDA paper's wedge): FS 1.302 at phi = 25 deg, critical 19.7
    r = EVALUATORS["wedge-hb"].fn(_wedge_scene(tmp_path), tmp_path, {})
    assert set(r) == set(EVALUATORS["wedge-hb"].results)
    assert r["wedge"] == 1 and r["two_planes"] == 1
    assert r["fs"] == pytest.approx(1.302, abs=1e-3)
    assert r["phi_crit"] == pytest.approx(19.7, abs=0.05)
    # friction only: FS scales with tan(phi) (same geometry at another friction)
    r30 = EVALUATORS["wedge-hb"].fn(_wedge_scene(tmp_path, friction=30.0, name="w30.toml"), tmp_path, {})
    assert r30["fs"] == pytest.approx(r["fs"] * math.tan(math.radians(30)) / math.tan(math.radians(25)), rel=1e-9)


def test_wedge_hb_sampled_pole_below_horizon_and_no_wedge(tmp_path):
    # a Fisher sample may come out as dip > 90: (135, 185) is the plane 45/005 seen from below
    r = EVALUATORS["wedge-hb"].fn(_wedge_scene(tmp_path, joint_a=(135.0, 185.0)), tmp_path, {})
    assert r["fs"] == pytest.approx(1.302, abs=1e-3)
    # joints whose line of intersection dips into the slope: no wedge slides out; every value but the flag NaN
    r = EVALUATORS["wedge-hb"].fn(_wedge_scene(tmp_path, joint_a=(45.0, 185.0), joint_b=(55.0, 315.0), name="n.toml"),
                                  tmp_path, {})
    assert r["wedge"] == 0 and math.isnan(r["fs"]) and math.isnan(r["phi_crit"])


@pytest.mark.parametrize("pair", [(45, 5), (135, 185), (-30, 100), (100, 10), (90, 370), (0, 0), (260, 40)])
def test_orientation_is_the_same_plane(pair):
    dip, dd = orientation(pair)
    assert 0 <= dip <= 90 and 0 <= dd < 360
    a, b = dip_to_normal(*pair), dip_to_normal(dip, dd)
    assert abs(abs(float(a @ b)) - 1.0) < 1e-12  # same plane (normal up to its sign)


def test_wedge_dda_against_hoek_bray(tmp_path):
    r = EVALUATORS["wedge-dda"].fn(_wedge_scene(tmp_path), tmp_path / "case", {})
    assert set(r) == set(EVALUATORS["wedge-dda"].results)
    assert r["fs_hb"] == pytest.approx(1.302, abs=1e-3)
    assert r["phi_crit_dda"] == pytest.approx(19.7, abs=0.2)
    assert abs(r["error_fs"]) < 0.01
    assert r["error_fs"] == pytest.approx(r["fs_dda"] / r["fs_hb"] - 1.0, rel=1e-12)
    assert r["fs_dda"] == pytest.approx(math.tan(math.radians(25.0)) / math.tan(math.radians(r["phi_crit_dda"])))
    assert (tmp_path / "case" / "wedge_dda.json").is_file()


# -- detached clusters ----------------------------------------------------------------------------------
def _bfs_detached(centers, radii, pairs, colour, lo, hi, faces):
    """Plain-Python reference: breadth-first search over the bonded non-red spheres."""
    n = len(centers)
    adj = [[] for _ in range(n)]
    for i, j in pairs:
        i, j = int(i), int(j)
        if colour[i] != 1 and colour[j] != 1:
            adj[i].append(j)
            adj[j].append(i)
    seen = [False] * n
    out = []
    for s in range(n):
        if seen[s] or colour[s] == 1:
            continue
        comp, q = [], deque([s])
        seen[s] = True
        while q:
            u = q.popleft()
            comp.append(u)
            for v in adj[u]:
                if not seen[v]:
                    seen[v] = True
                    q.append(v)
        supported = False
        for u in comp:
            for f in faces:
                ax = "xyz".index(f[0])
                d = centers[u][ax] - lo[ax] if f[1] == "-" else hi[ax] - centers[u][ax]
                if d <= 2 * radii[u]:
                    supported = True
        if not supported:
            out.append(len(comp))
    return len(out), sum(out), max(out, default=0)


SMALL_DFN = """
name = "small_dfn"
[domain]
min = [0.0, 0.0, 0.0]
max = [3.0, 3.0, 2.0]
[packing]
kind = "cubic"
radius = 0.1
[bonds]
rule = "colour"
[dfn]
seed = 7
[[joint_set]]
name = "J1"
dip = 80.0
dip_direction = 30.0
kappa = 10.0
p32 = 2.5
radius = 0.6
[[joint_set]]
name = "J2"
dip = 10.0
dip_direction = 200.0
kappa = 10.0
p32 = 2.0
radius = 0.6
[[discontinuity]]
name = "fault"
centre = [1.5, 1.5, 1.0]
dip = 60.0
dip_direction = 120.0
radius = 5.0
thickness = 0.25
"""


def test_sgim_build_detached_clusters_against_bfs(tmp_path):
    from sgim.builder import build_model
    from sgim.scene import load_scene

    p = tmp_path / "small_dfn.toml"
    p.write_text(SMALL_DFN)
    r = EVALUATORS["sgim-build"].fn(p, tmp_path, {})
    assert set(r) == set(EVALUATORS["sgim-build"].results)
    scene = load_scene(p)
    m = build_model(scene)
    pairs = np.asarray(m.bonds).reshape(-1, 2)[m.bonded]
    c, rad, col = m.centers.tolist(), m.radii.tolist(), m.colour.tolist()
    lo, hi = scene.domain.min.tolist(), scene.domain.max.tolist()
    ref = _bfs_detached(c, rad, pairs.tolist(), col, lo, hi, ("x-", "x+", "y-", "y+", "z-"))
    assert ref[0] > 0  # the network does detach pieces: the comparison means something
    assert (r["detached_clusters"], r["detached_spheres"], r["largest_detached"]) == ref
    assert r["red"] == int(np.sum(m.colour == 1)) and r["spheres"] == m.n
    assert r["red_fraction"] == pytest.approx(r["red"] / r["spheres"])
    # another choice of supported faces, same reference
    got = detached_clusters(m.centers, m.radii, pairs, m.colour, lo, hi, faces=("z-",))
    assert (got["detached_clusters"], got["detached_spheres"], got["largest_detached"]) == \
        _bfs_detached(c, rad, pairs.tolist(), col, lo, hi, ("z-",))


def test_detached_clusters_layer_cut_by_a_full_joint(tmp_path):
    # a cube of 10 x 10 x 10 cubic-packed spheres cut at mid-height by a joint across the whole domain: held by
    # the bottom face alone, the upper 500 spheres form one detached cluster; held by the sides as well, none
    from sgim.builder import build_model
    from sgim.scene import load_scene

    p = tmp_path / "layer.toml"
    p.write_text('name = "layer"\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n[packing]\nkind = "cubic"\n'
                 'radius = 0.05\n[bonds]\nrule = "colour"\n[[discontinuity]]\nname = "j"\ncentre = [0.5, 0.5, 0.5]\n'
                 'dip = 0.0\ndip_direction = 0.0\nradius = 5.0\nthickness = 0.0\n')
    m = build_model(load_scene(p))
    pairs = np.asarray(m.bonds).reshape(-1, 2)[m.bonded]
    got = detached_clusters(m.centers, m.radii, pairs, m.colour, (0, 0, 0), (1, 1, 1), faces=("z-",))
    assert got["detached_clusters"] == 1 and got["detached_spheres"] == 500 and got["largest_detached"] == 500
    got = detached_clusters(m.centers, m.radii, pairs, m.colour, (0, 0, 0), (1, 1, 1))
    assert got["detached_clusters"] == 0 and got["detached_spheres"] == 0


# -- dda-run ---------------------------------------------------------------------------------------------
def _incline_scene(tmp_path, friction=20.0, duration=0.5):
    text = (STUDY_SCENES / "incline.toml").read_text()
    text = text.replace("friction = 20.0", f"friction = {friction}").replace("duration = 1.0", f"duration = {duration}")
    p = tmp_path / f"incline_{friction:g}.toml"
    p.write_text(text)
    return p


def test_dda_run_incline_against_analytical(tmp_path):
    r = EVALUATORS["dda-run"].fn(_incline_scene(tmp_path), tmp_path, {})
    assert set(r) == set(EVALUATORS["dda-run"].results)
    t = r["steps"] * r["dt"]
    a = math.radians(30.0)
    s_ref = 0.5 * G * (math.sin(a) - math.tan(math.radians(20.0)) * math.cos(a)) * t * t
    assert r["reference"] == pytest.approx(s_ref, rel=1e-9)
    assert abs(r["error_disp"]) < 2e-3
    assert r["displacement"] == pytest.approx(s_ref, rel=2e-3)
    assert r["moved"] == 1 and r["error_energy"] < 1e-3


def test_dda_run_incline_that_holds(tmp_path):
    # friction 40 > slope 30: the block must stay; error = displacement / block size
    r = EVALUATORS["dda-run"].fn(_incline_scene(tmp_path, friction=40.0, duration=0.3), tmp_path, {})
    assert r["reference"] == 0.0
    assert 0 <= r["error_disp"] < 1e-3 and r["moved"] == 0


# -- sgim-volume -----------------------------------------------------------------------------------------
def test_sgim_volume_inclined_plane(tmp_path):
    text = (STUDY_SCENES / "excavation_plane.toml").read_text().replace("radius = 1.0", "radius = 0.5")
    p = tmp_path / "plane.toml"
    p.write_text(text)
    r = EVALUATORS["sgim-volume"].fn(p, tmp_path, {})
    assert set(r) == set(EVALUATORS["sgim-volume"].results)
    # exact volume below z = 12 + 0.25 x + 0.1 y over 40 x 30: plan area x height at the centre
    assert r["exact_volume"] == pytest.approx(40 * 30 * (12 + 0.25 * 20 + 0.1 * 15), rel=1e-12)
    # the kept sites: cubic lattice centres whose whole sphere lies below the plane (distance >= r)
    c = np.arange(0.5, 40, 1.0)  # r = 0.5: centres 2 r apart from r off the box
    X, Y, Z = np.meshgrid(c, c[c < 30], c[c < 30], indexing="ij")
    dist = (12 + 0.25 * X + 0.1 * Y - Z) / math.sqrt(1 + 0.25 ** 2 + 0.1 ** 2)
    n = int(np.sum(dist >= 0.5))
    assert r["spheres"] == n
    assert r["kept_volume"] == pytest.approx(n * 1.0 ** 3, rel=1e-12)  # one (2 r)^3 cell per kept site
    assert r["error_volume"] == pytest.approx(n / r["exact_volume"] - 1, rel=1e-9)


# -- dda-spheres (the adapters' in-house run) --------------------------------------------------------------
def test_dda_spheres_hanging_block_against_bond_graph(tmp_path):
    # the bonded block hangs from its fixed top layer; the part below the joint has no bond path to it and falls
    from adapters.spec import from_scene

    scene = Path(__file__).resolve().parents[1] / "cases" / "scenes" / "crossval" / "hang_joint.toml"
    r = EVALUATORS["dda-spheres"].fn(scene, tmp_path, {})
    assert set(r) == set(EVALUATORS["dda-spheres"].results)
    run = from_scene(scene)
    adj = [[] for _ in range(run.n)]
    for i, j in zip(run.bond_i.tolist(), run.bond_j.tolist()):
        adj[i].append(j)
        adj[j].append(i)
    held = [bool(f) for f in run.fixed]
    q = deque(k for k in range(run.n) if held[k])
    while q:
        u = q.popleft()
        for v in adj[u]:
            if not held[v]:
                held[v] = True
                q.append(v)
    falls = run.n - sum(held)
    assert 0 < falls < run.n
    assert r["detached"] == falls and r["reference_detached"] == falls and r["error_detached"] == 0.0
