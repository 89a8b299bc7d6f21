"""HID report parsing: a pure function of the bytes, checked field by field on report bytes laid
out as each device sends them, against values worked out by hand; the numba kernel against the
slow int.from_bytes reference on random reports; malformed reports; profile-file errors. The
DualShock 4 and DualSense are also checked against the kernel's emulated pads
(test_hid_kernel_devices.py); the vectors here cover what that emulation leaves out (the IMU
clock, the PS and mute buttons, the USB adaptor) and the devices it does not have."""
import logging
import math
import zlib

import numpy as np
import pytest

from capture.hid.calibration import (CalibrationError, FeatureRequest, ImuCalibration,
                                     parse_calibration, requests)
from capture.hid.parse import (MalformedReport, parse_into, parse_report,
                               parse_report_reference, parse_status, parse_status_reference,
                               split_reports)
from capture.hid.profile import (ProfileError, available_profiles, load_profile, parse_profile,
                                 skipped_profiles)
from capture.hid.status import (BatteryState, Connection, SensorClock, battery_from_status,
                                connection_of)

GYRO = math.pi / 180 / 16.384     # rad/s per count (2000 deg/s full scale)
G = 9.80665


def hexbytes(text):
    return bytes.fromhex(text.replace(" ", ""))


def values(profile, data):
    out = parse_report(profile, hexbytes(data) if isinstance(data, str) else data)
    return dict(zip(profile.channels, out))


def status(profile, data):
    out = parse_status(profile, hexbytes(data) if isinstance(data, str) else data)
    return dict(zip(profile.status, out))


def signed(data, seed=0xA1):
    """A Bluetooth report with its CRC32 (of the seed byte and the bytes before it) in its
    last 4 bytes."""
    data = bytearray(data)
    crc = zlib.crc32(bytes(data[:-4]), zlib.crc32(bytes([seed])))
    data[-4:] = crc.to_bytes(4, "little")
    return bytes(data)


def test_shipped_profiles_load_and_fit_their_devices():
    profiles = available_profiles()
    assert {"p5", "spacemouse", "dualshock4", "dualsense", "generic"} <= set(profiles)
    assert profiles["spacemouse"].matches(0x046D, 0xC626)
    assert profiles["dualshock4"].matches(0x054C, 0x09CC)
    assert profiles["dualshock4"].matches(0x054C, 0x0BA0)          # the USB adaptor
    assert profiles["dualsense"].matches(0x054C, 0x0CE6)
    assert not profiles["dualsense"].matches(0x054C, 0x09CC)
    assert profiles["p5"].channels[:5] == ("index", "middle", "ring", "pinky", "thumb")
    assert profiles["generic"].channels == tuple(f"byte{i}" for i in range(64))
    assert profiles["dualshock4"].status == ("battery", "battery_state", "cable", "sensor_time")
    assert profiles["dualsense"].calibration == "dualsense"
    touch = [f"touch{k}_{a}" for k in (0, 1) for a in ("x", "y", "down")]
    assert set(touch) <= set(profiles["dualshock4"].channels)
    assert set(touch) <= set(profiles["dualsense"].channels)
    buttons = [f"button_{k}" for k in range(1, 33)]
    assert profiles["spacemouse"].channels[6:] == tuple(buttons)


def test_spacemouse_opens_only_the_multi_axis_interface():
    """The Universal Receiver has one vendor:product for its 3D-mouse, mouse and keyboard
    interfaces; only Generic Desktop / Multi-axis Controller (0x01 / 0x08) is the SpaceMouse."""
    mouse = load_profile("spacemouse")
    assert mouse.matches(0x256F, 0xC652, usage_page=0x01, usage=0x08)
    assert not mouse.matches(0x256F, 0xC652, usage_page=0x01, usage=0x02)     # its mouse
    assert not mouse.matches(0x256F, 0xC652, usage_page=0x0C, usage=0x01)     # consumer keys
    assert mouse.matches(0x256F, 0xC652, usage_page=0, usage=0)   # the system does not say
    assert mouse.matches(0x256F, 0xC652)


