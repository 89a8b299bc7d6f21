"""HID device profiles: data files (TOML) that say which devices a profile fits and where each
channel sits in the report bytes. Parsed once into frozen objects; the per-report work is done by
`capture.hid.parse` on the compiled arrays.

A profile file::

    name = "spacemouse"                 # what `hid:NAME` asks for
    title = "3Dconnexion SpaceMouse"    # one line for `mop devices`
    rate = 60.0                         # nominal report rate [Hz]
    usage_page = 0x01                   # optional: only HID interfaces with this top-level
    usage = 0x08                        #   usage (per device too); unknown (0) always fits
    calibration = "dualshock4"          # optional: IMU calibration read from the device
                                        #   (see capture.hid.calibration)

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
    # when = {bit = 287, width = 1, equals = 0}   # the value is NaN unless these bits equal

    [[report.status]]                   # a value about the device, not the performer (battery,
    channel = "battery"                 #   cable, sensor clock): same keys as a field; kept
    ...                                 #   apart from the channels (`Profile.status`)

    [[report.skip]]                     # the report carries no input when these bits are equal
    bit = 250                           #   (a receiver with no controller paired): neither
    width = 1                           #   channels nor status are written
    equals = 1
    comment = "no controller connected to the adaptor"

A report may reuse another's fields and status fields with a byte shift (the same data in a
longer Bluetooth report): `fields_from = "usb"`, `byte_shift = 2`; with `truncate = true` only
those that fit in the (shorter) report are taken. Skip rules and `crc32_seed = 0xA1` (the
report ends in a CRC32, little-endian, of that seed byte and the bytes before it; a report
that does not match is malformed) are not inherited. A profile with
`raw = true` and `length = N` exposes the report bytes themselves as channels byte0 ..
byte{N-1}.

Status names with a meaning across profiles (`capture.hid.status`): `battery` (charge 0..1),
`battery_state` (0 discharging, 1 charging, 2 full, 3 not charging; NaN unknown), `cable`
(1 = USB cable plugged in), `sensor_time` [s] (the IMU's own clock; wraps).
"""
from __future__ import annotations

import logging
import math
import os
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

log = logging.getLogger(__name__)

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
               "unit", "comment", "when"}
_CONDITION_KEYS = {"bit", "width", "order", "equals", "comment"}
_REPORT_KEYS = {"name", "id", "length", "field", "status", "skip", "fields_from", "byte_shift",
                "truncate", "crc32_seed", "comment"}
_PROFILE_KEYS = {"name", "title", "rate", "device", "report", "raw", "length", "comment",
                 "read_size", "calibration", "usage_page", "usage"}
_DEVICE_KEYS = {"vendor_id", "product_id", "name", "comment", "usage_page", "usage"}
CALIBRATIONS = ("dualshock4", "dualsense")     # readers in capture.hid.calibration

# columns of a compiled layout (see capture.hid.parse.decode_fields); COND_START = -1: no
# condition
(L_INDEX, L_START, L_NBYTES, L_BIG, L_SHIFT, L_WIDTH, L_SIGNED, L_FLOAT, L_LUT_START,
 L_LUT_LENGTH, L_COND_START, L_COND_NBYTES, L_COND_BIG, L_COND_SHIFT, L_COND_WIDTH,
 L_COND_EQUALS) = range(16)
LAYOUT_COLUMNS = 16


class ProfileError(ValueError):
    """A profile file that does not describe a valid layout; the message names file and key."""


@dataclass(frozen=True)
class Bits:
    """Where an integer sits in a report: `nbytes` (<= 5) bytes from `start` assembled into one
    word (big-endian when `big_endian`), then `width` bits taken from bit `shift` of it."""
    start: int
    nbytes: int
    big_endian: bool
    shift: int
    width: int

    @property
    def end(self) -> int:
        """One past the last byte read."""
        return self.start + self.nbytes

    def raw(self, data: bytes) -> int:
        """The unsigned bits, with Python integers (the slow, obvious reference)."""
        word = int.from_bytes(bytes(data[self.start:self.end]),
                              "big" if self.big_endian else "little")
        return (word >> self.shift) & ((1 << self.width) - 1)

    def shifted(self, by: int) -> "Bits":
        return replace(self, start=self.start + by)


