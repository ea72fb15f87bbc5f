"""Plain-data description of one block: the interface between block generation and the engine.

A :class:`BlockSpec` is what the geometry side (``dda.shapes``, ``dda.cut``, ``dda.generate``) produces and
what the engine (``dda.system.BlockSystem.add_block``) consumes. It holds no topology beyond the face lists;
the engine builds its half-edge structure from it.

Conventions
-----------
- ``vertices``: (n, 3) float64 world coordinates of a convex polyhedron.
- ``faces``: one list of vertex indices per face, ordered counter-clockwise when seen from outside the block,
  so that the right-hand rule gives the outward normal.
- ``dof``: 6 for a rigid block, 12 for a deformable block (DDA first-order displacement function).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class BlockSpec:
    """One convex block as a scene gives it: vertices, faces (counter-clockwise seen from outside), name,
    material, fixed / prescribed flags, initial velocities, body force and degrees of freedom (6 or 12)."""

    vertices: np.ndarray            # (n,3) float64, world coordinates, convex polyhedron
    faces: list[list[int]]          # vertex indices per face, counter-clockwise seen from outside (outward normal)
    name: str = ""
    fixed: bool = False
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)
    material: str = "rock"          # key into the scene's [[material]] tables
    dof: int = 6                    # 6 rigid, 12 deformable (DDA first-order displacement function)

    def __post_init__(self):
        self.vertices = np.ascontiguousarray(np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3))
        self.faces = [[int(i) for i in f] for f in self.faces]
