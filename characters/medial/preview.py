"""Matplotlib pictures of medial objects (docs figures, quick looks; not a real-time renderer).

Surfaces are drawn as flat-shaded triangles (Lambert + ambient) with matplotlib's painter's
sort; skeletons as points. Use mop's 3D renderer for frames of a performance.
"""
from __future__ import annotations

import numpy as np


def _shade(vertices, faces, color, light):
    tri = vertices[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    light = np.asarray(light, dtype=np.float64)
    light = light / np.linalg.norm(light)
    lambert = np.clip(normals @ light, 0.0, 1.0)
    intensity = 0.35 + 0.65 * lambert
    rgb = np.clip(np.asarray(color)[None, :3] * intensity[:, None], 0.0, 1.0)
    return tri, rgb


def draw_mesh(ax, vertices, faces, *, color=(0.85, 0.6, 0.35), alpha=1.0,
              light=(0.4, -0.6, 0.9), edgecolor="none", linewidth=0.0):
    """Add a flat-shaded triangle mesh to a 3D axes.

    vertices : (V, 3) float, faces : (F, 3) int; color : RGB in [0, 1]
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri, rgb = _shade(np.asarray(vertices, dtype=np.float64), np.asarray(faces), color, light)
    rgba = np.concatenate([rgb, np.full((len(rgb), 1), alpha)], axis=1)
    collection = Poly3DCollection(tri, facecolors=rgba, edgecolors=edgecolor, linewidths=linewidth)
    ax.add_collection3d(collection)
    return collection


def set_equal_limits(ax, points, *, margin: float = 0.05):
    """Equal aspect 3D limits around points (P, 3)."""
    points = np.asarray(points)
    low, high = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (low + high)
    half = 0.5 * float(np.max(high - low)) * (1.0 + margin)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
