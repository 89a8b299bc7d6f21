"""Closed triangle surfaces: loading, cleaning, repair, inside tests and distances.

Everything here works on plain arrays: vertices (V, 3) float64 [m] and faces (F, 3) int64 with
outward (counter-clockwise seen from outside) winding. trimesh is used only to read files and to
fill holes; it is imported lazily (extra `mop[mesh]`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

_JIT = dict(cache=True, nogil=True, error_model="numpy")


def _trimesh():
    try:
        import trimesh
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("latex puppets need trimesh to read meshes: pip install 'mop[mesh]'") \
            from error
    return trimesh


# --- loading ---------------------------------------------------------------------------------

@dataclass
class LoadedMesh:
    """A mesh as read: vertices (V, 3) float64, faces (F, 3) int64, colors (V, 4) uint8 or None."""

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray | None
    source: str


def load_mesh(mesh) -> LoadedMesh:
    """Read `mesh`: a path to anything trimesh loads (OBJ, PLY, STL, GLB, ...) or a
    trimesh.Trimesh / trimesh.Scene. Vertices are taken as given (not merged yet)."""
    trimesh = _trimesh()
    source = "<mesh>"
    if isinstance(mesh, (str, Path)):
        path = Path(mesh)
        if not path.exists():
            raise FileNotFoundError(f"mesh file not found: {path}")
        source = str(path)
        try:
            loaded = trimesh.load(path, force="mesh", process=False)
        except Exception as error:  # trimesh raises many types for unreadable files
            raise ValueError(f"could not read a mesh from {path}: {error}") from error
        mesh = loaded
    if isinstance(mesh, trimesh.Scene):
        mesh = mesh.to_geometry() if hasattr(mesh, "to_geometry") else mesh.dump(concatenate=True)
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"mesh must be a path or a trimesh.Trimesh, got {type(mesh).__name__}")
    vertices = np.array(mesh.vertices, dtype=np.float64)
    faces = np.array(mesh.faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise ValueError(f"{source}: expected vertices of shape (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"{source}: expected triangle faces of shape (F, 3), got {faces.shape}")
    colors = None
    visual = getattr(mesh, "visual", None)
    if visual is not None and getattr(visual, "kind", None) == "vertex":
        c = np.asarray(visual.vertex_colors)
        if c.shape == (len(vertices), 4):
            colors = c.astype(np.uint8)
    return LoadedMesh(vertices, faces, colors, source)


# --- cleaning and repair -----------------------------------------------------------------------

@dataclass
class CleanSurface:
    """A closed, consistently outward-wound triangle surface.

    vertices : (V, 3) float64 [m]; faces : (F, 3) int64
    index_map : (V_in,) int64: input vertex -> cleaned vertex, -1 where the vertex was dropped
    colors : (V, 4) uint8 or None
    repairs : what was changed, in words (merged duplicates, degenerate faces, holes filled ...)
    """

    vertices: np.ndarray
    faces: np.ndarray
    index_map: np.ndarray
    colors: np.ndarray | None = None
    repairs: list[str] = field(default_factory=list)


def edge_use_counts(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undirected edges (E, 2) int64 (sorted pairs) and how many faces use each, (E,) int64."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return unique, counts


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """The closed loops of boundary edges (edges used by exactly one face), each (L,) int64
    vertex indices in order. Edges that do not close a loop are returned as open chains."""
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    edges, counts = edge_use_counts(faces)
    single = {tuple(e) for e in edges[counts == 1]}
    successor: dict[int, list[int]] = {}
    for a, b in directed:
        key = (min(a, b), max(a, b))
        if key in single:
            successor.setdefault(int(a), []).append(int(b))
    loops = []
    while successor:
        start = next(iter(successor))
        loop = [start]
        current = start
        while True:
            nexts = successor.get(current)
            if not nexts:
                break
            nxt = nexts.pop()
            if not nexts:
                del successor[current]
            if nxt == start:
                break
            loop.append(nxt)
            current = nxt
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _describe_holes(vertices: np.ndarray, faces: np.ndarray) -> str:
    loops = boundary_loops(faces)
    edges, counts = edge_use_counts(faces)
    parts = [f"{int((counts == 1).sum())} boundary edges in {len(loops)} loop(s)"]
    for i, loop in enumerate(sorted(loops, key=len, reverse=True)[:5]):
        centre = vertices[loop].mean(0)
        parts.append(f"hole {i + 1}: {len(loop)} edges around "
                     f"({centre[0]:.4g}, {centre[1]:.4g}, {centre[2]:.4g})")
    if len(loops) > 5:
        parts.append(f"... and {len(loops) - 5} more")
    return "; ".join(parts)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume [m^3], positive for outward winding."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def clean_surface(vertices: np.ndarray, faces: np.ndarray, *, colors=None,
                  source: str = "<mesh>") -> CleanSurface:
    """Merge coincident vertices, drop degenerate and duplicate faces and unused vertices, fill
    holes where trimesh can, and orient the surface outward. Raises ValueError naming the holes
    when the surface cannot be closed, or the non-manifold edges when it is not a surface."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"{source}: vertices must be finite, got NaN or inf")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{source}: face indices must be in [0, {len(vertices)}), got "
                         f"[{faces.min()}, {faces.max()}]")
    repairs: list[str] = []
    diagonal = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    if diagonal <= 0:
        raise ValueError(f"{source}: all vertices coincide; expected a solid")
    # 1. merge coincident vertices (OBJ files split them along texture seams)
    quantum = diagonal * 1e-9
    keys = np.round((vertices - vertices.min(0)) / quantum).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if len(first) < len(vertices):
        repairs.append(f"merged {len(vertices) - len(first)} duplicate vertices")
    merged_vertices = vertices[first]
    merged_colors = None if colors is None else np.asarray(colors)[first]
    merged_faces = inverse[faces]
    merged_faces = _drop_bad_faces(merged_vertices, merged_faces, diagonal, repairs, source)
    merged_faces = _close_holes(merged_vertices, merged_faces, repairs, source)
    # unused vertices
    used = np.zeros(len(merged_vertices), dtype=bool)
    used[merged_faces.ravel()] = True
    new_index = np.full(len(merged_vertices), -1, dtype=np.int64)
    new_index[used] = np.arange(int(used.sum()))
    if not used.all():
        repairs.append(f"dropped {int((~used).sum())} vertices used by no face")
    out_vertices = merged_vertices[used]
    out_colors = None if merged_colors is None else merged_colors[used]
    out_faces = new_index[merged_faces]
    # consistent outward winding
    out_faces = _orient_outward(out_vertices, out_faces, repairs, source)
    index_map = new_index[inverse]
    for note in repairs:
        log.info("%s: %s", source, note)
    return CleanSurface(out_vertices, out_faces, index_map, out_colors, repairs)