def test_p5_style_glove_report():
    p5 = load_profile("p5")
    v = values(p5, "01"          # report id 1
                   "fc 08 01 54"  # bends, 6 bits each MSB-first from bit 8:
                                  #   111111 000000 100000 000001 010101 -> 63, 0, 32, 1, 21
                   "50"           # bits 38-39 pad, bits 40-43 button nibble 0101 -> A and C
                   "d2 04"        # x = 1234 -> 0.1234 m
                   "0c fe"        # y = -500 -> -0.05 m
                   "b8 0b"        # z = 3000 -> 0.3 m
                   "28 23"        # yaw = 9000 -> 90 degrees
                   "6c ee"        # pitch = -4500 -> -45 degrees
                   "00 00")       # roll = 0
    assert v["index"] == pytest.approx(1.0)
    assert v["middle"] == 0.0
    assert v["ring"] == pytest.approx(32 / 63)
    assert v["pinky"] == pytest.approx(1 / 63)
    assert v["thumb"] == pytest.approx(21 / 63)
    assert (v["button_a"], v["button_b"], v["button_c"]) == (1.0, 0.0, 1.0)
    assert (v["x"], v["y"], v["z"]) == pytest.approx((0.1234, -0.05, 0.3))
    assert (v["yaw"], v["pitch"], v["roll"]) == pytest.approx((math.pi / 2, -math.pi / 4, 0.0))


def test_spacemouse_separate_and_combined_reports():
    mouse = load_profile("spacemouse")
    t = values(mouse, "01"      # report 1, 7 bytes: translation (older SpaceNavigator)
                      "5e 01"   # tx = 350 -> 1.0 (full deflection)
                      "a2 fe"   # ty = -350 -> -1.0
                      "00 00")  # tz = 0
    assert (t["tx"], t["ty"], t["tz"]) == pytest.approx((1.0, -1.0, 0.0))
    assert math.isnan(t["rx"]) and math.isnan(t["button_1"])   # not in this report
    r = values(mouse, "02"      # report 2: rotation
                      "af 00"   # rx = 175 -> 0.5
                      "00 00"   # ry = 0
                      "51 ff")  # rz = -175 -> -0.5
    assert (r["rx"], r["ry"], r["rz"]) == pytest.approx((0.5, 0.0, -0.5))
    assert math.isnan(r["tx"])
    m = values(mouse, "01"          # report 1, 13 bytes (newer devices): all six axes
                      "5e 01 00 00 00 00"   # tx = 1.0, ty = tz = 0
                      "af 00 00 00 00 00")  # rx = 0.5, ry = rz = 0
    assert (m["tx"], m["rx"], m["rz"]) == pytest.approx((1.0, 0.5, 0.0))


def test_spacemouse_buttons_read_every_bit_of_the_bitmask():
    mouse = load_profile("spacemouse")
    b = values(mouse, "03"      # report 3, 3 bytes (SpaceNavigator): buttons 1..16
                      "02 00")  # bit 1: right button
    assert (b["button_1"], b["button_2"]) == (0.0, 1.0)
    assert math.isnan(b["button_17"])                           # not in a 16-bit bitmask
    pro = values(mouse, "03"    # report 3, 5 bytes (SpaceMouse Pro): buttons 1..32
                        "01"    # bit 0: button 1
                        "00"
                        "40"    # byte 3 bit 6 = bit 22: button 23
                        "05")   # byte 4 bits 0, 2 = bits 24, 26: buttons 25 and 27
    pressed = [k for k in range(1, 33) if pro[f"button_{k}"] == 1.0]
    assert pressed == [1, 23, 25, 27]
    assert sum(pro[f"button_{k}"] == 0.0 for k in range(1, 33)) == 28
    longer = values(mouse, "03 00 00 00 80 00 00")   # 7 bytes: the 32-bit layout, rest ignored
    assert longer["button_32"] == 1.0


def test_spacemouse_wireless_battery_report():
    mouse = load_profile("spacemouse")
    report = hexbytes("17"      # report 0x17: battery
                      "37"      # 55 %
                      "00")
    assert status(mouse, report)["battery"] == pytest.approx(0.55)
    state = np.full(len(mouse.channels), 0.5)
    parsed = parse_into(mouse, report, state)
    assert not parsed.carried_input and (state == 0.5).all()    # no input in it
    level, battery_state, cable = battery_from_status(mouse, parse_status(mouse, report))
    assert (level, battery_state, cable) == (pytest.approx(0.55), None, None)


