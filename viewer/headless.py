"""A real headless Chromium (the system's `chromium`) driven over the DevTools protocol: open a page,
wait, take a screenshot (the viewer's tests and its frame-rate benchmark). Standard library and
`websockets` (a viser dependency) only."""
from __future__ import annotations

import base64
import itertools
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path


def chromium_path() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


class HeadlessChromium:
    def __init__(self, width: int = 1280, height: int = 800, timeout_s: float = 60.0):
        from websockets.sync.client import connect

        self.profile = Path(tempfile.mkdtemp(prefix="e4dgs-chromium-"))
        self.proc = subprocess.Popen(
            [chromium_path(), "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
             f"--window-size={width},{height}", f"--user-data-dir={self.profile}", "--remote-debugging-port=0",
             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        port_file = self.profile / "DevToolsActivePort"
        deadline = time.monotonic() + timeout_s
        while not (port_file.exists() and port_file.read_text().strip()):
            if time.monotonic() > deadline or self.proc.poll() is not None:
                self.close()
                raise RuntimeError("chromium did not start")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=10).read())
        page = next(t for t in targets if t.get("type") == "page")
        self.ws = connect(page["webSocketDebuggerUrl"], max_size=None, open_timeout=timeout_s)
        self._ids = itertools.count(1)
        # A headless page never has the focus, and viser's client retries a failed connection only while
        # its page has it: on a busy machine one failed first attempt left the page unconnected for good.
        self.call("Emulation.setFocusEmulationEnabled", enabled=True)

    def call(self, method: str, timeout_s: float = 60.0, **params):
        i = next(self._ids)
        self.ws.send(json.dumps({"id": i, "method": method, "params": params}))
        deadline = time.monotonic() + timeout_s
        while True:
            msg = json.loads(self.ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            if msg.get("id") == i:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def open(self, url: str) -> None:
        self.call("Page.navigate", url=url)

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def evaluate(self, expression: str):
        return self.call("Runtime.evaluate", expression=expression, returnByValue=True).get("result", {}).get("value")

    def close(self) -> None:
        try:
            if getattr(self, "ws", None) is not None:
                self.ws.close()
        finally:
            if self.proc.poll() is None:
                os.killpg(self.proc.pid, signal.SIGTERM)
                try:
                    self.proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                    self.proc.wait()
            # Chromium keeps its singleton socket in a folder of its own under TMPDIR
            # (org.chromium.Chromium.*), linked from the profile, and leaves it behind when it exits.
            socket = self.profile / "SingletonSocket"
            if socket.is_symlink():
                folder = Path(os.readlink(socket)).parent
                if folder.name.startswith("org.chromium."):
                    shutil.rmtree(folder, ignore_errors=True)
            shutil.rmtree(self.profile, ignore_errors=True)
