"""Reading gesture recordings in the sktime/aeon ``.ts`` text format (the UCR/UEA time-series
archive's), to try followers on published gesture sets without hardware.

A ``.ts`` file has ``@``-headers, then after ``@data`` one recording per line: each channel a
comma-separated list of values, channels separated by ``:``, the class label last (when the
header says ``@classLabel true``); ``?`` is a missing value. Recordings may differ in length.
"""
from __future__ import annotations

import codecs
import importlib.util
import os
import pickle

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


def _wheel_path(package: str, *parts: str, install: str) -> str:
    spec = importlib.util.find_spec(package)
    if spec is None:
        raise ImportError(f"these recordings come inside the {package} wheel: pip install "
                          f"{install}")
    path = os.path.join(spec.submodule_search_locations[0], *parts)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{package} has no {parts[-1]} (looked for {path})")
    return path


class _ArraysOnly(pickle.Unpickler):
    """Unpickles numpy arrays, dtypes and plain containers, and refuses every other class: the
    file is read without running anything it names."""

    ALLOWED = {("numpy.core.multiarray", "_reconstruct"),
               ("numpy._core.multiarray", "_reconstruct"), ("numpy", "ndarray"),
               ("numpy", "dtype"), ("_codecs", "encode")}

    def find_class(self, module, name):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refusing {module}.{name} in a recordings file")
        if name == "encode":
            return codecs.encode
        if name == "_reconstruct":
            return np._core.multiarray._reconstruct
        return getattr(np, name)


def seglearn_watch(*, rate: float = 10.0, seconds: float = 10.0):
    """Smartwatch recordings shipped inside the seglearn wheel: 10 subjects performing sets of 7
    shoulder exercises (pendulum, abduction, forward elevation, internal and external rotation,
    trapezius, row) with the left and the right arm, 6 channels (accelerometer [g] and
    gyroscope [rad/s]) at 50 Hz.

    Each set becomes one take: ``seconds`` from the middle of it, resampled to ``rate`` Hz by
    averaging. Returns (takes: list of 140 (T, 6) float arrays, labels (140,) str, subjects
    (140,) int 1-10). Raises ImportError when seglearn is not installed."""
    path = _wheel_path("seglearn", "data", "watch_dataset.npy", install="seglearn")
    with open(path, "rb") as handle:
        if np.lib.format.read_magic(handle) == (1, 0):
            np.lib.format.read_array_header_1_0(handle)
        else:
            np.lib.format.read_array_header_2_0(handle)
        data = _ArraysOnly(handle, encoding="latin1").load().item()
    step = int(round(50.0 / rate))
    length = int(round(seconds * rate)) * step
    takes = []
    for series in data["X"]:
        middle = (series.shape[0] - length) // 2
        stretch = np.asarray(series[middle:middle + length], dtype=np.float64)
        takes.append(stretch.reshape(-1, step, stretch.shape[1]).mean(axis=1))
    names = [str(n) for n in data["y_labels"]]
    labels = np.array([names[int(i)] for i in data["y"]])
    return takes, labels, np.asarray(data["subject"], dtype=int)
