"""Numba kernels of the windowed forward algorithm, in stages.

Every kernel reads a ``model.ForwardModel`` (built once) and writes a ``model.ForwardState``
(see ``followers.model`` for the layout). One frame of template ``k`` (``template_step``):

1. ``_begin`` / ``_predict``: a fresh follower starts on its first state; otherwise each track
   keeps the states within ``p`` of its rounded mean (MOP equations 6-7; the entry track the
   first ``2p + 1``), mixes its speed levels and advances; a new repetition is seeded at the
   first state (``_seed_entry``).
2. ``_emit``: the emission of every state in either track's support.
3. ``_weigh``: the recognition scores (``frame_loglik`` rows 1-2) from the predicted states;
   each row times its emission, scaled by the largest so nothing under- or overflows however
   long the run, and divided by the per-frame normaliser (``_normalise`` when nothing is
   observed).
4. ``_adapt_scales``: the online emission scales (EM on one scalar per template).
5. ``_prune``: edge states holding almost nothing are dropped (beam pruning).
6. ``_finish``: each track's moments; the entry track takes over when it holds more mass.

The emission of state ``j`` under model ``e`` is the sum over observed channels ``d`` of
``-0.5 * min(w[e, j, d] * (x[d] - template[j, d])**2, cap) - 0.5 * log(2 pi sigma[e, j, d]**2)``
(``cap = inf``: the paper's plain Gaussian, equation 1). With ``p >= T`` and no restart this is
the full forward algorithm.
"""
from __future__ import annotations

import math

import numpy as np

from followers._cells import subframe_moments, subframe_rows
from followers._exp import exp_nonpositive
from followers._jit import inline, kernel, plain
from followers.config import FollowerConfig
from followers.intervals import RHO_MAX

# the default number of speed levels: the loops over one state's levels run a count the
# compiler knows for it (unrolled, no loop of unknown length per state)
LEVELS = FollowerConfig.speed_levels


@plain
def _row_total(row):
    """The sum of one state's levels, in order (compiled without reassociation, so that the
    order does not depend on whether, or how, a loop around it is vectorised)."""
    total = 0.0
    if row.shape[0] == LEVELS:
        for m in range(LEVELS):
            total += row[m]
    else:
        for m in range(row.shape[0]):
            total += row[m]
    return total


@inline
def _scale_row(row, f):
    """One state's levels times ``f``, in place."""
    if row.shape[0] == LEVELS:
        for m in range(LEVELS):
            row[m] *= f
    else:
        for m in range(row.shape[0]):
            row[m] *= f


@inline
def prepare_frame(model, state, x):
    """Clean one input frame ``x (D,)`` into ``state.xs`` and ``state.observed``: NaN is a
    missing channel (xs 0, observed 0), and so is a value outside [lower, upper] (+-inf, a
    stuck or absurd sensor: counted in ``state.outliers``). A channel that never moves in the
    demonstrations (``model.moving``) is left out too, unless it is an outlier. Returns the
    number of observed channels."""
    lower, upper, xs, observed = model.lower, model.upper, state.xs, state.observed
    count = 0
    outliers = 0
    for d in range(x.shape[0]):
        v = x[d]
        if v >= lower[d] and v <= upper[d]:  # False for NaN
            keep = model.moving[d]
            xs[d] = v if keep else 0.0
            observed[d] = 1.0 if keep else 0.0
            count += 1 if keep else 0
        else:
            xs[d] = 0.0
            observed[d] = 0.0
            if v == v:
                outliers += 1
    state.outliers[0] = outliers
    return count


