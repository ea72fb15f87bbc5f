"""Shared by the block-engine tests: an axis-aligned box written out by hand (independent of dda.shapes)."""
from __future__ import annotations

import numpy as np

from dda.blockspec import BlockSpec


def box(lo, hi, **kw):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return BlockSpec(v, f, **kw)
