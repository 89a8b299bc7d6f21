"""The shape every puppet kind shares: what a session steps and a renderer draws.

    from characters import Puppet
    isinstance(puppet, Puppet)       # True for ImagePuppet, LatexPuppet, MedialObject

A puppet owns a physical model (built once) and its state (what changes per step). Each frame
the session hands it named targets (pin positions, finger bends, joint angles: whatever its
`target_names` are) and a time step; a renderer then reads `surface()` and `faces`.

A new kind is a package under `characters/` (its builders and its runtime) whose puppet class
has these members; `mop.session.puppets` registers it with the application.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Protocol, runtime_checkable

if TYPE_CHECKING:  # annotations only: importing the protocol stays free
    import numpy as np

    from .model import MassSpring, SpringState


@runtime_checkable
class Puppet(Protocol):
    """model : MassSpring, read-only in the frame loop; state : SpringState, advanced by step.
    faces : (F, 3) int, the triangles of `surface()`; target_names : the names `step` accepts.
    """

    model: MassSpring
    state: SpringState

    @property
    def faces(self) -> np.ndarray: ...

    @property
    def target_names(self) -> tuple[str, ...]: ...

    def reset(self) -> None:
        """Back to rest: rest positions, zero velocity."""

    def step(self, dt: float, targets: Mapping[str, Any]) -> None:
        """Advance by dt [s] towards `targets` {name: position or angle}; absent = at rest."""

    def surface(self) -> np.ndarray:
        """(V, 2|3) float: the deformed visual geometry now."""
