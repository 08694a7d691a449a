"""`e4dgs viewer`: its camera arithmetic against analytic answers; a real headless Chromium connected
to it shows the model (the image the server sends for a dataset camera and time is
`model.render(camera, t)`, and the page's screenshot is not blank); paths that are neither a dataset
nor a run are refused in one line; starting, serving and stopping leave no process and no file."""
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from viewer.geometry import (browser_intrinsics, fov_y_of, letterbox, matrix_to_quat_wxyz, pose_from_wxyz,
                             quat_wxyz_to_matrix, render_scale, scaled)
from viewer.headless import chromium_path
from viewer.panels import nearest, to_uint8_rgb

ROOT = Path(__file__).resolve().parents[2]
TRAIN = {"train.iterations": 8, "train.scale_schedule": False, "train.warm_up": 3, "train.densify.enabled": False,
         "train.init.n_points_object": 400, "train.checkpoint_every": 8, "train.snapshots": []}


def _need_chromium():
    if chromium_path() is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is missing: CI must install it (.ci/run does: apt-get install chromium)")
        pytest.skip("no chromium on this machine (apt-get install chromium)")


# -- arithmetic -------------------------------------------------------------------------------------
def test_a_closed_browser_leaves_nothing_in_the_temporary_folder(monkeypatch):
    """Chromium makes a folder of its own for its singleton socket under TMPDIR and leaves it behind
    (hundreds of org.chromium.Chromium.* folders in /tmp after some test runs)."""
    _need_chromium()
    from viewer.headless import HeadlessChromium

    # A short folder: a Unix socket's path must stay under 108 bytes, and pytest's tmp_path is long.
    outer = Path(tempfile.mkdtemp(prefix="e4t"))
    try:
        monkeypatch.setenv("TMPDIR", str(outer))
        monkeypatch.setattr("tempfile.tempdir", None)
        browser = HeadlessChromium(300, 200)
        try:
            browser.open("data:text/html,<p>page</p>")
            _wait(lambda: browser.evaluate("document.readyState") == "complete", 30.0, "the page did not load")
        finally:
            browser.close()
        assert sorted(p.name for p in outer.iterdir()) == []
    finally:
        shutil.rmtree(outer, ignore_errors=True)


def test_quaternions_and_matrices_round_trip(rng):
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        R = quat_wxyz_to_matrix(q)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(matrix_to_quat_wxyz(R), q, atol=1e-9)
    # 90 degrees about z: x -> y
    np.testing.assert_allclose(quat_wxyz_to_matrix([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]) @ [1, 0, 0],
                               [0, 1, 0], atol=1e-12)
    with pytest.raises(ValueError, match="quaternion"):
        quat_wxyz_to_matrix([0, 0, 0, 0])


def test_browser_camera_intrinsics_are_the_pinhole_of_its_field_of_view():
    K, w, h = browser_intrinsics(np.pi / 2, 1.5, 200)            # 90 degrees high: f = h / 2
    assert (w, h) == (300, 200)
    np.testing.assert_allclose(K, [[100, 0, 150], [0, 100, 100], [0, 0, 1]])
    assert fov_y_of(K, h) == pytest.approx(np.pi / 2)
    K2, w2, h2 = scaled(K, w, h, 0.5)
    assert (w2, h2) == (150, 100) and fov_y_of(K2, h2) == pytest.approx(np.pi / 2)
    c2w = pose_from_wxyz([1, 2, 3], [1, 0, 0, 0])
    np.testing.assert_allclose(c2w, [[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]])
    assert render_scale(0.0) == 0.5 and render_scale(5.0) == 1.0


def test_letterbox_centres_the_image_at_the_canvas_aspect():
    img = np.full((260, 346, 3), 7, np.uint8)
    canvas, (x0, y0) = letterbox(img, 2.0, [1, 2, 3])
    assert canvas.shape == (260, 520, 3) and (x0, y0) == (87, 0)
    assert np.array_equal(canvas[:, x0:x0 + 346], img) and np.array_equal(canvas[0, 0], [1, 2, 3])
    canvas, (x0, y0) = letterbox(img, 1.0, [0, 0, 0])
    assert canvas.shape == (346, 346, 3) and (x0, y0) == (0, 43)


def test_nearest_frame_and_uint8_conversion():
    from scene_format.reader import FrameRecord

    recs = [FrameRecord(0, i, t, t / 100, Path(f"{i}.png")) for i, t in enumerate([0, 10, 20])]
    assert [nearest(recs, t).index for t in (-5, 4, 5, 6, 100)] == [0, 0, 0, 1, 2]
    assert nearest([], 3) is None
    out = to_uint8_rgb(np.array([[0.0, 0.5, 1.0, 2.0]], np.float32))
    assert out.shape == (1, 4, 3) and out[0, :, 0].tolist() == [0, 128, 255, 255]


