"""HID gloves and controllers through hidapi (the `hidraw` backend on Linux).

`HidSource(profile)` finds a device the profile fits (or opens the one given by path or
vendor:product), reads its input reports on a thread, parses each with the profile (a pure
function of the bytes) and holds the last value of channels carried by other reports. When the
device goes away the source reports DISCONNECTED and opens it again when it is back. On open
it reads the IMU calibration the device keeps (profiles that name one), and while reading it
keeps what the device says about itself: `device_status()` (battery, cable, connection, IMU
clock, no controller on a receiver).
"""
from __future__ import annotations

import logging
import sys
import time

import numpy as np

from ..clock import MonotonicClock
from ..source import ThreadedSource
from .profile import Profile, available_profiles, load_profile
from .status import (Connection, DeviceStatus, SensorClock, battery_from_status, connection_of,
                     sensor_clock_period)

log = logging.getLogger(__name__)


def hid_backend():
    """The hidapi module: `hidraw` (Linux hidraw backend) where available, else `hid`."""
    try:
        if sys.platform.startswith("linux"):
            import hidraw as backend
        else:
            import hid as backend
    except ImportError:
        raise ImportError("HID sources need hidapi: pip install 'mop[capture]' (the PyPI "
                          "package 'hidapi', not 'hid')") from None
    return backend


def enumerate_devices() -> list[dict]:
    """Every HID device hidapi sees: dicts with path (bytes), vendor_id, product_id,
    product_string, manufacturer_string, serial_number, usage_page, usage, interface_number."""
    backend = hid_backend()
    try:
        return list(backend.enumerate())
    except OSError as error:   # no udev, no permission: same as no device
        log.info("HID enumeration failed: %s", error)
        return []


def _fits(profile: Profile, device: dict) -> bool:
    return profile.matches(device.get("vendor_id", -1), device.get("product_id", -1),
                           usage_page=device.get("usage_page"), usage=device.get("usage"))


def list_hid_devices(*, status: bool = True, timeout: float = 0.3) -> list[dict]:
    """HID devices with the profiles that fit them: each dict from `enumerate_devices` plus
    "profiles": [profile names] (the generic profile fits every device) and, with `status`,
    "status": what a device with a profile of its own says about itself in its first reports
    (`DeviceStatus.as_dict()`, up to `timeout` s each; {"error": ...} when it cannot be
    read). One entry per path."""
    profiles = available_profiles()
    seen, out = set(), []
    for device in enumerate_devices():
        path = device.get("path")
        if path in seen:
            continue
        seen.add(path)
        names = [name for name, p in profiles.items() if not p.raw and _fits(p, device)]
        entry = dict(device)
        entry["profiles"] = names + (["generic"] if "generic" in profiles else [])
        if status and names:
            try:
                entry["status"] = probe_status(path, profiles[names[0]],
                                               timeout=timeout).as_dict()
            except OSError as error:
                entry["status"] = {"error": str(error)}
        out.append(entry)
    return out


def probe_status(path: bytes | str, profile: Profile, *, timeout: float = 0.3) -> DeviceStatus:
    """Open the device at `path`, read reports for up to `timeout` s and return what they say
    about the device (no calibration is read). Raises OSError when it cannot be opened."""
    path = path.encode() if isinstance(path, str) else path
    from .parse import MalformedReport, parse_into
    backend = hid_backend()
    device = backend.device()
    try:
        device.open_path(path)
    except (OSError, IOError) as error:
        raise OSError(f"cannot open {path.decode(errors='replace')}: {error}") from None
    state = np.full(len(profile.channels), np.nan)
    values = np.full(len(profile.status), np.nan)
    no_input = ""
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            data = device.read(profile.read_size, max(1, int(1000 * (deadline - time.monotonic()))))
            if not data:
                continue
            try:
                parsed = parse_into(profile, bytes(data), state, values)
            except MalformedReport:
                continue
            no_input = parsed.skipped
            if not parsed.skipped and (np.isfinite(values).any() or not profile.status):
                break
    finally:
        device.close()
    battery, state_, cable = battery_from_status(profile, values)
    return DeviceStatus(connection_of(path), battery, state_, cable, None, "", no_input)


