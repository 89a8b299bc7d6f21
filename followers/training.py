"""A follower from several demonstrations of one action: a left-to-right HMM trained with
Baum–Welch, keeping the left-to-right topology.

The chain has one state per frame of a typical demonstration and the transitions
``i -> i, i + 1, i + 2``; no other transition exists, so training keeps that topology. The
chain starts in the first state. The means start from the demonstrations aligned by dynamic
time warping; the forward-backward pass runs in log space on the band of the transition
matrix (``followers._baum_welch``), so no demonstration underflows and a step costs S (2 +
skips) per frame, not S². Each variance is at least ``(0.05 rms spread)²`` of the
demonstrations (the constrained maximum, so every iteration still raises the likelihood).

``train_follower`` makes a follower of the model's means that carries its demonstrations
(``followers.demos.combine`` around those means): its sigma is widened per state by how far
the takes stray from the template, as a follower of several takes is, and a bank uses the
takes as it uses an action's several takes. By default it runs no Baum–Welch update: the
demonstrations aligned and averaged recognise other performers better than the maximum-
likelihood means, which fit the demonstrations ever closer (states one demonstration skips
and another dwells in; see ``docs/design/followers.md``).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numba as nb
import numpy as np

from followers._baum_welch import accumulate, emission_log, forward_backward
from followers.config import FollowerConfig
from followers.defaults import as_template
from followers.demos import combine, warp
from followers.follower import Follower, resolve_config
from followers.preprocessing import resample

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainedModel:
    """The outcome of :func:`train_hmm`.

    means : (S, D) float [input units]; sigma : (S, D) float [input units]
    transitions : (S, S) float: trained transition matrix (left-to-right)
    log_likelihoods : (I,) float: total log-likelihood of the demonstrations before each
        Baum–Welch update [nats] (non-decreasing up to rounding; empty for no update)
    seconds : float: the time training took
    """

    means: np.ndarray
    sigma: np.ndarray
    transitions: np.ndarray
    log_likelihoods: np.ndarray
    seconds: float


def left_to_right(states: int, *, skips: int = 1) -> np.ndarray:
    """(S, S) transition matrix: from state i, uniform over i .. i + 1 + skips (clipped at the
    end; the last state is absorbing)."""
    matrix = np.zeros((states, states))
    for i in range(states):
        last = min(states - 1, i + 1 + skips)
        matrix[i, i:last + 1] = 1.0 / (last - i + 1)
    return matrix


@nb.njit(cache=True)
def _squared_distances(reference, other):
    """(S, N) squared Euclidean distances between the frames of ``reference (S, D)`` and
    ``other (N, D)``."""
    S, N = reference.shape[0], other.shape[0]
    distance = np.empty((S, N))
    for i in range(S):
        for j in range(N):
            c = 0.0
            for d in range(reference.shape[1]):
                diff = reference[i, d] - other[j, d]
                c += diff * diff
            distance[i, j] = c
    return distance


def _dtw_map(reference, other):
    """For each frame of ``other (N, D)``, the frame of ``reference (S, D)`` it aligns with
    under dynamic time warping (squared Euclidean cost, steps (1,0), (0,1), (1,1)); where
    several reference frames share it, the first. Returns (N,) int64."""
    span = warp(_squared_distances(reference, other))
    mapping = np.zeros(other.shape[0], dtype=np.int64)
    for i in range(span.shape[0] - 1, -1, -1):
        mapping[span[i, 0]:span[i, 1] + 1] = i
    return mapping


def aligned_statistics(demos: list[np.ndarray], states: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-state mean and variance of the demonstrations after aligning each with dynamic time
    warping to the demonstration whose length is the median, stretched to ``states`` frames.

    demos : list of (T_i, D) float. Returns means (S, D) and variances (S, D) [input units]."""
    order = np.argsort([d.shape[0] for d in demos])
    reference = resample(demos[order[len(order) // 2]], states)
    total = np.zeros_like(reference)
    total_sq = np.zeros_like(reference)
    count = np.zeros(states)
    for d in demos:
        mapping = _dtw_map(reference, d)
        np.add.at(total, mapping, d)
        np.add.at(total_sq, mapping, d ** 2)
        np.add.at(count, mapping, 1.0)
    seen = count > 0
    means = reference.copy()
    means[seen] = total[seen] / count[seen, None]
    var = np.zeros_like(reference)
    var[seen] = np.maximum(total_sq[seen] / count[seen, None] - means[seen] ** 2, 0.0)
    return means, var


def train_hmm(demonstrations, *, states: int | None = None, iterations: int = 10,
              skips: int = 1) -> TrainedModel:
    """Train a left-to-right Gaussian HMM (diagonal covariances) on demonstrations of one action.

    demonstrations : list of (T_i, D) float arrays [input units] (gaps filled; one is allowed).
    states : int, optional: number of states. Default: the median demonstration length.
    iterations : int >= 0: Baum–Welch iterations (0: the demonstrations aligned by dynamic
    time warping to the median-length one and averaged per state, the starting point).
    skips : int >= 0: states a transition may skip.
    """
    if isinstance(demonstrations, np.ndarray):
        demonstrations = [demonstrations]
    demos = [as_template(d, name=f"demonstration {i}") for i, d in enumerate(demonstrations)]
    if not demos:
        raise ValueError("train_hmm needs at least one demonstration, got none")
    D = demos[0].shape[1]
    for i, d in enumerate(demos):
        if d.shape[1] != D:
            raise ValueError(f"every demonstration needs the same channels: demonstration 0 has "
                             f"{D}, demonstration {i} has {d.shape[1]}")
    lengths = np.array([d.shape[0] for d in demos])
    S = int(np.median(lengths)) if states is None else int(states)
    if S < 2:
        raise ValueError(f"states must be >= 2, got {S}")
    if int(iterations) < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}")
    if int(skips) < 0:
        raise ValueError(f"skips must be >= 0, got {skips}")
    shortest = lengths.min()
    if S > shortest * (2 + skips) - 1:
        raise ValueError(f"{S} states cannot be crossed in {shortest} frames with {skips} skip(s);"
                         f" use fewer states or more skips")

    # initial means and spreads: the demonstrations aligned by dynamic time warping to the
    # median-length one, then averaged per state (Baum-Welch only refines from there)
    began = time.perf_counter()
    means, var = aligned_statistics(demos, S)
    pooled = np.concatenate(demos, axis=0).std(axis=0)
    floor = (0.05 * max(float(np.sqrt(np.mean(pooled ** 2))), 1e-6)) ** 2
    var = var + floor
    log_a = _banded(left_to_right(S, skips=int(skips)), int(skips) + 2)
    history = baum_welch(demos, means, var, log_a, int(iterations), floor)
    transitions = _dense(log_a)
    log.debug("trained %d-state left-to-right HMM on %d demonstrations: log-likelihood %s",
              S, len(demos), history)
    return TrainedModel(means=means, sigma=np.sqrt(var), transitions=transitions,
                        log_likelihoods=history, seconds=time.perf_counter() - began)


def _banded(matrix: np.ndarray, J: int) -> np.ndarray:
    """(S, J) log transition probabilities i -> i + j of a left-to-right ``matrix (S, S)``."""
    S = matrix.shape[0]
    band = np.zeros((S, J))
    for j in range(J):
        band[:S - j, j] = np.diagonal(matrix, j)
    with np.errstate(divide="ignore"):
        return np.log(band)


def _dense(log_a: np.ndarray) -> np.ndarray:
    S, J = log_a.shape
    matrix = np.zeros((S, S))
    for j in range(J):
        matrix[np.arange(S - j), np.arange(j, S)] = np.exp(log_a[:S - j, j])
    return matrix


def baum_welch(demos: list[np.ndarray], means: np.ndarray, var: np.ndarray, log_a: np.ndarray,
               iterations: int, floor: float) -> np.ndarray:
    """``iterations`` Baum–Welch updates of ``means``, ``var`` (S, D) and the banded log
    transitions ``log_a`` (S, J), in place; each variance at least ``floor``. A state no
    demonstration visits keeps its values. Returns the log-likelihood before each update."""
    S, D = means.shape
    history = np.empty(iterations)
    work = [(np.empty((d.shape[0], S)), np.empty((d.shape[0], S)), np.empty((d.shape[0], S)))
            for d in demos]
    for it in range(iterations):
        weight, first, second = np.zeros(S), np.zeros((S, D)), np.zeros((S, D))
        moves = np.zeros_like(log_a)
        total = 0.0
        for x, (log_b, alpha, beta) in zip(demos, work):
            emission_log(x, means, var, log_b)
            loglik = forward_backward(log_b, log_a, alpha, beta)
            accumulate(x, log_b, log_a, alpha, beta, loglik, weight, first, second, moves)
            total += loglik
        history[it] = total
        seen = weight > 1e-12 * max(1.0, weight.max())
        w = weight[seen, None]
        means[seen] = first[seen] / w
        var[seen] = np.maximum(second[seen] / w - means[seen] ** 2, floor)
        rows = moves.sum(axis=1)
        moving = rows > 0.0
        with np.errstate(divide="ignore"):
            log_a[moving] = np.log(moves[moving] / rows[moving, None])
    return history


def train_follower(demonstrations, *, states: int | None = None, iterations: int = 0,
                   window=None, transitions=None, config=None) -> Follower:
    """A :class:`~followers.Follower` from several demonstrations of one action.

    The template is the means of :func:`train_hmm` (``states``, ``iterations``; by default
    the demonstrations aligned and averaged, without a Baum–Welch update), and the follower
    carries the demonstrations combined around it (``followers.demos.combine``): its sigma
    and, in a bank, the action's are the default widened per state by their spread, as for a
    follower of several takes. The follower uses its own ``transitions`` (default
    ``"speed"``), not the trained ones: those describe the tempo of the demonstrations, while
    a performer is followed from 0.4x to 2.5x of it."""
    trained = train_hmm(demonstrations, states=states, iterations=iterations)
    config = resolve_config(config, transitions, FollowerConfig.preset)
    combined = combine(demonstrations, config=config, name="demonstrations",
                       template=trained.means)
    return Follower(combined, window=window, transitions=transitions, config=config)
