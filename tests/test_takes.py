"""Takes and the take folder: the Python API, time alignment, export, damaged files, a recording
killed with SIGKILL, and the `mop takes`, `mop record` and `mop devices` commands."""
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from characters import Motion
from mop.cli import main
from mop.takes import ActionStream, Take, TakeError, TakeStore, check_name, performer_templates

ROOT = Path(__file__).resolve().parent.parent


def motion(duration=2.0):
    return Motion({"hand": ([0.0, duration / 2, duration], [[0, 0], [1, 2], [0, 4]]),
                   "jaw": ([0.0, duration], [0.0, 1.0])})


def sample_take(rng, *, performer="ana", action="wave", frames=120, duration=2.0):
    times = np.linspace(0.0, duration * 1.1, frames)
    values = np.c_[np.sin(times), np.cos(times), rng.normal(size=frames)]
    values[7, 2] = np.nan
    return Take(performer, action, {"action": ActionStream(times, values, ("a", "b", "c"), 60.0,
                                                           {"kind": "osc"})},
                motion=motion(duration), rate=25.0, device="osc:127.0.0.1:9000/glove",
                calibration={"range": [0, 1]},
                alignment={"method": "duration", "action_start": 0.1,
                           "action_end": 0.1 + duration})


def test_save_load_list_delete(tmp_path, rng):
    store = TakeStore(tmp_path / "recordings")
    take = sample_take(rng)
    name = store.save(take)
    assert name == "ana-wave-001" and store.new_name("ana", "wave") == "ana-wave-002"
    loaded = store.load(name)
    assert (loaded.performer, loaded.action, loaded.rate) == ("ana", "wave", 25.0)
    assert loaded.motion == take.motion
    np.testing.assert_array_equal(loaded.times, take.times)
    np.testing.assert_array_equal(loaded.values, take.values)
    assert loaded.channels == ("a", "b", "c") and loaded.stream.rate == 60.0
    assert loaded.stream.device == {"kind": "osc"}
    assert loaded.calibration == {"range": [0, 1]} and loaded.alignment == take.alignment
    assert loaded.complete and loaded.problems == [] and loaded.created
    take.created = "2024-06-11T00:00:00+00:00"
    assert store.load(store.save(take, name="dated")).created == take.created
    store.delete("dated")
    store.save(sample_take(rng, performer="bo", action="nod"))
    infos = store.list()
    assert [i.name for i in infos] == ["ana-wave-001", "bo-nod-001"]
    assert infos[0].duration == 2.0 and infos[0].frames == 120 and infos[0].complete
    assert [i.name for i in store.list(performer="bo")] == ["bo-nod-001"]
    with pytest.raises(FileExistsError, match="already exists"):
        store.save(take, name="ana-wave-001")
    store.delete("bo-nod-001")
    assert store.names() == ["ana-wave-001"] and "bo-nod-001" not in store
    with pytest.raises(KeyError, match="no take 'bo-nod-001'"):
        store.load("bo-nod-001")


def test_names_and_takes_are_validated(rng):
    with pytest.raises(ValueError, match="take names use letters"):
        check_name("../escape")
    with pytest.raises(ValueError, match="non-empty performer"):
        Take("", "wave", {"action": ActionStream([0.0], [[1.0]], ("a",))})
    with pytest.raises(ValueError, match="needs an 'action' stream"):
        Take("ana", "wave", {})
    with pytest.raises(ValueError, match="needs 2 channel names, got 1"):
        ActionStream([0.0, 1.0], np.zeros((2, 2)), ("a",))


def test_alignment_normalises_the_action_interval_onto_the_motion(rng):
    take = sample_take(rng)
    grid, aligned = take.aligned()
    assert grid.size == round(2.0 * 25) + 1 and grid[-1] == pytest.approx(2.0)
    # the action interval [0.1, 2.1] s maps onto [0, 2] s: x(t) = sin(t) sampled there
    np.testing.assert_allclose(aligned[:, 0], np.sin(0.1 + grid), atol=2e-4)
    grid50, aligned50 = take.aligned(50.0)
    assert aligned50.shape == (101, 3)
    columns, table = take.motion_table(grid)
    assert columns == ["hand.0", "hand.1", "jaw"]
    np.testing.assert_allclose(table[:, 2], grid / 2.0)