@inline
def _emission_rows(model, state, k, first, last, all_observed, inv_scale2, norm_shift,
                   exact_shift):
    """``state.logb[e, j]`` for rows first..last: e = 0 the follower's model, its sigma times
    the online scale (``inv_scale2``; ``norm_shift = -n_obs log(scale)``); with ``model.dual``
    e = 1 the recognition model and e = 2 the exact-repetition component (model 0's sigma
    without the online scale, times the template's exact scale per channel; ``exact_shift``:
    minus the sum of its logs over the observed channels), else e = 1 a copy of e = 0.
    ``state.residual[j]``: the capped sum of squared z-scores of model 0."""
    templates, weights, cap, dual = model.templates, model.weights, model.cap, model.dual
    xs, observed, out = state.xs, state.observed, state.logb
    exact_scale2 = model.exact_inv2[k]
    D = xs.shape[0]
    # every channel observed at the unscaled sigma (the common case): the factors that are
    # exactly 1 left out
    plain = all_observed and inv_scale2 == 1.0
    for j in range(first, last + 1):
        acc = 0.0
        acc_rec = 0.0
        acc_exact = 0.0
        if dual and plain:
            for d in range(D):
                diff = xs[d] - templates[j, d]
                sq = diff * diff
                v = weights[0, j, d] * sq
                acc += v if v < cap else cap
                w = weights[1, j, d] * sq
                acc_rec += w if w < cap else cap
                v *= exact_scale2[d]
                acc_exact += v if v < cap else cap
        elif dual:
            for d in range(D):
                diff = xs[d] - templates[j, d]
                sq = observed[d] * diff * diff
                v = weights[0, j, d] * sq * inv_scale2
                acc += v if v < cap else cap
                v = weights[1, j, d] * sq
                acc_rec += v if v < cap else cap
                v = weights[0, j, d] * sq * exact_scale2[d]
                acc_exact += v if v < cap else cap
        else:
            for d in range(D):
                diff = xs[d] - templates[j, d]
                v = weights[0, j, d] * observed[d] * diff * diff * inv_scale2
                acc += v if v < cap else cap
        norm, norm_rec = _row_norm(model, state, j, all_observed)
        state.residual[j] = acc
        out[0, j] = norm + norm_shift - 0.5 * acc
        if dual:
            out[1, j] = norm_rec - 0.5 * acc_rec
            out[2, j] = norm + exact_shift - 0.5 * acc_exact
        else:
            out[1, j] = out[0, j]


@inline
def _row_norm(model, state, j, all_observed):
    """The normalising terms of row j's emission (models 0 and 1) over the observed channels."""
    log_norm, observed = model.log_norm, state.observed
    norm_rec = 0.0
    if all_observed:
        norm = model.log_norm_sum[0, j]
        if model.dual:
            norm_rec = model.log_norm_sum[1, j]
        return norm, norm_rec
    norm = 0.0
    for d in range(observed.shape[0]):
        norm += log_norm[0, j, d] * observed[d]
    if model.dual:
        for d in range(observed.shape[0]):
            norm_rec += log_norm[1, j, d] * observed[d]
    return norm, norm_rec


@inline
def _clear_rows(state, track, first, last):
    alpha, rowsum = state.alpha, state.rowsum
    for j in range(first, last + 1):
        rowsum[track, j] = 0.0
        for m in range(alpha.shape[2]):
            alpha[track, j, m] = 0.0


@inline
def _mix_speeds(model, state, track, first, last):
    """Rows first..last of a track, each speed level given its neighbours' share, into
    ``state.mixed`` rows A.. (A = the largest advance), with A zero rows on either side."""
    alpha, change, mixed = state.alpha, model.speed_change, state.mixed
    M = alpha.shape[2]
    A = model.advance.shape[0] - 1
    n = last - first + 1
    for i in range(A):
        for m in range(M):
            mixed[i, m] = 0.0
            mixed[n + A + i, m] = 0.0
    if M == 1:
        for i in range(n):
            mixed[A + i, 0] = alpha[track, first + i, 0]
        return
    if n * M <= model.change_tiled.shape[1]:
        _mix_flat(model, state, track, first, n)
        return
    stay, up, down = change[0], change[1], change[2]
    for i in range(n):
        row = alpha[track, first + i]
        out = mixed[A + i]
        out[0] = row[0] * stay[0] + row[1] * down[0]
        for m in range(1, M - 1):
            out[m] = row[m] * stay[m] + row[m - 1] * up[m] + row[m + 1] * down[m]
        out[M - 1] = row[M - 1] * stay[M - 1] + row[M - 2] * up[M - 1]


@inline
def _mix_flat(model, state, track, first, n):
    """``_mix_speeds`` of n rows (M > 1) as one pass over their n M values: a level's
    neighbours are the values either side, the levels at a row's ends taking nothing across
    it (their tiled coefficient is 0), so one loop runs over every row and level."""
    alpha = state.alpha
    S, M = alpha.shape[1], alpha.shape[2]
    base = (track * S + first) * M
    end = n * M - 1
    src = state.flat_alpha[base:base + end + 1]
    dst = state.flat_mixed[(model.advance.shape[0] - 1) * M:]
    stay, up, down = model.change_tiled[0], model.change_tiled[1], model.change_tiled[2]
    dst[0] = src[0] * stay[0] + src[1] * down[0]
    # views shifted by one value, so that every index is the loop's own
    below, at, above = src[:end - 1], src[1:end], src[2:]
    into, stay_at, up_at, down_at = dst[1:end], stay[1:end], up[1:end], down[1:end]
    for q in range(end - 1):
        into[q] = at[q] * stay_at[q] + below[q] * up_at[q] + above[q] * down_at[q]
    dst[end] = src[end] * stay[end] + src[end - 1] * up[end]


