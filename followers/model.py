"""What the forward kernels read (a model, built once) and write (a state, every frame).

K followers share one ``ForwardModel``: their templates stacked one above the other
(``S = sum(T_k)`` states in all, template ``k`` rows ``offsets[k] : offsets[k] + lengths[k]``),
their emission tables and the transition model's tables. A ``ForwardState`` holds everything
that changes per frame, preallocated; a kernel never allocates. Both are named tuples of
arrays, so that numba compiles (and caches) a kernel that takes them as a few arguments, and a
new table or state array is one new field here, read by name where it is used.

The layout of the state (see ``_kernels`` for the algorithm):

- ``alpha (2, S, M)``: the normalised forward variables of two *tracks* per template over
  (state, speed level). The *main* track is the current repetition, the *entry* track the
  hypothesis that a new one began recently (fed by the restart probabilities). Their masses
  sum to 1 after each frame; rows outside a track's support are zero.
- ``rowsum (2, S)``: per-state mass of each track; ``support (K, 2, 2)``: first and last state
  of each track's support (empty: last < first); ``moments (K, 2, 3)``: mass, mean state and
  state variance of each track; ``main (K,)``: which track is the main one; ``fresh (K,)``:
  no frame yet.
- ``loglik (K,)``: log-likelihood of everything since reset; ``frame_loglik (3, K)``: of the
  last frame under the follower's emission model (row 0) and the recognition model (row 1; a
  copy of row 0 unless ``model.dual``). With ``mixture[0] = w > 0`` the recognition model is
  a mixture per state: ``w`` on model 2 (an exact repetition: model 0's sigma times the
  template's ``exact`` scale per channel) and ``1 - w`` on model 1; row 2 is then the log of
  model 2's share of the frame's score.
- ``scale2 (2, K)``, ``scale_weight (2, K)``: each template's learned emission scale squared
  (row 0: the recursion's, row 1: the report's inside a cell) and the forgetful counts behind
  them (``model.adapt``: forgetting factor, lowest and highest scale squared; factor 0: fixed).
- ``temper (K, 3 + D)``: each template's tempering of the recursion's emission variance
  (``model.temper``): the factor in force, the lag-one and lag-zero sums of the residual
  and its last value per channel (``_kernels._temper``).
- Set by the owner between frames: ``restart (K, 2)`` [probability per frame of a new
  repetition from anywhere, from the last state], ``subframe (K,)`` (report the position
  inside a state's cell), ``mixture (1,)`` (the weight above).
- ``outliers (1,)``: channels of the last frame outside ``[model.lower, model.upper]`` (far
  outside what the templates span: a stuck or absurd sensor), left out like missing ones.
  A channel that never moves in the demonstrations (``model.moving`` false) is left out of
  every score too, unless it is an outlier (``followers.defaults.moving_channels``).
- Scratch: ``xs, observed (D,)`` (the cleaned frame), ``residual (S,)`` (each
  state's capped sum of squared z-scores), ``lift (S,)`` (each state's emission over the
  frame's largest), ``sub (4, S)`` (see ``_kernels._subframe_rows``), ``mixed (T + 2A, M)``
  (one track's rows with their speed levels mixed, ``_kernels._mix_speeds``; T the longest
  template, A the largest advance).
- ``flat_alpha``, ``flat_mixed``: ``alpha`` and ``mixed`` as one flat array each (views of the
  same memory), for the kernels that run over a block of rows and levels as one loop.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from followers._kernels import upsample_into
from followers.defaults import moving_channels, moving_rms
from followers.transitions import TransitionModel



class ForwardModel(NamedTuple):
    """The tables of K followers, read-only to the kernels."""

    templates: np.ndarray      # (S, D) float [input units]
    offsets: np.ndarray        # (K,) int64: first row of each template
    lengths: np.ndarray        # (K,) int64: states of each template
    half_windows: np.ndarray   # (K,) int64: window half-width [states]
    weights: np.ndarray        # (E, S, D): 1 / sigma**2 per emission model (E = 2 when dual)
    log_norm: np.ndarray       # (E, S, D): -0.5 log(2 pi sigma**2)
    log_norm_sum: np.ndarray   # (E, S): its sum over channels
    exact_inv2: np.ndarray     # (K, D): 1 / exact scale**2 (model 2, relative to model 0)
    exact_log: np.ndarray      # (K, D): log exact scale
    lower: np.ndarray          # (D,): a value outside [lower, upper] is an outlier (left out)
    upper: np.ndarray          # (D,)
    moving: np.ndarray         # (D,) bool: false for a channel that never moves (left out)
    advance: np.ndarray        # (A + 1, M): P(advance by a states | speed level m)
    advance_tail: np.ndarray   # (A + 1, M): P(advance >= a), what lands on the last state
    speed_change: np.ndarray   # (3, M): P(level m stays), P(from m - 1 to m), P(m + 1 to m)
    initial_speed: np.ndarray  # (M,): speed level distribution of a new repetition
    change_tiled: np.ndarray   # (3, L M): speed_change repeated along rows of M levels
    advance_tiled: np.ndarray  # (A + 1, L M): advance likewise (L: the widest kept block + A;
                               # L = 0 unless A = 3)
    adapt: np.ndarray          # (2, 3): [forgetting factor, lowest, highest scale**2] per row
    temper: np.ndarray         # (3,): [forgetting factor, largest factor (1: off), clip
                               # (sigmas)] of the tempering (``_kernels._temper``)
    cap: float                 # squared z-scores are capped at this (inf: plain Gaussian)
    prune: float               # edge states below this mass are dropped (0: never)
    tilt: float                # steepest prior slope across a cell [nats per frame]
    dual: bool                 # a recognition model (rows 1 and 2 of frame_loglik)


class ForwardState(NamedTuple):
    """What changes every frame (see the module docstring)."""

    alpha: np.ndarray
    rowsum: np.ndarray
    logb: np.ndarray
    support: np.ndarray
    moments: np.ndarray
    main: np.ndarray
    fresh: np.ndarray
    loglik: np.ndarray
    frame_loglik: np.ndarray
    scale2: np.ndarray
    scale_weight: np.ndarray
    temper: np.ndarray
    restart: np.ndarray
    subframe: np.ndarray
    mixture: np.ndarray
    outliers: np.ndarray
    xs: np.ndarray
    observed: np.ndarray
    residual: np.ndarray
    lift: np.ndarray
    sub: np.ndarray
    mixed: np.ndarray
    flat_alpha: np.ndarray
    flat_mixed: np.ndarray


class Forward(NamedTuple):
    """A forward model with what its owner needs to reset a state."""

    model: ForwardModel
    resolution: int            # states per template frame
    restart: tuple[float, float]    # the chain's (from anywhere, from the last state)
    scale_prior: np.ndarray    # (2,): weight of scale 1 at each reset, per row of scale2


def _stacked(arrays: list[np.ndarray], owned: bool) -> np.ndarray:
    """The (T_k, D) arrays one above the other in a new C-contiguous float64 array, or, when
    there is one and it is ``owned`` (made here, not the caller's), that array itself."""
    if owned and len(arrays) == 1:
        return np.ascontiguousarray(arrays[0], dtype=np.float64)
    return np.ascontiguousarray(np.concatenate(arrays, axis=0), dtype=np.float64)


def upsample(values: np.ndarray, factor: int) -> np.ndarray:
    """(T, D) -> (factor * (T - 1) + 1, D): linear interpolation, original frames kept."""
    T, D = values.shape
    out = np.empty((factor * (T - 1) + 1, D))
    upsample_into(values, factor, out)
    return out


def _adaptation(setting) -> tuple[np.ndarray, float]:
    """([forgetting factor, lowest**2, highest**2], prior) of an online scale, or zeros."""
    if setting is None:
        return np.zeros(3), 0.0
    memory, prior, lowest, highest = (float(v) for v in setting)
    return np.array([np.exp(-1.0 / memory), lowest ** 2, highest ** 2]), prior


def _emission_tables(sigmas: list[np.ndarray], rec: list[np.ndarray] | None, factor: int,
                     S: int):
    """(weights, log_norm, log_norm_sum) of each emission model (``sigmas``; ``rec`` when
    given): weights = 1 / sigma**2 and log_norm = 0.5 log(weights / 2 pi), from the K
    templates' (T_k, D) sigmas upsampled by ``factor`` (``upsample``) to S rows in all,
    each written in place (every temporary of this size would be fresh memory to fault in)."""
    models = (sigmas,) if rec is None else (sigmas, rec)
    weights = np.empty((len(models), S, sigmas[0].shape[1]))
    for row, model in enumerate(models):
        if factor == 1:
            np.concatenate(model, axis=0, out=weights[row])
            continue
        first = 0
        for sigma in model:
            last = first + factor * (sigma.shape[0] - 1) + 1
            upsample_into(np.ascontiguousarray(sigma, dtype=np.float64), factor,
                          weights[row, first:last])
            first = last
    np.square(weights, out=weights)
    np.reciprocal(weights, out=weights)
    log_norm = np.log(weights)
    log_norm -= math.log(2.0 * math.pi)
    log_norm *= 0.5
    return weights, log_norm, log_norm.sum(axis=2)


def _tempering(setting) -> np.ndarray:
    """[forgetting factor, largest factor, clip] of the tempering; [0, 1, 0] (off) for None."""
    if setting is None:
        return np.array([0.0, 1.0, 0.0])
    memory, cap, clip = (float(v) for v in setting)
    return np.array([math.exp(-1.0 / memory), cap, min(clip, 1e300)])


def _transition_tables(transitions: TransitionModel):
    """The transition model's tables by level along the last axis (what the kernels'
    innermost loops run over)."""
    advance = np.asarray(transitions.advance, dtype=np.float64)
    # tail[m, r] = P(advance >= r): what lands on the absorbing last state
    tail = np.cumsum(advance[:, ::-1], axis=1)[:, ::-1]
    change = np.asarray(transitions.speed_change, dtype=np.float64)
    into = np.zeros((3, change.shape[0]))
    into[0] = change[:, 1]
    into[1, 1:] = change[:-1, 2]
    into[2, :-1] = change[1:, 0]
    return (np.ascontiguousarray(advance.T), np.ascontiguousarray(tail.T), into,
            np.ascontiguousarray(transitions.initial_speed, dtype=np.float64))


def _tiled(tables, windows: np.ndarray, lengths: np.ndarray):
    """The speed change's and the advance's (rows, M) tables each repeated for as many rows
    of M levels as a track's transition reaches at most (a kept block is at most 2 p + 1 states
    of its template, and the advance adds A), so that a kernel runs over a block of rows and
    levels as one flat array. The advance only for A = 3 (the flat pass's four taps; other
    advances run state by state): none is made that no kernel reads."""
    advance, _, into, _ = tables
    rows = int(np.minimum(lengths, 2 * np.minimum(windows, lengths) + 1).max())
    rows += advance.shape[0] - 1
    flat = rows if advance.shape[0] == 4 else 0
    return np.tile(into, rows), np.tile(advance, flat)


def _exact_scales(exact, K: int, D: int) -> np.ndarray:
    scales = np.ones((K, D))
    if exact is None:
        return scales
    try:
        scales[:] = exact
    except ValueError:
        raise ValueError(f"the exact-repetition scale must be a float or ({K}, {D}), got shape "
                         f"{np.shape(exact)}") from None
    if not (np.all(scales > 0.0) and np.all(np.isfinite(scales))):
        raise ValueError(f"the exact-repetition scales must be finite and > 0, got "
                         f"{scales.min()} to {scales.max()}")
    return scales


def span_bounds(stacked: np.ndarray, span: float,
                moving: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper), each (D,): ``span`` times each channel's range over ``stacked`` beyond
    that range (a channel that never moves counts a twentieth of the RMS range over the
    ``moving`` channels; if none moves, 1), outside which an input value is an outlier."""
    lo, hi = stacked.min(axis=0), stacked.max(axis=0)
    width = hi - lo
    rms = moving_rms(width, moving)
    width = np.maximum(width, 0.05 * rms) if rms > 0.0 else np.ones_like(width)
    return lo - span * width, hi + span * width


def build_forward(templates: list[np.ndarray], sigmas: list[np.ndarray], windows,
                  transitions: TransitionModel, *, cap: float, prune: float, tilt: float,
                  outlier_span: float, recognition: list[np.ndarray] | None = None,
                  exact=None, adaptation=None, report_adaptation=None, temper=None,
                  moving=None) -> Forward:
    """The forward model of K followers that share one transition model.

    templates, sigmas : K (T_k, D) float arrays (validated) [input units]; windows (K,) int
        [template frames]; with ``transitions.resolution = R > 1`` each template and sigma is
        upsampled to R (T_k - 1) + 1 states.
    cap : squared z-scores are capped at it; prune : mass below which edge states are dropped;
    tilt : see ``_cells._tilt``; outlier_span : see ``span_bounds``.
    recognition : K (T_k, D) sigmas of a second emission model that only scores frames, or
        None; exact : with it, the exact-repetition component's scale relative to ``sigmas``
        (a float or (K, D)), or None for no mixture.
    adaptation, report_adaptation : (memory [frames], prior [frames], lowest, highest scale)
        of the recursion's and the report's online emission scale, or None (fixed).
    temper : (memory [frames], largest factor, clip [sigmas]) of the tempering of the
        recursion's emission variance by the residual's correlation, or None (none).
    moving : (D,) bool, the channels that move in the demonstrations (None: in the templates).
    """
    if moving is None:
        moving = moving_channels(templates)
    R = transitions.resolution
    if R > 1:
        # R states per template frame: the template and its sigmas (``_emission_tables``),
        # linearly interpolated
        templates = [upsample(t, R) for t in templates]
        windows = np.asarray(windows) * R
    K, D = len(templates), int(templates[0].shape[1])
    if exact is not None and recognition is None:
        raise ValueError("an exact-repetition mixture needs a recognition model")
    lengths = np.array([t.shape[0] for t in templates], dtype=np.int64)
    offsets = np.zeros(K, dtype=np.int64)
    offsets[1:] = np.cumsum(lengths)[:-1]
    # one template is taken as it is (R > 1: the upsampled copy); set-up time is mostly the
    # first touch of fresh memory (page faults), so no array is copied that need not be
    stacked = _stacked(templates, owned=R > 1)
    weights, log_norm, log_norm_sum = _emission_tables(sigmas, recognition, R,
                                                       stacked.shape[0])
    scales = _exact_scales(exact, K, D)
    lower, upper = span_bounds(stacked, outlier_span, moving)
    adapt, prior = _adaptation(adaptation)
    report, report_prior = _adaptation(report_adaptation)
    windows = np.ascontiguousarray(windows, dtype=np.int64)
    tables = _transition_tables(transitions)
    model = ForwardModel(
        stacked, offsets, lengths, windows, weights, log_norm, log_norm_sum,
        np.ascontiguousarray(1.0 / scales ** 2), np.ascontiguousarray(np.log(scales)), lower,
        upper, np.ascontiguousarray(moving, dtype=np.bool_), *tables,
        *_tiled(tables, windows, lengths), np.stack([adapt, report]),
        _tempering(temper), float(cap), float(prune), float(tilt), recognition is not None)
    return Forward(model, R, (transitions.restart_anywhere, transitions.restart),
                   np.array([prior, report_prior]))


def forward_state(forward: Forward) -> ForwardState:
    """A fresh state for ``forward`` (reset)."""
    model = forward.model
    K, S, D = model.lengths.shape[0], model.templates.shape[0], model.templates.shape[1]
    M = model.initial_speed.shape[0]
    A = model.advance.shape[0] - 1
    alpha = np.zeros((2, S, M))
    mixed = np.zeros((int(model.lengths.max()) + 2 * A, M))
    state = ForwardState(
        alpha=alpha, rowsum=np.zeros((2, S)), logb=np.zeros((3, S)),
        support=np.zeros((K, 2, 2), dtype=np.int64), moments=np.zeros((K, 2, 3)),
        main=np.zeros(K, dtype=np.int64), fresh=np.ones(K, dtype=np.bool_), loglik=np.zeros(K),
        frame_loglik=np.zeros((3, K)), scale2=np.ones((2, K)), scale_weight=np.zeros((2, K)),
        temper=np.zeros((K, 3 + D)), restart=np.tile(forward.restart, (K, 1)),
        subframe=np.zeros(K, dtype=np.bool_),
        mixture=np.zeros(1), outliers=np.zeros(1, dtype=np.int64), xs=np.zeros(D),
        observed=np.zeros(D), residual=np.zeros(S), lift=np.zeros(S), sub=np.zeros((4, S)),
        mixed=mixed, flat_alpha=alpha.reshape(-1), flat_mixed=mixed.reshape(-1))
    _reset_tracks(forward, state)  # alpha and rowsum are fresh zeros
    return state


def reset_forward(forward: Forward, state: ForwardState) -> None:
    """Forget every frame: the next one is the first of a performance (the owner's settings,
    ``restart``, ``subframe`` and ``mixture``, are left as they are)."""
    state.alpha[:] = 0.0
    state.rowsum[:] = 0.0
    _reset_tracks(forward, state)


def _reset_tracks(forward: Forward, state: ForwardState) -> None:
    """``reset_forward`` but for alpha and rowsum."""
    state.support[:, :, 0] = 1
    state.support[:, :, 1] = 0
    state.moments[:] = 0.0
    state.main[:] = 0
    state.fresh[:] = True
    state.loglik[:] = 0.0
    state.frame_loglik[:] = 0.0
    state.outliers[:] = 0
    state.scale2[:] = 1.0
    state.scale_weight[:] = forward.scale_prior[:, None]
    state.temper[:] = 0.0
    state.temper[:, 0] = 1.0
    state.temper[:, 2] = 1e-9


def check_frame(x, channels: int) -> np.ndarray:
    """``x`` as a (channels,) float64 array, or ValueError naming both shapes."""
    arr = np.ascontiguousarray(x, dtype=np.float64)
    if arr.shape != (channels,):
        raise ValueError(f"frame must have {channels} channel(s) (shape ({channels},)), got "
                         f"shape {arr.shape}")
    return arr
