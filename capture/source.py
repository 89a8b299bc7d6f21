"""The `Source` protocol and the reader-thread machinery every device source shares.

A source produces `Frame`s: `read(timeout)` returns the next one (or None on timeout), `channels`
names the D values, `rate` is the nominal rate [Hz], `status` is ok / stalled / disconnected, and
`stats` counts frames, drops, malformed input and reconnects. Sources are context managers.

`ThreadedSource` runs one reader thread per device: it opens the device, reads, stamps each
arrival on the shared monotonic clock, parses, queues a Frame, and when the device goes away it
keeps trying to open it again every `reconnect_interval` seconds.
"""
from __future__ import annotations

import logging
import math
import queue
import threading
from typing import Iterator, Sequence

import numpy as np

from .clock import CLOCK, MonotonicClock
from .frame import Frame, SourceStats, Status
from .resample import interpolate

log = logging.getLogger(__name__)


class EndOfStream(Exception):
    """Raised inside a reader when a finite source (video file, take) has no more data."""


class Source:
    """Base class of every source. Subclasses set `kind` and implement `read`, `close`, `status`.

    channels : tuple of D channel names; rate : nominal frame rate [Hz] (0 when unknown);
    spec : the string that opens it again (for take metadata)."""

    kind = "source"

    def __init__(self, channels: Sequence[str] = (), rate: float = 0.0, *,
                 clock: MonotonicClock | None = None, spec: str = ""):
        self._channels = tuple(str(c) for c in channels)
        self.rate = float(rate)
        self.clock = clock or CLOCK
        self.spec = spec
        self._stats = SourceStats()
        self._stats_lock = threading.Lock()
        self.closed = False

    # -- description ------------------------------------------------------------------------
    @property
    def channels(self) -> tuple[str, ...]:
        return self._channels

    @property
    def stats(self) -> SourceStats:
        """A copy of the counters (see `SourceStats`)."""
        with self._stats_lock:
            return self._stats.copy()

    @property
    def status(self) -> Status:
        raise NotImplementedError

    @property
    def ended(self) -> bool:
        """True when a finite source has delivered everything and will produce no more."""
        return False

    def describe(self) -> dict:
        """What a take records about the device: kind, spec, channels, rate."""
        return {"kind": self.kind, "spec": self.spec, "channels": list(self.channels),
                "rate": self.rate}

    # -- reading ----------------------------------------------------------------------------
    def read(self, timeout: float | None = None) -> Frame | None:
        raise NotImplementedError

    def __iter__(self) -> Iterator[Frame]:
        """Frames until the source ends (finite sources) or is closed."""
        while not self.closed:
            frame = self.read(timeout=0.1)
            if frame is not None:
                yield frame
            elif self.ended:
                return

    def close(self) -> None:
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        count = len(self.channels)
        return (f"{type(self).__name__}({self.spec or self.kind!r}, {count} "
                f"channel{'' if count == 1 else 's'}, {self.status.value})")

    # -- helpers for subclasses -------------------------------------------------------------
    def _count(self, **increments) -> None:
        with self._stats_lock:
            for name, amount in increments.items():
                setattr(self._stats, name, getattr(self._stats, name) + amount)

    def _problem(self, text: str, *, malformed: bool = False) -> None:
        with self._stats_lock:
            self._stats.note(text)
            if malformed:
                self._stats.malformed += 1


