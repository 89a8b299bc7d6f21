"""The session loop's parts: blending, channel selection, feeds, stage composition."""
import math

import numpy as np
import pytest

from characters import Motion
from mop.render.compose import Stage, blend_over
from mop.session.feeds import ENDED, FAILED, OK, SILENT, SourceFeed, TakeFeed
from mop.session.loop import FollowState, PerformerRuntime, Track, smoothstep


def ramp(name, start, end, duration=2.0):
    return Motion({name: ([0.0, duration], [[start], [end]])})


def test_smoothstep_ends_and_middle():
    assert smoothstep(-1) == 0 and smoothstep(0) == 0 and smoothstep(1) == 1 and smoothstep(3) == 1
    assert smoothstep(0.5) == pytest.approx(0.5)
    assert smoothstep(0.25) == pytest.approx(0.25 ** 2 * (3 - 0.5))


def test_track_cross_fades_between_actions_then_plays_the_new_one():
    a, b = ramp("bend", 0.0, 1.0), ramp("bend", 10.0, 20.0)
    track = Track("p", {"a": (a, (("bend", "finger"),)), "b": (b, (("bend", "finger"),))},
                  {"finger": [0.0]}, blend=0.4)
    out = {}
    track.update(0.0, FollowState(action="a", progress=0.5), out)
    # from nothing to "a": no previous targets, so the new motion plays at once
    assert out["finger"] == pytest.approx(0.5) and isinstance(out["finger"], float)
    track.update(1.0, FollowState(action="a", progress=0.75), out)
    assert out["finger"] == pytest.approx(0.75)
    # switch to "b" at t = 1.0: the fade starts from what "a" last gave (0.75)
    for t, progress in [(1.0, 0.0), (1.1, 0.1), (1.2, 0.2), (1.3, 0.3), (1.4, 0.4), (1.8, 0.5)]:
        out.clear()
        track.update(t, FollowState(action="b", progress=progress), out)
        goal = 10.0 + 10.0 * progress
        w = smoothstep((t - 1.0) / 0.4)
        assert out["finger"] == pytest.approx((1 - w) * 0.75 + w * goal), t
    assert track.current == "b" and track.weight == 1.0


def test_track_relaxes_to_rest_then_lets_go_and_ignores_foreign_actions():
    a = Motion({"hand": ([0.0, 1.0], [[5.0, 5.0], [9.0, 1.0]])})
    track = Track("p", {"a": (a, (("hand", "paw"),))}, {"paw": [5.0, 5.0]}, blend=0.5)
    out = {}
    track.update(0.0, FollowState(action="a", progress=1.0), out)
    assert out["paw"] == pytest.approx([9.0, 1.0])
    # an action this track does not know (it drives another character) = rest here
    out.clear()
    track.update(0.25, FollowState(action="somebody_else", progress=0.3), out)
    assert out["paw"] == pytest.approx([9.0, 1.0])       # the fade starts where it was
    out.clear()
    track.update(0.5, FollowState(action=None), out)
    w = smoothstep(0.5)
    assert out["paw"] == pytest.approx((1 - w) * np.array([9.0, 1.0]) + w * np.array([5.0, 5.0]))
    out.clear()
    track.update(0.8, FollowState(action=None), out)
    assert out == {}        # fade finished: the target is let go, the puppet relaxes by itself
    assert track.current is None


def test_hold_keeps_the_end_pose_and_a_new_performance_blends_in_from_it():
    a = ramp("bend", 0.0, 1.0)
    track = Track("p", {"a": (a, (("bend", "finger"),))}, {"finger": [0.0]}, blend=0.4,
                  after={"a": "hold"})
    out = {}
    track.update(0.0, FollowState(action="a", progress=0.9), out)
    for t in (0.04, 1.0, 5.0):                  # the performer stopped: the pose stays
        out.clear()
        track.update(t, FollowState(action=None), out)
        assert out["finger"] == pytest.approx(0.9) and track.mode == "hold"
    out.clear()
    track.update(5.2, FollowState(action="a", progress=0.1), out)   # "a" again, from its start
    w = smoothstep(0.0)
    assert track.mode == "active" and out["finger"] == pytest.approx((1 - w) * 0.9 + w * 0.1)
    out.clear()
    track.update(5.4, FollowState(action="a", progress=0.2), out)
    w = smoothstep(0.5)
    assert out["finger"] == pytest.approx((1 - w) * 0.9 + w * 0.2)


