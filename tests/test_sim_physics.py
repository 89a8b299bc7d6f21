"""Physics of the integrators against analytic results and conservation laws."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from characters import Control, ImplicitEuler, MassSpring, ProjectiveDynamics, Verlet
from characters.model import tetrahedral_lattice


def two_masses(k=50.0, m=0.2, stretch=0.05, dim=3):
    x = np.zeros((2, dim))
    x[1, 0] = 1.0
    model = MassSpring(x, [[0, 1]], stiffness=k, mass=m)
    state = model.state()
    state.x[1, 0] += stretch
    return model, state


def measured_period(elongation, dt):
    """Mean period from upward zero crossings, linearly interpolated between samples."""
    s = np.asarray(elongation)
    up = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    crossings = (up + s[up] / (s[up] - s[up + 1])) * dt
    return float(np.mean(np.diff(crossings)))


@pytest.mark.slow
def test_single_spring_period_verlet():
    k, m = 50.0, 0.2
    model, state = two_masses(k, m)
    dt = 1e-4
    integrator = Verlet()
    elongation = []
    for _ in range(30000):
        integrator.step(model, state, dt)
        elongation.append(np.linalg.norm(state.x[1] - state.x[0]) - 1.0)
    analytic = 2 * math.pi / math.sqrt(k / (m / 2))  # reduced mass m/2
    assert measured_period(elongation, dt) == pytest.approx(analytic, rel=0.01)
    # and the tighter truth: position Verlet's period error is O((omega dt)^2)
    assert abs(measured_period(elongation, dt) / analytic - 1) < 1e-3


@pytest.mark.slow
def test_verlet_conserves_energy_without_damping(rng):
    nodes = 30
    x = rng.normal(size=(nodes, 3))
    pairs = np.array([(i, j) for i in range(nodes) for j in range(i + 1, nodes)
                      if np.linalg.norm(x[i] - x[j]) < 1.3])
    # a net hanging from its two highest nodes: gravity does work, but nothing falls forever
    top = np.argsort(x[:, 2])[-2:]
    model = MassSpring(x, pairs, stiffness=20.0, mass=rng.uniform(0.5, 1.5, nodes),
                       gravity=(0, 0, -9.81), fixed=top)
    state = model.state()
    state.v[:] = 0.3 * rng.normal(size=state.v.shape)
    state.v[top] = 0
    integrator = Verlet()
    dt = 1e-3
    positions = [state.x.copy()]
    for _ in range(4000):
        integrator.step(model, state, dt)
        positions.append(state.x.copy())
    # position Verlet conserves energy measured with the central-difference velocity
    # (state.v is the backward difference (x_{n+1} - x_n) / dt, half a step behind)
    positions = np.array(positions)
    velocity = (positions[2:] - positions[:-2]) / (2 * dt)
    kinetic = np.array([model.kinetic_energy(v) for v in velocity])
    potential = np.array([model.spring_energy(x) + model.gravity_energy(x)
                          for x in positions[1:-1]])
    energy = kinetic + potential
    scale = kinetic.max()  # the energy that sloshes between forms
    assert np.ptp(energy) < 1e-3 * scale
    # no secular drift: the last quarter is no further off than the first
    assert abs(energy[-1000:].mean() - energy[:1000].mean()) < 2e-4 * scale


def test_verlet_conserves_momentum(rng):
    nodes = 25
    x = rng.normal(size=(nodes, 3))
    pairs = np.array([(i, j) for i in range(nodes) for j in range(i + 1, nodes)
                      if np.linalg.norm(x[i] - x[j]) < 1.4])
    model = MassSpring(x, pairs, stiffness=30.0, damping=0.5, mass=rng.uniform(0.5, 2, nodes))
    state = model.state()
    state.x += 0.1 * rng.normal(size=x.shape)
    state.v[:] = rng.normal(size=x.shape)
    p0 = model.momentum(state)
    integrator = Verlet()
    for _ in range(2000):
        integrator.step(model, state, 1e-3)
    np.testing.assert_allclose(model.momentum(state), p0, atol=1e-9)


def test_verlet_velocity_damping_decays_like_exp():
    model = MassSpring([[0.0, 0], [1, 0]], [[0, 1]], stiffness=0.0, velocity_damping=2.0)
    state = model.state()
    state.v[:] = [[1.0, 0], [1.0, 0]]
    Verlet().step(model, state, 0.5)
    np.testing.assert_allclose(state.v[:, 0], math.exp(-1.0))


def test_pins_carry_nodes_and_fixed_nodes_stay():
    x = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    model = MassSpring(x, [[0, 1], [1, 2]], stiffness=10.0, fixed=[2], gravity=(0, 0, -9.8))
    state = model.state()
    integrator = Verlet(substeps=4)
    integrator.step(model, state, 0.1, Control(pins={0: (0, 0, 0.5)}))
    np.testing.assert_allclose(state.x[0], [0, 0, 0.5])
    np.testing.assert_allclose(state.x[2], [2, 0, 0])
    assert state.x[1, 2] < 0.1  # the free node lags behind the pin (and sags)
    assert state.t == pytest.approx(0.1)


def test_target_force_pulls_towards_target():
    model = MassSpring([[0.0, 0], [0.5, 0]], [[0, 1]], stiffness=1.0, mass=1.0,
                       velocity_damping=1.0)
    state = model.state()
    control = Control(targets={1: (0.5, 1.0)}, target_stiffness=40.0, target_damping=8.0)
    integrator = Verlet(substeps=10)
    for _ in range(1000):
        integrator.step(model, state, 0.01, control)
    # equilibrium of a soft spring and a stiff target: both nodes drift to the target height
    assert state.x[1, 1] == pytest.approx(1.0, abs=0.05)
    assert np.abs(state.v).max() < 0.05


# --- all integrators --------------------------------------------------------------------------


INTEGRATORS = {
    "verlet": lambda: Verlet(),
    "implicit": lambda: ImplicitEuler(tolerance=1e-10),
    "implicit-cholesky": lambda: ImplicitEuler(tolerance=1e-10, preconditioner="cholesky"),
    "projective": lambda: ProjectiveDynamics(iterations=30, chebyshev_rho=None),
    "projective-default": lambda: ProjectiveDynamics(),
}


def random_cloud(rng, nodes=20, radius=1.4, **kwargs):
    x = rng.normal(size=(nodes, 3))
    pairs = np.array([(i, j) for i in range(nodes) for j in range(i + 1, nodes)
                      if np.linalg.norm(x[i] - x[j]) < radius])
    return MassSpring(x, pairs, mass=rng.uniform(0.5, 2, nodes), **kwargs)


@pytest.mark.parametrize("name", list(INTEGRATORS))
@pytest.mark.slow
def test_momentum_conserved_without_external_forces(rng, name):
    model = random_cloud(rng, stiffness=30.0, damping=0.5)
    state = model.state()
    state.x += 0.1 * rng.normal(size=state.x.shape)
    state.v[:] = rng.normal(size=state.x.shape)
    p0 = model.momentum(state)
    integrator = INTEGRATORS[name]()
    for _ in range(200):
        report = integrator.step(model, state, 5e-3)
        assert report.ok
    np.testing.assert_allclose(model.momentum(state), p0, atol=1e-7)


@pytest.mark.parametrize("name", ["implicit", "implicit-cholesky", "projective"])
def test_implicit_energy_never_increases(rng, name):
    model = random_cloud(rng, stiffness=50.0)
    state = model.state()
    state.v[:] = rng.normal(size=state.x.shape)
    integrator = INTEGRATORS[name]()
    energy = model.energy(state)
    for _ in range(300):
        integrator.step(model, state, 0.02)
        now = model.energy(state)
        assert now <= energy * (1 + 1e-9)
        energy = now


def reference_dv(model, state, h):
    """Dense linearised backward-Euler step with finite-difference Jacobians (slow, obvious)."""
    n, d = state.x.shape
    x0, v0 = state.x.ravel(), state.v.ravel()

    def force(xf, vf):
        return model.forces(xf.reshape(n, d), vf.reshape(n, d)).ravel()

    eps = 1e-7
    K = np.zeros((n * d, n * d))
    C = np.zeros((n * d, n * d))
    for col in range(n * d):
        e = np.zeros(n * d)
        e[col] = eps
        # stiffness at v = 0: Baraff-Witkin drop the damping force's dependence on x
        K[:, col] = (force(x0 + e, 0 * v0) - force(x0 - e, 0 * v0)) / (2 * eps)
        C[:, col] = (force(x0, v0 + e) - force(x0, v0 - e)) / (2 * eps)
    M = np.diag(np.repeat(model.mass, d))
    A = M - h * C - h * h * K
    b = h * (force(x0, v0) + h * K @ v0)
    return np.linalg.solve(A, b).reshape(n, d)


@pytest.mark.parametrize("preconditioner", ["jacobi", "cholesky"])
def test_implicit_step_matches_dense_newton_step(rng, preconditioner):
    x = rng.normal(size=(12, 3))
    pairs = np.array([(i, j) for i in range(12) for j in range(i + 1, 12)])
    # every spring stretched: the definiteness clamp is inactive, so the Jacobian is exact
    model = MassSpring(x, pairs, stiffness=rng.uniform(5, 20, len(pairs)),
                       damping=rng.uniform(0, 1, len(pairs)), mass=rng.uniform(0.5, 2, 12),
                       rest_length=0.8 * np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1),
                       gravity=(0, -9.8, 0), velocity_damping=0.7)
    state = model.state()
    state.v[:] = rng.normal(size=x.shape)
    v0, x0 = state.v.copy(), state.x.copy()
    h = 0.01
    dv = reference_dv(model, state, h)
    ImplicitEuler(tolerance=1e-12, preconditioner=preconditioner).step(model, state, h)
    np.testing.assert_allclose(state.v - v0, dv, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(state.x, x0 + h * state.v, rtol=1e-12, atol=1e-12)


def chain_model(spring_damping=True):
    """Three masses in a damped, gravity-loaded 2D chain hanging from a fixed node."""
    x = np.array([[0.0, 0.0], [0.3, -0.1], [0.6, -0.3], [0.8, -0.6]])
    return MassSpring(x, [[0, 1], [1, 2], [2, 3], [1, 3]], stiffness=[40.0, 30.0, 50.0, 10.0],
                      damping=[0.2, 0.1, 0.3, 0.0] if spring_damping else 0.0,
                      mass=[1.0, 0.5, 0.8, 0.6],
                      gravity=(0, -9.81), velocity_damping=0.2, fixed=[0])


def reference_trajectory(model, state, duration):
    free = ~model.fixed
    n, d = state.x.shape

    def rhs(_, y):
        x = y[: n * d].reshape(n, d)
        v = y[n * d:].reshape(n, d)
        a = model.forces(x, v) / model.mass[:, None]
        a[~free] = 0
        return np.concatenate([v.ravel(), a.ravel()])

    y0 = np.concatenate([state.x.ravel(), state.v.ravel()])
    sol = solve_ivp(rhs, (0, duration), y0, method="DOP853", rtol=1e-11, atol=1e-12)
    return sol.y[: n * d, -1].reshape(n, d)


@pytest.mark.parametrize("name", ["implicit", "projective"])
@pytest.mark.slow
def test_implicit_converges_to_reference_as_dt_shrinks(name):
    # projective dynamics damps springs isotropically (a documented difference), so it is
    # compared on the same chain without spring damping (velocity damping stays)
    model = chain_model(spring_damping=name == "implicit")
    start = model.state()
    start.v[1:] = [[1.0, 0.5], [-0.5, 1.0], [0.3, -0.2]]
    duration = 0.8
    truth = reference_trajectory(model, start, duration)
    errors = []
    for steps in (40, 80, 160, 320, 640):
        state = start.copy()
        integrator = (ImplicitEuler(tolerance=1e-12) if name == "implicit"
                      else ProjectiveDynamics(iterations=100))
        for _ in range(steps):
            integrator.step(model, state, duration / steps)
        errors.append(np.abs(state.x - truth).max())
    errors = np.array(errors)
    ratios = errors[:-1] / errors[1:]
    # first order: halving dt halves the error (approached from below as dt shrinks)
    assert np.all(ratios > 1.6) and np.all(ratios < 2.2), (errors, ratios)
    assert ratios[-1] > 1.9, (errors, ratios)
    assert errors[-1] < 0.01


def test_implicit_preconditioners_agree_with_pins_and_targets(rng):
    x, springs, _ = tetrahedral_lattice((3, 3, 2), 0.1)
    model = MassSpring(x, springs, stiffness=rng.uniform(50, 500, len(springs)), damping=0.3,
                       mass=0.05, gravity=(0, 0, -9.81), velocity_damping=0.5, fixed=[0])
    pins = np.flatnonzero(x[:, 2] == 0)[1:4]
    control = Control(pins=(pins, x[pins] + [0.05, 0, 0.02]), targets={len(x) - 1: (0, 0, 1.0)},
                      target_stiffness=20.0, target_damping=0.5)
    results = []
    for preconditioner in ("jacobi", "cholesky"):
        state = model.state()
        integrator = ImplicitEuler(tolerance=1e-12, preconditioner=preconditioner)
        for _ in range(5):
            integrator.step(model, state, 1 / 30, control)
        results.append(state.x)
    np.testing.assert_allclose(results[0], results[1], atol=1e-9)
    np.testing.assert_allclose(results[0][pins], x[pins] + [0.05, 0, 0.02])
    with pytest.raises(ValueError, match="preconditioner must be one of"):
        ImplicitEuler(preconditioner="ilu")


def test_default_integrator_is_projective():
    from characters import default_integrator
    integrator = default_integrator()
    assert isinstance(integrator, ProjectiveDynamics)
    assert integrator.iterations is None and integrator.chebyshev_rho == 0.9
    # 8 local/global iterations per step longer than 1/40 s, 6 per shorter one (substeps count)
    assert [integrator.iterations_for(h) for h in (1 / 25, 1 / 30, 1 / 40, 1 / 60)] == [8, 8, 6, 6]
    assert ProjectiveDynamics(iterations=5).iterations_for(1 / 60) == 5
    model = MassSpring([[0.0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1], [1, 2], [0, 2]],
                       stiffness=100.0, mass=0.01, gravity=(0, 0, -9.8))
    state = model.state()
    assert integrator.step(model, state, 1 / 25).iterations == 8
    assert integrator.step(model, state, 1 / 60).iterations == 6
    with pytest.raises(ValueError, match="iterations must be >= 1 or None"):
        ProjectiveDynamics(iterations=0)
    with pytest.raises(ValueError, match="chebyshev_rho"):
        ProjectiveDynamics(chebyshev_rho=1.5)


@pytest.mark.parametrize("chebyshev", [None, 0.9])
def test_projective_converges_to_backward_euler_minimiser(rng, chebyshev):
    """Converged local/global iterations = the minimiser of the backward-Euler objective
    |x - y|_M^2 / (2 h^2) + E(x) (Liu et al. 2013), found here by scipy's L-BFGS."""
    from scipy.optimize import minimize

    x0, springs, _ = tetrahedral_lattice((2, 2, 1), 0.1)
    model = MassSpring(x0, springs, stiffness=rng.uniform(20, 60, len(springs)),
                       mass=rng.uniform(0.05, 0.1, len(x0)), gravity=(0, 0, -9.81),
                       fixed=np.flatnonzero(x0[:, 2] == 0)[:2])
    state = model.state()
    state.v[:] = rng.normal(scale=0.5, size=x0.shape)
    state.v[model.fixed] = 0
    h = 0.05
    free = ~model.fixed
    y = state.x + h * state.v + h * h * model.gravity

    def objective(flat):
        x = state.x.copy()
        x[free] = flat.reshape(-1, 3)
        inertia = 0.5 / h ** 2 * np.sum(model.mass[free, None] * (x[free] - y[free]) ** 2)
        grad = model.mass[free, None] * (x[free] - y[free]) / h ** 2
        forces = model.forces(x, np.zeros_like(x)) - model.mass[:, None] * model.gravity
        return inertia + model.spring_energy(x), (grad - forces[free]).ravel()

    best = minimize(objective, y[free].ravel(), jac=True, method="L-BFGS-B",
                    options=dict(ftol=1e-15, gtol=1e-12, maxiter=10000))
    integrator = ProjectiveDynamics(iterations=400, chebyshev_rho=chebyshev)
    integrator.step(model, state, h)
    np.testing.assert_allclose(state.x[free], best.x.reshape(-1, 3), atol=1e-6)


@pytest.mark.parametrize("name", ["projective", "verlet"])
def test_spring_damping_does_not_brake_rigid_rotation(name):
    """Damping acts along springs: heavy spring damping leaves a spinning stiff block spinning
    as fast as without it (an isotropic damper on relative velocity would stop it).

    (ImplicitEuler is left out: its single linearised Newton step itself bleeds about half of
    this block's rotational energy in 30 steps, damping or not; see docs/core.md.)"""
    x, springs, _ = tetrahedral_lattice((2, 2, 2), 0.05)
    x = x - x.mean(0)
    energies = []
    for damping in (0.0, 5.0):
        model = MassSpring(x, springs, stiffness=2000.0, damping=damping, mass=0.01)
        state = model.state()
        state.v[:] = np.cross([0.0, 0.0, 3.0], x)
        integrator = ProjectiveDynamics(iterations=30) if name == "projective" else Verlet(
            substeps=20)
        for _ in range(30):
            integrator.step(model, state, 0.01)
        energies.append(model.kinetic_energy(state.v))
    undamped, damped = energies
    assert damped == pytest.approx(undamped, rel=0.03)
