"""The One Euro filter (Casiez, Roussel and Vogel, CHI 2012) over a vector of channels.

A low-pass filter whose cutoff rises with speed: at rest it removes the jitter of a tracker
(cutoff `min_cutoff`), when the performer moves it follows with little lag (cutoff
`min_cutoff + beta * speed`). Speeds are measured per channel in "ranges per second": each
channel's speed is divided by its `scale` (1 for a 0..1 channel, 30 for an angle in degrees,
...), so one `beta` suits channels of different units.

NaN is a missing value: it passes through as NaN and the channel starts afresh at its next
value (a face that comes back is not pulled from where it was lost).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class OneEuroConfig:
    """min_cutoff [Hz]: cutoff at rest (lower = steadier, more lag when starting to move);
    beta [1 / range]: how fast the cutoff rises with speed (higher = less lag in fast moves);
    d_cutoff [Hz]: cutoff of the speed estimate."""
    min_cutoff: float = 1.5
    beta: float = 2.0
    d_cutoff: float = 1.0

    def __post_init__(self):
        for name in ("min_cutoff", "beta", "d_cutoff"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"One Euro {name} must be a finite number, got {value!r}")
        if not self.min_cutoff > 0 or not self.d_cutoff > 0:
            raise ValueError(f"One Euro min_cutoff and d_cutoff must be > 0 Hz, got "
                             f"{self.min_cutoff!r} and {self.d_cutoff!r}")
        if self.beta < 0:
            raise ValueError(f"One Euro beta must be >= 0, got {self.beta!r}")


def _alpha(cutoff: np.ndarray | float, dt: float):
    """Smoothing factor of an exponential filter with this cutoff [Hz] at step dt [s]."""
    return 1.0 / (1.0 + 1.0 / (2.0 * math.pi * cutoff * dt))


class OneEuroFilter:
    """One Euro filter state for D channels.

    scale : (D,) float > 0, each channel's typical range (speeds are divided by it).
    `filter(t, values)` -> the filtered (D,) array (a new array each call, safe to queue)."""

    def __init__(self, scale, config: OneEuroConfig | None = None):
        self.config = config or OneEuroConfig()
        self.scale = np.asarray(scale, dtype=np.float64).ravel()
        if not np.all(self.scale > 0):
            raise ValueError("One Euro channel scales must be > 0")
        size = self.scale.size
        self._value = np.full(size, np.nan)
        self._speed = np.zeros(size)
        self._t: float | None = None

    def reset(self) -> None:
        self._value[:] = np.nan
        self._speed[:] = 0.0
        self._t = None

    def filter(self, t: float, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        if values.shape != self._value.shape:
            raise ValueError(f"expected {self._value.size} values, got {values.shape}")
        config = self.config
        out = values.copy()
        fresh = ~np.isfinite(self._value)
        if self._t is None or not t > self._t:
            # the first frame, or time went back (a file started again): start afresh
            np.copyto(self._value, values)
            self._speed[:] = 0.0
            self._t = t
            return out
        dt = t - self._t
        self._t = t
        seen = np.isfinite(values)
        continuing = seen & ~fresh
        speed = (values - self._value) / dt / self.scale
        a_d = _alpha(config.d_cutoff, dt)
        self._speed = np.where(continuing, a_d * speed + (1.0 - a_d) * self._speed, 0.0)
        cutoff = config.min_cutoff + config.beta * np.abs(self._speed)
        a = _alpha(cutoff, dt)
        smoothed = a * values + (1.0 - a) * self._value
        np.copyto(out, smoothed, where=continuing)
        # a lost channel forgets its state; one that comes back starts from its new value
        self._value = np.where(seen, out, np.nan)
        return out