# -- a browser on a served model --------------------------------------------------------------------
@pytest.fixture(scope="module")
def trained(motion_scene, tmp_path_factory):
    from recon.api import fit

    out = tmp_path_factory.mktemp("viewer_runs")
    fit(motion_scene, "d3dgs", out_dir=out / "d3dgs-0123", overrides={**TRAIN, "frames": "sharp"}, progress=False)
    fit(motion_scene, "e4dgs", out_dir=out / "e4dgs-4567", overrides=TRAIN, progress=False)
    return out


def _wait(pred, timeout_s=90.0, what="the viewer did not answer in time"):
    """Wait for a condition (never for a guessed time): poll `pred` until it holds, failing after timeout_s."""
    t0 = time.monotonic()
    while not pred():
        assert time.monotonic() - t0 < timeout_s, what() if callable(what) else what
        time.sleep(0.05)


def test_the_headless_page_has_the_focus_viser_needs_to_retry_a_connection():
    """viser's client retries a failed websocket connection only while document.hasFocus(); a headless
    page has none unless emulated, so one failed first attempt on a busy machine (the CI flake: no GUI
    within 90 s) was never retried."""
    _need_chromium()
    from viewer.headless import HeadlessChromium

    browser = HeadlessChromium(300, 200)
    try:
        browser.open("data:text/html,<p>page</p>")
        _wait(lambda: browser.evaluate("document.readyState") == "complete", 30.0, "the page did not load")
        assert browser.evaluate("document.hasFocus()") is True
    finally:
        browser.close()


def test_a_tab_gets_its_panels_before_its_browser_reports_a_camera(motion_scene):
    """The side panels (frames, events) need no camera: a tab whose browser has not reported one yet (a
    busy machine's software WebGL; the second CI flake: the GUI but no panel within 90 s) gets them at
    once; its 3D background waits for the camera and is not forgotten."""
    from types import SimpleNamespace

    from viewer.app import TabState, Viewer
    from viewer.sources import open_source

    viewer = Viewer([open_source(motion_scene)], port=0)
    try:
        added = []

        class Handle(SimpleNamespace):
            def remove(self):
                added.remove(self)

        def add_image(image, label, **_):
            added.append(Handle(image=image, label=label))
            return added[-1]

        client = SimpleNamespace(client_id=7, gui=SimpleNamespace(add_image=add_image))
        st = TabState()
        st.handles["images"] = []
        st.dirty = st.panels_dirty = True
        viewer._serve(client, st, time.monotonic(), camera_ready=False)
        assert [h.label for h in added] and any("events" in h.label for h in added)
        assert st.dirty and 7 not in viewer.sent                    # the background still to render
    finally:
        viewer.stop()


def test_a_tab_is_served_only_once_its_controls_exist(motion_scene):
    """The render loop serves every registered tab: registered before its controls were built (a
    connect slowed by a busy machine), a tab was served without its status line (KeyError 'status'),
    and its panels, marked done, never came."""
    from unittest.mock import MagicMock

    from viewer.app import Viewer
    from viewer.sources import open_source

    viewer = Viewer([open_source(motion_scene)], port=0)
    try:
        seen = []
        client = MagicMock(client_id=7)
        client.gui.add_markdown.side_effect = lambda *a, **k: seen.append(7 in viewer.tab_ids()) or MagicMock()
        viewer._connect(client)
        assert seen and not any(seen)                    # not served while its controls were being added
        assert 7 in viewer.tab_ids()                      # and served once they are
    finally:
        viewer.stop()


