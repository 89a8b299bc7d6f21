"""The shipped medial creature: a caterpillar with a bending body, a nodding head and a jaw.

Built procedurally: ellipsoids (body segments, stubby legs, head, eyes) joined by a smooth union,
minus a wedge for the mouth, meshed as a level set by manifold3d (its marching tetrahedra keep the
triangles well shaped, which the medial skeleton and the springs both need). Units: metres; the
creature is about 0.44 m long, a hand-puppet size. Axes as mop's 3D renderer expects them: +y up,
the head towards +x, its left side towards +z (the field below is written z-up and turned).

``python -m characters.assets.caterpillar [DIR]`` rewrites the assets in characters/assets/:
``medial_caterpillar.obj`` (surface), ``medial_caterpillar.joints.json`` (sections, planes,
pivots, axes; the format of ``characters.medial.joints.JointSpec``) and
``medial_caterpillar.motion.json`` (a demo clip addressing the sections by name).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..medial.joints import JointCut, JointSpec

NAME = "medial_caterpillar"
DATA = Path(__file__).resolve().parent

_SEGMENTS_X = (0.0, 0.07, 0.14, 0.21)
_HEAD = (0.30, 0.0, 0.085, 0.075, 0.066, 0.064)      # centre (x, y, z), radii (x, y, z) [m]
_MOUTH_CORNER = (0.285, 0.072)     # (x, height) of the back of the mouth [m]
_LIP_ANGLES = (math.radians(14.0), math.radians(-16.0))   # upper and lower lip planes
_BLEND = 0.022                                          # smooth-union width [m]


def _ellipsoids():
    balls = []
    for k, x in enumerate(_SEGMENTS_X):
        z = 0.05 + 0.008 * math.sin(1.3 * k + 0.5)
        radius = 0.044 + 0.004 * k
        balls.append((x, 0.0, z, radius, radius, 0.95 * radius))
        for side in (-1.0, 1.0):                                   # stubby legs
            balls.append((x, side * 0.032, 0.014, 0.016, 0.016, 0.016))
    balls.append(_HEAD)
    for side in (-1.0, 1.0):                                       # eyes
        balls.append((0.32, side * 0.034, 0.14, 0.019, 0.019, 0.019))
    return tuple(balls)


_BALLS = _ellipsoids()


def caterpillar_sdf(x: float, y: float, z: float, balls=_BALLS) -> float:
    """Signed distance-like field [m] of the caterpillar, z up: positive inside."""
    inside = -1e9
    for cx, cy, cz, rx, ry, rz in balls:
        dx, dy, dz = (x - cx) / rx, (y - cy) / ry, (z - cz) / rz
        value = (1.0 - math.sqrt(dx * dx + dy * dy + dz * dz)) * min(rx, ry, rz)
        # polynomial smooth maximum: segments melt into each other instead of creasing
        blend = max(_BLEND - abs(inside - value), 0.0) / _BLEND
        inside = max(inside, value) + blend * blend * _BLEND * 0.25
    # the mouth: a wedge between two lip planes, open towards +x from the mouth corner
    ex, ez = x - _MOUTH_CORNER[0], z - _MOUTH_CORNER[1]
    upper, lower = _LIP_ANGLES
    below_upper = -(ez * math.cos(upper) - ex * math.sin(upper))
    above_lower = ez * math.cos(lower) - ex * math.sin(lower)
    wedge = min(below_upper, above_lower, ex)
    # smooth minimum with the negated wedge rounds the lips
    a, b, k = inside, -wedge, 0.01
    blend = max(k - abs(a - b), 0.0) / k
    return min(a, b) - blend * blend * k * 0.25


def caterpillar_mesh(*, edge_length: float = 0.012):
    """The caterpillar's closed surface (trimesh.Trimesh) with edges of about `edge_length` [m]."""
    import manifold3d
    import trimesh

    if not edge_length > 0:
        raise ValueError(f"edge_length must be > 0 [m], got {edge_length}")
    bounds = [-0.07, -0.09, -0.02, 0.40, 0.09, 0.18]
    solid = manifold3d.Manifold.level_set(caterpillar_sdf, bounds, edge_length, 0.0,
                                          0.05 * edge_length)
    mesh = solid.to_mesh()
    z_up = np.asarray(mesh.vert_properties[:, :3], dtype=np.float64)
    # (x, y, z) z-up -> (x, z, -y) y-up: a proper rotation, so the winding stays outward
    y_up = np.stack([z_up[:, 0], z_up[:, 2], -z_up[:, 1]], axis=1)
    return trimesh.Trimesh(y_up, np.asarray(mesh.tri_verts, dtype=np.int64), process=True)


def caterpillar_joints() -> JointSpec:
    """Sections: body -> tail | front; front -> chest | head; head -> skull | jaw.

    Positive angles pitch a section nose-up about its pivot: the front and the head lift, the
    tail dips; a positive jaw angle opens the mouth.
    """
    lift = (0.0, 0.0, 1.0)          # about +z: +x (towards the head) turns to +y (up)
    corner_x, corner_height = _MOUTH_CORNER
    cuts = (
        JointCut(section="body", names=("tail", "front"), point=(0.105, 0.05, 0.0),
                 normal=(1.0, 0.0, 0.0), axis=lift, pivot=(0.105, 0.05, 0.0)),
        JointCut(section="front", names=("chest", "head"), point=(0.252, 0.06, 0.0),
                 normal=(1.0, 0.0, 0.0), axis=lift, pivot=(0.252, 0.06, 0.0)),
        JointCut(section="head", names=("skull", "jaw"), point=(corner_x, corner_height, 0.0),
                 normal=(0.0, -1.0, 0.0), axis=(0.0, 0.0, -1.0),
                 pivot=(0.265, corner_height, 0.0)),
    )
    return JointSpec(root="body", cuts=cuts,
                     extras={"mesh": f"{NAME}.obj", "motion": f"{NAME}.motion.json"})


def caterpillar_motion_channels() -> dict:
    """A 4 s loop: the jaw chatters, the head nods, the tail and the front sway [rad]."""
    times = np.linspace(0.0, 4.0, 41)
    phase = 2.0 * math.pi * times / 4.0
    jaw = 0.35 * np.clip(np.sin(4.0 * phase), 0.0, None)
    head = 0.25 * np.sin(phase)
    front = 0.15 * np.sin(phase + 0.8)
    tail = -0.2 * np.sin(2.0 * phase)
    return {"jaw": (times, jaw), "head": (times, head), "front": (times, front),
            "tail": (times, tail)}


def write_assets(directory: Path | str = DATA, *, edge_length: float = 0.012) -> list[Path]:
    """Write the mesh, joints and motion files; returns their paths."""
    from ..motion import Motion

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    mesh = caterpillar_mesh(edge_length=edge_length)
    paths = [directory / f"{NAME}.obj", directory / f"{NAME}.joints.json",
             directory / f"{NAME}.motion.json"]
    mesh.export(paths[0], include_normals=False, include_texture=False)
    caterpillar_joints().save(paths[1])
    Motion(caterpillar_motion_channels()).save(paths[2])
    return paths


if __name__ == "__main__":  # pragma: no cover - asset regeneration
    import sys

    for path in write_assets(sys.argv[1] if len(sys.argv) > 1 else DATA):
        sys.stdout.write(f"wrote {path}\n")
