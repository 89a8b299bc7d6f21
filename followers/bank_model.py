"""What a bank adds to its followers' forward model: built once (``BankModel``) and changed
every frame (``BankState``), read and written by ``_bank_kernels``.

- The followers' sigmas: with the defaults, two multiples of a lone follower's default sigma
  (``default_sigma``, its base level from all templates together so that every follower
  measures distance alike): ``following_scale`` for the forward recursion, and
  ``recognition_scale`` (floored at ``recognition_floor`` of each template's own channel
  spread) for the recognition score, with an exact-repetition component as narrow as each
  template's own noise.
- The background model: one Gaussian over every frame of every take ("some pose of this
  performer"), against which the rejection's fit is measured. Its spread, which also floors
  the outline models' variances, is floored like the default sigma's (``sigma_floor`` times
  the RMS spread): no model of the bank resolves a channel finer than its followers do.
- The outline models: per action a coarse left-to-right HMM of ``outline_states`` states over
  equal stretches of its takes, each a diagonal Gaussian with the mean and variance of that
  stretch of every take.
- An action demonstrated several times (``followers.demos``) is one template, their average;
  the spread of its takes widens both sigmas per state.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from followers.config import BankConfig
from followers.defaults import (exact_scales, moving_columns, noise_sigmas,
                               pooled_sigma, recognition_sigma)


class BankModel(NamedTuple):
    """A bank's tables and constants, read-only to the kernels (see ``BankConfig`` for the
    meaning of the constants)."""

    outline_mean: np.ndarray         # (K, S, D): each outline state's mean [input units]
    outline_inv_var: np.ndarray      # (K, S, D): 1 / its variance
    outline_log_norm: np.ndarray     # (K, S, D): -0.5 log(2 pi variance)
    outline_log_norm_sum: np.ndarray  # (K, S): its sum over channels
    background_mean: np.ndarray      # (D,): the background Gaussian
    background_weight: np.ndarray    # (D,): 1 / its variance
    background_log_norm: np.ndarray  # (D,)
    thresholds: np.ndarray           # (K,): an action is accepted while fit >= threshold
    outline_weight: float
    outline_fit_margin: float        # [nats per channel], finite
    outline_restart: float
    decay: float                     # forgetting factor of the evidence per frame
    fit_decay: float                 # forgetting factor of the fit per frame
    evidence_cap: float
    lead_cap: float
    lead_cap_at_end: float
    end_fraction: float
    fit_floor: float
    enter_margin: float
    leave_margin: float
    switch_margin: float
    learn_mixture: bool              # learn the exact component's weight (a mixture exists)
    mixture_start: float             # its weight at each reset (0: no mixture)
    mixture_prior: float             # [frames]
    mixture_decay: float
    mixture_lowest: float
    mixture_highest: float
    idle_restart: float
    active_restart: float
    subframe: bool                   # the shown action's follower reports inside its cells


class BankState(NamedTuple):
    """What a bank changes every frame, besides its followers' state."""

    outline_alpha: np.ndarray    # (K, S): each outline model's normalised forward variables
    outline_scratch: np.ndarray  # (S,)
    outline_ll: np.ndarray       # (K,): this frame's outline log-likelihood
    outline_total: np.ndarray    # (K,): its sum since reset
    outline_fresh: np.ndarray    # (1,) bool: no frame yet
    recent: np.ndarray           # (K,) <= 0: the posterior's evidence, the leader at 0
    fit: np.ndarray              # (K,): the rejection's fit [nats per channel per frame]
    fit_weight: np.ndarray       # (1,): the fit's forgetful count
    posterior: np.ndarray        # (K,): over actions
    progress: np.ndarray         # (K,): each follower's main-track progress [0, 1]
    variance: np.ndarray         # (K,): its variance [progress units squared]
    decision: np.ndarray         # (4,) int64: see ``_bank_kernels``
    mixture_state: np.ndarray    # (2,): [weight, forgetful count]
    gated: np.ndarray            # (1,) int64: the action the followers were last gated for
    outlier_frames: np.ndarray   # (1,) int64: frames since reset with an outlier channel


