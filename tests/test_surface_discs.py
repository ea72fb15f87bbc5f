"""Triangulated discontinuities: a fine polygon against the equivalent disc, a listric fault
against brute force over every triangle, defects, errors and the model file."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sgim import shapes
from sgim.builder import build_model
from sgim.meshquery import TriMesh
from sgim.model import SphereModel
from sgim.scene import SceneError, scene_from_dict

# ---------------------------------------------------------------------------
# brute force (numpy over every triangle), written apart from the library


def closest_brute(p, V, F, chunk=2000):
    """Nearest point of the triangle set to each p: (dist, foot (n,3), face)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    dist = np.empty(len(p))
    foot = np.empty((len(p), 3))
    face = np.empty(len(p), np.int64)
    for s in range(0, len(p), chunk):
        q = p[s:s + chunk]
        h = np.einsum("nmk,mk->nm", q[:, None] - a[None], n)
        proj = q[:, None] - h[..., None] * n[None]
        ins = np.ones(h.shape, bool)
        for u, v in ((a, b), (b, c), (c, a)):
            ins &= np.einsum("nmk,mk->nm", np.cross((v - u)[None], proj - u[None]), n) >= 0
        cand = [np.where(ins[..., None], proj, np.inf)]
        for u, v in ((a, b), (b, c), (c, a)):
            t = np.clip(np.einsum("nmk,mk->nm", q[:, None] - u[None], v - u) / ((v - u) ** 2).sum(1), 0, 1)
            cand.append(u[None] + t[..., None] * (v - u)[None])
        cand = np.stack(cand, 2)  # (n, m, 4, 3)
        d = np.linalg.norm(cand - q[:, None, None, :], axis=3)
        d = np.where(np.isfinite(d), d, np.inf)
        flat = d.reshape(len(q), -1).argmin(1)
        fi, ki = np.divmod(flat, 4)
        dist[s:s + chunk] = d.reshape(len(q), -1)[np.arange(len(q)), flat]
        foot[s:s + chunk] = cand[np.arange(len(q)), fi, ki]
        face[s:s + chunk] = fi
    return dist, foot, face


def boundary_segments(F):
    e = np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, cnt = np.unique(e, axis=0, return_counts=True)
    return u[cnt == 1]


def dist_to_segments(p, V, E):
    a, b = V[E[:, 0]], V[E[:, 1]]
    t = np.clip(np.einsum("nmk,mk->nm", p[:, None] - a[None], b - a) / ((b - a) ** 2).sum(1), 0, 1)
    return np.linalg.norm(p[:, None] - (a[None] + t[..., None] * (b - a)[None]), axis=2).min(1)


def height_at(xy, V, F):
    """z of the surface above plan points (nan outside its plan footprint)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    out = np.full(len(xy), np.nan)
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    for s in range(0, len(xy), 2000):
        q = xy[s:s + 2000]
        l1 = ((b[:, 1] - c[:, 1]) * (q[:, None, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (q[:, None, 1] - c[:, 1])) / den
        l2 = ((c[:, 1] - a[:, 1]) * (q[:, None, 0] - c[:, 0]) + (a[:, 0] - c[:, 0]) * (q[:, None, 1] - c[:, 1])) / den
        l3 = 1 - l1 - l2
        ins = (l1 >= 0) & (l2 >= 0) & (l3 >= 0)
        z = l1 * a[:, 2] + l2 * b[:, 2] + l3 * c[:, 2]
        hit = ins.any(1)
        out[s:s + 2000][hit] = z[hit, ins[hit].argmax(1)]
    return out


# ---------------------------------------------------------------------------

BASE = {
    "name": "surf",
    "domain": {"min": [-6.0, -5.0, -5.0], "max": [6.0, 5.0, 5.0]},
    "packing": {"kind": "cubic", "radius": 0.4},
    "output": {"formats": ["npz"]},
}


def build(discs, rule="colour", **extra):
    sc = scene_from_dict({**BASE, "discontinuity": discs, "bonds": {"rule": rule}, **extra}, "scene.toml")
    return sc, build_model(sc)


def polygon_disc(M, normal, R, n):
    """A fan of n triangles around M in the plane of the disc, counter-clockwise about normal."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    ang = 2 * np.pi * np.arange(n) / n
    V = np.vstack([M, M + R * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)])
    F = np.array([[0, 1 + i, 1 + (i + 1) % n] for i in range(n)])
    return V, F


