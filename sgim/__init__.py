"""SGIM: sphere generator for irregular geological models.

Packs spheres in a domain, excavates them with triangulated surfaces, cuts them
with discontinuities (colours and membership) and builds the bond list.
"""
__version__ = "0.1.0"
