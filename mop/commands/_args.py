"""Argument types every command shares, checked when the command line is parsed (argparse then
prints `mop CMD: error: argument --x: ...` and exits 2), so bad numbers never reach the work.

    parser.add_argument("--preview", type=port, ...)          # 0..65535 (0 = any free port)
    parser.add_argument("--duration", type=seconds, ...)      # finite, > 0
    parser.add_argument("--countdown", type=seconds_or_zero)  # finite, >= 0
    parser.add_argument("--fps", type=rate, ...)              # finite, > 0, at most MAX_RATE

`CommandError` is the error a command raises for anything the user can fix; `mop.cli.main`
prints it as one line (exit 1), like ValueError / OSError.
"""
from __future__ import annotations

import argparse
import math

MAX_RATE = 1000.0       # [Hz] frames per second no command needs more of (a glove streams ~100)
MAX_SECONDS = 24 * 3600.0   # [s] one day: longer durations are a typo, not a show


class CommandError(Exception):
    """What a user did wrong or must fix, in one line; `exit_code` is what `mop` returns."""

    def __init__(self, message: str, *, exit_code: int = 1):
        super().__init__(message)
        self.exit_code = exit_code


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{what} must be a finite number, got {text!r}")
    return value


def port(text: str) -> int:
    """A TCP/UDP port: an integer 0..65535 (0 = any free port)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a port is an integer 0..65535, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"a port is an integer 0..65535 (0 = any free port), "
                                         f"got {value}")
    return value


def seconds(text: str) -> float:
    """A duration [s]: finite, > 0 and at most a day."""
    value = _number(text, "a duration")
    if not 0 < value <= MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"a duration is > 0 and at most {MAX_SECONDS:g} s "
                                         f"(a day), got {text}")
    return value


def seconds_or_zero(text: str) -> float:
    """A time [s]: finite, >= 0 and at most a day."""
    value = _number(text, "a time")
    if not 0 <= value <= MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"a time is >= 0 and at most {MAX_SECONDS:g} s "
                                         f"(a day), got {text}")
    return value


def rate(text: str) -> float:
    """A rate [Hz] (frames per second): finite, > 0, at most MAX_RATE."""
    value = _number(text, "a rate")
    if not 0 < value <= MAX_RATE:
        raise argparse.ArgumentTypeError(f"a rate is > 0 and at most {MAX_RATE:g} Hz, got {text}")
    return value


def whole_rate(text: str) -> int:
    """A rate [Hz] that must be a whole number of frames per second."""
    value = rate(text)
    if value != int(value):
        raise argparse.ArgumentTypeError(f"a rate here is a whole number of Hz, got {text}")
    return int(value)


def positive(text: str) -> float:
    """A finite number > 0."""
    value = _number(text, "the value")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"the value must be > 0, got {text}")
    return value


MAX_FRAMES = 90_000     # frames a command renders without being asked: an hour at 25 fps


def check_frame_budget(frames: int, *, fps: float, limit: int = MAX_FRAMES) -> None:
    """Refuse work whose frame count is beyond `limit`, saying how to lift it."""
    if frames > limit:
        raise CommandError(f"this would render {frames:,} frames ({frames / fps / 3600:.3g} h "
                           f"at {fps:g} fps); the limit is {limit:,}: render a part with "
                           f"--duration SECONDS, or lift the limit with --max-frames {frames}")


class WorkEstimate:
    """Says once, a few seconds into a long job, how long the whole of it will take, when that
    is more than `threshold` seconds: `estimate.update(done)` after each unit of work."""

    def __init__(self, total: int, what: str, *, stream=None, after: float = 3.0,
                 threshold: float = 60.0):
        import sys
        import time
        self.total, self.what = int(total), what
        self.stream = stream if stream is not None else sys.stderr
        self.after, self.threshold = after, threshold
        self._clock = time.perf_counter
        self.started = self._clock()
        self.said = False

    def update(self, done: int) -> float | None:
        """The estimated seconds left once said, else None."""
        if self.said or done <= 0:
            return None
        elapsed = self._clock() - self.started
        if elapsed < self.after:
            return None
        self.said = True
        left = elapsed / done * (self.total - done)
        if left > self.threshold:
            print(f"warning: {self.what}: about {left / 60:.1f} min more for {self.total:,} "
                  f"frames ({done / elapsed:.3g} frames/s); Ctrl-C stops and keeps what is "
                  f"done", file=self.stream, flush=True)
        return left


def kernels_compiled(packages=("characters", "followers")) -> bool:
    """True when numba's cache holds compiled kernels of every package named (its index files
    beside the sources, or under NUMBA_CACHE_DIR when that is set)."""
    import hashlib
    import importlib.util
    import os
    from pathlib import Path

    root = os.environ.get("NUMBA_CACHE_DIR")
    for name in packages:
        spec = importlib.util.find_spec(name)
        if spec is None or not spec.submodule_search_locations:
            continue
        folder = os.path.abspath(next(iter(spec.submodule_search_locations)))
        if root:        # numba's layout there: FOLDERNAME_sha1(absolute folder)
            where = Path(root) / (os.path.basename(folder) + "_"
                                  + hashlib.sha1(folder.encode()).hexdigest())
        else:
            where = Path(folder) / "__pycache__"
        if not any(where.glob("*.nbi")):
            return False
    return True


def say_if_kernels_compile(stream=None) -> bool:
    """Say first that this run compiles the kernels (a fresh install: minutes, once)."""
    import sys
    if kernels_compiled():
        return False
    print("first run: compiling mop's simulation and follower kernels, once; this takes 2-3 "
          "minutes on a laptop, later runs start at once", file=stream or sys.stderr, flush=True)
    return True
