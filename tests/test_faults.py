"""Fault injection with real faults: a file system that fills up during video output and
during recording, kill -9 of `mop record`, a take copied without its WAL, a stale WAL, absurd
and malformed input over a real OSC socket. Each test asserts the message, the exit code and
that nothing recorded before the fault is lost.

The full disk is a small tmpfs mounted in a private mount namespace (tests/faults.py says how,
and why that is a real ENOSPC); where no namespace can be had the disk tests skip, saying so.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from faults import ROOT, mop_env, run_on_small_disk, small_disk_prefix

DATA = ROOT / "characters" / "assets"
TAKES = ROOT / "recordings" / "demo"

needs_small_disk = pytest.mark.skipif(small_disk_prefix() is None,
                                      reason="no private mount namespace (unshare -m / -rm) "
                                             "to mount a small tmpfs in")


def _one_error_line(stderr: str, *words: str) -> str:
    lines = [line for line in stderr.splitlines() if "error:" in line]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr, stderr
    for word in words:
        assert word.lower() in lines[0].lower(), (word, stderr)
    return lines[0]


SMALL_SESSION = f"""
[session]
fps = 25
size = [320, 180]
background = "#1d2330"
takes = "{TAKES}"

[performers.glove]
source = "replay:glove_show"
channels = ["thumb", "index", "middle", "ring", "pinky"]

[characters.momo]
kind = "image"
asset = "momo"
position = [0.5, 0.5]
scale = 0.9

