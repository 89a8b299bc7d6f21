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
from enum import Enum
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

MIN_IMAGE_SIDE = 16          # [px] below this there is no character to build a mesh on
MAX_IMAGE_SIDE = 8192        # [px] larger pictures would not fit a frame buffer sensibly
DEFAULT_TOLERANCE_FLOOR = 32.0   # [0..255 RGB distance] cartoon edges antialias within this
MAX_BACKGROUND_NOISE = 40.0  # [0..255] corner spread above which the background is not plain
MAX_FIELD_NOISE = 12.0       # [0..255] a lit background this busy is a scene, not a backdrop
PLAIN_SPREAD = 10.0          # [0..255] a background this flat is keyed by one colour (plain)
MIN_TRANSPARENT_FRACTION = 0.01   # an alpha channel outlines a character if this much is clear
ANALYSIS_SIZE = 640          # [px] larger pictures are analysed on a copy this big
TEXTURED_SHARE = 0.01        # a cut-out is doubtful when the textured pixels it left out
                             # (light.textured_outside) are this share of its area


def require_cv2():
    """OpenCV, imported on first use (connected components, contours, distance transforms)."""
    try:
        import cv2
    except ImportError:
        raise ImportError("image puppets need OpenCV to cut out and mesh pictures: "
                          "pip install 'mop[image]'") from None
    return cv2


class PictureKind(str, Enum):
    """How a picture's character is found (`remove_background(kind=...)`).

    auto: alpha if the alpha channel is transparent somewhere, plain if the border is one flat
    colour, else the light field, as a drawing if what stands out is thin strokes, else as a
    photo. alpha: the picture's own alpha channel. plain: one background colour from the
    corners, erased within a tolerance. photo: a smooth background field (uneven light,
    shadows), the edge refined by GrabCut. drawing: the same field; the ink's outline, small
    gaps closed, filled with everything it encloses."""

    AUTO = "auto"
    ALPHA = "alpha"
    PLAIN = "plain"
    PHOTO = "photo"
    DRAWING = "drawing"


@dataclass(frozen=True)
class Cutout:
    """The result of background removal.

    rgba : (H, W, 4) uint8: the picture, straight alpha = feathered character alpha
    mask : (H, W) bool: the character (largest component, small holes filled)
    background_colour : (3,) float [0..255] | None: the estimated background: the corners'
        colour, or the light field's mean (None if the picture's own alpha channel was used)
    tolerance : float [0..255] | None: the colour distance beyond which a pixel stood out
    kind : PictureKind: the path that found the character (never AUTO)
    notes : tuple of str: what a user should know about the result (an outline left open,
        an alpha channel ignored)
    """

    rgba: np.ndarray
    mask: np.ndarray
    background_colour: np.ndarray | None
    tolerance: float | None
    kind: PictureKind = PictureKind.PLAIN
    notes: tuple = ()


def load_image(image) -> np.ndarray:
    """A path or array (H, W), (H, W, 1|3|4), uint8 / uint16 / float in [0, 1] / bool, as
    (H, W, 3|4) uint8. RGBA whose alpha is fully opaque is returned as RGB.

    Files are read with Pillow as they come from phones and editors: turned upright by their
    EXIF orientation; 16-bit greyscale scaled to 8 bits (not clipped); palette, greyscale,
    CMYK and bilevel pictures converted to RGB (palette transparency kept as alpha)."""
    if isinstance(image, (str, Path)):
        array = _read_picture(Path(image))
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


