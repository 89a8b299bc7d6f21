"""The connection map (paper equations 3-4): the visual mesh follows the decimated surface.

Each visual vertex i is connected to its nearest decimated vertices j by edge distance (the
length of the shortest path along the visual mesh's edges, so a vertex of the upper lip never
connects to the lower lip across the mouth slit). The weights fall with that distance and sum to
one,

    w_ij = (1 / delta_ij) / sum_k (1 / delta_ik)

(a vertex that is itself a decimated vertex follows it alone), and after every step

    T(v_i) = sum_j w_ij T(v_j),      visual_i = visual_rest_i + T(v_i).

Equation 3 as printed divides each distance by the sum of distances, which would give the
farther connector the larger weight; the weight used here is its inverse-distance reading.
The weights are a sparse (V, n) matrix built once; applying it is one CSR product per frame.

Distance weights interpolate like Shepard's method: around each decimated vertex the visual
surface keeps a small dimple when the coarse mesh rotates (the rendered frog looked pebbly with
its jaw open). `weighting="barycentric"` keeps equation 4 and the edge-distance neighbourhood
but weighs the three corners of the nearest decimated triangle by the barycentric coordinates
of the vertex's closest point on it, which follows rotations smoothly.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np
from numba import njit

_JIT = dict(cache=True, nogil=True, error_model="numpy")


def edge_graph(vertices: np.ndarray, faces: np.ndarray):
    """CSR adjacency of the mesh edges: starts (V+1,) int64, neighbours (2E,) int64, lengths
    (2E,) float [m]."""
    edges = np.unique(np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    both = np.concatenate([edges, edges[:, ::-1]])
    order = np.lexsort((both[:, 1], both[:, 0]))
    both = both[order]
    starts = np.zeros(len(vertices) + 1, dtype=np.int64)
    np.add.at(starts, both[:, 0] + 1, 1)
    np.cumsum(starts, out=starts)
    lengths = np.linalg.norm(vertices[both[:, 0]] - vertices[both[:, 1]], axis=1)
    return starts, np.ascontiguousarray(both[:, 1]), lengths


@njit(**_JIT)
def nearest_sources(starts, neighbours, lengths, sources, k):
    """The k nearest sources of every vertex by shortest-path distance (multi-source Dijkstra
    that lets each vertex be settled once per source, up to k sources).

    Returns found (V, k) int64 source positions in `sources` (-1 = fewer reachable) and
    distance (V, k) float [m], each row sorted by distance."""
    vertex_count = starts.shape[0] - 1
    found = np.full((vertex_count, k), -1, dtype=np.int64)
    distance = np.full((vertex_count, k), np.inf)
    settled = np.zeros(vertex_count, dtype=np.int64)
    heap = [(0.0, np.int64(0), np.int64(0))]
    heap.pop()
    for s in range(sources.shape[0]):
        heap.append((0.0, np.int64(sources[s]), np.int64(s)))
    heapq.heapify(heap)
    while len(heap) > 0:
        d, v, s = heapq.heappop(heap)
        if settled[v] >= k:
            continue
        duplicate = False
        for i in range(settled[v]):
            if found[v, i] == s:
                duplicate = True
                break
        if duplicate:
            continue
        found[v, settled[v]] = s
        distance[v, settled[v]] = d
        settled[v] += 1
        for e in range(starts[v], starts[v + 1]):
            w = neighbours[e]
            if settled[w] >= k:
                continue
            seen = False
            for i in range(settled[w]):
                if found[w, i] == s:
                    seen = True
                    break
            if not seen:
                heapq.heappush(heap, (d + lengths[e], w, s))
    return found, distance


@njit(**_JIT)
def apply_connection(indptr, indices, weights, rest_visual, node_rest, node_x, out):
    """out (V, 3) = rest_visual + W (node_x - node_rest), W in CSR (indptr, indices, weights);
    node arrays (n, 3) [m]. No allocation."""
    for i in range(out.shape[0]):
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            w = weights[p]
            tx += w * (node_x[j, 0] - node_rest[j, 0])
            ty += w * (node_x[j, 1] - node_rest[j, 1])
            tz += w * (node_x[j, 2] - node_rest[j, 2])
        out[i, 0] = rest_visual[i, 0] + tx
        out[i, 1] = rest_visual[i, 1] + ty
        out[i, 2] = rest_visual[i, 2] + tz


@njit(**_JIT)
def _closest_barycentric(p, a, b, c):
    """Barycentric weights (wa, wb, wc) >= 0 of the point of triangle abc closest to p, and the
    squared distance (Ericson, Real-Time Collision Detection 5.1.5)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = ab @ ap
    d2 = ac @ ap
    if d1 <= 0.0 and d2 <= 0.0:
        wa, wb, wc = 1.0, 0.0, 0.0
    else:
        bp = p - b
        d3 = ab @ bp
        d4 = ac @ bp
        vc = d1 * d4 - d3 * d2
        cp = p - c
        d5 = ab @ cp
        d6 = ac @ cp
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            wa, wb, wc = 0.0, 1.0, 0.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            t = d1 / (d1 - d3)
            wa, wb, wc = 1.0 - t, t, 0.0
        elif d6 >= 0.0 and d5 <= d6:
            wa, wb, wc = 0.0, 0.0, 1.0
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            t = d2 / (d2 - d6)
            wa, wb, wc = 1.0 - t, 0.0, t
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            wa, wb, wc = 0.0, 1.0 - t, t
        else:
            denom = 1.0 / (va + vb + vc)
            wb = vb * denom
            wc = vc * denom
            wa = 1.0 - wb - wc
    q = wa * a + wb * b + wc * c
    e = p - q
    return wa, wb, wc, e @ e


