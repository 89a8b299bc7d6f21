"""One action follower: a template turned into a left-to-right HMM, followed frame by frame."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from followers import _kernels
from followers._engine import ForwardEngine
from followers.defaults import as_sigma, as_template, as_window, default_sigma, default_window
from followers.transitions import TransitionModel, transition_model

# outlier cap of the default transition models [sigmas]: one channel further than this from a
# state costs the same for every state, so a glitching sensor cannot drag the follower around
DEFAULT_OUTLIER_SIGMAS = 5.0
# the default models drop states at the edges of the posterior holding less than this mass
# (beam pruning): a confident follower then touches a few states, not the whole window
PRUNE_MASS = 1e-8
# states per template frame of a lone follower's "speed" model (by name; a bank keeps 1, its
# per-frame budget). A speed level between two whole advances per frame (0.48x: 0 or 1 state)
# moves a one-state-per-frame chain by a coin flip each frame, so its position diffuses where a
# performer's does not: on one channel the 90 % interval held 96-99.5 % of frames at 0.5x and
# 1.5x. Three states per frame shrink that diffusion ninefold (docs/followers.md, revision 12);
# four sixteenfold, with the tempo allowed to wander a little more (FOLLOWER_SPEED_JITTER per
# frame to each neighbouring speed level, the bank's 0.01 otherwise), which keeps the interval
# from turning narrow at 2x: revision 15, the interval inside 85-95 % on every set and speed of
# the benchmark (it held 97 % of Wiimote frames at 0.5x with 3 states and 0.01)
FOLLOWER_RESOLUTION = 4
FOLLOWER_SPEED_JITTER = 0.015
# revision 19: the reported variance of a lone follower's "speed" model (by name) is the forward
# distribution's times tempo ** TEMPO_EXPONENT, the tempo the follower's own advance per frame
# [template frames per frame] over TEMPO_MEMORY frames, within the model's speed range. The
# interval held the truth in more frames at 0.5x than at 2x on every set measured (revision 15,
# benchmark draw: GunPoint 93.1 / 87.8 %, held out 93.7 / 90.5, Wiimote 94.5 / 87.0,
# BasicMotions 92.7 / 89.5 % at 0.5x / 2x; Wiimote's 0.5x 95.1-95.3 % in other draws, above the
# 85-95 % target). Exponents 0 / 0.2 / 0.3 / 0.4 over three draws of every set and speed
# (seeds 7-9 of the benchmark's protocol): coverage 86.0-95.3 / 87.7-93.6 / 88.9-93.9 /
# 88.1-94.2 %; 0.2 centres it most (docs/followers.md, revision 19). The true speed in place
# of the estimate (exponent 0.3) gives figures within 2 points of the estimate's.
TEMPO_EXPONENT = 0.2
TEMPO_MEMORY = 10.0
# online emission scale of the default models when sigma is estimated (not given): memory
# [frames], prior weight of scale 1 [frames], lowest and highest scale of the estimated sigma.
# The light prior (0.2 frames) lets a follower sharpen within its first frames (the rest pose):
# chosen with the speed prior on GunPoint's training gestures (docs/followers.md, revision 7)
SCALE_ADAPTATION = (30.0, 0.2, 0.1, 2.0)


def resolve_subframe(subframe, kind: str) -> bool:
    if subframe is None:
        return kind != "mop"
    if not isinstance(subframe, (bool, np.bool_)):
        raise TypeError(f"subframe must be True, False or None, got {subframe!r}")
    return bool(subframe)


def resolve_adaptation(adapt_sigma, sigma_given: bool, kind: str):
    if adapt_sigma is None:
        adapt_sigma = not sigma_given and kind != "mop"
    if not isinstance(adapt_sigma, (bool, np.bool_)):
        raise TypeError(f"adapt_sigma must be True, False or None, got {adapt_sigma!r}")
    return SCALE_ADAPTATION if adapt_sigma else None


@dataclass(frozen=True, slots=True)
class FollowerOutput:
    """What a follower says after one frame.

    progress : float in [0, 1]: expected template position / (T - 1)
    variance : float >= 0: variance of that position [progress units squared] (times the
        performer's tempo to the power 0.2 with ``tempo_variance``, see ``Follower``)
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


def resolve_transitions(transitions, *, resolution: int = 1,
                        speed_jitter: float | None = None) -> TransitionModel:
    """A TransitionModel as given, or built by name (for ``"speed"``: ``resolution`` states per
    template frame, and ``speed_jitter`` if given, ``transition_model``'s default otherwise)."""
    if isinstance(transitions, TransitionModel):
        return transitions
    if isinstance(transitions, str):
        if transitions == "speed":
            jitter = {} if speed_jitter is None else {"speed_jitter": speed_jitter}
            return transition_model("speed", resolution=resolution, **jitter)
        return transition_model(transitions)
    raise TypeError(f"transitions must be a name ('speed', 'mop', 'skip') or a TransitionModel, "
                    f"got {type(transitions).__name__}")


def _own(array: np.ndarray, given) -> np.ndarray:
    """``array`` (validated from ``given``), copied if it shares memory with ``given``."""
    if isinstance(given, np.ndarray) and np.may_share_memory(array, given):
        return array.copy()
    return array


def resolve_cap(outlier_sigmas, kind: str) -> float:
    if outlier_sigmas is None:
        outlier_sigmas = math.inf if kind == "mop" else DEFAULT_OUTLIER_SIGMAS
    value = float(outlier_sigmas)
    if not value > 0:
        raise ValueError(f"outlier_sigmas must be > 0 (inf: plain Gaussian), got {outlier_sigmas}")
    return value * value


class Follower:
    """Follows a performer through one recorded action (MOP, section 3.2).

    Parameters
    ----------
    template : (T, D) float [input units], T >= 2 (a (T,) array is one channel): the action as
        demonstrated, one HMM state per frame.
    sigma : float, (D,) or (T, D) float [input units], optional: the Gaussian emission's
        standard deviation (one shared value as in the paper, one per channel, or one per state
        and channel). Default: estimated from the template (see ``followers.defaults``).
    window : int, optional: half-width p of the forward window [states]; ``window >= T`` runs
        the full forward algorithm. Default: ``followers.defaults.default_window(T)``.
    transitions : ``"speed"`` (default), ``"mop"``, ``"skip"`` or a
        :class:`~followers.transitions.TransitionModel`. ``"mop"`` is the paper to the letter;
        ``"speed"`` follows performers from 0.5x to 2x the demonstration's speed, with
        ``FOLLOWER_RESOLUTION`` (4) states per template frame and a speed jitter of
        ``FOLLOWER_SPEED_JITTER`` (0.015) (a model built with ``transition_model`` keeps its
        own ``resolution`` and jitter, 1 and 0.01 by default).
    outlier_sigmas : float, optional: a channel further than this many sigmas from a state counts
        as this far (inf: plain Gaussian). Default: inf for ``"mop"``, 5 otherwise.
    adapt_sigma : bool, optional: learn the emission's scale online (sigma in use = sigma x
        ``sigma_scale``; the scale is the forgetful mean, over ``SCALE_ADAPTATION[0]`` frames, of
        the posterior-expected squared z-score per channel: EM on one scalar, kept within
        ``SCALE_ADAPTATION[2:]``). Default: on when sigma is estimated (its shape comes from
        the template, its scale from how closely the performer actually repeats it), off when
        sigma is given and for ``"mop"``. With a well-matched scale the posterior's variance
        is calibrated (the 90 % interval holds the true position about 90 % of the time).

    subframe : bool, optional: report the position between template frames. Each state of the
        posterior stands for its cell (half a frame either side); the performer is placed
        along the template's straight segments to the neighbouring frames by this frame's
        emission there, the prediction's slope across the cell as prior
        (``followers._kernels._subframe_rows``), with its own emission scale (learned online
        along the template's direction when sigma is estimated). Progress and variance then
        hold the position inside a cell, not only which cell; the recursion itself is
        unchanged. Progress stays exactly 0 on the first state and 1 on the last. Default:
        on, off for ``"mop"`` (the paper's first moment and variance of the state
        distribution, to the letter).
    tempo_variance : bool, optional: report the variance times the performer's tempo to the
        power ``TEMPO_EXPONENT`` (0.2), the tempo being the follower's own advance per frame
        [template frames per frame] over ``TEMPO_MEMORY`` (10) frames, within the model's
        speed range: the forward distribution's spread alone overstates the error of a slow
        performer and understates a fast one's (see ``TEMPO_EXPONENT``). Progress is
        unchanged. Default: on for ``"speed"`` given by name, off otherwise (``"mop"`` reports
        the paper's variance; a given ``TransitionModel`` the forward distribution's).

    With ``"mop"`` the window is fixed (equation 7); with the other models, states at the edges
    of the posterior holding less than ``PRUNE_MASS`` are also dropped, so a confident follower
    touches a few states rather than the whole window.
    """

    def __init__(self, template, *, sigma=None, window=None, transitions="speed",
                 outlier_sigmas=None, adapt_sigma=None, subframe=None, tempo_variance=None):
        # our own copies where validation handed back the caller's arrays: the template is
        # made read-only below, and neither may change under the follower
        tmpl = _own(as_template(template), template)
        if tempo_variance is None:
            tempo_variance = isinstance(transitions, str) and transitions == "speed"
        if not isinstance(tempo_variance, (bool, np.bool_)):
            raise TypeError(f"tempo_variance must be True, False or None, got {tempo_variance!r}")
        model = resolve_transitions(transitions, resolution=FOLLOWER_RESOLUTION,
                                    speed_jitter=FOLLOWER_SPEED_JITTER)
        T, D = tmpl.shape
        self._sigma = (default_sigma(tmpl) if sigma is None
                       else _own(as_sigma(sigma, (T, D)), sigma))
        self._window = default_window(T) if window is None else as_window(window, T)
        self._transitions = model
        self._engine = ForwardEngine(
            [tmpl], [self._sigma], np.array([self._window]), model,
            cap=resolve_cap(outlier_sigmas, model.kind),
            prune=0.0 if model.kind == "mop" else PRUNE_MASS,
            scale_adaptation=resolve_adaptation(adapt_sigma, sigma is not None, model.kind),
            subframe=resolve_subframe(subframe, model.kind),
            report_adaptation=None if sigma is not None else SCALE_ADAPTATION)
        self._template = tmpl
        self._template.setflags(write=False)
        # (span, gain, lowest, highest, exponent) of _kernels.tempo_calibrate, or None
        self._tempo = ((T - 1.0, 1.0 / TEMPO_MEMORY, float(model.speeds.min()),
                        float(model.speeds.max()), TEMPO_EXPONENT) if tempo_variance else None)
        self._tempo_state = np.array([0.0, 1.0])
        # one frame's progress and variance for the kernel, reused
        self._frame_progress, self._frame_variance = np.zeros(1), np.zeros(1)

    # ---- parameters ---------------------------------------------------------------------------
    @property
    def template(self) -> np.ndarray:
        """(T, D) float64, read-only."""
        return self._template

    @property
    def sigma(self) -> np.ndarray:
        """(T, D) float64 [input units]: per state and channel."""
        return self._sigma.copy()

    @property
    def window(self) -> int:
        """Window half-width p [states]."""
        return self._window

    @property
    def sigma_scale(self) -> float:
        """The emission scale learned online (sigma in use = ``sigma`` x this); 1.0 until the
        first frame, and always 1.0 when the scale is not adapted (``adapt_sigma``)."""
        return float(math.sqrt(self._engine.scale2[0, 0]))

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
        self._engine.reset()
        self._tempo_state[0] = 0.0
        self._tempo_state[1] = 1.0

    def step(self, x) -> FollowerOutput:
        """Follow one frame ``x (D,) float`` (NaN = missing channel; all NaN = no observation)."""
        engine = self._engine
        engine.step(engine.check_frame(x))
        progress, variance = engine.progress_of(0)
        if self._tempo is not None:
            self._frame_progress[0] = progress
            self._frame_variance[0] = variance
            _kernels.tempo_calibrate(self._frame_progress, self._frame_variance, *self._tempo,
                                     self._tempo_state)
            variance = float(self._frame_variance[0])
        return FollowerOutput(progress, variance, float(engine.loglik[0]),
                              float(engine.frame_loglik[0, 0]))

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
        progress, variance, loglik = self._engine.run(np.ascontiguousarray(arr))
        progress, variance = progress[:, 0], variance[:, 0]
        if self._tempo is not None:
            _kernels.tempo_calibrate(progress, variance, *self._tempo, self._tempo_state)
        return FollowerTrace(progress, variance, loglik[:, 0])

    def __repr__(self) -> str:
        return (f"Follower(T={self.length}, D={self.channels}, window={self._window}, "
                f"transitions={self._transitions.kind!r})")
