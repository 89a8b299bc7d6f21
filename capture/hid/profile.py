"""HID device profiles: data files (TOML) that say which devices a profile fits and where each
channel sits in the report bytes. Parsed once into frozen objects; the per-report work is done by
`capture.hid.parse` on the compiled arrays.

A profile file::

    name = "spacemouse"                 # what `hid:NAME` asks for
    title = "3Dconnexion SpaceMouse"    # one line for `mop devices`
    rate = 60.0                         # nominal report rate [Hz]

    [[device]]                          # devices the profile fits (none: only by explicit path)
    vendor_id = 0x046d
    product_id = 0xc626
    name = "SpaceNavigator"

    [[report]]                          # one input report layout
    name = "translation"
    id = 1                              # first byte (omit for devices without report ids)
    length = 7                          # bytes, including the id byte
    [[report.field]]
    channel = "tx"                      # channel name (channels are ordered by first use)
    type = "i16le"                      # u8 i8 u16le i16le u16be i16be u32le i32le f32le, or
    byte = 1                            #   "ubits"/"sbits" with bit = N, width = W, order =
    scale = 0.002857                    #   "lsb" (bit N = byte N//8, bit N%8) or "msb"
    center = 0                          # value = (raw - center) * scale
    unit = "1"                          # documentation
    comment = "push right is positive"  # what the field is (one per field)
    # lookup = [...]                    # raw -> value table (nan allowed), instead of scale

A report may reuse another's fields with a byte shift (the same data in a longer Bluetooth
report): `fields_from = "usb"`, `byte_shift = 2`. A profile with `raw = true` and `length = N`
exposes the report bytes themselves as channels byte0 .. byte{N-1}.
"""
from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

PROFILE_DIR = Path(__file__).resolve().parent.parent / "profiles"
USER_PROFILE_ENV = "MOP_HID_PROFILES"    # extra folders of profiles, os.pathsep-separated

_BYTE_TYPES = {   # type -> (bytes, signed, big-endian, float)
    "u8": (1, False, False, False), "i8": (1, True, False, False),
    "u16le": (2, False, False, False), "i16le": (2, True, False, False),
    "u16be": (2, False, True, False), "i16be": (2, True, True, False),
    "u32le": (4, False, False, False), "i32le": (4, True, False, False),
    "f32le": (4, False, False, True),
}
_BIT_TYPES = {"ubits": False, "sbits": True}
_FIELD_KEYS = {"channel", "type", "byte", "bit", "width", "order", "scale", "center", "lookup",
               "unit", "comment"}
_REPORT_KEYS = {"name", "id", "length", "field", "fields_from", "byte_shift", "comment"}
_PROFILE_KEYS = {"name", "title", "rate", "device", "report", "raw", "length", "comment",
                 "read_size"}
_DEVICE_KEYS = {"vendor_id", "product_id", "name", "comment"}


class ProfileError(ValueError):
    """A profile file that does not describe a valid layout; the message names file and key."""


@dataclass(frozen=True)
class Field:
    """One channel inside a report, resolved to bit arithmetic.

    start : first byte; nbytes : bytes read into one integer word (<= 5); big_endian : word
    assembly order; shift, width : bits taken from the word; signed : two's complement;
    is_float : reinterpret 4 bytes as float32 LE; center, scale : value = (raw - center) * scale;
    lookup : raw -> value table (empty: none)."""
    channel: str
    start: int
    nbytes: int
    big_endian: bool
    shift: int
    width: int
    signed: bool
    is_float: bool
    center: float
    scale: float
    lookup: tuple[float, ...]
    unit: str
    comment: str

    @property
    def end(self) -> int:
        """One past the last byte the field reads."""
        return self.start + self.nbytes


@dataclass(frozen=True)
class Report:
    """One input report layout. report_id None = the device sends no report-id byte."""
    name: str
    report_id: int | None
    length: int
    fields: tuple[Field, ...]
    comment: str = ""
    # compiled arrays for the kernel (see capture.hid.parse.decode_fields)
    arrays: tuple = ()


