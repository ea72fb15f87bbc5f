"""Shape library and convex-polyhedron helpers producing :class:`dda.blockspec.BlockSpec`.

Shapes (``shape(name, size, **kw)``), all centred on their centroid at ``center`` (default the origin) and
optionally turned by a 3x3 rotation matrix ``rotation`` (applied about the centroid):

==============  ===========================================================================================
``tetrahedron``  regular tetrahedron, edge length ``size``
``pyramid``      square pyramid with all eight edges of length ``size`` (height size/sqrt(2))
``cube``         cube of edge ``size``
``octahedron``   regular octahedron, edge length ``size``
``brick``        box ``size`` x ``width`` x ``height`` (defaults: width = size/2, height = size/4)
``prism``        right prism over a regular polygon with ``sides`` sides (default 3) of edge ``size``,
                 ``height`` long along z (default ``size``)
==============  ===========================================================================================

``PAPER_SHAPES`` are the four shapes of the explicit 3D-DDA paper's falling-polyhedra scene.

Faces are ordered counter-clockwise seen from outside (outward normal by the right-hand rule). Hull faces
are polygons: the coplanar triangles of a convex hull are merged, and vertices that lie on a straight face
edge (no turn) are removed.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from sgim.geometry import MeshError
from sgim.portable import each2, matmul, norm, sin_cos_deg

from .blockspec import BlockSpec

SHAPES = ("tetrahedron", "pyramid", "cube", "octahedron", "brick", "prism")
PAPER_SHAPES = ("tetrahedron", "pyramid", "cube", "octahedron")


class GeometryError(ValueError):
    """A shape or cut cannot be built from the given parameters (one-line message)."""


# ---------------------------------------------------------------------------------------------------------
# measures of a BlockSpec


def _cross(a, b):
    """Row-wise cross product of (..., 3) arrays (faster than np.cross on small inputs)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def face_normals(spec: BlockSpec) -> np.ndarray:
    """Outward unit normal of every face (Newell's method, robust for polygons)."""
    v = spec.vertices
    out = np.zeros((len(spec.faces), 3))
    for k, f in enumerate(spec.faces):
        p = v[f]
        n = _cross(p, np.roll(p, -1, axis=0)).sum(0)
        out[k] = n / norm(n)
    return out


def _fan(faces):
    tri = [(f[0], a, b) for f in faces for a, b in zip(f[1:-1], f[2:])]
    return np.array(tri, dtype=np.int64).reshape(-1, 3)


def volume_centroid(spec: BlockSpec):
    """Exact volume and centroid of a closed polyhedron with outward faces (fan tetrahedra)."""
    v = spec.vertices
    ref = v.mean(0)
    t = _fan(spec.faces)
    p0, p1, p2 = v[t[:, 0]] - ref, v[t[:, 1]] - ref, v[t[:, 2]] - ref
    vols = np.einsum("ij,ij->i", p0, _cross(p1, p2)) / 6.0
    vol = float(vols.sum())
    return vol, ref + (vols[:, None] * (p0 + p1 + p2)).sum(0) / (4.0 * vol)


def volume(spec: BlockSpec) -> float:
    return volume_centroid(spec)[0]


def check_convex(spec: BlockSpec, tol: float = 1e-9) -> list[str]:
    """Problems found with ``spec`` as a closed convex polyhedron with outward CCW faces ([] if none).

    ``tol`` is relative to the block's size (bounding-box diagonal).
    """
    v, faces = spec.vertices, spec.faces
    problems = []
    if len(v) < 4 or len(faces) < 4:
        return [f"needs at least 4 vertices and 4 faces (has {len(v)}, {len(faces)})"]
    scale = norm(np.ptp(v, axis=0)) or 1.0
    # closed and consistently oriented: every directed edge once, its reverse once
    directed = {}
    for k, f in enumerate(faces):
        if len(f) < 3 or len(set(f)) != len(f):
            problems.append(f"face {k} is degenerate: {f}")
            continue
        for a, b in zip(f, f[1:] + f[:1]):
            if (a, b) in directed:
                problems.append(f"edge {a}->{b} used twice in the same direction (faces {directed[(a, b)]}, {k})")
            directed[(a, b)] = k
    for (a, b), k in directed.items():
        if (b, a) not in directed:
            problems.append(f"edge {a}-{b} of face {k} is open (no neighbouring face)")
    used = {i for f in faces for i in f}
    if len(used) != len(v):
        problems.append(f"{len(v) - len(used)} vertices are used by no face")
    if problems:
        return problems
    vol, c = volume_centroid(spec)
    if not vol > 0:
        return [f"volume {vol:g} is not positive (faces inward or flat)"]
    n = face_normals(spec)
    for k, f in enumerate(faces):
        d = matmul(v, n[k]) - matmul(n[k], v[f[0]])
        if np.abs(d[f]).max() > tol * scale:
            problems.append(f"face {k} is not planar (off by {np.abs(d[f]).max():.3g})")
        if d.max() > tol * scale:
            problems.append(f"vertex {int(d.argmax())} lies {d.max():.3g} outside face {k}: not convex")
        if matmul(n[k], v[f[0]] - c) <= 0:
            problems.append(f"face {k} normal points inward")
    return problems


