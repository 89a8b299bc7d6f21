"""Takes: a performer's recorded action paired with the motion that played, and the folder of
take files they live in.

A take file is one `capture.store` SQLite file, `<folder>/<name>.sqlite`:
- stream "action" (and any further streams): the raw action frames, times [s] from the moment
  the motion started playing, values (N, D), NaN = missing;
- attachment "motion": the paired `characters.Motion` as `Motion.to_dict()`;
- metadata: {"kind": "mop.take", "version": 1, "performer", "action", "rate" [Hz, the session
  rate templates are sampled at], "device" (source spec), "source" (what the source reported),
  "calibration", "alignment", "clock_start" [s, capture clock at the motion start], ...}.

Time alignment (MOP section 3.1.3): action X and motion Y must have the same length before a
follower is trained. `alignment` records the action interval [action_start, action_end] [s]
that corresponds to the whole motion; `Take.aligned()` maps it linearly onto [0, duration] and
samples it at the take's rate (`capture.resample.align_durations`). The raw action is kept, so
a take can be re-aligned or re-simulated later.

Files are written while recording (`TakeStore.record`), so a crash keeps all but the last
~50 ms; such a take loads with `complete=False`. A damaged file raises `TakeError`; its
`salvaged` holds the take as far as it could be read (`load(name, salvage=True)` returns it).
"""
from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from capture.resample import align_durations
from capture.store import (SUFFIX, StoreContents, StoreError, StoreWriter, fold_wal, read_info,
                           read_store, remove_store_file)
from capture.store import repair as repair_store

KIND = "mop.take"
VERSION = 1
ACTION_STREAM = "action"
MOTION_ATTACHMENT = "motion"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")


class TakeError(ValueError):
    """A take file that cannot be read as a take; `salvaged` is the Take as far as it could be
    read (complete=False, `problems` says what is missing), or None."""

    def __init__(self, message: str, *, salvaged: "Take | None" = None):
        super().__init__(message)
        self.salvaged = salvaged


def _motion_class():
    from characters import Motion
    return Motion


@dataclass(frozen=True)
class ActionStream:
    """Raw frames of one input: times (N,) float [s] from the motion start, values (N, D) float
    (NaN = missing), channels (D names), rate [Hz] (nominal), device (what the source reported)."""
    times: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    rate: float = 0.0
    device: Mapping = field(default_factory=dict)

    def __post_init__(self):
        times = np.asarray(self.times, dtype=np.float64)
        values = np.asarray(self.values, dtype=np.float64)
        if values.ndim == 1:
            values = values[:, None]
        if times.ndim != 1 or values.ndim != 2 or values.shape[0] != times.shape[0]:
            raise ValueError(f"an action stream needs times (N,) and values (N, D), got "
                             f"{times.shape} and {values.shape}")
        if len(self.channels) != values.shape[1]:
            raise ValueError(f"an action stream with {values.shape[1]} values per frame needs "
                             f"{values.shape[1]} channel names, got {len(self.channels)}")
        if times.size > 1 and np.any(np.diff(times) < 0):
            raise ValueError("action stream times must be non-decreasing")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "channels", tuple(str(c) for c in self.channels))


