"""Character mask -> regular grid triangle mesh (Animatron's triangulation).

A regular grid of points covers the character's bounding box. A grid cell is kept when its four
corners are inside the character's contour (even-odd rule over the outer contour and the holes)
or when it holds a contour point, so border cells cover the whole silhouette while little
background is meshed. The contour polygon runs through boundary pixel centres and cuts diagonal
steps, so a grid corner in such a sliver fails the even-odd test although its cell holds
character pixels and no contour point; as a safety net a cell holding any character pixel is
kept too (this adds a few cells, 0-8 on the sample character at 25 size/cell combinations).
Each kept cell gives two triangles (the split diagonal alternates like a checkerboard, so the
mesh has no preferred shear direction) and six springs: its four sides and both diagonals.

Coordinates: pixel centres are at integer (x = column, y = row); the rest mesh is in those
picture pixels. Triangles are ordered so that their signed area
0.5 ((x1 - x0)(y2 - y0) - (x2 - x0)(y1 - y0)) is positive (clockwise on screen, y down).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .background import require_cv2

MAX_CELLS = 60_000   # beyond this the simulation is no longer interactive: ask for a coarser grid


@njit(cache=True, nogil=True)
def even_odd_inside(points, polygon_xy, polygon_starts, out):
    """Even-odd rule: out[p] = a ray from points[p] towards +x crosses the polygons an odd
    number of times.

    points : (P, 2) float [px]; polygon_xy : (V, 2) float [px], all polygons concatenated;
    polygon_starts : (R + 1,) int, polygon r is polygon_xy[starts[r]:starts[r + 1]] (closed
    implicitly); out : (P,) bool, written.
    """
    for p in range(points.shape[0]):
        px = points[p, 0]
        py = points[p, 1]
        inside = False
        for r in range(polygon_starts.shape[0] - 1):
            begin = polygon_starts[r]
            end = polygon_starts[r + 1]
            j = end - 1
            for i in range(begin, end):
                yi = polygon_xy[i, 1]
                yj = polygon_xy[j, 1]
                if (yi > py) != (yj > py):
                    xi = polygon_xy[i, 0]
                    xj = polygon_xy[j, 0]
                    crossing = xj + (py - yj) * (xi - xj) / (yi - yj)
                    if px < crossing:
                        inside = not inside
                j = i
        out[p] = inside


def signed_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(F,) float [px^2]: signed triangle areas, positive for the rest orientation.

    vertices : (N, 2) float [px]; triangles : (F, 3) int."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                  - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def character_contours(mask: np.ndarray) -> list[np.ndarray]:
    """Outer contour first, then hole contours: each (K, 2) float [px] through boundary pixel
    centres. mask : (H, W) bool, one connected component."""
    cv2 = require_cv2()
    contours, hierarchy = cv2.findContours(mask.astype(np.uint8), cv2.RETR_CCOMP,
                                           cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise ValueError("the character mask is empty: nothing to mesh")
    contours = [c.reshape(-1, 2).astype(np.float64) for c in contours]
    outer = [i for i in range(len(contours)) if hierarchy[0, i, 3] < 0]
    outer.sort(key=lambda i: -len(contours[i]))
    ordered = [contours[outer[0]]] + [c for i, c in enumerate(contours) if i != outer[0]]
    return ordered


@dataclass(frozen=True)
class GridMesh:
    """A regular-grid triangle mesh of a character.

    vertices : (N, 2) float [px] rest positions; triangles : (F, 3) int; springs : (M, 2) int
    (four sides and both diagonals of every kept cell, each once).
    origin : (2,) float [px]; cell_size : float [px]; kept : (rows, cols) bool, cell (r, c)
    spanning origin + cell_size * ([c, c + 1], [r, r + 1]);
    corner_index : (rows + 1, cols + 1) int, vertex index of each grid point or -1;
    contours : list of (K, 2) float [px], outer contour first.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    springs: np.ndarray
    origin: np.ndarray
    cell_size: float
    kept: np.ndarray
    corner_index: np.ndarray
    contours: list

    def cells_of(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: whether each point (P, 2) [px] lies in a kept cell (on the mesh)."""
        cell = np.floor((np.asarray(points, float) - self.origin) / self.cell_size).astype(int)
        rows, cols = self.kept.shape
        valid = (cell[:, 0] >= 0) & (cell[:, 0] < cols) & (cell[:, 1] >= 0) & (cell[:, 1] < rows)
        inside = np.zeros(len(cell), dtype=bool)
        inside[valid] = self.kept[cell[valid, 1], cell[valid, 0]]
        return inside


def build_grid_mesh(mask: np.ndarray, cell_size: float, *, margin: int = 0) -> GridMesh:
    """Triangulate a character mask on a regular grid.

    mask : (H, W) bool (one connected component); cell_size : float [px] grid spacing;
    margin : int [px]: cells holding a pixel within this many pixels (chessboard distance) of
    the character are kept too. A picture's alpha reaches past its mask's pixel centres (a
    pixel is a square, and bilinear sampling reads one more texel), so a margin of 1 keeps
    all of a feathered edge on the mesh, and 2 when the mask was downscaled for meshing;
    without it, a deformed mesh would cut the edge along its cells.
    """
    if not np.isfinite(cell_size) or cell_size < 2.0:
        raise ValueError(f"cell_size must be at least 2 pixels (of the meshed picture), got "
                         f"{cell_size}")
    contours = character_contours(mask)
    if margin > 0:
        cv2 = require_cv2()
        square = np.ones((2 * margin + 1, 2 * margin + 1), np.uint8)
        ys, xs = np.nonzero(cv2.dilate(mask.astype(np.uint8), square))
    else:
        ys, xs = np.nonzero(mask)
    low = np.array([xs.min(), ys.min()], dtype=np.float64)
    span = np.array([xs.max(), ys.max()], dtype=np.float64) - low
    counts = np.floor(span / cell_size).astype(int) + 1          # cells along x, y
    if counts[0] * counts[1] > MAX_CELLS:
        raise ValueError(f"cell_size {cell_size:g} px gives a {counts[0]}x{counts[1]} grid "
                         f"(more than {MAX_CELLS} cells); use a larger cell_size")
    # centre the grid on the character so every pixel centre is strictly inside it
    origin = low - (counts * cell_size - span) / 2.0
    cols, rows = int(counts[0]), int(counts[1])

    gx = origin[0] + cell_size * np.arange(cols + 1)
    gy = origin[1] + cell_size * np.arange(rows + 1)
    grid = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)
    polygon_xy = np.ascontiguousarray(np.concatenate(contours))
    starts = np.cumsum([0] + [len(c) for c in contours]).astype(np.int64)
    corner_inside = np.zeros(len(grid), dtype=bool)
    even_odd_inside(grid, polygon_xy, starts, corner_inside)
    corner_inside = corner_inside.reshape(rows + 1, cols + 1)

    kept = (corner_inside[:-1, :-1] & corner_inside[:-1, 1:]
            & corner_inside[1:, :-1] & corner_inside[1:, 1:])
    # border cells: any cell holding a contour point (covers what the corner test misses); a
    # point on a grid line is held by the cells on both sides, so it is never on the mesh's
    # outer edge (where a renderer's tie rule could drop it)
    relative = (polygon_xy - origin) / cell_size
    for nudge in ((-1e-7, -1e-7), (-1e-7, 1e-7), (1e-7, -1e-7), (1e-7, 1e-7)):
        cell = np.clip(np.floor(relative + nudge).astype(int), 0, [cols - 1, rows - 1])
        kept[cell[:, 1], cell[:, 0]] = True
    # safety net: the contour polygon runs through boundary pixel centres and cuts diagonal
    # steps, so a grid corner can fall in such a sliver and fail the even-odd test while its
    # cell holds character pixels but no contour point; keep any cell holding a character pixel
    cell = np.floor((np.stack([xs, ys], 1) - origin) / cell_size).astype(int)
    kept[cell[:, 1], cell[:, 0]] = True

    used = np.zeros((rows + 1, cols + 1), dtype=bool)
    used[:-1, :-1] |= kept
    used[:-1, 1:] |= kept
    used[1:, :-1] |= kept
    used[1:, 1:] |= kept
    corner_index = np.full((rows + 1, cols + 1), -1, dtype=np.int64)
    corner_index[used] = np.arange(int(used.sum()))
    vertices = grid.reshape(rows + 1, cols + 1, 2)[used]

    r, c = np.nonzero(kept)
    a = corner_index[r, c]
    b = corner_index[r, c + 1]
    cc = corner_index[r + 1, c + 1]
    d = corner_index[r + 1, c]
    even = ((r + c) % 2) == 0
    # even cells split along a-c, odd cells along b-d; all four triangles are positive
    first = np.where(even[:, None], np.stack([a, b, cc], 1), np.stack([a, b, d], 1))
    second = np.where(even[:, None], np.stack([a, cc, d], 1), np.stack([b, cc, d], 1))
    triangles = np.concatenate([first, second]).astype(np.int64)

    pairs = np.concatenate([np.stack(p, 1) for p in
                            ((a, b), (b, cc), (d, cc), (a, d), (a, cc), (b, d))])
    pairs.sort(axis=1)
    springs = np.unique(pairs, axis=0).astype(np.int64)
    return GridMesh(vertices=vertices, triangles=triangles, springs=springs, origin=origin,
                    cell_size=float(cell_size), kept=kept, corner_index=corner_index,
                    contours=contours)
