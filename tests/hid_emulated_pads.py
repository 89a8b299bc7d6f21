"""The kernel HID selftests' emulated DualShock 4 and DualSense (package hid-tools, module
hidtools), used here only to build report bytes from values: their devices normally register
with the kernel through /dev/uhid, which these machines do not have, so that node is not
opened (`emulated`). hid-tools has no argument for the analog triggers (usages Rx, Ry of the
report descriptor): `emulated` devices take `device.triggers = (l2, r2)`, still placed by
hid-tools' report builder from the real descriptor."""
from __future__ import annotations

import os
from contextlib import contextmanager

import pytest

try:
    from hidtools import uhid as hidtools_uhid
    from hidtools.device import base_device, sony_gamepad
    from hidtools.device.base_gamepad import BaseGamepad
    MISSING = ""
except (ImportError, OSError) as error:     # OSError: the libevdev.so.2 it loads is missing
    hidtools_uhid = base_device = sony_gamepad = BaseGamepad = None
    MISSING = (f"hid-tools is not usable ({error}); pip install 'hid-tools[uhid]' and "
               f"apt-get install libevdev2 (scripts/setup.sh --test does both)")


class _NoUhid:
    """The os module as hidtools.uhid sees it, with /dev/uhid opened as /dev/null."""

    def __getattr__(self, name):
        return getattr(os, name)

    @staticmethod
    def open(path, flags, *args):
        return os.open(os.devnull if path == "/dev/uhid" else path, flags, *args)


def _with_triggers(cls):
    class WithTriggers(cls):
        triggers = (0, 0)

        def store_axes(self, which, gamepad, data):
            super().store_axes(which, gamepad, data)
            gamepad.rx, gamepad.ry = self.triggers

    WithTriggers.__name__ = cls.__name__
    return WithTriggers


@contextmanager
def emulated(class_name: str):
    """An emulated pad: "PS4ControllerUSB", "PS4ControllerBluetooth", "PS5ControllerUSB" or
    "PS5ControllerBluetooth"."""
    if MISSING:
        pytest.skip(MISSING)
    cls = _with_triggers(getattr(sony_gamepad, class_name))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(hidtools_uhid, "os", _NoUhid())
        patch.setattr(base_device, "UdevHIDIsReady", base_device.HIDIsReady)
        device = cls()
    try:
        yield device
    finally:
        hidtools_uhid.UHIDDevice._remove_fd_from_poll(device.fd)
        hidtools_uhid.UHIDDevice._devices.remove(device)
        os.close(device.fd)


def feature_report(device, report_id: int) -> bytes:
    """A feature report of the emulated pad (report id first)."""
    code, data = device.get_report(0, report_id, 0)
    if code != 0:
        raise OSError(f"the emulated pad has no feature report {report_id:#04x}")
    return bytes(data)
