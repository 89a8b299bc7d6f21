"""The parameters and running state of K followers that share one transition model.

Both :class:`followers.Follower` (K = 1) and :class:`followers.FollowerBank` hold one engine;
the engine owns the preallocated arrays and calls the kernels in ``_kernels``.
"""
from __future__ import annotations

import math

import numpy as np

from followers import _kernels
from followers.transitions import TransitionModel

# a clamped value stays this many (template range + sigma) away from the template's range, which
# keeps every squared distance finite in float64 while still being "far away"
_CLAMP_SPAN = 1e3


def _stacked(arrays: list[np.ndarray], owned: bool) -> np.ndarray:
    """The (T_k, D) arrays one above the other in a new C-contiguous float64 array, or, when
    there is one and it is ``owned`` (made here, not the caller's), that array itself."""
    if owned and len(arrays) == 1:
        return np.ascontiguousarray(arrays[0], dtype=np.float64)
    return np.ascontiguousarray(np.concatenate(arrays, axis=0), dtype=np.float64)


def _upsample(values: np.ndarray, factor: int) -> np.ndarray:
    """(T, D) -> (factor * (T - 1) + 1, D): linear interpolation, original frames kept."""
    T, D = values.shape
    out = np.empty((factor * (T - 1) + 1, D))
    out[::factor] = values
    for r in range(1, factor):
        w = r / factor
        out[r::factor] = (1.0 - w) * values[:-1] + w * values[1:]
    return out


