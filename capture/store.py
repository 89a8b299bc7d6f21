"""The take store's file layer: one SQLite file holding timestamped frame streams, metadata and
named JSON attachments, written while capturing.

Crash safety: the file is in WAL mode and a background thread commits whatever was appended at
least every `commit_interval` (default 50 ms). A committed transaction survives the death of the
process (SIGKILL included: it is in the WAL, in the OS page cache), so a killed recording keeps
everything but the last commit interval, and the file opens again as an incomplete take.
`synchronous=NORMAL` trades the last commits on *power loss* for speed; a process crash loses
nothing that was committed. The WAL is checkpointed into the main file every
`checkpoint_interval` (default 1 s), so the `.sqlite` file alone (copied without its `-wal`)
holds all but the last second of a killed recording.

A WAL belongs to its file: each store has a meta row `store_id` = {"id": random hex, "commit":
count} that every write transaction updates, so every WAL carries its own store's row. A reader
that finds a `-wal` beside a file compares the row the main file holds alone with the row seen
through the WAL: another id (a WAL from another file) or a lower count (an older copy of its own
WAL) raises `StoreError` instead of silently replacing the take's content. `repair(path)` moves
such a WAL aside and folds a good one back in (`fold_wal`).

A full disk is `OSError(errno.ENOSPC)` naming the file: when the store is created nothing is
left behind; while recording, the frames committed before the fault stay in the file.

Schema (version 1)::

    meta(key TEXT PRIMARY KEY, value TEXT)        -- JSON values: format, schema_version,
                                                  -- created, complete, metadata
    streams(id INTEGER PRIMARY KEY, name TEXT UNIQUE, channels TEXT, rate REAL, metadata TEXT)
    frames(stream INTEGER, seq INTEGER, t REAL, data BLOB,   -- data: D float64 little-endian
           PRIMARY KEY (stream, seq)) WITHOUT ROWID
    attachments(name TEXT PRIMARY KEY, content TEXT)          -- JSON text

`PRAGMA application_id` is 0x4D4F5054 ("MOPT") and `user_version` the schema version, so a foreign
SQLite file is told apart at once. A damaged or foreign file raises `StoreError`, whose
`salvaged` holds whatever could be read (`salvage(path)` does the same without raising).

This module is usable on its own (numpy and the standard library only); `mop.takes` builds takes
on it and the replay source reads it.
"""
from __future__ import annotations

import datetime as _dt
import errno
import json
import logging
import math
import os
import sqlite3
import threading
import time
import uuid
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence
from urllib.parse import quote

import numpy as np

log = logging.getLogger(__name__)

FORMAT = "mop-take-store"
SCHEMA_VERSION = 1
APPLICATION_ID = 0x4D4F5054          # "MOPT"
SUFFIX = ".sqlite"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_TABLES = ("meta", "streams", "frames", "attachments")
_MAX_ALONE_BYTES = 1 << 30      # a main file read whole to check a WAL's owner (hours of frames)

_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE streams (id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE,
                      channels TEXT NOT NULL, rate REAL NOT NULL, metadata TEXT NOT NULL);
CREATE TABLE frames (stream INTEGER NOT NULL, seq INTEGER NOT NULL, t REAL NOT NULL,
                     data BLOB NOT NULL, PRIMARY KEY (stream, seq)) WITHOUT ROWID;
