"""As-rigid-as-possible shape manipulation of a 2D triangle mesh (Igarashi, Moscovich and
Hughes, SIGGRAPH 2005), the two-step closed-form version.

Step 1, scale-free construction: every triangle's vertex is expressed in the frame of the
opposite edge, v_k = v_i + x (v_j - v_i) + y R90 (v_j - v_i), with (x, y) from the rest shape.
The sum over triangles and their three vertices of |v_k' - (that expression on v_i', v_j')|^2 is
a quadratic form v^T G v in the interleaved coordinates v (2N,); it allows rotation and uniform
scale but penalises shear. With the handle vertices q fixed, the free ones solve
G00 u = -G01 q.

Step 2, scale adjustment: each triangle of the step-1 result is fitted by a copy of its rest
triangle (a 4x4 least-squares problem per triangle, the same matrix every frame) and scaled back
to its rest size; the final positions minimise sum over the triangles' edges
|(v_j - v_i) - (f_j - f_i)|^2 for the fitted edge vectors f: H00 u = b - H01 q with a graph
Laplacian H, x and y sharing the factor.

G00 and H00 depend only on the rest mesh and *which* vertices are handles, so both are
factorised once per handle set (sparse Cholesky, cached) and every frame costs two triangular
solves and some vectorised per-triangle arithmetic. With one handle the result is the rest shape
translated; with none, the rest shape.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
import scipy.sparse as sp

# rotation by +90 degrees in the (x, y) plane: R90 (a, b) = (-b, a)
R90 = np.array([[0.0, -1.0], [1.0, 0.0]])


def local_coordinates(rest: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(F, 3, 2) float: for triangle t and k = 0, 1, 2, the (x, y) with
    v_k = v_i + x (v_j - v_i) + y R90 (v_j - v_i), where i = k+1, j = k+2 (mod 3).

    rest : (N, 2) float [px]; triangles : (F, 3) int."""
    out = np.empty((len(triangles), 3, 2))
    for k in range(3):
        vi = rest[triangles[:, (k + 1) % 3]]
        vj = rest[triangles[:, (k + 2) % 3]]
        vk = rest[triangles[:, k]]
        edge = vj - vi
        rotated = edge @ R90.T
        rel = vk - vi
        length2 = np.einsum("ij,ij->i", edge, edge)
        out[:, k, 0] = np.einsum("ij,ij->i", rel, edge) / length2
        out[:, k, 1] = np.einsum("ij,ij->i", rel, rotated) / length2
    return out


def similarity_matrix(rest: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """G (2N, 2N) sparse: the step-1 error sum |v_k - v_i - x e - y R90 e|^2, e = v_j - v_i,
    as v^T G v over interleaved coordinates v = (x0, y0, x1, y1, ...)."""
    node_count = len(rest)
    local = local_coordinates(rest, triangles)
    eye = np.eye(2)
    rows, cols, vals = [], [], []
    row_base = 0
    for k in range(3):
        x = local[:, k, 0][:, None, None]
        y = local[:, k, 1][:, None, None]
        # residual = vk - (1 - x) vi - x vj - y R90 (vj - vi)
        blocks = {
            k: np.broadcast_to(eye, (len(triangles), 2, 2)),
            (k + 1) % 3: -((1.0 - x) * eye - y * R90),
            (k + 2) % 3: -(x * eye + y * R90),
        }
        for corner, block in blocks.items():
            vertex = triangles[:, corner]
            for a in range(2):
                for b in range(2):
                    rows.append(row_base + 2 * np.arange(len(triangles)) + a)
                    cols.append(2 * vertex + b)
                    vals.append(block[:, a, b])
        row_base += 2 * len(triangles)
    residual = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(row_base, 2 * node_count))
    return (residual.T @ residual).tocsr()


