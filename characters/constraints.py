"""Position constraints applied after every (sub)step, from the medial paper (section 3.2).

- `CircumsphereConstraint`: a node may not leave a sphere of radius f_max x rest length about
  its rest position (or a centre the control moves); outside, it is put back on the sphere
  along the line to the centre.
- `SpringReductionConstraint`: chosen springs are kept within [f_min, f_max] x rest length by
  moving their ends along the spring (split by inverse mass: fixed and pinned ends stay),
  iterated because fixing one spring can break a neighbour.

A correction dx also changes the velocity by dx / h, as position-based dynamics does, so a
clamped node does not keep pushing outwards; the constraints thereby also damp.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .kernels import _JIT


@njit(**_JIT)
def clamp_to_spheres(x, v, nodes, centers, radius, h):
    """Put x[nodes[k]] back into the sphere (centers[k], radius[k]); returns how many moved."""
    d = x.shape[1]
    moved = 0
    for t in range(nodes.shape[0]):
        i = nodes[t]
        dist2 = 0.0
        for a in range(d):
            e = x[i, a] - centers[t, a]
            dist2 += e * e
        r = radius[t]
        if dist2 > r * r:
            scale = r / np.sqrt(dist2)
            for a in range(d):
                target = centers[t, a] + (x[i, a] - centers[t, a]) * scale
                v[i, a] += (target - x[i, a]) / h
                x[i, a] = target
            moved += 1
    return moved


@njit(**_JIT)
def clamp_spring_lengths(x, v, pairs, low, high, inverse_mass, h, iterations):
    """Gauss-Seidel passes moving spring ends so low[s] <= |x_j - x_i| <= high[s].

    Returns the largest relative violation left after the last pass (0 when all hold)."""
    d = x.shape[1]
    worst = 0.0
    for _ in range(iterations):
        worst = 0.0
        for s in range(pairs.shape[0]):
            i = pairs[s, 0]
            j = pairs[s, 1]
            wi = inverse_mass[i]
            wj = inverse_mass[j]
            if wi + wj == 0.0:
                continue
            length2 = 0.0
            for a in range(d):
                e = x[j, a] - x[i, a]
                length2 += e * e
            length = np.sqrt(length2)
            if length < low[s]:
                goal = low[s]
            elif length > high[s]:
                goal = high[s]
            else:
                continue
            violation = abs(length - goal) / goal
            if violation > worst:
                worst = violation
            if length == 0.0:
                continue  # no direction to push along; a neighbour will separate them
            share = (length - goal) / (length * (wi + wj))
            for a in range(d):
                e = x[j, a] - x[i, a]
                di = wi * share * e
                dj = -wj * share * e
                x[i, a] += di
                x[j, a] += dj
                v[i, a] += di / h
                v[j, a] += dj / h
    return worst


def _positive(value, count, name):
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 0:
        array = np.full(count, float(array))
    if array.shape != (count,) or not np.all(np.isfinite(array)) or np.any(array <= 0):
        raise ValueError(f"{name} must be a positive float or a (K,) = ({count},) array of them, "
                         f"got shape {array.shape}")
    return array


class CircumsphereConstraint:
    """Keep nodes within spheres about their rest positions.

    nodes : (K,) int; radius : float | (K,) [m] absolute radius, or give `max_factor` f_max
    and `rest_length` (K,) [m] (the medial paper: r = f_max x bone-spring rest length).
    name : how a Control addresses it to move the centres each step
    (Control(constraint_centers={name: (K, d)})); without that, centres are the rest positions.
    """

    def __init__(self, nodes, *, radius=None, max_factor=None, rest_length=None,
                 name: str = "circumsphere"):
        self.nodes = np.array(nodes, dtype=np.int64).ravel()
        count = self.nodes.size
        if radius is None:
            if max_factor is None or rest_length is None:
                raise ValueError("give either radius=, or max_factor= and rest_length=")
            if not max_factor >= 1:
                raise ValueError(f"max_factor must be >= 1, got {max_factor}")
            radius = float(max_factor) * _positive(rest_length, count, "rest_length")
        self.radius = _positive(radius, count, "radius")
        self.name = str(name)
        self.centers = None

    def check(self, model) -> None:
        if self.nodes.size and (self.nodes.min() < 0 or self.nodes.max() >= model.node_count):
            raise ValueError(f"circumsphere nodes must be in [0, {model.node_count}), got "
                             f"{self.nodes.min()}..{self.nodes.max()}")
        self.centers = np.ascontiguousarray(model.rest_positions[self.nodes])
        self.centers.setflags(write=False)

    def apply(self, x, v, h, inverse_mass, *, centers=None) -> int:
        """Clamp in place; returns how many nodes were moved."""
        if centers is None:
            if self.centers is None:
                raise ValueError("constraint not attached to a model: pass it to MassSpring")
            centers = self.centers
        else:
            centers = np.asarray(centers, dtype=np.float64)
            if centers.shape != (self.nodes.size, x.shape[1]):
                raise ValueError(f"centres for constraint {self.name!r} must have shape "
                                 f"({self.nodes.size}, {x.shape[1]}), got {centers.shape}")
        return clamp_to_spheres(x, v, self.nodes, centers, self.radius, h)

    def violation(self, x, centers=None) -> float:
        """Largest distance beyond the sphere relative to the radius (0 when all hold)."""
        centers = self.centers if centers is None else centers
        dist = np.linalg.norm(x[self.nodes] - centers, axis=1)
        return float(max(0.0, np.max(dist / self.radius - 1.0, initial=0.0)))


class SpringReductionConstraint:
    """Keep chosen springs within [min_factor, max_factor] x their rest length.

    springs : (S,) int indices into the model's springs, or None for all of them.
    iterations : Gauss-Seidel passes per application (the paper iterates because two bone
    springs share a mass point). Defaults from the paper: f_min = 0.8, f_max = 1.5.
    """

    def __init__(self, springs=None, *, min_factor: float = 0.8, max_factor: float = 1.5,
                 iterations: int = 4, name: str = "spring_reduction"):
        if not 0 < min_factor <= 1 <= max_factor:
            raise ValueError(f"need 0 < min_factor <= 1 <= max_factor, got {min_factor}, "
                             f"{max_factor}")
        if iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {iterations}")
        self.spring_index = None if springs is None else np.array(springs, dtype=np.int64).ravel()
        self.min_factor = float(min_factor)
        self.max_factor = float(max_factor)
        self.iterations = int(iterations)
        self.name = str(name)
        self.pairs = self.low = self.high = None
        self.last_violation = 0.0

    def check(self, model) -> None:
        index = (np.arange(model.spring_count) if self.spring_index is None
                 else self.spring_index)
        if index.size and (index.min() < 0 or index.max() >= model.spring_count):
            raise ValueError(f"spring-reduction springs must be in [0, {model.spring_count}), "
                             f"got {index.min()}..{index.max()}")
        self.pairs = np.ascontiguousarray(model.springs[index])
        rest = model.rest_length[index]
        self.low = self.min_factor * rest
        self.high = self.max_factor * rest
        for array in (self.pairs, self.low, self.high):
            array.setflags(write=False)

    def apply(self, x, v, h, inverse_mass, *, centers=None) -> float:
        """Clamp in place; returns the largest relative violation left."""
        if self.pairs is None:
            raise ValueError("constraint not attached to a model: pass it to MassSpring")
        self.last_violation = clamp_spring_lengths(x, v, self.pairs, self.low, self.high,
                                                   inverse_mass, h, self.iterations)
        return self.last_violation

    def violation(self, x) -> float:
        length = np.linalg.norm(x[self.pairs[:, 1]] - x[self.pairs[:, 0]], axis=1)
        over = np.maximum(length / self.high - 1.0, 1.0 - length / self.low)
        return float(max(0.0, over.max(initial=0.0)))
