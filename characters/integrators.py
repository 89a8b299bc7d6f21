"""Time integrators: each `step(model, state, dt, control=None) -> StepReport` advances a state.

- `Verlet`: position Verlet (velocity form), explicit, with substeps.
- `ImplicitEuler`: backward Euler linearised with one Newton iteration (Baraff-Witkin), solved
  by warm-started PCG (block-Jacobi, or the prefactored projective-dynamics matrix) on a
  fixed, spring-indexed block pattern.
- `ProjectiveDynamics` (the default, see `default_integrator`): Liu et al. 2013 local/global
  iterations with one prefactored sparse Cholesky (cholespy), optional Chebyshev acceleration.

All share the safety net of `Integrator.step`: a step that produces NaN/inf or whose energy jumps
beyond what the control could have injected is rolled back and retried with more substeps; if
all retries fail the state is restored (velocities zeroed) and the report says so.
"""
from __future__ import annotations

import logging
import math
import weakref
from dataclasses import dataclass

import numpy as np

from . import kernels
from .control import Control, ResolvedControl
from .model import MassSpring, SpringState

log = logging.getLogger(__name__)


@dataclass
class StepReport:
    """What happened in one `step` call.

    ok: the state advanced to a finite, plausible result.
    substeps: substeps used by the accepted attempt (or the last one tried).
    retries: attempts rolled back before the accepted one.
    rolled_back: True if all attempts failed and the state was restored (velocities zeroed).
    reason: why the last rejected attempt was rejected ("" if none was).
    energy_before, energy_after: kinetic + elastic + gravity potential (relative to the
        step's start) [J], NaN if unchecked. A step is rejected when energy_after exceeds
        energy_growth x energy_before plus what the control could have injected.
    iterations: solver iterations of the accepted attempt (CG or local/global), 0 for Verlet.
    """

    ok: bool = True
    substeps: int = 1
    retries: int = 0
    rolled_back: bool = False
    reason: str = ""
    energy_before: float = math.nan
    energy_after: float = math.nan
    iterations: int = 0


class StepFailure(RuntimeError):
    """Raised inside an attempt that cannot be completed (e.g. a singular factorisation):
    `Integrator.step` treats it like a blow-up, rolls back and retries."""


class _Scratch:
    """Per-model buffers an integrator reuses across steps (no allocation per step)."""

    def __init__(self, model: MassSpring):
        shape = model.rest_positions.shape
        self.x0 = np.empty(shape)
        self.v0 = np.empty(shape)
        self.force = np.empty(shape)
        self.inverse_mass = np.empty(shape[0])  # model's, with this step's pins zeroed
        self.end_energy = None  # ((state identity, t), kinetic + elastic [J]) after a step
        self.pin_start = np.empty((0, shape[1]))
        lo, hi = model.rest_positions.min(0), model.rest_positions.max(0)
        self.size = float(np.linalg.norm(hi - lo)) or float(model.rest_length.mean(initial=1.0))
        # energy of a 1% strain in every spring: jumps below this are never suspicious
        self.energy_floor = float(0.5 * np.sum(model.stiffness * (0.01 * model.rest_length) ** 2))
        # per-node sum of incident stiffness: bounds the energy a pin displacement can inject
        incident = np.zeros(model.node_count)
        np.add.at(incident, model.springs[:, 0], model.stiffness)
        np.add.at(incident, model.springs[:, 1], model.stiffness)
        self.incident_stiffness = incident


