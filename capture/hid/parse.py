"""Report bytes -> channel values: a pure function of the bytes and the profile.

`parse_report(profile, data)` returns (D,) float64 with the channels this report carries and NaN
for the others; `parse_into` writes only the carried channels into a state vector (how a source
holds the last value of channels that arrive in other reports). Malformed input (unknown report
id, too short) raises `MalformedReport`, which a source counts and skips.

The decoding kernel is numba-compiled over the arrays a profile compiles to; `decode_reference`
is the slow, obvious version the tests compare it against.
"""
from __future__ import annotations

import struct

import numpy as np
from numba import njit

from .profile import Field, Profile, Report


class MalformedReport(ValueError):
    """Report bytes that fit no layout of the profile."""


@njit(cache=True)
def decode_fields(data, channel, start, nbytes, big_endian, shift, width, signed, is_float,
                  center, scale, lut_start, lut_length, lut, out):  # pragma: no cover - numba
    """Decode F fields of one report into `out`.

    data : (L,) uint8 report bytes; per field (F,): channel int (index into out), start int
    [byte], nbytes int (<= 5), big_endian bool, shift int [bit], width int [bit], signed bool,
    is_float bool, center float, scale float, lut_start int, lut_length int (0 = no table);
    lut : (M,) float table; out : (D,) float64, written at the fields' channels only."""
    for f in range(channel.shape[0]):
        s = start[f]
        if is_float[f]:
            word = np.uint32(0)
            for k in range(4):
                word |= np.uint32(data[s + k]) << np.uint32(8 * k)
            value = np.float64(np.array([word], dtype=np.uint32).view(np.float32)[0])
            out[channel[f]] = (value - center[f]) * scale[f]
            continue
        word = np.int64(0)
        n = nbytes[f]
        if big_endian[f]:
            for k in range(n):
                word = (word << 8) | np.int64(data[s + k])
        else:
            for k in range(n):
                word |= np.int64(data[s + k]) << (8 * k)
        w = width[f]
        raw = (word >> shift[f]) & ((np.int64(1) << w) - 1)
        if signed[f] and (raw >> (w - 1)) & 1:
            raw -= np.int64(1) << w
        if lut_length[f] > 0:
            if 0 <= raw < lut_length[f]:
                out[channel[f]] = lut[lut_start[f] + raw]
            else:
                out[channel[f]] = np.nan
        else:
            out[channel[f]] = (np.float64(raw) - center[f]) * scale[f]


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
    return max(fitting, key=lambda r: r.length)


def parse_into(profile: Profile, data: bytes | bytearray | memoryview, out: np.ndarray
               ) -> Report:
    """Write the channels carried by one report into `out` (D,) float64; return its layout."""
    report = select_report(profile, data)
    buffer = np.frombuffer(data, dtype=np.uint8)
    if profile.raw:
        count = min(buffer.shape[0], out.shape[0])
        out[:count] = buffer[:count]
        out[count:] = np.nan
        return report
    decode_fields(buffer, *report.arrays, out)
    return report


def parse_report(profile: Profile, data: bytes | bytearray | memoryview) -> np.ndarray:
    """Channel values of one report: (D,) float64 in the profile's units, NaN for channels this
    report does not carry. Raises MalformedReport."""
    out = np.full(len(profile.channels), np.nan)
    parse_into(profile, data, out)
    return out


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
    chunk = bytes(data[field.start:field.end])
    if field.is_float:
        return (struct.unpack("<f", chunk)[0] - field.center) * field.scale
    word = int.from_bytes(chunk, "big" if field.big_endian else "little")
    raw = (word >> field.shift) & ((1 << field.width) - 1)
    if field.signed and raw >= 1 << (field.width - 1):
        raw -= 1 << field.width
    if field.lookup:
        return field.lookup[raw] if raw < len(field.lookup) else float("nan")
    return (raw - field.center) * field.scale


def parse_report_reference(profile: Profile, data: bytes) -> np.ndarray:
    out = np.full(len(profile.channels), np.nan)
    report = select_report(profile, data)
    for field in report.fields:
        if field.end <= len(data):
            out[profile.channels.index(field.channel)] = decode_field_reference(field, data)
    return out
