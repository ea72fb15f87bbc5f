"""Inner excavations: built-in shapes against their analytic solids, the removal rule against
brute force, scene errors, and the build."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sgim import shapes
from sgim.builder import build_model
from sgim.cavities import cavity_set
from sgim.meshquery import TriMesh
from sgim.packing import lattice_for
from sgim.scene import SceneError, scene_from_dict
from test_meshquery import box_sdf, brute_distance

_SCRIPT = Path(sys.executable).parent / "sgim"
SGIM = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "sgim.cli"]


# ---------------------------------------------------------------------------
# analytic mitred tubes (the definition: a union of prisms cut by the mitre planes)

def _tube_parts(path):
    P = np.asarray(path, float)
    T = np.diff(P, axis=0)
    T /= np.linalg.norm(T, axis=1)[:, None]
    M = [T[0]] + [(T[i - 1] + T[i]) / np.linalg.norm(T[i - 1] + T[i]) for i in range(1, len(T))] + [T[-1]]
    return P, T, M


def _frame(t):
    up = np.array([0.0, 0.0, 1.0])
    v = up - (up @ t) * t
    v /= np.linalg.norm(v)
    return np.cross(v, t), v


def tube_classes(p, path, in_section, margin):
    """(surely inside, surely outside) of a section swept along path with mitred joints.

    in_section(u, v, grow) says if local (u, v) lies in the section grown by ``grow``."""
    P, T, M = _tube_parts(path)
    inside = np.zeros(len(p), bool)
    maybe = np.zeros(len(p), bool)
    for i in range(len(T)):
        u, v = _frame(T[i])
        a = (p - P[i]) @ M[i]
        b = (p - P[i + 1]) @ M[i + 1]
        lu, lv = (p - P[i]) @ u, (p - P[i]) @ v
        inside |= (a > margin) & (b < -margin) & in_section(lu, lv, -margin)
        maybe |= (a > -margin) & (b < margin) & in_section(lu, lv, margin)
    return inside, ~maybe


def circle_section(R):
    return lambda u, v, g: np.hypot(u, v) < R + g


def horseshoe_section(w, h):
    rc, hs = w / 2, h - w / 2

    def f(u, v, g):
        wall = (np.abs(u) < rc + g) & (v > -g) & (v < hs)
        crown = (v >= hs) & (np.hypot(u, v - hs) < rc + g)
        return wall | crown

    return f


# a bend in a vertical plane, then two in a horizontal plane (the joints are exact there)
PATH = [[-20.0, 0.0, 3.0], [0.0, 0.0, 5.0], [8.0, 0.0, 5.0], [22.0, 12.0, 5.0], [22.0, 30.0, 5.0]]


def test_circular_tunnel_matches_mitred_cylinders():
    R, n = 2.5, 48
    V, F = shapes.circular_tunnel(PATH, R, n)
    mesh = TriMesh(V, F)
    assert mesh.closed and mesh.report["flipped_faces"] == 0 and mesh.volume > 0
    rng = np.random.default_rng(11)
    p = rng.uniform([-24, -5, -1], [27, 35, 10], (60000, 3))
    err = R * (1 - math.cos(math.pi / n)) + 1e-6  # the inscribed polygon's sagitta
    sure_in, sure_out = tube_classes(p, PATH, circle_section(R), err)
    ins = mesh.inside(p)
    assert sure_in.sum() > 3000 and sure_out.sum() > 30000
    assert np.all(ins[sure_in]) and not np.any(ins[sure_out])
    # away from the joints and caps: inside == distance to the polyline axis < R
    P = np.asarray(PATH)
    dseg, tpar = [], []
    for i in range(len(P) - 1):
        a, b = P[i], P[i + 1]
        t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        dseg.append(np.linalg.norm(p - (a + t[:, None] * (b - a)), axis=1))
        tpar.append(t * np.linalg.norm(b - a))
    dseg, tpar = np.array(dseg), np.array(tpar)
    k = dseg.argmin(0)
    L = np.linalg.norm(np.diff(P, axis=0), axis=1)
    along = tpar[k, np.arange(len(p))]
    clear = (along > 2 * R) & (along < L[k] - 2 * R)
    d = dseg.min(0)
    ok = clear & (np.abs(d - R) > err)
    assert ok.sum() > 10000
    assert np.array_equal(ins[ok], d[ok] < R)


def test_horseshoe_tunnel_matches_analytic_section():
    w, h, n = 6.0, 5.0, 40
    V, F = shapes.horseshoe_tunnel(PATH, w, h, n)
    mesh = TriMesh(V, F)
    assert mesh.closed and mesh.report["flipped_faces"] == 0
    rng = np.random.default_rng(12)
    p = rng.uniform([-24, -6, 0], [28, 35, 12], (60000, 3))
    narc = n - 3
    err = (w / 2) * (1 - math.cos(math.pi / narc / 2)) + 1e-6
    sure_in, sure_out = tube_classes(p, PATH, horseshoe_section(w, h), err)
    ins = mesh.inside(p)
    assert sure_in.sum() > 2000
    assert np.all(ins[sure_in]) and not np.any(ins[sure_out])
    # a flat invert: the path runs along its centre, so the lowest points of a straight
    # horizontal tunnel are at the path height
    V2, _ = shapes.horseshoe_tunnel([[0, 0, 7.0], [10, 0, 7.0]], w, h, 41)  # 38 arc facets: apex vertex
    assert abs(V2[:, 2].min() - 7.0) < 1e-12 and abs(V2[:, 2].max() - 12.0) < 1e-12


def test_ellipsoid_and_box_cavities():
    c, r = np.array([1.0, -2.0, 3.0]), np.array([4.0, 2.0, 3.0])
    mesh = TriMesh(*shapes.ellipsoid(c, r, 64))
    rng = np.random.default_rng(13)
    p = rng.uniform(c - r - 1, c + r + 1, (40000, 3))
    q = np.sqrt((((p - c) / r) ** 2).sum(1))
    ins = mesh.inside(p)
    # the chords of a 64 x 32 grid stay within 1 - cos(pi/32) of the surface (relative)
    tol = 1 - math.cos(math.pi / 32) + 1e-9
    assert np.all(ins[q < 1 - tol]) and not np.any(ins[q > 1])
    lo, hi = np.array([0.3, 0.1, -0.7]), np.array([2.9, 1.3, 0.6])
    box = TriMesh(*shapes.box(lo, hi))
    p = rng.uniform(lo - 1, hi + 1, (20000, 3))
    sdf = box_sdf(p, lo, hi)
    assert np.array_equal(box.inside(p), sdf < 0)
    r = 0.35
    assert np.array_equal(box.overlaps(p, r), sdf < r)


def test_overlap_rule_against_brute_force():
    V, F = shapes.circular_tunnel([[0, 0, 0], [6, 1, 0.5], [10, 4, 0.5]], 1.2, 16)
    mesh = TriMesh(V, F)
    rng = np.random.default_rng(14)
    p = rng.uniform([-2, -3, -3], [12, 7, 3], (4000, 3))
    rad = rng.uniform(0.1, 0.6, len(p))
    d = brute_distance(p, mesh.vertices, mesh.faces).min(1)
    # the inside half of the rule is checked against the analytic solids above; here the
    # distance half against brute force (every triangle), with a radius per sphere
    ref = mesh.inside(p) | (d < rad)
    assert np.array_equal(mesh.overlaps(p, rad), ref)


def test_shape_parameters_refused():
    with pytest.raises(shapes.ShapeError, match="bend"):
        shapes.circular_tunnel([[0, 0, 0], [10, 0, 0], [0, 1, 0]], 1.0)
    with pytest.raises(shapes.ShapeError, match="too short"):
        shapes.circular_tunnel([[0, 0, 0], [10, 0, 0], [10.2, 3, 0], [0, 4, 0]], 2.0)
    with pytest.raises(shapes.ShapeError, match="width / 2"):
        shapes.horseshoe_tunnel([[0, 0, 0], [10, 0, 0]], 6.0, 2.0)
    with pytest.raises(shapes.ShapeError, match="repeats"):
        shapes.circular_tunnel([[0, 0, 0], [0, 0, 0], [5, 0, 0]], 1.0)


# ---------------------------------------------------------------------------
# scenes and the build

BASE = {
    "name": "cav",
    "domain": {"min": [-6.0, -5.0, -4.0], "max": [7.0, 6.0, 5.0]},
    "packing": {"kind": "cubic", "radius": 0.45},
    "output": {"formats": ["npz"]},
}


def scene(**extra):
    d = {**BASE, **extra}
    return scene_from_dict(d, "scene.toml")


def test_build_removes_exactly_the_overlapping_sites():
    lo1, hi1 = [-2.13, -1.71, -1.37], [1.29, 0.83, 2.11]
    sc = scene(cavity=[
        {"name": "room", "shape": "box", "min": lo1, "max": hi1},
        {"name": "cave", "shape": "ellipsoid", "centre": [4.1, 3.3, 1.2], "radii": [1.7, 1.3, 2.2], "segments": 32},
    ])
    model = build_model(sc)
    sites = lattice_for(sc).all_centres()
    r = sc.packing.radius
    cave = sc.cavities[1].mesh
    d_cave = brute_distance(sites, cave.vertices, cave.faces).min(1)
    gone = (box_sdf(sites, np.array(lo1), np.array(hi1)) < r) | (d_cave < r) | cave.inside(sites)
    # the ellipsoid mesh's inside agrees with the analytic solid away from its chords
    q = np.sqrt((((sites - [4.1, 3.3, 1.2]) / [1.7, 1.3, 2.2]) ** 2).sum(1))
    far = (q < 0.97) | (q > 1.0)
    assert np.array_equal(cave.inside(sites)[far], (q < 1)[far])
    kept = {tuple(x) for x in np.round(model.centers, 9)}
    want = {tuple(x) for x in np.round(sites[~gone], 9)}
    assert kept == want
    meta = model.meta["cavities"]
    assert [m["name"] for m in meta] == ["room", "cave"]
    assert sum(m["spheres_removed"] for m in meta) == int(gone.sum())


def test_clearance_of_scene_cavities():
    sc = scene(cavity=[
        {"shape": "box", "min": [-2.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0]},
        {"shape": "box", "min": [0.0, -3.0, -0.5], "max": [0.8, 3.0, 0.5]},  # crosses the first
    ])
    ms = cavity_set(sc)
    rng = np.random.default_rng(15)
    p = rng.uniform([-3, -4, -2], [2, 4, 2], (5000, 3))
    a = box_sdf(p, np.array([-2.0, -1, -1]), np.array([1.0, 1, 1]))
    b = box_sdf(p, np.array([0.0, -3, -0.5]), np.array([0.8, 3, 0.5]))
    np.testing.assert_allclose(ms.clearance(p), np.minimum(a, b), atol=1e-12)
    assert scene().cavities == [] and cavity_set(scene()) is None


def _cube_faces_open():
    V, F = shapes.box([0, 0, 0], [1, 1, 1])
    return V, F[2:]  # the bottom face missing


def test_open_cavity_refused(tmp_path):
    V, F = _cube_faces_open()
    with pytest.raises(SceneError) as e:
        scene(cavity=[{"vertices": V.tolist(), "faces": F.tolist()}])
    msg = str(e.value)
    assert "cavity[0].faces" in msg and "not closed" in msg and "\n" not in msg
    import meshio

    meshio.write(tmp_path / "open.stl", meshio.Mesh(V, [("triangle", F)]))
    with pytest.raises(SceneError) as e:
        scene_from_dict({**BASE, "cavity": [{"file": "open.stl"}]}, tmp_path / "scene.toml")
    msg = str(e.value)
    assert "cavity[0].file" in msg and "'open.stl'" in msg and "not closed" in msg
    # a closed file with a tiny hole (one small triangle of a fine sphere missing) is accepted
    Vs, Fs = shapes.ellipsoid([0, 0, 0], [2, 2, 2], 48)
    meshio.write(tmp_path / "holed.stl", meshio.Mesh(Vs, [("triangle", Fs[5:])]))
    sc = scene_from_dict({**BASE, "cavity": [{"file": "holed.stl"}]}, tmp_path / "scene.toml")
    assert not sc.cavities[0].mesh.closed


@pytest.mark.parametrize("cav, key", [
    ({"shape": "horseshoe_tunnel", "path": [[0, 0, 0], [5, 0, 0]], "width": 4.0, "height": 1.0}, "cavity[0].height"),
    ({"shape": "circular_tunnel", "path": [[0, 0, 0], [5, 0, 0], [0, 0.5, 0]], "radius": 1.0},
     "cavity[0].path[1]"),
    ({"shape": "circular_tunnel", "path": [[0, 0, 0]], "radius": 1.0}, "cavity[0].path"),
    ({"shape": "circular_tunnel", "path": [[0, 0, 0], [5, 0, 0]], "radius": -1.0}, "cavity[0].radius"),
    ({"shape": "circular_tunnel", "path": [[0, 0, 0], [5, 0, 0]], "radius": 1.0, "width": 2.0}, "cavity[0].width"),
    ({"shape": "circular_tunnel", "path": [[0, 0, 0], [5, 0, 0]], "radius": 1.0, "segments": 7.5},
     "cavity[0].segments"),
    ({"shape": "tube", "path": [[0, 0, 0], [5, 0, 0]]}, "cavity[0].shape"),
    ({"shape": "box", "min": [50, 50, 50], "max": [51, 51, 51]}, "cavity[0]"),
    ({"shape": "box", "min": [0, 0, 0], "max": [1, 1, 1], "file": "x.stl"}, "cavity[0]"),
])
def test_bad_cavity_keys(cav, key):
    with pytest.raises(SceneError) as e:
        scene(cavity=[cav])
    assert str(e.value).startswith(f"scene.toml: {key} = ")


def test_cli_open_cavity_exit_2_and_no_output(tmp_path):
    V, F = _cube_faces_open()
    text = (
        'name = "bad"\n[domain]\nmin = [-2, -2, -2]\nmax = [3, 3, 3]\n[packing]\nradius = 0.5\n'
        f"[[cavity]]\nvertices = {V.tolist()}\nfaces = {F.tolist()}\n"
    )
    (tmp_path / "bad.toml").write_text(text)
    res = subprocess.run([*SGIM, "build", "bad.toml", "-o", "out"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=240)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "cavity[0].faces" in lines[0] and "not closed" in lines[0]
    assert not (tmp_path / "out").exists() and list(tmp_path.iterdir()) == [tmp_path / "bad.toml"]
