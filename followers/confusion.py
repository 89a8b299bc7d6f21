"""How confusable recorded actions are: feedback for an author right after recording.

Each demonstration is performed back to the bank of all the actions, uniformly time-warped to
0.7x, 1x and 1.4x its speed (a performer never repeats a demonstration at exactly its tempo).
For each pair, ``matrix[i, j]`` is the fraction of those frames on which the follower of action
``j`` *accepts* demonstration ``i``: it explains the input better than the bank's background
model by the bank's rejection margin (see :class:`followers.FollowerBank`). The diagonal says
how well each action is recognised as itself; a large off-diagonal value says that action ``j``'s
follower would happily take ``i`` for its own, i.e. the two are too close. ``decisions`` gives
what the bank as a whole concluded on the same frames.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from followers.bank import FollowerBank
from followers.preprocessing import time_warp

CONFUSABILITY_SPEEDS = (0.7, 1.0, 1.4)


@dataclass(frozen=True)
class Confusability:
    """names : tuple of A action names
    matrix : (A, A) float in [0, 1]: ``matrix[i, j]`` = fraction of frames of demonstration i
        (time-warped) that follower j accepts (rows: demonstration, columns: follower)
    decisions : (A, A + 1) float in [0, 1]: fraction of those frames on which the bank decided
        each action (last column: none)
    """

    names: tuple[str, ...]
    matrix: np.ndarray
    decisions: np.ndarray

    def most_confusable(self) -> tuple[str, str, float]:
        """(demonstration, follower, acceptance) of the largest off-diagonal entry."""
        off = self.matrix.copy()
        np.fill_diagonal(off, -1.0)
        if off.shape[0] < 2:
            raise ValueError("one action cannot be confused with another")
        i, j = np.unravel_index(int(np.argmax(off)), off.shape)
        return self.names[i], self.names[j], float(self.matrix[i, j])

    def plot(self, ax=None, *,
             title: str = "How strongly each follower accepts each demonstration"):
        """Draw the matrix on a matplotlib axis (made if None); returns the axis."""
        try:
            import matplotlib.pyplot as plt
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("drawing needs matplotlib: pip install matplotlib") from exc
        if ax is None:
            size = 1.2 + 0.75 * len(self.names)
            _, ax = plt.subplots(figsize=(size + 1.3, size))
        image = ax.imshow(self.matrix, cmap="viridis", vmin=0.0, vmax=1.0)
        ticks = range(len(self.names))
        ax.set_xticks(ticks, self.names, rotation=35, ha="right")
        ax.set_yticks(ticks, self.names)
        ax.set_xlabel("follower")
        ax.set_ylabel("demonstration performed")
        ax.set_title(title)
        for (i, j), value in np.ndenumerate(self.matrix):
            ax.text(j, i, f"{value:.2f}", ha="center", va="center",
                    color="black" if value > 0.6 else "white", fontsize=9)
        ax.figure.colorbar(image, ax=ax, fraction=0.046, pad=0.04, label="acceptance")
        return ax

    def save(self, path, *, dpi: int = 100) -> None:
        """Draw the matrix into a PNG file at ``path``."""
        import matplotlib
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        ax = self.plot()
        ax.figure.tight_layout()
        ax.figure.savefig(path, dpi=dpi)
        plt.close(ax.figure)


def confusability(templates, *, speeds=CONFUSABILITY_SPEEDS, **bank_options) -> Confusability:
    """Pairwise acceptance matrix of a set of actions.

    templates : {name: (T, D) float} or a :class:`FollowerBank` (its templates and settings).
    speeds : tempos at which each demonstration is replayed [x demonstration speed].
    bank_options : passed to :class:`FollowerBank` (sigma, window, transitions, memory,
        reject_margin, ...) when ``templates`` is a mapping.
    """
    bank = templates if isinstance(templates, FollowerBank) else FollowerBank(templates,
                                                                               **bank_options)
    speeds = tuple(float(s) for s in speeds)
    if not speeds or min(speeds) <= 0:
        raise ValueError(f"speeds must be positive tempos, got {speeds}")
    names = bank.actions
    A = len(names)
    accepted = np.zeros((A, A))
    decided = np.zeros((A, A + 1))
    # the first frames only fill the rejection's memory: count from there
    skip = int(np.ceil(bank.config.fit_memory))
    for i, name in enumerate(names):
        demo = bank.template(name)
        frames = 0
        for speed in speeds:
            performance, _ = time_warp(demo, speed)
            n = performance.shape[0]
            trace = bank.follow(performance)
            start = min(skip, n - 1)
            fits = trace["fits"][start:]
            accepted[i] += (fits >= bank.thresholds[None, :]).sum(axis=0)
            chosen = trace["action"][start:]
            decided[i] += np.bincount(np.where(chosen < 0, A, chosen), minlength=A + 1)
            frames += n - start
        accepted[i] /= frames
        decided[i] /= frames
    bank.reset()
    return Confusability(names=tuple(names), matrix=accepted, decisions=decided)
