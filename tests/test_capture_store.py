"""The take store's SQLite file layer: round trips, reading while writing, commit intervals,
foreign / damaged / newer files with clear errors and salvage."""
import sqlite3
import time
from pathlib import Path

import numpy as np
import pytest

from capture.store import (SCHEMA_VERSION, StoreError, StoreWriter, read_attachment, read_info,
                           read_store, salvage)


def write_sample(path, rng, frames=500, width=4):
    times = np.cumsum(rng.uniform(0.001, 0.02, frames))
    values = rng.normal(size=(frames, width))
    values[rng.random((frames, width)) < 0.05] = np.nan
    with StoreWriter(path, metadata={"performer": "ana", "nested": {"k": [1, 2]}}) as writer:
        writer.add_stream("action", [f"c{i}" for i in range(width)], rate=100.0,
                          metadata={"device": "osc"})
        writer.append_many("action", times[:100], values[:100])
        for t, row in zip(times[100:], values[100:]):
            writer.append("action", t, row)
        writer.add_stream("extra", ["x"], rate=10.0)
        writer.append("extra", 0.5, [7.0])
        writer.put_attachment("motion", {"channels": {"jaw": [0, 1]}})
    return times, values


def test_round_trip_is_exact_and_leaves_one_self_contained_file(tmp_path, rng):
    path = tmp_path / "take.sqlite"
    times, values = write_sample(path, rng)
    contents = read_store(path)
    assert contents.complete and contents.problems == []
    assert contents.schema_version == SCHEMA_VERSION
    assert contents.metadata == {"performer": "ana", "nested": {"k": [1, 2]}}
    action = contents.streams["action"]
    np.testing.assert_array_equal(action.times, times)
    np.testing.assert_array_equal(action.values, values)      # NaN where NaN was written
    assert action.channels == ("c0", "c1", "c2", "c3") and action.rate == 100.0
    assert action.metadata == {"device": "osc"}
    assert contents.streams["extra"].values.tolist() == [[7.0]]
    assert contents.attachments == {"motion": {"channels": {"jaw": [0, 1]}}}
    assert read_attachment(path, "motion") == {"channels": {"jaw": [0, 1]}}
    info = read_info(path)
    assert info["streams"]["action"]["frames"] == 500 and info["complete"]
    # closed properly: WAL folded back, no companion files, rollback journal mode
    assert not (tmp_path / "take.sqlite-wal").exists()
    db = sqlite3.connect(path)
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    db.close()


def test_frames_are_readable_by_another_connection_within_100_ms(tmp_path):
    path = tmp_path / "live.sqlite"
    writer = StoreWriter(path, commit_interval=0.05)
    try:
        writer.add_stream("action", ["a"])
        db = sqlite3.connect(path)
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        db.close()
        for k in range(40):
            writer.append("action", k * 0.01, [float(k)])
        time.sleep(0.1)
        contents = read_store(path)       # a second reader while the writer is open
        assert contents.streams["action"].values.ravel().tolist() == list(range(40))
        assert not contents.complete
        assert "interrupted" in contents.problems[0]
    finally:
        writer.close()
    assert read_store(path).complete
    assert writer.stats.worst_unsaved_age < 0.1 + 0.05   # commit interval + a commit
    assert writer.stats.frames == 40


def test_writer_validates_its_input(tmp_path):
    with pytest.raises(ValueError, match=r"commit_interval must be in \(0, 0.1\]"):
        StoreWriter(tmp_path / "a.sqlite", commit_interval=0.5)
    with StoreWriter(tmp_path / "b.sqlite") as writer:
        writer.add_stream("action", ["a", "b"])
        with pytest.raises(ValueError, match=r"takes \(2,\) values per frame, got shape \(3,\)"):
            writer.append("action", 0.0, [1, 2, 3])
        with pytest.raises(KeyError, match="no stream 'nope'"):
            writer.append("nope", 0.0, [1, 2])
        with pytest.raises(ValueError, match="already exists"):
            writer.add_stream("action", ["a"])
        with pytest.raises(TypeError, match="JSON-serialisable"):
            writer.put_attachment("bad", {"x": np.zeros(2)})
        with pytest.raises(ValueError, match="must be finite"):
            writer.append("action", float("nan"), [1, 2])
    with pytest.raises(FileExistsError, match="already exists"):
        StoreWriter(tmp_path / "b.sqlite")


def test_a_text_file_is_not_a_take_store(tmp_path):
    path = tmp_path / "notes.sqlite"
    path.write_text("these are my notes\n")
    with pytest.raises(StoreError, match=r"not a mop take store: not an SQLite file \(it "
                                         r"starts with b'these are my not"):
        read_store(path)
    (tmp_path / "empty.sqlite").write_bytes(b"")
    with pytest.raises(StoreError, match="an empty file"):
        read_store(tmp_path / "empty.sqlite")
    with pytest.raises(FileNotFoundError, match="take store not found"):
        read_store(tmp_path / "missing.sqlite")