@dataclass(frozen=True)
class Condition:
    """`bits` equal to `equals` (a field's `when`, a report's `skip`)."""
    bits: Bits
    equals: int
    comment: str = ""

    def holds(self, data: bytes) -> bool:
        return self.bits.raw(data) == self.equals

    def shifted(self, by: int) -> "Condition":
        return replace(self, bits=self.bits.shifted(by))


@dataclass(frozen=True)
class Field:
    """One channel (or status value) inside a report, resolved to bit arithmetic.

    bits : where the raw integer sits; signed : two's complement; is_float : reinterpret 4
    bytes as float32 LE; center, scale : value = (raw - center) * scale; lookup : raw -> value
    table (empty: none); when : the value is NaN unless this condition holds (None: always)."""
    channel: str
    bits: Bits
    signed: bool
    is_float: bool
    center: float
    scale: float
    lookup: tuple[float, ...]
    unit: str
    comment: str
    when: Condition | None = None

    @property
    def start(self) -> int:
        return self.bits.start

    @property
    def end(self) -> int:
        """One past the last byte the field (and its condition) reads."""
        return max(self.bits.end, self.when.bits.end if self.when else 0)

    def shifted(self, by: int) -> "Field":
        return replace(self, bits=self.bits.shifted(by),
                       when=self.when.shifted(by) if self.when else None)


@dataclass(frozen=True)
class Report:
    """One input report layout. report_id None = the device sends no report-id byte.

    fields : channel values; status_fields : values about the device (`Profile.status`);
    skip : conditions under which the report carries no input (its channels are not written);
    crc32_seed : the report ends in a CRC32 (LE) of this seed byte and the bytes before it
    (None: no check); arrays, status_arrays : the compiled layouts
    (capture.hid.parse.decode_fields)."""
    name: str
    report_id: int | None
    length: int
    fields: tuple[Field, ...]
    comment: str = ""
    status_fields: tuple[Field, ...] = ()
    skip: tuple[Condition, ...] = ()
    crc32_seed: int | None = None
    arrays: tuple = ()
    status_arrays: tuple = ()


@dataclass(frozen=True)
class DeviceMatch:
    """A device a profile fits: USB vendor:product, and, when given, the HID usage page and
    usage of the interface (a receiver that is also a mouse has one hidraw node per
    interface)."""
    vendor_id: int
    product_id: int
    name: str = ""
    usage_page: int | None = None
    usage: int | None = None

    def fits(self, vendor_id, product_id, usage_page=None, usage=None) -> bool:
        """Same ids, and the same usage where both sides know it (hidapi reports 0 when the
        system does not say)."""
        if vendor_id != self.vendor_id or product_id != self.product_id:
            return False
        for wanted, seen in ((self.usage_page, usage_page), (self.usage, usage)):
            if wanted is not None and seen not in (None, 0) and seen != wanted:
                return False
        return True


@dataclass(frozen=True)
class Profile:
    """A device profile: channels (D names in order) with units, status values (S names) with
    units, reports, devices it fits, and the IMU calibration reader it names ("" none)."""
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
    status: tuple[str, ...] = ()
    status_units: tuple[str, ...] = ()
    calibration: str = ""

    def matches(self, vendor_id: int, product_id: int, *, usage_page: int | None = None,
                usage: int | None = None) -> bool:
        return any(d.fits(vendor_id, product_id, usage_page, usage) for d in self.devices)

    def device_name(self, vendor_id: int, product_id: int) -> str:
        for d in self.devices:
            if d.vendor_id == vendor_id and d.product_id == product_id:
                return d.name
        return ""

    @property
    def numbered(self) -> bool:
        return any(r.report_id is not None for r in self.reports)

    def with_affine(self, affine: Mapping[str, tuple[float, float]]) -> "Profile":
        """The same profile with (center, scale) replaced for the named channels in every
        report (a device's own calibration); unknown names raise ValueError."""
        unknown = sorted(set(affine) - set(self.channels))
        if unknown:
            raise ValueError(f"profile {self.name!r} has no channel(s) {unknown}")
        reports = []
        for r in self.reports:
            fields = tuple(replace(f, center=float(affine[f.channel][0]),
                                   scale=float(affine[f.channel][1]))
                           if f.channel in affine else f for f in r.fields)
            reports.append(replace(r, fields=fields,
                                   arrays=_compile(fields, list(self.channels))))
        return replace(self, reports=tuple(reports))


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
    if kind is float and not math.isfinite(value):
        _fail(path, where, f"{key!r} must be finite, got {value!r}")
    return kind(value)


