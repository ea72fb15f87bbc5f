"""Explicit 3D DDA engine: convex polyhedral blocks and the spheres of SGIM models (docs/ARCHITECTURE.md)."""
import sgim as _sgim  # noqa: F401  (numba's cache folder for this source version: sgim/kernel_cache.py)
