"""Numba kernels of the windowed forward algorithm (pure array functions).

Layout shared by every kernel (K templates stacked, ``S = sum(T_k)`` states in all):

- ``templates (S, D) float64``: template ``k`` is rows ``offsets[k] : offsets[k] + lengths[k]``.
- ``alpha (2, S, M) float64``: the normalised forward variables of two *tracks* per template,
  over (state, speed level). The *main* track is the current repetition; the *entry* track is
  the hypothesis that a new repetition began recently (fed by the restart probability). Their
  masses sum to 1 after each frame. Rows outside a track's support are always zero.
- ``rowsum (2, S) float64``: per-state mass of each track (summed over speed levels).
- ``support (K, 2, 2) int64``: first and last state of each track's support (empty: last < first).
- ``moments (K, 2, 3) float64``: mass, mean state and state variance of each track.
- ``main (K,) int64``: which track (0 or 1) is the main one; ``fresh (K,) bool``: no frame yet.
- ``loglik (K,) float64``: log-likelihood of everything since reset; ``frame_loglik (3, K)``:
  of the last frame alone, under the follower's emission model (row 0) and under the bank's
  recognition model (row 1; a copy of row 0 unless ``dual``). With ``mixture = w > 0`` the
  recognition model is a two-component mixture per state: weight ``w`` on model 2 (the narrow
  one: an exact repetition) and ``1 - w`` on model 1 (another performance); row 2 is then the
  log of the narrow component's share of the frame's score (its responsibility, from which a
  bank learns ``w``; written only for frames with an observed channel).
- ``adapt (2, 3) float64``: [forgetting factor, lowest, highest scale**2] of the emission
  scales learned online (factor 0: fixed); ``scale2 (2, K)``: each template's current
  scale**2, which multiplies model 0's sigma**2; ``scale_weight (2, K)``: the forgetful counts
  behind them. Row 0 is the recursion's scale, row 1 the report's: the position inside a
  state's cell (``subframe (K,) bool``, scratch ``sub (4, S)``: see ``_subframe_rows``).
  ``residual (S,)``: scratch, each state's capped sum of squared z-scores this frame.

The emission of state ``j`` is ``sum over observed channels d`` of
``-0.5 * min(w[e, j, d] * (x[d] - template[j, d])**2, cap) - 0.5 * log(2 pi sigma[e, j, d]**2)``
with ``w = 1 / sigma**2``, sigma per model ``e`` (0: the follower's, 1: recognition, 2: the
recognition mixture's narrow component: model 0's sigma, unscaled, times the template's
exact scale per channel), state and channel: ``weights, log_norm (E, S, D)``, E = 2 with a
recognition model (``dual``), else 1 (model 2 needs only its (K, D) scales).
``cap = inf`` is the plain Gaussian of the paper (equation 1); a finite cap bounds what one wild
channel can do. Each frame is scaled by the largest emission, so nothing under- or overflows
however long the run.

Windowing (MOP equations 6-7): before each transition a track keeps only the states within
``p`` of its rounded mean (shifted to stay inside the template); the mass outside is dropped and
the per-frame normaliser ``k`` renormalises what remains. The entry track's window is always the
first ``2p + 1`` states. With ``p >= T`` and no restart this is the full forward algorithm.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

# The per-frame kernels may reassociate and fuse multiply-adds ({"reassoc", "contract"}: about
# 8 % off a K = 32 bank step, 0.186 against 0.202 ms in alternating runs, every benchmark figure
# unchanged), but not assume away NaN or inf: -inf marks "no state yet" and an overflow check
# compares against inf.

@nb.njit(cache=True)
def prepare_frame(x, lower, upper, xs, observed):
    """Clean one input frame: NaN -> missing, +-inf and huge values clamped into [lower, upper].

    x : (D,) float (any values); lower, upper : (D,) float [input units]
    xs : (D,) float64 out: clamped values (0 where missing); observed : (D,) float64 out: 1 or 0.
    Returns the number of observed channels.
    """
    count = 0
    for d in range(x.shape[0]):
        v = x[d]
        if v != v:
            xs[d] = 0.0
            observed[d] = 0.0
        else:
            if v < lower[d]:
                v = lower[d]
            elif v > upper[d]:
                v = upper[d]
            xs[d] = v
            observed[d] = 1.0
            count += 1
    return count


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _emission_rows(templates, weights, log_norm, log_norm_sum, first, last, xs, observed,
                   all_observed, cap, dual, inv_scale2, norm_shift, exact_scale2, exact_shift,
                   out, residual):
    # out[e, j] = sum over observed d of -0.5 * min(w[e, j, d] * (x[d] - template[j, d])**2, cap)
    #             + log_norm[e, j, d], for rows first..last; e = 0 the follower's model, whose
    #             sigma is multiplied by the online scale (w / scale**2; norm_shift =
    #             -n_obs * log(scale)), e = 1 the recognition model (only when dual, else a copy
    #             of e = 0), e = 2 (only when dual) the recognition mixture's narrow
    #             component: model 0's sigma without the online scale, times the template's
    #             exact scale per channel (exact_scale2 (D,) = its inverse square, exact_shift =
    #             minus the sum of its logs over the observed channels).
    #             residual[j]: the capped sum of squared z-scores of model 0.
    D = xs.shape[0]
    for j in range(first, last + 1):
        acc = 0.0
        acc_rec = 0.0
        acc_exact = 0.0
        if dual:
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
        # (row 1 of weights and log_norm exists only when dual)
        norm_rec = 0.0
        if all_observed:
            norm = log_norm_sum[0, j]
            if dual:
                norm_rec = log_norm_sum[1, j]
        else:
            norm = 0.0
            for d in range(D):
                norm += log_norm[0, j, d] * observed[d]
            if dual:
                for d in range(D):
                    norm_rec += log_norm[1, j, d] * observed[d]
        residual[j] = acc
        out[0, j] = norm + norm_shift - 0.5 * acc
        if dual:
            out[1, j] = norm_rec - 0.5 * acc_rec
            out[2, j] = norm + exact_shift - 0.5 * acc_exact
        else:
            out[1, j] = out[0, j]


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _clear_rows(alpha, rowsum, track, first, last):
    M = alpha.shape[2]
    for j in range(first, last + 1):
        rowsum[track, j] = 0.0
        for m in range(M):
            alpha[track, j, m] = 0.0


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _predict_track(alpha, rowsum, track, off, T, lo, hi, keep_scale, advance, advance_tail,
                   advance_range, speed_change, mix):
    """Transition one track in place: truncate to [lo, hi] (state indices within the template),
    mix speed levels, advance. Returns the last target state. ``keep_scale`` multiplies the mass
    (1 - restart). ``advance_range (M, 2)``: first and last nonzero advance of each level.
    ``mix`` is a (M,) scratch."""
    M = alpha.shape[2]
    A = advance.shape[1] - 1
    if M > 1:
        for i in range(lo, hi + 1):
            r = off + i
            for m in range(M):
                v = alpha[track, r, m] * speed_change[m, 1]
                if m > 0:
                    v += alpha[track, r, m - 1] * speed_change[m - 1, 2]
                if m < M - 1:
                    v += alpha[track, r, m + 1] * speed_change[m + 1, 0]
                mix[m] = v
            for m in range(M):
                alpha[track, r, m] = mix[m]
    top = hi + A
    if top > T - 1:
        top = T - 1
    # descending, so every source row (<= target) is read before it is overwritten
    for j in range(top, lo - 1, -1):
        r = off + j
        total = 0.0
        if j == T - 1:
            # absorbing end: every advance that would pass the last state lands on it
            for m in range(M):
                s = 0.0
                for i in range(max(lo, T - 1 - A), min(hi, T - 1) + 1):
                    s += alpha[track, off + i, m] * advance_tail[m, T - 1 - i]
                s *= keep_scale
                alpha[track, r, m] = s
                total += s
        else:
            for m in range(M):
                s = 0.0
                # only the advances level m can make (two neighbours for a fractional speed)
                a_first = advance_range[m, 0]
                a_last = advance_range[m, 1]
                i = j - a_last
                if i < lo:
                    a_last = j - lo
                i = j - a_first
                if i > hi:
                    a_first = j - hi
                for a in range(a_first, a_last + 1):
                    s += alpha[track, r - a, m] * advance[m, a]
                s *= keep_scale
                alpha[track, r, m] = s
                total += s
        rowsum[track, r] = total
    return top


@nb.njit(cache=True)
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


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
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


_SQRT2 = math.sqrt(2.0)
_SQRT_2PI = math.sqrt(2.0 * math.pi)
# steepest prior slope across a cell, [nats per frame] (see ``_tilt``)
TILT = 10.0
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


@nb.njit(cache=True)
def _truncated_exponential(rate, h):
    """v in [0, h] with density proportional to exp(-rate v), rate > 0: (log of the integral of
    exp(-rate v) over [0, h], mean, mean square)."""
    q = math.exp(-rate * h)
    ratio = q / (1.0 - q)
    return (math.log1p(-q) - math.log(rate), 1.0 / rate - h * ratio,
            2.0 / (rate * rate) - (h * h + 2.0 * h / rate) * ratio)


@nb.njit(cache=True)
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


@nb.njit(cache=True)
def _segment(templates, weights, xs, observed, cap, inv_scale2, j, other):
    """The squared z-distance from x to the point u of the way from template row j to row
    ``other`` is ``r_j - 2 a u + n u**2`` over the observed channels not at the cap (each
    channel d contributing ``g_d = w_d step_d**2`` to n). Returns (a, n, pa, pb, pc): with
    them the same distance *along the segment's direction*, each channel's squared z-score
    weighted by its share ``g_d / n`` of the position's information, is
    ``(pa - 2 pb u + pc u**2) / n``; the report's scale is learned from that (a position
    placed by channels that move is only as uncertain as their noise)."""
    a = 0.0
    n = 0.0
    pa = 0.0
    pb = 0.0
    pc = 0.0
    for d in range(xs.shape[0]):
        w = weights[0, j, d] * observed[d] * inv_scale2
        diff = xs[d] - templates[j, d]
        if w * diff * diff < cap:
            step = templates[other, d] - templates[j, d]
            a += w * diff * step
            g = w * step * step
            n += g
            pa += g * w * diff * diff
            pb += g * w * diff * step
            pc += g * g
    return a, n, pa, pb, pc


@nb.njit(cache=True)
def _along(pa, pb, pc, n, mean, square):
    """Expected squared z-score along a segment (``_segment``) under an offset with this mean
    and mean square; -1 for a segment of zero length (nothing to learn from)."""
    if not n > 0.0:
        return -1.0
    return (pa - 2.0 * mean * pb + square * pc) / n


@nb.njit(cache=True)
def _tilt(rowsum, logb, track, r, other):
    """The prior's slope across the cell of row r towards row ``other`` (its neighbour): the
    log-ratio of their predicted masses (posterior over this frame's emission), within
    +-``TILT``; -``TILT`` when the neighbour holds nothing."""
    v = rowsum[track, other]
    if v <= 0.0:
        return -TILT
    c = math.log(v / rowsum[track, r]) - (logb[0, other] - logb[0, r])
    return -TILT if c < -TILT else (TILT if c > TILT else c)


@nb.njit(cache=True)
def _subframe_rows(templates, weights, xs, observed, cap, inv_scale2, in_report, residual,
                   rowsum, logb, track, off, T, first, last, sub):
    """Where inside its cell each state of a track puts the performer: the positions within
    half a frame of the state along the template's straight segments to its neighbours,
    weighted by this frame's emission there (at the report's scale, ``inv_scale2``) and by
    the prediction's slope across the cell (``_tilt``: the predicted masses interpolated
    log-linearly).

    sub (4, S) float64 out, for the rows of states holding more than 1e-6 (others 0): the
    mean offset [states], its mean square, the expected squared z-score along the template's
    direction there (``_segment``; -1 where a segment has zero length), and the weight of the
    cell: its state's mass, the point emission of the recursion swapped for the report's
    emission integrated over the cell (``in_report``: the recursion's scale**2 over the
    report's), summing to 1.
    The first and last states keep their position (progress stays 0 at rest and 1 at the end)
    and add only their spread towards their one neighbour."""
    top_weight = -np.inf
    for j in range(first, last + 1):
        r = off + j
        sub[0, r] = 0.0
        sub[1, r] = 0.0
        sub[2, r] = 0.0
        sub[3, r] = -np.inf
        if rowsum[track, r] <= 1e-6:
            continue
        log_f = log_b = mean_f = mean_b = square_f = square_b = 0.0
        a_f = n_f = a_b = n_b = 0.0
        pa_f = pb_f = pc_f = pa_b = pb_b = pc_b = 0.0
        if j + 1 < T:
            a_f, n_f, pa_f, pb_f, pc_f = _segment(templates, weights, xs, observed, cap,
                                                  inv_scale2, r, r + 1)
            log_f, mean_f, square_f = _half_cell(a_f + _tilt(rowsum, logb, track, r, r + 1),
                                                 n_f, 0.5)
        if j > 0:
            a_b, n_b, pa_b, pb_b, pc_b = _segment(templates, weights, xs, observed, cap,
                                                  inv_scale2, r, r - 1)
            log_b, mean_b, square_b = _half_cell(a_b + _tilt(rowsum, logb, track, r, r - 1),
                                                 n_b, 0.5)
        if 0 < j < T - 1:
            top = log_f if log_f > log_b else log_b
            wf = math.exp(log_f - top)
            wb = math.exp(log_b - top)
            inv = 1.0 / (wf + wb)
            sub[0, r] = (wf * mean_f - wb * mean_b) * inv
            sub[1, r] = (wf * square_f + wb * square_b) * inv
            along_f = _along(pa_f, pb_f, pc_f, n_f, mean_f, square_f)
            along_b = _along(pa_b, pb_b, pc_b, n_b, mean_b, square_b)
            if along_f < 0.0 or along_b < 0.0:
                sub[2, r] = -1.0
            else:
                sub[2, r] = (wf * along_f + wb * along_b) * inv
            cell = top + math.log(wf + wb)
        elif j == 0:
            sub[1, r] = square_f
            sub[2, r] = _along(pa_f, pb_f, pc_f, n_f, mean_f, square_f)
            cell = log_f
        else:
            sub[1, r] = square_b
            sub[2, r] = _along(pa_b, pb_b, pc_b, n_b, mean_b, square_b)
            cell = log_b
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


@nb.njit(cache=True)
def _subframe_moments(sub, off, first, last, T):
    """Mean and variance of a track's position [states], each state standing for its cell as
    ``_subframe_rows`` placed and weighted it."""
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


@nb.njit(cache=True)
def _argmax_row(rowsum, track, off, first, last):
    best = first
    best_v = -1.0
    for j in range(first, last + 1):
        if rowsum[track, off + j] > best_v:
            best_v = rowsum[track, off + j]
            best = j
    return best


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _predictive_loglik(rowsum, logb, model, support, k, off):
    """log sum_j predicted_j * b_j(x) over both tracks, for emission model ``model``, scaled so
    that it neither under- nor overflows."""
    shift = -np.inf
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            if rowsum[t, off + j] > 0.0 and logb[model, off + j] > shift:
                shift = logb[model, off + j]
    if shift == -np.inf:
        return -1e300
    c = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            c += rowsum[t, off + j] * math.exp(logb[model, off + j] - shift)
    if c > 1e-280:
        return math.log(c) + shift
    best = -np.inf
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            v = rowsum[t, off + j]
            if v > 0.0:
                lv = math.log(v) + logb[model, off + j]
                if lv > best:
                    best = lv
    c = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            c += rowsum[t, off + j] * math.exp(logb[model, off + j] - best)
    return math.log(c) + best if c > 0.0 else -1e300


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def template_step(k, templates, offsets, lengths, half_windows, weights, log_norm, log_norm_sum,
                  xs, observed, n_obs, cap, dual, mixture, exact_inv2, exact_log, prune,
                  advance, advance_tail, advance_range, speed_change, initial_speed, restart,
                  alpha, rowsum, logb, support, moments, main, fresh, loglik, frame_loglik, mix,
                  adapt, scale2, scale_weight, residual, subframe, sub):
    """One frame of the windowed forward algorithm for template ``k`` (see the module docstring
    for the layout). ``weights (E, S, D)``: 1 / sigma**2 per model and state (E = 2 when
    ``dual``, else 1); ``log_norm (E, S, D)``: -0.5 log(2 pi sigma**2), ``log_norm_sum (E, S)``
    its sum over channels;
    ``dual``: score frames with model 1 too; ``mixture`` in [0, 1): with dual, the weight of
    model 2 (model 0's sigma times ``exp(exact_log[k])`` per channel; ``exact_inv2 (K, D)``
    the inverse square of that scale) in the recognition score (0: model 1 alone);
    ``half_windows (K,)``: window half-width p in states (>= T: full forward); ``prune``: 0,
    or a mass below which states at the edges of a track's support are dropped (beam pruning:
    the support stays inside the window but is often much narrower).
    ``advance_range (M, 2)``: first and last nonzero advance per level; ``mix (M,)``:
    scratch."""
    off = offsets[k]
    T = lengths[k]
    M = alpha.shape[2]
    p = half_windows[k]
    mt = main[k]
    et = 1 - mt
    # restart (K, 2): per frame, the probability of a new repetition from anywhere (an
    # abandoned one, a late start) and from the absorbing last state (the current one is over)
    r_any = restart[k, 0]
    r_end = restart[k, 1]
    use_entry = r_any > 0.0 or r_end > 0.0

    if not fresh[k]:
        if moments[k, 0, 0] + moments[k, 1, 0] <= 0.0:
            fresh[k] = True  # nothing left anywhere (cannot happen with finite input): start over

    if fresh[k]:
        for t in range(2):
            if support[k, t, 1] >= support[k, t, 0]:
                _clear_rows(alpha, rowsum, t, off + support[k, t, 0], off + support[k, t, 1])
            support[k, t, 0] = 1
            support[k, t, 1] = 0
        mt = 0
        et = 1
        main[k] = 0
        total = 0.0
        for m in range(M):
            alpha[mt, off, m] = initial_speed[m]
            total += initial_speed[m]
        rowsum[mt, off] = total
        support[k, mt, 0] = 0
        support[k, mt, 1] = 0
        fresh[k] = False
    else:
        keep = 1.0 - r_any
        for t in range(2):
            first = support[k, t, 0]
            last = support[k, t, 1]
            if last < first:
                continue
            if t == mt:
                half = p
                lo, hi = _window(int(math.floor(moments[k, t, 1] + 0.5)), half, T)
                kept_lo = max(lo, first)
                kept_hi = min(hi, last)
                kept = 0.0
                for j in range(kept_lo, kept_hi + 1):
                    kept += rowsum[t, off + j]
                if kept <= 0.0:
                    # mass on both sides of an empty middle: centre on the mode instead
                    mode = _argmax_row(rowsum, t, off, first, last)
                    lo, hi = _window(mode, half, T)
                    kept_lo = max(lo, first)
                    kept_hi = min(hi, last)
            else:
                # the entry track only holds repetitions that began recently: eq. 7's first case
                lo, hi = _window(0, p, T)
                kept_lo = first
                kept_hi = min(hi, last)
            if first < kept_lo:
                _clear_rows(alpha, rowsum, t, off + first, off + kept_lo - 1)
            if last > kept_hi:
                _clear_rows(alpha, rowsum, t, off + kept_hi + 1, off + last)
            if kept_hi < kept_lo:
                support[k, t, 0] = 1
                support[k, t, 1] = 0
                continue
            top = _predict_track(alpha, rowsum, t, off, T, kept_lo, kept_hi, keep, advance,
                                 advance_tail, advance_range, speed_change, mix)
            support[k, t, 0] = kept_lo
            support[k, t, 1] = top
        if use_entry:
            # a new repetition starts at the first state (mass before this frame was 1): with
            # r_any from anywhere, with r_end out of the main track's last state
            seed = r_any
            last = off + T - 1
            if r_end > 0.0 and support[k, mt, 1] == T - 1 and rowsum[mt, last] > 0.0:
                seed += r_end * rowsum[mt, last]
                for m in range(M):
                    alpha[mt, last, m] *= 1.0 - r_end
                rowsum[mt, last] *= 1.0 - r_end
            total = 0.0
            for m in range(M):
                v = seed * initial_speed[m]
                alpha[et, off, m] += v
                total += v
            rowsum[et, off] += total
            if support[k, et, 1] < support[k, et, 0]:
                support[k, et, 1] = 0
            support[k, et, 0] = 0

    # ---- emission over the union of both supports -------------------------------------------
    m_first = support[k, mt, 0]
    m_last = support[k, mt, 1]
    e_first = support[k, et, 0]
    e_last = support[k, et, 1]
    has_main = m_last >= m_first
    has_entry = e_last >= e_first
    shift = 0.0
    s2 = scale2[0, k]
    inv_scale2 = 1.0 / s2
    norm_shift = -0.5 * n_obs * math.log(s2)
    exact_scale2 = exact_inv2[k]
    exact_shift = 0.0
    if dual and mixture > 0.0:
        for d in range(xs.shape[0]):
            exact_shift -= observed[d] * exact_log[k, d]
    if n_obs > 0:
        all_observed = n_obs == xs.shape[0]
        if has_main:
            _emission_rows(templates, weights, log_norm, log_norm_sum, off + m_first,
                           off + m_last, xs, observed, all_observed, cap, dual, inv_scale2,
                           norm_shift, exact_scale2, exact_shift, logb, residual)
        if has_entry:
            # only the rows the main track did not already cover
            if not has_main or e_last < m_first or e_first > m_last:
                _emission_rows(templates, weights, log_norm, log_norm_sum, off + e_first,
                               off + e_last, xs, observed, all_observed, cap, dual,
                               inv_scale2, norm_shift, exact_scale2, exact_shift, logb,
                               residual)
            else:
                if e_first < m_first:
                    _emission_rows(templates, weights, log_norm, log_norm_sum, off + e_first,
                                   off + m_first - 1, xs, observed, all_observed, cap, dual,
                                   inv_scale2, norm_shift, exact_scale2, exact_shift, logb,
                                   residual)
                if e_last > m_last:
                    _emission_rows(templates, weights, log_norm, log_norm_sum, off + m_last + 1,
                                   off + e_last, xs, observed, all_observed, cap, dual,
                                   inv_scale2, norm_shift, exact_scale2, exact_shift, logb,
                                   residual)
        if dual:
            score = _predictive_loglik(rowsum, logb, 1, support, k, off)
            if mixture > 0.0:
                # the mixture per state, summed over the same predicted states: the two
                # models' predictive likelihoods, mixed
                a = math.log(mixture) + _predictive_loglik(rowsum, logb, 2, support, k, off)
                b = math.log1p(-mixture) + score
                top = a if a > b else b
                score = top + math.log(math.exp(a - top) + math.exp(b - top))
                frame_loglik[2, k] = a - score
            frame_loglik[1, k] = score
        shift = -np.inf
        for t in range(2):
            first = support[k, t, 0]
            last = support[k, t, 1]
            for j in range(first, last + 1):
                if rowsum[t, off + j] > 0.0 and logb[0, off + j] > shift:
                    shift = logb[0, off + j]
        if shift == -np.inf:
            shift = 0.0
        c = 0.0
        for t in range(2):
            for j in range(support[k, t, 0], support[k, t, 1] + 1):
                c += rowsum[t, off + j] * math.exp(logb[0, off + j] - shift)
        if not c > 1e-280:
            # the rows with mass all sit far below the best row: rescale by the best product
            best = -np.inf
            for t in range(2):
                for j in range(support[k, t, 0], support[k, t, 1] + 1):
                    v = rowsum[t, off + j]
                    if v > 0.0:
                        lv = math.log(v) + logb[0, off + j]
                        if lv > best:
                            best = lv
            shift = best
        for t in range(2):
            for j in range(support[k, t, 0], support[k, t, 1] + 1):
                r = off + j
                e = math.exp(logb[0, r] - shift)
                rowsum[t, r] *= e
                for m in range(M):
                    alpha[t, r, m] *= e
    c = 0.0
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            c += rowsum[t, off + j]
    if n_obs == 0 and c > 0.0:
        frame_loglik[1, k] = math.log(c)
    if not (c > 0.0 and c < np.inf):
        # unreachable with clamped input; keep the output finite and start over next frame
        frame_loglik[0, k] = -1e300
        frame_loglik[1, k] = -1e300
        loglik[k] = max(loglik[k] - 1e300, -1e308)
        fresh[k] = True
        moments[k, 0, 0] = 0.0
        moments[k, 1, 0] = 0.0
        return
    inv = 1.0 / c
    for t in range(2):
        for j in range(support[k, t, 0], support[k, t, 1] + 1):
            r = off + j
            rowsum[t, r] *= inv
            for m in range(M):
                alpha[t, r, m] *= inv
    refined = subframe[k] and n_obs > 0
    if refined:
        if adapt[1, 0] <= 0.0:
            scale2[1, k] = s2
        # the reported position, in the units of the report's own scale (below)
        _subframe_rows(templates, weights, xs, observed, cap, 1.0 / scale2[1, k],
                       s2 / scale2[1, k], residual, rowsum, logb, mt, off, T, support[k, mt, 0],
                       support[k, mt, 1], sub)
    if adapt[0, 0] > 0.0 and n_obs > 0:
        # EM on the emission scale: its maximum-likelihood value given this frame is the
        # posterior-expected squared z-score per channel (in units of the unscaled sigma);
        # a forgetful mean of it over recent frames becomes the scale of the next frames
        expected = 0.0
        for t in range(2):
            for j in range(support[k, t, 0], support[k, t, 1] + 1):
                expected += rowsum[t, off + j] * residual[off + j]
        target = s2 * expected / n_obs
        scale_weight[0, k] = adapt[0, 0] * scale_weight[0, k] + 1.0
        new_s2 = s2 + (target - s2) / scale_weight[0, k]
        scale2[0, k] = min(max(new_s2, adapt[0, 1]), adapt[0, 2])
    if refined and adapt[1, 0] > 0.0:
        # the report's scale: EM with the performer anywhere along the template's segments
        # (``_subframe_rows``), on the squared z-scores along the segments' direction, over the
        # main track. Between two template frames the distance to the nearest frame overstates
        # the noise, which the recursion's scale keeps (it holds on to the track better for
        # it) but the spread reported inside a cell must not; and the channels that place the
        # performer are the ones that move, whose sigma (estimated from the template's own
        # variation) is the widest: averaged over all channels, the report's sd ran 1.5x wide
        r2 = scale2[1, k]
        expected = 0.0
        mass = 0.0
        for j in range(support[k, mt, 0], support[k, mt, 1] + 1):
            v = sub[3, off + j]
            if v > 0.0 and sub[2, off + j] >= 0.0:
                expected += v * sub[2, off + j]
                mass += v
        if mass > 0.0:
            scale_weight[1, k] = adapt[1, 0] * scale_weight[1, k] + 1.0
            r2 += (r2 * expected / mass - r2) / scale_weight[1, k]
            scale2[1, k] = min(max(r2, adapt[1, 1]), adapt[1, 2])
    step_ll = math.log(c) + shift
    frame_loglik[0, k] = step_ll
    if not dual:
        frame_loglik[1, k] = step_ll
    total_ll = loglik[k] + step_ll
    loglik[k] = total_ll if total_ll > -1e308 else -1e308
    if prune > 0.0:
        # beam pruning: edge states holding almost nothing cost work and change nothing
        for t in range(2):
            first = support[k, t, 0]
            last = support[k, t, 1]
            while first <= last and rowsum[t, off + first] < prune:
                for m in range(M):
                    alpha[t, off + first, m] = 0.0
                rowsum[t, off + first] = 0.0
                first += 1
            while last >= first and rowsum[t, off + last] < prune:
                for m in range(M):
                    alpha[t, off + last, m] = 0.0
                rowsum[t, off + last] = 0.0
                last -= 1
            support[k, t, 0] = first
            support[k, t, 1] = last
            if last < first:
                support[k, t, 0] = 1
                support[k, t, 1] = 0
    for t in range(2):
        mass, mean, var = _moments(rowsum, t, off, support[k, t, 0], support[k, t, 1])
        moments[k, t, 0] = mass
        moments[k, t, 1] = mean
        moments[k, t, 2] = var
    if moments[k, et, 0] > moments[k, mt, 0]:
        # the new repetition explains the input better: it becomes the current one
        if support[k, mt, 1] >= support[k, mt, 0]:
            _clear_rows(alpha, rowsum, mt, off + support[k, mt, 0], off + support[k, mt, 1])
        support[k, mt, 0] = 1
        support[k, mt, 1] = 0
        mass = moments[k, et, 0]
        inv = 1.0 / mass
        for j in range(support[k, et, 0], support[k, et, 1] + 1):
            r = off + j
            rowsum[et, r] *= inv
            for m in range(M):
                alpha[et, r, m] *= inv
        moments[k, et, 0] = 1.0
        moments[k, mt, 0] = 0.0
        moments[k, mt, 1] = 0.0
        moments[k, mt, 2] = 0.0
        main[k] = et
    if refined and main[k] == mt:
        # the reported position: each state stands for its cell along the template's segments
        mean, var = _subframe_moments(sub, off, support[k, mt, 0], support[k, mt, 1], T)
        moments[k, mt, 1] = mean
        moments[k, mt, 2] = var


@nb.njit(cache=True)
def bank_step(x, lower, upper, templates, offsets, lengths, half_windows, weights, log_norm,
              log_norm_sum, cap, dual, mixture, exact_inv2, exact_log, prune, advance,
              advance_tail, advance_range, speed_change, initial_speed, restart, alpha, rowsum,
              logb, support, moments, main, fresh, loglik, frame_loglik, xs, observed, mix,
              adapt, scale2, scale_weight, residual, subframe, sub):
    """One frame for all K templates. ``x (D,)`` is the raw input frame. Returns the number of
    observed channels."""
    n_obs = prepare_frame(x, lower, upper, xs, observed)
    for k in range(offsets.shape[0]):
        template_step(k, templates, offsets, lengths, half_windows, weights, log_norm,
                      log_norm_sum, xs, observed, n_obs, cap, dual, mixture, exact_inv2,
                      exact_log, prune, advance, advance_tail, advance_range, speed_change,
                      initial_speed, restart, alpha, rowsum, logb, support, moments, main,
                      fresh, loglik, frame_loglik, mix, adapt, scale2, scale_weight, residual,
                      subframe, sub)
    return n_obs


@nb.njit(cache=True)
def follow_sequence(X, lower, upper, templates, offsets, lengths, half_windows, weights, log_norm,
                    log_norm_sum, cap, dual, mixture, exact_inv2, exact_log, prune, advance,
                    advance_tail, advance_range, speed_change, initial_speed, restart, alpha,
                    rowsum, logb, support, moments, main, fresh, loglik, frame_loglik, xs,
                    observed, mix, adapt, scale2, scale_weight, residual, subframe, sub,
                    out_progress, out_variance, out_loglik):
    """Run ``bank_step`` over the rows of ``X (N, D)``; write each template's main-track
    progress and variance (in [0, 1] units) and cumulative log-likelihood into
    ``out_* (N, K)``."""
    K = offsets.shape[0]
    for n in range(X.shape[0]):
        bank_step(X[n], lower, upper, templates, offsets, lengths, half_windows, weights,
                  log_norm, log_norm_sum, cap, dual, mixture, exact_inv2, exact_log, prune,
                  advance, advance_tail, advance_range, speed_change, initial_speed, restart,
                  alpha, rowsum, logb, support, moments, main, fresh, loglik, frame_loglik, xs,
                  observed, mix, adapt, scale2, scale_weight, residual, subframe, sub)
        for k in range(K):
            span = lengths[k] - 1.0
            t = main[k]
            out_progress[n, k] = moments[k, t, 1] / span  # a division: exactly 1 at the end
            out_variance[n, k] = moments[k, t, 2] / (span * span)
            out_loglik[n, k] = loglik[k]


@nb.njit(cache=True)
def tempo_calibrate(progress, variance, span, gain, lowest, highest, exponent, state):
    """Scale a lone follower's variance by its performer's tempo, in place, frame by frame.

    progress, variance (N,) float: the follower's outputs, in [0, 1] units; span = T - 1
    [template frames]. The tempo is a forgetful mean (gain = 1 / memory [frames]) of the
    forward advance per frame [template frames per frame; a step back, a new repetition,
    counts as 0], kept within [lowest, highest]; variance := variance * tempo ** exponent.
    state (2,) float in/out: the last progress and the tempo (reset: 0 and 1)."""
    keep = 1.0 - gain
    for n in range(progress.shape[0]):
        advance = (progress[n] - state[0]) * span
        if advance < 0.0:
            advance = 0.0
        state[0] = progress[n]
        state[1] = keep * state[1] + gain * advance
        tempo = state[1]
        if tempo < lowest:
            tempo = lowest
        elif tempo > highest:
            tempo = highest
        variance[n] *= tempo ** exponent
