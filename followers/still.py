"""Still input is no action: a performer holding still between gestures.

Left alone, a bank holds the last action at its end, or starts another at its first frames,
for as long as the performer holds still: nothing in the forward recursion says "none of
these". This stage looks at the input itself. Input becomes **still** at a frame when, over
the last ``BankConfig.still_frames`` frames, every channel stayed within ``still_band`` times
that channel's spread over every take (a frame with a missing channel is not still; a
channel that never moves in any take is not judged). While
the input is still, the shown action is replaced by "no action" unless the action itself
holds still there (below); once replaced, the input stays still while every channel stays
within ``RELEASE`` times the band. A person standing still is not a sensor at rest: they sway
and shift their weight, and by the band alone their hold flickers between still and moving.
(A pause that keeps its action is held to the band itself, so the action moves on with the
performer.)

- an action whose takes are mostly still (a "stand" or "rest" action) is never replaced;
- otherwise the action is replaced at its end (progress >= ``end_fraction``), in its
  still lead-in (where every recording starts before the gesture does), and wherever its
  template is not still itself; a pause inside a gesture, still in the template too, stays.
  The template's own stillness is judged over a window ``SLOWEST`` times as long as the
  input's: a performer at half the demonstration's tempo stays twice as long at a turning
  point (the top of a slow chomp) that the template passes in a moment. For the same reason
  the pause lasts at most ``1 / SLOWEST`` times the template's still stretch there: input
  still for longer is no action there too (a performer who stopped where the gesture
  slows).

The rule only changes what the bank *shows*: the followers, the posterior and the rejection
go on underneath, so the action comes back as soon as the input moves again and explains it.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from followers.defaults import moving_rms

# an action is a "still action" when more than this share of its takes' frames are still
STILL_ACTION_SHARE = 0.5
# the lead-in is protected up to this much progress past its last still frame
LEAD_MARGIN = 0.02
# performers down to this fraction of the demonstration's tempo (the followers' design range)
SLOWEST = 0.5
# still input shown as no action stays still while every channel stays within this many
# times the band
RELEASE = 2.0


class StillModel(NamedTuple):
    """What the still stage needs, built once per bank."""

    frames: int              # window length [frames] (0: off)
    band: np.ndarray         # (D,) float: the largest range per channel that counts as still
    still_action: np.ndarray  # (K,) bool: the action's takes are mostly still
    lead: np.ndarray         # (K,) float: progress up to which the template's lead-in is still
    template_still: list     # K (T_k,) bool: the template is still at this frame
    template_run: list       # K (T_k,) int: frames the template's still stretch there lasts
    end: float               # progress from which an action has been performed


def still_mask(X: np.ndarray, frames: int, band: np.ndarray) -> np.ndarray:
    """(N,) bool: frame i of ``X (N, D)`` ends ``frames`` frames each of whose channels stays
    within ``band (D,)`` (the first ``frames - 1`` frames are never still; NaN is not)."""
    N = X.shape[0]
    out = np.zeros(N, dtype=bool)
    if frames < 1 or N < frames:
        return out
    windows = sliding_window_view(X, frames, axis=0)       # (N - frames + 1, D, frames)
    with np.errstate(invalid="ignore"):
        spans = windows.max(axis=2) - windows.min(axis=2)
        out[frames - 1:] = np.all(spans <= band, axis=1)    # NaN compares False
    return out


def build_still(templates: list[np.ndarray], takes: list[list[np.ndarray]], frames: int,
                band: float, end: float, floor: float, moving: np.ndarray) -> StillModel:
    """The still stage of a bank of ``templates`` (K (T_k, D)) demonstrated by ``takes``
    (per action its (T_i, D) takes); ``frames``: window [frames] (0: off); ``band``: x each
    channel's spread over every take, floored at ``floor`` times their RMS (as the default
    sigma is); ``end``: the bank's end fraction; ``moving``: (D,) bool, the channels that move
    in the takes (``defaults.moving_channels``)."""
    every = np.concatenate([t for action in takes for t in action], axis=0)
    spread = every.std(axis=0)
    spread = np.maximum(spread, floor * moving_rms(spread, moving))
    # a channel that never moves is not judged (live it is left out, or an outlier)
    widths = np.where(moving, band * spread, np.inf)
    still_action = np.array([
        np.mean(np.concatenate([still_mask(t, frames, widths) for t in action]))
        > STILL_ACTION_SHARE for action in takes]) if frames > 0 else np.zeros(len(takes), bool)
    masks, runs, lead = [], [], []
    short = max(int(round(SLOWEST * frames)), 2)
    for template in templates:
        mask = still_mask(template, frames, widths)
        masks.append(still_mask(template, short, widths) if frames > 0 else mask)
        runs.append(stretches(masks[-1], short))
        leading = mask.copy()
        leading[:max(frames - 1, 0)] = True
        first_moving = int(np.argmin(leading)) if not leading.all() else len(leading)
        lead.append(first_moving / (len(template) - 1))
    return StillModel(int(frames), widths, still_action, np.array(lead), masks, runs,
                      float(end))


def stretches(mask: np.ndarray, frames: int) -> np.ndarray:
    """(N,) int: for each frame of a still ``mask`` (N,) judged over ``frames`` frames, how
    many frames the still stretch it lies in lasts (its window included; 0: not still)."""
    out = np.zeros(mask.size, dtype=np.int64)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        out[start:stop] = stop - start + frames - 1
    return out


def holds_no_action(model: StillModel, action: int, progress: float, duration: int = 0) -> bool:
    """Whether input still for ``duration`` frames at ``progress`` of ``action`` (>= 0) is
    shown as no action."""
    if model.still_action[action]:
        return False
    if progress >= model.end or progress <= model.lead[action] + LEAD_MARGIN:
        return True
    mask = model.template_still[action]
    i = int(round(progress * (len(mask) - 1)))
    return not mask[i] or SLOWEST * duration > model.template_run[action][i]


class StillState:
    """What the still stage carries from frame to frame."""

    __slots__ = ("quiet", "duration")

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.quiet = False   # the last frame was shown as no action, its input still
        self.duration = 0    # frames the input has been still (its window included)


def judge(model: StillModel, state: StillState, entry: bool, held: bool, action: int,
          progress: float) -> int:
    """The action to show (-1: no action) for ``action`` (-1: none) at ``progress``, the
    input still by the band (``entry``) or by ``RELEASE`` times it (``held``); ``state`` is
    updated. Once still input is shown as no action, it stays still by the wider band."""
    still = entry or (state.quiet and held)
    state.duration = (state.duration + 1 if state.duration else model.frames) if still else 0
    if still and action >= 0 and holds_no_action(model, action, progress, state.duration):
        action = -1
    state.quiet = still and action < 0
    return action


class StillWindow:
    """The last ``frames`` frames of a performance, for :func:`still_mask` one frame at a time
    (nothing allocated per frame)."""

    def __init__(self, model: StillModel, channels: int):
        self.model = model
        self._frames = np.full((max(model.frames, 1), channels), np.nan)
        self._span = np.empty(channels)
        self._low = np.empty(channels)
        self._seen = 0
        self.entry = self.held = False

    def reset(self) -> None:
        self._frames.fill(np.nan)
        self._seen = 0
        self.entry = self.held = False

    def load(self, X: np.ndarray) -> None:
        """Start over from the last frames of ``X (N, D)``, as if pushed one by one."""
        self.reset()
        for x in X[-self._frames.shape[0]:]:
            self.push(x)

    def push(self, x: np.ndarray) -> None:
        """Add frame ``x (D,)``: ``entry`` says whether the input is still at it by the band
        (:func:`still_mask`), ``held`` by ``RELEASE`` times the band."""
        self.entry = self.held = False
        if self.model.frames < 1:
            return
        self._frames[self._seen % self.model.frames] = x
        self._seen += 1
        if self._seen < self.model.frames:
            return
        np.max(self._frames, axis=0, out=self._span)
        np.min(self._frames, axis=0, out=self._low)
        np.subtract(self._span, self._low, out=self._span)
        with np.errstate(invalid="ignore"):
            self.entry = bool(np.all(self._span <= self.model.band))
            np.divide(self._span, RELEASE, out=self._span)
            self.held = bool(np.all(self._span <= self.model.band))
