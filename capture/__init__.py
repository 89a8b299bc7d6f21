"""capture: everything a performer does enters mop here.

Sources (HID gloves and controllers, cameras with trackers, OSC streams, replays of stored takes)
produce `Frame`s stamped on one monotonic clock; `open_source(spec)` opens any of them from a
short string; `capture.store` is the crash-safe SQLite file layer takes are written to.

    from capture import open_source
    with open_source("osc:127.0.0.1:9000/glove") as source:
        frame = source.read(timeout=0.1)     # Frame | None: frame.t [s], frame.values (D,)

This package imports numpy only; device backends (hidapi, OpenCV, python-osc, numba) are
imported when a source of that kind is opened.
"""
from .clock import CLOCK, MonotonicClock, now
from .frame import Frame, SourceStats, Status
from .source import EndOfStream, Resampled, Source, ThreadedSource
from .spec import open_source

__all__ = ["CLOCK", "EndOfStream", "Frame", "MonotonicClock", "Resampled", "Source",
           "SourceStats", "Status", "ThreadedSource", "now", "open_source"]
