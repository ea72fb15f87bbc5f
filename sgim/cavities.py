"""Inner excavations (tunnels, caverns, drifts): closed surfaces that delete spheres.

A sphere is removed by a cavity when its centre is inside the closed surface or closer
than its radius to it (the sphere overlaps the cavity).  Cavities come from ``[[cavity]]``
tables (sgim/scene.py): a mesh file, vertices + faces, or a built-in shape of
sgim/shapes.py; all of them end as a :class:`sgim.meshquery.TriMesh` on the same code path.

For packers: :func:`cavity_meshes` gives the meshes of a scene, :func:`cavity_set` joins them
into a :class:`sgim.meshquery.MeshSet` whose ``clearance(points, max_dist)`` (or, inside numba
code, ``sgim._meshq.clearance_point(D, x, y, z, maxd)`` with ``D = cavity_set(scene).kernel_data()``)
is the signed distance from a centre to the nearest cavity surface, negative inside a cavity:
a sphere of radius r at p is clear of every cavity when ``clearance >= r``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _meshq as K
from .meshquery import MeshSet, TriMesh

CAVITY_SHAPES = ("circular_tunnel", "horseshoe_tunnel", "ellipsoid", "box")


@dataclass
class Cavity:
    """A closed cavity surface from the scene."""

    name: str
    mesh: TriMesh
    key: str  # key path in the scene, for messages
    source: str  # "file NAME", "vertices" or the shape name
    params: dict = field(default_factory=dict)


def cavity_meshes(scene):
    """The TriMesh of every cavity of a scene, in scene order."""
    return [c.mesh for c in getattr(scene, "cavities", [])]


def cavity_set(scene):
    """All cavity meshes of a scene as one MeshSet (None when the scene has no cavity)."""
    meshes = cavity_meshes(scene)
    return MeshSet(meshes) if meshes else None


def overlapping(cavities, centres, radii):
    """Boolean mask of the spheres removed by any cavity, and the count per cavity.

    Only the spheres in each cavity's bounding box padded by the largest radius are
    tested against its surface.
    """
    c = np.ascontiguousarray(centres, dtype=float)
    rad = np.ascontiguousarray(np.broadcast_to(np.asarray(radii, dtype=float), (len(c),)))
    gone = np.zeros(len(c), bool)
    counts = []
    for cav in cavities:
        hit = K.removed_by_cavity(cav.mesh.kernel_data(), 0, c, rad)
        counts.append(int((hit & ~gone).sum()))
        gone |= hit
    return gone, counts


def carve(cavities, centres, radius, progress=None):
    """Drop the sites removed by the cavities: (kept centres, meta list for the model)."""
    if not cavities:
        return centres, []
    gone, counts = overlapping(cavities, centres, radius)
    meta = []
    for cav, n in zip(cavities, counts):
        m = cav.mesh
        meta.append({"name": cav.name, "source": cav.source, "faces": int(m.n_faces),
                     "closed": bool(m.closed), "boundary_edges": int(len(m.boundary_edges)),
                     "volume": round(float(m.volume), 6), "spheres_removed": n,
                     "bbox": [m.lo.tolist(), m.hi.tolist()], **cav.params})
    if progress:
        progress(f"cavities: {int(gone.sum())} of {len(centres)} sites removed by {len(cavities)} cavities")
    return centres[~gone], meta