def _text(table, key, path, where, default="") -> str:
    value = table.get(key, default)
    if not isinstance(value, str):
        _fail(path, where, f"{key!r} must be a string, got {value!r}")
    return value


def _tables(table, key, path, where) -> list:
    """table[key] as a list of tables ([[key]] in TOML)."""
    value = table.get(key, [])
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        _fail(path, where, f"{key!r} must be a list of tables ([[{key}]]), got {value!r}")
    return value


def _unknown(table: Mapping, allowed: set, path, where):
    extra = sorted(set(table) - allowed)
    if extra:
        _fail(path, where, f"unknown key(s) {extra}; expected some of {sorted(allowed)}")


def _bit_range(table: Mapping, path, where: str, length: int, width_limit: int = 32) -> Bits:
    """bit = N, width = W, order = lsb|msb -> Bits (checked to lie inside the report)."""
    bit = _number(table, "bit", path, where, kind=int)
    width = _number(table, "width", path, where, kind=int)
    order = table.get("order", "lsb")
    if order not in ("lsb", "msb"):
        _fail(path, where, f"'order' must be 'lsb' or 'msb', got {order!r}")
    if not 1 <= width <= width_limit:
        _fail(path, where, f"'width' must be 1..{width_limit} bits, got {width}")
    if bit < 0:
        _fail(path, where, f"'bit' must be >= 0, got {bit}")
    start = bit // 8
    nbytes = (bit + width - 1) // 8 - start + 1
    if order == "lsb":
        # bit N is bit N % 8 of byte N // 8; the word is little-endian
        bits = Bits(start, nbytes, False, bit % 8, width)
    else:
        # bit N counts from the most significant bit of byte 0 (P5 glove packing)
        bits = Bits(start, nbytes, True, 8 * nbytes - (bit % 8) - width, width)
    if start + nbytes > length:
        _fail(path, where, f"reads bytes {start}..{start + nbytes - 1}, outside the "
                           f"{length}-byte report")
    return bits


def _condition(table, path, where: str, length: int) -> Condition:
    if not isinstance(table, dict):
        _fail(path, where, f"a condition must be a table {{bit, width, equals}}, got {table!r}")
    _unknown(table, _CONDITION_KEYS, path, where)
    bits = _bit_range(table, path, where, length)
    equals = _number(table, "equals", path, where, kind=int)
    if not 0 <= equals < (1 << bits.width):
        _fail(path, where, f"'equals' = {equals} does not fit in {bits.width} bit(s)")
    return Condition(bits, equals, _text(table, "comment", path, where))


def _field(table: Mapping, path, where: str, length: int) -> Field:
    _unknown(table, _FIELD_KEYS, path, where)
    channel = table.get("channel")
    if not isinstance(channel, str) or not channel:
        _fail(path, where, f"'channel' must be a non-empty string, got {channel!r}")
    where = f"{where} ({channel})"
    kind = table.get("type")
    if not isinstance(kind, str):
        _fail(path, where, f"'type' must be a string such as \"u8\" or \"ubits\", got {kind!r}")
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
        if start < 0 or start + nbytes > length:
            _fail(path, where, f"reads bytes {start}..{start + nbytes - 1}, outside the "
                               f"{length}-byte report")
        bits = Bits(start, nbytes, big, 0, 8 * nbytes)
    elif kind in _BIT_TYPES:
        if "byte" in table:
            _fail(path, where, f"type {kind!r} takes 'bit' and 'width', not 'byte'")
        signed, is_float = _BIT_TYPES[kind], False
        bits = _bit_range(table, path, where, length)
    else:
        _fail(path, where, f"'type' must be one of {sorted(_BYTE_TYPES) + sorted(_BIT_TYPES)}, "
                           f"got {kind!r}")
    if lookup and is_float:
        _fail(path, where, "a float field cannot have a lookup table")
    when = _condition(table["when"], path, f"{where} when", length) if "when" in table else None
    return Field(channel, bits, signed, is_float, center, scale,
                 tuple(float(v) for v in lookup), _text(table, "unit", path, where),
                 _text(table, "comment", path, where), when)