class ThreadedSource(Source):
    """A source whose device is read by a background thread.

    Subclasses implement:
      `_open_device()` -> None: open the device, raise OSError when it is not there;
      `_pump(timeout)` -> None: wait up to `timeout` s for data, call `_emit(t, values)` per
        frame; raise OSError when the device is lost, EndOfStream when a finite source is done;
      `_close_device()` -> None.

    Parameters (keyword-only)
    -------------------------
    queue_size : frames kept for the reader; when full, a live source drops the oldest
        (counted in stats.dropped), a finite source (`backpressure=True`) waits instead, so that
        a file or take played as fast as possible loses nothing.
    stall_timeout : [s] without a frame before the status turns STALLED (default
        max(0.25, 5 / rate)).
    reconnect_interval : [s] between attempts to open a lost device; reconnect=False gives up.
    """

    def __init__(self, channels: Sequence[str] = (), rate: float = 0.0, *,
                 clock: MonotonicClock | None = None, spec: str = "", queue_size: int = 1024,
                 backpressure: bool = False, stall_timeout: float | None = None,
                 reconnect: bool = True, reconnect_interval: float = 0.5):
        super().__init__(channels, rate, clock=clock, spec=spec)
        if queue_size < 1:
            raise ValueError(f"queue_size must be >= 1, got {queue_size}")
        if stall_timeout is None:
            stall_timeout = max(0.25, 5.0 / rate) if rate > 0 else 0.5
        if not stall_timeout > 0:
            raise ValueError(f"stall_timeout must be > 0 s, got {stall_timeout!r}")
        if not reconnect_interval > 0:
            raise ValueError(f"reconnect_interval must be > 0 s, got {reconnect_interval!r}")
        self.stall_timeout = float(stall_timeout)
        self.reconnect = reconnect
        self.reconnect_interval = float(reconnect_interval)
        self.backpressure = backpressure
        self._queue: queue.Queue[Frame] = queue.Queue(maxsize=queue_size)
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._attempted = threading.Event()
        self._ended = False
        self._seq = 0
        self._last_arrival = -math.inf
        self._connected_at = -math.inf
        self._thread: threading.Thread | None = None

    # -- lifecycle --------------------------------------------------------------------------
    def _start(self, *, wait: bool = True, timeout: float = 5.0) -> None:
        """Start the reader thread. With `wait`, return after the first attempt to open the
        device and raise OSError if it failed (so that opening a missing device is an error,
        while losing it later is a reconnection)."""
        self._thread = threading.Thread(target=self._run, name=f"mop-{self.kind}", daemon=True)
        self._thread.start()
        if wait:
            self._attempted.wait(timeout)
            if not self._connected.is_set() and not self._ended:
                error = self._stats.last_error or "no answer"
                self.close()
                raise OSError(f"{self.spec or self.kind}: could not open the device: {error}")

    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._connected.is_set():
                try:
                    self._open_device()
                except EndOfStream:
                    self._ended = True
                    self._attempted.set()
                    return
                except Exception as error:  # OSError mostly; any failure means "not there"
                    self._problem(f"open failed: {error}")
                    self._attempted.set()
                    if not self.reconnect:
                        self._ended = True
                        return
                    self._stop.wait(self.reconnect_interval)
                    continue
                self._count(connects=1)
                self._connected_at = self.clock.now()
                self._connected.set()
                self._attempted.set()
            try:
                self._pump(0.05)
            except EndOfStream:
                self._disconnect()
                self._ended = True
                return
            except Exception as error:
                if self._stop.is_set():
                    break
                log.info("%s: device lost: %s", self.spec or self.kind, error)
                self._problem(f"device lost: {error}")
                self._count(disconnects=1)
                self._disconnect()
                if not self.reconnect:
                    self._ended = True
                    return
                self._stop.wait(self.reconnect_interval)
        self._disconnect()

    def _disconnect(self) -> None:
        if self._connected.is_set():
            self._connected.clear()
            try:
                self._close_device()
            except Exception:
                log.debug("closing %s failed", self.kind, exc_info=True)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
            if self._thread.is_alive():
                log.warning("%s: reader thread did not stop within 2 s", self.spec or self.kind)

    # -- subclass hooks ---------------------------------------------------------------------
    def _open_device(self) -> None:
        raise NotImplementedError

    def _pump(self, timeout: float) -> None:
        raise NotImplementedError

    def _close_device(self) -> None:
        pass

    def _emit(self, t: float, values: np.ndarray) -> None:
        """Queue one frame. `values` must be a fresh (D,) float64 array the source no longer
        writes to."""
        nan_count = values.size - int(np.count_nonzero(np.isfinite(values)))
        if nan_count:
            # inf is not a measurement either: everything non-finite becomes NaN = missing
            np.copyto(values, np.nan, where=~np.isfinite(values))
        frame = Frame(t, values, self._seq)
        self._seq += 1
        self._last_arrival = t
        if self.backpressure:
            while not self._stop.is_set():
                try:
                    self._queue.put(frame, timeout=0.05)
                    break
                except queue.Full:
                    continue
        else:
            try:
                self._queue.put_nowait(frame)
            except queue.Full:
                try:
                    self._queue.get_nowait()
                except queue.Empty:
                    pass
                self._queue.put_nowait(frame)
                self._count(dropped=1)
        self._count(frames=1, nan_values=nan_count)

    # -- the Source protocol ----------------------------------------------------------------
    def read(self, timeout: float | None = None) -> Frame | None:
        """The next frame, waiting up to `timeout` s (None: until one comes or the source
        ends); None on timeout or after the end of a finite source."""
        if timeout is not None and timeout <= 0:
            try:
                return self._queue.get_nowait()
            except queue.Empty:
                return None
        deadline = None if timeout is None else self.clock.now() + timeout
        while True:
            wait = 0.1 if deadline is None else min(0.1, deadline - self.clock.now())
            if wait <= 0:
                return None
            try:
                return self._queue.get(timeout=wait)
            except queue.Empty:
                if self._ended or self.closed:
                    try:
                        return self._queue.get_nowait()
                    except queue.Empty:
                        return None

    @property
    def ended(self) -> bool:
        return self._ended and self._queue.empty()

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    @property
    def status(self) -> Status:
        if self.closed or not self._connected.is_set():
            return Status.DISCONNECTED
        last = max(self._last_arrival, self._connected_at)
        if self.clock.now() - last > self.stall_timeout:
            return Status.STALLED
        return Status.OK

    def wait_connected(self, timeout: float) -> bool:
        """Block until the device is open (True) or `timeout` s pass (False)."""
        return self._connected.wait(timeout)


