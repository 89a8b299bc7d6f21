"""Fault injection with real faults: a file system that fills up during video output and
during recording, kill -9 of `mop record`, a take copied without its WAL, a stale WAL, absurd
and malformed input over a real OSC socket. Each test asserts the message, the exit code and
that nothing recorded before the fault is lost.

The full disk is a small tmpfs mounted in a private mount namespace (tests/faults.py says how,
and why that is a real ENOSPC); where no namespace can be had the disk tests skip, saying so.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from faults import ROOT, run_on_small_disk, small_disk_prefix

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
@pytest.mark.parametrize("kind, suffix", [("puppet", ".mp4"), ("puppet", ".mkv"),
                                          ("perform", ".mp4"), ("demo", ".mkv")])
def test_a_full_disk_during_video_output_is_an_error_naming_the_file(kind, suffix, tmp_path):
    disk = tmp_path / "disk"
    out = disk / f"out{suffix}"
    result = run_on_small_disk(_video_command(kind, out, tmp_path), disk=disk, size_kb=256)
    assert result.returncode == 1, (result.stdout, result.stderr)
    _one_error_line(result.stderr, f"mop {kind}: error", str(out), "no space left")
    assert f"wrote {out}" not in result.stdout


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