@dataclass(frozen=True)
class DeviceMatch:
    vendor_id: int
    product_id: int
    name: str = ""


@dataclass(frozen=True)
class Profile:
    """A device profile: channels (D names in order), units (D), reports, devices it fits."""
    name: str
    title: str
    rate: float
    channels: tuple[str, ...]
    units: tuple[str, ...]
    reports: tuple[Report, ...]
    devices: tuple[DeviceMatch, ...]
    raw: bool = False
    read_size: int = 64
    path: Path | None = None

    def matches(self, vendor_id: int, product_id: int) -> bool:
        return any(d.vendor_id == vendor_id and d.product_id == product_id for d in self.devices)

    def device_name(self, vendor_id: int, product_id: int) -> str:
        for d in self.devices:
            if d.vendor_id == vendor_id and d.product_id == product_id:
                return d.name
        return ""

    @property
    def numbered(self) -> bool:
        return any(r.report_id is not None for r in self.reports)


def _fail(path, where: str, message: str):
    raise ProfileError(f"{path}: {where}: {message}")


def _number(table, key, path, where, *, default=None, kind=float):
    value = table.get(key, default)
    if value is None:
        _fail(path, where, f"missing {key!r}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(path, where, f"{key!r} must be a number, got {value!r}")
    if kind is int and not isinstance(value, int):
        _fail(path, where, f"{key!r} must be an integer, got {value!r}")
    return kind(value)


def _unknown(table: Mapping, allowed: set, path, where):
    extra = sorted(set(table) - allowed)
    if extra:
        _fail(path, where, f"unknown key(s) {extra}; expected some of {sorted(allowed)}")


def _field(table: Mapping, path, where: str, length: int) -> Field:
    _unknown(table, _FIELD_KEYS, path, where)
    channel = table.get("channel")
    if not isinstance(channel, str) or not channel:
        _fail(path, where, f"'channel' must be a non-empty string, got {channel!r}")
    where = f"{where} ({channel})"
    kind = table.get("type")
    scale = _number(table, "scale", path, where, default=1.0)
    center = _number(table, "center", path, where, default=0.0)
    lookup = table.get("lookup", [])
    if not isinstance(lookup, list) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in lookup):
        _fail(path, where, f"'lookup' must be a list of numbers, got {lookup!r}")
    if kind in _BYTE_TYPES:
        if "bit" in table or "width" in table or "order" in table:
            _fail(path, where, f"type {kind!r} takes 'byte', not 'bit'/'width'/'order'")
        nbytes, signed, big, is_float = _BYTE_TYPES[kind]
        start = _number(table, "byte", path, where, kind=int)
        shift, width = 0, 8 * nbytes
    elif kind in _BIT_TYPES:
        if "byte" in table:
            _fail(path, where, f"type {kind!r} takes 'bit' and 'width', not 'byte'")
        signed, is_float = _BIT_TYPES[kind], False
        bit = _number(table, "bit", path, where, kind=int)
        width = _number(table, "width", path, where, kind=int)
        order = table.get("order", "lsb")
        if order not in ("lsb", "msb"):
            _fail(path, where, f"'order' must be 'lsb' or 'msb', got {order!r}")
        if not 1 <= width <= 32:
            _fail(path, where, f"'width' must be 1..32 bits, got {width}")
        if bit < 0:
            _fail(path, where, f"'bit' must be >= 0, got {bit}")
        start = bit // 8
        nbytes = (bit + width - 1) // 8 - start + 1
        if order == "lsb":
            # bit N is bit N % 8 of byte N // 8; the word is little-endian
            big, shift = False, bit % 8
        else:
            # bit N counts from the most significant bit of byte 0 (P5 glove packing)
            big, shift = True, 8 * nbytes - (bit % 8) - width
    else:
        _fail(path, where, f"'type' must be one of {sorted(_BYTE_TYPES) + sorted(_BIT_TYPES)}, "
                           f"got {kind!r}")
    if start < 0 or start + nbytes > length:
        _fail(path, where, f"reads bytes {start}..{start + nbytes - 1}, outside the "
                           f"{length}-byte report")
    if lookup and is_float:
        _fail(path, where, "a float field cannot have a lookup table")
    if not (math.isfinite(scale) and math.isfinite(center)):
        _fail(path, where, "'scale' and 'center' must be finite")
    return Field(channel, start, nbytes, big, shift, width, signed, is_float, center, scale,
                 tuple(float(v) for v in lookup), str(table.get("unit", "")),
                 str(table.get("comment", "")))


