"""Cameras and video files through OpenCV's VideoCapture, turned into channels by a tracker.

A device index is a live camera: frames are stamped when grabbed, and a camera that stops
delivering is reopened. A video file stands in for a camera: by default it plays at its own
frame rate (realtime=True, each frame stamped with its scheduled time), from the moment its
first frame is asked for (`read`), not when it is opened, so a session's build or a countdown
does not eat its beginning; with realtime=False it is read as fast as the tracker goes, without
dropping a frame (tests, offline processing).
At the end a file ends the source (or loops).

Live (a camera, or a file in real time), two threads share the work: the reader grabs every
frame the camera delivers and keeps only the newest; the tracker thread tracks the newest frame
it has not seen yet. A tracker slower than the camera then skips frames (counted in
`timing()["skipped"]`) instead of falling behind, and a file's reader more than LATE_FRAMES
frames behind its schedule passes over the late ones, as a camera would drop them; a Frame is
never older than one grab plus one tracking step. Nothing of this runs in the caller's thread:
`read()` only takes finished Frames off a queue.
"""
from __future__ import annotations

import logging
import os
import threading
from collections import deque
from pathlib import Path

import numpy as np

from ..clock import MonotonicClock
from ..frame import Status
from ..source import EndOfStream, ThreadedSource
from .base import Tracker, _cv2
from .smoothing import OneEuroConfig, OneEuroFilter
from .trackers import make_tracker

log = logging.getLogger(__name__)

TIMING_WINDOW = 60   # frames over which frame rate, latency and tracking time are reported
LATE_FRAMES = 2      # a file read in real time this many frames late catches up by reading faster