def test_loop_plays_on_at_the_motions_own_pace_from_where_it_was():
    a = ramp("bend", 0.0, 1.0, duration=2.0)
    track = Track("p", {"a": (a, (("bend", "finger"),))}, {"finger": [0.0]}, blend=0.4,
                  after={"a": "loop"})
    out = {}
    track.update(0.0, FollowState(action="a", progress=0.5), out)
    for k in range(1, 80):                      # 3.2 s on: 1.6 loops of a 2 s motion
        out.clear()
        track.update(0.04 * k, FollowState(action=None), out)
        expected = (0.5 + 0.04 * k / 2.0) % 1.0
        assert track.mode == "loop" and track.progress == pytest.approx(expected)
        assert out["finger"] == pytest.approx(expected)


def test_zero_blend_cuts_like_mop():
    a, b = ramp("x", 0.0, 1.0), ramp("x", 5.0, 6.0)
    track = Track("p", {"a": (a, (("x", "x"),)), "b": (b, (("x", "x"),))}, {"x": [0.0]},
                  blend=0.0)
    out = {}
    track.update(0.0, FollowState(action="a", progress=1.0), out)
    track.update(0.04, FollowState(action="b", progress=0.0), out)
    assert out["x"] == pytest.approx(5.0)


class ListSource:
    """A source that hands out prepared frames, can be unplugged and re-plugged (fault
    injection for the feed's error handling)."""

    class Frame:
        def __init__(self, t, values):
            self.t, self.values = t, np.asarray(values, float)

    def __init__(self, channels):
        self.channels = tuple(channels)
        self.queue = []
        self.unplugged = False
        self.closed = False

    def read(self, timeout=None):
        if self.unplugged:
            raise OSError("device unplugged")
        return self.queue.pop(0) if self.queue else None

    def close(self):
        self.closed = True


def test_source_feed_silence_failure_and_rejoin():
    now = [0.0]
    plugged = {"ok": True}
    sources = []

    def opener():
        if not plugged["ok"]:
            raise OSError("no such device")
        source = ListSource(("a", "b"))
        sources.append(source)
        return source

    feed = SourceFeed(opener, name="p", stale_after=0.5, retry=1.0, latency=0.05,
                      clock=lambda: now[0])
    assert feed.status == SILENT and feed.channels == ("a", "b")
    sources[0].queue += [ListSource.Frame(0.0, [1, 2]), ListSource.Frame(0.04, [3, 4])]
    now[0] = 0.04
    assert feed.poll(0.0, due=0.04) is None and feed.status == SILENT   # not 50 ms old yet
    now[0] = 0.08
    assert feed.poll(0.0, due=0.08) == pytest.approx([1, 2])   # locked: the first sample
    assert feed.status == OK and feed.latency == pytest.approx(0.08) and feed.frames == 2
    now[0] = 0.10
    assert feed.poll(0.0, due=0.10) == pytest.approx([2, 3])   # the input 80 ms ago
    now[0] = 0.3
    assert feed.poll(0.0, due=0.3) == pytest.approx([3, 4]) and feed.late == 1   # held
    now[0] = 0.6
    assert feed.poll(0.0, due=0.6) is None and feed.status == SILENT and feed.latency is None
    sources[0].unplugged = True
    plugged["ok"] = False
    now[0] = 1.0
    assert feed.poll(1.0, due=1.0) is None and feed.status == FAILED
    assert "unplugged" in feed.message and sources[0].closed
    now[0] = 1.5                                             # before the retry time: no attempt
    assert feed.poll(1.5, due=1.5) is None and len(sources) == 1
    now[0] = 2.1                                             # retry fails: still unplugged
    assert feed.poll(2.1, due=2.1) is None and feed.status == FAILED
    assert "no such device" in feed.message
    plugged["ok"] = True
    now[0] = 3.2
    assert feed.poll(3.2, due=3.2) is None and feed.status == SILENT and len(sources) == 2
    sources[1].queue.append(ListSource.Frame(3.2, [7, 8]))
    now[0] = 3.3
    assert feed.poll(3.3, due=3.3) == pytest.approx([7, 8]) and feed.status == OK
    assert feed.latency == pytest.approx(0.1)                # locked again, to the new input