def _shifted(field: Field, shift: int, length: int, path, where) -> Field:
    moved = Field(field.channel, field.start + shift, field.nbytes, field.big_endian,
                  field.shift, field.width, field.signed, field.is_float, field.center,
                  field.scale, field.lookup, field.unit, field.comment)
    if moved.start < 0 or moved.end > length:
        _fail(path, where, f"field {field.channel!r} shifted by {shift} falls outside the "
                           f"{length}-byte report")
    return moved


def _compile(fields: Iterable[Field], channels: list[str]) -> tuple:
    fields = list(fields)
    lut: list[float] = []
    lut_start, lut_length = [], []
    for f in fields:
        lut_start.append(len(lut))
        lut_length.append(len(f.lookup))
        lut.extend(f.lookup)
    i64 = np.int64
    return (np.array([channels.index(f.channel) for f in fields], i64),
            np.array([f.start for f in fields], i64),
            np.array([f.nbytes for f in fields], i64),
            np.array([f.big_endian for f in fields], np.bool_),
            np.array([f.shift for f in fields], i64),
            np.array([f.width for f in fields], i64),
            np.array([f.signed for f in fields], np.bool_),
            np.array([f.is_float for f in fields], np.bool_),
            np.array([f.center for f in fields], np.float64),
            np.array([f.scale for f in fields], np.float64),
            np.array(lut_start, i64), np.array(lut_length, i64),
            np.array(lut if lut else [0.0], np.float64))