class Integrator:
    """Base class: validation, pins, rollback and retry. Subclasses implement `_advance`."""

    def __init__(self, *, substeps: int = 1, max_retries: int = 3, check_energy: bool = True,
                 energy_growth: float = 2.0):
        if not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise ValueError(f"substeps must be an int >= 1, got {substeps!r}")
        if not isinstance(max_retries, (int, np.integer)) or max_retries < 0:
            raise ValueError(f"max_retries must be an int >= 0, got {max_retries!r}")
        if not energy_growth > 1:
            raise ValueError(f"energy_growth must be > 1, got {energy_growth}")
        self.substeps = int(substeps)
        self.max_retries = int(max_retries)
        self.check_energy = bool(check_energy)
        self.energy_growth = float(energy_growth)
        self.last_report = StepReport()
        self._scratch: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(substeps={self.substeps})"

    def _scratch_for(self, model: MassSpring) -> _Scratch:
        scratch = self._scratch.get(model)
        if scratch is None:
            scratch = self._scratch[model] = _Scratch(model)
        return scratch

    def _energy(self, model: MassSpring, x, v, x_ref) -> float:
        """Kinetic + elastic + gravity potential relative to x_ref [J] (for the blow-up check)."""
        energy = (kernels.kinetic_energy(v, model.mass, model.inverse_mass)
                  + model.spring_energy(x))
        if model.gravity.any():
            energy += kernels.gravity_work(x, x_ref, model.mass, model.inverse_mass,
                                           model.gravity)
        return energy

    def _budget(self, model, scratch, control: ResolvedControl, x0, dt) -> float:
        """Energy [J] the control could plausibly inject in one step (generously)."""
        budget = scratch.energy_floor
        if control.pin_index.size:
            moved = control.pin_position - x0[control.pin_index]
            squared = np.einsum("ij,ij->i", moved, moved)
            budget += float(np.sum(scratch.incident_stiffness[control.pin_index] * squared))
            budget += float(np.sum(model.mass[control.pin_index] * squared)) / (dt * dt)
        if control.target_index.size:
            pull = control.target_position - x0[control.target_index]
            budget += float(np.sum(control.target_stiffness * np.einsum("ij,ij->i", pull, pull)))
        if control.force_index.size:
            magnitude = np.linalg.norm(control.force_value, axis=1)
            budget += float(np.sum(magnitude * scratch.size
                                   + (magnitude * dt) ** 2 / model.mass[control.force_index]))
        for constraint in model.constraints:
            centers = control.constraint_centers.get(getattr(constraint, "name", None))
            if centers is not None:
                nodes = constraint.nodes
                moved = np.asarray(centers, dtype=np.float64) - x0[nodes]
                budget += float(np.sum(model.mass[nodes] * np.einsum("ij,ij->i", moved, moved))
                                / (dt * dt))
        return budget

    def step(self, model: MassSpring, state: SpringState, dt: float,
             control: Control | None = None) -> StepReport:
        """Advance `state` by dt [s] under `control`; returns a StepReport (also last_report)."""
        if not isinstance(model, MassSpring):
            raise TypeError(f"model must be a MassSpring, got {type(model).__name__}")
        model.check_state(state)
        dt = float(dt)
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a finite time step > 0 [s], got {dt}")
        resolved = ResolvedControl(control, model)
        scratch = self._scratch_for(model)
        scratch.x0[...] = state.x
        scratch.v0[...] = state.v
        t0 = state.t
        report = StepReport()
        if self.check_energy:
            # the last accepted step's end energy, if this is the state it left behind
            # (saves two passes over the springs per step); gravity potential restarts at 0
            cached = scratch.end_energy
            if cached is not None and cached[0] == (id(state.x), id(state.v), state.t):
                report.energy_before = cached[1]
            else:
                report.energy_before = self._energy(model, state.x, state.v, scratch.x0)
            limit = (self.energy_growth * report.energy_before
                     + self._budget(model, scratch, resolved, state.x, dt))
        substeps = self.substeps
        for attempt in range(self.max_retries + 1):
            report.substeps = substeps
            reason = ""
            try:
                # overflow becomes inf and is caught below, not a warning mid-step
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    iterations = self._run(model, state, dt, resolved, substeps, scratch)
            except StepFailure as failure:
                reason = str(failure)
            if not reason and not (kernels.all_finite(state.x)
                                   and kernels.all_finite(state.v)):
                reason = "NaN or inf in the state"
            if not reason and self.check_energy:
                report.energy_after = self._energy(model, state.x, state.v, scratch.x0)
                if not report.energy_after <= limit:  # also catches a NaN energy
                    reason = (f"energy jumped from {report.energy_before:.3g} J to "
                              f"{report.energy_after:.3g} J (limit {limit:.3g} J)")
            if not reason:
                report.iterations = iterations
                state.t = t0 + dt
                if self.check_energy:
                    elastic = report.energy_after
                    if model.gravity.any():
                        elastic -= kernels.gravity_work(state.x, scratch.x0, model.mass,
                                                        model.inverse_mass, model.gravity)
                    scratch.end_energy = ((id(state.x), id(state.v), state.t), elastic)
                break
            report.retries = attempt + 1
            report.reason = reason
            state.x[...] = scratch.x0
            state.v[...] = scratch.v0
            self._rejected(model)
            substeps *= 4
        else:
            report.ok = False
            report.rolled_back = True
            report.retries = self.max_retries + 1
            state.x[...] = scratch.x0
            state.v[...] = 0.0  # whatever energy led here is dropped rather than kept
            scratch.end_energy = None
            if resolved.pin_index.size:
                state.x[resolved.pin_index] = resolved.pin_position
            state.t = t0 + dt
            log.warning("%s: step at t=%.4f s rolled back after %d attempts (%s)",
                        type(self).__name__, t0, report.retries, report.reason)
        if report.ok and report.retries:
            log.info("%s: step at t=%.4f s needed %d substeps (%s)", type(self).__name__, t0,
                     report.substeps, report.reason)
        self.last_report = report
        return report

    def _run(self, model, state, dt, control, substeps, scratch) -> int:
        """Advance in `substeps` equal steps, moving pins linearly to their targets."""
        h = dt / substeps
        pins = control.pin_index
        scratch.inverse_mass[...] = model.inverse_mass
        scratch.inverse_mass[pins] = 0.0
        if pins.size:
            start = scratch.x0[pins]
            delta = (control.pin_position - start) / substeps
        iterations = 0
        for s in range(substeps):
            self._begin_substep(state, (s + 1) / substeps, h)
            if pins.size:
                goal = start + delta * (s + 1)
                iterations += self._advance(model, state, h, control, goal)
            else:
                iterations += self._advance(model, state, h, control, None)
            for constraint in model.constraints:
                constraint.apply(state.x, state.v, h, scratch.inverse_mass,
                                 centers=control.constraint_centers.get(constraint.name))
        return iterations

    def _begin_substep(self, state, fraction: float, h: float) -> None:
        """Hook: called before each substep of h [s] with the share of the step done at its
        end (1 for the last); subclasses move what the step carries kinematically."""

    def _advance(self, model, state, h, control, pin_goal) -> int:
        raise NotImplementedError

    def _rejected(self, model) -> None:
        """Hook: forget warm starts after a rejected attempt."""