@dataclass
class Take:
    """One recorded action paired with its motion.

    performer, action : names; streams : {name: ActionStream}, "action" is the main one;
    motion : characters.Motion | None; rate : [Hz] session rate for templates; device : source
    spec; calibration : JSON dict (camera intrinsics, ranges, ...); alignment : {"method",
    "action_start", "action_end", "motion_duration"} [s]; extra : other metadata.
    """
    performer: str
    action: str
    streams: dict[str, ActionStream]
    motion: Any = None
    rate: float = 50.0
    device: str = ""
    calibration: dict = field(default_factory=dict)
    alignment: dict = field(default_factory=dict)
    created: str = ""
    name: str = ""
    complete: bool = True
    problems: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        for label, value in (("performer", self.performer), ("action", self.action)):
            if not isinstance(value, str) or not value:
                raise ValueError(f"a take needs a non-empty {label} name, got {value!r}")
        if ACTION_STREAM not in self.streams:
            raise ValueError(f"a take needs an {ACTION_STREAM!r} stream, got "
                             f"{list(self.streams)}")
        if not self.rate > 0:
            raise ValueError(f"a take's rate must be > 0 Hz, got {self.rate!r}")

    # -- the main stream ------------------------------------------------------------------
    @property
    def stream(self) -> ActionStream:
        return self.streams[ACTION_STREAM]

    @property
    def times(self) -> np.ndarray:
        """(N,) float [s] of the action frames."""
        return self.stream.times

    @property
    def values(self) -> np.ndarray:
        """(N, D) float raw action values."""
        return self.stream.values

    @property
    def channels(self) -> tuple[str, ...]:
        return self.stream.channels

    @property
    def duration(self) -> float:
        """[s] of the motion (or of the captured action when there is no motion)."""
        if self.motion is not None and self.motion.duration > 0:
            return float(self.motion.duration)
        times = self.times
        return float(times[-1] - times[0]) if times.size > 1 else 0.0

    # -- time alignment (MOP 3.1.3) ---------------------------------------------------------
    def action_interval(self) -> tuple[float, float]:
        """[start, end] [s] of the action that pairs with the whole motion."""
        times = self.times
        if times.size < 2:
            raise ValueError(f"take {self.name or self.action!r} has {times.size} action "
                             f"frame(s); at least 2 are needed to align it")
        start = float(self.alignment.get("action_start", times[0]))
        end = float(self.alignment.get("action_end", times[-1]))
        return start, end

    def aligned(self, rate: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The action normalised to the motion's duration and sampled at `rate` (default the
        take's): (grid (T,) float [s] in motion time, X (T, D) float). X is the template a
        follower learns; the motion sampled at `grid` is the paired Y."""
        start, end = self.action_interval()
        return align_durations(self.times, self.values, start=start, end=end,
                               duration=self.duration, rate=rate or self.rate)

    def motion_table(self, times) -> tuple[list[str], np.ndarray]:
        """The motion sampled at times (T,) [s]: (column names, (T, C) float); a channel with c
        components gives columns name.0 .. name.{c-1} (just name when c = 1)."""
        if self.motion is None:
            return [], np.zeros((len(times), 0))
        sampled = self.motion.sample_many(np.asarray(times, dtype=np.float64))
        names, columns = [], []
        for name, block in sampled.items():
            block = np.asarray(block, dtype=np.float64).reshape(len(times), -1)
            if block.shape[1] == 1:
                names.append(name)
            else:
                names.extend(f"{name}.{i}" for i in range(block.shape[1]))
            columns.append(block)
        return names, (np.concatenate(columns, axis=1) if columns
                       else np.zeros((len(times), 0)))

    def metadata(self) -> dict:
        """The JSON metadata stored with the take."""
        meta = dict(self.extra)
        meta.update(kind=KIND, version=VERSION, performer=self.performer, action=self.action,
                    rate=self.rate, device=self.device, calibration=self.calibration,
                    alignment=self.alignment,
                    motion_duration=None if self.motion is None else self.motion.duration)
        return meta


@dataclass(frozen=True)
class TakeInfo:
    """A line of `TakeStore.list()`: enough to choose a take without loading its frames."""
    name: str
    performer: str
    action: str
    duration: float
    frames: int
    channels: tuple[str, ...]
    complete: bool
    created: str
    problem: str = ""


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def check_name(name: str) -> str:
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"take names use letters, digits, '.', '_' and '-' (at most 128, "
                         f"starting with a letter or digit), got {name!r}")
    return name


def _take_from_contents(contents: StoreContents, name: str) -> Take:
    meta = dict(contents.metadata)
    kind = meta.pop("kind", None)
    if kind != KIND:
        raise TakeError(f"{contents.path} is a take store file but not a take (kind "
                        f"{kind!r}, expected {KIND!r})")
    version = meta.pop("version", VERSION)
    if not isinstance(version, int) or version > VERSION:
        raise TakeError(f"{contents.path}: take version {version!r} is newer than this mop "
                        f"reads ({VERSION})")
    streams = {}
    for stream_name, stream in contents.streams.items():
        streams[stream_name] = ActionStream(stream.times, stream.values, stream.channels,
                                            stream.rate, stream.metadata.get("device", {}))
    problems = list(contents.problems)
    if ACTION_STREAM not in streams:
        problems.append("no action stream was recorded")
        streams[ACTION_STREAM] = ActionStream(np.zeros(0), np.zeros((0, 0)), ())
    motion = None
    motion_data = contents.attachments.get(MOTION_ATTACHMENT)
    if motion_data is not None:
        try:
            motion = _motion_class().from_dict(motion_data)
        except (ValueError, TypeError) as error:
            problems.append(f"the motion could not be read: {error}")
    rate = meta.pop("rate", 50.0)
    meta.pop("motion_duration", None)
    return Take(performer=str(meta.pop("performer", "?") or "?"),
                action=str(meta.pop("action", "?") or "?"), streams=streams, motion=motion,
                rate=float(rate) if isinstance(rate, (int, float)) and rate > 0 else 50.0,
                device=str(meta.pop("device", "")), calibration=dict(meta.pop("calibration", {})
                                                                     or {}),
                alignment=dict(meta.pop("alignment", {}) or {}), created=contents.created,
                name=name, complete=contents.complete, problems=problems, extra=meta)


class TakeRecorder:
    """Writes one take while it is being captured (from `TakeStore.record`).

    Frames are given on the capture clock; they are stored relative to `start` (the moment
    the motion started). Commits happen in the background at least every 50 ms."""

    def __init__(self, store: "TakeStore", name: str, take_metadata: dict, *,
                 motion=None, start: float | None = None, channels: Sequence[str] | None = None,
                 stream_rate: float = 0.0, device_info: Mapping | None = None,
                 commit_interval: float = 0.05):
        self.store = store
        self.name = name
        self.path = store.file(name)
        self.start = start
        self._metadata = dict(take_metadata)
        self._stream_rate = stream_rate
        self._device_info = dict(device_info or {})
        self.writer = StoreWriter(self.path, metadata=self._metadata,
                                  commit_interval=commit_interval)
        if motion is not None:
            self.writer.put_attachment(MOTION_ATTACHMENT, motion.to_dict())
        self.channels: tuple[str, ...] | None = None
        if channels:
            self._open_stream(channels)
        self.frames = 0
        self.last_t: float | None = None

    def _open_stream(self, channels: Sequence[str]) -> None:
        self.channels = tuple(channels)
        self.writer.add_stream(ACTION_STREAM, self.channels, rate=self._stream_rate,
                               metadata={"device": self._device_info})

    def append(self, t: float, values, *, channels: Sequence[str] | None = None) -> None:
        """One frame: t [s] on the capture clock, values (D,). `channels` names them if the
        stream was not declared yet (e.g. an OSC source that learns its channels)."""
        if self.channels is None:
            if not channels:
                raise ValueError("the action stream's channels are not known yet: pass "
                                 "channels= with the first frame")
            self._open_stream(channels)
        if self.start is None:
            self.start = float(t)
            self.update(clock_start=self.start)
        self.writer.append(ACTION_STREAM, float(t) - self.start, values)
        self.frames += 1
        self.last_t = float(t)

    def append_frame(self, frame, channels: Sequence[str] | None = None) -> None:
        """A `capture.Frame`."""
        self.append(frame.t, frame.values, channels=channels)

    def update(self, **metadata) -> None:
        """Add or change metadata keys (committed at once)."""
        self._metadata.update(metadata)
        self.writer.set_metadata(self._metadata)

    def finish(self, *, alignment: Mapping | None = None) -> str:
        """Store the alignment, mark the take complete, close the file; returns the name."""
        if self.channels is None:
            self.abort()
            raise ValueError(f"take {self.name!r} received no frame: nothing was stored")
        if alignment is not None:
            self._metadata["alignment"] = dict(alignment)
            self.writer.set_metadata(self._metadata)
        self.writer.close(complete=True)
        return self.name

    def abort(self) -> None:
        """Close without marking the take complete (it stays readable as interrupted). A write
        failure that caused the abort was raised already: closing does not raise it again."""
        try:
            self.writer.close(complete=False)
        except OSError:
            pass

    @property
    def frames_kept(self) -> int:
        """Frames committed to the file (what a crash or a full disk cannot take away)."""
        return self.writer.stats.frames

    def discard(self) -> None:
        """Close and delete the file."""
        self.writer.close(complete=False)
        remove_store_file(self.path)

    def __enter__(self) -> "TakeRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()


class TakeStore:
    """A folder of take files (`<name>.sqlite`).

    store = TakeStore("recordings")
    name = store.save(take)                  # write a whole take programmatically
    with store.record(performer="ana", action="wave", motion=motion, channels=src.channels,
                      device=spec) as rec:   # write while capturing
        rec.append(frame.t, frame.values); ...; rec.finish(alignment={...})
    store.list(); store.load(name); store.export(name, "wave.npz"); store.delete(name)
    """

    def __init__(self, folder: str | os.PathLike, *, create: bool = True):
        self.path = Path(folder)
        if self.path.exists() and not self.path.is_dir():
            raise ValueError(f"a take store is a folder; {self.path} is a file")
        if create:
            self.path.mkdir(parents=True, exist_ok=True)
        elif not self.path.is_dir():
            raise FileNotFoundError(f"take folder not found: {self.path}")

    def __repr__(self) -> str:
        return f"TakeStore({str(self.path)!r})"

    # -- names ------------------------------------------------------------------------------
    def file(self, name: str) -> Path:
        return self.path / f"{check_name(name)}{SUFFIX}"

    def names(self) -> list[str]:
        return sorted(p.name[:-len(SUFFIX)] for p in self.path.glob(f"*{SUFFIX}")
                      if _NAME.match(p.name[:-len(SUFFIX)]))

    def __contains__(self, name: str) -> bool:
        return isinstance(name, str) and bool(_NAME.match(name)) and self.file(name).is_file()

    def new_name(self, performer: str, action: str) -> str:
        """<performer>-<action>-NNN, the first number not taken."""
        stem = re.sub(r"[^A-Za-z0-9._-]+", "_", f"{performer}-{action}").strip("._-") or "take"
        for number in range(1, 100000):
            name = f"{stem}-{number:03d}"
            if not self.file(name).exists():
                return name
        raise ValueError(f"no free take name for {stem!r}")

    # -- listing ----------------------------------------------------------------------------
    def list(self, *, performer: str | None = None) -> list[TakeInfo]:
        """A TakeInfo per take file, by name; damaged files are listed with their problem."""
        infos = []
        for name in self.names():
            try:
                self.fold(name)
                info = read_info(self.file(name))
            except (StoreError, OSError) as error:
                infos.append(TakeInfo(name, "?", "?", 0.0, 0, (), False, "", str(error)))
                continue
            meta = info["metadata"]
            if meta.get("kind") != KIND:
                infos.append(TakeInfo(name, "?", "?", 0.0, 0, (), info["complete"],
                                      info["created"], f"not a take (kind {meta.get('kind')!r})"))
                continue
            stream = info["streams"].get(ACTION_STREAM, {})
            duration = meta.get("motion_duration")
            if not isinstance(duration, (int, float)) or not info["complete"]:
                # an interrupted take is as long as what it holds, not as what was planned
                start, end = stream.get("start"), stream.get("end")
                duration = (end - start) if start is not None and end is not None else 0.0
            entry = TakeInfo(name, str(meta.get("performer", "?")), str(meta.get("action", "?")),
                             float(duration), int(stream.get("frames", 0)),
                             tuple(stream.get("channels", ())), info["complete"],
                             info["created"],
                             "" if info["complete"] else "interrupted recording")
            if performer is None or entry.performer == performer:
                infos.append(entry)
        return infos

    # -- reading ----------------------------------------------------------------------------
    def load(self, name: str, *, salvage: bool = False) -> Take:
        """The take called `name` (KeyError if there is none). A damaged file raises TakeError
        (with `.salvaged`), or with salvage=True returns what could be read."""
        path = self.file(name)
        if not path.is_file():
            raise KeyError(f"no take {name!r} in {self.path}")
        try:
            self.fold(name)
            contents = read_store(path)
        except StoreError as error:
            salvaged = None
            if error.salvaged is not None:
                try:
                    salvaged = _take_from_contents(error.salvaged, name)
                    salvaged.complete = False
                except (TakeError, ValueError):
                    salvaged = None
            if salvage and salvaged is not None:
                return salvaged
            hint = "" if salvaged is None else (
                f"; {salvaged.values.shape[0]} action frames can be salvaged with "
                f"load({name!r}, salvage=True) or `mop takes show {name} --salvage`")
            raise TakeError(f"take {name!r}: {error}{hint}", salvaged=salvaged) from None
        return _take_from_contents(contents, name)

    def fold(self, name: str) -> bool:
        """Fold the WAL a killed recording left beside take `name` back into its file (True
        when it did; False when there was none, or it is being recorded, or the folder is
        read-only). A WAL that belongs to another file raises StoreError."""
        return fold_wal(self.file(name))

    def repair(self, name: str) -> list[str]:
        """Make take `name`'s file whole (`capture.store.repair`): what was done, a line each."""
        path = self.file(name)
        if not path.is_file():
            raise KeyError(f"no take {name!r} in {self.path}")
        return repair_store(path)

    # -- writing ----------------------------------------------------------------------------
    def record(self, *, performer: str, action: str, channels: Sequence[str] | None = None,
               motion=None, rate: float = 50.0, device: str = "",
               device_info: Mapping | None = None, stream_rate: float = 0.0,
               calibration: Mapping | None = None, name: str | None = None,
               start: float | None = None, extra: Mapping | None = None,
               commit_interval: float = 0.05) -> TakeRecorder:
        """Start writing a take while it is captured. `start` is the capture-clock time the
        motion started (default: the first frame's time)."""
        name = check_name(name) if name else self.new_name(performer, action)
        if self.file(name).exists():
            raise FileExistsError(f"take {name!r} already exists in {self.path}")
        probe = Take(performer, action, {ACTION_STREAM: ActionStream(np.zeros(0),
                                                                     np.zeros((0, 0)), ())},
                     motion=motion, rate=rate, device=device,
                     calibration=dict(calibration or {}), extra=dict(extra or {}))
        meta = probe.metadata()
        if start is not None:
            meta["clock_start"] = float(start)
        return TakeRecorder(self, name, meta, motion=motion, start=start, channels=channels,
                            stream_rate=stream_rate, device_info=device_info,
                            commit_interval=commit_interval)

    def save(self, take: Take, *, name: str | None = None, overwrite: bool = False) -> str:
        """Write a whole take; returns its name (take.name, `name`, or a new one)."""
        name = check_name(name or take.name) if (name or take.name) else \
            self.new_name(take.performer, take.action)
        path = self.file(name)
        if path.exists() and not overwrite:
            raise FileExistsError(f"take {name!r} already exists in {self.path} (pass "
                                  f"overwrite=True to replace it)")
        meta = take.metadata()
        with StoreWriter(path, metadata=meta, overwrite=overwrite,
                         created=take.created or None) as writer:
            if take.motion is not None:
                writer.put_attachment(MOTION_ATTACHMENT, take.motion.to_dict())
            for stream_name, stream in take.streams.items():
                writer.add_stream(stream_name, stream.channels, rate=stream.rate,
                                  metadata={"device": dict(stream.device)})
                writer.append_many(stream_name, stream.times, stream.values)
        take.name = name
        return name

    def delete(self, name: str) -> None:
        path = self.file(name)
        if not path.is_file():
            raise KeyError(f"no take {name!r} in {self.path}")
        remove_store_file(path)

    # -- export -----------------------------------------------------------------------------
    def export(self, name: str, destination: str | os.PathLike, *, format: str | None = None,
               salvage: bool = False, overwrite: bool = False) -> list[Path]:
        """Write the take as .npz or CSV; returns the files written.

        npz: action_times (N,), action_values (N, D), action_channels (D,) str, aligned_times
        (T,), aligned_action (T, D), motion_columns (C,) str, motion_values (T, C), and
        metadata_json (a JSON string); further streams as stream_<name>_times/_values/_channels.
        csv: <destination> with t and the raw action channels, and <stem>.aligned.csv with the
        aligned action next to the motion (t, action channels, motion columns). A folder as
        destination (an existing one, or a path ending in '/') gets <folder>/<name>.<format>.
        Existing files are an error (FileExistsError) unless overwrite=True."""
        destination = Path(destination)
        if destination.exists() and not destination.is_dir() and not destination.is_file():
            raise ValueError(f"{destination} is not a regular file or folder (a device or "
                             f"pipe): export to a file")
        folder = destination.is_dir() or str(destination).endswith(("/", os.sep))
        format = (format or ("" if folder else destination.suffix.lstrip(".")) or "npz").lower()
        if format not in ("npz", "csv"):
            raise ValueError(f"export format must be 'npz' or 'csv', got {format!r} (from "
                             f"{destination})")
        if folder:
            destination = destination / f"{check_name(name)}.{format}"
        suffix = f".{format}"
        first = destination if destination.suffix == suffix else \
            destination.with_name(destination.name + suffix)
        targets = [first] if format == "npz" else [first,
                                                   first.with_name(first.stem + ".aligned.csv")]
        existing = [str(t) for t in targets if t.exists()]
        if existing and not overwrite:
            raise FileExistsError(f"{', '.join(existing)} already exist(s): choose another "
                                  f"--out, or pass --force to replace")
        take = self.load(name, salvage=salvage)
        aligned_times, aligned = (take.aligned() if take.times.size >= 2
                                  else (np.zeros(0), np.zeros((0, len(take.channels)))))
        motion_columns, motion_values = take.motion_table(aligned_times)
        destination.parent.mkdir(parents=True, exist_ok=True)
        metadata = take.metadata()
        metadata.update(name=take.name, created=take.created, complete=take.complete,
                        problems=take.problems)
        if format == "npz":
            arrays = {"action_times": take.times, "action_values": take.values,
                      "action_channels": np.array(take.channels, dtype=np.str_),
                      "aligned_times": aligned_times, "aligned_action": aligned,
                      "motion_columns": np.array(motion_columns, dtype=np.str_),
                      "motion_values": motion_values,
                      "metadata_json": np.array(json.dumps(metadata, allow_nan=False))}
            for stream_name, stream in take.streams.items():
                if stream_name != ACTION_STREAM:
                    arrays[f"stream_{stream_name}_times"] = stream.times
                    arrays[f"stream_{stream_name}_values"] = stream.values
                    arrays[f"stream_{stream_name}_channels"] = np.array(stream.channels,
                                                                        dtype=np.str_)
            target = destination if destination.suffix == ".npz" else \
                destination.with_name(destination.name + ".npz")
            np.savez(target, **arrays)
            return [target]
        raw = destination if destination.suffix == ".csv" else \
            destination.with_name(destination.name + ".csv")
        paired = raw.with_name(raw.stem + ".aligned.csv")
        _write_csv(raw, ["t", *take.channels], np.column_stack([take.times, take.values]))
        _write_csv(paired, ["t", *take.channels, *motion_columns],
                   np.column_stack([aligned_times, aligned, motion_values]))
        return [raw, paired]


def _write_csv(path: Path, header: Sequence[str], rows: np.ndarray) -> None:
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for row in rows:
            # repr round-trips a float64 exactly; NaN (missing) is written as an empty cell
            writer.writerow(["" if math.isnan(v) else repr(float(v)) for v in row])


def performer_templates(store: TakeStore, performer: str, *, rate: float,
                        channels: Sequence[str] | None = None,
                        exclude: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """{take name: (T, D) aligned action} of every complete demonstration of `performer` (a
    take with a motion; show takes are performances, not demonstrations) whose action channels
    equal `channels` (default: those of the first take found), sampled at `rate`."""
    templates: dict[str, np.ndarray] = {}
    for info in store.list(performer=performer):
        if info.name in exclude or not info.complete or info.problem:
            continue
        if channels is not None and tuple(info.channels) != tuple(channels):
            continue
        try:
            take = store.load(info.name)
        except (TakeError, KeyError):
            continue
        if take.times.size < 2 or take.motion is None:
            continue
        channels = take.channels
        templates[info.name] = take.aligned(rate)[1]
    return templates


# -- performer calibration takes -----------------------------------------------------------------

CALIBRATION_ACTION = "calibration"
CALIBRATION_KEY = "performer_calibration"   # metadata of a calibration take: {"rest_seconds"}


def is_calibration(take: Take) -> bool:
    """A performer's calibration take (`mop record --calibrate`): the rest pose held, then
    every channel through its range; no motion."""
    return isinstance(take.extra.get(CALIBRATION_KEY), dict)


def calibration_of(take: Take, channels: Sequence[str] | None = None):
    """The `followers.calibration.Calibration` a calibration take measures, over `channels`
    (default: all of the take's). Raises TakeError naming the take when it is not one, lacks
    a channel or cannot be measured."""
    from followers.calibration import REST_SECONDS, measure
    if not is_calibration(take):
        raise TakeError(f"take {take.name!r} is not a calibration take (record one with "
                        f"`mop record --calibrate --performer {take.performer} --source ...`)")
    names = tuple(channels) if channels else take.channels
    missing = [c for c in names if c not in take.channels]
    if missing:
        raise TakeError(f"calibration take {take.name!r} has no channel {missing[0]!r}; it has "
                        f"{', '.join(take.channels)}")
    rest = take.extra[CALIBRATION_KEY].get("rest_seconds", REST_SECONDS)
    if not isinstance(rest, (int, float)) or not 0 < rest < math.inf:
        raise TakeError(f"calibration take {take.name!r}: rest_seconds {rest!r} is not a "
                        f"number of seconds > 0")
    index = [take.channels.index(c) for c in names]
    try:
        return measure(take.values[:, index], take.times, rest_seconds=float(rest),
                       channels=names)
    except ValueError as error:
        raise TakeError(f"calibration take {take.name!r}: {error}") from None


def newest_calibration(store: TakeStore, performer: str,
                       channels: Sequence[str] = ()) -> str | None:
    """The name of `performer`'s newest complete calibration take holding `channels`, or
    None."""
    found = []
    for info in store.list(performer=performer):
        if info.action != CALIBRATION_ACTION or not info.complete or info.problem:
            continue
        if any(c not in info.channels for c in channels):
            continue
        try:
            take = store.load(info.name)
        except (TakeError, KeyError):
            continue
        if is_calibration(take):
            found.append((info.created, info.name))
    return max(found)[1] if found else None
