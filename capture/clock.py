"""The capture clock: one monotonic time base for every source, take and session.

CLOCK_MONOTONIC (`time.monotonic`) is system-wide on Linux, so timestamps from different threads
and processes (a recorder and the test that kills it) compare directly. Sources take a `clock`
argument so that a session can hand every source the same object."""
from __future__ import annotations

import threading
import time


class MonotonicClock:
    """Seconds on CLOCK_MONOTONIC; `sleep_until` wakes early when `stop` is set."""

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, deadline: float, stop: threading.Event | None = None) -> bool:
        """Sleep until `deadline` [s]; return False if `stop` was set first."""
        delay = deadline - time.monotonic()
        if delay <= 0:
            return not (stop is not None and stop.is_set())
        if stop is None:
            time.sleep(delay)
            return True
        return not stop.wait(delay)

    def __repr__(self) -> str:
        return "MonotonicClock()"


CLOCK = MonotonicClock()


def now() -> float:
    """Current time [s] on the shared capture clock."""
    return time.monotonic()
