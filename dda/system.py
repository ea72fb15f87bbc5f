"""BlockSystem: every block of a model as flat structure-of-arrays (numba-ready).

Each block is stored in its principal body frame: local vertex coordinates relative to the centroid along the
principal axes of inertia, so the body inertia tensor is diagonal. The world pose is the centroid ``pos`` and a
unit quaternion ``quat`` (w, x, y, z) turning body coordinates into world coordinates.

Per-block ranges ``vert_start``, ``face_start``, ``he_start``, ``edge_start`` (length n_blocks + 1) index the
concatenated vertex, face, half-edge and edge arrays; half-edge links (next / prev / pair / face / origin) and
``vert_he`` / ``face_he`` hold global indices. ``edge_he`` lists one half-edge per undirected edge.

Loads and prescribed motion: ``add_block(..., prescribed=True)`` (or a spec attribute ``prescribed``) makes a
block move at its given velocity and angular velocity whatever the forces (a pushing plate); ``add_body_load``
adds a constant world force at a block's centroid, ``add_point_load`` a constant world force at a point of the
block (given in world coordinates of the initial pose, carried with the block).

Blocks carry ``dof`` (6 rigid, 12 deformable: DDA's first-order displacement function, six constant strains
besides the rigid motion; see dda/_deform.py). Per-block arrays are indexed by block and the integrator
dispatches on it; deformable blocks add their body-frame matrices ``m9`` (rotation-strain mass matrix),
``m9inv`` and ``vc`` (V C), zero for rigid blocks. A deformable block cannot be prescribed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sgim.portable import eigh3, matmul, norm

from .polyhedra import PolyhedronError, check_convex, face_planes, half_edges, mass_properties


def quat_from_matrix(R):
    """Unit quaternion (w, x, y, z) of a proper rotation matrix."""
    R = np.asarray(R, float)
    t = np.trace(R)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / norm(q)


def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


@dataclass
class _Block:
    name: str
    vloc: np.ndarray
    faces: list
    he: object
    nloc: np.ndarray
    dloc: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    mass: float
    inertia: np.ndarray  # principal moments (3,)
    volume: float
    fixed: bool
    velocity: np.ndarray
    angular_velocity: np.ndarray
    material: str
    density: float
    E: float
    nu: float
    dof: int
    prescribed: bool = False
    body_force: np.ndarray = None
    mats: tuple = None  # deformable blocks: (M9, M9^-1, V C) in the body frame


class BlockSystem:
    """Collects blocks (``add_block``) and exposes them as flat arrays (``arrays()``)."""

    def __init__(self):
        self._blocks: list[_Block] = []
        self._arrays = None
        self.materials: list[str] = []
        self._point_loads: list = []  # (block, body-frame offset, world force)

    def __len__(self):
        return len(self._blocks)

    @property
    def n_blocks(self):
        return len(self._blocks)

    def add_block(self, spec, density=2600.0, E=1e10, nu=0.25, fixed=None, material=None, prescribed=None) -> int:
        """Add a convex block from a BlockSpec (or anything with .vertices / .faces); return its index.

        ``prescribed=True`` (default: the spec's ``prescribed`` attribute, if any) moves the block at the spec's
        velocity and angular velocity (world frame, about the centroid) for the whole run.

        Raises PolyhedronError when the faces are not a closed, outward-oriented convex polyhedron.
        """
        v = np.asarray(spec.vertices, float).reshape(-1, 3)
        faces = [list(map(int, f)) for f in spec.faces]
        he = half_edges(len(v), faces)
        check_convex(v, faces)
        mp = mass_properties(v, faces)
        if not density > 0:
            raise ValueError(f"density must be > 0 (got {density!r})")
        dof = int(getattr(spec, "dof", 6))
        if dof not in (6, 12):
            raise ValueError(f"dof must be 6 (rigid) or 12 (deformable) (got {dof!r})")
        if dof == 12 and not (E > 0 and -1.0 < nu < 0.5):
            raise ValueError(f"a deformable block needs E > 0 and -1 < nu < 0.5 (got E = {E!r}, nu = {nu!r})")
        moments, axes = eigh3(mp.inertia)  # right-handed, the same bits on every CPU (sgim/portable.py)
        vloc = matmul(v - mp.centroid, axes)  # body coordinates along the principal axes
        nloc, dloc = face_planes(vloc, faces)
        name = getattr(spec, "name", "") or f"block{len(self._blocks)}"
        mat = material if material is not None else getattr(spec, "material", "rock")
        if mat not in self.materials:
            self.materials.append(mat)
        blk = _Block(
            name=name, vloc=vloc, faces=faces, he=he, nloc=nloc, dloc=dloc, pos=mp.centroid.copy(),
            quat=quat_from_matrix(axes), mass=density * mp.volume, inertia=density * moments, volume=mp.volume,
            fixed=bool(getattr(spec, "fixed", False) if fixed is None else fixed),
            velocity=np.asarray(getattr(spec, "velocity", (0.0, 0.0, 0.0)), float),
            angular_velocity=np.asarray(getattr(spec, "angular_velocity", (0.0, 0.0, 0.0)), float),
            material=mat, density=float(density), E=float(E), nu=float(nu), dof=dof,
            prescribed=bool(getattr(spec, "prescribed", False) if prescribed is None else prescribed),
            body_force=np.zeros(3),
        )
        if blk.prescribed and blk.fixed:
            raise ValueError(f"block {name!r} cannot be both fixed and prescribed")
        if blk.prescribed and dof == 12:
            raise ValueError(f"block {name!r}: a deformable block (dof = 12) cannot be prescribed")
        if dof == 12:
            from ._deform import block_matrices  # lazy: dda._deform loads numba, rigid-only systems never need it

            blk.mats = block_matrices(vloc, faces, density, E, nu)
        self._blocks.append(blk)
        self._arrays = None
        return len(self._blocks) - 1

    def add_body_load(self, i, force):
        """Add a constant world force [N] at the centroid of block i (adds up over calls)."""
        f = np.asarray(force, float).reshape(3)
        if not np.all(np.isfinite(f)):
            raise ValueError(f"load force must be finite (got {force!r})")
        self._blocks[i].body_force = self._blocks[i].body_force + f
        self._arrays = None

    def add_point_load(self, i, point, force):
        """Add a constant world force [N] acting at `point` (world coordinates in the initial pose) of block i.

        The point moves with the block; the force keeps its world direction and size."""
        b = self._blocks[i]
        f = np.asarray(force, float).reshape(3)
        x = np.asarray(point, float).reshape(3)
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(x))):
            raise ValueError("load point and force must be finite")
        r = matmul(quat_to_matrix(b.quat).T, x - b.pos)
        self._point_loads.append((int(i), r, f))
        self._arrays = None

    def add_blocks(self, specs, **kw) -> list[int]:
        return [self.add_block(s, **kw) for s in specs]

    def block(self, i) -> _Block:
        return self._blocks[i]

    def arrays(self) -> "SystemArrays":
        if self._arrays is None:
            self._arrays = SystemArrays.build(self._blocks, self.materials, self._point_loads)
        return self._arrays


@dataclass
class SystemArrays:
    # per block
    names: list
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    angmom: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray  # principal moments (n,3)
    volume: np.ndarray
    fixed: np.ndarray
    material: np.ndarray
    dof: np.ndarray
    radius: np.ndarray  # largest vertex distance from the centroid
    vert_start: np.ndarray
    face_start: np.ndarray
    he_start: np.ndarray
    edge_start: np.ndarray
    # per vertex / face / half-edge / edge
    vloc: np.ndarray
    nloc: np.ndarray
    dloc: np.ndarray
    he_origin: np.ndarray
    he_next: np.ndarray
    he_prev: np.ndarray
    he_pair: np.ndarray
    he_face: np.ndarray
    vert_he: np.ndarray
    face_he: np.ndarray
    edge_he: np.ndarray
    face_vert_start: np.ndarray  # face -> its vertex loop in face_verts (for output meshes)
    face_verts: np.ndarray
    # loads and prescribed motion
    kin: np.ndarray = None  # (n,) bool: prescribed velocity
    wpres: np.ndarray = None  # (n,3) prescribed world angular velocity
    bforce: np.ndarray = None  # (n,3) constant force at the centroid
    pl_start: np.ndarray = None  # (n+1,) point loads of block i: rows pl_start[i]:pl_start[i+1]
    pl_r: np.ndarray = None  # (p,3) body-frame offset from the centroid
    pl_f: np.ndarray = None  # (p,3) world force
    # deformable blocks (zero for rigid ones)
    m9: np.ndarray = None  # (n,9,9) rotation-strain mass matrix (body frame)
    m9inv: np.ndarray = None  # (n,9,9) its inverse
    vc: np.ndarray = None  # (n,6,6) V C

    @staticmethod
    def build(blocks, materials, point_loads=()):
        n = len(blocks)
        vs = np.zeros(n + 1, np.int64)
        fs = np.zeros(n + 1, np.int64)
        hs = np.zeros(n + 1, np.int64)
        es = np.zeros(n + 1, np.int64)
        for i, b in enumerate(blocks):
            vs[i + 1] = vs[i] + len(b.vloc)
            fs[i + 1] = fs[i] + len(b.faces)
            hs[i + 1] = hs[i] + b.he.n_half_edges
            es[i + 1] = es[i] + b.he.n_half_edges // 2

        def cat(get, dtype, shape=()):
            parts = [np.asarray(get(b), dtype).reshape((-1,) + shape) for b in blocks]
            return np.ascontiguousarray(np.concatenate(parts)) if parts else np.zeros((0,) + shape, dtype)

        he_origin = np.concatenate([b.he.he_origin + vs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        he_next = np.concatenate([b.he.he_next + hs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        he_prev = np.concatenate([b.he.he_prev + hs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        he_pair = np.concatenate([b.he.he_pair + hs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        he_face = np.concatenate([b.he.he_face + fs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        vert_he = np.concatenate([b.he.vert_he + hs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        face_he = np.concatenate([b.he.face_he + hs[i] for i, b in enumerate(blocks)]) if n else np.zeros(0, int)
        edge_he = []
        for i, b in enumerate(blocks):
            loc = np.arange(b.he.n_half_edges)
            edge_he.append(loc[loc < b.he.he_pair] + hs[i])
        edge_he = np.concatenate(edge_he) if n else np.zeros(0, int)
        fv_start = [0]
        fv = []
        for i, b in enumerate(blocks):
            for f in b.faces:
                fv.extend(int(x) + int(vs[i]) for x in f)
                fv_start.append(len(fv))
        radius = np.array([float(np.max(np.linalg.norm(b.vloc, axis=1))) for b in blocks])
        angmom = np.zeros((n, 3))
        for i, b in enumerate(blocks):
            if not b.fixed:
                R = quat_to_matrix(b.quat)
                angmom[i] = matmul(R, b.inertia * matmul(R.T, b.angular_velocity))
        vel = cat(lambda b: b.velocity, float, (3,))
        for i, b in enumerate(blocks):
            if b.fixed:
                vel[i] = 0.0
        kin = np.array([b.prescribed for b in blocks], bool)
        wpres = np.zeros((n, 3))
        for i, b in enumerate(blocks):
            if b.prescribed:
                wpres[i] = b.angular_velocity
                angmom[i] = 0.0
        order = sorted(range(len(point_loads)), key=lambda k: point_loads[k][0])
        pl_start = np.zeros(n + 1, np.int64)
        for k in order:
            pl_start[point_loads[k][0] + 1] += 1
        pl_start = np.cumsum(pl_start).astype(np.int64)
        pl_r = np.array([point_loads[k][1] for k in order], float).reshape(-1, 3)
        pl_f = np.array([point_loads[k][2] for k in order], float).reshape(-1, 3)
        bforce = np.array([b.body_force for b in blocks], float).reshape(-1, 3)
        m9 = np.zeros((n, 9, 9))
        m9inv = np.zeros((n, 9, 9))
        vc = np.zeros((n, 6, 6))
        for i, b in enumerate(blocks):
            if b.mats is not None:
                m9[i], m9inv[i], vc[i] = b.mats
        return SystemArrays(
            names=[b.name for b in blocks],
            pos=cat(lambda b: b.pos, float, (3,)), quat=cat(lambda b: b.quat, float, (4,)), vel=vel,
            angmom=angmom, mass=np.array([b.mass for b in blocks], float),
            inertia=cat(lambda b: b.inertia, float, (3,)), volume=np.array([b.volume for b in blocks], float),
            fixed=np.array([b.fixed for b in blocks], bool),
            material=np.array([materials.index(b.material) for b in blocks], np.int64),
            dof=np.array([b.dof for b in blocks], np.int64), radius=radius,
            vert_start=vs, face_start=fs, he_start=hs, edge_start=es,
            vloc=cat(lambda b: b.vloc, float, (3,)), nloc=cat(lambda b: b.nloc, float, (3,)),
            dloc=cat(lambda b: b.dloc, float),
            he_origin=he_origin.astype(np.int64), he_next=he_next.astype(np.int64), he_prev=he_prev.astype(np.int64),
            he_pair=he_pair.astype(np.int64), he_face=he_face.astype(np.int64), vert_he=vert_he.astype(np.int64),
            face_he=face_he.astype(np.int64), edge_he=edge_he.astype(np.int64),
            face_vert_start=np.array(fv_start, np.int64), face_verts=np.array(fv, np.int64),
            kin=kin, wpres=wpres, bforce=bforce, pl_start=pl_start, pl_r=pl_r, pl_f=pl_f,
            m9=m9, m9inv=m9inv, vc=vc,
        )

    @property
    def n(self):
        return len(self.mass)


__all__ = ["BlockSystem", "SystemArrays", "PolyhedronError", "quat_from_matrix", "quat_to_matrix"]
