"""Report bytes -> channel values: a pure function of the bytes and the profile.

`parse_report(profile, data)` returns (D,) float64 with the channels this report carries and NaN
for the others; `parse_into` writes only the carried channels into a state vector (how a source
holds the last value of channels that arrive in other reports) and, when asked, the report's
status values (battery, cable, sensor clock) into a status vector; `parse_status` returns those
alone. A report a profile's skip rule matches (a receiver with no controller connected) carries
no input: its channels are not written and `parse_into` returns the rule's reason. Malformed
input (unknown report id, too short) raises `MalformedReport`, which a source counts and skips.

The decoding kernel is numba-compiled over the arrays a profile compiles to;
`parse_report_reference` is the slow, obvious version the tests compare it against.
"""
from __future__ import annotations

import struct
import zlib
from typing import NamedTuple

import numpy as np
from numba import njit

from .profile import (L_BIG, L_COND_BIG, L_COND_EQUALS, L_COND_NBYTES, L_COND_SHIFT,
                      L_COND_START, L_COND_WIDTH, L_FLOAT, L_INDEX, L_LUT_LENGTH, L_LUT_START,
                      L_NBYTES, L_SHIFT, L_SIGNED, L_START, L_WIDTH, Field, Profile, Report)


class MalformedReport(ValueError):
    """Report bytes that fit no layout of the profile."""


class Parsed(NamedTuple):
    """What `parse_into` did: the layout that read the report, and, when one of its skip rules
    matched, the reason ("" otherwise: channels and status were written)."""
    report: Report
    skipped: str = ""

    @property
    def carried_input(self) -> bool:
        """True when the report wrote channel values (not skipped, not a status-only report)."""
        return not self.skipped and bool(self.report.fields)


@njit(cache=True)
def _bits(data, start, nbytes, big_endian, shift, width):  # pragma: no cover - numba
    """`width` unsigned bits from bit `shift` of the word made of data[start:start+nbytes]."""
    word = np.int64(0)
    if big_endian:
        for k in range(nbytes):
            word = (word << 8) | np.int64(data[start + k])
    else:
        for k in range(nbytes):
            word |= np.int64(data[start + k]) << (8 * k)
    return (word >> shift) & ((np.int64(1) << width) - 1)


@njit(cache=True)
def decode_fields(data, layout, affine, lut, out):  # pragma: no cover - numba
    """Decode F fields of one report into `out`.

    data : (L,) uint8 report bytes; layout : (F, 16) int64, one row per field with the columns
    named L_* in capture.hid.profile (index into out, bytes, bits, sign, float, lookup range,
    condition); affine : (F, 2) float64 (center, scale); lut : (M,) float64 lookup tables;
    out : (D,) float64, written at the fields' indices only (NaN where a condition fails or a
    lookup has no entry)."""
    for f in range(layout.shape[0]):
        row = layout[f]
        index = row[L_INDEX]
        if row[L_COND_START] >= 0:
            cond = _bits(data, row[L_COND_START], row[L_COND_NBYTES], row[L_COND_BIG] != 0,
                         row[L_COND_SHIFT], row[L_COND_WIDTH])
            if cond != row[L_COND_EQUALS]:
                out[index] = np.nan
                continue
        s = row[L_START]
        if row[L_FLOAT]:
            word = np.uint32(0)
            for k in range(4):
                word |= np.uint32(data[s + k]) << np.uint32(8 * k)
            value = np.float64(np.array([word], dtype=np.uint32).view(np.float32)[0])
            out[index] = (value - affine[f, 0]) * affine[f, 1]
            continue
        w = row[L_WIDTH]
        raw = _bits(data, s, row[L_NBYTES], row[L_BIG] != 0, row[L_SHIFT], w)
        if row[L_SIGNED] and (raw >> (w - 1)) & 1:
            raw -= np.int64(1) << w
        length = row[L_LUT_LENGTH]
        if length > 0:
            if 0 <= raw < length:
                out[index] = lut[row[L_LUT_START] + raw]
            else:
                out[index] = np.nan
        else:
            out[index] = (np.float64(raw) - affine[f, 0]) * affine[f, 1]


def select_report(profile: Profile, data: bytes | bytearray | memoryview) -> Report:
    """The layout that reads `data`: same report id, length <= len(data) (longest such);
    extra trailing bytes are ignored, as some firmwares pad reports."""
    size = len(data)
    if size == 0:
        raise MalformedReport("empty report (0 bytes)")
    if profile.raw:
        return profile.reports[0]
    report_id = data[0] if profile.numbered else None
    candidates = [r for r in profile.reports if r.report_id == report_id]
    if not candidates:
        known = sorted({f"{r.report_id:#04x}" for r in profile.reports})
        raise MalformedReport(f"unknown report id {report_id:#04x} for profile "
                              f"{profile.name!r} (knows {', '.join(known)})")
    fitting = [r for r in candidates if r.length <= size]
    if not fitting:
        lengths = sorted(r.length for r in candidates)
        what = f"report {report_id:#04x}" if report_id is not None else "report"
        raise MalformedReport(f"{what} is {size} bytes; profile {profile.name!r} expects "
                              f"{' or '.join(map(str, lengths))}")
    report = max(fitting, key=lambda r: r.length)
    if report.crc32_seed is not None and not crc_matches(report, data):
        raise MalformedReport(f"report {report_id:#04x} ({report.name}): CRC32 does not match "
                              f"(damaged in transit)")
    return report


