"""Numba kernels of a bank's frame: its followers, its outline models, and the decision.

A ``BankModel`` (built once, see ``followers.bank_model``) and a ``BankState`` (changed every
frame) sit beside the followers' ``ForwardModel`` / ``ForwardState``. One frame
(``bank_step``): the followers (``_kernels.forward_step``), the outline models
(``outline_step``), then the decision in stages: ``_evidence`` (the posterior's running
evidence), ``_fits`` (the rejection's fit against the background model), ``_posterior``,
``_decide`` (rejection and switch hysteresis);
then the recognition mixture's weight is learned (``learn_mixture``) and the shown action's
follower gets its own restart rate (``gate``).

``state.decision (4,) int64``: [active action (-1 = none), best action, frames seen, frames
since the active action changed].
"""
from __future__ import annotations

import math

import numpy as np

from followers._exp import exp_nonpositive
from followers._jit import inline, kernel
from followers._kernels import forward_step, main_progress


@kernel
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


@kernel
def observed_log_density(xs, mean, inv_var, log_norm_sum, cap):
    """``capped_log_density`` of a frame with every channel observed: the normalising terms
    summed beforehand (``log_norm_sum``, a float), so that a channel costs its squared z-score
    alone."""
    total = 0.0
    for d in range(xs.shape[0]):
        diff = xs[d] - mean[d]
        total += min(diff * diff * inv_var[d], cap)
    return log_norm_sum - 0.5 * total


@inline
def _outline_predict(alpha, k, restart):
    """Stay or move on with probability 0.5 each (the last state absorbing), then with
    probability ``restart`` back to the first state (a new repetition, or an action taken up
    after another one)."""
    S = alpha.shape[1]
    if S > 1:
        # from the last state down, so that alpha[s - 1] is still the old value
        alpha[k, S - 1] += 0.5 * alpha[k, S - 2]
        for s in range(S - 2, 0, -1):
            alpha[k, s] = 0.5 * (alpha[k, s] + alpha[k, s - 1])
        alpha[k, 0] *= 0.5
        for s in range(S):
            alpha[k, s] *= 1.0 - restart
        alpha[k, 0] += restart


@kernel
def outline_step(fmodel, fstate, bmodel, bstate, n_obs):
    """One frame of every action's outline model: a left-to-right HMM of S states over
    stretches of its template, one diagonal Gaussian per state. Writes ``outline_ll (K,)``
    (this frame's log-likelihood given the past; 0 when n_obs = 0) and adds it to
    ``outline_total``. The first frame after a reset is emitted by the first state without a
    transition before it."""
    alpha, scratch = bstate.outline_alpha, bstate.outline_scratch
    mean, inv_var, log_norm = bmodel.outline_mean, bmodel.outline_inv_var, bmodel.outline_log_norm
    K, S = alpha.shape
    predict = not bstate.outline_fresh[0]
    bstate.outline_fresh[0] = False
    every = n_obs == fstate.xs.shape[0]
    for k in range(K):
        if predict:
            _outline_predict(alpha, k, bmodel.outline_restart)
        if n_obs == 0:
            bstate.outline_ll[k] = 0.0
            continue
        top = -np.inf
        for s in range(S):
            if every:
                b = observed_log_density(fstate.xs, mean[k, s], inv_var[k, s],
                                         bmodel.outline_log_norm_sum[k, s], fmodel.cap)
            else:
                b = capped_log_density(fstate.xs, fstate.observed, mean[k, s], inv_var[k, s],
                                       log_norm[k, s], fmodel.cap)
            scratch[s] = b
            if alpha[k, s] > 0.0 and b > top:
                top = b
        for s in range(S):
            alpha[k, s] *= exp_nonpositive(scratch[s] - top if alpha[k, s] > 0.0 else -np.inf)
        total = 0.0
        for s in range(S):
            total += alpha[k, s]
        for s in range(S):
            alpha[k, s] /= total
        bstate.outline_ll[k] = math.log(total) + top
        bstate.outline_total[k] += bstate.outline_ll[k]


