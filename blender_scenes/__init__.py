"""Procedural Blender scenes, one module per scene (arrives with the dataset issue)."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