def test_a_headless_browser_sees_the_model_render_at_a_dataset_camera_and_time(trained, motion_scene, tmp_path):
    _need_chromium()
    from recon.model import load
    from viewer.app import Viewer
    from viewer.headless import HeadlessChromium
    from viewer.sources import open_source

    model = load(trained / "d3dgs-0123")
    assert model.meta.deform_enabled
    viewer = Viewer([open_source(trained / "d3dgs"), open_source(trained / "e4dgs-4567")], port=0)
    browser = HeadlessChromium(1100, 700)
    try:
        browser.open(viewer.url)
        _wait(lambda: viewer.tab_ids() and viewer.sent.get(viewer.tab_ids()[0]) is not None
              and viewer.sent[viewer.tab_ids()[0]].scale == 1.0)
        cid = viewer.tab_ids()[0]
        for camera, t in ((0, 0.0), (1, 0.7)):
            viewer.snap(cid, camera)
            viewer.set_time(cid, t)
            _wait(lambda: (s := viewer.sent.get(cid)) is not None and s.camera == camera and s.t == t
                  and s.scale == 1.0)
            sent = viewer.sent[cid]
            want = np.round(model.render(camera, t).numpy() * 255.0).astype(np.uint8)
            assert sent.image.shape == want.shape == (48, 64, 3)
            assert np.array_equal(sent.image, want)
            x0, y0 = sent.box                               # the letterboxed frame carries it unchanged
            assert np.array_equal(sent.frame[y0:y0 + 48, x0:x0 + 64], want)
        other = load(trained / "e4dgs-4567")
        assert not np.array_equal(model.render(1, 0.7).numpy(), model.render(1, 0.0).numpy())   # time matters
        _wait(lambda: browser.evaluate("document.body.innerText.includes('at this view and time')"))
        text = browser.evaluate("document.body.innerText")
        assert "sharp, cam1" in text and "events" in text and "ON red, OFF blue" in text
        assert f"{len(other):,} Gaussians" in text                                 # the second run beside it
        shots = []

        def drawn() -> bool:                                  # the 3D view (left of the GUI panel) not blank
            try:    # a software-GL frame on a starved core can miss one call's minute (a full suite on one core)
                png = browser.screenshot()
            except TimeoutError:
                return False
            shots.append(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR))
            return shots[-1] is not None and shots[-1][:, :600].astype(np.float64).std() > 5.0

        _wait(drawn, 240.0, what="the browser never drew the render and the cameras")
        shot = shots[-1]
    finally:
        browser.close()
        viewer.stop()
    assert shot.shape[1] == 1100 and shot.shape[0] > 400
    cv2.imwrite(str(tmp_path / "viewer.png"), shot)


