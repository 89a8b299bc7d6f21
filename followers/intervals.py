"""Honest progress intervals when the performer differs from the demonstration.

A follower's progress variance is the spread of its posterior over template positions. The
posterior treats every frame's residual (input minus template at the position) as
independent noise, and so it grows confident as frames accumulate. A performer who differs
from the demonstration by a gain, an offset or a smoother hand leaves a residual that is
the *same* from frame to frame: frames agree with each other without adding information,
and the interval holding the truth 90 % of the time on a replayed take holds it 60-70 % of
the time for such a performer.

The report is corrected, the recursion left alone: per frame the residual at the reported
position, divided by the emission sigma there, is averaged over channels; an exponential
window (``FollowerConfig.residual_memory`` frames; each residual clipped at
``outlier_sigmas``) estimates its lag-one autocorrelation
``rho``; the variance is multiplied by ``(1 + rho) / (1 - rho)`` (the variance of a mean of
AR(1) samples against independent ones) and by the residual's mean square where it exceeds 1
(a performer further from the template than its sigma says), at most ``residual_cap``. The
mean square is the window's average over the frames seen so far (the exponential average
divided by its weights' sum), so the first frames of a performance count in full rather than
as if preceded by a perfect fit. What the factor adds, ``factor - 1`` times the variance, is
taken of the variance plus that of a uniform position within one state (1/12 of a state's
width squared, ``FollowerConfig.resolution`` states per template frame): a posterior on one
state has almost no variance, while a performer who differs is off by a part of a state that
no factor of it reaches. Independent residuals within the sigma (the demonstration replayed)
leave the interval as it was.

A lone follower's recursion is tempered by the same correlation, from the posterior's mean
residual, at most ``FollowerConfig.residual_temper`` times (``_kernels._temper``): correlated
frames count as fewer frames there too, so that a level the template does not reach does not
pull the follower off to where the template meets it. The report is widened on top as above.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

# the autocorrelation is clipped to [0, RHO_MAX]
RHO_MAX = 0.95
# state layout: lag-one sum, lag-zero sum, the weights' sum, then the previous residual per
# channel
_HEAD = 3


def interval_state(channels: int) -> np.ndarray:
    """A fresh state for :func:`widen` (reset it with :func:`reset_interval`)."""
    state = np.empty(_HEAD + channels)
    reset_interval(state)
    return state


def reset_interval(state: np.ndarray) -> None:
    state[0] = 0.0
    state[1] = 1e-9
    state[2] = 0.0
    state[_HEAD:] = 0.0


@nb.njit(cache=True)
def widen(templates, sigmas, offsets, which, X, progress, variance, memory, cap, clip,
          resolution, state):
    """Widen ``variance (N,)`` in place by each frame's correlation and fit factor.

    templates, sigmas : (sum T_k, D) the followers' templates and sigmas stacked;
    offsets, lengths implied: template ``k`` is rows ``offsets[k]:offsets[k + 1]``;
    which : (N,) int: the template each frame's ``progress`` is on (< 0: none, the frame is
    left alone); X : (N, D) input (NaN, inf: missing; a channel of infinite sigma, one that
    never moves, is left out); memory [frames]; cap [x variance];
    clip [sigmas]: a residual counts at most this far (an absurd value, an outlier, would
    hold the estimate for many frames); resolution : states per template frame; state : see
    ``interval_state``, carried across calls."""
    decay = math.exp(-1.0 / memory)
    D = X.shape[1]
    for n in range(X.shape[0]):
        k = which[n]
        if k < 0:
            continue
        start = offsets[k]
        T = offsets[k + 1] - start
        position = progress[n] * (T - 1)
        low = min(int(position), T - 2)
        w = position - low
        lag1 = 0.0
        lag0 = 0.0
        seen = 0
        for d in range(D):
            x = X[n, d]
            a = start + low
            scale = (1.0 - w) * sigmas[a, d] + w * sigmas[a + 1, d]
            if not (math.isfinite(x) and math.isfinite(scale)):
                state[_HEAD + d] = 0.0
                continue
            expected = (1.0 - w) * templates[a, d] + w * templates[a + 1, d]
            r = min(max((x - expected) / scale, -clip), clip)
            lag1 += r * state[_HEAD + d]
            lag0 += r * r
            state[_HEAD + d] = r
            seen += 1
        if seen > 0:
            state[0] = decay * state[0] + (1.0 - decay) * lag1 / seen
            state[1] = decay * state[1] + (1.0 - decay) * lag0 / seen
            state[2] = decay * state[2] + (1.0 - decay)
        rho = min(max(state[0] / state[1], 0.0), RHO_MAX)
        square = state[1] / state[2] if state[2] > 0.0 else 0.0
        factor = min(cap, (1.0 + rho) / (1.0 - rho) * max(1.0, square))
        width = 1.0 / (resolution * (T - 1))    # a state [progress]
        variance[n] += (factor - 1.0) * (variance[n] + width * width / 12.0)


def widen_arguments(intervals, config, which, X, progress, variance, state):
    """``widen``'s arguments for the ``stacked`` templates ``intervals`` under a
    ``FollowerConfig``; None when the config does not widen (``residual_cap`` <= 1)."""
    if not config.residual_cap > 1.0:
        return None
    return (*intervals, which, X, progress, variance, config.residual_memory,
            config.residual_cap, min(config.outlier_sigmas, 1e300), float(config.resolution),
            state)


def stacked(templates, sigmas, moving=None):
    """(templates (sum T_k, D), sigmas (sum T_k, D), offsets (K + 1,) int64) for ``widen``;
    the sigma of a channel that never moves (``moving (D,)`` false; None: every one moves)
    infinite."""
    offsets = np.zeros(len(templates) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([t.shape[0] for t in templates])
    scales = np.concatenate([np.broadcast_to(s, t.shape) for t, s in zip(templates, sigmas)],
                            axis=0)
    if moving is not None and not moving.all():
        scales[:, ~moving] = np.inf
    return (np.ascontiguousarray(np.concatenate(templates, axis=0)),
            np.ascontiguousarray(scales), offsets)
