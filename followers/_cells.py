"""Numba kernels that place a follower's position *inside* a state's cell.

Each state of the posterior stands for its cell, half a template frame either side of it. The
performer is placed along the template's straight segments to the neighbouring frames by this
frame's emission there, with the prediction's slope across the cell as prior (``_tilt``), so
progress and variance hold the position between template frames, not only which state. The
recursion itself is unchanged; only what is reported.
"""
from __future__ import annotations

import math

import numpy as np

from followers._jit import inline, kernel

_SQRT2 = math.sqrt(2.0)
_SQRT_2PI = math.sqrt(2.0 * math.pi)
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


@kernel
def _truncated_exponential(rate, h):
    """v in [0, h] with density proportional to exp(-rate v), rate > 0: (log of the integral of
    exp(-rate v) over [0, h], mean, mean square)."""
    q = math.exp(-rate * h)
    ratio = q / (1.0 - q)
    return (math.log1p(-q) - math.log(rate), 1.0 / rate - h * ratio,
            2.0 / (rate * rate) - (h * h + 2.0 * h / rate) * ratio)


@kernel
def _half_cell(a, n, h):
    """v in [0, h] with density proportional to exp(a v - n v**2 / 2), n >= 0 (the position
    posterior along one template segment): (log of its integral, mean, mean square)."""
    if n * h * h < 1e-8:
        # (nearly) no curvature over the interval: a truncated exponential, or uniform
        if abs(a * h) < 1e-6:
            return math.log(h), 0.5 * h, h * h / 3.0
        if a < 0.0:
            return _truncated_exponential(-a, h)
        logz, mean, square = _truncated_exponential(a, h)
        return a * h + logz, h - mean, h * h - 2.0 * h * mean + square
    s = 1.0 / math.sqrt(n)
    m = a / n
    lo = -m / s
    hi = (h - m) / s
    if lo > 35.0 or hi < -35.0:
        # the mode lies far outside (erfc would underflow): only the Gaussian's tail is inside,
        # an exponential from the nearer end, its curvature to first order (c: about the
        # distance in standard deviations to the power -2)
        slope = a if lo > 35.0 else n * h - a
        logz, mean, square = _truncated_exponential(-slope, h)
        c = n / (slope * slope)
        logz += math.log1p(-c)
        mean *= 1.0 - 2.0 * c
        square *= 1.0 - 5.0 * c
        if lo > 35.0:
            return logz, mean, square
        return a * h - 0.5 * n * h * h + logz, h - mean, h * h - 2.0 * h * mean + square
    if lo > 0.0:
        z = 0.5 * (math.erfc(lo / _SQRT2) - math.erfc(hi / _SQRT2))
    elif hi < 0.0:
        z = 0.5 * (math.erfc(-hi / _SQRT2) - math.erfc(-lo / _SQRT2))
    else:
        z = 0.5 * (math.erf(hi / _SQRT2) - math.erf(lo / _SQRT2))
    if not z > 0.0:
        return -np.inf, 0.5 * h, h * h / 3.0
    phi_lo = math.exp(-0.5 * lo * lo) / _SQRT_2PI
    phi_hi = math.exp(-0.5 * hi * hi) / _SQRT_2PI
    shift = (phi_lo - phi_hi) / z
    mean = m + s * shift
    var = s * s * (1.0 + (lo * phi_lo - hi * phi_hi) / z - shift * shift)
    if mean < 0.0:
        mean = 0.0
    elif mean > h:
        mean = h
    if var < 0.0:
        var = 0.0
    return 0.5 * a * m + math.log(s) + _LOG_SQRT_2PI + math.log(z), mean, var + mean * mean


@inline
def _segment(model, state, inv_scale2, j, other):
    """The squared z-distance from x to the point u of the way from template row j to row
    ``other`` is ``r_j - 2 a u + n u**2`` over the observed channels not at the cap (each
    channel d contributing ``g_d = w_d step_d**2`` to n). Returns (a, n, pa, pb, pc): with
    them the same distance *along the segment's direction*, each channel's squared z-score
    weighted by its share ``g_d / n`` of the position's information, is
    ``(pa - 2 pb u + pc u**2) / n``; the report's scale is learned from that (a position
    placed by channels that move is only as uncertain as their noise)."""
    templates, weights, xs, observed = model.templates, model.weights, state.xs, state.observed
    a = 0.0
    n = 0.0
    pa = 0.0
    pb = 0.0
    pc = 0.0
    for d in range(xs.shape[0]):
        w = weights[0, j, d] * observed[d] * inv_scale2
        diff = xs[d] - templates[j, d]
        if w * diff * diff < model.cap:
            step = templates[other, d] - templates[j, d]
            a += w * diff * step
            g = w * step * step
            n += g
            pa += g * w * diff * diff
            pb += g * w * diff * step
            pc += g * g
    return a, n, pa, pb, pc