CREATE TABLE attachments (name TEXT PRIMARY KEY, content TEXT NOT NULL);
"""


class StoreError(ValueError):
    """A file that is not a readable take store. `salvaged` is a `StoreContents` with what could
    be read (and its `problems`), or None when nothing could."""

    def __init__(self, message: str, *, path: Path | str | None = None,
                 salvaged: "StoreContents | None" = None):
        super().__init__(message)
        self.path = Path(path) if path is not None else None
        self.salvaged = salvaged


@dataclass(frozen=True)
class Stream:
    """One stored stream: times (N,) float [s] (capture clock), values (N, D) float64 (NaN =
    missing), channels (D names), rate [Hz] (nominal, 0 = unknown), metadata (JSON dict)."""
    name: str
    channels: tuple[str, ...]
    rate: float
    metadata: dict
    times: np.ndarray
    values: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0]) if self.times.size else 0.0


@dataclass
class StoreContents:
    """Everything in one store file. `complete` is False for a recording that was interrupted;
    `problems` lists what was wrong with a damaged file (empty for a healthy one)."""
    path: Path
    metadata: dict
    streams: dict[str, Stream]
    attachments: dict[str, Any]
    complete: bool
    created: str
    schema_version: int
    problems: list[str] = field(default_factory=list)


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _json(value: Any, what: str) -> str:
    try:
        return json.dumps(value, allow_nan=False, separators=(",", ":"))
    except (TypeError, ValueError) as error:
        raise TypeError(f"{what} must be JSON-serialisable (no NaN, no arrays): {error}") from None


def _is_disk_full(error: BaseException) -> bool:
    if isinstance(error, OSError):
        return error.errno in (errno.ENOSPC, errno.EDQUOT)
    return isinstance(error, sqlite3.Error) and (
        getattr(error, "sqlite_errorcode", None) == 13 or "disk is full" in str(error))


def _storage_error(error: BaseException, path: Path, what: str) -> OSError:
    """An OSError naming the file for a failed write: ENOSPC for a full disk."""
    if _is_disk_full(error):
        return OSError(errno.ENOSPC, f"no space left on the disk: {what}", str(path))
    return OSError(errno.EIO, f"{what} ({type(error).__name__}: {error})", str(path))


# ------------------------------------------------------------------------------------------
# writing


@dataclass
class WriterStats:
    """What a writer measured: commits made, frames written, the longest gap between two
    commits while frames were waiting [s], and the oldest a frame ever got before its commit [s]
    (the most a crash could lose)."""
    commits: int = 0
    frames: int = 0
    worst_commit_interval: float = 0.0
    worst_unsaved_age: float = 0.0
    commit_seconds: list[float] = field(default_factory=list)


class StoreWriter:
    """Writes one store file while capturing; thread-safe.

    Parameters
    ----------
    path : the new file (`.sqlite`); an existing file is an error unless overwrite=True.
    metadata : JSON dict stored with the file (replace later with `set_metadata`).
    commit_interval : [s] between background commits (<= 0.1; default 0.05).
    created : ISO time to record as the creation time (default: now, UTC).
    max_pending : frames allowed to wait for a commit. When more wait, or the oldest waited
        1.5 commit intervals, the append commits in the appending thread (backpressure: a
        producer faster than the disk is slowed to the disk's pace instead of piling up frames
        a crash would lose).
    checkpoint_interval : [s] between WAL checkpoints into the main file (what a copy of the
        `.sqlite` alone holds of a killed recording).
    """

    def __init__(self, path: str | os.PathLike, *, metadata: Mapping | None = None,
                 commit_interval: float = 0.05, overwrite: bool = False,
                 max_pending: int = 5000, created: str | None = None,
                 checkpoint_interval: float = 1.0):
        if not 0 < commit_interval <= 0.1:
            raise ValueError(f"commit_interval must be in (0, 0.1] s so that a crash loses at "
                             f"most 100 ms, got {commit_interval!r}")
        self.path = Path(path)
        if self.path.exists():
            if not overwrite:
                raise FileExistsError(f"{self.path} already exists (pass overwrite=True to "
                                      f"replace it)")
            remove_store_file(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.commit_interval = float(commit_interval)
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        if not checkpoint_interval > 0:
            raise ValueError(f"checkpoint_interval must be > 0 s, got {checkpoint_interval!r}")
        self.checkpoint_interval = float(checkpoint_interval)
        self.max_pending = int(max_pending)
        self.store_id = uuid.uuid4().hex
        self.stats = WriterStats()
        self._db_lock = threading.Lock()
        # appends go to a deque without the commit thread's lock: a lock shared by a tight
        # append loop and the committer starves the committer (Python locks are not fair)
        self._pending: deque[tuple] = deque()
        self._pending_since: float | None = None
        self._append_lock = threading.Lock()     # between appending threads only
        self._flush_lock = threading.Lock()      # between committing threads only
        self._streams: dict[str, tuple[int, int]] = {}      # name -> (id, D)
        self._next_seq: dict[int, int] = {}
        self._last_commit = time.monotonic()
        self._error: BaseException | None = None
        self._closed = False
        self._last_checkpoint = time.monotonic()
        self._commit_count = 0
        meta = {"format": FORMAT, "schema_version": SCHEMA_VERSION,
                "store_id": {"id": self.store_id, "commit": 0},
                "created": str(created) if created else _now_iso(),
                "complete": False, "metadata": dict(metadata or {})}
        rows = [(k, _json(v, f"metadata {k!r}")) for k, v in meta.items()]
        try:
            self._db = sqlite3.connect(str(self.path), check_same_thread=False,
                                       isolation_level=None)
            self._create(rows)
        except (sqlite3.Error, OSError) as error:
            # nothing half-made stays behind as a take
            db = getattr(self, "_db", None)
            if db is not None:
                db.close()
            remove_store_file(self.path)
            raise _storage_error(error, self.path, "the take store could not be created, "
                                                   "nothing was written") from None
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, name="mop-store-commit",
                                         daemon=True)
        self._flusher.start()

    def _create(self, rows) -> None:
        db = self._db
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=NORMAL")
        db.execute(f"PRAGMA application_id={APPLICATION_ID}")
        db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
        db.execute("BEGIN")
        try:
            for statement in _SCHEMA.strip().split(";"):
                if statement.strip():
                    db.execute(statement)
            db.executemany("INSERT INTO meta(key, value) VALUES (?, ?)", rows)
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise
        # the main file holds the schema and the id from the start (a copy without the WAL
        # is a take, not "tables: none")
        self._checkpoint(self._db, strict=True)

    def _checkpoint(self, db: sqlite3.Connection, *, strict: bool = False) -> None:
        """Copy the WAL's committed pages into the main file (PASSIVE: never waits)."""
        try:
            busy, _, _ = db.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchone()
        except sqlite3.Error as error:
            if strict:
                raise
            # the WAL keeps everything: a checkpoint that fails loses nothing
            log.info("take store %s: checkpoint failed: %s", self.path, error)
            return
        if busy and strict:
            log.info("take store %s: checkpoint blocked by a reader", self.path)
        self._last_checkpoint = time.monotonic()

    # -- structure --------------------------------------------------------------------------
    def add_stream(self, name: str, channels: Sequence[str], *, rate: float = 0.0,
                   metadata: Mapping | None = None) -> str:
        """Declare a stream of D = len(channels) values per frame; returns its name."""
        self._check_open()
        if not isinstance(name, str) or not name:
            raise TypeError(f"a stream name must be a non-empty string, got {name!r}")
        if name in self._streams:
            raise ValueError(f"stream {name!r} already exists in {self.path}")
        channels = [str(c) for c in channels]
        if not channels:
            raise ValueError(f"stream {name!r} needs at least one channel")
        cursor = self._execute(
            "INSERT INTO streams(name, channels, rate, metadata) VALUES (?, ?, ?, ?)",
            (name, _json(channels, "channels"), float(rate),
             _json(dict(metadata or {}), f"stream {name!r} metadata")),
            f"stream {name!r} could not be added")
        stream_id = int(cursor.lastrowid)
        self._streams[name] = (stream_id, len(channels))
        self._next_seq[stream_id] = 0
        return name

    def set_metadata(self, metadata: Mapping) -> None:
        """Replace the file's metadata (committed at once)."""
        self._meta("metadata", dict(metadata))

    def put_attachment(self, name: str, content: Any) -> None:
        """Store a JSON-serialisable object under `name` (committed at once)."""
        self._check_open()
        text = _json(content, f"attachment {name!r}")
        self._execute("INSERT OR REPLACE INTO attachments(name, content) VALUES (?, ?)",
                      (str(name), text), f"attachment {name!r} could not be stored")

    def _meta(self, key: str, value: Any) -> None:
        self._check_open()
        text = _json(value, f"metadata {key!r}")
        self._execute("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", (key, text),
                      f"metadata {key!r} could not be stored")

    def _stamp(self) -> None:
        """Inside a transaction: mark it with this store's id and a commit count (what tells a
        WAL's owner and age)."""
        self._commit_count += 1
        self._db.execute("UPDATE meta SET value=? WHERE key='store_id'",
                         (_json({"id": self.store_id, "commit": self._commit_count}, "id"),))

    def _execute(self, statement: str, parameters: tuple, what: str):
        with self._db_lock:
            try:
                self._db.execute("BEGIN")
                cursor = self._db.execute(statement, parameters)
                self._stamp()
                self._db.execute("COMMIT")
                return cursor
            except sqlite3.Error as error:
                if self._db.in_transaction:
                    try:
                        self._db.execute("ROLLBACK")
                    except sqlite3.Error:
                        pass
                if _is_disk_full(error):
                    self._error = _storage_error(
                        error, self.path, f"{what}; the {self.stats.frames} frames committed "
                                          f"before are kept")
                    raise self._error from error
                raise

    # -- frames -----------------------------------------------------------------------------
    def append(self, stream: str, t: float, values) -> None:
        """Queue one frame (t [s], values (D,) float) of `stream`; committed within
        `commit_interval`."""
        stream_id, width = self._stream(stream)
        row = np.ascontiguousarray(values, dtype="<f8")
        if row.shape != (width,):
            raise ValueError(f"stream {stream!r} takes ({width},) values per frame, got shape "
                             f"{row.shape}")
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"frame time must be finite, got {t!r}")
        with self._append_lock:
            seq = self._next_seq[stream_id]
            self._next_seq[stream_id] = seq + 1
            if self._pending_since is None:
                self._pending_since = time.monotonic()
            self._pending.append((stream_id, seq, t, row.tobytes()))
        self._backpressure()

    def append_many(self, stream: str, times, values) -> None:
        """Queue N frames: times (N,) [s], values (N, D)."""
        stream_id, width = self._stream(stream)
        times = np.asarray(times, dtype=np.float64)
        block = np.ascontiguousarray(values, dtype="<f8")
        if times.ndim != 1 or block.shape != (times.shape[0], width):
            raise ValueError(f"stream {stream!r}: expected times (N,) and values (N, {width}), "
                             f"got {times.shape} and {block.shape}")
        if not np.all(np.isfinite(times)):
            raise ValueError("frame times must be finite")
        with self._append_lock:
            first = self._next_seq[stream_id]
            self._next_seq[stream_id] = first + times.shape[0]
            if self._pending_since is None:
                self._pending_since = time.monotonic()
            self._pending.extend((stream_id, first + i, float(t), block[i].tobytes())
                                 for i, t in enumerate(times))
        self._backpressure()

    def _backpressure(self) -> None:
        # the background commit is late (a producer outpacing the disk, or a busy machine):
        # commit here, so that frames never wait much longer than the commit interval
        since = self._pending_since
        if len(self._pending) > self.max_pending or (
                since is not None and time.monotonic() - since > 1.5 * self.commit_interval):
            self.flush()

    def frame_count(self, stream: str) -> int:
        """Frames appended to `stream` so far (committed or not)."""
        stream_id, _ = self._stream(stream)
        return self._next_seq[stream_id]

    def flush(self) -> None:
        """Commit every queued frame now."""
        with self._flush_lock:
            self._flush()

    def _flush(self) -> None:
        since, self._pending_since = self._pending_since, None
        pending = self._pending
        # popleft is atomic; frames appended meanwhile stay for the next commit
        rows = [pending.popleft() for _ in range(len(pending))]
        if not rows:
            return
        if since is None:
            since = time.monotonic()
        started = time.monotonic()
        with self._db_lock:
            try:
                self._db.execute("BEGIN")
                self._db.executemany(
                    "INSERT INTO frames(stream, seq, t, data) VALUES (?, ?, ?, ?)", rows)
                self._stamp()
                self._db.execute("COMMIT")
            except BaseException as error:
                # a failed COMMIT may have ended the transaction already
                if self._db.in_transaction:
                    try:
                        self._db.execute("ROLLBACK")
                    except sqlite3.Error:
                        pass
                if isinstance(error, (sqlite3.Error, OSError)):
                    raise _storage_error(
                        error, self.path, f"a commit of {len(rows)} frames failed; the "
                        f"{self.stats.frames} frames committed before are kept") from error
                raise
        done = time.monotonic()
        stats = self.stats
        stats.commits += 1
        stats.frames += len(rows)
        stats.commit_seconds.append(done - started)
        stats.worst_unsaved_age = max(stats.worst_unsaved_age, done - since)
        if since <= self._last_commit + self.commit_interval:
            # frames were waiting since the previous commit: this gap is a commit interval
            stats.worst_commit_interval = max(stats.worst_commit_interval,
                                              done - self._last_commit)
        self._last_commit = done

    def _flush_loop(self) -> None:
        checkpointer = None
        try:
            while not self._stop.wait(self.commit_interval):
                try:
                    self.flush()
                except BaseException as error:   # disk full, file removed: report next call
                    log.info("take store %s: commit failed: %s", self.path, error)
                    self._error = error
                    return
                if time.monotonic() - self._last_checkpoint >= self.checkpoint_interval:
                    # on a connection of its own and without the writer's lock: commits go on
                    # (from the appending thread) while pages are copied and synced
                    if checkpointer is None:
                        checkpointer = sqlite3.connect(str(self.path), isolation_level=None,
                                                       timeout=0)
                    self._checkpoint(checkpointer)
        finally:
            if checkpointer is not None:
                checkpointer.close()

    # -- end --------------------------------------------------------------------------------
    def close(self, *, complete: bool = True) -> None:
        """Commit what is left, mark the file complete, fold the WAL back into the file (so a
        finished take is a single self-contained file) and close it."""
        if self._closed:
            return
        self._stop.set()
        self._flusher.join()
        try:
            if self._error is None:
                try:
                    self.flush()
                    if complete:
                        self._meta("complete", True)
                except (sqlite3.Error, OSError) as error:
                    self._error = error
        finally:
            self._closed = True
            with self._db_lock:
                try:
                    self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
                    self._db.execute("PRAGMA journal_mode=DELETE")
                except sqlite3.Error as error:
                    # another connection is reading, or the disk is full: the file stays in
                    # WAL mode, just as readable; the WAL is folded in later (fold_wal)
                    log.info("take store %s: left in WAL mode (%s)", self.path, error)
                finally:
                    self._db.close()
        if self._error is not None:
            raise self._failure() from self._error

    def _failure(self) -> OSError:
        error = self._error
        if isinstance(error, OSError) and error.filename is not None:
            return error
        return _storage_error(error, self.path, f"a commit failed; the {self.stats.frames} "
                                                f"frames committed before are kept")

    def __enter__(self) -> "StoreWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(complete=exc_type is None)

    def _stream(self, name: str) -> tuple[int, int]:
        self._check_open()
        try:
            return self._streams[name]
        except KeyError:
            raise KeyError(f"no stream {name!r} in {self.path}; add_stream() it first "
                           f"(streams: {', '.join(self._streams) or 'none'})") from None

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"take store {self.path} is closed")
        if self._error is not None:
            raise self._failure() from self._error


