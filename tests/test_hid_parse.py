"""HID report parsing: a pure function of the bytes, checked field by field on report bytes laid
out as each device sends them, against values worked out by hand; the numba kernel against the
slow int.from_bytes reference on random reports; malformed reports; profile-file errors."""
import math

import numpy as np
import pytest

from capture.hid.parse import (MalformedReport, parse_into, parse_report,
                               parse_report_reference, split_reports)
from capture.hid.profile import ProfileError, available_profiles, load_profile, parse_profile

GYRO = math.pi / 180 / 16.384     # rad/s per count (2000 deg/s full scale)
G = 9.80665


def values(profile, data):
    out = parse_report(profile, bytes.fromhex(data.replace(" ", "")))
    return dict(zip(profile.channels, out))


def test_shipped_profiles_load_and_fit_their_devices():
    profiles = available_profiles()
    assert {"p5", "spacemouse", "dualshock4", "dualsense", "generic"} <= set(profiles)
    assert profiles["spacemouse"].matches(0x046D, 0xC626)
    assert profiles["dualshock4"].matches(0x054C, 0x09CC)
    assert profiles["dualsense"].matches(0x054C, 0x0CE6)
    assert not profiles["dualsense"].matches(0x054C, 0x09CC)
    assert profiles["p5"].channels[:5] == ("index", "middle", "ring", "pinky", "thumb")
    assert profiles["generic"].channels == tuple(f"byte{i}" for i in range(64))


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
    b = values(mouse, "03"      # report 3: buttons
                      "02 00")  # bit 1: right button
    assert (b["button_1"], b["button_2"]) == (0.0, 1.0)
    m = values(mouse, "01"          # report 1, 13 bytes (newer devices): all six axes
                      "5e 01 00 00 00 00"   # tx = 1.0, ty = tz = 0
                      "af 00 00 00 00 00")  # rx = 0.5, ry = rz = 0
    assert (m["tx"], m["rx"], m["rz"]) == pytest.approx((1.0, 0.5, 0.0))


DS4_USB = ("01"        # report id 1 (USB)
           "ff"        # lx = 255 -> +1 (full right)
           "80"        # ly = 128 -> +0.0039
           "00"        # rx = 0 -> -1 (full left)
           "7f"        # ry = 127 -> -0.0039
           "21"        # hat 1 (north-east) in the low nibble; bit 5 = cross
           "11"        # bit 0 = L1, bit 4 = share
           "09"        # bit 0 = PS; counter = 0x09 >> 2 = 2
           "ff"        # L2 analog = 255 -> 1
           "00"        # R2 analog = 0
           "3412"      # sensor timestamp (not a channel)
           "1b"        # battery temperature (not a channel)
           "1000"      # gyro x = 16 counts -> 1 deg/s
           "f0ff"      # gyro y = -16 counts -> -1 deg/s
           "0000"      # gyro z = 0
           "0000"      # accel x = 0
           "0020"      # accel y = 8192 counts -> 1 g
           "00e0"      # accel z = -8192 counts -> -1 g
           ) + "00" * 39


def check_ds4(v):
    assert (v["lx"], v["rx"]) == pytest.approx((1.0, -1.0))
    assert (v["ly"], v["ry"]) == pytest.approx((0.5 / 127.5, -0.5 / 127.5))
    assert (v["dpad_x"], v["dpad_y"]) == (1.0, 1.0)
    assert (v["cross"], v["square"], v["circle"], v["triangle"]) == (1.0, 0.0, 0.0, 0.0)
    assert (v["l1"], v["r1"], v["share"], v["options"]) == (1.0, 0.0, 1.0, 0.0)
    assert (v["ps"], v["touchpad_click"], v["counter"]) == (1.0, 0.0, 2.0)
    assert (v["l2"], v["r2"]) == (1.0, 0.0)
    assert (v["gyro_x"], v["gyro_y"], v["gyro_z"]) == pytest.approx((16 * GYRO, -16 * GYRO, 0))
    assert (v["accel_x"], v["accel_y"], v["accel_z"]) == pytest.approx((0.0, G, -G))


def test_dualshock4_usb_report():
    ds4 = load_profile("dualshock4")
    assert len(bytes.fromhex(DS4_USB)) == 64
    check_ds4(values(ds4, DS4_USB))


def test_dualshock4_bluetooth_report_is_the_usb_layout_two_bytes_later():
    ds4 = load_profile("dualshock4")
    bluetooth = "11" + "c0" + "00" + DS4_USB[2:] + "00" * 12   # id 0x11, 2 header bytes
    assert len(bytes.fromhex(bluetooth)) == 78
    check_ds4(values(ds4, bluetooth))


