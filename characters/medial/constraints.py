"""The spring-reduction constraint specialised to a medial object's bone springs.

Same rule and same arithmetic order as the core's `SpringReductionConstraint` (characters/
constraints.py), which stays the reference the tests compare against: each bone spring is kept
within [f_min, f_max] x its rest length by moving its mass-point end (bone points are kinematic),
in Gauss-Seidel passes. What a medial object knows lets it be cheaper: every mass point has
exactly two bone springs and no other constrained spring, so points are independent and the
passes can run per point, in cache, stopping as soon as a pass changes nothing - which for most
points is the first one. The core's kernel runs every pass over every spring.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def clamp_bone_springs(x, v, points, inner, outer, low, high, h, iterations):
    """Keep low[k] <= |x[bone] - x[points[k]]| <= high[k] for bone in (inner[k], outer[k]).

    x, v : (N, 3) float [m, m/s], written; points, inner, outer : (K,) int node indices;
    low, high : (K,) float [m]; h : substep [s] (a correction dx adds dx / h to the velocity).
    Returns the largest relative violation left after the last pass that ran (0 if none).
    """
    worst = 0.0
    for k in range(points.shape[0]):
        p = points[k]
        violated = 0.0
        for _ in range(iterations):
            violated = 0.0
            for side in range(2):
                q = inner[k] if side == 0 else outer[k]
                ex = x[q, 0] - x[p, 0]
                ey = x[q, 1] - x[p, 1]
                ez = x[q, 2] - x[p, 2]
                length = np.sqrt(ex * ex + ey * ey + ez * ez)
                if length < low[k]:
                    goal = low[k]
                elif length > high[k]:
                    goal = high[k]
                else:
                    continue
                violation = abs(length - goal) / goal
                if violation > violated:
                    violated = violation
                if length == 0.0:
                    continue  # no direction: the other spring will move the point off the bone
                share = (length - goal) / length
                x[p, 0] += share * ex
                x[p, 1] += share * ey
                x[p, 2] += share * ez
                v[p, 0] += share * ex / h
                v[p, 1] += share * ey / h
                v[p, 2] += share * ez / h
            if violated == 0.0:
                break
        # what the last pass found (and corrected): 0 once a pass finds nothing to do
        if violated > worst:
            worst = violated
    return worst


class BoneSpringReduction:
    """Spring reduction on the two bone springs of each mass point (the constraint protocol of
    characters/constraints.py: `name`, `check(model)`, `apply(x, v, h, inverse_mass, centers=)`).

    points : (K,) int surface nodes; inner, outer : (K,) int their bone points;
    rest_length : (K,) float [m] bone-spring rest length L (> 0); min_factor, max_factor: f_min,
    f_max; iterations: passes per application (most points stop after the first).
    """

    def __init__(self, points, inner, outer, rest_length, *, min_factor: float, max_factor: float,
                 iterations: int, name: str = "medial_spring_reduction"):
        if not 0 < min_factor <= 1 <= max_factor:
            raise ValueError(f"need 0 < min_factor <= 1 <= max_factor, got {min_factor}, "
                             f"{max_factor}")
        if iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {iterations}")
        self.points = np.ascontiguousarray(points, dtype=np.int64)
        self.inner = np.ascontiguousarray(inner, dtype=np.int64)
        self.outer = np.ascontiguousarray(outer, dtype=np.int64)
        rest = np.asarray(rest_length, dtype=np.float64)
        if not (self.points.shape == self.inner.shape == self.outer.shape == rest.shape):
            raise ValueError("points, inner, outer and rest_length must have the same (K,) shape, "
                             f"got {self.points.shape}, {self.inner.shape}, {self.outer.shape}, "
                             f"{rest.shape}")
        if np.any(~(rest > 0)):
            raise ValueError("bone-spring rest lengths must be > 0")
        self.min_factor = float(min_factor)
        self.max_factor = float(max_factor)
        self.low = min_factor * rest
        self.high = max_factor * rest
        self.iterations = int(iterations)
        self.name = str(name)
        self.last_violation = 0.0

    def check(self, model) -> None:
        nodes = np.concatenate([self.points, self.inner, self.outer])
        if nodes.size and (nodes.min() < 0 or nodes.max() >= model.node_count):
            raise ValueError(f"bone-spring nodes must be in [0, {model.node_count})")
        bones = np.concatenate([self.inner, self.outer])
        if np.any(model.inverse_mass[bones] != 0):
            raise ValueError("bone points must be fixed nodes (kinematic) for BoneSpringReduction")

    def apply(self, x, v, h, inverse_mass, *, centers=None) -> float:
        """Clamp in place; returns the largest relative violation left."""
        self.last_violation = clamp_bone_springs(x, v, self.points, self.inner, self.outer,
                                                 self.low, self.high, float(h), self.iterations)
        return self.last_violation
