"""Medial objects: milliseconds per 1/25 s frame by spring count, both constraint methods.

    python3 benchmarks/medial_object.py [--frames 100] [--quick]
    python3 benchmarks/medial_object.py --pictures docs/img     # the README's figures instead

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

    from characters.assets.caterpillar import caterpillar_joints, caterpillar_mesh
    from characters.medial.mesh_input import load_closed_mesh

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


# --- the README's pictures -----------------------------------------------------------------------

SECTION_COLOURS = np.array([[0.6, 0.6, 0.6], [0.95, 0.6, 0.2], [0.3, 0.6, 0.9],
                            [0.85, 0.35, 0.3], [0.4, 0.75, 0.4], [0.6, 0.45, 0.8],
                            [0.95, 0.5, 0.7]])


def _render(items, *, size, eye, target, bounds):
    """One offscreen pyrender frame of [(vertices, faces, colours | None, look)], y up."""
    from mop.render.scene3d import Scene3D, _look_at

    with Scene3D(size=size, camera=_look_at(np.asarray(eye, float), np.asarray(target, float)),
                 background="white", antialias=True) as scene:
        for vertices, faces, colours, look in items:
            scene.add(vertices, faces, colors=colours, look=look)
        scene.frame(bounds)
        return scene.render()


def _label(image, text):
    from PIL import Image, ImageDraw

    picture = Image.fromarray(image).convert("RGB")
    ImageDraw.Draw(picture).text((10, 8), text, fill=(40, 40, 40))
    return np.asarray(picture)


def pictures(folder) -> list:
    """docs/img/medial_duck_skeleton.png, medial_caterpillar_joints.png, medial_materials.png."""
    os.makedirs(folder, exist_ok=True)
    return [_duck_picture(folder), _caterpillar_picture(folder), _materials_picture(folder)]


def _duck_picture(folder) -> str:
    """The skeleton inside pybullet's duck (y up): the front half cut away."""
    import pybullet_data
    from PIL import Image

    from characters.medial import MedialObject

    duck = MedialObject.from_mesh(os.path.join(pybullet_data.getDataPath(), "duck.obj"))
    vertices, faces = duck.rest_vertices, duck.faces
    bounds = np.stack([vertices.min(0), vertices.max(0)])
    centre = bounds.mean(0)
    back = vertices[faces].mean(axis=1)[:, 2] < centre[2] + 0.05
    red = np.tile([[0.85, 0.15, 0.2]], (len(vertices), 1))
    panels = []
    for direction, text in (((0.35, 0.3, 1.0), "skeleton (red) in the duck, front half cut away"),
                            ((1.0, 0.25, 0.35), "from the side")):
        eye = centre + 3.6 * np.asarray(direction) / np.linalg.norm(direction)
        items = [(vertices, faces[back], None, "clay"), (duck.skeleton, faces, red, "matte")]
        image = _render(items, size=(480, 420), eye=eye, target=centre, bounds=bounds)
        panels.append(_label(image, text))
    path = os.path.join(folder, "medial_duck_skeleton.png")
    Image.fromarray(np.concatenate(panels, axis=1)).save(path, optimize=True)
    return path


def _caterpillar_picture(folder) -> str:
    """The caterpillar (y up): sections at rest, then four joints rotated at once, then one
    joint bent hard (the surface folds on the inner side, stretches outside)."""
    from PIL import Image

    from characters.medial import MedialObject

    creature = MedialObject.shipped("medial_caterpillar", constraint="spring_reduction")
    colours = SECTION_COLOURS[creature.joints.section_of_vertex % len(SECTION_COLOURS)]
    rest = creature.surface()
    pose = {"jaw": 0.55, "head": 0.35, "front": 0.25, "tail": 0.35}
    for _ in range(60):
        creature.step(FRAME, pose)
    posed = creature.surface()
    bounds = np.stack([rest.min(0), rest.max(0)])
    centre = bounds.mean(0)
    panels = []
    for surface, direction, text in (
            (rest, (0.0, 0.15, 1.0), "at rest: tail, chest, skull, jaw"),
            (posed, (0.0, 0.15, 1.0), "jaw 0.55, head 0.35, front 0.25, tail 0.35 rad")):
        eye = centre + 0.62 * np.asarray(direction) / np.linalg.norm(direction)
        image = _render([(surface, creature.faces, colours, "matte")], size=(480, 360),
                        eye=eye, target=centre, bounds=bounds)
        panels.append(_label(image, text))
    creature.reset()
    for _ in range(60):
        creature.step(FRAME, {"front": 0.6})
    joint = np.array([0.105, 0.07, 0.0])
    eye = joint + 0.45 * np.array([0.0, 0.2, 1.0]) / np.linalg.norm([0.0, 0.2, 1.0])
    image = _render([(creature.surface(), creature.faces, colours, "matte")], size=(480, 360),
                    eye=eye, target=joint, bounds=np.stack([joint - 0.08, joint + 0.08]))
    panels.append(_label(image, "front 0.6 rad: folded above the joint, stretched below"))
    path = os.path.join(folder, "medial_caterpillar_joints.png")
    Image.fromarray(np.concatenate(panels, axis=1)).save(path, optimize=True)
    return path