def test_dualsense_usb_report():
    ds5 = load_profile("dualsense")
    report = ("01"      # report id 1 (USB)
              "80"      # lx = 128
              "00"      # ly = 0 -> -1 (full up)
              "80 80"   # rx, ry centred
              "80"      # L2 = 128 -> 0.502
              "ff"      # R2 = 255 -> 1
              "2a"      # sequence number 42
              "88"      # hat 8 = released; bit 7 = triangle
              "22"      # bit 1 = R1, bit 5 = options
              "05"      # bit 0 = PS, bit 2 = mute
              "00"      # buttons[3]
              "00000000"    # reserved
              "0000"    # gyro x = 0
              "0004"    # gyro y = 1024 counts -> 62.5 deg/s
              "00fc"    # gyro z = -1024 counts
              "0000"    # accel x
              "0020"    # accel y = 8192 -> 1 g
              "0000"    # accel z
              ) + "00" * 36
    assert len(bytes.fromhex(report)) == 64
    v = values(ds5, report)
    assert v["ly"] == pytest.approx(-1.0) and v["lx"] == pytest.approx(0.5 / 127.5)
    assert (v["l2"], v["r2"], v["counter"]) == pytest.approx((128 / 255, 1.0, 42.0))
    assert (v["dpad_x"], v["dpad_y"]) == (0.0, 0.0)
    assert (v["triangle"], v["cross"], v["r1"], v["options"], v["l1"]) == (1, 0, 1, 1, 0)
    assert (v["ps"], v["mute"], v["touchpad_click"]) == (1, 1, 0)
    assert v["gyro_y"] == pytest.approx(1024 * GYRO) and v["gyro_z"] == pytest.approx(-1024 * GYRO)
    assert v["accel_y"] == pytest.approx(G)


def test_dpad_hat_values_map_to_directions_and_invalid_hat_is_missing():
    ds4 = load_profile("dualshock4")
    expected = {0: (0, 1), 2: (1, 0), 4: (0, -1), 6: (-1, 0), 7: (-1, 1), 8: (0, 0)}
    for hat, (x, y) in expected.items():
        data = bytearray(bytes.fromhex(DS4_USB))
        data[5] = (data[5] & 0xF0) | hat
        v = dict(zip(ds4.channels, parse_report(ds4, bytes(data))))
        assert (v["dpad_x"], v["dpad_y"]) == (x, y), hat
    data = bytearray(bytes.fromhex(DS4_USB))
    data[5] = (data[5] & 0xF0) | 12           # not a hat value: missing, not a direction
    v = dict(zip(ds4.channels, parse_report(ds4, bytes(data))))
    assert math.isnan(v["dpad_x"]) and math.isnan(v["dpad_y"])


def test_generic_profile_exposes_raw_bytes_and_nan_beyond_the_report():
    generic = load_profile("generic")
    out = parse_report(generic, bytes([7, 0, 255, 128]))
    assert out[:4].tolist() == [7, 0, 255, 128]
    assert np.isnan(out[4:]).all()


@pytest.mark.parametrize("name", ["p5", "spacemouse", "dualshock4", "dualsense", "generic"])
def test_kernel_matches_slow_reference_on_random_reports(name, rng):
    profile = load_profile(name)
    for report in profile.reports:
        for _ in range(40):
            data = bytearray(rng.integers(0, 256, report.length, dtype=np.uint8).tobytes())
            if report.report_id is not None:
                data[0] = report.report_id
            fast = parse_report(profile, bytes(data))
            slow = parse_report_reference(profile, bytes(data))
            np.testing.assert_array_equal(fast, slow)


def test_float_and_signed_bit_fields_match_reference(rng):
    profile = parse_profile({"name": "custom", "report": [{"id": 5, "length": 12, "field": [
        {"channel": "pressure", "type": "f32le", "byte": 1, "scale": 2.0},
        {"channel": "tilt", "type": "sbits", "bit": 43, "width": 11},
        {"channel": "wide", "type": "ubits", "bit": 54, "width": 32, "order": "msb"},
        {"channel": "be", "type": "i16be", "byte": 10, "center": 3.0}]}]})
    for _ in range(100):
        data = bytearray(rng.integers(0, 256, 12, dtype=np.uint8).tobytes())
        data[0] = 5
        np.testing.assert_array_equal(parse_report(profile, bytes(data)),
                                      parse_report_reference(profile, bytes(data)))
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
    with pytest.raises(MalformedReport, match=r"report 0x01 is 10 bytes; .* expects 64"):
        parse_report(ds4, bytes([1] * 10))
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
])
def test_bad_profiles_name_the_file_and_key(table, message):
    with pytest.raises(ProfileError, match=message) as info:
        parse_profile(table, path="custom.toml")
    assert "custom.toml" in str(info.value)


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