@inline
def _advance_row(mixed, i, target, by, keep_scale):
    """``target`` := keep_scale * sum over a of ``mixed`` row i - a times ``by[a]`` (per
    level); returns its mass."""
    M = target.shape[0]
    if by.shape[0] == 4:
        # the common case (every advance of the speed model), in one pass over the levels
        s0, s1, s2, s3 = mixed[i], mixed[i - 1], mixed[i - 2], mixed[i - 3]
        b0, b1, b2, b3 = by[0], by[1], by[2], by[3]
        for m in range(M):
            target[m] = (((s0[m] * b0[m] + s1[m] * b1[m]) + s2[m] * b2[m]) + s3[m] * b3[m]
                         ) * keep_scale
    else:
        for m in range(M):
            acc = 0.0
            for a in range(by.shape[0]):
                acc += mixed[i - a, m] * by[a, m]
            target[m] = acc * keep_scale
    # summed in a loop that writes nothing (see _lift_rows)
    return _row_total(target)


@inline
def _advance_flat(model, state, track, first, n, keep_scale):
    """``_advance_row`` of target rows first..first + n - 1 (none the absorbing last state,
    A = 3) as one pass over their n M values, then each row's mass."""
    alpha, rowsum = state.alpha, state.rowsum
    S, M = alpha.shape[1], alpha.shape[2]
    size = n * M
    base = (track * S + first) * M
    dst = state.flat_alpha[base:base + size]
    src = state.flat_mixed
    s0, s1, s2, s3 = src[3 * M:3 * M + size], src[2 * M:2 * M + size], src[M:M + size], \
        src[:size]
    by = model.advance_tiled
    b0, b1, b2, b3 = by[0], by[1], by[2], by[3]
    for q in range(size):
        dst[q] = (((s0[q] * b0[q] + s1[q] * b1[q]) + s2[q] * b2[q]) + s3[q] * b3[q]) \
            * keep_scale
    # summed in a loop that writes nothing (see _lift_rows)
    for i in range(n):
        rowsum[track, first + i] = _row_total(alpha[track, first + i])


@inline
def _predict_track(model, state, track, off, T, lo, hi, keep_scale):
    """Transition one track: truncated to states [lo, hi] of the template, speed levels
    mixed (``_mix_speeds``), advanced; the mass times ``keep_scale`` (1 - restart). Returns
    the last target state."""
    alpha, rowsum, mixed = state.alpha, state.rowsum, state.mixed
    A = model.advance.shape[0] - 1
    _mix_speeds(model, state, track, off + lo, off + hi)
    top = min(hi + A, T - 1)
    # target state j takes mixed row j - a (zero outside [lo, hi]) with ``advance[a]``; the
    # absorbing end takes every advance that would pass it (``advance_tail``)
    start = lo
    flat = top - lo if top == T - 1 else top - lo + 1
    if A == 3 and flat * alpha.shape[2] <= model.advance_tiled.shape[1]:
        _advance_flat(model, state, track, off + lo, flat, keep_scale)
        start = lo + flat
    for j in range(start, top + 1):
        by = model.advance_tail if j == T - 1 else model.advance
        rowsum[track, off + j] = _advance_row(mixed, j - lo + A, alpha[track, off + j], by,
                                              keep_scale)
    return top


@kernel
def _window(center, half, T):
    lo = center - half
    hi = center + half
    if lo < 0:
        hi -= lo
        lo = 0
    if hi > T - 1:
        lo -= hi - (T - 1)
        hi = T - 1
    if lo < 0:
        lo = 0
    return lo, hi


@kernel
def _moments(rowsum, track, off, first, last):
    mass = 0.0
    mean = 0.0
    for j in range(first, last + 1):
        v = rowsum[track, off + j]
        mass += v
        mean += v * j
    if mass <= 0.0:
        return 0.0, 0.0, 0.0
    # rounding must not carry the mean past the support (progress 1 + 2e-16 at the end)
    mean = min(max(mean / mass, float(first)), float(last))
    var = 0.0
    for j in range(first, last + 1):
        dj = j - mean
        var += rowsum[track, off + j] * dj * dj
    return mass, mean, var / mass


@kernel
def _argmax_row(rowsum, track, off, first, last):
    best = first
    best_v = -1.0
    for j in range(first, last + 1):
        if rowsum[track, off + j] > best_v:
            best_v = rowsum[track, off + j]
            best = j
    return best


@inline
def _begin(model, state, k):
    """A fresh follower: every track emptied, the main one on the first state with the
    initial speed distribution."""
    off = model.offsets[k]
    support = state.support
    for t in range(2):
        if support[k, t, 1] >= support[k, t, 0]:
            _clear_rows(state, t, off + support[k, t, 0], off + support[k, t, 1])
        support[k, t, 0] = 1
        support[k, t, 1] = 0
    state.main[k] = 0
    total = 0.0
    for m in range(model.initial_speed.shape[0]):
        state.alpha[0, off, m] = model.initial_speed[m]
        total += model.initial_speed[m]
    state.rowsum[0, off] = total
    support[k, 0, 0] = 0
    support[k, 0, 1] = 0
    state.fresh[k] = False