class ForwardEngine:
    """K windowed forward followers stepped together by one kernel call.

    templates : list of K (T_k, D) float64 arrays (validated)
    sigmas : list of K (T_k, D) float [input units]: per template frame and channel
    windows : (K,) int [template frames]
    (with ``transitions.resolution = R > 1`` the engine holds R (T_k - 1) + 1 states per template)
    transitions : TransitionModel; cap : float (inf = plain Gaussian) [squared sigmas]
    recognition_sigmas : list of K (T_k, D) float, optional: a second emission model that only
        scores each frame (``frame_loglik[1]``) from the same predicted state distribution;
        None scores with the follower's own model
    recognition_mixture : (weight, scale), optional, with recognition_sigmas: the recognition
        model becomes a mixture per state, ``weight`` in (0, 1) on a Gaussian of the follower's
        sigma times ``scale`` (not the learned scale; a float, or (K, D): per template and
        channel, each > 0) and ``1 - weight`` on the recognition_sigmas' one. The weight is
        ``self.mixture``, which may change between frames (a bank learns it from
        ``frame_loglik[2]``, the narrow component's log share of each frame's score)
    prune : float: edge states of a track's support below this mass are dropped (0 = never)
    scale_adaptation : (memory [frames], prior [frames], lowest, highest scale) or None: learn
        each follower's emission scale online (sigma x scale, EM on one scalar per template,
        see ``_kernels.template_step``); None keeps sigma as given
    subframe : report each follower's position inside its states' cells (``subframe (K,)``,
        settable per follower); report_adaptation : as scale_adaptation, for the emission
        scale of that report (None: the recursion's scale)
    """

    def __init__(self, templates: list[np.ndarray], sigmas: list[np.ndarray], windows: np.ndarray,
                 transitions: TransitionModel, *, cap: float, prune: float,
                 recognition_sigmas: list[np.ndarray] | None = None,
                 recognition_mixture: tuple[float, float | np.ndarray] | None = None,
                 scale_adaptation: tuple[float, float, float, float] | None = None,
                 subframe: bool = False,
                 report_adaptation: tuple[float, float, float, float] | None = None):
        R = transitions.resolution
        if R > 1:
            # R states per template frame: the template and its sigma, linearly interpolated
            templates = [_upsample(t, R) for t in templates]
            sigmas = [_upsample(s, R) for s in sigmas]
            if recognition_sigmas is not None:
                recognition_sigmas = [_upsample(s, R) for s in recognition_sigmas]
            windows = np.asarray(windows) * R
        self.resolution = R
        self.channels = int(templates[0].shape[1])
        self.lengths = np.array([t.shape[0] for t in templates], dtype=np.int64)
        self.offsets = np.zeros(len(templates), dtype=np.int64)
        self.offsets[1:] = np.cumsum(self.lengths)[:-1]
        # one template is taken as it is (R > 1: the upsampled copy); set-up time is mostly
        # the first touch of fresh memory (page faults), so no array is copied that need not be
        self.templates = _stacked(templates, owned=R > 1)
        self.sigmas = _stacked(sigmas, owned=R > 1)
        # emission models: 0 drives the forward recursion, 1 (and 2, the narrow component of a
        # recognition mixture) only score frames for recognition
        self.dual = recognition_sigmas is not None
        rec = _stacked(recognition_sigmas, owned=R > 1) if self.dual else self.sigmas
        self.mixture = 0.0
        # the narrow component's scale per template and channel: its inverse square and log
        self.exact_scales = np.ones((len(templates), self.channels))
        if recognition_mixture is not None:
            if not self.dual:
                raise ValueError("a recognition mixture needs recognition_sigmas")
            weight, scale = recognition_mixture
            self.mixture = float(weight)
            try:
                self.exact_scales[:] = scale
            except ValueError:
                raise ValueError(f"a recognition mixture's scale must be a float or "
                                 f"{self.exact_scales.shape}, got shape {np.shape(scale)}"
                                 ) from None
            if not (0.0 < self.mixture < 1.0 and np.all(self.exact_scales > 0.0)
                    and np.all(np.isfinite(self.exact_scales))):
                raise ValueError(f"a recognition mixture needs a weight in (0, 1) and scales "
                                 f"> 0, got weight {weight} and scales from "
                                 f"{self.exact_scales.min()} to {self.exact_scales.max()}")
        self.exact_inv2 = np.ascontiguousarray(1.0 / self.exact_scales ** 2)
        self.exact_log = np.ascontiguousarray(np.log(self.exact_scales))
        # weights = 1 / sigma^2 and log_norm = -0.5 log(2 pi sigma^2) = 0.5 log(weights / 2 pi),
        # in place (each temporary of this size would be fresh memory to fault in); row 1, the
        # recognition model's, only when there is one
        models = (self.sigmas, rec) if self.dual else (self.sigmas,)
        self.weights = np.empty((len(models),) + self.sigmas.shape)
        for row, sigma in enumerate(models):
            np.square(sigma, out=self.weights[row])
        np.reciprocal(self.weights, out=self.weights)
        self.state_log_norm = np.log(self.weights)
        self.state_log_norm -= math.log(2.0 * math.pi)
        self.state_log_norm *= 0.5
        self.state_log_norm_sum = self.state_log_norm.sum(axis=2)
        self.half_windows = np.ascontiguousarray(windows, dtype=np.int64)
        self.transitions = transitions
        self.cap = float(cap)
        self.prune = float(prune)
        self.advance = np.ascontiguousarray(transitions.advance, dtype=np.float64)
        # advance_tail[m, r] = P(advance >= r): what lands on the absorbing last state
        self.advance_tail = np.ascontiguousarray(
            np.cumsum(self.advance[:, ::-1], axis=1)[:, ::-1])
        nonzero = self.advance > 0
        self.advance_range = np.ascontiguousarray(np.stack(
            [nonzero.argmax(axis=1), nonzero.shape[1] - 1 - nonzero[:, ::-1].argmax(axis=1)],
            axis=1), dtype=np.int64)
        self.speed_change = np.ascontiguousarray(transitions.speed_change, dtype=np.float64)
        self.initial_speed = np.ascontiguousarray(transitions.initial_speed, dtype=np.float64)
        lo = self.templates.min(axis=0)
        hi = self.templates.max(axis=0)
        span = _CLAMP_SPAN * (hi - lo + self.sigmas.max(axis=0))
        self.lower = lo - span
        self.upper = hi + span

        K = len(templates)
        # per template: [restart from anywhere, restart from the last state] per frame (a bank
        # sets the first per follower: FollowerBank._gate_shown)
        self.restart = np.tile([transitions.restart_anywhere, transitions.restart], (K, 1))
        S = int(self.lengths.sum())
        M = transitions.levels
        self.alpha = np.zeros((2, S, M))
        self.rowsum = np.zeros((2, S))
        self.logb = np.zeros((3, S))
        self.support = np.zeros((K, 2, 2), dtype=np.int64)
        self.moments = np.zeros((K, 2, 3))
        self.main = np.zeros(K, dtype=np.int64)
        self.fresh = np.ones(K, dtype=np.bool_)
        self.loglik = np.zeros(K)
        self.frame_loglik = np.zeros((3, K))
        self._xs = np.zeros(self.channels)
        self._observed = np.zeros(self.channels)
        self._mix = np.zeros(M)
        self.residual = np.zeros(S)
        # per template: report the position inside each state's cell (see
        # ``_kernels._subframe_rows``); a bank turns it on for the shown action's follower only
        self.subframe = np.full(K, bool(subframe))
        self._sub = np.zeros((4, S))
        self.scale2 = np.ones((2, K))
        self.scale_weight = np.zeros((2, K))
        # scale adaptation of the recursion (row 0) and of the report inside a cell (row 1)
        self.adapt = np.zeros((2, 3))
        self._scale_prior = np.zeros((2, 1))
        for row, setting in enumerate((scale_adaptation, report_adaptation)):
            if setting is None:
                continue
            memory, prior, lowest, highest = (float(v) for v in setting)
            if not (memory > 0 and prior >= 0 and 0 < lowest <= 1.0 <= highest):
                raise ValueError(f"scale adaptation needs memory > 0, prior >= 0 and "
                                 f"0 < lowest <= 1 <= highest, got {setting}")
            self.adapt[row] = [np.exp(-1.0 / memory), lowest ** 2, highest ** 2]
            self._scale_prior[row] = prior
        self.reset()

    @property
    def count(self) -> int:
        return int(self.lengths.shape[0])

    def reset(self) -> None:
        self.alpha[:] = 0.0
        self.rowsum[:] = 0.0
        self.support[:, :, 0] = 1
        self.support[:, :, 1] = 0
        self.moments[:] = 0.0
        self.main[:] = 0
        self.fresh[:] = True
        self.loglik[:] = 0.0
        self.frame_loglik[:] = 0.0
        self.scale2[:] = 1.0
        self.scale_weight[:] = self._scale_prior

    def check_frame(self, x) -> np.ndarray:
        arr = np.ascontiguousarray(x, dtype=np.float64)
        if arr.shape != (self.channels,):
            raise ValueError(f"frame must have {self.channels} channel(s) (shape "
                             f"({self.channels},)), got shape {arr.shape}")
        return arr

    def step(self, x: np.ndarray) -> int:
        """Advance all K followers by one frame ``x (D,) float64``; returns observed channels."""
        return _kernels.bank_step(
            x, self.lower, self.upper, self.templates, self.offsets, self.lengths,
            self.half_windows, self.weights, self.state_log_norm, self.state_log_norm_sum,
            self.cap, self.dual, self.mixture, self.exact_inv2, self.exact_log, self.prune,
            self.advance, self.advance_tail, self.advance_range, self.speed_change,
            self.initial_speed, self.restart,
            self.alpha, self.rowsum, self.logb, self.support, self.moments, self.main, self.fresh,
            self.loglik, self.frame_loglik, self._xs, self._observed, self._mix, self.adapt,
            self.scale2, self.scale_weight, self.residual, self.subframe, self._sub)

    def run(self, X: np.ndarray):
        """Step through ``X (N, D) float64``; returns progress, variance, log-likelihood, each
        (N, K) float64."""
        N = X.shape[0]
        K = self.count
        progress = np.empty((N, K))
        variance = np.empty((N, K))
        loglik = np.empty((N, K))
        _kernels.follow_sequence(
            X, self.lower, self.upper, self.templates, self.offsets, self.lengths,
            self.half_windows, self.weights, self.state_log_norm, self.state_log_norm_sum,
            self.cap, self.dual, self.mixture, self.exact_inv2, self.exact_log, self.prune,
            self.advance, self.advance_tail, self.advance_range, self.speed_change,
            self.initial_speed, self.restart,
            self.alpha, self.rowsum, self.logb, self.support, self.moments, self.main, self.fresh,
            self.loglik, self.frame_loglik, self._xs, self._observed, self._mix, self.adapt,
            self.scale2, self.scale_weight, self.residual, self.subframe, self._sub, progress,
            variance, loglik)
        return progress, variance, loglik

    def progress_of(self, k: int) -> tuple[float, float]:
        """Main-track progress and variance of template k, in [0, 1] units."""
        t = self.main[k]
        span = self.lengths[k] - 1.0
        # a division: exactly 1 at the end
        return (float(self.moments[k, t, 1] / span), float(self.moments[k, t, 2] / span ** 2))
