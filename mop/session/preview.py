"""The live preview: a small local web server showing the rendered stream, every performer's
follower state and the session's timing.

    GET /             the page (mop/preview/index.html, preview.js, preview.css)
    GET /state.json   performers (status, action, progress, variance, log-likelihood, posterior),
                      characters (tracks, targets), timing (per-stage ms), frame counters
    GET /frame.jpg    the newest rendered frame (JPEG; transparency shown over dark grey)
    GET /stream.mjpg  the rendered stream as MJPEG (for VLC, OBS, a browser <img>)

It binds 127.0.0.1 by default: the page is for the people in the room, not the network. The
server runs in daemon threads; the session loop only hands it a copy of a frame now and then
(at most `max_rate` per second), and encoding happens in the server's threads, on request.
"""
from __future__ import annotations

import json
import logging
import math
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

ASSETS = Path(__file__).resolve().parent.parent / "preview"
_CONTENT_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                  ".css": "text/css; charset=utf-8"}


def _jsonable(value):
    """NaN / inf are not JSON: send them as null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    return value


class PreviewOutput:
    """Serve the preview page on http://host:port/ (port 0 = any free port; see `.url`)."""

    def __init__(self, *, host: str = "127.0.0.1", port: int = 0, max_rate: float = 12.0,
                 jpeg_quality: int = 80):
        self.max_rate = max_rate
        self.jpeg_quality = jpeg_quality
        self.session = None         # set by the builder: timing comes from session.report()
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._frame: np.ndarray | None = None
        self._frame_number = -1
        self._jpeg: tuple[int, bytes] | None = None
        self._state: dict = {"frame": 0, "performers": {}, "characters": {}}
        self._last_copy = -math.inf
        self.requests: dict[str, int] = {}
        self.closed = False
        handler = type("PreviewHandler", (_Handler,), {"preview": self})
        self.server = ThreadingHTTPServer((host, int(port)), handler)
        self.server.daemon_threads = True
        self.host, self.port = self.server.server_address[:2]
        self.thread = threading.Thread(target=self.server.serve_forever,
                                       name="mop-preview", daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # called by the session loop ------------------------------------------------------------
    def write(self, frame, state, *, repeat: bool = False) -> None:
        now = time.monotonic()
        copy_frame = frame is not None and not repeat and now - self._last_copy >= 1 / self.max_rate
        picture = frame.copy() if copy_frame else None
        with self._lock:
            self._state = state
            if picture is not None:
                self._frame = picture
                self._frame_number = state["frame"]
                self._last_copy = now
                self._changed.notify_all()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        with self._lock:
            self._changed.notify_all()
        self.server.shutdown()
        self.server.server_close()

    # called by the server's threads ------------------------------------------------------------
    def state_json(self) -> bytes:
        with self._lock:
            state = dict(self._state)
        session = self.session
        if session is not None:
            report = session.report()
            state["timing"] = report.stages
            state["events"] = report.events[-20:]
            state["wall_seconds"] = report.wall_seconds
        state["closed"] = self.closed
        return json.dumps(_jsonable(state)).encode()

    def jpeg(self) -> tuple[int, bytes] | None:
        """(frame number, JPEG bytes) of the newest frame, encoded once per frame."""
        import cv2
        with self._lock:
            frame, number, cached = self._frame, self._frame_number, self._jpeg
        if frame is None:
            return None
        if cached is not None and cached[0] == number:
            return cached
        alpha = frame[..., 3:4].astype(np.float32) * (1 / 255)
        rgb = frame[..., :3].astype(np.float32) * alpha + 40.0 * (1 - alpha)
        ok, data = cv2.imencode(".jpg", rgb[..., ::-1].astype(np.uint8),
                                [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        if not ok:
            raise RuntimeError("JPEG encoding of the preview frame failed")
        encoded = (number, data.tobytes())
        with self._lock:
            self._jpeg = encoded
        return encoded

    def wait_frame(self, after: int, timeout: float) -> bool:
        with self._changed:
            return self._changed.wait_for(
                lambda: self._frame_number > after or self.closed, timeout=timeout)


class _Handler(BaseHTTPRequestHandler):
    preview: PreviewOutput
    server_version = "mop-preview"

    def log_message(self, format, *args):  # the default writes every request to stderr
        log.debug("preview: " + format, *args)

    def _send(self, body: bytes, content_type: str, status=HTTPStatus.OK) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self):  # noqa: N802 (http.server's naming)
        path = self.path.split("?", 1)[0]
        counts = self.preview.requests
        counts[path] = counts.get(path, 0) + 1
        try:
            if path in ("/", "/index.html"):
                self._asset("index.html")
            elif path in ("/preview.js", "/preview.css"):
                self._asset(path[1:])
            elif path == "/state.json":
                self._send(self.preview.state_json(), "application/json")
            elif path == "/frame.jpg":
                encoded = self.preview.jpeg()
                if encoded is None:
                    self._send(b"no frame yet", "text/plain", HTTPStatus.SERVICE_UNAVAILABLE)
                else:
                    self._send(encoded[1], "image/jpeg")
            elif path == "/stream.mjpg":
                self._stream()
            else:
                self._send(b"not found", "text/plain", HTTPStatus.NOT_FOUND)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the viewer went away

    def _asset(self, name: str) -> None:
        path = ASSETS / name
        self._send(path.read_bytes(), _CONTENT_TYPES[path.suffix])

    def _stream(self) -> None:
        boundary = "mopframe"
        self.send_response(HTTPStatus.OK)
        self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={boundary}")
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        last = -1
        while not self.preview.closed:
            if not self.preview.wait_frame(last, timeout=1.0):
                continue
            encoded = self.preview.jpeg()
            if encoded is None:
                continue
            last, data = encoded
            self.wfile.write(f"--{boundary}\r\nContent-Type: image/jpeg\r\n"
                             f"Content-Length: {len(data)}\r\n\r\n".encode())
            self.wfile.write(data)
            self.wfile.write(b"\r\n")