DS4_USB = ("01"        # report id 1 (USB)
           "ff"        # lx = 255 -> +1 (full right)
           "80"        # ly = 128 -> +0.0039 (down)
           "00"        # rx = 0 -> -1 (full left)
           "7f"        # ry = 127 -> -0.0039 (up)
           "21"        # hat 1 (north-east) in the low nibble; bit 5 = cross
           "11"        # bit 0 = L1, bit 4 = share
           "09"        # bit 0 = PS; counter = 0x09 >> 2 = 2
           "ff"        # L2 analog = 255 -> 1
           "00"        # R2 analog = 0
           "3412"      # IMU clock 0x1234 = 4660 counts of 16/3 us -> 24.853 ms
           "1b"        # battery temperature (not read)
           "1000"      # gyro x = 16 counts -> 1 deg/s
           "f0ff"      # gyro y = -16 counts -> -1 deg/s
           "0000"      # gyro z = 0
           "0000"      # accel x = 0
           "0020"      # accel y = 8192 counts -> 1 g
           "00e0"      # accel z = -8192 counts -> -1 g
           "0000000000"    # bytes 25..29 reserved
           "1b"        # byte 30: bit 4 cable in, level 11 = full
           "00"        # byte 31: bit 2 clear (a USB adaptor has a controller)
           "00"        # byte 32 reserved
           "01"        # byte 33: one touch record
           "2a"        # byte 34: the record's touch clock
           "05"        # byte 35: point 0 active (bit 7 clear), contact id 5
           "c0 73 1d"  # x = 0x3c0 = 960 (c0 + low nibble 3), y = 0x1d7 = 471 (nibble 7, 1d)
           "86 000000"  # point 1 inactive (bit 7 set): no finger
           ) + "00" * 21


def check_ds4(v, st):
    assert (v["lx"], v["rx"]) == pytest.approx((1.0, -1.0))
    assert (v["ly"], v["ry"]) == pytest.approx((0.5 / 127.5, -0.5 / 127.5))
    assert (v["dpad_x"], v["dpad_y"]) == (1.0, -1.0)       # north-east: right and up
    assert (v["cross"], v["square"], v["circle"], v["triangle"]) == (1.0, 0.0, 0.0, 0.0)
    assert (v["l1"], v["r1"], v["share"], v["options"]) == (1.0, 0.0, 1.0, 0.0)
    assert (v["ps"], v["touchpad_click"], v["counter"]) == (1.0, 0.0, 2.0)
    assert (v["l2"], v["r2"]) == (1.0, 0.0)
    assert (v["gyro_x"], v["gyro_y"], v["gyro_z"]) == pytest.approx((16 * GYRO, -16 * GYRO, 0))
    assert (v["accel_x"], v["accel_y"], v["accel_z"]) == pytest.approx((0.0, G, -G))
    assert (v["touch0_down"], v["touch0_x"], v["touch0_y"]) == pytest.approx(
        (1.0, 960 / 1919, 471 / 941))
    assert v["touch1_down"] == 0.0 and math.isnan(v["touch1_x"]) and math.isnan(v["touch1_y"])
    assert st["sensor_time"] == pytest.approx(4660 * 16 / 3 * 1e-6)
    assert (st["battery"], st["battery_state"], st["cable"]) == (1.0, 2.0, 1.0)


def test_dualshock4_bluetooth_report_is_the_usb_layout_two_bytes_later():
    ds4 = load_profile("dualshock4")
    bluetooth = signed(hexbytes("11" + "c0" + "00" + DS4_USB[2:]) + bytes(12))  # 2 header bytes
    assert len(bluetooth) == 78
    check_ds4(values(ds4, bluetooth), status(ds4, bluetooth))
    damaged = bytearray(bluetooth)
    damaged[5] ^= 0x10                  # one bit flipped on the way: the CRC32 catches it
    with pytest.raises(MalformedReport, match=r"report 0x11 \(bluetooth\): CRC32 does not"):
        parse_report(ds4, bytes(damaged))


def test_dualshock4_bluetooth_short_report():
    ds4 = load_profile("dualshock4")
    v = values(ds4, "01"        # report id 1, 10 bytes: Bluetooth before the switch
                    "00 ff"     # lx = -1, ly = +1 (down)
                    "80 80"     # right stick centred
                    "86"        # hat 6 (west); bit 7 = triangle
                    "00"
                    "01"        # PS
                    "00 80")    # L2 = 0, R2 = 128
    assert (v["lx"], v["ly"], v["dpad_x"], v["dpad_y"]) == (-1.0, 1.0, -1.0, 0.0)
    assert (v["triangle"], v["ps"], v["r2"]) == (1.0, 1.0, pytest.approx(128 / 255))
    assert math.isnan(v["gyro_x"]) and math.isnan(v["touch0_down"])