def _compile(fields: Iterable[Field], names: list[str]) -> tuple:
    """Fields -> (layout (F, 16) int64, affine (F, 2) float64 [center, scale], lut (M,)
    float64), the arrays capture.hid.parse.decode_fields reads; index = position in `names`."""
    fields = list(fields)
    layout = np.zeros((len(fields), LAYOUT_COLUMNS), np.int64)
    affine = np.zeros((len(fields), 2), np.float64)
    lut: list[float] = []
    for row, f in enumerate(fields):
        b = f.bits
        layout[row, :L_LUT_START] = (names.index(f.channel), b.start, b.nbytes, b.big_endian,
                                     b.shift, b.width, f.signed, f.is_float)
        layout[row, L_LUT_START:L_COND_START] = (len(lut), len(f.lookup))
        lut.extend(f.lookup)
        if f.when is None:
            layout[row, L_COND_START] = -1
        else:
            c = f.when.bits
            layout[row, L_COND_START:] = (c.start, c.nbytes, c.big_endian, c.shift, c.width,
                                          f.when.equals)
        affine[row] = (f.center, f.scale)
    return layout, affine, np.array(lut if lut else [0.0], np.float64)


def _derived(table, source: Report, length: int, path, where):
    """The fields, status fields of `source` shifted by byte_shift (only those that fit with
    truncate = true)."""
    shift = _number(table, "byte_shift", path, where, default=0, kind=int)
    truncate = table.get("truncate", False)
    if not isinstance(truncate, bool):
        _fail(path, where, f"'truncate' must be true or false, got {truncate!r}")
    if "field" in table or "status" in table:
        _fail(path, where, "a report with 'fields_from' takes its fields from there; give "
                           "'field'/'status' or 'fields_from', not both")

    def moved(fields):
        out = []
        for f in fields:
            g = f.shifted(shift)
            if g.start >= 0 and g.end <= length:
                out.append(g)
            elif not truncate:
                _fail(path, where, f"field {f.channel!r} shifted by {shift} falls outside the "
                                   f"{length}-byte report (truncate = true keeps only the "
                                   f"fields that fit)")
        return tuple(out)
    return moved(source.fields), moved(source.status_fields)


def _report(table, index, by_name, path):
    where = f"report[{index}]"
    _unknown(table, _REPORT_KEYS, path, where)
    report_name = _text(table, "name", path, where, default=f"report{index}")
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
        source = by_name.get(table["fields_from"]) if isinstance(table["fields_from"], str) \
            else None
        if source is None:
            _fail(path, where, f"'fields_from' names {table['fields_from']!r}, not an "
                               f"earlier report ({sorted(by_name)})")
        fields, status = _derived(table, source, length, path, where)
    else:
        if "byte_shift" in table or "truncate" in table:
            _fail(path, where, "'byte_shift' and 'truncate' go with 'fields_from'")
        fields = tuple(_field(t, path, f"{where} field[{i}]", length)
                       for i, t in enumerate(_tables(table, "field", path, where)))
        status = tuple(_field(t, path, f"{where} status[{i}]", length)
                       for i, t in enumerate(_tables(table, "status", path, where)))
    skip = tuple(_condition(t, path, f"{where} skip[{i}]", length)
                 for i, t in enumerate(_tables(table, "skip", path, where)))
    crc32_seed = _optional_int(table, "crc32_seed", path, where)
    if crc32_seed is not None and not (0 <= crc32_seed <= 255 and length > 4):
        _fail(path, where, f"'crc32_seed' must be a byte (0..255) on a report longer than the "
                           f"4 CRC bytes, got {crc32_seed}")
    if not fields and not status:
        _fail(path, where, "has no fields (and no status values)")
    for group in (fields, status):
        seen = set()
        for f in group:
            if f.channel in seen:
                _fail(path, where, f"{f.channel!r} appears twice in one report")
            seen.add(f.channel)
    return Report(report_name, report_id, length, fields,
                  _text(table, "comment", path, where), status, skip, crc32_seed)


