"""Load and check the surface mesh a medial object is built from.

Repairs that are always made (and logged), because they never change the shape:
- vertices that differ only by texture coordinates or normals are merged (OBJ files split
  vertices along texture seams, which opens a closed surface into patches);
- degenerate and duplicate faces and unreferenced vertices are removed;
- a surface wound inside-out (negative volume) is inverted.

Everything else raises ValueError: open surfaces, inconsistent winding, too few vertices,
self-intersections.
"""
from __future__ import annotations

import logging
from os import PathLike

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

#: a closed surface with fewer vertices than this has no usable skeleton (an octahedron has 6)
MIN_VERTICES = 12
#: the most faces a medial object is built from unless asked: qhull's Voronoi step grows about
#: with the square of the vertex count on round shapes (icospheres on a busy 2-core laptop:
#: 1,280 faces 0.75 s, 5,120 faces 4.6-12 s, 20,480 faces more than 5 min)
MAX_FACES = 10_000


def _trimesh():
    try:
        import trimesh
    except ImportError as error:  # pragma: no cover - the mesh extra is part of the dev install
        raise ImportError("medial objects need trimesh: pip install 'mop[mesh]'") from error
    return trimesh


def load_closed_mesh(mesh, *, check_self_intersections: bool = True,
                     max_faces: int = MAX_FACES):
    """A repaired copy of `mesh` (path or trimesh.Trimesh) that is closed and outward-wound.

    Raises TypeError for anything else than a path or a Trimesh, ValueError for an unreadable
    file, non-finite vertices, more than `max_faces` faces, an open, inconsistently wound, too
    coarse or self-intersecting surface.
    """
    mesh, source = _read_mesh(mesh)
    _check_contents(mesh, source, max_faces)
    before = len(mesh.vertices)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.vertices) != before:
        log.info("%s: merged/removed %d duplicate or unused vertices (texture seams)",
                 source, before - len(mesh.vertices))
    _check_closed(mesh, source)
    if mesh.volume < 0:
        mesh.invert()
        log.info("%s: faces were wound inside-out; inverted them", source)
    if check_self_intersections:
        _repair_small_self_intersections(mesh, source)
    return mesh


def _read_mesh(mesh):
    """(a Trimesh of our own, the name errors give it) from a path or a Trimesh."""
    trimesh = _trimesh()
    if isinstance(mesh, (str, PathLike)):
        try:
            # unprocessed, so that a NaN vertex is reported as such, not as the holes that
            # trimesh's clean-up would leave where it dropped it
            loaded = trimesh.load(mesh, force="mesh", process=False)
        except FileNotFoundError:
            raise FileNotFoundError(f"mesh file not found: {mesh!s}") from None
        except Exception as error:  # trimesh raises many types (even ImportError) for junk
            raise ValueError(f"{mesh!s} cannot be read as a mesh ({type(error).__name__}: "
                             f"{error})") from None
        if not isinstance(loaded, trimesh.Trimesh):
            raise ValueError(f"{mesh!s} holds no triangle mesh (got {type(loaded).__name__})")
        source = str(mesh)
        mesh = loaded
    elif isinstance(mesh, trimesh.Trimesh):
        source = "the mesh"
        mesh = mesh.copy()
    else:
        raise TypeError(f"mesh must be a path or a trimesh.Trimesh, got {type(mesh).__name__}")
    return mesh, source


def _check_contents(mesh, source: str, max_faces: int) -> None:
    if len(mesh.faces) == 0:
        raise ValueError(f"{source} has no faces; expected a closed triangle surface")
    finite = np.isfinite(np.asarray(mesh.vertices, dtype=np.float64)).all(axis=1)
    if not finite.all():
        raise ValueError(f"{source} has {int((~finite).sum())} vertices with NaN or infinite "
                         f"coordinates (e.g. vertex {int(np.flatnonzero(~finite)[0])}); expected "
                         f"finite positions")
    if len(mesh.faces) > max_faces:
        raise ValueError(
            f"{source} has {len(mesh.faces):,} faces; the medial skeleton (a Voronoi diagram "
            f"of every vertex) is limited to {max_faces:,} faces, beyond which it takes "
            f"minutes: simplify the mesh first (trimesh's simplify_quadric_decimation), or "
            f"lift the limit with max_faces={len(mesh.faces)}")


