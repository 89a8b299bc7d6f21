"""Decimation of the puppet surface (paper section 4.1) and the measures that compare it.

Each step removes one vertex v by collapsing it into a neighbour u (a half-edge collapse: the
kept vertices are a subset of the input's, so finger regions and the connection map can refer to
them by index). The removal priority of v is its cheapest valid collapse:

    cost(v -> u) = lambda * roundness_error + (1 - lambda) * quadric_error

- roundness: R = circumradius / shortest edge of each triangle the collapse would create,
  normalised R* = (1 / sqrt 3) / R (1 for an equilateral triangle, -> 0 for a sliver); the
  roundness error is the worst new triangle's 1 - R*. (The paper writes the minimum over the
  new faces; the worst face is what keeps every triangle round, so that is the one used.)
- quadric (Garland-Heckbert): sqrt(u^T (Q_v + Q_u) u) / h, the accumulated plane-distance error
  at the kept position, as a fraction of the target edge length h, so that lambda weighs two
  dimensionless numbers.
- normal flipping: the largest angle between a new face normal and v's vertex normal (and the
  face's own normal before the collapse); a collapse at or above the threshold tau is rejected
  outright, which also keeps strongly curved places (lip edges, eyelids) from being flattened.

The vertex with the lowest cost goes first; costs around the kept vertex are recomputed after
each collapse, and a popped vertex is re-evaluated before it is removed (lazy priority queue).
Decimation stops at the requested vertex count or when no valid collapse is left.
"""
from __future__ import annotations

import heapq
import logging
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .surface import SurfaceDistance, face_normals

log = logging.getLogger(__name__)

_JIT = dict(cache=True, nogil=True, error_model="numpy")
_CAPACITY = 48  # faces around one vertex; a collapse that would exceed it is not made
_INV_SQRT3 = 1.0 / math.sqrt(3.0)


# --- per-triangle measures (pure, vectorised) ------------------------------------------------

