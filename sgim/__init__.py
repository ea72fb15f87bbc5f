"""SGIM: sphere generator for irregular geological models.

Packs spheres in a domain, excavates them with triangulated surfaces, cuts them
with discontinuities (colours and membership) and builds the bond list.
"""
from .kernel_cache import configure as _configure_kernel_cache

_configure_kernel_cache()  # before any kernel module is imported (sgim/kernel_cache.py)

__version__ = "0.1.0"