def edge_incidence(triangles: np.ndarray, node_count: int) -> tuple[np.ndarray, sp.csr_matrix]:
    """Every triangle's three edges (3F, 2) int (i -> j) and the (3F, N) sparse incidence
    D with D v = v_j - v_i; the step-2 Laplacian is D^T D."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    count = len(edges)
    rows = np.repeat(np.arange(count), 2)
    cols = edges[:, ::-1].ravel()           # +1 at j, -1 at i
    vals = np.tile([1.0, -1.0], count)
    return edges, sp.csr_matrix((vals, (rows, cols)), shape=(count, node_count))


def fit_matrices(rest: np.ndarray, triangles: np.ndarray):
    """Per triangle, the least-squares map fit (F, 4, 6) from its three step-1 vertices
    (a, b, c) (6,) to the fitted v0, v1 (4,) of a similar copy of the rest triangle, and
    M0, M1 (F, 2, 2) giving v2 = M0 v0 + M1 v1 (M0 = (1 - x) I - y R90, M1 = x I + y R90,
    (x, y) the rest v2 in the frame of edge 0 -> 1). Returns (fit, M0, M1)."""
    local = local_coordinates(rest, triangles)[:, 2]    # vertex 2 on edge 0 -> 1
    x = local[:, 0][:, None, None]
    y = local[:, 1][:, None, None]
    eye = np.eye(2)
    m0 = (1.0 - x) * eye - y * R90
    m1 = x * eye + y * R90
    m0t, m1t = m0.transpose(0, 2, 1), m1.transpose(0, 2, 1)
    lhs = np.empty((len(triangles), 4, 4))
    lhs[:, :2, :2] = eye + m0t @ m0
    lhs[:, :2, 2:] = m0t @ m1
    lhs[:, 2:, :2] = m1t @ m0
    lhs[:, 2:, 2:] = eye + m1t @ m1
    rhs = np.zeros((len(triangles), 4, 6))
    rhs[:, :2, :2] = eye
    rhs[:, 2:, 2:4] = eye
    rhs[:, :2, 4:] = m0t
    rhs[:, 2:, 4:] = m1t
    return np.linalg.solve(lhs, rhs), m0, m1


class _Factor:
    """One sparse SPD matrix factorised once (cholespy), solving for many right-hand sides."""

    def __init__(self, matrix: sp.spmatrix):
        import cholespy
        coo = sp.coo_matrix(matrix)
        self.size = coo.shape[0]
        self._solver = cholespy.CholeskySolverD(
            self.size, coo.row.astype(np.int32), coo.col.astype(np.int32),
            coo.data.astype(np.float64), cholespy.MatrixType.COO)

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> np.ndarray:
        self._solver.solve(np.ascontiguousarray(rhs), out)
        return out


class _HandleSystems:
    """Everything that depends on the handle set: index splits and the two factorisations."""

    def __init__(self, deformer: "ArapDeformer", handles: np.ndarray):
        node_count = deformer.node_count
        self.handles = handles
        is_handle = np.zeros(node_count, dtype=bool)
        is_handle[handles] = True
        self.free = np.flatnonzero(~is_handle)
        free2 = np.stack([2 * self.free, 2 * self.free + 1], 1).ravel()
        handle2 = np.stack([2 * handles, 2 * handles + 1], 1).ravel()
        g = deformer.similarity
        self.g_free = _Factor(g[free2][:, free2])
        self.g_coupling = g[free2][:, handle2].tocsr()
        h = deformer.laplacian
        self.h_free = _Factor(h[self.free][:, self.free])
        self.h_coupling = h[self.free][:, handles].tocsr()
        self.d_free_t = deformer.incidence[:, self.free].T.tocsr()
        self.step1 = np.empty(2 * len(self.free))
        self.step2 = np.empty((len(self.free), 2))


class ArapDeformer:
    """Two-step ARAP deformation of a fixed 2D triangle mesh.

    rest : (N, 2) float [px] rest positions; triangles : (F, 3) int (one connected mesh).
    `deform(handles, positions)` returns (N, 2) float [px]; handle sets seen before reuse their
    factorisations (`factorisations` counts how many were made).
    """

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, *, cache_size: int = 16):
        self.rest = np.array(rest, dtype=np.float64)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.node_count = len(self.rest)
        self.similarity = similarity_matrix(self.rest, self.triangles)
        self.edges, self.incidence = edge_incidence(self.triangles, self.node_count)
        self.laplacian = (self.incidence.T @ self.incidence).tocsr()
        self.fit, self._m0, self._m1 = fit_matrices(self.rest, self.triangles)
        rest_edge = self.rest[self.triangles[:, 1]] - self.rest[self.triangles[:, 0]]
        self._rest_edge_length = np.linalg.norm(rest_edge, axis=1)
        self._cache: OrderedDict = OrderedDict()
        self._cache_size = int(cache_size)
        self.factorisations = 0

    def systems(self, handles: np.ndarray) -> _HandleSystems:
        key = handles.tobytes()
        systems = self._cache.get(key)
        if systems is None:
            systems = _HandleSystems(self, handles)
            self.factorisations += 1
            self._cache[key] = systems
            if len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        return systems

    def scale_free(self, systems: _HandleSystems, positions: np.ndarray) -> np.ndarray:
        """Step 1: (N, 2) float [px], rotation and uniform scale allowed."""
        q = positions.ravel()
        rhs = -(systems.g_coupling @ q)
        systems.g_free.solve(rhs, systems.step1)
        out = np.empty((self.node_count, 2))
        out[systems.free] = systems.step1.reshape(-1, 2)
        out[systems.handles] = positions
        return out

    def fitted_edges(self, intermediate: np.ndarray) -> np.ndarray:
        """(3F, 2) float [px]: edge vectors (as in `edges`) of each triangle's rest copy fitted
        to the intermediate shape and scaled back to its rest size."""
        corners = intermediate[self.triangles].reshape(len(self.triangles), 6)
        v01 = np.einsum("fij,fj->fi", self.fit, corners)
        v0, v1 = v01[:, :2], v01[:, 2:]
        v2 = np.einsum("fij,fj->fi", self._m0, v0) + np.einsum("fij,fj->fi", self._m1, v1)
        length = np.linalg.norm(v1 - v0, axis=1)
        scale = np.divide(self._rest_edge_length, length, out=np.ones_like(length),
                          where=length > 1e-12)[:, None]
        # scaling about the centroid changes edge vectors only by the factor
        e01, e12, e20 = (v1 - v0) * scale, (v2 - v1) * scale, (v0 - v2) * scale
        return np.concatenate([e01, e12, e20])

    def deform(self, handles, positions) -> np.ndarray:
        """handles : (P,) int vertex indices; positions : (P, 2) float [px] -> (N, 2) float."""
        handles = np.asarray(handles, dtype=np.int64).ravel()
        positions = np.asarray(positions, dtype=np.float64).reshape(len(handles), 2)
        if len(handles) == 0:
            return self.rest.copy()
        order = np.argsort(handles)
        handles, positions = handles[order], positions[order]
        if np.any(np.diff(handles) == 0):
            raise ValueError(f"a vertex is given twice as a handle: {handles.tolist()}")
        if len(handles) == 1:
            return self.rest + (positions[0] - self.rest[handles[0]])
        systems = self.systems(handles)
        intermediate = self.scale_free(systems, positions)
        fitted = self.fitted_edges(intermediate)
        rhs = systems.d_free_t @ fitted - systems.h_coupling @ positions
        systems.h_free.solve(rhs, systems.step2)
        out = np.empty((self.node_count, 2))
        out[systems.free] = systems.step2
        out[handles] = positions
        return out