def remove_store_file(path: str | os.PathLike) -> None:
    """Delete a store file with its WAL and shared-memory companions."""
    path = Path(path)
    for companion in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
        try:
            companion.unlink()
        except FileNotFoundError:
            pass


# ------------------------------------------------------------------------------------------
# reading


def _describe_start(path: Path) -> str:
    with open(path, "rb") as handle:
        head = handle.read(16)
    return repr(head[:16]) if head else "an empty file"


def _open_readonly(path: Path, *, check_wal: bool = True) -> sqlite3.Connection:
    if not path.exists():
        raise FileNotFoundError(f"take store not found: {path}")
    if path.is_dir():
        raise StoreError(f"{path} is a folder, not a take store file", path=path)
    if not path.is_file():      # a pipe or a device would block or never end
        raise StoreError(f"{path} is not a regular file (a pipe, socket or device)", path=path)
    with open(path, "rb") as handle:
        head = handle.read(16)
    if head != _SQLITE_MAGIC:
        raise StoreError(f"{path} is not a mop take store: not an SQLite file (it starts with "
                         f"{_describe_start(path)})", path=path)
    wal = _wal_path(path)
    if check_wal and wal.is_file() and wal.stat().st_size > 0:
        check_wal_belongs(path)
    # mode=ro still replays a WAL left by a killed writer (SQLite creates the -shm if needed)
    uri = f"file:{quote(str(path.resolve()))}?mode=ro"
    return sqlite3.connect(uri, uri=True, check_same_thread=False)


