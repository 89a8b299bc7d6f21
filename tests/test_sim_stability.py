"""Stiff latex at 25 fps, rollback of blow-ups, constraints under violent control, bad input."""
import logging

import numpy as np
import pytest

from characters import (CircumsphereConstraint, Control, ImplicitEuler, MassSpring,
                        ProjectiveDynamics, SpringReductionConstraint, Verlet, material)
from characters.model import tetrahedral_lattice

INTEGRATORS = {
    "verlet": Verlet,
    "implicit": ImplicitEuler,
    "projective": ProjectiveDynamics,
}


def latex_block(spacing=0.01, cubes=(4, 4, 4)):
    x, springs, _ = tetrahedral_lattice(cubes, spacing)
    rest = np.linalg.norm(x[springs[:, 1]] - x[springs[:, 0]], axis=1)
    k, c, m = material("latex_skin").lattice_parameters(rest, spacing=spacing)
    return MassSpring(x, springs, stiffness=k, damping=c, mass=m, gravity=(0, 0, -9.81))


def shake(model, integrator, steps=50, dt=1 / 25, amplitude=0.02):
    base = np.flatnonzero(model.rest_positions[:, 2] == 0)
    state = model.state()
    reports = []
    for n in range(steps):
        offset = [amplitude * np.sin(2 * np.pi * 2 * n * dt), 0, 0]
        control = Control(pins=(base, model.rest_positions[base] + offset))
        reports.append(integrator.step(model, state, dt, control))
    return state, reports


@pytest.mark.parametrize("name", ["implicit", "projective"])
def test_stiff_latex_block_stable_at_25fps(name):
    model = latex_block()
    state, reports = shake(model, INTEGRATORS[name](max_retries=0))
    assert all(r.ok and r.retries == 0 for r in reports)
    # the stiff block follows its shaken base nearly rigidly: no node strays more than
    # the shaking amplitude from its rest position (plus a little sag)
    assert np.abs(state.x - model.rest_positions).max() < 0.025
    lengths = model.spring_lengths(state.x)
    assert np.abs(lengths / model.rest_length - 1).max() < 0.1


def test_explicit_verlet_blows_up_on_the_same_block(caplog):
    model = latex_block()
    with caplog.at_level(logging.WARNING, logger="characters.integrators"):
        state, reports = shake(model, Verlet(max_retries=0), steps=5)
    assert not all(r.ok for r in reports)
    failed = next(r for r in reports if not r.ok)
    assert failed.rolled_back and ("energy" in failed.reason or "NaN" in failed.reason)
    assert "rolled back" in caplog.text
    # the blow-up never reached the state
    assert np.all(np.isfinite(state.x))
    assert np.abs(state.x - model.rest_positions).max() < 0.05


def test_rollback_retries_with_substeps():
    # one spring, omega = 100 rad/s: dt = 0.05 is far beyond Verlet's limit 2/omega = 0.02,
    # 16 substeps (h = 0.003) are well within it
    model = MassSpring([[0.0, 0, 0], [1, 0, 0]], [[0, 1]], stiffness=5000.0, fixed=[0])
    state = model.state()
    state.x[1, 0] = 1.01
    before = model.energy(state)
    integrator = Verlet(max_retries=3)
    reports = []
    for _ in range(20):
        reports.append(integrator.step(model, state, 0.05))
        # the amplitude stays that of the initial 1 cm stretch (up to Verlet's error at 4 substeps)
        assert abs(state.x[1, 0] - 1.0) < 0.02
    assert all(r.ok for r in reports)
    assert sum(r.retries > 0 and r.substeps > 1 for r in reports) >= 10
    assert integrator.last_report is reports[-1]
    assert model.energy(state) < 5 * before


def test_failed_step_restores_state():
    model = MassSpring([[0.0, 0, 0], [1, 0, 0]], [[0, 1]], stiffness=5000.0, fixed=[0])
    state = model.state()
    state.x[1, 0] = 1.01
    x_before = state.x.copy()
    report = Verlet(max_retries=0).step(model, state, 0.5)
    # a single step of 0.5 s is 25x over the limit: rejected, the state is the old one
    if report.ok:  # one step may survive by luck of phase; the next ones will not
        report = Verlet(max_retries=0).step(model, state, 0.5)
    assert not report.ok and report.rolled_back
    assert np.all(np.isfinite(state.x)) and np.all(state.v == 0)
    assert np.abs(state.x - x_before).max() < 0.2


def test_nan_in_control_is_refused_not_simulated():
    model = latex_block(cubes=(1, 1, 1))
    with pytest.raises(ValueError, match="not finite"):
        Verlet().step(model, model.state(), 0.01, Control(forces={0: (np.inf, 0, 0)}))


