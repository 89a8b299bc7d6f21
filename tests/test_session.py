"""Whole sessions: deterministic replay, a failing source, Ctrl-C, outputs, OSC between processes.

Built on the shipped demo takes (recordings/demo) and shipped characters; see session_files.py."""
import hashlib
import re
import signal
import socket
import time

import numpy as np
import pytest

from mop.session import Mode, load_session
from mop.session.build import Overrides, build_session
from session_files import TAKES, free_udp_port, mop_process, session_text, write_session

pytestmark = pytest.mark.slow   # whole sessions, several in real time


class FrameLog:
    """An output that keeps every frame, the states, and a digest of every puppet's surface
    (the states and surfaces as the loop sends them, the frames as the render worker writes)."""

    def __init__(self):
        self.frames, self.states, self.surfaces = [], [], []
        self.session = None

    def send(self, state):
        self.states.append(state)
        self.surfaces.append(tuple(
            hashlib.sha1(np.ascontiguousarray(c.puppet.surface()).tobytes()).hexdigest()
            for c in self.session.characters))

    def write(self, frame, state, *, repeat=False):
        assert not repeat and state is self.states[len(self.frames)]
        self.frames.append(frame.copy())

    def close(self):
        pass


def replay(path, *, duration):
    log = FrameLog()
    session = build_session(load_session(path), mode=Mode.REPLAY, extra_outputs=[log])
    log.session = session
    report = session.run(duration=duration)
    return session, report, log


def test_two_performers_three_characters_replayed_twice_give_identical_frames(tmp_path):
    path = write_session(tmp_path)
    first, report, log_a = replay(path, duration=4.4)
    second, _, log_b = replay(path, duration=4.4)
    assert report.frames == 110 and len(log_a.frames) == 110
    # what the followers said, every target, every puppet's geometry: bit for bit the same
    assert log_a.states == log_b.states
    assert log_a.surfaces == log_b.surfaces
    # the pictures, 2D and 3D layers composed: byte for byte (mop.render.scene3d draws meshes
    # and sums lights in a fixed order, otherwise a stray pixel may round one level differently)
    differing = [k for k, (a, b) in enumerate(zip(log_a.frames, log_b.frames))
                 if not np.array_equal(a, b)]
    assert differing == []
    # ... and the frames are not trivially equal: the characters moved
    digests = {hashlib.sha1(frame.tobytes()).hexdigest() for frame in log_a.frames}
    assert len(digests) > 90
    # the followers recognised what was performed, and momo listened to both performers
    assert {"glove_ripple", "glove_chomp"} <= first.performers[0].seen
    assert {"hand_circle", "hand_lift"} <= first.performers[1].seen
    momo = first.characters[0]
    assert sorted(track.performer for track in momo.tracks) == ["glove", "hand"]
    actions = {(name, track["action"]) for state in log_a.states
               for name, character in state["characters"].items()
               for track in character["tracks"]}
    assert {("momo", "glove_ripple"), ("momo", "hand_lift"), ("creature", "hand_circle"),
            ("worm", "glove_chomp")} <= actions
    assert report.stages["simulate"]["count"] == 110


def test_replay_runs_until_the_takes_end_and_reports_timing(tmp_path):
    session = build_session(load_session(write_session(tmp_path)),
                            overrides=Overrides(render=False))
    report = session.run()
    longest = max(feed.duration for feed in (p.feed for p in session.performers))
    # both takes end, then the characters get `blend` seconds to settle
    assert report.frames == pytest.approx((longest + 0.3) * 25, abs=2)
    assert report.rendered == 0
    assert [e["status"] for e in report.events] == ["ended", "ended"]
    text = report.format()
    for stage in ("capture", "follow", "simulate", "input to pose"):
        assert stage in text
    assert report.stages["input_to_pose"]["median"] > 0