def test_a_feed_whose_frames_come_in_late_is_late_not_silent():
    """A busy tracker delivers each frame 0.7 s after the moment it stamps: that is more than
    stale_after, yet frames keep coming in, so the performer stays followed (on the newest
    frame) and goes silent only once nothing has come in for stale_after."""
    now = [0.0]
    source = ListSource(("a",))
    feed = SourceFeed(lambda: source, name="p", stale_after=0.5, latency=0.05,
                      clock=lambda: now[0])
    statuses = []
    for k in range(40):                          # 2 s at 20 frames a second
        now[0] = 0.7 + 0.05 * k
        source.queue.append(ListSource.Frame(0.05 * k, [float(k)]))
        values = feed.poll(now[0], due=now[0])
        statuses.append(feed.status)
        if feed.status == OK:
            assert values == pytest.approx([k])          # the newest: later ones are not in
    assert statuses[-30:] == [OK] * 30 and feed.late > 0
    last = now[0]
    now[0] = last + 0.45
    assert feed.poll(now[0], due=now[0]) is not None and feed.status == OK
    now[0] = last + 0.55
    assert feed.poll(now[0], due=now[0]) is None and feed.status == SILENT


def arrivals(rng, times, *, jitter):
    """Arrival stamps of samples sent at `times`: a little late, each by its own amount."""
    return times + rng.uniform(0.0, jitter, times.size)


@pytest.mark.parametrize("rate, before", [(50.0, 0.0), (30.0, 0.0), (200.0, 0.0),
                                          (50.0, 0.7), (30.0, 0.35)])
def test_a_live_feed_gives_the_frames_a_replay_of_the_same_take_gives(rng, rate, before):
    """The input a follower sees live equals what a replay of the same take gives, frame for
    frame: resampled at the frame times from the first sample on, though frames ran late.
    When the input was flowing `before` seconds before the show, from where the show met it."""
    times = np.arange(int(6 * rate)) / rate
    values = np.stack([np.sin(2.3 * times), times ** 2, np.cos(7.0 * times)], axis=1)
    values[37, 1] = np.nan                                       # a missing value
    start = 100.0 + rng.uniform(0, 1)                            # the show starts ...
    origin = start - before + rng.uniform(0.0, 0.5)              # ... and the sender then
    source = ListSource(("a", "b", "c"))
    stamped = arrivals(rng, origin + times, jitter=1e-9)
    now = [start]
    feed = SourceFeed(lambda: source, name="p", latency=0.05, clock=lambda: now[0])
    sent, live, k = 0, [], 0
    while len(live) < 120:
        due = start + k / 25.0
        # a late loop: the frame runs up to 0.3 s after it was due, the input has gone on
        now[0] = due + (0.3 if 40 <= k < 50 else 0.002)
        while sent < times.size and stamped[sent] <= now[0]:
            source.queue.append(ListSource.Frame(stamped[sent], values[sent]))
            sent += 1
        value = feed.poll(k / 25.0, due=due)
        if value is not None:
            live.append(value.copy())
        k += 1
    assert 0.05 <= feed.latency <= 0.05 + 1 / 25.0 + 1e-9 and feed.late == 0
    first = int(np.argmin(np.abs(origin + times - (start + (k - 120) / 25.0 - feed.latency))))
    take = TakeFeed(times[first:], values[first:], ("a", "b", "c"))
    assert before or first == 0
    replayed = [take.poll(k / 25.0).copy() for k in range(120)]
    for frame, (a, b) in enumerate(zip(live, replayed)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6, err_msg=f"frame {frame}")