@inline
def _kept(model, state, k, t):
    """The states of template k's track t that its window keeps: (first, last)."""
    off, T, p = model.offsets[k], model.lengths[k], model.half_windows[k]
    first, last = state.support[k, t, 0], state.support[k, t, 1]
    if t != state.main[k]:
        # the entry track only holds repetitions that began recently: eq. 7's first case
        _, hi = _window(0, p, T)
        return first, min(hi, last)
    lo, hi = _window(int(math.floor(state.moments[k, t, 1] + 0.5)), p, T)
    kept_lo, kept_hi = max(lo, first), min(hi, last)
    kept = 0.0
    for j in range(kept_lo, kept_hi + 1):
        kept += state.rowsum[t, off + j]
    if kept <= 0.0:
        # mass on both sides of an empty middle: centre on the mode instead
        lo, hi = _window(_argmax_row(state.rowsum, t, off, first, last), p, T)
        kept_lo, kept_hi = max(lo, first), min(hi, last)
    return kept_lo, kept_hi


@inline
def _predict(model, state, k):
    """Both tracks of template k through the window and the transition."""
    off, T = model.offsets[k], model.lengths[k]
    support = state.support
    keep = 1.0 - state.restart[k, 0]
    for t in range(2):
        first, last = support[k, t, 0], support[k, t, 1]
        if last < first:
            continue
        kept_lo, kept_hi = _kept(model, state, k, t)
        if first < kept_lo:
            _clear_rows(state, t, off + first, off + kept_lo - 1)
        if last > kept_hi:
            _clear_rows(state, t, off + kept_hi + 1, off + last)
        if kept_hi < kept_lo:
            support[k, t, 0] = 1
            support[k, t, 1] = 0
            continue
        support[k, t, 1] = _predict_track(model, state, t, off, T, kept_lo, kept_hi, keep)
        support[k, t, 0] = kept_lo


@inline
def _seed_entry(model, state, k):
    """A new repetition starts at the first state (the mass before this frame was 1): with
    ``restart[k, 0]`` from anywhere, with ``restart[k, 1]`` out of the main track's last
    state."""
    off, T = model.offsets[k], model.lengths[k]
    alpha, rowsum, support = state.alpha, state.rowsum, state.support
    mt = state.main[k]
    et = 1 - mt
    seed = state.restart[k, 0]
    r_end = state.restart[k, 1]
    last = off + T - 1
    if r_end > 0.0 and support[k, mt, 1] == T - 1 and rowsum[mt, last] > 0.0:
        seed += r_end * rowsum[mt, last]
        for m in range(alpha.shape[2]):
            alpha[mt, last, m] *= 1.0 - r_end
        rowsum[mt, last] *= 1.0 - r_end
    total = 0.0
    for m in range(alpha.shape[2]):
        v = seed * model.initial_speed[m]
        alpha[et, off, m] += v
        total += v
    rowsum[et, off] += total
    if support[k, et, 1] < support[k, et, 0]:
        support[k, et, 1] = 0
    support[k, et, 0] = 0


@inline
def _emit(model, state, k, n_obs):
    """The emission of every row in the union of both tracks' supports (each row once)."""
    off = model.offsets[k]
    support = state.support
    mt = state.main[k]
    et = 1 - mt
    s2 = state.scale2[0, k] * state.temper[k, 0]
    inv_scale2 = 1.0 / s2
    norm_shift = -0.5 * n_obs * math.log(s2)
    exact_shift = 0.0
    if model.dual and state.mixture[0] > 0.0:
        for d in range(state.xs.shape[0]):
            exact_shift -= state.observed[d] * model.exact_log[k, d]
    every = n_obs == state.xs.shape[0]
    m_first, m_last = support[k, mt, 0], support[k, mt, 1]
    e_first, e_last = support[k, et, 0], support[k, et, 1]
    has_main = m_last >= m_first
    if has_main:
        _emission_rows(model, state, k, off + m_first, off + m_last, every, inv_scale2,
                       norm_shift, exact_shift)
    if e_last < e_first:
        return
    # only the rows the main track did not already cover
    if not has_main or e_last < m_first or e_first > m_last:
        _emission_rows(model, state, k, off + e_first, off + e_last, every, inv_scale2,
                       norm_shift, exact_shift)
        return
    if e_first < m_first:
        _emission_rows(model, state, k, off + e_first, off + m_first - 1, every, inv_scale2,
                       norm_shift, exact_shift)
    if e_last > m_last:
        _emission_rows(model, state, k, off + m_last + 1, off + e_last, every, inv_scale2,
                       norm_shift, exact_shift)


