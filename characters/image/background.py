"""Background removal for image puppets: picture -> character mask and a feathered alpha.

As in Animatron's puppet tool: a picture with a real alpha channel uses it; otherwise the
background colour is estimated from the four image corners and every colour within a tolerance of
it is erased, then the edge is feathered. The largest connected part that is left is the
character. Enclosed regions erased that way are filled back in (character pixels that happen to
be near the background colour) unless they are large and really look like the background (a gap
between an arm and the body).

Conventions: images are (H, W, C) uint8 arrays, rows top to bottom; colour distances are
Euclidean in RGB on the 0..255 scale.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

MIN_IMAGE_SIDE = 16          # [px] below this there is no character to build a mesh on
MAX_IMAGE_SIDE = 8192        # [px] larger pictures would not fit a frame buffer sensibly
DEFAULT_TOLERANCE_FLOOR = 32.0   # [0..255 RGB distance] cartoon edges antialias within this
MAX_BACKGROUND_NOISE = 40.0  # [0..255] corner spread above which the background is not plain


def require_cv2():
    """OpenCV, imported on first use (connected components, contours, distance transforms)."""
    try:
        import cv2
    except ImportError:
        raise ImportError("image puppets need OpenCV to cut out and mesh pictures: "
                          "pip install 'mop[image]'") from None
    return cv2


@dataclass(frozen=True)
class Cutout:
    """The result of background removal.

    rgba : (H, W, 4) uint8: the picture, straight alpha = feathered character alpha
    mask : (H, W) bool: the character (largest component, small holes filled)
    background_colour : (3,) float [0..255] | None: the estimated background (None if the
        picture's own alpha channel was used)
    tolerance : float [0..255] | None: the colour tolerance used
    """

    rgba: np.ndarray
    mask: np.ndarray
    background_colour: np.ndarray | None
    tolerance: float | None


def load_image(image) -> np.ndarray:
    """A path or array (H, W), (H, W, 1|3|4), uint8 / uint16 / float in [0, 1] / bool, as
    (H, W, 3|4) uint8. RGBA whose alpha is fully opaque is returned as RGB."""
    if isinstance(image, (str, Path)):
        path = Path(image)
        if not path.exists():
            raise FileNotFoundError(f"image file not found: {path}")
        from PIL import Image, UnidentifiedImageError
        try:
            with Image.open(path) as opened:
                opened.load()
                has_alpha = opened.mode in ("RGBA", "LA", "PA") or (
                    opened.mode == "P" and "transparency" in opened.info)
                array = np.asarray(opened.convert("RGBA" if has_alpha else "RGB"))
        except UnidentifiedImageError:
            raise ValueError(f"{path} is not an image Pillow can read") from None
    elif isinstance(image, np.ndarray):
        array = image
    else:
        raise TypeError(f"image must be a path or a numpy array, got {type(image).__name__}")

    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (3, 4)):
        raise ValueError(f"image must have shape (H, W), (H, W, 3) or (H, W, 4), got {array.shape}")
    if array.dtype == bool:
        array = array.astype(np.uint8) * 255
    elif array.dtype == np.uint16:
        array = (array >> 8).astype(np.uint8)
    elif np.issubdtype(array.dtype, np.floating):
        if not np.all(np.isfinite(array)):
            raise ValueError("image holds NaN or inf values")
        low, high = float(array.min()), float(array.max())
        if low < 0.0 or high > 1.0:
            raise ValueError(f"a float image must hold values in [0, 1], got [{low:g}, {high:g}]")
        array = np.round(array * 255.0).astype(np.uint8)
    elif array.dtype != np.uint8:
        raise TypeError(f"image dtype must be uint8, uint16, float or bool, got {array.dtype}")
    if array.ndim == 2:
        array = np.repeat(array[:, :, None], 3, axis=2)
    height, width = array.shape[:2]
    if min(height, width) < MIN_IMAGE_SIDE:
        raise ValueError(f"image is {width}x{height} pixels: too small to hold a character; "
                         f"give at least {MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE}")
    if max(height, width) > MAX_IMAGE_SIDE:
        raise ValueError(f"image is {width}x{height} pixels: larger than the supported "
                         f"{MAX_IMAGE_SIDE} per side; downscale it first")
    if array.shape[2] == 4 and array[:, :, 3].min() == 255:
        array = array[:, :, :3]
    return np.ascontiguousarray(array)


def estimate_background(rgb: np.ndarray, *, patch: int | None = None):
    """Background colour and noise from the image corners.

    rgb : (H, W, 3) uint8. Returns (colour (3,) float [0..255], spread float [0..255]: the 99th
    percentile of corner-pixel distances to that colour). Corners covered by the character
    (disagreeing with the others) are ignored; fewer than two agreeing corners is an error.
    """
    height, width = rgb.shape[:2]
    size = patch or max(2, round(0.04 * min(height, width)))
    corners = [rgb[:size, :size], rgb[:size, -size:], rgb[-size:, :size], rgb[-size:, -size:]]
    pixels = [c.reshape(-1, 3).astype(np.float64) for c in corners]
    medians = np.array([np.median(p, axis=0) for p in pixels])
    spreads = np.array([np.percentile(np.linalg.norm(p - m, axis=1), 99)
                        for p, m in zip(pixels, medians)])
    # Each corner votes for the corners close to it; the largest agreeing group is background.
    limit = max(DEFAULT_TOLERANCE_FLOOR, 2.0 * float(np.median(spreads)))
    agree = np.linalg.norm(medians[:, None] - medians[None], axis=2) <= limit
    best = int(np.argmax(agree.sum(1)))
    group = np.flatnonzero(agree[best])
    if group.size < 2:
        listed = ", ".join("#%02x%02x%02x" % tuple(int(round(c)) for c in m) for m in medians)
        raise ValueError(f"no separable foreground: the four image corners have different colours "
                         f"({listed}), so there is no plain background to remove; give a picture "
                         f"on a plain background or with an alpha channel")
    colour = np.median(np.concatenate([pixels[i] for i in group]), axis=0)
    spread = float(np.percentile(np.concatenate(
        [np.linalg.norm(pixels[i] - colour, axis=1) for i in group]), 99))
    return colour, spread


def _largest_component(foreground: np.ndarray) -> np.ndarray:
    cv2 = require_cv2()
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        foreground.astype(np.uint8), connectivity=8)
    if count <= 1:
        return np.zeros_like(foreground)
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return labels == largest


def _fill_holes(mask: np.ndarray, max_hole_fraction: float,
                distance: np.ndarray | None = None, hole_tolerance: float = 0.0) -> np.ndarray:
    """Fill background islands enclosed by the mask, except real holes.

    An enclosed island stays a hole only if it is larger than max_hole_fraction of the mask's
    area and, when a colour distance map (H, W) is given, its median distance to the background
    colour is within hole_tolerance: background showing through (between an arm and the body)
    is exactly the background colour, while character parts that are merely close to it (white
    eyes on a cream background) are not."""
    cv2 = require_cv2()
    holes = ~mask
    count, labels, stats, _ = cv2.connectedComponentsWithStats(holes.astype(np.uint8),
                                                               connectivity=4)
    if count <= 1:
        return mask
    height, width = mask.shape
    x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    w, h = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
    enclosed = ~((x == 0) | (y == 0) | (x + w == width) | (y + h == height))
    enclosed[0] = False   # label 0 is the mask itself
    keep_hole = enclosed & (stats[:, cv2.CC_STAT_AREA] > max_hole_fraction * mask.sum())
    if distance is not None:
        for label in np.flatnonzero(keep_hole):
            if np.median(distance[labels == label]) > hole_tolerance:
                keep_hole[label] = False
    fill = enclosed & ~keep_hole
    if not fill.any():
        return mask
    return mask | fill[labels]


def feather_alpha(mask: np.ndarray, feather: float) -> np.ndarray:
    """(H, W) uint8 alpha: 255 inside, ramping to 0 over `feather` px inward from the edge.

    Feathering inward keeps the background colour out of the visible edge (no halo)."""
    if feather <= 0:
        return mask.astype(np.uint8) * 255
    cv2 = require_cv2()
    inside = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 3)
    # a boundary pixel is at distance 1: it gets alpha 1/(feather+1) .. ramp to 1
    alpha = np.clip(inside / (feather + 1.0), 0.0, 1.0)
    return np.round(alpha * 255).astype(np.uint8)


def remove_background(image: np.ndarray, *, tolerance: float | None = None,
                      feather: float = 1.5, max_hole_fraction: float = 0.002,
                      min_character_fraction: float = 0.001) -> Cutout:
    """Find the character in a loaded picture (see `load_image`).

    image : (H, W, 3|4) uint8
    tolerance : float [0..255 RGB distance] | None: colours closer than this to the background
        are erased; None = max(32, 1.5 x the corner noise)
    feather : float [px] >= 0: width of the alpha ramp inside the edge
    max_hole_fraction : enclosed holes smaller than this fraction of the character's area are
        filled; larger ones too unless their median colour is within tolerance / 2 of the
        background (so white eyes on a cream background stay, background seen through a gap
        between an arm and the body goes)
    min_character_fraction : a largest part smaller than this fraction of the image is an error
    """
    cv2 = require_cv2()
    if feather < 0 or not np.isfinite(feather):
        raise ValueError(f"feather must be a finite width >= 0 [px], got {feather}")
    height, width = image.shape[:2]
    background_colour = None
    if image.shape[2] == 4:
        alpha_in = image[:, :, 3]
        if alpha_in.max() == 0:
            raise ValueError("image is fully transparent: its alpha channel is 0 everywhere, so "
                             "there is no character")
        foreground = alpha_in >= 128
        rgb = image[:, :, :3]
    else:
        rgb = image
        if int(rgb.max()) - int(rgb.min()) <= 2:
            raise ValueError("image is uniform (every pixel is about #%02x%02x%02x): there is no "
                             "character to cut out" % tuple(int(c) for c in rgb[0, 0]))
        background_colour, spread = estimate_background(rgb)
        if spread > MAX_BACKGROUND_NOISE:
            raise ValueError(f"no separable foreground: the image corners vary by {spread:.0f} "
                             f"(0..255 scale) so the background is not plain; give a picture on "
                             f"a plain background or with an alpha channel")
        if tolerance is None:
            tolerance = max(DEFAULT_TOLERANCE_FLOOR, 1.5 * spread)
        elif not np.isfinite(tolerance) or tolerance <= 0:
            raise ValueError(f"tolerance must be a colour distance > 0 (0..255 scale), got "
                             f"{tolerance}")
        distance = np.sqrt(((rgb.astype(np.float32) - background_colour.astype(np.float32)) ** 2)
                           .sum(axis=2))
        if spread > 6.0:
            # noisy background: a 3x3 median keeps edges and removes isolated noise pixels
            distance = cv2.medianBlur(distance, 3)
        foreground = distance > tolerance
        if not foreground.any():
            raise ValueError(f"image is uniform: no pixel differs from the background colour "
                             f"#%02x%02x%02x by more than the tolerance {tolerance:.0f}"
                             % tuple(int(round(c)) for c in background_colour))

    mask = _largest_component(foreground)
    area = int(mask.sum())
    if area < max(16, min_character_fraction * height * width):
        raise ValueError(f"no separable foreground: the largest part that differs from the "
                         f"background is {area} pixels of {width}x{height}; give a picture where "
                         f"the character stands out from a plain background")
    if background_colour is None:
        mask = _fill_holes(mask, max_hole_fraction)
    else:
        mask = _fill_holes(mask, max_hole_fraction, distance, 0.5 * tolerance)
    if mask.mean() > 0.97:
        raise ValueError(f"no separable foreground: {100 * mask.mean():.1f}% of the picture "
                         f"differs from the corner colour, so no background was found")
    if image.shape[2] == 4:
        # The picture's own alpha is already a clean edge: keep it (no feathering), on the kept
        # character and its soft rim just outside the alpha >= 128 mask.
        rim = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        alpha = np.where(rim, image[:, :, 3], 0).astype(np.uint8)
    else:
        alpha = feather_alpha(mask, feather)
    rgba = np.dstack([rgb, alpha])
    log.debug("background removal: %d character pixels of %dx%d", area, width, height)
    return Cutout(rgba=rgba, mask=mask, background_colour=background_colour,
                  tolerance=None if tolerance is None else float(tolerance))
