"""Motion clips: named channels of keyframes sampled over time.

A channel is (times (K,) float [s], strictly increasing, values (K, c) float): a pin position
(c = 2 or 3) [m or px], a finger bend (c = 1) or a joint angle (c = 1) [rad], addressed by name.
Sampling clamps t into [0, duration]; before a channel's first key it holds the first value,
after its last key the last value.

File format (.json): {"format": "mop.motion", "version": 1, "interpolation": "linear",
"channels": {name: {"times": [...], "values": [[...], ...]}}}.
"""
from __future__ import annotations

import json
import math
from enum import Enum
from pathlib import Path
from typing import Mapping

import numpy as np

FORMAT = "mop.motion"
VERSION = 1


class Interpolation(str, Enum):
    LINEAR = "linear"
    CUBIC = "cubic"      # Catmull-Rom through the keys (uniform tangents from neighbours)
    STEP = "step"        # hold the last key


def _parse_interpolation(value) -> Interpolation:
    try:
        return Interpolation(value)
    except ValueError:
        raise ValueError(f"interpolation must be one of {[i.value for i in Interpolation]}, "
                         f"got {value!r}") from None


def _channel(name, times, values) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(name, str) or not name:
        raise TypeError(f"channel names must be non-empty strings, got {name!r}")
    try:
        t = np.array(times, dtype=np.float64)
        v = np.array(values, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"channel {name!r}: times and values must be numeric arrays "
                         f"(ragged value rows?): {error}") from None
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"channel {name!r}: times must be a non-empty 1-D array, got shape "
                         f"{t.shape}")
    if v.ndim == 1:
        v = v[:, None]
    if v.ndim != 2 or v.shape[0] != t.shape[0] or v.shape[1] == 0:
        raise ValueError(f"channel {name!r}: values must have shape ({t.shape[0]}, c) to match "
                         f"{t.shape[0]} times, got {v.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"channel {name!r}: times contain NaN or inf at key "
                         f"{int(np.flatnonzero(~np.isfinite(t))[0])}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"channel {name!r}: values contain NaN or inf at key "
                         f"{int(np.flatnonzero(~np.isfinite(v).all(1))[0])}")
    if t[0] < 0:
        raise ValueError(f"channel {name!r}: times must start at >= 0 s, got {t[0]}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(f"channel {name!r}: times must be strictly increasing, got "
                         f"{t[k]} then {t[k + 1]} at keys {k}, {k + 1}")
    t.setflags(write=False)
    v.setflags(write=False)
    return t, v


