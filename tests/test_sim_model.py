"""MassSpring / SpringState / Control: validation, energies and forces against NumPy references."""
import numpy as np
import pytest

from characters import Control, MassSpring, SpringState
from characters import kernels


def random_model(rng, nodes=40, springs=120, dim=3, damping=True):
    x = rng.normal(size=(nodes, dim))
    pairs = rng.integers(0, nodes, size=(springs * 2, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]][:springs]
    return MassSpring(x, pairs, stiffness=rng.uniform(1, 10, len(pairs)),
                      damping=rng.uniform(0, 1, len(pairs)) if damping else 0.0,
                      mass=rng.uniform(0.5, 2, nodes), gravity=np.r_[0, -9.81, 0][:dim],
                      velocity_damping=0.3)


def reference_forces(model, x, v):
    """Plain per-spring loop: the obvious formula, no tricks."""
    f = np.zeros_like(x)
    for s, (i, j) in enumerate(model.springs):
        e = x[j] - x[i]
        length = np.linalg.norm(e)
        u = e / length
        mag = model.stiffness[s] * (length - model.rest_length[s]) \
            + model.damping[s] * np.dot(v[j] - v[i], u)
        f[i] += mag * u
        f[j] -= mag * u
    f += model.mass[:, None] * (model.gravity - model.velocity_damping * v)
    f[model.fixed] = 0
    return f


@pytest.mark.parametrize("dim", [2, 3])
def test_forces_match_reference(rng, dim):
    model = random_model(rng, dim=dim)
    x = model.rest_positions + 0.1 * rng.normal(size=model.rest_positions.shape)
    v = rng.normal(size=x.shape)
    np.testing.assert_allclose(model.forces(x, v), reference_forces(model, x, v), rtol=1e-10,
                               atol=1e-10)