def _optional_int(table, key, path, where, default=None):
    return _number(table, key, path, where, kind=int) if key in table else default


def _id16(table, key, path, where, default=None, *, required=False):
    """A 16-bit USB or HID id (vendor, product, usage page, usage); None when absent."""
    if required and key not in table:
        _fail(path, where, f"missing {key!r}")
    value = _optional_int(table, key, path, where, default)
    if value is not None and not 0 <= value <= 0xFFFF:
        _fail(path, where, f"{key!r} must be 0..0xffff, got {value}")
    return value


def _raw_profile(data, name, title, rate, devices, path) -> Profile:
    length = _number(data, "length", path, "top level", default=64, kind=int)
    if not 1 <= length <= 4096:
        _fail(path, "top level", f"'length' must be 1..4096 bytes, got {length}")
    channels = [f"byte{i}" for i in range(length)]
    fields = tuple(Field(f"byte{i}", Bits(i, 1, False, 0, 8), False, False, 0.0, 1.0, (), "",
                         "") for i in range(length))
    report = Report("raw", None, length, fields, "raw report bytes",
                    arrays=_compile(fields, channels))
    read_size = _number(data, "read_size", path, "top level", default=length, kind=int)
    if not 1 <= read_size <= 65536:
        _fail(path, "top level", f"'read_size' must be 1..65536 bytes, got {read_size}")
    return Profile(name, title, rate, tuple(channels), ("",) * length, (report,),
                   tuple(devices), raw=True, read_size=read_size,
                   path=Path(path) if path else None)


def parse_profile(data: Mapping, *, path: str | Path = "<profile>") -> Profile:
    """Build a Profile from the parsed TOML of a profile file (errors name file and key)."""
    if not isinstance(data, Mapping):
        _fail(path, "top level", f"expected a table, got {type(data).__name__}")
    _unknown(data, _PROFILE_KEYS, path, "top level")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        _fail(path, "top level", f"'name' must be a non-empty string, got {name!r}")
    title = _text(data, "title", path, "top level", default=name)
    rate = _number(data, "rate", path, "top level", default=0.0)
    if rate < 0:
        _fail(path, "top level", f"'rate' must be >= 0 reports per second, got {rate}")
    calibration = _text(data, "calibration", path, "top level")
    if calibration and calibration not in CALIBRATIONS:
        _fail(path, "top level", f"'calibration' must be one of {list(CALIBRATIONS)}, got "
                                 f"{calibration!r}")
    usage_page = _id16(data, "usage_page", path, "top level")
    usage = _id16(data, "usage", path, "top level")
    devices = []
    for index, table in enumerate(_tables(data, "device", path, "top level")):
        where = f"device[{index}]"
        _unknown(table, _DEVICE_KEYS, path, where)
        devices.append(DeviceMatch(_id16(table, "vendor_id", path, where, required=True),
                                   _id16(table, "product_id", path, where, required=True),
                                   _text(table, "name", path, where),
                                   _id16(table, "usage_page", path, where, usage_page),
                                   _id16(table, "usage", path, where, usage)))
    raw = data.get("raw", False)
    if not isinstance(raw, bool):
        _fail(path, "top level", f"'raw' must be true or false, got {raw!r}")
    if raw:
        return _raw_profile(data, name, title, rate, devices, path)
    tables = _tables(data, "report", path, "top level")
    if not tables:
        _fail(path, "top level", "needs at least one [[report]] (or raw = true)")
    reports: list[Report] = []
    by_name: dict[str, Report] = {}
    for index, table in enumerate(tables):
        report = _report(table, index, by_name, path)
        reports.append(report)
        by_name[report.name] = report
    keys = [(r.report_id, r.length) for r in reports]
    if len(set(keys)) != len(keys):
        _fail(path, "reports", "two reports share the same id and length")
    if len({r.report_id is None for r in reports}) > 1:
        _fail(path, "reports", "mixes reports with and without an id byte")
    channels, units = _names(r.fields for r in reports)
    status, status_units = _names(r.status_fields for r in reports)
    overlap = sorted(set(channels) & set(status))
    if overlap:
        _fail(path, "reports", f"{overlap} named both as channel and as status")
    compiled = tuple(replace(r, arrays=_compile(r.fields, channels),
                             status_arrays=_compile(r.status_fields, status)) for r in reports)
    read_size = _number(data, "read_size", path, "top level",
                        default=max(64, max(r.length for r in reports)), kind=int)
    if not 1 <= read_size <= 65536:
        _fail(path, "top level", f"'read_size' must be 1..65536 bytes, got {read_size}")
    return Profile(name, title, rate, tuple(channels), tuple(units), compiled, tuple(devices),
                   raw=False, read_size=read_size, path=Path(path) if path else None,
                   status=tuple(status), status_units=tuple(status_units),
                   calibration=calibration)


