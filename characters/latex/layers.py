"""Internal layers of the latex puppet (paper section 4.2): biting spheres, an advancing front,
and tetrahedra by the Delaunay criterion.

Front 0 is the decimated surface. For every face (a, b, c) of the current front, three spheres
of radius rho (the face's mean edge length: the local bite) centred on its corners meet in two
points on the face's axis through the circumcentre; the one on the inner side is a candidate
Steiner point (for an equilateral face it is the apex of a regular tetrahedron). Candidates are
packed like bubbles: in order of face roundness, a candidate is kept only if it is inside the
solid, at least `margin * rho` from the surface, and no kept or existing point lies within
`packing * rho`. The kept points form the next front; its faces are found in the Delaunay
tetrahedralisation of all points so far (a face of three new points whose tetrahedron on one
side reaches back to the older front faces inward). Two fronts below the surface give three
closed node layers:

    layer 0  latex skin: the decimated surface vertices
    layer 1  foam: the first front inward
    layer 2  hand cavity: the second front (the cavity wall) and the core it encloses

The final tetrahedra are the Delaunay tetrahedra of all points whose centroid, face centroids
and edge midpoints lie inside the visual surface (so none bridges the mouth slit), with
near-zero volumes dropped and all oriented to positive volume.

Material layers of springs and tetrahedra follow the puppet's build-up: the latex skin is the
membrane of springs between two surface nodes; the hand cavity is what lies wholly on or inside
the cavity wall (springs and tetrahedra whose nodes are all layer 2); everything between is foam.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numba import njit

from .surface import InsideTest, SurfaceDistance, unique_edges, unique_rows

log = logging.getLogger(__name__)

_JIT = dict(cache=True, nogil=True, error_model="numpy")

LAYER_NAMES = ("latex", "foam", "cavity")


@dataclass
class Layers:
    """The physical mesh inside a decimated surface.

    points : (N, 3) float [m]: layer-0 nodes first (the decimated surface vertices, in order)
    layer : (N,) int64: 0 latex skin, 1 foam, 2 hand cavity
    tetrahedra : (K, 4) int64, each with positive volume
    tetrahedron_layer : (K,) int64: 0 all nodes on the skin, 2 all in the cavity, else 1
    springs : (M, 2) int64: unique tetrahedron edges and surface edges
    spring_layer : (M,) int64: 0 skin membrane, 2 cavity, else 1 (foam)
    surface_faces : (F, 3) int64: the decimated surface's triangles (nodes of layer 0)
    """

    points: np.ndarray
    layer: np.ndarray
    tetrahedra: np.ndarray
    tetrahedron_layer: np.ndarray
    springs: np.ndarray
    spring_layer: np.ndarray
    surface_faces: np.ndarray


def tetrahedron_volumes(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """(K,) float [m^3] signed volumes (positive when (b-a, c-a, d-a) is right-handed)."""
    a, b, c, d = (points[tetrahedra[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0


def _circumcentre(a, b, c):
    """Circumcentres (F, 3) and circumradii (F,) of triangles abc (each (F, 3))."""
    ab = b - a
    ac = c - a
    n = np.cross(ab, ac)
    n2 = np.einsum("ij,ij->i", n, n)
    offset = (np.cross(n, ab) * np.einsum("ij,ij->i", ac, ac)[:, None]
              + np.cross(ac, n) * np.einsum("ij,ij->i", ab, ab)[:, None]) / (2.0 * n2[:, None])
    return a + offset, np.linalg.norm(offset, axis=1)


def biting_sphere_apexes(points: np.ndarray, faces: np.ndarray, inward: np.ndarray):
    """Inner meeting point of the three spheres of radius rho around each face's corners.

    points (N, 3) [m]; faces (F, 3) int; inward (F, 3) unit vectors pointing into the solid.
    Returns apexes (F, 3) [m] and rho (F,) [m]. Where the spheres do not meet inside the face's
    prism (obtuse faces), the apex is placed at the regular-tetrahedron height over the
    centroid instead."""
    a, b, c = (points[faces[:, i]] for i in range(3))
    rho = (np.linalg.norm(b - a, axis=1) + np.linalg.norm(c - b, axis=1)
           + np.linalg.norm(a - c, axis=1)) / 3.0
    centre, radius = _circumcentre(a, b, c)
    centroid = (a + b + c) / 3.0
    height = np.sqrt(np.maximum(rho ** 2 - radius ** 2, 0.0))
    # barycentric test: is the circumcentre inside the triangle (acute face)?
    acute = np.ones(len(faces), dtype=bool)
    for p, q, r in ((a, b, c), (b, c, a), (c, a, b)):
        acute &= np.einsum("ij,ij->i", q - p, r - p) > 0
    regular = rho * np.sqrt(2.0 / 3.0)
    use = acute & (height > 0.5 * regular)
    base = np.where(use[:, None], centre, centroid)
    lift = np.where(use, height, regular)
    return base + inward * lift[:, None], rho


@njit(cache=True)
def _greedy_pack(order, candidates, radius, neighbour_starts, neighbour_items, accepted):
    """Keep candidates in `order` unless an already kept one lies within its radius."""
    for k in range(order.shape[0]):
        i = order[k]
        ok = True
        for j in range(neighbour_starts[i], neighbour_starts[i + 1]):
            other = neighbour_items[j]
            if accepted[other]:
                d = candidates[i] - candidates[other]
                if d @ d < radius[i] * radius[i]:
                    ok = False
                    break
        accepted[i] = ok


def _pack(candidates, rho, quality, existing, *, packing, inside, distance, margin):
    """Bubble packing of candidate points; returns the indices kept."""
    from scipy.spatial import cKDTree
    keep = inside(candidates)
    keep &= distance(candidates) >= margin * rho
    if len(existing):
        gap, _ = cKDTree(existing).query(candidates)
        keep &= gap >= packing * rho
    index = np.flatnonzero(keep)
    if index.size == 0:
        return index
    pts = candidates[index]
    radius = packing * rho[index]
    lists = cKDTree(pts).query_ball_point(pts, radius)
    sizes = np.fromiter((len(item) for item in lists), dtype=np.int64, count=len(lists))
    starts = np.zeros(len(pts) + 1, dtype=np.int64)
    np.cumsum(sizes, out=starts[1:])
    items = np.concatenate([np.asarray(item, dtype=np.int64) for item in lists])
    order = np.argsort(-quality[index], kind="stable").astype(np.int64)
    accepted = np.zeros(len(pts), dtype=np.bool_)
    _greedy_pack(order, np.ascontiguousarray(pts), radius, starts, items, accepted)
    return index[accepted]


def _kept_tetrahedra(points, inside, *, volume_floor):
    """Delaunay tetrahedra of points that lie inside the solid, oriented positive."""
    from scipy.spatial import Delaunay
    tets = Delaunay(points).simplices.astype(np.int64)
    p = points[tets]  # (K, 4, 3)
    # centroid first (cheap rejection), then the edge midpoints of the survivors: a tetrahedron
    # bridging the mouth slit or a concave dent has its centroid or an edge outside
    keep = inside(p.mean(1))
    tets, p = tets[keep], p[keep]
    pairs = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
    probe = np.stack([0.5 * (p[:, i] + p[:, j]) for i, j in pairs], axis=1)  # (K, 6, 3)
    tets = tets[inside(probe.reshape(-1, 3)).reshape(len(tets), -1).all(1)]
    volume = tetrahedron_volumes(points, tets)
    negative = volume < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    volume = np.abs(volume)
    return tets[volume > volume_floor]


def _front_faces(tets, layer, front):
    """Faces of the tetrahedra made of three `front` nodes whose fourth node is outer; returns
    faces (F, 3) and inward unit normals (computed by the caller from the outer node)."""
    faces = []
    outer = []
    for skip in range(4):
        corners = [k for k in range(4) if k != skip]
        tri = tets[:, corners]
        on_front = (layer[tri] == front).all(1)
        is_outer = layer[tets[:, skip]] < front
        chosen = on_front & is_outer
        faces.append(tri[chosen])
        outer.append(tets[chosen, skip])
    faces = np.concatenate(faces)
    outer = np.concatenate(outer)
    key = np.sort(faces, axis=1)
    base = int(key.max()) + 1 if len(key) else 1
    _, first, counts = np.unique((key[:, 0] * base + key[:, 1]) * base + key[:, 2],
                                 return_index=True, return_counts=True)
    single = first[counts == 1]  # a face with outer nodes on both sides is not a front face
    return faces[single], outer[single]


def build_layers(surface_points: np.ndarray, surface_faces: np.ndarray, visual_vertices,
                 visual_faces, *, packing: float = 0.75, margin: float = 0.3,
                 inside: InsideTest | None = None,
                 distance: SurfaceDistance | None = None) -> Layers:
    """Three node layers and their tetrahedra inside a decimated surface.

    surface_points (n, 3) [m], surface_faces (F, 3) int: the decimated surface (outward)
    visual_vertices (V, 3), visual_faces (F_v, 3): the full surface used for inside tests
    packing: minimum distance between new points, in units of the local bite rho
    margin: minimum distance of new points from the surface, in units of rho
    Raises ValueError when the mesh is too coarse or too thin for three layers.
    """
    inside = inside or InsideTest(visual_vertices, visual_faces)
    distance = distance or SurfaceDistance(visual_vertices, visual_faces)
    points = np.asarray(surface_points, dtype=np.float64)
    layer = np.zeros(len(points), dtype=np.int64)
    edges = unique_edges(surface_faces)
    spacing = float(np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1).mean())
    volume_floor = 1e-6 * spacing ** 3

    a, b, c = (points[surface_faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    front_faces, inward = surface_faces, -normal
    from .decimate import roundness
    for front in (1, 2):
        if len(front_faces) == 0:
            break
        candidates, rho = biting_sphere_apexes(points, front_faces, inward)
        quality = roundness(points, front_faces)
        kept = _pack(candidates, rho, quality, points, packing=packing, inside=inside,
                     distance=distance, margin=margin)
        log.debug("front %d: %d faces, %d candidates kept", front, len(front_faces), len(kept))
        if len(kept) == 0:
            break
        points = np.concatenate([points, candidates[kept]])
        layer = np.concatenate([layer, np.full(len(kept), front, dtype=np.int64)])
        if front == 2:
            break
        tets = _kept_tetrahedra(points, inside, volume_floor=volume_floor)
        front_faces, outer = _front_faces(tets, layer, front)
        if len(front_faces) == 0:
            break
        fa, fb, fc = (points[front_faces[:, i]] for i in range(3))
        normal = np.cross(fb - fa, fc - fa)
        normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
        away = (fa + fb + fc) / 3.0 - points[outer]
        flip = np.einsum("ij,ij->i", normal, away) < 0
        normal[flip] *= -1
        inward = normal

    counts = np.bincount(layer, minlength=3)
    if counts[1] < 4 or counts[2] < 4:
        raise ValueError(
            f"too few nodes for three layers: the decimated surface has {counts[0]} vertices "
            f"(mean edge {spacing:.3g} m) and only {counts[1]} foam and {counts[2]} cavity nodes "
            f"fit inside it (each inner layer needs at least 4). The puppet is too thin for "
            f"this spacing: ask for more masses so the surface is finer")
    tets = _kept_tetrahedra(points, inside, volume_floor=volume_floor)
    # interior nodes that no kept tetrahedron uses would float free: drop them
    used = np.zeros(len(points), dtype=bool)
    used[tets.ravel()] = True
    used[layer == 0] = True
    if not used.all():
        renumber = np.cumsum(used) - 1
        tets = renumber[tets]
        points = points[used]
        layer = layer[used]
    counts = np.bincount(layer, minlength=3)
    if counts[1] < 4 or counts[2] < 4:
        raise ValueError(f"too few connected interior nodes for three layers ({counts[1]} foam, "
                         f"{counts[2]} cavity); ask for more masses")
    tet_edges = np.concatenate([tets[:, [i, j]] for i, j in ((0, 1), (0, 2), (0, 3), (1, 2),
                                                                 (1, 3), (2, 3))])
    springs = unique_rows(np.sort(np.concatenate([tet_edges, unique_edges(surface_faces)]),
                                  axis=1))
    return Layers(points, layer, tets, material_layer(layer[tets]), springs,
                  material_layer(layer[springs]), np.asarray(surface_faces, dtype=np.int64))


def material_layer(node_layers: np.ndarray) -> np.ndarray:
    """(K,) int64 material layer of elements whose node layers are (K, c): 0 when all nodes
    are skin nodes, 2 when all are cavity nodes, 1 (foam) otherwise."""
    out = np.ones(len(node_layers), dtype=np.int64)
    out[(node_layers == 0).all(1)] = 0
    out[(node_layers == 2).all(1)] = 2
    return out
