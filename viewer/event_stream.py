"""The viewer of a bare event file (a recording `e4dgs import` wrote, or any of the toolkit's .h5): the
stream on a time line that starts at its first event, wherever that is (Unix-epoch microseconds
included), and the events of a window before the slider's time drawn as `e4dgs draw-events` draws them.

    v = EventStreamViewer("recording.h5", port=0); print(v.url); ...; v.stop()
"""
from __future__ import annotations

import threading
import warnings
from pathlib import Path

import numpy as np

from eventio.event_file import EventFile
from eventio.representations import annotate, event_frame
from viewer.app import quiet_aborted_handshakes, server_url

DEFAULT_WINDOW_US = 2_000


class EventStreamViewer:
    def __init__(self, path: str | Path, host: str = "127.0.0.1", port: int = 8080):
        import viser

        self.path = Path(path)
        self.events = EventFile(self.path)
        if self.events.n == 0:
            self.events.close()
            raise ValueError(f"{self.path}: no events (an empty stream): nothing to show")
        self.start_us = int(self.events.times(0, 1)[0])
        self.end_us = int(self.events.times(self.events.n - 1, self.events.n)[0]) + 1
        self._lock = threading.Lock()
        warnings.filterwarnings("ignore", message="Queued a .* on a closed connection")
        quiet_aborted_handshakes()
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.on_client_connect(self._connect)

    @property
    def url(self) -> str:
        return server_url(self.server)

    @property
    def label(self) -> str:
        return (f"events {self.path.name} ({self.events.n:,} events, {self.events.width}x{self.events.height}, "
                f"{self.start_us} .. {self.end_us - 1} us)")

    def picture(self, since_start_us: float, window_us: float) -> tuple[str, np.ndarray]:
        """(title, uint8 [H+18, W, 3]) of the events in [t - window, t), t = the first event + since_start_us."""
        t1 = self.start_us + int(round(np.clip(since_start_us, 0, self.end_us - self.start_us)))
        t0 = max(self.start_us, t1 - max(1, int(round(window_us))))
        with self._lock:
            stream = self.events.window(t0, t1)
        title = f"{len(stream):,} events in [{t0}, {t1}) us (ON red, OFF blue)"
        return title, annotate(event_frame(stream), t0 - self.start_us, t1 - self.start_us)

    def _connect(self, client) -> None:
        gui = client.gui
        span_ms = (self.end_us - self.start_us) / 1000.0
        gui.add_markdown(f"**{self.label}**\n\ntime: milliseconds since the first event ({self.start_us} us)")
        time_h = gui.add_slider("time (ms)", min=0.0, max=span_ms, step=min(0.1, span_ms), initial_value=min(span_ms, 2.0))
        window_h = gui.add_slider("event window (ms)", min=0.001, max=max(span_ms, 0.002), step=0.001,
                                  initial_value=min(DEFAULT_WINDOW_US / 1000.0, span_ms))
        title, image = self.picture(time_h.value * 1000.0, window_h.value * 1000.0)
        image_h = gui.add_image(image, label=title, format="png")

        def redraw(_):
            t, img = self.picture(time_h.value * 1000.0, window_h.value * 1000.0)
            image_h.image, image_h.label = img, t
        time_h.on_update(redraw)
        window_h.on_update(redraw)

    def stop(self) -> None:
        self.server.stop()
        self.events.close()
