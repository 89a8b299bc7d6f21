"""Several takes of one action: their average, their spread, the outlier, and followers and
banks built from them (synthetic takes whose truth is known)."""
import numpy as np
import pytest

from followers import Follower, FollowerBank, combine, default_sigma, resample, time_warp
from followers.demos import _align, average, is_takes


def curve(T=120, D=2):
    """A smooth two-channel gesture: a rise, a swing and a return."""
    t = np.linspace(0.0, 1.0, T)
    return np.stack([np.sin(2 * np.pi * t) + 2 * t, np.cos(3 * np.pi * t) * (1 - t)], axis=1)[:, :D]


def warped_takes(rng, count=5, noise=0.02, speeds=(0.8, 0.9, 1.0, 1.1, 1.25), jitter=0.1):
    shape = curve()
    takes = []
    for k in range(count):
        take, _ = time_warp(shape, speeds[k % len(speeds)], jitter=jitter, rng=rng)
        takes.append(take + rng.normal(scale=noise, size=take.shape))
    return shape, takes


def off_shape(shape, values):
    """Root mean square distance of ``values`` from ``shape`` once aligned to it in time (each
    frame of the shape against the mean of the frames aligned to it)."""
    span = _align(shape, values, np.ones(shape.shape[1]))
    aligned = np.stack([values[a:b + 1].mean(axis=0) for a, b in span])
    return float(np.sqrt(np.mean((aligned - shape) ** 2)))


def test_average_of_warped_takes_recovers_their_shape(rng):
    """Five takes of one shape at 0.8-1.25x, the tempo wandering by 40 %: their aligned
    average keeps the shape (within a few hundredths of its spread, timing aside), clearly
    closer than the takes stretched to one length and averaged, whose swings blur."""
    shape, takes = warped_takes(rng, jitter=0.4)
    d = combine(takes)
    assert d.template.shape == (int(np.median([len(t) for t in takes])), 2)
    ours = off_shape(shape, d.template)
    plain = off_shape(shape, np.mean([resample(t, len(shape)) for t in takes], axis=0))
    assert ours < 0.05 * shape.std()
    assert ours * 1.2 < plain, (ours, plain)


def test_spread_is_how_far_takes_stray_where_they_stray(rng):
    """Eight takes of one shape whose second channel holds still over the last third, each
    holding it at its own level (offsets of standard deviation 0.3), plus noise 0.02: the
    spread is several times the noise there and near the noise before it. It is what a
    follower sees, less than the offsets' 0.3: the follower places a take's held frames
    where the template comes closest to them."""
    shape = curve()
    shape[80:, 1] = shape[80, 1]
    takes = []
    offsets = np.array([-1.5, -1.0, -0.5, -0.2, 0.2, 0.5, 1.0, 1.5])
    for offset in 0.3 * offsets / offsets.std(ddof=1):
        take = shape + rng.normal(scale=0.02, size=shape.shape)
        take[80:, 1] += offset
        takes.append(take)
    d = combine(takes)
    late = np.median(d.spread[88:, 1])
    early = np.median(d.spread[:70])
    assert 0.15 < late < 0.4, late
    assert early < 0.06, early


def test_the_take_that_strays_is_named(rng):
    _, takes = warped_takes(rng)
    assert combine(takes).outlier() is None
    odd = takes[3].copy()
    odd[:, 0] *= -1.0  # the same timing, the first channel upside down
    takes[3] = odd
    d = combine(takes)
    assert d.outlier() == 3
    assert np.argmax(d.distances) == 3
    assert combine(takes[:2]).outlier() is None  # two takes: no majority to stray from


def test_one_take_is_its_own_template(rng):
    take = curve() + rng.normal(scale=0.01, size=(120, 2))
    d = combine(take)
    np.testing.assert_array_equal(d.template, take)
    assert not d.spread.any() and d.count == 1
    np.testing.assert_array_equal(combine([take]).template, take)