def roundness(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Normalised roundness R* (F,) float in [0, 1] of each face: (1/sqrt 3) * shortest edge /
    circumradius; 1 for equilateral triangles, 0 for degenerate ones."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    la = np.linalg.norm(b - c, axis=1)
    lb = np.linalg.norm(c - a, axis=1)
    lc = np.linalg.norm(a - b, axis=1)
    double_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        circumradius = la * lb * lc / (2.0 * double_area)
        value = _INV_SQRT3 * np.minimum(np.minimum(la, lb), lc) / circumradius
    return np.where(double_area > 0, np.clip(value, 0.0, 1.0), 0.0)


def plane_quadrics(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Garland-Heckbert quadric of each vertex, (V, 10) float [m^2 at a unit point]: the upper
    triangle (q11 q12 q13 q14 q22 q23 q24 q33 q34 q44) of sum over incident faces of p p^T, with
    p = (n, -n . x0) the face's plane."""
    normals, _ = face_normals(vertices, faces)
    d = -np.einsum("ij,ij->i", normals, vertices[faces[:, 0]])
    p = np.concatenate([normals, d[:, None]], axis=1)
    rows, cols = np.triu_indices(4)
    per_face = p[:, rows] * p[:, cols]
    q = np.zeros((len(vertices), 10))
    for corner in range(3):
        np.add.at(q, faces[:, corner], per_face)
    return q


# --- compiled kernel -------------------------------------------------------------------------

@njit(**_JIT)
def _quadric_error(q, i, j, p):
    x, y, z = p[0], p[1], p[2]
    terms = (x * x, 2 * x * y, 2 * x * z, 2 * x, y * y, 2 * y * z, 2 * y, z * z, 2 * z, 1.0)
    total = 0.0
    for k in range(10):
        total += (q[i, k] + q[j, k]) * terms[k]
    return total


@njit(**_JIT)
def _neighbours(v, faces, vf, vf_n, out):
    count = 0
    for k in range(vf_n[v]):
        f = vf[v, k]
        for c in range(3):
            w = faces[f, c]
            if w == v:
                continue
            seen = False
            for i in range(count):
                if out[i] == w:
                    seen = True
                    break
            if not seen:
                out[count] = w
                count += 1
    return count


@njit(**_JIT)
def _vertex_normal(v, vertices, faces, vf, nf):
    """v's area-weighted unit normal as a 3-tuple, and the normal's length before scaling
    (0: undefined)."""
    nx = 0.0
    ny = 0.0
    nz = 0.0
    for k in range(nf):
        f = vf[v, k]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ux = vertices[b, 0] - vertices[a, 0]
        uy = vertices[b, 1] - vertices[a, 1]
        uz = vertices[b, 2] - vertices[a, 2]
        wx = vertices[c, 0] - vertices[a, 0]
        wy = vertices[c, 1] - vertices[a, 1]
        wz = vertices[c, 2] - vertices[a, 2]
        nx += uy * wz - uz * wy
        ny += uz * wx - ux * wz
        nz += ux * wy - uy * wx
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    if length == 0.0:
        return (0.0, 0.0, 0.0), 0.0
    return (nx / length, ny / length, nz / length), length


@njit(**_JIT)
def _link_holds(count_v, nb_v, count_u, nb_u, vf_n):
    """The link condition of collapsing v into u: exactly two shared neighbours, none of
    valence 3 (else the collapse pinches the surface)."""
    common = 0
    for i in range(count_v):
        for j in range(count_u):
            if nb_v[i] == nb_u[j]:
                common += 1
                if vf_n[nb_v[i]] <= 3:
                    return False
    return common == 2


@njit(**_JIT)
def _worst_new_face(v, u, surface, normal, rule):
    """The worst roundness error (1 - R*) among the faces that collapsing v into u creates;
    -1 when the collapse is rejected (a sliver, or a face normal turned past tau)."""
    vertices, faces, vf, vf_n = surface[0], surface[1], surface[2], surface[3]
    cos_tau, area_floor = rule[1], rule[3]
    nvx, nvy, nvz = normal
    worst = 0.0
    for k in range(vf_n[v]):
        f = vf[v, k]
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        if i0 == u or i1 == u or i2 == u:
            continue
        # the face before (i0 i1 i2) and after (v replaced by u)
        ax, ay, az = vertices[i0, 0], vertices[i0, 1], vertices[i0, 2]
        bx, by, bz = vertices[i1, 0], vertices[i1, 1], vertices[i1, 2]
        cx, cy, cz = vertices[i2, 0], vertices[i2, 1], vertices[i2, 2]
        ox = (by - ay) * (cz - az) - (bz - az) * (cy - ay)
        oy = (bz - az) * (cx - ax) - (bx - ax) * (cz - az)
        oz = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if i0 == v:
            ax, ay, az = vertices[u, 0], vertices[u, 1], vertices[u, 2]
        elif i1 == v:
            bx, by, bz = vertices[u, 0], vertices[u, 1], vertices[u, 2]
        else:
            cx, cy, cz = vertices[u, 0], vertices[u, 1], vertices[u, 2]
        nx = (by - ay) * (cz - az) - (bz - az) * (cy - ay)
        ny = (bz - az) * (cx - ax) - (bx - ax) * (cz - az)
        nz = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        double_area = np.sqrt(nx * nx + ny * ny + nz * nz)
        if double_area <= area_floor:
            return -1.0
        nx /= double_area
        ny /= double_area
        nz /= double_area
        old_length = np.sqrt(ox * ox + oy * oy + oz * oz)
        if nx * nvx + ny * nvy + nz * nvz < cos_tau:
            return -1.0
        if old_length > 0.0 and (nx * ox + ny * oy + nz * oz) / old_length < cos_tau:
            return -1.0
        la = np.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
        lb = np.sqrt((cx - bx) ** 2 + (cy - by) ** 2 + (cz - bz) ** 2)
        lc = np.sqrt((ax - cx) ** 2 + (ay - cy) ** 2 + (az - cz) ** 2)
        circumradius = la * lb * lc / (2.0 * double_area)
        r_star = 0.5773502691896258 * min(la, lb, lc) / circumradius
        if 1.0 - r_star > worst:
            worst = 1.0 - r_star
    return worst


@njit(**_JIT)
def _evaluate(v, surface, rule, scratch):
    """(cost, best neighbour) of removing v; (inf, -1) when no collapse is valid.

    surface : (vertices, faces, vf, vf_n, q, locked), the mesh as the collapses left it
    rule : (lambda, cos tau, 1 / h, area floor), the cost's weights and rejection limits
    scratch : (nb_v, nb_u), two neighbour lists of 2 * capacity + 2 entries"""
    vertices, faces, vf, vf_n, q, locked = surface
    lam, inv_h = rule[0], rule[2]
    nb_v, nb_u = scratch
    nf = vf_n[v]
    if locked[v] or nf < 3:
        return np.inf, -1
    normal, length = _vertex_normal(v, vertices, faces, vf, nf)
    if length == 0.0:
        return np.inf, -1
    count_v = _neighbours(v, faces, vf, vf_n, nb_v)
    if count_v != nf:  # a closed manifold vertex has as many neighbours as faces
        return np.inf, -1
    best = np.inf
    best_u = -1
    for iu in range(count_v):
        u = nb_v[iu]
        new_valence = vf_n[u] + nf - 4
        if new_valence > vf.shape[1] or new_valence < 3:
            continue
        count_u = _neighbours(u, faces, vf, vf_n, nb_u)
        if not _link_holds(count_v, nb_v, count_u, nb_u, vf_n):
            continue
        worst = _worst_new_face(v, u, surface, normal, rule)
        if worst < 0.0:
            continue
        dq = _quadric_error(q, u, v, vertices[u])
        cost = lam * worst + (1.0 - lam) * np.sqrt(max(dq, 0.0)) * inv_h
        if cost < best:
            best = cost
            best_u = u
    return best, best_u


@njit(**_JIT)
def _remove_face(w, f, vf, vf_n):
    for k in range(vf_n[w]):
        if vf[w, k] == f:
            vf[w, k] = vf[w, vf_n[w] - 1]
            vf_n[w] -= 1
            return


@njit(**_JIT)
def _collapse(v, u, faces, face_alive, vf, vf_n, q):
    for k in range(vf_n[v]):
        f = vf[v, k]
        if faces[f, 0] == u or faces[f, 1] == u or faces[f, 2] == u:
            face_alive[f] = False
            for c in range(3):
                w = faces[f, c]
                if w != v:
                    _remove_face(w, f, vf, vf_n)
        else:
            for c in range(3):
                if faces[f, c] == v:
                    faces[f, c] = u
            vf[u, vf_n[u]] = f
            vf_n[u] += 1
    vf_n[v] = 0
    q[u] += q[v]


@njit(**_JIT)
def _setup(vertices, faces, capacity):
    """Vertex -> face incidence (vf (V, capacity), vf_n (V,)) and per-vertex plane quadrics
    q (V, 10), as in plane_quadrics."""
    vertex_count = vertices.shape[0]
    face_count = faces.shape[0]
    vf = np.full((vertex_count, capacity), -1, dtype=np.int64)
    vf_n = np.zeros(vertex_count, dtype=np.int64)
    for f in range(face_count):
        for c in range(3):
            w = faces[f, c]
            if vf_n[w] < capacity:
                vf[w, vf_n[w]] = f
                vf_n[w] += 1
    q = np.zeros((vertex_count, 10))
    for f in range(face_count):
        a = vertices[faces[f, 0]]
        n = np.cross(vertices[faces[f, 1]] - a, vertices[faces[f, 2]] - a)
        length = np.sqrt(n @ n)
        if length == 0.0:
            continue
        n /= length
        p = np.array([n[0], n[1], n[2], -(n @ a)])
        row = 0
        qq = np.zeros(10)
        for i in range(4):
            for j in range(i, 4):
                qq[row] = p[i] * p[j]
                row += 1
        for c in range(3):
            q[faces[f, c]] += qq
    return vf, vf_n, q


@njit(**_JIT)
def removal_cost_kernel(vertices, faces, locked, rule, capacity):
    """Initial removal priority of every vertex: cost (V,) and best neighbour (V,) (-1: none).
    rule as in _evaluate."""
    vf, vf_n, q = _setup(vertices, faces, capacity)
    surface = (vertices, faces, vf, vf_n, q, locked)
    scratch = (np.empty(2 * capacity + 2, dtype=np.int64),
               np.empty(2 * capacity + 2, dtype=np.int64))
    cost = np.full(vertices.shape[0], np.inf)
    target = np.full(vertices.shape[0], -1, dtype=np.int64)
    for v in range(vertices.shape[0]):
        cost[v], target[v] = _evaluate(v, surface, rule, scratch)
    return cost, target


@njit(**_JIT)
def decimate_kernel(vertices, faces, locked, target_count, rule, capacity):
    """Half-edge collapse decimation (rule as in _evaluate); returns (alive (V,) bool,
    face_alive (F,) bool, faces (F, 3) int64 rewritten, removed count, stopped_early)."""
    vertex_count = vertices.shape[0]
    face_count = faces.shape[0]
    faces = faces.copy()
    face_alive = np.ones(face_count, dtype=np.bool_)
    vf, vf_n, q = _setup(vertices, faces, capacity)
    alive = vf_n > 0
    alive_count = 0
    for i in range(vertex_count):
        if alive[i]:
            alive_count += 1
    surface = (vertices, faces, vf, vf_n, q, locked)
    scratch = (np.empty(2 * capacity + 2, dtype=np.int64),
               np.empty(2 * capacity + 2, dtype=np.int64))
    nb_w = np.empty(2 * capacity + 2, dtype=np.int64)
    stamp = np.zeros(vertex_count, dtype=np.int64)
    heap = [(0.0, np.int64(0), np.int64(0))]
    heap.pop()
    for v in range(vertex_count):
        if alive[v]:
            cost, u = _evaluate(v, surface, rule, scratch)
            if u >= 0:
                heap.append((cost, np.int64(v), np.int64(0)))
    heapq.heapify(heap)
    removed = 0
    while alive_count > target_count and len(heap) > 0:
        cost, v, s = heapq.heappop(heap)
        if not alive[v] or s != stamp[v]:
            continue
        fresh, u = _evaluate(v, surface, rule, scratch)
        stamp[v] += 1
        if u < 0:
            continue
        if fresh > cost + 1e-12:
            heapq.heappush(heap, (fresh, v, stamp[v]))
            continue
        _collapse(v, u, faces, face_alive, vf, vf_n, q)
        alive[v] = False
        alive_count -= 1
        removed += 1
        count = _neighbours(u, faces, vf, vf_n, nb_w)
        for i in range(count + 1):
            w = u if i == count else nb_w[i]
            stamp[w] += 1
            c2, u2 = _evaluate(w, surface, rule, scratch)
            if u2 >= 0:
                heapq.heappush(heap, (c2, w, stamp[w]))
    return alive, face_alive, faces, removed, alive_count > target_count


# --- Python entry point ----------------------------------------------------------------------

@dataclass
class Decimation:
    """A decimated surface whose vertices are a subset of the input's.

    kept : (n,) int64 input vertex index of each decimated vertex
    faces : (F', 3) int64 triangles over the decimated vertices (0..n-1), outward wound
    stopped_early : True when no valid collapse was left before the target count
    """

    kept: np.ndarray
    faces: np.ndarray
    stopped_early: bool
    target_vertices: int


def _rule(roundness_weight: float, normal_threshold: float, h: float) -> tuple:
    """The kernels' cost rule: (lambda, cos tau, 1 / h, area floor [m^2 doubled])."""
    return (float(roundness_weight), math.cos(math.radians(normal_threshold)), 1.0 / h,
            (h * 1e-6) ** 2)


def target_edge_length(vertices: np.ndarray, faces: np.ndarray, vertex_count: int) -> float:
    """Edge length [m] of an equilateral triangulation of the same area with vertex_count
    vertices (a closed surface has about twice as many faces as vertices)."""
    _, areas = face_normals(vertices, faces)
    return math.sqrt(2.0 * float(areas.sum()) / (math.sqrt(3.0) * max(vertex_count, 4)))


def decimate(vertices: np.ndarray, faces: np.ndarray, *, target_vertices: int,
             roundness_weight: float = 0.5, normal_threshold: float = 60.0,
             locked: np.ndarray | None = None) -> Decimation:
    """Decimate a closed surface to about target_vertices vertices (paper 4.1).

    vertices : (V, 3) float [m]; faces : (F, 3) int (closed, outward wound)
    roundness_weight : lambda in [0, 1]; 0 = quadric error only, 1 = roundness only
    normal_threshold : tau [degrees]; collapses that turn a face normal this far are rejected
    locked : (V,) bool or indices: vertices that are never removed (finger regions)
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if not 0.0 <= roundness_weight <= 1.0:
        raise ValueError(f"roundness_weight (lambda) must be in [0, 1], got {roundness_weight}")
    if not 0.0 < normal_threshold <= 180.0:
        raise ValueError(f"normal_threshold must be an angle in (0, 180] degrees, got "
                         f"{normal_threshold}")
    target_vertices = int(target_vertices)
    if target_vertices < 4:
        raise ValueError(f"target_vertices must be >= 4 (a tetrahedron), got {target_vertices}")
    mask = np.zeros(len(vertices), dtype=np.bool_)
    if locked is not None:
        locked = np.asarray(locked)
        if locked.dtype == bool:
            mask[:] = locked
        else:
            mask[locked.astype(np.int64)] = True
    h = target_edge_length(vertices, faces, target_vertices)
    alive, face_alive, new_faces, _, stopped = decimate_kernel(
        vertices, faces, mask, target_vertices, _rule(roundness_weight, normal_threshold, h),
        _CAPACITY)
    kept = np.flatnonzero(alive)
    renumber = np.full(len(vertices), -1, dtype=np.int64)
    renumber[kept] = np.arange(len(kept))
    out_faces = renumber[new_faces[face_alive]]
    if stopped:
        log.info("decimation stopped at %d vertices (asked for %d): no collapse left below the "
                 "normal threshold %.0f deg", len(kept), target_vertices, normal_threshold)
    return Decimation(kept, out_faces, bool(stopped), target_vertices)


def removal_costs(vertices: np.ndarray, faces: np.ndarray, *, target_vertices: int,
                  roundness_weight: float = 0.5, normal_threshold: float = 60.0,
                  locked=None) -> tuple[np.ndarray, np.ndarray]:
    """The priority each vertex starts with: cost (V,) float (inf: no valid collapse) and the
    neighbour it would collapse into (V,) int (-1: none). Same arguments as `decimate`."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    mask = np.zeros(len(vertices), dtype=np.bool_)
    if locked is not None:
        mask[np.asarray(locked)] = True
    h = target_edge_length(vertices, faces, target_vertices)
    return removal_cost_kernel(vertices, faces, mask,
                               _rule(roundness_weight, normal_threshold, h), _CAPACITY)


# --- comparison with plain quadric decimation -----------------------------------------------

def quadric_reference(vertices: np.ndarray, faces: np.ndarray, *, target_faces: int):
    """Plain Garland-Heckbert decimation by fast-simplification (through trimesh), the
    reference the paper's combination is compared with. Returns (vertices, faces)."""
    try:
        import trimesh
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        out = mesh.simplify_quadric_decimation(face_count=int(target_faces))
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("the quadric reference needs trimesh and fast-simplification: "
                          "pip install 'mop[mesh]'") from error
    return np.asarray(out.vertices, dtype=np.float64), np.asarray(out.faces, dtype=np.int64)


def surface_samples(vertices: np.ndarray, faces: np.ndarray, count: int,
                    rng: np.random.Generator) -> np.ndarray:
    """(count + V, 3) points: the vertices plus area-uniform random points on the faces."""
    _, areas = face_normals(vertices, faces)
    chosen = rng.choice(len(faces), size=count, p=areas / areas.sum())
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    a, b, c = (vertices[faces[chosen, i]] for i in range(3))
    points = (1 - r1)[:, None] * a + (r1 * (1 - r2))[:, None] * b + (r1 * r2)[:, None] * c
    return np.concatenate([vertices, points])


def hausdorff(vertices_a, faces_a, vertices_b, faces_b, *, samples: int = 20000,
              seed: int = 0) -> float:
    """Symmetric Hausdorff distance [m] between two surfaces, from `samples` area-uniform points
    (plus the vertices) on each, measured exactly to the other surface."""
    rng = np.random.default_rng(seed)
    to_b = SurfaceDistance(vertices_b, faces_b)(surface_samples(vertices_a, faces_a, samples, rng))
    to_a = SurfaceDistance(vertices_a, faces_a)(surface_samples(vertices_b, faces_b, samples, rng))
    return float(max(to_b.max(), to_a.max()))


@dataclass
class QualityReport:
    """Triangle quality and shape error of one decimated surface."""

    vertices: int
    faces: int
    roundness_min: float
    roundness_p05: float
    roundness_mean: float
    sliver_share: float  # share of faces with R* < 0.5
    hausdorff: float  # [m]
    hausdorff_relative: float  # / bounding box diagonal


def quality(original_vertices, original_faces, vertices, faces, *, samples: int = 20000,
            seed: int = 0) -> QualityReport:
    r = roundness(vertices, faces)
    distance = hausdorff(original_vertices, original_faces, vertices, faces, samples=samples,
                         seed=seed)
    diagonal = float(np.linalg.norm(original_vertices.max(0) - original_vertices.min(0)))
    return QualityReport(len(vertices), len(faces), float(r.min()), float(np.percentile(r, 5)),
                         float(r.mean()), float((r < 0.5).mean()), distance, distance / diagonal)
