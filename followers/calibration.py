"""Performer calibration: another performer's offset and gain per channel, measured from a
short calibration take (the rest pose held, then every channel moved through its range) and
mapped onto the author's, so that their input fits the author's demonstrations.

    author = measure(author_take_values, author_take_times)       # rest, low, high per channel
    alice = measure(alice_values, alice_times)
    to_author = calibrate(alice, author)                          # ChannelMap gain, offset
    bank.follow(normaliser(to_author(alice_performance)))

The map is affine per channel: ``x -> gain * x + offset`` with ``gain = author span /
performer span`` (span: the 2nd to 98th percentile of the take) and the performer's rest
landing on the author's rest. ``ChannelMap.fold(shift, scale)`` folds it into a following
``(x - shift) / scale`` normalisation, so it costs nothing per frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

REST_SECONDS = 2.0          # the calibration take opens with this long a hold of the rest pose
RANGE_PERCENTILES = (2.0, 98.0)   # a channel's span, robust to a few glitches
GAIN_LIMITS = (0.25, 4.0)   # a gain outside these is a bad take, not another performer
MIN_FRAMES = 3              # frames needed in the rest part and in the whole take


@dataclass(frozen=True)
class Calibration:
    """What one calibration take says about a performer, per channel [input units].

    rest (D,): median of the rest part; low, high (D,): the 2nd and 98th percentiles of the
    whole take; channels: names (may be empty)."""
    rest: np.ndarray
    low: np.ndarray
    high: np.ndarray
    channels: tuple[str, ...] = ()

    @property
    def span(self) -> np.ndarray:
        return self.high - self.low

    def as_dict(self) -> dict:
        """JSON-ready numbers (what `mop record --calibrate` stores with the take)."""
        return {"rest": self.rest.tolist(), "low": self.low.tolist(),
                "high": self.high.tolist(), "channels": list(self.channels)}


@dataclass(frozen=True)
class ChannelMap:
    """``x -> gain * x + offset`` per channel (gain, offset (D,)); ``notes`` say which
    channels were left at gain 1 and why."""
    gain: np.ndarray
    offset: np.ndarray
    notes: tuple[str, ...] = field(default=())

    def __call__(self, values) -> np.ndarray:
        """values (..., D) -> mapped copy (NaN stays NaN)."""
        arr = np.asarray(values, dtype=np.float64)
        if arr.shape[-1:] != self.gain.shape:
            raise ValueError(f"values must be (..., {self.gain.shape[0]}), one value a channel, "
                             f"got shape {arr.shape}")
        return arr * self.gain + self.offset

    def fold(self, shift, scale) -> tuple[np.ndarray, np.ndarray]:
        """(shift', scale') with ``(x - shift') / scale' == (self(x) - shift) / scale``."""
        shift = np.asarray(shift, dtype=np.float64)
        scale = np.asarray(scale, dtype=np.float64)
        return (shift - self.offset) / self.gain, scale / self.gain


def measure(values, times=None, *, rest_seconds: float = REST_SECONDS, rate: float | None = None,
            channels=()) -> Calibration:
    """A performer's rest and range per channel from a calibration take.

    values : (N, D) [input units], NaN = missing; times : (N,) [s] (or ``rate`` [Hz]); the
    frames of the first ``rest_seconds`` are the rest pose, every frame counts for the range.
    Raises ValueError naming the problem: too few frames, a channel with no value."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] < MIN_FRAMES:
        raise ValueError(f"a calibration take needs at least {MIN_FRAMES} frames of (N, D) "
                         f"values, got shape {np.shape(values)}")
    if times is None:
        if not rate or not rate > 0:
            raise ValueError("a calibration take needs its frame times or a rate > 0 Hz")
        times = np.arange(arr.shape[0]) / rate
    times = np.asarray(times, dtype=np.float64)
    if times.shape != arr.shape[:1]:
        raise ValueError(f"times {times.shape} do not match {arr.shape[0]} frames")
    names = tuple(channels) or tuple(f"channel {d}" for d in range(arr.shape[1]))
    finite = np.isfinite(arr)
    empty = np.flatnonzero(finite.sum(axis=0) < MIN_FRAMES)
    if empty.size:
        raise ValueError(f"the calibration take has fewer than {MIN_FRAMES} values of "
                         f"{names[empty[0]]!r}")
    resting = times <= times[0] + rest_seconds
    rest_part = np.where(finite[resting], arr[resting], np.nan)
    short = np.flatnonzero(np.isfinite(rest_part).sum(axis=0) < MIN_FRAMES)
    if short.size:
        raise ValueError(f"the calibration take's first {rest_seconds:g} s (the rest pose) hold "
                         f"fewer than {MIN_FRAMES} values of {names[short[0]]!r}")
    data = np.where(finite, arr, np.nan)
    low, high = np.nanpercentile(data, RANGE_PERCENTILES, axis=0)
    return Calibration(np.nanmedian(rest_part, axis=0), low, high, tuple(channels))


def calibrate(performer: Calibration, reference: Calibration) -> ChannelMap:
    """The map that takes ``performer``'s input onto ``reference``'s (the author's): gain =
    reference span / performer span, the rests meet. A channel that did not move in either
    take, or whose gain falls outside GAIN_LIMITS, keeps gain 1 (its rest is still matched)
    and is named in ``notes``."""
    if performer.rest.shape != reference.rest.shape:
        raise ValueError(f"the calibrations have {performer.rest.size} and "
                         f"{reference.rest.size} channels")
    if performer.channels and reference.channels and performer.channels != reference.channels:
        raise ValueError(f"the calibrations name different channels: "
                         f"{', '.join(performer.channels)} against "
                         f"{', '.join(reference.channels)}")
    names = performer.channels or reference.channels or tuple(
        f"channel {d}" for d in range(performer.rest.size))
    gain = np.ones(performer.rest.size)
    notes = []
    for d in range(gain.size):
        mine, theirs = performer.span[d], reference.span[d]
        if not (mine > 0 and theirs > 0):
            notes.append(f"{names[d]}: did not move in a calibration take; only its rest is "
                         f"matched")
            continue
        ratio = theirs / mine
        if not GAIN_LIMITS[0] <= ratio <= GAIN_LIMITS[1]:
            notes.append(f"{names[d]}: ranges differ {ratio:.3g}x (beyond "
                         f"{GAIN_LIMITS[0]:g}-{GAIN_LIMITS[1]:g}x); only its rest is matched")
            continue
        gain[d] = ratio
    offset = reference.rest - gain * performer.rest
    return ChannelMap(gain, offset, tuple(notes))
