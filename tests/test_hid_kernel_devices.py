"""The DualShock 4 and DualSense profiles against an independent source: the emulated pads the
Linux kernel's HID selftests feed to hid-playstation (package hid-tools, module hidtools).

hid-tools builds each input report from the pad's real report descriptor (sticks, hat, buttons,
triggers placed by the HID parser) and fills the vendor part (gyro, accelerometer, touchpad,
battery) as the driver reads it; the IMU values it takes are the driver's calibrated units
(1/1024 deg/s, 1/8192 g), turned into raw counts with the calibration its feature reports
carry. Here random values go in, and mop's parsed channels must give them back. What hid-tools
0.12 does not emulate is covered by hand-written vectors in test_hid_parse.py: the IMU sensor
timestamp (it leaves those bytes 0), the PS and mute buttons (not among its settable buttons)
and the DualShock 4 USB adaptor.

Only the report building of hid-tools is used (tests/hid_emulated_pads.py).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from capture.hid.calibration import CalibrationError, parse_calibration, requests
from capture.hid.parse import parse_into, parse_report, parse_report_reference
from capture.hid.profile import load_profile
from capture.hid.status import BatteryState, Connection, battery_from_status
from hid_emulated_pads import MISSING, BaseGamepad, emulated, feature_report, sony_gamepad

if MISSING:
    pytest.skip(MISSING, allow_module_level=True)

G = 9.80665
GYRO_UNIT = 1024 * 180 / math.pi        # kernel units (1/1024 deg/s) per rad/s
ACCEL_UNIT = 8192 / G                   # kernel units (1/8192 g) per m/s^2
# hid-tools' button numbers, in the order of its buttons_map (BTN_WEST, BTN_SOUTH, ...)
BUTTONS = {1: "square", 2: "cross", 3: "circle", 4: "triangle", 5: "l1", 6: "r1",
           7: "l2_button", 8: "r2_button", 9: "share", 10: "options", 11: "l3", 12: "r3"}
# the kernel's hat table (hid-playstation ps_gamepad_hat_mapping): N, NE, E, SE, S, SW, W, NW,
# then 8 and above centre; y is down-positive, as in mop
HAT = [(0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1)]

DEVICES = {
    "dualshock4-usb": ("PS4ControllerUSB", "dualshock4", Connection.USB, (1920, 942)),
    "dualshock4-bluetooth": ("PS4ControllerBluetooth", "dualshock4", Connection.BLUETOOTH,
                             (1920, 942)),
    "dualsense-usb": ("PS5ControllerUSB", "dualsense", Connection.USB, (1920, 1080)),
    "dualsense-bluetooth": ("PS5ControllerBluetooth", "dualsense", Connection.BLUETOOTH,
                            (1920, 1080)),
}


class Checks:
    """Counts the field comparisons a test makes (so that a test that compared nothing
    fails)."""

    def __init__(self):
        self.count = 0

    def equal(self, got, want, what):
        self.count += 1
        assert got == want, f"{what}: got {got}, expected {want}"

    def close(self, got, want, tolerance, what):
        self.count += 1
        assert abs(got - want) <= tolerance, f"{what}: got {got}, expected {want} +- {tolerance}"


def feature_calibration(device, kind, connection):
    """The calibration mop reads from the emulated pad's own feature report."""
    request = requests(kind, connection)[0]
    return parse_calibration(feature_report(device, request.report_id), request)


def random_event(rng, size, touched):
    """Arguments for hid-tools' create_report, drawn at random."""
    width, height = size
    event = dict(left=tuple(int(v) for v in rng.integers(0, 256, 2)),
                 right=tuple(int(v) for v in rng.integers(0, 256, 2)),
                 hat_switch=int(rng.integers(0, 16)),
                 buttons={b: bool(rng.integers(0, 2)) for b in BUTTONS},
                 gyro=tuple(int(v) for v in rng.integers(-1_900_000, 1_900_001, 3)),
                 accel=tuple(int(v) for v in rng.integers(-30_000, 30_001, 3)))
    if touched:
        ids = rng.choice(128, size=int(rng.integers(1, 3)), replace=False)
        event["touch"] = []
        for i in ids:
            point = sony_gamepad.PSTouchPoint(int(i), int(rng.integers(0, width)),
                                              int(rng.integers(0, height)))
            point.tipswitch = bool(rng.random() < 0.8)     # else: this finger lifts
            event["touch"].append(point)
    return event