@pytest.mark.parametrize("rule", ["colour", "geometric"])
@pytest.mark.parametrize("thickness", [0.0, 1.1])
def test_flat_polygon_equals_disc_away_from_rim(rule, thickness):
    M, R, n = np.array([0.3, -0.2, 0.1]), 3.7, 256
    dip, dd = 35.0, 120.0
    S = np.array([math.sin(math.radians(dip)) * math.sin(math.radians(dd)),
                  math.sin(math.radians(dip)) * math.cos(math.radians(dd)), math.cos(math.radians(dip))])
    V, F = polygon_disc(M, S, R, n)
    _, m_disc = build([{"centre": M.tolist(), "dip": dip, "dip_direction": dd, "radius": R, "thickness": thickness}],
                      rule)
    sc, m_surf = build([{"vertices": V.tolist(), "faces": F.tolist(), "thickness": thickness}], rule)
    assert sc.surfaces and not sc.discontinuities
    c = m_disc.centers
    assert np.array_equal(c, m_surf.centers)
    rel = c - M
    rho = np.linalg.norm(rel - np.outer(rel @ S, S), axis=1)
    rim = (rho >= R * math.cos(math.pi / n) - 1e-9) & (rho <= R + 1e-9)
    assert np.array_equal(m_disc.colour[~rim], m_surf.colour[~rim])
    assert (m_disc.colour != 0).sum() > 60
    # the membership rows agree, offsets included
    keep_d = ~rim[m_disc.member_sphere]
    keep_s = ~rim[m_surf.member_sphere]
    assert np.array_equal(m_disc.member_sphere[keep_d], m_surf.member_sphere[keep_s])
    assert np.array_equal(m_disc.member_kind[keep_d], m_surf.member_kind[keep_s])
    np.testing.assert_allclose(m_disc.member_offset[keep_d], m_surf.member_offset[keep_s], atol=1e-9)
    # bonds: the same cuts for pairs whose ends are clear of the rim by a bond length
    lmax = 2 * 0.4 * 1.001
    clear = (rho < R * math.cos(math.pi / n) - lmax) | (rho > R + lmax)
    both = clear[m_disc.bonds[:, 0]] & clear[m_disc.bonds[:, 1]]
    assert np.array_equal(m_disc.bonded[both], m_surf.bonded[both])
    assert (~m_disc.bonded[both]).sum() > 50


LISTRIC = {"name": "L", "shape": "listric", "trace": [-3.0, 0.3, 5.5], "dip_direction": 80.0, "dip_top": 72.0,
           "dip_bottom": 28.0, "depth": 10.0, "length": 7.0, "resolution": 0.9}
FAR_DISC = {"name": "far", "centre": [-5.0, -4.0, -4.0], "normal": [0, 0, 1.0], "radius": 0.5}


def _reference(model, mesh, band_of):
    """Brute-force membership of every sphere for surface mesh (V, F)."""
    V, F = mesh
    c = model.centers
    dist, foot, face = closest_brute(c, V, F)
    bnd = dist_to_segments(foot, V, boundary_segments(F)) < 1e-9
    a, b, cc = V[F[face, 0]], V[F[face, 1]], V[F[face, 2]]
    nrm = np.cross(b - a, cc - a)
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    # sign: from the face when the foot is inside it, else vertically (the fault is a height field)
    interior = np.ones(len(c), bool)
    for u, v in ((a, b), (b, cc), (cc, a)):
        t = np.clip(((foot - u) * (v - u)).sum(1) / ((v - u) ** 2).sum(1), 0, 1)
        interior &= np.linalg.norm(foot - (u + t[:, None] * (v - u)), axis=1) > 1e-7
    zs = height_at(c[:, :2], V, F)
    side = np.where(interior, np.sign(((c - foot) * nrm).sum(1)), np.sign(c[:, 2] - zs))
    member = (dist <= band_of(c)) & ~bnd
    return dist, side, member, interior | np.isfinite(zs)


