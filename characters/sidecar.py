"""Reading the JSON sidecars that travel with assets (motions, joints, finger regions, pins),
strictly: a JSON number is a number (not a bool, not a string), true/false is a bool (not
"false"), a list has the length asked for, and a version newer than this code reads is refused.
Every error is a ValueError or TypeError whose message names the file and the key, whatever the
bytes of the file (binary junk, deep nesting, the wrong types).

    document = read_json(path, "motion file")
    check_header(document, format="mop.motion", version=1, where=str(path))
    x, y, z = point(document["point"], f"{path}: point", size=3)
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np


def _text(path: Path, kind: str, what: str) -> str:
    """A file's text; a missing file is FileNotFoundError, anything else unreadable a
    ValueError naming it (a folder, a pipe or device, bytes that are not UTF-8)."""
    if not path.exists():
        raise FileNotFoundError(f"{what} not found: {path}")
    if path.is_dir():
        raise ValueError(f"{path}: a folder, expected a {kind} {what}")
    if not path.is_file():      # a pipe or a device would block or never end
        raise ValueError(f"{path}: not a regular file, expected a {kind} {what}")
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not a {kind} {what} (not UTF-8 text: {error.reason} at "
                         f"byte {error.start})") from None


def read_json(path: str | Path, what: str = "file") -> Any:
    """A JSON document from a file; every way it can be unreadable is a ValueError naming it
    (FileNotFoundError when it is not there)."""
    path = Path(path)
    text = _text(path, "JSON", what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON ({error})") from None
    except RecursionError:
        raise ValueError(f"{path}: JSON nested too deeply to read") from None


def check_header(document: Mapping, *, format: str, version: int, where: str,
                 required: bool = False) -> None:
    """The "format" and "version" keys of a sidecar: the right format, an integer version this
    mop reads. Absent keys are accepted unless `required`."""
    found = document.get("format")
    if found is None and not required:
        pass
    elif found != format:
        raise ValueError(f"{where}: format is {found!r}, expected {format!r}")
    number = document.get("version", None if required else version)
    if isinstance(number, bool) or not isinstance(number, int):
        raise TypeError(f"{where}: version must be an integer, got {number!r}")
    if not 1 <= number <= version:
        raise ValueError(f"{where}: version {number} is not one this mop reads (1..{version}); "
                         f"it was written by a newer mop, or is damaged")


def number(value: Any, what: str, *, finite: bool = True) -> float:
    """A JSON number (not a bool, not a string) as float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{what} must be a number, got {value!r:.60}")
    value = float(value)
    if finite and not math.isfinite(value):
        raise ValueError(f"{what} must be finite, got {value}")
    return value


def boolean(value: Any, what: str) -> bool:
    """A JSON true / false; anything else (the string "false", 0, null) is an error."""
    if not isinstance(value, bool):
        raise TypeError(f"{what} must be true or false, got {value!r:.60}"
                        + (" (a string)" if isinstance(value, str) else ""))
    return value


def point(value: Any, what: str, size: int = 2) -> tuple[float, ...]:
    """A list of `size` finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise TypeError(f"{what} must be a list of {size} numbers, got {value!r:.60}")
    return tuple(number(v, f"{what}[{k}]") for k, v in enumerate(value))


def indices(value: Any, what: str) -> np.ndarray:
    """A non-empty list of integers (not bools) as (K,) int64."""
    if not isinstance(value, (list, tuple)) or not value:
        raise TypeError(f"{what} must be a non-empty list of integer indices, got {value!r:.60}")
    for k, item in enumerate(value):
        if isinstance(item, bool) or not isinstance(item, int):
            raise TypeError(f"{what}[{k}] must be an integer index, got {item!r:.60}")
    try:
        return np.asarray(value, dtype=np.int64)
    except OverflowError:
        raise ValueError(f"{what}: an index does not fit in 64 bits") from None


def read_toml(path: str | Path, what: str = "file") -> dict:
    """A TOML document from a file; every way it can be unreadable is a ValueError naming it
    (FileNotFoundError when it is not there)."""
    import tomllib

    path = Path(path)
    text = _text(path, "TOML", what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: not valid TOML ({error})") from None
    except RecursionError:
        raise ValueError(f"{path}: TOML nested too deeply to read") from None


def numeric_lists(value: Any, what: str) -> Any:
    """`value` itself when it is a number or (nested) lists of numbers, none a bool or a string
    (numpy would read "1" and true as numbers)."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, (list, tuple)):
            stack.extend(item)
        elif isinstance(item, bool) or not isinstance(item, (int, float)):
            raise TypeError(f"{what} must hold numbers only, found {item!r:.60}")
    return value
