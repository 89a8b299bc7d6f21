"""The data types every source shares: `Frame`, `Status`, `SourceStats`.

Low module: numpy only. Nothing here knows about devices."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np


class Status(str, Enum):
    """Health of a source, as seen by the one reading it.

    OK: frames are arriving. NOT_SEEN: frames are arriving but a camera's tracker does not find
    what it tracks (no face, no hand in the picture): the values are NaN. STALLED: the device is
    open but nothing arrived for longer than the source's `stall_timeout`. DISCONNECTED: the
    device is gone (unplugged, port lost, file or take ended); a live source keeps trying to
    reconnect."""
    OK = "ok"
    NOT_SEEN = "not seen"
    STALLED = "stalled"
    DISCONNECTED = "disconnected"


@dataclass(frozen=True, slots=True)
class Frame:
    """One timestamped sample of a source.

    t : float [s] on the capture clock (`capture.clock`, CLOCK_MONOTONIC): when the data arrived
        in this process (for replays: when it is scheduled).
    values : (D,) float64, read-only; NaN = channel missing (not tracked, not yet received).
    seq : int, arrival counter within the source (0, 1, ...); gaps show frames dropped before
        they were read.
    """
    t: float
    values: np.ndarray
    seq: int = -1

    def __post_init__(self):
        values = self.values
        if not isinstance(values, np.ndarray) or values.dtype != np.float64 or values.ndim != 1:
            values = np.asarray(values, dtype=np.float64)
            if values.ndim != 1:
                raise ValueError(f"Frame.values must be a 1-D array (D,), got shape {values.shape}")
            object.__setattr__(self, "values", values)
        if values.flags.writeable:
            # a read-only view: the frame cannot be changed through it, the caller's array is
            # left as it was
            values = values.view()
            values.flags.writeable = False
            object.__setattr__(self, "values", values)
        if type(self.t) is not float:
            object.__setattr__(self, "t", float(self.t))
        if not math.isfinite(self.t):
            raise ValueError(f"Frame.t must be a finite time in seconds, got {self.t!r}")


@dataclass(slots=True)
class SourceStats:
    """Counters a source keeps while it runs (read them with `source.stats`, a copy).

    frames: frames produced; dropped: frames discarded because nobody read them in time (queue
    full) or, for OSC, datagrams the kernel dropped (SO_RXQ_OVFL); malformed: reports / packets
    that could not be parsed and were skipped; nan_values: channel values that arrived as NaN or
    inf (stored as NaN = missing); unmapped: OSC messages to an address the source does not map;
    connects / disconnects: device sessions opened / lost; last_error: the latest problem, as
    text."""
    frames: int = 0
    dropped: int = 0
    malformed: int = 0
    nan_values: int = 0
    unmapped: int = 0
    connects: int = 0
    disconnects: int = 0
    last_error: str = ""
    problems: dict[str, int] = field(default_factory=dict)

    def note(self, problem: str) -> None:
        """Count a problem by kind (e.g. "unknown report id 0x07") and remember it as the last."""
        if problem not in self.problems and len(self.problems) >= 64:
            problem_key = "(other problems)"    # bounded: a flood of distinct errors stays small
        else:
            problem_key = problem
        self.problems[problem_key] = self.problems.get(problem_key, 0) + 1
        self.last_error = problem

    def copy(self) -> "SourceStats":
        return replace(self, problems=dict(self.problems))