DS5_USB = ("01"         # report id 1 (USB)
           "80"         # lx = 128
           "00"         # ly = 0 -> -1 (full up)
           "80 80"      # rx, ry centred
           "80"         # L2 = 128 -> 0.502
           "ff"         # R2 = 255 -> 1
           "2a"         # sequence number 42
           "88"         # hat 8 = released; bit 7 = triangle
           "22"         # bit 1 = R1, bit 5 = options
           "05"         # bit 0 = PS, bit 2 = mute
           "00"         # buttons[3]
           "00000000"   # bytes 12..15 reserved
           "0000"       # gyro x = 0
           "0004"       # gyro y = 1024 counts -> 62.5 deg/s
           "00fc"       # gyro z = -1024 counts
           "0000"       # accel x
           "0020"       # accel y = 8192 -> 1 g
           "0000"       # accel z
           "78563412"   # IMU clock 0x12345678 counts of 1/3 us -> 101.807 s
           "00"         # byte 32 reserved
           "01 c0 73 1d"    # point 0: active, id 1, x = 960, y = 471
           "82 000000"  # point 1 inactive
           + "00" * 12 +    # bytes 41..52 reserved
           "1a"         # byte 53: charging (high nibble 1), level 10 = 100 %
           ) + "00" * 10


def check_ds5(v, st):
    assert v["ly"] == pytest.approx(-1.0) and v["lx"] == pytest.approx(0.5 / 127.5)
    assert (v["l2"], v["r2"], v["counter"]) == pytest.approx((128 / 255, 1.0, 42.0))
    assert (v["dpad_x"], v["dpad_y"]) == (0.0, 0.0)
    assert (v["triangle"], v["cross"], v["r1"], v["options"], v["l1"]) == (1, 0, 1, 1, 0)
    assert (v["ps"], v["mute"], v["touchpad_click"]) == (1, 1, 0)
    assert v["gyro_y"] == pytest.approx(1024 * GYRO) and v["gyro_z"] == pytest.approx(-1024 * GYRO)
    assert v["accel_y"] == pytest.approx(G)
    assert (v["touch0_down"], v["touch0_x"], v["touch0_y"]) == pytest.approx(
        (1.0, 960 / 1919, 471 / 1079))
    assert v["touch1_down"] == 0.0 and math.isnan(v["touch1_y"])
    assert st["sensor_time"] == pytest.approx(0x12345678 / 3 * 1e-6)
    assert (st["battery"], st["battery_state"]) == (1.0, 1.0)


@pytest.mark.parametrize("name, report, check", [("dualshock4", DS4_USB, check_ds4),
                                                 ("dualsense", DS5_USB, check_ds5)])
def test_usb_reports(name, report, check):
    profile = load_profile(name)
    assert len(hexbytes(report)) == 64
    check(values(profile, report), status(profile, report))


def test_dualsense_bluetooth_report_is_the_usb_layout_one_byte_later():
    ds5 = load_profile("dualsense")
    bluetooth = signed(hexbytes("31"        # report id 0x31 (Bluetooth)
                                "00"        # sequence number and tag
                                + DS5_USB[2:])   # the USB report's 63 bytes after its id
                       + bytes(13)          # bytes 65..73, then the CRC32 (bytes 74..77)
                       )
    assert len(bluetooth) == 78
    check_ds5(values(ds5, bluetooth), status(ds5, bluetooth))
    with pytest.raises(MalformedReport, match="CRC32 does not match"):
        parse_report(ds5, bluetooth[:-1] + bytes([bluetooth[-1] ^ 1]))


def test_dpad_hat_values_map_to_directions_and_released_above_seven():
    ds4 = load_profile("dualshock4")
    expected = {0: (0, -1), 1: (1, -1), 2: (1, 0), 3: (1, 1), 4: (0, 1), 5: (-1, 1),
                6: (-1, 0), 7: (-1, -1)}
    expected.update({hat: (0, 0) for hat in range(8, 16)})     # the null state: centre
    for hat, (x, y) in expected.items():
        data = bytearray(hexbytes(DS4_USB))
        data[5] = (data[5] & 0xF0) | hat
        v = dict(zip(ds4.channels, parse_report(ds4, bytes(data))))
        assert (v["dpad_x"], v["dpad_y"]) == (x, y), hat


