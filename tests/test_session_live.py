"""A real live show on loopback, under load, compared frame by frame with its replay.

Two performers are other processes (`mop send`) replaying recorded show takes over OSC, with
gestures at 0.7x and 1.5x their demonstrated pace; three characters (the latex frog, the
cut-out, the medial caterpillar) go to a video, to OSC out and to the preview page, which a
client polls ten times a second; a busy process holds one core. Every session frame must reach
OSC out, the followers must say per frame what they say when the same takes are replayed (the
same action, progress within 0.02), and the video must have one frame per session frame."""
import json
import os
import re
import socket
import subprocess
import sys
import threading
import time
import urllib.request

import numpy as np
import pytest

from session_files import ROOT, free_udp_port, mop_command, mop_process, show_takes

SHOWS = {
    "glove_live": ("glove", [(None, 0.6), ("chomp", 0.7), (None, 0.8), ("ripple", 1.5),
                             (None, 0.8)]),
    "hand_live": ("hand", [(None, 0.4), ("circle", 1.5), (None, 0.8), ("lift", 0.7),
                           (None, 0.8)]),
}
DURATION = 8.5     # [s] of session time: both shows (6.7 s at most) and their start


def session_file(folder, takes, *, glove_port, hand_port):
    path = folder / "live.toml"
    path.write_text(f"""
[session]
fps = 25
blend = 0.3
size = [320, 180]
takes = "{takes}"

[performers.glove]
source = "osc:127.0.0.1:{glove_port}/glove?channels=thumb,index,middle,ring,pinky"

[performers.hand]
source = "osc:127.0.0.1:{hand_port}/hand?channels=x,y,z"

[characters.frog]
kind = "latex"
asset = "froggy"
position = [0.2, 0.55]
scale = 0.7
options = {{ masses = 1000 }}

[characters.momo]
kind = "image"
asset = "momo"
position = [0.5, 0.5]

[characters.creature]
kind = "medial"
asset = "medial_caterpillar"
position = [0.8, 0.55]

[[actions]]
take = "glove_chomp"
performer = "glove"
character = "frog"

[[actions]]
take = "glove_ripple"
performer = "glove"
character = "momo"

[[actions]]
take = "hand_circle"
performer = "hand"
character = "creature"

[[actions]]
take = "hand_lift"
performer = "hand"
character = "momo"
""")
    return path


class OscLog(threading.Thread):
    """Every bundle that arrives on a loopback port: {frame: {performer: (input frame, action,
    progress)}}."""

    def __init__(self):
        super().__init__(daemon=True)
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.socket.bind(("127.0.0.1", 0))
        self.socket.settimeout(0.2)
        self.port = self.socket.getsockname()[1]
        self.frames: dict[int, dict] = {}
        self.stop = threading.Event()

    def run(self):
        from pythonosc.osc_bundle import OscBundle
        while not self.stop.is_set():
            try:
                data = self.socket.recv(1 << 16)
            except socket.timeout:
                continue
            performers, frame = {}, None
            for message in OscBundle(data):
                if message.address == "/mop/frame":
                    frame = message.params[0]
                elif message.address.startswith("/mop/performer/"):
                    _, action, progress, _, _, step = message.params
                    performers[message.address.rsplit("/", 1)[1]] = (step, action, progress)
            self.frames[frame] = performers

    def close(self):
        self.stop.set()
        self.join()
        self.socket.close()

    def by_input_frame(self, performer):
        """{input frame: (action, progress)} of one performer, over the frames it followed."""
        out = {}
        for performers in self.frames.values():
            step, action, progress = performers[performer]
            if step >= 0:
                out[step] = (action, progress)
        return out


class Viewer(threading.Thread):
    """A preview client: /frame.jpg and /state.json, ten times a second each."""

    def __init__(self, url):
        super().__init__(daemon=True)
        self.url, self.stop = url, threading.Event()
        self.pictures = self.states = self.refused = 0

    def run(self):
        while not self.stop.wait(0.1):
            for page in ("frame.jpg", "state.json"):
                try:
                    with urllib.request.urlopen(self.url + page, timeout=2) as response:
                        body = response.read()
                    if page == "frame.jpg":
                        self.pictures += body[:2] == b"\xff\xd8"
                    else:
                        self.states += "performers" in json.loads(body)
                except OSError:
                    self.refused += 1


