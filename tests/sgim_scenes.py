"""Random scenes for the sgim tests (inputs only: nothing here computes an expected result)."""
from __future__ import annotations

import numpy as np

from sgim_ref import plane_abcd


def random_box(rng, r_range=(0.35, 0.6), extent_range=(3.0, 6.5)):
    lo = rng.uniform(-5.0, 5.0, 3)
    hi = lo + rng.uniform(*extent_range, 3)
    r = float(rng.uniform(*r_range))
    return lo, hi, r


def plan_surface(rng, lo, hi, npts=None, slope=1.0, margin=0.25):
    """Random height field over (a bit more than) the box, triangulated in plan (Delaunay)."""
    from scipy.spatial import Delaunay

    npts = npts or int(rng.integers(4, 14))
    ext = hi - lo
    xy = rng.uniform(lo[:2] - margin * ext[:2], hi[:2] + margin * ext[:2], (npts, 2))
    base = rng.uniform(lo[2] + 0.2 * ext[2], hi[2] - 0.1 * ext[2])
    gx, gy = rng.normal(0, slope, 2)
    z = base + gx * (xy[:, 0] - xy[:, 0].mean()) + gy * (xy[:, 1] - xy[:, 1].mean()) \
        + rng.normal(0, 0.3 * slope * ext[2] / 3, npts)
    verts = np.column_stack([xy, z])
    faces = Delaunay(xy).simplices.astype(np.int64)
    return _drop_degenerate(verts, faces)


def soup_surface(rng, lo, hi, nfaces=None, size=2.0, steep=False):
    """Unconnected random triangles, some reaching out of the box; steep ones on request."""
    nfaces = nfaces or int(rng.integers(1, 7))
    ext = hi - lo
    verts, faces = [], []
    for f in range(nfaces):
        c = rng.uniform(lo - 0.2 * ext, hi + 0.2 * ext)
        c[2] = rng.uniform(lo[2], hi[2])
        d = rng.normal(0, size, (3, 3))
        if steep:
            d[:, 2] *= 6.0
        verts.append(c + d)
        faces.append([3 * f, 3 * f + 1, 3 * f + 2])
    return _drop_degenerate(np.array(verts).reshape(-1, 3), np.array(faces, np.int64))


def vertical_surface(rng, lo, hi, nfaces=None):
    """Vertical facets (C0 = 0 exactly): dyadic coordinates on a plan line, so that every
    determinant is evaluated without rounding."""
    nfaces = nfaces or int(rng.integers(1, 4))
    q = 1 / 64
    verts, faces = [], []
    for f in range(nfaces):
        p0 = np.round(rng.uniform(lo[:2], hi[:2]) / q) * q
        p1 = np.round(rng.uniform(lo[:2] - 1, hi[:2] + 1) / q) * q
        t = rng.choice([0.25, 0.5, 0.75])
        pm = p0 + t * (p1 - p0)
        zs = np.round(rng.uniform(lo[2] - 0.5, hi[2] + 0.5, 3) / q) * q
        verts += [[p0[0], p0[1], zs[0]], [p1[0], p1[1], zs[1]], [pm[0], pm[1], zs[2]]]
        faces.append([3 * f, 3 * f + 1, 3 * f + 2])
    verts, faces = _drop_degenerate(np.array(verts, float), np.array(faces, np.int64))
    for tri in verts[faces]:
        assert plane_abcd(*tri)[2] == 0.0, "test scene: vertical facet with C0 != 0"
    return verts, faces


def _drop_degenerate(verts, faces):
    tri = verts[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    size2 = max(float(np.ptp(verts, axis=0).max()) ** 2, 1e-300)
    keep = area2 > 1e-6 * size2
    return verts, faces[keep]


def random_surfaces(rng, lo, hi, rules=("paper", "exact"), kinds=("plan", "steep", "soup", "vertical")):
    """1-3 surfaces of random kinds and rules: list of (vertices, faces, rule)."""
    out = []
    for _ in range(int(rng.integers(1, 4))):
        kind = rng.choice(kinds)
        if kind == "plan":
            v, f = plan_surface(rng, lo, hi, slope=rng.uniform(0.0, 0.8))
        elif kind == "steep":
            v, f = plan_surface(rng, lo, hi, slope=rng.uniform(2.0, 8.0))
        elif kind == "soup":
            v, f = soup_surface(rng, lo, hi, steep=bool(rng.integers(2)))
        else:
            v, f = vertical_surface(rng, lo, hi)
        if len(f):
            out.append((v, f, str(rng.choice(rules))))
    return out


def random_disc_dict(rng, lo, hi, r, thick=None):
    ext = hi - lo
    d = {"centre": rng.uniform(lo + 0.1 * ext, hi - 0.1 * ext).tolist(),
         "radius": float(rng.uniform(0.5, 1.2) * ext.max() / 2)}
    if rng.integers(2):
        d["normal"] = rng.normal(0, 1, 3).tolist()
    else:
        d["dip"] = float(rng.uniform(0, 90))
        d["dip_direction"] = float(rng.uniform(0, 360))
    if thick is None:
        thick = bool(rng.integers(3) == 0)
    d["thickness"] = float(rng.uniform(0.3, 2.5) * r) if thick else 0.0
    return d


def random_scene_dict(rng, kind=None, rule=None, ndiscs=None):
    lo, hi, r = random_box(rng)
    kind = kind or str(rng.choice(["cubic", "cubic", "hexagonal", "fcc"]))
    ex = []
    for v, f, rl in random_surfaces(rng, lo, hi, kinds=("plan", "steep", "soup")):
        if np.any(v.max(0) < lo) or np.any(v.min(0) > hi):
            continue  # wholly outside the box: a scene error, tested elsewhere
        ex.append({"vertices": v.tolist(), "faces": f.tolist(), "rule": rl})
    if rng.integers(2):
        # one surface in the 'points' form (triangulated in plan by sgim)
        ext = hi - lo
        pts = np.column_stack([rng.uniform(lo[:2] - 0.2 * ext[:2], hi[:2] + 0.2 * ext[:2], (6, 2)),
                               rng.uniform(lo[2] + 0.5 * ext[2], hi[2] + 0.5, 6)])
        ex.append({"points": pts.tolist(), "rule": str(rng.choice(["paper", "exact"]))})
    ndiscs = int(rng.integers(0, 4)) if ndiscs is None else ndiscs
    discs = [random_disc_dict(rng, lo, hi, r) for _ in range(ndiscs)]
    return {
        "name": "random",
        "domain": {"min": lo.tolist(), "max": hi.tolist()},
        "packing": {"kind": kind, "radius": r},
        "excavation": ex,
        "discontinuity": discs,
        "bonds": {"rule": rule or str(rng.choice(["colour", "geometric"])),
                  "tolerance": float(rng.choice([1e-3, 0.05, 0.15]))},
    }
