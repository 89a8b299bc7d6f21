"""Reading gesture recordings in the sktime/aeon ``.ts`` text format (the UCR/UEA time-series
archive's), to try followers on published gesture sets without hardware.

A ``.ts`` file has ``@``-headers, then after ``@data`` one recording per line: each channel a
comma-separated list of values, channels separated by ``:``, the class label last (when the
header says ``@classLabel true``); ``?`` is a missing value. Recordings may differ in length.
"""
from __future__ import annotations

import importlib.util
import os

import numpy as np


def read_ts(path) -> tuple[list[np.ndarray], np.ndarray]:
    """Recordings and labels of a ``.ts`` file.

    Returns a list of (T_i, D) float arrays (missing values NaN) and an (N,) str array of labels
    (empty strings when the file has none). Raises ValueError naming the line of a malformed
    recording (channels of different lengths, a value that is not a number, no ``@data``).
    """
    series, labels = [], []
    labelled = False  # until a @classLabel true header says otherwise
    data = False
    with open(path, encoding="utf-8") as handle:
        for number, raw in enumerate(handle, 1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            if not data:
                head = line.lower()
                if head.startswith("@classlabel"):
                    labelled = head.split()[1:2] == ["true"]
                elif head.startswith("@data"):
                    data = True
                continue
            fields = line.split(":")
            label = fields.pop() if labelled else ""
            try:
                channels = [np.array([np.nan if v.strip() == "?" else float(v)
                                      for v in field.split(",")]) for field in fields]
            except ValueError as error:
                raise ValueError(f"{path}, line {number}: not a number ({error})") from None
            if not channels or len({len(c) for c in channels}) != 1:
                raise ValueError(f"{path}, line {number}: channels of different lengths "
                                 f"{[len(c) for c in channels]}")
            series.append(np.stack(channels, axis=1))
            labels.append(label.strip())
    if not data:
        raise ValueError(f"{path}: no @data section: not a .ts file")
    return series, np.array(labels, dtype=str)


def aeon_dataset(name: str, split: str) -> tuple[list[np.ndarray], np.ndarray]:
    """A dataset shipped inside the aeon wheel (e.g. "PickupGestureWiimoteZ", split "TRAIN" or
    "TEST"), read with :func:`read_ts` without importing aeon (its import is slow).

    Raises ImportError when aeon is not installed, FileNotFoundError when it has no such set.
    """
    spec = importlib.util.find_spec("aeon")
    if spec is None:
        raise ImportError(f"the {name} recordings come inside the aeon wheel: "
                          f"pip install 'mop[test]'")
    path = os.path.join(spec.submodule_search_locations[0], "datasets", "data", name,
                        f"{name}_{split}.ts")
    if not os.path.exists(path):
        raise FileNotFoundError(f"aeon has no {name} {split} split (looked for {path})")
    return read_ts(path)
