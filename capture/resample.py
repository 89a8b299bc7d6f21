"""Resampling timestamped frames onto a regular grid (the session rate).

Kernels are pure array functions; `Resampled` (in `capture.source`) streams them.

Rule for missing values (NaN): a grid point between two samples is the linear interpolation when
both neighbours are known, otherwise the value of the nearer neighbour (which may itself be NaN).
Outside the sampled interval the edge value is held."""
from __future__ import annotations

import numpy as np


def _check(times: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if times.ndim != 1:
        raise ValueError(f"times must be (N,), got shape {times.shape}")
    if values.ndim != 2 or values.shape[0] != times.shape[0]:
        raise ValueError(f"values must be (N, D) with N = {times.shape[0]} to match times, got "
                         f"shape {values.shape}")
    if times.shape[0] == 0:
        raise ValueError("cannot resample an empty stream (0 samples)")
    if times.shape[0] > 1 and np.any(np.diff(times) < 0):
        raise ValueError("times must be non-decreasing")
    return times, values


def interpolate(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Values at `grid` times from samples (times, values).

    times : (N,) float [s], non-decreasing; values : (N, D) float, NaN = missing;
    grid : (K,) float [s]. Returns (K, D) float64."""
    times, values = _check(times, values)
    grid = np.asarray(grid, dtype=np.float64)
    if times.shape[0] == 1:
        return np.repeat(values, grid.shape[0], axis=0)
    right = np.searchsorted(times, grid, side="right")
    left = np.clip(right - 1, 0, times.shape[0] - 2)
    t0 = times[left]
    span = times[left + 1] - t0
    # duplicate timestamps (span 0) take the later sample
    weight = np.where(span > 0, (grid - t0) / np.where(span > 0, span, 1.0), 1.0)
    np.clip(weight, 0.0, 1.0, out=weight)
    v0 = values[left]
    v1 = values[left + 1]
    w = weight[:, None]
    out = v0 * (1.0 - w) + v1 * w
    missing = np.isnan(v0) | np.isnan(v1)
    if missing.any():
        nearer = np.where(w < 0.5, v0, v1)
        out = np.where(missing, nearer, out)
    return out


def regular_grid(start: float, stop: float, rate: float) -> np.ndarray:
    """Times start, start + 1/rate, ... up to stop (inclusive within 1e-9 s): (K,) float [s]."""
    if not rate > 0:
        raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
    if stop < start:
        raise ValueError(f"stop ({stop}) must not be before start ({start})")
    count = int(np.floor((stop - start) * rate + 1e-9)) + 1
    return start + np.arange(count) / rate


def resample(times: np.ndarray, values: np.ndarray, rate: float, *,
             start: float | None = None, stop: float | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
    """A stream resampled at `rate` [Hz] from `start` (default: first sample) to `stop`
    (default: last sample). Returns (grid (K,) float [s], values (K, D) float64)."""
    times, values = _check(times, values)
    start = float(times[0]) if start is None else float(start)
    stop = float(times[-1]) if stop is None else float(stop)
    grid = regular_grid(start, stop, rate)
    return grid, interpolate(times, values, grid)


def align_durations(times: np.ndarray, values: np.ndarray, *, start: float, end: float,
                    duration: float, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Time alignment by duration normalisation (MOP section 3.1.3): the action captured over
    [start, end] on its own clock is mapped linearly onto [0, duration] of the motion and sampled
    at `rate`, so action X and motion Y have the same length T.

    times : (N,) float [s]; values : (N, D) float. Returns (grid (T,) float [s] in motion time,
    X (T, D) float64), T = round(duration * rate) + 1."""
    times, values = _check(times, values)
    if not end > start:
        raise ValueError(f"the action interval must have end > start, got [{start}, {end}]")
    if not duration > 0:
        raise ValueError(f"the motion duration must be > 0 s, got {duration!r}")
    if not rate > 0:
        raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
    count = int(round(duration * rate)) + 1
    grid = np.linspace(0.0, duration, count)
    action_times = start + grid * ((end - start) / duration)
    return grid, interpolate(times, values, action_times)
