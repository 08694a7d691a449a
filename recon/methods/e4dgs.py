"""E-4DGS (paper sections 3-4): deformable Gaussians supervised by multi-view events.

`e4dgs` trains a grayscale model on events alone; `e4dgs_rgb` a colour model on events plus the
blurred RGB frames of one level. Model outputs are sRGB-encoded like the dataset's images; the event
loss decodes them to linear light and applies the simulator's response (log(I + eps) or lin-log,
read from the event files), so L_hat is the quantity the events measure. Each step:

1. ESS: a camera and a window of N events (recon.event_windows), and with `views_per_step` > 1 the
   same time window on other cameras; N_gt from the events and the simulator's thresholds, with
   N(0, sigma) jitter on event-free pixels (recon.event_supervision.gt_counts);
2. renders at the window's end points, poses interpolated along each camera's trajectory (the
   deformation field runs once for both end points and every camera: recon.deform's forward_times);
3. AES: N_pred = (L_hat(t_end) - L_hat(t_start)) / C_hat with a learnable C_hat = exp(log_c);
4. L = mean over the cameras of 1.0 L_recon + 0.005 TV(render at t_end) [+ 1.0 (L1 + D-SSIM) on a
   blurred frame, on every `rgb_every`-th step].

IIP prunes by importance (the rasterizer's max alpha x transmittance over the training cameras at
`iip_times` timestamps); there is no opacity reset. Test views are scored after per-image colour
correction on log intensity (common.color_correction).
"""
from __future__ import annotations

import math
import numpy as np
import torch
from torch import nn

from scene_format.reader import SceneDataset
from recon import event_supervision as ev
from common.color_correction import correct_colors
from recon.methods.e4dgs_config import E4DGSConfig
from recon.event_windows import EventSource, WindowSampler
from recon.device import to_device
from recon.losses import photometric_loss
from recon.methods import register
from recon.model import DynamicGaussians
from recon.method import Method
from recon.dataset_views import BlurView, blur_views, dataset_camera
from recon.coarse import block_mean, coarse_camera, coarse_srgb

PAPER_PIXELS = 346 * 260


def importance(model: DynamicGaussians, dataset: SceneDataset, n_times: int, backend: str = "auto") -> torch.Tensor:
    """IIP's w_i [N]: max over the dataset's cameras x n_times timestamps of the Gaussian's largest
    alpha x transmittance on any pixel (on the model's device, rendered with `backend`)."""
    w = torch.zeros(len(model), device=model.device)
    for k in range(dataset.n_cameras):
        for t in np.linspace(0.0, 1.0, n_times):
            out = model.render_output(dataset_camera(dataset, k, int(round(t * dataset.duration_us))), float(t), backend)
            w = torch.maximum(w, out.max_weight.detach())
    return w