def test_a_live_feed_ends_with_its_source_and_rebases_foreign_timestamps():
    source = ListSource(("a",))
    source.ended = False
    now = [1000.0]
    feed = SourceFeed(lambda: source, name="p", latency=0.0, clock=lambda: now[0])
    source.queue += [ListSource.Frame(0.0, [1.0])]        # not a capture-clock time
    assert feed.poll(0.0, due=1000.0) == pytest.approx([1.0]) and feed.rebased == 1
    source.queue += [ListSource.Frame(1000.02, [3.0])]
    source.ended = True
    now[0] = 1000.01
    assert feed.poll(0.0, due=1000.01) == pytest.approx([2.0])   # still following what came
    now[0] = 1000.05
    assert feed.poll(0.0, due=1000.05) is None and feed.status == ENDED


def test_take_feed_interpolates_like_numpy_and_ends(rng):
    times = np.cumsum(rng.uniform(0.01, 0.05, 60))
    values = rng.normal(size=(60, 3))
    feed = TakeFeed(times, values, ("x", "y", "z"))
    for t in rng.uniform(0, times[-1] - times[0], 50):
        expected = [np.interp(t, times - times[0], values[:, k]) for k in range(3)]
        assert feed.poll(t) == pytest.approx(expected)
    assert feed.poll(feed.duration + 0.01) is None and feed.status == ENDED
    looping = TakeFeed(times, values, ("x", "y", "z"), loop=True)
    t = 0.3 * looping.duration
    assert looping.poll(t + 2 * looping.duration) == pytest.approx(looping.poll(t).copy())
    with pytest.raises(ValueError, match="increasing"):
        TakeFeed([0.0, 0.0, 1.0], np.zeros((3, 1)), ("x",))


class CountingBank:
    """Records what a performer's bank is fed (the selection and normalisation under test)."""

    def __init__(self):
        self.seen, self.resets = [], 0

    def step(self, x):
        self.seen.append(np.array(x))
        return FollowState(action="a", progress=0.5)

    def reset(self):
        self.resets += 1


def test_performer_selects_channels_by_name_and_normalises():
    source = ListSource(("pinky", "thumb", "x", "index"))
    feed = SourceFeed(lambda: source, name="p", latency=0.0, clock=lambda: 0.0)
    bank = CountingBank()
    performer = PerformerRuntime("p", feed, bank, channels=("thumb", "index"),
                                 shift=[1.0, 2.0], scale=[2.0, 4.0])
    source.queue.append(ListSource.Frame(0, [9.0, 5.0, 0.0, math.nan]))
    performer.values = feed.poll(0.0)
    performer.status = feed.status
    performer.follow()
    assert bank.seen[0][0] == pytest.approx(2.0) and math.isnan(bank.seen[0][1])
    performer.values, performer.status = None, SILENT
    performer.follow()
    assert bank.resets == 1 and performer.state.action is None
    source.channels = ("thumb",)
    feed.channels = ("thumb",)
    performer.values, performer.status = np.array([1.0]), OK
    performer.follow()       # a source without the channels asked for cannot be followed
    assert performer.state.action is None
    assert "no channel 'index'; it has thumb" in performer.problem


def reference_over(dst, src):
    """Porter-Duff 'over' with straight alpha, pixel by pixel."""
    out = np.zeros_like(dst, dtype=float)
    for index in np.ndindex(dst.shape[:2]):
        s, d = src[index] / 255.0, dst[index] / 255.0
        a = s[3] + d[3] * (1 - s[3])
        rgb = (s[:3] * s[3] + d[:3] * d[3] * (1 - s[3])) / a if a > 0 else np.zeros(3)
        out[index] = np.concatenate([rgb, [a]]) * 255.0
    return out


