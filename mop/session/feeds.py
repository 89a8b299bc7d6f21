"""Feeds: what the session loop asks of a performer's input each frame.

A feed answers `poll(t, due=...)` with the performer's values for one session frame, without
blocking, and keeps a status: "ok", "silent" (no input for `stale_after` seconds), "failed" (the
source raised; it is reopened every `retry` seconds) or "ended" (a take or a video file ran out).
The loop puts a performer's characters to rest whenever the status is not "ok".

Both feeds resample the input at the session's frame times with the same rule
(`sample_at`: linear between the two samples around a time, the nearer one where either is
missing), so a live performance and a replay of its take give the follower the same values:

- `TakeFeed` samples a recorded take at session time t (the take's first sample is frame 0):
  replay mode runs faster than real time and gives the same values, hence the same frames,
  every time.
- `SourceFeed` wraps any `capture` source (glove, camera, OSC peer). It keeps what arrived with
  its timestamps and gives each frame the input as it was `latency` seconds before the frame was
  due: once the first sample is there, the performer's own clock is locked to the session's
  (the first sample feeds a frame, and each later frame one frame period further into the
  input), so a follower that fell behind catches up on the input at its true times, never on
  whatever happened to arrive last.
"""
from __future__ import annotations

import logging
import math
import time
from typing import Callable

import numpy as np

log = logging.getLogger(__name__)

OK, SILENT, FAILED, ENDED = "ok", "silent", "failed", "ended"