@inline
def _predictive_loglik(state, e, k, off):
    """log sum_j predicted_j * b_j(x) over both tracks, for emission model ``e``, scaled so
    that it neither under- nor overflows."""
    rowsum, logb, support = state.rowsum, state.logb, state.support
    shift = -np.inf
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            if rowsum[t, off + j] > 0.0 and logb[e, off + j] > shift:
                shift = logb[e, off + j]
    if shift == -np.inf:
        return -1e300
    c = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            c += rowsum[t, off + j] * math.exp(logb[e, off + j] - shift)
    if c > 1e-280:
        return math.log(c) + shift
    best = -np.inf
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            v = rowsum[t, off + j]
            if v > 0.0:
                lv = math.log(v) + logb[e, off + j]
                if lv > best:
                    best = lv
    c = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            c += rowsum[t, off + j] * math.exp(logb[e, off + j] - best)
    return math.log(c) + best if c > 0.0 else -1e300


@inline
def _mixed(score, mixture, exact):
    """The recognition score: ``mixture`` of the exact component's predictive log-likelihood
    with ``1 - mixture`` of model 1's (``score``), and the log of the exact one's share."""
    a = math.log(mixture) + exact
    b = math.log1p(-mixture) + score
    top = a if a > b else b
    mixed = top + math.log(math.exp(a - top) + math.exp(b - top))
    return mixed, a - mixed


@inline
def _tops(state, k, off, dual, mixed):
    """The largest emission of each model over the rows that hold mass."""
    rowsum, logb, support = state.rowsum, state.logb, state.support
    top0 = -np.inf
    top1 = -np.inf
    top2 = -np.inf
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            r = off + j
            if rowsum[t, r] > 0.0:
                top0 = max(top0, logb[0, r])
                if dual:
                    top1 = max(top1, logb[1, r])
                    if mixed:
                        top2 = max(top2, logb[2, r])
    return top0, top1, top2


@inline
def _lift_rows(state, k, off, tops, dual, mixed):
    """``state.lift[r]``: row r's emission (model 0) over ``exp(tops[0])`` where it holds
    mass, else 0 (``tops``: at least the largest emission of each model over those rows);
    returns the mass each model leaves, sum_j predicted_j * exp(logb[e, j] - tops[e]) (e = 0,
    1 when ``dual``, 2 when ``mixed``; 0 otherwise), in one pass."""
    rowsum, logb, support, lift = state.rowsum, state.logb, state.support, state.lift
    top0, top1, top2 = tops
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    for t in range(2):
        first, last = off + support[k, t, 0], off + support[k, t, 1]
        for r in range(first, last + 1):
            lift[r] = exp_nonpositive(logb[0, r] - top0 if rowsum[t, r] > 0.0 else -np.inf)
        # the sums in a loop that writes nothing: a loop that also writes ``lift`` is
        # compiled with a check of where the arrays lie, and sums in another order when the
        # check fails, so the last bit would depend on the arrays' addresses
        for r in range(first, last + 1):
            v = rowsum[t, r]
            c0 += v * lift[r]
            if dual:
                held = v > 0.0
                c1 += v * exp_nonpositive(logb[1, r] - top1 if held else -np.inf)
                if mixed:
                    c2 += v * exp_nonpositive(logb[2, r] - top2 if held else -np.inf)
    return c0, c1, c2


@inline
def _lift_rows_far(state, k, off, shift):
    """``_lift_rows`` for any ``shift`` (a row's emission may exceed it by up to 709)."""
    rowsum, logb, support, lift = state.rowsum, state.logb, state.support, state.lift
    c = 0.0
    for t in range(2):
        for r in range(off + support[k, t, 0], off + support[k, t, 1] + 1):
            v = rowsum[t, r]
            e = math.exp(logb[0, r] - shift) if v > 0.0 else 0.0
            lift[r] = e
            c += v * e
    return c