def parse_selector(selector: str) -> dict:
    """"/dev/hidraw0" -> {"path": ...}; "046d:c626" -> {"vendor_id", "product_id"}."""
    if not selector:
        return {}
    if selector.startswith("/"):
        return {"path": selector}
    parts = selector.split(":")
    if len(parts) == 2:
        try:
            return {"vendor_id": int(parts[0], 16), "product_id": int(parts[1], 16)}
        except ValueError:
            pass
    raise ValueError(f"HID device selector {selector!r}: expected a /dev/hidrawN path or "
                     f"VID:PID in hex (e.g. 046d:c626)")


class HidSource(ThreadedSource):
    """A HID device read through a profile.

    Parameters
    ----------
    profile : Profile, a profile name ("p5", "spacemouse", "dualshock4", "dualsense",
        "generic") or a .toml path.
    path : open this hidraw node (e.g. "/dev/hidraw0") instead of searching.
    vendor_id, product_id : search for this device instead of the profile's device list.
    wait : raise OSError at once when no device can be opened (default); with wait=False the
        source starts DISCONNECTED and connects when a device appears.
    Other keyword arguments go to `ThreadedSource` (stall_timeout, reconnect_interval, ...).
    """

    kind = "hid"

    def __init__(self, profile: Profile | str, *, path: str | bytes | None = None,
                 vendor_id: int | None = None, product_id: int | None = None,
                 clock: MonotonicClock | None = None, spec: str = "", wait: bool = True,
                 **options):
        self.profile = load_profile(profile)
        super().__init__(self.profile.channels, self.profile.rate, clock=clock,
                         spec=spec or f"hid:{self.profile.name}", **options)
        self._path = path.encode() if isinstance(path, str) else path
        self._vendor_id = vendor_id
        self._product_id = product_id
        if self.profile.raw and not (path or vendor_id is not None):
            raise ValueError(f"profile {self.profile.name!r} fits any device: say which, e.g. "
                             f"hid:{self.profile.name}@/dev/hidraw0 or "
                             f"hid:{self.profile.name}@046d:c626")
        self._state = np.full(len(self.channels), np.nan)
        self._status = np.full(len(self.profile.status), np.nan)
        period = sensor_clock_period(self.profile)
        self._clock_period = period
        self._sensor_clock = SensorClock(period) if period else None
        self._sensor_time: float | None = None
        self._status_clock_index = (self.profile.status.index("sensor_time")
                                    if period else -1)
        self._no_input = ""
        self._connection = Connection.UNKNOWN
        self._calibration = ""
        self._device_profile = self.profile     # with the open device's own calibration
        self._tail = b""
        self._device = None
        self.device_info: dict = {}
        # numba compiles the decoder (or loads it from its cache) here, at open time, rather
        # than on the first report
        from .parse import parse_into, split_reports
        self._parse_into, self._split = parse_into, split_reports
        warm = np.full(len(self.channels), np.nan)
        warm_status = np.full(len(self.profile.status), np.nan)
        for report in self.profile.reports[:1]:
            dummy = bytearray(report.length)
            if report.report_id is not None:
                dummy[0] = report.report_id
            parse_into(self.profile, bytes(dummy), warm, warm_status)
        self._start(wait=wait)

    def describe(self) -> dict:
        info = super().describe()
        info.update(profile=self.profile.name, units=list(self.profile.units),
                    device={k: (v.decode() if isinstance(v, bytes) else v)
                            for k, v in self.device_info.items()},
                    device_status=self.device_status().as_dict())
        return info

    def device_status(self) -> DeviceStatus:
        """What the device said about itself in its latest reports (see `DeviceStatus`)."""
        battery, state, cable = battery_from_status(self.profile, self._status.copy())
        return DeviceStatus(self._connection, battery, state, cable, self._sensor_time,
                            self._calibration, self._no_input)

    def _find(self) -> tuple[bytes, dict]:
        if self._path:
            return self._path, {"path": self._path}
        devices = enumerate_devices()
        if self._vendor_id is not None:
            chosen = [d for d in devices if d.get("vendor_id") == self._vendor_id and (
                self._product_id is None or d.get("product_id") == self._product_id)]
            # of a receiver's several interfaces, the one the profile describes
            chosen.sort(key=lambda d: not _fits(self.profile, d))
        else:
            chosen = [d for d in devices if _fits(self.profile, d)]
        if chosen:
            return chosen[0]["path"], chosen[0]
        wanted = (f"{self._vendor_id:04x}:{(self._product_id or 0):04x}"
                  if self._vendor_id is not None else
                  ", ".join(f"{d.vendor_id:04x}:{d.product_id:04x}"
                            for d in self.profile.devices) or "none listed")
        present = ", ".join(f"{d.get('vendor_id', 0):04x}:{d.get('product_id', 0):04x} "
                            f"{d.get('product_string') or ''}".strip() for d in devices)
        raise OSError(f"no HID device fits profile {self.profile.name!r} (looking for "
                      f"{wanted}); present: {present or 'no HID devices'}")

    def _open_device(self) -> None:
        path, info = self._find()
        backend = hid_backend()
        device = backend.device()
        try:
            device.open_path(path)
        except (OSError, IOError) as error:
            raise OSError(f"cannot open {path.decode(errors='replace')}: {error} (unplugged? "
                          f"no permission? a udev rule can give access to /dev/hidraw*)"
                          ) from None
        self._device = device
        self.device_info = info
        # values from before a reconnection are stale
        self._state[:] = np.nan
        self._status[:] = np.nan
        self._sensor_clock = SensorClock(self._clock_period) if self._clock_period else None
        self._sensor_time = None
        self._no_input = ""
        self._tail = b""
        self._connection = connection_of(path)
        self._device_profile = self._calibrated(device)

    def _calibrated(self, device) -> Profile:
        """The profile with the IMU calibration the device reports, or as it is (nominal
        scales) when the device gives none."""
        if not self.profile.calibration:
            self._calibration = ""
            return self.profile
        from .calibration import read_calibration
        calibration, problem = read_calibration(device, self.profile.calibration,
                                                self._connection)
        if calibration is None or not calibration.affine():
            self._calibration = "nominal"
            log.info("%s: no IMU calibration from the device (%s); nominal scales",
                     self.spec, problem or "no usable axis")
            return self.profile
        self._calibration = "device" if calibration.complete else "device (some axes nominal)"
        return self.profile.with_affine(calibration.affine())

    def _pump(self, timeout: float) -> None:
        data = self._device.read(self.profile.read_size, max(1, int(timeout * 1000)))
        if not data:
            return
        t = self.clock.now()
        full = len(data) >= self.profile.read_size
        data = self._tail + bytes(data) if self._tail else bytes(data)
        # a read that filled the buffer may have stopped inside a report (stream-like nodes)
        reports, self._tail = self._split(self.profile, data, allow_tail=full)
        for report in reports:
            try:
                parsed = self._parse_into(self._device_profile, report, self._state,
                                          self._status)
            except ValueError as error:     # MalformedReport: count it, keep reading
                self._problem(str(error), malformed=True)
                continue
            if parsed.skipped:
                if parsed.skipped != self._no_input:   # counted once per change, not per report
                    self._problem(parsed.skipped)
                self._no_input = parsed.skipped
                continue
            if self._no_input and self._calibration == "nominal":
                # a controller has just connected to a receiver that had none: its
                # calibration can be read now (the kernel does the same)
                self._device_profile = self._calibrated(self._device)
                parsed = self._parse_into(self._device_profile, report, self._state,
                                          self._status)
            self._no_input = ""
            if self._sensor_clock is not None:
                self._sensor_time = self._sensor_clock.update(
                    self._status[self._status_clock_index])
            if parsed.carried_input:
                self._emit(t, self._state.copy())

    def _close_device(self) -> None:
        device, self._device = self._device, None
        if device is not None:
            device.close()