def _read_picture(path: Path) -> np.ndarray:
    """A picture file -> (H, W) | (H, W, 3|4) array, upright, in its own bit depth."""
    if not path.exists():
        raise FileNotFoundError(f"image file not found: {path}")
    from PIL import Image, ImageOps, UnidentifiedImageError
    try:
        with Image.open(path) as opened:
            opened.load()
            upright = ImageOps.exif_transpose(opened)
    except UnidentifiedImageError:
        raise ValueError(f"{path} is not an image Pillow can read") from None
    except OSError as error:
        raise ValueError(f"{path}: the picture cannot be decoded ({error})") from None
    mode = upright.mode
    if mode.startswith("I;16") or mode == "I":
        values = np.asarray(upright).astype(np.int64)
        high = int(values.max()) if values.size else 0
        # 16-bit greyscale (PNG, TIFF): scale, never clip to white
        full = 255 if high <= 255 and mode == "I" else 65535 if high <= 65535 else high
        return np.round(np.clip(values, 0, None) * (255.0 / full)).astype(np.uint8)
    if mode == "F":
        return np.asarray(upright, dtype=np.float64)
    has_alpha = mode in ("RGBA", "LA", "PA", "RGBa", "La") or (
        mode in ("P", "L", "RGB") and "transparency" in upright.info)
    try:
        return np.asarray(upright.convert("RGBA" if has_alpha else "RGB"))
    except ValueError as error:
        raise ValueError(f"{path}: Pillow cannot turn a {mode} picture into RGB ({error}); "
                         f"save it as an RGB PNG or JPEG") from None


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


def largest_component(foreground: np.ndarray) -> np.ndarray:
    """(H, W) bool: the largest 8-connected part of a mask (all False if it is empty)."""
    cv2 = require_cv2()
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        foreground.astype(np.uint8), connectivity=8)
    if count <= 1:
        return np.zeros_like(foreground, dtype=bool)
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return labels == largest


def _enclosed_regions(mask: np.ndarray):
    """(labels (H, W) int, stats, enclosed (L,) bool): the 4-connected regions outside the
    mask, and which of them touch no picture border (label 0 is the mask itself)."""
    cv2 = require_cv2()
    count, labels, stats, _ = cv2.connectedComponentsWithStats((~mask).astype(np.uint8),
                                                               connectivity=4)
    height, width = mask.shape
    x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    w, h = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
    enclosed = ~((x == 0) | (y == 0) | (x + w == width) | (y + h == height))
    enclosed[0] = False
    return labels, stats, enclosed