def _drop_bad_faces(vertices, faces, diagonal, repairs, source) -> np.ndarray:
    """Faces without the degenerate (a repeated vertex or a numerically zero area) and the
    duplicate ones (same three vertices); at least four must be left."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    double_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    repeated = ((faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
                | (faces[:, 2] == faces[:, 0]))
    degenerate = repeated | (double_area <= (diagonal * 1e-7) ** 2)
    if degenerate.any():
        repairs.append(f"removed {int(degenerate.sum())} degenerate faces")
        faces = faces[~degenerate]
    _, keep = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    if len(keep) < len(faces):
        repairs.append(f"removed {len(faces) - len(keep)} duplicate faces")
        faces = faces[np.sort(keep)]
    if len(faces) < 4:
        raise ValueError(f"{source}: only {len(faces)} usable faces left; a closed solid "
                         f"needs at least 4")
    return faces


def _close_holes(vertices, faces, repairs, source) -> np.ndarray:
    """The faces of a closed 2-manifold: holes filled by trimesh when it can do so without new
    vertices; ValueError naming the non-manifold edges or the holes otherwise."""
    edges, counts = edge_use_counts(faces)
    if np.any(counts > 2):
        bad = edges[counts > 2]
        raise ValueError(
            f"{source}: {len(bad)} non-manifold edges (shared by more than two faces), e.g. "
            f"between vertices at {vertices[bad[0, 0]].round(4).tolist()} and "
            f"{vertices[bad[0, 1]].round(4).tolist()}; expected a closed 2-manifold")
    if not np.any(counts == 1):
        return faces
    description = _describe_holes(vertices, faces)
    trimesh = _trimesh()
    patch = trimesh.Trimesh(vertices, faces, process=False)
    trimesh.repair.fill_holes(patch)
    filled = np.asarray(patch.faces, dtype=np.int64)
    if len(patch.vertices) != len(vertices):
        filled = None  # trimesh added vertices: we need a stable vertex numbering
    if filled is not None:
        _, counts_after = edge_use_counts(filled)
    if filled is None or np.any(counts_after != 2):
        raise ValueError(f"{source}: the surface is open and could not be closed: "
                         f"{description}. Close these holes in a modeller, or pass a "
                         f"watertight mesh")
    repairs.append(f"filled holes ({description})")
    return filled


def _orient_outward(vertices, faces, repairs, source) -> np.ndarray:
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, counts = np.unique(directed, axis=0, return_counts=True)
    if np.any(counts > 1):
        trimesh = _trimesh()
        patch = trimesh.Trimesh(vertices, faces, process=False)
        trimesh.repair.fix_winding(patch)
        faces = np.asarray(patch.faces, dtype=np.int64)
        directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        _, counts = np.unique(directed, axis=0, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(f"{source}: faces cannot be wound consistently (a one-sided "
                             f"surface?); expected an orientable closed surface")
        repairs.append("made the face winding consistent")
    # each connected component is flipped on its own if it encloses negative volume
    labels = face_components(faces)
    for label in np.unique(labels):
        part = faces[labels == label]
        if signed_volume(vertices, part) < 0:
            faces[labels == label] = part[:, ::-1]
            repairs.append(f"turned component {int(label)} outward")
    return faces


def face_components(faces: np.ndarray) -> np.ndarray:
    """(F,) int64 connected-component label of each face (faces sharing a vertex connect)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    face_count = len(faces)
    vertex_count = int(faces.max()) + 1
    rows = np.repeat(np.arange(face_count), 3)
    graph = coo_matrix((np.ones(rows.size), (rows, faces.ravel() + face_count)),
                       shape=(face_count + vertex_count,) * 2)
    _, labels = connected_components(graph, directed=False)
    return labels[:face_count].astype(np.int64)