@kernel
def learn_mixture(fstate, bmodel, bstate, n_obs):
    """One EM step, with forgetting, on the weight of the recognition mixture's exact
    component after a frame: a forgetful mean (``bmodel.mixture_decay`` per frame) of the
    posterior-weighted share of the frame's score that the component explains, its count in
    ``bstate.mixture_state[1]``, kept within the model's range. Sets ``fstate.mixture[0]``
    for the next frame; a frame with nothing observed changes nothing."""
    state = bstate.mixture_state
    if n_obs > 0:
        share = 0.0
        for k in range(bstate.posterior.shape[0]):
            share += bstate.posterior[k] * math.exp(fstate.frame_loglik[2, k])
        state[1] = bmodel.mixture_decay * state[1] + 1.0
        weight = state[0] + (share - state[0]) / state[1]
        state[0] = min(max(weight, bmodel.mixture_lowest), bmodel.mixture_highest)
    fstate.mixture[0] = state[0]


@inline
def progress_of_all(fmodel, fstate, bstate):
    for k in range(bstate.progress.shape[0]):
        bstate.progress[k], bstate.variance[k] = main_progress(fmodel.lengths, fstate.moments,
                                                               fstate.main, k)


@inline
def _evidence(fstate, bmodel, bstate):
    """Each action's frame score (recognition log-likelihood plus ``outline_weight`` times the
    outline model's) relative to the frame's best, at most ``evidence_cap`` against it, added
    to its forgetful sum ``recent``. Returns the leader."""
    K = bstate.recent.shape[0]
    score, outline, w = fstate.frame_loglik[1], bstate.outline_ll, bmodel.outline_weight
    frame_best = -np.inf
    for k in range(K):
        frame_best = max(frame_best, score[k] + w * outline[k])
    leader = -np.inf
    leading = 0
    for k in range(K):
        evidence = max(score[k] + w * outline[k] - frame_best, -bmodel.evidence_cap)
        bstate.recent[k] = bmodel.decay * bstate.recent[k] + evidence
        if bstate.recent[k] > leader:
            leader = bstate.recent[k]
            leading = k
    return leading


@inline
def _fits(fstate, bmodel, bstate, n_obs, cap, outlier):
    """The rejection's fit: a forgetful mean (``fit_decay``) of each follower's log-likelihood
    ratio against the background model per observed channel [nats per channel per frame],
    each frame counting at least ``fit_floor``; a frame counts as the better of the follower's
    score and its outline model's less ``outline_fit_margin`` per channel (an irregular
    repetition its follower loses track of is still the action). A frame with an ``outlier``
    channel counts ``fit_floor`` for every action."""
    background = 0.0
    if not outlier:
        background = capped_log_density(fstate.xs, fstate.observed, bmodel.background_mean,
                                        bmodel.background_weight, bmodel.background_log_norm,
                                        cap)
    bstate.fit_weight[0] = bmodel.fit_decay * bstate.fit_weight[0] + 1.0
    inv_w = 1.0 / bstate.fit_weight[0]
    for k in range(bstate.fit.shape[0]):
        per_channel = bmodel.fit_floor
        if not outlier:
            explained = max(fstate.frame_loglik[1, k],
                            bstate.outline_ll[k] - bmodel.outline_fit_margin * n_obs)
            per_channel = max((explained - background) / n_obs, bmodel.fit_floor)
        bstate.fit[k] += (per_channel - bstate.fit[k]) * inv_w


@inline
def _bound_lead(bmodel, bstate, leading):
    """No action trails the leader by more than the lead cap (``lead_cap_at_end`` once the
    leader's follower is at its end: a performer rarely abandons a gesture halfway, and
    another performer's take is decided by all of its middle); the leader at 0."""
    leader = bstate.recent[leading]
    limit = bmodel.lead_cap_at_end if bstate.progress[leading] >= bmodel.end_fraction \
        else bmodel.lead_cap
    for k in range(bstate.recent.shape[0]):
        bstate.recent[k] = max(bstate.recent[k], leader - limit) - leader


@inline
def _posterior(bstate):
    """Softmax of ``recent``; returns the best action."""
    recent, posterior = bstate.recent, bstate.posterior
    best = 0
    top = recent[0]
    for k in range(1, recent.shape[0]):
        if recent[k] > top:
            top = recent[k]
            best = k
    for k in range(recent.shape[0]):
        posterior[k] = math.exp(recent[k] - top)
    total = 0.0  # summed in a loop that writes nothing: in order wherever the arrays lie
    for k in range(recent.shape[0]):
        total += posterior[k]
    for k in range(recent.shape[0]):
        posterior[k] /= total
    return best