def fill_enclosed(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the mask with every region it encloses filled."""
    labels, _, enclosed = _enclosed_regions(mask)
    return mask | enclosed[labels]


def fill_holes(mask: np.ndarray, max_hole_fraction: float,
               distance: np.ndarray | None = None, hole_tolerance: float = 0.0) -> np.ndarray:
    """Fill background islands enclosed by the mask, except real holes.

    An enclosed island stays a hole only if it is larger than max_hole_fraction of the mask's
    area and, when a colour distance map (H, W) is given, its median distance to the background
    is within hole_tolerance: background showing through (between an arm and the body) is
    the background's colour, while character parts that are merely close to it (white eyes on
    a cream background) are not."""
    cv2 = require_cv2()
    labels, stats, enclosed = _enclosed_regions(mask)
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


def remove_background(image: np.ndarray, *, kind="auto", tolerance: float | None = None,
                      feather: float = 1.5, close_gaps: float | None = None,
                      max_hole_fraction: float = 0.002,
                      min_character_fraction: float = 0.001) -> Cutout:
    """Find the character in a loaded picture (see `load_image`).

    image : (H, W, 3|4) uint8
    kind : "auto" | "alpha" | "plain" | "photo" | "drawing" (see PictureKind): how to find
        the character; "auto" picks one from the picture
    tolerance : float [0..255 RGB distance] | None: colours closer than this to the background
        are background; None = automatic (plain: max(32, 1.5 x the corner noise); photo and
        drawing: from the background's noise, at least 20)
    feather : float [px] >= 0: width of the alpha ramp inside the edge
    close_gaps : float [px] | None: a drawing's outline is closed across gaps up to this
        wide; None = three stroke widths (at least 4 px)
    max_hole_fraction : enclosed holes smaller than this fraction of the character's area are
        filled; larger ones too unless their median colour is within tolerance / 2 of the
        background (so white eyes on a cream background stay, background seen through a gap
        between an arm and the body goes). A drawing's outline is filled whole.
    min_character_fraction : a largest part smaller than this fraction of the image is an error

    Pictures larger than ANALYSIS_SIZE are analysed on a downscaled copy; the mask and alpha
    come back at full size, with a smooth edge (the alpha then ramps over about one analysed
    pixel, whatever `feather`, as long as it is > 0).
    """
    try:
        kind = PictureKind(str(kind).strip().lower())
    except ValueError:
        raise ValueError(f"kind must be one of {[k.value for k in PictureKind]}, got "
                         f"{kind!r}") from None
    if feather < 0 or not np.isfinite(feather):
        raise ValueError(f"feather must be a finite width >= 0 [px], got {feather}")
    if close_gaps is not None and not (np.isfinite(close_gaps) and close_gaps > 0):
        raise ValueError(f"close_gaps must be a width > 0 [px], got {close_gaps}")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a colour distance > 0 (0..255 scale), got "
                         f"{tolerance}")
    notes = []
    if image.shape[2] == 4:
        transparent = float((image[:, :, 3] < 128).mean())
        if kind is PictureKind.ALPHA or (kind is PictureKind.AUTO
                                         and transparent >= MIN_TRANSPARENT_FRACTION):
            return _alpha_cutout(image, max_hole_fraction, min_character_fraction)
        notes.append(f"the alpha channel was ignored: only {100 * transparent:.2f}% of the "
                     f"picture is transparent, so it does not outline a character")
        image = _over_white(image)
    elif kind is PictureKind.ALPHA:
        raise ValueError("kind 'alpha' needs a picture with an alpha channel; this one has "
                         "none: try kind 'auto'")
    rgb = image
    height, width = rgb.shape[:2]
    scale = min(1.0, ANALYSIS_SIZE / max(height, width))
    work = rgb
    if scale < 1.0:
        work = shrink(rgb, (max(1, round(width * scale)), max(1, round(height * scale))))
    if int(work.max()) - int(work.min()) <= 2:
        raise ValueError("image is uniform (every pixel is about #%02x%02x%02x): there is no "
                         "character to cut out" % tuple(int(c) for c in work[0, 0]))
    plain = kind is PictureKind.PLAIN or (kind in (PictureKind.AUTO, PictureKind.DRAWING)
                                          and border_is_plain(work))
    found = _find_character(work, kind, plain=plain, tolerance=tolerance,
                            close_gaps=None if close_gaps is None else close_gaps * scale,
                            max_hole_fraction=max_hole_fraction,
                            min_character_fraction=min_character_fraction)
    notes += [_open_outline_note(found.drawing, scale)] if found.drawing is not None and \
        not found.drawing.closed else []
    notes += [_textured_note(found)] if _doubtful(found.textured, found.mask) else []
    if scale == 1.0:
        mask = found.mask
        alpha = feather_alpha(mask, feather)
    else:
        mask, alpha = upsample_mask(found.mask, (height, width), feather=feather > 0)
    share = np.count_nonzero(mask) / mask.size
    if share > 0.97:
        raise ValueError(f"no separable foreground: {100 * share:.1f}% of the picture "
                         f"differs from the background, so no background was found; "
                         f"give a picture with background around the character")
    log.debug("background removal (%s): %d character pixels of %dx%d", found.kind.value,
              int(np.count_nonzero(mask)), width, height)
    return Cutout(rgba=_with_alpha(rgb, alpha), mask=mask,
                  background_colour=found.background_colour, tolerance=found.tolerance,
                  kind=found.kind, notes=tuple(notes))


def shrink(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """An image (H, W[, C]) uint8 downscaled to size (width, height) by area averaging, in
    halving steps first (a fractional area resize of a 12-megapixel photo costs several
    times as much as halvings do)."""
    cv2 = require_cv2()
    while image.shape[1] >= 2 * size[0] and image.shape[0] >= 2 * size[1]:
        image = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2),
                           interpolation=cv2.INTER_AREA)
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def shrink_any(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(height, width) bool: a mask downscaled to size (width, height) <= its own, where a
    small pixel is set if the centre of any set pixel falls in it (or, at the far edge of
    its block, in the next one: a superset by at most a pixel row or column)."""
    cv2 = require_cv2()
    height, width = mask.shape
    starts, spans = [], []
    for full, small in ((height, size[1]), (width, size[0])):
        owner = np.floor((np.arange(full) + 0.5) * small / full).astype(np.int64)
        starts.append(np.searchsorted(owner, np.arange(small)))
        spans.append(int(np.diff(np.append(starts[-1], full)).max()))
    # every pixel becomes the maximum of the largest block below and right of it; keep each
    # block's first pixel
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((spans[0], spans[1]), np.uint8),
                       anchor=(0, 0), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return grown[starts[0]][:, starts[1]] > 0


def _with_alpha(rgb: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: RGB and an alpha channel, interleaved."""
    cv2 = require_cv2()
    rgba = cv2.cvtColor(rgb, cv2.COLOR_RGB2RGBA)
    rgba[:, :, 3] = alpha
    return rgba


def _over_white(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: an RGBA picture composited over white."""
    alpha = rgba[:, :, 3:4].astype(np.float32) / 255.0
    return np.round(rgba[:, :, :3] * alpha + 255.0 * (1.0 - alpha)).astype(np.uint8)


def upsample_mask(mask: np.ndarray, shape: tuple[int, int], *,
                  feather: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A mask found on a downscaled copy, brought to full size with a smooth edge rather than
    the small copy's pixel steps: the mask lightly blurred, interpolated, and thresholded at
    one half. Returns (mask (H, W) bool, alpha (H, W) uint8): the alpha ramps from 0 at that
    edge to 255 where the interpolated value reaches 1, about one analysed pixel inside
    (feather=False: a hard edge)."""
    cv2 = require_cv2()
    soft = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 0.7)
    height, width = shape
    full = cv2.resize(np.round(soft * 255).astype(np.uint8), (width, height),
                      interpolation=cv2.INTER_LINEAR)
    # 2 (value - 1/2), on the 0..255 scale, saturating: 0 outside, 255 a pixel inside
    alpha = cv2.multiply(cv2.subtract(full, 127), 2)
    mask_full = alpha > 0
    if not feather:
        return mask_full, mask_full.astype(np.uint8) * 255
    return mask_full, alpha


def border_is_plain(rgb: np.ndarray) -> bool:
    """Whether the background is one flat colour (a digital picture on a plain background,
    what the corner colour key handles): the light field fitted to the border band varies by
    at most PLAIN_SPREAD over the picture. A flat border is not enough: paper under a
    vignette is even along its border and brighter in the middle."""
    from . import light
    height, width = rgb.shape[:2]
    coefficients, _ = light.fit_field(rgb.astype(np.float32), light.border_band(height, width),
                                      light.FIRST_DEGREE)
    field = light.evaluate_field(coefficients, light.FIRST_DEGREE, 32, 32).reshape(-1, 3)
    spread = np.linalg.norm(field - np.median(field, axis=0), axis=1).max()
    return float(spread) <= PLAIN_SPREAD


def _character_check(mask: np.ndarray, min_character_fraction: float, where: str) -> None:
    height, width = mask.shape
    area = int(mask.sum())
    if area < max(16, min_character_fraction * height * width):
        raise ValueError(f"no separable foreground: the largest part that differs from the "
                         f"background is {area} pixels of {width}x{height}; {where}")


@dataclass(frozen=True)
class _Found:
    mask: np.ndarray
    kind: PictureKind
    background_colour: np.ndarray
    tolerance: float
    drawing: object = None     # drawing.FilledDrawing for a drawing
    textured: int = 0          # [px] textured pixels left out (light.textured_outside)


@dataclass(frozen=True)
class _Contrast:
    """How each pixel stands out from the background: foreground (H, W) bool, what stands
    out; sharp (H, W) float32, the colour distance to the background on the picture itself;
    threshold [0..255]; background (H, W, 3) float32; colour (3,) its mean; shadows (H, W)
    bool, the background in the character's shadow (sure background); weak (H, W) bool | None,
    what stands out a little and does not look like shadow (the character's where joined to
    it; None for the plain key); smoothed (H, W, 3) float32 | None, the picture lightly
    smoothed as the light field's residual was measured (None for the plain key)."""

    foreground: np.ndarray
    sharp: np.ndarray
    threshold: float
    background: np.ndarray
    colour: np.ndarray
    shadows: np.ndarray
    weak: np.ndarray | None = None
    smoothed: np.ndarray | None = None


def _alpha_cutout(image, max_hole_fraction, min_character_fraction) -> Cutout:
    """The picture's own alpha channel: alpha >= 128 is the character, its soft edge kept."""
    cv2 = require_cv2()
    alpha_in = image[:, :, 3]
    if alpha_in.max() == 0:
        raise ValueError("image is fully transparent: its alpha channel is 0 everywhere, so "
                         "there is no character")
    mask = largest_component(alpha_in >= 128)
    _character_check(mask, min_character_fraction, "its alpha channel holds no character")
    mask = fill_holes(mask, max_hole_fraction)
    # The picture's own alpha is already a clean edge: keep it (no feathering), on the kept
    # character and its soft rim just outside the alpha >= 128 mask.
    rim = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    alpha = np.where(rim, alpha_in, 0).astype(np.uint8)
    return Cutout(rgba=np.dstack([image[:, :, :3], alpha]), mask=mask, background_colour=None,
                  tolerance=None, kind=PictureKind.ALPHA)


def _plain_contrast(rgb, tolerance) -> _Contrast:
    """One background colour from the corners, colours within a tolerance of it erased
    (Animatron's key, for digital pictures on a flat colour)."""
    cv2 = require_cv2()
    background_colour, spread = estimate_background(rgb)
    if spread > MAX_BACKGROUND_NOISE:
        raise ValueError(f"the background is not plain: the picture's corners vary by "
                         f"{spread:.0f} (0..255 scale); try kind 'photo' (--kind photo) for a "
                         f"background lit unevenly, or give a picture with an alpha channel")
    if tolerance is None:
        tolerance = max(DEFAULT_TOLERANCE_FLOOR, 1.5 * spread)
    distance = np.sqrt(((rgb.astype(np.float32) - background_colour.astype(np.float32)) ** 2)
                       .sum(axis=2))
    # noisy background: a 3x3 median keeps edges and removes isolated noise pixels
    keyed = cv2.medianBlur(distance, 3) if spread > 6.0 else distance
    foreground = keyed > tolerance
    if not foreground.any():
        raise ValueError(f"image is uniform: no pixel differs from the background colour "
                         f"#%02x%02x%02x by more than the tolerance {tolerance:.0f}"
                         % tuple(int(round(c)) for c in background_colour))
    background = np.broadcast_to(background_colour.astype(np.float32), rgb.shape)
    return _Contrast(foreground=foreground, sharp=distance, threshold=float(tolerance),
                     background=background, colour=background_colour,
                     shadows=np.zeros(foreground.shape, bool))


def _field_contrast(rgb, tolerance) -> _Contrast:
    """A smooth light field fitted to the background (characters/image/light.py)."""
    from . import light
    segmentation = light.segment_by_field(rgb, threshold=tolerance)
    if tolerance is None and segmentation.field.noise > MAX_FIELD_NOISE:
        raise ValueError(f"the background is not plain: away from the character it varies by "
                         f"{segmentation.field.noise:.0f} (0..255 scale) around a smooth light "
                         f"(a scene, a textured surface, or a character filling the picture); "
                         f"photograph the character on a plain surface, give a picture with "
                         f"an alpha channel, or give a tolerance to cut at (tolerance=, "
                         f"--tolerance)")
    shadows, shaded = light.shadow_pixels(segmentation)
    return _Contrast(foreground=segmentation.foreground & ~shadows,
                     sharp=light.colour_distance(rgb.astype(np.float32),
                                                 segmentation.background),
                     threshold=segmentation.field.threshold,
                     background=segmentation.background,
                     colour=np.array(require_cv2().mean(segmentation.background)[:3]),
                     shadows=shadows,
                     weak=light.weak_foreground(segmentation) & ~shaded & ~shadows,
                     smoothed=segmentation.smoothed)


def _find_character(rgb, kind, *, plain, tolerance, close_gaps, max_hole_fraction,
                    min_character_fraction) -> _Found:
    """The character's mask on the analysed copy: what stands out from the background
    (plain key or light field); a drawing's outline filled, a solid character's holes
    filled except the background's, and with the light field its edge refined (GrabCut)."""
    from . import drawing, light
    contrast = _plain_contrast(rgb, tolerance) if plain else _field_contrast(rgb, tolerance)
    texture = None if contrast.smoothed is None else light.fine_texture(contrast.smoothed)
    main = largest_component(contrast.foreground)
    _character_check(main, min_character_fraction,
                     "give a picture where the character stands out from its background")
    found = dict(background_colour=contrast.colour, tolerance=contrast.threshold)
    # a drawing's edge is measured on the picture itself: the noise blur widens thin lines
    ink = drawing.stroke_edges(contrast.foreground, contrast.sharp, contrast.threshold)
    if kind is PictureKind.DRAWING or (kind is PictureKind.AUTO
                                       and drawing.is_line_drawing(
                                           main, ink, max_hole_fraction=max_hole_fraction)):
        filled = drawing.fill_outline(ink, gap_limit=close_gaps)
        # an open outline's puppet is its strokes, leaving out what is drawn inside
        textured = _textured_count(texture if filled.closed else None, filled.mask)
        # texture left out all round, where paper would be smooth: a textured photograph
        # (grass on grey of its mean) taken for strokes, which the photo's cut finds
        if kind is PictureKind.DRAWING or not _doubtful(textured, filled.mask):
            return _Found(mask=filled.mask, kind=PictureKind.DRAWING, drawing=filled,
                          textured=textured, **found)
    if plain:
        first = fill_holes(main, max_hole_fraction, contrast.sharp, 0.5 * contrast.threshold)
        return _Found(mask=first, kind=PictureKind.PLAIN, **found)
    # a part coloured almost like the backdrop, joined to what stands out, is the character's
    main = light.grow_into(main, contrast.weak)
    first = fill_holes(main, max_hole_fraction, contrast.sharp, 0.5 * contrast.threshold)
    # GrabCut's colour models see the picture with its noise smoothed, as the residual was
    # measured: a part a few levels off the backdrop is lost in single pixels' noise
    refined = light.refine_edge(contrast.smoothed, contrast.background, first,
                                sure_background=contrast.shadows)
    refined = largest_component(light.settle_edge(rgb, contrast.background,
                                                  largest_component(refined),
                                                  contrast.smoothed))
    mask = fill_holes(refined if refined.any() else first, max_hole_fraction, contrast.sharp,
                      0.5 * contrast.threshold)
    return _Found(mask=mask, kind=PictureKind.PHOTO, textured=_textured_count(texture, mask),
                  **found)


def _textured_count(texture, mask) -> int:
    """[px] the textured pixels a cut-out left out (0 without a light field's texture)."""
    from . import light
    return 0 if texture is None else int(light.textured_outside(texture, mask).sum())


def _doubtful(textured: int, mask: np.ndarray) -> bool:
    """A cut-out is doubtful when the textured pixels it left out are TEXTURED_SHARE of it."""
    return textured >= TEXTURED_SHARE * mask.sum()


def _textured_note(found: _Found) -> str:
    """What to tell a user whose cut-out left out much that is textured unlike the backdrop."""
    area = int(found.mask.sum())
    ratio = found.textured / max(area, 1)
    amount = f"{ratio:.1f} times" if ratio >= 1 else f"{100 * ratio:.0f}% of"
    return (f"the cut-out may be wrong: it is {100 * area / found.mask.size:.1f}% of the "
            f"picture, and away from its edge it left out parts textured unlike the backdrop "
            f"at the picture's border, {amount} its area: a character of the backdrop's colour "
            f"that differs from it only by its texture (grass, gravel, the moon on grey) is not "
            f"told apart by colour; photograph it on a backdrop of another colour, or give a "
            f"picture with an alpha channel")


def _open_outline_note(filled, scale: float) -> str:
    """What to tell a user whose drawing's outline stays open (in picture pixels)."""
    limit = filled.gap_limit / scale
    if len(filled.open_ends) >= 2:
        (x1, y1), (x2, y2) = filled.open_ends[:2] / scale
        gap = float(np.hypot(x2 - x1, y2 - y1))
        where = (f"its strokes end at ({x1:.0f}, {y1:.0f}) and ({x2:.0f}, {y2:.0f}), "
                 f"{gap:.0f} px apart")
        wider = gap + 1
    else:
        where = "its ink encloses nothing"
        wider = 2 * limit
    return (f"the drawing's outline is not closed: {where}, more than the {limit:.0f} px gap "
            f"closed automatically, so the puppet is the strokes alone; close the outline "
            f"with the pen, or close wider gaps (close_gaps={wider:.0f}, --close-gaps "
            f"{wider:.0f})")