@kernel
def _along(pa, pb, pc, n, mean, square):
    """Expected squared z-score along a segment (``_segment``) under an offset with this mean
    and mean square; -1 for a segment of zero length (nothing to learn from)."""
    if not n > 0.0:
        return -1.0
    return (pa - 2.0 * mean * pb + square * pc) / n


@inline
def _tilt(state, track, r, other, limit):
    """The prior's slope across the cell of row r towards row ``other`` (its neighbour): the
    log-ratio of their predicted masses (posterior over this frame's emission), within
    +-``limit``; -``limit`` when the neighbour holds nothing."""
    rowsum, logb = state.rowsum, state.logb
    v = rowsum[track, other]
    if v <= 0.0:
        return -limit
    c = math.log(v / rowsum[track, r]) - (logb[0, other] - logb[0, r])
    return -limit if c < -limit else (limit if c > limit else c)


@inline
def _side(model, state, track, inv_scale2, r, other):
    """One side of row r's cell, towards ``other``: (log weight, mean offset, mean square,
    expected squared z-score along it); see ``_segment`` and ``_half_cell``."""
    a, n, pa, pb, pc = _segment(model, state, inv_scale2, r, other)
    log_w, mean, square = _half_cell(a + _tilt(state, track, r, other, model.tilt), n, 0.5)
    return log_w, mean, square, _along(pa, pb, pc, n, mean, square)


@inline
def _cell(model, state, track, inv_scale2, r, j, T):
    """Row r (state j of a template of T states): (log weight of its cell, mean offset, mean
    square, expected squared z-score along the segments). The first and last states keep
    their position (progress stays 0 at rest and 1 at the end) and add only their spread
    towards their one neighbour."""
    if j == 0:
        log_f, _, square_f, along_f = _side(model, state, track, inv_scale2, r, r + 1)
        return log_f, 0.0, square_f, along_f
    if j == T - 1:
        log_b, _, square_b, along_b = _side(model, state, track, inv_scale2, r, r - 1)
        return log_b, 0.0, square_b, along_b
    log_f, mean_f, square_f, along_f = _side(model, state, track, inv_scale2, r, r + 1)
    log_b, mean_b, square_b, along_b = _side(model, state, track, inv_scale2, r, r - 1)
    top = log_f if log_f > log_b else log_b
    wf = math.exp(log_f - top)
    wb = math.exp(log_b - top)
    inv = 1.0 / (wf + wb)
    along = -1.0 if (along_f < 0.0 or along_b < 0.0) else (wf * along_f + wb * along_b) * inv
    return (top + math.log(wf + wb), (wf * mean_f - wb * mean_b) * inv,
            (wf * square_f + wb * square_b) * inv, along)


@inline
def subframe_rows(model, state, k, track, inv_scale2, in_report):
    """Where inside its cell each state of template k's ``track`` puts the performer, at the
    report's scale (``inv_scale2``; ``in_report``: the recursion's scale**2 over the
    report's).

    state.sub (4, S) out, for the rows of states holding more than 1e-6 (others 0): the mean
    offset [states], its mean square, the expected squared z-score along the template's
    direction there (-1 where a segment has zero length), and the weight of the cell: its
    state's mass, the point emission of the recursion swapped for the report's emission
    integrated over the cell, summing to 1."""
    off, T = model.offsets[k], model.lengths[k]
    first, last = state.support[k, track, 0], state.support[k, track, 1]
    sub, rowsum, residual = state.sub, state.rowsum, state.residual
    top_weight = -np.inf
    for j in range(first, last + 1):
        r = off + j
        sub[0, r] = 0.0
        sub[1, r] = 0.0
        sub[2, r] = 0.0
        sub[3, r] = -np.inf
        if rowsum[track, r] <= 1e-6:
            continue
        cell, sub[0, r], sub[1, r], sub[2, r] = _cell(model, state, track, inv_scale2, r, j, T)
        w = math.log(rowsum[track, r]) + 0.5 * residual[r] * (1.0 - in_report) + cell
        sub[3, r] = w
        if w > top_weight:
            top_weight = w
    total = 0.0
    for j in range(first, last + 1):
        r = off + j
        w = math.exp(sub[3, r] - top_weight) if sub[3, r] > -np.inf else 0.0
        sub[3, r] = w
        total += w
    if total > 0.0:
        for j in range(first, last + 1):
            sub[3, off + j] /= total


@kernel
def subframe_moments(sub, off, first, last, T):
    """Mean and variance of a track's position [states], each state standing for its cell as
    ``subframe_rows`` placed and weighted it."""
    mass = 0.0
    mean = 0.0
    square = 0.0
    for j in range(first, last + 1):
        r = off + j
        v = sub[3, r]
        mass += v
        # positions relative to the first state keep the sums small
        at = j - first + sub[0, r]
        mean += v * at
        square += v * (at * at + sub[1, r] - sub[0, r] * sub[0, r])
    if mass <= 0.0:
        return 0.0, 0.0
    mean /= mass
    var = square / mass - mean * mean
    # rounding must not carry the position past either end of the template
    return min(max(first + mean, 0.0), T - 1.0), max(var, 0.0)
