"""A generated scene's frames as training / evaluation views: cameras posed along the recorded
trajectories, and images in the channels a model predicts (sRGB-encoded, as the dataset stores them)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from scene_format.reader import DatasetError, FrameRecord, SceneDataset
from recon.raster import Camera
from recon.render import camera_from_pose
from common.color import srgb_luma


def gray_from_srgb(rgb: np.ndarray) -> np.ndarray:
    """[..., 3] sRGB in [0, 1] -> [...] sRGB-encoded luma of the linear light (how gray/ frames are made)."""
    return srgb_luma(rgb).astype(np.float32)


def dataset_camera(dataset: SceneDataset, camera: int, t_us) -> Camera:
    """Raster camera of dataset camera `camera` at time t_us (interpolated along its trajectory)."""
    intr = dataset.intrinsics
    return camera_from_pose(intr.K, dataset.pose(camera, t_us), intr.width, intr.height)


def record_camera(dataset: SceneDataset, rec: FrameRecord) -> Camera:
    return dataset_camera(dataset, rec.camera, rec.t_us)


def _sized(dataset: SceneDataset, path, img: np.ndarray) -> np.ndarray:
    """The image if it has the cameras' size, else DatasetError naming the file (when it is loaded,
    not when a loss meets it)."""
    want = (dataset.intrinsics.height, dataset.intrinsics.width)
    if img.shape[:2] != want:
        raise DatasetError(f"{path}: {img.shape[1]}x{img.shape[0]} pixels, the scene's cameras are {want[1]}x{want[0]}")
    return img


def load_frame(dataset: SceneDataset, rec: FrameRecord, channels: int) -> np.ndarray:
    """Frame [H, W, channels] in [0, 1] (sRGB-encoded as stored); DatasetError for a frame that is not
    of the cameras' size or kind."""
    if channels == 3:
        img = _sized(dataset, rec.path, dataset.load_image(rec.path))
        if img.ndim != 3:
            raise DatasetError(f"{rec.path}: expected an RGB image")
        return img
    path = rec.gray_path if rec.gray_path is not None else rec.path
    img = _sized(dataset, path, dataset.load_image(path))
    return (gray_from_srgb(img) if img.ndim == 3 else img)[..., None]


@dataclass
class BlurView:
    """A blurred training frame and where to render it: one camera per sample time across its exposure."""
    cameras: list[Camera]
    times: list[float]        # normalised clip times of the samples
    image: torch.Tensor       # [H, W, C] sRGB-encoded, as stored


def blur_views(dataset: SceneDataset, level: str, samples: int, mode: str, channels: int) -> list[BlurView]:
    """Every training frame of blur level `level`. mode "mean": `samples` render times spread evenly from
    the first to the last rendered frame of the exposure (how the dataset averaged it); "centre": one
    render at the exposure centre."""
    views = []
    for rec in dataset.blurred_frames(level):
        if mode == "mean" and rec.exposure_us is not None:
            t_us = np.linspace(rec.exposure_us[0], rec.exposure_us[1], samples)
        else:
            t_us = np.array([rec.t_us])
        cams = [dataset_camera(dataset, rec.camera, t) for t in t_us]
        views.append(BlurView(cams, [float(t) / dataset.duration_us for t in t_us],
                              torch.from_numpy(load_frame(dataset, rec, channels))))
    return views