def _check_closed(mesh, source: str) -> None:
    """Closed, manifold, consistently wound and fine enough for a skeleton."""
    edges = mesh.edges_sorted
    _, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = int(np.sum(counts == 1))
    nonmanifold = int(np.sum(counts > 2))
    if boundary:
        raise ValueError(
            f"{source} is not a closed surface: {boundary} boundary edges (holes); a medial "
            "object needs a closed (watertight) mesh - fill the holes first "
            "(e.g. trimesh.repair.fill_holes)")
    if nonmanifold:
        raise ValueError(
            f"{source} is not a manifold surface: {nonmanifold} edges are shared by more than two "
            "faces (parts touching along an edge, or duplicate vertices merged); expected every "
            "edge to join exactly two faces")
    if not mesh.is_winding_consistent:
        raise ValueError(f"{source} has inconsistent face winding; expected every face wound the "
                         "same way (trimesh.repair.fix_winding can repair it)")
    if len(mesh.vertices) < MIN_VERTICES:
        raise ValueError(
            f"{source} is too coarse: {len(mesh.vertices)} vertices, need at least {MIN_VERTICES} "
            "for a skeleton (subdivide it, e.g. trimesh.remesh.subdivide)")


def _repair_small_self_intersections(mesh, source: str) -> None:
    """Push back vertices that poke slightly through a face; refuse larger crossings."""
    vertices = np.array(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces)
    max_shift = SMALL_INTERSECTION * float(mesh.edges_unique_length.mean())
    pairs, moved = repair_small_self_intersections(vertices, faces, max_shift=max_shift)
    if len(pairs):
        raise ValueError(
            f"{source} intersects itself: {len(pairs)} pairs of faces cross (e.g. faces "
            f"{int(pairs[0, 0])} and {int(pairs[0, 1])}) by more than {SMALL_INTERSECTION:g} "
            "of the mean edge length; expected a surface that bounds one solid - union "
            "overlapping parts first (trimesh.boolean.union, engine='manifold')")
    if moved:
        mesh.vertices = vertices
        log.info("%s: pushed %d vertices back through faces they poked through (small "
                 "self-intersections)", source, moved)


#: self-intersections where one vertex pokes through a face by less than this fraction of the
#: mean edge length are repaired by moving the vertex back (pybullet's duck has one)
SMALL_INTERSECTION = 0.05


def repair_small_self_intersections(vertices, faces, *, max_shift: float, rounds: int = 5):
    """Move vertices that poke slightly through a face back to the side of their neighbours.

    vertices : (V, 3) float, modified in place; faces : (F, 3) int
    max_shift : float [mesh units]       deeper crossings are left alone (and reported)
    For each crossing pair, the *lonely* vertex of one face (alone on its side of the other
    face's plane) with the smallest depth is moved across that plane by its depth plus a margin.
    Returns ``(pairs (K, 2) int still crossing, moved: int vertex moves made)``.
    """
    moved = 0
    pairs = self_intersections(vertices, faces)
    for _ in range(rounds):
        if not len(pairs):
            break
        progress = False
        for f, g in pairs:
            best = None
            for plane_face, other in ((f, g), (g, f)):
                a, b, c = vertices[faces[plane_face]]
                normal = np.cross(b - a, c - a)
                normal /= np.linalg.norm(normal)
                signed = (vertices[faces[other]] - a) @ normal
                sides = np.sign(signed)
                for k in range(3):
                    if sides[k] != 0 and np.all(sides[np.arange(3) != k] == -sides[k]):
                        depth = abs(signed[k])
                        if best is None or depth < best[0]:
                            best = (depth, faces[other][k], -sides[k] * normal)
            if best is None or best[0] > max_shift:
                continue
            depth, vertex, direction = best
            vertices[vertex] += direction * (depth + 1e-3 * max_shift)
            moved += 1
            progress = True
        pairs = self_intersections(vertices, faces)
        if not progress:
            break
    return pairs, moved


