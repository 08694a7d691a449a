"""Event pictures: an event frame (ON and OFF in two colours), with its time window and colour key,
or with a flow drawn over it.

    >>> import numpy as np
    >>> from eventio.events import EVENT_DTYPE, EventStream
    >>> ev = np.zeros(3, EVENT_DTYPE)
    >>> ev["x"], ev["y"], ev["p"] = [0, 0, 1], [0, 0, 0], [1, 1, -1]
    >>> img = event_frame(EventStream(ev, 2, 1), saturate_count=2)
    >>> img.shape, img[0, 0].tolist(), img[0, 1].tolist()      # two ON events saturate; one OFF half-strength
    ((1, 2, 3), [220, 40, 40], [148, 168, 238])
"""
from __future__ import annotations

import numpy as np

from eventio.events import EventStream

ON_RGB = np.array([220, 40, 40], np.float64)    # red
OFF_RGB = np.array([40, 80, 220], np.float64)   # blue (mirror of ON, so a tie is neutral)
BACKGROUND_RGB = np.array([255, 255, 255], np.float64)


def event_frame(stream: EventStream, saturate_count: int = 3) -> np.ndarray:
    """RGB uint8 [H,W,3]: white background, ON events red, OFF blue, mixed pixels blended.

    Colour strength grows with the event count and saturates at `saturate_count` events.
    """
    H, W = stream.height, stream.width
    ev = stream.events
    idx = ev["y"].astype(np.int64) * W + ev["x"]
    on = np.bincount(idx[ev["p"] > 0], minlength=H * W).reshape(H, W).astype(np.float64)
    off = np.bincount(idx[ev["p"] < 0], minlength=H * W).reshape(H, W).astype(np.float64)
    total = on + off
    strength = np.minimum(total / max(saturate_count, 1), 1.0)[..., None]
    frac_on = np.divide(on, total, out=np.zeros_like(on), where=total > 0)[..., None]
    colour = frac_on * ON_RGB + (1.0 - frac_on) * OFF_RGB
    img = (1.0 - strength) * BACKGROUND_RGB + strength * colour
    return np.round(img).astype(np.uint8)


FLOW_RGB = (0, 140, 0)      # arrows of a drawn flow: dark green, apart from ON red and OFF blue


def overlay_flow(frame: np.ndarray, flow: np.ndarray, valid: np.ndarray, scale: int = 1, step_px: int = 8) -> np.ndarray:
    """The event frame scaled up `scale` times (nearest), with a flow [H, W, 2] (px, at the sensor's
    resolution) drawn as arrows from every step_px-th valid pixel centre to where it goes (non-finite
    flow skipped)."""
    import cv2

    if flow.shape[:2] != frame.shape[:2]:
        raise ValueError(f"the flow is {flow.shape[1]}x{flow.shape[0]} pixels, the events {frame.shape[1]}x{frame.shape[0]}")
    img = np.ascontiguousarray(np.repeat(np.repeat(frame, scale, 0), scale, 1) if scale > 1 else frame)
    h, w = flow.shape[:2]
    for y in range(step_px // 2, h, step_px):
        for x in range(step_px // 2, w, step_px):
            if valid[y, x] and np.isfinite(flow[y, x]).all():
                a = ((x + 0.5) * scale, (y + 0.5) * scale)
                # an arrow leaving the picture is drawn to just past its edge (a huge flow stays drawable)
                b = (np.clip((x + 0.5 + flow[y, x, 0]) * scale, -w * scale, 2 * w * scale),
                     np.clip((y + 0.5 + flow[y, x, 1]) * scale, -h * scale, 2 * h * scale))
                cv2.arrowedLine(img, tuple(int(round(v)) for v in a), tuple(int(round(v)) for v in b), FLOW_RGB, 1,
                                cv2.LINE_AA, tipLength=0.3)
    return img


def annotate(frame: np.ndarray, t0_us: int, t1_us: int, scale: int = 1) -> np.ndarray:
    """The event frame scaled up `scale` times (nearest), over a strip with its time window and the
    colour key (ON red, OFF blue)."""
    import cv2

    img = np.repeat(np.repeat(frame, scale, 0), scale, 1) if scale > 1 else frame
    h, w = img.shape[:2]
    strip = np.full((18, w, 3), 255, np.uint8)
    text = f"{t0_us / 1000:.3f}-{t1_us / 1000:.3f} ms"
    cv2.putText(strip, text, (3, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    for k, (label, rgb) in enumerate((("ON", ON_RGB), ("OFF", OFF_RGB))):
        x = w - 70 + 36 * k
        if x > 0:
            strip[5:13, x:x + 8] = rgb.astype(np.uint8)
            cv2.putText(strip, label, (x + 10, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([img, strip], 0)
