"""Skeletonisation of a closed surface mesh (medial-surface paper, section 3.1).

Each surface point owns one Voronoi cell of the surface points. The cell's Voronoi points that
lie behind every face incident to the point are its *internal* Voronoi points; their average
distance ``d`` to the point places the skeletal point on the negative vertex normal,
``s = p - d n``. Where a point has no internal Voronoi point, the skeletal point is the surface
point itself. The skeleton therefore has one point per surface vertex and the mesh's connectivity.

One addition to the paper (documented in docs/medial_objects.md): a medial ball tangent at
``p`` cannot reach past the midpoint of the chord that ``-n`` cuts through the solid, so ``d`` is
clamped to half that chord. Far Voronoi points in flat or thin regions pass the local face-normal
test and would otherwise push the skeletal point through the opposite side of the shape.

Everything here is a pure array function; ``characters.medial`` calls them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class Skeleton:
    """The result of :func:`skeletonize`.

    points : (V, 3) float [mesh units]   one skeletal point per surface vertex
    depth : (V,) float [mesh units]      distance from each surface vertex to its skeletal point
    fallback : (V,) bool                 no internal Voronoi point: the skeletal point is the vertex
    clamped : (V,) bool                  depth was cut to half the inner chord along -normal
    internal_counts : (V,) int           internal Voronoi points found in each vertex's cell
    """

    points: np.ndarray
    depth: np.ndarray
    fallback: np.ndarray
    clamped: np.ndarray
    internal_counts: np.ndarray


def voronoi_cell_pairs(points: np.ndarray):
    """Flatten the Voronoi cells of `points` into (owner, Voronoi point) pairs.

    points : (V, 3) float                surface points
    Returns ``owner (P,) int`` (index of the surface point whose cell it is),
    ``corner (P,) int`` (index into ``voronoi_points``) and ``voronoi_points (Q, 3) float``.
    Points at infinity (qhull's -1) are left out: they are never internal.
    """
    from scipy.spatial import QhullError, Voronoi

    points = np.asarray(points, dtype=np.float64)
    try:
        voronoi = Voronoi(points)
    except QhullError as error:
        raise ValueError(
            f"Voronoi diagram of the {len(points)} surface points failed (qhull: "
            f"{str(error).splitlines()[0]}); expected a closed mesh with enough vertices in "
            "general position") from error
    regions = [voronoi.regions[r] for r in voronoi.point_region]
    lengths = np.fromiter((len(r) for r in regions), dtype=np.int64, count=len(regions))
    owner = np.repeat(np.arange(len(points)), lengths)
    corner = np.fromiter((c for r in regions for c in r), dtype=np.int64, count=int(lengths.sum()))
    finite = corner >= 0
    return owner[finite], corner[finite], voronoi.vertices


def internal_voronoi_mask(points, face_normals, vertex_faces, owner, corner_points):
    """Which (owner, Voronoi point) pairs lie behind every face incident to the owner.

    points : (V, 3) float                surface points
    face_normals : (F, 3) float          outward unit face normals
    vertex_faces : (V, K) int            faces around each vertex, padded with -1
    owner : (P,) int                     owning surface point of each pair
    corner_points : (P, 3) float         the Voronoi point of each pair
    Returns ``(P,) bool``.
    """
    return _internal_mask(np.ascontiguousarray(points, dtype=np.float64),
                          np.ascontiguousarray(face_normals, dtype=np.float64),
                          np.ascontiguousarray(vertex_faces, dtype=np.int64),
                          np.ascontiguousarray(owner, dtype=np.int64),
                          np.ascontiguousarray(corner_points, dtype=np.float64))


@njit(cache=True)
def _internal_mask(points, face_normals, vertex_faces, owner, corner_points):
    mask = np.empty(owner.shape[0], dtype=np.bool_)
    for pair in range(owner.shape[0]):
        vertex = owner[pair]
        ox = corner_points[pair, 0] - points[vertex, 0]
        oy = corner_points[pair, 1] - points[vertex, 1]
        oz = corner_points[pair, 2] - points[vertex, 2]
        inside = True
        for k in range(vertex_faces.shape[1]):
            face = vertex_faces[vertex, k]
            if face < 0:   # padding
                continue
            if (face_normals[face, 0] * ox + face_normals[face, 1] * oy
                    + face_normals[face, 2] * oz) >= 0.0:
                inside = False
                break
        mask[pair] = inside
    return mask


def internal_voronoi_mask_reference(points, face_normals, vertex_faces, owner, corner_points):
    """Slow per-pair loop of :func:`internal_voronoi_mask`, for tests."""
    mask = np.zeros(len(owner), dtype=bool)
    for pair, (vertex, corner) in enumerate(zip(owner, corner_points)):
        ok = True
        for face in vertex_faces[vertex]:
            if face < 0:
                continue
            if np.dot(face_normals[face], corner - points[vertex]) >= 0.0:
                ok = False
                break
        mask[pair] = ok
    return mask


@njit(cache=True, inline="always")
def _ray_triangle(ox, oy, oz, dx, dy, dz, triangles, f):
    """Moeller-Trumbore distance along the ray to triangle f (inf if it misses)."""
    ax, ay, az = triangles[f, 0, 0], triangles[f, 0, 1], triangles[f, 0, 2]
    e1x = triangles[f, 1, 0] - ax
    e1y = triangles[f, 1, 1] - ay
    e1z = triangles[f, 1, 2] - az
    e2x = triangles[f, 2, 0] - ax
    e2y = triangles[f, 2, 1] - ay
    e2z = triangles[f, 2, 2] - az
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if abs(det) < 1e-300:
        return np.inf
    inv = 1.0 / det
    tx, ty, tz = ox - ax, oy - ay, oz - az
    u = (tx * px + ty * py + tz * pz) * inv
    # a small tolerance: on symmetric meshes the ray runs exactly through an edge or a vertex
    # of the opposite side, which exact tests can miss on both neighbours
    if u < -1e-9 or u > 1.0 + 1e-9:
        return np.inf
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < -1e-9 or u + v > 1.0 + 1e-9:
        return np.inf
    return (e2x * qx + e2y * qy + e2z * qz) * inv


@njit(cache=True)
def first_hits_reference(origins, directions, triangles, min_hit):
    """Brute force over all triangles: nearest hit beyond `min_hit` per ray (inf if none)."""
    result = np.full(origins.shape[0], np.inf)
    for r in range(origins.shape[0]):
        best = np.inf
        for f in range(triangles.shape[0]):
            t = _ray_triangle(origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0],
                              directions[r, 1], directions[r, 2], triangles, f)
            if t > min_hit and t < best:
                best = t
        result[r] = best
    return result


@njit(cache=True)
def _build_grid(triangles, low, cell, shape):
    """CSR lists of the triangles whose bounding box overlaps each grid cell."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    counts = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    face_count = triangles.shape[0]
    bounds = np.empty((face_count, 6), dtype=np.int64)
    for f in range(face_count):
        for a in range(3):
            lo = min(triangles[f, 0, a], triangles[f, 1, a], triangles[f, 2, a])
            hi = max(triangles[f, 0, a], triangles[f, 1, a], triangles[f, 2, a])
            top = shape[a] - 1
            bounds[f, a] = min(max(int((lo - low[a]) / cell), 0), top)
            bounds[f, 3 + a] = min(max(int((hi - low[a]) / cell), 0), top)
        for i in range(bounds[f, 0], bounds[f, 3] + 1):
            for j in range(bounds[f, 1], bounds[f, 4] + 1):
                for k in range(bounds[f, 2], bounds[f, 5] + 1):
                    counts[(i * ny + j) * nz + k + 1] += 1
    starts = np.cumsum(counts)
    fill = starts[:-1].copy()
    items = np.empty(starts[-1], dtype=np.int64)
    for f in range(face_count):
        for i in range(bounds[f, 0], bounds[f, 3] + 1):
            for j in range(bounds[f, 1], bounds[f, 4] + 1):
                for k in range(bounds[f, 2], bounds[f, 5] + 1):
                    c = (i * ny + j) * nz + k
                    items[fill[c]] = f
                    fill[c] += 1
    return starts, items


@njit(cache=True)
def _first_hits_grid(origins, directions, triangles, min_hit, low, cell, shape, starts, items):
    """Nearest hit per ray, walking the grid cells the ray crosses (Amanatides-Woo)."""
    ny, nz = shape[1], shape[2]
    result = np.full(origins.shape[0], np.inf)
    index = np.empty(3, dtype=np.int64)
    step = np.empty(3, dtype=np.int64)
    t_max = np.empty(3)
    t_delta = np.empty(3)
    for r in range(origins.shape[0]):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        for a in range(3):
            q = (origins[r, a] - low[a]) / cell
            index[a] = min(max(int(q), 0), shape[a] - 1)
            d = directions[r, a]
            if d > 0.0:
                step[a] = 1
                t_max[a] = ((index[a] + 1) * cell + low[a] - origins[r, a]) / d
                t_delta[a] = cell / d
            elif d < 0.0:
                step[a] = -1
                t_max[a] = (index[a] * cell + low[a] - origins[r, a]) / d
                t_delta[a] = -cell / d
            else:
                step[a] = 0
                t_max[a] = np.inf
                t_delta[a] = np.inf
        best = np.inf
        while True:
            c = (index[0] * ny + index[1]) * nz + index[2]
            for p in range(starts[c], starts[c + 1]):
                t = _ray_triangle(ox, oy, oz, dx, dy, dz, triangles, items[p])
                if t > min_hit and t < best:
                    best = t
            # leave the cell through its nearest face; stop once the best hit is inside it
            a = 0
            if t_max[1] < t_max[a]:
                a = 1
            if t_max[2] < t_max[a]:
                a = 2
            if best <= t_max[a]:
                break
            index[a] += step[a]
            if index[a] < 0 or index[a] >= shape[a]:
                break
            t_max[a] += t_delta[a]
        result[r] = best
    return result


def inner_chord_lengths(points, normals, triangles, *, min_hit: float, cell: float | None = None):
    """Length of the chord that the ray ``p - t n`` cuts through the solid, per vertex.

    points : (V, 3) float, normals : (V, 3) float unit outward vertex normals
    triangles : (F, 3, 3) float           the surface's triangles
    min_hit : float [mesh units]          hits closer than this are the vertex's own faces
    cell : float [mesh units] | None      grid cell size (default: twice the mean edge length)
    Returns ``(V,) float`` (inf where the ray hits nothing, which on a closed mesh only happens
    on numerical edge cases).
    """
    triangles = np.ascontiguousarray(triangles, dtype=np.float64)
    origins = np.ascontiguousarray(points, dtype=np.float64)
    directions = np.ascontiguousarray(-np.asarray(normals, dtype=np.float64))
    low = triangles.reshape(-1, 3).min(axis=0)
    high = triangles.reshape(-1, 3).max(axis=0)
    if cell is None:
        edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2)
        cell = 2.0 * float(edges.mean())
    # keep the grid to a few million cells whatever the mesh
    cell = max(float(cell), float(np.max(high - low)) / 256.0)
    shape = np.maximum(np.ceil((high - low) / cell).astype(np.int64), 1)
    starts, items = _build_grid(triangles, low, cell, shape)
    return _first_hits_grid(origins, directions, triangles, float(min_hit), low, cell, shape,
                            starts, items)