class Motion:
    """A clip of named keyframe channels.

    Parameters
    ----------
    channels : {name: (times (K,) float [s], values (K, c) float)}; values (K,) means c = 1
    interpolation : "linear" (default), "cubic" (Catmull-Rom) or "step"
    """

    def __init__(self, channels: Mapping[str, tuple], *, interpolation: str = "linear"):
        if not isinstance(channels, Mapping):
            raise TypeError(f"channels must be a mapping name -> (times, values), got "
                            f"{type(channels).__name__}")
        self.interpolation = _parse_interpolation(interpolation)
        self._channels: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, pair in channels.items():
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise ValueError(f"channel {name!r}: expected a pair (times, values), got "
                                 f"{type(pair).__name__}")
            self._channels[name] = _channel(name, *pair)
        self.duration = max((t[-1] for t, _ in self._channels.values()), default=0.0)
        self.duration = float(self.duration)
        self._groups = _build_groups(self._channels, self.duration)

    # description -------------------------------------------------------------------------
    @property
    def channel_names(self) -> list[str]:
        return list(self._channels)

    def channel_size(self, name: str) -> int:
        """c: components of the channel's values (1 for a scalar channel)."""
        return self._get(name)[1].shape[1]

    def keys(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(times (K,), values (K, c)) of one channel (read-only arrays)."""
        return self._get(name)

    def _get(self, name):
        try:
            return self._channels[name]
        except KeyError:
            raise KeyError(f"motion has no channel {name!r}; it has {self.channel_names}") from None

    def __repr__(self) -> str:
        count = len(self._channels)
        return (f"Motion({count} channel{'' if count == 1 else 's'}, {self.duration:.3f} s, "
                f"{self.interpolation.value})")

    def __eq__(self, other) -> bool:
        if not isinstance(other, Motion):
            return NotImplemented
        return (self.interpolation == other.interpolation and self.channel_names ==
                other.channel_names and all(
                    np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
                    for a, b in zip(self._channels.values(), other._channels.values())))

    # sampling ----------------------------------------------------------------------------
    def sample(self, t: float) -> dict[str, np.ndarray]:
        """Values at time t [s] (clamped into [0, duration]): {name: (c,) float}."""
        t = float(t)
        if math.isnan(t):
            raise ValueError("t must be a time in seconds, got NaN")
        t = min(max(t, 0.0), self.duration)
        out = {}
        for group in self._groups:
            rows = group.sample(t, self.interpolation)
            for name, row in zip(group.names, rows):
                out[name] = row
        return {name: out[name] for name in self._channels}

    def sample_many(self, times) -> dict[str, np.ndarray]:
        """Values at many times (T,) [s]: {name: (T, c) float} (for baking, plots).

        Samples channel by channel with the plain scalar code (the reference `sample` is
        tested against)."""
        ts = np.clip(np.asarray(times, dtype=np.float64), 0.0, self.duration)
        return {name: np.stack([_sample_channel(k, v, float(t), self.interpolation) for t in ts])
                if ts.size else np.zeros((0, v.shape[1]))
                for name, (k, v) in self._channels.items()}

    # files -------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-compatible dict (see the module docstring for the layout)."""
        return {"format": FORMAT, "version": VERSION, "interpolation": self.interpolation.value,
                "channels": {name: {"times": t.tolist(), "values": v.tolist()}
                             for name, (t, v) in self._channels.items()}}

    @classmethod
    def from_dict(cls, data: Mapping) -> "Motion":
        if not isinstance(data, Mapping):
            raise TypeError(f"a motion dict must be a mapping, got {type(data).__name__}")
        from characters.sidecar import check_header, numeric_lists
        if data.get("format", FORMAT) != FORMAT:
            raise ValueError(f"not a motion: format is {data.get('format')!r}, expected {FORMAT!r}")
        check_header(data, format=FORMAT, version=VERSION, where="motion")
        channels = data.get("channels")
        if not isinstance(channels, Mapping):
            raise ValueError("a motion dict needs 'channels': {name: {'times': [...], "
                             "'values': [...]}}")
        pairs = {}
        for name, channel in channels.items():
            if (not isinstance(channel, Mapping) or "times" not in channel
                    or "values" not in channel):
                raise ValueError(f"channel {name!r}: expected {{'times': [...], 'values': [...]}}, "
                                 f"got {channel!r:.80}")
            pairs[name] = (numeric_lists(channel["times"], f"channel {name!r}: times"),
                           numeric_lists(channel["values"], f"channel {name!r}: values"))
        interpolation = data.get("interpolation", "linear")
        if not isinstance(interpolation, str):
            raise TypeError(f"interpolation must be a name, got {interpolation!r:.60}")
        return cls(pairs, interpolation=interpolation)

    def save(self, path) -> None:
        path = Path(path)
        if path.suffix.lower() != ".json":
            raise ValueError(f"motions are saved as .json files, got {path}")
        path.write_text(json.dumps(self.to_dict(), allow_nan=False))

    @classmethod
    def load(cls, path) -> "Motion":
        path = Path(path)
        if path.suffix.lower() != ".json":
            raise ValueError(f"motions are loaded from .json files, got {path}")
        from characters.sidecar import read_json
        data = read_json(path, "motion file")
        try:
            return cls.from_dict(data)
        except (ValueError, TypeError) as error:
            raise type(error)(f"{path}: {error}") from None


class _Group:
    """Channels of one size c, concatenated so one searchsorted serves them all.

    Channel g's times are shifted by g x stride (stride > duration + 1), which keeps the
    concatenation sorted; a query t becomes t + g x stride per channel.
    """

    def __init__(self, names, channels, stride):
        self.names = names
        count = len(names)
        self.shift = np.arange(count) * stride
        self.times = np.concatenate([channels[n][0] + g * stride for g, n in enumerate(names)])
        self.values = np.concatenate([channels[n][1] for n in names])
        sizes = np.array([channels[n][0].size for n in names])
        self.start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self.end = self.start + sizes  # one past the last key

    def sample(self, t: float, interpolation: Interpolation) -> np.ndarray:
        q = t + self.shift
        k = np.searchsorted(self.times, q, side="right") - 1
        k0 = np.maximum(np.minimum(k, self.end - 2), self.start)
        k1 = np.minimum(k0 + 1, self.end - 1)
        t0, t1 = self.times[k0], self.times[k1]
        span = t1 - t0
        single = span <= 0
        u = np.clip((q - t0) / np.where(single, 1.0, span), 0.0, 1.0)
        u[single] = 0.0
        p0, p1 = self.values[k0], self.values[k1]
        if interpolation is Interpolation.STEP:
            return np.where((u >= 1.0)[:, None], p1, p0)
        if interpolation is Interpolation.LINEAR:
            return p0 + u[:, None] * (p1 - p0)
        span = np.where(single, 1.0, span)
        chord = (p1 - p0) / span[:, None]
        before = np.maximum(k0 - 1, self.start)
        after = np.minimum(k0 + 2, self.end - 1)
        has_before = (k0 > self.start)[:, None]
        has_after = (k0 + 2 < self.end)[:, None]
        m0 = np.where(has_before, (p1 - self.values[before])
                      / np.where(has_before[:, 0], t1 - self.times[before], 1.0)[:, None], chord)
        m1 = np.where(has_after, (self.values[after] - p0)
                      / np.where(has_after[:, 0], self.times[after] - t0, 1.0)[:, None], chord)
        u = u[:, None]
        u2, u3 = u * u, u * u * u
        s = span[:, None]
        return ((2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * s * m0
                + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * s * m1)


def _build_groups(channels, duration) -> list[_Group]:
    stride = float(duration) + 2.0
    by_size: dict[int, list[str]] = {}
    for name, (_, values) in channels.items():
        by_size.setdefault(values.shape[1], []).append(name)
    return [_Group(names, channels, stride) for names in by_size.values()]


def _sample_channel(times: np.ndarray, values: np.ndarray, t: float,
                    interpolation: Interpolation) -> np.ndarray:
    count = times.shape[0]
    if count == 1 or t <= times[0]:
        return values[0].copy()
    if t >= times[-1]:
        return values[-1].copy()
    k = int(np.searchsorted(times, t, side="right")) - 1  # times[k] <= t < times[k+1]
    if interpolation is Interpolation.STEP:
        return values[k].copy()
    t0, t1 = times[k], times[k + 1]
    u = (t - t0) / (t1 - t0)
    p0, p1 = values[k], values[k + 1]
    if interpolation is Interpolation.LINEAR:
        return p0 + u * (p1 - p0)
    # Catmull-Rom with non-uniform key spacing: tangents by finite differences over neighbours
    span = t1 - t0
    m0 = (p1 - values[k - 1]) / (t1 - times[k - 1]) if k > 0 else (p1 - p0) / span
    m1 = (values[k + 2] - p0) / (times[k + 2] - t0) if k + 2 < count else (p1 - p0) / span
    u2, u3 = u * u, u * u * u
    return ((2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * span * m0
            + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * span * m1)


def blend(a: Mapping[str, np.ndarray], b: Mapping[str, np.ndarray],
          weight: float) -> dict[str, np.ndarray]:
    """Mix two samples: (1 - weight) a + weight b per channel; weight in [0, 1].

    Channels present in only one sample are kept as they are (a channel that is not driven is
    at rest, so there is nothing to mix it with). Sizes must agree where both have a channel.
    """
    w = float(weight)
    if not 0.0 <= w <= 1.0:
        raise ValueError(f"blend weight must be in [0, 1], got {weight}")
    out = {}
    for name in {**a, **b}:
        if name not in b:
            out[name] = np.asarray(a[name], dtype=np.float64).copy()
        elif name not in a:
            out[name] = np.asarray(b[name], dtype=np.float64).copy()
        else:
            va = np.asarray(a[name], dtype=np.float64)
            vb = np.asarray(b[name], dtype=np.float64)
            if va.shape != vb.shape:
                raise ValueError(f"blend: channel {name!r} has shape {va.shape} in one sample and "
                                 f"{vb.shape} in the other")
            out[name] = (1.0 - w) * va + w * vb
    return out
