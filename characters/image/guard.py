"""A position constraint that keeps a 2D mass-spring mesh from folding over.

Springs alone have no sense of area: pushed together hard enough (a pin driven towards an
anchor), a cell's springs can all be near their rest length while the cell is flipped inside
out, and the picture shows a fold. After every substep this constraint finds the triangles
whose signed area fell below `min_area_fraction` of their rest area and moves their corners
apart along the area gradient (a linearised position-based-dynamics projection, split by
inverse mass), a few Gauss-Seidel passes. As with the core's constraints, a correction dx
changes the velocity by dx / h.

It follows the core's constraint protocol (characters/constraints.py): `check(model)`,
`apply(x, v, h, inverse_mass, *, centers=None)`. The integrator passes the model's inverse
masses, which do not know this step's pins; pinned vertices may be nudged within a substep and
are put back on their targets by the integrator's next substep and by the puppet's step.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def unfold_triangles(x, v, triangles, min_area, weights, h, iterations):
    """Push triangles back to signed area >= min_area[t] [px^2]; x, v (N, 2) in place.

    triangles : (F, 3) int; weights : (N,) float inverse masses (0 = immovable).
    Returns how many triangles were below their minimum in the last pass."""
    below = 0
    for _ in range(iterations):
        below = 0
        for t in range(triangles.shape[0]):
            a = triangles[t, 0]
            b = triangles[t, 1]
            c = triangles[t, 2]
            ax, ay = x[a, 0], x[a, 1]
            bx, by = x[b, 0], x[b, 1]
            cx, cy = x[c, 0], x[c, 1]
            area = 0.5 * ((bx - ax) * (cy - ay) - (cx - ax) * (by - ay))
            if area >= min_area[t]:
                continue
            below += 1
            # gradient of the signed area with respect to each corner
            gax, gay = 0.5 * (by - cy), 0.5 * (cx - bx)
            gbx, gby = 0.5 * (cy - ay), 0.5 * (ax - cx)
            gcx, gcy = 0.5 * (ay - by), 0.5 * (bx - ax)
            wa, wb, wc = weights[a], weights[b], weights[c]
            denominator = (wa * (gax * gax + gay * gay) + wb * (gbx * gbx + gby * gby)
                           + wc * (gcx * gcx + gcy * gcy))
            if denominator <= 1e-12:
                continue
            step = (min_area[t] - area) / denominator
            for vertex, w, gx, gy in ((a, wa, gax, gay), (b, wb, gbx, gby), (c, wc, gcx, gcy)):
                dx = w * step * gx
                dy = w * step * gy
                x[vertex, 0] += dx
                x[vertex, 1] += dy
                v[vertex, 0] += dx / h
                v[vertex, 1] += dy / h
        if below == 0:
            break
    return below


class NoFoldConstraint:
    """Keeps every triangle's signed area >= min_area_fraction x its rest area.

    triangles : (F, 3) int; rest : (N, 2) float [px] rest positions (areas must be > 0)."""

    def __init__(self, triangles: np.ndarray, rest: np.ndarray, *,
                 min_area_fraction: float = 0.1, iterations: int = 4, name: str = "no_fold"):
        if not 0.0 <= min_area_fraction < 1.0:
            raise ValueError(f"min_area_fraction must be in [0, 1), got {min_area_fraction}")
        self.triangles = np.ascontiguousarray(triangles, dtype=np.int64)
        a, b, c = (rest[self.triangles[:, k]] for k in range(3))
        rest_area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                           - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
        if np.any(rest_area <= 0):
            raise ValueError("NoFoldConstraint needs positively oriented rest triangles")
        self.min_area = min_area_fraction * rest_area
        self.iterations = int(iterations)
        self.name = name
        self.last_below = 0

    def check(self, model) -> None:
        if model.dim != 2:
            raise ValueError(f"{self.name}: a 2D constraint, the model is {model.dim}D")
        if self.triangles.size and self.triangles.max() >= model.node_count:
            raise ValueError(f"{self.name}: triangles index {self.triangles.max()} but the "
                             f"model has {model.node_count} nodes")

    def apply(self, x, v, h, inverse_mass, *, centers=None) -> int:
        self.last_below = int(unfold_triangles(x, v, self.triangles, self.min_area,
                                               inverse_mass, float(h), self.iterations))
        return self.last_below
