"""Procedural Blender scenes, one module per scene (`build(cfg)` in each; only this package and datagen/ import bpy)."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
