"""Automatic pins from a silhouette's skeleton: a pin at the end of every limb and an anchor in
the body, with neither a hand-placed pin (Animatron) nor a pose-estimation model
(AnimatedDrawings).

The silhouette is thinned to its one-pixel skeleton (Zhang-Suen, on a copy at most
SKELETON_SIZE px). Branches that end in a free end are limbs unless they are spurs: a branch
whose end's inscribed disc reaches less than SPUR_REACH of the figure's size beyond the disc
inscribed at its junction is a bump of the outline, and is pruned (repeatedly, since pruning a
spur can merge two branches). Each remaining end is a limb tip: its pin sits at the
silhouette's extreme point: the point farthest from the branch's start within the branch's
outermost disc (the top of a head on a neck), or where the ray along the branch's last stretch
leaves the silhouette (the tip of an arm), a little inside the edge. The anchor is the
skeleton's centre (the point whose farthest limb tip is nearest, through the skeleton), where
the body is.

Names say where a pin is, seen from the anchor: `top`, `bottom`, `left`, `right` by the
direction the limb points in (y down), numbered `_1`, `_2`, ... when a side has several
(left to right for top and bottom, top to bottom for left and right); the anchor is `body`.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .background import require_cv2

SKELETON_SIZE = 192      # [px] the skeleton is found on a copy of the mask at most this big
SPUR_REACH = 0.04        # branches reaching less than this x size past their junction's disc
MAX_LIMBS = 10           # at most this many limb pins, the farthest-reaching first
TIP_INSET = 0.01         # [x size] a tip's pin sits this far inside the silhouette's edge


@dataclass(frozen=True)
class ProposedPin:
    """name : str; xy : (2,) float [px] in the mask's pixels; fixed : bool (the anchor);
    reach : float [px]: how far the limb reaches beyond the body's inscribed circle (0 for the
    anchor)."""

    name: str
    xy: tuple[float, float]
    fixed: bool
    reach: float


# the 16 pixels of the square ring two pixels out, in order around it
_RING = ([(-2, c) for c in range(-2, 3)] + [(r, 2) for r in range(-1, 3)]
         + [(2, c) for c in range(1, -3, -1)] + [(r, -2) for r in range(1, -2, -1)])
_STEPS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def _branch_counts(skeleton: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(neighbours, branches), both (H, W) int, 0 off the skeleton: how many skeleton pixels
    touch each skeleton pixel (1 at a free end), and how many branches pass two pixels out:
    separate runs of skeleton pixels on the ring around it (2 along a line, staircases and
    all; 3 or more at a junction, however the thinning drew the crossing)."""
    height, width = skeleton.shape
    padded = np.pad(skeleton, 2)
    near = sum(padded[2 + dr:2 + dr + height, 2 + dc:2 + dc + width].astype(np.int16)
               for dr, dc in _STEPS)
    ring = [padded[2 + dr:2 + dr + height, 2 + dc:2 + dc + width] for dr, dc in _RING]
    runs = sum((~ring[k] & ring[(k + 1) % len(ring)]).astype(np.int16)
               for k in range(len(ring)))
    return np.where(skeleton, near, 0), np.where(skeleton, runs, 0)


def _walk(pixels: set, sources: list) -> dict:
    """{pixel: steps}: breadth-first distances through 8-connected pixels from sources."""
    distance = {source: 0 for source in sources}
    queue = deque(sources)
    while queue:
        row, col = queue.popleft()
        for dr, dc in _STEPS:
            step = (row + dr, col + dc)
            if step in pixels and step not in distance:
                distance[step] = distance[(row, col)] + 1
                queue.append(step)
    return distance


def _leaves(skeleton: np.ndarray, inside: np.ndarray) -> list:
    """The skeleton's free branches: [(path, reach [px], joined)] where path is the (row,
    col) pixels of a branch from its free end to where it meets a junction (its last pixel:
    the junction's thickest pixel), reach how far the branch's inscribed discs reach past the
    junction's disc, joined whether it meets one. Junctions are the pixels where three
    branches or more pass two pixels out (clusters of them: thinning draws a crossing as a
    little knot); branches are what lies between."""
    cv2 = require_cv2()
    _, runs = _branch_counts(skeleton)
    junction = skeleton & (runs >= 3)
    _, cluster_of = cv2.connectedComponents(junction.astype(np.uint8), connectivity=8)
    count, segment_of = cv2.connectedComponents((skeleton & ~junction).astype(np.uint8),
                                                connectivity=8)
    leaves = []
    for label in range(1, count):
        rows, cols = np.nonzero(segment_of == label)
        pixels = set(zip(rows.tolist(), cols.tolist()))
        around = cluster_of[np.clip(rows[:, None] + np.array([-1, -1, -1, 0, 0, 1, 1, 1]), 0,
                                    skeleton.shape[0] - 1),
                            np.clip(cols[:, None] + np.array([-1, 0, 1, -1, 1, -1, 0, 1]), 0,
                                    skeleton.shape[1] - 1)]
        met = set(np.unique(around).tolist()) - {0}
        if len(met) > 1:
            continue                                # between two junctions: not a limb
        if met:
            knot = met.pop()
            base = [(int(r), int(c)) for r, c, row in zip(rows, cols, around)
                    if knot in row]
            knot_rows, knot_cols = np.nonzero(cluster_of == knot)
            best = int(np.argmax(inside[knot_rows, knot_cols]))
            centre = (int(knot_rows[best]), int(knot_cols[best]))
            if len(_walk(set(base), base[:1])) < len(base):
                continue                            # a loop back into its junction
            steps = _walk(pixels, base)
            radius_there = float(inside[centre])
        else:
            leaves += _stroke_ends(pixels, inside)
            continue
        path = sorted(steps, key=steps.get, reverse=True) + [centre]
        _, outermost = _outermost(path, inside)
        leaves.append((path, outermost - radius_there, True))
    return leaves


