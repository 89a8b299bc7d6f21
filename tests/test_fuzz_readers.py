"""Fuzzing every JSON and TOML reader with random mutations of the files mop ships: whatever
the bytes, a reader returns a result or raises ValueError / TypeError (FileNotFoundError for a
path that is gone) with a message that names the file. Nothing else comes out: no KeyError,
AttributeError, IndexError, RecursionError, UnicodeDecodeError, and no bare numpy message.

The mutations are seeded from MOP_TEST_SEED (printed in pytest's header); MOP_FUZZ_CASES sets
the number of cases per shipped file (default 250: about 3,500 in all). A failure prints
the seed, the case number and the mutated text, so it can be replayed.
"""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
ASSETS = ROOT / "characters" / "assets"
CASES = int(os.environ.get("MOP_FUZZ_CASES", "250"))


def _motion(path):
    from characters import Motion
    return Motion.load(path)


def _joints(path):
    from characters.medial.joints import JointSpec
    return JointSpec.load(path)


def _regions(path):
    from characters.latex.regions import parse_regions
    return parse_regions(path)


def _pins(path):
    from mop.sidecars import read_pins
    return read_pins(path)


def _puppet_pins(path):
    """`mop puppet`'s reading of a pins file."""
    from mop.commands.puppet import load_pins
    return load_pins(path)


def _session(path):
    from mop.session import load_session
    return load_session(path)


def _materials(path):
    from characters.materials import load_materials
    return load_materials(path)


def _hid_profile(path):
    from capture.hid.profile import load_profile_file
    return load_profile_file(path)


READERS = [
    ("momo_wave.json", ASSETS / "momo_wave.json", _motion),
    ("caterpillar motion", ASSETS / "medial_caterpillar.motion.json", _motion),
    ("caterpillar joints", ASSETS / "medial_caterpillar.joints.json", _joints),
    ("froggy regions", ASSETS / "froggy.json", _regions),
    ("momo pins", ASSETS / "momo.pins.json", _pins),
    ("momo pins via mop puppet", ASSETS / "momo.pins.json", _puppet_pins),
    ("demo session", ROOT / "sessions" / "demo.toml", _session),
    ("materials", ROOT / "characters" / "materials.toml", _materials),
    *[(f"hid profile {p.stem}", p, _hid_profile)
      for p in sorted((ROOT / "capture" / "profiles").glob("*.toml"))],
]

# values a careless or hostile hand puts where a number, a name or a table was
_JSON_VALUES = [None, True, False, "false", "true", "", "x" * 300, "../../etc/passwd", 0, -1, 1,
                99, 2 ** 70, -(2 ** 70), 1e308, -1e308, 1e-320, 0.5, float("nan"), float("inf"),
                -float("inf"), [], {}, [[]], [None], ["a", 1], [1e308, -1e308], {"": {}},
                {"format": None}, list(range(50))]
_TOML_VALUES = ["true", "false", '"false"', '""', '"x"', "0", "-1", "99", "1e308", "-1e308",
                "nan", "inf", "-inf", "[]", "{}", "[[]]", "[1, \"a\"]", '"../../x"',
                "99999999999999999999", "0.0", "[nan, inf]", "{ a = 1 }", "1979-05-27"]


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(node, list):
        for index, value in enumerate(node[:20]):
            yield from _paths(value, prefix + (index,))


def _mutate_json(text: str, rng: np.random.Generator) -> str:
    document = json.loads(text)
    paths = list(_paths(document))
    for _ in range(int(rng.integers(1, 4))):
        path = paths[int(rng.integers(len(paths)))]
        if not path:
            document = _JSON_VALUES[int(rng.integers(len(_JSON_VALUES)))]
            break
        parent = document
        try:
            for key in path[:-1]:
                parent = parent[key]
            key = path[-1]
            action = rng.integers(4)
            if action == 0 and isinstance(parent, dict):
                del parent[key]
            elif action == 1 and isinstance(parent, dict):
                parent[f"extra{int(rng.integers(100))}"] = parent[key]
            elif action == 2 and isinstance(parent, list):
                parent.insert(int(key), _JSON_VALUES[int(rng.integers(len(_JSON_VALUES)))])
            else:
                parent[key] = _JSON_VALUES[int(rng.integers(len(_JSON_VALUES)))]
        except (KeyError, IndexError, TypeError):
            continue
    return json.dumps(document)


