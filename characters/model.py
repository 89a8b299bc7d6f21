"""The mass-spring model (built once, read-only) and its state (what changes each step).

Units: positions in metres (or pixels for 2D image puppets: everything then scales with the
length unit), masses in kg, time in seconds. Forces follow from those (N for metres and kg).

A spring joining nodes i and j with rest length r, stiffness k and damping c pushes node i with

    f_i = (k (l - r) + c (v_j - v_i) . u) u,      u = (x_j - x_i) / l,   l = |x_j - x_i|

and node j with -f_i. On top of that each free node feels gravity m g and a velocity damping
-m c_vd v (the medial paper's C_vd, as a rate here; see materials.py for the conversion).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from . import kernels


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _per_item(value, count: int, name: str, what: str) -> np.ndarray:
    """Broadcast a scalar or validate a (count,) array of finite non-negative floats."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 0:
        array = np.full(count, float(array))
    elif array.shape != (count,):
        raise ValueError(
            f"{name} must be a float or an array of shape ({count},) (one per {what}), "
            f"got shape {array.shape}")
    else:
        array = np.array(array, dtype=np.float64)  # own copy: the caller may keep mutating theirs
    if not np.all(np.isfinite(array)):
        bad = int(np.flatnonzero(~np.isfinite(array))[0])
        raise ValueError(f"{name} must be finite, got {array[bad]} for {what} {bad}")
    if np.any(array < 0):
        bad = int(np.flatnonzero(array < 0)[0])
        raise ValueError(f"{name} must be >= 0, got {array[bad]} for {what} {bad}")
    return array


@dataclass
class SpringState:
    """What an integrator writes each step.

    x : (N, d) float [m] node positions
    v : (N, d) float [m/s] node velocities
    t : float [s] simulated time since the state was made
    """

    x: np.ndarray
    v: np.ndarray
    t: float = 0.0

    def copy(self) -> "SpringState":
        return SpringState(self.x.copy(), self.v.copy(), self.t)

    def assign(self, other: "SpringState") -> None:
        """Copy another state's values into this one's arrays (no allocation)."""
        self.x[...] = other.x
        self.v[...] = other.v
        self.t = other.t


class SpringPlan:
    """The springs of a 3D model laid out for the split force kernels (kernels.scatter_rows):
    each spring oriented so its first node is the smaller index, sorted by that node, indices as
    uint32, per-spring arrays permuted to match, and one (6, C) scratch buffer reused by every
    pass, C = min(M, kernels.SPLIT_CHUNK) springs (the passes run chunk by chunk). Built once
    per model (MassSpring.plan); read-only except the scratch.

    si, sj : (M,) uint32; order : (M,) int64 [plan position -> model spring index];
    rest_length, stiffness, damping : (M,) float64 in plan order; damped : any damping > 0;
    scratch : (6, C) float64.
    The kernels' sums do not depend on the order; sorting makes them fast. A model stepped
    from two threads at once would share the scratch: give each thread its own model.
    """

    def __init__(self, model: "MassSpring"):
        springs = model.springs
        first = springs.min(axis=1)
        second = springs.max(axis=1)
        order = np.lexsort((second, first))
        self.order = _readonly(order)
        self.si = _readonly(np.ascontiguousarray(first[order], dtype=np.uint32))
        self.sj = _readonly(np.ascontiguousarray(second[order], dtype=np.uint32))
        self.rest_length = _readonly(np.ascontiguousarray(model.rest_length[order]))
        self.stiffness = _readonly(np.ascontiguousarray(model.stiffness[order]))
        self.damping = _readonly(np.ascontiguousarray(model.damping[order]))
        self.damped = bool(self.damping.any())
        self.scratch = np.empty((6, max(1, min(len(order), kernels.SPLIT_CHUNK))))

    def take(self, values: np.ndarray) -> np.ndarray:
        """(M,) per-spring values in model order -> a contiguous copy in plan order."""
        return np.ascontiguousarray(np.asarray(values)[self.order])


