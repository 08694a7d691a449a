"""Procedural Blender scenes, one module per scene (arrives with the dataset issue)."""