def test_outputs_png_with_alpha_chroma_key_and_osc(tmp_path):
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(2.0)
    port = receiver.getsockname()[1]
    path = write_session(tmp_path, background="transparent")
    config = load_session(path)
    session = build_session(config, overrides=Overrides(png=str(tmp_path / "png"),
                                                        osc=("127.0.0.1", port)))
    session.run(duration=1.0)
    from PIL import Image
    frames = sorted((tmp_path / "png").glob("*.png"))
    assert len(frames) == 25
    picture = np.asarray(Image.open(frames[-1]))
    assert picture.shape == (180, 320, 4)
    assert picture[0, 0, 3] == 0 and picture[..., 3].max() == 255   # transparent around them
    from pythonosc.osc_bundle import OscBundle
    bundle = OscBundle(receiver.recv(65536))
    addresses = {message.address: message.params for message in bundle}
    assert addresses["/mop/frame"][0] == 0
    assert addresses["/mop/performer/glove"][0] == "ok"
    assert "/mop/character/momo/action" in addresses
    receiver.close()

    chroma = write_session(tmp_path, name="chroma.toml", background="chroma")
    session = build_session(load_session(chroma), overrides=Overrides(
        video=str(tmp_path / "chroma.mkv")))
    session.run(duration=0.4)
    import cv2
    capture = cv2.VideoCapture(str(tmp_path / "chroma.mkv"))
    ok, bgr = capture.read()
    assert ok and tuple(bgr[0, 0][::-1]) == (0, 177, 64)             # broadcast green


def test_session_errors_name_the_key(tmp_path):
    from mop.cli import main
    path = write_session(tmp_path)
    bad = path.read_text().replace('take = "hand_circle"', 'take = "hand_cirkle"')
    path.write_text(bad)
    with pytest.raises(ValueError, match=r"actions\[2\]\.take: take 'hand_cirkle' is not in"):
        build_session(load_session(path), overrides=Overrides(render=False))
    path.write_text(session_text().replace('channels = { thumb = "jaw"',
                                           'channels = { thumb = "chin"'))
    with pytest.raises(ValueError, match=r"actions\[3\]\.channels: character 'worm' has no "
                                         r"target 'chin'; expected one of"):
        build_session(load_session(path), overrides=Overrides(render=False))
    path.write_text(session_text().replace("fps = 25", "fps = 24"))
    assert main(["perform", str(path), "--replay"]) == 1


def wait_for_line(stream, pattern, timeout):
    """Read lines until one matches; returns the match (the stream is a text pipe)."""
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        line = stream.readline()
        if not line:
            break
        seen.append(line)
        match = re.search(pattern, line)
        if match:
            return match
    raise AssertionError(f"no line matching {pattern!r} within {timeout} s (or the stream "
                         f"ended); last lines: {seen[-10:]}")


def test_timing_on_request_and_ctrl_c_leaves_a_playable_video(tmp_path):
    import cv2
    path = write_session(tmp_path)
    video = tmp_path / "show.mp4"
    process = mop_process("perform", path, "--realtime", "--loop", "--out", video)
    try:
        while int(wait_for_line(process.stderr, r"^frame (\d+) ", timeout=60).group(1)) < 30:
            pass                                                 # more than a second of show
        process.send_signal(signal.SIGUSR1)                      # timing on request
        wait_for_line(process.stderr, r"^\s+simulate\s+[\d.]+", timeout=30)
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 130, err
    assert "interrupted: every output was finalised" in err
    written = int(re.search(r"wrote .*show\.mp4 \((\d+) frames\)", out).group(1))
    capture = cv2.VideoCapture(str(video))
    assert capture.isOpened()
    count = 0
    while capture.read()[0]:
        count += 1
    assert count == written and count >= 25
    assert capture.get(cv2.CAP_PROP_FRAME_WIDTH) == 320