def test_a_foreign_sqlite_database_is_named_as_such(tmp_path):
    path = tmp_path / "other.sqlite"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE customers (id INTEGER, name TEXT)")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match=r"an SQLite database but not a mop take store "
                                         r"\(application id 0x0, tables: customers\)") as info:
        read_store(path)
    assert info.value.salvaged is not None and info.value.salvaged.streams == {}


def test_a_newer_schema_is_refused_with_what_can_be_salvaged(tmp_path, rng):
    path = tmp_path / "future.sqlite"
    times, values = write_sample(path, rng, frames=50)
    db = sqlite3.connect(path)
    db.execute("UPDATE meta SET value='7' WHERE key='schema_version'")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match="schema 7; this mop reads up to 1: upgrade mop") as info:
        read_store(path)
    np.testing.assert_array_equal(info.value.salvaged.streams["action"].values, values)


def test_a_damaged_file_gives_a_clear_error_and_the_readable_frames(tmp_path, rng):
    path = tmp_path / "damaged.sqlite"
    times, values = write_sample(path, rng, frames=6000, width=8)
    data = bytearray(path.read_bytes())
    page = 4096
    pages = len(data) // page
    for k in range(pages // 2, pages // 2 + 3):          # three pages in the middle of the data
        data[k * page:(k + 1) * page] = rng.integers(0, 256, page, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=r"damaged\.sqlite is damaged .*salvaged \d+ frames "
                                         r"of 'action'") as info:
        read_store(path)
    rescued = info.value.salvaged.streams["action"]
    assert 0 < rescued.times.size < 6000
    # every frame that was salvaged is exactly the frame that was written at that time
    index = np.searchsorted(times, rescued.times)
    np.testing.assert_array_equal(times[index], rescued.times)
    np.testing.assert_array_equal(values[index], rescued.values)
    assert any("unreadable" in p or "skipped" in p for p in info.value.salvaged.problems)
    assert salvage(path).streams["action"].times.size == rescued.times.size


def test_a_truncated_file_salvages_its_beginning(tmp_path, rng):
    path = tmp_path / "cut.sqlite"
    times, values = write_sample(path, rng, frames=6000, width=8)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.6) // 4096 * 4096])
    with pytest.raises(StoreError, match="is damaged") as info:
        read_store(path)
    salvaged = info.value.salvaged
    assert salvaged is not None
    rescued = salvaged.streams.get("action")
    if rescued is not None and rescued.times.size:
        index = np.searchsorted(times, rescued.times)
        np.testing.assert_array_equal(values[index], rescued.values)
        assert rescued.times.size < 6000


def test_repair_salvages_a_damaged_file_and_keeps_the_original(tmp_path, rng):
    from capture.store import repair
    path = tmp_path / "damaged.sqlite"
    times, values = write_sample(path, rng, frames=6000, width=8)
    data = bytearray(path.read_bytes())
    middle = len(data) // 4096 // 2
    data[middle * 4096:(middle + 2) * 4096] = rng.integers(0, 256, 8192, np.uint8).tobytes()
    path.write_bytes(bytes(data))
    done = repair(path)
    assert len(done) == 1 and "damaged.sqlite.damaged" in done[0]
    assert (tmp_path / "damaged.sqlite.damaged").read_bytes() == bytes(data)
    mended = read_store(path)                     # reads without error now
    rescued = mended.streams["action"]
    assert 0 < rescued.times.size < 6000
    index = np.searchsorted(times, rescued.times)
    np.testing.assert_array_equal(values[index], rescued.values)
    assert repair(path) == []                     # healthy now
    assert not list(tmp_path.glob("*.salvaged*"))


def test_an_older_copy_of_a_stores_own_wal_is_refused(tmp_path):
    """A WAL copied away early and put back after the file moved on would take frames away."""
    import shutil
    import subprocess
    import sys

    from capture.store import check_wal_belongs
    path = tmp_path / "live.sqlite"
    script = (
        "import sys, time, os, shutil\n"
        "from capture.store import StoreWriter\n"
        "w = StoreWriter(sys.argv[1], checkpoint_interval=0.3)\n"
        "w.add_stream('a', ['x'])\n"
        "for i in range(40):\n"
        "    w.append('a', i * 0.01, [i]); time.sleep(0.01)\n"
        "w.flush(); shutil.copy(sys.argv[1] + '-wal', sys.argv[1] + '.early-wal')\n"
        "for i in range(40, 200):\n"
        "    w.append('a', i * 0.01, [i]); time.sleep(0.01)\n"
        "w.flush(); time.sleep(0.5)\n"
        "os._exit(0)\n")                          # dies without closing, like kill -9
    env = {**__import__("os").environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    subprocess.run([sys.executable, "-c", script, str(path)], check=True, env=env)
    shutil.copy(f"{path}.early-wal", f"{path}-wal")
    with pytest.raises(StoreError, match="is older than|does not fit"):
        check_wal_belongs(path)
    with pytest.raises(StoreError, match="takes repair"):
        read_store(path)