def check_size(arrays: list[np.ndarray], config: BankConfig, *, levels: int,
               resolution: int) -> int:
    """The bytes a bank of ``arrays`` needs for its model and state (with what building them
    holds at once); ValueError when that is above ``config.max_bytes``."""
    states = resolution * sum(a.shape[0] for a in arrays)
    channels = arrays[0].shape[1]
    # templates, emission tables of two models, sigmas while building; forward variables
    need = 8 * states * (8 * channels + 2 * levels + 10)
    if need > config.max_bytes:
        raise ValueError(
            f"a bank of {len(arrays)} templates ({states} states x {channels} channels) needs "
            f"about {need / 1e9:.1f} GB, more than BankConfig.max_bytes = "
            f"{config.max_bytes / 1e9:.1f} GB; use fewer or shorter templates, or pass "
            f"config=BankConfig(max_bytes=...) to allow it")
    return need


def segment_moments(stacked: np.ndarray, starts: np.ndarray):
    """(mean, variance), each (len(starts), D), of the runs of rows of ``stacked (N, D)`` that
    begin at ``starts`` (increasing, the first 0) and end where the next begins."""
    counts = np.diff(np.append(starts, stacked.shape[0]))[:, None]
    mean = np.add.reduceat(stacked, starts, axis=0) / counts
    centred = stacked - np.repeat(mean, counts[:, 0], axis=0)
    return mean, np.add.reduceat(centred * centred, starts, axis=0) / counts


def pooled_moments(mean: np.ndarray, variance: np.ndarray, counts: np.ndarray,
                   owner: np.ndarray, K: int):
    """(mean, variance), each (K, ...), of groups of segments pooled: segment ``i`` (its
    ``mean``, ``variance`` and ``counts`` rows, leading axis) belongs to group ``owner[i]``."""
    total = np.zeros((K,) + counts.shape[1:])
    np.add.at(total, owner, counts)
    first = np.zeros((K,) + mean.shape[1:])
    second = np.zeros_like(first)
    np.add.at(first, owner, counts * mean)
    np.add.at(second, owner, counts * (variance + mean * mean))
    first /= total
    return first, np.maximum(second / total - first * first, 0.0)


def bank_sigmas(actions: list, config: BankConfig, moving: np.ndarray, own=None):
    """(following, recognition, exact) sigmas of the default emission models: K (T_k, D)
    sigmas for the recursion, K for the recognition score, and the exact-repetition
    component's (K, D) scale relative to the following sigma (None: no mixture).

    actions : K ``followers.demos.Demonstrations``, one take each or several. An action of
    several takes adds their spread (``FollowerConfig.spread_weight`` of its square) to both
    sigmas per state, and its exact component is as narrow as its takes' own noise.
    moving : (D,) bool, the channels that move in the takes (``defaults.moving_channels``).
    own : K (T_k, D) sigmas or None (a trained follower's per-state spread, say): that
    action's base sigma, floored at the pooled default; None: the pooled default."""
    arrays = [a.template for a in actions]
    own = own or [None] * len(arrays)
    takes = [t for a in actions for t in a.takes]
    pooled = pooled_sigma(takes, config.follower)
    bases = [np.broadcast_to(pooled, a.shape) if o is None else np.maximum(o, pooled)
             for a, o in zip(arrays, own)]
    offsets = np.cumsum([0] + [a.shape[0] for a in arrays[:-1]])
    spread = np.zeros((len(arrays), moving.size))
    _, variance = segment_moments(np.concatenate(moving_columns(arrays, moving), axis=0),
                                  offsets)
    spread[:, moving] = np.sqrt(variance)
    weight = config.follower.spread_weight

    def widened(scale, base, action):
        sigma = scale * base
        return sigma if action.count < 2 else np.sqrt(sigma ** 2 + weight * action.spread ** 2)

    sigmas = [widened(config.following_scale, b, a) for b, a in zip(bases, actions)]
    recognition = [recognition_sigma(s, widened(config.recognition_scale, b, a), config, moving)
                   for s, b, a in zip(spread, bases, actions)]
    exact = None
    if config.mixture_start > 0.0:
        typical = np.stack([pooled if o is None else np.median(b, axis=0)
                            for o, b in zip(own, bases)])
        noise = noise_sigmas(arrays)
        for k, action in enumerate(actions):
            if action.noise is not None:
                noise[k] = action.noise
        exact = exact_scales(noise, typical, config.exact_floor)
        exact /= config.following_scale
    return sigmas, recognition, exact


