"""End to end through the real hidapi `hidraw` backend: a /dev/hidraw node simulated in user
space by umockdev (sysfs + udev properties from a device description, report bytes from a
script), plus tests/data/hid/hidraw_shim.c (compiled here with gcc) that answers the report
descriptor ioctls umockdev does not, and can "unplug" the node for the reconnection test.

Each test runs a child Python under `umockdev-run` that opens `hid:PROFILE` exactly as a user
would (enumeration by vendor/product id, open, read) and prints the frames as JSON; the test
compares them with the pure parser applied to the same bytes. The DualShock 4 runs use the
kernel selftests' emulated pad (hid-tools): its real report descriptor, its reports and the
calibration feature report the shim serves, so the whole path (calibration read on open,
Bluetooth CRC, status) is checked against values that did not come from mop."""
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from capture.hid.calibration import parse_calibration, requests
from capture.hid.parse import MalformedReport, parse_into
from capture.hid.profile import load_profile
from capture.hid.status import Connection
from hid_emulated_pads import emulated, feature_report

pytestmark = [pytest.mark.device, pytest.mark.slow]

ROOT = Path(__file__).resolve().parent.parent
SHIM_SOURCE = Path(__file__).resolve().parent / "data" / "hid" / "hidraw_shim.c"

# minimal report descriptors (HID 1.11 items) with the usage pages hidapi reports
DESCRIPTORS = {
    # Generic Desktop / Multi-axis Controller, report 1: 3 x 16-bit axes
    "spacemouse": "05010908a101a10285010930093109321a00802aff7f750f9503810200c0c0",
    # Generic Desktop / Game Pad, report 1: 63 vendor bytes
    "dualshock4": "05010905a101850106 00ff09201500 26ff00750895 3f8102c0".replace(" ", ""),
    # Vendor page 0xff00, report 1: 17 bytes
    "p5": "0600ff0901a10185011500 26ff007508951181 02c0".replace(" ", ""),
    # Generic Desktop / Mouse, report 2: 3 bytes (the Universal Receiver's mouse interface)
    "mouse": "05010902a101850209300931150026ff00750895028102c0",
}


