"""Defaults estimated from the templates themselves, and template validation.

- **sigma** (per channel, the same for every state): ``SIGMA_FRACTION`` (0.25) times the
  channel's standard deviation over all frames of the template (of all templates, in a bank),
  floored at ``SIGMA_FLOOR`` (0.05) times the root-mean-square of those deviations (so a channel
  that never moves in the demonstration does not make every other value impossible), and 1.0
  when the template does not move at all. A performer repeating a demonstration rarely differs
  from it by less than a quarter of the channel's range of motion; a much smaller sigma makes
  the follower brittle, a much larger one blurs positions (measured on GunPoint: 0.15-0.4 all
  give median errors near 1 %).
- **exact-repetition sigma** (a bank's recognition mixture, per channel): the template's own
  noise, from its second differences (``noise_sigma``), clipped to [``EXACT_FLOOR`` (0.25), 1]
  times the default sigma (``exact_scale``): a take replayed by its performer differs from the
  demonstration by about the sensor's noise.
- **window** (half-width p, in states): ``ceil(WINDOW_FRACTION * T)`` (a fifth of the
  template), at least ``WINDOW_MIN`` (8) and at most T. The posterior of a follower that is on
  track is a few states wide; p only has to hold it through ambiguous stretches (a held pose),
  which in demonstrations of gestures rarely exceed a fifth of the template. With the default
  ``"speed"`` transitions, beam pruning then keeps only the states that matter inside it.
"""
from __future__ import annotations

import math

import numpy as np

SIGMA_FRACTION = 0.25
SIGMA_FLOOR = 0.05
LOCAL_FRACTION = 0.05
RECOGNITION_FRACTION = 0.5
EXACT_FLOOR = 0.25
WINDOW_FRACTION = 0.2
WINDOW_MIN = 8


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


def local_variance(template: np.ndarray, half: int) -> np.ndarray:
    """Variance of each channel over frames ``t - half .. t + half`` (clipped at the ends).

    template : (T, D) float. Returns (T, D) float [input units squared]."""
    T = template.shape[0]
    c1 = np.vstack([np.zeros((1, template.shape[1])), np.cumsum(template, axis=0)])
    c2 = np.vstack([np.zeros((1, template.shape[1])), np.cumsum(template ** 2, axis=0)])
    lo = np.clip(np.arange(T) - half, 0, T)
    hi = np.clip(np.arange(T) + half + 1, 0, T)
    n = (hi - lo)[:, None]
    mean = (c1[hi] - c1[lo]) / n
    return np.maximum((c2[hi] - c2[lo]) / n - mean ** 2, 0.0)


def channel_spread(templates: list[np.ndarray]) -> np.ndarray:
    """(D,) float: standard deviation of each channel over every frame of the templates
    (computed from per-template sums, without stacking them)."""
    count = sum(t.shape[0] for t in templates)
    total = sum(t.sum(axis=0) for t in templates)
    mean = total / count
    square = sum(((t - mean) ** 2).sum(axis=0) for t in templates)
    return np.sqrt(square / count)


def default_sigma(template: np.ndarray, *, pooled: list[np.ndarray] | None = None,
                  local: float = 0.0) -> np.ndarray:
    """Per-state, per-channel sigma estimated from a template.

    template : (T, D) float (validated); pooled : optional list of (T_k, D) templates whose
    channel spreads set the base level (a bank passes all its templates, so every follower
    measures distance the same way). local : float >= 0: also add this times the template's
    local variance over +-``LOCAL_FRACTION`` of its length (0, the default, for gestures; about
    1 suits repetitive activities, whose repetitions never line up frame by frame, at the cost
    of blurrier positions). Returns (T, D) float [input units]."""
    spread = channel_spread(pooled if pooled else [template])
    rms = float(np.sqrt(np.mean(spread ** 2)))
    if rms <= 0.0:
        return np.ones_like(template)
    base = SIGMA_FRACTION * np.maximum(spread, SIGMA_FLOOR * rms)
    var = np.broadcast_to(base ** 2, template.shape).copy()
    if local > 0:
        half = max(1, int(round(LOCAL_FRACTION * template.shape[0])))
        var += float(local) * local_variance(template, half)
    return np.sqrt(var)


def recognition_sigma(template: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Sigma of the bank's recognition score for one template (see ``FollowerBank``).

    Recognising *which* action is performed must tolerate what following need not: another
    performance of an action differs from the demonstration in intensity as well as timing. Per
    state: the follower's sigma, but at least ``RECOGNITION_FRACTION`` of the template's own
    channel spread (floored like the default sigma).

    template : (T, D) float; sigma : (T, D) float. Returns (T, D) float [input units]."""
    spread = template.std(axis=0)
    rms = float(np.sqrt(np.mean(spread ** 2)))
    if rms <= 0.0:
        return sigma.copy()
    own = RECOGNITION_FRACTION * np.maximum(spread, SIGMA_FLOOR * rms)
    return np.maximum(sigma, own[None, :])


def noise_sigma(template: np.ndarray) -> np.ndarray:
    """(D,) float: each channel's sensor noise estimated from the template itself [input units].

    The median absolute second difference: white noise of standard deviation s has second
    differences of standard deviation sqrt(6) s, while a motion sampled densely enough has
    second differences near zero, so the median (robust to the motion's few sharp turns)
    measures the noise: ``median |x[t+1] - 2 x[t] + x[t-1] - m| / (0.6745 sqrt(6))`` with ``m``
    the median second difference. Zeros for templates of fewer than 3 frames."""
    if template.shape[0] < 3:
        return np.zeros(template.shape[1])
    second = np.diff(template, n=2, axis=0)
    mad = np.median(np.abs(second - np.median(second, axis=0)), axis=0)
    return mad / (0.6745 * math.sqrt(6.0))


def exact_scale(template: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(D,) float: the scale of a bank's exact-repetition model for one template, relative to
    the follower's default ``sigma (T, D)``: the template's own noise (``noise_sigma``) per
    channel, clipped to [``EXACT_FLOOR``, 1] times the default. A performer's own take
    replayed differs from the demonstration by about its sensor noise; a channel noisier than
    the default sigma (repetitive activities) keeps the default, and a nearly noiseless one
    (GunPoint's smoothed positions: 0.3 % of their spread) is floored at a quarter of it."""
    base = np.median(sigma, axis=0)
    ratio = noise_sigma(template) / base
    return np.clip(ratio, EXACT_FLOOR, 1.0)


def default_window(length: int) -> int:
    """Window half-width p [states] for a template of ``length`` frames."""
    return int(min(length, max(WINDOW_MIN, math.ceil(WINDOW_FRACTION * length))))


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