@njit(cache=True)
def _segment_hits_triangle(p, q, a, b, c, eps):
    """Does the open segment p-q cross the interior of triangle abc (Moeller-Trumbore)?"""
    d0 = q[0] - p[0]
    d1 = q[1] - p[1]
    d2 = q[2] - p[2]
    e10, e11, e12 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    e20, e21, e22 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    h0 = d1 * e22 - d2 * e21
    h1 = d2 * e20 - d0 * e22
    h2 = d0 * e21 - d1 * e20
    det = e10 * h0 + e11 * h1 + e12 * h2
    scale = np.sqrt((e10 * e10 + e11 * e11 + e12 * e12) * (e20 * e20 + e21 * e21 + e22 * e22)
                    * (d0 * d0 + d1 * d1 + d2 * d2))
    if abs(det) <= 1e-12 * scale:  # parallel or coplanar: not a crossing
        return False
    inv = 1.0 / det
    s0, s1, s2 = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    u = (s0 * h0 + s1 * h1 + s2 * h2) * inv
    if u <= eps or u >= 1.0 - eps:
        return False
    r0 = s1 * e12 - s2 * e11
    r1 = s2 * e10 - s0 * e12
    r2 = s0 * e11 - s1 * e10
    v = (d0 * r0 + d1 * r1 + d2 * r2) * inv
    if v <= eps or u + v >= 1.0 - eps:
        return False
    t = (e20 * r0 + e21 * r1 + e22 * r2) * inv
    return eps < t < 1.0 - eps


@njit(cache=True)
def _intersecting_pairs(vertices, faces, order, lower, upper, eps, out):
    """Sweep-and-prune over x of the face boxes, then an exact edge-triangle test."""
    found = 0
    face_count = faces.shape[0]
    for oi in range(face_count):
        i = order[oi]
        for oj in range(oi + 1, face_count):
            j = order[oj]
            if lower[j, 0] > upper[i, 0]:
                break
            if (lower[j, 1] > upper[i, 1] or lower[i, 1] > upper[j, 1]
                    or lower[j, 2] > upper[i, 2] or lower[i, 2] > upper[j, 2]):
                continue
            shared = False
            for a in range(3):
                for b in range(3):
                    if faces[i, a] == faces[j, b]:
                        shared = True
            if shared:  # neighbours touch by construction
                continue
            hit = False
            for first, second in ((i, j), (j, i)):
                ta = vertices[faces[second, 0]]
                tb = vertices[faces[second, 1]]
                tc = vertices[faces[second, 2]]
                for e in range(3):
                    p = vertices[faces[first, e]]
                    q = vertices[faces[first, (e + 1) % 3]]
                    if _segment_hits_triangle(p, q, ta, tb, tc, eps):
                        hit = True
                        break
                if hit:
                    break
            if hit:
                if found < out.shape[0]:
                    out[found, 0] = min(i, j)
                    out[found, 1] = max(i, j)
                found += 1
    return found


def self_intersections(vertices, faces, *, max_report: int = 1000) -> np.ndarray:
    """Pairs of faces that cross each other (faces sharing a vertex are not tested).

    vertices : (V, 3) float, faces : (F, 3) int
    Returns ``(K, 2) int`` face index pairs, at most `max_report` of them.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    corners = vertices[faces]
    lower = corners.min(axis=1)
    upper = corners.max(axis=1)
    order = np.argsort(lower[:, 0], kind="stable")
    out = np.zeros((max_report, 2), dtype=np.int64)
    found = _intersecting_pairs(vertices, faces, order, lower, upper, 1e-9, out)
    return out[:min(found, max_report)]
