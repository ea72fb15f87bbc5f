"""The block model of an sgim scene (dda/geoblocks.py) against independent references: the region's volume in
closed form (a box minus an inverted square frustum pit, minus box and ellipsoid cavities) or as the exact
polyhedral volume under a triangulated terrain; every block closed (V - E + F = 2), convex, outward; random points
inside exactly one block when they lie in the region (its own definition: below the surface's height, outside
the cavities) and in none otherwise; a disc that reaches no block cuts nothing; per point of a disc-made face,
joint or intact equals a brute-force test against every disc of the scene; bad [blocks] keys name their path."""
import copy

import numpy as np
import pytest

from dda.blockcut import euler_characteristic, face_planes
from dda.geoblocks import INTACT, KINDS, build_blocks
from dda.shapes import check_convex
from sgim.common import SceneError
from sgim.geometry import dip_to_normal, triangulate_plan
from sgim.scene import scene_from_dict

# the pit: domain 100 x 80 x 50, ground at z = 40, an inverted square frustum from [30,70]x[20,60] at the ground
# down to [40,60]x[30,50] at z = 20 (walls of slope 2)
O = [[0, 0, 40], [100, 0, 40], [100, 80, 40], [0, 80, 40]]
T = [[30, 20, 40], [70, 20, 40], [70, 60, 40], [30, 60, 40]]
F = [[40, 30, 20], [60, 30, 20], [60, 50, 20], [40, 50, 20]]
PIT_FACES = [[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
             [4, 5, 9], [4, 9, 8], [5, 6, 10], [5, 10, 9], [6, 7, 11], [6, 11, 10], [7, 4, 8], [7, 8, 11],
             [8, 9, 10], [8, 10, 11]]
FRUSTUM = 20.0 / 3.0 * (40 * 40 + 20 * 20 + 40 * 20)


def pit_height(p):
    """Height of the pit surface above (x, y): a transcription of the frustum's definition."""
    m = np.minimum.reduce([p[:, 0] - 30, 70 - p[:, 0], p[:, 1] - 20, 60 - p[:, 1]])
    return np.where(m > 0, np.maximum(20.0, 40.0 - 2.0 * m), 40.0)


def pit_scene(**blocks):
    data = {
        "domain": {"min": [0, 0, 0], "max": [100, 80, 50]},
        "packing": {"kind": "cubic", "radius": 0.5},
        "excavation": [{"name": "pit", "vertices": O + T + F, "faces": PIT_FACES}],
        "discontinuity": [
            {"name": "J1", "centre": [20, 30, 25], "dip": 60, "dip_direction": 120, "radius": 14},
            {"name": "J2", "centre": [75, 55, 30], "dip": 35, "dip_direction": 250, "radius": 9},
            {"name": "F1", "centre": [50, 40, 15], "dip": 70, "dip_direction": 300, "radius": 40, "thickness": 2.0},
        ],
        "blocks": {"min_volume": 0.5, "joint_set": [
            {"name": "S1", "dip": 80, "dip_direction": 130, "spacing": 17, "origin": [1, 2, 3]},
            {"name": "S2", "dip": 15, "dip_direction": 10, "spacing": 13}]},
    }
    data["blocks"].update(blocks)
    return data


def block_check(model):
    """Every block closed, convex and outward (dda.shapes.check_convex with Euler's V - E + F = 2)."""
    for i, spec in enumerate(model.specs()):
        assert euler_characteristic(model.blocks[i]) == 2, i
        assert check_convex(spec, tol=1e-7) == [], (i, check_convex(spec, tol=1e-7)[:2])


def point_counts(model, pts):
    """How many blocks hold each point (inside every face plane)."""
    count = np.zeros(len(pts), np.int64)
    for b in model.blocks:
        lo, hi = b.v.min(0), b.v.max(0)
        near = np.nonzero(np.all((pts >= lo) & (pts <= hi), axis=1))[0]
        if len(near):
            n, d = face_planes(b)
            count[near] += (pts[near] @ n.T - d < 0).all(1)
    return count


def test_pit_volume_closed_form_and_block_validity():
    sc = scene_from_dict(pit_scene(), "pit.toml")
    m = build_blocks(sc)
    ref = 100 * 80 * 40 - FRUSTUM
    assert abs(m.volumes().sum() - ref) <= 1e-9 * ref
    assert m.summary()["blocks"] == len(m.blocks) > 100
    block_check(m)
    assert (m.volumes() > 0).all()
    # the fault's slab pieces carry its material
    assert "F1" in m.summary()["materials"]
    rng = np.random.default_rng(5)
    pts = rng.uniform([0, 0, 0], [100, 80, 50], size=(40000, 3))
    h = pit_height(pts)
    pts = pts[np.abs(pts[:, 2] - h) > 1e-6]
    count = point_counts(m, pts)
    assert count.max() <= 1  # no two blocks overlap
    below = pts[:, 2] < pit_height(pts)
    assert (count[below] == 1).all() and (count[~below] == 0).all()


def test_cavities_box_and_ellipsoid_removed_exactly():
    data = pit_scene()
    data["cavity"] = [{"name": "room", "shape": "box", "min": [5, 5, 5], "max": [25, 27, 15]},
                      {"name": "cavern", "shape": "ellipsoid", "centre": [80, 20, 15], "radii": [8, 5, 6],
                       "segments": 16}]
    sc = scene_from_dict(data, "cav.toml")
    m = build_blocks(sc)
    ell = sc.cavities[1].mesh
    ref = 100 * 80 * 40 - FRUSTUM - 20 * 22 * 10 - abs(ell.volume)
    assert abs(m.volumes().sum() - ref) <= 1e-9 * ref
    block_check(m)
    rng = np.random.default_rng(7)
    pts = rng.uniform([0, 0, 0], [100, 80, 40], size=(30000, 3))
    pts = pts[np.abs(pts[:, 2] - pit_height(pts)) > 1e-6]
    inside = np.asarray(ell.inside(pts), bool) | np.all((pts > [5, 5, 5]) & (pts < [25, 27, 15]), axis=1)
    region = (pts[:, 2] < pit_height(pts)) & ~inside
    count = point_counts(m, pts)
    assert count.max() <= 1
    assert (count[region] == 1).all() and (count[~region] == 0).all()
    kinds = {KINDS[m.sources[s].kind] for b in m.blocks for s in b.src}
    assert {"domain", "joint", "excavation", "fault"} <= kinds


def test_triangulated_terrain_exact_volume():
    rng = np.random.default_rng(11)
    xs, ys = np.arange(0, 61, 10.0), np.arange(0, 51, 10.0)
    pts = np.array([[x, y, 25 + rng.uniform(-8, 8)] for x in xs for y in ys])
    data = {"domain": {"min": [0, 0, 0], "max": [60, 50, 40]}, "packing": {"kind": "cubic", "radius": 0.5},
            "excavation": [{"name": "terrain", "points": pts.tolist()}],
            "blocks": {"min_volume": 0.2, "joint_set": [
                {"name": "A", "dip": 70, "dip_direction": 40, "spacing": 7},
                {"name": "B", "dip": 50, "dip_direction": 220, "spacing": 9},
                {"name": "C", "dip": 5, "dip_direction": 100, "spacing": 6}]}}
    m = build_blocks(scene_from_dict(data, "terrain.toml"))
    v, f = triangulate_plan(pts)
    tri = v[f]
    area = 0.5 * np.abs((tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1])
                        - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0]))
    ref = float((area * tri[:, :, 2].mean(1)).sum())  # the exact integral of a linear height over each triangle
    assert abs(area.sum() - 60 * 50) < 1e-9 * 3000
    assert abs(m.volumes().sum() - ref) <= 1e-9 * ref
    block_check(m)
    assert any(KINDS[m.sources[s].kind] == "intact" for b in m.blocks for s in b.src)  # valley splits