def _wal_path(path: Path) -> Path:
    return Path(f"{path}-wal")


def _main_file_alone(path: Path) -> sqlite3.Connection | None:
    """The store as its main file holds it without the WAL (an in-memory copy), or None."""
    if path.stat().st_size > _MAX_ALONE_BYTES:
        log.info("take store %s: too large to check its WAL's owner in memory", path)
        return None
    data = bytearray(path.read_bytes())
    if len(data) < 512 or data[:16] != _SQLITE_MAGIC:
        return None
    data[18] = data[19] = 1        # read as a rollback-journal file: the WAL is not looked at
    db = sqlite3.connect(":memory:")
    try:
        db.deserialize(bytes(data))
        return db
    except sqlite3.Error:
        db.close()
        return None


def _identity(db: sqlite3.Connection) -> tuple[str, int] | None:
    """(store id, commit count); stores written before ids: (creation time, 0)."""
    try:
        meta = {key: json.loads(value) for key, value in db.execute(
            "SELECT key, value FROM meta WHERE key IN ('store_id', 'created')")}
    except (sqlite3.Error, json.JSONDecodeError):
        return None
    stamp = meta.get("store_id")
    if isinstance(stamp, dict) and isinstance(stamp.get("id"), str) \
            and isinstance(stamp.get("commit"), int):
        return stamp["id"], stamp["commit"]
    created = meta.get("created")
    return (str(created), 0) if created else None