def with_edge_alphas(rng, image):
    """Set about a third of the pixels' alpha to 0 and a third to 255 (the branches a
    compiled blend takes), the rest stays random."""
    pick = rng.integers(0, 3, image.shape[:2])
    image[..., 3][pick == 0] = 0
    image[..., 3][pick == 1] = 255
    return image


def test_blend_over_matches_porter_duff_and_clips(rng):
    canvas = with_edge_alphas(rng, rng.integers(0, 256, (12, 16, 4), dtype=np.uint8))
    layer = with_edge_alphas(rng, rng.integers(0, 256, (5, 7, 4), dtype=np.uint8))
    expected = canvas.astype(float).copy()
    expected[3:8, -4:] = reference_over(canvas[3:8, -4:], layer[:, :4])
    blend_over(canvas, layer, 12, 3)            # the right part of the layer is off-canvas
    assert np.abs(canvas.astype(float) - expected).max() <= 1.0
    stage = Stage((16, 12), (10, 20, 30))
    frame = stage.clear()
    assert (frame[..., :3] == (10, 20, 30)).all() and (frame[..., 3] == 255).all()
    opaque = np.full((4, 4, 4), 200, np.uint8)
    opaque[..., 3] = 255
    stage.place(opaque, (0.5, 0.5))
    assert (frame[4:8, 6:10, :3] == 200).all() and (frame[3, 6:10, :3] == (10, 20, 30)).all()


def test_opaque_fast_path_matches_general_path(rng):
    canvas = rng.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    canvas[..., 3] = 255
    layer = with_edge_alphas(rng, rng.integers(0, 256, (9, 11, 4), dtype=np.uint8))
    fast, general = canvas.copy(), canvas.copy()
    blend_over(fast, layer, -3, 14, opaque=True)
    blend_over(general, layer, -3, 14)
    assert np.abs(fast.astype(int) - general.astype(int)).max() <= 1
    assert (fast[..., 3] == 255).all()


def test_opaque_blend_is_the_rounded_integer_mix_byte_for_byte(rng):
    canvas = rng.integers(0, 256, (60, 80, 4), dtype=np.uint8)
    canvas[..., 3] = 255
    layer = with_edge_alphas(rng, rng.integers(0, 256, (50, 40, 4), dtype=np.uint8))
    alpha = layer[..., 3:4].astype(np.int64)
    expected = canvas.copy()
    region = expected[7:57, 30:70, :3].astype(np.int64)
    expected[7:57, 30:70, :3] = (layer[..., :3] * alpha + region * (255 - alpha) + 127) // 255
    blend_over(canvas, layer, 30, 7, opaque=True)
    assert np.array_equal(canvas, expected)
    with pytest.raises(ValueError, match="uint8"):
        blend_over(canvas, layer.astype(np.float32), 0, 0)
    with pytest.raises(ValueError, match="RGBA"):
        blend_over(canvas, layer[..., :3].copy(), 0, 0)


class SlowRenderer:
    """Draws the stand-in with the fallback mesh renderer, then takes `delay` seconds more (a
    stand-in for an expensive 3D render)."""

    def __init__(self, puppet, delay):
        from mop.render.compose import MeshLayerRenderer
        self.inner = MeshLayerRenderer(puppet.model.rest_positions, puppet.faces, height=40)
        self.delay = delay

    def render(self, puppet):
        import time
        time.sleep(self.delay)
        return self.inner.render(puppet)


class SlowPuppet:
    """The stand-in puppet whose step takes `pause` seconds more on the frames `when` says."""

    def __init__(self, when, pause):
        from session_standin import StripPuppet
        self.inner = StripPuppet(("tip",))
        self.when, self.pause, self.steps = when, pause, 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def step(self, dt, targets):
        import time
        if self.when(self.steps):
            time.sleep(self.pause)
        self.steps += 1
        self.inner.step(dt, targets)