def outline_models(stacked: np.ndarray, lengths: np.ndarray, states: int,
                   config: BankConfig, owner: np.ndarray | None = None):
    """Every action's outline model: ``(mean, variance)``, each (K, states, D), from
    ``states`` equal stretches of each take (the first ``T % states`` a frame longer; every
    T >= states), stretch ``j`` of an action's takes pooled; ``stacked (sum T_i, D)``: the
    takes one above the other, ``lengths`` theirs, ``owner`` each take's action (None: one
    take per action)."""
    n, D = lengths.shape[0], stacked.shape[1]
    offsets = np.cumsum(np.append(0, lengths[:-1]))
    q, r = np.divmod(lengths, states)
    i = np.arange(states)
    starts = (offsets[:, None] + i * q[:, None] + np.minimum(i, r[:, None])).ravel()
    mean, variance = segment_moments(stacked, starts)
    whole_mean, own = segment_moments(stacked, offsets)
    mean, variance = mean.reshape(n, states, D), variance.reshape(n, states, D)
    K = n
    if owner is not None and owner.shape[0] > int(owner.max()) + 1:
        K = int(owner.max()) + 1
        counts = np.diff(np.append(starts, stacked.shape[0])).reshape(n, states, 1)
        mean, variance = pooled_moments(mean, variance, counts, owner, K)
        _, own = pooled_moments(whole_mean, own, lengths[:, None].astype(float), owner, K)
    spread = stacked.std(axis=0)
    rms = float(np.sqrt(np.mean(spread ** 2)))
    spread = np.maximum(spread, config.follower.sigma_floor * rms) if rms > 0.0 else \
        np.ones_like(spread)
    floor = config.outline_own_variance * own + config.outline_floor * spread ** 2
    return mean, variance + floor[:, None, :], spread


def moving_outlines(stacked: np.ndarray, moving: np.ndarray, lengths: np.ndarray, states: int,
                    config: BankConfig, owner: np.ndarray):
    """``outline_models`` and the background's mean, from the ``moving (D,)`` channels alone;
    a channel that never moves (left out of every score) gets its value as the mean and a
    variance and spread of 1."""
    if moving.all():
        return (*outline_models(stacked, lengths, states, config, owner), stacked.mean(axis=0))
    live = stacked[:, moving]
    live_mean, live_variance, live_spread = outline_models(live, lengths, states, config, owner)
    mean = np.empty(live_mean.shape[:2] + moving.shape)
    mean[...] = stacked[0]
    variance = np.ones_like(mean)
    spread, background = np.ones(moving.size), stacked[0].copy()
    mean[..., moving], variance[..., moving], spread[moving] = (live_mean, live_variance,
                                                                live_spread)
    background[moving] = live.mean(axis=0)
    return mean, variance, spread, background