def sample_at(times: np.ndarray, values: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
    """The stream (times (K,) float [s], non-decreasing; values (K, D) float, NaN = missing) at
    time t [s], into out (D,): linear between the samples around t; where either of them is
    missing, the nearer one (which may be missing too); outside the samples, the edge value.
    The same rule as `capture.resample.interpolate`, for one time and without allocating."""
    count = times.shape[0]
    if count == 1 or t <= times[0]:
        out[...] = values[0]
        return out
    if t >= times[count - 1]:
        out[...] = values[count - 1]
        return out
    right = int(np.searchsorted(times, t, side="right"))
    left = right - 1
    t0, t1 = times[left], times[right]
    weight = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
    v0, v1 = values[left], values[right]
    np.multiply(v0, 1.0 - weight, out=out)
    out += weight * v1
    if not np.isfinite(out).all():
        np.copyto(out, v0 if weight < 0.5 else v1, where=np.isnan(v0) | np.isnan(v1))
    return out


class TakeFeed:
    """A recorded action stream, sampled at session time t (`sample_at`).

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
        self.latency = 0.0
        self._out = np.empty(values.shape[1])

    def poll(self, t: float, *, due: float | None = None) -> np.ndarray | None:
        """Values (D,) at session time t [s], or None once the take has ended (`due`, the
        frame's wall-clock time, does not matter to a take)."""
        if self.loop:
            t = math.fmod(t, self.duration)
        elif t > self.duration:
            self.status = ENDED
            return None
        self.frames += 1
        return sample_at(self.times, self.values, t, self._out)

    def close(self) -> None:
        pass


class _History:
    """The samples a live feed still needs: times (K,) and values (K, D) in growing arrays, the
    oldest dropped as frames pass them (no allocation per sample once the arrays are big
    enough; at most `limit` samples are kept, the oldest dropped first)."""

    def __init__(self, width: int, *, limit: int = 1 << 16):
        self.limit = limit
        self.times = np.empty(256)
        self.values = np.empty((256, width))
        self.start = self.end = 0
        self.overflow = 0

    @property
    def width(self) -> int:
        return self.values.shape[1]

    def __len__(self) -> int:
        return self.end - self.start

    def clear(self) -> None:
        self.start = self.end = 0

    def append(self, t: float, values: np.ndarray) -> None:
        if self.end == self.times.shape[0]:
            kept = self.end - self.start
            if kept >= self.limit:           # nobody reads: keep the newest
                self.start += kept - self.limit + 1
                self.overflow += kept - self.limit + 1
                kept = self.end - self.start
            if kept * 2 > self.times.shape[0]:
                size = min(self.times.shape[0] * 2, self.limit * 2)
                times, block = np.empty(size), np.empty((size, self.width))
            else:
                times, block = self.times, self.values
            times[:kept] = self.times[self.start:self.end]
            block[:kept] = self.values[self.start:self.end]
            self.times, self.values = times, block
            self.start, self.end = 0, kept
        self.times[self.end] = t
        self.values[self.end] = values
        self.end += 1

    def first_time(self) -> float:
        return float(self.times[self.start])

    def last_time(self) -> float:
        return float(self.times[self.end - 1])

    def anchor(self, latest: float, period: float) -> float | None:
        """Where a feed locks for a frame that may use input up to `latest` [s]: the first
        sample of the last `period` before it (the very first sample when the input has just
        begun); else the newest one before it (sparse input); None when there is none yet.
        Older samples are forgotten."""
        times = self.times[self.start:self.end]
        last = int(np.searchsorted(times, latest, side="right")) - 1
        if last < 0:
            return None
        first = int(np.searchsorted(times, latest - period, side="left"))
        index = min(first, last)
        self.start += index
        return float(times[index])

    def sample(self, t: float, out: np.ndarray) -> np.ndarray:
        """Values at t into out, and forget what no later (t' >= t) sample needs."""
        times = self.times[self.start:self.end]
        sample_at(times, self.values[self.start:self.end], t, out)
        before = int(np.searchsorted(times, t, side="right")) - 1
        if before > 0:
            self.start += before
        return out


def _status(source) -> str:
    """A capture source's status as text ("ok", "stalled", "disconnected"); "ok" when it has
    none."""
    reported = getattr(source, "status", "ok")
    return getattr(reported, "value", reported)


class SourceFeed:
    """A live `capture` source, resampled at the session's frame times.

    Each poll drains what arrived and keeps it with its capture timestamps (the shared
    monotonic clock). Once a sample is `latency` seconds older than a frame's due time, the feed
    locks: that frame gets the first sample of the input (or, when the input was flowing before
    the show, the first of the last frame `period`), and frame k after it the input k frame
    periods later. The latency is then fixed (between `latency` and `latency` + `period`) until
    the source falls silent or fails; a frame whose next sample has not arrived yet gets the
    newest one (counted in `late`).

    `opener()` returns a fresh source (it is called again to rejoin after a failure);
    `clock()` is the capture clock in seconds (injectable for tests)."""

    def __init__(self, opener: Callable[[], object], *, name: str, stale_after: float = 0.5,
                 retry: float = 1.0, latency: float = 0.05, period: float = 0.04,
                 clock: Callable[[], float] = time.monotonic):
        self.name = name
        self.opener = opener
        self.stale_after = stale_after
        self.retry = retry
        self.min_latency = float(latency)
        self.period = float(period)
        self.clock = clock
        self.source = None
        self.channels: tuple[str, ...] = ()
        self.status = FAILED
        self.message = "not opened"
        self.frames = 0              # samples received
        self.late = 0                # frames that had to use the newest sample (next not there)
        self.rebased = 0             # samples whose timestamp was not on the capture clock
        self.latency: float | None = None   # [s] fixed once locked; None while unlocked
        self.last_arrival = -math.inf   # [s] capture clock: when a frame last came in
        self.next_retry = -math.inf
        self._history: _History | None = None
        self._out = np.empty(0)
        self._opened_at: float | None = None
        self._open()

    def _open(self) -> None:
        try:
            self.source = self.opener()
            self.channels = tuple(self.source.channels)
            self.status = SILENT
            self.message = "waiting for the first frame"
            self._opened_at = None      # silence counts from the first frame that asks
            self._unlock()
        except Exception as error:  # a device may be unplugged at start: keep retrying
            self._fail(error)

    def _fail(self, error: BaseException) -> None:
        self.status = FAILED
        self.message = f"{type(error).__name__}: {error}"
        self.next_retry = self.clock() + self.retry
        self._unlock()
        if self.source is not None:
            try:
                self.source.close()
            except Exception:
                log.debug("closing failed source %s", self.name, exc_info=True)
        self.source = None

    def _unlock(self) -> None:
        self.latency = None
        if self._history is not None:
            self._history.clear()

    def _drain(self, now: float) -> None:
        """Move every frame that arrived into the history (timestamps kept)."""
        source = self.source
        while True:
            frame = source.read(timeout=0)
            if frame is None:
                return
            values = frame.values
            history = self._history
            if history is None or history.width != values.shape[0]:
                # the first frame, or a source that learnt its channel count (OSC)
                history = self._history = _History(values.shape[0])
                self._out = np.empty(values.shape[0])
                self.latency = None
                self.channels = tuple(source.channels)
            t = float(frame.t)
            if not (now - 60.0 <= t <= now + 0.1):
                # not stamped on the capture clock (e.g. a take read as fast as possible)
                t = now
                self.rebased += 1
            if len(history) and t < history.last_time():
                t = history.last_time()
            history.append(t, values)
            self.frames += 1
            self.last_arrival = now

    def poll(self, t: float, *, due: float | None = None) -> np.ndarray | None:
        """Values (D,) for the frame due at `due` [s, capture clock; default now], or None
        while there is nothing to follow (`t`, the session time, does not matter here)."""
        now = self.clock()
        due = now if due is None else due
        if self.source is None:
            if now < self.next_retry:
                return None
            self._open()
            if self.source is None:
                return None
        try:
            self._drain(now)
        except Exception as error:  # the source broke: close it, reopen it later
            self._fail(error)
            return None
        if self._opened_at is None:
            self._opened_at = due
        history = self._history
        newest = history.last_time() if history is not None and len(history) else -math.inf
        followed = self.latency is not None and due - self.latency > newest
        status = None
        if getattr(self.source, "ended", False) and (followed or newest == -math.inf):
            status, message = ENDED, "the source ended"
        elif _status(self.source) == "disconnected":
            # a capture source reconnects by itself: keep it and keep asking
            status, message = FAILED, "the device is disconnected"
        elif due - max(self.last_arrival, self._opened_at) > self.stale_after:
            # judged by arrival, not by the frames' own stamps: a busy tracker that delivers
            # each frame late is a late input, not a silent one
            status, message = SILENT, f"no input for {self.stale_after:g} s"
        if status is not None:
            if self.status != status:
                self.status, self.message = status, message
            self._unlock()
            return None
        if history is None or not len(history):
            return None
        if self.latency is None:
            anchor = history.anchor(due - self.min_latency, self.period)
            if anchor is None:
                return None          # too fresh to interpolate: lock at a later frame
            self.latency = due - anchor
        if self.status != OK:
            self.status, self.message = OK, ""
        at = due - self.latency
        if at > newest:
            self.late += 1
        return history.sample(at, self._out)

    def close(self) -> None:
        if self.source is not None:
            try:
                self.source.close()
            finally:
                self.source = None
