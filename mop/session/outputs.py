"""Where a session's frames and states go: video, PNG sequence, OSC, the live preview.

Every output has `write(frame, state, *, repeat)` and `close()`. `frame` is the composed
(H, W, 4) uint8 RGBA picture (straight alpha) or None when nothing was rendered yet; `repeat`
is True when live mode dropped this frame's render and `frame` is the previous picture (a video
repeats it to keep its duration; a PNG sequence does not write it again).
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)


class VideoOutput:
    """MP4 / MKV / GIF / AVI / WebM through `mop.export.open_writer`.

    background : (r, g, b) drawn under transparent pixels (video has no alpha)."""

    def __init__(self, path: str | Path, *, fps: int, size: tuple[int, int],
                 background: tuple[int, int, int] = (0, 0, 0)):
        from mop.export import open_writer
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.writer = open_writer(self.path, fps=fps, size=tuple(size), background=background)
        self.frames = 0

    def write(self, frame, state, *, repeat: bool = False) -> None:
        if frame is None:
            return
        self.writer.write(frame)
        self.frames += 1

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


class PngOutput:
    """A folder of frame_000000.png ... with alpha (RGBA), through `mop.export.open_writer`.
    Dropped (repeated) frames are not written again."""

    def __init__(self, folder: str | Path, *, fps: int, size: tuple[int, int]):
        from mop.export import open_writer
        self.folder = Path(folder)
        self.writer = open_writer(self.folder, fps=fps, size=tuple(size), background=None)
        self.frames = 0

    def write(self, frame, state, *, repeat: bool = False) -> None:
        if frame is None or repeat:
            return
        self.writer.write(frame)
        self.frames += 1

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


class OscOutput:
    """Each frame, one OSC bundle (one UDP datagram, so nothing is reordered or half-sent) with:

    /mop/frame                       i frame, f t [s]
    /mop/performer/NAME              s status, s action ("" = none), f progress, f variance,
                                     f log-likelihood
    /mop/character/NAME/action       s action ("" = rest), s performer — one per track
    /mop/character/NAME/progress     f progress in [0, 1], f blend weight — one per track
    /mop/character/NAME/target/T     f... the control target T (1, 2 or 3 floats)
    """

    def __init__(self, host: str, port: int):
        try:
            from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
            from pythonosc.osc_message_builder import OscMessageBuilder
            from pythonosc.udp_client import UDPClient
        except ImportError:
            raise ImportError("OSC out needs python-osc: pip install 'mop[capture]'") from None
        self._bundle = OscBundleBuilder
        self._message = OscMessageBuilder
        self._immediately = IMMEDIATELY
        self.client = UDPClient(host, int(port))
        self.address = (host, int(port))
        self.sent = 0
        self.failed = 0

    def _add(self, bundle, address: str, *args) -> None:
        message = self._message(address=address)
        for arg in args:
            message.add_arg(arg)
        bundle.add_content(message.build())

    def build(self, state: dict):
        """The OSC bundle (pythonosc OscBundle) for one frame's state."""
        bundle = self._bundle(self._immediately)
        self._add(bundle, "/mop/frame", int(state["frame"]), float(state["t"]))
        for name, performer in state["performers"].items():
            self._add(bundle, f"/mop/performer/{name}", performer["status"],
                      performer["action"] or "", float(performer["progress"]),
                      float(performer["variance"]), float(performer["log_likelihood"]))
        for name, character in state["characters"].items():
            for track in character["tracks"]:
                self._add(bundle, f"/mop/character/{name}/action", track["action"] or "",
                          track["performer"])
                self._add(bundle, f"/mop/character/{name}/progress", float(track["progress"]),
                          float(track["blend"]))
            for target, value in character["targets"].items():
                self._add(bundle, f"/mop/character/{name}/target/{target}",
                          *(float(v) for v in value))
        return bundle.build()

    def write(self, frame, state, *, repeat: bool = False) -> None:
        try:
            self.client.send(self.build(state))
            self.sent += 1
        except OSError as error:  # nobody listening is not fatal to a show; count it
            self.failed += 1
            if self.failed == 1:
                log.warning("OSC out to %s:%d failed: %s", *self.address, error)

    def close(self) -> None:
        sock = getattr(self.client, "_sock", None)  # UDPClient has no public close()
        if sock is not None:
            sock.close()
