"""The browser viewer (viser): a dataset's moving cameras, frames, blur levels and events on one time
line, and trained deformable Gaussians rendered from the browser's camera by the project's renderer.

    v = Viewer([open_source("runs/quick/hinge/e4dgs")], port=0)    # port 0: a free port
    print(v.url); ...; v.stop()

Each browser tab has its own time, camera choice and view. A render thread serves every tab: while
the tab's camera moves it renders at half resolution (JPEG), once it has rested 0.3 s at full
resolution (PNG, lossless); `snap` puts the tab's camera on a dataset camera, and the render then
uses that camera's exact intrinsics and pose at the slider's time (what `model.render(index, t)`
gives). `sent[client_id]` keeps the last image sent to each tab, with what it shows.
"""
from __future__ import annotations

import logging
import threading
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import torch

from recon.raster import Camera
from recon.render import camera_from_pose, deformed, render_deformed
from viewer.geometry import (browser_intrinsics, fov_y_of, letterbox, matrix_to_quat_wxyz, pose_from_wxyz,
                             render_scale, scaled)
from viewer.panels import Panel, ScenePanels, to_uint8_rgb
from viewer.sources import Source

FRAME_US = 1e6 / 3000.0        # one rendered frame of the datasets (3000 FPS): the slider's step
TICK_S = 0.02                  # the render thread's polling period
SNAP_ECHO_S = 0.5              # camera reports this soon after we moved the browser's camera are its echo
CAMERA_COLORS = [(230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48), (145, 30, 180)]


class _AbortedHandshakes(logging.Filter):
    """websockets logs "opening handshake failed" with a traceback when a browser opens a speculative
    connection and closes it before sending its request: nothing the viewer or its user can act on."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "opening handshake failed"


def server_url(server) -> str:
    """The address a browser opens for a viser server."""
    host = server.get_host()
    return f"http://{'localhost' if host in ('0.0.0.0', '127.0.0.1') else host}:{server.get_port()}"


def quiet_aborted_handshakes() -> None:
    """Keep websockets' aborted-handshake tracebacks out of the console (installed once per process)."""
    log = logging.getLogger("websockets.server")
    if not any(isinstance(f, _AbortedHandshakes) for f in log.filters):
        log.addFilter(_AbortedHandshakes())


@dataclass
class Sent:
    """An image sent to a tab as its background, and what it shows."""
    image: np.ndarray             # uint8 [H, W, 3]: the render
    frame: np.ndarray             # uint8 [H', W', 3]: what went to the browser (the render, letterboxed
    box: tuple[int, int]          # to a dataset camera's aspect when snapped) and where the render sits in it (x0, y0)
    t: float                      # normalised time
    camera: int | None            # dataset camera index when snapped, else None (the browser's own camera)
    scale: float                  # resolution factor (1 = full)
    seconds: float                # time to render it


@dataclass
class TabState:
    t: float = 0.0
    camera: int = 0
    window_ms: float = 2.0
    playing: bool = False
    snapped: int | None = None
    snap_request: int | None = 0  # a new tab opens on cam0's view at t = 0
    snap_pose: np.ndarray | None = None
    snap_sent: list = field(default_factory=list)   # recent poses we put the browser's camera at (their echoes)
    snap_set_at: float = 0.0      # when we last moved the browser's camera
    last_move: float = 0.0
    dirty: bool = True            # background must be rendered again
    panels_dirty: bool = True     # the side images must be redrawn
    rendered_full: bool = False
    frusta_at: tuple | None = None  # (time, selected camera) the frusta were last drawn at
    handles: dict = field(default_factory=dict)


class TimedModel:
    """A model with its deformation cached for the last time asked (a moving view re-rasterizes only)."""

    def __init__(self, model):
        self.model = model
        self._t: float | None = None
        self._state = None
        self._lock = threading.Lock()

    @torch.no_grad()
    def render(self, camera: Camera, t: float) -> np.ndarray:
        with self._lock:
            if self._t != t:
                field = self.model.deform if self.model.meta.deform_enabled else None
                self._state = deformed(self.model.gaussians, field, t, self.model.meta.precision)
                self._t = t
            out = render_deformed(self.model.gaussians, self._state, camera, self.model.background)
        return to_uint8_rgb(out.image.clamp(0.0, 1.0).cpu().numpy())