@njit(**_JIT)
def barycentric_weights(points, node_points, node_faces, face_starts, face_items, found,
                        out_nodes, out_weights):
    """For each point, the decimated triangle around its candidate nodes (found (P, k), -1 =
    none) that comes closest to it, and the barycentric weights of that closest point.
    Writes out_nodes (P, 3) (-1 where no candidate triangle exists) and out_weights (P, 3)."""
    for i in range(points.shape[0]):
        best = np.inf
        out_nodes[i, 0] = -1
        for a in range(found.shape[1]):
            j = found[i, a]
            if j < 0:
                continue
            for e in range(face_starts[j], face_starts[j + 1]):
                f = face_items[e]
                wa, wb, wc, d2 = _closest_barycentric(points[i], node_points[node_faces[f, 0]],
                                                      node_points[node_faces[f, 1]],
                                                      node_points[node_faces[f, 2]])
                if d2 < best:
                    best = d2
                    for c in range(3):
                        out_nodes[i, c] = node_faces[f, c]
                    out_weights[i, 0] = wa
                    out_weights[i, 1] = wb
                    out_weights[i, 2] = wc


@dataclass
class ConnectionMap:
    """Sparse weights (V, n) in CSR arrays: indptr (V+1,), indices (nnz,) node index,
    weights (nnz,) float, rows summing to one."""

    indptr: np.ndarray
    indices: np.ndarray
    weights: np.ndarray
    node_count: int

    def matrix(self):
        """The weights as a scipy.sparse.csr_matrix of shape (V, n)."""
        from scipy.sparse import csr_matrix
        return csr_matrix((self.weights, self.indices, self.indptr),
                          shape=(len(self.indptr) - 1, self.node_count))


class Skin:
    """The visual mesh from the surface nodes, picklable (a render process can draw a puppet
    from its n surface nodes instead of its V visual vertices): `skin(nodes, out)` writes
    out (V, 3) = rest + W (nodes - node_rest) for nodes (n, 3) [m] and returns it."""

    def __init__(self, connection: ConnectionMap, rest_visual: np.ndarray,
                 node_rest: np.ndarray):
        self.indptr, self.indices = connection.indptr, connection.indices
        self.weights = connection.weights
        self.rest_visual = np.ascontiguousarray(rest_visual, dtype=np.float64)
        self.node_rest = np.ascontiguousarray(node_rest, dtype=np.float64)
        self.shape = self.rest_visual.shape

    def __call__(self, nodes: np.ndarray, out: np.ndarray) -> np.ndarray:
        apply_connection(self.indptr, self.indices, self.weights, self.rest_visual,
                         self.node_rest, nodes, out)
        return out