[[actions]]
take = "glove_ripple"
performer = "glove"
character = "momo"
"""


def _video_command(kind: str, out: Path, tmp_path: Path) -> list[str]:
    if kind == "puppet":
        return ["puppet", str(DATA / "momo.png"), "--motion", str(DATA / "momo_wave.json"),
                "--out", str(out)]
    session = tmp_path / "small.toml"
    session.write_text(SMALL_SESSION)
    if kind == "perform":
        return ["perform", str(session), "--replay", "--duration", "6", "--quiet",
                "--out", str(out)]
    return ["demo", "--session", str(session), "--quiet", "--out", str(out)]


@needs_small_disk
@pytest.mark.parametrize("kind, suffix", [
    ("puppet", ".mkv"),
    pytest.param("puppet", ".mp4", marks=pytest.mark.slow),
    pytest.param("perform", ".mp4", marks=pytest.mark.slow),
    pytest.param("demo", ".mkv", marks=pytest.mark.slow)])
def test_a_full_disk_during_video_output_is_an_error_naming_the_file(kind, suffix, tmp_path):
    disk = tmp_path / "disk"
    out = disk / f"out{suffix}"
    result = run_on_small_disk(_video_command(kind, out, tmp_path), disk=disk, size_kb=256)
    assert result.returncode == 1, (result.stdout, result.stderr)
    _one_error_line(result.stderr, f"mop {kind}: error", str(out), "no space left")
    assert f"wrote {out}" not in result.stdout


@pytest.mark.slow
@needs_small_disk
def test_a_video_that_fits_is_written_and_read_back(tmp_path):
    import cv2

    disk = tmp_path / "disk"
    keep = tmp_path / "keep"
    result = run_on_small_disk(_video_command("puppet", disk / "out.mp4", tmp_path), disk=disk,
                               size_kb=16384, keep=keep)
    assert result.returncode == 0, result.stderr
    capture = cv2.VideoCapture(str(keep / "out.mp4"))
    assert capture.get(cv2.CAP_PROP_FRAME_COUNT) == 101      # 4 s at 25 fps, both ends
    capture.release()


@pytest.mark.slow
@needs_small_disk
def test_a_full_disk_for_the_record_preview_is_an_error(tmp_path):
    disk = tmp_path / "disk"
    preview = disk / "preview.mp4"
    result = run_on_small_disk(
        ["record", "--performer", "ann", "--action", "wave", "--motion",
         str(DATA / "momo_wave.json"), "--source", "replay:" + str(TAKES / "glove_show"),
         "--recordings", str(tmp_path / "takes"), "--preview", str(preview)],
        disk=disk, size_kb=64)
    assert result.returncode == 1, (result.stdout, result.stderr)
    _one_error_line(result.stderr, str(preview), "no space left")
    assert not list((tmp_path / "takes").glob("*.sqlite"))


def _record_argv(folder: Path, *, name="t1", preview="none", source=None) -> list[str]:
    return ["record", "--performer", "ann", "--action", "wave", "--motion",
            str(DATA / "momo_wave.json"), "--source",
            source or "replay:" + str(TAKES / "glove_show"), "--recordings", str(folder),
            "--name", name, "--countdown", "0", "--preview", preview]


def _frames(folder: Path, name: str):
    from mop.takes import TakeStore
    take = TakeStore(folder, create=False).load(name)
    return take


@needs_small_disk
def test_a_full_disk_when_record_starts_leaves_no_take(tmp_path):
    disk = tmp_path / "disk"
    keep = tmp_path / "keep"
    result = run_on_small_disk(_record_argv(disk / "takes"), disk=disk, size_kb=64, keep=keep,
                               setup=f"mkdir -p {disk}/takes", prefill=True)
    assert result.returncode == 1, (result.stdout, result.stderr)
    _one_error_line(result.stderr, "mop record: error", str(disk / "takes" / "t1.sqlite"),
                    "no space left", "nothing was written")
    assert "Traceback" not in result.stderr
    assert sorted(p.name for p in (keep / "takes").iterdir()) == []


@needs_small_disk
def test_a_full_disk_while_recording_keeps_what_was_recorded_before(tmp_path):
    disk = tmp_path / "disk"
    keep, before = tmp_path / "keep", tmp_path / "before"
    take = disk / "takes" / "t1.sqlite"
    result = run_on_small_disk(_record_argv(disk / "takes"), disk=disk, size_kb=1024, keep=keep,
                               fill_when_exists=str(take), snapshot=before)
    assert result.returncode == 1, (result.stdout, result.stderr)
    line = _one_error_line(result.stderr, "mop record: error", str(take), "no space left",
                           "recorded before are kept as take t1")
    assert "rollback" not in result.stderr
    saved = _frames(before / "takes", "t1")
    kept = _frames(keep / "takes", "t1")
    assert not kept.complete
    assert f"the {kept.times.size} frames" in line
    # nothing recorded before the fault is lost, and what is kept is what was recorded
    assert saved.times.size >= 10
    assert kept.times.size >= saved.times.size
    assert (kept.values[:saved.times.size] == saved.values).all()
    assert kept.times.size < 200                     # the take stopped at the fault


def _kill_recording_midway(folder: Path, name: str, seconds: float) -> int:
    """Start `mop record` (a 4 s take from a replayed glove), SIGKILL it `seconds` into the
    take; returns its exit status."""
    import os
    import signal
    import time

    process = subprocess.Popen([sys.executable, "-m", "mop", *_record_argv(folder, name=name)],
                               env=mop_env(), cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    take = folder / f"{name}.sqlite"
    deadline = time.monotonic() + 60
    while not take.exists() and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    time.sleep(seconds)
    os.kill(process.pid, signal.SIGKILL)
    return process.wait()


@pytest.mark.slow
def test_kill_9_then_copying_only_the_sqlite_keeps_all_but_the_last_second(tmp_path):
    import shutil

    folder, copy = tmp_path / "takes", tmp_path / "copy"
    assert _kill_recording_midway(folder, "t1", 2.6) == -9
    assert (folder / "t1.sqlite-wal").exists()      # the last moments live in the WAL
    copy.mkdir()
    shutil.copy(folder / "t1.sqlite", copy / "t1.sqlite")
    alone = _frames(copy, "t1")
    # listing folds the WAL back: the file alone is then the whole take
    listing = subprocess.run([sys.executable, "-m", "mop", "takes", "--recordings", str(folder),
                              "list"], env=mop_env(), capture_output=True, text=True)
    assert listing.returncode == 0, listing.stderr
    assert "(interrupted)" in listing.stdout
    assert not (folder / "t1.sqlite-wal").exists()
    whole = _frames(folder, "t1")
    assert not alone.complete and not whole.complete
    # about 2.6 s at 50 Hz were recorded; the copy lacks at most the last checkpoint interval
    assert whole.times.size >= 100
    assert alone.times.size >= whole.times.size - 50 - 5
    assert (alone.values == whole.values[:alone.times.size]).all()
    show = subprocess.run([sys.executable, "-m", "mop", "takes", "--recordings", str(copy),
                           "show", "t1"], env=mop_env(), capture_output=True, text=True)
    assert show.returncode == 0, show.stderr
    assert f"{alone.times.size} frames" in show.stdout
    assert "captured of the planned 4.00 s" in show.stdout


@pytest.mark.slow
def test_a_stale_wal_beside_another_take_is_detected_and_moved_aside(tmp_path):
    import shutil

    killed, folder = tmp_path / "killed", tmp_path / "takes"
    assert _kill_recording_midway(killed, "k", 1.5) == -9
    folder.mkdir()
    shutil.copy(TAKES / "glove_chomp.sqlite", folder / "chomp.sqlite")
    original = _frames(folder, "chomp")
    shutil.copy(killed / "k.sqlite-wal", folder / "chomp.sqlite-wal")

    def mop_takes(*argv):
        return subprocess.run([sys.executable, "-m", "mop", "takes", "--recordings",
                               str(folder), *argv], env=mop_env(), capture_output=True,
                              text=True)

    show = mop_takes("show", "chomp")
    assert show.returncode == 1
    _one_error_line(show.stderr, "chomp.sqlite-wal does not belong to", "takes repair")
    listing = mop_takes("list")
    assert listing.returncode == 0 and "DAMAGED" in listing.stdout
    repaired = mop_takes("repair", "chomp")
    assert repaired.returncode == 0, repaired.stderr
    assert "moved the WAL aside to chomp.sqlite-wal.foreign" in repaired.stdout
    assert (folder / "chomp.sqlite-wal.foreign").exists()       # moved, never deleted
    after = _frames(folder, "chomp")
    assert after.complete
    assert (after.values == original.values).all() and (after.times == original.times).all()
    assert mop_takes("repair").stdout.strip() == "chomp: healthy: nothing to do"


# -- hostile input over a real OSC socket ------------------------------------------------------

def _free_udp_port() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class _Sender:
    """A thread sending `/glove` messages of 5 floats to a port every `period` s: channel 0
    counts the good messages (1, 2, 3, ...) unless `values` fixes them; `junk` datagrams go
    out between two good ones."""

    def __init__(self, port: int, *, values=None, junk=(), period=0.02):
        import socket
        import threading
        self.port, self.values, self.junk, self.period = port, values, list(junk), period
        self.sent = 0
        self.stop = threading.Event()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        import time

        from pythonosc.osc_message_builder import OscMessageBuilder
        target = ("127.0.0.1", self.port)
        while not self.stop.is_set():
            builder = OscMessageBuilder("/glove")
            values = self.values or [float(self.sent + 1), 0.2, 0.4, 0.6, 0.8]
            for value in values:
                builder.add_arg(float(value), "f")
            self.sock.sendto(builder.build().dgram, target)
            self.sent += 1
            for packet in self.junk:
                self.sock.sendto(packet, target)
                time.sleep(0.0002)
            time.sleep(self.period)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()
        self.sock.close()


def _junk_bundles() -> list[bytes]:
    head = b"#bundle\x00" + b"\x00" * 7 + b"\x01"
    nested = b"/glove\x00\x00,f\x00\x00\x00\x00\x00\x00"
    for _ in range(20):
        nested = head + len(nested).to_bytes(4, "big") + nested
    return [head + b"\x00\x00\x00\x04\x00\x00\x00\x00",          # content neither kind
            head + b"\x00\x00\x01\x00/glove",                      # element past the end
            head + b"\xff\xff\xff\xf0",                             # negative size
            nested,                                                 # 20 bundles deep
            head + b"\x00\x00\x00\x0c/glove\x00\x00,Iq\x00",       # unknown type tags
            b"#bundle\x00\x00\x00",                                  # cut short
            head + b"\x00\x00\x00\x10/glove\x00\x00,fffff\x00\x00"]  # arguments missing


@pytest.mark.slow
def test_a_flood_of_malformed_bundles_loses_no_good_frame(tmp_path):
    import numpy as np

    port = _free_udp_port()
    junk = _junk_bundles() * 6          # 42 junk datagrams per good one
    with _Sender(port, junk=junk):
        result = subprocess.run(
            [sys.executable, "-m", "mop",
             *_record_argv(tmp_path, source=f"osc:127.0.0.1:{port}/glove?channels=5")],
            env=mop_env(), cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Could not identify" not in result.stderr
    assert "error" not in result.stderr.lower()
    take = _frames(tmp_path, "t1")
    counter = take.values[:, 0]
    assert take.times.size >= 40             # the sender's pace under junk: ~30-50 ms a frame
    # every good message sent during the take is kept, in order, and nothing else
    assert (np.diff(counter) == 1).all()
    assert take.extra["source_stats"]["dropped"] == 0
    assert (take.values[:, 1:] == np.array([0.2, 0.4, 0.6, 0.8], np.float32)).all()
    skipped = int(result.stdout.split(" malformed inputs skipped")[0].rsplit(" ", 1)[-1])
    assert skipped >= 40 * take.times.size


def _glove_session(folder: Path, port: int) -> Path:
    session = folder / "glove.toml"
    session.write_text(SMALL_SESSION.replace('source = "replay:glove_show"',
                                             f'source = "osc:127.0.0.1:{port}/glove"'))
    return session


def _listen_performer_actions(port: int, stop, actions: list) -> None:
    """What `mop perform --osc-out` says the glove performer does, frame by frame, until
    `stop` is set."""
    import socket

    from pythonosc.osc_packet import OscPacket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", port))
        sock.settimeout(0.2)
        while not stop.is_set():
            try:
                data = sock.recv(65535)
            except socket.timeout:
                continue
            for timed in OscPacket(data).messages:
                if timed.message.address == "/mop/performer/glove":
                    actions.append(timed.message.params[1])


@pytest.mark.slow
@pytest.mark.parametrize("value", [1e6, -50.0])
def test_a_glove_stuck_at_an_absurd_value_plays_nothing(value, tmp_path):
    import threading

    port, out_port = _free_udp_port(), _free_udp_port()
    session = _glove_session(tmp_path, port)
    heard: list[str] = []
    stop = threading.Event()
    listener = threading.Thread(target=_listen_performer_actions, args=(out_port, stop, heard),
                                daemon=True)
    listener.start()
    with _Sender(port, values=[value] * 5):
        result = subprocess.run(
            [sys.executable, "-m", "mop", "perform", str(session), "--duration", "4",
             "--no-render", "--quiet", "--osc-out", f"127.0.0.1:{out_port}"],
            env=mop_env(), cwd=ROOT, capture_output=True, text=True, timeout=120)
    stop.set()
    listener.join()
    assert result.returncode == 0, result.stderr
    assert len(heard) >= 50                 # 4 s at 25 fps, what was said frame by frame
    played = [a for a in heard if a]
    assert played == [], f"a glove stuck at {value} played {sorted(set(played))}"


@pytest.mark.slow
@needs_small_disk
def test_a_full_disk_during_png_frames_keeps_the_frames_before_it(tmp_path):
    from PIL import Image

    disk, keep = tmp_path / "disk", tmp_path / "keep"
    result = run_on_small_disk(
        ["puppet", str(DATA / "momo.png"), "--motion", str(DATA / "momo_wave.json"), "--out",
         str(disk / "frames")], disk=disk, size_kb=2048, keep=keep)
    assert result.returncode == 1, (result.stdout, result.stderr)
    line = _one_error_line(result.stderr, "mop puppet: error", "no space left",
                           "frames before it are complete")
    frames = sorted((keep / "frames").iterdir())
    assert frames and all(f.suffix == ".png" for f in frames)       # no .part left behind
    assert f"the {len(frames)} frames before it" in line
    for frame in frames:                                             # each one whole
        Image.open(frame).load()