@pytest.mark.slow
def test_elastic_only_kernel_matches(rng):
    model = random_model(rng, damping=False)
    x = model.rest_positions + 0.1 * rng.normal(size=model.rest_positions.shape)
    a = np.zeros_like(x)
    b = np.zeros_like(x)
    c = np.zeros_like(x)
    plan = model.plan
    kernels.spring_forces_elastic_3d(x, plan.si, plan.sj, plan.rest_length, plan.stiffness,
                                     plan.scratch, a)
    kernels.spring_forces(x, np.zeros_like(x), model.springs, model.rest_length,
                          model.stiffness, model.damping, b)
    kernels.spring_forces_elastic_fused(x, model.springs, model.rest_length, model.stiffness, c)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(c, b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("chunk", [None, 1, 5])
@pytest.mark.slow
def test_split_kernels_match_fused_in_any_spring_order(rng, chunk):
    """The split passes (gather, arithmetic, scatter by runs) give the fused loop's sums for
    springs in random order and orientation, and the plan puts them back in model order; also
    when the passes run in chunks narrower than a run of springs sharing a first node."""
    model = random_model(rng)
    x = model.rest_positions + 0.1 * rng.normal(size=model.rest_positions.shape)
    v = rng.normal(size=x.shape)
    plan = model.plan
    scratch = plan.scratch if chunk is None else np.full((6, chunk), np.nan)
    if chunk is None:
        assert scratch.shape == (6, min(model.spring_count, kernels.SPLIT_CHUNK))
    else:  # the chunk boundaries must cut runs, or this case tests nothing new
        assert np.any(plan.si[chunk::chunk] == plan.si[chunk - 1:-1:chunk])
    assert np.all(np.diff(plan.si.astype(np.int64)) >= 0) and np.all(plan.si <= plan.sj)
    pairs = np.sort(model.springs, axis=1)[plan.order]
    np.testing.assert_array_equal(pairs, np.stack([plan.si, plan.sj], axis=1))
    np.testing.assert_array_equal(plan.stiffness, model.stiffness[plan.order])
    fused = np.zeros_like(x)
    kernels.spring_forces(x, v, model.springs, model.rest_length, model.stiffness,
                          model.damping, fused)
    split = np.zeros_like(x)
    kernels.spring_forces_3d(x, v, plan.si, plan.sj, plan.rest_length, plan.stiffness,
                             plan.damping, scratch, split)
    np.testing.assert_allclose(split, fused, rtol=1e-11, atol=1e-11)
    # the elastic energy, split against its fused form
    assert kernels.spring_energy_3d(x, plan.si, plan.sj, plan.rest_length, plan.stiffness,
                                    scratch) == pytest.approx(
        kernels.spring_energy(x, model.springs, model.rest_length, model.stiffness), rel=1e-12)
    # the projective step's right-hand side at an iterate x: the 3D base (without the
    # isotropic damper, which cancels) plus the split local step, against the fused 2D-style
    # kernels that keep both terms
    h = 1 / 25
    weight = h * h * model.stiffness * model.rest_length
    damping_h = h * model.damping
    x_start = x - h * v
    known_index = np.array([0, 3], dtype=np.int64)
    known = rng.normal(size=x.shape)
    mask = np.zeros(len(x), dtype=bool)
    mask[known_index] = True
    free_nodes = np.flatnonzero(~mask)
    free_id = np.where(mask, -1, np.arange(len(x)))
    accel = rng.normal(size=x.shape)
    base = np.zeros_like(x)
    start, spring_set = (x_start, v, accel, known), (model.springs, model.stiffness, model.damping)
    kernels.pd_base_rhs(start, spring_set, (model.mass, free_nodes, free_id), h, 0.3, base)
    expected = np.zeros_like(x)
    kernels.pd_local_rhs_damped(x, x_start, model.springs, weight, damping_h, base, known_index,
                                known, expected)
    i, j = model.springs[:, 0], model.springs[:, 1]
    one = mask[i] != mask[j]
    ends = np.where(mask[i][one], 1, 0)
    rows = np.arange(one.sum())
    base_3d = np.zeros_like(x)
    start_damping = np.full((3, model.spring_count), np.nan)  # every entry must be written
    boundary = (model.springs[one][rows, ends].astype(np.int64),
                model.springs[one][rows, 1 - ends].astype(np.int64),
                (h * h * model.stiffness + damping_h)[one])
    kernels.pd_base_rhs_3d(start, (plan.si, plan.sj, plan.take(damping_h)), boundary,
                           (model.mass, free_nodes), h, 0.3, base_3d, start_damping)
    ends_sorted = x_start[plan.sj] - x_start[plan.si]
    np.testing.assert_allclose(start_damping, (plan.take(damping_h)[:, None] * ends_sorted).T,
                               rtol=1e-12, atol=1e-15)
    got = np.zeros_like(x)
    kernels.pd_local_rhs_3d(x, plan.si, plan.sj, plan.take(weight), start_damping, base_3d,
                            known_index, known, scratch, got)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(got[known_index], known[known_index])


def test_forces_are_minus_energy_gradient(rng):
    model = random_model(rng, damping=False)
    x = model.rest_positions + 0.05 * rng.normal(size=model.rest_positions.shape)
    v = np.zeros_like(x)
    state = SpringState(x, v)
    f = model.forces(x, v)
    eps = 1e-6
    for i, a in [(0, 0), (3, 1), (17, 2)]:
        plus, minus = x.copy(), x.copy()
        plus[i, a] += eps
        minus[i, a] -= eps
        grad = (model.energy(SpringState(plus, v))
                - model.energy(SpringState(minus, v))) / (2 * eps)
        assert f[i, a] == pytest.approx(-grad, rel=1e-5, abs=1e-6)
    assert model.energy(state) == pytest.approx(
        model.spring_energy(x) - np.sum(model.mass * (x @ model.gravity)))


def test_model_is_read_only_and_state_is_fresh(rng):
    model = random_model(rng)
    for array in (model.rest_positions, model.springs, model.stiffness, model.mass,
                  model.rest_length, model.inverse_mass):
        with pytest.raises(ValueError):
            array[0] = 0
    a, b = model.state(), model.state()
    a.x[0] += 1
    assert not np.shares_memory(a.x, b.x)
    np.testing.assert_array_equal(b.x, model.rest_positions)
    assert np.all(b.v == 0)


def test_inputs_are_copied():
    x = np.array([[0.0, 0], [1, 0]])
    k = np.array([5.0])
    model = MassSpring(x, [[0, 1]], stiffness=k)
    x[1, 0] = 7
    k[0] = 9
    assert model.rest_positions[1, 0] == 1 and model.stiffness[0] == 5


@pytest.mark.parametrize("kwargs, message", [
    (dict(springs=[[0, 0]]), "to itself"),
    (dict(springs=[[0, 5]]), "must be in"),
    (dict(springs=[[-1, 1]]), "must be in"),
    (dict(springs=[[0, 1, 2]]), "shape"),
    (dict(springs=[[0.5, 1]]), "integer"),
    (dict(stiffness=-1.0), "stiffness must be >= 0"),
    (dict(stiffness=[1.0, 2.0]), "stiffness must be a float or an array of shape (1,)"),
    (dict(damping=np.nan), "damping must be finite"),
    (dict(mass=-1.0), "mass must be >= 0"),
    (dict(mass=0.0), "mass must be > 0"),
    (dict(mass=[1.0, 1, 1]), "shape (2,)"),
    (dict(positions=[[0, 0, 0, 0], [1, 0, 0, 0]]), "(N, 2) or (N, 3)"),
    (dict(positions=[[0, 0], [0, 0]]), "rest length"),
    (dict(gravity=(0, 0, -9.8)), "gravity must have shape (2,)"),
    (dict(velocity_damping=-1), "velocity_damping"),
    (dict(fixed=[3]), "fixed node indices"),
])
def test_invalid_models_raise(kwargs, message):
    args = dict(positions=[[0.0, 0], [1, 0]], springs=[[0, 1]], stiffness=1.0)
    args.update(kwargs)
    error = TypeError if "integer" in message else ValueError
    with pytest.raises(error, match=message.replace("(", r"\(").replace(")", r"\)")):
        MassSpring(args.pop("positions"), args.pop("springs"), **args)


def test_state_shape_checked():
    model = MassSpring([[0.0, 0], [1, 0]], [[0, 1]], stiffness=1.0)
    with pytest.raises(ValueError, match="shape"):
        model.energy(SpringState(np.zeros((3, 2)), np.zeros((3, 2))))


def test_control_forms_and_validation():
    model = MassSpring(np.eye(3), [[0, 1], [1, 2]], stiffness=1.0)
    c = Control(pins={0: (0, 0, 1)}, targets=(np.array([2]), np.array([[1.0, 1, 1]])),
                target_stiffness=5.0, forces={1: [0, 0, -1]})
    r = c.resolved(model)
    assert r.pin_index.tolist() == [0] and r.target_stiffness.tolist() == [5.0]
    with pytest.raises(ValueError, match="out of range"):
        Control(pins={7: (0, 0, 0)}).resolved(model)
    with pytest.raises(ValueError, match="this model is 3D"):
        Control(pins={0: (0, 0)}).resolved(model)
    with pytest.raises(ValueError, match="both pinned and targeted"):
        Control(pins={0: (0, 0, 0)}, targets={0: (0, 0, 0)}, target_stiffness=1)
    with pytest.raises(ValueError, match="no effect"):
        Control(targets={0: (0, 0, 0)})
    with pytest.raises(ValueError, match="not finite"):
        Control(pins={0: (np.nan, 0, 0)})
    with pytest.raises(TypeError, match="dict"):
        Control(pins=[1, 2, 3])
    with pytest.raises(ValueError, match="target_stiffness"):
        Control(targets={0: (0, 0, 0)}, target_stiffness=[1.0, 2.0])