# --- geometry helpers ------------------------------------------------------------------------

def face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (F, 3) float and areas (F,) float [m^2] of the faces."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    cross = np.cross(b - a, c - a)
    double_area = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(double_area, 1e-300)[:, None]
    return normals, 0.5 * double_area


def unique_rows(pairs: np.ndarray) -> np.ndarray:
    """Unique rows of a (P, 2) non-negative int array, sorted (faster than np.unique(axis=0))."""
    pairs = np.asarray(pairs, dtype=np.int64)
    if len(pairs) == 0:
        return pairs.reshape(0, 2)
    base = int(pairs.max()) + 1
    keys = np.unique(pairs[:, 0] * base + pairs[:, 1])
    return np.stack([keys // base, keys % base], axis=1)


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """(E, 2) int64 sorted undirected edges of a triangle (or any polygon) list."""
    faces = np.asarray(faces)
    corners = faces.shape[1]
    pairs = np.concatenate([faces[:, [i, (i + 1) % corners]] for i in range(corners)])
    return unique_rows(np.sort(pairs, axis=1))


def mean_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    edges = unique_edges(faces)
    return float(np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).mean())


# --- inside test: ray parity on a (y, z) grid -----------------------------------------------

# A fixed generic rotation: rays along +x of the rotated frame never run along the axis-aligned
# edges and faces that modelled and generated meshes are full of.
_R = np.array([[0.8660254, -0.3535534, 0.3535534],
               [0.3535534, 0.9330127, 0.0669873],
               [-0.3535534, 0.0669873, 0.9330127]])


@njit(**_JIT)
def _build_grid(tri_y, tri_z, y0, z0, cell, cells):
    """CSR lists of the triangles whose (y, z) bounding box touches each grid cell."""
    face_count = tri_y.shape[0]
    counts = np.zeros(cells * cells + 1, dtype=np.int64)
    for f in range(face_count):
        ya = int((min(tri_y[f, 0], tri_y[f, 1], tri_y[f, 2]) - y0) / cell)
        yb = int((max(tri_y[f, 0], tri_y[f, 1], tri_y[f, 2]) - y0) / cell)
        za = int((min(tri_z[f, 0], tri_z[f, 1], tri_z[f, 2]) - z0) / cell)
        zb = int((max(tri_z[f, 0], tri_z[f, 1], tri_z[f, 2]) - z0) / cell)
        for iy in range(max(ya, 0), min(yb, cells - 1) + 1):
            for iz in range(max(za, 0), min(zb, cells - 1) + 1):
                counts[iy * cells + iz + 1] += 1
    for i in range(cells * cells):
        counts[i + 1] += counts[i]
    items = np.empty(counts[-1], dtype=np.int64)
    fill = counts[:-1].copy()
    for f in range(face_count):
        ya = int((min(tri_y[f, 0], tri_y[f, 1], tri_y[f, 2]) - y0) / cell)
        yb = int((max(tri_y[f, 0], tri_y[f, 1], tri_y[f, 2]) - y0) / cell)
        za = int((min(tri_z[f, 0], tri_z[f, 1], tri_z[f, 2]) - z0) / cell)
        zb = int((max(tri_z[f, 0], tri_z[f, 1], tri_z[f, 2]) - z0) / cell)
        for iy in range(max(ya, 0), min(yb, cells - 1) + 1):
            for iz in range(max(za, 0), min(zb, cells - 1) + 1):
                items[fill[iy * cells + iz]] = f
                fill[iy * cells + iz] += 1
    return counts, items


@njit(**_JIT)
def _parity(points, tri_x, tri_y, tri_z, y0, z0, cell, cells, starts, items, out):
    for p in range(points.shape[0]):
        px, py, pz = points[p, 0], points[p, 1], points[p, 2]
        iy = int(np.floor((py - y0) / cell))
        iz = int(np.floor((pz - z0) / cell))
        if iy < 0 or iz < 0 or iy >= cells or iz >= cells:
            out[p] = False
            continue
        c = iy * cells + iz
        crossings = 0
        for k in range(starts[c], starts[c + 1]):
            f = items[k]
            ay, az = tri_y[f, 0] - py, tri_z[f, 0] - pz
            by, bz = tri_y[f, 1] - py, tri_z[f, 1] - pz
            cy, cz = tri_y[f, 2] - py, tri_z[f, 2] - pz
            w0 = by * cz - bz * cy
            w1 = cy * az - cz * ay
            w2 = ay * bz - az * by
            if not ((w0 > 0 and w1 > 0 and w2 > 0) or (w0 < 0 and w1 < 0 and w2 < 0)):
                continue
            total = w0 + w1 + w2
            x_hit = (w0 * tri_x[f, 0] + w1 * tri_x[f, 1] + w2 * tri_x[f, 2]) / total
            if x_hit > px:
                crossings += 1
        out[p] = (crossings % 2) == 1


class InsideTest:
    """Point-in-solid test for a closed surface by ray parity, built once, queried many times.

    Rays run along +x of a fixed rotated frame; triangles are binned by their (y, z) extent on a
    square grid, so a query costs about (faces per cell). Exact up to points lying exactly on a
    projected edge (measure zero for generated points)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        rotated = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64) @ _R.T)
        tri = rotated[np.asarray(faces, dtype=np.int64)]
        self._x = np.ascontiguousarray(tri[:, :, 0])
        self._y = np.ascontiguousarray(tri[:, :, 1])
        self._z = np.ascontiguousarray(tri[:, :, 2])
        lo = rotated.min(0)
        hi = rotated.max(0)
        span = float(max(hi[1] - lo[1], hi[2] - lo[2])) * 1.0001 + 1e-12
        self._cells = int(np.clip(np.sqrt(len(faces)) * 0.7, 4, 512))
        self._cell = span / self._cells
        self._y0, self._z0 = float(lo[1]), float(lo[2])
        self._starts, self._items = _build_grid(self._y, self._z, self._y0, self._z0,
                                                self._cell, self._cells)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: True where points (P, 3) [m] lie inside the surface."""
        rotated = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3) @ _R.T)
        out = np.zeros(len(rotated), dtype=np.bool_)
        _parity(rotated, self._x, self._y, self._z, self._y0, self._z0, self._cell,
                self._cells, self._starts, self._items, out)
        return out