def test_export_npz_and_csv_round_trip(tmp_path, rng):
    store = TakeStore(tmp_path / "recordings")
    take = sample_take(rng)
    name = store.save(take)
    [npz] = store.export(name, tmp_path / "out" / "wave.npz")
    data = np.load(npz, allow_pickle=False)
    np.testing.assert_array_equal(data["action_values"], take.values)
    assert data["action_channels"].tolist() == ["a", "b", "c"]
    grid, aligned = take.aligned()
    np.testing.assert_array_equal(data["aligned_action"], aligned)
    assert data["motion_columns"].tolist() == ["hand.0", "hand.1", "jaw"]
    meta = json.loads(str(data["metadata_json"]))
    assert meta["performer"] == "ana" and meta["name"] == name and meta["complete"]
    raw, paired = store.export(name, tmp_path / "out" / "wave.csv")
    assert paired.name == "wave.aligned.csv"
    header = raw.read_text().splitlines()[0]
    assert header == "t,a,b,c"
    table = np.genfromtxt(raw, delimiter=",", skip_header=1)     # empty cell -> NaN
    np.testing.assert_array_equal(table, np.c_[take.times, take.values])
    table = np.genfromtxt(paired, delimiter=",", skip_header=1)
    assert table.shape == (grid.size, 1 + 3 + 3)
    with pytest.raises(ValueError, match="export format must be 'npz' or 'csv'"):
        store.export(name, tmp_path / "wave.xlsx")


def test_recorder_writes_while_capturing(tmp_path):
    store = TakeStore(tmp_path)
    with store.record(performer="ana", action="wave", motion=motion(1.0), rate=50.0,
                      device="test", start=100.0) as recorder:
        for k in range(30):
            recorder.append(100.0 + k * 0.02, [k, -k], channels=["x", "y"])
        time.sleep(0.12)
        midway = store.load(recorder.name)        # readable while still being written
        assert midway.values.shape == (30, 2) and not midway.complete
        name = recorder.finish(alignment={"method": "duration", "action_start": 0.0,
                                          "action_end": 1.0})
    take = store.load(name)
    assert take.complete and take.alignment["action_end"] == 1.0
    np.testing.assert_allclose(take.times, np.arange(30) * 0.02)
    assert take.extra["clock_start"] == 100.0


def test_a_take_keeps_its_frames_that_a_late_tracker_delivers_after_the_end(tmp_path):
    from capture import Frame, Status
    from capture.source import Source
    from mop.commands.record import _capture

    class Ticking:
        """A clock that moves 1 ms each time it is read."""
        t = 0.0

        def now(self):
            self.t += 0.001
            return self.t

    class LateTracker(Source):
        """Frames at 100 Hz, each readable 0.3 s after its own time (a tracker behind)."""
        status = Status.OK

        def __init__(self, clock):
            super().__init__(("x",), 100.0, clock=clock)
            self.frames = [Frame(k / 100.0, [k / 100.0]) for k in range(400)]

        def read(self, timeout=None):
            if self.frames and self.frames[0].t + 0.3 <= self.clock.now():
                return self.frames.pop(0)
            return None

    source = LateTracker(Ticking())
    store = TakeStore(tmp_path)
    with store.record(performer="ana", action="wave", motion=motion(1.0), rate=100.0,
                      device="test", channels=["x"], start=0.5) as recorder:
        _capture(source, recorder, start=0.5, duration=1.0, label="wave")
        name = recorder.finish(alignment={"method": "duration", "action_start": 0.0,
                                          "action_end": 1.0})
    take = store.load(name)
    # every frame of [0.5, 1.5], the last 0.3 s of them read after the take's end
    np.testing.assert_allclose(take.times, np.arange(101) / 100.0, atol=1e-9)
    np.testing.assert_allclose(take.values[:, 0], 0.5 + np.arange(101) / 100.0, atol=1e-9)


