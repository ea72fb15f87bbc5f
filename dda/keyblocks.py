"""Key blocks of a block model: the groups of blocks that cannot stand under gravity, found before they move.

Blocks joined by cemented (intact rock) contact points move as one body while the cement holds, so the test is
made per cluster: the blocks connected by cemented contacts (current_pairs). A cluster with a fixed block is
held. Each other cluster is tested on its contact planes with the rest of the model (one per distinct normal: a
face-to-face contact's points share theirs) by the translation modes of block theory (Goodman & Shi), each
with its limit equilibrium (Hoek & Bray's planar and wedge sliding): it lifts off along its weight when that
leaves every contact plane; it slides on one plane, along the weight's part in it, when that direction leaves
the other planes and beats the plane's friction; it slides on two, along their line of intersection, when the
line leaves the others, the weight's part across the line presses into both and its part along the line beats
their friction. A cluster with an open mode cannot stand: a key block. (A linear programme over contact forces
inside the friction cones would call more blocks safe: with a non-associated friction law it can wedge a body
against a side wall that its weight never presses on.)

Not counted: rotation (toppling and rotational sliding are not tested), the cohesion and tensile strength of
the contacts that are not cemented (the joints' own, taken as lost). The contact planes and laws are the engine's
after its first step (``Simulation``: the pairs it found, their normals, the law row of each face,
dda/_kinds.py), so the screening sees what the run will see.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ._state import LAW_TANPHI
from .system import quat_to_matrix


@dataclass
class KeyBlocks:
    cluster: np.ndarray  # per block: its cluster (blocks joined by cemented points)
    held: np.ndarray  # per cluster: it has a fixed or prescribed block
    cannot_stand: np.ndarray  # per cluster: free, and no contact forces carry its weight (a key block)

    @property
    def blocks(self):
        """Indices of the blocks of the clusters that cannot stand."""
        return np.flatnonzero(self.cannot_stand[self.cluster])

    def summary(self, volume):
        """Counts for summary.json: clusters, free clusters, and the key blocks (clusters, blocks, volume)."""
        b = self.blocks
        return {"clusters": int(len(self.held)), "free_clusters": int((~self.held).sum()),
                "key_clusters": int(self.cannot_stand.sum()), "key_blocks": int(len(b)),
                "key_volume_m3": float(np.asarray(volume)[b].sum())}


def _spans_area(points, rel=1e-6):
    """True when the points are not all on one line (or one point): their second principal spread is above
    `rel` of the first."""
    if len(points) < 3:
        return False
    sv = np.linalg.svd(points - points.mean(0), compute_uv=False)
    return bool(sv[0] > 0.0 and sv[1] > rel * sv[0])


def current_pairs(sim):
    """The engine's contact pairs now: (a, b, normal a -> b, cemented). A pair is cemented when it has a bonded
    point and its points span an area (the engine gives a point its share of the contact polygon's area, and
    cohesion and tensile strength per area): two blocks that meet only along an edge or at a corner (diagonal
    neighbours across a joint, whose faces on an intact split lie in one plane) have bonded points of no
    strength."""
    c = int(sim.cur[0])
    n = int(sim.c_n_pair[c])
    npt = sim.c_np[c, :n]
    cemented = np.zeros(n, bool)
    for s in range(n):
        cemented[s] = bool(sim.c_bond[c, s, :npt[s]].any()) and _spans_area(sim.c_pos[c, s, :npt[s]])
    keep = npt > 0
    return sim.c_a[c, :n][keep], sim.c_b[c, :n][keep], sim.c_nrm[c, :n][keep], cemented[keep]


def world_normals(sim):
    """Outward unit normal of every face (the system's face order) at the current state."""
    A = sim.A
    out = np.empty_like(A.nloc)
    for i in range(len(A.mass)):
        f0, f1 = int(A.face_start[i]), int(A.face_start[i + 1])
        out[f0:f1] = A.nloc[f0:f1] @ quat_to_matrix(sim.quat[i]).T
    return out


def face_tanphi(sim):
    """tan(phi) of every face's law: its own row (dda/_kinds.py: a joint set, disc, fault or intact split), else
    its block's material law (domain and excavation faces)."""
    A = sim.A
    nf = int(A.face_start[-1])
    owner = np.repeat(np.arange(len(A.mass)), np.diff(A.face_start))
    rows = np.asarray(sim.face_laws[0])
    row = np.where(rows >= 0, rows, A.material[owner]) if len(rows) == nf else A.material[owner]
    return sim.lawtab[row, row, LAW_TANPHI]


def _face_on(normals, f0, f1, n, cos_tol=0.999):
    """Index of the face in f0:f1 whose outward normal is n (within cos_tol), -1 when none is."""
    k = int(np.argmax(normals[f0:f1] @ n))
    return f0 + k if normals[f0 + k] @ n > cos_tol else -1


def can_stand(normals, tanphi, force, tol=1e-9):
    """False when a body in contact on the planes of outward normals `normals` (friction tan(phi) `tanphi`) and
    driven by `force` (its weight) can translate: by the modes of block theory (Goodman & Shi), lifting off
    every plane along the force, sliding on one plane along the force's part in it (pressed into it), or
    sliding on two along their line of intersection (pressed into both): a mode is open when the direction leaves
    every other plane (normal . direction <= tol) and the force along it beats the friction the mode's normal
    forces give."""
    m = np.asarray(normals, float).reshape(-1, 3)
    mu = np.asarray(tanphi, float)
    r = np.asarray(force, float)
    scale = float(np.linalg.norm(r))
    if scale == 0.0:
        return True
    r = r / scale
    k = len(m)

    def leaves(s, skip):
        d = m @ s
        d[list(skip)] = -1.0
        return bool((d <= tol).all())

    if leaves(r, ()):  # lift-off along the force
        return False
    for i in range(k):
        n_i = float(r @ m[i])  # pressed into plane i
        rt = r - n_i * m[i]
        t = float(np.linalg.norm(rt))
        if n_i > 0.0 and t > tol and leaves(rt / t, (i,)) and t > mu[i] * n_i:
            return False
    for i in range(k):
        for j in range(i + 1, k):
            line = np.cross(m[i], m[j])
            ln = float(np.linalg.norm(line))
            if ln <= tol:
                continue
            line /= ln
            along = float(r @ line)
            if along < 0.0:
                line, along = -line, -along
            if along <= tol or not leaves(line, (i, j)):
                continue
            # the force's part across the line, pressed into both planes: r_perp = N_i m_i + N_j m_j, N >= 0
            rp = r - along * line
            g = np.array([[m[i] @ m[i], m[i] @ m[j]], [m[i] @ m[j], m[j] @ m[j]]])
            ni, nj = np.linalg.solve(g, [rp @ m[i], rp @ m[j]])
            if ni >= 0.0 and nj >= 0.0 and along > mu[i] * ni + mu[j] * nj:
                return False
    return True


def distinct_planes(normals, tanphi, tol=1e-6):
    """One row per distinct normal (within tol), each with the smallest friction of its pairs."""
    normals = np.asarray(normals, float).reshape(-1, 3)
    if len(normals) == 0:
        return normals, np.zeros(0)
    key = np.round(normals / tol).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    mu = np.full(len(first), np.inf)
    np.minimum.at(mu, inv.ravel(), np.asarray(tanphi, float))
    return normals[first], mu


def key_blocks(sim, free_face, gravity=None, cemented=True):
    """The key blocks of the engine's model now (after at least one step: the cemented contacts are found then).
    `free_face` flags the faces with nothing across them (excavation, cavity and domain faces); every other face
    of a cut model has rock across it, touching or not (a contact the first step has not loaded has no points
    yet), so the contact planes of a cluster are its members' faces less the free ones and those between two of
    its members. With cemented=False the cement is taken as broken: every block is a cluster of its own."""
    A = sim.A
    g = np.asarray(sim.gravity if gravity is None else gravity, float)
    nb = len(A.mass)
    a, b, nrm, bonded = current_pairs(sim)
    if not cemented:
        bonded[:] = False
    graph = coo_matrix((np.ones(int(bonded.sum())), (a[bonded], b[bonded])), shape=(nb, nb))
    ncl, cluster = connected_components(graph, directed=False)
    held = np.zeros(ncl, bool)
    np.logical_or.at(held, cluster, np.asarray(A.fixed, bool) | np.asarray(A.kin, bool))
    load = np.zeros((ncl, 3))  # each cluster's weight (a mass-scaled block's body force gives its weight back)
    np.add.at(load, cluster, A.mass[:, None] * g + A.bforce)
    normals = world_normals(sim)
    tanphi = face_tanphi(sim)
    contact = ~np.asarray(free_face, bool)
    for s in np.flatnonzero(cluster[a] == cluster[b]):  # faces between two members: inside the cluster
        for blk, n in ((a[s], nrm[s]), (b[s], -nrm[s])):
            f = _face_on(normals, int(A.face_start[blk]), int(A.face_start[blk + 1]), n)
            if f >= 0:
                contact[f] = False
    owner = np.repeat(np.arange(nb), np.diff(A.face_start))
    faces = np.flatnonzero(contact & ~held[cluster[owner]])
    fcl = cluster[owner[faces]]
    order = np.argsort(fcl, kind="stable")
    faces, fcl = faces[order], fcl[order]
    starts = np.searchsorted(fcl, np.arange(ncl + 1))
    cannot = np.zeros(ncl, bool)
    for c in np.flatnonzero(~held):
        f = faces[starts[c]:starts[c + 1]]
        planes, mu = distinct_planes(normals[f], tanphi[f])
        cannot[c] = not can_stand(planes, mu, load[c])
    return KeyBlocks(cluster=cluster, held=held, cannot_stand=cannot)
