"""IMU calibration that Sony pads report about themselves, read from a feature report.

A DualShock 4 and a DualSense send raw gyroscope and accelerometer counts; each pad also keeps
its own calibration (biases, and the counts at known rates and at +-1 g) in a feature report:
0x02 (37 bytes) on a DualShock 4 over USB, 0x05 (41 bytes, CRC32 at the end) over Bluetooth,
0x05 on a DualSense. The numbers are read as the Linux hid-playstation driver reads them:

    gyro:   value = raw * (speed_plus + speed_minus) / (|plus - bias| + |minus - bias|)  [deg/s]
    accel:  value = (raw - bias) * 2 / (plus - minus)  [g],  bias = plus - (plus - minus) / 2

(the gyro bias is not subtracted: the pad removes it itself). An axis whose denominator is 0
(clones, emulators) keeps the profile's nominal scale. `parse_calibration` is a pure function
of the bytes; `read_calibration` asks an open hidapi device.
"""
from __future__ import annotations

import logging
import math
import struct
import zlib
from dataclasses import dataclass

from .status import Connection

log = logging.getLogger(__name__)

G = 9.80665                      # standard gravity [m/s^2]
FEATURE_CRC_SEED = 0xA3          # Bluetooth feature reports: CRC32 over 0xA3 + the bytes
GYRO_CHANNELS = ("gyro_x", "gyro_y", "gyro_z")
ACCEL_CHANNELS = ("accel_x", "accel_y", "accel_z")


class CalibrationError(ValueError):
    """Feature report bytes that are not a calibration report."""


@dataclass(frozen=True)
class AxisCalibration:
    """value = (raw - bias) * numer / denom, in deg/s (gyro) or g (accel); denom 0 = unusable."""
    bias: int
    numer: int
    denom: int

    @property
    def valid(self) -> bool:
        return self.denom != 0


@dataclass(frozen=True)
class ImuCalibration:
    """Per-axis calibration of a pad: gyro (x, y, z) and accel (x, y, z)."""
    gyro: tuple[AxisCalibration, AxisCalibration, AxisCalibration]
    accel: tuple[AxisCalibration, AxisCalibration, AxisCalibration]

    def affine(self) -> dict[str, tuple[float, float]]:
        """{channel: (center, scale)} giving rad/s and m/s^2 for the usable axes (see
        `Profile.with_affine`)."""
        out = {}
        for names, axes, unit in ((GYRO_CHANNELS, self.gyro, math.pi / 180),
                                  (ACCEL_CHANNELS, self.accel, G)):
            for name, axis in zip(names, axes):
                if axis.valid:
                    out[name] = (float(axis.bias), axis.numer / axis.denom * unit)
        return out

    @property
    def complete(self) -> bool:
        return all(a.valid for a in self.gyro + self.accel)


@dataclass(frozen=True)
class FeatureRequest:
    """Which feature report holds the calibration, and how its gyro values are ordered."""
    report_id: int
    size: int
    interleaved: bool     # pitch+, pitch-, yaw+, yaw-, roll+, roll- (else all + then all -)
    crc: bool             # ends in a CRC32 (Bluetooth)


def requests(kind: str, connection: Connection) -> list[FeatureRequest]:
    """The feature reports to try, in order, for a pad of `kind` attached by `connection`."""
    if kind == "dualsense":
        return [FeatureRequest(0x05, 41, True, connection is Connection.BLUETOOTH)]
    if kind == "dualshock4":
        usb = FeatureRequest(0x02, 37, True, False)
        bluetooth = FeatureRequest(0x05, 41, False, True)
        if connection is Connection.USB:
            return [usb]
        if connection is Connection.BLUETOOTH:
            return [bluetooth]
        return [usb, bluetooth]
    raise ValueError(f"unknown IMU calibration {kind!r}; known: dualshock4, dualsense")


def parse_calibration(data: bytes, request: FeatureRequest) -> ImuCalibration:
    """The calibration in one feature report (report id first). Raises CalibrationError when
    the id, the size or (Bluetooth) the CRC32 is not right."""
    data = bytes(data)
    if len(data) < request.size:
        raise CalibrationError(f"calibration report {request.report_id:#04x} is {len(data)} "
                               f"bytes, expected {request.size}")
    data = data[:request.size]
    if data[0] != request.report_id:
        raise CalibrationError(f"expected feature report {request.report_id:#04x}, got "
                               f"{data[0]:#04x}")
    if request.crc:
        body, (stored,) = data[:-4], struct.unpack("<I", data[-4:])
        if zlib.crc32(body, zlib.crc32(bytes([FEATURE_CRC_SEED]))) != stored:
            raise CalibrationError(f"calibration report {request.report_id:#04x}: CRC32 "
                                   f"does not match")
    v = struct.unpack_from("<17h", data, 1)       # 17 signed 16-bit values from byte 1
    bias = v[0:3]                                  # pitch, yaw, roll
    if request.interleaved:
        plus, minus = v[3:9:2], v[4:9:2]
    else:
        plus, minus = v[3:6], v[6:9]
    speed = v[9] + v[10]                           # speed_plus + speed_minus [deg/s]
    gyro = tuple(AxisCalibration(0, speed, abs(p - b) + abs(m - b))
                 for p, m, b in zip(plus, minus, bias))
    accel = []
    for k in range(3):
        a_plus, a_minus = v[11 + 2 * k], v[12 + 2 * k]
        span = a_plus - a_minus                    # counts between +1 g and -1 g
        accel.append(AxisCalibration(a_plus - int(span / 2), 2, span))
    return ImuCalibration(gyro, tuple(accel))


def read_calibration(device, kind: str, connection: Connection
                     ) -> tuple[ImuCalibration | None, str]:
    """Ask an open hidapi device for its calibration: (calibration, "") or (None, why not).
    Reading it also switches a Bluetooth pad from its short report to the full one."""
    problems = []
    for request in requests(kind, connection):
        try:
            data = bytes(device.get_feature_report(request.report_id, request.size))
            return parse_calibration(data, request), ""
        except (OSError, ValueError) as error:
            problems.append(f"feature report {request.report_id:#04x}: {error}")
    return None, "; ".join(problems)