@register
class E4DGS(Method):
    name = "e4dgs"
    config_cls = E4DGSConfig
    uses_rgb = False
    inputs = ("events",)

    def __init__(self, dataset: SceneDataset, cfg: E4DGSConfig):
        super().__init__(dataset, cfg)
        e = cfg.events
        sources = [EventSource(dataset.event_file(k)) for k in range(dataset.n_cameras)]
        for src in sources:      # windows are cut every step: from memory where the events fit
            src.load()
        self.n_range = self.window_counts(dataset, e, [s.n for s in sources])
        n_fixed = int(round(sum(self.n_range) / 2))
        self.sampler = WindowSampler(sources, self.n_range if e.ess else None, n_fixed)
        src = self.sampler.sources[0]
        self.c_pos, self.c_neg = src.thresholds()
        self.c_ref = 0.5 * (self.c_pos + self.c_neg)
        sensor = src.sensor   # the file's sensor record (eventio.sensor): the response L_hat must match
        self.response = {"mode": sensor.log_mode, "eps": float(sensor.log_eps),
                         "linlog_threshold_dn": float(sensor.linlog_threshold_dn),
                         "dn_per_unit": float(sensor.linlog_dn_per_unit)}
        if e.views_per_step > dataset.n_cameras:
            raise ValueError(f"events.views_per_step: {e.views_per_step} cameras asked for, the dataset "
                             f"{dataset.dir} has {dataset.n_cameras}")
        self.device = torch.device("cpu")
        self.log_c = nn.Parameter(torch.tensor(math.log(e.c_init)), requires_grad=e.aes)
        self.blur_views = self._blur_views() if self.uses_rgb else []

    def to_device(self, device: torch.device) -> None:
        self.device = device
        self.log_c = nn.Parameter(self.log_c.detach().to(device), requires_grad=self.log_c.requires_grad)
        self.blur_views = to_device(self.blur_views, device)

    @staticmethod
    def window_counts(dataset: SceneDataset, e, n_events: list[int]) -> tuple[int, int]:
        """[N_min, N_max] for this dataset (see EventConfig) from each camera's event count:
        window_fraction of the smallest stream, or the paper's range scaled by the pixel count;
        capped at max_window_fraction."""
        smallest = min(n_events)
        if e.window_scale == "rate":
            lo, hi = (f * smallest for f in e.window_fraction)
        else:
            lo, hi = e.n_events_object if dataset.scene.kind == "object" else e.n_events_room
            ratio = dataset.intrinsics.width * dataset.intrinsics.height / PAPER_PIXELS
            lo, hi = lo * ratio, hi * ratio
        cap = max(1, int(e.max_window_fraction * smallest))
        return min(max(1, round(lo)), cap), min(max(1, round(hi)), cap)

    @property
    def c_hat(self) -> torch.Tensor:
        return torch.exp(self.log_c)

    @classmethod
    def channels_of(cls, cfg: E4DGSConfig) -> int:
        return 3 if cls.uses_rgb else 1

    def setup_model(self, model: DynamicGaussians) -> None:
        if self.cfg.events.inherit_deformation:
            model.gaussians.anchors = model.gaussians.means.detach().clone()

    def extra_parameters(self) -> list[dict]:
        return [{"params": [self.log_c], "lr": self.cfg.events.c_lr, "name": "c_hat"}] if self.cfg.events.aes else []

    def state_dict(self) -> dict:
        return {"log_c": self.log_c.detach().cpu().clone()}

    def load_state_dict(self, state: dict) -> None:
        with torch.no_grad():
            self.log_c.copy_(state["log_c"].to(self.log_c.device))

    # -- data -----------------------------------------------------------------------------------
    def _blur_views(self) -> list[BlurView]:
        return blur_views(self.dataset, self.cfg.rgb_frames, self.cfg.rgb_samples, self.cfg.rgb_render, 3)

    def log_intensity(self, image: torch.Tensor) -> torch.Tensor:
        """Rendered sRGB image [H, W, C] -> L_hat [H, W] through the simulator's response."""
        lum = ev.luminance_t(ev.srgb_to_linear_t(image))
        r = self.response
        return ev.log_response_t(lum, r["mode"], r["eps"], r["linlog_threshold_dn"], r["dn_per_unit"])

    # -- one iteration --------------------------------------------------------------------------
    def event_loss(self, trainer, windows):
        """Mean event loss over windows that share one time interval (one per camera)."""
        ds, e = self.dataset, self.cfg.events
        t_start_us, t_end_us = windows[0].t_start_us, windows[0].t_end_us
        t_s = min(max(t_start_us / ds.duration_us, 0.0), 1.0)
        t_e = min(max(t_end_us / ds.duration_us, 0.0), 1.0)
        f = trainer.render_factor
        cams_s = [coarse_camera(dataset_camera(ds, w.camera, t_start_us), f) for w in windows]
        cams_e = [coarse_camera(dataset_camera(ds, w.camera, t_end_us), f) for w in windows]
        outs_s, outs_e = trainer.model.render_outputs_times([cams_s, cams_e], [t_s, t_e], trainer.backend)
        intr = ds.intrinsics
        loss = 0.0
        for window, out_s, out_e in zip(windows, outs_s, outs_e):
            de, hits = ev.event_maps(window.x, window.y, window.p, intr.width, intr.height, self.c_pos, self.c_neg)
            n_gt = torch.from_numpy(ev.gt_counts(de, hits, self.c_ref, e.noise_sigma if e.ess else 0.0,
                                                 trainer.rng)).to(self.device)
            n_gt = block_mean(n_gt, f)        # counts are linear in log intensity: block means (recon.coarse)
            n_pred = ev.predicted_counts(self.log_intensity(out_s.image), self.log_intensity(out_e.image), self.c_hat)
            loss = loss + e.lambda_recon * ev.multiscale_recon_loss(n_gt, n_pred, e.loss_scales, e.recon_eps)
            if e.lambda_tv > 0:
                loss = loss + e.lambda_tv * ev.tv_loss(out_e.image)
        renders = list(zip(outs_s, cams_s)) + list(zip(outs_e, cams_e))
        return loss / len(windows), renders

    def rgb_loss(self, trainer):
        view = self.blur_views[trainer.next_index(len(self.blur_views))]
        f = trainer.render_factor
        cameras = [coarse_camera(c, f) for c in view.cameras]
        outs = [trainer.model.render_output(c, t, trainer.backend) for c, t in zip(cameras, view.times)]
        pred = ev.exposure_mean([o.image for o in outs])
        loss = photometric_loss(pred, coarse_srgb(view.image, f), self.cfg.lambda_dssim)
        return loss, list(zip(outs, cameras))

    def step(self, trainer, iteration: int):
        e = self.cfg.events
        # one view draws exactly what it always did (sample_views also draws a camera order)
        windows = [self.sampler.sample(trainer.rng)] if e.views_per_step == 1 else \
            self.sampler.sample_views(trainer.rng, e.views_per_step)
        loss, renders = self.event_loss(trainer, windows)
        if self.uses_rgb and self.cfg.lambda_rgb > 0 and iteration % self.cfg.rgb_every == 0:
            l_rgb, more = self.rgb_loss(trainer)
            loss, renders = loss + self.cfg.lambda_rgb * l_rgb, renders + more
        for out, _ in renders:
            if out.means2d.requires_grad:
                out.means2d.retain_grad()
        return loss, renders

    # -- intensity importance pruning -----------------------------------------------------------
    def importance(self, model: DynamicGaussians, backend: str = "auto") -> torch.Tensor:
        return importance(model, self.dataset, self.cfg.events.iip_times, backend)

    def prune_mask(self, trainer, iteration: int):
        e = self.cfg.events
        if not e.iip or iteration < trainer.tcfg.scaled(e.iip_start) or \
                iteration % trainer.tcfg.scaled(e.iip_interval) != 0:
            return None
        return self.importance(trainer.model, trainer.backend) < e.iip_threshold

    # -- evaluation -----------------------------------------------------------------------------
    @classmethod
    def correction(cls, cfg: E4DGSConfig):
        return lambda pred, gt: correct_colors(pred, gt)[0]


@register
class E4DGSRGB(E4DGS):
    name = "e4dgs_rgb"
    uses_rgb = True
    inputs = ("events", "rgb")
    blur_level_field = "rgb_frames"
