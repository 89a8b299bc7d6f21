"""Motion clips: sampling against hand-computed values, files round-trip, validation, blend."""
import json

import numpy as np
import pytest

from characters import Motion, blend


def clip(interpolation="linear"):
    return Motion({
        "hand": ([0.0, 1.0, 3.0], [[0, 0, 0], [1, 2, 0], [1, 2, 4]]),
        "jaw": ([0.5, 2.0], [0.0, 1.0]),
    }, interpolation=interpolation)


def test_description():
    m = clip()
    assert m.duration == 3.0
    assert m.channel_names == ["hand", "jaw"]
    assert m.channel_size("hand") == 3 and m.channel_size("jaw") == 1
    with pytest.raises(KeyError, match="no channel 'nose'"):
        m.channel_size("nose")


def test_linear_sampling_and_clamping():
    m = clip()
    s = m.sample(0.5)
    np.testing.assert_allclose(s["hand"], [0.5, 1.0, 0.0])
    np.testing.assert_allclose(s["jaw"], [0.0])
    np.testing.assert_allclose(m.sample(2.0)["hand"], [1, 2, 2])
    np.testing.assert_allclose(m.sample(1.25)["jaw"], [0.5])
    np.testing.assert_allclose(m.sample(-5)["hand"], [0, 0, 0])       # clamped to 0
    np.testing.assert_allclose(m.sample(99)["hand"], [1, 2, 4])       # clamped to duration
    np.testing.assert_allclose(m.sample(2.7)["jaw"], [1.0])           # held after last key
    assert m.sample(1.0)["hand"].shape == (3,)
    with pytest.raises(ValueError, match="NaN"):
        m.sample(float("nan"))


def test_sample_returns_copies():
    m = clip()
    s = m.sample(0.0)
    s["hand"][0] = 99
    assert m.sample(0.0)["hand"][0] == 0


def test_step_and_cubic():
    m = clip("step")
    np.testing.assert_allclose(m.sample(0.99)["hand"], [0, 0, 0])
    np.testing.assert_allclose(m.sample(1.0)["hand"], [1, 2, 0])
    # Catmull-Rom passes through keys and reproduces a linear function exactly
    t = np.array([0.0, 0.3, 1.0, 1.1, 2.5])
    line = Motion({"x": (t, 2 * t + 1)}, interpolation="cubic")
    for time in np.linspace(0, 2.5, 23):
        assert line.sample(time)["x"][0] == pytest.approx(2 * time + 1)
    smooth = Motion({"x": (np.arange(5.0), [0, 1, 0, 1, 0])}, interpolation="cubic")
    assert smooth.sample(2.0)["x"][0] == pytest.approx(0)
    assert smooth.sample(1.5)["x"][0] == pytest.approx(0.5)  # symmetric between 1 and 0
    with pytest.raises(ValueError, match="interpolation must be one of"):
        Motion({"x": ([0], [0])}, interpolation="spline")


def test_sample_many_matches_sample():
    m = clip("cubic")
    ts = np.linspace(-1, 4, 17)
    many = m.sample_many(ts)
    for k, t in enumerate(ts):
        for name, value in m.sample(t).items():
            np.testing.assert_allclose(many[name][k], value)


def test_round_trip(tmp_path):
    m = clip("cubic")
    path = tmp_path / "wave.json"
    m.save(path)
    back = Motion.load(path)
    assert back == m
    assert back.interpolation.value == "cubic"
    assert Motion.from_dict(json.loads(json.dumps(m.to_dict()))) == m
    with pytest.raises(ValueError, match=".json"):
        m.save(tmp_path / "wave.pkl")


@pytest.mark.parametrize("channels, message", [
    ({"arm": ([0, 1, 1], [0, 1, 2])}, "channel 'arm': times must be strictly increasing"),
    ({"arm": ([0, 2, 1], [0, 1, 2])}, "channel 'arm': times must be strictly increasing"),
    ({"arm": ([0, 1], [0, np.nan])}, "channel 'arm': values contain NaN"),
    ({"arm": ([0, np.nan], [0, 1])}, "channel 'arm': times contain NaN"),
    ({"arm": ([0, 1], [[0, 1], [0, 1, 2]])}, "channel 'arm'.*ragged"),
    ({"arm": ([0, 1, 2], [[0, 1], [0, 1]])}, r"channel 'arm': values must have shape \(3, c\)"),
    ({"arm": ([], [])}, "channel 'arm': times must be a non-empty"),
    ({"arm": ([-1, 0], [0, 1])}, "channel 'arm': times must start at >= 0"),
    ({"arm": [0, 1]}, "channel 'arm': times must be a non-empty 1-D"),
    ({"arm": ([0, 1],)}, "channel 'arm': expected a pair"),
])
def test_validation(channels, message):
    with pytest.raises(ValueError, match=message):
        Motion(channels)


def test_load_errors_name_the_file(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"channels": {"leg": {"times": [0, 0], "values": [1, 2]}}}))
    with pytest.raises(ValueError, match="bad.json.*channel 'leg'"):
        Motion.load(path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        Motion.load(path)
    with pytest.raises(ValueError, match="format"):
        Motion.from_dict({"format": "something.else", "channels": {}})


def test_blend():
    a = {"hand": np.array([0.0, 0, 0]), "jaw": np.array([1.0])}
    b = {"hand": np.array([2.0, 4, 6]), "eye": np.array([3.0])}
    mixed = blend(a, b, 0.25)
    np.testing.assert_allclose(mixed["hand"], [0.5, 1, 1.5])
    np.testing.assert_allclose(mixed["jaw"], [1.0])
    np.testing.assert_allclose(mixed["eye"], [3.0])
    np.testing.assert_allclose(blend(a, b, 0)["hand"], a["hand"])
    np.testing.assert_allclose(blend(a, b, 1)["hand"], b["hand"])
    with pytest.raises(ValueError, match="in \\[0, 1\\]"):
        blend(a, b, 1.5)
    with pytest.raises(ValueError, match="'hand' has shape"):
        blend(a, {"hand": np.zeros(2)}, 0.5)


@pytest.mark.parametrize("interpolation", ["linear", "cubic", "step"])
def test_vectorised_sample_matches_scalar_reference(rng, interpolation):
    channels = {}
    for c in range(25):
        keys = int(rng.integers(1, 9))
        times = np.sort(rng.choice(np.linspace(0, 4, 400), keys, replace=False))
        channels[f"ch{c}"] = (times, rng.normal(size=(keys, int(rng.integers(1, 4)))))
    m = Motion(channels, interpolation=interpolation)
    for t in np.r_[rng.uniform(-1, 5, 60), 0.0, m.duration, [k[0] for k, _ in channels.values()]]:
        fast = m.sample(t)
        slow = {name: v[0] for name, v in m.sample_many([t]).items()}
        assert list(fast) == list(channels)
        for name in channels:
            np.testing.assert_allclose(fast[name], slow[name], rtol=1e-12, atol=1e-12)
            assert fast[name].shape == (m.channel_size(name),)