def test_disc_reaching_no_block_cuts_nothing():
    base = scene_from_dict(pit_scene(), "a.toml")
    data = pit_scene()
    # in the pit's air: at z = 35 the pit spans x 32.5..67.5, y 22.5..57.5
    data["discontinuity"].append({"name": "air", "centre": [50, 40, 35], "dip": 30, "dip_direction": 80,
                                  "radius": 3})
    sc = scene_from_dict(data, "b.toml")
    a, b = build_blocks(base), build_blocks(sc)
    assert len(a.blocks) == len(b.blocks)
    for x, y in zip(a.blocks, b.blocks):
        assert np.array_equal(x.v, y.v) and x.faces == y.faces
    # the same disc moved into the rock cuts
    data["discontinuity"][-1]["centre"] = [50, 40, 10]
    c = build_blocks(scene_from_dict(data, "c.toml"))
    assert len(c.blocks) > len(a.blocks)


def test_point_kind_against_every_disc():
    data = pit_scene()
    sc = scene_from_dict(data, "k.toml")
    m = build_blocks(sc)
    planes = []  # brute force: every disc's (and every fault face's) plane and radius, from the scene itself
    for d in data["discontinuity"]:
        n = dip_to_normal(d["dip"], d["dip_direction"])
        t = d.get("thickness", 0.0)
        for off in ((-t / 2, t / 2) if t > 0 else (0.0,)):
            planes.append((np.asarray(d["centre"], float) + off * n, n, d["radius"], "fault" if t > 0 else "joint"))
    rng = np.random.default_rng(3)
    seen = {"joint": 0, "fault": 0, "intact": 0}
    for i, b in enumerate(m.blocks):
        for k, f in enumerate(b.faces):
            if m.sources[b.src[k]].shape != "disc":
                continue
            w = rng.dirichlet(np.ones(len(f)), size=40)
            w[:5] = np.eye(len(f))[rng.integers(0, len(f), 5)]  # vertices too
            p = w @ b.v[f]
            got = m.point_kinds(i, k, p)
            # the one disc plane holding the whole face, then each point against that disc's radius
            holding = [q for q in planes if (np.abs((b.v[f] - q[0]) @ q[1]) < 1e-6).all()]
            assert len(holding) == 1, (i, k, len(holding))
            c, n, r, kind = holding[0]
            rel = p - c
            radial = np.linalg.norm(rel - np.outer(rel @ n, n), axis=1)
            want = np.where(radial <= r, KINDS.index(kind), INTACT)
            assert np.array_equal(got, want), (i, k)
            for g in got:
                seen[KINDS[g]] += 1
    assert min(seen.values()) > 0, seen  # joint, fault and intact points all occur