# ---------------------------------------------------------------------------------------------------------
# convex hull with polygon faces


def _order_polygon(points, normal):
    c = points.mean(0)
    u = points[np.argmax(np.linalg.norm(points - c, axis=1))] - c
    u -= normal * matmul(normal, u)
    u /= norm(u)
    w = _cross(normal, u)
    d = points - c
    return np.argsort(each2(math.atan2, matmul(d, w), matmul(d, u)), kind="stable")


def _drop_collinear(loop, pts, eps):
    """Remove the vertices of a polygon loop where the boundary does not turn."""
    if len(loop) <= 3:
        return loop
    p = pts[loop]
    a, c = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
    turn = np.linalg.norm(_cross(p - a, c - p), axis=1)
    keep = turn > eps * np.maximum(np.linalg.norm(c - a, axis=1), 1e-300) ** 2
    if keep.sum() < 3:
        return loop
    return [i for i, k in zip(loop, keep) if k]


def convex_hull(points, tol: float = 1e-9, **fields) -> BlockSpec:
    """Convex hull of ``points`` as a BlockSpec with polygon faces.

    Neighbouring hull triangles whose planes agree within ``tol`` times the hull size are merged into one
    face; vertices that end up on a straight edge or inside a face are dropped. ``fields`` are passed to
    BlockSpec (name, fixed, material, ...).
    """
    from scipy.spatial import ConvexHull, QhullError  # lazy: scipy loads only when a hull is built (start-up)

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 4 or not np.all(np.isfinite(pts)):
        raise GeometryError(f"a convex hull needs at least 4 finite points (got {len(pts)})")
    scale = norm(np.ptp(pts, axis=0))
    try:
        hull = ConvexHull(pts)
    except QhullError:
        raise GeometryError("points are coplanar or degenerate: they enclose no volume") from None
    eq = hull.equations  # outward unit normal, offset
    simp = hull.simplices
    nt = len(simp)
    eps = tol * scale
    # union-find over neighbouring coplanar triangles
    parent = list(range(nt))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    ii = np.repeat(np.arange(nt), 3)
    jj = hull.neighbors.ravel()
    sel = jj > ii
    ii, jj = ii[sel], jj[sel]
    dij = np.abs(np.einsum("kvc,kc->kv", pts[simp[jj]], eq[ii, :3]) + eq[ii, 3:4]).max(1)
    dji = np.abs(np.einsum("kvc,kc->kv", pts[simp[ii]], eq[jj, :3]) + eq[jj, 3:4]).max(1)
    same = (np.maximum(dij, dji) <= eps) & (np.einsum("kc,kc->k", eq[ii, :3], eq[jj, :3]) > 0)
    for i, j in zip(ii[same].tolist(), jj[same].tolist()):
        parent[find(i)] = find(j)
    groups = {}
    for i in range(nt):
        groups.setdefault(find(i), []).append(i)
    loops = []
    for tris in groups.values():
        idx = np.unique(simp[tris].ravel())
        # plane of the group: area-weighted mean of the outward triangle normals
        p = pts[simp[tris]]
        area = np.linalg.norm(_cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        an = (eq[tris, :3] * area[:, None]).sum(0)
        nrm = an / norm(an)
        order = _order_polygon(pts[idx], nrm)
        loop = [int(i) for i in idx[order]]
        loop = _drop_collinear(loop, pts, max(tol, 1e-12))
        loops.append(loop)
    used = sorted({i for lp in loops for i in lp})
    remap = {old: new for new, old in enumerate(used)}
    faces = [[remap[i] for i in lp] for lp in loops]
    return BlockSpec(pts[used].copy(), faces, **fields)


# ---------------------------------------------------------------------------------------------------------
# transformations


def transformed(spec: BlockSpec, rotation=None, translation=(0.0, 0.0, 0.0), about=None, **fields) -> BlockSpec:
    """A copy of ``spec`` rotated by ``rotation`` (3x3) about ``about`` (default its centroid), then moved."""
    v = spec.vertices
    if rotation is not None:
        r = np.asarray(rotation, float).reshape(3, 3)
        c = volume_centroid(spec)[1] if about is None else np.asarray(about, float)
        v = matmul(v - c, r.T) + c
    v = v + np.asarray(translation, float)
    keep = dict(name=spec.name, fixed=spec.fixed, velocity=spec.velocity, angular_velocity=spec.angular_velocity,
                material=spec.material, dof=spec.dof)
    keep.update(fields)
    return BlockSpec(v, [list(f) for f in spec.faces], **keep)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix drawn uniformly on SO(3) (unit quaternion from four normal deviates)."""
    q = rng.standard_normal(4)
    while norm(q) < 1e-12:
        q = rng.standard_normal(4)
    w, x, y, z = q / norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotation_about(axis, angle_deg) -> np.ndarray:
    """Rotation matrix by ``angle_deg`` about ``axis`` (right-hand rule)."""
    a = np.asarray(axis, float)
    a = a / norm(a)
    s, c = sin_cos_deg(angle_deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + s * k + (1 - c) * matmul(k, k)


# ---------------------------------------------------------------------------------------------------------
# the shape library


def box(lo, hi, **fields) -> BlockSpec:
    """Axis-aligned box between corners ``lo`` and ``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if not np.all(hi > lo):
        raise GeometryError(f"box corners must satisfy hi > lo (got lo={lo.tolist()}, hi={hi.tolist()})")
    v = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return BlockSpec(v, faces, **fields)


def prism_from_polygon(polygon, z0, z1, **fields) -> BlockSpec:
    """Right prism over a convex plan polygon ``[(x, y), ...]`` between heights ``z0 < z1``."""
    p = np.asarray(polygon, float).reshape(-1, 2)
    if not z1 > z0:
        raise GeometryError(f"prism needs z1 > z0 (got {z0}, {z1})")
    pts = np.vstack([np.column_stack([p, np.full(len(p), z0)]), np.column_stack([p, np.full(len(p), z1)])])
    return convex_hull(pts, **fields)


def _raw_shape(name, size, **kw):
    s = float(size)
    if name == "tetrahedron":
        v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) * (s / (2 * np.sqrt(2)))
    elif name == "pyramid":
        h = s / np.sqrt(2)
        v = np.array([[-s / 2, -s / 2, 0], [s / 2, -s / 2, 0], [s / 2, s / 2, 0], [-s / 2, s / 2, 0], [0, 0, h]])
    elif name == "cube":
        v = box([-s / 2] * 3, [s / 2] * 3).vertices
    elif name == "octahedron":
        r = s / np.sqrt(2)
        v = np.array([[r, 0, 0], [-r, 0, 0], [0, r, 0], [0, -r, 0], [0, 0, r], [0, 0, -r]])
    elif name == "brick":
        w = float(kw.pop("width", s / 2))
        h = float(kw.pop("height", s / 4))
        if not (w > 0 and h > 0):
            raise GeometryError(f"brick width and height must be > 0 (got {w}, {h})")
        v = box([-s / 2, -w / 2, -h / 2], [s / 2, w / 2, h / 2]).vertices
    elif name == "prism":
        n = int(kw.pop("sides", 3))
        h = float(kw.pop("height", s))
        if n < 3 or not h > 0:
            raise GeometryError(f"prism needs sides >= 3 and height > 0 (got {n}, {h})")
        r = s / (2 * np.sin(np.pi / n))
        t = 2 * np.pi * np.arange(n) / n
        ring = np.column_stack([r * np.cos(t), r * np.sin(t)])
        v = np.vstack([np.column_stack([ring, np.full(n, -h / 2)]), np.column_stack([ring, np.full(n, h / 2)])])
    else:
        raise GeometryError(f"unknown shape {name!r} (known: {', '.join(SHAPES)})")
    return v, kw


