"""Replay of a stored take (a `capture.store` file) as a source.

Real time (default): frames come at their recorded spacing (optionally `speed` times faster),
stamped with their scheduled time on the capture clock. As fast as possible (realtime=False):
frames come as quickly as they are read, none dropped, stamped with their recorded time
relative to the first frame. Either way the values and the relative times are exactly the stored
ones, on every run.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .clock import MonotonicClock
from .source import EndOfStream, ThreadedSource
from .store import SUFFIX, read_store


def resolve_take_path(path: str | os.PathLike) -> Path:
    """recordings/NAME -> recordings/NAME.sqlite (either spelling works)."""
    path = Path(path)
    if path.is_file():
        return path
    with_suffix = path.with_name(path.name + SUFFIX)
    if with_suffix.is_file():
        return with_suffix
    folder = path.parent
    known = sorted(p.name[:-len(SUFFIX)] for p in folder.glob(f"*{SUFFIX}")) \
        if folder.is_dir() else []
    raise FileNotFoundError(f"no take {path.name!r} in {folder}/ (tried {path} and "
                            f"{with_suffix}); takes there: {', '.join(known) or 'none'}")


class ReplaySource(ThreadedSource):
    """A stored stream played back as a source.

    Parameters
    ----------
    path : the take file (the .sqlite suffix may be left out).
    stream : which stream (default "action", else the first).
    realtime : pace at the recorded timing (default) or deliver as fast as possible.
    speed : playback speed factor in real time (2 = twice as fast).
    loop : start again after the last frame instead of ending.
    """

    kind = "replay"

    def __init__(self, path: str | os.PathLike, *, stream: str | None = None,
                 realtime: bool = True, speed: float = 1.0, loop: bool = False,
                 clock: MonotonicClock | None = None, spec: str = "", wait: bool = True,
                 **options):
        self.path = resolve_take_path(path)
        contents = read_store(self.path)
        if not contents.streams:
            raise ValueError(f"{self.path} holds no stream to replay")
        if stream is None:
            stream = "action" if "action" in contents.streams else next(iter(contents.streams))
        if stream not in contents.streams:
            raise ValueError(f"{self.path} has no stream {stream!r}; it has "
                             f"{', '.join(contents.streams)}")
        data = contents.streams[stream]
        if data.times.size == 0:
            raise ValueError(f"{self.path}: stream {stream!r} has no frames")
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.stream = stream
        self.metadata = contents.metadata
        self.complete = contents.complete
        self._times = data.times - data.times[0]
        self._values = data.values
        self.realtime = bool(realtime)
        self.speed = float(speed)
        self.loop = bool(loop)
        options.setdefault("backpressure", not self.realtime)
        options.setdefault("reconnect", False)
        rate = data.rate
        if not rate and data.times.size > 1:
            rate = (data.times.size - 1) / max(self._times[-1], 1e-9)
        super().__init__(data.channels, rate * (self.speed if self.realtime else 1.0),
                         clock=clock, spec=spec or f"replay:{path}", **options)
        self._index = 0
        self._origin = 0.0
        self._start(wait=wait)

    @property
    def duration(self) -> float:
        """[s] of the recorded stream."""
        return float(self._times[-1])

    def describe(self) -> dict:
        info = super().describe()
        info.update(path=str(self.path), stream=self.stream, realtime=self.realtime,
                    speed=self.speed)
        return info

    def _open_device(self) -> None:
        self._index = 0
        self._origin = self.clock.now()
        self._lap = 0.0

    def _pump(self, timeout: float) -> None:
        if self._index >= self._times.size:
            if not self.loop:
                raise EndOfStream
            # the next lap starts one mean frame interval after the last frame
            step = self._times[-1] / max(self._times.size - 1, 1)
            self._lap += self._times[-1] + step
            self._index = 0
        offset = self._lap + self._times[self._index]
        if self.realtime:
            t = self._origin + offset / self.speed
            if not self.clock.sleep_until(t, self._stop):
                return
        else:
            t = offset
        self._emit(t, np.array(self._values[self._index], dtype=np.float64))
        self._index += 1
