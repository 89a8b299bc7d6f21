"""The followers of one performer's recorded actions, stepped together: which action is being
performed (or none), and how far along.

Per frame, one numba call (``_bank_kernels.bank_step``) steps every follower (their templates
stacked in one ``ForwardModel``), every action's outline model, and the decision: the
posterior over actions from each action's accumulated recognition score, the rejection of
input that no action explains better than the background model, and the hysteresis that
keeps the decision from flickering. The tuning numbers are ``BankConfig``'s; what each
mechanism costs and buys is measured in ``docs/design/followers.md``.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping

import numpy as np

from followers import _bank_kernels
from followers._jit import entry as compiled_entry
from followers.bank_model import (bank_sigmas, bank_state, build_bank_model, check_size,
                                  reset_bank)
from followers.bank_output import BankOutput, BankTrace
from followers.config import BankConfig, FollowerConfig
from followers.defaults import as_sigma, as_window, default_window, moving_channels
from followers.demos import Demonstrations, combine
from followers.follower import Follower, adaptation, chain, resolve_config
from followers.model import build_forward, check_frame, forward_state, reset_forward
from followers.novelty import build_novelty, novelty, novelty_trace
from followers.intervals import (interval_state, reset_interval, stacked, widen,
                                 widen_arguments)
from followers.still import RELEASE, StillState, StillWindow, build_still, judge, still_mask


log = logging.getLogger(__name__)
# a bank of this many templates, or of this many template values (frames x channels), times
# one step when it is built
_PROBED = (256, 2_000_000)


def _named_actions(templates, config: BankConfig):
    """Names, each action's takes combined (``followers.demos.combine``) and each one's own
    sigma (a ``Follower`` value's given sigma, else None), from a mapping or a sequence of
    pairs; a value is one take (an array), several (a list of arrays) or a ``Follower``."""
    items = list(templates.items()) if isinstance(templates, Mapping) else list(templates)
    if not items:
        raise ValueError("a FollowerBank needs at least one template, got none")
    names, actions, own, seen = [], [], [], set()
    for entry in items:
        if not (isinstance(entry, tuple) and len(entry) == 2):
            raise TypeError("templates must be a mapping {name: (T, D) array or list of them} or "
                            f"a sequence of (name, array) pairs, got an item "
                            f"{type(entry).__name__}")
        name, takes = entry
        if not isinstance(name, str):
            raise TypeError(f"action names must be str, got {name!r}")
        if name in seen:
            raise ValueError(f"action name {name!r} appears twice")
        seen.add(name)
        names.append(name)
        if isinstance(takes, Follower):
            actions.append(takes.demonstrations or combine(np.array(takes.template),
                                                           name=f"template {name!r}"))
            own.append(takes.sigma if takes.sigma_given else None)
        else:
            actions.append(combine(takes, config=config.follower, name=f"template {name!r}"))
            own.append(None)
    D = actions[0].template.shape[1]
    for name, action in zip(names, actions):
        if action.template.shape[1] != D:
            raise ValueError(f"every template needs the same channels: {names[0]!r} has {D}, "
                             f"{name!r} has {action.template.shape[1]}")
    return names, actions, own


def _given_sigmas(sigma, names, arrays) -> list[np.ndarray]:
    if isinstance(sigma, Mapping):
        if set(sigma) != set(names):
            raise ValueError(f"a sigma mapping needs one entry per action {names}, got keys "
                             f"{sorted(sigma)}")
        return [as_sigma(sigma[n], a.shape) for n, a in zip(names, arrays)]
    return [as_sigma(sigma, a.shape) for a in arrays]


def resolve_bank_config(config, transitions, reject_margin) -> BankConfig:
    """A BankConfig from the ``config=`` argument and the convenience keywords."""
    if config is None:
        config = BankConfig()
    elif not isinstance(config, BankConfig):
        raise TypeError(f"config must be a BankConfig, got {type(config).__name__}")
    if transitions is not None:
        given = None if config.follower == FollowerConfig.bank_preset() else config.follower
        config = config.replace(follower=resolve_config(given, transitions,
                                                        FollowerConfig.bank_preset))
    if reject_margin is not None:
        config = config.replace(reject_margin=float(reject_margin))
    return config


class FollowerBank:
    """Recognises which of several recorded actions a performer is doing, and how far along.

    templates : {name: (T_k, D) float, a list of such arrays, or a Follower} (or a sequence of
        (name, value) pairs): per action one take or several, all with the same D channels
        [input units]. Several takes of an action become one template, their average, whose
        default sigma is widened per state by how far the takes stray from it
        (``followers.demos``); the bank's cost per frame is that of one template per action.
        A ``Follower`` (one from ``train_follower``, say) gives its template (its takes, if it
        was made from several) and, if it was given one, its per-state sigma as that action's
        base sigma, floored at the bank's default; the bank's scales apply to it as to the
        default.
    sigma : float or (D,) for every action, or {name: float, (D,) or (T_k, D)}, optional [input
        units]: the emission sigma of both the forward recursion and the recognition score,
        used as given. Default: multiples of each action's base sigma (the default estimated
        from all templates together; ``BankConfig.following_scale``, ``recognition_scale``),
        with an exact-repetition component in the recognition score.
    window : int, optional: window half-width p [template frames] for all followers. Default:
        per template, ``followers.defaults.default_window``.
    transitions : as for :class:`followers.Follower`; a name selects
        ``FollowerConfig.bank_preset(name)`` for the followers.
    reject_margin : float, optional: ``BankConfig.reject_margin`` (``-inf``: never reject).
    config : :class:`~followers.config.BankConfig`, optional: every other setting.
    """

    def __init__(self, templates, *, sigma=None, window=None, transitions=None,
                 reject_margin=None, config: BankConfig | None = None):
        self.config = config = resolve_bank_config(config, transitions, reject_margin)
        fc = config.follower
        names, actions, own = _named_actions(templates, config)
        arrays = [a.template for a in actions]
        model = chain(fc, transitions)
        check_size(arrays, config, levels=model.levels, resolution=model.resolution)
        K = len(arrays)
        moving = moving_channels([t for a in actions for t in a.takes])
        defaults = sigma is None
        recognition = exact = None
        if defaults:
            sigmas, recognition, exact = bank_sigmas(actions, config, moving, own)
            if model.kind == "mop":  # the paper's chain scores frames as the paper does
                recognition = exact = None
        else:
            sigmas = _given_sigmas(sigma, names, arrays)
        windows = np.array([default_window(a.shape[0], fc) if window is None
                            else as_window(window, a.shape[0]) for a in arrays])
        self._names = tuple(names)
        self._index = {n: i for i, n in enumerate(names)}
        self._templates = arrays
        self._sigmas = sigmas
        self._transitions = model
        self._forward = build_forward(
            arrays, sigmas, windows, model, cap=fc.outlier_sigmas ** 2, prune=fc.prune_mass,
            tilt=fc.subframe_tilt, outlier_span=fc.outlier_span, recognition=recognition,
            exact=exact,
            adaptation=adaptation(fc, fc.adapt_sigma and defaults and model.kind != "mop"),
            report_adaptation=adaptation(fc, defaults),
            moving=moving)
        self._exact = np.ones((K, arrays[0].shape[1])) if exact is None else exact
        self._demonstrations = actions
        self._model = build_bank_model(
            actions, config, resolution=self._forward.resolution, restart=self._forward.restart,
            subframe=fc.subframe, mixture=config.mixture_start if exact is not None else 0.0,
            moving=moving)
        self._still = build_still(arrays, [list(a.takes) for a in actions], config.still_frames,
                                  config.still_band, config.end_fraction, fc.sigma_floor,
                                  moving)
        self._still_window = StillWindow(self._still, arrays[0].shape[1])
        self._still_state = StillState()
        # the shown variance widened by the residual's autocorrelation (followers.intervals)
        self._intervals = stacked(arrays, sigmas, self._forward.model.moving)
        self._interval_state = interval_state(arrays[0].shape[1])
        self._frame = np.zeros((1, arrays[0].shape[1]))
        self._shown, self._shown_progress, self._shown_variance = (
            np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1))
        self._state = forward_state(self._forward)
        self._bank = bank_state(self._model)
        self._kernels = self._widen_args = None  # per-frame kernels (``_entries``)
        self._out = BankOutput(self)
        self._fit_sum, self._fit_frames = np.zeros(K), 0   # the fits since reset
        self._novelty = None     # undefined unless an action has two takes (no spread)
        if any(len(a.takes) > 1 for a in actions):
            self._novelty = build_novelty([[self._run(t).fits for t in a.takes]
                                           for a in actions])
        self.reset()
        if K >= _PROBED[0] or sum(a.size for a in arrays) >= _PROBED[1]:
            self._probe()

    def _probe(self) -> None:
        """Time one step of a large bank; say in the log when it is slower than a frame."""
        x = np.ascontiguousarray(self._templates[0][0])
        self.step(x)
        start = time.perf_counter()
        self.step(x)
        took = time.perf_counter() - start
        self.reset()
        if took > self.config.frame_budget:
            log.warning("a bank of %d templates takes about %.0f ms per frame, more than the "
                        "%.0f ms of BankConfig.frame_budget: it cannot follow in real time; "
                        "use fewer or shorter templates, or fewer channels", len(self._names),
                        1e3 * took, 1e3 * self.config.frame_budget)

    # ---- description ----------------------------------------------------------------------------
    @property
    def actions(self) -> tuple[str, ...]:
        """Action names, in the order of every per-action array."""
        return self._names

    @property
    def channels(self) -> int:
        return int(self._templates[0].shape[1])

    @property
    def lengths(self) -> np.ndarray:
        """(K,) int: template lengths [frames]."""
        return np.array([a.shape[0] for a in self._templates])

    def sigma(self, action: str) -> np.ndarray:
        """(T, D) float [input units]: the sigma of one action's forward recursion."""
        return np.array(self._sigmas[self._index[action]])

    def template(self, action: str) -> np.ndarray:
        """(T, D) float: the template of one action (its takes' average when several)."""
        return self._templates[self._index[action]].copy()

    def demonstrations(self, action: str) -> Demonstrations:
        """One action's takes combined: its template, their spread, how consistent they are."""
        return self._demonstrations[self._index[action]]

    @property
    def thresholds(self) -> np.ndarray:
        """(K,) float: rejection thresholds on ``fits``."""
        return self._model.thresholds.copy()

    @property
    def exact_sigmas(self) -> np.ndarray:
        """(K, D) float [input units]: each action's exact-repetition sigma per channel (its
        template's own noise, see ``defaults.exact_scales``; unused without a mixture)."""
        return np.stack([s[0] for s in self._sigmas]) * self._exact

    # ---- live per-action arrays (updated in place by every step; copy to keep) -----------------
    @property
    def posteriors(self) -> np.ndarray:
        """(K,) float: posterior over actions after the last frame."""
        return self._bank.posterior

    @property
    def progresses(self) -> np.ndarray:
        """(K,) float in [0, 1]: every follower's progress after the last frame."""
        return self._bank.progress

    @property
    def variances(self) -> np.ndarray:
        """(K,) float: every follower's progress variance [progress units squared]."""
        return self._bank.variance

    @property
    def recognition_mixture(self) -> float:
        """Weight of the exact-repetition component in the next frame's recognition score
        (0: none), learned from the performance since the last reset."""
        return float(self._state.mixture[0])

    @property
    def log_likelihoods(self) -> np.ndarray:
        """(K,) float: every follower's log-likelihood since reset."""
        return self._state.loglik

    @property
    def outline_log_likelihoods(self) -> np.ndarray:
        """(K,) float: every action's outline-model log-likelihood since reset."""
        return self._bank.outline_total

    @property
    def recent_log_likelihoods(self) -> np.ndarray:
        """(K,) float <= 0: the posterior's evidence (frame scores relative to each frame's
        best action, bounded, forgotten with ``memory``), the leader at 0."""
        return self._bank.recent

    @property
    def outlier_frames(self) -> int:
        """Frames since reset with a channel far outside what the templates span."""
        return int(self._bank.outlier_frames[0])

    @property
    def fits(self) -> np.ndarray:
        """(K,) float: each action's recent log-likelihood ratio against the background model
        [nats per channel per frame]."""
        return self._bank.fit

    @property
    def novelty(self) -> float:
        """How unlike every action's own demonstrations the input since reset is
        (``followers.novelty``): about 1 for a take like them, large for an unrecorded action;
        nan before the first frame or when no action has two takes."""
        if not self._fit_frames or self._novelty is None:
            return float("nan")
        return novelty(self._novelty, self._fit_sum / self._fit_frames)

    # ---- running --------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything: the next frame is the first of a performance."""
        reset_forward(self._forward, self._state)
        reset_bank(self._model, self._bank)
        self._state.mixture[0] = self._model.mixture_start
        gate = self._kernels[2] if self._kernels else _bank_kernels.gate
        gate(self._state, self._model, self._bank, -1)
        self._still_window.reset()
        self._still_state.reset()
        reset_interval(self._interval_state)
        self._fit_sum[:] = 0.0
        self._fit_frames = 0
        self._publish()

    def step(self, x) -> BankOutput:
        """Follow one frame ``x (D,) float`` (NaN = missing channel) with every follower.

        Returns the bank's :class:`BankOutput`, **the same object every call** (fields updated
        in place; ``.copy()`` keeps a snapshot). No array is allocated when ``x`` is already a
        float64 array."""
        step, widen_shown, _, args = self._kernels or self._entries()
        row = args[4]  # the frame, a view made once
        row[:] = check_frame(x, row.shape[0])
        step(*args)
        self._fit_sum += self._bank.fit
        self._fit_frames += 1
        self._still_window.push(row)
        self._shown[0] = self._publish(judged=True)
        self._shown_progress[0] = self._out.progress
        self._shown_variance[0] = self._out.variance
        if widen_shown is not None:
            widen_shown(*self._widen_args)
        self._out.variance = float(self._shown_variance[0])
        return self._out

    def _entries(self):
        """``step``'s and ``reset``'s kernels resolved once for its own arrays
        (``followers._jit.entry``)."""
        args = (self._forward.model, self._state, self._model, self._bank, self._frame[0])
        step = compiled_entry(_bank_kernels.bank_step, *args)
        self._widen_args = widen_arguments(
            self._intervals, self.config.follower, self._shown, self._frame,
            self._shown_progress, self._shown_variance, self._interval_state)
        widen_shown = (None if self._widen_args is None
                       else compiled_entry(widen, *self._widen_args))
        gate = compiled_entry(_bank_kernels.gate, self._state, self._model, self._bank, -1)
        self._kernels = (step, widen_shown, gate, args)
        return self._kernels

    def _widen(self, X, shown, progress, variance) -> None:
        """``variance`` of the ``shown`` actions widened in place (``followers.intervals``)."""
        args = widen_arguments(self._intervals, self.config.follower, shown, X, progress,
                               variance, self._interval_state)
        if args is not None:
            widen(*args)

    def _publish(self, judged: bool = False, quiet: bool = False) -> int:
        """The output from the bank's state; ``judged``: the still stage judges this frame
        (``followers.still``); ``quiet``: it showed no action for it already. Returns the
        index of the action whose progress is shown."""
        out, decision = self._out, self._bank.decision
        active = int(decision[0])
        shown = active if active >= 0 else int(decision[1])
        if judged:
            window = self._still_window
            active = judge(self._still, self._still_state, window.entry, window.held, active,
                           float(self._bank.progress[max(active, 0)]))
        elif quiet:
            active = -1
        out.action = self._names[active] if active >= 0 else None
        out.index = active
        out.best = self._names[int(decision[1])]
        out.progress = float(self._bank.progress[shown])
        out.variance = float(self._bank.variance[shown])
        out.log_likelihood = float(self._state.loglik[shown])
        out.fit = float(self._bank.fit[shown])
        out.threshold = float(self._model.thresholds[shown])
        out.outlier = bool(self._state.outliers[0] > 0)
        return shown

    def follow(self, X) -> dict[str, np.ndarray]:
        """Step through ``X (N, D)`` from a fresh start; returns arrays for plotting:
        ``action`` (N,) int (-1: none), ``progress``/``variance`` (N,) of the shown action,
        ``progresses``, ``posteriors``, ``log_likelihoods``, ``fits`` each (N, K), and
        ``novelty`` (N,): ``novelty`` after each frame."""
        arr = np.asarray(X, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != self.channels:
            raise ValueError(f"X must be (N, {self.channels}), got shape {arr.shape}")
        arr = np.ascontiguousarray(arr)
        trace = self._run(arr)
        self._fit_sum[:] = trace.fits.sum(axis=0)
        self._fit_frames = arr.shape[0]
        shown = np.where(trace.action >= 0, trace.action, np.argmax(trace.posteriors, axis=1))
        self._widen(arr, shown, trace.progress, trace.variance)
        self._judge_still(arr, trace)
        self._still_window.load(arr)
        self._publish(quiet=bool(arr.shape[0]) and trace.action[-1] < 0)
        if arr.shape[0]:
            self._out.variance = float(trace.variance[-1])
        novel = (np.full(arr.shape[0], np.nan) if self._novelty is None
                 else novelty_trace(self._novelty, trace.fits))
        return {**trace._asdict(), "novelty": novel}

    def _run(self, X) -> BankTrace:
        """The kernels' trace of ``X (N, D)`` (contiguous float) from a fresh start."""
        trace = BankTrace.empty(X.shape[0], len(self._names))
        self.reset()
        _bank_kernels.bank_run(self._forward.model, self._state, self._model, self._bank,
                               np.ascontiguousarray(X, dtype=np.float64), trace)
        return trace

    def _judge_still(self, X, trace) -> None:
        """The still stage over a traced performance ``X (N, D)``: ``trace.action`` set to -1
        where still input shows no action (as ``step`` would, frame by frame)."""
        model = self._still
        if model.frames < 1:
            return
        entry = still_mask(X, model.frames, model.band)
        held = still_mask(X, model.frames, RELEASE * model.band)
        for i in range(X.shape[0]):
            trace.action[i] = judge(model, self._still_state, bool(entry[i]), bool(held[i]),
                                    int(trace.action[i]), float(trace.progress[i]))

    def __repr__(self) -> str:
        return (f"FollowerBank({len(self._names)} actions: {', '.join(self._names)}; "
                f"D={self.channels}, transitions={self._transitions.kind!r})")
