"""One browser tab driven over Chromium's DevTools protocol (websocket-client): the live
page's tests (flight, review, map layers) share it."""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any


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
