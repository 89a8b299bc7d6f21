"""Frames, resampling kernels (against a slow reference), streaming resampling, replay of stored
takes (deterministic, real time, looped), and source specs."""
import math
import time

import numpy as np
import pytest

from capture import Frame, Resampled, Source, Status, open_source
from capture.resample import align_durations, interpolate, regular_grid, resample
from capture.spec import parse_options, split_spec
from capture.store import StoreWriter


def test_frame_is_read_only_and_checked():
    values = np.array([1.0, 2.0])
    frame = Frame(1, values)
    assert frame.t == 1.0 and type(frame.t) is float
    with pytest.raises(ValueError):
        frame.values[0] = 5.0
    values[0] = 7.0                       # the caller's array is not frozen by the frame
    with pytest.raises(ValueError, match=r"1-D array \(D,\), got shape \(2, 2\)"):
        Frame(0.0, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="finite time"):
        Frame(float("nan"), [1.0])


def interpolate_reference(times, values, grid):
    """Point by point, straight from the rule in capture.resample's docstring."""
    out = np.empty((len(grid), values.shape[1]))
    for k, t in enumerate(grid):
        if t <= times[0]:
            out[k] = values[0]
            continue
        if t >= times[-1]:
            out[k] = values[-1]
            continue
        i = max(j for j in range(len(times) - 1) if times[j] <= t)
        t0, t1 = times[i], times[i + 1]
        w = 1.0 if t1 == t0 else (t - t0) / (t1 - t0)
        for d in range(values.shape[1]):
            a, b = values[i, d], values[i + 1, d]
            if math.isnan(a) or math.isnan(b):
                out[k, d] = a if w < 0.5 else b
            else:
                out[k, d] = a * (1 - w) + b * w
    return out


def test_interpolate_matches_reference_with_gaps_and_duplicates(rng):
    times = np.sort(rng.uniform(0, 5, 60))
    times[10] = times[11]                               # a duplicate timestamp
    values = rng.normal(size=(60, 3))
    values[rng.random((60, 3)) < 0.15] = np.nan
    grid = np.linspace(-0.5, 5.5, 301)
    np.testing.assert_allclose(interpolate(times, values, grid),
                               interpolate_reference(times, values, grid), rtol=0, atol=1e-12)


def test_resample_grid_and_errors():
    grid = regular_grid(0.0, 1.0, 50.0)
    assert grid.size == 51 and grid[-1] == pytest.approx(1.0)
    times = np.array([0.0, 0.5, 1.0])
    grid, values = resample(times, np.c_[times * 2], 4.0)
    np.testing.assert_allclose(values.ravel(), grid * 2)
    with pytest.raises(ValueError, match="values must be \\(N, D\\) with N = 3"):
        interpolate(times, np.zeros((2, 1)), grid)
    with pytest.raises(ValueError, match="non-decreasing"):
        interpolate(times[::-1], np.zeros((3, 1)), grid)
    with pytest.raises(ValueError, match="rate must be > 0"):
        regular_grid(0, 1, 0)


def test_align_durations_maps_the_action_interval_onto_the_motion():
    # the performer took 3 s (from 1 s to 4 s) for a 2 s motion: x(t) = t on the action clock
    times = np.linspace(0.0, 5.0, 501)
    values = np.c_[times, times ** 2]
    grid, aligned = align_durations(times, values, start=1.0, end=4.0, duration=2.0, rate=10.0)
    assert grid.size == 21 and grid[-1] == pytest.approx(2.0)
    expected_time = 1.0 + grid * 1.5
    np.testing.assert_allclose(aligned[:, 0], expected_time, atol=1e-12)
    np.testing.assert_allclose(aligned[:, 1], expected_time ** 2, atol=1e-4)
    with pytest.raises(ValueError, match="end > start"):
        align_durations(times, values, start=2.0, end=2.0, duration=1.0, rate=10.0)