# --- distance to a surface ------------------------------------------------------------------

@njit(**_JIT)
def _point_triangle_distance2(p, a, b, c):
    """Squared distance from p to triangle abc (Ericson, Real-Time Collision Detection 5.1.5)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = ab @ ap
    d2 = ac @ ap
    if d1 <= 0.0 and d2 <= 0.0:
        q = a
    else:
        bp = p - b
        d3 = ab @ bp
        d4 = ac @ bp
        if d3 >= 0.0 and d4 <= d3:
            q = b
        else:
            vc = d1 * d4 - d3 * d2
            if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
                q = a + (d1 / (d1 - d3)) * ab
            else:
                cp = p - c
                d5 = ab @ cp
                d6 = ac @ cp
                if d6 >= 0.0 and d5 <= d6:
                    q = c
                else:
                    vb = d5 * d2 - d1 * d6
                    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                        q = a + (d2 / (d2 - d6)) * ac
                    else:
                        va = d3 * d6 - d5 * d4
                        if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                            q = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b)
                        else:
                            denom = 1.0 / (va + vb + vc)
                            q = a + ab * (vb * denom) + ac * (vc * denom)
    e = p - q
    return e @ e


@njit(**_JIT)
def _candidate_distances(points, vertices, faces, starts, items, out):
    for p in range(points.shape[0]):
        best = np.inf
        for k in range(starts[p], starts[p + 1]):
            f = items[k]
            d2 = _point_triangle_distance2(points[p], vertices[faces[f, 0]],
                                           vertices[faces[f, 1]], vertices[faces[f, 2]])
            if d2 < best:
                best = d2
        out[p] = np.sqrt(best)


class SurfaceDistance:
    """Exact unsigned distance [m] from points to a triangle surface, built once.

    For each query the nearest vertex gives an upper bound d; every face that can be closer has
    its centroid within d + (its largest centroid-to-corner distance), which a KD-tree finds."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        from scipy.spatial import cKDTree
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self._faces = np.ascontiguousarray(faces, dtype=np.int64)
        tri = self._vertices[self._faces]
        self._centroids = tri.mean(1)
        self._reach = float(np.linalg.norm(tri - self._centroids[:, None, :], axis=2).max())
        self._vertex_tree = cKDTree(self._vertices)
        self._centroid_tree = cKDTree(self._centroids)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(P,) float [m] distances of points (P, 3) [m] to the surface."""
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        upper, _ = self._vertex_tree.query(points)
        lists = self._centroid_tree.query_ball_point(points, upper + self._reach)
        sizes = np.fromiter((len(item) for item in lists), dtype=np.int64, count=len(lists))
        starts = np.zeros(len(points) + 1, dtype=np.int64)
        np.cumsum(sizes, out=starts[1:])
        items = (np.concatenate([np.asarray(item, dtype=np.int64) for item in lists])
                 if starts[-1] else np.zeros(0, dtype=np.int64))
        out = np.empty(len(points))
        _candidate_distances(points, self._vertices, self._faces, starts, items, out)
        return out
