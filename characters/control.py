"""What the outside world asks of a model for one step: hard pins, target pulls, external forces.

Pins move a node exactly to a position (it moves linearly there over the step, as if carried).
Targets pull a node towards a position with a spring of `target_stiffness` and a damper of
`target_damping` (force k_t (p - x) - c_t v): this is how motions and gloves drive puppets.
External forces are added as given.

Each of pins / targets / forces may be given as a dict {node: vector} or as a pair
(indices (P,) int, vectors (P, d) float). Per-target stiffness/damping may be a float or (T,).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

_EMPTY_INDEX = np.zeros(0, dtype=np.int64)


def _pairs(value, name: str):
    """dict | (indices, vectors) | None -> (indices (P,) int64, vectors (P, d) float64)."""
    if value is None:
        return _EMPTY_INDEX, None
    if isinstance(value, Mapping):
        if not value:
            return _EMPTY_INDEX, None
        keys = list(value.keys())
        try:
            index = np.array([int(key) for key in keys], dtype=np.int64)
        except (TypeError, ValueError):
            raise TypeError(f"{name} keys must be node indices (int), got {keys[:3]!r}") from None
        rows = [np.asarray(vec, dtype=np.float64).ravel() for vec in value.values()]
        sizes = {row.size for row in rows}
        if len(sizes) != 1:
            raise ValueError(
                f"{name} vectors must all have the same size, got sizes {sorted(sizes)}")
        vectors = np.stack(rows)
    elif isinstance(value, tuple) and len(value) == 2:
        index = np.asarray(value[0])
        if index.ndim != 1 or not (index.size == 0 or np.issubdtype(index.dtype, np.integer)):
            raise TypeError(f"{name} indices must be a (P,) int array, got dtype {index.dtype} "
                            f"shape {index.shape}")
        index = index.astype(np.int64)
        vectors = np.asarray(value[1], dtype=np.float64)
        if vectors.ndim != 2 or vectors.shape[0] != index.shape[0]:
            raise ValueError(f"{name} vectors must have shape ({index.shape[0]}, d) to match the "
                             f"indices, got {vectors.shape}")
        if index.size == 0:
            return _EMPTY_INDEX, None
    else:
        raise TypeError(f"{name} must be a dict {{node: vector}} or a pair (indices, vectors), "
                        f"got {type(value).__name__}")
    if len(np.unique(index)) != len(index):
        raise ValueError(f"{name} name a node more than once: {index.tolist()[:10]}")
    if not np.all(np.isfinite(vectors)):
        bad = int(index[np.flatnonzero(~np.isfinite(vectors).all(1))[0]])
        raise ValueError(f"{name} vector for node {bad} is not finite")
    return index, vectors


def _gains(value, count: int, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 0:
        array = np.full(count, float(array))
    elif array.shape != (count,):
        raise ValueError(f"{name} must be a float or have shape ({count},) (one per target), got "
                         f"{array.shape}")
    if not np.all(np.isfinite(array)) or np.any(array < 0):
        raise ValueError(f"{name} must be finite and >= 0, got {array[~(array >= 0)][:3]}")
    return array


class Control:
    """One step's input. Arrays (after construction):

    pin_index (P,) int, pin_position (P, d) [m];
    target_index (T,) int, target_position (T, d) [m], target_stiffness (T,) [N/m],
    target_damping (T,) [N s/m];
    force_index (F,) int, force_value (F, d) [N];
    constraint_centers: {constraint name: (K, d) [m]} optional moving centres for constraints.
    """

    __slots__ = ("pin_index", "pin_position", "target_index", "target_position",
                 "target_stiffness", "target_damping", "force_index", "force_value",
                 "constraint_centers")

    def __init__(self, pins=None, targets=None, *, target_stiffness=0.0, target_damping=0.0,
                 forces=None, constraint_centers: Mapping[str, np.ndarray] | None = None):
        self.pin_index, self.pin_position = _pairs(pins, "pins")
        self.target_index, self.target_position = _pairs(targets, "targets")
        self.force_index, self.force_value = _pairs(forces, "forces")
        self.target_stiffness = _gains(target_stiffness, len(self.target_index), "target_stiffness")
        self.target_damping = _gains(target_damping, len(self.target_index), "target_damping")
        if len(self.target_index) and not np.any(self.target_stiffness > 0) and not np.any(
                self.target_damping > 0):
            raise ValueError("targets were given with target_stiffness = target_damping = 0: "
                             "they would have no effect; pass target_stiffness=k [N/m]")
        both = np.intersect1d(self.pin_index, self.target_index)
        if both.size:
            raise ValueError(f"node {int(both[0])} is both pinned and targeted; choose one")
        self.constraint_centers = dict(constraint_centers or {})

    @classmethod
    def empty(cls) -> "Control":
        return cls()

    def __repr__(self) -> str:
        return (f"Control({len(self.pin_index)} pins, {len(self.target_index)} targets, "
                f"{len(self.force_index)} forces)")

    def resolved(self, model) -> "ResolvedControl":
        """Check against a model and return arrays with the model's dimension."""
        return ResolvedControl(self, model)


class ResolvedControl:
    """A Control checked against one model: every array present (possibly empty), right d."""

    __slots__ = ("pin_index", "pin_position", "target_index", "target_position",
                 "target_stiffness", "target_damping", "force_index", "force_value",
                 "constraint_centers")

    def __init__(self, control: Control | None, model):
        n, d = model.node_count, model.dim
        empty = np.zeros((0, d))
        if control is None:
            self.pin_index = self.target_index = self.force_index = _EMPTY_INDEX
            self.pin_position = self.target_position = self.force_value = empty
            self.target_stiffness = self.target_damping = np.zeros(0)
            self.constraint_centers = {}
            return
        if not isinstance(control, Control):
            raise TypeError(f"control must be a Control or None, got {type(control).__name__}")
        for kind in ("pin", "target", "force"):
            index = getattr(control, f"{kind}_index")
            vectors = getattr(control, f"{kind}_position" if kind != "force" else "force_value")
            if index.size:
                if index.min() < 0 or index.max() >= n:
                    bad = index[(index < 0) | (index >= n)][0]
                    raise ValueError(f"{kind} node {int(bad)} is out of range for a model with "
                                     f"{n} nodes")
                if vectors.shape[1] != d:
                    raise ValueError(f"{kind} vectors have {vectors.shape[1]} components; this "
                                     f"model is {d}D")
            else:
                vectors = empty
            setattr(self, f"{kind}_index", index)
            setattr(self, f"{kind}_position" if kind != "force" else "force_value", vectors)
        self.target_stiffness = control.target_stiffness
        self.target_damping = control.target_damping
        self.constraint_centers = {}
        names = {getattr(c, "name", None): c for c in model.constraints}
        for name, centers in control.constraint_centers.items():
            constraint = names.get(name)
            if constraint is None or not hasattr(constraint, "nodes"):
                raise ValueError(f"constraint_centers names {name!r}, but the model has no "
                                 f"constraint of that name with centres (it has "
                                 f"{sorted(n for n in names if n)})")
            array = np.asarray(centers, dtype=np.float64)
            if array.shape != (constraint.nodes.size, d) or not np.all(np.isfinite(array)):
                raise ValueError(f"centres for constraint {name!r} must be finite with shape "
                                 f"({constraint.nodes.size}, {d}), got {array.shape}")
            self.constraint_centers[name] = array
