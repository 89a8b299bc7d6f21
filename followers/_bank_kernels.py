"""Numba kernel of the bank's per-frame decision: posterior, fit, rejection, hysteresis.

Everything is written into preallocated arrays; ``state (4,) int64`` holds
``[active action (-1 = none), best action, frames seen, frames since the active action changed]``.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def capped_log_density(xs, observed, mean, inv_var, log_norm, cap):
    """log of a diagonal Gaussian at the cleaned frame ``xs (D,)``, over its observed channels
    (``observed (D,)`` 1 or 0; missing channels have xs 0), each squared z-score capped at
    ``cap``; mean, inv_var, log_norm (D,) float: mean, 1 / variance, -0.5 log(2 pi variance).
    Branch-free, so that the compiler vectorises it."""
    total = 0.0
    for d in range(xs.shape[0]):
        diff = xs[d] - mean[d]
        z2 = min(diff * diff * inv_var[d], cap)
        total += observed[d] * (log_norm[d] - 0.5 * z2)
    return total


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def outline_step(xs, observed, n_obs, mean, inv_var, log_norm, cap, restart, alpha, scratch,
                 frame_ll, total_ll, fresh):
    """One frame of every action's outline model: a left-to-right HMM of S states (stay or move
    on with probability 0.5 each, the last state absorbing; then, with probability ``restart``,
    back to the first state: a new repetition), one diagonal Gaussian per state.

    xs (D,) float, observed (D,) float, n_obs: the cleaned frame (see ``_kernels.prepare_frame``;
        n_obs = 0 only predicts); mean, inv_var, log_norm (K, S, D) float: each state's mean,
        1 / variance and -0.5 log(2 pi variance); cap: squared z-scores are capped at it
    alpha (K, S) float in/out: normalised forward variables; scratch (S,) float
    frame_ll (K,) float out: log-likelihood of this frame given the past (0 when n_obs = 0);
    total_ll (K,) float in/out: its sum since reset
    fresh (1,) bool in/out: True until the first frame, which the first state emits (the reset
        puts alpha there) without a transition before it
    """
    K, S = alpha.shape
    predict = not fresh[0]
    fresh[0] = False
    for k in range(K):
        # predict, from the last state down so that alpha[s - 1] is still the old value
        if predict and S > 1:
            alpha[k, S - 1] += 0.5 * alpha[k, S - 2]
            for s in range(S - 2, 0, -1):
                alpha[k, s] = 0.5 * (alpha[k, s] + alpha[k, s - 1])
            alpha[k, 0] *= 0.5
            # a new repetition (or an action taken up after another one) can begin at any frame
            for s in range(S):
                alpha[k, s] *= 1.0 - restart
            alpha[k, 0] += restart
        if n_obs == 0:
            frame_ll[k] = 0.0
            continue
        top = -np.inf
        for s in range(S):
            b = capped_log_density(xs, observed, mean[k, s], inv_var[k, s], log_norm[k, s], cap)
            scratch[s] = b
            if alpha[k, s] > 0.0 and b > top:
                top = b
        total = 0.0
        for s in range(S):
            v = alpha[k, s] * math.exp(scratch[s] - top) if alpha[k, s] > 0.0 else 0.0
            alpha[k, s] = v
            total += v
        for s in range(S):
            alpha[k, s] /= total
        frame_ll[k] = math.log(total) + top
        total_ll[k] += frame_ll[k]


@nb.njit(cache=True)
def learn_mixture(log_share, posterior, n_obs, decay, lowest, highest, state):
    """One EM step, with forgetting, on the weight of the recognition mixture's narrow component
    (an exact repetition of the demonstration) after a frame.

    log_share (K,) float: each follower's log share of this frame's recognition score that the
        narrow component explains (``frame_loglik[2]``); posterior (K,) float: the posterior
        over actions after this frame; n_obs: observed channels (0: the frame says nothing,
        nothing changes)
    decay : float in (0, 1): forgetting factor per frame; lowest, highest: the weight's range
    state (2,) float in/out: [weight, forgetful count of the frames behind it]
    Returns the new weight: the posterior-weighted share, averaged over recent frames with
    the count as the averaging weight (a reset puts the starting weight and its prior count).
    """
    if n_obs == 0:
        return state[0]
    share = 0.0
    for k in range(posterior.shape[0]):
        share += posterior[k] * math.exp(log_share[k])
    state[1] = decay * state[1] + 1.0
    weight = state[0] + (share - state[0]) / state[1]
    state[0] = min(max(weight, lowest), highest)
    return state[0]


@nb.njit(cache=True)
def bank_decide(frame_loglik, outline_ll, outline_weight, outline_fit_margin, xs, observed,
                n_obs, background_mean,
                background_weight, background_log_norm, cap, decay, fit_decay, evidence_cap,
                lead_cap, lead_cap_at_end, fit_floor, recent, fit, likelihood_fit, fit_weight, pace,
                last_position, last_main, since_end, end_fraction, pace_floor, pace_decay,
                pace_reference, pace_weight, posterior, thresholds, enter_margin, leave_margin,
                switch_margin, state, moments, main, lengths, progress, variance):
    """Update the bank's decision after one frame.

    frame_loglik (3, K) float: each follower's log-likelihood of this frame under its own
        emission model (row 0) and its recognition model (row 1, what the bank uses; row 2 is
        read by ``learn_mixture``)
    outline_ll (K,) float, outline_weight : float >= 0: each action's outline-model frame
        log-likelihood (``outline_step``) and its weight in the posterior's evidence
    outline_fit_margin : float >= 0 [nats per channel] or inf: in ``fit`` a frame counts as
        the better of its follower's score and its outline model's less this margin per
        observed channel (inf: the follower's alone)
    xs (D,) float: the cleaned frame; observed (D,) float: 1 or 0 (see ``_kernels.prepare_frame``)
    n_obs : int: observed channels this frame (0: the frame says nothing, nothing changes)
    background_mean, background_weight, background_log_norm (D,) float: the background model, one
        Gaussian over every frame of every template (mean, 1 / variance, -0.5 log(2 pi var));
        cap: the followers' outlier cap [squared sigmas], applied to it too
    decay : float in (0, 1]: forgetting factor of ``recent`` per frame (exp(-1 / memory);
        1 = no forgetting, the lead cap alone lets a new action take over)
    fit_decay : float in (0, 1): forgetting factor of ``fit`` per frame
    evidence_cap, lead_cap, lead_cap_at_end : float > 0 [nats]: one frame can count at most
        ``evidence_cap`` against a follower (relative to the frame's best), and no follower
        trails the leader by more than ``lead_cap`` in ``recent``, or ``lead_cap_at_end`` while
        the leader's follower is at the end of its template (``progress >= end_fraction``: its
        action performed, the next one may begin). An action that was wrong for a long time
        thus owes little, and a switch is followed as soon as the new action has been clearly
        better for a few frames, while one odd frame cannot flip the decision.
    fit_floor : float [nats per channel]: one frame counts at most this low in ``fit``, for
        the same reason (an action that was badly rejected recovers within a few frames)
    recent (K,) float in/out: forgetful sum of frame log-likelihoods relative to each frame's
        best follower, bounded as above, then shifted so that the leader is at 0 (<= 0 each)
    likelihood_fit (K,) float in/out: forgetful mean over frames of the per-channel
        log-likelihood ratio of each follower against the background model [nats per channel
        per frame]
    fit_weight (1,) float in/out: normaliser of that mean
    pace (K,) float in/out: forgetful mean of each follower's forward advance per frame
        [states per frame] (time constant 1 / (1 - pace_decay) frames; starts at
        ``pace_reference``); last_position (K,) float in/out: main-track mean state last frame;
        last_main (K,) int64 in/out: each follower's main track last frame (a change: a new
        repetition began); since_end (K,) float in/out: frames since the follower's progress
        last reached ``end_fraction`` (its mean rarely sits on the last state itself). These
        four are only updated when pace_weight > 0.
    end_fraction : float in (0, 1]: progress from which a follower has performed its action
    pace_floor : float > 0 [states per frame]: ``pace`` never falls below it
    pace_decay : float in [0, 1); pace_reference : float > 0 [states per frame];
        pace_weight : float >= 0 [nats per channel per frame]: the progress-plausibility term
        (see ``FollowerBank``): ``pace_weight * min(0, log(pace / pace_reference))``
    fit (K,) float out: ``likelihood_fit`` plus that (non-positive) term: what the rejection
        compares with ``thresholds``
    posterior (K,) float out: softmax of ``recent``
    thresholds (K,) float: a follower accepts the input when ``fit >= threshold``
    enter_margin, leave_margin : float >= 0: hysteresis on the rejection (to become active an
        action needs fit >= threshold + enter_margin; it stays active while
        fit >= threshold - leave_margin)
    switch_margin : float >= 0 [nats]: how far another action's ``recent`` must exceed the
        active one's for it to take over
    moments (K, 2, 3), main (K,), lengths (K,): the engine's tracks (see ``_kernels``)
    progress, variance (K,) float out: each follower's main-track progress [0, 1] and variance
    """
    K = frame_loglik.shape[1]
    for k in range(K):
        span = lengths[k] - 1.0
        t = main[k]
        progress[k] = moments[k, t, 1] / span  # a division: exactly 1 at the end
        variance[k] = moments[k, t, 2] / (span * span)
    if n_obs > 0:
        # the pace is only followed when it counts (pace_weight > 0: off by default)
        if pace_weight > 0.0:
            for k in range(K):
                position = progress[k] * (lengths[k] - 1)
                step = position - last_position[k]
                restarted = main[k] != last_main[k]
                last_main[k] = main[k]
                if step < 0.0:
                    # a hesitation is no evidence of advancing
                    step = 0.0
                if progress[k] >= end_fraction:
                    since_end[k] = 0.0
                else:
                    since_end[k] += 1.0
                if since_end[k] <= lengths[k]:
                    # a follower that reached the end of its template has performed the whole
                    # action: holding the end pose (which often resembles the first, so a new
                    # repetition takes over) is not being stuck, for as long as the action took
                    step = pace_reference
                last_position[k] = position
                if restarted:
                    # a new repetition took over: it is judged afresh
                    pace[k] = pace_reference
                pace[k] = pace_decay * pace[k] + (1.0 - pace_decay) * step
                if pace[k] < pace_floor:
                    # bounded, so that an action that was idle for long is judged afresh within a
                    # few frames once it is performed (a switch from another action)
                    pace[k] = pace_floor
        background = capped_log_density(xs, observed, background_mean, background_weight,
                                        background_log_norm, cap)
        fit_weight[0] = fit_decay * fit_weight[0] + 1.0
        inv_w = 1.0 / fit_weight[0]
        frame_best = -np.inf
        for k in range(K):
            score = frame_loglik[1, k] + outline_weight * outline_ll[k]
            if score > frame_best:
                frame_best = score
        leader = -np.inf
        leading = 0
        for k in range(K):
            value = frame_loglik[1, k]
            evidence = value + outline_weight * outline_ll[k] - frame_best
            if evidence < -evidence_cap:
                evidence = -evidence_cap
            recent[k] = decay * recent[k] + evidence
            if recent[k] > leader:
                leader = recent[k]
                leading = k
            # the outline model, less a margin: an irregular repetition of the action (a take
            # of another session) that its follower loses track of is still the action
            explained = outline_ll[k] - outline_fit_margin * n_obs
            if value > explained:
                explained = value
            per_channel = (explained - background) / n_obs
            if per_channel < fit_floor:
                per_channel = fit_floor
            likelihood_fit[k] = likelihood_fit[k] + (per_channel - likelihood_fit[k]) * inv_w
        for k in range(K):
            # a performance of the action advances through its template; an input that a stretch
            # of it merely resembles (a rest pose) keeps the follower stuck there
            penalty = pace_weight * math.log(pace[k] / pace_reference) if pace_weight > 0.0 \
                else 0.0
            fit[k] = likelihood_fit[k] + (penalty if penalty < 0.0 else 0.0)
        # relative to the leader: without forgetting (decay 1) the sums would drift without bound.
        # In the middle of the leader's action the others may trail further: a performer
        # rarely abandons a gesture halfway, and another performer's take is decided by all
        # of its middle
        limit = lead_cap_at_end if progress[leading] >= end_fraction else lead_cap
        for k in range(K):
            if recent[k] < leader - limit:
                recent[k] = leader - limit
            recent[k] -= leader
        state[2] += 1
    best = 0
    top = recent[0]
    for k in range(1, K):
        if recent[k] > top:
            top = recent[k]
            best = k
    total = 0.0
    for k in range(K):
        v = math.exp(recent[k] - top)
        posterior[k] = v
        total += v
    for k in range(K):
        posterior[k] /= total
    state[1] = best
    if state[2] == 0:
        return
    active = state[0]
    new = active
    if active >= 0:
        if fit[active] < thresholds[active] - leave_margin:
            new = -1
        if best != active and recent[best] - recent[active] >= switch_margin and \
                fit[best] >= thresholds[best] + enter_margin:
            new = best
    elif fit[best] >= thresholds[best] + enter_margin:
        new = best
    if new != active:
        state[0] = new
        state[3] = 0
    else:
        state[3] += 1
