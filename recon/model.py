"""A trained (or training) dynamic scene: canonical Gaussians + deformation field + what rendering needs.

    model = recon.load("runs/lego/d3dgs")          # a model.pt file or the folder holding it
    image = model.render(camera, t)                # [H, W, C] float in [0, 1]; camera: Camera or index

`camera` is a `recon.raster.Camera` (any intrinsics and pose) or the index of one of the dataset's
cameras, posed at time t along its recorded trajectory. t is the clip's normalised time in [0, 1].
"""
from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from scene_format.cameras import CameraTrajectory, Intrinsics
from common.checkpoint import torch_load
from common.fileio import atomic_output
from recon.deform import DeformationField, make_field
from recon.gaussians import GaussianModel
from recon.raster import Camera, RenderOutput
from recon.render import camera_from_pose, check_time, render_at, render_views, render_views_times

FORMAT = "e4dgs-dynamic-gaussians/1"


@dataclass
class ModelMeta:
    method: str
    channels: int
    sh_degree: int
    background: list[float]
    extent: float                     # scene extent (3DGS's cameras_extent)
    duration_us: int                  # clip length; t = t_us / duration_us
    deform_enabled: bool = False      # False until the warm-up has passed
    precision: str = "float32"        # the deformation's dtype (float32 | bfloat16) it trained and renders in
    deform_field: dict = field(default_factory=lambda: {"kind": "mlp"})   # recon.deform.make_field's spec
    active_sh_degree: int = 0
    iteration: int = 0
    scene: str = ""
    config: dict = field(default_factory=dict)   # the method's resolved config
    # per-channel (gain, offset) on log intensity, set by event methods' colour correction (or None)
    color_correction: list | None = None