class Recorder:
    """A state output and a frame output in one: what the loop sent, what the worker wrote."""

    def __init__(self):
        self.sent, self.written = [], []

    def send(self, state):
        performer = state["performers"]["p"]
        self.sent.append((state["frame"], performer["action"], performer["progress"]))

    def write(self, frame, state, *, repeat=False):
        self.written.append((state["frame"], repeat, frame.copy()))

    def close(self):
        pass


def standin_session(mode, *, delay, pause=None, max_lag=0.5):
    from followers import FollowerBank
    from mop.session.loop import CharacterRuntime, Session
    from session_standin import StripPuppet
    u = np.linspace(0.0, 1.0, 40)[:, None]
    template = np.sin(np.pi * u) ** 2
    show = np.concatenate([template, template, template])
    feed = TakeFeed(np.arange(len(show)) / 25.0, show, ("x",), loop=True)
    performer = PerformerRuntime("p", feed, FollowerBank({"bump": template}), channels=("x",))
    motion = Motion({"tip": ([0.0, 1.6], [[0.0], [2.0]])})
    puppet = StripPuppet(("tip",)) if pause is None else SlowPuppet(*pause)
    character = CharacterRuntime("c", puppet, SlowRenderer(puppet, delay), tracks=[
        Track("p", {"bump": (motion, (("tip", "tip"),))}, {"tip": 0.0}, blend=0.2)])
    recorder = Recorder()
    session = Session([performer], [character], fps=25, mode=mode,
                      stage=Stage((64, 48), (0, 0, 0)), outputs=[recorder], max_lag=max_lag)
    return session, recorder


@pytest.mark.slow
def test_live_mode_follows_every_frame_and_repeats_the_pictures_it_drops():
    replayed, reference = standin_session("replay", delay=0.0)
    replayed.run(duration=2.0)
    session, recorder = standin_session("live", delay=0.06)   # a render takes 1.5 periods
    report = session.run(duration=2.0)
    assert report.wall_seconds == pytest.approx(2.0, abs=0.3)     # real time was kept ...
    assert report.frames == 50 and report.slipped == 0, report.format()   # every frame
    # the followers saw the same input as in the replay: the same actions and progress
    assert recorder.sent == reference.sent and len(recorder.sent) == 50
    # one picture per frame, in order; the dropped ones repeat the picture before them
    assert [index for index, _, _ in recorder.written] == list(range(50))
    repeats = [k for k, (_, repeat, _) in enumerate(recorder.written) if repeat]
    assert report.dropped == len(repeats) > 10 and report.rendered + report.dropped == 50
    for k in repeats:
        if k > 0:
            assert np.array_equal(recorder.written[k][2], recorder.written[k - 1][2])
    assert "real time: every frame followed and simulated" in report.format()


@pytest.mark.slow
def test_a_late_frame_is_caught_up_at_its_own_time_not_skipped():
    replayed, reference = standin_session("replay", delay=0.0)
    replayed.run(duration=2.0)
    hiccup = (lambda step: step == 22, 0.3)       # warm-up steps twice, so frame 20 stalls
    session, recorder = standin_session("live", delay=0.0, pause=hiccup)
    report = session.run(duration=2.0)
    assert report.frames == 50 and report.slipped == 0, report.format()
    assert report.late_frames >= 5
    assert report.max_late == pytest.approx(0.3, abs=0.15)
    assert recorder.sent == reference.sent
    assert report.wall_seconds == pytest.approx(2.0, abs=0.3)
    assert "caught up" in report.verdict()


@pytest.mark.slow
def test_a_machine_too_slow_for_the_rate_is_reported_plainly():
    always = (lambda step: True, 0.06)             # the simulation alone takes 1.5 periods
    session, recorder = standin_session("live", delay=0.0, pause=always, max_lag=0.2)
    report = session.run(duration=1.2)
    assert report.slips >= 1 and report.slipped > 0.2
    assert report.verdict().startswith("NOT real time")
    assert [frame for frame, _, _ in recorder.sent] == list(range(report.frames))
    assert [index for index, _, _ in recorder.written] == list(range(report.frames))
    assert any(e["status"] == "behind" for e in report.events)


