"""An action from several demonstrations: one template, and how far takes of it stray.

A performer never repeats an action exactly, and neither does the author: several takes of
one action show what varies from take to take (intensity here, a pause there) and what does
not. ``combine`` turns them into one :class:`Demonstrations`:

- **template** (T, D): the takes averaged after aligning them in time (dynamic time
  warping barycentre averaging: each take is aligned to the current average, every average
  frame becomes the mean of the take frames aligned to it, repeated), as long as the take of
  median length. One template per action keeps a bank's cost per frame that of one take.
- **spread** (T, D): per template frame and channel, how far the takes lie from the
  template where a follower of the template places them (the root mean square of their
  residuals, smoothed over a few percent of the template, times ``n / (n - 1)`` for the
  takes' own share in the average). A take of the action by another performer strays about
  as far; a follower adds this to its emission sigma (``FollowerConfig.spread_weight``).
  Dynamic time warping alone would not measure it: it bends each take onto the average
  frame by frame and leaves almost no residual, where a follower's tempo model cannot.
- **noise** (D,): the takes' own sensor noise (the median over takes of
  ``defaults.noise_sigma``; None for one take, whose noise a bank measures with the others').
- **distances** (n,): each take's root mean square residual in units of the template's
  channel spread: how consistent the takes are, and which one is the outlier
  (:meth:`Demonstrations.outlier`).

One take gives its own frames as the template and zero spread.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from followers.config import FollowerConfig
from followers.defaults import as_template, moving_channels, noise_sigmas, pooled_sigma

# rounds of aligning every take to the average and averaging again (Wiimote pick-up, five
# takes: the largest change of a frame in the fifth round is 0.06 of the channel's spread)
AVERAGE_ROUNDS = 5
# half-width of the smoothing of the spread, as a fraction of the template (at least 2 frames):
# five takes give five residuals per frame, too few for a spread of their own
SPREAD_SMOOTHING = 0.03
# a take is called the outlier when its distance exceeds the others' median by this factor
OUTLIER_FACTOR = 1.5
# aligning two takes holds two (S + 1) x (N + 1) float tables: at most this many cells each
# (16 bytes a cell: 0.8 GB), about two takes of 7,000 frames
ALIGN_CELLS = 50_000_000


@dataclass(frozen=True)
class Demonstrations:
    """Several takes of one action, combined (see the module docstring).

    template : (T, D) float [input units]; spread : (T, D) float >= 0 [input units];
    noise : (D,) float [input units] (None for one take); distances : (n,) float [template
    channel spreads];
    lengths : (n,) int: each take's frames; takes : the n (T_i, D) takes, validated.
    """

    template: np.ndarray
    spread: np.ndarray
    noise: np.ndarray | None
    distances: np.ndarray
    lengths: np.ndarray
    takes: tuple

    @property
    def count(self) -> int:
        return len(self.takes)

    def outlier(self) -> int | None:
        """Index of the take that strays most from the others, if it strays more than
        ``OUTLIER_FACTOR`` times the others' median distance (None with fewer than 3 takes
        or when none does)."""
        if self.count < 3:
            return None
        worst = int(np.argmax(self.distances))
        others = np.delete(self.distances, worst)
        return worst if self.distances[worst] > OUTLIER_FACTOR * np.median(others) else None


def is_takes(value) -> bool:
    """True when ``value`` is several takes (a list or tuple of arrays), False for one array
    (or anything a template is made of: nested lists of numbers are one take)."""
    return isinstance(value, (list, tuple)) and len(value) > 0 and all(
        isinstance(v, np.ndarray) for v in value)


def _align(reference, take, weight):
    """For each frame of ``reference (S, D)``, the first and last frame of ``take (N, D)``
    aligned to it by dynamic time warping (channel-weighted squared distances, steps (1, 0),
    (0, 1), (1, 1); a channel of weight 0 left out): (S, 2) int64."""
    kept = weight > 0.0
    a = reference[:, kept] * np.sqrt(weight[kept])
    b = take[:, kept] * np.sqrt(weight[kept])
    distance = (a * a).sum(axis=1)[:, None] + (b * b).sum(axis=1)[None, :] - 2.0 * (a @ b.T)
    return warp(np.maximum(distance, 0.0))


@nb.njit(cache=True)
def warp(distance):
    """The alignment of ``_align`` from its (S, N) matrix of frame distances: for each row, the
    first and last column on the dynamic-time-warping path (S, 2) int64."""
    S, N = distance.shape
    cost = np.full((S + 1, N + 1), np.inf)
    cost[0, 0] = 0.0
    for i in range(1, S + 1):
        for j in range(1, N + 1):
            c = distance[i - 1, j - 1]
            best = cost[i - 1, j - 1]
            if cost[i - 1, j] < best:
                best = cost[i - 1, j]
            if cost[i, j - 1] < best:
                best = cost[i, j - 1]
            cost[i, j] = c + best
    span = np.empty((S, 2), dtype=np.int64)
    span[:, 0] = N
    span[:, 1] = -1
    i, j = S, N
    while i > 0 and j > 0:
        if j - 1 < span[i - 1, 0]:
            span[i - 1, 0] = j - 1
        if j - 1 > span[i - 1, 1]:
            span[i - 1, 1] = j - 1
        diag, up, left = cost[i - 1, j - 1], cost[i - 1, j], cost[i, j - 1]
        if diag <= up and diag <= left:
            i -= 1
            j -= 1
        elif up <= left:
            i -= 1
        else:
            j -= 1
    return span


def average(takes: list[np.ndarray], weight: np.ndarray, rounds: int = AVERAGE_ROUNDS):
    """The takes' average after alignment (T, D), T the median take length: starting from
    the take of median length, ``rounds`` times align every take to the average and replace
    each average frame by the mean of the take frames aligned to it."""
    order = np.argsort([t.shape[0] for t in takes], kind="stable")
    mean = takes[order[(len(takes) - 1) // 2]].copy()
    if len(takes) == 1:
        return mean
    for _ in range(rounds):
        total = np.zeros_like(mean)
        count = np.zeros(mean.shape[0])
        for take in takes:
            span = _align(mean, take, weight)
            csum = np.vstack([np.zeros((1, take.shape[1])), np.cumsum(take, axis=0)])
            total += csum[span[:, 1] + 1] - csum[span[:, 0]]
            count += span[:, 1] - span[:, 0] + 1
        mean = total / count[:, None]
    return mean


def _smooth(values: np.ndarray, half: int) -> np.ndarray:
    """Moving sum over +-``half`` rows of (T, ...) ``values``, edges held."""
    padded = np.concatenate([np.repeat(values[:1], half, axis=0), values,
                             np.repeat(values[-1:], half, axis=0)])
    csum = np.concatenate([np.zeros((1,) + values.shape[1:]), np.cumsum(padded, axis=0)])
    return csum[2 * half + 1:] - csum[:-2 * half - 1]


def residuals(template: np.ndarray, take: np.ndarray, config: FollowerConfig):
    """Where a follower of ``template`` with the default sigma (``config``) places each frame
    of ``take``, and the squared residual there: (position (N,) [template frames], squared
    residual (N, D))."""
    from followers.follower import Follower  # the follower module imports this one
    trace = Follower(template, config=config).follow(take)
    position = trace.progress * (template.shape[0] - 1)
    low = np.minimum(np.floor(position).astype(np.int64), template.shape[0] - 2)
    w = (position - low)[:, None]
    expected = (1.0 - w) * template[low] + w * template[low + 1]
    return position, (take - expected) ** 2


def spread_of(template: np.ndarray, takes: list[np.ndarray], config: FollowerConfig):
    """(spread (T, D), each take's mean squared residual (n, D)): see the module docstring."""
    T, D = template.shape
    total = np.zeros((T, D))
    count = np.zeros(T)
    per_take = []
    for take in takes:
        position, square = residuals(template, take, config)
        low = np.minimum(np.floor(position).astype(np.int64), T - 2)
        w = position - low
        np.add.at(total, low, (1.0 - w)[:, None] * square)
        np.add.at(total, low + 1, w[:, None] * square)
        np.add.at(count, low, 1.0 - w)
        np.add.at(count, low + 1, w)
        per_take.append(square.mean(axis=0))
    half = max(2, int(round(SPREAD_SMOOTHING * T)))
    variance = _smooth(total, half) / np.maximum(_smooth(count, half), 1e-12)[:, None]
    n = len(takes)
    return np.sqrt(variance * n / (n - 1)), np.array(per_take)


def _validated(takes, name: str) -> list[np.ndarray]:
    """The takes (one array, or a list of them) as validated (T_i, D) arrays of one D, short
    enough to align."""
    if not is_takes(takes):
        takes = [as_template(takes, name=name)]
    else:
        takes = [as_template(t, name=f"{name}, take {i}") for i, t in enumerate(takes)]
    D = takes[0].shape[1]
    for i, take in enumerate(takes):
        if take.shape[1] != D:
            raise ValueError(f"every take of {name} needs the same channels: take 0 has {D}, "
                             f"take {i} has {take.shape[1]}")
    longest = max(t.shape[0] for t in takes)
    if len(takes) > 1 and longest * int(np.median([t.shape[0] for t in takes])) > ALIGN_CELLS:
        raise ValueError(f"the takes of {name} are too long to align (the longest has {longest} "
                         f"frames; aligning it would take {longest ** 2 * 16 / 1e9:.1f} GB or "
                         f"so): cut each take to the action itself")
    return takes


def combine(takes, *, config: FollowerConfig | None = None, name: str = "action",
            template: np.ndarray | None = None) -> Demonstrations:
    """Several takes of one action (a list of (T_i, D) arrays, or one array) as one
    :class:`Demonstrations`; ``config``: the followers' settings (the default sigma that
    weighs channels in the alignment; the chain of the follower that measures the spread, at
    one state per frame and a fixed sigma). ``name`` names the action in errors.
    ``template`` (T, D), optional: the takes' template made elsewhere (a trained HMM's means,
    say), around which their spread is measured; default: their average (``average``).

    Raises ValueError for takes with different channels, too short or with non-finite values;
    TypeError for what is not an array."""
    config = FollowerConfig() if config is None else config
    takes = _validated(takes, name)
    lengths = np.array([t.shape[0] for t in takes])
    if template is not None:
        template = as_template(template, name=f"template of {name}")
        if template.shape[1] != takes[0].shape[1]:
            raise ValueError(f"the template of {name} has {template.shape[1]} channels, its "
                             f"takes {takes[0].shape[1]}")
    if len(takes) == 1:
        one = takes[0] if template is None else template
        return Demonstrations(one, np.zeros_like(one), None, np.zeros(1), lengths, tuple(takes))
    noise = np.median(noise_sigmas(takes), axis=0)
    base = pooled_sigma(takes, config)
    moving = moving_channels(takes)
    if template is None:  # a channel that never moves aligns nothing and keeps its value
        template = average(takes, np.where(moving, 1.0 / base ** 2, 0.0))
        template[:, ~moving] = takes[0][0, ~moving]
    measuring = config.replace(resolution=1, adapt_sigma=False, tempo_variance=False)
    spread, per_take = spread_of(template, takes, measuring)
    scale = np.maximum(template.std(axis=0), base)
    distances = np.sqrt((per_take / scale ** 2)[:, moving].mean(axis=1))
    return Demonstrations(template, spread, noise, distances, lengths, tuple(takes))
