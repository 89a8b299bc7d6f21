"""What is plugged in: HID devices with the profiles that fit them, cameras that open, and how
to reach the OSC source. Used by `mop devices`."""
from __future__ import annotations

import importlib.util
import logging

log = logging.getLogger(__name__)


def list_devices(*, cameras: bool = True) -> dict:
    """{"hid": [...], "hid_error": str, "profiles": {name: title}, "skipped_profiles":
    {path: why}, "cameras": [...], "camera_error": str, "trackers": {name: {"models": bool |
    None, "needs": str}}, "vision": {"installed", "distribution", "error"}, "opencv": bool,
    "osc": {"host", "port", "address", "spec"}}. Each HID device with a profile of its own
    carries "status": battery and connection as it reports them
    (`capture.hid.status.DeviceStatus.as_dict()`). A tracker's "models" is True when its model
    files are installed, False when they are not, None when it needs none; nothing is imported
    to find out."""
    result: dict = {"hid": [], "hid_error": "", "profiles": {}, "skipped_profiles": {},
                    "cameras": [], "camera_error": "", "trackers": {}, "vision": {}}
    try:
        from .hid.profile import available_profiles, skipped_profiles
        result["profiles"] = {name: p.title for name, p in sorted(available_profiles().items())}
        result["skipped_profiles"] = {str(path): why for path, why in skipped_profiles().items()}
        from .hid.source import list_hid_devices
        result["hid"] = list_hid_devices()
    except ImportError as error:
        result["hid_error"] = str(error)
    if cameras:
        try:
            from .camera.source import list_cameras
            result["cameras"] = list_cameras()
        except ImportError as error:
            result["camera_error"] = str(error)
    from .camera.markerless import EXTRA, models_status
    from .camera.trackers import MARKERLESS, tracker_names
    vision = models_status()
    result["vision"] = {key: vision[key] for key in ("installed", "distribution", "error")}
    for name in tracker_names():
        if name in MARKERLESS:
            result["trackers"][name] = {"models": vision["trackers"][name],
                                        "needs": f"MediaPipe models ({EXTRA})"}
        else:
            result["trackers"][name] = {"models": None, "needs": "OpenCV"}
    result["opencv"] = importlib.util.find_spec("cv2") is not None
    from .osc import WEKINATOR_ADDRESS, WEKINATOR_PORT
    result["osc"] = {"host": "127.0.0.1", "port": WEKINATOR_PORT, "address": WEKINATOR_ADDRESS,
                     "spec": f"osc:127.0.0.1:{WEKINATOR_PORT}{WEKINATOR_ADDRESS}"}
    return result