def _move_pins(state: SpringState, control: ResolvedControl, pin_goal, h: float) -> None:
    """Carry pinned nodes to pin_goal over h: position set, velocity = displacement / h."""
    pins = control.pin_index
    state.v[pins] = (pin_goal - state.x[pins]) / h
    state.x[pins] = pin_goal


class Verlet(Integrator):
    """Position Verlet with velocity damping and substeps (the medial and Animatron papers).

    x_{n+1} = x_n + e^{-c_vd h} (x_n - x_{n-1}) + h^2 F(x_n, v_n) / m, written in velocity form
    (v = (x_{n+1} - x_n) / h), so it is symplectic without damping. Explicit: stable only for
    h below ~2 / omega_max, hence `substeps` per `dt`.
    """

    def _advance(self, model, state, h, control, pin_goal) -> int:
        f = self._scratch_for(model).force
        f[...] = 0.0
        model.add_spring_forces(state.x, state.v, f)
        kernels.node_forces(state.x, state.v, model.mass, model.gravity, 0.0,
                            control.target_index, control.target_position,
                            control.target_stiffness, control.target_damping,
                            control.force_index, control.force_value, f)
        retention = math.exp(-model.velocity_damping * h)
        # pinned nodes have inverse mass 0 in the scratch copy: carried, not integrated
        kernels.symplectic_update(state.x, state.v, f, self._scratch_for(model).inverse_mass, h,
                                  retention)
        if control.pin_index.size:
            _move_pins(state, control, pin_goal, h)
        return 0


class _ImplicitBuffers:
    def __init__(self, model: MassSpring):
        n, d, m = model.node_count, model.dim, model.spring_count
        self.blocks = np.zeros((m, d, d))
        self.diag = np.zeros((n, d, d))
        self.diag_inverse = np.zeros((n, d, d))
        self.diagonal = np.einsum("iaa->ia", self.diag)  # writable view of the block diagonals
        self.force = np.zeros((n, d))
        self.kv = np.zeros((n, d))
        self.rhs = np.zeros((n, d))
        self.dv = np.zeros((n, d))
        self.work = [np.zeros((n, d)) for _ in range(4)]
        self.free = np.zeros(n)
        self.base_free = (~model.fixed).astype(np.float64)