def crc_matches(report: Report, data) -> bool:
    """The CRC32 in the last 4 bytes of the report (LE) is that of its seed byte followed by
    the bytes before it (DualShock 4 and DualSense Bluetooth reports, seed 0xA1)."""
    end = report.length - 4
    seed = zlib.crc32(bytes((report.crc32_seed,)))
    return zlib.crc32(bytes(data[:end]), seed) == int.from_bytes(bytes(data[end:end + 4]),
                                                                 "little")


def parse_into(profile: Profile, data: bytes | bytearray | memoryview, out: np.ndarray,
               status: np.ndarray | None = None) -> Parsed:
    """Write the channels carried by one report into `out` (D,) float64, and its status values
    into `status` (S,) float64 when given. When a skip rule of the report matches (e.g. a USB
    adaptor with no controller), neither is written and the result names the reason. Raises
    MalformedReport."""
    report = select_report(profile, data)
    buffer = np.frombuffer(data, dtype=np.uint8)
    if profile.raw:
        count = min(buffer.shape[0], out.shape[0])
        out[:count] = buffer[:count]
        out[count:] = np.nan
        return Parsed(report)
    for rule in report.skip:
        if rule.holds(data):
            return Parsed(report, rule.comment or f"report {report.name!r} carries no input")
    if status is not None and report.status_fields:
        decode_fields(buffer, *report.status_arrays, status)
    if report.fields:
        decode_fields(buffer, *report.arrays, out)
    return Parsed(report)


def parse_report(profile: Profile, data: bytes | bytearray | memoryview) -> np.ndarray:
    """Channel values of one report: (D,) float64 in the profile's units, NaN for channels this
    report does not carry (all of them when a skip rule matched). Raises MalformedReport."""
    out = np.full(len(profile.channels), np.nan)
    parse_into(profile, data, out)
    return out


def parse_status(profile: Profile, data: bytes | bytearray | memoryview) -> np.ndarray:
    """Status values of one report: (S,) float64 (`profile.status` names), NaN for the ones this
    report does not carry. Raises MalformedReport."""
    out = np.full(len(profile.channels), np.nan)
    status = np.full(len(profile.status), np.nan)
    parse_into(profile, data, out, status)
    return status


def split_reports(profile: Profile, data: bytes, *, allow_tail: bool = False
                  ) -> tuple[list[bytes], bytes]:
    """Split one read into reports: (reports, tail).

    A real hidraw read returns exactly one report. A read through a stream (umockdev's emulated
    node, a serial bridge) can return several back to back, and, when it filled the read
    buffer, end inside a report; reports are separated with the profile's report ids and
    lengths. With allow_tail, an incomplete last report is returned as `tail` (to be prefixed to
    the next read). Data that splits no way is returned whole as one report (and then fails to
    parse, and is counted)."""
    if profile.raw or not profile.numbered:
        return [data], b""
    if any(r.length == len(data) and r.report_id == data[0] for r in profile.reports):
        return [data], b""
    lengths: dict[int, list[int]] = {}
    for r in profile.reports:
        lengths.setdefault(r.report_id, []).append(r.length)
    size = len(data)

    def split(position: int) -> list[int] | None:
        if position == size:
            return []
        candidates = lengths.get(data[position], ())
        for length in sorted(candidates, reverse=True):
            if position + length <= size:
                rest = split(position + length)
                if rest is not None:
                    return [length] + rest
        if allow_tail and candidates and size - position < max(candidates):
            return [-(size - position)]          # an incomplete report: the tail
        return None

    sizes = split(0) if size <= 4096 else None
    if not sizes:
        return [data], b""
    parts, position, tail = [], 0, b""
    for length in sizes:
        if length < 0:
            tail = bytes(data[position:])
            break
        parts.append(bytes(data[position:position + length]))
        position += length
    return parts, tail


# -- the slow, obvious reference (tests) ---------------------------------------------------

def decode_field_reference(field: Field, data: bytes) -> float:
    """One field decoded with Python integers and struct, straight from its definition."""
    if field.when is not None and not field.when.holds(data):
        return float("nan")
    if field.is_float:
        chunk = bytes(data[field.bits.start:field.bits.end])
        return (struct.unpack("<f", chunk)[0] - field.center) * field.scale
    raw = field.bits.raw(data)
    width = field.bits.width
    if field.signed and raw >= 1 << (width - 1):
        raw -= 1 << width
    if field.lookup:
        return field.lookup[raw] if 0 <= raw < len(field.lookup) else float("nan")
    return (raw - field.center) * field.scale


def parse_report_reference(profile: Profile, data: bytes) -> np.ndarray:
    out = np.full(len(profile.channels), np.nan)
    report = select_report(profile, data)
    if profile.raw:
        count = min(len(data), out.shape[0])
        out[:count] = list(bytes(data[:count]))
        return out
    if any(rule.bits.raw(data) == rule.equals for rule in report.skip):
        return out
    for field in report.fields:
        out[profile.channels.index(field.channel)] = decode_field_reference(field, data)
    return out


def parse_status_reference(profile: Profile, data: bytes) -> np.ndarray:
    out = np.full(len(profile.status), np.nan)
    report = select_report(profile, data)
    if any(rule.bits.raw(data) == rule.equals for rule in report.skip):
        return out
    for field in report.status_fields:
        out[profile.status.index(field.channel)] = decode_field_reference(field, data)
    return out