@inline
def _weigh(model, state, k):
    """Each row of both tracks times its emission (model 0) over the largest one, then both
    tracks divided by their total mass c; returns (c, the log of the scale), c = 0 when it is
    not a positive finite number (``_lost``). Before that, from the predicted states, the
    recognition score (``frame_loglik[1, k]``): model 1's predictive likelihood, or its
    mixture with model 2's (weight ``mixture[0]``, whose log share goes to
    ``frame_loglik[2, k]``). One pass finds each model's largest emission, one takes the
    exponentials of all three (the rows with mass may all sit far below the best row: then
    ``_predictive_loglik`` and the best product of mass and emission)."""
    off, dual = model.offsets[k], model.dual
    rowsum, logb, support, alpha, lift = (state.rowsum, state.logb, state.support,
                                          state.alpha, state.lift)
    mixture = state.mixture[0]
    mixed = dual and mixture > 0.0
    top0, top1, top2 = _tops(state, k, off, dual, mixed)
    shift = top0 if top0 > -np.inf else 0.0
    c, c1, c2 = _lift_rows(state, k, off, (shift, top1, top2), dual, mixed)
    if dual:
        score = math.log(c1) + top1 if c1 > 1e-280 else _predictive_loglik(state, 1, k, off)
        if mixed:
            exact = math.log(c2) + top2 if c2 > 1e-280 else \
                _predictive_loglik(state, 2, k, off)
            score, state.frame_loglik[2, k] = _mixed(score, mixture, exact)
        state.frame_loglik[1, k] = score
    if not c > 1e-280:
        best = -np.inf
        for t in range(2):
            for j in range(support[k, t, 0], support[k, t, 1] + 1):
                v = rowsum[t, off + j]
                if v > 0.0:
                    best = max(best, math.log(v) + logb[0, off + j])
        shift = best
        c = _lift_rows_far(state, k, off, shift)
    if not (c > 0.0 and c < np.inf):
        _lost(state, k)
        return 0.0, shift
    inv = 1.0 / c
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            r = off + j
            f = lift[r] * inv
            rowsum[t, r] *= f
            _scale_row(alpha[t, r], f)
    return c, shift


@inline
def _lost(state, k):
    """A frame whose mass is not a positive finite number (unreachable with bounded input):
    the follower starts over next frame and says so with a finite, very low likelihood."""
    state.frame_loglik[0, k] = -1e300
    state.frame_loglik[1, k] = -1e300
    state.loglik[k] = max(state.loglik[k] - 1e300, -1e308)
    state.fresh[k] = True
    state.moments[k, 0, 0] = 0.0
    state.moments[k, 1, 0] = 0.0


@inline
def _normalise(model, state, k):
    """A frame with nothing observed: both tracks divided by their total mass c, whose log is
    the recognition score; returns c, or 0 (``_lost``)."""
    off = model.offsets[k]
    rowsum, support, alpha = state.rowsum, state.support, state.alpha
    c = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            c += rowsum[t, off + j]
    if c > 0.0:
        state.frame_loglik[1, k] = math.log(c)
    if not (c > 0.0 and c < np.inf):
        _lost(state, k)
        return 0.0
    inv = 1.0 / c
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            r = off + j
            rowsum[t, r] *= inv
            _scale_row(alpha[t, r], inv)
    return c


@inline
def _adapt_recursion(model, state, k, n_obs, s2):
    """EM on the recursion's emission scale: its maximum-likelihood value given this frame is
    the posterior-expected squared z-score per channel (in units of the unscaled sigma); a
    forgetful mean of it over recent frames becomes the scale of the next frames. ``s2``: the
    scale squared the frame was weighed with (the learned one times the tempering)."""
    off, support, adapt = model.offsets[k], state.support, model.adapt
    expected = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            expected += state.rowsum[t, off + j] * state.residual[off + j]
    target = s2 * expected / n_obs
    learned = state.scale2[0, k]
    state.scale_weight[0, k] = adapt[0, 0] * state.scale_weight[0, k] + 1.0
    new_s2 = learned + (target - learned) / state.scale_weight[0, k]
    state.scale2[0, k] = min(max(new_s2, adapt[0, 1]), adapt[0, 2])


@inline
def _adapt_report(model, state, k):
    """EM on the report's scale, with the performer anywhere along the template's segments
    (``subframe_rows``), on the squared z-scores along the segments' direction over the main
    track. Between two template frames the distance to the nearest frame overstates the
    noise, which the recursion's scale keeps but the spread reported inside a cell must not;
    and the channels that place the performer are the ones that move, whose sigma is the
    widest."""
    off, mt, sub, adapt = model.offsets[k], state.main[k], state.sub, model.adapt
    r2 = state.scale2[1, k]
    expected = 0.0
    mass = 0.0
    for j in range(state.support[k, mt, 0], state.support[k, mt, 1] + 1):
        v = sub[3, off + j]
        if v > 0.0 and sub[2, off + j] >= 0.0:
            expected += v * sub[2, off + j]
            mass += v
    if mass > 0.0:
        state.scale_weight[1, k] = adapt[1, 0] * state.scale_weight[1, k] + 1.0
        r2 += (r2 * expected / mass - r2) / state.scale_weight[1, k]
        state.scale2[1, k] = min(max(r2, adapt[1, 1]), adapt[1, 2])