def test_replay_mode_runs_faster_than_real_time_and_renders_every_frame():
    session, recorder = standin_session("replay", delay=0.0)
    report = session.run(duration=4.0)
    assert report.wall_seconds < 4.0
    assert report.frames == 100 and report.rendered == 100 and report.dropped == 0
    assert [(index, repeat) for index, repeat, _ in recorder.written] == [
        (k, False) for k in range(100)]
    assert session.performers[0].seen == {"bump"}


def test_source_feed_follows_a_capture_source_reporting_disconnected():
    source = ListSource(("a",))
    source.status = "disconnected"          # capture's Status value while it reconnects
    now = [0.0]
    feed = SourceFeed(lambda: source, name="p", latency=0.0, clock=lambda: now[0])
    assert feed.poll(0.0) is None and feed.status == FAILED
    assert "disconnected" in feed.message and not source.closed   # kept: it reconnects itself
    source.status = "ok"
    source.queue.append(ListSource.Frame(0.1, [4.0]))
    now[0] = 0.1
    assert feed.poll(0.1) == pytest.approx([4.0]) and feed.status == OK


def test_video_output_repeats_a_dropped_picture_without_converting_it_again(tmp_path):
    """A repeat appends the picture the writer encoded last and never reads the frame handed
    with it (here a blank one, to tell); a repeat before any picture writes the one given."""
    cv2 = pytest.importorskip("cv2")
    from mop.export import over_colour
    from mop.session.outputs import VideoOutput
    rng = np.random.default_rng(3)
    pictures = [rng.integers(0, 256, (24, 32, 4), dtype=np.uint8) for _ in range(2)]
    blank = np.zeros_like(pictures[0])
    output = VideoOutput(tmp_path / "v.mkv", fps=25, size=(32, 24), background=(16, 32, 48))
    writes = [(0, True), (0, True), (1, False), (1, True), (1, True), (0, False)]
    for k, (picture, repeat) in enumerate(writes):
        handed = blank if repeat and k > 0 else pictures[picture]
        output.write(handed, {"frame": k}, repeat=repeat)
    output.close()
    assert output.frames == len(writes)
    capture = cv2.VideoCapture(str(tmp_path / "v.mkv"))
    read = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        read.append(frame[:, :, ::-1])
    capture.release()
    assert len(read) == len(writes)
    for frame, (picture, _) in zip(read, writes):
        assert np.array_equal(frame, over_colour(pictures[picture], (16, 32, 48)))


class GatedRenderer:
    """Draws a blank layer; every render after the first `free` ones waits until the file
    `gate` exists (a test holds the pictures back for as long as it likes, in a thread or a
    process)."""

    def __init__(self, gate, free=0):
        self.gate, self.free, self.renders = str(gate), free, 0

    def render(self, puppet):
        import os
        import time
        self.renders += 1
        deadline = time.monotonic() + 60.0
        while self.renders > self.free and not os.path.exists(self.gate):
            if time.monotonic() > deadline:
                break
            time.sleep(0.01)
        return np.zeros((8, 8, 4), np.uint8)