# -- the command --------------------------------------------------------------------------------------
def _cli(args, cwd, **kw):
    return subprocess.run([sys.executable, "-m", "e4dgs.cli", "viewer", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, **kw)


def test_paths_that_are_neither_dataset_nor_run_are_refused_in_one_line(trained, tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "model.pt").write_bytes(b"not a model")
    cases = {tmp_path / "nowhere": "no such folder", tmp_path / "empty": "neither a dataset scene",
             trained: "a folder of runs, not a run", tmp_path / "bad": "cannot read it as a model file"}
    for path, words in cases.items():
        r = _cli([path, "--port", "0"], cwd=tmp_path)
        assert r.returncode == 1 and words in r.stderr and str(path) in r.stderr, (path, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    run_json = trained / "e4dgs-4567" / "run.json"
    assert json.loads(run_json.read_text())["scene_dir"]


def _serve(paths: list[str], cwd: Path, err_file: Path, env: dict | None = None):
    """`e4dgs viewer PATHS --port 0` started, its stderr into `err_file` (readable while it runs, for
    a failure's message); (process, the URL it printed, or None)."""
    import threading

    proc = subprocess.Popen([sys.executable, "-m", "e4dgs.cli", "viewer", *paths, "--port", "0"],
                            stdout=subprocess.PIPE, stderr=err_file.open("w"), text=True, cwd=cwd, env=env)
    proc.lines = []                          # its stdout, read on as it runs (a failure's message shows it)
    url = None
    for line in proc.stdout:
        proc.lines.append(line)
        if "open http" in line:
            url = line.split("open ")[1].split()[0]
            break
    proc.reader = threading.Thread(target=lambda: proc.lines.extend(proc.stdout), daemon=True)
    proc.reader.start()
    return proc, url


def _stopped(proc, timeout_s: float = 30.0) -> str:
    """Wait for the viewer process to exit; its whole stdout."""
    proc.wait(timeout=timeout_s)
    proc.reader.join(timeout=timeout_s)
    return "".join(proc.lines)


def _descendants(pid: int) -> set[int]:
    out = subprocess.run(["ps", "-e", "-o", "pid=,ppid="], capture_output=True, text=True).stdout.split()
    children = {}
    for p, pp in zip(out[::2], out[1::2]):
        children.setdefault(int(pp), []).append(int(p))
    found, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            found.add(c)
            todo.append(c)
    return found


def test_the_command_serves_then_stops_on_ctrl_c_leaving_no_process_and_no_file(motion_scene, tmp_path):
    _need_chromium()
    from viewer.headless import HeadlessChromium

    work = tmp_path / "cwd"
    work.mkdir()
    home = tmp_path / "home"
    home.mkdir()
    env = {**os.environ, "HOME": str(home), "TMPDIR": str(tmp_path / "tmp")}
    (tmp_path / "tmp").mkdir()
    before = {p for p in motion_scene.rglob("*")}
    err_file = tmp_path / "viewer-stderr.txt"
    proc, url = _serve([str(motion_scene)], work, err_file, env=env)
    try:
        assert url and url.startswith("http://localhost:")
        browser = HeadlessChromium(900, 600)
        try:
            browser.open(url)
            t0 = time.monotonic()
            _wait(lambda: browser.evaluate("document.body.innerText.includes('events')"), 90.0,
                  lambda: f"the page never showed the scene's sources; its text: "
                          f"{browser.evaluate('document.body.innerText')[:300]!r}; the viewer's stderr: "
                          f"{err_file.read_text()[-1500:]!r}; its stdout: {''.join(proc.lines)[-1500:]!r}")
            print(f"page ready after {time.monotonic() - t0:.1f} s")
            assert "sharp, cam0" in browser.evaluate("document.body.innerText")
        finally:
            browser.close()
        helpers = _descendants(proc.pid)
        proc.send_signal(signal.SIGINT)
        out = _stopped(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
    err = err_file.read_text()
    assert proc.returncode == 0, err[-2000:]
    assert "viewer: stopped" in out and "Traceback" not in err
    _wait(lambda: not [p for p in helpers if Path(f"/proc/{p}").exists()], 30.0,
          f"helper processes still alive: {[p for p in helpers if Path(f'/proc/{p}').exists()]}")
    assert list(work.iterdir()) == [] and list((tmp_path / "tmp").iterdir()) == []
    assert {p for p in motion_scene.rglob("*")} == before


def test_a_browsers_aborted_handshake_prints_nothing_but_other_errors_still_do(caplog):
    """A fresh-clone CI failed on websockets' 'opening handshake failed' traceback in the viewer's stderr
    (Chromium's speculative connection, closed before its request); a user saw it too."""
    import logging

    from viewer.app import quiet_aborted_handshakes

    quiet_aborted_handshakes()
    quiet_aborted_handshakes()                        # once per process, however often a viewer starts
    log = logging.getLogger("websockets.server")
    assert sum(type(f).__name__ == "_AbortedHandshakes" for f in log.filters) == 1
    with caplog.at_level(logging.ERROR, logger="websockets.server"):
        try:
            raise EOFError("connection closed while reading HTTP request line")
        except EOFError:
            logging.LoggerAdapter(log, {}).error("opening handshake failed", exc_info=True)
        log.error("something else went wrong")
    assert [r.getMessage() for r in caplog.records] == ["something else went wrong"]


def _epoch_file(tmp_path) -> tuple[Path, np.ndarray]:
    from eventio.events import EventStream, make_events
    from eventio.h5io import write_events

    rng = np.random.default_rng(3)
    n = 4000
    t = 1_700_000_000_123_456 + np.sort(rng.integers(0, 500_000, n))
    s = EventStream(make_events(t, rng.integers(0, 64, n), rng.integers(0, 48, n), rng.choice([-1, 1], n)), 64, 48)
    return write_events(tmp_path / "rec.h5", s), t


def test_an_epoch_stamped_event_file_is_shown_from_its_first_event(tmp_path):
    """A recording at Unix-epoch times in the viewer: the time line starts at its first event, and the
    picture of a window holds exactly the events whose absolute times lie in it."""
    from viewer.event_stream import EventStreamViewer

    path, t = _epoch_file(tmp_path)
    v = EventStreamViewer(path, port=0)
    try:
        assert (v.start_us, v.end_us) == (int(t[0]), int(t[-1]) + 1) and "1700000000" in v.label
        title, img = v.picture(100_000, 20_000)
        t1 = int(t[0]) + 100_000
        expected = int(np.sum((t >= t1 - 20_000) & (t < t1)))
        assert title.startswith(f"{expected:,} events in [{t1 - 20_000}, {t1}) us") and img.shape == (48 + 18, 64, 3)
        assert v.picture(-5, 1000)[0].startswith("0 events") and v.picture(10 ** 12, 10 ** 12)[0].startswith("4,000 events")
    finally:
        v.stop()


def test_the_command_serves_an_epoch_stamped_recording_in_a_browser(tmp_path):
    _need_chromium()
    from viewer.headless import HeadlessChromium

    path, t = _epoch_file(tmp_path)
    proc, url = _serve([str(path)], tmp_path, tmp_path / "viewer-stderr.txt")
    try:
        assert url
        browser = HeadlessChromium(900, 600)
        try:
            browser.open(url)
            _wait(lambda: browser.evaluate("document.body.innerText.includes('events in [')"))
            text = browser.evaluate("document.body.innerText")
            assert f"{int(t[0])} us" in text and "4,000 events" in text
        finally:
            browser.close()
        proc.send_signal(signal.SIGINT)
        out = _stopped(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
    err = (tmp_path / "viewer-stderr.txt").read_text()
    assert proc.returncode == 0 and "viewer: stopped" in out and "Traceback" not in err, err[-2000:]