def write_take(path, times, values, channels=("a", "b"), rate=100.0):
    with StoreWriter(path) as writer:
        writer.add_stream("action", channels, rate=rate)
        writer.append_many("action", times, values)
    return path


def test_replay_as_fast_as_possible_is_exact_and_deterministic(tmp_path, rng):
    times = 12.0 + np.cumsum(rng.uniform(0.005, 0.015, 300))
    values = rng.normal(size=(300, 2))
    values[5, 1] = np.nan
    write_take(tmp_path / "take.sqlite", times, values)
    runs = []
    for _ in range(2):
        with open_source(f"replay:{tmp_path / 'take'}?realtime=false") as source:
            runs.append(list(source))
            assert source.ended and source.status is Status.DISCONNECTED
    first, second = runs
    assert [f.t for f in first] == [f.t for f in second]
    np.testing.assert_array_equal([f.t for f in first], times - times[0])
    np.testing.assert_array_equal(np.array([f.values for f in first]), values)
    np.testing.assert_array_equal(np.array([f.values for f in second]), values)
    assert [f.seq for f in first] == list(range(300))


def test_replay_in_real_time_keeps_the_recorded_timing(tmp_path):
    times = np.arange(31) * 0.01
    write_take(tmp_path / "take.sqlite", times, np.c_[times, -times])
    for speed in (1.0, 2.0):
        started = time.monotonic()
        with open_source(f"replay:{tmp_path / 'take'}", speed=speed) as source:
            frames = list(source)
        elapsed = time.monotonic() - started
        stamps = np.array([f.t for f in frames])
        np.testing.assert_allclose(stamps - stamps[0], times / speed, atol=1e-9)
        assert elapsed >= 0.3 / speed - 0.01
        assert stamps[0] >= started                     # on the same monotonic clock


def test_replay_loops(tmp_path):
    times = np.array([0.0, 0.1, 0.2])
    write_take(tmp_path / "take.sqlite", times, np.c_[times, times])
    with open_source(f"replay:{tmp_path / 'take'}?realtime=false&loop=true") as source:
        frames = [source.read(timeout=1) for _ in range(7)]
    np.testing.assert_allclose([f.t for f in frames], [0, .1, .2, .3, .4, .5, .6], atol=1e-12)
    np.testing.assert_array_equal([f.values[0] for f in frames], [0, .1, .2, 0, .1, .2, 0])


def test_replay_errors_name_what_exists(tmp_path):
    write_take(tmp_path / "wave.sqlite", np.array([0.0, 1.0]), np.zeros((2, 2)))
    with pytest.raises(FileNotFoundError, match="no take 'nod'.*takes there: wave"):
        open_source(f"replay:{tmp_path / 'nod'}")
    with pytest.raises(ValueError, match="has no stream 'glove'; it has action"):
        open_source(f"replay:{tmp_path / 'wave'}?stream=glove")


def test_streaming_linear_resampling_equals_the_batch_kernel(tmp_path, rng):
    times = np.cumsum(rng.uniform(0.002, 0.03, 200))
    values = rng.normal(size=(200, 2))
    write_take(tmp_path / "take.sqlite", times, values)
    with open_source(f"replay:{tmp_path / 'take'}?realtime=false&rate=50") as source:
        assert isinstance(source, Resampled)
        frames = list(source)
    relative = times - times[0]
    grid = regular_grid(0.0, relative[-1], 50.0)
    np.testing.assert_allclose([f.t for f in frames], grid, atol=1e-9)
    np.testing.assert_allclose(np.array([f.values for f in frames]),
                               interpolate(relative, values, grid), atol=1e-12)
    assert [f.seq for f in frames] == list(range(len(grid)))


class SteppedClock:
    """A clock that moves only when someone sleeps on it: `sleep_until` jumps to the deadline."""

    def __init__(self):
        self.t = 0.0

    def now(self):
        return self.t

    def sleep_until(self, deadline, stop=None):
        self.t = max(self.t, deadline)
        return True