def test_takes_are_lists_of_arrays_and_nothing_else():
    assert is_takes([np.zeros((3, 1)), np.zeros((4, 1))])
    assert not is_takes(np.zeros((3, 1)))
    assert not is_takes([[0.0, 1.0], [2.0, 3.0]])  # nested numbers: one take
    assert not is_takes([])


def test_bad_takes_are_named():
    good = curve()
    with pytest.raises(ValueError, match="takes of template 'long' are too long to align"):
        FollowerBank({"long": [np.zeros((8000, 1)), np.zeros((7500, 1))]})
    with pytest.raises(ValueError, match="template 'wave', take 1 has non-finite"):
        FollowerBank({"wave": [good, np.where(np.arange(120)[:, None] == 5, np.nan, good)]})
    with pytest.raises(ValueError, match="every take of template 'wave' needs the same channels"):
        FollowerBank({"wave": [good, good[:, :1]]})


def test_bank_of_several_takes_has_one_template_per_action(rng):
    """Two actions of five takes each and one of a single take: three followers; the averaged
    action's sigma is wider where its takes differ; new takes of each are recognised."""
    _, wave = warped_takes(rng)
    other = [np.stack([c[:, 1], -c[:, 0]], axis=1) for c in warped_takes(rng)[1]]
    still = np.full((60, 2), 0.5) + rng.normal(scale=0.01, size=(60, 2))
    bank = FollowerBank({"wave": wave[:4], "turn": other[:4], "rest": still})
    assert bank.actions == ("wave", "turn", "rest") and len(bank.lengths) == 3
    np.testing.assert_allclose(bank.template("wave"), combine(wave[:4]).template)
    assert bank.demonstrations("rest").count == 1
    sigma = bank.sigma("wave")
    assert sigma.max() > sigma.min()  # widened by the spread, state by state
    for name, take in (("wave", wave[4]), ("turn", other[4])):
        assert bank.actions[bank.follow(take)["action"][-1]] == name


def test_a_list_of_one_take_is_that_take(rng):
    take = curve() + rng.normal(scale=0.01, size=(120, 2))
    other = curve()[::-1] + rng.normal(scale=0.01, size=(120, 2))
    performance, _ = time_warp(take, 1.3)
    one = FollowerBank({"a": take, "b": other}).follow(performance)
    listed = FollowerBank({"a": [take], "b": [other]}).follow(performance)
    for key in one:
        np.testing.assert_array_equal(one[key], listed[key])


def test_follower_from_several_takes(rng):
    """A follower of five takes whose middle swing differs in size from take to take (0.5 to
    1.5 times) follows a sixth; its sigma is the default widened by the takes' spread, most
    where they differ."""
    shape = curve()
    takes = []
    for gain in (0.5, 0.75, 1.0, 1.25, 1.5, 1.1):
        take = shape.copy()
        take[40:80, 0] = shape[40, 0] + gain * (shape[40:80, 0] - shape[40, 0])
        take, _ = time_warp(take, rng.uniform(0.8, 1.25), jitter=0.1, rng=rng)
        takes.append(take + rng.normal(scale=0.02, size=take.shape))
    f = Follower(takes[:5])
    d = f.demonstrations
    assert d.count == 5 and f.length == len(d.template)
    base = default_sigma(d.template, pooled=takes[:5])
    np.testing.assert_allclose(f.sigma, np.sqrt(base ** 2 + f.config.spread_weight
                                                * d.spread ** 2))
    middle = slice(int(0.4 * f.length), int(0.6 * f.length))
    assert f.sigma[middle, 0].max() > 1.08 * np.median(f.sigma[:int(0.2 * f.length), 0])
    trace = f.follow(takes[5])
    assert trace.progress[-1] > 0.95
    assert np.all(np.diff(trace.progress) > -0.05)


def test_average_is_deterministic_and_keeps_the_median_length(rng):
    _, takes = warped_takes(rng)
    weight = np.ones(2)
    first = average(takes, weight)
    np.testing.assert_array_equal(first, average(takes, weight))
    assert len(first) == sorted(len(t) for t in takes)[2]
