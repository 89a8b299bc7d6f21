"""`mop devices`: what can be captured from here: HID devices with the profiles that fit them,
cameras that open, and how to send OSC."""
from __future__ import annotations

import json


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "devices", help="list HID devices (with matching profiles), cameras, camera trackers "
                        "and the OSC input",
        description="Lists the HID devices hidapi sees with the device profiles that fit them, "
                    "the cameras that open, the camera trackers (and whether the face, hands "
                    "and pose models are installed), and the OSC address performers can send "
                    "to, each with the source spec that opens it.")
    parser.add_argument("--json", action="store_true", help="print the listing as JSON")
    parser.add_argument("--no-cameras", action="store_true",
                        help="do not try to open cameras")
    parser.set_defaults(func=run)


TRACKER_TITLES = {
    "face": "face: mouth, brows, blinks, head angles",
    "hands": "hands: the glove's finger bends, pinch, wrist",
    "pose": "body: shoulders, elbows, wrists, lean",
    "aruco": "ArUco marker poses",
    "color": "coloured markers or a colour glove",
    "haar": "Haar face box, eyes, smile",
    "silhouette": "hand silhouette, or its shadow",
}


def _text(value) -> str:
    return value.decode(errors="replace") if isinstance(value, bytes) else str(value or "")


def _hid_status(status: dict) -> str:
    """One line from a HID device's status: connection, battery, cable."""
    if "error" in status:
        return f"status not read: {status['error']}"
    from capture.hid.status import BatteryState, Connection, DeviceStatus
    known = DeviceStatus(
        Connection(status.get("connection") or ""), status.get("battery"),
        BatteryState(status["battery_state"]) if status.get("battery_state") else None,
        status.get("cable"), None, status.get("calibration") or "",
        status.get("no_input") or "")
    return known.text() or "no battery or connection state reported"


def run(args) -> int:
    from capture.devices import list_devices

    found = list_devices(cameras=not args.no_cameras)
    if args.json:
        print(json.dumps(found, default=_text, indent=2))
        return 0
    print("HID devices:")
    if found["hid_error"]:
        print(f"  unavailable: {found['hid_error']}")
    elif not found["hid"]:
        print("  none found (plug one in; on Linux /dev/hidraw* must be readable)")
    for device in found["hid"]:
        path = _text(device.get("path"))
        name = " ".join(filter(None, (_text(device.get("manufacturer_string")),
                                      _text(device.get("product_string"))))) or "?"
        profiles = device["profiles"]
        best = next((p for p in profiles if p != "generic"), "generic")
        print(f"  {path:<14} {device.get('vendor_id', 0):04x}:{device.get('product_id', 0):04x}"
              f"  {name}")
        print(f"  {'':<14} profiles: {', '.join(profiles)};  open with hid:{best}@{path}")
        if "status" in device:
            print(f"  {'':<14} {_hid_status(device['status'])}")
    print("HID profiles:")
    for name, title in found["profiles"].items():
        print(f"  {name:<12} {title}")
    for path, why in found.get("skipped_profiles", {}).items():
        print(f"  skipped {path}: {why}")
    print("Cameras:")
    if found["camera_error"]:
        print(f"  unavailable: {found['camera_error']}")
    elif args.no_cameras:
        print("  not probed (--no-cameras)")
    elif not found["cameras"]:
        print("  none found (a video file works as a camera: camera:clip.mkv:color)")
    for camera in found["cameras"]:
        print(f"  {camera['index']:<3} {camera['width']}x{camera['height']} @ "
              f"{camera['fps']:g} fps;  open with camera:{camera['index']}:TRACKER")
    print("Camera trackers (camera:0:TRACKER; a video file works as a camera too):")
    for name, tracker in found["trackers"].items():
        if tracker["models"] is None:
            state = ("ready (OpenCV)" if found["opencv"] else
                     "unavailable: needs OpenCV (pip install 'mop[capture]')")
        elif tracker["models"]:
            state = f"models installed ({found['vision']['distribution']})"
        else:
            state = f"models NOT installed: {tracker['needs']}"
        print(f"  {name:<11} {TRACKER_TITLES.get(name, ''):<46} {state}")
    osc = found["osc"]
    print("OSC:")
    print(f"  listen with {osc['spec']} (Wekinator's default port and address); any port and "
          f"address work, e.g. osc:127.0.0.1:9000/glove")
    print("  performers on other machines: osc:0.0.0.0:9000/glove and send to this machine")
    return 0