def test_touch_point_lifted_is_missing_not_zero():
    ds4 = load_profile("dualshock4")
    data = bytearray(hexbytes(DS4_USB))
    data[35] |= 0x80                     # point 0 lifted
    v = values(ds4, bytes(data))
    assert v["touch0_down"] == 0.0 and math.isnan(v["touch0_x"]) and math.isnan(v["touch0_y"])


def test_usb_adaptor_without_controller_is_no_input_and_no_battery():
    ds4 = load_profile("dualshock4")
    adaptor = bytearray(64)              # what the adaptor sends with no controller: zeros...
    adaptor[0] = 0x01
    adaptor[31] = 0x04                   # ...and byte 31 bit 2 set
    state = np.full(len(ds4.channels), 0.25)
    st = np.full(len(ds4.status), 0.5)
    parsed = parse_into(ds4, bytes(adaptor), state, st)
    assert parsed.skipped == "no controller connected to the USB Wireless Adaptor"
    assert (state == 0.25).all() and (st == 0.5).all()
    adaptor[31] = 0x00                   # the same zeros from a connected pad are input
    assert parse_into(ds4, bytes(adaptor), state, st).carried_input
    assert state[ds4.channels.index("lx")] == -1.0


def battery_with(name, vector, position, byte):
    """battery_from_status of a vector with its status byte replaced."""
    profile = load_profile(name)
    data = bytearray(hexbytes(vector))
    data[position] = byte
    return battery_from_status(profile, parse_status(profile, bytes(data)))


@pytest.mark.parametrize("name, vector, position, byte, expected", [
    ("dualshock4", DS4_USB, 30, 0x05, (0.55, BatteryState.DISCHARGING, False)),
    ("dualshock4", DS4_USB, 30, 0x0A, (1.0, BatteryState.DISCHARGING, False)),
    ("dualshock4", DS4_USB, 30, 0x15, (0.55, BatteryState.CHARGING, True)),
    ("dualshock4", DS4_USB, 30, 0x1B, (1.0, BatteryState.FULL, True)),
    ("dualshock4", DS4_USB, 30, 0x1E, (None, None, True)),      # cable in, 14: charge error
    ("dualsense", DS5_USB, 53, 0x03, (0.35, BatteryState.DISCHARGING, None)),
    ("dualsense", DS5_USB, 53, 0x28, (1.0, BatteryState.FULL, None)),   # full, any level
    ("dualsense", DS5_USB, 53, 0xA4, (None, BatteryState.NOT_CHARGING, None)),
    ("dualsense", DS5_USB, 53, 0xF4, (None, None, None)),       # charging error: unknown
])
def test_battery_from_status_follows_the_driver(name, vector, position, byte, expected):
    level, state, cable = battery_with(name, vector, position, byte)
    assert (level if level is None else round(level, 9), state, cable) == expected


def test_sensor_clock_unwraps_the_device_clock():
    period = 65536 * 16 / 3 * 1e-6                     # the DualShock 4's: 0.35 s
    clock = SensorClock(period)
    ticks = [65000, 65400, 200, 600, 65300, 100]       # 4 ms steps but one of 1 s (not seen)
    times = [clock.update(t * 16 / 3 * 1e-6) for t in ticks]
    steps = np.diff(times) / (16 / 3 * 1e-6)
    np.testing.assert_allclose(steps, [400, 336, 400, 64700, 336])
    assert times[0] == 0.0 and clock.update(float("nan")) == times[-1]


def test_connection_of_something_that_is_not_a_hidraw_node():
    assert connection_of(None) is Connection.UNKNOWN
    assert connection_of("/dev/hidraw999") is Connection.UNKNOWN     # no such sysfs entry
    assert connection_of(b"/home/not-hidraw") is Connection.UNKNOWN


CALIBRATION_USB = ("02"                      # feature report 0x02 (DualShock 4, USB)
                   "0100 feff 0000"          # gyro bias pitch 1, yaw -2, roll 0
                   "2823 d8dc"               # pitch + 9000, pitch - -9000
                   "3223 cedc"               # yaw + 9010, yaw - -9010
                   "1e23 e2dc"               # roll + 8990, roll - -8990
                   "1c02 1c02"               # speed + 540, speed - 540 [deg/s]
                   "1020 f0df"               # accel x + 8208, x - -8208
                   "0020 00e0"               # accel y + 8192, y - -8192
                   "9c20 9cdf"               # accel z + 8348, z - -8292
                   "0000")                   # two bytes the driver does not read


