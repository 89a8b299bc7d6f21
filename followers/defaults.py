"""Defaults estimated from the templates themselves, and template validation.

- **sigma** (per channel, the same for every state): ``sigma_fraction`` times the channel's
  standard deviation over all frames of the template (of all templates, in a bank), the
  spread floored at ``sigma_floor`` times the root-mean-square spread over the channels that
  move (so a channel that moves little does not make every other value impossible), and 1.0
  when the template does not move at all. A performer repeating a demonstration rarely
  differs from it by less than a quarter of the channel's range of motion; a much smaller
  sigma makes the follower brittle, a much larger one blurs positions.
- **a channel that never moves** (one value in every take up to rounding,
  ``moving_channels``) tells no action from another: the followers leave it out of every
  score like a missing channel (a value far outside what the takes span still counts as an
  outlier), and no statistic over channels counts it (``moving_columns``, ``moving_rms``).
- **recognition sigma** (a bank): at least ``recognition_floor`` of each template's own
  channel spread: another performance of an action differs from the demonstration in
  intensity as well as timing.
- **exact-repetition scale** (a bank): the template's own noise from its second differences
  (``noise_sigmas``), within [``exact_floor``, 1] times the default sigma.
- **window** (half-width p, in states): ``ceil(window_fraction * T)``, at least ``window_min``
  and at most T. The posterior of a follower on track is a few states wide; p only has to
  hold it through ambiguous stretches (a held pose).

Every number here is a field of ``FollowerConfig`` or ``BankConfig``.
"""
from __future__ import annotations

import math

import numpy as np

from followers.config import FollowerConfig
from followers.preprocessing import changes

_DEFAULT = FollowerConfig()