def _checked_positions(positions) -> np.ndarray:
    x = np.array(positions, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise ValueError(f"positions must have shape (N, 2) or (N, 3), got {x.shape}")
    if x.shape[0] == 0:
        raise ValueError("positions must hold at least one node, got 0")
    if not np.all(np.isfinite(x)):
        raise ValueError("positions must be finite, got NaN or inf")
    return x


def _checked_springs(springs, node_count: int) -> np.ndarray:
    """(M, 2) int32 node pairs: integers (or integral floats) in range, no self-loops."""
    s = np.asarray(springs)
    if s.size == 0:
        s = np.zeros((0, 2), dtype=np.int64)
    if s.ndim != 2 or s.shape[1] != 2:
        raise ValueError(f"springs must have shape (M, 2), got {s.shape}")
    if not (np.issubdtype(s.dtype, np.integer)):
        if np.issubdtype(s.dtype, np.floating) and np.all(s == np.round(s)):
            s = s.astype(np.int64)
        else:
            raise TypeError(f"springs must hold integer node indices, got dtype {s.dtype}")
    s = np.array(s, dtype=np.int32)
    if s.size and (s.min() < 0 or s.max() >= node_count):
        bad = int(np.flatnonzero((s < 0).any(1) | (s >= node_count).any(1))[0])
        raise ValueError(f"spring {bad} joins nodes {tuple(s[bad])}: indices must be in "
                         f"[0, {node_count}) for {node_count} nodes")
    self_loops = np.flatnonzero(s[:, 0] == s[:, 1])
    if self_loops.size:
        raise ValueError(f"spring {int(self_loops[0])} joins node {int(s[self_loops[0], 0])} "
                         f"to itself")
    return s


def _checked_gravity(gravity, dim: int) -> np.ndarray:
    g = np.zeros(dim) if gravity is None else np.array(gravity, dtype=np.float64)
    if g.shape != (dim,):
        raise ValueError(f"gravity must have shape ({dim},) for {dim}D positions, got {g.shape}")
    if not np.all(np.isfinite(g)):
        raise ValueError(f"gravity must be finite, got {g}")
    return g


def _fixed_mask(fixed, node_count: int) -> np.ndarray:
    """(N,) bool from a mask or a sequence of node indices (None: nothing fixed)."""
    fixed_mask = np.zeros(node_count, dtype=bool)
    if fixed is None:
        return fixed_mask
    f = np.asarray(fixed)
    if f.dtype == bool:
        if f.shape != (node_count,):
            raise ValueError(f"fixed as a mask must have shape ({node_count},), got {f.shape}")
        fixed_mask[:] = f
        return fixed_mask
    f = f.astype(np.int64).ravel()
    if f.size and (f.min() < 0 or f.max() >= node_count):
        raise ValueError(f"fixed node indices must be in [0, {node_count}), got "
                         f"{f[(f < 0) | (f >= node_count)][0]}")
    fixed_mask[f] = True
    return fixed_mask


class MassSpring:
    """A mass-spring system: rest positions, springs, masses, damping, gravity, fixed nodes.

    Built once; every array is read-only. Integrators read a model and write a `SpringState`.

    Parameters
    ----------
    positions : (N, d) float [m], d = 2 or 3: rest positions (also the initial state)
    springs : (M, 2) int: node index pairs, i != j
    stiffness : float | (M,) float [N/m]: Hooke's constant per spring
    damping : float | (M,) float [N s/m]: damping along each spring (relative velocity)
    mass : float | (N,) float [kg]: per-node mass, > 0
    gravity : (d,) float [m/s^2]: default zero
    velocity_damping : float [1/s]: C_vd as a rate, force -m c_vd v on every node
    rest_length : (M,) float [m]: default the distances in `positions`
    fixed : (N,) bool | sequence of int: nodes that never move (infinite mass)
    constraints : sequence of constraints (see constraints.py) applied after each step
    """

    def __init__(self, positions, springs, *, stiffness, damping=0.0, mass=1.0, gravity=None,
                 velocity_damping: float = 0.0, rest_length=None, fixed=None,
                 constraints: Sequence = ()):
        x = _checked_positions(positions)
        node_count, dim = x.shape
        s = _checked_springs(springs, node_count)
        spring_count = s.shape[0]

        if rest_length is None:
            rest = np.linalg.norm(x[s[:, 1]] - x[s[:, 0]], axis=1)
        else:
            rest = _per_item(rest_length, spring_count, "rest_length", "spring")
        zero = np.flatnonzero(rest <= 0)
        if zero.size:
            raise ValueError(f"spring {int(zero[0])} has rest length {rest[zero[0]]}: springs "
                             f"need a positive rest length (two nodes at the same position?)")

        masses = _per_item(mass, node_count, "mass", "node")
        if np.any(masses == 0):
            bad = int(np.flatnonzero(masses == 0)[0])
            raise ValueError(f"mass must be > 0, got 0 for node {bad} (use fixed= to pin a node)")

        g = _checked_gravity(gravity, dim)
        vd = float(velocity_damping)
        if not np.isfinite(vd) or vd < 0:
            raise ValueError(f"velocity_damping must be a finite rate >= 0 [1/s], got {vd}")

        fixed_mask = _fixed_mask(fixed, node_count)

        self.rest_positions = _readonly(x)
        self.springs = _readonly(s)
        self.rest_length = _readonly(rest)
        self.stiffness = _readonly(_per_item(stiffness, spring_count, "stiffness", "spring"))
        self.damping = _readonly(_per_item(damping, spring_count, "damping", "spring"))
        self.mass = _readonly(masses)
        inverse = 1.0 / masses
        inverse[fixed_mask] = 0.0
        self.inverse_mass = _readonly(inverse)
        self.fixed = _readonly(fixed_mask)
        self.gravity = _readonly(g)
        self.velocity_damping = vd
        self.constraints = tuple(constraints)
        for constraint in self.constraints:
            check = getattr(constraint, "check", None)
            if check is None:
                raise TypeError(f"constraints must be constraint objects with check() and apply(), "
                                f"got {type(constraint).__name__}")
            check(self)

    # sizes -------------------------------------------------------------------------------
    @property
    def plan(self) -> SpringPlan:
        """The springs laid out for the split 3D force kernels (built on first use)."""
        plan = self.__dict__.get("_plan")
        if plan is None:
            if self.dim != 3:
                raise ValueError(f"SpringPlan is for 3D models, this one is {self.dim}D")
            plan = self.__dict__["_plan"] = SpringPlan(self)
        return plan

    @property
    def node_count(self) -> int:
        return self.rest_positions.shape[0]

    @property
    def spring_count(self) -> int:
        return self.springs.shape[0]

    @property
    def dim(self) -> int:
        return self.rest_positions.shape[1]

    def __repr__(self) -> str:
        return (f"MassSpring({self.node_count} nodes, {self.spring_count} springs, {self.dim}D, "
                f"{int(self.fixed.sum())} fixed, {len(self.constraints)} constraints)")

    # state and diagnostics ---------------------------------------------------------------
    def state(self) -> SpringState:
        """A fresh state at rest: x (N, d) copy of the rest positions [m], v (N, d) zeros [m/s]."""
        return SpringState(self.rest_positions.copy(), np.zeros_like(self.rest_positions), 0.0)

    def check_state(self, state: SpringState) -> None:
        shape = self.rest_positions.shape
        if not isinstance(state, SpringState):
            raise TypeError(f"state must be a SpringState, got {type(state).__name__}")
        if state.x.shape != shape or state.v.shape != shape:
            raise ValueError(f"state arrays must have shape {shape} for this model, got "
                             f"x {state.x.shape} and v {state.v.shape}")
        if state.x.dtype != np.float64 or state.v.dtype != np.float64:
            raise TypeError(f"state arrays must be float64, got {state.x.dtype}, {state.v.dtype}")

    def spring_energy(self, x: np.ndarray) -> float:
        """Elastic energy sum k (l - r)^2 / 2 [J] at positions x : (N, d) float [m]."""
        if self.dim == 3:
            plan = self.plan
            return float(kernels.spring_energy_3d(x, plan.si, plan.sj, plan.rest_length,
                                                  plan.stiffness, plan.scratch))
        return float(kernels.spring_energy(x, self.springs, self.rest_length, self.stiffness))

    def add_spring_forces(self, x: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """Add every spring's elastic + along-spring damping force to out (N, d) [N] at x, v
        (N, d) float64: the split kernels over the plan in 3D, the fused loop in 2D."""
        if self.dim == 3:
            plan = self.plan
            if plan.damped:
                kernels.spring_forces_3d(x, v, plan.si, plan.sj, plan.rest_length,
                                         plan.stiffness, plan.damping, plan.scratch, out)
            else:  # no spring has a damper: velocities need not be gathered
                kernels.spring_forces_elastic_3d(x, plan.si, plan.sj, plan.rest_length,
                                                 plan.stiffness, plan.scratch, out)
        else:
            kernels.spring_forces(x, v, self.springs, self.rest_length, self.stiffness,
                                  self.damping, out)

    def kinetic_energy(self, v: np.ndarray) -> float:
        """sum m |v|^2 / 2 [J] over free nodes; v : (N, d) float [m/s]."""
        free = ~self.fixed
        return float(0.5 * np.einsum("i,ij,ij->", self.mass[free], v[free], v[free]))

    def gravity_energy(self, x: np.ndarray) -> float:
        """-sum m g . x [J] over free nodes (zero at the origin)."""
        free = ~self.fixed
        return float(-np.dot(self.mass[free], x[free] @ self.gravity))

    def energy(self, state: SpringState) -> float:
        """Kinetic + spring + gravity potential energy [J] of a state."""
        self.check_state(state)
        return (self.kinetic_energy(state.v) + self.spring_energy(state.x)
                + self.gravity_energy(state.x))

    def forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Internal + gravity + velocity-damping forces (N, d) [N] at x, v (no control)."""
        out = np.zeros_like(x)
        self.add_spring_forces(x, v, out)
        out += self.mass[:, None] * (self.gravity[None, :] - self.velocity_damping * v)
        out[self.fixed] = 0.0
        return out

    def spring_lengths(self, x: np.ndarray) -> np.ndarray:
        """(M,) float [m] current spring lengths at x : (N, d)."""
        return np.linalg.norm(x[self.springs[:, 1]] - x[self.springs[:, 0]], axis=1)

    def momentum(self, state: SpringState) -> np.ndarray:
        """(d,) float [kg m/s] total linear momentum of the free nodes."""
        free = ~self.fixed
        return self.mass[free] @ state.v[free]


# --- simple volumetric meshes (tests, benchmarks, quick experiments) -----------------------

_EVEN_CUBE = np.array([[0b100, 0b010, 0b001, 0b111],
                       [0b000, 0b100, 0b010, 0b001],
                       [0b110, 0b100, 0b010, 0b111],
                       [0b101, 0b100, 0b001, 0b111],
                       [0b011, 0b010, 0b001, 0b111]])


def tetrahedral_lattice(shape, spacing: float, *, origin=(0.0, 0.0, 0.0), inside=None):
    """A block of cubes, each split into 5 tetrahedra (alternating so faces match).

    shape : (nx, ny, nz) cubes per axis; spacing [m] cube edge; origin (3,) [m] first corner;
    inside : optional callable (P, 3) -> (P,) bool keeping only tetrahedra whose four corners
    are inside (e.g. an ellipsoid for a head-like volume).
    Returns positions (N, 3) float [m], springs (M, 2) int (unique tetrahedron edges, sorted
    for memory locality) and tetrahedra (K, 4) int.
    """
    nx, ny, nz = (int(s) for s in shape)
    if min(nx, ny, nz) < 1 or not spacing > 0:
        raise ValueError(f"need shape >= (1, 1, 1) cubes and spacing > 0, got {shape}, {spacing}")
    grid = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1),
                                indexing="ij"), -1).reshape(-1, 3)
    points = np.asarray(origin, dtype=np.float64) + spacing * grid
    node_id = np.arange(len(grid)).reshape(nx + 1, ny + 1, nz + 1)
    cubes = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"),
                     -1).reshape(-1, 3)
    odd = cubes.sum(1) % 2 == 1
    tets = []
    for parity, chosen in ((False, cubes[~odd]), (True, cubes[odd])):
        for corners in _EVEN_CUBE:
            bits = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in corners])
            if parity:
                bits[:, 0] = 1 - bits[:, 0]  # mirror in x so shared faces split the same way
            ijk = chosen[:, None, :] + bits[None]
            tets.append(node_id[ijk[..., 0], ijk[..., 1], ijk[..., 2]])
    tets = np.concatenate(tets)
    if inside is not None:
        keep_point = np.asarray(inside(points), dtype=bool)
        tets = tets[keep_point[tets].all(1)]
    used = np.unique(tets)
    remap = np.full(len(points), -1)
    remap[used] = np.arange(used.size)
    tets = remap[tets]
    points = points[used]
    edges = np.concatenate([tets[:, [a, b]] for a in range(4) for b in range(a + 1, 4)])
    edges = np.unique(np.sort(edges, axis=1), axis=0)  # sorted by first node: cache-friendly
    return points, edges.astype(np.int32), tets.astype(np.int64)
