"""What the viewer shows of a dataset camera at a time: its sharp frame, each blur level's frame (with
its exposure and measured blur), its event frame over a window, and, where the scene has ground
truth, the frame's depth and optical flow (colour wheel), as labelled uint8 images.

    panels = ScenePanels(SceneDataset("data/quick/hinge"))
    for p in panels.at(camera=2, t_us=40_000, window_us=2_000): ...   # Panel(title, image [H, W, 3])
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np

from scene_format.reader import FrameRecord, SceneDataset
from eventio.event_file import EventFile
from eventio.representations import annotate, event_frame


@dataclass(frozen=True)
class Panel:
    title: str                 # what the image is, with its time and figures
    image: np.ndarray          # uint8 [H, W, 3]


def to_uint8_rgb(img: np.ndarray) -> np.ndarray:
    """float [H, W] / [H, W, 1] / [H, W, 3] in [0, 1] (or uint8) as uint8 [H, W, 3]."""
    a = np.asarray(img)
    if a.dtype != np.uint8:
        a = np.round(np.clip(np.nan_to_num(a.astype(np.float32)), 0.0, 1.0) * 255.0).astype(np.uint8)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    return np.ascontiguousarray(a)


def nearest(records: list[FrameRecord], t_us: int) -> FrameRecord | None:
    """The record whose t_us is closest to t_us (records sorted by t_us; the earlier on a tie)."""
    if not records:
        return None
    times = [r.t_us for r in records]
    i = bisect.bisect_left(times, t_us)
    if i == 0:
        return records[0]
    if i == len(records):
        return records[-1]
    return records[i - 1] if t_us - times[i - 1] <= times[i] - t_us else records[i]


def _by_camera(records: list[FrameRecord], n_cameras: int) -> list[list[FrameRecord]]:
    out: list[list[FrameRecord]] = [[] for _ in range(n_cameras)]
    for r in records:
        out[r.camera].append(r)
    return [sorted(rs, key=lambda r: r.t_us) for rs in out]


class ScenePanels:
    """A scene's frames and events indexed for look-ups by camera and time (files read on demand)."""

    def __init__(self, dataset: SceneDataset):
        self.dataset = dataset
        n = dataset.n_cameras
        self.sharp = _by_camera(dataset.frames("train") + dataset.frames("test"), n)
        self.levels = dataset.blur_levels()
        self.blurred = {lv: _by_camera(dataset.blurred_frames(lv), n) for lv in self.levels}
        self.blur_figures = dataset.facts.blur          # level -> BlurLevelFacts
        self._events: dict[int, EventFile] = {}

    def sharp_frame(self, camera: int, t_us: int) -> FrameRecord | None:
        return nearest(self.sharp[camera], t_us)

    def events(self, camera: int) -> EventFile:
        if camera not in self._events:
            self._events[camera] = EventFile(self.dataset.event_file(camera))
        return self._events[camera]

    def event_image(self, camera: int, t0_us: int, t1_us: int) -> np.ndarray:
        """uint8 [H+18, W, 3]: events with t0 <= t < t1 (ON red, OFF blue) over a strip with the window
        and the colour key."""
        stream = self.events(camera).window(int(t0_us), int(t1_us))
        return annotate(event_frame(stream), int(t0_us), int(t1_us))

    def at(self, camera: int, t_us: int, window_us: int) -> list[Panel]:
        """Sharp frame, each blur level's frame and the event frame of `camera` nearest to t_us."""
        panels = []
        rec = self.sharp_frame(camera, t_us)
        if rec is not None:
            panels.append(Panel(f"sharp, cam{camera} frame {rec.index} at {rec.t_us / 1000:.2f} ms",
                                to_uint8_rgb(self.dataset.load_image(rec.path))))
        for lv in self.levels:
            b = nearest(self.blurred[lv][camera], t_us)
            if b is None:
                continue
            fig = self.blur_figures.get(lv)
            per_cam = fig.per_camera_median_px if fig else ()
            px = per_cam[camera] if camera < len(per_cam) else (fig.median_px if fig else None)
            px = float("nan") if px is None else px
            span = (f"exposure {b.exposure_us[0] / 1000:.2f}-{b.exposure_us[1] / 1000:.2f} ms"
                    if b.exposure_us else "")
            panels.append(Panel(f"blur {lv}: {span} ({fig.exposure_ms if fig else float('nan'):.2f} ms), "
                                f"measured {px:.1f} px (median, this camera)",
                                to_uint8_rgb(self.dataset.load_image(b.path))))
        t1 = int(t_us)
        t0 = max(0, t1 - int(window_us))
        panels.append(Panel(f"events {t0 / 1000:.2f}-{t1 / 1000:.2f} ms (ON red, OFF blue)",
                            self.event_image(camera, t0, t1)))
        if rec is not None and self.dataset.ground_truth_kinds:
            panels += self.ground_truth_panels(rec)
        return panels

    def ground_truth_panels(self, rec: FrameRecord) -> list[Panel]:
        """Depth and flow pictures of a kept frame (what the scene's ground truth holds)."""
        from common.flow import depth_to_rgb, flow_to_rgb

        gt = self.dataset.ground_truth(rec.camera, rec.index)
        out = []
        if gt.depth_m is not None:
            seen = gt.depth_m[gt.depth_m > 0]
            span = f"{seen.min():.2f}-{seen.max():.2f} m" if seen.size else "no surface"
            out.append(Panel(f"depth, frame {rec.index}: {span} (near bright)", depth_to_rgb(gt.depth_m)))
        if gt.flow_px is not None:
            top = float(np.hypot(*gt.flow_px[gt.flow_valid].T).max()) if gt.flow_valid.any() else 0.0
            out.append(Panel(f"flow to frame {rec.index + 1}: up to {top:.1f} px (hue: direction, "
                             "saturation: speed; black: invalid)", flow_to_rgb(gt.flow_px, gt.flow_valid)))
        elif gt.velocity_px_per_ms is not None:
            v = gt.velocity_px_per_ms
            out.append(Panel(f"image velocity, frame {rec.index} (last kept frame): px/ms",
                             flow_to_rgb(v, np.any(v != 0, -1))))
        return out

    def close(self) -> None:
        for f in self._events.values():
            f.close()
        self._events.clear()