def _stroke_ends(pixels: set, inside: np.ndarray) -> list:
    """A skeleton without junctions (an oval, a bean): its two ends as branches from its
    thickest pixel, reach measured past the disc inscribed there (a disc has none)."""
    far = _walk(pixels, [next(iter(pixels))])
    along = _walk(pixels, [max(far, key=far.get)])
    centre = max(pixels, key=lambda p: inside[p])
    middle = along[centre]
    leaves = []
    for side in (lambda d: d <= middle, lambda d: d >= middle):
        half = sorted((p for p in along if side(along[p])),
                      key=lambda p: abs(along[p] - middle), reverse=True)
        if len(half) > 1:
            _, outermost = _outermost(half, inside)
            leaves.append((half, outermost - float(inside[centre]), False))
    return leaves


def _thin(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the one-pixel skeleton of a mask (Guo-Hall thinning: it keeps pointed
    protrusions, a horse's muzzle, that Zhang-Suen erodes away depending on their side)."""
    cv2 = require_cv2()
    return cv2.ximgproc.thinning(mask.astype(np.uint8) * 255,
                                 thinningType=cv2.ximgproc.THINNING_GUOHALL) > 0


def limb_branches(mask: np.ndarray):
    """Skeleton of a mask with its spurs pruned.

    mask : (H, W) bool, one piece. Returns (skeleton (H, W) bool, inside (H, W) float32
    [px]: distance to the edge, branches: list of (tip (row, col), path list from the tip to
    its junction, reach [px]))."""
    cv2 = require_cv2()
    inside = cv2.distanceTransform(np.pad(mask.astype(np.uint8), 1), cv2.DIST_L2,
                                   cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    skeleton = _thin(mask)
    ys, xs = np.nonzero(mask)
    size = float(max(xs.max() - xs.min(), ys.max() - ys.min()) + 1)
    while True:
        leaves = _leaves(skeleton, inside)
        spurs = [leaf for leaf in leaves if leaf[2] and leaf[1] < SPUR_REACH * size]
        if not spurs:
            break
        # prune the shortest spur first: two spurs of one fork would otherwise both go, and
        # the other may then be the end of a limb
        path, _, _ = min(spurs, key=lambda leaf: leaf[1])
        for pixel in path[:-1]:
            skeleton[pixel] = False
    return skeleton, inside, [(path[0], path, max(reach, 0.0)) for path, reach, _ in leaves]


def _outermost(path: list, inside: np.ndarray) -> tuple[tuple[int, int], float]:
    """The branch pixel whose inscribed disc reaches farthest from the branch's start
    (path[-1]), among those outside the start's own disc, and how far [px]."""
    pixels = np.array(path, float)
    radii = inside[tuple(np.array(path).T)]
    away = np.hypot(*(pixels - pixels[-1]).T)
    reach = np.where(away >= radii[-1], away + radii, -1.0)
    best = int(np.argmax(reach)) if reach.max() > 0 else 0
    return path[best], float(away[best] + radii[best])


def _centre(skeleton: np.ndarray, inside: np.ndarray, tips: list) -> tuple[int, int]:
    """The skeleton pixel whose farthest tip, through the skeleton, is nearest (ties: the
    thickest); the thickest skeleton pixel when there are no tips."""
    if not tips:
        rows, cols = np.nonzero(skeleton)
        best = int(np.argmax(inside[rows, cols]))
        return int(rows[best]), int(cols[best])
    height, width = skeleton.shape
    farthest = np.zeros(skeleton.shape, np.int32)
    for tip in tips:
        distance = np.full(skeleton.shape, -1, np.int32)
        distance[tip] = 0
        queue = deque([tip])
        while queue:
            row, col = queue.popleft()
            for dr, dc in _STEPS:
                r, c = row + dr, col + dc
                if 0 <= r < height and 0 <= c < width and skeleton[r, c] and distance[r, c] < 0:
                    distance[r, c] = distance[row, col] + 1
                    queue.append((r, c))
        farthest = np.maximum(farthest, np.where(distance < 0, 1 << 30, distance))
    rows, cols = np.nonzero(skeleton)
    score = farthest[rows, cols] - 1e-3 * inside[rows, cols]
    best = int(np.argmin(score))
    return int(rows[best]), int(cols[best])


def _tip_point(mask: np.ndarray, inside: np.ndarray, path: list, body: tuple[int, int],
               scale: float, size: float) -> np.ndarray:
    """(x, y) [px of the full picture]: the limb's extreme point, moved back inside by
    TIP_INSET x size (a pin holds picture, not the edge). Of two candidates, the one farther
    from the body (the anchor, `body` (row, col)): the silhouette's point farthest from the
    body within the branch's outermost inscribed disc (the top of a head on a neck), and
    where the ray along the branch's last stretch leaves the silhouette (thinning stops
    short of a blunt end)."""
    start = np.array(body, float)
    outer, _ = _outermost(path, inside)
    centre = np.array(outer, float)
    radius = inside[outer] + 1.5
    low = np.maximum(np.floor(centre - radius).astype(int), 0)
    high = np.minimum(np.ceil(centre + radius).astype(int) + 1, mask.shape)
    rows, cols = np.nonzero(mask[low[0]:high[0], low[1]:high[1]])
    near = np.stack([rows + low[0], cols + low[1]], axis=1).astype(float)
    near = near[np.hypot(*(near - centre).T) <= radius]
    candidates = [near[np.argmax(np.hypot(*(near - start).T))]] if len(near) else [centre]
    end = np.array(path[0], float)
    back = np.array(path[min(len(path) - 1, max(4, int(inside[path[0]]) + 2))], float)
    direction = end - back
    if np.hypot(*direction) > 0:
        direction /= np.hypot(*direction)
        point = end.copy()
        while True:
            row, col = np.round(point + 0.5 * direction).astype(int)
            if not (0 <= row < mask.shape[0] and 0 <= col < mask.shape[1] and mask[row, col]):
                break
            point = point + 0.5 * direction
        candidates.append(point)
    tip = max(candidates, key=lambda c: np.hypot(*(c - start)))
    towards = centre - tip
    distance = np.hypot(*towards)
    if distance > 0:
        tip = tip + towards / distance * min(TIP_INSET * size * scale, distance)
    return (tip[::-1] + 0.5) / scale - 0.5


def propose_pins(mask: np.ndarray) -> list[ProposedPin]:
    """Pins for a silhouette: one at each limb's tip (driven), one anchor in the body (fixed).

    mask : (H, W) bool, the character (one piece). Returns the anchor first, then the limbs
    by name. Positions are in the mask's pixels (x = column, y = row)."""
    cv2 = require_cv2()
    height, width = mask.shape
    scale = min(1.0, SKELETON_SIZE / max(height, width))
    small = mask
    if scale < 1.0:
        size = (max(1, round(width * scale)), max(1, round(height * scale)))
        small = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
        scale = size[0] / width
    from .background import largest_component
    small = largest_component(small)
    if not small.any():
        raise ValueError("the character is too small to find its limbs")
    skeleton, inside, branches = limb_branches(small)
    ys, xs = np.nonzero(mask)
    size = float(max(xs.max() - xs.min(), ys.max() - ys.min()) + 1)
    branches = sorted((b for b in branches if b[2] >= SPUR_REACH * size * scale),
                      key=lambda b: -b[2])[:MAX_LIMBS]
    centre = _centre(skeleton, inside, [b[0] for b in branches])
    anchor = (np.array(centre[::-1], float) + 0.5) / scale - 0.5
    limbs = [(_tip_point(small, inside, path, centre, scale, size), reach / scale)
             for _, path, reach in branches]
    pins = [ProposedPin(name="body", xy=(float(anchor[0]), float(anchor[1])), fixed=True,
                        reach=0.0)]
    return pins + _named(limbs, anchor)


def _named(limbs: list, anchor: np.ndarray) -> list[ProposedPin]:
    """Limb pins named by the side they point to from the anchor, numbered along the side."""
    sides: dict[str, list] = {"top": [], "bottom": [], "left": [], "right": []}
    for xy, reach in limbs:
        dx, dy = xy - anchor
        if abs(dy) >= abs(dx):
            sides["top" if dy < 0 else "bottom"].append((xy, reach))
        else:
            sides["left" if dx < 0 else "right"].append((xy, reach))
    named = []
    for side, members in sides.items():
        along = 0 if side in ("top", "bottom") else 1
        members.sort(key=lambda m: m[0][along])
        for number, (xy, reach) in enumerate(members, start=1):
            name = side if len(members) == 1 else f"{side}_{number}"
            named.append(ProposedPin(name=name, xy=(float(xy[0]), float(xy[1])), fixed=False,
                                     reach=float(reach)))
    return named
