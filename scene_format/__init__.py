"""The scene format: a generated scene folder as a typed, verified data set, below both its writer
(datagen) and its readers (recon, benchmark, viewer). Pure Python and NumPy, no bpy.

    reader.py      SceneDataset: config, camera trajectories, frame lists, blur levels, masks, event files
    cameras.py     intrinsics, axis conventions, pose interpolation, projection, cameras.json
    config.py      the scene config (scene.yaml), strict typed dataclasses
    transforms.py  the D-NeRF style frame lists (transforms_*.json)
    verify.py      `e4dgs check`: every file against the manifest
"""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
from scene_format.reader import DatasetError, FrameRecord, SceneDataset, SceneDescription  # noqa: F401