def check_wal_belongs(path: str | os.PathLike) -> None:
    """Raise StoreError when the `-wal` beside `path` is not its own: it came from another store
    file (another id), or is an older copy of its own (it would take frames away). A file whose
    main part holds no readable identity (killed before its first checkpoint) is trusted."""
    path = Path(path)
    wal = _wal_path(path)
    alone_db = _main_file_alone(path)
    if alone_db is None:
        return
    try:
        alone = _identity(alone_db)
    finally:
        alone_db.close()
    if alone is None:
        return
    uri = f"file:{quote(str(path.resolve()))}?mode=ro"
    try:
        db = sqlite3.connect(uri, uri=True)
        try:
            through = _identity(db)
        finally:
            db.close()
    except sqlite3.Error:
        through = None
    hint = "it was not applied; `mop takes repair` (or capture.store.repair) moves it aside"
    if through is None:
        raise StoreError(f"{wal} does not fit {path}: read together they are no readable take "
                         f"store (a WAL from another file, or an older copy of its own); {hint}",
                         path=path)
    if through[0] != alone[0]:
        raise StoreError(f"{wal} does not belong to {path}: it holds another take store's "
                         f"pages (store {through[0]}, the file is {alone[0]}); {hint}", path=path)
    if through[1] < alone[1]:
        raise StoreError(f"{wal} is older than {path} itself (commit {through[1]}, the file "
                         f"holds {alone[1]}): applying it would take recorded frames away; "
                         f"{hint}", path=path)