@inline
def _temper(model, state, k):
    """The recursion's emission variance for the next frame, widened by the residual's
    correlation (``followers.intervals``, here in the recursion): per channel the posterior's
    mean residual in units of the unscaled sigma, clipped at ``model.temper[2]`` sigmas; an
    exponential window (forgetting factor ``model.temper[0]``) of its lag-one and lag-zero
    products, averaged over the observed channels, gives ``rho`` in [0, RHO_MAX];
    ``state.temper[k, 0]`` := min(``model.temper[1]``, (1 + rho) / (1 - rho)). A residual
    correlated from frame to frame (another performer: a gain, an offset, a smoother hand)
    counts less per frame, so that a level the template does not reach costs the follower
    less than running off to where it does; an independent one (the take replayed) leaves the
    recursion as it was. ``state.temper[k]``: [factor, lag-one sum, lag-zero sum, the previous
    residual per channel]."""
    off, support, rowsum = model.offsets[k], state.support, state.rowsum
    templates, weights, xs, observed = model.templates, model.weights, state.xs, state.observed
    decay, cap, clip = model.temper[0], model.temper[1], model.temper[2]
    sums = state.temper[k]
    lag1 = 0.0
    lag0 = 0.0
    seen = 0
    for d in range(xs.shape[0]):
        if observed[d] == 0.0:
            sums[3 + d] = 0.0
            continue
        r = 0.0
        for t in range(2):
            for j in range(off + support[k, t, 0], off + support[k, t, 1] + 1):
                r += rowsum[t, j] * (xs[d] - templates[j, d]) * math.sqrt(weights[0, j, d])
        r = min(max(r, -clip), clip)
        lag1 += r * sums[3 + d]
        lag0 += r * r
        sums[3 + d] = r
        seen += 1
    sums[1] = decay * sums[1] + (1.0 - decay) * lag1 / seen
    sums[2] = decay * sums[2] + (1.0 - decay) * lag0 / seen
    rho = min(max(sums[1] / sums[2], 0.0), RHO_MAX) if sums[2] > 0.0 else 0.0
    sums[0] = min(cap, (1.0 + rho) / (1.0 - rho))


@inline
def _prune(model, state, k):
    """Beam pruning: edge states holding almost nothing cost work and change nothing."""
    off, support, rowsum, alpha = model.offsets[k], state.support, state.rowsum, state.alpha
    for t in range(2):
        first = support[k, t, 0]
        last = support[k, t, 1]
        while first <= last and rowsum[t, off + first] < model.prune:
            for m in range(alpha.shape[2]):
                alpha[t, off + first, m] = 0.0
            rowsum[t, off + first] = 0.0
            first += 1
        while last >= first and rowsum[t, off + last] < model.prune:
            for m in range(alpha.shape[2]):
                alpha[t, off + last, m] = 0.0
            rowsum[t, off + last] = 0.0
            last -= 1
        support[k, t, 0] = first
        support[k, t, 1] = last
        if last < first:
            support[k, t, 0] = 1
            support[k, t, 1] = 0


@inline
def _finish(model, state, k, mt, refined):
    """Each track's moments; the entry track becomes the main one when it explains the input
    better (a new repetition); the reported position inside the cells when ``refined``."""
    off, T = model.offsets[k], model.lengths[k]
    support, moments, rowsum, alpha = state.support, state.moments, state.rowsum, state.alpha
    et = 1 - mt
    for t in range(2):
        mass, mean, var = _moments(rowsum, t, off, support[k, t, 0], support[k, t, 1])
        moments[k, t, 0] = mass
        moments[k, t, 1] = mean
        moments[k, t, 2] = var
    if moments[k, et, 0] > moments[k, mt, 0]:
        if support[k, mt, 1] >= support[k, mt, 0]:
            _clear_rows(state, mt, off + support[k, mt, 0], off + support[k, mt, 1])
        support[k, mt, 0] = 1
        support[k, mt, 1] = 0
        inv = 1.0 / moments[k, et, 0]
        for j in range(support[k, et, 0], support[k, et, 1] + 1):
            r = off + j
            rowsum[et, r] *= inv
            _scale_row(alpha[et, r], inv)
        moments[k, et, 0] = 1.0
        moments[k, mt, 0] = 0.0
        moments[k, mt, 1] = 0.0
        moments[k, mt, 2] = 0.0
        state.main[k] = et
    if refined and state.main[k] == mt:
        mean, var = subframe_moments(state.sub, off, support[k, mt, 0], support[k, mt, 1], T)
        moments[k, mt, 1] = mean
        moments[k, mt, 2] = var


