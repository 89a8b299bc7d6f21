"""Performer calibration: a calibration take's rest and range, and the map from one performer's
input onto the author's (followers.calibration), on real recordings (BasicMotions)."""
import numpy as np
import pytest

from followers.calibration import (GAIN_LIMITS, Calibration, ChannelMap, calibrate, measure)


@pytest.fixture(scope="module")
def motions():
    from followers import aeon_dataset
    X, y = aeon_dataset("BasicMotions", "TRAIN")     # read from the wheel, aeon not imported
    return X, y.astype(str)


def calibration_values(takes, rate=10.0, rest_seconds=2.0):
    """A calibration take from real takes: their median first frame held, then the takes."""
    rest = np.median([t[0] for t in takes], axis=0)
    return np.vstack([np.repeat(rest[None], int(rest_seconds * rate) + 1, axis=0), *takes])


def test_an_affine_performer_is_mapped_back_exactly(motions):
    X, y = motions
    takes = [X[np.flatnonzero(y == c)[0]] for c in sorted(set(y))]
    author = calibration_values(takes)
    gain = np.array([0.7, 1.3, 1.0, 2.0, 0.5, 1.15])
    offset = np.array([0.5, -2.0, 0.0, 1.0, 3.0, -0.1])
    performer = author * gain + offset
    mapped = calibrate(measure(performer, rate=10.0), measure(author, rate=10.0))
    assert not mapped.notes
    np.testing.assert_allclose(mapped.gain, 1 / gain, rtol=1e-9)
    np.testing.assert_allclose(mapped(performer), author, atol=1e-9)
    # folded into a normalisation: the same numbers with no per-frame work
    shift, scale = np.arange(6.0), np.linspace(1.0, 2.0, 6)
    folded_shift, folded_scale = mapped.fold(shift, scale)
    np.testing.assert_allclose((performer - folded_shift) / folded_scale,
                               (author - shift) / scale, atol=1e-9)


def test_rest_and_range_come_from_the_parts_of_the_take():
    rate = 20.0
    rest = np.full((int(2 * rate), 2), [0.2, -1.0])
    sweep = np.stack([np.linspace(-1, 3, 200), np.linspace(5, 9, 200)], axis=1)
    values = np.vstack([rest, sweep])
    values[50, 0] = np.nan                        # a missing value is left out
    measured = measure(values, rate=rate, channels=("a", "b"))
    np.testing.assert_allclose(measured.rest, [0.2, -1.0])
    # the 2nd and 98th percentiles of every frame, rest included
    finite = values[np.isfinite(values[:, 0]), 0]
    assert measured.low[0] == pytest.approx(np.percentile(finite, 2))
    assert measured.high[1] == pytest.approx(np.percentile(values[:, 1], 98))
    assert measured.as_dict()["channels"] == ["a", "b"]


def test_a_channel_that_did_not_move_or_differs_absurdly_keeps_gain_one():
    author = Calibration(np.zeros(3), np.array([-1.0, -1.0, 0.0]), np.array([1.0, 1.0, 0.0]),
                         ("a", "b", "c"))
    performer = Calibration(np.ones(3), np.array([-100.0, -2.0, 0.0]),
                            np.array([100.0, 2.0, 1.0]), ("a", "b", "c"))
    mapped = calibrate(performer, author)
    np.testing.assert_allclose(mapped.gain, [1.0, 0.5, 1.0])
    np.testing.assert_allclose(mapped(performer.rest), author.rest)   # rests always meet
    assert len(mapped.notes) == 2
    assert mapped.notes[0].startswith("a: ranges differ") and f"{GAIN_LIMITS[1]:g}x" in \
        mapped.notes[0]
    assert mapped.notes[1].startswith("c: did not move")


def test_bad_calibration_takes_are_refused_naming_the_problem():
    with pytest.raises(ValueError, match="at least 3 frames"):
        measure(np.zeros((2, 1)), rate=10.0)
    with pytest.raises(ValueError, match="times or a rate"):
        measure(np.zeros((10, 1)))
    values = np.zeros((40, 2))
    values[:, 1] = np.nan
    with pytest.raises(ValueError, match="fewer than 3 values of 'wrist'"):
        measure(values, rate=10.0, channels=("thumb", "wrist"))
    values = np.zeros((40, 1))
    values[:30] = np.nan                          # nothing in the rest part
    with pytest.raises(ValueError, match="first 2 s .the rest pose."):
        measure(values, rate=10.0)
    one = Calibration(np.zeros(1), np.zeros(1), np.ones(1), ("a",))
    with pytest.raises(ValueError, match="different channels: b against a"):
        calibrate(Calibration(np.zeros(1), np.zeros(1), np.ones(1), ("b",)), one)
    with pytest.raises(ValueError, match="1 and 2 channels"):
        calibrate(one, Calibration(np.zeros(2), np.zeros(2), np.ones(2)))
    with pytest.raises(ValueError, match=r"must be \(\.\.\., 1\), one value a channel, "
                                         r"got shape \(3, 2\)"):
        ChannelMap(np.ones(1), np.zeros(1))(np.zeros((3, 2)))
