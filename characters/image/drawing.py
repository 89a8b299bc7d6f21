"""Line drawings: a pen outline on paper becomes a filled silhouette.

What the background leaves of a drawing is ink: thin strokes. The stroke's edge is put where
the ink's contrast is half way between paper and ink (a threshold at half the local peak),
which is where the pen's line ends whatever its colour and width. Gaps in the outline up to
`gap_limit` px (a pen lifted a moment early; by default three stroke widths) are closed: the
ink is grown until its ends meet across the gaps (by at most half the limit), what that
encloses is filled, and the fill is shrunk back to the ink's outer edge. Everything the
outline encloses (the paper inside, and the eyes and buttons drawn there) is the character.

An outline that stays open (a gap wider than the limit) encloses nothing: the strokes alone are
the character, as drawn (a line puppet), and the result names the open ends so the user can
close them with the pen or ask for a wider gap limit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .background import fill_enclosed, fill_holes, largest_component, require_cv2

HALF_PEAK_WINDOW = 7     # [px] the ink's local peak contrast is taken over this square
GAP_WIDTHS = 3.0         # gaps up to this many stroke widths are closed ...
GAP_FLOOR = 4.0          # ... and always gaps up to this many pixels
THIN_FRACTION = 0.05     # strokes thinner than this fraction of the figure make a drawing
OUTLINE_FRACTION = 0.1   # so does an outline of ink thinner than this, enclosing paper
ENCLOSED_PAPER = 0.15    # an outline encloses paper when it holds this share of its ink


def stroke_edges(foreground: np.ndarray, residual: np.ndarray, threshold: float) -> np.ndarray:
    """(H, W) bool: the ink out to half of its local peak contrast.

    foreground : (H, W) bool, residual : (H, W) float [0..255]: distance to the background;
    threshold : [0..255], the background's own noise threshold (a floor)."""
    cv2 = require_cv2()
    square = np.ones((HALF_PEAK_WINDOW, HALF_PEAK_WINDOW), np.uint8)
    peak = cv2.dilate(residual.astype(np.float32), square)
    return foreground & (residual > np.maximum(threshold, 0.5 * peak))


def stroke_width(mask: np.ndarray) -> float:
    """[px] the mean width of a mask's strokes: twice its area over its perimeter (outer and
    hole contours). A stroke of width w and length L has area w L and perimeter about 2 L; a
    solid figure's width measured so is about half its size."""
    cv2 = require_cv2()
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    perimeter = sum(cv2.arcLength(contour, True) for contour in contours)
    if perimeter <= 0:
        return 0.0
    return float(2.0 * mask.sum() / perimeter)


def figure_size(mask: np.ndarray) -> float:
    """[px] the longer side of the mask's bounding box."""
    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return 0.0
    return float(max(xs.max() - xs.min(), ys.max() - ys.min()) + 1)


def is_line_drawing(mask: np.ndarray, ink: np.ndarray | None = None, *,
                    max_hole_fraction: float = 0.0) -> bool:
    """A figure drawn in lines (a pen drawing) rather than a solid shape (a photographed
    object, a coloured-in cartoon): what stands out is strokes thinner than THIN_FRACTION of
    the figure's size; or it is an outline: ink, out to its real edge, thinner than
    OUTLINE_FRACTION of the figure, enclosing paper of at least ENCLOSED_PAPER of its area (a
    small figure drawn with a thick pen). A photographed object encloses little background
    (at most 5 % of its area in the tuning pictures); a cartoon's white eyes do, but it is
    solid colour, as wide as the figure.

    mask : (H, W) bool, what stands out (one piece); ink : (H, W) bool, the strokes out to
    their real edge (`stroke_edges`); max_hole_fraction: the mask's holes smaller than this
    fraction of its area do not count as its edge (the speckle of a textured photograph
    would make it look thin; the paper inside an outline is much larger)."""
    size = figure_size(mask)
    if size == 0:
        return False
    if stroke_width(fill_holes(mask, max_hole_fraction)) < THIN_FRACTION * size:
        return True
    if ink is None:
        return False
    strokes = ink & mask
    enclosed = int((fill_enclosed(mask) & ~mask).sum())
    return (stroke_width(strokes) < OUTLINE_FRACTION * size
            and enclosed >= ENCLOSED_PAPER * int(strokes.sum()))


