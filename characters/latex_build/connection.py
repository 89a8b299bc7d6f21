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


def build_connection(vertices: np.ndarray, faces: np.ndarray, kept: np.ndarray, *,
                     connectors: int = 3) -> ConnectionMap:
    """Connect each visual vertex (V, 3) to its `connectors` nearest decimated vertices.

    kept (n,) int: the visual vertex index of each decimated vertex (decimation keeps a subset).
    Raises ValueError if some visual vertex reaches no decimated vertex along the edges (a
    mesh component that decimation emptied)."""
    if connectors < 1:
        raise ValueError(f"connectors must be >= 1, got {connectors}")
    starts, neighbours, lengths = edge_graph(vertices, faces)
    kept = np.ascontiguousarray(kept, dtype=np.int64)
    found, distance = nearest_sources(starts, neighbours, lengths, kept, int(connectors))
    unreached = found[:, 0] < 0
    if unreached.any():
        raise ValueError(f"{int(unreached.sum())} visual vertices reach no decimated vertex "
                         f"along the mesh edges (a separate mesh part lost all its vertices); "
                         f"ask for more masses")
    valid = found >= 0
    with np.errstate(divide="ignore"):
        inverse = np.where(valid, 1.0 / distance, 0.0)
    exact = distance[:, 0] == 0.0
    inverse[exact] = 0.0
    inverse[exact, 0] = 1.0
    weights = inverse / inverse.sum(1, keepdims=True)
    keep = valid & (weights > 0)  # zero-weight slots stay out of the matrix
    indptr = np.zeros(len(vertices) + 1, dtype=np.int64)
    np.cumsum(keep.sum(1), out=indptr[1:])
    return ConnectionMap(indptr, found[keep].astype(np.int64), weights[keep], len(kept))