@pytest.mark.parametrize("thickness", [0.0, 1.3])
def test_listric_fault_against_brute_force(thickness):
    sc, model = build([FAR_DISC, {**LISTRIC, "thickness": thickness}])
    mesh = sc.surfaces[0].mesh
    assert mesh.normals[:, 2].min() > 0
    V, F = shapes.listric(LISTRIC["trace"], 80.0, 72.0, 28.0, 10.0, 7.0, 0.9)
    band = (lambda c: np.full(len(c), thickness / 2)) if thickness else (lambda c: np.full(len(c), 0.8))
    dist, side, member, known = _reference(model, (V, F), band)
    sel = model.member_disc == 1
    got = np.zeros(model.n, bool)
    got[model.member_sphere[sel]] = True
    ties = np.abs(dist - band(model.centers)) < 1e-9
    assert np.array_equal(got[~ties], member[~ties])
    near = dist <= band(model.centers)
    assert member.sum() > 150 and (near & ~member).sum() > 20  # the surface's boundary excludes some
    s = model.member_sphere[sel]
    np.testing.assert_allclose(np.abs(model.member_offset[sel]), dist[s], rtol=1e-9, atol=1e-12)
    if thickness:
        assert np.all(model.member_kind[sel] == 1)
        assert np.array_equal(model.colour == 1, member)
    else:
        ok = known[s] & (dist[s] > 1e-9)
        want = np.where(side[s] <= 0, 2, 3)
        assert ok.sum() > 0.95 * len(s)
        assert np.array_equal(model.member_kind[sel][ok], want[ok])
        np.testing.assert_array_equal(np.sign(model.member_offset[sel][ok]), side[s][ok])


def test_listric_geometric_rule_cuts_crossing_bonds():
    sc, model = build([FAR_DISC, LISTRIC], "geometric")
    V, F = shapes.listric(LISTRIC["trace"], 80.0, 72.0, 28.0, 10.0, 7.0, 0.9)
    c = model.centers
    zs = height_at(c[:, :2], V, F)
    # bonds with both ends over the interior of the footprint, a bond length from its edges
    lmax = 2 * 0.4 * 1.001
    shrink = np.ones(len(c), bool)
    for dx, dy in ((lmax, 0), (-lmax, 0), (0, lmax), (0, -lmax)):
        shrink &= np.isfinite(height_at(c[:, :2] + [dx, dy], V, F))
    i, j = model.bonds[:, 0], model.bonds[:, 1]
    f_i, f_j = c[i, 2] - zs[i], c[j, 2] - zs[j]
    ok = shrink[i] & shrink[j] & (np.abs(f_i) > 1e-9) & (np.abs(f_j) > 1e-9)
    crosses = np.sign(f_i) != np.sign(f_j)
    assert (ok & crosses).sum() > 100
    assert np.array_equal((model.cut_by == 1)[ok], crosses[ok])
    # nothing is cut where the surface is not (far from every discontinuity)
    far = (np.abs(f_i) > 2) & (c[i, 2] > -4) & ~np.isnan(zs[i])
    assert np.all(model.bonded[far])


