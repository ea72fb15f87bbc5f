"""The contact law of block (and sphere) contact points, and its defaults: the one place that says what an
unset kn, ks, friction or damping is, for the block engine, the sphere engine and the engine-neutral sphere runs of
adapters/spec.py (``from_model``). No numba here: adapters read the defaults without loading the kernels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class ContactLaw:
    """Contact law of block (and sphere) contact points: normal and shear stiffness kn, ks [N/m per point],
    Coulomb friction [deg], cohesion and tensile strength [Pa], damping [ratio of critical]."""

    kn: float = 1e9
    ks: float | None = None  # default kn / 2
    friction_deg: float = 30.0
    cohesion: float = 0.0
    tensile: float = 0.0
    damping: float = 0.0

    def row(self):
        ks = self.kn / 2 if self.ks is None else self.ks
        if not (self.kn > 0 and ks > 0):
            raise ValueError(f"contact stiffness must be > 0 (kn = {self.kn!r}, ks = {ks!r})")
        if not 0 <= self.friction_deg < 90:
            raise ValueError(f"friction angle must be in [0, 90) degrees (got {self.friction_deg!r})")
        if self.cohesion < 0 or self.tensile < 0 or self.damping < 0:
            raise ValueError("cohesion, tensile strength and damping must be >= 0")
        return [self.kn, ks, math.tan(math.radians(self.friction_deg)), self.cohesion, self.tensile, self.damping]
