"""Strict readers for the small JSON files that sit beside assets (pins of an image puppet).

    pins = read_pins("momo.pins.json")        # {name: Pin(xy=(x, y), fixed=False)}
    pins = parse_pins(document, where="...")  # the same from a parsed document

A pins file is {"format": "mop.pins", "version": 1, "pins": {"hand": {"xy": [x, y]},
"feet": {"xy": [x, y], "fixed": true}}} in picture pixels; {"hand": [x, y]} (a bare table,
or a "pins" section inside a motion file) is accepted too. Types are strict (see
`characters.sidecar`): "fixed" is a JSON true/false (the string "false" is an error, not a true
value), "xy" two finite numbers, and a "version" newer than this mop reads is refused. Every
error is a ValueError or TypeError whose message names the file and the key.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from characters.sidecar import boolean, check_header, point, read_json

PINS_FORMAT = "mop.pins"
PINS_VERSION = 1


@dataclass(frozen=True)
class Pin:
    xy: tuple[float, float]     # [px] in the picture
    fixed: bool = False         # an anchor that stays put rather than a driven pin


def parse_pins(document: Any, *, where: str) -> dict[str, Pin]:
    """{name: Pin} from a pins document, a bare {name: [x, y] | {"xy", "fixed"}} table, or the
    "pins" section of a motion file."""
    if not isinstance(document, Mapping):
        raise TypeError(f"{where}: expected pins as {{name: {{'xy': [x, y], 'fixed': false}}}}, "
                        f"got {type(document).__name__}")
    table = document
    if "pins" in document and isinstance(document.get("pins"), Mapping) or \
            "format" in document or "version" in document:
        check_header(document, format=PINS_FORMAT, version=PINS_VERSION, where=where)
        table = document.get("pins")
        if not isinstance(table, Mapping):
            raise TypeError(f"{where}: 'pins' must map pin names to {{'xy': [x, y]}}, got "
                            f"{table!r:.60}")
    if not table:
        raise ValueError(f"{where}: no pins given")
    pins = {}
    for name, entry in table.items():
        what = f"{where}: pin {name!r}"
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"{what}: a pin name must be a non-empty string")
        if isinstance(entry, (list, tuple)):
            entry = {"xy": entry}
        if not isinstance(entry, Mapping):
            raise TypeError(f"{what} must be [x, y] or {{'xy': [x, y], 'fixed': false}}, got "
                            f"{entry!r:.60}")
        unknown = sorted(set(entry) - {"xy", "fixed"})
        if unknown:
            raise ValueError(f"{what}: unknown key(s) {', '.join(map(repr, unknown))}; a pin "
                             f"has 'xy' and 'fixed'")
        if "xy" not in entry:
            raise ValueError(f"{what} needs 'xy': [x, y] in pixels")
        x, y = point(entry["xy"], f"{what}: 'xy'")
        pins[name] = Pin((x, y), boolean(entry.get("fixed", False), f"{what}: 'fixed'"))
    return pins


def read_pins(path: str | Path) -> dict[str, Pin]:
    """{name: Pin} from a pins file (see the module docstring)."""
    path = Path(path)
    return parse_pins(read_json(path, "pins file"), where=str(path))
