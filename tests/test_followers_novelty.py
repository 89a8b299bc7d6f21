"""The bank's novelty (``followers.novelty``): an action nobody recorded against another
performance of a recorded one, both by a performer unlike the demonstrations."""
import numpy as np
import pytest

from followers import FollowerBank, time_warp
from followers.novelty import build_novelty, novelty, novelty_trace


def shape(rng, T=80, D=3):
    """A smooth random gesture with its own start pose."""
    steps = rng.normal(size=(T + 10, D))
    kernel = np.ones(10) / 10
    smooth = np.stack([np.convolve(steps[:, d], kernel, "valid") for d in range(D)], axis=1)
    return 1.5 * np.cumsum(smooth, axis=0)[:T] + rng.normal(scale=2.0, size=D)


def performed(rng, gesture, gain):
    """``gesture`` at a tempo of 0.7-1.4x, each channel scaled by 1 +- ``gain`` about its
    mean, with sensor noise."""
    take, _ = time_warp(gesture, rng.uniform(0.7, 1.4), jitter=0.1, rng=rng)
    centre = take.mean(axis=0)
    take = (take - centre) * (1 + gain * rng.uniform(-1, 1, size=take.shape[1])) + centre
    return take + rng.normal(scale=0.1, size=take.shape)


def knownness(bank, take):
    return -bank.follow(take)["novelty"][10:].mean()


def auroc(positive, negative):
    p, n = np.asarray(positive)[:, None], np.asarray(negative)[None, :]
    return float((p > n).mean() + 0.5 * (p == n).mean())


def from_rest(rng, rest):
    """A gesture from the shared ``rest`` pose out and back: 20 frames at rest, a 60-frame
    excursion, 20 at rest."""
    out = shape(rng, 60, rest.size)
    out = out - out[0] + rest
    out = out - np.linspace(0, 1, 60)[:, None] * (out[-1] - rest)
    still = np.repeat(rest[None], 20, axis=0)
    return np.vstack([still, out, still])


def test_an_unrecorded_gesture_is_novel_and_a_known_one_by_another_performer_is_not(seed):
    """Four gestures, five takes each (the demonstrations vary by +-10 % per channel); the
    performances vary by +-30 %, fitting their follower worse than the demonstrations did.
    Over 12 unrecorded gestures and 12 performances of known ones the novelty separates them
    (measured over seeds 0-19: AUROC 0.95-1.0)."""
    rng = np.random.default_rng(seed)
    gestures = [shape(rng) for _ in range(4)]
    bank = FollowerBank({f"g{k}": [performed(rng, g, 0.1) for _ in range(5)]
                         for k, g in enumerate(gestures)})
    known = [performed(rng, gestures[k % 4], 0.3) for k in range(12)]
    unknown = [performed(rng, shape(rng), 0.3) for _ in range(12)]
    assert auroc([knownness(bank, x) for x in known],
                 [knownness(bank, x) for x in unknown]) >= 0.9


def test_a_sway_at_the_shared_rest_pose_is_novel_though_every_action_fits_it(seed):
    """Three gestures from one rest pose and back. A performer swaying at the rest pose is
    explained well by every action's rest stretch: the best action's fit takes it for more
    known than other performances of the gestures (measured over seeds 0-19: AUROC 0.01-0.29,
    median 0.10), while the fit of every action at once is unlike any action's own takes
    (the novelty's AUROC 0.90-1.0, median 1.0)."""
    rng = np.random.default_rng(seed)
    rest = rng.normal(scale=2.0, size=3)
    gestures = [from_rest(rng, rest) for _ in range(3)]
    bank = FollowerBank({f"g{k}": [performed(rng, g, 0.1) for _ in range(5)]
                         for k, g in enumerate(gestures)})
    known = [performed(rng, gestures[k % 3], 0.3) for k in range(12)]
    frames = np.linspace(0, 6, 100)[:, None]
    sways = [rest + 0.2 * np.sin(frames) * rng.normal(size=3)
             + rng.normal(scale=0.1, size=(100, 3)) for _ in range(12)]
    assert auroc([knownness(bank, x) for x in known],
                 [knownness(bank, x) for x in sways]) >= 0.85


def test_the_step_by_step_novelty_is_the_traced_one(rng):
    takes = {f"g{k}": [shape(rng) for _ in range(2)] for k in range(3)}
    bank = FollowerBank(takes)
    X = takes["g1"][0]
    traced = bank.follow(X)["novelty"]
    bank.reset()
    assert np.isnan(bank.novelty)
    stepped = []
    for x in X:
        bank.step(x)
        stepped.append(bank.novelty)
    np.testing.assert_allclose(stepped, traced, rtol=1e-9)
    assert (traced >= 0).all()


def test_the_profile_is_the_takes_mean_and_the_scale_their_pooled_spread():
    a = [np.array([[1.0, 0.0], [3.0, 0.0]]), np.array([[3.0, 2.0]])]  # take means (2,0), (3,2)
    b = [np.array([[0.0, 1.0]]), np.array([[0.0, 3.0]])]
    model = build_novelty([a, b])
    np.testing.assert_allclose(model.profiles, [[2.5, 1.0], [0.0, 2.0]])
    # deviations: action a (-0.5, -1), (0.5, 1); action b (0, -1), (0, 1): 4.5 over 2 dof x 2
    assert model.scale == pytest.approx(np.sqrt(4.5 / 4.0))
    assert novelty(model, np.array([0.0, 2.0])) == 0.0
    np.testing.assert_allclose(novelty_trace(model, np.array([[0.0, 2.0], [5.0, 2.0]])),
                               [0.0, ((2.5 - 2.5) ** 2 + 1.0) / 2 / model.scale ** 2])


def test_one_take_per_action_leaves_the_novelty_undefined(rng):
    bank = FollowerBank({f"g{k}": shape(rng) for k in range(2)})
    assert np.isnan(bank.follow(shape(rng))["novelty"]).all()
