"""`open_source(spec)`: any source from a short string.

    hid:PROFILE[@DEVICE]           hid:p5, hid:spacemouse, hid:generic@/dev/hidraw3,
                                   hid:dualshock4@054c:09cc, hid:path/to/profile.toml
    camera:DEVICE[:TRACKER]        camera:0:face, camera:0:hands, camera:0:pose,
                                   camera:0:aruco, camera:clip.mkv:color
    osc:[HOST][:PORT][/ADDRESS]    osc:127.0.0.1:9000/glove, osc: (Wekinator: 127.0.0.1:6448
                                   /wek/inputs), osc:0.0.0.0:9000/glove (other machines)
    replay:PATH                    replay:recordings/NAME (the .sqlite suffix may be left out)

Options follow a "?" as key=value pairs joined by "&": numbers, true/false, and comma lists, e.g.
`camera:0:aruco?ids=0,1&marker_length=0.04`, `replay:recordings/wave?realtime=false`,
`osc:127.0.0.1:9000/glove?channels=5`, `hid:p5?stall_timeout=1`. `rate=50` resamples the
source to 50 Hz (`resample=linear|hold`). Keyword arguments of `open_source` override the string.
"""
from __future__ import annotations

from typing import Any
from urllib.parse import unquote

from .source import Resampled, Source

KINDS = ("hid", "camera", "osc", "replay")
_SOURCE_OPTIONS = {"stall_timeout", "reconnect_interval", "reconnect", "queue_size",
                   "backpressure", "wait"}
_CAMERA_OPTIONS = _SOURCE_OPTIONS | {"realtime", "loop", "width", "height", "fps", "smooth",
                                     "smooth_cutoff", "smooth_beta"}


def _value(text: str) -> Any:
    text = unquote(text)
    lowered = text.lower()
    if lowered in ("true", "yes", "on"):
        return True
    if lowered in ("false", "no", "off"):
        return False
    if "," in text:
        return [_value(part) for part in text.split(",") if part != ""]
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_options(query: str) -> dict[str, Any]:
    """"a=1&b=x,y" -> {"a": 1, "b": ["x", "y"]}."""
    options: dict[str, Any] = {}
    for pair in filter(None, query.split("&")):
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"source option {pair!r}: expected key=value")
        options[key] = _value(value)
    return options


def split_spec(spec: str) -> tuple[str, str, dict[str, Any]]:
    """"camera:0:aruco?ids=1" -> ("camera", "0:aruco", {"ids": 1})."""
    if not isinstance(spec, str):
        raise TypeError(f"a source spec is a string like 'hid:p5', got {type(spec).__name__}")
    kind, sep, rest = spec.partition(":")
    if not sep or kind not in KINDS:
        raise ValueError(f"source spec {spec!r}: expected KIND:..., KIND one of "
                         f"{', '.join(KINDS)} (e.g. hid:p5, camera:0:aruco, "
                         f"osc:127.0.0.1:9000/glove, replay:recordings/NAME)")
    body, _, query = rest.partition("?")
    return kind, body, parse_options(query)


def _hid(body: str, options: dict, spec: str) -> Source:
    from .hid.source import HidSource, parse_selector
    profile, _, selector = body.partition("@")
    if not profile:
        raise ValueError(f"{spec!r}: name a HID profile, e.g. hid:p5 or hid:spacemouse")
    options = {**parse_selector(selector), **options}
    return HidSource(profile, spec=spec, **options)


def _camera(body: str, options: dict, spec: str) -> Source:
    from .camera.source import CameraSource
    from .camera.trackers import TRACKERS, tracker_names
    device, tracker = body, "color"
    head, sep, tail = body.rpartition(":")
    if sep and tail in TRACKERS:
        device, tracker = head, tail
    elif sep and head and tail and not tail.isdigit():
        raise ValueError(f"{spec!r}: unknown tracker {tail!r}; available: "
                         f"{', '.join(tracker_names())}")
    if not device:
        raise ValueError(f"{spec!r}: name a camera index or a video file, e.g. camera:0:aruco")
    source_options = {k: v for k, v in options.items() if k in _CAMERA_OPTIONS}
    tracker_options = {k: v for k, v in options.items() if k not in _CAMERA_OPTIONS}
    target: int | str = int(device) if device.isdigit() else device
    if "ids" in tracker_options and not isinstance(tracker_options["ids"], list):
        tracker_options["ids"] = [tracker_options["ids"]]
    return CameraSource(target, tracker, tracker_options=tracker_options, spec=spec,
                        **source_options)


def _osc(body: str, options: dict, spec: str) -> Source:
    from .osc import WEKINATOR_ADDRESS, WEKINATOR_PORT, OscSource
    slash = body.find("/")
    hostport, address = (body, None) if slash < 0 else (body[:slash], body[slash:])
    host, port = "127.0.0.1", WEKINATOR_PORT
    if hostport:
        name, sep, number = hostport.rpartition(":")
        if sep:
            host = name or host
            if number:
                try:
                    port = int(number)
                except ValueError:
                    raise ValueError(f"{spec!r}: port must be a number, got {number!r}") from None
        elif hostport.isdigit():
            port = int(hostport)
        else:
            host = hostport
    channels = options.pop("channels", None)
    if isinstance(channels, str):
        channels = [channels]
    if "mapping" in options:
        return OscSource(host, port, options.pop("mapping"), spec=spec, **options)
    return OscSource(host, port, address=address or WEKINATOR_ADDRESS, channels=channels,
                     spec=spec, **options)


def _replay(body: str, options: dict, spec: str) -> Source:
    from .replay import ReplaySource
    if not body:
        raise ValueError(f"{spec!r}: name a take, e.g. replay:recordings/NAME")
    if "fast" in options:
        options["realtime"] = not options.pop("fast")
    return ReplaySource(body, spec=spec, **options)


_OPENERS = {"hid": _hid, "camera": _camera, "osc": _osc, "replay": _replay}


def open_source(spec: str, **overrides) -> Source:
    """Open a source from its spec string (see the module docstring); keyword arguments
    override options of the string. Raises ValueError for a bad spec, OSError / FileNotFoundError
    when the device or file is not there."""
    kind, body, options = split_spec(spec)
    options.update(overrides)
    rate = options.pop("rate", None)
    method = options.pop("resample", "linear")
    source = _OPENERS[kind](body, options, spec)
    if rate is not None:
        return Resampled(source, float(rate), method=method)
    return source