@dataclass(frozen=True)
class FilledDrawing:
    """mask : (H, W) bool, the character; closed : bool, whether the outline enclosed
    anything; gap_limit : float [px], the widest gap that was closed; stroke_width : [px];
    open_ends : (E, 2) float [px] (x, y): where an open outline's strokes end (empty if
    closed), nearest pair first."""

    mask: np.ndarray
    closed: bool
    gap_limit: float
    stroke_width: float
    open_ends: np.ndarray


def fill_outline(ink: np.ndarray, *, gap_limit: float | None = None) -> FilledDrawing:
    """The character a drawing's ink outlines.

    ink : (H, W) bool, the strokes (several pieces: an outline and details inside it);
    gap_limit : [px] the widest gap in the outline to close (default: GAP_WIDTHS stroke
    widths, at least GAP_FLOOR px). The result is the largest piece of ink, gaps closed, with
    everything it encloses; if it encloses nothing (an open outline), that piece of ink."""
    cv2 = require_cv2()
    main = largest_component(ink)
    width = max(1.0, stroke_width(main))
    if gap_limit is None:
        gap_limit = max(GAP_FLOOR, GAP_WIDTHS * width)
    # the smallest growth that closes the outline (a large one would fill a narrow inside
    # with ink before it could enclose anything); closed means enclosing paper of at least
    # ENCLOSED_PAPER of the ink's area, not a speck inside a stroke
    largest_radius = max(1, int(np.ceil(gap_limit / 2.0)))
    least = ENCLOSED_PAPER * main.sum()
    radius = 1
    while True:
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        grown = largest_component(cv2.dilate(ink.astype(np.uint8), disc) > 0)
        filled = fill_enclosed(grown)
        closed = (filled & ~grown).sum() >= least
        if closed or radius == largest_radius:
            break
        radius = min(2 * radius, largest_radius)
    if not closed:
        return FilledDrawing(mask=main, closed=False, gap_limit=float(gap_limit),
                             stroke_width=width,
                             open_ends=stroke_ends(main, apart=gap_limit))
    shape = cv2.erode(filled.astype(np.uint8), disc) > 0
    mask = largest_component(shape & ~_corner_slivers(shape, ink, radius))
    return FilledDrawing(mask=fill_enclosed(mask), closed=True, gap_limit=float(gap_limit),
                         stroke_width=width, open_ends=np.zeros((0, 2)))


def _corner_slivers(shape: np.ndarray, ink: np.ndarray, radius: int) -> np.ndarray:
    """(H, W) bool: paper that growing and shrinking by `radius` added in the outline's
    concave corners: pieces of `shape` outside the ink that touch the shape's edge and are
    smaller than the rounding's scale, (2 radius)^2. The paper inside the outline touches
    the edge only across a closed gap, and is larger."""
    cv2 = require_cv2()
    paper = shape & ~ink
    count, labels, stats, _ = cv2.connectedComponentsWithStats(paper.astype(np.uint8),
                                                               connectivity=4)
    edge = shape & ~(cv2.erode(shape.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
    touching = np.zeros(count, bool)
    touching[np.unique(labels[edge & paper])] = True
    sliver = touching & (stats[:, cv2.CC_STAT_AREA] < (2 * radius) ** 2)
    sliver[0] = False
    return sliver[labels]


def stroke_ends(ink: np.ndarray, *, apart: float = 0.0) -> np.ndarray:
    """(E, 2) float [px] (x, y): the free ends of a drawing's strokes (skeleton pixels with one
    neighbour), first the two nearest to each other that are more than `apart` px apart
    (where an outline most likely failed to close)."""
    cv2 = require_cv2()
    ridge = (cv2.ximgproc.thinning(ink.astype(np.uint8) * 255) > 0).astype(np.uint8)
    neighbours = cv2.filter2D(ridge, cv2.CV_16S, np.ones((3, 3), np.float32),
                              borderType=cv2.BORDER_CONSTANT) - ridge
    ys, xs = np.nonzero((ridge > 0) & (neighbours == 1))
    ends = np.stack([xs, ys], axis=1).astype(np.float64)
    if len(ends) < 2:
        return ends
    distance = np.linalg.norm(ends[:, None] - ends[None], axis=2)
    distance[distance <= apart] = np.inf
    if not np.isfinite(distance).any():
        return ends
    first, second = np.unravel_index(int(np.argmin(distance)), distance.shape)
    order = [first, second] + [i for i in range(len(ends)) if i not in (first, second)]
    return ends[order]