_TOML_VALUE_LINE = re.compile(r"^(\s*[A-Za-z0-9_.\"-]+\s*=\s*)(.+)$", re.M)


def _mutate_toml(text: str, rng: np.random.Generator) -> str:
    lines = list(_TOML_VALUE_LINE.finditer(text))
    for _ in range(int(rng.integers(1, 4))):
        if not lines:
            break
        match = lines[int(rng.integers(len(lines)))]
        action = rng.integers(5)
        if action == 0:     # the key's line goes
            text = text.replace(match.group(0), "", 1)
        elif action == 1:   # a table header breaks or repeats
            text = text.replace("[", "[[", 1) if rng.integers(2) else text + "\n[session]\n"
        else:
            value = _TOML_VALUES[int(rng.integers(len(_TOML_VALUES)))]
            text = text.replace(match.group(0), match.group(1) + value, 1)
        lines = list(_TOML_VALUE_LINE.finditer(text))
    return text


def _mutate_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    data = bytearray(data)
    for _ in range(int(rng.integers(1, 6))):
        if not data:
            break
        at = int(rng.integers(len(data)))
        action = rng.integers(5)
        if action == 0:
            data[at] = int(rng.integers(256))
        elif action == 1:
            del data[at:at + int(rng.integers(1, 40))]
        elif action == 2:
            data[at:at] = bytes(rng.integers(0, 256, int(rng.integers(1, 12)), dtype=np.uint8))
        elif action == 3:
            del data[at:]
        else:
            data[at:at] = data[max(0, at - 30):at]
    return bytes(data)


def _mutations(path: Path, rng: np.random.Generator):
    text = path.read_text()
    structured = _mutate_json if path.suffix == ".json" else _mutate_toml
    for case in range(CASES):
        kind = rng.integers(3)
        if kind == 0:
            yield case, _mutate_bytes(text.encode(), rng)
        else:
            try:
                yield case, structured(text, rng).encode()
            except (ValueError, RecursionError):
                yield case, _mutate_bytes(text.encode(), rng)
    # a few hand-made attacks on every reader
    yield "empty", b""
    yield "binary", bytes(range(256)) * 4
    yield "deep", b"[" * 100000 + b"]" * 100000 if path.suffix == ".json" else \
        b"a = " + b"[" * 100000 + b"]" * 100000
    yield "nul", text.encode().replace(b"\n", b"\x00\n", 3)


@pytest.mark.slow
@pytest.mark.parametrize("label, shipped, reader", READERS, ids=[r[0] for r in READERS])
def test_a_reader_raises_only_clear_errors_on_mutated_files(label, shipped, reader, tmp_path,
                                                             seed):
    rng = np.random.default_rng([seed, sum(map(ord, label))])
    reader(shipped)                     # the shipped file itself reads
    target = tmp_path / shipped.name
    failures = []
    for case, data in _mutations(shipped, rng):
        target.write_bytes(data)
        try:
            reader(target)
        except (ValueError, TypeError, FileNotFoundError) as error:
            message = str(error)
            if str(target) not in message and target.name not in message:
                failures.append((case, f"{type(error).__name__} without the file's name: "
                                       f"{message[:200]}", data))
        except Exception as error:      # noqa: BLE001 - exactly what this test looks for
            failures.append((case, f"{type(error).__name__}: {str(error)[:200]}", data))
        if len(failures) >= 5:
            break
    if failures:
        report = "\n".join(f"  case {case}: {what}\n    input: {data[:300]!r}"
                           for case, what, data in failures)
        pytest.fail(f"{label} (MOP_TEST_SEED={seed}): {len(failures)} unclear errors\n{report}")


def test_the_mutations_are_not_all_rejected(seed):
    """A fuzzer whose every case fails to parse tests nothing beyond the parser."""
    rng = np.random.default_rng(seed)
    text = (ASSETS / "momo_wave.json").read_text()
    parsed = 0
    for _ in range(100):
        try:
            json.loads(_mutate_json(text, rng))
            parsed += 1
        except ValueError:
            pass
    assert parsed >= 90
    assert not math.isnan(float(parsed))