def shape(name: str, size: float, center=(0.0, 0.0, 0.0), rotation=None, **kw) -> BlockSpec:
    """A library shape (see the module docstring) with its centroid at ``center``.

    Extra keywords: ``width``/``height`` (brick), ``sides``/``height`` (prism); the rest go to BlockSpec.
    """
    if not (np.isfinite(size) and size > 0):
        raise GeometryError(f"shape size must be > 0 (got {size})")
    v, fields = _raw_shape(name, size, **kw)
    fields.setdefault("name", name)
    spec = convex_hull(v, **fields)
    c = volume_centroid(spec)[1]
    return transformed(spec, rotation=rotation, translation=np.asarray(center, float) - c, about=c)


def circumradius(spec: BlockSpec) -> float:
    """Largest distance from the centroid to a vertex."""
    c = volume_centroid(spec)[1]
    return float(np.linalg.norm(spec.vertices - c, axis=1).max())


# ---------------------------------------------------------------------------------------------------------
# convex mesh files


def load_convex_mesh(path, tol: float = 1e-6, **fields) -> BlockSpec:
    """Read one closed convex polyhedron from a surface mesh file (any meshio format).

    Triangle, quad and polygon cells are accepted. Raises MeshError (from ``sgim.geometry``) when the file
    cannot be read, has no surface cells, is open (an edge not shared by exactly two faces), is inconsistently
    oriented, or is not convex within ``tol`` times its size. Orientation (all faces inward) is corrected.
    """
    import meshio  # lazy: meshio loads only when a mesh file is read (start-up)

    path = Path(path)
    if not path.is_file():
        raise MeshError("file not found")
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            mesh = meshio.read(str(path))
    except Exception as exc:  # meshio raises many kinds
        first = str(exc).splitlines()[0] if str(exc) else ""
        raise MeshError(f"unreadable mesh file ({exc.__class__.__name__}: {first})") from None
    pts = np.asarray(mesh.points, float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise MeshError("mesh points must be 3D")
    if not np.all(np.isfinite(pts)):
        raise MeshError("mesh has NaN or infinite coordinates")
    surface = ("triangle", "quad") + tuple(t for t in {c.type for c in mesh.cells} if t.startswith("polygon"))
    faces = [list(map(int, row)) for c in mesh.cells if c.type in surface for row in np.asarray(c.data)]
    volumes = sorted({c.type for c in mesh.cells if c.type not in surface and c.type not in ("vertex", "line")})
    if volumes:
        raise MeshError(f"mesh has cells other than surface polygons ({', '.join(volumes)})")
    if not faces:
        raise MeshError("mesh has no surface cells (triangle, quad or polygon)")
    # merge duplicated points, drop unused ones
    uniq, inv = np.unique(pts, axis=0, return_inverse=True)
    inv = inv.ravel()
    faces = [[int(inv[i]) for i in f] for f in faces]
    faces = [[a for k, a in enumerate(f) if a != f[k - 1]] for f in faces]
    used = sorted({i for f in faces for i in f})
    remap = {o: n for n, o in enumerate(used)}
    spec = BlockSpec(uniq[used], [[remap[i] for i in f] for f in faces], **fields)
    # topology first (open / inconsistent), then orientation, then convexity
    problems = [p for p in check_convex(spec, tol) if "open" in p or "twice" in p or "degenerate" in p]
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise MeshError(f"mesh is not a closed surface: {problems[0]}{more}")
    vol = volume(spec)
    if vol < 0:
        spec = BlockSpec(spec.vertices, [f[::-1] for f in spec.faces], **fields)
        vol = -vol
    if not vol > 0:
        raise MeshError("mesh encloses no volume")
    problems = check_convex(spec, tol)
    if problems:
        raise MeshError(f"mesh is not convex: {problems[0]}")
    hull = convex_hull(spec.vertices, **fields)
    if abs(volume(hull) - vol) > tol * vol * 10:
        raise MeshError("mesh is not convex: its volume differs from its convex hull's")
    return hull