class ImplicitEuler(Integrator):
    """Backward Euler with one Newton iteration (the latex paper's scheme, Baraff-Witkin 1998).

    Solves (M (1 + h c_vd) - h C - h^2 K) dv = h (f(x, v) + h K v), v += dv, x += h v, with K, C
    the force Jacobians in x and v. The system lives in a fixed spring-indexed block pattern
    (one d x d block per spring, one per node: no allocation per step), compressed springs drop
    their transverse (indefinite) term, and PCG solves it warm-started from the previous step's
    dv.

    tolerance: relative residual of the CG solve; max_iterations: CG iteration cap per step.
    preconditioner: "jacobi" (3x3 block diagonal; cheap, many iterations on stiff meshes) or
    "cholesky" (the projective-dynamics matrix M + h C_L + h^2 L, factorised once per step size
    and pin set with cholespy: it bounds the system from above, so few iterations are needed).
    """

    PRECONDITIONERS = ("jacobi", "cholesky")

    def __init__(self, *, substeps: int = 1, tolerance: float = 1e-4, max_iterations: int = 500,
                 preconditioner: str = "jacobi", **kwargs):
        super().__init__(substeps=substeps, **kwargs)
        if preconditioner not in self.PRECONDITIONERS:
            raise ValueError(f"preconditioner must be one of {self.PRECONDITIONERS}, got "
                             f"{preconditioner!r}")
        self.preconditioner = preconditioner
        self._factors: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self.factorisations = 0
        if not 0 < tolerance < 1:
            raise ValueError(f"tolerance must be in (0, 1), got {tolerance}")
        if max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self._buffers: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def _buffers_for(self, model) -> _ImplicitBuffers:
        buffers = self._buffers.get(model)
        if buffers is None:
            buffers = self._buffers[model] = _ImplicitBuffers(model)
        return buffers

    def _rejected(self, model) -> None:
        buffers = self._buffers.get(model)
        if buffers is not None:
            buffers.dv[...] = 0.0

    def _advance(self, model, state, h, control, pin_goal) -> int:
        b = self._buffers_for(model)
        x, v = state.x, state.v
        b.diag[...] = 0.0
        b.force[...] = 0.0
        b.kv[...] = 0.0
        kernels.implicit_assemble(x, v, model.springs, model.rest_length, model.stiffness,
                                  model.damping, h, b.blocks, b.diag, b.force, b.kv)
        kernels.node_forces(x, v, model.mass, model.gravity, model.velocity_damping,
                            control.target_index, control.target_position,
                            control.target_stiffness, control.target_damping,
                            control.force_index, control.force_value, b.force)
        b.diagonal += (model.mass * (1.0 + h * model.velocity_damping))[:, None]
        if control.target_index.size:
            t = control.target_index
            b.diagonal[t] += (h * h * control.target_stiffness
                              + h * control.target_damping)[:, None]
            b.kv[t] -= control.target_stiffness[:, None] * v[t]
        np.multiply(b.kv, h, out=b.rhs)
        b.rhs += b.force
        b.rhs *= h
        if not kernels.all_finite(b.rhs):
            raise StepFailure("implicit Euler: the linear system's right-hand side overflowed")
        b.free[...] = b.base_free
        dv = b.dv  # warm start: last step's velocity change
        dv[model.fixed] = 0.0
        if control.pin_index.size:
            p = control.pin_index
            b.free[p] = 0.0
            dv[p] = (pin_goal - x[p]) / h - v[p]
        r, z, pvec, q = b.work
        if self.preconditioner == "cholesky":
            factorisation, created = _cached_factorisation(self._factors, model, h, control)
            self.factorisations += created
            iterations = self._cholesky_pcg(model, b, factorisation, dv)
        else:
            kernels.invert_blocks(b.diag, b.free, b.diag_inverse)
            system = (model.springs, b.blocks, b.diag, b.diag_inverse, b.free)
            iterations = kernels.block_pcg(system, b.rhs, dv, (r, z, pvec, q), self.tolerance,
                                           self.max_iterations)
        kernels.implicit_update(x, v, dv, b.free, h)
        if control.pin_index.size:
            _move_pins(state, control, pin_goal, h)
        return iterations

    def _cholesky_pcg(self, model, b, factorisation, dv) -> int:
        """PCG with the prefactored projective-dynamics matrix as preconditioner."""
        r, z, p, q = b.work
        free = b.free[:, None]
        solve = factorisation.solver.solve
        kernels.block_matvec(model.springs, b.blocks, b.diag, dv, q)
        np.subtract(b.rhs, q, out=r)
        r *= free
        solve(r, z)
        z *= free
        rz = kernels._dot(r, z)
        np.multiply(b.rhs, free, out=q)
        solve(q, p)
        target = self.tolerance ** 2 * kernels._dot(q, p)
        p[...] = z
        iteration = 0
        while iteration < self.max_iterations and rz > target and rz > 0:
            kernels.block_matvec(model.springs, b.blocks, b.diag, p, q)
            q *= free
            pq = kernels._dot(p, q)
            if pq <= 0:
                break
            kernels.cg_step(dv, r, p, q, rz / pq)
            solve(r, z)
            z *= free
            rz_new = kernels._dot(r, z)
            kernels.cg_direction(p, z, rz_new / rz)
            rz = rz_new
            iteration += 1
        return iteration