def fold_wal(path: str | os.PathLike) -> bool:
    """Fold a `-wal` left by a killed recording back into its file, so that the file alone is
    the whole take. Returns True when it did; False when there was nothing to fold or the file
    is busy (still being recorded) or cannot be written. A WAL that does not belong raises
    StoreError (see `check_wal_belongs`)."""
    path = Path(path)
    wal = _wal_path(path)
    if not path.is_file():
        return False            # not there, or not a regular file: the reader says what it is
    if not wal.is_file():
        with open(path, "rb") as handle:
            header = handle.read(20)
        if len(header) < 20 or header[18] != 2:
            return False    # not in WAL mode: nothing to fold
    elif wal.stat().st_size > 0:
        check_wal_belongs(path)
    try:
        db = sqlite3.connect(str(path), timeout=0.2, isolation_level=None)
    except sqlite3.Error:
        return False
    try:
        # switching out of WAL mode needs the file to ourselves: a live recording keeps it
        mode = db.execute("PRAGMA journal_mode=DELETE").fetchone()[0]
        return str(mode).lower() == "delete"
    except sqlite3.Error as error:
        log.info("take store %s: WAL not folded (%s)", path, error)
        return False
    finally:
        db.close()


def repair(path: str | os.PathLike) -> list[str]:
    """Make a store file whole again; returns what was done, one line each (empty: healthy).

    A `-wal` that belongs is folded in; one that does not (or is stale) is moved aside as
    `<file>-wal.foreign` (never deleted). A damaged file is salvaged: the damaged original is
    kept as `<file>.damaged` and what could be read is written in its place."""
    path = Path(path)
    done: list[str] = []
    wal = _wal_path(path)
    if wal.is_file():
        try:
            if fold_wal(path):
                done.append("folded the WAL of an interrupted recording back into the file")
        except StoreError as error:
            aside = _free_name(Path(f"{wal}.foreign"))
            os.replace(wal, aside)
            shm = Path(f"{path}-shm")
            if shm.exists():
                shm.unlink()
            fold_wal(path)      # the file alone, out of WAL mode
            reason = str(error).split("; it was not applied")[0]
            done.append(f"moved the WAL aside to {aside.name}: {reason}")
    try:
        read_store(path)
    except StoreError as error:
        salvaged = error.salvaged
        if salvaged is None:
            raise
        # written aside first and renamed: a repair killed midway leaves the original as it was
        fresh = _free_name(Path(f"{path}.salvaged"))
        write_contents(fresh, salvaged)
        kept = _free_name(Path(f"{path}.damaged"))
        os.replace(path, kept)
        os.replace(fresh, path)
        done.append(f"salvaged {_salvage_summary(salvaged)} into a new file; the damaged "
                    f"original is kept as {kept.name}")
    return done


def _free_name(path: Path) -> Path:
    candidate, number = path, 1
    while candidate.exists():
        number += 1
        candidate = path.with_name(f"{path.name}.{number}")
    return candidate


def write_contents(path: str | os.PathLike, contents: StoreContents) -> None:
    """Write a whole StoreContents (e.g. a salvaged one) as a new store file. A contents that
    was not complete stays marked interrupted."""
    with StoreWriter(path, metadata=contents.metadata, created=contents.created or None) as w:
        for name, content in contents.attachments.items():
            w.put_attachment(name, content)
        for name, stream in contents.streams.items():
            w.add_stream(name, stream.channels, rate=stream.rate, metadata=stream.metadata)
            w.append_many(name, stream.times, stream.values)
        if not contents.complete:
            w.close(complete=False)