class Viewer:
    def __init__(self, sources: list[Source], host: str = "127.0.0.1", port: int = 8080, slowmo: float = 100.0,
                 verbose: bool = False):
        import viser

        if not sources:
            raise ValueError("viewer: nothing to show")
        self.sources = sources
        self.primary = sources[0]
        self.dataset = next((s.dataset for s in sources if s.dataset is not None), None)
        self.panels = ScenePanels(self.dataset) if self.dataset is not None else None
        self.models = [TimedModel(s.model) for s in sources if s.model is not None]
        if self.dataset is not None:
            self.trajectories = self.dataset.cameras
            self.duration_us = self.dataset.duration_us
        else:
            self.trajectories = self.primary.model.cameras
            self.duration_us = self.primary.model.meta.duration_us
        if not self.trajectories:
            raise ValueError(f"{self.primary.path}: the model records no cameras and no dataset is readable")
        self.slowmo = float(slowmo)
        self.sent: dict[int, Sent] = {}
        self.move_render_s: list[float] = []         # render + send time of each low-resolution frame
        self._tabs: dict[int, TabState] = {}
        self._lock = threading.RLock()
        self._stop = threading.Event()
        # a tab that closes while its images are being sent: viser warns, nothing is lost
        warnings.filterwarnings("ignore", message="Queued a .* on a closed connection")
        quiet_aborted_handshakes()
        self.server = viser.ViserServer(host=host, port=port, verbose=verbose)
        self.server.gui.configure_theme(control_width="large")
        self._add_trajectories()
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        self._thread = threading.Thread(target=self._loop, name="viewer-render", daemon=True)
        self._thread.start()

    # -- addresses -------------------------------------------------------------------------------
    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        return server_url(self.server)

    # -- scene -----------------------------------------------------------------------------------
    def _pose(self, camera: int, t: float) -> np.ndarray:
        return self.trajectories[camera].pose_at(t * self.duration_us)

    def _add_trajectories(self) -> None:
        for k, traj in enumerate(self.trajectories):
            centres = traj.c2w[:, :3, 3]
            segs = np.stack([centres[:-1], centres[1:]], axis=1)
            self.server.scene.add_line_segments(f"/trajectories/cam{k}", segs.astype(np.float32),
                                                colors=CAMERA_COLORS[k % len(CAMERA_COLORS)], thickness=2.0,
                                                thickness_units="screen")

    def _update_frusta(self, client, st: TabState) -> None:
        intr = self.trajectories[0].intrinsics
        fov = fov_y_of(intr.K, intr.height)
        for k in range(len(self.trajectories)):
            c2w = self._pose(k, st.t)
            name = f"/cameras/cam{k}"
            colour = (0, 0, 0) if k == st.camera else CAMERA_COLORS[k % len(CAMERA_COLORS)]
            client.scene.add_camera_frustum(name, fov=fov, aspect=intr.width / intr.height, scale=0.25,
                                            color=colour, wxyz=matrix_to_quat_wxyz(c2w[:3, :3]),
                                            position=c2w[:3, 3], thickness=3.0 if k == st.camera else 1.5,
                                            thickness_units="screen")

    # -- tabs ------------------------------------------------------------------------------------
    def _connect(self, client) -> None:
        st = TabState()
        gui = client.gui
        n = len(self.trajectories)
        dur_ms = self.duration_us / 1000.0
        gui.add_markdown("**" + " | ".join(s.label for s in self.sources) + "**"
                         + "".join(f"\n\n{s.path}: {s.note}" for s in self.sources if s.note))
        h = st.handles
        h["time"] = gui.add_slider("time (ms)", min=0.0, max=dur_ms, step=FRAME_US / 1000.0, initial_value=0.0)
        h["play"] = gui.add_button("play / pause")
        h["slowmo"] = gui.add_number("slow motion (x)", initial_value=self.slowmo, min=1.0, max=100000.0, step=1.0)
        h["camera"] = gui.add_dropdown("camera", tuple(f"cam{k}" for k in range(n)), initial_value="cam0")
        h["snap"] = gui.add_button("snap view to camera")
        h["window"] = gui.add_slider("event window (ms)", min=FRAME_US / 1000.0, max=max(dur_ms, 1.0),
                                     step=FRAME_US / 1000.0, initial_value=min(2.0, dur_ms))
        h["status"] = gui.add_markdown("")
        h["images"] = []

        def on_time(_):
            with self._lock:
                st.t = float(np.clip(h["time"].value * 1000.0 / self.duration_us, 0.0, 1.0))
                st.dirty = st.panels_dirty = True

        def on_play(_):
            with self._lock:
                st.playing = not st.playing

        def on_camera(_):
            with self._lock:
                st.camera = int(str(h["camera"].value).removeprefix("cam"))
                st.panels_dirty = True

        def on_window(_):
            with self._lock:
                st.window_ms = float(h["window"].value)
                st.panels_dirty = True

        def on_slowmo(_):
            with self._lock:
                self.slowmo = max(1.0, float(h["slowmo"].value))

        h["time"].on_update(on_time)
        h["play"].on_click(on_play)
        h["camera"].on_update(on_camera)
        h["window"].on_update(on_window)
        h["slowmo"].on_update(on_slowmo)
        h["snap"].on_click(lambda _: self.snap(client.client_id, st.camera))
        client.camera.on_update(lambda cam: self._camera_moved(client.client_id))
        with self._lock:      # served from now on: the render loop finds every handle of the tab there
            self._tabs[client.client_id] = st

    def _disconnect(self, client) -> None:
        with self._lock:
            self._tabs.pop(client.client_id, None)

    def _camera_moved(self, client_id: int) -> None:
        with self._lock:
            st = self._tabs.get(client_id)
            if st is None:
                return
            if st.snapped is not None:
                client = self.server.get_clients().get(client_id)
                pose = pose_from_wxyz(client.camera.position, client.camera.wxyz) if client else None
                if time.monotonic() - st.snap_set_at < SNAP_ECHO_S or (
                        pose is not None and any(np.allclose(pose, p, atol=1e-2) for p in st.snap_sent)):
                    return                           # the echo of our own snap (the browser reports late,
                                                     # and may report the steps between its parts)
                st.snapped = None
                st.snap_pose = None
                st.snap_sent = []
            st.last_move = time.monotonic()
            st.dirty = True
            st.rendered_full = False

    def set_playing(self, client_id: int, playing: bool) -> None:
        """Start or stop a tab's time playing (the Play button's state)."""
        with self._lock:
            st = self._tabs.get(client_id)
            if st is not None:
                st.playing = bool(playing)

    def snap(self, client_id: int, camera: int) -> None:
        """Put the tab's view on dataset camera `camera`: from the next frame on, renders use its exact
        intrinsics and its pose at the tab's time, and the view follows it as time moves."""
        with self._lock:
            st = self._tabs.get(client_id)
            if st is None:
                return
            st.snap_request = camera

    def _apply_snap(self, client, st: TabState) -> None:
        """(under the lock) Move the browser's camera onto the snapped dataset camera at the tab's time."""
        if st.snap_request is not None:
            st.snapped, st.camera, st.snap_request = st.snap_request, st.snap_request, None
            st.dirty = st.panels_dirty = True
            st.rendered_full = False
        c2w = self._pose(st.snapped, st.t)
        if st.snap_pose is not None and np.array_equal(c2w, st.snap_pose):
            return
        intr = self.trajectories[st.snapped].intrinsics
        st.snap_pose = c2w
        st.snap_sent = st.snap_sent[-15:] + [c2w]
        st.snap_set_at = time.monotonic()
        with client.atomic():
            client.camera.fov = fov_y_of(intr.K, intr.height)
            client.camera.position = c2w[:3, 3]
            client.camera.look_at = c2w[:3, 3] + c2w[:3, 2]
            client.camera.up_direction = -c2w[:3, 1]

    def set_time(self, client_id: int, t: float) -> None:
        """Move a tab's slider to normalised time t (as dragging it would)."""
        with self._lock:
            st = self._tabs[client_id]
        st.handles["time"].value = float(t) * self.duration_us / 1000.0
        with self._lock:
            st.t = float(np.clip(t, 0.0, 1.0))
            st.dirty = st.panels_dirty = True

    def tab_ids(self) -> list[int]:
        with self._lock:
            return list(self._tabs)

    # -- rendering -------------------------------------------------------------------------------
    def _view_camera(self, client, st: TabState, scale: float) -> Camera:
        if st.snapped is not None:
            intr = self.trajectories[st.snapped].intrinsics
            K, w, h = scaled(intr.K, intr.width, intr.height, scale)
            return camera_from_pose(K, self._pose(st.snapped, st.t), w, h)
        height = self.trajectories[0].intrinsics.height
        K, w, h = browser_intrinsics(client.camera.fov, client.camera.aspect, max(1, round(height * scale)))
        return camera_from_pose(K, pose_from_wxyz(client.camera.position, client.camera.wxyz), w, h)

    def _background(self) -> np.ndarray:
        if self.models:
            bg = np.asarray(self.models[0].model.meta.background, np.float64)
            return np.repeat(bg, 3)[:3] if bg.size == 1 else bg[:3]
        return np.zeros(3)

    def _render_background(self, client, st: TabState, scale: float) -> None:
        t0 = time.perf_counter()
        if self.models:
            img = self.models[0].render(self._view_camera(client, st, scale), st.t)
        elif st.snapped is not None and self.panels is not None:
            rec = self.panels.sharp_frame(st.snapped, round(st.t * self.duration_us))
            img = to_uint8_rgb(self.dataset.load_image(rec.path))
        else:                                  # a dataset seen from a free view: the 3D scene alone
            if self.sent.pop(client.client_id, None) is not None:
                client.scene.set_background_image(None)
            return
        frame, box = img, (0, 0)
        if st.snapped is not None:          # the exact camera's image, undistorted in the browser's canvas
            fill = np.round(np.clip(self._background(), 0, 1) * 255).astype(np.uint8)
            frame, box = letterbox(img, client.camera.aspect, fill)
        lossless = scale == 1.0
        client.scene.set_background_image(frame, format="png" if lossless else "jpeg", jpeg_quality=85)
        dt = time.perf_counter() - t0
        self.sent[client.client_id] = Sent(img, frame, box, st.t, st.snapped, scale, dt)
        if not lossless:
            self.move_render_s.append(dt)

    def _side_panels(self, client, st: TabState) -> list[Panel]:
        panels: list[Panel] = []
        if len(self.models) > 1 and st.rendered_full:
            cam = self._view_camera(client, st, 1.0)
            for src, m in zip([s for s in self.sources if s.model is not None][1:], self.models[1:]):
                panels.append(Panel(f"{src.label} at this view and time", m.render(cam, st.t)))
        if self.panels is not None:
            panels += self.panels.at(st.camera, round(st.t * self.duration_us), round(st.window_ms * 1000.0))
        return panels

    def _show_panels(self, client, st: TabState, panels: list[Panel]) -> None:
        handles = st.handles["images"]
        for i, p in enumerate(panels):
            if i < len(handles):
                handles[i].image = p.image
                handles[i].label = p.title
            else:
                handles.append(client.gui.add_image(p.image, label=p.title, format="jpeg", jpeg_quality=90))
        for extra in handles[len(panels):]:
            extra.remove()
        del handles[len(panels):]

    def _serve(self, client, st: TabState, now: float, camera_ready: bool = True) -> None:
        """One tick of a tab: its time, snap, background render (once the browser has reported its
        camera) and side panels (which need no camera: they show as soon as the tab connects)."""
        with self._lock:
            if st.playing:
                st.t = (st.t + TICK_S * 1e6 / (self.slowmo * self.duration_us)) % 1.0
                st.dirty = st.panels_dirty = True
                st.handles["time"].value = st.t * self.duration_us / 1000.0
            if camera_ready and (st.snap_request is not None or st.snapped is not None):
                self._apply_snap(client, st)
            moved_ago = now - st.last_move
            scale = render_scale(moved_ago)
            due = st.dirty or (not st.rendered_full and scale == 1.0)
            panels_due = st.panels_dirty or (due and scale == 1.0 and len(self.models) > 1)
            st.panels_dirty = False
            if camera_ready:
                st.dirty = False
        if due and camera_ready:
            if st.snapped is not None:
                scale = 1.0
            if st.frusta_at != (st.t, st.camera):
                self._update_frusta(client, st)
                st.frusta_at = (st.t, st.camera)
            self._render_background(client, st, scale)
            st.rendered_full = scale == 1.0
            st.handles["status"].content = (f"t = {st.t * self.duration_us / 1000:.2f} ms; "
                                            + (f"view: cam{st.snapped} (exact)" if st.snapped is not None
                                               else "view: free") + f"; render scale {scale:g}")
        if panels_due:
            self._show_panels(client, st, self._side_panels(client, st))

    def _loop(self) -> None:
        while not self._stop.is_set():
            now = time.monotonic()
            clients = self.server.get_clients()
            with self._lock:
                tabs = [(clients[c], st) for c, st in self._tabs.items() if c in clients]
            for client, st in tabs:
                try:                               # has the tab reported its camera yet?
                    ready = getattr(client.camera, "_state", None) is not None and client.camera._state.update_timestamp != 0.0
                    self._serve(client, st, now, ready)
                except Exception as exc:  # noqa: BLE001 - a closing tab must not stop the others
                    if not self._stop.is_set():
                        print(f"viewer: tab {client.client_id}: {type(exc).__name__}: {exc}")
            self._stop.wait(TICK_S)

    def stop(self) -> None:
        """Stop serving: the render thread, the server's threads and sockets, the open event files."""
        self._stop.set()
        self._thread.join(timeout=10.0)
        self.server.stop()
        if self.panels is not None:
            self.panels.close()