def test_calibration_from_the_feature_report():
    request = requests("dualshock4", Connection.USB)[0]
    calibration = parse_calibration(hexbytes(CALIBRATION_USB), request)
    assert [a.denom for a in calibration.gyro] == [9000 - 1 + 9000 + 1, 9012 + 9008, 17980]
    assert [a.numer for a in calibration.gyro] == [1080] * 3
    assert [(a.bias, a.denom) for a in calibration.accel] == [(0, 16416), (0, 16384),
                                                              (28, 16640)]
    affine = calibration.affine()
    assert affine["gyro_x"] == (0.0, pytest.approx(1080 / 18000 * math.pi / 180))
    assert affine["accel_z"] == (28.0, pytest.approx(2 / 16640 * G))
    ds4 = load_profile("dualshock4").with_affine(affine)
    v = values(ds4, DS4_USB)
    assert v["gyro_x"] == pytest.approx(16 * 1080 / 18000 * math.pi / 180)
    assert v["accel_z"] == pytest.approx((-8192 - 28) * 2 / 16640 * G)
    assert v["lx"] == 1.0                                   # other channels untouched


def test_calibration_refuses_what_is_not_one_and_keeps_nominal_axes():
    request = requests("dualshock4", Connection.USB)[0]
    with pytest.raises(CalibrationError, match="expected feature report 0x02, got 0x05"):
        parse_calibration(b"\x05" + bytes(36), request)
    with pytest.raises(CalibrationError, match="is 10 bytes, expected 37"):
        parse_calibration(b"\x02" + bytes(9), request)
    zeros = parse_calibration(b"\x02" + bytes(36), request)     # a clone that fills zeros
    assert isinstance(zeros, ImuCalibration) and not zeros.complete
    assert zeros.affine() == {}                              # every axis stays nominal
    assert [r.report_id for r in requests("dualshock4", Connection.UNKNOWN)] == [0x02, 0x05]
    bluetooth = FeatureRequest(0x05, 41, False, True)
    with pytest.raises(CalibrationError, match="CRC32"):
        parse_calibration(b"\x05" + bytes(40), bluetooth)


@pytest.mark.parametrize("name", ["p5", "spacemouse", "dualshock4", "dualsense", "generic"])
def test_kernel_matches_slow_reference_on_random_reports(name, rng):
    profile = load_profile(name)
    for report in profile.reports:
        for _ in range(40):
            data = bytearray(rng.integers(0, 256, report.length, dtype=np.uint8).tobytes())
            if report.report_id is not None:
                data[0] = report.report_id
            if report.crc32_seed is not None:
                data = bytearray(signed(data, report.crc32_seed))
            fast = parse_report(profile, bytes(data))
            slow = parse_report_reference(profile, bytes(data))
            np.testing.assert_array_equal(fast, slow)
            np.testing.assert_array_equal(parse_status(profile, bytes(data)),
                                          parse_status_reference(profile, bytes(data)))


def test_float_signed_and_conditional_fields_match_reference(rng):
    profile = parse_profile({"name": "custom", "report": [{"id": 5, "length": 12, "field": [
        {"channel": "pressure", "type": "f32le", "byte": 1, "scale": 2.0},
        {"channel": "tilt", "type": "sbits", "bit": 43, "width": 11},
        {"channel": "wide", "type": "ubits", "bit": 54, "width": 32, "order": "msb"},
        {"channel": "be", "type": "i16be", "byte": 10, "center": 3.0,
         "when": {"bit": 40, "width": 3, "equals": 5}}]}]})
    conditions_met = 0
    for _ in range(200):
        data = bytearray(rng.integers(0, 256, 12, dtype=np.uint8).tobytes())
        data[0] = 5
        fast = parse_report(profile, bytes(data))
        np.testing.assert_array_equal(fast, parse_report_reference(profile, bytes(data)))
        conditions_met += (data[5] & 7) == 5
        assert math.isnan(fast[3]) == ((data[5] & 7) != 5)
    assert conditions_met > 0
    data = bytearray(12)
    data[0] = 5
    data[1:5] = np.float32(float("nan")).tobytes()
    assert math.isnan(parse_report(profile, bytes(data))[0])   # a NaN float stays missing