def test_defective_and_downward_meshes_give_the_same_colours():
    _, ref = build([LISTRIC])
    V, F = shapes.listric(LISTRIC["trace"], 80.0, 72.0, 28.0, 10.0, 7.0, 0.9)
    rng = np.random.default_rng(21)
    soup = V[F].reshape(-1, 3) + rng.normal(0, 1e-10, (3 * len(F), 3))
    Fs = np.arange(3 * len(F)).reshape(-1, 3)
    flip = rng.random(len(Fs)) < 0.1
    Fs[flip] = Fs[flip][:, [0, 2, 1]]
    Fs = np.vstack([Fs, Fs[:5]])  # duplicates
    _, m1 = build([{"vertices": soup.tolist(), "faces": Fs.tolist()}])
    assert np.array_equal(m1.colour, ref.colour)
    _, m2 = build([{"vertices": V.tolist(), "faces": F[:, [0, 2, 1]].tolist()}])  # every normal downward
    assert np.array_equal(m2.colour, ref.colour)
    assert (ref.colour == 2).sum() > 100 and (ref.colour == 3).sum() > 100


def test_mesh_file_surface_equals_the_shape(tmp_path):
    import meshio

    _, ref = build([{**LISTRIC, "thickness": 0.9}])
    V, F = shapes.listric(LISTRIC["trace"], 80.0, 72.0, 28.0, 10.0, 7.0, 0.9)
    meshio.write(tmp_path / "fault.obj", meshio.Mesh(V, [("triangle", F)]))
    sc = scene_from_dict({**BASE, "discontinuity": [{"file": "fault.obj", "thickness": 0.9}]},
                         tmp_path / "scene.toml")
    model = build_model(sc)
    assert sc.surfaces[0].source == "file fault.obj"
    assert np.array_equal(model.colour, ref.colour) and (model.colour == 1).sum() > 100


def test_model_file_describes_the_surfaces(tmp_path):
    sc, model = build([FAR_DISC, {**LISTRIC, "thickness": 0.7}, LISTRIC])
    model.save(tmp_path / "m.npz")
    back = SphereModel.load(tmp_path / "m.npz")
    s = back.surfaces
    assert list(s["surf_index"]) == [1, 2] and list(s["discontinuity_kind"]) == [0, 1, 1]
    assert list(s["surf_name"]) == ["L", "L"] and list(s["surf_thickness"]) == [0.7, 0.0]
    assert back.counts()["discontinuities"] == 3
    vs, fs = s["surf_vertex_start"], s["surf_face_start"]
    for k in range(2):
        V = s["surf_vertices"][vs[k]:vs[k + 1]]
        F = s["surf_faces"][fs[k]:fs[k + 1]] - vs[k]
        sd, face, bnd = TriMesh(V, F).signed_closest(back.centers, max_dist=2.0)
        sel = back.member_disc == k + 1
        np.testing.assert_allclose(sd[back.member_sphere[sel]], back.member_offset[sel], atol=1e-12)
    assert np.array_equal(back.colour, model.colour)


@pytest.mark.parametrize("tab, key", [
    ({**LISTRIC, "dip_top": 0.0}, "discontinuity[0].dip_top"),
    ({**LISTRIC, "dip_bottom": 95.0}, "discontinuity[0].dip_bottom"),
    ({**LISTRIC, "depth": -1.0}, "discontinuity[0].depth"),
    ({**LISTRIC, "shape": "ramp"}, "discontinuity[0].shape"),
    ({**LISTRIC, "radius": 3.0}, "discontinuity[0].radius"),
    ({**LISTRIC, "trace": [100.0, 100.0, 100.0]}, "discontinuity[0]"),
    ({"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 3]]}, "discontinuity[0].faces[0]"),
    ({"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]], "trace": [0, 0, 0]},
     "discontinuity[0].trace"),
    ({"file": "missing.stl"}, "discontinuity[0].file"),
])
def test_bad_surface_discontinuities(tab, key):
    with pytest.raises(SceneError) as e:
        scene_from_dict({**BASE, "discontinuity": [tab]}, "scene.toml")
    assert str(e.value).startswith(f"scene.toml: {key} = ")