class _Factorisation:
    """The prefactored global matrix of one (model, h, known set, targets) and its buffers.

    The system keeps all N rows: rows of known nodes (pinned this step, or fixed) are identity
    rows whose right-hand side is the known position, and their columns are moved to the
    right-hand side of their free neighbours, which keeps the matrix SPD and lets the solver
    write straight into the state.
    """

    def __init__(self, model: MassSpring, h: float, known: np.ndarray, control: ResolvedControl):
        from scipy import sparse

        try:
            from cholespy import CholeskySolverD, MatrixType
        except ImportError as error:  # pragma: no cover - cholespy is a core dependency
            raise ImportError("ProjectiveDynamics needs cholespy: pip install cholespy") from error
        n, d = model.node_count, model.dim
        self.known_index = np.flatnonzero(known).astype(np.int64)
        self.free_nodes = np.flatnonzero(~known).astype(np.int64)
        self.free_id = np.where(known, -1, np.arange(n)).astype(np.int64)
        diagonal = model.mass * (1.0 + h * model.velocity_damping)
        spring = h * h * model.stiffness + h * model.damping
        i, j = model.springs[:, 0], model.springs[:, 1]
        diagonal = diagonal + np.bincount(i, spring, n) + np.bincount(j, spring, n)
        if control.target_index.size:
            np.add.at(diagonal, control.target_index,
                      h * h * control.target_stiffness + h * control.target_damping)
        diagonal[known] = 1.0
        both = ~known[i] & ~known[j]
        rows = np.concatenate([np.arange(n), i[both], j[both]])
        cols = np.concatenate([np.arange(n), j[both], i[both]])
        vals = np.concatenate([diagonal, -spring[both], -spring[both]])
        matrix = sparse.csr_matrix((vals, (rows, cols)), shape=(n, n))
        matrix.sum_duplicates()
        matrix.sort_indices()
        if not np.all(np.isfinite(matrix.data)):
            raise StepFailure(f"global matrix not finite at step {h:g} s")
        try:
            self.solver = CholeskySolverD(n, matrix.indptr.astype(np.int32),
                                          matrix.indices.astype(np.int32),
                                          matrix.data.astype(np.float64), MatrixType.CSR)
        except ValueError as error:  # cholespy: "Matrix is not positive definite!"
            raise StepFailure(f"Cholesky factorisation failed at step {h:g} s ({error})") \
                from None
        self.weight = h * h * model.stiffness * model.rest_length
        self.damping_h = h * model.damping
        if d == 3:  # the split local step reads them in the plan's order
            plan = model.plan
            self.plan = plan
            self.plan_weight = plan.take(self.weight)
            self.plan_damping_h = plan.take(self.damping_h)
            one_known = known[i] != known[j]
            ends = np.where(known[i][one_known], 1, 0)  # which column holds the free end
            pairs = model.springs[one_known]
            rows = np.arange(len(pairs))
            self.couple_free = np.ascontiguousarray(pairs[rows, ends], dtype=np.int64)
            self.couple_known = np.ascontiguousarray(pairs[rows, 1 - ends], dtype=np.int64)
            self.couple = np.ascontiguousarray(spring[one_known])
            self.start_damping = np.zeros((3, model.spring_count))  # h c e0, plan order
        self.base = np.zeros((n, d))
        self.rhs = np.zeros((n, d))
        self.solved = np.zeros((n, d))
        self.previous = np.zeros((n, d))
        self.x_start = np.zeros((n, d))
        self.v_start = np.zeros((n, d))
        self.known_positions = np.zeros((n, d))
        self.accel = np.zeros((n, d))


