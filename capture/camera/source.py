"""Cameras and video files through OpenCV's VideoCapture, turned into channels by a tracker.

A device index is a live camera: frames are stamped when grabbed, and a camera that stops
delivering is reopened. A video file stands in for a camera: by default it plays at its own
frame rate (realtime=True), from the moment its first frame is asked for (`read`), not when it
is opened, so a session's build or a countdown does not eat its beginning; with realtime=False
it is read as fast as the tracker goes, without dropping a frame (tests, offline processing).
At the end a file ends the source (or loops).
"""
from __future__ import annotations

import logging
import os
import threading
from pathlib import Path

import numpy as np

from ..clock import MonotonicClock
from ..source import EndOfStream, ThreadedSource
from .trackers import Tracker, _cv2, make_tracker

log = logging.getLogger(__name__)


class CameraSource(ThreadedSource):
    """Frames of a camera or video file, through a tracker.

    Parameters
    ----------
    device : camera index (int) or video file path.
    tracker : a Tracker or a tracker name ("aruco", "color", "face", "hand").
    tracker_options : keyword options for a tracker given by name.
    realtime : for files, pace frames at the file's rate (default True); ignored for cameras.
    loop : for files, start again at the end instead of ending.
    width, height, fps : requested camera mode (cameras only; the camera may pick another).
    """

    kind = "camera"

    def __init__(self, device: int | str | os.PathLike, tracker: Tracker | str = "color", *,
                 tracker_options: dict | None = None, realtime: bool = True, loop: bool = False,
                 width: int | None = None, height: int | None = None, fps: float | None = None,
                 clock: MonotonicClock | None = None, spec: str = "", wait: bool = True,
                 **options):
        self.tracker = make_tracker(tracker, **(tracker_options or {}))
        self.is_file = not isinstance(device, int)
        if self.is_file:
            device = str(device)
            if not Path(device).is_file():
                raise FileNotFoundError(f"video file not found: {device}")
        self.device = device
        self.realtime = bool(realtime)
        self.loop = bool(loop)
        self.requested = (width, height, fps)
        options.setdefault("backpressure", self.is_file and not self.realtime)
        if self.is_file:
            options.setdefault("reconnect", False)
        super().__init__(self.tracker.channels, 0.0, clock=clock,
                         spec=spec or f"camera:{device}:{self.tracker.name}", **options)
        self._capture = None
        self._image: np.ndarray | None = None
        self.frame_size: tuple[int, int] | None = None
        self._index = 0
        self._started_at = 0.0
        self._asked = threading.Event()      # a file in real time plays once a frame is asked for
        self._waiting = False
        _cv2()
        self._start(wait=wait)

    def describe(self) -> dict:
        info = super().describe()
        info.update(device=self.device, frame_size=self.frame_size, realtime=self.realtime,
                    **self.tracker.describe())
        return info

    def _open_device(self) -> None:
        cv2 = _cv2()
        capture = cv2.VideoCapture(self.device)
        if not capture.isOpened():
            capture.release()
            what = "video file" if self.is_file else "camera"
            raise OSError(f"OpenCV cannot open {what} {self.device!r}")
        if not self.is_file:
            width, height, fps = self.requested
            if width:
                capture.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            if height:
                capture.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
            if fps:
                capture.set(cv2.CAP_PROP_FPS, fps)
        rate = capture.get(cv2.CAP_PROP_FPS)
        self.rate = float(rate) if rate and rate > 0 else 30.0
        self.frame_size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
                           int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if not self.stall_timeout or self.stall_timeout < 5.0 / self.rate:
            self.stall_timeout = 5.0 / self.rate
        self._capture = capture
        self._index = 0
        self._started_at = self.clock.now()
        self._waiting = self.is_file and self.realtime

    def _pump(self, timeout: float) -> None:
        cv2 = _cv2()
        capture = self._capture
        if self._waiting:
            if not self._asked.wait(timeout):
                return
            self._waiting = False
            self._started_at = self.clock.now()
        if self.is_file and self.realtime:
            due = self._started_at + self._index / self.rate
            if not self.clock.sleep_until(due, self._stop):
                return
        if not capture.grab():
            if not self.is_file:
                raise OSError(f"camera {self.device} stopped delivering frames")
            if self.loop and self._index > 0:
                capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                self._started_at = self.clock.now()
                self._index = 0
                return
            raise EndOfStream
        t = self.clock.now()
        ok, image = capture.retrieve(self._image)
        if not ok or image is None:
            self._problem("a grabbed frame could not be decoded", malformed=True)
            self._index += 1
            return
        self._image = image
        self._index += 1
        self._emit(t, np.asarray(self.tracker.process(image), dtype=np.float64))

    def read(self, timeout: float | None = None):
        self._asked.set()
        return super().read(timeout)

    def _close_device(self) -> None:
        capture, self._capture = self._capture, None
        if capture is not None:
            capture.release()


def list_cameras(max_index: int = 8) -> list[dict]:
    """Cameras that open: [{"index", "width", "height", "fps"}]. On Linux only indices with a
    /dev/videoN node are tried (so nothing is probed on a machine without cameras)."""
    cv2 = _cv2()
    indices = range(max_index)
    if os.path.isdir("/dev"):
        indices = [i for i in indices if os.path.exists(f"/dev/video{i}")]
    found = []
    for index in indices:
        capture = cv2.VideoCapture(index)
        try:
            if capture.isOpened() and capture.grab():
                found.append({"index": index,
                              "width": int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
                              "height": int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                              "fps": float(capture.get(cv2.CAP_PROP_FPS))})
        finally:
            capture.release()
    return found
