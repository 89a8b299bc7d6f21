"""Froggy: the shipped latex hand-puppet head, generated procedurally.

A frog head (two smoothly blended ellipsoids, bulging eyes, nostrils) with a deep mouth slit
cut from the front to a rounded hinge two thirds of the way back, meshed from its signed
distance by manifold3d's level set, coloured per vertex (green skin, pale throat, white eyes
with black pupils, pink mouth). Finger regions: the four fingers on the roof of the mouth, the
thumb on its floor; opening the hand turns them about the hinge, which opens the mouth.

Units are metres; +y is up, +z is the front (the frog looks along +z).

Regenerate the shipped files with ``python -m characters.assets.froggy``: it writes
characters/assets/froggy.ply and characters/assets/froggy.json.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent

# shape parameters [m]
HEAD_RADII = (0.12, 0.072, 0.105)
JAW_CENTRE = (0.0, -0.022, 0.012)
JAW_RADII = (0.118, 0.055, 0.1)
EYE_RADIUS = 0.032
EYE_CENTRES = ((0.056, 0.058, 0.03), (-0.056, 0.058, 0.03))
NOSTRILS = ((0.017, 0.036, 0.095), (-0.017, 0.036, 0.095))
NOSTRIL_RADIUS = 0.0065
MOUTH_Y = -0.014         # height of the mouth line at the middle
MOUTH_SMILE = 1.1        # the mouth line rises by MOUTH_SMILE * x^2 towards the corners
HINGE_Z = -0.035         # the slit ends here, in a rounded hinge
HINGE_HALF_GAP = 0.0036  # half the slit's height at the hinge
SLIT_OPENING = 0.016     # half-gap grows by this much per metre towards the front

FINGER_DEGREES = -24.0   # roof of the mouth turns up (about +x) at full opening
THUMB_DEGREES = 18.0     # floor turns down


def _smooth_min(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def _ellipsoid(p, centre, radii):
    """Approximate signed distance, negative inside (Quilez's bound)."""
    q = (p - np.asarray(centre)) / np.asarray(radii)
    k0 = np.linalg.norm(q, axis=-1)
    k1 = np.linalg.norm(q / np.asarray(radii), axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


def mouth_line(x):
    return MOUTH_Y + MOUTH_SMILE * x * x


def _slit(p):
    """Signed distance of the mouth slit, negative inside the slit."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    dy = np.abs(y - mouth_line(x))
    half_gap = HINGE_HALF_GAP + SLIT_OPENING * np.maximum(z - HINGE_Z, 0.0)
    wedge = np.maximum(dy - half_gap, HINGE_Z - z)
    hinge = np.hypot(y - mouth_line(x), z - HINGE_Z) - HINGE_HALF_GAP
    return np.minimum(wedge, hinge)


def frog_distance(p: np.ndarray) -> np.ndarray:
    """Signed distance [m] of the frog head at points p (..., 3), negative inside."""
    head = _ellipsoid(p, (0.0, 0.0, 0.0), HEAD_RADII)
    jaw = _ellipsoid(p, JAW_CENTRE, JAW_RADII)
    d = _smooth_min(head, jaw, 0.03)
    for centre in EYE_CENTRES:
        eye = np.linalg.norm(p - np.asarray(centre), axis=-1) - EYE_RADIUS
        d = _smooth_min(d, eye, 0.014)
    for centre in NOSTRILS:
        nostril = np.linalg.norm(p - np.asarray(centre), axis=-1) - NOSTRIL_RADIUS
        d = -_smooth_min(-d, nostril, 0.003)
    return -_smooth_min(-d, _slit(p), 0.0025)


def _colours(vertices: np.ndarray) -> np.ndarray:
    skin = np.array([86, 160, 58])
    throat = np.array([196, 208, 120])
    mouth = np.array([178, 62, 78])
    white = np.array([244, 244, 236])
    pupil = np.array([18, 18, 22])
    nostril = np.array([40, 80, 30])
    colours = np.tile(skin, (len(vertices), 1)).astype(np.float64)
    x, y, z = vertices.T
    # pale throat under the mouth, blended
    t = np.clip((mouth_line(x) - 0.012 - y) / 0.02, 0, 1) * np.clip((z + 0.02) / 0.05, 0, 1)
    colours = colours * (1 - t[:, None]) + throat * t[:, None]
    on_slit = np.abs(_slit(vertices)) < 0.0025
    colours[on_slit] = mouth
    for centre in EYE_CENTRES:
        offset = vertices - np.asarray(centre)
        r = np.linalg.norm(offset, axis=1)
        on_eye = (r < EYE_RADIUS + 0.0035) & (offset[:, 1] > -0.012)
        colours[on_eye] = white
        look = np.array([0.35 * math.copysign(1.0, centre[0]), 0.3, 0.9])
        look /= np.linalg.norm(look)
        cosine = (offset @ look) / np.maximum(r, 1e-12)
        colours[on_eye & (cosine > 0.86)] = pupil
    for centre in NOSTRILS:
        near = np.linalg.norm(vertices - np.asarray(centre), axis=1) < NOSTRIL_RADIUS + 0.002
        colours[near] = nostril
    out = np.empty((len(vertices), 4), dtype=np.uint8)
    out[:, :3] = np.clip(np.round(colours), 0, 255)
    out[:, 3] = 255
    return out


def generate(edge_length: float = 0.0065):
    """Build the frog: vertices (V, 3) float [m], faces (F, 3) int64, colours (V, 4) uint8,
    and the sidecar dict (finger regions, landmarks)."""
    import manifold3d
    bounds = (-0.15, -0.11, -0.14, 0.15, 0.12, 0.14)

    def sdf(x, y, z):
        return float(-frog_distance(np.array([x, y, z])))

    solid = manifold3d.Manifold.level_set(sdf, list(bounds), edge_length)
    mesh = solid.to_mesh()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(mesh.tri_verts, dtype=np.int64)
    # level_set keeps the larger component structure; make sure the winding is outward
    from ..latex.surface import clean_surface
    clean = clean_surface(vertices, faces, source="froggy")
    vertices, faces = clean.vertices, clean.faces
    colours = _colours(vertices)
    return vertices, faces, colours, _sidecar(vertices, faces)


def _on_slit_side(vertices, upper: bool):
    y_line = mouth_line(vertices[:, 0])
    side = vertices[:, 1] > y_line if upper else vertices[:, 1] < y_line
    return (np.abs(_slit(vertices)) < 0.0025) & side


def _sidecar(vertices: np.ndarray, faces: np.ndarray) -> dict:
    from ..latex.regions import Opening, RegionSpec, sidecar_dict, _components
    hinge = (0.0, MOUTH_Y, HINGE_Z)
    regions = {}

    def pick(centre, radius, upper):
        candidates = np.flatnonzero(_on_slit_side(vertices, upper))
        near = candidates[np.linalg.norm(vertices[candidates] - centre, axis=1) <= radius]
        pieces = _components(near, faces)
        return max(pieces, key=len)

    fingers = {"index": 0.058, "middle": 0.02, "ring": -0.02, "pinky": -0.058}
    for name, x in fingers.items():
        centre = np.array([x, mouth_line(x), 0.055])
        members = pick(centre, 0.016, upper=True)
        regions[name] = RegionSpec(name, vertices=members, opening=Opening(
            "rotate", origin=hinge, axis=(1.0, 0.0, 0.0), degrees=FINGER_DEGREES))
    members = pick(np.array([0.0, MOUTH_Y, 0.045]), 0.024, upper=False)
    regions["thumb"] = RegionSpec("thumb", vertices=members, opening=Opening(
        "rotate", origin=hinge, axis=(1.0, 0.0, 0.0), degrees=THUMB_DEGREES))
    regions = {name: regions[name] for name in ("thumb", "index", "middle", "ring", "pinky")}

    # landmarks: the middle of the upper and lower lip, at the front
    x, y, z = vertices.T
    middle = np.abs(x) < 0.012
    landmarks = {}
    for name, upper in (("upper_lip", True), ("lower_lip", False)):
        side = middle & ((y > mouth_line(x)) if upper else (y < mouth_line(x)))
        side &= np.abs(y - mouth_line(x)) < 0.02
        chosen = np.flatnonzero(side)
        front = chosen[np.argsort(-z[chosen])[:4]]
        landmarks[name] = front
    sidecar = sidecar_dict(regions, landmarks)
    sidecar["description"] = ("Froggy, mop's procedurally generated latex hand-puppet head. "
                              "Fingers on the roof of the mouth, thumb on its floor; opening "
                              "turns them about the mouth hinge. Units: metres, +y up, +z front.")
    return sidecar


def write(directory: Path = DATA, *, edge_length: float = 0.0065) -> tuple[Path, Path]:
    """Generate and write froggy.ply (with vertex colours) and froggy.json into directory."""
    import trimesh
    vertices, faces, colours, sidecar = generate(edge_length)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    mesh_path = directory / "froggy.ply"
    trimesh.Trimesh(vertices, faces, vertex_colors=colours, process=False).export(mesh_path)
    sidecar_path = directory / "froggy.json"
    sidecar_path.write_text(json.dumps(sidecar, indent=1) + "\n")
    return mesh_path, sidecar_path


if __name__ == "__main__":  # pragma: no cover - asset generation
    import sys
    sys.stdout.write("".join(f"{path}\n" for path in write()))