def test_a_damaged_take_gives_an_error_and_a_salvage(tmp_path, rng):
    store = TakeStore(tmp_path)
    times = np.arange(6000) * 0.01
    values = rng.normal(size=(6000, 8))
    take = Take("ana", "wave", {"action": ActionStream(times, values, tuple("abcdefgh"))},
                motion=motion())
    name = store.save(take)
    path = store.file(name)
    data = bytearray(path.read_bytes())
    middle = len(data) // 4096 // 2 * 4096
    data[middle:middle + 3 * 4096] = rng.integers(0, 256, 3 * 4096, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    with pytest.raises(TakeError, match=r"take 'ana-wave-001': .* is damaged.*can be salvaged "
                                        r"with load\('ana-wave-001', salvage=True\)") as info:
        store.load(name)
    rescued = store.load(name, salvage=True)
    assert not rescued.complete and rescued.problems
    assert 0 < rescued.values.shape[0] < 6000
    index = np.searchsorted(times, rescued.times)
    np.testing.assert_array_equal(values[index], rescued.values)
    assert rescued.motion == take.motion
    assert info.value.salvaged is not None


def test_a_foreign_file_in_the_folder_is_listed_as_damaged(tmp_path, capsys):
    store = TakeStore(tmp_path)
    (tmp_path / "notes.sqlite").write_text("not a database")
    [info] = store.list()
    assert info.name == "notes" and "not an SQLite file" in info.problem
    with pytest.raises(TakeError, match="not an SQLite file"):
        store.load("notes")
    assert main(["takes", "--recordings", str(tmp_path), "list"]) == 0
    assert "notes  DAMAGED: " in capsys.readouterr().out


RECORDER = textwrap.dedent("""\
    import sys, time
    import numpy as np
    from characters import Motion
    from mop.takes import TakeStore
    store = TakeStore(sys.argv[1])
    recorder = store.record(performer="ana", action="wave", channels=["k", "sin", "t"],
                            motion=Motion({"jaw": ([0.0, 30.0], [0.0, 1.0])}), rate=50.0,
                            device="test:generator", name="killed")
    print("ready", flush=True)
    k = 0
    while True:
        t = time.monotonic()
        recorder.append(t, [k, np.sin(k), t])
        # what was captured, through a pipe that outlives the process
        sys.stdout.write(f"{k} {t!r}\\n")
        sys.stdout.flush()
        k += 1
        time.sleep(0.002)
    """)


@pytest.mark.slow
def test_a_recording_killed_with_sigkill_keeps_all_but_the_last_100_ms(tmp_path, capsys):
    folder = tmp_path / "recordings"
    script = tmp_path / "recorder.py"
    script.write_text(RECORDER)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    child = subprocess.Popen([sys.executable, str(script), str(folder)], stdout=subprocess.PIPE,
                             text=True, env=env)
    lines: list[str] = []
    ready = threading.Event()

    def collect():
        for line in child.stdout:
            if line.startswith("ready"):
                ready.set()
            else:
                lines.append(line)

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()
    assert ready.wait(30), "the recorder did not start"
    time.sleep(0.8)
    killed_at = time.monotonic()
    child.send_signal(signal.SIGKILL)
    child.wait(10)
    reader.join(10)
    child.stdout.close()
    captured = [(int(k), float(t)) for k, t in (line.split() for line in lines if line.strip())]
    assert child.returncode == -signal.SIGKILL and len(captured) > 50

    store = TakeStore(folder)
    take = store.load("killed")                    # readable, no salvage needed
    assert not take.complete
    stored = take.values
    count = stored.shape[0]
    # a prefix of what was captured, exactly
    np.testing.assert_array_equal(stored[:, 0], np.arange(count))
    np.testing.assert_array_equal(stored[:, 1], np.sin(np.arange(count)))
    captured_t = np.array([t for _, t in captured])
    np.testing.assert_array_equal(stored[:, 2], captured_t[:count])
    # ... holding everything captured more than 100 ms before the kill
    must_have = int(np.count_nonzero(captured_t < killed_at - 0.100))
    assert count >= must_have, (count, must_have)
    np.testing.assert_allclose(take.times, stored[:, 2] - stored[0, 2])
    assert main(["takes", "--recordings", str(folder), "show", "killed"]) == 0
    out = capsys.readouterr().out
    assert "INTERRUPTED" in out and f"{count} frames" in out


def test_takes_commands(tmp_path, rng, capsys, monkeypatch):
    folder = tmp_path / "recordings"
    store = TakeStore(folder)
    name = store.save(sample_take(rng))
    assert main(["takes", "--recordings", str(folder), "list"]) == 0
    out = capsys.readouterr().out
    assert "ana-wave-001" in out and "wave" in out and "3: a, b, c" in out
    assert main(["takes", "--recordings", str(folder), "show", name]) == 0
    out = capsys.readouterr().out
    assert "performer   ana" in out and "motion      2 channels, 2.000 s: hand, jaw" in out
    assert "1 missing value" in out
    monkeypatch.chdir(tmp_path)
    assert main(["takes", "--recordings", str(folder), "export", name, "--format", "csv"]) == 0
    assert (tmp_path / f"{name}.csv").is_file() and (tmp_path / f"{name}.aligned.csv").is_file()
    assert main(["takes", "--recordings", str(folder), "export", name,
                 "--out", str(tmp_path / "x.npz")]) == 0
    assert (tmp_path / "x.npz").is_file()
    with open(os.devnull) as null:
        monkeypatch.setattr(sys, "stdin", null)
        assert main(["takes", "--recordings", str(folder), "delete", name]) == 1
    assert "refusing to delete" in capsys.readouterr().err
    assert main(["takes", "--recordings", str(folder), "delete", name, "--yes"]) == 0
    assert store.names() == []
    assert main(["takes", "--recordings", str(folder), "show", "nothing"]) == 1
    assert "no take 'nothing'" in capsys.readouterr().err


@pytest.mark.slow
def test_record_command_with_a_replayed_performer(tmp_path, capsys):
    import cv2
    performer = TakeStore(tmp_path / "performer")
    times = np.arange(400) * 0.01                      # 100 Hz for 4 s
    source_values = np.c_[times, np.sin(3 * times)]
    performer.save(Take("someone", "input", {"action": ActionStream(times, source_values,
                                                                    ("x", "y"), 100.0)}),
                   name="input")
    clip = tmp_path / "wave.json"
    motion(0.6).save(clip)
    folder = tmp_path / "recordings"
    preview = tmp_path / "preview.mp4"
    arguments = ["record", "--performer", "bo", "--action", "wave", "--motion", str(clip),
                 "--source", f"replay:{tmp_path / 'performer' / 'input'}", "--recordings",
                 str(folder), "--countdown", "0", "--rate", "25", "--preview", str(preview)]
    assert main(arguments) == 0
    out = capsys.readouterr().out
    assert "stored take bo-wave-001" in out and "confusability" in out
    take = TakeStore(folder).load("bo-wave-001")
    assert take.motion == motion(0.6) and take.complete and take.device.startswith("replay:")
    assert take.alignment == {"method": "duration", "action_start": 0.0, "action_end": 0.6,
                              "motion_duration": 0.6}
    assert 50 <= take.values.shape[0] <= 62                 # 0.6 s of a 100 Hz input
    # what was recorded is a run of consecutive input frames, unchanged
    first = int(round(take.values[0, 0] * 100))
    np.testing.assert_array_equal(take.values,
                                  source_values[first:first + take.values.shape[0]])
    assert np.all(take.times >= 0) and np.all(take.times <= 0.6)
    video = cv2.VideoCapture(str(preview))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 16   # 0.6 s at 25 fps, both ends
    assert (video.get(cv2.CAP_PROP_FRAME_WIDTH), video.get(cv2.CAP_PROP_FRAME_HEIGHT)) == (640,
                                                                                           360)
    video.release()
    # a second action of the same performer is compared with the first
    arguments[arguments.index("wave")] = "nod"
    arguments[arguments.index(str(preview))] = "none"
    assert main(arguments) == 0
    out = capsys.readouterr().out
    assert "stored take bo-nod-001" in out
    assert "confusability" in out and "first take" not in out
    templates = performer_templates(TakeStore(folder), "bo", rate=25.0)
    assert sorted(templates) == ["bo-nod-001", "bo-wave-001"]
    assert templates["bo-wave-001"].shape == (16, 2)
    # the same action again is a numbered take of it: one action of two takes, their
    # consistency reported, compared with the other action as one
    arguments[arguments.index("nod")] = "wave"
    assert main(arguments) == 0
    out = capsys.readouterr().out
    assert "stored take bo-wave-002" in out
    assert re.search(r"2 takes of this action; distance of each from their average "
                     r"\(channel spreads\): bo-wave-001 [\d.]+, bo-wave-002 \(new\) [\d.]+", out)
    assert "confusability of wave with the performer's other actions" in out
    assert re.search(r"^  nod +accepts the new action", out, re.M)


def test_record_command_errors(tmp_path, capsys):
    assert main(["record", "--performer", "bo", "--action", "wave", "--motion",
                 str(tmp_path / "none.json"), "--source", "osc:127.0.0.1:0/x",
                 "--recordings", str(tmp_path)]) == 1
    assert "none.json" in capsys.readouterr().err
    motion(0.5).save(tmp_path / "m.json")
    assert main(["record", "--performer", "bo", "--action", "wave", "--motion",
                 str(tmp_path / "m.json"), "--source", "glove:1",
                 "--recordings", str(tmp_path), "--preview", "none"]) == 1
    assert "KIND one of" in capsys.readouterr().err
    # a device that is not plugged in: one line, no traceback, nothing stored
    assert main(["record", "--performer", "bo", "--action", "wave", "--motion",
                 str(tmp_path / "m.json"), "--source", "hid:p5",
                 "--recordings", str(tmp_path / "none"), "--preview", "none"]) == 1
    assert "no HID device fits profile 'p5'" in capsys.readouterr().err
    assert TakeStore(tmp_path / "none").names() == []


def test_devices_command(capsys):
    assert main(["devices", "--no-cameras"]) == 0
    out = capsys.readouterr().out
    assert "HID profiles:" in out and "spacemouse" in out and "dualshock4" in out
    assert "osc:127.0.0.1:6448/wek/inputs" in out
    assert main(["devices", "--no-cameras", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert set(listing["profiles"]) >= {"p5", "spacemouse", "dualshock4", "dualsense", "generic"}
    assert listing["osc"]["port"] == 6448
