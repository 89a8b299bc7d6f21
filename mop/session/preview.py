"""The live preview: a small local web server showing the rendered stream, every performer's
follower state and the session's timing.

    GET /             the page (mop/preview/index.html, preview.js, preview.css)
    GET /state.json   performers (status, action, progress, variance, log-likelihood, posterior),
                      characters (tracks, targets), timing (per-stage ms), frame counters,
                      whether the show keeps real time
    GET /frame.jpg    the newest rendered frame (JPEG; transparency shown over dark grey)
    GET /stream.mjpg  the rendered stream as MJPEG (for VLC, OBS, a browser <img>)

It binds 127.0.0.1 by default: the page is for the people in the room, not the network.
Viewers can never slow the show: the loop only hands over a reference to its state each frame
(`send`), and the render worker encodes a JPEG at most `max_rate` times a second (`JpegEncoder`,
its bytes come to `publish`); the server's threads only serve bytes made once, whatever the
number of viewers. The server
itself is bounded: at most `max_connections` connections at a time (more are closed at once),
`timeout` seconds for a silent or stuck client, and request counts only for its own pages.
"""
from __future__ import annotations

import json
import logging
import math
import socket
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
PAGES = ("/", "/index.html", "/preview.js", "/preview.css", "/state.json", "/frame.jpg",
         "/stream.mjpg")
MAX_CONNECTIONS = 32
TIMEOUT = 10.0


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


class _BoundedServer(ThreadingHTTPServer):
    """A threading HTTP server with at most `limit` connections being served at a time: one
    more is closed at once (counted in `refused`), so idle or hostile clients cannot pile up
    threads."""

    daemon_threads = True
    request_queue_size = 64

    def __init__(self, address, handler, *, limit: int):
        self.limit = limit
        self.active = 0
        self.refused = 0
        self._count_lock = threading.Lock()
        super().__init__(address, handler)

    def process_request(self, request, client_address):
        with self._count_lock:
            if self.active >= self.limit:
                self.refused += 1
                refuse = True
            else:
                self.active += 1
                refuse = False
        if refuse:
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            with self._count_lock:
                self.active -= 1
            raise

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._count_lock:
                self.active -= 1


class JpegEncoder:
    """A frame output that makes the preview's JPEG: at most `max_rate` pictures a second, each
    handed to `publish(frame number, JPEG bytes)` (`connect`). It runs where the pictures are
    made - the render process, usually - so viewers cost the session nothing."""

    def __init__(self, *, max_rate: float = 12.0, jpeg_quality: int = 80):
        self.max_rate = max_rate
        self.jpeg_quality = jpeg_quality
        self.publish = None
        self._last = -math.inf
        self._flatten = None                  # mop.export.OverColourBGR, once sized

    def connect(self, publish) -> None:
        self.publish = publish

    def write(self, frame, state, *, repeat: bool = False) -> None:
        now = time.monotonic()
        if frame is None or repeat or now - self._last < 1.0 / self.max_rate:
            return
        self._last = now
        self.publish(int(state["frame"]), self.encode(frame))

    def encode(self, frame: np.ndarray) -> bytes:
        """JPEG of an RGBA frame; transparent parts over dark grey."""
        import cv2

        from mop.export import OverColourBGR
        size = (frame.shape[1], frame.shape[0])
        if self._flatten is None or self._flatten.size != size:
            self._flatten = OverColourBGR((40, 40, 40), size)
        bgr = self._flatten(frame)
        ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        if not ok:
            raise RuntimeError("JPEG encoding of the preview frame failed")
        return data.tobytes()

    def close(self) -> None:
        pass


class PreviewOutput:
    """Serve the preview page on http://host:port/ (port 0 = any free port; see `.url`)."""

    def __init__(self, *, host: str = "127.0.0.1", port: int = 0, max_rate: float = 12.0,
                 jpeg_quality: int = 80, max_connections: int = MAX_CONNECTIONS,
                 timeout: float = TIMEOUT):
        self.max_rate = max_rate
        self.jpeg_quality = jpeg_quality
        self.session = None         # set by the builder: timing comes from session.report()
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._jpeg: tuple[int, bytes] | None = None
        self._state: dict = {"frame": 0, "performers": {}, "characters": {}}
        self._state_json: tuple[int, float, bytes] | None = None
        self._encoder: JpegEncoder | None = None
        self.requests: dict[str, int] = {}
        self.frames = 0
        self.closed = False
        handler = type("PreviewHandler", (_Handler,), {"preview": self, "timeout": timeout})
        self.server = _BoundedServer((host, int(port)), handler, limit=max_connections)
        self.host, self.port = self.server.server_address[:2]
        self.thread = threading.Thread(target=self.server.serve_forever,
                                       name="mop-preview", daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # called by the session loop, every frame -----------------------------------------------
    def send(self, state: dict) -> None:
        self._state = state          # one reference: the loop never waits here

    # the pictures: drawn and encoded by the render worker -----------------------------------
    def recipe(self):
        """The JPEG encoder, rebuilt in the render process; what it makes comes back to
        `publish`."""
        return (JpegEncoder, (), {"max_rate": self.max_rate,
                                  "jpeg_quality": self.jpeg_quality})

    def write(self, frame, state, *, repeat: bool = False) -> None:
        """Encode here (a render thread, when the pictures are not made in a process)."""
        if self._encoder is None:
            self._encoder = JpegEncoder(max_rate=self.max_rate, jpeg_quality=self.jpeg_quality)
            self._encoder.connect(self.publish)
        self._encoder.write(frame, state, repeat=repeat)

    def publish(self, number: int, data: bytes) -> None:
        """The newest JPEG (frame number, bytes): what /frame.jpg and /stream.mjpg serve."""
        self.frames += 1
        with self._lock:
            self._jpeg = (number, data)
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
    def count(self, path: str) -> None:
        """Requests per page of ours; everything else is one "other" count (bounded)."""
        key = path if path in PAGES else "other"
        with self._lock:
            self.requests[key] = self.requests.get(key, 0) + 1

    def state_json(self) -> bytes:
        """The newest state as JSON, made once per frame (and at most 20 times a second)."""
        state = self._state
        cached = self._state_json
        now = time.monotonic()
        if cached is not None and (cached[0] == state.get("frame") or now - cached[1] < 0.05) \
                and not self.closed:
            return cached[2]
        state = dict(state)
        session = self.session
        if session is not None:
            report = session.report()
            state["timing"] = report.stages
            state["events"] = report.events[-20:]
            state["wall_seconds"] = report.wall_seconds
            state["verdict"] = report.verdict()
            state.update(session.counters())
        state["closed"] = self.closed
        body = json.dumps(_jsonable(state)).encode()
        self._state_json = (state.get("frame"), now, body)
        return body

    def jpeg(self) -> tuple[int, bytes] | None:
        """(frame number, JPEG bytes) of the newest encoded frame."""
        return self._jpeg

    def wait_frame(self, after: int, timeout: float) -> bool:
        with self._changed:
            return self._changed.wait_for(
                lambda: (self._jpeg is not None and self._jpeg[0] > after) or self.closed,
                timeout=timeout)


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
        self.preview.count(path)
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
        except (BrokenPipeError, ConnectionResetError, socket.timeout):
            pass  # the viewer went away, or stopped reading

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