def as_template(template, *, name: str = "template") -> np.ndarray:
    """Validate a template and return it as a C-contiguous ``(T, D) float64`` array.

    A 1-D array is one channel. Raises ValueError for fewer than 2 frames, no channel, or
    non-finite values (fill gaps first, e.g. with :func:`followers.fill_gaps`)."""
    arr = np.asarray(template)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(f"{name} must be (T, D) (frames x channels), got shape {arr.shape}")
    if arr.shape[0] < 2 or arr.shape[1] < 1:
        raise ValueError(f"{name} needs at least 2 frames and 1 channel, got shape {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        rows = np.unique(np.nonzero(bad)[0])
        raise ValueError(f"{name} has non-finite values in {rows.size} frame(s) (first: frame "
                         f"{rows[0]}); fill the gaps first (followers.fill_gaps)")
    return arr


def channel_spread(templates: list[np.ndarray]) -> np.ndarray:
    """(D,) float: standard deviation of each channel over every frame of the templates
    (computed from per-template sums, without stacking them)."""
    count = sum(t.shape[0] for t in templates)
    total = sum(t.sum(axis=0) for t in templates)
    mean = total / count
    square = sum(((t - mean) ** 2).sum(axis=0) for t in templates)
    return np.sqrt(square / count)


def moving_channels(templates: list[np.ndarray]) -> np.ndarray:
    """(D,) bool: the channels whose value changes somewhere in ``templates`` by more than
    rounding (``preprocessing.changes``, the normaliser's rule); every channel when none
    does."""
    high = np.max([t.max(axis=0) for t in templates], axis=0)
    low = np.min([t.min(axis=0) for t in templates], axis=0)
    moving = changes(high - low, np.maximum(np.abs(high), np.abs(low)))
    return moving if moving.any() else np.ones_like(moving)


def moving_columns(arrays: list[np.ndarray], moving: np.ndarray) -> list[np.ndarray]:
    """``arrays`` (each (N_i, D)) cut to their ``moving (D,)`` columns (the same list when
    every channel moves): what a channel-by-channel statistic is computed from, so that it
    is the same to the last bit with or without a channel that never moves."""
    return arrays if moving.all() else [a[:, moving] for a in arrays]


def moving_rms(spread: np.ndarray, moving: np.ndarray) -> float:
    """The root-mean-square of ``spread (D,)`` over the ``moving (D,)`` channels."""
    return float(np.sqrt(np.mean(spread[moving] ** 2)))


def pooled_sigma(templates: list[np.ndarray], config: FollowerConfig = _DEFAULT) -> np.ndarray:
    """(D,) float [input units]: the default sigma per channel from the spread of all
    ``templates`` together (see the module docstring)."""
    moving = moving_channels(templates)
    spread = np.zeros(moving.size)
    spread[moving] = channel_spread(moving_columns(templates, moving))
    rms = moving_rms(spread, moving)
    if rms <= 0.0:
        return np.ones_like(spread)
    return config.sigma_fraction * np.maximum(spread, config.sigma_floor * rms)


def default_sigma(template: np.ndarray, *, pooled: list[np.ndarray] | None = None,
                  config: FollowerConfig = _DEFAULT) -> np.ndarray:
    """(T, D) float [input units]: the default sigma of ``template (T, D)``, the same for
    every state; ``pooled``: the templates whose spread sets it (a bank's, so that every
    follower measures distance alike), default the template alone."""
    base = pooled_sigma(pooled if pooled else [template], config)
    return np.ascontiguousarray(np.broadcast_to(base, template.shape))


def recognition_sigma(spread: np.ndarray, sigma: np.ndarray, config,
                      moving: np.ndarray) -> np.ndarray:
    """(T, D) float: a bank's recognition sigma for one template: ``sigma`` (T, D), but at
    least ``config.recognition_floor`` times the template's own channel ``spread (D,)``
    (floored like the default sigma, over the bank's ``moving (D,)`` channels); ``config`` a
    ``BankConfig``."""
    rms = moving_rms(spread, moving)
    if rms <= 0.0:
        return np.array(sigma)
    own = config.recognition_floor * np.maximum(spread, config.follower.sigma_floor * rms)
    return np.maximum(sigma, own[None, :])


def noise_sigma(template: np.ndarray) -> np.ndarray:
    """(D,) float: each channel's sensor noise estimated from the template itself [input units].

    The median absolute second difference: white noise of standard deviation s has second
    differences of standard deviation sqrt(6) s, while a motion sampled densely enough has
    second differences near zero, so the median (robust to the motion's few sharp turns)
    measures the noise: ``median |x[t+1] - 2 x[t] + x[t-1] - m| / (0.6745 sqrt(6))`` with ``m``
    the median second difference. Zeros for templates of fewer than 3 frames."""
    return noise_sigmas([template])[0]


def noise_sigmas(templates: list[np.ndarray]) -> np.ndarray:
    """(K, D) float: ``noise_sigma`` of every template, templates of one length at once."""
    K, D = len(templates), templates[0].shape[1]
    out = np.zeros((K, D))
    lengths = np.array([t.shape[0] for t in templates])
    for length in np.unique(lengths):
        if length < 3:
            continue
        which = np.nonzero(lengths == length)[0]
        second = np.diff(np.stack([templates[k] for k in which]), n=2, axis=1)
        centre = np.median(second, axis=1, keepdims=True)
        out[which] = np.median(np.abs(second - centre), axis=1) / (0.6745 * math.sqrt(6.0))
    return out


def exact_scales(noise: np.ndarray, sigmas: np.ndarray, floor: float) -> np.ndarray:
    """(K, D) float: the scale of a bank's exact-repetition component for each action,
    relative to its default sigma (``sigmas (K, D)``, per channel): its takes' own noise per
    channel (``noise (K, D)``, see ``noise_sigmas``), clipped to [``floor``, 1]. A take
    replayed by its performer differs from the demonstration by about its sensor noise; a
    channel noisier than the default sigma keeps the default, a nearly noiseless one is
    floored."""
    return np.clip(noise / sigmas, floor, 1.0)


def default_window(length: int, config: FollowerConfig = _DEFAULT) -> int:
    """Window half-width p [states] for a template of ``length`` frames."""
    return int(min(length, max(config.window_min,
                               math.ceil(config.window_fraction * length))))


def as_sigma(sigma, shape: tuple[int, int]) -> np.ndarray:
    """Validate a user sigma (scalar, (D,) or (T, D)) and return it as (T, D) float64."""
    T, D = shape
    arr = np.asarray(sigma, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(D, float(arr))
    if arr.shape == (D,):
        arr = np.broadcast_to(arr, (T, D))
    if arr.shape != (T, D):
        raise ValueError(f"sigma must be a scalar, one value per channel ({D},) or one per state "
                         f"and channel ({T}, {D}); got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"sigma must be finite and > 0, got min {arr.min()}")
    return np.ascontiguousarray(arr)


def as_window(window, length: int) -> int:
    """Validate a user window half-width (int >= 1)."""
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)):
        raise TypeError(f"window must be an int (half-width in states), got {window!r}")
    if window < 1:
        raise ValueError(f"window must be >= 1 state, got {window}")
    return int(window)
