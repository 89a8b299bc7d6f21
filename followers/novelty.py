"""How unlike every recorded action's own demonstrations an input is: the bank's novelty.

A bank's fit (each action's log-likelihood ratio against the background model) says how well
an action explains the input, in absolute terms: another performer's take of a known action
fits about as badly as an unrecorded action, and simple input (a still stretch) fits well
whatever it is. What separates them is the *profile*: the fit of every action at once. A take
of a recorded action is explained by every action of the bank about as that action's own
demonstrations are (its own follower well, the others each by its own amount); an unrecorded
action gives a profile no action's demonstrations give.

- ``NoveltyModel``: per action the profile of its demonstrations (the mean over its takes of
  each take's mean fit, every action's), and one scale: the takes' spread about their action's
  profile, pooled over every action and component. Built once, from the bank following each
  of its own takes.
- The novelty of an input after ``t`` frames: the mean squared distance, in that scale, of its
  fits' mean since reset from the nearest action's profile (``novelty``). About 1 for a take
  like the demonstrations, large for one unlike every action's.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class NoveltyModel(NamedTuple):
    """Each action's profile (K, K) [nats per channel per frame] and the pooled scale (float,
    same unit; nan when no action has two takes: the novelty is then undefined)."""

    profiles: np.ndarray
    scale: float


def build_novelty(fits: list[list[np.ndarray]]) -> NoveltyModel:
    """The model from ``fits[k]``: action k's takes, each followed by the bank, as (N_i, K)
    fit traces (``FollowerBank.follow(take)["fits"]``)."""
    means = [np.array([trace.mean(axis=0) for trace in takes]) for takes in fits]
    profiles = np.stack([m.mean(axis=0) for m in means])
    spread = [((m - m.mean(axis=0)) ** 2).sum(axis=0) for m in means if m.shape[0] > 1]
    dof = sum(m.shape[0] - 1 for m in means)
    if not spread:
        return NoveltyModel(profiles, float("nan"))
    variance = float(np.sum(spread)) / (dof * profiles.shape[1])
    return NoveltyModel(profiles, max(np.sqrt(variance), 1e-9))


def novelty(model: NoveltyModel, mean_fit: np.ndarray) -> float:
    """The novelty of fits whose mean since reset is ``mean_fit (K,)``."""
    return float(_nearest(model, mean_fit[None, :])[0])


def novelty_trace(model: NoveltyModel, fits: np.ndarray) -> np.ndarray:
    """(N,) the novelty after each frame of a traced input's ``fits (N, K)``."""
    running = np.cumsum(fits, axis=0) / np.arange(1, fits.shape[0] + 1)[:, None]
    return _nearest(model, running)


def _nearest(model: NoveltyModel, means: np.ndarray) -> np.ndarray:
    """(N,) each row of ``means (N, K)``: its mean squared distance, in the model's scale,
    from the nearest action's profile."""
    distance = ((means[:, None, :] - model.profiles[None]) / model.scale) ** 2
    return distance.mean(axis=2).min(axis=1)
