"""Pictures people actually bring, built for tests with a known true silhouette.

- `photo_on_background`: a real photograph cut to a silhouette, over a coloured background lit
  unevenly (a brightness gradient across the picture, a lamp on one side), with sensor noise,
  optionally a soft shadow cast on the background, then JPEG-compressed.
- `pen_drawing`: a closed pen outline (several shapes, any ink colour, any width) with details
  drawn inside, on paper with a vignette, noise and JPEG.
- Silhouettes with known limb tips for automatic pins: `star`, `stick_figure`.

Every function takes a numpy Generator and returns uint8 pictures and bool masks; nothing is
read from disk except the photographs themselves (`photo`).
"""
from __future__ import annotations

import io

import numpy as np

PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "motorcycle_left", "grace_hopper")
# the cut-out's numbers were chosen on these photographs and outline shapes only ...
TUNING_PHOTOS = ("rocket", "motorcycle_left", "grace_hopper")
TUNING_OUTLINES = ("blob", "star", "pear", "ghost")
# ... and are checked on these as well, which were not used for choosing
HELD_OUT_PHOTOS = ("astronaut", "coffee", "chelsea")
HELD_OUT_OUTLINES = ("bear", "fish")
# more photographs, of other kinds (greyscale, microscopy, textures), checked only
OTHER_PHOTOS = ("camera", "immunohistochemistry", "moon", "coins", "clock", "hubble_deep_field",
                "retina", "cell", "brick", "grass", "gravel")
INK_NAMES = ("black", "blue", "red", "green", "brown", "violet")
# greyscale textures: on a grey backdrop of their own mean only texture tells them apart
TEXTURES = ("moon", "grass", "gravel")


def photo(name: str) -> np.ndarray:
    """(H, W, 3) uint8: a real photograph shipped inside a package (scikit-image's data, or
    matplotlib's sample portrait)."""
    if name == "grace_hopper":
        from matplotlib import cbook
        from PIL import Image
        with Image.open(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False)) as opened:
            return np.asarray(opened.convert("RGB"))
    if name == "motorcycle_left":
        from skimage import data
        return np.ascontiguousarray(data.stereo_motorcycle()[0])
    from skimage import data
    picture = getattr(data, name)()
    if picture.ndim == 2:
        picture = np.repeat(picture[:, :, None], 3, axis=2)
    return np.ascontiguousarray(picture[:, :, :3]).astype(np.uint8)


def _cv2():
    import cv2
    return cv2


def jpeg(picture: np.ndarray, quality: int) -> np.ndarray:
    """The picture after a round trip through JPEG at this quality (Pillow, 4:2:0)."""
    from PIL import Image
    buffer = io.BytesIO()
    Image.fromarray(picture).save(buffer, format="JPEG", quality=int(quality))
    buffer.seek(0)
    with Image.open(buffer) as opened:
        return np.asarray(opened.convert("RGB"))