class CameraSource(ThreadedSource):
    """Frames of a camera or video file, through a tracker.

    Parameters
    ----------
    device : camera index (int) or video file path.
    tracker : a Tracker or a tracker name ("face", "hands", "pose", "aruco", "color", "haar",
        "silhouette").
    tracker_options : keyword options for a tracker given by name.
    realtime : for files, pace frames at the file's rate (default True); ignored for cameras.
    loop : for files, start again at the end instead of ending.
    width, height, fps : requested camera mode (cameras only; the camera may pick another).
    smooth : One Euro smoothing of the channels (default off: takes keep raw values); True for
        the default filter, or set `smooth_cutoff` [Hz] (steadiness at rest) and `smooth_beta`
        (less lag in fast moves), which turn it on.
    """

    kind = "camera"

    def __init__(self, device: int | str | os.PathLike, tracker: Tracker | str = "color", *,
                 tracker_options: dict | None = None, realtime: bool = True, loop: bool = False,
                 width: int | None = None, height: int | None = None, fps: float | None = None,
                 smooth: bool = False, smooth_cutoff: float | None = None,
                 smooth_beta: float | None = None, clock: MonotonicClock | None = None,
                 spec: str = "", wait: bool = True, **options):
        self.is_file = not isinstance(device, int)
        if self.is_file:
            device = str(device)
            if not Path(device).is_file():
                raise FileNotFoundError(f"video file not found: {device}")
        _cv2()
        self.tracker = make_tracker(tracker, **(tracker_options or {}))
        self.device = device
        self.realtime = bool(realtime)
        self.loop = bool(loop)
        self.requested = (width, height, fps)
        # live: frames come at the camera's pace whether or not they are tracked
        self.live = not self.is_file or self.realtime
        self.smoothing = self._smoothing(smooth, smooth_cutoff, smooth_beta)
        self._filter = (None if self.smoothing is None
                        else OneEuroFilter(self.tracker.channel_scales(), self.smoothing))
        options.setdefault("backpressure", not self.live)
        if self.is_file:
            options.setdefault("reconnect", False)
        super().__init__(self.tracker.channels, 0.0, clock=clock,
                         spec=spec or f"camera:{device}:{self.tracker.name}", **options)
        self._capture = None
        self.frame_size: tuple[int, int] | None = None
        self._index = 0
        self._pictures = 0            # frames grabbed from a file, loops included
        self._started_at = 0.0
        self._asked = threading.Event()      # a file in real time plays once a frame is asked for
        self._held = False
        self._seen = True
        # three image buffers, reused: one being grabbed into, one waiting, one being tracked
        self._images: list[np.ndarray | None] = [None, None, None]
        self._grabbing = 0
        self._waiting: tuple[int, float, float] | None = None   # (buffer, grab, picture time)
        self._tracking: int | None = None
        self._handoff = threading.Condition()
        self._grabbed_times: deque[float] = deque(maxlen=TIMING_WINDOW)
        self._emitted_times: deque[float] = deque(maxlen=TIMING_WINDOW)
        self._latencies: deque[float] = deque(maxlen=TIMING_WINDOW)
        self._track_times: deque[float] = deque(maxlen=TIMING_WINDOW)
        self._skipped = 0
        self._tracker_thread: threading.Thread | None = None
        if self.live:
            self._tracker_thread = threading.Thread(target=self._track_loop, daemon=True,
                                                    name="mop-camera-tracker")
            self._tracker_thread.start()
        try:
            self._start(wait=wait)
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _smoothing(smooth, cutoff, beta) -> OneEuroConfig | None:
        if cutoff is None and beta is None and not smooth:
            return None
        defaults = OneEuroConfig()
        return OneEuroConfig(min_cutoff=defaults.min_cutoff if cutoff is None else cutoff,
                             beta=defaults.beta if beta is None else beta)

    # -- what the source reports -------------------------------------------------------------
    def describe(self) -> dict:
        info = super().describe()
        smoothing = None if self.smoothing is None else {
            "filter": "one-euro", "min_cutoff": self.smoothing.min_cutoff,
            "beta": self.smoothing.beta, "d_cutoff": self.smoothing.d_cutoff}
        info.update(device=self.device, frame_size=self.frame_size, realtime=self.realtime,
                    smoothing=smoothing, **self.tracker.describe())
        return info

    @property
    def status(self) -> Status:
        status = super().status
        if status is Status.OK and not self._seen:
            return Status.NOT_SEEN
        return status

    @property
    def frame_rate(self) -> float:
        """Frames per second delivered lately (tracked frames), 0 before two frames."""
        return _rate(self._emitted_times)

    @property
    def latency(self) -> float:
        """[s] median time from a frame's grab to its Frame being ready, over the last
        frames; NaN before the first."""
        latencies = list(self._latencies)
        return float(np.median(latencies)) if latencies else float("nan")

    def timing(self) -> dict:
        """{"fps": tracked frames per second, "camera_fps": grabbed frames per second,
        "latency_ms": median grab -> Frame, "track_ms": median tracking time per frame (None
        before the first frame), "skipped": frames the tracker had no time for} over the last
        frames."""
        tracked = list(self._track_times)
        latency = self.latency
        return {"fps": self.frame_rate, "camera_fps": _rate(self._grabbed_times),
                "latency_ms": None if latency != latency else latency * 1e3,
                "track_ms": float(np.median(tracked)) * 1e3 if tracked else None,
                "skipped": self._skipped}

    @property
    def ended(self) -> bool:
        if not super().ended:
            return False
        with self._handoff:
            return self._waiting is None and self._tracking is None

    # -- the reader thread -------------------------------------------------------------------
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
        count = capture.get(cv2.CAP_PROP_FRAME_COUNT) if self.is_file else 0
        self._frame_count = int(count) if count and count > 0 else None
        self._started_at = self.clock.now()
        self._held = self.is_file and self.realtime

    def _free_buffer(self) -> int:
        with self._handoff:
            busy = {self._tracking, None if self._waiting is None else self._waiting[0]}
        return next(k for k in range(3) if k not in busy)

    def _pump(self, timeout: float) -> None:
        cv2 = _cv2()
        capture = self._capture
        if self._held:
            if not self._asked.wait(timeout):
                return
            self._held = False
            self._started_at = self.clock.now()
        due = None
        if self.is_file and self.realtime:
            due = self._started_at + self._index / self.rate
            if not self.clock.sleep_until(due, self._stop):
                return
            due = self._catch_up(capture, due)
        if not capture.grab():
            if not self.is_file:
                raise OSError(f"camera {self.device} stopped delivering frames")
            if self.loop and self._index > 0:
                capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                self._started_at = self.clock.now()
                self._index = 0
                return
            raise EndOfStream
        # a file played in real time is stamped with each frame's scheduled time, as a replayed
        # take is (a late grab shows in the latency, not in the frame spacing); a camera's grab
        # with the time it came
        t = self.clock.now() if due is None else due
        # smoothing runs on the picture's own time: a file's frame times, a camera's grabs
        picture_t = self._pictures / self.rate if self.is_file else t
        self._pictures += 1
        slot = self._free_buffer() if self.live else 0
        ok, image = capture.retrieve(self._images[slot])
        self._index += 1
        if not ok or image is None:
            self._problem("a grabbed frame could not be decoded", malformed=True)
            return
        self._images[slot] = image
        self._grabbed_times.append(t)
        if not self.live:
            self._track(image, t, picture_t)
            return
        with self._handoff:
            if self._waiting is not None:
                self._skipped += 1          # the tracker had no time for the previous one
            self._waiting = (slot, t, picture_t)
            self._handoff.notify()

    def _catch_up(self, capture, due: float) -> float:
        """A file more than LATE_FRAMES frames behind its schedule passes over the frames whose
        time has gone (grabbed, not decoded into pictures nor tracked; counted as skipped), as a
        camera whose reader is late drops them; a frame or two late is read up without loss.
        Returns the due time of the frame read next."""
        behind = int((self.clock.now() - self._started_at) * self.rate) - self._index
        if self._frame_count is not None:          # the last frame is always read
            behind = min(behind, self._frame_count - 1 - self._index)
        if behind <= LATE_FRAMES:
            return due
        for _ in range(behind):
            if not capture.grab():
                break                      # the end: the next grab says so
            self._index += 1
            self._pictures += 1
            self._skipped += 1
        return self._started_at + self._index / self.rate

    def read(self, timeout: float | None = None):
        self._asked.set()
        return super().read(timeout)

    def _close_device(self) -> None:
        capture, self._capture = self._capture, None
        if capture is not None:
            capture.release()

    # -- tracking -----------------------------------------------------------------------------
    def _track(self, image: np.ndarray, t: float, picture_t: float) -> None:
        start = self.clock.now()
        values = np.asarray(self.tracker.process(image), dtype=np.float64)
        self._seen = bool(np.isfinite(values).any())
        if self._filter is not None:
            values = self._filter.filter(picture_t, values)
        self._emit(t, values)
        done = self.clock.now()
        self._track_times.append(done - start)
        self._latencies.append(done - t)
        self._emitted_times.append(done)

    def _track_loop(self) -> None:
        """The tracker thread (live sources): tracks the newest grabbed frame."""
        while not self._stop.is_set():
            with self._handoff:
                while self._waiting is None and not self._stop.is_set():
                    self._handoff.wait(0.1)
                if self._stop.is_set():
                    return
                slot, t, picture_t = self._waiting
                self._waiting = None
                self._tracking = slot
            try:
                self._track(self._images[slot], t, picture_t)
            except Exception as error:  # a tracker failure must not kill the source
                log.warning("%s: tracking failed: %s", self.spec, error)
                self._problem(f"tracking failed: {error}", malformed=True)
            finally:
                with self._handoff:
                    self._tracking = None

    def close(self) -> None:
        if self.closed:
            return
        super().close()
        with self._handoff:
            self._handoff.notify_all()
        thread = self._tracker_thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
            if thread.is_alive():
                log.warning("%s: tracker thread did not stop within 2 s", self.spec)
        try:
            self.tracker.close()
        except Exception:
            log.debug("closing tracker %s failed", self.tracker.name, exc_info=True)


def _rate(times) -> float:
    times = list(times)
    if len(times) < 2 or times[-1] <= times[0]:
        return 0.0
    return (len(times) - 1) / (times[-1] - times[0])


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
