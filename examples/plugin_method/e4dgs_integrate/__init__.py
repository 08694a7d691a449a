"""An outside method for the e4dgs toolkit, as a plug-in: direct event integration + D3DGS.

The classic events-only baseline without a network: each camera's events are summed per pixel into a
log intensity (each event steps it by +-`contrast`), with a leak that forgets the start (a high-pass
filter of cut-off `cutoff_hz`, as in Scheerlinck et al., ACCV 2018, without frames), read out at the
camera's training timestamps as gray frames, and a D3DGS is trained on them. Like every events-only
method it knows no absolute intensity, so it is scored after the benchmark's log gain / offset.

It lives outside the toolkit and is found through the entry point `integrate_d3dgs` of the group
`e4dgs.methods` (pyproject.toml). After `pip install ./examples/plugin_method`:

    e4dgs train data/quick/hinge --method integrate_d3dgs
    # a bench preset cell:  mine: {method: integrate_d3dgs, label: "Event integration + D3DGS"}
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from common.color import linear_to_srgb
from common.color_correction import correct_colors
from common.config import ConfigError
from recon.config import TrainConfig
from recon.methods.d3dgs import D3DGS, TrainView
from recon.dataset_views import record_camera
from eventio.event_file import EventFile


@dataclass(frozen=True)
class IntegrateConfig:
    contrast: float = 0.25        # log-intensity step of one event (the sensor's nominal threshold)
    cutoff_hz: float = 5.0        # leak: the integrated image forgets with this corner frequency
    base: float = 0.18            # linear intensity of log intensity 0 (mid-grey) in the frames
    lambda_dssim: float = 0.2
    train: TrainConfig = field(default_factory=TrainConfig)

    def __post_init__(self):
        for name in ("contrast", "base"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive value, got {getattr(self, name)!r}")
        if not self.cutoff_hz >= 0:
            raise ConfigError(f"cutoff_hz: expected a value >= 0, got {self.cutoff_hz!r}")
        if not 0 <= self.lambda_dssim <= 1:
            raise ConfigError(f"lambda_dssim: expected a value in [0, 1], got {self.lambda_dssim!r}")


def integrate(x: np.ndarray, y: np.ndarray, p: np.ndarray, t_us: np.ndarray, read_us: np.ndarray, width: int,
              height: int, contrast: float, cutoff_hz: float) -> np.ndarray:
    """Log intensity [K, H, W] at the sorted times read_us [K] from events (x, y, p in {-1, +1}, t_us)
    sorted in time: each event adds p * contrast; between read-outs everything decays by
    exp(-2 pi cutoff_hz dt) (the leak is applied per read-out interval)."""
    out = np.empty((len(read_us), height, width), np.float32)
    log_i = np.zeros(height * width, np.float64)
    ends = np.searchsorted(t_us, read_us, side="right")
    start, t_prev = 0, read_us[0]
    for k, (end, t) in enumerate(zip(ends, read_us)):
        log_i *= np.exp(-2 * np.pi * cutoff_hz * (t - t_prev) * 1e-6)
        if end > start:
            log_i += contrast * np.bincount(y[start:end].astype(np.int64) * width + x[start:end],
                                            weights=p[start:end], minlength=height * width)
        out[k] = log_i.reshape(height, width)
        start, t_prev = end, t
    return out


class IntegrateD3DGS(D3DGS):
    name = "integrate_d3dgs"
    config_cls = IntegrateConfig
    inputs = ("events",)
    blur_level_field = None

    @classmethod
    def channels_of(cls, cfg: IntegrateConfig) -> int:
        return 1

    @classmethod
    def correction(cls, cfg: IntegrateConfig):
        return lambda pred, gt: correct_colors(pred, gt)[0]

    def training_records(self):
        return self.dataset.frames("train")

    def training_views(self) -> list[TrainView]:
        views = []
        for cam in sorted({r.camera for r in self.training_records()}):
            recs = sorted((r for r in self.training_records() if r.camera == cam), key=lambda r: r.t_us)
            with EventFile(self.dataset.event_file(cam)) as ev:
                i0, i1 = 0, ev.n
                x, y, p = ev.rows(i0, i1)
                t = ev.times(i0, i1)
                log_i = integrate(np.asarray(x), np.asarray(y), np.asarray(p, np.float64), t,
                                  np.array([r.t_us for r in recs], np.int64), ev.width, ev.height,
                                  self.cfg.contrast, self.cfg.cutoff_hz)
            frames = np.clip(linear_to_srgb(np.clip(self.cfg.base * np.exp(log_i), 0, 1)), 0, 1).astype(np.float32)
            views += [TrainView(record_camera(self.dataset, r), r.time, torch.from_numpy(f[..., None].copy()))
                      for r, f in zip(recs, frames)]
        return views