# a `mop send` that has done its imports and waits for a line on stdin to start: the senders'
# start-up (seconds of CPU) happens before the show, not inside it
READY_SENDER = """
import sys
import capture.replay, capture.store, pythonosc.udp_client  # noqa: F401
import pythonosc.osc_message_builder  # noqa: F401
import mop.session.config  # noqa: F401
from mop.cli import main
sys.stdout.write("ready\\n")
sys.stdout.flush()
sys.stdin.readline()
sys.exit(main(["send", *sys.argv[1:]]))
"""


def ready_sender(*arguments) -> subprocess.Popen:
    process = subprocess.Popen([sys.executable, "-c", READY_SENDER, *map(str, arguments)],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=ROOT,
                               env=dict(os.environ, PYTHONUNBUFFERED="1"))
    assert process.stdout.readline().strip() == "ready", process.stderr.read()[-2000:]
    return process


def wait_for(stream, pattern, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = stream.readline()
        if not line:
            break
        match = re.search(pattern, line)
        if match:
            return match
    raise AssertionError(f"no line matching {pattern!r}")


def count_frames(path):
    import cv2
    capture = cv2.VideoCapture(str(path))
    count = 0
    while capture.grab():
        count += 1
    capture.release()
    return count


@pytest.mark.slow
def test_a_live_show_under_load_follows_every_frame_as_its_replay_does(tmp_path):
    takes = show_takes(tmp_path / "takes", SHOWS, seed=2718)
    glove_port, hand_port = free_udp_port(), free_udp_port()
    path = session_file(tmp_path, takes, glove_port=glove_port, hand_port=hand_port)
    video = tmp_path / "live.mkv"
    live = OscLog()
    live.start()
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    if hasattr(os, "sched_setaffinity") and len(os.sched_getaffinity(0)) > 1:
        os.sched_setaffinity(busy.pid, {sorted(os.sched_getaffinity(0))[-1]})
    performer = mop_process("perform", path, "--out", video, "--preview", "0", "--osc-out",
                            f"127.0.0.1:{live.port}", "--duration", DURATION)
    senders, viewer = [], None
    try:
        for name, port, address in (("glove_live", glove_port, "/glove"),
                                     ("hand_live", hand_port, "/hand")):
            senders.append(ready_sender(f"replay:{takes / name}", "--to", f"127.0.0.1:{port}",
                                        "--address", address, "--quiet"))
        url = wait_for(performer.stderr, r"^preview: (http://\S+)", timeout=120).group(1)
        wait_for(performer.stderr, r"^the show is on", timeout=120)
        viewer = Viewer(url)
        viewer.start()
        for sender in senders:
            sender.stdin.write("go\n")
            sender.stdin.flush()
        out, err = performer.communicate(timeout=180)
    finally:
        for process in senders + [busy, performer]:
            process.kill()
        if viewer is not None:
            viewer.stop.set()
        live.close()
    assert performer.returncode == 0, err[-3000:]
    frames = int(re.search(r"^(\d+) frames at 25 fps", out, re.M).group(1))
    assert "real time: every frame followed and simulated" in out, out

    # every session frame reached OSC out, and the video has one picture per frame
    assert sorted(live.frames) == list(range(frames))
    assert count_frames(video) == frames
    assert viewer.pictures > 20 and viewer.states > 20

    # the same takes replayed: the followers say the same, input frame by input frame
    replayed = OscLog()
    replayed.start()
    try:
        done = subprocess.run(
            mop_command("perform", path, "--replay", "glove=glove_live", "hand=hand_live",
                        "--no-render", "--quiet", "--osc-out", f"127.0.0.1:{replayed.port}"),
            capture_output=True, text=True, timeout=300, cwd=ROOT)
        time.sleep(0.5)
    finally:
        replayed.close()
    assert done.returncode == 0, done.stderr[-3000:]
    for name in ("glove", "hand"):
        seen, reference = live.by_input_frame(name), replayed.by_input_frame(name)
        common = sorted(set(seen) & set(reference))
        assert len(common) >= 0.95 * len(reference), (name, len(common), len(reference))
        actions = [(n, seen[n][0], reference[n][0]) for n in common
                   if seen[n][0] != reference[n][0]]
        assert actions == [], f"{name}: {len(actions)} frames differ: {actions[:10]}"
        error = np.array([abs(seen[n][1] - reference[n][1]) for n in common])
        assert error.max() <= 0.02, (name, float(error.max()), int(np.argmax(error)))

