"""Preparing demonstrations: channel normalisation, gap filling, resampling, and the time
alignment of an action with its motion (MOP section 3.1.3)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# a spread below this times a channel's magnitude (at least 1) is rounding, not motion: the
# channel never changes
ROUNDING = 1e-12


def changes(spread: np.ndarray, level: np.ndarray) -> np.ndarray:
    """(D,) bool: the channels whose ``spread (D,)`` is more than rounding at their ``level``
    (D,) [the same units]."""
    return spread > ROUNDING * np.maximum(1.0, np.abs(level))


def _as_2d(values, name: str) -> tuple[np.ndarray, bool]:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim == 1:
        return arr[:, None], True
    if arr.ndim != 2:
        raise ValueError(f"{name} must be (N,) or (N, D), got shape {arr.shape}")
    return arr, False


@dataclass(frozen=True)
class ChannelNormaliser:
    """``(x - shift) / scale`` per channel.

    shift : (D,) float [input units]; scale : (D,) float > 0 [input units]
    """

    shift: np.ndarray
    scale: np.ndarray

    def __call__(self, values) -> np.ndarray:
        """values (..., D) float -> normalised copy, same shape (NaN stays NaN)."""
        arr = np.asarray(values, dtype=np.float64)
        if arr.shape[-1:] != self.shift.shape:
            raise ValueError(f"values must be (..., {self.shift.shape[0]}), one value a channel, "
                             f"got shape {arr.shape}")
        return (arr - self.shift) / self.scale

    def inverse(self, values) -> np.ndarray:
        """Undo the normalisation: values (..., D) -> values * scale + shift."""
        arr = np.asarray(values, dtype=np.float64)
        return arr * self.scale + self.shift


def fit_normaliser(demonstrations, *, how: str = "zscore") -> ChannelNormaliser:
    """A per-channel normaliser fitted on every frame of every demonstration together.

    demonstrations : (T, D) array or a list of them [input units]; NaN ignored.
    how : ``"zscore"`` (mean 0, standard deviation 1) or ``"range"`` (min 0, max 1).
    A channel that never changes gets scale 1 (it is only shifted)."""
    arrays = demonstrations if isinstance(demonstrations, (list, tuple)) else [demonstrations]
    if not arrays:
        raise ValueError("fit_normaliser needs at least one demonstration, got none")
    stacked = np.concatenate([_as_2d(a, "demonstration")[0] for a in arrays], axis=0)
    finite = np.isfinite(stacked)
    if not finite.any(axis=0).all():
        empty = np.nonzero(~finite.any(axis=0))[0]
        raise ValueError(f"channel(s) {empty.tolist()} have no finite value in the demonstrations")
    data = np.where(finite, stacked, np.nan)
    if how == "zscore":
        shift = np.nanmean(data, axis=0)
        scale = np.nanstd(data, axis=0)
    elif how == "range":
        shift = np.nanmin(data, axis=0)
        scale = np.nanmax(data, axis=0) - shift
    else:
        raise ValueError(f"how must be 'zscore' or 'range', got {how!r}")
    scale = np.where(changes(scale, shift), scale, 1.0)
    return ChannelNormaliser(shift=shift, scale=scale)


def normalise(demonstrations, *, how: str = "zscore"):
    """Normalise one demonstration or a list of them with one shared normaliser.

    Returns ``(normalised, normaliser)``: the same structure as the input (an array or a list of
    arrays, each (T, D) float) and the :class:`ChannelNormaliser` to apply to live frames."""
    normaliser = fit_normaliser(demonstrations, how=how)
    if isinstance(demonstrations, (list, tuple)):
        return [normaliser(d) for d in demonstrations], normaliser
    return normaliser(demonstrations), normaliser


def fill_gaps(values, *, max_gap: int | None = None) -> np.ndarray:
    """Fill non-finite samples by linear interpolation along time, per channel (edges: nearest
    value).

    values : (T,) or (T, D) float. max_gap : int, optional [frames]: raise ValueError if a run
    of missing samples is longer. Raises ValueError when a channel has no finite sample."""
    arr, flat = _as_2d(values, "values")
    out = arr.copy()
    t = np.arange(arr.shape[0])
    for d in range(arr.shape[1]):
        ok = np.isfinite(arr[:, d])
        if ok.all():
            continue
        if not ok.any():
            raise ValueError(f"channel {d} has no finite sample to fill its gaps from")
        if max_gap is not None:
            run = np.diff(np.concatenate([[0], (~ok).astype(np.int8), [0]]))
            lengths = np.nonzero(run == -1)[0] - np.nonzero(run == 1)[0]
            if lengths.max() > max_gap:
                raise ValueError(f"channel {d} has a gap of {lengths.max()} frames, more than "
                                 f"max_gap={max_gap}")
        out[:, d] = np.interp(t, t[ok], arr[ok, d])
    return out[:, 0] if flat else out


def resample(values, length: int) -> np.ndarray:
    """Linearly resample ``values (N, D)`` (or (N,)) to ``length`` frames spanning the same
    duration (first and last frames kept)."""
    arr, flat = _as_2d(values, "values")
    length = int(length)
    if length < 1:
        raise ValueError(f"length must be >= 1, got {length}")
    if arr.shape[0] < 1:
        raise ValueError("cannot resample an empty sequence")
    if arr.shape[0] == 1:
        out = np.repeat(arr, length, axis=0)
    else:
        src = np.linspace(0.0, arr.shape[0] - 1.0, length)
        base = np.arange(arr.shape[0], dtype=np.float64)
        out = np.stack([np.interp(src, base, arr[:, d]) for d in range(arr.shape[1])], axis=1)
    return out[:, 0] if flat else out


def align(action, motion, *, action_rate: float | None = None,
          motion_rate: float | None = None, length: str | int = "action"):
    """Give an action and its motion the same number of frames (MOP section 3.1.3).

    The two were captured together but at different rates or durations; the paper normalises
    their durations so that frame t of the action pairs with frame t of the motion. Both are
    stretched linearly over their full duration onto a common frame count.

    action : (Ta, Da) float; motion : (Tm, Dm) float (1-D arrays are one channel).
    action_rate, motion_rate : float [Hz], optional: if given, the two durations must agree to
        within 10 % (else ValueError: they were not captured together).
    length : ``"action"`` (default: keep the action's frames, resample the motion), ``"motion"``,
        or an int frame count for both.
    Returns ``(action, motion)`` resampled, each (T, D) float64 (1-D inputs stay 1-D).
    """
    a, a_flat = _as_2d(action, "action")
    m, m_flat = _as_2d(motion, "motion")
    if a.shape[0] < 2 or m.shape[0] < 2:
        raise ValueError(f"action and motion need >= 2 frames each, got {a.shape[0]} and "
                         f"{m.shape[0]}")
    if (action_rate is None) != (motion_rate is None):
        raise ValueError("give both action_rate and motion_rate, or neither")
    if action_rate is not None:
        if not (action_rate > 0 and motion_rate > 0):
            raise ValueError(f"rates must be > 0 Hz, got {action_rate} and {motion_rate}")
        da = (a.shape[0] - 1) / action_rate
        dm = (m.shape[0] - 1) / motion_rate
        if abs(da - dm) > 0.1 * max(da, dm):
            raise ValueError(f"the action lasts {da:.3f} s and the motion {dm:.3f} s: more than "
                             f"10 % apart, so they were not captured together")
    if length == "action":
        n = a.shape[0]
    elif length == "motion":
        n = m.shape[0]
    elif isinstance(length, (int, np.integer)) and not isinstance(length, bool) and length >= 2:
        n = int(length)
    else:
        raise ValueError(f"length must be 'action', 'motion' or an int >= 2, got {length!r}")
    a2 = a if a.shape[0] == n else resample(a, n)
    m2 = m if m.shape[0] == n else resample(m, n)
    return (a2[:, 0] if a_flat else a2), (m2[:, 0] if m_flat else m2)


def time_warp(values, speed, *, jitter: float = 0.0, rng: np.random.Generator | None = None,
              smoothness: int = 20, hold: int = 0):
    """Replay a demonstration at another tempo: what a performer at ``speed`` x would produce.

    values : (T, D) or (T,) float. speed : float > 0 [x demonstration speed].
    jitter : float >= 0: the tempo also wanders smoothly by about this fraction (log scale,
        a random walk smoothed over ``smoothness`` frames; needs ``rng``).
    hold : int >= 0: frames the last pose is held at the end.
    Returns ``(warped (N, D) or (N,), position (N,) float in [0, 1])``: the replayed frames
    (linear interpolation) and the true template position of each, as a fraction of T - 1.
    """
    arr, flat = _as_2d(values, "values")
    speed = float(speed)
    if not speed > 0:
        raise ValueError(f"speed must be > 0, got {speed}")
    T = arr.shape[0]
    if T < 2:
        raise ValueError(f"values need >= 2 frames, got {T}")
    if jitter > 0:
        if rng is None:
            raise ValueError("jitter needs rng (a numpy Generator)")
        steps = int(np.ceil((T - 1) / speed * 3)) + 2
        noise = rng.normal(size=steps + smoothness)
        wander = np.convolve(noise, np.ones(smoothness), "valid")[:steps]
        wander *= jitter / max(float(wander.std()), 1e-12)
        rates = speed * np.exp(wander)
    else:
        rates = np.full(int(np.ceil((T - 1) / speed)) + 2, speed)
    tau = np.concatenate([[0.0], np.cumsum(rates)])
    tau = tau[tau < T - 1]
    tau = np.concatenate([tau, np.full(1 + int(hold), T - 1.0)])
    base = np.arange(T, dtype=np.float64)
    out = np.stack([np.interp(tau, base, arr[:, d]) for d in range(arr.shape[1])], axis=1)
    return (out[:, 0] if flat else out), tau / (T - 1)