class DynamicGaussians:
    def __init__(self, gaussians: GaussianModel, deform: DeformationField, meta: ModelMeta,
                 cameras: list[CameraTrajectory] | None = None):
        self.gaussians = gaussians
        self.deform = deform
        self.meta = meta
        self.cameras = cameras or []

    def __len__(self) -> int:
        return len(self.gaussians)

    @property
    def background(self) -> torch.Tensor:
        return torch.tensor(self.meta.background, dtype=torch.float32, device=self.device)

    @property
    def device(self) -> torch.device:
        return self.gaussians.means.device

    def to(self, device: torch.device | str) -> "DynamicGaussians":
        """Move the Gaussians and the deformation field to `device` (in place; returns self)."""
        self.gaussians.to(device)
        if self.gaussians.anchors is not None:
            self.gaussians.anchors = self.gaussians.anchors.to(device)
        self.deform.to(device)
        return self

    def camera(self, index: int, t: float) -> Camera:
        """Dataset camera `index` at normalised time t, posed along its recorded trajectory."""
        if not 0 <= index < len(self.cameras):
            raise ValueError(f"camera index {index} out of range: the model knows {len(self.cameras)} camera(s)")
        traj = self.cameras[index]
        t_us = check_time(t) * self.meta.duration_us
        return camera_from_pose(traj.intrinsics.K, traj.pose_at(t_us), traj.intrinsics.width, traj.intrinsics.height)

    def render_output(self, camera: Camera, t: float, backend: str = "auto") -> RenderOutput:
        """Differentiable render at normalised time t (the deformation applies once enabled)."""
        field = self.deform if self.meta.deform_enabled else None
        return render_at(self.gaussians, field, camera, t, self.background, backend, self.meta.precision)

    def render_outputs(self, cameras: list[Camera], t: float, backend: str = "auto") -> list[RenderOutput]:
        """Differentiable renders of several cameras at time t, sharing one deformation evaluation."""
        field = self.deform if self.meta.deform_enabled else None
        return render_views(self.gaussians, field, cameras, t, self.background, backend, self.meta.precision)

    def render_outputs_times(self, cameras: list[list[Camera]], times: list[float],
                             backend: str = "auto") -> list[list[RenderOutput]]:
        """Differentiable renders of cameras[k] at times[k], one deformation call for all the times."""
        field = self.deform if self.meta.deform_enabled else None
        return render_views_times(self.gaussians, field, cameras, times, self.background, backend, self.meta.precision)

    @torch.no_grad()
    def render(self, camera: Camera | int, t: float, backend: str = "auto") -> torch.Tensor:
        """Image [H, W, C] in [0, 1] of `camera` (a Camera, or a dataset camera index) at time t, as a torch
        tensor on the model's device (`render_numpy` gives a NumPy array on the CPU)."""
        check_time(t)
        if isinstance(camera, bool) or not isinstance(camera, (int, np.integer, Camera)):
            raise ValueError(f"camera: expected a Camera (recon.render.camera_from_pose(K, c2w, width, height)) or a "
                             f"dataset camera index, got {type(camera).__name__}")
        cam = self.camera(camera, t) if isinstance(camera, (int, np.integer)) else camera
        return self.render_output(cam, t, backend).image.clamp(0.0, 1.0)

    def render_numpy(self, camera: Camera | int, t: float, backend: str = "auto") -> np.ndarray:
        """`render` as a float32 array [H, W, C] on the CPU, whatever device the model is on."""
        return self.render(camera, t, backend).cpu().numpy()

    def non_finite(self) -> list[str]:
        """Names of the parameters holding inf or NaN (gaussians.<name>, deform.<name>); [] when all are finite."""
        return ([f"gaussians.{n}" for n, p in self.gaussians.named_parameters() if not torch.isfinite(p).all()]
                + [f"deform.{n}" for n, p in self.deform.named_parameters() if not torch.isfinite(p).all()])

    # -- files ----------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return {"format": FORMAT, "meta": asdict(self.meta),
                "gaussians": {k: v.detach().cpu().clone() for k, v in self.gaussians.state_dict().items()},
                "deform": {k: v.detach().cpu().clone() for k, v in self.deform.state_dict().items()},
                "cameras": [{"intrinsics": c.intrinsics.to_dict(), "times_us": c.times_us.tolist(),
                             "c2w_opencv": c.c2w.tolist()} for c in self.cameras]}

    def save(self, path: str | Path) -> None:
        """Write the model to `path` atomically (a half-written file never appears)."""
        with atomic_output(path) as tmp:
            torch.save(self.state(), tmp)

    @classmethod
    def from_state(cls, state: dict[str, Any], source: str = "<state>") -> "DynamicGaussians":
        if not isinstance(state, dict) or state.get("format") != FORMAT:
            raise ValueError(f"{source}: not a model file of this toolkit (expected format {FORMAT!r})")
        meta = ModelMeta(**upgrade_meta(copy.deepcopy(state["meta"])))
        n = state["gaussians"]["means"].shape[0]
        gaussians = GaussianModel(n, meta.sh_degree, meta.channels)
        if "anchors" in state["gaussians"]:
            gaussians.anchors = torch.zeros(n, 3)
        if "motion" in state["gaussians"]:
            gaussians.enable_motion(state["gaussians"]["motion"].shape[1])
        gaussians.load_state_dict(state["gaussians"])
        gaussians.active_sh_degree = meta.active_sh_degree
        deform = make_field(meta.deform_field)
        deform.load_state_dict(state["deform"])
        cams = [CameraTrajectory(Intrinsics(**c["intrinsics"]), np.asarray(c["times_us"], np.int64),
                                 np.asarray(c["c2w_opencv"], np.float64)) for c in state.get("cameras", [])]
        return cls(gaussians, deform, meta, cams)


def upgrade_meta(meta: dict) -> dict:
    """A stored ModelMeta mapping of an older version in today's terms: `deform_bf16: true / false`
    (also inside the stored config's train section) became `precision: bfloat16 / float32`."""
    train = meta.get("config", {}).get("train") if isinstance(meta.get("config"), dict) else None
    for m in (meta, train if isinstance(train, dict) else {}):
        if "deform_bf16" in m:
            m["precision"] = "bfloat16" if m.pop("deform_bf16") else "float32"
    return meta


def load(path: str | Path) -> DynamicGaussians:
    """Load a model: a model .pt file, or a training folder (its model.pt)."""
    path = Path(path)
    if path.is_dir():
        path = path / "model.pt"
    if not path.exists():
        if (path.parent / "checkpoint.pt").exists():
            raise FileNotFoundError(f"{path}: training in {path.parent} has not finished (it has a checkpoint.pt): "
                                    "run the same `e4dgs train` again to finish it")
        raise FileNotFoundError(f"{path}: no such model file (train one with `e4dgs train`)")
    state = torch_load(path, "a model file: not a model saved by this toolkit")
    return DynamicGaussians.from_state(state, str(path))