def test_parse_into_holds_channels_of_other_reports():
    mouse = load_profile("spacemouse")
    state = np.full(len(mouse.channels), np.nan)
    parse_into(mouse, bytes.fromhex("015e01a2fe0000"), state)
    parse_into(mouse, bytes.fromhex("02af00000051ff"), state)
    v = dict(zip(mouse.channels, state))
    assert (v["tx"], v["ty"], v["rx"], v["rz"]) == pytest.approx((1, -1, 0.5, -0.5))


def test_malformed_reports_raise_with_what_was_expected():
    ds4 = load_profile("dualshock4")
    with pytest.raises(MalformedReport, match=r"unknown report id 0x07.*knows 0x01, 0x11"):
        parse_report(ds4, bytes([7] * 64))
    with pytest.raises(MalformedReport, match=r"report 0x01 is 9 bytes; .* expects 10 or 64"):
        parse_report(ds4, bytes([1] * 9))
    with pytest.raises(MalformedReport, match="empty report"):
        parse_report(ds4, b"")


def test_split_reports_separates_concatenated_reads():
    mouse = load_profile("spacemouse")
    a, b, c = (bytes.fromhex("015e01a2fe0000"), bytes.fromhex("02af00000051ff"),
               bytes.fromhex("030200"))
    assert split_reports(mouse, a + b + c) == ([a, b, c], b"")
    assert split_reports(mouse, a) == ([a], b"")
    # a read that stopped inside a report keeps the start of it for the next read
    assert split_reports(mouse, a + b[:3], allow_tail=True) == ([a], b[:3])
    # data that cannot be split is passed on whole (and will fail to parse)
    assert split_reports(mouse, b"\x09\x09\x09") == ([b"\x09\x09\x09"], b"")


@pytest.mark.parametrize("table, message", [
    ({"name": "x"}, "needs at least one"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "field": [
        {"channel": "a", "type": "u16le", "byte": 3}]}]}, r"bytes 3\.\.4, outside the 4-byte"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "field": [
        {"channel": "a", "type": "u12", "byte": 1}]}]}, "'type' must be one of"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "field": [
        {"channel": "a", "type": "u8", "byte": 1, "sclae": 2}]}]}, r"unknown key\(s\) \['sclae'\]"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "field": [
        {"channel": "a", "type": "ubits", "bit": 8, "width": 40}]}]}, "'width' must be 1..32"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "fields_from": "usb"}]}, "'fields_from'"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "field": [
        {"channel": "a", "type": "u8", "byte": 1, "when": {"bit": 8, "width": 2, "equals": 4}}
    ]}]}, r"'equals' = 4 does not fit in 2 bit"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "field": [
        {"channel": "a", "type": "u8", "byte": 1}], "skip": [{"bit": 40, "width": 1,
                                                              "equals": 1}]}]},
     r"skip\[0\]: reads bytes 5\.\.5, outside the 4-byte"),
    ({"name": "x", "report": [
        {"name": "long", "id": 1, "length": 8, "field": [
            {"channel": "a", "type": "u8", "byte": 1}, {"channel": "b", "type": "u8",
                                                        "byte": 7}]},
        {"name": "short", "id": 1, "length": 4, "fields_from": "long"}]},
     r"field 'b' shifted by 0 falls outside the 4-byte report \(truncate = true"),
    ({"name": "x", "calibration": "wii", "report": [{"id": 1, "length": 2, "field": [
        {"channel": "a", "type": "u8", "byte": 1}]}]}, r"'calibration' must be one of"),
    ({"name": "x", "device": "054c:05c4", "report": []}, r"'device' must be a list of tables"),
    ({"name": "x", "report": [{"id": 1, "length": 2, "field": [
        {"channel": "a", "type": "u8", "byte": 1}], "status": [
        {"channel": "a", "type": "u8", "byte": 1}]}]}, r"named both as channel and as status"),
    ({"name": "x", "report": [{"id": 1, "length": 4, "crc32_seed": 300, "field": [
        {"channel": "a", "type": "u8", "byte": 1}]}]}, r"'crc32_seed' must be a byte"),
])
def test_bad_profiles_name_the_file_and_key(table, message):
    with pytest.raises(ProfileError, match=message) as info:
        parse_profile(table, path="custom.toml")
    assert "custom.toml" in str(info.value)


def test_truncated_copy_keeps_the_fields_that_fit():
    profile = parse_profile({"name": "x", "report": [
        {"name": "long", "id": 1, "length": 8, "field": [
            {"channel": "a", "type": "u8", "byte": 1},
            {"channel": "b", "type": "u8", "byte": 7}]},
        {"name": "short", "id": 1, "length": 4, "fields_from": "long", "truncate": True}]})
    assert parse_report(profile, bytes([1, 9, 0, 0])).tolist()[0] == 9.0
    assert math.isnan(parse_report(profile, bytes([1, 9, 0, 0]))[1])


