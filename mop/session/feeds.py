"""Feeds: what the session loop asks of a performer's input each frame.

A feed answers `poll(t)` with the performer's newest values without blocking, and keeps a status:
"ok", "silent" (no frame for `stale_after` seconds), "failed" (the source raised; it is reopened
every `retry` seconds) or "ended" (a replay ran out). The loop puts a performer's characters to
rest whenever the status is not "ok".

- `SourceFeed` wraps any `capture` source (glove, camera, OSC peer, a paced replay): live input.
- `TakeFeed` samples a recorded take at the session's own clock: replay mode runs faster than
  real time and gives the same values, hence the same frames, every time.
"""
from __future__ import annotations

import logging
import math
import time
from typing import Callable

import numpy as np

log = logging.getLogger(__name__)

OK, SILENT, FAILED, ENDED = "ok", "silent", "failed", "ended"


class TakeFeed:
    """A recorded action stream, sampled (linearly interpolated) at session time t.

    times : (K,) float [s], increasing; values : (K, D) float; channels : D names."""

    def __init__(self, times, values, channels, *, name: str = "take", loop: bool = False):
        times = np.asarray(times, dtype=np.float64)
        values = np.asarray(values, dtype=np.float64)
        if times.ndim != 1 or values.ndim != 2 or values.shape[0] != times.shape[0]:
            raise ValueError(f"take {name!r}: expected times (K,) and values (K, D), got "
                             f"{times.shape} and {values.shape}")
        if times.size < 2 or np.any(np.diff(times) <= 0):
            raise ValueError(f"take {name!r}: expected at least 2 samples at increasing times")
        self.name = name
        self.times = times - times[0]
        self.values = values
        self.channels = tuple(channels)
        self.loop = loop
        self.duration = float(self.times[-1])
        self.status = OK
        self.message = ""
        self.frames = 0
        self._out = np.empty(values.shape[1])

    def poll(self, t: float) -> np.ndarray | None:
        """Values (D,) at session time t [s], or None once the take has ended."""
        if self.loop:
            t = math.fmod(t, self.duration)
        elif t > self.duration:
            self.status = ENDED
            return None
        index = int(np.searchsorted(self.times, t, side="right")) - 1
        index = min(max(index, 0), self.times.size - 2)
        t0, t1 = self.times[index], self.times[index + 1]
        weight = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
        np.multiply(self.values[index], 1.0 - weight, out=self._out)
        self._out += weight * self.values[index + 1]
        self.frames += 1
        return self._out

    def close(self) -> None:
        pass


class SourceFeed:
    """A live `capture` source: each poll drains what arrived and keeps the newest frame.

    `opener()` returns a fresh source (it is called again to rejoin after a failure);
    `clock()` is the monotonic clock in seconds (injectable for tests)."""

    def __init__(self, opener: Callable[[], object], *, name: str, stale_after: float = 0.5,
                 retry: float = 1.0, clock: Callable[[], float] = time.monotonic):
        self.name = name
        self.opener = opener
        self.stale_after = stale_after
        self.retry = retry
        self.clock = clock
        self.source = None
        self.channels: tuple[str, ...] = ()
        self.status = FAILED
        self.message = "not opened"
        self.frames = 0
        self.last_arrival = -math.inf
        self.next_retry = -math.inf
        self.values: np.ndarray | None = None
        self._open()

    def _open(self) -> None:
        try:
            self.source = self.opener()
            self.channels = tuple(self.source.channels)
            self.status = SILENT
            self.message = "waiting for the first frame"
            self.last_arrival = self.clock()
        except Exception as error:  # a device may be unplugged at start: keep retrying
            self._fail(error)

    def _fail(self, error: BaseException) -> None:
        self.status = FAILED
        self.message = f"{type(error).__name__}: {error}"
        self.next_retry = self.clock() + self.retry
        if self.source is not None:
            try:
                self.source.close()
            except Exception:
                log.debug("closing failed source %s", self.name, exc_info=True)
        self.source = None

    def poll(self, t: float) -> np.ndarray | None:
        """Values (D,) of the newest frame, or None while there is none to use."""
        now = self.clock()
        if self.source is None:
            if now < self.next_retry:
                return None
            self._open()
            if self.source is None:
                return None
        newest = None
        try:
            while True:
                frame = self.source.read(timeout=0)
                if frame is None:
                    break
                newest = frame
        except Exception as error:  # the source broke: close it, reopen it later
            self._fail(error)
            return None
        if newest is not None:
            self.frames += 1
            self.last_arrival = now
            self.values = np.asarray(newest.values, dtype=np.float64)
            self.status = OK
            self.message = ""
            return self.values
        reported = getattr(self.source, "status", "ok")
        reported = getattr(reported, "value", reported)
        if reported == "disconnected":
            # a capture source reconnects by itself: keep it and keep asking
            self.status = FAILED
            self.message = "the device is disconnected"
            return None
        if now - self.last_arrival > self.stale_after:
            if self.status != SILENT:
                self.status = SILENT
                self.message = f"no input for {self.stale_after:g} s"
            return None
        return self.values if self.status == OK else None

    def close(self) -> None:
        if self.source is not None:
            try:
                self.source.close()
            finally:
                self.source = None
