"""What a bank says: ``BankOutput`` each frame (one object, updated in place) and
``BankTrace`` over a whole input (``FollowerBank.follow``)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class BankTrace(NamedTuple):
    """A bank's outputs over N frames (``FollowerBank.follow``; a mapping by ``_asdict()``)."""

    action: np.ndarray           # (N,) int: the active action's index (-1: none)
    progress: np.ndarray         # (N,): the shown action's progress [0, 1]
    variance: np.ndarray         # (N,): its variance [progress units squared]
    progresses: np.ndarray       # (N, K): every follower's progress
    posteriors: np.ndarray       # (N, K): the posterior over actions
    log_likelihoods: np.ndarray  # (N, K): every follower's log-likelihood since reset
    fits: np.ndarray             # (N, K): every action's fit [nats per channel per frame]
    outlier: np.ndarray          # (N,) bool: a channel far outside the templates' range

    @classmethod
    def empty(cls, N: int, K: int) -> BankTrace:
        return cls(np.empty(N, dtype=np.int64), np.empty(N), np.empty(N),
                   *(np.empty((N, K)) for _ in range(4)), np.empty(N, dtype=np.bool_))


class BankOutput:
    """What a bank says after one frame. **The bank reuses one instance**: its fields change at
    the next ``step``; call :meth:`copy` to keep a snapshot.

    action : str | None: the action being performed (None: nothing recorded explains the input)
    index : int: position of ``action`` in ``bank.actions`` (-1 for None)
    best : str: the most probable action, even when rejected
    progress : float in [0, 1]: progress of ``action`` (of ``best`` when action is None)
    variance : float >= 0: variance of that progress [progress units squared]
    log_likelihood : float: that follower's log-likelihood since reset
    fit : float: that action's recent log-likelihood ratio against the background model [nats
        per channel per frame]; the action is accepted while ``fit >= threshold``
    threshold : float: that action's rejection threshold
    outlier : bool: a channel of this frame was far outside what the templates span (a stuck
        or absurd sensor; ``FollowerConfig.outlier_span``): it was left out, and the frame is
        no action (``bank.outlier_frames`` counts them since reset)
    posterior : dict[str, float]: probability of each action (built on access)
    log_likelihoods : dict[str, float]: every follower's log-likelihood since reset
    """

    __slots__ = ("_bank", "action", "index", "best", "progress", "variance", "log_likelihood",
                 "fit", "threshold", "outlier", "_frozen")
    _FIELDS = ("action", "index", "best", "progress", "variance", "log_likelihood", "fit",
               "threshold", "outlier")

    def __init__(self, bank):
        self._bank = bank
        self._frozen = None
        self.action = None
        self.index = -1
        self.best = bank.actions[0]
        self.progress = self.variance = self.log_likelihood = self.fit = self.threshold = 0.0
        self.outlier = False

    @property
    def posterior(self) -> dict[str, float]:
        if self._frozen is not None:
            return dict(self._frozen[0])
        return dict(zip(self._bank.actions, self._bank.posteriors.tolist()))

    @property
    def log_likelihoods(self) -> dict[str, float]:
        if self._frozen is not None:
            return dict(self._frozen[1])
        return dict(zip(self._bank.actions, self._bank.log_likelihoods.tolist()))

    def copy(self) -> BankOutput:
        """A snapshot that later steps do not change."""
        other = BankOutput(self._bank)
        for name in self._FIELDS:
            setattr(other, name, getattr(self, name))
        other._frozen = (self.posterior, self.log_likelihoods)
        return other

    def __repr__(self) -> str:
        return (f"BankOutput(action={self.action!r}, progress={self.progress:.3f}, "
                f"variance={self.variance:.2e}, best={self.best!r}, fit={self.fit:.2f}, "
                f"threshold={self.threshold:.2f}, outlier={self.outlier})")
