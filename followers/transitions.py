"""Transition models of the left-to-right follower chain.

Every model here is one shape that the forward kernels understand: the hidden state is a
template position ``i`` (one state per template frame) and a *speed level* ``m``.
Each frame the speed level may change (tridiagonal ``speed_change``), then the position
advances by ``a`` states with probability ``advance[m, a]``; whatever would pass the last
state stays there (the last state is absorbing). Optionally, a new repetition begins at the
first state with the initial speed distribution: with probability ``restart`` per frame out of
the last state (the current repetition is over) and ``restart_anywhere`` from any state.

- ``"mop"`` — the paper's chain, to the letter: one speed level whose advance is
  0 or 1 state with probability 0.5 each, no restart.
- ``"speed"`` (default) — a speed state: ``levels`` speeds log-spaced over
  ``[min_speed, max_speed]`` (default 0.4x–2.5x, wider than the 0.5x–2x it is specified for,
  so the extremes are not at the edge of the prior). A fractional speed ``s`` advances
  ``floor(s)`` or ``floor(s) + 1`` states with probabilities that make the mean advance ``s``.
  The speed level changes to a neighbour with probability ``speed_jitter`` per frame, so the
  follower keeps the performer's tempo through stretches where the input says nothing
  (a held pose) yet adapts when the performer accelerates. A repetition starts with every
  speed in the range equally likely (``speed_prior="uniform"``, a density flat in speed:
  level weights proportional to their speed on the log grid) or with every level equally
  likely (``"log-uniform"``, flat in log speed, which favours the slow half of the range).
  A new repetition begins from the last state with probability 1e-3 per frame, and by
  default not from anywhere else (``restart_anywhere=0``: with 1e-3 from every state, on
  repetitive real data a single fast multi-channel frame could throw the follower back to the
  start mid-gesture: p95 progress error 50-56 % at 0.5x). A repetition abandoned halfway is
  picked up again once the follower has run out its template.
  ``resolution=R`` upsamples the template to R states per frame (R times the work): a speed
  between two whole advances per frame then moves the chain by a coin flip over 1/R of a frame
  instead of a whole one. ``transition_model`` defaults to 1 (a bank's per-frame budget); a
  lone ``Follower`` uses 4 (``FollowerConfig.resolution``: the flips' spread had the progress
  interval too wide at 0.5x and 1.5x), with a speed jitter of 0.015.
- ``"skip"`` — one speed level with skip transitions of 0–3 states (a memoryless
  alternative, kept for comparison in the benchmark).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TRANSITION_KINDS = ("speed", "mop", "skip")


@dataclass(frozen=True)
class TransitionModel:
    """Arrays the forward kernel reads; build with :func:`transition_model`.

    Attributes
    ----------
    kind : str, one of ``TRANSITION_KINDS``
    speeds : (M,) float [template frames per frame]: mean advance of each speed level
    advance : (M, A + 1) float: ``advance[m, a]`` = P(advance by ``a`` states | level m); a state
        is 1 / resolution template frames
    speed_change : (M, 3) float: P(level m -> m - 1, m, m + 1); rows sum to 1
    initial_speed : (M,) float: distribution of the speed level at the first frame
    restart : float in [0, 1): per-frame probability that a new repetition begins, out of the
        last state
    restart_anywhere : float in [0, 1): the same, out of every state
    resolution : int >= 1: HMM states per template frame. With 2, the template is linearly
        upsampled and a performer at 0.5x advances exactly one state per frame instead of
        0 or 1 at random.
    """

    kind: str
    speeds: np.ndarray
    advance: np.ndarray
    speed_change: np.ndarray
    initial_speed: np.ndarray
    restart: float
    resolution: int = 1
    restart_anywhere: float = 0.0

    @property
    def levels(self) -> int:
        return int(self.speeds.shape[0])

    @property
    def max_advance(self) -> int:
        return int(self.advance.shape[1] - 1)


def _fractional_advance(speeds: np.ndarray) -> np.ndarray:
    max_adv = int(np.floor(speeds.max())) + 1
    table = np.zeros((speeds.shape[0], max_adv + 1))
    for m, s in enumerate(speeds):
        whole = int(np.floor(s))
        frac = s - whole
        table[m, whole] += 1.0 - frac
        table[m, whole + 1] += frac
    return table


SPEED_PRIORS = ("uniform", "log-uniform")
DEFAULT_RESTART = 1e-3
DEFAULT_RESTART_ANYWHERE = 0.0


def transition_model(kind: str = "speed", *, min_speed: float = 0.4, max_speed: float = 2.5,
                     levels: int = 11, speed_jitter: float = 0.01, speed_prior: str = "uniform",
                     resolution: int | None = None,
                     restart: float | None = None,
                     restart_anywhere: float | None = None) -> TransitionModel:
    """Build a transition model by name.

    Parameters
    ----------
    kind : ``"speed"`` (default), ``"mop"`` or ``"skip"``; see the module docstring.
    min_speed, max_speed : float > 0 [x template speed]: range of the speed levels ("speed").
    levels : int >= 1: number of log-spaced speed levels ("speed").
    speed_jitter : float in [0, 0.5]: per-frame probability of moving to each neighbouring level.
    speed_prior : ``"uniform"`` (every speed in the range equally likely at the start of a
        repetition) or ``"log-uniform"`` (every level equally likely) ("speed").
    resolution : int >= 1 or None: states per template frame ("speed"; default 1). "mop" and
        "skip" always use 1 (one state per frame, as in the paper).
    restart : float in [0, 1) or None: per-frame probability of a new repetition starting at the
        first state once the current one is over (out of the absorbing last state). None means
        1e-3 for "speed" and "skip", 0 for "mop" (the paper has none).
    restart_anywhere : float in [0, 1) or None: the same from any state (an abandoned
        repetition picked up at once; a jump back to the start mid-gesture when a frame fits
        the current repetition badly). None means 0. A ``FollowerBank`` sets its own per
        follower (``active_restart``).
    """
    if not isinstance(kind, str) or kind not in TRANSITION_KINDS:
        raise ValueError(f"transitions must be one of {TRANSITION_KINDS}, got {kind!r}")
    if restart is None:
        restart = 0.0 if kind == "mop" else DEFAULT_RESTART
    if restart_anywhere is None:
        restart_anywhere = DEFAULT_RESTART_ANYWHERE
    restart = float(restart)
    restart_anywhere = float(restart_anywhere)
    for name, value in (("restart", restart), ("restart_anywhere", restart_anywhere)):
        if not 0.0 <= value < 1.0:
            raise ValueError(f"{name} must be a probability in [0, 1), got {value}")
    if kind != "speed" and resolution not in (None, 1):
        raise ValueError(f"resolution applies to 'speed' transitions only, got {resolution} "
                         f"with {kind!r}")
    if resolution is None:
        resolution = 1
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) \
            or resolution < 1:
        raise ValueError(f"resolution must be an int >= 1, got {resolution!r}")
    if kind == "mop":
        advance = np.array([[0.5, 0.5]])
        speeds = np.array([0.5])
        change = np.array([[0.0, 1.0, 0.0]])
        initial = np.ones(1)
    elif kind == "skip":
        advance = np.array([[0.2, 0.35, 0.3, 0.15]])
        speeds = advance @ np.arange(4.0)
        change = np.array([[0.0, 1.0, 0.0]])
        initial = np.ones(1)
    else:
        if not (0 < min_speed < max_speed):
            raise ValueError(f"need 0 < min_speed < max_speed, got {min_speed}, {max_speed}")
        if int(levels) < 1:
            raise ValueError(f"levels must be >= 1, got {levels}")
        if not 0.0 <= speed_jitter <= 0.5:
            raise ValueError(f"speed_jitter must be in [0, 0.5], got {speed_jitter}")
        if speed_prior not in SPEED_PRIORS:
            raise ValueError(f"speed_prior must be one of {SPEED_PRIORS}, got {speed_prior!r}")
        levels = int(levels)
        speeds = np.geomspace(min_speed, max_speed, levels) if levels > 1 else np.array(
            [np.sqrt(min_speed * max_speed)])
        advance = _fractional_advance(speeds * resolution)
        change = np.tile([speed_jitter, 1.0 - 2.0 * speed_jitter, speed_jitter], (levels, 1))
        # reflecting ends: the probability of leaving the range stays on the edge level
        change[0, 1] += change[0, 0]
        change[0, 0] = 0.0
        change[-1, 1] += change[-1, 2]
        change[-1, 2] = 0.0
        # log-spaced levels: weights proportional to the speed make the density flat in speed
        initial = speeds / speeds.sum() if speed_prior == "uniform" else np.full(
            levels, 1.0 / levels)
    for arr in (speeds, advance, change, initial):
        arr.setflags(write=False)
    return TransitionModel(kind=kind, speeds=speeds, advance=np.ascontiguousarray(advance),
                           speed_change=np.ascontiguousarray(change),
                           initial_speed=initial, restart=restart, resolution=int(resolution),
                           restart_anywhere=restart_anywhere)