@kernel
def template_step(model, state, k, n_obs):
    """One frame of the windowed forward algorithm for template ``k`` (the frame already in
    ``state.xs`` / ``state.observed``, ``n_obs`` channels observed)."""
    if not state.fresh[k] and state.moments[k, 0, 0] + state.moments[k, 1, 0] <= 0.0:
        state.fresh[k] = True  # nothing left anywhere (cannot happen with finite input)
    if state.fresh[k]:
        _begin(model, state, k)
    else:
        _predict(model, state, k)
        if state.restart[k, 0] > 0.0 or state.restart[k, 1] > 0.0:
            _seed_entry(model, state, k)
    mt = state.main[k]
    shift = 0.0
    if n_obs > 0:
        _emit(model, state, k, n_obs)
        c, shift = _weigh(model, state, k)
    else:
        c = _normalise(model, state, k)
    if c == 0.0:
        return
    s2 = state.scale2[0, k] * state.temper[k, 0]
    if model.temper[1] > 1.0 and n_obs > 0:
        _temper(model, state, k)
    refined = state.subframe[k] and n_obs > 0
    if refined:
        if model.adapt[1, 0] <= 0.0:
            state.scale2[1, k] = s2
        # the reported position, in the units of the report's own scale
        subframe_rows(model, state, k, mt, 1.0 / state.scale2[1, k], s2 / state.scale2[1, k])
    if model.adapt[0, 0] > 0.0 and n_obs > 0:
        _adapt_recursion(model, state, k, n_obs, s2)
    if refined and model.adapt[1, 0] > 0.0:
        _adapt_report(model, state, k)
    step_ll = math.log(c) + shift
    state.frame_loglik[0, k] = step_ll
    if not model.dual:
        state.frame_loglik[1, k] = step_ll
    total = state.loglik[k] + step_ll
    state.loglik[k] = total if total > -1e308 else -1e308
    if model.prune > 0.0:
        _prune(model, state, k)
    _finish(model, state, k, mt, refined)


@kernel
def forward_step(model, state, x):
    """One frame ``x (D,)`` (raw input) for every template. Returns the observed channels."""
    n_obs = prepare_frame(model, state, x)
    for k in range(model.offsets.shape[0]):
        template_step(model, state, k, n_obs)
    return n_obs


@kernel
def main_progress(lengths, moments, main, k):
    """(progress in [0, 1], its variance) of template k's main track (``model.lengths``,
    ``state.moments``, ``state.main``)."""
    span = lengths[k] - 1.0
    t = main[k]
    # a division: exactly 1 at the end
    return moments[k, t, 1] / span, moments[k, t, 2] / (span * span)


@kernel
def follow_frame(model, state, x, progress, variance):
    """``forward_step`` for a lone follower; its main-track progress and variance into
    ``progress``, ``variance`` (1,)."""
    forward_step(model, state, x)
    progress[0], variance[0] = main_progress(model.lengths, state.moments, state.main, 0)


@kernel
def forward_run(model, state, X, progress, variance, loglik):
    """``forward_step`` over the rows of ``X (N, D)``; each template's main-track progress and
    variance (in [0, 1] units) and cumulative log-likelihood into ``(N, K)`` arrays."""
    for n in range(X.shape[0]):
        forward_step(model, state, X[n])
        for k in range(model.offsets.shape[0]):
            progress[n, k], variance[n, k] = main_progress(model.lengths, state.moments,
                                                           state.main, k)
            loglik[n, k] = state.loglik[k]


@kernel
def tempo_calibrate(progress, variance, span, tempo, state):
    """Scale a lone follower's variance by its performer's tempo, in place, frame by frame.

    progress, variance (N,) float: the follower's outputs, in [0, 1] units; span = T - 1
    [template frames]. ``tempo (4,)``: [gain = 1 / memory [frames], lowest, highest,
    exponent]: the tempo is a forgetful mean of the forward advance per frame [template
    frames per frame; a step back, a new repetition, counts as 0], kept within [lowest,
    highest]; variance := variance * tempo ** exponent.
    state (2,) float in/out: the last progress and the tempo (reset: 0 and 1)."""
    gain, lowest, highest, exponent = tempo[0], tempo[1], tempo[2], tempo[3]
    keep = 1.0 - gain
    for n in range(progress.shape[0]):
        advance = (progress[n] - state[0]) * span
        if advance < 0.0:
            advance = 0.0
        state[0] = progress[n]
        state[1] = keep * state[1] + gain * advance
        value = min(max(state[1], lowest), highest)
        variance[n] *= value ** exponent


@plain
def upsample_into(values, factor, out):
    """``out (factor (T - 1) + 1, D)`` := ``values (T, D)`` linearly interpolated, ``factor``
    rows per row, the original rows kept; NumPy's ``(1 - w) a + w b``, in one pass."""
    T, D = values.shape
    for t in range(T - 1):
        base = factor * t
        for d in range(D):
            out[base, d] = values[t, d]
        for r in range(1, factor):
            w = r / factor
            for d in range(D):
                out[base + r, d] = (1.0 - w) * values[t, d] + w * values[t + 1, d]
    for d in range(D):
        out[factor * (T - 1), d] = values[T - 1, d]