def parse_profile(data: Mapping, *, path: str | Path = "<profile>") -> Profile:
    """Build a Profile from the parsed TOML of a profile file (errors name file and key)."""
    _unknown(data, _PROFILE_KEYS, path, "top level")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        _fail(path, "top level", f"'name' must be a non-empty string, got {name!r}")
    title = str(data.get("title", name))
    rate = _number(data, "rate", path, "top level", default=0.0)
    devices = []
    for index, table in enumerate(data.get("device", [])):
        where = f"device[{index}]"
        _unknown(table, _DEVICE_KEYS, path, where)
        devices.append(DeviceMatch(_number(table, "vendor_id", path, where, kind=int),
                                   _number(table, "product_id", path, where, kind=int),
                                   str(table.get("name", ""))))
    if data.get("raw", False):
        length = _number(data, "length", path, "top level", default=64, kind=int)
        if not 1 <= length <= 4096:
            _fail(path, "top level", f"'length' must be 1..4096 bytes, got {length}")
        channels = [f"byte{i}" for i in range(length)]
        fields = [Field(f"byte{i}", i, 1, False, 0, 8, False, False, 0.0, 1.0, (), "", "")
                  for i in range(length)]
        report = Report("raw", None, length, tuple(fields), "raw report bytes",
                        _compile(fields, channels))
        return Profile(name, title, rate, tuple(channels), ("",) * length, (report,),
                       tuple(devices), raw=True,
                       read_size=int(data.get("read_size", length)),
                       path=Path(path) if path else None)
    tables = data.get("report")
    if not tables:
        _fail(path, "top level", "needs at least one [[report]] (or raw = true)")
    channels: list[str] = []
    units: dict[str, str] = {}
    reports: list[Report] = []
    by_name: dict[str, Report] = {}
    for index, table in enumerate(tables):
        where = f"report[{index}]"
        _unknown(table, _REPORT_KEYS, path, where)
        report_name = str(table.get("name", f"report{index}"))
        where = f"report {report_name!r}"
        report_id = table.get("id")
        if report_id is not None:
            report_id = _number(table, "id", path, where, kind=int)
            if not 0 <= report_id <= 255:
                _fail(path, where, f"'id' must be 0..255, got {report_id}")
        length = _number(table, "length", path, where, kind=int)
        if not 1 <= length <= 4096:
            _fail(path, where, f"'length' must be 1..4096 bytes, got {length}")
        if "fields_from" in table:
            source = by_name.get(table["fields_from"])
            if source is None:
                _fail(path, where, f"'fields_from' names {table['fields_from']!r}, not an "
                                   f"earlier report ({sorted(by_name)})")
            shift = _number(table, "byte_shift", path, where, default=0, kind=int)
            fields = [_shifted(f, shift, length, path, where) for f in source.fields]
        else:
            fields = [_field(t, path, f"{where} field[{i}]", length)
                      for i, t in enumerate(table.get("field", []))]
        if not fields:
            _fail(path, where, "has no fields")
        seen = set()
        for f in fields:
            if f.channel in seen:
                _fail(path, where, f"channel {f.channel!r} appears twice in one report")
            seen.add(f.channel)
            if f.channel not in channels:
                channels.append(f.channel)
                units[f.channel] = f.unit
        report = Report(report_name, report_id, length, tuple(fields),
                        str(table.get("comment", "")))
        reports.append(report)
        by_name[report_name] = report
    keys = [(r.report_id, r.length) for r in reports]
    if len(set(keys)) != len(keys):
        _fail(path, "reports", "two reports share the same id and length")
    if len({r.report_id is None for r in reports}) > 1:
        _fail(path, "reports", "mixes reports with and without an id byte")
    compiled = tuple(Report(r.name, r.report_id, r.length, r.fields, r.comment,
                            _compile(r.fields, channels)) for r in reports)
    read_size = int(data.get("read_size", max(64, max(r.length for r in reports))))
    return Profile(name, title, rate, tuple(channels), tuple(units[c] for c in channels),
                   compiled, tuple(devices), raw=False, read_size=read_size,
                   path=Path(path) if path else None)


def load_profile_file(path: str | Path) -> Profile:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"HID profile file not found: {path}") from None
    except tomllib.TOMLDecodeError as error:
        raise ProfileError(f"{path}: not valid TOML: {error}") from None
    return parse_profile(data, path=path)


def profile_dirs() -> list[Path]:
    """Where profiles are looked up: the folders in $MOP_HID_PROFILES, then the shipped ones."""
    extra = [Path(p) for p in os.environ.get(USER_PROFILE_ENV, "").split(os.pathsep) if p]
    return extra + [PROFILE_DIR]


_CACHE: dict[Path, tuple[float, Profile]] = {}


def _cached(path: Path) -> Profile:
    mtime = path.stat().st_mtime
    hit = _CACHE.get(path)
    if hit is None or hit[0] != mtime:
        hit = (mtime, load_profile_file(path))
        _CACHE[path] = hit
    return hit[1]


def available_profiles() -> dict[str, Profile]:
    """{name: Profile} of every profile file found (user folders override shipped ones)."""
    found: dict[str, Profile] = {}
    for folder in reversed(profile_dirs()):
        if folder.is_dir():
            for path in sorted(folder.glob("*.toml")):
                profile = _cached(path.resolve())
                found[profile.name] = profile
    return found


def load_profile(name_or_path: str | Path | Profile) -> Profile:
    """A profile by name ("p5", "spacemouse", "dualshock4", "dualsense", "generic") or by the
    path of a .toml file."""
    if isinstance(name_or_path, Profile):
        return name_or_path
    text = str(name_or_path)
    if text.endswith(".toml"):
        return load_profile_file(text)
    profiles = available_profiles()
    try:
        return profiles[text]
    except KeyError:
        raise ValueError(f"unknown HID profile {text!r}; available: "
                         f"{', '.join(sorted(profiles))} (or give a .toml file)") from None
