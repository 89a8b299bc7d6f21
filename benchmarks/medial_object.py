"""Medial objects: milliseconds per 1/25 s frame by spring count, both constraint methods.

    python3 benchmarks/medial_object.py [--frames 100] [--quick]

A frame is everything `MedialObject.step(1/25, targets)` does: posing the bones of every joint
section (several sections move each frame), the Verlet substeps the material's stiffness needs
for stability, and the constraint after every substep. Meshes: the shipped caterpillar meshed at
several resolutions (its three joints all moving), and pybullet's bunny and duck Loop-subdivided
(one joint). The goal: >= 50,000 springs at 25 fps on one core, i.e. a frame < 40 ms. The paper
ran 17,000 springs at 25 fps on a 2007 Pentium IV.

Reference in the same process: the core's bare `Verlet` on the same model for the same number
of substeps, with no joints and no constraints ("bare"); the ratio says what the medial work
(posing bones, constraints, substep loop) costs on top of the spring integration.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

FRAME = 1.0 / 25.0


def meshes(quick: bool):
    """(label, trimesh, joints) from about 2k to 170k springs."""
    import pybullet_data
    import trimesh

    from characters.medial_build.creature import caterpillar_joints, caterpillar_mesh
    from characters.medial_build.mesh_input import load_closed_mesh

    joints = caterpillar_joints()
    edges = (0.012, 0.007) if quick else (0.012, 0.009, 0.007, 0.006)
    for edge in edges:
        yield f"caterpillar edge {edge * 1000:.0f} mm", caterpillar_mesh(edge_length=edge), joints
    data = pybullet_data.getDataPath()
    for name, levels in (("bunny", (0, 1, 2) if quick else (0, 1, 2, 3)), ("duck", (0, 1))):
        base = load_closed_mesh(os.path.join(data, f"{name}.obj"))
        centre = base.bounds.mean(axis=0)
        cut = [dict(section="body", names=["lower", "upper"], point=centre.tolist(),
                    normal=[0.0, 0.0, 1.0], axis=[1.0, 0.0, 0.0])]
        for level in levels:
            vertices, faces = np.asarray(base.vertices), np.asarray(base.faces)
            if level:
                vertices, faces = trimesh.remesh.subdivide_loop(vertices, faces, level)
            yield f"{name} x{4 ** level} faces", trimesh.Trimesh(vertices, faces), cut


def pose_at(obj, t: float) -> dict:
    """Every joint section swinging at its own pace [rad]."""
    names = obj.target_names
    return {name: 0.35 * math.sin(2.0 * math.pi * (0.4 + 0.23 * k) * t)
            for k, name in enumerate(names) if k % 2}


def time_frames(step, frames: int) -> np.ndarray:
    times = np.empty(frames)
    for k in range(frames):
        start = time.perf_counter()
        step(k)
        times[k] = time.perf_counter() - start
    return times * 1e3


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100, help="frames timed per case")
    parser.add_argument("--quick", action="store_true", help="fewer sizes")
    parser.add_argument("--material", default="skin", help="medial material preset")
    args = parser.parse_args(argv)

    from characters import Verlet
    from characters.medial import MedialObject

    print(f"medial objects, material {args.material!r}, {args.frames} frames of 1/25 s per case, "
          f"one core (numba, no threads)")
    header = (f"{'mesh':26s} {'vertices':>8s} {'springs':>8s} {'build s':>7s} {'sub':>3s}  "
              f"{'constraint':16s} {'median ms':>9s} {'p90 ms':>7s} {'fps':>6s} {'bare ms':>7s} "
              f"{'ratio':>5s}")
    print(header)
    print("-" * len(header))
    rows = []
    for label, mesh, joints in meshes(args.quick):
        for constraint in ("circumsphere", "spring_reduction"):
            start = time.perf_counter()
            obj = MedialObject.from_mesh(mesh, material=args.material, constraint=constraint,
                                         joints=joints)
            build = time.perf_counter() - start
            substeps = obj.substeps_for(FRAME)

            def medial_frame(k, obj=obj):
                obj.step(FRAME, pose_at(obj, k * FRAME))

            for k in range(10):   # compile and settle
                medial_frame(k)
            medial = time_frames(medial_frame, args.frames)

            bare_model = obj.model
            bare_state = bare_model.state()
            bare = Verlet(substeps=substeps, check_energy=False)
            # the same springs without constraints: rebuild a model without them
            from characters import MassSpring
            plain = MassSpring(bare_model.rest_positions, bare_model.springs,
                               stiffness=bare_model.stiffness, mass=bare_model.mass,
                               velocity_damping=bare_model.velocity_damping,
                               rest_length=bare_model.rest_length, fixed=bare_model.fixed)
            plain_state = plain.state()
            plain_state.x[obj.dynamic_vertices] += 1e-3   # something to integrate

            def bare_frame(k):
                bare.step(plain, plain_state, FRAME)

            for k in range(5):
                bare_frame(k)
            reference = time_frames(bare_frame, args.frames)
            del bare_state
            median, p90 = float(np.median(medial)), float(np.percentile(medial, 90))
            ratio = median / float(np.median(reference))
            rows.append((label, obj.vertex_count, obj.model.spring_count, constraint, median))
            print(f"{label:26s} {obj.vertex_count:8d} {obj.model.spring_count:8d} {build:7.2f} "
                  f"{substeps:3d}  {constraint:16s} {median:9.2f} {p90:7.2f} {1e3 / median:6.0f} "
                  f"{float(np.median(reference)):7.2f} {ratio:5.2f}", flush=True)
    print()
    for constraint in ("circumsphere", "spring_reduction"):
        fast = [r for r in rows if r[3] == constraint and r[4] < 40.0]
        if fast:
            best = max(fast, key=lambda r: r[2])
            print(f"{constraint}: largest object within a 40 ms frame (25 fps): "
                  f"{best[2]:,} springs ({best[0]}, {best[4]:.1f} ms)")
    at_goal = [r for r in rows if r[2] >= 50_000]
    if at_goal:
        worst = max(at_goal, key=lambda r: r[4] / r[2])
        print(f"goal >= 50,000 springs at 25 fps: slowest case at/above 50k springs is "
              f"{worst[4]:.1f} ms for {worst[2]:,} springs ({worst[0]}, {worst[3]}) -> "
              f"{'met' if all(r[4] < 40.0 for r in at_goal) else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