def expected_battery(kind, battery, connection):
    """(level 0..1, state) as hid-playstation reads what hid-tools writes for `battery`."""
    cable = battery.cable_connected or connection is Connection.USB
    if kind == "dualshock4":
        data = 11 if battery.full else battery.capacity // 10
        if not cable:
            return (min(data * 10 + 5, 100) / 100, BatteryState.DISCHARGING)
        if data == 11:
            return 1.0, BatteryState.FULL
        return min(data * 10 + 5, 100) / 100, BatteryState.CHARGING
    if battery.full:
        return 1.0, BatteryState.FULL
    state = BatteryState.CHARGING if cable else BatteryState.DISCHARGING
    return min(battery.capacity // 10 * 10 + 5, 100) / 100, state


def check_event(checks, v, event, size, triggers):
    """Every channel of one parsed report against the values hid-tools was given."""
    for name, raw in zip(("lx", "ly", "rx", "ry"), event["left"] + event["right"]):
        checks.equal(round(v[name] * 127.5 + 127.5, 6), raw, name)
    x, y = HAT[event["hat_switch"]] if event["hat_switch"] < 8 else (0, 0)
    checks.equal((v["dpad_x"], v["dpad_y"]), (x, y), f"d-pad for hat {event['hat_switch']}")
    for number, name in BUTTONS.items():
        name = name if name in v else "create"          # the DualSense's share button
        checks.equal(v[name], float(event["buttons"][number]), name)
    for name, raw in zip(("l2", "r2"), triggers):
        checks.equal(round(v[name] * 255, 6), raw, name)
    check_imu(checks, v, event)
    check_touch(checks, v, event, size)


def check_imu(checks, v, event):
    # one raw count either way: hid-tools truncates when it turns units into counts
    for axis, want in zip("xyz", event["gyro"]):
        checks.close(v[f"gyro_{axis}"] * GYRO_UNIT, want, 63.0, f"gyro_{axis}")
    for axis, want in zip("xyz", event["accel"]):
        checks.close(v[f"accel_{axis}"] * ACCEL_UNIT, want, 1.01, f"accel_{axis}")


def check_touch(checks, v, event, size):
    width, height = size
    points = event.get("touch")
    if points is None:
        for k in (0, 1):
            checks.equal(v[f"touch{k}_down"], 0.0, f"touch{k}_down")
            checks.equal(math.isnan(v[f"touch{k}_x"]), True, f"touch{k}_x without a finger")
        return
    seen = set()
    for k in (0, 1):
        if v[f"touch{k}_down"] == 1.0:
            seen.add((round(v[f"touch{k}_x"] * (width - 1)),
                      round(v[f"touch{k}_y"] * (height - 1))))
        else:
            checks.equal(math.isnan(v[f"touch{k}_y"]), True, f"touch{k}_y without a finger")
    checks.equal(seen, {(p.x, p.y) for p in points if p.tipswitch}, "touch points")


@pytest.mark.parametrize("name", sorted(DEVICES))
def test_emulated_pads_reports_give_back_what_was_put_in(name, rng):
    class_name, kind, connection, size = DEVICES[name]
    nominal = load_profile(kind)
    checks = Checks()
    with emulated(class_name) as device:
        calibration = feature_calibration(device, kind, connection)
        profile = nominal.with_affine(calibration.affine())
        for index in range(60):
            device.triggers = tuple(int(t) for t in rng.integers(0, 256, 2))
            battery = device.battery
            battery.cable_connected = bool(rng.integers(0, 2))
            battery.capacity = int(rng.integers(0, 101))
            battery.full = bool(rng.integers(0, 2)) and battery.capacity == 100
            event = random_event(rng, size, touched=index >= 10)
            report = bytes(device.create_report(**event))
            assert report[0] == (0x01 if connection is Connection.USB else
                                 {"dualshock4": 0x11, "dualsense": 0x31}[kind])
            state = np.full(len(profile.channels), np.nan)
            status = np.full(len(profile.status), np.nan)
            parsed = parse_into(profile, report, state, status)
            checks.equal(parsed.skipped, "", "skipped")
            v = dict(zip(profile.channels, state))
            check_event(checks, v, event, size, device.triggers)
            level, state_, _ = battery_from_status(profile, status)
            want_level, want_state = expected_battery(kind, battery, connection)
            checks.close(level, want_level, 1e-9, "battery")
            checks.equal(state_, want_state, "battery state")
            # the numba kernel and the slow reference agree on what the emulator sent
            np.testing.assert_array_equal(parse_report(profile, report),
                                          parse_report_reference(profile, report))
    assert checks.count >= 60 * 29      # 29 to 31 per report


def test_calibration_read_from_the_emulated_feature_reports():
    """The calibration parsed from each emulated pad's feature report is the one hid-tools
    lists as hid-playstation's result for it (bias, numerator, denominator per axis)."""
    checks = Checks()
    for class_name, kind, connection, _ in DEVICES.values():
        with emulated(class_name) as device:
            calibration = feature_calibration(device, kind, connection)
            for axes, reference, unit in ((calibration.gyro, device.gyroscope_calibration_data,
                                           1024),
                                          (calibration.accel,
                                           device.accelerometer_calibration_data, 8192)):
                for axis, key in zip(axes, "xyz"):
                    want = reference[key]
                    checks.equal(axis.bias, want["bias"], f"{class_name} {key} bias")
                    checks.equal(axis.denom, want["denom"], f"{class_name} {key} denom")
                    checks.equal(axis.numer * unit, want["numer"], f"{class_name} {key} numer")
            assert calibration.complete
    assert checks.count == 4 * 2 * 3 * 3


def test_bluetooth_calibration_with_a_bad_crc_is_refused():
    with emulated("PS5ControllerBluetooth") as device:
        request = requests("dualsense", Connection.BLUETOOTH)[0]
        data = bytearray(feature_report(device, request.report_id))
        parse_calibration(bytes(data), request)                 # signed by the emulator
        data[5] ^= 0x01
        with pytest.raises(CalibrationError, match="CRC32"):
            parse_calibration(bytes(data), request)


@pytest.mark.parametrize("class_name, kind", [("PS4ControllerBluetooth", "dualshock4"),
                                              ("PS5ControllerBluetooth", "dualsense")])
def test_bluetooth_short_report_from_the_descriptor(class_name, kind, rng):
    """Report 0x01 of the Bluetooth descriptors (10 bytes): what a pad sends before it is
    switched to the full report, and what some third-party pads always send."""
    profile = load_profile(kind)
    checks = Checks()
    with emulated(class_name) as device:
        for _ in range(40):
            device.triggers = tuple(int(t) for t in rng.integers(0, 256, 2))
            event = random_event(rng, (1920, 942), touched=False)
            del event["gyro"], event["accel"]
            report = bytes(BaseGamepad.create_report(device, **event))
            checks.equal((report[0], len(report)), (0x01, 10), "short report id and size")
            v = dict(zip(profile.channels, parse_report(profile, report)))
            for name, raw in zip(("lx", "ly", "rx", "ry"), event["left"] + event["right"]):
                checks.equal(round(v[name] * 127.5 + 127.5, 6), raw, name)
            x, y = HAT[event["hat_switch"]] if event["hat_switch"] < 8 else (0, 0)
            checks.equal((v["dpad_x"], v["dpad_y"]), (x, y), "d-pad")
            for number, name in BUTTONS.items():
                name = name if name in v else "create"
                checks.equal(v[name], float(event["buttons"][number]), name)
            for name, raw in zip(("l2", "r2"), device.triggers):
                checks.equal(round(v[name] * 255, 6), raw, name)
            # the short report carries no IMU, touchpad or battery
            assert math.isnan(v["gyro_x"]) and math.isnan(v["touch0_down"])
    assert checks.count == 40 * 20


def test_the_usb_adaptor_without_a_controller_carries_no_input():
    """The DualShock 4 USB Wireless Adaptor keeps sending report 0x01 when no controller is
    connected, near zero (sticks at -1, d-pad up), with byte 31 bit 2 set (hid-playstation's
    DS4_STATUS1_DONGLE_STATE): no channel and no status is taken from it."""
    profile = load_profile("dualshock4")
    with emulated("PS4ControllerUSB") as device:
        connected = bytearray(device.create_report(left=(0, 0), right=(0, 0), hat_switch=0))
    absent = bytearray(connected)
    absent[31] |= 0x04
    state = np.full(len(profile.channels), np.nan)
    status = np.full(len(profile.status), np.nan)
    parsed = parse_into(profile, bytes(absent), state, status)
    assert parsed.skipped == "no controller connected to the USB Wireless Adaptor"
    assert not parsed.carried_input
    assert np.isnan(state).all() and np.isnan(status).all()
    assert np.isnan(parse_report(profile, bytes(absent))).all()
    assert np.isnan(parse_report_reference(profile, bytes(absent))).all()
    # the same report with the controller there is input: full left, full up
    v = dict(zip(profile.channels, parse_report(profile, bytes(connected))))
    assert (v["lx"], v["ly"], v["dpad_y"]) == (-1.0, -1.0, -1.0)
