"""The tracker base class and the checks every tracker shares (numpy only; OpenCV is imported
when a tracker asks for it)."""
from __future__ import annotations

import numpy as np


def _cv2():
    try:
        import cv2
    except ImportError:
        raise ImportError("camera sources need OpenCV: pip install 'mop[capture]' "
                          "(opencv-contrib-python-headless)") from None
    return cv2


def _image(image: np.ndarray) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 \
            or image.shape[2] != 3:
        shape = getattr(image, "shape", None)
        dtype = getattr(image, "dtype", type(image).__name__)
        raise ValueError(f"a tracker takes a BGR image (H, W, 3) uint8, got {shape} {dtype}")
    return image


class Tracker:
    """Base class: `channels` (D names), `process(image (H, W, 3) uint8 BGR) -> (D,) float`
    (a new array each call), `describe()` -> the parameters, for take metadata; `scales` (D,)
    each channel's typical range (for smoothing); `reset()` forgets what was tracked,
    `close()` frees what the tracker holds."""
    name = "tracker"
    channels: tuple[str, ...] = ()
    scales: tuple[float, ...] | None = None

    def process(self, image: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"tracker": self.name}

    def channel_scales(self) -> np.ndarray:
        """(D,) float: `scales`, or 1 for every channel when the tracker gives none."""
        if self.scales is None or len(self.scales) != len(self.channels):
            return np.ones(len(self.channels))
        return np.asarray(self.scales, dtype=np.float64)

    def reset(self) -> None:
        pass

    def close(self) -> None:
        pass