@pytest.mark.parametrize("name", list(INTEGRATORS))
@pytest.mark.slow
def test_constraints_hold_under_violent_control(rng, name):
    # a "medial" strip: surface nodes, each tied to a fixed inner bone point by a bone spring
    count = 12
    surface = np.c_[np.linspace(0, 1, count), np.zeros(count), np.full(count, 0.2)]
    bones = surface - [0, 0, 0.2]
    x = np.vstack([surface, bones])
    surface_springs = [(i, i + 1) for i in range(count - 1)]
    bone_springs = [(i, count + i) for i in range(count)]
    springs = np.array(surface_springs + bone_springs)
    reduce_index = np.arange(len(surface_springs), len(springs))
    sphere = CircumsphereConstraint(np.arange(1, count // 2), max_factor=1.5,
                                    rest_length=np.full(count // 2 - 1, 0.2))
    reduction = SpringReductionConstraint(reduce_index[count // 2:], min_factor=0.8,
                                          max_factor=1.5, iterations=4)
    model = MassSpring(x, springs, stiffness=200.0, damping=0.5, mass=0.05,
                       fixed=np.arange(count, 2 * count), constraints=[sphere, reduction])
    state = model.state()
    integrator = INTEGRATORS[name]()
    worst_sphere = worst_spring = 0.0
    for _ in range(10_000):
        # the first node is yanked around by up to 2 m a step; a random node gets a huge kick
        kick = int(rng.integers(1, count))
        control = Control(pins={0: surface[0] + rng.normal(scale=0.7, size=3)},
                          forces={kick: rng.normal(scale=500.0, size=3)})
        integrator.step(model, state, 1 / 60, control)
        worst_sphere = max(worst_sphere, sphere.violation(state.x))
        worst_spring = max(worst_spring, reduction.violation(state.x))
    assert worst_sphere < 1e-9
    assert worst_spring < 1e-9
    assert np.all(np.isfinite(state.x))


def test_spring_reduction_iterates_shared_nodes():
    # one node held by two fixed bone points: fixing one spring breaks the other, so a single
    # pass leaves a violation that iterating removes
    x = np.array([[0.0, 0, 0], [-1, 0, 0], [1, 0, 0.0]])
    once = SpringReductionConstraint(min_factor=0.9, max_factor=1.1, iterations=1)
    many = SpringReductionConstraint(min_factor=0.9, max_factor=1.1, iterations=50)
    results = []
    for constraint in (once, many):
        model = MassSpring(x, [[0, 1], [0, 2]], stiffness=1.0, fixed=[1, 2],
                           constraints=[constraint])
        moved = x.copy()
        moved[0] = [0.0, 1.0, 0]  # 1.41 from both bones: each fix breaks the other
        constraint.apply(moved, np.zeros_like(moved), 0.01, model.inverse_mass)
        results.append(constraint.violation(moved))
    assert results[0] > 1e-3 and results[1] < 1e-6


def test_circumsphere_moving_centres():
    x = np.array([[0.0, 0, 0], [1, 0, 0]])
    sphere = CircumsphereConstraint([1], radius=0.1, name="tip")
    model = MassSpring(x, [[0, 1]], stiffness=1.0, constraints=[sphere])
    state = model.state()
    Verlet().step(model, state, 0.01, Control(constraint_centers={"tip": [[1.0, 2.0, 0]]}))
    assert np.linalg.norm(state.x[1] - [1, 2, 0]) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="centres for constraint 'tip'"):
        Verlet().step(model, state, 0.01, Control(constraint_centers={"tip": [[1.0, 2.0]]}))


def test_projective_refactorises_only_when_needed():
    model = latex_block(cubes=(2, 2, 2))
    state = model.state()
    integrator = ProjectiveDynamics()
    base = np.flatnonzero(model.rest_positions[:, 2] == 0)
    for n in range(5):  # pins move, the set stays: one factorisation
        integrator.step(model, state, 1 / 60, Control(pins=(base, model.rest_positions[base]
                                                            + [0, 0, 0.001 * n])))
    assert integrator.factorisations == 1
    integrator.step(model, state, 1 / 30, Control(pins=(base, model.rest_positions[base])))
    assert integrator.factorisations == 2  # new step size
    more = np.append(base, model.node_count - 1)
    report = integrator.step(model, state, 1 / 30, Control(pins=(more, state.x[more])))
    assert report.retries == 0 and integrator.factorisations == 3  # new pin set


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_step_validation(name):
    model = latex_block(cubes=(1, 1, 1))
    integrator = INTEGRATORS[name]()
    with pytest.raises(ValueError, match="dt must be"):
        integrator.step(model, model.state(), 0.0)
    with pytest.raises(ValueError, match="dt must be"):
        integrator.step(model, model.state(), float("nan"))
    with pytest.raises(TypeError, match="control must be a Control"):
        integrator.step(model, model.state(), 0.01, {0: (0, 0, 0)})
    with pytest.raises(TypeError, match="model must be a MassSpring"):
        integrator.step("model", model.state(), 0.01)
    with pytest.raises(ValueError, match="substeps"):
        INTEGRATORS[name](substeps=0)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_non_finite_step_is_rolled_back_even_without_energy_check(name):
    model = MassSpring([[0.0, 0, 0], [1, 0, 0]], [[0, 1]], stiffness=10.0)
    state = model.state()
    # a finite but absurd force overflows the positions to inf within the step
    control = Control(forces={1: (1e308, 1e308, 0)})
    report = INTEGRATORS[name](check_energy=False, max_retries=1).step(model, state, 1e10,
                                                                       control)
    assert not report.ok and report.rolled_back
    # (at this step size the projective matrix cannot even be factorised: also a failure)
    assert any(word in report.reason for word in ("NaN or inf", "factorisation", "overflow"))
    assert np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v))
    np.testing.assert_array_equal(state.x, model.rest_positions)


def test_all_finite_kernel_sees_nan_and_inf():
    from characters import kernels
    assert not kernels.all_finite(np.array([[np.nan, 1.0]]))
    assert not kernels.all_finite(np.array([[1.0, -np.inf]]))
    assert kernels.all_finite(np.zeros((3, 2)))