def _tables(db: sqlite3.Connection) -> list[str]:
    return [row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type='table'")]


def _check_identity(db: sqlite3.Connection, path: Path) -> int:
    """Return the schema version; raise StoreError for a foreign file or a newer schema."""
    tables = _tables(db)
    application_id = db.execute("PRAGMA application_id").fetchone()[0]
    if "meta" not in tables:
        raise StoreError(f"{path} is an SQLite database but not a mop take store (application "
                         f"id {application_id:#x}, tables: {', '.join(tables) or 'none'})",
                         path=path)
    row = db.execute("SELECT value FROM meta WHERE key='format'").fetchone()
    found = json.loads(row[0]) if row else None
    if found != FORMAT:
        raise StoreError(f"{path} is an SQLite database but not a mop take store (format "
                         f"{found!r}, expected {FORMAT!r})", path=path)
    row = db.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
    version = json.loads(row[0]) if row else None
    if not isinstance(version, int):
        raise StoreError(f"{path}: schema_version is {version!r}, expected an integer", path=path)
    if version > SCHEMA_VERSION:
        raise StoreError(f"{path} was written with take store schema {version}; this mop reads "
                         f"up to {SCHEMA_VERSION}: upgrade mop", path=path)
    return version


def _decode_rows(rows: Iterable[tuple], width: int, name: str, problems: list[str] | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    times, blobs, bad = [], [], 0
    expected = 8 * width
    for _seq, t, data in rows:
        if not isinstance(data, (bytes, bytearray)) or len(data) != expected or t is None \
                or not math.isfinite(t):
            bad += 1
            continue
        times.append(t)
        blobs.append(data)
    if bad:
        message = f"stream {name!r}: {bad} frame(s) with a wrong size or time skipped"
        if problems is None:
            raise StoreError(message)
        problems.append(message)
    values = np.frombuffer(b"".join(blobs), dtype="<f8").reshape(len(blobs), width)
    return np.asarray(times, dtype=np.float64), values.astype(np.float64)


def _stream_rows(db, stream_id) -> list[tuple]:
    return db.execute("SELECT seq, t, data FROM frames WHERE stream=? ORDER BY seq",
                      (stream_id,)).fetchall()


def _read_strict(db: sqlite3.Connection, path: Path) -> StoreContents:
    version = _check_identity(db, path)
    meta = {key: json.loads(value) for key, value in db.execute("SELECT key, value FROM meta")}
    streams = {}
    for stream_id, name, channels, rate, metadata in db.execute(
            "SELECT id, name, channels, rate, metadata FROM streams ORDER BY id").fetchall():
        channels = tuple(json.loads(channels))
        times, values = _decode_rows(_stream_rows(db, stream_id), len(channels), name, None)
        streams[name] = Stream(name, channels, float(rate), json.loads(metadata), times, values)
    attachments = {name: json.loads(content)
                   for name, content in db.execute("SELECT name, content FROM attachments")}
    complete = bool(meta.get("complete", False))
    problems = [] if complete else ["the recording did not finish (interrupted): the take ends "
                                    "with its last commit"]
    return StoreContents(path, dict(meta.get("metadata") or {}), streams, attachments,
                         complete, str(meta.get("created", "")), version, problems)


def read_store(path: str | os.PathLike) -> StoreContents:
    """Read a whole store file. An interrupted recording reads fine (complete=False). A damaged
    or foreign file raises StoreError with `.salvaged` set to what could be read."""
    path = Path(path)
    db = _open_readonly(path)
    try:
        return _read_strict(db, path)
    except StoreError as error:
        error.salvaged = _salvage_or_none(path)
        raise
    except (sqlite3.DatabaseError, json.JSONDecodeError, TypeError, ValueError) as error:
        salvaged = _salvage_or_none(path)
        what = "nothing could be salvaged" if salvaged is None else \
            f"salvaged {_salvage_summary(salvaged)}"
        raise StoreError(f"{path} is damaged ({type(error).__name__}: {error}); {what}",
                         path=path, salvaged=salvaged) from None
    finally:
        db.close()


def _salvage_summary(contents: StoreContents) -> str:
    parts = [f"{len(s.times)} frames of {name!r}" for name, s in contents.streams.items()]
    return ", ".join(parts) if parts else "metadata only"


def _salvage_or_none(path: Path) -> StoreContents | None:
    try:
        return salvage(path)
    except Exception:   # the file may be beyond reading at all
        log.debug("salvaging %s failed", path, exc_info=True)
        return None


def salvage(path: str | os.PathLike) -> StoreContents:
    """Read whatever can be read from a damaged store file, row by row where the file is
    broken. `problems` says what was lost. Raises StoreError when the file is not SQLite."""
    path = Path(path)
    db = _open_readonly(path)
    problems: list[str] = []
    try:
        meta: dict = {}
        for key in ("format", "schema_version", "created", "complete", "metadata"):
            try:
                row = db.execute("SELECT value FROM meta WHERE key=?", (key,)).fetchone()
                if row is not None:
                    meta[key] = json.loads(row[0])
            except (sqlite3.DatabaseError, json.JSONDecodeError) as error:
                problems.append(f"meta {key!r} unreadable: {error}")
        if meta.get("format") not in (FORMAT, None):
            problems.append(f"format is {meta.get('format')!r}, expected {FORMAT!r}")
        streams = {}
        try:
            stream_rows = db.execute(
                "SELECT id, name, channels, rate, metadata FROM streams ORDER BY id").fetchall()
        except sqlite3.DatabaseError as error:
            problems.append(f"stream table unreadable: {error}")
            stream_rows = []
        for stream_id, name, channels, rate, metadata in stream_rows:
            try:
                channels = tuple(json.loads(channels))
                metadata = json.loads(metadata)
            except (json.JSONDecodeError, TypeError) as error:
                problems.append(f"stream {name!r}: description unreadable: {error}")
                continue
            rows, lost = _salvage_rows(db, stream_id)
            if lost:
                problems.append(f"stream {name!r}: {lost} unreadable frame range(s) skipped")
            times, values = _decode_rows(rows, len(channels), name, problems)
            streams[name] = Stream(name, channels, float(rate), metadata, times, values)
        attachments = {}
        try:
            names = [row[0] for row in db.execute("SELECT name FROM attachments")]
        except sqlite3.DatabaseError as error:
            problems.append(f"attachment list unreadable: {error}")
            names = []
        for name in names:
            try:
                row = db.execute("SELECT content FROM attachments WHERE name=?",
                                 (name,)).fetchone()
                attachments[name] = json.loads(row[0])
            except (sqlite3.DatabaseError, json.JSONDecodeError, TypeError) as error:
                problems.append(f"attachment {name!r} unreadable: {error}")
        complete = bool(meta.get("complete", False))
        if not complete:
            problems.append("the recording did not finish (interrupted)")
        version = meta.get("schema_version", 0)
        return StoreContents(path, dict(meta.get("metadata") or {}), streams, attachments,
                             complete, str(meta.get("created", "")),
                             version if isinstance(version, int) else 0, problems)
    finally:
        db.close()


def _salvage_rows(db: sqlite3.Connection, stream_id: int, chunk: int = 4096
                  ) -> tuple[list[tuple], int]:
    """Rows of one stream, reading in seq ranges and splitting the ranges that fail until the
    broken rows are isolated. Returns (rows, number of unreadable ranges)."""
    query = "SELECT seq, t, data FROM frames WHERE stream=? AND seq>=? AND seq<? ORDER BY seq"
    try:
        top = db.execute("SELECT max(seq) FROM frames WHERE stream=?", (stream_id,)).fetchone()[0]
        top = -1 if top is None else int(top)
    except sqlite3.DatabaseError:
        top = None          # the index itself is broken: walk until the data runs out
    rows: list[tuple] = []
    lost = 0

    def read_range(low: int, high: int) -> bool:
        nonlocal lost
        try:
            found = db.execute(query, (stream_id, low, high)).fetchall()
        except sqlite3.DatabaseError:
            if high - low <= 1:
                lost += 1
                return False
            middle = (low + high) // 2
            read_range(low, middle)
            read_range(middle, high)
            return True
        rows.extend(found)
        return bool(found)

    low = 0
    empty_runs = 0
    while True:
        if top is not None and low > top:
            break
        found = read_range(low, low + chunk)
        low += chunk
        if top is None:
            empty_runs = 0 if found else empty_runs + 1
            if empty_runs >= 4:
                break
    rows.sort(key=lambda row: row[0])
    return rows, lost


def read_info(path: str | os.PathLike) -> dict:
    """A store's metadata and per-stream frame counts and spans, without loading the frames:
    {"metadata", "complete", "created", "streams": {name: {"channels", "rate", "frames",
    "start", "end"}}}. Raises StoreError for a damaged or foreign file."""
    path = Path(path)
    db = _open_readonly(path)
    try:
        _check_identity(db, path)
        meta = {key: json.loads(value) for key, value in db.execute("SELECT key, value FROM meta")}
        streams = {}
        for stream_id, name, channels, rate in db.execute(
                "SELECT id, name, channels, rate FROM streams ORDER BY id").fetchall():
            count, start, end = db.execute(
                "SELECT count(*), min(t), max(t) FROM frames WHERE stream=?",
                (stream_id,)).fetchone()
            streams[name] = {"channels": json.loads(channels), "rate": rate, "frames": count,
                             "start": start, "end": end}
        attachments = [row[0] for row in db.execute("SELECT name FROM attachments")]
        return {"metadata": dict(meta.get("metadata") or {}),
                "complete": bool(meta.get("complete", False)),
                "created": str(meta.get("created", "")), "streams": streams,
                "attachments": attachments}
    except (sqlite3.DatabaseError, json.JSONDecodeError) as error:
        raise StoreError(f"{path} is damaged ({type(error).__name__}: {error})",
                         path=path) from None
    finally:
        db.close()


def read_attachment(path: str | os.PathLike, name: str) -> Any:
    """One attachment of a store file (KeyError when absent)."""
    path = Path(path)
    db = _open_readonly(path)
    try:
        _check_identity(db, path)
        row = db.execute("SELECT content FROM attachments WHERE name=?", (name,)).fetchone()
    except sqlite3.DatabaseError as error:
        raise StoreError(f"{path} is damaged ({error})", path=path) from None
    finally:
        db.close()
    if row is None:
        raise KeyError(f"{path} has no attachment {name!r}")
    return json.loads(row[0])