def test_a_killed_source_rests_its_characters_while_the_others_go_on(tmp_path):
    """The hand performer is another process sending OSC; it is killed mid-show and restarted.
    Meanwhile the glove (a replayed take on the live clock) keeps driving its characters."""
    port = free_udp_port()
    path = write_session(tmp_path, hand_source=f"osc:127.0.0.1:{port}/hand?channels=x,y,z",
                         glove_source="replay:glove_show")
    sender_command = ["send", f"replay:{TAKES / 'hand_show'}?loop=true",
                      "--to", f"127.0.0.1:{port}", "--address", "/hand"]
    session = build_session(load_session(path), mode=Mode.LIVE,
                            overrides=Overrides(render=False))
    senders = []
    timeline = []
    marks = {}

    def watch(current):
        state = current.state()
        hand = state["performers"]["hand"]["status"]
        creature = state["characters"]["creature"]["tracks"][0]["action"]
        timeline.append((current.t, hand, creature, state["performers"]["glove"]["action"]))
        if not senders:
            senders.append(mop_process(*sender_command))
        if "killed" not in marks and (creature == "hand_circle" or current.t > 12):
            senders[0].kill()
            marks["killed"] = current.t
        elif "killed" in marks and "restarted" not in marks and current.t > marks["killed"] + 2.5:
            senders.append(mop_process(*sender_command))
            marks["restarted"] = current.t
        elif "restarted" in marks and "back" not in marks and hand == "ok":
            marks["back"] = current.t
        elif "back" in marks and current.t > marks["back"] + 1:
            current.request_stop()

    try:
        report = session.run(duration=25.0, progress=watch)
    finally:
        for sender in senders:
            sender.kill()
    killed, restarted = marks["killed"], marks["restarted"]
    before = [row for row in timeline if row[0] <= killed]
    # silent once its last input is stale_after (0.4 s) old; the frame that saw the kill may
    # have run up to max_lag (0.5 s) behind that input
    silent = [row for row in timeline if killed + 1.0 < row[0] < restarted]
    assert any(row[1] == "ok" and row[2] == "hand_circle" for row in before)
    assert silent and all(row[1] == "silent" and row[2] is None for row in silent)
    # the glove's characters kept going while the hand was gone: frames kept coming, and the
    # glove's follower kept following
    assert any(row[3] is not None for row in silent)
    assert len(timeline) >= 0.8 * timeline[-1][0] * 25
    assert "back" in marks, "the hand performer did not rejoin"
    kinds = [(e["performer"], e["status"]) for e in report.events]
    assert ("hand", "silent") in kinds
    assert any(e["performer"] == "hand" and e["message"].startswith("back") for e in
               report.events)


def test_a_performer_on_another_process_joins_over_osc(tmp_path):
    """Two processes on loopback: `mop send` replays the hand take as OSC; `mop perform` follows
    it and sends the characters' state out as OSC, which this test reads."""
    hand_port, out_port = free_udp_port(), free_udp_port()
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", out_port))
    listener.settimeout(0.5)
    path = write_session(tmp_path, hand_source=f"osc:127.0.0.1:{hand_port}/hand?channels=x,y,z")
    performer = mop_process("perform", path, "--realtime", "--duration", "20", "--no-render",
                            "--osc-out", f"127.0.0.1:{out_port}")
    sender = None
    try:
        wait_for_line(performer.stderr, r"^performing", timeout=60)
        sender = mop_process("send", f"replay:{TAKES / 'hand_show'}?loop=true", "--to",
                             f"127.0.0.1:{hand_port}", "--address", "/hand")
        from pythonosc.osc_bundle import OscBundle
        creature_actions, hand_status = set(), set()
        deadline = time.monotonic() + 30
        while (time.monotonic() < deadline and performer.poll() is None
               and not ("ok" in hand_status and "hand_circle" in creature_actions)):
            try:
                data = listener.recv(65536)
            except socket.timeout:
                continue
            for message in OscBundle(data):
                if message.address == "/mop/character/creature/action":
                    creature_actions.add(message.params[0])
                elif message.address == "/mop/performer/hand":
                    hand_status.add(message.params[0])
        performer.send_signal(signal.SIGINT)
        out, err = performer.communicate(timeout=30)
    finally:
        performer.kill()
        if sender is not None:
            sender.kill()
        listener.close()
    assert performer.returncode in (0, 130), err
    assert "ok" in hand_status
    assert "hand_circle" in creature_actions


def test_mop_send_tags_each_frame_with_its_capture_time():
    """Every datagram `mop send` sends is a bundle tagged with the frame's capture time: a take
    replayed in real time has the take's spacing in its tags, whatever the sending loop's."""
    from capture import open_source
    from capture.osc import time_tag
    port = free_udp_port()
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", port))
    listener.settimeout(5.0)
    sender = mop_process("send", f"replay:{TAKES / 'hand_show'}", "--to", f"127.0.0.1:{port}",
                         "--address", "/hand", "--duration", "1.5")
    tags = []
    try:
        while len(tags) < 20:
            tags.append(time_tag(listener.recv(65536)))
    finally:
        sender.kill()
        listener.close()
    with open_source(f"replay:{TAKES / 'hand_show'}?realtime=false") as take:
        times = [take.read(timeout=1.0).t for _ in range(len(tags))]
    assert None not in tags
    assert np.allclose(np.diff(tags), np.diff(times), atol=1e-5)
    assert abs(tags[0] - time.time()) < 60.0