def skeletonize(mesh) -> Skeleton:
    """Skeletal points of a closed, consistently wound `mesh` (trimesh.Trimesh), section 3.1."""
    points = np.asarray(mesh.vertices, dtype=np.float64)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    owner, corner, voronoi_points = voronoi_cell_pairs(points)
    corner_points = voronoi_points[corner]
    internal = internal_voronoi_mask(
        points, np.asarray(mesh.face_normals), np.asarray(mesh.vertex_faces), owner, corner_points)
    distances = np.linalg.norm(corner_points - points[owner], axis=1)
    vertex_count = len(points)
    counts = np.bincount(owner[internal], minlength=vertex_count)
    sums = np.bincount(owner[internal], weights=distances[internal], minlength=vertex_count)
    fallback = counts == 0
    depth = np.where(fallback, 0.0, sums / np.maximum(counts, 1))

    edge_lengths = mesh.edges_unique_length
    chords = inner_chord_lengths(points, normals, np.asarray(mesh.triangles),
                                 min_hit=1e-3 * float(edge_lengths.mean()))
    clamped = depth > 0.5 * chords
    depth = np.where(clamped, 0.5 * chords, depth)
    skeleton = points - depth[:, None] * normals
    return Skeleton(points=skeleton, depth=depth, fallback=fallback, clamped=clamped,
                    internal_counts=counts)