@inline
def _decide(bmodel, bstate, best, outlier):
    """Rejection and switch hysteresis: an action becomes active when its fit reaches its
    threshold plus ``enter_margin``, stays while above the threshold less ``leave_margin``,
    and another one takes over when its evidence is ``switch_margin`` ahead and it may
    enter. A frame with an ``outlier`` channel is no action."""
    decision, fit, threshold = bstate.decision, bstate.fit, bmodel.thresholds
    active = decision[0]
    new = active
    enters = fit[best] >= threshold[best] + bmodel.enter_margin and not outlier
    if outlier:
        new = -1
    elif active >= 0:
        if fit[active] < threshold[active] - bmodel.leave_margin:
            new = -1
        if best != active and bstate.recent[best] - bstate.recent[active] >= \
                bmodel.switch_margin and enters:
            new = best
    elif enters:
        new = best
    if new != active:
        decision[0] = new
        decision[3] = 0
    else:
        decision[3] += 1


@kernel
def gate(fstate, bmodel, bstate, shown):
    """Settings for the next frame that depend on the shown action (-1: none): its follower
    restarts from anywhere at ``active_restart``, every other one at ``idle_restart``; only
    its follower places the position inside each state's cell (``subframe``: what is
    reported, at a cost per frame as large as the emission's when a posterior is spread)."""
    for k in range(fstate.restart.shape[0]):
        fstate.restart[k, 0] = bmodel.idle_restart
        fstate.subframe[k] = False
    if shown >= 0:
        fstate.restart[shown, 0] = bmodel.active_restart
        fstate.subframe[shown] = bmodel.subframe
    bstate.gated[0] = shown


@kernel
def decide(fmodel, fstate, bmodel, bstate, n_obs):
    """The bank's decision after its followers and outline models saw a frame."""
    progress_of_all(fmodel, fstate, bstate)
    outlier = fstate.outliers[0] > 0
    if outlier:
        bstate.outlier_frames[0] += 1
    if n_obs > 0:
        leading = _evidence(fstate, bmodel, bstate)
        _fits(fstate, bmodel, bstate, n_obs, fmodel.cap, outlier)
        _bound_lead(bmodel, bstate, leading)
        bstate.decision[2] += 1
    elif outlier:
        _fits(fstate, bmodel, bstate, n_obs, fmodel.cap, outlier)
        bstate.decision[2] += 1
    best = _posterior(bstate)
    bstate.decision[1] = best
    if bstate.decision[2] > 0:
        _decide(bmodel, bstate, best, outlier)


@kernel
def bank_step(fmodel, fstate, bmodel, bstate, x):
    """One frame ``x (D,)`` (raw input) for the whole bank. Returns the shown action's index
    (the active one, or the best while none is accepted)."""
    n_obs = forward_step(fmodel, fstate, x)
    outline_step(fmodel, fstate, bmodel, bstate, n_obs)
    decide(fmodel, fstate, bmodel, bstate, n_obs)
    if bmodel.learn_mixture:
        learn_mixture(fstate, bmodel, bstate, n_obs)
    shown = bstate.decision[0] if bstate.decision[0] >= 0 else bstate.decision[1]
    if shown != bstate.gated[0]:
        gate(fstate, bmodel, bstate, shown)
    return shown


@kernel
def bank_run(fmodel, fstate, bmodel, bstate, X, trace):
    """``bank_step`` over the rows of ``X (N, D)``, what it said into ``trace`` (a
    ``bank_output.BankTrace`` of (N,) and (N, K) arrays)."""
    for n in range(X.shape[0]):
        shown = bank_step(fmodel, fstate, bmodel, bstate, X[n])
        trace.action[n] = bstate.decision[0]
        trace.progress[n] = bstate.progress[shown]
        trace.variance[n] = bstate.variance[shown]
        for k in range(bstate.progress.shape[0]):
            trace.progresses[n, k] = bstate.progress[k]
            trace.posteriors[n, k] = bstate.posterior[k]
            trace.log_likelihoods[n, k] = fstate.loglik[k]
            trace.fits[n, k] = bstate.fit[k]
        trace.outlier[n] = fstate.outliers[0] > 0