BAD = [
    ({"colour": 1}, "blocks.colour"),
    ({"min_volume": -1}, "blocks.min_volume"),
    ({"cut_by": ["nope"]}, "blocks.cut_by[0]"),
    ({"cut_by": "J1"}, "blocks.cut_by"),
    ({"friction": 95}, "blocks.friction"),
    ({"joint_set": [{"dip": 40, "dip_direction": 10}]}, "blocks.joint_set[0].spacing"),
    ({"joint_set": [{"dip": 40, "dip_direction": 10, "spacing": -2}]}, "blocks.joint_set[0].spacing"),
    ({"joint_set": [{"dip": 40, "dip_direction": 10, "spacing": 2, "persistence": 1.5}]},
     "blocks.joint_set[0].persistence"),
    ({"joint_set": [{"dip": 40, "dip_direction": 10, "spacing": 2, "extent": {"min": [0, 0, 9], "max": [5, 5, 1]}}]},
     "blocks.joint_set[0].extent.max[2]"),
    ({"joint_set": [{"dip": 40, "dip_direction": 10, "spacing": 2, "wobble": 1}]}, "blocks.joint_set[0].wobble"),
]


@pytest.mark.parametrize("change,key", BAD)
def test_bad_blocks_keys_name_their_path(change, key):
    data = pit_scene()
    data["blocks"] = copy.deepcopy(change)
    with pytest.raises(SceneError) as exc:
        scene_from_dict(data, "bad.toml")
    assert exc.value.key == key
    assert str(exc.value).startswith(f"bad.toml: {key} = ")


def test_cut_by_selects_discs_and_min_volume_skips_sliver_cuts():
    m_all = build_blocks(scene_from_dict(pit_scene(), "a.toml"))
    m_f = build_blocks(scene_from_dict(pit_scene(cut_by=["F1"]), "f.toml"))
    names = {m_f.sources[s].name for b in m_f.blocks for s in b.src}
    assert "F1" in names and "J1" not in names and "J2" not in names
    assert len(m_f.blocks) < len(m_all.blocks)
    big = build_blocks(scene_from_dict(pit_scene(min_volume=400.0), "big.toml"))
    assert big.stats["sliver_cuts_skipped"] > 0
    ref = 100 * 80 * 40 - FRUSTUM
    assert abs(big.volumes().sum() - ref) <= 1e-9 * ref


