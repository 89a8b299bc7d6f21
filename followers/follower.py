"""One action follower: a template turned into a left-to-right HMM, followed frame by frame."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from followers import _kernels
from followers._jit import entry as compiled_entry
from followers.config import FollowerConfig
from followers.defaults import as_sigma, as_template, as_window, default_sigma, default_window
from followers.demos import Demonstrations, combine, is_takes
from followers.intervals import (interval_state, reset_interval, stacked, widen,
                                 widen_arguments)
from followers.model import build_forward, check_frame, forward_state, reset_forward
from followers.transitions import TransitionModel, transition_model


@dataclass(frozen=True, slots=True)
class FollowerOutput:
    """What a follower says after one frame.

    progress : float in [0, 1]: expected template position / (T - 1)
    variance : float >= 0: variance of that position [progress units squared] (times the
        performer's tempo to the power ``tempo_exponent`` with ``tempo_variance``, widened
        when the residual is correlated from frame to frame: ``followers.intervals``)
    log_likelihood : float: log-likelihood of everything seen since reset (natural log of a
        density in the input's units; comparable across templates with the same channels)
    frame_log_likelihood : float: the last frame's share of ``log_likelihood``
    """

    progress: float
    variance: float
    log_likelihood: float
    frame_log_likelihood: float


@dataclass(frozen=True)
class FollowerTrace:
    """A follower's outputs over a sequence: each array (N,) float64, same units as
    :class:`FollowerOutput`."""

    progress: np.ndarray
    variance: np.ndarray
    log_likelihood: np.ndarray


def chain(config: FollowerConfig, transitions=None) -> TransitionModel:
    """The transition model of ``config`` (or ``transitions``, a TransitionModel, as given)."""
    if isinstance(transitions, TransitionModel):
        return transitions
    c = config
    if c.transitions != "speed":
        return transition_model(c.transitions, restart=c.restart,
                                restart_anywhere=c.restart_anywhere)
    return transition_model("speed", min_speed=c.speed_min, max_speed=c.speed_max,
                            levels=c.speed_levels, speed_jitter=c.speed_jitter,
                            speed_prior=c.speed_prior, resolution=c.resolution,
                            restart=c.restart, restart_anywhere=c.restart_anywhere)


def resolve_config(config, transitions, preset) -> FollowerConfig:
    """A FollowerConfig from the ``config=`` and ``transitions=`` arguments: a chain's name
    alone picks its ``preset``; with a config too, it replaces the config's chain; a
    TransitionModel picks the preset of its kind (its own resolution and rates are used)."""
    if isinstance(transitions, TransitionModel):
        base = preset(transitions.kind) if config is None else config
        return base.replace(transitions=transitions.kind, resolution=1, tempo_variance=False)
    if transitions is not None and not isinstance(transitions, str):
        raise TypeError(f"transitions must be a name ('speed', 'mop', 'skip') or a "
                        f"TransitionModel, got {type(transitions).__name__}")
    if config is None:
        return preset(transitions or "speed")
    if not isinstance(config, FollowerConfig):
        raise TypeError(f"config must be a FollowerConfig, got {type(config).__name__}")
    if transitions is None or transitions == config.transitions:
        return config
    return config.replace(transitions=transitions,
                          resolution=config.resolution if transitions == "speed" else 1)


def adaptation(config: FollowerConfig, learn: bool):
    """(memory, prior, lowest, highest) of an online emission scale, or None when fixed."""
    if not learn:
        return None
    return (config.adapt_memory, config.adapt_prior, config.adapt_lowest, config.adapt_highest)


def tempering(config: FollowerConfig, on: bool):
    """(memory, largest factor, clip) of the recursion's tempering by the residual's
    correlation, or None when off."""
    if not (on and config.residual_temper > 1.0):
        return None
    return (config.residual_memory, config.residual_temper, config.outlier_sigmas)


def _own(array: np.ndarray, given) -> np.ndarray:
    """``array`` (validated from ``given``), copied if it shares memory with ``given``."""
    if isinstance(given, np.ndarray) and np.may_share_memory(array, given):
        return array.copy()
    return array


class Follower:
    """Follows a performer through one recorded action (MOP, section 3.2).

    template : (T, D) float [input units], T >= 2 (a (T,) array is one channel): the action as
        demonstrated, one HMM state per frame; or a list of such arrays, several takes of the
        action: the template is then their average and the default sigma is widened per state
        by how far they stray from it (``followers.demos``; ``demonstrations``); or those takes
        already combined (a :class:`~followers.demos.Demonstrations`).
    sigma : float, (D,) or (T, D) float [input units], optional: the Gaussian emission's
        standard deviation. Default: estimated from the template (``followers.defaults``),
        its scale then learned online (``config.adapt_sigma``); a given sigma is used as given.
    window : int, optional: half-width p of the forward window [template frames]; ``window >=
        T`` runs the full forward algorithm. Default: ``followers.defaults.default_window``.
    transitions : ``"speed"`` (default), ``"mop"`` (the paper to the letter), ``"skip"``, or a
        :class:`~followers.transitions.TransitionModel` used as it is. A name alone selects
        ``FollowerConfig.preset(name)``.
    config : :class:`~followers.config.FollowerConfig`, optional: every other setting.
    """

    def __init__(self, template, *, sigma=None, window=None, transitions=None,
                 config: FollowerConfig | None = None):
        self.config = config = resolve_config(config, transitions, FollowerConfig.preset)
        model = chain(config, transitions)
        self._demonstrations = None
        if isinstance(template, Demonstrations):
            self._demonstrations = template
            tmpl = template.template.copy()
        elif is_takes(template):
            self._demonstrations = combine(template, config=config)
            tmpl = self._demonstrations.template
        else:
            # our own copy where validation handed back the caller's array: the template is
            # made read-only below, and must not change under the follower
            tmpl = _own(as_template(template), template)
        T, D = tmpl.shape
        given = self._sigma_given = sigma is not None
        if given:
            self._sigma = _own(as_sigma(sigma, (T, D)), sigma)
        elif self._demonstrations is None:
            self._sigma = default_sigma(tmpl, config=config)
        else:
            d = self._demonstrations
            base = default_sigma(tmpl, pooled=list(d.takes), config=config)
            self._sigma = np.sqrt(base ** 2 + config.spread_weight * d.spread ** 2)
        self._window = default_window(T, config) if window is None else as_window(window, T)
        self._transitions = model
        mop = model.kind == "mop"
        self._forward = build_forward(
            [tmpl], [self._sigma], np.array([self._window]), model,
            cap=config.outlier_sigmas ** 2, prune=config.prune_mass, tilt=config.subframe_tilt,
            outlier_span=config.outlier_span,
            adaptation=adaptation(config, config.adapt_sigma and not given and not mop),
            report_adaptation=adaptation(config, not given),
            temper=tempering(config, not given and not mop))
        self._state = forward_state(self._forward)
        self._state.subframe[:] = config.subframe
        self._template = tmpl
        self._template.setflags(write=False)
        # [gain, lowest, highest, exponent] of _kernels.tempo_calibrate, or None
        self._tempo = np.array([1.0 / config.tempo_memory, float(model.speeds.min()),
                                float(model.speeds.max()), config.tempo_exponent]
                               ) if config.tempo_variance else None
        self._tempo_state = np.array([0.0, 1.0])
        # one frame's progress and variance for the kernels, reused
        self._frame_progress, self._frame_variance = np.zeros(1), np.zeros(1)
        # the variance widened by the residual's autocorrelation (followers.intervals)
        self._intervals = stacked([tmpl], [self._sigma], self._forward.model.moving)
        self._interval_state = interval_state(D)
        self._frame = np.zeros((1, D))
        self._on = np.zeros(1, dtype=np.int64)
        self._calls = ()  # per-frame kernels (``_entries``)

    # ---- parameters ---------------------------------------------------------------------------
    @property
    def template(self) -> np.ndarray:
        """(T, D) float64, read-only."""
        return self._template

    @property
    def demonstrations(self):
        """The takes combined (:class:`followers.demos.Demonstrations`) when the follower was
        made from several, else None."""
        return self._demonstrations

    @property
    def sigma(self) -> np.ndarray:
        """(T, D) float64 [input units]: per state and channel."""
        return self._sigma.copy()

    @property
    def sigma_given(self) -> bool:
        """True when the sigma was given (``sigma=``), not estimated from the template."""
        return self._sigma_given

    @property
    def window(self) -> int:
        """Window half-width p [template frames]."""
        return self._window

    @property
    def sigma_scale(self) -> float:
        """The emission scale learned online (sigma in use = ``sigma`` x this); 1.0 until the
        first frame, and always 1.0 when the scale is not adapted."""
        return float(math.sqrt(self._state.scale2[0, 0]))

    @property
    def transitions(self) -> TransitionModel:
        return self._transitions

    @property
    def length(self) -> int:
        return int(self._template.shape[0])

    @property
    def channels(self) -> int:
        return int(self._template.shape[1])

    # ---- running --------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything seen: the next frame is the first of a performance."""
        reset_forward(self._forward, self._state)
        self._tempo_state[:] = (0.0, 1.0)
        reset_interval(self._interval_state)

    def step(self, x) -> FollowerOutput:
        """Follow one frame ``x (D,) float`` (NaN = missing channel; all NaN = no observation)."""
        self._frame[0] = check_frame(x, self.channels)
        for kernel, args in self._calls or self._entries():
            kernel(*args)
        state = self._state
        return FollowerOutput(float(self._frame_progress[0]), float(self._frame_variance[0]),
                              float(state.loglik[0]), float(state.frame_loglik[0, 0]))

    def _entries(self):
        """``step``'s kernels and their arguments, resolved once for its own arrays
        (``followers._jit.entry``: no type resolution per frame)."""
        args = (self._forward.model, self._state, self._frame[0], self._frame_progress,
                self._frame_variance)
        calls = [(compiled_entry(_kernels.follow_frame, *args), args)]
        if self._tempo is not None:
            args = (self._frame_progress, self._frame_variance, self.length - 1.0, self._tempo,
                    self._tempo_state)
            calls.append((compiled_entry(_kernels.tempo_calibrate, *args), args))
        args = widen_arguments(self._intervals, self.config, self._on, self._frame,
                               self._frame_progress, self._frame_variance, self._interval_state)
        if args is not None:
            calls.append((compiled_entry(widen, *args), args))
        self._calls = tuple(calls)
        return self._calls

    def follow(self, X, *, reset: bool = True) -> FollowerTrace:
        """Follow a whole sequence ``X (N, D) float`` (from a fresh start unless ``reset=False``).
        Returns a :class:`FollowerTrace` of (N,) arrays."""
        arr = np.asarray(X, dtype=np.float64)
        if arr.ndim == 1 and self.channels == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] != self.channels:
            raise ValueError(f"X must be (N, {self.channels}) (frames x channels), got shape "
                             f"{arr.shape}")
        if reset:
            self.reset()
        N = arr.shape[0]
        progress, variance, loglik = np.empty((N, 1)), np.empty((N, 1)), np.empty((N, 1))
        arr = np.ascontiguousarray(arr)
        _kernels.forward_run(self._forward.model, self._state, arr, progress, variance, loglik)
        progress, variance = progress[:, 0], variance[:, 0]
        if self._tempo is not None:
            _kernels.tempo_calibrate(progress, variance, self.length - 1.0, self._tempo,
                                     self._tempo_state)
        self._widen(arr, np.zeros(N, dtype=np.int64), progress, variance)
        return FollowerTrace(progress, variance, loglik[:, 0])

    def _widen(self, X, which, progress, variance) -> None:
        """``variance`` widened in place by the residual's autocorrelation."""
        args = widen_arguments(self._intervals, self.config, which, X, progress, variance,
                               self._interval_state)
        if args is not None:
            widen(*args)

    def __repr__(self) -> str:
        return (f"Follower(T={self.length}, D={self.channels}, window={self._window}, "
                f"transitions={self._transitions.kind!r})")
