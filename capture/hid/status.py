"""What a device says about itself, apart from the performer's input: battery, cable, how it
is connected, its IMU clock, and whether its input is there at all (a USB adaptor with no
controller paired). Read from a report's status values (`Profile.status`) by pure functions;
`SensorClock` unwraps a device clock across its wrap-arounds.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from enum import Enum
from pathlib import Path

import numpy as np

from .profile import Profile


class BatteryState(str, Enum):
    """Charging state, as the Linux power-supply class names it (codes 0..3 in profiles)."""
    DISCHARGING = "discharging"
    CHARGING = "charging"
    FULL = "full"
    NOT_CHARGING = "not charging"


_STATE_CODES = {0: BatteryState.DISCHARGING, 1: BatteryState.CHARGING, 2: BatteryState.FULL,
                3: BatteryState.NOT_CHARGING}


class Connection(str, Enum):
    USB = "usb"
    BLUETOOTH = "bluetooth"
    UNKNOWN = ""


@dataclass(frozen=True)
class DeviceStatus:
    """A snapshot of what the device reported about itself.

    connection : how it is attached (from the system); battery : charge 0..1 or None (not
    reported, or unknown while the device reports a charge error); battery_state : charging
    state or None; cable : USB cable plugged in (None: not reported); sensor_time : the IMU's
    own clock [s], unwrapped since the device was opened (None: no IMU clock); calibration :
    "device" (read from the device), "nominal" (the profile's scales) or "" (no IMU);
    no_input : why the latest report carried no input ("" when it did)."""
    connection: Connection = Connection.UNKNOWN
    battery: float | None = None
    battery_state: BatteryState | None = None
    cable: bool | None = None
    sensor_time: float | None = None
    calibration: str = ""
    no_input: str = ""

    def as_dict(self) -> dict:
        out = asdict(self)
        out["connection"] = self.connection.value
        out["battery_state"] = self.battery_state.value if self.battery_state else None
        return out

    def text(self) -> str:
        """One line for people: 'USB, battery 55 % (charging), cable in'."""
        parts = []
        if self.connection is not Connection.UNKNOWN:
            parts.append("USB" if self.connection is Connection.USB else "Bluetooth")
        if self.no_input:
            parts.append(self.no_input)
        if self.battery is not None:
            state = f" ({self.battery_state.value})" if self.battery_state else ""
            parts.append(f"battery {round(100 * self.battery)} %{state}")
        elif self.battery_state is not None:
            parts.append(f"battery {self.battery_state.value}")
        if self.cable is not None:
            parts.append("cable in" if self.cable else "no cable")
        if self.calibration:
            parts.append(f"IMU calibration: {self.calibration}")
        return ", ".join(parts)


def battery_from_status(profile: Profile, status: np.ndarray
                        ) -> tuple[float | None, BatteryState | None, bool | None]:
    """(battery 0..1, state, cable) from a status vector (S,) of `profile`. The level counts
    only while the state is known and not an error; FULL is 1.0 whatever the level says, as the
    Linux driver reads these devices."""
    values = dict(zip(profile.status, status.tolist()))
    level = values.get("battery", math.nan)
    code = values.get("battery_state", math.nan)
    cable = values.get("cable", math.nan)
    state = _STATE_CODES.get(int(code)) if math.isfinite(code) else None
    if "battery_state" in values:
        if state is BatteryState.FULL:
            level = 1.0
        elif state not in (BatteryState.DISCHARGING, BatteryState.CHARGING):
            level = math.nan
    return (float(level) if math.isfinite(level) else None, state,
            bool(cable) if math.isfinite(cable) else None)


class SensorClock:
    """Unwraps a device clock that wraps at `period` seconds into seconds since the first
    reading (a missed wrap, a gap longer than the period, cannot be seen)."""

    def __init__(self, period: float):
        self.period = float(period)
        self._last: float | None = None
        self._total = 0.0

    def update(self, reading: float) -> float | None:
        if not math.isfinite(reading):
            return None if self._last is None else self._total
        if self._last is not None:
            step = reading - self._last
            if step < 0:
                step += self.period
            self._total += step
        self._last = reading
        return self._total


def sensor_clock_period(profile: Profile) -> float | None:
    """The wrap period [s] of the profile's `sensor_time` status field (2^width counts)."""
    for report in profile.reports:
        for field in report.status_fields:
            if field.channel == "sensor_time":
                return (1 << field.bits.width) * field.scale
    return None


def connection_of(path: str | bytes | None) -> Connection:
    """USB or Bluetooth for a /dev/hidrawN node, from sysfs (HID_ID=BUS:VENDOR:PRODUCT);
    UNKNOWN when the system does not say."""
    if isinstance(path, bytes):
        path = path.decode(errors="replace")
    if not path or not path.startswith("/dev/hidraw"):
        return Connection.UNKNOWN
    uevent = Path("/sys/class/hidraw") / Path(path).name / "device" / "uevent"
    try:
        lines = uevent.read_text().splitlines()
    except OSError:
        return Connection.UNKNOWN
    for line in lines:
        if line.startswith("HID_ID="):
            bus = line[len("HID_ID="):].split(":")[0]
            try:
                return {0x03: Connection.USB, 0x05: Connection.BLUETOOTH}.get(
                    int(bus, 16), Connection.UNKNOWN)
            except ValueError:
                return Connection.UNKNOWN
    return Connection.UNKNOWN