def _materials_picture(folder) -> str:
    """The five presets: surface speed after the bunny's top is flung by 0.5 rad and held."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pybullet_data

    from characters.medial import MedialObject

    bunny = os.path.join(pybullet_data.getDataPath(), "bunny.obj")
    cut = [dict(section="body", names=["bottom", "top"], point=[0.0, 0.0, 0.2],
                normal=[0.0, 0.0, 1.0], axis=[1.0, 0.0, 0.0])]
    dt, seconds = 0.02, 8.0
    figure, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name in ("thick skin", "water", "plastic", "skin", "tight cloth"):
        obj = MedialObject.from_mesh(bunny, material=name, joints=cut)
        posed_rest = obj.posed_rest({"top": 0.5})
        top = obj.joints.vertices_of("top")
        previous = obj.surface()
        speed, sway = [], []
        for _ in range(int(round(seconds / dt))):
            obj.step(dt, {"top": 0.5})
            now = obj.surface()
            speed.append(np.sqrt(np.mean(np.sum((now - previous) ** 2, axis=1))) / dt)
            sway.append(np.mean(now[top, 1] - posed_rest[top, 1]))
            previous = now
        times = dt * np.arange(1, len(speed) + 1)
        axes[0].semilogy(times[1:], np.maximum(speed[1:], 1e-6), label=name)
        axes[1].plot(times, 1e3 * np.asarray(sway), label=name)
    axes[0].set(xlabel="time after the fling [s]", ylabel="RMS surface speed [units/s]",
                title="wobble: water rings longest, plastic never moves", ylim=(1e-6, 10))
    axes[1].set(xlabel="time after the fling [s]", ylabel="mean sway of the top [1e-3 units]",
                title="sway: tight cloth (D 0.2) swings slowest", xlim=(0, 1.5))
    axes[0].legend(fontsize=8)
    figure.tight_layout()
    path = os.path.join(folder, "medial_materials.png")
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100, help="frames timed per case")
    parser.add_argument("--quick", action="store_true", help="fewer sizes")
    parser.add_argument("--material", default="skin", help="medial material preset")
    parser.add_argument("--pictures", metavar="FOLDER", default=None,
                        help="write the README's pictures to FOLDER instead of timing")
    args = parser.parse_args(argv)
    if args.pictures:
        for path in pictures(args.pictures):
            print(f"wrote {path} ({os.path.getsize(path) // 1024} KB)")
        return 0

    from characters import MassSpring, Verlet
    from characters.medial import MedialObject

    print(f"medial objects, material {args.material!r}, {args.frames} frames of 1/25 s per case, "
          f"one core (numba, no threads)")
    header = (f"{'mesh':26s} {'vertices':>8s} {'springs':>8s} {'build s':>7s} {'sub':>3s}  "
              f"{'constraint':16s} {'median ms':>9s} {'p90 ms':>7s} {'min ms':>6s} {'fps':>6s} "
              f"{'bare ms':>7s} {'ratio':>5s}")
    print(header)
    print("-" * len(header))
    rows = []
    for label, mesh, joints in meshes(args.quick):
        for constraint in ("circumsphere", "spring_reduction"):
            start = time.perf_counter()
            # the larger meshes exceed the default face limit on purpose (they take a while)
            obj = MedialObject.from_mesh(mesh, material=args.material, constraint=constraint,
                                         joints=joints, max_faces=len(mesh.faces))
            build = time.perf_counter() - start
            substeps = obj.substeps_for(FRAME)

            def medial_frame(k, obj=obj):
                obj.step(FRAME, pose_at(obj, k * FRAME))

            for k in range(10):   # compile and settle
                medial_frame(k)
            medial = time_frames(medial_frame, args.frames)

            # the reference: the same springs, masses and fixed nodes, no joints, no constraints
            model = obj.model
            plain = MassSpring(model.rest_positions, model.springs, stiffness=model.stiffness,
                               mass=model.mass, velocity_damping=model.velocity_damping,
                               rest_length=model.rest_length, fixed=model.fixed)
            plain_state = plain.state()
            plain_state.x[obj.dynamic_vertices] += 1e-3   # something to integrate
            bare = Verlet(substeps=substeps, check_energy=False)

            def bare_frame(k, bare=bare, plain=plain, plain_state=plain_state):
                bare.step(plain, plain_state, FRAME)

            for k in range(5):
                bare_frame(k)
            reference = time_frames(bare_frame, args.frames)
            median, p90 = float(np.median(medial)), float(np.percentile(medial, 90))
            ratio = median / float(np.median(reference))
            rows.append((label, obj.vertex_count, obj.model.spring_count, constraint, median))
            print(f"{label:26s} {obj.vertex_count:8d} {obj.model.spring_count:8d} {build:7.2f} "
                  f"{substeps:3d}  {constraint:16s} {median:9.2f} {p90:7.2f} {medial.min():6.2f} "
                  f"{1e3 / median:6.0f} "
                  f"{float(np.median(reference)):7.2f} {ratio:5.2f}", flush=True)
    print()
    for constraint in ("circumsphere", "spring_reduction"):
        fast = [r for r in rows if r[3] == constraint and r[4] < 40.0]
        if fast:
            best = max(fast, key=lambda r: r[2])
            print(f"{constraint}: largest object within a 40 ms frame (25 fps): "
                  f"{best[2]:,} springs ({best[0]}, {best[4]:.1f} ms)")
    for constraint in ("circumsphere", "spring_reduction"):
        at_goal = sorted((r for r in rows if r[3] == constraint and r[2] >= 50_000),
                         key=lambda r: r[2])
        if at_goal:
            first = at_goal[0]
            print(f"goal >= 50,000 springs at 25 fps ({constraint}): {first[2]:,} springs "
                  f"({first[0]}) take {first[4]:.1f} ms per frame -> "
                  f"{'met' if first[4] < 40.0 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
