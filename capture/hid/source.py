"""HID gloves and controllers through hidapi (the `hidraw` backend on Linux).

`HidSource(profile)` finds a device the profile fits (or opens the one given by path or
vendor:product), reads its input reports on a thread, parses each with the profile (a pure
function of the bytes) and holds the last value of channels carried by other reports. When the
device goes away the source reports DISCONNECTED and opens it again when it is back.
"""
from __future__ import annotations

import logging
import sys

import numpy as np

from ..clock import MonotonicClock
from ..source import ThreadedSource
from .profile import Profile, available_profiles, load_profile

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


def list_hid_devices() -> list[dict]:
    """HID devices with the profiles that fit them: each dict from `enumerate_devices` plus
    "profiles": [profile names] (the generic profile fits every device). One entry per path."""
    profiles = available_profiles()
    seen, out = set(), []
    for device in enumerate_devices():
        path = device.get("path")
        if path in seen:
            continue
        seen.add(path)
        names = [name for name, p in profiles.items()
                 if p.matches(device.get("vendor_id", -1), device.get("product_id", -1))]
        entry = dict(device)
        entry["profiles"] = names + (["generic"] if "generic" in profiles else [])
        out.append(entry)
    return out


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
        self._tail = b""
        self._device = None
        self.device_info: dict = {}
        # numba compiles the decoder (or loads it from its cache) here, at open time, rather
        # than on the first report
        from .parse import parse_into, split_reports
        self._parse_into, self._split = parse_into, split_reports
        warm = np.full(len(self.channels), np.nan)
        for report in self.profile.reports[:1]:
            dummy = bytearray(report.length)
            if report.report_id is not None:
                dummy[0] = report.report_id
            parse_into(self.profile, bytes(dummy), warm)
        self._start(wait=wait)

    def describe(self) -> dict:
        info = super().describe()
        info.update(profile=self.profile.name, units=list(self.profile.units),
                    device={k: (v.decode() if isinstance(v, bytes) else v)
                            for k, v in self.device_info.items()})
        return info

    def _find(self) -> tuple[bytes, dict]:
        if self._path:
            return self._path, {"path": self._path}
        devices = enumerate_devices()
        for device in devices:
            vendor, product = device.get("vendor_id"), device.get("product_id")
            if self._vendor_id is not None:
                fits = vendor == self._vendor_id and (self._product_id is None
                                                      or product == self._product_id)
            else:
                fits = self.profile.matches(vendor, product)
            if fits:
                return device["path"], device
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
        self._tail = b""

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
                self._parse_into(self.profile, report, self._state)
            except ValueError as error:     # MalformedReport: count it, keep reading
                self._problem(str(error), malformed=True)
                continue
            self._emit(t, self._state.copy())

    def _close_device(self) -> None:
        device, self._device = self._device, None
        if device is not None:
            device.close()
