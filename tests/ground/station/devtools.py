"""One browser tab driven over Chromium's DevTools protocol (websocket-client): the live
page's tests (flight, review, map layers) share it."""

from __future__ import annotations

import base64
import fcntl
import json
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

CHROMIUM = Path("/usr/bin/chromium")
START_TIMEOUT_S = 180.0
"""How long a Chromium may take to open its DevTools endpoint: a hang guard (about 1-2 s on
an idle machine, tens of seconds with the suite's 3 workers on 2 loaded cores)."""


def start_chromium(profile: Path, url: str = "about:blank") -> tuple[subprocess.Popen[bytes], int]:
    """Headless Chromium (1280 x 800) on ``profile`` showing ``url``; returns the process
    and its DevTools port once the endpoint answers.

    The port is Chromium's own pick (``--remote-debugging-port=0``, read back from the
    profile's ``DevToolsActivePort``): a port chosen beforehand can be taken by then. The
    test processes start one Chromium at a time (a lock file in the temp folder): several
    starting at once on a loaded machine take longer than all of them one after another.
    """
    profile.mkdir(parents=True, exist_ok=True)
    active = profile / "DevToolsActivePort"
    active.unlink(missing_ok=True)
    lock = Path(tempfile.gettempdir()) / "holescan-tests-chromium-start.lock"
    with open(lock, "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        proc = subprocess.Popen(
            [
                str(CHROMIUM),
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--no-first-run",
                f"--user-data-dir={profile}",
                "--remote-debugging-port=0",
                "--window-size=1280,800",
                url,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            port = _answering(active)
            if port is not None:
                return proc, port
            if proc.poll() is not None:
                raise AssertionError(f"Chromium exited with {proc.returncode} before its DevTools")
            if time.monotonic() > deadline:
                proc.kill()
                proc.wait()
                raise AssertionError(
                    f"timed out after {START_TIMEOUT_S} s waiting for Chromium's DevTools endpoint"
                )
            time.sleep(0.1)


def _answering(active: Path) -> int | None:
    """The DevTools port written in ``active`` if it answers HTTP, else None."""
    try:
        port = int(active.read_text().split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/version", timeout=5) as r:
            json.loads(r.read())
    except (OSError, ValueError, IndexError):  # not written yet, half written, not up
        return None
    return port


class Tab:
    """One tab over the DevTools protocol; ``ws_url`` its ``webSocketDebuggerUrl``."""

    def __init__(self, ws_url: str) -> None:
        import websocket

        self.ws = websocket.create_connection(ws_url, timeout=20)
        self._id = 0

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        self._id += 1
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise AssertionError(msg["error"])
                return dict(msg["result"])

    def js(self, expr: str) -> Any:
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True, awaitPromise=True)
        return r["result"].get("value")

    def key(self, key: str) -> None:
        """A real key press (keyDown with its text, keyUp), as the keyboard sends it."""
        code = {"ArrowDown": 40, "ArrowUp": 38}[key] if len(key) > 1 else ord(key.upper())
        text = {"text": key} if len(key) == 1 else {}
        for kind in ("keyDown", "keyUp"):
            self.call(
                "Input.dispatchKeyEvent",
                type=kind,
                key=key,
                windowsVirtualKeyCode=code,
                **(text if kind == "keyDown" else {}),
            )

    def screenshot(self, path: Path) -> None:
        data = self.call("Page.captureScreenshot", format="png")["data"]
        path.write_bytes(base64.b64decode(data))

    def close(self) -> None:
        self.ws.close()