def _cached_factorisation(cache, model, h, control):
    """(factorisation, created): one prefactored matrix per model, rebuilt when the step size,
    the known (pinned or fixed) set, or the targets' set or gains change."""
    known = model.fixed.copy()
    known[control.pin_index] = True
    key = (h, known.tobytes(), control.target_index.tobytes(),
           control.target_stiffness.tobytes(), control.target_damping.tobytes())
    cached = cache.get(model)
    if cached is not None and cached[0] == key:
        return cached[1], False
    factorisation = _Factorisation(model, h, known, control)
    cache[model] = (key, factorisation)
    return factorisation, True


class ProjectiveDynamics(Integrator):
    """Projective dynamics for mass-spring systems (Liu, Bargteil, O'Brien, Kavan 2013).

    Backward Euler as a minimisation, solved by local/global iterations: the local step
    projects every spring onto its rest length, the global step solves one constant sparse
    SPD system (M (1 + h c_vd) + h C + h^2 L) for x, y and z together with a sparse Cholesky
    factor computed once (cholespy) and reused until the step size, the pinned set or the
    targets' set/gains change. Each plain iteration lowers the step's objective, so the
    scheme is stable at any step size; too few iterations make a material look softer.

    iterations: local/global iterations per step, or None (default): 8 for steps longer than
    1/40 s, 6 for shorter ones (`iterations_for`; a shorter step starts closer to its solution
    and converges faster per iteration: on the stiff-rubber head 6 iterations at 1/60 s leave a
    fixed-point residual of 0.009 mm, 8 at 1/25 s 0.039 mm). chebyshev_rho: spectral-radius
    estimate for Chebyshev acceleration (Wang 2015), None to disable; it starts after
    `chebyshev_start` plain iterations. The defaults (rho 0.9) are the measured best, see
    `default_integrator`. Spring damping enters the prefactored matrix isotropically (a Laplacian
    damper on relative velocity, which would also brake rigid rotation); the local step hands
    the transverse part back at the current iterate, so converged iterations damp along the
    springs only, as ImplicitEuler and Verlet do.
    """

    # the default iteration counts: steps longer than SHORT_STEP [s] / up to it
    LONG_STEP_ITERATIONS, SHORT_STEP_ITERATIONS, SHORT_STEP = 8, 6, 1.0 / 40.0

    def __init__(self, *, substeps: int = 1, iterations: int | None = None,
                 chebyshev_rho: float | None = 0.9, chebyshev_start: int = 2,
                 chebyshev_gamma: float = 1.0, **kwargs):
        super().__init__(substeps=substeps, **kwargs)
        if iterations is not None and iterations < 1:
            raise ValueError(f"iterations must be >= 1 or None, got {iterations}")
        if chebyshev_rho is not None and not (
                isinstance(chebyshev_rho, (int, float)) and 0 < chebyshev_rho < 1):
            raise ValueError(f"chebyshev_rho must be in (0, 1) or None, got {chebyshev_rho!r}")
        self.iterations = None if iterations is None else int(iterations)
        self.chebyshev_rho = chebyshev_rho
        self.chebyshev_start = max(int(chebyshev_start), 1)
        self.chebyshev_gamma = float(chebyshev_gamma)
        self._factors: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self.factorisations = 0  # how many times a matrix was factorised (diagnostics, tests)

    def _factor_for(self, model, h, control) -> _Factorisation:
        factorisation, created = _cached_factorisation(self._factors, model, h, control)
        self.factorisations += created
        return factorisation

    def _advance(self, model, state, h, control, pin_goal) -> int:
        fac = self._factor_for(model, h, control)
        x, v = state.x, state.v
        known = fac.known_positions   # x, fixed nodes staying where they are, pins at the goal
        kernels.pd_step_start(x, v, fac.x_start, fac.v_start, known, control.pin_index,
                              control.pin_position if pin_goal is None else pin_goal)
        accel = fac.accel
        accel[...] = model.gravity
        if control.force_index.size:
            np.add.at(accel, control.force_index,
                      control.force_value / model.mass[control.force_index, None])
        start = (fac.x_start, fac.v_start, accel, known)
        if model.dim == 3:
            kernels.pd_base_rhs_3d(start, (fac.plan.si, fac.plan.sj, fac.plan_damping_h),
                                   (fac.couple_free, fac.couple_known, fac.couple),
                                   (model.mass, fac.free_nodes), h, model.velocity_damping,
                                   fac.base, fac.start_damping)
        else:
            kernels.pd_base_rhs(start, (model.springs, model.stiffness, model.damping),
                                (model.mass, fac.free_nodes, fac.free_id), h,
                                model.velocity_damping, fac.base)
        # targets; warm start: carry the shape along with its velocity, x + h v. Not the usual
        # inertial prediction y = x + h v + h^2 a: when h^2 g exceeds an element's size, y drops
        # free nodes through their fixed neighbours and the local steps settle on inverted
        # springs
        chebyshev = self.chebyshev_rho is not None
        targets = (control.target_index, control.target_position, control.target_stiffness,
                   control.target_damping)
        kernels.pd_warm_start(x, v, h, fac.base, fac.x_start, targets, fac.known_index, known,
                              fac.previous if chebyshev else fac.previous[:0])
        direct = x.flags.c_contiguous and not chebyshev
        rho2 = self.chebyshev_rho ** 2 if chebyshev else 0.0
        omega = 1.0
        split = model.dim == 3
        damped = not split and bool(model.damping.any())  # the 2D kernels' choice only
        plan = fac.plan if split else None
        iterations = self.iterations_for(h)
        for iteration in range(iterations):
            if split:
                kernels.pd_local_rhs_3d(x, plan.si, plan.sj, fac.plan_weight,
                                        fac.start_damping, fac.base, fac.known_index, known,
                                        plan.scratch, fac.rhs)
            elif damped:
                kernels.pd_local_rhs_damped(x, fac.x_start, model.springs, fac.weight,
                                            fac.damping_h, fac.base, fac.known_index, known,
                                            fac.rhs)
            else:
                kernels.pd_local_rhs(x, model.springs, fac.weight, fac.base, fac.known_index,
                                     known, fac.rhs)
            if direct:
                fac.solver.solve(fac.rhs, x)
                continue
            fac.solver.solve(fac.rhs, fac.solved)
            if not chebyshev or iteration < self.chebyshev_start:
                fac.previous[...] = x
                x[...] = fac.solved
            else:
                omega = (2.0 / (2.0 - rho2) if iteration == self.chebyshev_start
                         else 4.0 / (4.0 - rho2 * omega))
                kernels.chebyshev_update(x, fac.solved, fac.previous, omega,
                                         self.chebyshev_gamma)
        kernels.pd_step_end(x, fac.x_start, h, v)
        return iterations

    def iterations_for(self, h: float) -> int:
        """Local/global iterations of one (sub)step of h seconds."""
        if self.iterations is not None:
            return self.iterations
        return (self.SHORT_STEP_ITERATIONS if h <= self.SHORT_STEP * (1 + 1e-9)
                else self.LONG_STEP_ITERATIONS)


def default_integrator() -> Integrator:
    """The integrator puppets should use unless they have a reason not to.

    ProjectiveDynamics with its defaults: 8 local/global iterations per step longer than 1/40 s
    and 6 per shorter step, Chebyshev acceleration (rho 0.9). Measured in benchmarks/sim.py on
    stiff-rubber heads shaken by the hand: the only integrator within a 60 fps budget at 10k
    masses / 45k springs (one prefactored solve per iteration), stable at any step size, and
    1.1-1.3 mm RMS from the converged reference at both 1/60 s and 1/25 s. Without Chebyshev, 8-10
    iterations were as good at 1/60 s on the 10k head but 4.5-4.8 mm off at 1/25 s and 2.3-2.6 mm
    at 1/60 s on a coarser head; one Newton step with PCG is 4-8x slower, explicit Verlet needs
    hundreds of substeps per frame on stiff material.
    """
    return ProjectiveDynamics()
