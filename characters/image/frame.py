"""An image puppet's frame in one compiled call: every Verlet substep adds the spring forces,
updates, carries the pins towards their targets and unfolds folded triangles, with Python's
lock released.

The same kernels, in the same order, as the integrator's substep loop (`Integrator._run` with
`Verlet._advance`, the pins' carry and `NoFoldConstraint.apply`), so both give identical
states; the loop stays for steps with target pulls or external forces.

    frame = FrameArrays.of(model, constraint)   # once; arrays shared with the model
    below = run_substeps(frame, x, v, x0, pin_index, pin_position, substeps, h, retention)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..kernels import node_forces, spring_forces, symplectic_update
from .guard import unfold_triangles


class FrameArrays(NamedTuple):
    """A 2D mass-spring model's arrays, its no-fold guard's, and the frame's scratch (N nodes,
    M springs, F triangles)."""

    springs: np.ndarray             # (M, 2) int
    rest_length: np.ndarray         # (M,) [px]
    stiffness: np.ndarray           # (M,)
    damping: np.ndarray             # (M,)
    mass: np.ndarray                # (N,)
    inverse_mass: np.ndarray        # (N,) the model's (0 for fixed nodes)
    gravity: np.ndarray             # (2,)
    weighed: bool                   # gravity is not zero (else node forces add nothing)
    force: np.ndarray               # (N, 2) scratch
    free_mass: np.ndarray           # (N,) scratch: inverse masses with this step's pins at 0
    triangles: np.ndarray           # (F, 3) int64: the guard's
    min_area: np.ndarray            # (F,) [px^2]
    iterations: int                 # the guard's Gauss-Seidel passes
    no_index: np.ndarray            # (0,) int64: no targets, no external forces
    no_rows: np.ndarray             # (0, 2)
    no_gains: np.ndarray            # (0,)

    @classmethod
    def of(cls, model, guard) -> "FrameArrays":
        """Views of a 2D MassSpring's arrays and of its NoFoldConstraint `guard`."""
        return cls(model.springs, model.rest_length, model.stiffness, model.damping, model.mass,
                   model.inverse_mass, model.gravity, bool(model.gravity.any()),
                   np.zeros_like(model.rest_positions), np.zeros(model.node_count),
                   guard.triangles, guard.min_area, int(guard.iterations),
                   np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0))


@njit(cache=True, nogil=True)
def _carry_pins(x, v, x0, pin_index, pin_position, substeps, s, h):
    """Pinned nodes to their goal at the end of substep s (a straight line from x0 over the
    substeps): velocity = displacement / h, all velocities before any position, as with
    fancy indexing."""
    for k in range(pin_index.shape[0]):
        i = pin_index[k]
        for a in range(x.shape[1]):
            start = x0[i, a]
            goal = start + (pin_position[k, a] - start) / substeps * (s + 1)
            v[i, a] = (goal - x[i, a]) / h
    for k in range(pin_index.shape[0]):
        i = pin_index[k]
        for a in range(x.shape[1]):
            start = x0[i, a]
            x[i, a] = start + (pin_position[k, a] - start) / substeps * (s + 1)


@njit(cache=True, nogil=True)
def run_substeps(frame, x, v, x0, pin_index, pin_position, substeps, h, retention):
    """`substeps` Verlet substeps of h [s] (velocity retention e^(-c_vd h) per substep), the
    pins (P,) carried from x0 to pin_position (P, 2); returns how many triangles the guard
    left below their minimum area in its last pass of the last substep."""
    frame.free_mass[...] = frame.inverse_mass
    for k in range(pin_index.shape[0]):
        frame.free_mass[pin_index[k]] = 0.0
    below = 0
    for s in range(substeps):
        frame.force[...] = 0.0
        spring_forces(x, v, frame.springs, frame.rest_length, frame.stiffness, frame.damping,
                      frame.force)
        if frame.weighed:
            node_forces(x, v, frame.mass, frame.gravity, 0.0, frame.no_index, frame.no_rows,
                        frame.no_gains, frame.no_gains, frame.no_index, frame.no_rows,
                        frame.force)
        symplectic_update(x, v, frame.force, frame.free_mass, h, retention)
        if pin_index.shape[0]:
            _carry_pins(x, v, x0, pin_index, pin_position, substeps, s, h)
        below = unfold_triangles(x, v, frame.triangles, frame.min_area, frame.free_mass, h,
                                 frame.iterations)
    return below