def _fill(points, height, width) -> np.ndarray:
    cv2 = _cv2()
    mask = np.zeros((height, width), np.uint8)
    cv2.fillPoly(mask, [np.round(points * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    return mask.astype(bool)


def blob(rng, height, width, *, lobes=5) -> np.ndarray:
    """Outline (K, 2) float [px] of a smooth random star-like shape (concave, with lobes)."""
    theta = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    radius = np.ones_like(theta)
    for k in range(2, lobes + 2):
        radius += rng.uniform(0.03, 0.14) * np.cos(k * theta + rng.uniform(0, 2 * np.pi))
    scale = rng.uniform(0.30, 0.40) * min(height, width) / radius.max()
    centre = np.array([width / 2, height / 2]) + rng.uniform(-0.05, 0.05, 2) * [width, height]
    return centre + scale * radius[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)


def creature(rng, height, width) -> np.ndarray:
    """(H, W) bool: a character-like silhouette: a body, a head and four limbs (ellipses)."""
    cv2 = _cv2()
    mask = np.zeros((height, width), np.uint8)
    size = min(height, width)
    centre = np.array([width / 2, height * 0.55]) + rng.uniform(-0.04, 0.04, 2) * size
    body = rng.uniform(0.14, 0.2, 2) * size
    cv2.ellipse(mask, tuple(np.round(centre).astype(int)), tuple(np.round(body).astype(int)),
                rng.uniform(-20, 20), 0, 360, 1, -1)
    head = centre - [rng.uniform(-0.05, 0.05) * size, body[1] + 0.08 * size]
    cv2.circle(mask, tuple(np.round(head).astype(int)), int(rng.uniform(0.09, 0.12) * size),
               1, -1)
    for angle in (rng.uniform(190, 230), rng.uniform(-50, -10), rng.uniform(100, 120),
                  rng.uniform(60, 80)):
        direction = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
        length = rng.uniform(0.16, 0.24) * size
        mid = centre + direction * (0.7 * max(body) + 0.5 * length)
        cv2.ellipse(mask, tuple(np.round(mid).astype(int)),
                    (int(length / 2), int(rng.uniform(0.03, 0.05) * size)), angle, 0, 360, 1, -1)
    return mask.astype(bool)


def backdrop_colour(rng) -> np.ndarray:
    """(3,) float: a background colour of any hue, from greys to saturated, not too dark."""
    import colorsys
    hue, saturation, value = rng.uniform(0, 1), rng.uniform(0.0, 0.9), rng.uniform(0.4, 0.95)
    return np.array(colorsys.hsv_to_rgb(hue, saturation, value)) * 255


def silhouettes(rng, height, width):
    """(name, (H, W) bool) for three kinds of silhouette: a creature, a blob, a star."""
    yield "creature", creature(rng, height, width)
    yield "blob", _fill(blob(rng, height, width), height, width)
    shape, _ = star(rng, min(height, width))
    canvas = np.zeros((height, width), bool)
    top, left = (height - shape.shape[0]) // 2, (width - shape.shape[1]) // 2
    canvas[top:top + shape.shape[0], left:left + shape.shape[1]] = shape
    yield "star", canvas


def lighting(rng, height, width, *, gradient: float) -> np.ndarray:
    """(H, W) float gain: brightness varying linearly by `gradient` (0.25 = 25 %) across the
    picture in a random direction, brightest on the lamp's side."""
    angle = rng.uniform(0, 2 * np.pi)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    along = np.cos(angle) * xs + np.sin(angle) * ys
    along = (along - along.min()) / (along.max() - along.min())
    return 1.0 - gradient * along


def photo_on_background(rng, picture: np.ndarray, mask: np.ndarray, *, colour, gradient=0.25,
                        noise=6.0, quality=75, shadow=0.0):
    """A photograph cut to `mask` over a background of `colour` lit by a gradient.

    The photograph is lit by the same lamp (multiplied by the gain). shadow > 0 casts a soft
    shadow of the silhouette on the background, that much darker, offset down and sideways.
    Returns (H, W, 3) uint8 JPEG-compressed at `quality` (None: no compression)."""
    cv2 = _cv2()
    height, width = mask.shape
    gain = lighting(rng, height, width, gradient=gradient)
    background = np.asarray(colour, np.float64)[None, None, :] * gain[:, :, None]
    if shadow > 0:
        size = min(height, width)
        offset = np.float32([[1, 0, 0.05 * size], [0, 1, 0.04 * size]])
        cast = cv2.warpAffine(mask.astype(np.float32), offset, (width, height))
        cast = cv2.GaussianBlur(cast, (0, 0), 0.02 * size)
        background *= 1.0 - shadow * cast[:, :, None]
    lit = picture.astype(np.float64) * gain[:, :, None]
    composite = np.where(mask[:, :, None], lit, background)
    composite += rng.normal(0.0, noise, composite.shape)
    composite = np.clip(np.round(composite), 0, 255).astype(np.uint8)
    return composite if quality is None else jpeg(composite, quality)


def texture_on_its_mean(rng, name: str):
    """(name of the silhouette, picture (H, W, 3) uint8, truth (H, W) bool) for each of the
    three silhouettes: a texture of TEXTURES cut to it over a grey backdrop of the texture's
    own mean, lit 25-50 % unevenly, noise and JPEG 65-80 as in the photo tests."""
    picture = photo(name)
    grey = np.full(3, picture.mean())
    for shape, truth in silhouettes(rng, *picture.shape[:2]):
        yield shape, photo_on_background(
            rng, picture, truth, colour=grey, gradient=rng.uniform(0.25, 0.5),
            noise=rng.uniform(3, 8), quality=int(rng.integers(65, 81))), truth


def shadow_case(rng, picture: np.ndarray, *, colour=(200, 190, 120)):
    """A photograph cut to a creature over a backdrop lit 30 % unevenly, casting a soft shadow
    40 % dark on it, JPEG at 75. Returns (picture (H, W, 3) uint8, truth (H, W) bool, shadow
    (H, W) bool: the backdrop darkened by at least 20 % by the shadow, away from the
    character (3 px out), which the cut-out must leave out)."""
    cv2 = _cv2()
    height, width = picture.shape[:2]
    truth = creature(rng, height, width)
    composite = photo_on_background(rng, picture, truth, colour=colour, gradient=0.3,
                                    shadow=0.4, quality=75)
    shaded = photo_on_background(rng, np.zeros_like(picture), truth, colour=(100, 100, 100),
                                 gradient=0.0, noise=0.0, shadow=0.4, quality=None)
    near = cv2.dilate(truth.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    return composite, truth, (shaded[:, :, 0] < 80) & ~near

# --- pen drawings on paper ----------------------------------------------------------------------

INKS = {"black": (25, 25, 30), "blue": (30, 50, 160), "red": (180, 30, 40),
        "green": (30, 120, 50), "brown": (110, 70, 40), "violet": (100, 40, 140)}


def paper(rng, height, width, *, vignette=0.3, noise=4.0) -> np.ndarray:
    """(H, W, 3) float: off-white paper, darker towards the corners by up to `vignette`, with a
    light fall-off from one side (a phone photo under a desk lamp)."""
    tint = np.array([rng.uniform(235, 252), rng.uniform(232, 250), rng.uniform(222, 245)])
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    centre = np.array([width, height]) * rng.uniform(0.4, 0.6, 2)
    radius = np.hypot((xs - centre[0]) / width, (ys - centre[1]) / height) / np.hypot(0.6, 0.6)
    gain = (1.0 - vignette * np.clip(radius, 0, 1) ** 2) * lighting(rng, height, width,
                                                                     gradient=0.1)
    return tint[None, None, :] * gain[:, :, None] + rng.normal(0, noise, (height, width, 3))


def pen_drawing(rng, height, width, *, outline, ink="black", line_width=3, quality=75,
                vignette=0.3, gap=0.0, details=True):
    """A pen outline (K, 2) [px] drawn on paper, with details inside (eyes, a mouth, buttons).

    gap > 0 leaves that many pixels of the outline undrawn (a pen lifted too early).
    Returns (picture (H, W, 3) uint8, truth (H, W) bool: the filled outline out to the
    stroke's outer edge, details (H, W) bool: the ink of the details)."""
    cv2 = _cv2()
    colour = np.asarray(INKS[ink], np.float64)
    ink_mask = np.zeros((height, width), np.uint8)
    points = np.round(outline * 16).astype(np.int32)
    if gap > 0:
        steps = np.linalg.norm(np.diff(outline, axis=0, append=outline[:1]), axis=1)
        along = np.cumsum(steps)
        start = rng.uniform(0, along[-1] - gap)
        keep = (along < start) | (along > start + gap)
        first = int(np.argmin(keep))
        points = np.roll(points, -first - int((~keep).sum()), axis=0)
        cv2.polylines(ink_mask, [points[:len(points) - int((~keep).sum())]], False, 255,
                      line_width, cv2.LINE_AA, 4)
    else:
        cv2.polylines(ink_mask, [points], True, 255, line_width, cv2.LINE_AA, 4)
    truth = _fill(outline, height, width)
    stroke = np.zeros((height, width), np.uint8)
    cv2.polylines(stroke, [points], True, 1, line_width, cv2.LINE_8, 4)
    truth |= stroke.astype(bool)
    detail_mask = np.zeros((height, width), np.uint8)
    if details:
        ys, xs = np.nonzero(truth)
        inside = cv2.distanceTransform(truth.astype(np.uint8), cv2.DIST_L2, 5)
        centre = np.array([xs.mean(), ys.mean()])
        room = max(6.0, float(inside.max()))
        for dx in (-0.35, 0.35):                       # eyes
            eye = centre + room * np.array([dx, -0.35])
            if inside[int(eye[1]), int(eye[0])] > 0.2 * room:
                cv2.circle(detail_mask, tuple(np.round(eye).astype(int)),
                           max(3, int(0.12 * room)), 255, line_width, cv2.LINE_AA)
        mouth = tuple(np.round(centre + room * np.array([0, 0.15])).astype(int))
        cv2.ellipse(detail_mask, mouth, (int(0.3 * room), int(0.12 * room)), 0, 20, 160, 255,
                    line_width, cv2.LINE_AA)
        for k in range(2):                             # buttons, filled
            button = centre + room * np.array([0, 0.5 + 0.25 * k])
            if inside[int(button[1]), int(button[0])] > 0.2 * room:
                cv2.circle(detail_mask, tuple(np.round(button).astype(int)),
                           max(2, int(0.05 * room)), 255, -1, cv2.LINE_AA)
    coverage = np.maximum(ink_mask, detail_mask).astype(np.float64)[:, :, None] / 255.0
    sheet = paper(rng, height, width, vignette=vignette)
    # ink absorbs: the paper's light multiplied by the ink's colour
    drawn = sheet * (1.0 - coverage + coverage * colour / 255.0)
    drawn = np.clip(np.round(drawn), 0, 255).astype(np.uint8)
    picture = drawn if quality is None else jpeg(drawn, quality)
    return picture, truth, detail_mask > 127


def outline_shape(rng, kind: str, height, width) -> np.ndarray:
    """(K, 2) float [px]: a closed outline of a drawn character: 'blob', 'pear' (a body with
    a head), 'star' (rounded points), 'ghost' (a wavy hem), 'bear' (a head with two ears) or
    'fish' (a body and a tail)."""
    size = min(height, width)
    if kind in ("bear", "fish"):
        return _union_outline(rng, kind, height, width)
    centre = np.array([width / 2, height / 2]) + rng.uniform(-0.04, 0.04, 2) * size
    theta = np.linspace(0, 2 * np.pi, 600, endpoint=False)
    if kind == "blob":
        return blob(rng, height, width)
    if kind == "star":
        points = int(rng.integers(5, 8))
        radius = 1.0 + 0.45 * np.cos(points * theta + rng.uniform(0, 2 * np.pi)) ** 3
        radius *= rng.uniform(0.27, 0.36) * size / radius.max()
    elif kind == "pear":
        radius = 1.0 - 0.35 * np.sin(theta) ** 8 * (np.sin(theta) < 0) + 0.1 * np.cos(2 * theta)
        radius *= rng.uniform(0.3, 0.38) * size / radius.max()
    elif kind == "ghost":
        radius = np.ones_like(theta)
        wave = 0.08 * np.cos(9 * theta) * (np.sin(theta) > 0)
        radius = (radius + wave) * rng.uniform(0.3, 0.38) * size / 1.1
        stretch = np.where(np.sin(theta) > 0, 1.25, 1.0)
        return centre + radius[:, None] * np.stack([np.cos(theta), stretch * np.sin(theta)], 1)
    else:
        raise ValueError(kind)
    return centre + radius[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)


def _union_outline(rng, kind, height, width) -> np.ndarray:
    """The outer contour of a union of discs and ellipses (a bear's head, a fish)."""
    cv2 = _cv2()
    size = min(height, width)
    mask = np.zeros((height, width), np.uint8)
    centre = np.array([width / 2, height / 2]) + rng.uniform(-0.04, 0.04, 2) * size
    point = lambda p: tuple(int(round(v)) for v in p)   # noqa: E731
    if kind == "bear":
        radius = rng.uniform(0.24, 0.3) * size
        cv2.circle(mask, point(centre), int(radius), 1, -1)
        for side in (-1, 1):
            ear = centre + radius * np.array([side * 0.75, -0.75])
            cv2.circle(mask, point(ear), int(radius * rng.uniform(0.3, 0.4)), 1, -1)
    else:
        body = (int(rng.uniform(0.25, 0.3) * size), int(rng.uniform(0.14, 0.18) * size))
        cv2.ellipse(mask, point(centre), body, 0, 0, 360, 1, -1)
        tail = centre + [body[0] * 0.95, 0]
        fin = np.array([tail, tail + [0.15 * size, -0.13 * size],
                        tail + [0.15 * size, 0.13 * size]])
        cv2.fillPoly(mask, [np.round(fin).astype(np.int32)], 1)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(contours, key=len).reshape(-1, 2).astype(np.float64)


# --- silhouettes with known limb tips -------------------------------------------------------

def star(rng, size=400, points=5):
    """(mask (size, size) bool, tips (points, 2) float [px]): a star with sharp tips."""
    centre = np.array([size / 2, size / 2]) + rng.uniform(-0.04, 0.04, 2) * size
    start = rng.uniform(0, 2 * np.pi)
    outer, inner = rng.uniform(0.36, 0.42) * size, rng.uniform(0.14, 0.2) * size
    angles = start + np.arange(2 * points) * np.pi / points
    radii = np.where(np.arange(2 * points) % 2 == 0, outer, inner)
    polygon = centre + radii[:, None] * np.stack([np.cos(angles), np.sin(angles)], 1)
    return _fill(polygon, size, size), polygon[::2]


def stick_figure(rng, size=400, thickness=None):
    """(mask, tips (5, 2) [px]: head top, two hands, two feet): a thick stick figure."""
    cv2 = _cv2()
    t = int(thickness or rng.uniform(0.04, 0.07) * size)
    mask = np.zeros((size, size), np.uint8)
    neck = np.array([size * 0.5, size * 0.3]) + rng.uniform(-0.03, 0.03, 2) * size
    hip = neck + [rng.uniform(-0.03, 0.03) * size, 0.28 * size]
    head_r = rng.uniform(0.07, 0.09) * size
    head = neck - [0, head_r]
    hands = [neck + [-0.3 * size, rng.uniform(-0.05, 0.15) * size],
             neck + [0.3 * size, rng.uniform(-0.15, 0.05) * size]]
    feet = [hip + [-0.17 * size, 0.28 * size], hip + [0.15 * size, 0.29 * size]]
    point = lambda p: tuple(int(round(v)) for v in p)   # noqa: E731
    cv2.circle(mask, point(head), int(head_r), 1, -1)
    cv2.line(mask, point(neck), point(hip), 1, t)
    for end in hands:
        cv2.line(mask, point(neck + [0, 0.04 * size]), point(end), 1, t)
    for end in feet:
        cv2.line(mask, point(hip), point(end), 1, t)
    tips = [head - [0, head_r]]
    for end, start in ((hands[0], neck), (hands[1], neck), (feet[0], hip), (feet[1], hip)):
        direction = (end - start) / np.linalg.norm(end - start)
        tips.append(end + direction * t / 2)
    return mask.astype(bool), np.array(tips)


# scikit-image's horse silhouette (328x400): the tips of its limbs, read off the picture as
# the lowest point of each hoof, the lowest point of the tail, the front of the muzzle
HORSE_TIPS = np.array([(65, 311), (125.5, 304), (256.5, 309), (280.5, 312),   # hooves
                       (31, 251), (388, 86)])                                 # tail, muzzle


def horse() -> np.ndarray:
    """(328, 400) bool: scikit-image's horse silhouette (the horse True)."""
    from skimage import data
    return ~data.horse().astype(bool)


def worst_tip(pins, mask, tips) -> float:
    """The largest distance from a known limb tip (K, 2) [px] to its nearest driven pin of
    `pins` (ProposedPin list), as a fraction of the figure's size."""
    ys, xs = np.nonzero(mask)
    size = float(max(np.ptp(xs), np.ptp(ys)) + 1)
    driven = np.array([pin.xy for pin in pins if not pin.fixed])
    distance = np.linalg.norm(np.asarray(tips)[:, None] - driven[None], axis=2).min(axis=1)
    return float(distance.max() / size)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))