WEIGHTINGS = ("distance", "barycentric")


def build_connection(vertices: np.ndarray, faces: np.ndarray, kept: np.ndarray, *,
                     connectors: int = 3, weighting: str = "distance",
                     surface_faces: np.ndarray | None = None) -> ConnectionMap:
    """Connect each visual vertex (V, 3) to its nearest decimated vertices by edge distance.

    kept (n,) int: the visual vertex index of each decimated vertex (decimation keeps a subset).
    weighting "distance" (equation 3): the `connectors` nearest, inverse edge distance weights.
    weighting "barycentric": among the decimated triangles (surface_faces (F_s, 3), over the
    decimated vertices) around a vertex's 2 * connectors + 2 nearest, the one closest to it,
    with the barycentric weights of the closest point: an affine deformation of the decimated
    surface then moves the visual mesh exactly affinely (no dimples around the nodes); where
    no such triangle exists the distance weights are used.
    Raises ValueError if some visual vertex reaches no decimated vertex along the edges."""
    if connectors < 1:
        raise ValueError(f"connectors must be >= 1, got {connectors}")
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    if weighting == "barycentric" and surface_faces is None:
        raise ValueError("barycentric weighting needs the decimated surface_faces")
    starts, neighbours, lengths = edge_graph(vertices, faces)
    kept = np.ascontiguousarray(kept, dtype=np.int64)
    reach = connectors if weighting == "distance" else 2 * connectors + 2
    found, distance = nearest_sources(starts, neighbours, lengths, kept, int(reach))
    unreached = found[:, 0] < 0
    if unreached.any():
        raise ValueError(f"{int(unreached.sum())} visual vertices reach no decimated vertex "
                         f"along the mesh edges (a separate mesh part lost all its vertices); "
                         f"ask for more masses")
    near = found[:, :connectors]
    valid = near >= 0
    with np.errstate(divide="ignore"):
        inverse = np.where(valid, 1.0 / distance[:, :connectors], 0.0)
    exact = distance[:, 0] == 0.0
    inverse[exact] = 0.0
    inverse[exact, 0] = 1.0
    nodes = np.where(valid, near, -1)
    weights = inverse / inverse.sum(1, keepdims=True)
    if weighting == "barycentric":
        node_faces = np.ascontiguousarray(surface_faces, dtype=np.int64)
        order = np.argsort(node_faces.ravel(), kind="stable")
        face_items = (order // 3).astype(np.int64)
        face_starts = np.zeros(len(kept) + 1, dtype=np.int64)
        np.add.at(face_starts, node_faces.ravel() + 1, 1)
        np.cumsum(face_starts, out=face_starts)
        tri_nodes = np.full((len(vertices), 3), -1, dtype=np.int64)
        tri_weights = np.zeros((len(vertices), 3))
        barycentric_weights(np.ascontiguousarray(vertices, dtype=np.float64),
                            np.ascontiguousarray(vertices[kept], dtype=np.float64), node_faces,
                            face_starts, face_items, np.ascontiguousarray(found), tri_nodes,
                            tri_weights)
        use = (tri_nodes[:, 0] >= 0) & ~exact
        pad = max(connectors, 3)
        merged_nodes = np.full((len(vertices), pad), -1, dtype=np.int64)
        merged_weights = np.zeros((len(vertices), pad))
        merged_nodes[:, :connectors] = nodes
        merged_weights[:, :connectors] = weights
        merged_nodes[use] = -1
        merged_weights[use] = 0.0
        merged_nodes[use, :3] = tri_nodes[use]
        merged_weights[use, :3] = tri_weights[use]
        nodes, weights = merged_nodes, merged_weights
    keep = (nodes >= 0) & (weights > 0)  # zero-weight slots stay out of the matrix
    indptr = np.zeros(len(vertices) + 1, dtype=np.int64)
    np.cumsum(keep.sum(1), out=indptr[1:])
    return ConnectionMap(indptr, nodes[keep].astype(np.int64), weights[keep], len(kept))