def _toml(data):
    """A minimal TOML writer for the scene dicts above (tables, arrays of tables, numbers, strings, lists)."""
    def val(v):
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + "}"
        return repr(v)

    lines = []
    for k, v in data.items():
        if not isinstance(v, (dict, list)) or (isinstance(v, list) and not all(isinstance(x, dict) for x in v)):
            lines.append(f"{k} = {val(v)}")
    for k, v in data.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            subs = {a: b for a, b in v.items() if isinstance(b, list) and b and all(isinstance(x, dict) for x in b)}
            lines += [f"{a} = {val(b)}" for a, b in v.items() if a not in subs]
            for a, b in subs.items():
                for t in b:
                    lines.append(f"[[{k}.{a}]]")
                    lines += [f"{x} = {val(y)}" for x, y in t.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for t in v:
                lines.append(f"[[{k}]]")
                lines += [f"{x} = {val(y)}" for x, y in t.items()]
    return "\n".join(lines) + "\n"


def test_dda_blocks_command(tmp_path):
    import json
    import subprocess
    import sys

    import meshio

    scene = tmp_path / "pit.toml"
    scene.write_text(_toml(pit_scene()))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "dda.cli", "blocks", str(scene), "-o", str(out), "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert json.loads(r.stdout) == summary
    ref = 100 * 80 * 40 - FRUSTUM
    assert abs(summary["volume"] - ref) <= 1e-9 * ref
    mesh = meshio.read(out / "blocks.vtu")
    block = mesh.cell_data["block"][0]
    assert block.max() + 1 == summary["blocks"]
    assert (np.bincount(block) >= 4).all()  # every block has its faces' triangles
    kinds = {summary["kinds"][k] for k in np.unique(mesh.cell_data["kind"][0])}
    assert {"domain", "joint", "excavation", "fault"} <= kinds
    bad = pit_scene(colour=3)
    scene.write_text(_toml(bad))
    r = subprocess.run([sys.executable, "-m", "dda.cli", "blocks", str(scene), "-o", str(tmp_path / "o2")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "blocks.colour = 3" in r.stderr, r.stderr
    assert not (tmp_path / "o2").exists()


def test_persistence_and_extent_of_fabric_sets():
    base = {"domain": {"min": [0, 0, 0], "max": [40, 30, 20]}, "packing": {"kind": "cubic", "radius": 0.5}}
    full = dict(base, blocks={"joint_set": [{"dip": 60, "dip_direction": 30, "spacing": 3},
                                            {"dip": 20, "dip_direction": 200, "spacing": 4}]})
    half = copy.deepcopy(full)
    half["blocks"]["joint_set"][0]["persistence"] = 0.5
    box = copy.deepcopy(full)
    box["blocks"]["joint_set"][0]["extent"] = {"min": [5, 5, 0], "max": [30, 25, 20]}
    mf, mh, mb = (build_blocks(scene_from_dict(d, "p.toml")) for d in (full, half, box))
    for m in (mf, mh, mb):
        assert abs(m.volumes().sum() - 24000) <= 1e-9 * 24000
        block_check(m)
    assert len(mb.blocks) < len(mf.blocks) and len(mh.blocks) < len(mf.blocks)
    # the bounded set (cut last) made faces, each the section of a whole block with its centre in the box
    src = [k for k, s in enumerate(mb.sources) if s.name == "B1"]
    faces = [b.v[f] for b in mb.blocks for f, s in zip(b.faces, b.src) if s in src]
    assert faces and all(((p.mean(0) >= [5, 5, 0]) & (p.mean(0) <= [30, 25, 20])).all() for p in faces)
    far = [b for b in mf.blocks if (b.v.min(0)[:2] > [31, 26]).all() or (b.v.max(0)[:2] < [4, 4]).all()]
    assert far and not any(s in src for b in mb.blocks if (b.v.min(0)[:2] > [31, 26]).all() for s in b.src)


def test_triangulated_discontinuity_point_kinds():
    tri_v = [[5, 5, 8], [30, 8, 12], [12, 26, 9], [34, 28, 14]]
    data = {"domain": {"min": [0, 0, 0], "max": [40, 30, 20]}, "packing": {"kind": "cubic", "radius": 0.5},
            "discontinuity": [{"name": "S", "vertices": tri_v, "faces": [[0, 1, 2], [1, 3, 2]]}],
            "blocks": {"joint_set": [{"dip": 80, "dip_direction": 90, "spacing": 6}]}}
    m = build_blocks(scene_from_dict(data, "s.toml"))
    assert abs(m.volumes().sum() - 24000) <= 1e-9 * 24000
    block_check(m)
    v = np.array(tri_v, float)
    tris = [v[[0, 1, 2]], v[[1, 3, 2]]]
    rng = np.random.default_rng(2)
    seen = set()
    for i, b in enumerate(m.blocks):
        for k, f in enumerate(b.faces):
            if m.sources[b.src[k]].shape != "triangle":
                continue
            p = rng.dirichlet(np.ones(len(f)), size=30) @ b.v[f]
            got = m.point_kinds(i, k, p)
            # brute force: the point lies in (the plane of) one of the two triangles, by barycentric coordinates
            want = np.full(len(p), INTACT)
            for t in tris:
                n = np.cross(t[1] - t[0], t[2] - t[0])
                if not (np.abs((b.v[f] - t[0]) @ n) < 1e-6 * np.linalg.norm(n)).all():
                    continue
                m3 = np.column_stack([t[1] - t[0], t[2] - t[0], n])
                lam = np.linalg.solve(m3, (p - t[0]).T).T
                inside = (lam[:, 0] >= 0) & (lam[:, 1] >= 0) & (lam[:, 0] + lam[:, 1] <= 1)
                want[inside] = KINDS.index("joint")
            assert np.array_equal(got, want), (i, k)
            seen |= set(got.tolist())
    assert seen == {KINDS.index("joint"), INTACT}


def test_disc_reach_against_a_constrained_minimisation():
    """disc_reaches (section polygon, distance to the centre) against scipy's SLSQP: the nearest point to the
    disc's centre in the block and on its plane (inside every face plane), reached when within the radius."""
    from scipy.optimize import minimize

    from dda.blockcut import TBlock, disc_reaches
    from dda.shapes import random_rotation, shape

    rng = np.random.default_rng(8)
    agree = {True: 0, False: 0}
    for trial in range(150):
        spec = shape(["cube", "tetrahedron", "octahedron", "brick"][trial % 4], 2.0, rotation=random_rotation(rng))
        b = TBlock(spec.vertices, spec.faces, np.zeros(len(spec.faces), np.int64))
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        c = rng.uniform(-1.2, 1.2, 3)
        fn, fd = face_planes(b)
        res = minimize(lambda x: ((x - c) ** 2).sum(), c, jac=lambda x: 2 * (x - c), method="SLSQP",
                       constraints=[{"type": "ineq", "fun": lambda x: fd - fn @ x, "jac": lambda x: -fn},
                                    {"type": "eq", "fun": lambda x: np.array([n @ (x - c)]),
                                     "jac": lambda x: n[None, :]}], options={"ftol": 1e-14, "maxiter": 500})
        sec_ok = res.success and (fn @ res.x - fd <= 1e-7).all()
        if not sec_ok:  # the plane misses the block: no section, nothing reached
            assert not disc_reaches(b, c, n, 10.0)
            continue
        dist = float(np.linalg.norm(res.x - c))
        for r in (0.5 * dist, 2 * dist + 1e-3):
            if abs(r - dist) < 1e-6:
                continue
            got = disc_reaches(b, c, n, r)
            assert got == (dist <= r), (trial, r, dist)
            agree[got] += 1
    assert min(agree.values()) > 50, agree


def test_grid_finds_the_blocks_a_scan_of_every_box_finds():
    """The discs' cell grid (geoblocks._Grid) against a scan of every block's box (the definition _Pool.crossing
    transcribes): for random planes and disc boxes, the same blocks in the same order, also after blocks were
    replaced by their pieces."""
    from dda.blockcut import TBlock, split, unit
    from dda.geoblocks import BOX_FACES, _Grid, _Pool

    rng = np.random.default_rng(7)
    lo, hi = np.array([-10.0, -5.0, 0.0]), np.array([20.0, 15.0, 12.0])
    blocks = []
    for _ in range(300):
        a = rng.uniform(lo, hi - 0.5)
        b = np.minimum(a + rng.uniform(0.2, 4.0, 3), hi)
        v = np.array([[x, y, z] for z in (a[2], b[2]) for y in (a[1], b[1]) for x in (a[0], b[0])])
        blocks.append(TBlock(v, [list(f) for f in BOX_FACES], [0] * 6))
    pool = _Pool(blocks)
    grid = _Grid(pool, lo, hi)
    for step in range(60):
        n = unit(rng.normal(size=3))
        c = rng.uniform(lo, hi)
        r = rng.uniform(0.5, 8.0)
        blo, bhi = c - r, c + r
        ids = grid.crossing(n, float(n @ c), blo, bhi)
        ref = pool.crossing(n, float(n @ c), blo, bhi)
        assert [grid.blocks[i] for i in ids.tolist()] == [pool.blocks[i] for i in ref.tolist()]
        near = grid.near(blo, bhi)
        assert [grid.blocks[i] for i in near.tolist()] == [pool.blocks[i] for i in pool.near(blo, bhi).tolist()]
        if step % 3 == 0 and len(ref):  # cut the first crossing block in both, its pieces in its place
            i, k = int(ref[0]), int(ids[0])
            pieces = [p for p in split(pool.blocks[i], n, float(n @ c), 0) if p is not None]
            pool.replace({i: pieces})
            grid.replace({k: pieces})
    back = _Pool([])
    grid.to_pool(back)
    assert back.blocks == pool.blocks
    np.testing.assert_array_equal(back.lo, pool.lo)


def test_dda_blocks_bad_cut_away_is_refused_before_cutting(tmp_path, capsys):
    """dda blocks --png --cut-away with a bad expression: one line naming the option and value, exit 2, no
    output folder (the picture's cut-away leaves out the blocks whose centroid meets every condition, as
    sgim's cut_mask does for spheres)."""
    from dda.cli import main as dda_main

    scene = tmp_path / "pit.toml"
    scene.write_text(_toml(pit_scene()))
    out = tmp_path / "out"
    assert dda_main(["blocks", str(scene), "-o", str(out), "--png", "--cut-away", "q<1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--cut-away = 'q<1'" in err[0], err
    assert not out.exists()


def test_cavity_caps_are_wall_where_no_rock_lies_beyond_them():
    """cases/scenes/tunnel_blocks.toml (the tunnel is carved before the joint discs cut the crown): every face on
    the tunnel's facet planes is labelled by what lies beyond it, by brute force: points just outside a face
    labelled the tunnel's wall lie in the tunnel and in no block; a face labelled the tunnel's cap (intact rock)
    has another block beyond at least one of its points (random points of the face, 1e-6 of the block's size out)."""
    from cases import SCENES
    from sgim.scene import load_scene

    sc = load_scene(SCENES / "tunnel_blocks.toml")
    m = build_blocks(sc)
    names = [s.name for s in m.sources]
    wall, cap = names.index("tunnel"), names.index("tunnel (split)")
    mesh = sc.cavities[0].mesh
    rng = np.random.default_rng(3)
    seen = {wall: 0, cap: 0}
    for b in m.blocks:
        n, _ = face_planes(b)
        size = np.ptp(b.v, axis=0).max()
        for k, s in enumerate(b.src):
            if s not in seen:
                continue
            corners = b.v[b.faces[k]]
            w = rng.dirichlet(np.ones(len(corners)), size=200)
            pts = w @ corners + 1e-6 * size * n[k]
            beyond = point_counts(m, pts)
            if s == wall:
                assert (beyond == 0).all() and np.asarray(mesh.inside(pts), bool).all()
            else:
                assert beyond.max() == 1
            seen[s] += 1
    assert seen[wall] > 0 and seen[cap] > 0, seen