class Resampled(Source):
    """Any source, resampled to a fixed rate [Hz] on a grid anchored at its first frame.

    method="linear": data-driven; a grid frame is produced once a raw frame at or after its
        time has arrived (latency up to one raw frame interval), values linearly interpolated
        (see `capture.resample`). Works for sources played faster than real time.
    method="hold": clock-driven; `read` returns a frame at each grid time with the newest raw
        values (no added latency); NaN once the source has been silent for its stall timeout.
    """

    kind = "resampled"

    def __init__(self, source: Source, rate: float, *, method: str = "linear"):
        if not rate > 0:
            raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
        if method not in ("linear", "hold"):
            raise ValueError(f"method must be 'linear' or 'hold', got {method!r}")
        super().__init__(source.channels, rate, clock=source.clock, spec=source.spec)
        self.source = source
        self.method = method
        self.kind = source.kind
        self._period = 1.0 / rate
        self._origin: float | None = None
        self._next_index = 0
        self._previous: Frame | None = None
        self._pending: list[Frame] = []
        self._latest: Frame | None = None
        self._seq = 0

    @property
    def channels(self) -> tuple[str, ...]:
        return self.source.channels

    @property
    def status(self) -> Status:
        return self.source.status

    @property
    def ended(self) -> bool:
        return self.source.ended and not self._pending

    @property
    def stats(self) -> SourceStats:
        stats = self.source.stats
        with self._stats_lock:
            stats.dropped += self._stats.dropped   # grid points skipped by a late reader
        return stats

    def describe(self) -> dict:
        info = self.source.describe()
        info.update(resampled_rate=self.rate, resample_method=self.method)
        return info

    def close(self) -> None:
        self.closed = True
        self.source.close()

    def _frame(self, t: float, values: np.ndarray) -> Frame:
        frame = Frame(t, values, self._seq)
        self._seq += 1
        return frame

    def read(self, timeout: float | None = None) -> Frame | None:
        if self.method == "linear":
            return self._read_linear(timeout)
        return self._read_hold(timeout)

    def _read_linear(self, timeout):
        deadline = None if timeout is None else self.clock.now() + timeout
        while not self._pending:
            remaining = None if deadline is None else max(0.0, deadline - self.clock.now())
            raw = self.source.read(timeout=remaining)
            if raw is None:
                return None
            self._feed(raw)
            if deadline is not None and self.clock.now() >= deadline and not self._pending:
                return None
        return self._pending.pop(0)

    def _feed(self, raw: Frame) -> None:
        if self._origin is None:
            self._origin = raw.t
            self._previous = raw
            self._pending.append(self._frame(raw.t, raw.values.copy()))
            self._next_index = 1
            return
        previous = self._previous
        first = self._next_index
        last = int(math.floor((raw.t - self._origin) / self._period + 1e-9))
        if last >= first:
            grid = self._origin + np.arange(first, last + 1) * self._period
            values = interpolate(np.array([previous.t, raw.t]),
                                 np.stack([previous.values, raw.values]), grid)
            for t, row in zip(grid, values):
                self._pending.append(self._frame(float(t), row))
            self._next_index = last + 1
        if raw.t >= previous.t:
            self._previous = raw

    def _read_hold(self, timeout):
        while True:
            raw = self.source.read(timeout=0)
            if raw is None:
                break
            self._latest = raw
        if self._origin is None:
            if self._latest is None:
                raw = self.source.read(timeout=timeout)
                if raw is None:
                    return None
                self._latest = raw
            self._origin = self._latest.t
            self._next_index = 0
        now = self.clock.now()
        t_next = self._origin + self._next_index * self._period
        if t_next < now - self._period:
            # the reader fell behind: skip the grid points it missed instead of bursting
            missed = int((now - t_next) / self._period)
            self._next_index += missed
            self._count(dropped=missed)
            t_next = self._origin + self._next_index * self._period
        if timeout is not None and t_next > now + timeout:
            return None
        self.clock.sleep_until(t_next)
        while True:
            raw = self.source.read(timeout=0)
            if raw is None:
                break
            self._latest = raw
        self._next_index += 1
        stall = getattr(self.source, "stall_timeout", 0.5)
        if self._latest is None or t_next - self._latest.t > stall:
            values = np.full(len(self.channels), np.nan)
        else:
            values = self._latest.values.copy()
        return self._frame(t_next, values)