class Scripted(Source):
    """Stored frames, each readable once the clock has reached its time; silent after the last."""

    kind = "scripted"
    stall_timeout = 0.1

    def __init__(self, times, values, clock):
        super().__init__(("a",), 100.0, clock=clock)
        self.frames = [Frame(t, [v]) for t, v in zip(times, values)]

    @property
    def status(self):
        return Status.OK

    def read(self, timeout=None):
        if self.frames and self.frames[0].t <= self.clock.now():
            return self.frames.pop(0)
        return None


def test_hold_resampling_holds_the_newest_raw_value_at_each_grid_time():
    clock = SteppedClock()
    times = np.arange(50) / 100.0                      # 100 Hz for 0.5 s, then silence
    source = Resampled(Scripted(times, times, clock), 20.0, method="hold")
    frames = [source.read(timeout=1.0) for _ in range(14)]
    stamps = np.array([f.t for f in frames])
    np.testing.assert_allclose(stamps, np.arange(14) * 0.05, atol=1e-12)
    held = np.array([f.values[0] for f in frames])
    newest = [times[times <= t + 1e-12].max() for t in stamps]
    np.testing.assert_array_equal(held[:12], newest[:12])
    # 0.1 s stall timeout after the last raw frame at 0.49 s: NaN from 0.60 s on
    assert np.all(np.isnan(held[12:])) and not np.isnan(held[:12]).any()
    # a reader 0.2 s late skips the grid points it missed instead of bursting them out
    clock.t += 0.2
    late = source.read(timeout=1.0)
    assert late.t == pytest.approx(0.85) and source.stats.dropped == 3   # 0.70, 0.75, 0.80


def test_hold_resampling_of_a_replay_is_paced_by_the_clock(tmp_path):
    times = np.arange(100) * 0.01                      # 100 Hz for 1 s
    write_take(tmp_path / "take.sqlite", times, np.c_[times, times])
    with open_source(f"replay:{tmp_path / 'take'}", rate=20, resample="hold") as source:
        frames, returned = [], []
        for _ in range(10):
            frames.append(source.read(timeout=1.0))
            returned.append(time.monotonic())          # the capture clock is CLOCK_MONOTONIC
    stamps = np.array([f.t for f in frames])
    steps = np.diff(stamps) / 0.05                     # grid points, whole ones (late reads skip)
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    assert np.all(np.round(steps) >= 1)
    assert np.all(np.array(returned) >= stamps)        # paced: no frame before its time
    held = np.array([f.values[0] for f in frames])
    assert np.all(np.diff(held) >= 0) and held[-1] > held[0]


@pytest.mark.parametrize("spec, message", [
    ("glove:1", "expected KIND:..., KIND one of hid, camera, osc, replay"),
    ("hid:", "name a HID profile"),
    ("hid:p5@nonsense", "expected a /dev/hidrawN path or VID:PID"),
    ("hid:generic", "say which, e.g. hid:generic@/dev/hidraw0"),
    ("hid:p5?stall_timeout", "expected key=value"),
    ("camera::aruco", "name a camera index or a video file"),
    ("replay:", "name a take"),
])
def test_bad_specs_say_what_was_expected(spec, message):
    with pytest.raises(ValueError, match=message):
        open_source(spec)


@pytest.mark.slow
def test_a_missing_hid_device_is_an_oserror_naming_the_profile():
    with pytest.raises(OSError, match=r"no HID device fits profile 'p5' \(looking for "
                                      r"1209:0001\)"):
        open_source("hid:p5")


def test_spec_options_are_typed():
    assert split_spec("camera:0:aruco?ids=1,2&marker_length=0.04&realtime=false") == (
        "camera", "0:aruco", {"ids": [1, 2], "marker_length": 0.04, "realtime": False})
    assert parse_options("name=wave&speed=2") == {"name": "wave", "speed": 2}
    with pytest.raises(TypeError, match="a source spec is a string"):
        open_source(42)