def build_bank_model(actions: list, config: BankConfig, *, resolution: int,
                     restart: tuple[float, float], subframe: bool,
                     mixture: float, moving: np.ndarray) -> BankModel:
    """The bank's model for ``actions`` (K ``followers.demos.Demonstrations``);
    ``resolution``: the followers' states per template frame; ``restart``: their chain's (from
    anywhere, from the last state) per frame; ``subframe``: the shown follower reports inside
    its cells; ``mixture``: the exact component's starting weight (0: no mixture); ``moving``:
    (D,) bool, the channels that move in the takes."""
    c = config
    K = len(actions)
    takes = [t for a in actions for t in a.takes]
    owner = np.repeat(np.arange(K), [a.count for a in actions])
    lengths = np.array([t.shape[0] for t in takes])
    stacked = np.concatenate(takes, axis=0)
    outline_mean, variance, spread, background_mean = moving_outlines(
        stacked, moving, lengths, min(c.outline_states, lengths.min()), c,
        owner)
    rejecting = math.isfinite(c.reject_margin)
    hysteresis = c.reject_hysteresis if rejecting else 0.0
    idle = max(restart)
    log_norm = -0.5 * np.log(2.0 * np.pi * variance)
    return BankModel(
        outline_mean=outline_mean, outline_inv_var=1.0 / variance, outline_log_norm=log_norm,
        outline_log_norm_sum=log_norm.sum(axis=2),
        background_mean=background_mean, background_weight=1.0 / spread ** 2,
        background_log_norm=-0.5 * np.log(2.0 * np.pi * spread ** 2),
        thresholds=np.full(K, c.reject_margin if rejecting else -1e300),
        outline_weight=c.outline_weight,
        # a finite stand-in for inf (the kernel subtracts it times the channel count)
        outline_fit_margin=min(c.outline_fit_margin, 1e300), outline_restart=c.outline_restart,
        decay=math.exp(-1.0 / c.memory), fit_decay=math.exp(-1.0 / c.fit_memory),
        evidence_cap=c.evidence_cap, lead_cap=c.lead_cap, lead_cap_at_end=c.lead_cap_at_end,
        end_fraction=c.end_fraction, fit_floor=c.fit_floor, enter_margin=hysteresis,
        leave_margin=hysteresis, switch_margin=c.switch_margin,
        learn_mixture=mixture > 0.0 and c.learn_mixture, mixture_start=mixture,
        mixture_prior=c.mixture_prior, mixture_decay=math.exp(-1.0 / c.mixture_memory),
        mixture_lowest=min(c.mixture_lowest, mixture),
        mixture_highest=max(c.mixture_highest, mixture), idle_restart=idle,
        active_restart=min(idle, c.active_restart), subframe=subframe)


def bank_state(model: BankModel) -> BankState:
    """A bank state for ``model`` (reset it before use)."""
    K, S = model.outline_mean.shape[:2]
    return BankState(
        outline_alpha=np.zeros((K, S)), outline_scratch=np.zeros(S), outline_ll=np.zeros(K),
        outline_total=np.zeros(K), outline_fresh=np.ones(1, dtype=np.bool_),
        recent=np.zeros(K), fit=np.zeros(K), fit_weight=np.zeros(1), posterior=np.zeros(K),
        progress=np.zeros(K),
        variance=np.zeros(K), decision=np.zeros(4, dtype=np.int64), mixture_state=np.zeros(2),
        gated=np.zeros(1, dtype=np.int64), outlier_frames=np.zeros(1, dtype=np.int64))


def reset_bank(model: BankModel, state: BankState) -> None:
    """Forget every frame (the followers' state is reset by its owner)."""
    K = state.recent.shape[0]
    state.outline_alpha[:] = 0.0
    state.outline_alpha[:, 0] = 1.0
    state.outline_ll[:] = 0.0
    state.outline_total[:] = 0.0
    state.outline_fresh[:] = True
    for name in ("recent", "fit", "fit_weight", "progress", "variance"):
        getattr(state, name)[:] = 0.0
    state.posterior[:] = 1.0 / K
    state.decision[:] = (-1, 0, 0, 0)
    state.outlier_frames[:] = 0
    state.mixture_state[:] = (model.mixture_start, model.mixture_prior)