def _names(groups) -> tuple[list[str], list[str]]:
    """Names in order of first use, with the unit each was first given."""
    names: list[str] = []
    units: dict[str, str] = {}
    for fields in groups:
        for f in fields:
            if f.channel not in units:
                names.append(f.channel)
                units[f.channel] = f.unit
    return names, [units[n] for n in names]


def load_profile_file(path: str | Path) -> Profile:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"HID profile file not found: {path}") from None
    except UnicodeDecodeError as error:
        raise ProfileError(f"{path}: not UTF-8 text: {error}") from None
    except RecursionError:
        raise ProfileError(f"{path}: TOML nested too deeply to read") from None
    except tomllib.TOMLDecodeError as error:
        raise ProfileError(f"{path}: not valid TOML: {error}") from None
    return parse_profile(data, path=path)


def profile_dirs() -> list[Path]:
    """Where profiles are looked up: the folders in $MOP_HID_PROFILES, then the shipped ones."""
    extra = [Path(p) for p in os.environ.get(USER_PROFILE_ENV, "").split(os.pathsep) if p]
    return extra + [PROFILE_DIR]


_CACHE: dict[Path, tuple[float, Profile]] = {}
_SKIPPED: dict[Path, tuple[float, str]] = {}     # path -> (mtime, why), warned about once


def _cached(path: Path) -> Profile:
    mtime = path.stat().st_mtime
    hit = _CACHE.get(path)
    if hit is None or hit[0] != mtime:
        hit = (mtime, load_profile_file(path))
        _CACHE[path] = hit
    return hit[1]


def _scan() -> tuple[dict[str, Profile], dict[Path, str]]:
    found: dict[str, Profile] = {}
    skipped: dict[Path, str] = {}
    for folder in reversed(profile_dirs()):
        if not folder.is_dir():
            continue
        for path in sorted(folder.glob("*.toml")):
            try:
                profile = _cached(path.resolve())
            except (OSError, ValueError) as error:
                # one broken file must not take the other profiles down with it
                message = str(error).removeprefix(f"{path.resolve()}: ")
                skipped[path] = message
                try:
                    mtime = path.stat().st_mtime
                except OSError:
                    mtime = -1.0
                if _SKIPPED.get(path) != (mtime, message):
                    _SKIPPED[path] = (mtime, message)
                    log.warning("skipping HID profile %s: %s", path, message)
                continue
            found[profile.name] = profile
    return found, skipped


def available_profiles() -> dict[str, Profile]:
    """{name: Profile} of every profile file found (user folders override shipped ones). A file
    that does not load is skipped with a logged warning naming it (see `skipped_profiles`)."""
    return _scan()[0]


def skipped_profiles() -> dict[Path, str]:
    """{path: why} of the profile files in the profile folders that did not load."""
    return _scan()[1]


def load_profile(name_or_path: str | Path | Profile) -> Profile:
    """A profile by name ("p5", "spacemouse", "dualshock4", "dualsense", "generic") or by the
    path of a .toml file."""
    if isinstance(name_or_path, Profile):
        return name_or_path
    text = str(name_or_path)
    if text.endswith(".toml"):
        return load_profile_file(text)
    profiles, skipped = _scan()
    try:
        return profiles[text]
    except KeyError:
        broken = "".join(f"; skipped {path}: {why}" for path, why in skipped.items())
        raise ValueError(f"unknown HID profile {text!r}; available: "
                         f"{', '.join(sorted(profiles))} (or give a .toml file){broken}"
                         ) from None