def test_unknown_profile_name_lists_the_available_ones():
    with pytest.raises(ValueError, match="unknown HID profile 'glove9'.*dualsense.*p5"):
        load_profile("glove9")


def test_user_profile_folder_overrides(tmp_path, monkeypatch):
    (tmp_path / "mine.toml").write_text(
        'name = "mine"\nrate = 100.0\n[[report]]\nid = 2\nlength = 3\n'
        '[[report.field]]\nchannel = "knob"\ntype = "u16le"\nbyte = 1\nscale = 0.5\n'
        'comment = "a knob"\n')
    monkeypatch.setenv("MOP_HID_PROFILES", str(tmp_path))
    mine = load_profile("mine")
    assert parse_report(mine, bytes([2, 0x10, 0x00])).tolist() == [8.0]
    assert load_profile(tmp_path / "mine.toml").channels == ("knob",)


def test_one_bad_user_profile_is_skipped_with_a_warning_naming_it(tmp_path, monkeypatch, caplog):
    (tmp_path / "good.toml").write_text(
        'name = "good"\n[[report]]\nid = 1\nlength = 2\n'
        '[[report.field]]\nchannel = "knob"\ntype = "u8"\nbyte = 1\n')
    (tmp_path / "broken.toml").write_text('name = "broken"\n[[report]]\nid = \n')
    (tmp_path / "wrong.toml").write_text('name = "wrong"\ndevice = "054c:05c4"\n')
    (tmp_path / "binary.toml").write_bytes(b"\xff\xfe\x00junk")
    monkeypatch.setenv("MOP_HID_PROFILES", str(tmp_path))
    with caplog.at_level(logging.WARNING, logger="capture.hid.profile"):
        profiles = available_profiles()
    assert {"good", "dualshock4", "spacemouse"} <= set(profiles)
    assert not {"broken", "wrong"} & set(profiles)
    skipped = skipped_profiles()
    assert sorted(p.name for p in skipped) == ["binary.toml", "broken.toml", "wrong.toml"]
    assert "not valid TOML" in skipped[tmp_path / "broken.toml"]
    assert "'device' must be a list of tables" in skipped[tmp_path / "wrong.toml"]
    assert "not UTF-8" in skipped[tmp_path / "binary.toml"]
    warned = [r.getMessage() for r in caplog.records]
    assert any(str(tmp_path / "broken.toml") in m for m in warned)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="capture.hid.profile"):
        available_profiles()
    assert not caplog.records                     # warned once per file, not on every scan
    assert load_profile("good").channels == ("knob",)
    with pytest.raises(ValueError, match=r"unknown HID profile 'broken'.*skipped .*broken.toml"):
        load_profile("broken")


def test_damaged_profile_tables_raise_only_profile_errors(rng):
    """Any key of a shipped profile replaced by a value of another type (or removed): the
    reader says what is wrong (ProfileError), it never fails some other way."""
    import copy
    import tomllib
    from capture.hid.profile import PROFILE_DIR
    shipped = [tomllib.loads(p.read_text()) for p in sorted(PROFILE_DIR.glob("*.toml"))]
    odd = [None, 0, -1, 1.5, float("nan"), float("inf"), "x", "", True, [], {}, [1, 2],
           {"a": 1}, 10**30, [{}], [{"bit": 1}]]

    def places(node, where=()):
        yield where
        items = node.items() if isinstance(node, dict) else (
            enumerate(node) if isinstance(node, list) else ())
        for key, child in items:
            yield from places(child, where + (key,))

    errors = 0
    for _ in range(400):
        table = copy.deepcopy(shipped[int(rng.integers(len(shipped)))])
        where = [w for w in places(table) if w]
        target = where[int(rng.integers(len(where)))]
        parent = table
        for key in target[:-1]:
            parent = parent[key]
        if isinstance(parent, dict) and rng.random() < 0.2:
            del parent[target[-1]]
        else:
            parent[target[-1]] = copy.deepcopy(odd[int(rng.integers(len(odd)))])
        try:
            parse_profile(table, path="damaged.toml")
        except ProfileError as error:
            errors += 1
            assert str(error).startswith("damaged.toml: ")
    assert errors > 200