def _need(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pytest.skip(f"{tool} is not installed (apt-get install umockdev libumockdev-dev; "
                    f"scripts/setup.sh --test does it)")
    return path


@pytest.fixture(scope="module")
def shim(tmp_path_factory) -> Path:
    _need("umockdev-run")
    gcc = _need("gcc")
    target = tmp_path_factory.mktemp("hidshim") / "hidraw_shim.so"
    subprocess.run([gcc, "-shared", "-fPIC", "-O2", "-Wall", "-o", str(target),
                    str(SHIM_SOURCE), "-ldl"], check=True, capture_output=True)
    return target


def device_description(vendor: int, product: int, product_name: str, manufacturer: str,
                       descriptor: str, *, bus: int = 0x03, interfaces: int = 1) -> str:
    """A umockdev device description: USB device, then per interface k an interface, a HID
    device (bus 0x03 USB, 0x05 Bluetooth) and the node /dev/hidrawK."""
    usb = "/devices/pci0000:00/0000:00:14.0/usb1/1-2"
    out = [textwrap.dedent(f"""\
        P: {usb}
        N: bus/usb/001/004
        E: DEVNAME=/dev/bus/usb/001/004
        E: DEVTYPE=usb_device
        E: DRIVER=usb
        E: SUBSYSTEM=usb
        A: idVendor={vendor:04x}
        A: idProduct={product:04x}
        A: bcdDevice=0100
        A: manufacturer={manufacturer}
        A: product={product_name}
        """)]
    descriptors = descriptor if isinstance(descriptor, list) else [descriptor] * interfaces
    for k, rdesc in enumerate(descriptors):
        hid = f"{usb}/1-2:1.{k}/{bus:04X}:{vendor:04X}:{product:04X}.000{k + 1}"
        out.append(textwrap.dedent(f"""\
            P: {usb}/1-2:1.{k}
            E: DEVTYPE=usb_interface
            E: DRIVER=usbhid
            E: SUBSYSTEM=usb
            A: bInterfaceNumber=0{k}

            P: {hid}
            E: DRIVER=hid-generic
            E: HID_ID={bus:04X}:{vendor:08X}:{product:08X}
            E: HID_NAME={manufacturer} {product_name}
            E: HID_PHYS=usb-0000:00:14.0-2/input{k}
            E: HID_UNIQ=
            E: MODALIAS=hid:b{bus:04X}g0001v{vendor:08X}p{product:08X}
            E: SUBSYSTEM=hid
            H: report_descriptor={rdesc.upper()}

            P: {hid}/hidraw/hidraw{k}
            N: hidraw{k}
            L: device=../../../{bus:04X}:{vendor:04X}:{product:04X}.000{k + 1}
            E: DEVNAME=/dev/hidraw{k}
            E: MAJOR=241
            E: MINOR={k}
            E: SUBSYSTEM=hidraw
            """))
    return "\n".join(out)


def script_line(delay_ms: int, data: bytes) -> bytes:
    """One umockdev script read of one report, preceded by its length for the shim's framing
    (MOP_HID_FRAMED=1); bytes < 32 as ^@..^_, '^' as ^`, the rest verbatim."""
    if not 0 < len(data) < 256:
        raise ValueError(f"a report is 1..255 bytes here, got {len(data)}")
    out = bytearray(f"r {delay_ms} ".encode())
    for byte in bytes([len(data)]) + data:
        if byte == 0x5E:
            out += b"^`"
        elif byte < 32:
            out += bytes([0x5E, byte + 64])
        else:
            out.append(byte)
    return bytes(out)


CHILD = textwrap.dedent("""\
    import json, os, sys, time
    from capture import open_source, Status
    spec, expect, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    source = open_source(spec, reconnect_interval=0.1)
    frames, statuses = [], []
    def collect(count, limit):
        deadline = time.monotonic() + limit
        while len(frames) < count and time.monotonic() < deadline:
            frame = source.read(timeout=0.05)
            if frame is not None:
                frames.append(frame)
    if mode == "read":
        collect(expect, 15)
    else:   # unplug after a few frames, wait for DISCONNECTED, plug back, read on
        flag = os.environ["MOP_HID_UNPLUG"]
        collect(3, 15)
        open(flag, "w").close()
        deadline = time.monotonic() + 5
        while source.status is not Status.DISCONNECTED and time.monotonic() < deadline:
            frame = source.read(timeout=0.02)
            if frame is not None:
                frames.append(frame)
        statuses.append(source.status.value)
        time.sleep(0.3)
        statuses.append(source.status.value)
        produced = source.stats.frames
        os.remove(flag)
        # frames the source makes after the reconnection, and the status while they come
        deadline = time.monotonic() + 15
        while source.stats.frames < produced + 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        statuses.append(source.status.value)
        collect(produced + 3, 5)
    stats, info = source.stats, source.describe()
    device_status = source.device_status().as_dict()
    source.close()
    print(json.dumps({"channels": list(source.channels), "device_status": device_status,
                      "values": [f.values.tolist() for f in frames],
                      "seq": [f.seq for f in frames], "t": [f.t for f in frames],
                      "statuses": statuses, "malformed": stats.malformed,
                      "connects": stats.connects, "disconnects": stats.disconnects,
                      "problems": stats.problems, "device": info["device"]}))
    """)


def run_simulated(tmp_path, shim, *, spec, vendor, product, name, manufacturer, descriptor,
                  reports, expect, delay_ms=10, mode="read", bus=0x03, features=None,
                  node=0, interfaces=1, command=None, env=None):
    """Run the child under umockdev-run with the device described and `reports` scripted on
    /dev/hidraw{node}; return the JSON it prints last (with `command`, the argv to run after
    the interpreter instead: the finished process). features: {report id: bytes} the shim
    serves as feature reports."""
    (tmp_path / "device.umockdev").write_text(
        device_description(vendor, product, name, manufacturer, descriptor, bus=bus,
                           interfaces=interfaces))
    (tmp_path / "reports.script").write_bytes(
        b"\n".join(script_line(delay_ms, r) for r in reports) + b"\n")
    (tmp_path / "child.py").write_text(CHILD)
    opened = descriptor[node] if isinstance(descriptor, list) else descriptor
    env = dict(os.environ, **(env or {}), MOP_HID_DESCRIPTOR=opened, MOP_HID_FRAMED="1",
               MOP_HID_UNPLUG=str(tmp_path / "unplug"),
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    for report_id, data in (features or {}).items():
        env[f"MOP_HID_FEATURE_{report_id:02x}"] = data.hex()
    argv = command or [str(tmp_path / "child.py"), spec, str(expect), mode]
    run = ["umockdev-run", "-d", str(tmp_path / "device.umockdev"),
               "-s", f"/dev/hidraw{node}={tmp_path / 'reports.script'}", "--", "sh", "-c",
               f'LD_PRELOAD="{shim}:$LD_PRELOAD" exec "{sys.executable}" "$@"', "sh", *argv]
    done = subprocess.run(run, env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-3000:]
    if command:
        return done
    return json.loads(done.stdout.strip().splitlines()[-1])


def expected_frames(profile, reports):
    """What the source must produce: one frame per valid report with input, channels of other
    reports held, computed with the pure parser in this process."""
    state = np.full(len(profile.channels), np.nan)
    frames = []
    for report in reports:
        try:
            parsed = parse_into(profile, report, state)
        except MalformedReport:
            continue
        if parsed.carried_input:
            frames.append(state.copy())
    return np.array(frames)


def test_spacemouse_through_hidraw(tmp_path, shim, rng):
    profile = load_profile("spacemouse")
    reports = []
    for k in range(12):
        axes = rng.integers(-350, 351, 3).astype("<i2").tobytes()
        kind = k % 4
        if kind == 0:
            reports.append(b"\x01" + axes)                  # translation (7 bytes)
        elif kind == 1:
            reports.append(b"\x02" + axes)                  # rotation (7 bytes)
        elif kind == 2:
            reports.append(bytes([3, int(rng.integers(0, 4)), 0]))   # buttons
        else:
            reports.append(b"\x01" + axes + axes[::-1])     # 13-byte combined report
    reports.insert(5, bytes([0x07, 1, 2, 3, 4, 5, 6]))       # a report id nobody knows
    out = run_simulated(tmp_path, shim, spec="hid:spacemouse", vendor=0x046D, product=0xC626,
                        name="SpaceNavigator", manufacturer="3Dconnexion",
                        descriptor=DESCRIPTORS["spacemouse"], reports=reports, expect=12)
    want = expected_frames(profile, reports)
    got = np.array(out["values"], dtype=float)
    assert out["channels"] == list(profile.channels)
    assert got.shape == want.shape == (12, 38)
    np.testing.assert_array_equal(got, want)
    assert out["seq"] == list(range(12))
    assert np.all(np.diff(out["t"]) >= 0)
    assert out["malformed"] == 1
    assert any("unknown report id 0x07" in problem for problem in out["problems"])
    assert out["device"]["vendor_id"] == 0x046D and out["device"]["product_id"] == 0xC626
    assert out["device"]["product_string"] == "SpaceNavigator"


def test_dualshock4_and_p5_glove_through_hidraw(tmp_path, shim, rng):
    ds4 = load_profile("dualshock4")
    reports = []
    for _ in range(6):
        report = bytearray(rng.integers(0, 256, 64, dtype=np.uint8).tobytes())
        report[0] = 0x01
        report[31] &= ~0x04             # set, it would say "no controller on the adaptor"
        reports.append(bytes(report))
    (tmp_path / "ds4").mkdir()
    out = run_simulated(tmp_path / "ds4", shim,
                        spec="hid:dualshock4", vendor=0x054C, product=0x09CC,
                        name="Wireless Controller", manufacturer="Sony Interactive Entertainment",
                        descriptor=DESCRIPTORS["dualshock4"], reports=reports, expect=6)
    np.testing.assert_array_equal(np.array(out["values"], dtype=float),
                                  expected_frames(ds4, reports))
    assert out["malformed"] == 0

    p5 = load_profile("p5")
    reports = []
    for _ in range(6):
        report = bytearray(rng.integers(0, 256, 18, dtype=np.uint8).tobytes())
        report[0] = 0x01
        reports.append(bytes(report))
    reports.insert(2, bytes([0x01, 0xFC, 0x08]))             # cut short: 3 of 18 bytes
    (tmp_path / "p5").mkdir()
    out = run_simulated(tmp_path / "p5", shim,
                        spec="hid:p5", vendor=0x1209, product=0x0001, name="P5-style glove",
                        manufacturer="mop", descriptor=DESCRIPTORS["p5"], reports=reports,
                        expect=6)
    got = np.array(out["values"], dtype=float)
    np.testing.assert_array_equal(got, expected_frames(p5, reports))
    assert out["malformed"] == 1
    assert np.all((got[:, :5] >= 0) & (got[:, :5] <= 1))      # bends in [0, 1]


def test_unplugged_device_is_reported_and_reconnected(tmp_path, shim):
    reports = [b"\x01" + np.array([k, -k, 2 * k], "<i2").tobytes() for k in range(150)]
    out = run_simulated(tmp_path, shim, spec="hid:spacemouse", vendor=0x046D, product=0xC626,
                        name="SpaceNavigator", manufacturer="3Dconnexion",
                        descriptor=DESCRIPTORS["spacemouse"], reports=reports, expect=0,
                        delay_ms=30, mode="unplug")
    assert out["statuses"][:2] == ["disconnected", "disconnected"]
    assert out["statuses"][2] == "ok"
    assert out["connects"] == 2 and out["disconnects"] == 1
    assert any("device lost" in problem for problem in out["problems"])
    got = np.array(out["values"], dtype=float)
    assert got.shape[0] >= 6
    # frames before and after the reconnection are consecutive reports of the script, each
    # parsed whole (no report torn by the unplug)
    tx = got[:, 0] * 350
    np.testing.assert_allclose(tx, np.round(tx), atol=1e-9)
    assert np.all(np.diff(np.round(tx)) >= 1)
    np.testing.assert_allclose(got[:, 1], -got[:, 0])
    assert out["malformed"] == 0


def emulated_ds4_run(rng, class_name, count):
    """Reports, report descriptor (hex), calibration feature report and the values put in,
    from the kernel selftests' emulated DualShock 4."""
    bluetooth = "Bluetooth" in class_name
    with emulated(class_name) as device:
        request = requests("dualshock4", Connection.BLUETOOTH if bluetooth else Connection.USB)[0]
        feature = feature_report(device, request.report_id)
        reports, events = [], []
        for _ in range(count):
            event = dict(left=tuple(int(v) for v in rng.integers(0, 256, 2)),
                         right=tuple(int(v) for v in rng.integers(0, 256, 2)),
                         gyro=tuple(int(v) for v in rng.integers(-1_000_000, 1_000_001, 3)))
            device.battery.capacity = 55
            device.battery.cable_connected = False      # over USB the cable is in anyway
            reports.append(bytes(device.create_report(**event)))
            events.append(event)
        return reports, bytes(device.rdesc).hex(), {request.report_id: feature}, events


@pytest.mark.parametrize("class_name, bus", [("PS4ControllerUSB", 0x03),
                                             ("PS4ControllerBluetooth", 0x05)])
def test_dualshock4_emulated_pad_with_its_calibration(tmp_path, shim, rng, class_name, bus):
    """The kernel selftests' DualShock 4 over USB and Bluetooth: its descriptor, its reports
    (Bluetooth with their CRC32), and its calibration served as the feature report the source
    reads on open. The gyro comes back in the units hid-tools was given (one raw count of
    truncation), which the profile's nominal scale alone would miss by 0.1-0.7 %."""
    reports, rdesc, features, events = emulated_ds4_run(rng, class_name, 8)
    out = run_simulated(tmp_path, shim, spec="hid:dualshock4", vendor=0x054C, product=0x05C4,
                        name="Wireless Controller", manufacturer="Sony Computer Entertainment",
                        descriptor=rdesc, reports=reports, expect=8, bus=bus,
                        features=features)
    profile = load_profile("dualshock4")
    (report_id, feature), = features.items()
    request = requests("dualshock4", Connection.BLUETOOTH if bus == 5 else Connection.USB)[0]
    calibrated = profile.with_affine(parse_calibration(feature, request).affine())
    got = np.array(out["values"], dtype=float)
    np.testing.assert_array_equal(got, expected_frames(calibrated, reports))
    v = [dict(zip(out["channels"], row)) for row in got]
    for frame, event in zip(v, events):
        assert [round(frame[c] * 127.5 + 127.5, 6) for c in ("lx", "ly", "rx", "ry")] == \
            list(event["left"] + event["right"])
        for axis, want in zip("xyz", event["gyro"]):
            assert abs(frame[f"gyro_{axis}"] * 1024 * 180 / math.pi - want) <= 63
    status = out["device_status"]
    assert status["connection"] == ("bluetooth" if bus == 5 else "usb")
    assert status["calibration"] == "device"
    # 55 % written as level 5: the middle of 50-59 %; over USB the cable is in, charging
    assert status["battery"] == pytest.approx(0.55)
    assert status["battery_state"] == ("charging" if bus == 3 else "discharging")
    assert out["malformed"] == 0


def test_dualshock4_usb_adaptor_without_controller_gives_no_frames(tmp_path, shim, rng):
    """The USB Wireless Adaptor streams near-zero reports while no controller is connected:
    no frame (no phantom stick at -1), no battery, the reason in the status; frames start when
    a controller is there, with its calibration, which the adaptor could not give on open."""
    reports, rdesc, features, _ = emulated_ds4_run(rng, "PS4ControllerUSB", 6)
    absent = bytearray(64)
    absent[0], absent[31] = 0x01, 0x04
    script = [bytes(absent)] * 5 + reports
    out = run_simulated(tmp_path, shim, spec="hid:dualshock4", vendor=0x054C, product=0x0BA0,
                        name="DUALSHOCK 4 USB Wireless Adaptor",
                        manufacturer="Sony Interactive Entertainment", descriptor=rdesc,
                        reports=script, expect=6, features=features,
                        env={"MOP_HID_FEATURE_FAIL_FIRST": "1"})
    got = np.array(out["values"], dtype=float)
    assert got.shape[0] == 6
    (feature,) = features.values()
    calibrated = load_profile("dualshock4").with_affine(
        parse_calibration(feature, requests("dualshock4", Connection.USB)[0]).affine())
    np.testing.assert_array_equal(got, expected_frames(calibrated, reports))
    assert out["problems"].get("no controller connected to the USB Wireless Adaptor") == 1
    assert out["malformed"] == 0 and out["device_status"]["no_input"] == ""
    assert out["device_status"]["calibration"] == "device"


def test_spacemouse_receiver_opens_its_multi_axis_interface(tmp_path, shim, rng):
    """The Universal Receiver enumerates its mouse interface first; the source must open the
    multi-axis one (the only one with reports here, so a wrong choice reads nothing)."""
    reports = [b"\x01" + rng.integers(-350, 351, 6).astype("<i2").tobytes() for _ in range(5)]
    out = run_simulated(tmp_path, shim, spec="hid:spacemouse", vendor=0x256F, product=0xC652,
                        name="Universal Receiver", manufacturer="3Dconnexion",
                        descriptor=[DESCRIPTORS["mouse"], DESCRIPTORS["spacemouse"]],
                        interfaces=2, node=1, reports=reports, expect=5)
    np.testing.assert_array_equal(np.array(out["values"], dtype=float),
                                  expected_frames(load_profile("spacemouse"), reports))
    assert out["device"]["path"].endswith("hidraw1")


def test_mop_devices_shows_battery_and_connection(tmp_path, shim, rng):
    reports, rdesc, _, _ = emulated_ds4_run(rng, "PS4ControllerBluetooth", 40)
    profiles = tmp_path / "profiles"
    profiles.mkdir()
    (profiles / "broken.toml").write_text("name = \n")
    done = run_simulated(tmp_path, shim, spec="", vendor=0x054C, product=0x05C4,
                         name="Wireless Controller", manufacturer="Sony", descriptor=rdesc,
                         reports=reports, expect=0, bus=0x05,
                         command=["-m", "mop.cli", "devices", "--no-cameras"],
                         env={"MOP_HID_PROFILES": str(profiles)})
    text = done.stdout
    assert "Bluetooth, battery 55 % (discharging)" in text, text
    assert "skipped" in text and "broken.toml" in text, text