@pytest.mark.parametrize("kind", ["thread", "process"])
def test_replay_runs_ahead_of_its_pictures_and_draws_every_frame_in_order(tmp_path, kind):
    """Lossless pictures do not hold the loop frame by frame: while the first picture is being
    drawn the loop hands over the next SLOTS - 1 frames and goes on; only then does it wait.
    Every frame is drawn, none repeated, in order."""
    import threading

    from mop.session.loop import CharacterRuntime
    from mop.session.worker import SLOTS, RenderProcess, RenderWorker
    from session_standin import StripPuppet
    gate = tmp_path / "gate"
    # the render process draws once at rest before it says ready: that one is let through
    renderer = GatedRenderer(gate, free=0 if kind == "thread" else 1)
    character = CharacterRuntime("c", StripPuppet(("tip",)), renderer)
    recorder = Recorder()
    worker = (RenderWorker if kind == "thread" else RenderProcess)(
        Stage((16, 16), (0, 0, 0)), [character], [recorder], lossless=True)
    worker.start()
    worker.wait_ready()
    frames, handed = SLOTS + 3, []

    def loop():
        for index in range(frames):
            character.puppet.state.x[-1, 1] = index       # each frame's surface differs
            worker.submit(index, {"frame": index})
            handed.append(index)

    try:
        thread = threading.Thread(target=loop, daemon=True)
        thread.start()
        thread.join(5.0)                                  # the loop blocks once slots run out
        ahead = len(handed)
        assert ahead == SLOTS, ahead
        gate.touch()
        thread.join(30.0)
        assert len(handed) == frames
    finally:
        gate.touch()
        worker.finish(frames)
    assert [(index, repeat) for index, repeat, _ in recorder.written] == [
        (k, False) for k in range(frames)]
    assert worker.rendered == frames and worker.repeated == 0


def test_the_report_splits_the_simulate_stage_by_character():
    session, _ = standin_session("replay", delay=0.0)
    report = session.run(duration=1.0)
    part, whole = report.stages["simulate c"], report.stages["simulate"]
    assert part["count"] == whole["count"] == report.frames == 25
    assert 0 < part["mean"] <= whole["mean"]
    table = report.format().splitlines()
    row = table.index(next(line for line in table if line.startswith("  simulate")))
    assert table[row + 1].split()[0] == "c"


class DigestRenderer:
    """Draws the sha1 of the surface it is handed as seven opaque pixels: a picture that says
    exactly which vertices were drawn (in a thread or a process)."""

    def render(self, puppet):
        import hashlib
        digest = hashlib.sha1(np.ascontiguousarray(puppet.surface()).tobytes()).digest()
        rgb = np.frombuffer(digest + b"\0", np.uint8).reshape(7, 3)
        return np.concatenate([rgb, np.full((7, 1), 255, np.uint8)], axis=1)[None]


@pytest.mark.parametrize("kind", ["thread", "process"])
def test_a_latex_puppet_is_drawn_from_its_surface_nodes_as_from_its_surface(kind):
    """The worker copies a latex puppet's surface nodes, not its visual mesh, and draws the
    mesh from them: every picture equals the one drawn from the puppet's own surface()."""
    from characters import LatexPuppet
    from mop.session.loop import CharacterRuntime
    from mop.session.worker import RenderProcess, RenderWorker, snapshot_parts
    puppet = LatexPuppet.froggy(masses=400)
    take, skin = snapshot_parts(puppet)
    assert skin is puppet.skin and take().shape[0] < puppet.surface().shape[0] / 5
    character = CharacterRuntime("frog", puppet, DigestRenderer())
    recorder = Recorder()
    worker = (RenderWorker if kind == "thread" else RenderProcess)(
        Stage((16, 16), (0, 0, 0)), [character], [recorder], lossless=True)
    reference, expected = Stage((16, 16), (0, 0, 0)), []
    worker.start()
    try:
        worker.wait_ready()
        for index in range(5):
            puppet.step(0.04, {"thumb": index / 4, "pinky": 1.0 - index / 4})
            worker.submit(index, {"frame": index})
            reference.clear()
            reference.place(DigestRenderer().render(puppet), (0.5, 0.5))
            expected.append(reference.frame.copy())
    finally:
        worker.finish(5)
    assert [(index, repeat) for index, repeat, _ in recorder.written] == [
        (k, False) for k in range(5)]
    for (_, _, frame), wanted in zip(recorder.written, expected):
        np.testing.assert_array_equal(frame, wanted)
    assert not np.array_equal(expected[0], expected[-1])
