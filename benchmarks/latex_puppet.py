"""Latex hand puppets: simulation and rendering speed, decimation quality, and pictures.

    python benchmarks/latex_puppet.py                 # everything (a few minutes)
    python benchmarks/latex_puppet.py --quick         # smaller sizes, fewer frames
    python benchmarks/latex_puppet.py --pictures      # also write docs/img/latex_*.png

Sections:
1. The paper's Table 1 sizes (masses/springs) as exact synthetic mass-spring systems (random
   points in a ball joined by their shortest Delaunay edges), ms per 1/25 s frame (one step),
   for ImplicitEuler (one Newton iteration, the paper's scheme) and ProjectiveDynamics, next to
   the paper's update times (1.7 GHz Pentium 4).
2. The shipped frog built at 2k..20k masses (its real springs): build time and ms per frame
   while the glove opens and closes the mouth.
3. Rendering the deformed 40k-triangle frog at 720x576 (mop.render.scene3d: OpenGL through
   moderngl, EGL/llvmpipe): per-frame buffer update vs rebuilding the mesh's buffers,
   multisampling on/off, and pyrender's stock offscreen renderer as an outside reference; and
   simulation + rendering per frame, one after the other and pipelined on two threads.
4. Decimation (section 4.1) against plain quadric decimation (fast-simplification): triangle
   roundness and Hausdorff distance.

Simulation runs single-threaded (OMP_NUM_THREADS=1 is set below before numpy loads). Figures
are medians and 90th percentiles over the frames of one run on a shared machine.
"""
from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from characters import Control, ImplicitEuler, MassSpring, ProjectiveDynamics  # noqa: E402
from characters.latex import FROGGY, PD_ITERATIONS, LatexPuppet  # noqa: E402

FPS = 25.0
DT = 1.0 / FPS
PAPER = [(3744, 1872, 0.015), (3744, 6952, 0.025), (5664, 15056, 0.043), (9978, 25892, 0.076)]
FINGERS = ("thumb", "index", "middle", "ring", "pinky")


def stats(samples) -> str:
    ms = np.asarray(samples) * 1000.0
    return f"{np.median(ms):7.1f} ms (p90 {np.percentile(ms, 90):6.1f})"


def glove(frame: int) -> dict:
    """Open the hand over 1 s, hold, close over 1 s, hold: a 4 s loop."""
    t = (frame / FPS) % 4.0
    bend = min(t, 1.0) if t < 2.0 else max(0.0, 3.0 - t)
    return {finger: bend for finger in FINGERS}


# --- 1. the paper's sizes -----------------------------------------------------------------------

def synthetic_system(masses: int, springs: int, seed: int = 0) -> MassSpring:
    """masses nodes in a 0.2 m ball, joined by the `springs` shortest Delaunay edges (every node
    keeps at least its shortest edge), with foam-like stiffness and mass."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(masses, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    points = 0.1 * direction * rng.random((masses, 1)) ** (1 / 3)
    tets = Delaunay(points).simplices
    edges = np.sort(np.concatenate([tets[:, [i, j]] for i in range(4) for j in range(i + 1, 4)]),
                    axis=1)
    edges = np.unique(edges, axis=0)
    length = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
    order = np.argsort(length)
    must = np.zeros(len(edges), dtype=bool)
    for column in (0, 1):  # each node's shortest edge
        first = np.full(masses, -1)
        for e in order[::-1]:
            first[edges[e, column]] = e
        must[first[first >= 0]] = True
    chosen = list(np.flatnonzero(must))
    rest = [e for e in order if not must[e]]
    chosen = np.array(chosen + rest[:max(springs - len(chosen), 0)])[:springs]
    spacing = float(np.median(length[chosen]))
    return MassSpring(points, edges[chosen], stiffness=5.0e4 * length[chosen],
                      damping=0.05, mass=45.0 * spacing ** 3 * 4, velocity_damping=5.0)


def time_model(model: MassSpring, integrator, frames: int) -> list[float]:
    state = model.state()
    top = np.argsort(model.rest_positions[:, 1])[-20:]
    rest = model.rest_positions[top]
    times = []
    for frame in range(frames):
        lift = 0.02 * min(frame / 10, 1.0)
        control = Control(targets=(top, rest + [0.0, lift, 0.0]), target_stiffness=200.0,
                          target_damping=0.5)
        start = time.perf_counter()
        integrator.step(model, state, DT, control)
        times.append(time.perf_counter() - start)
    return times[2:]


def paper_sizes(frames: int) -> None:
    print("\n1. The paper's Table 1 sizes (exact masses/springs, synthetic ball), "
          "ms per 1/25 s frame, one core")
    print(f"{'masses':>7} {'springs':>8} {'paper P4':>9} {'ImplicitEuler':>27} "
          f"{f'ProjectiveDynamics ({PD_ITERATIONS} it.)':>27}")
    for masses, springs, paper in PAPER:
        model = synthetic_system(masses, springs)
        ie = time_model(model, ImplicitEuler(tolerance=1e-3, max_iterations=200), frames)
        pd = time_model(model, ProjectiveDynamics(iterations=PD_ITERATIONS), frames)
        print(f"{masses:7d} {springs:8d} {paper * 1000:7.0f} ms {stats(ie):>27} {stats(pd):>27}")


# --- 2. the frog at several sizes ---------------------------------------------------------------

def frog_sizes(sizes, frames: int) -> dict:
    print("\n2. Froggy built at several sizes (its own tetrahedral springs): ms per frame while "
          "the glove opens and closes the mouth")
    print(f"{'asked':>6} {'masses':>7} {'springs':>8} {'tets':>6} {'build':>7} "
          f"{f'ProjectiveDynamics ({PD_ITERATIONS} it.)':>27} {'ImplicitEuler':>27} "
          f"{'mouth gap':>16}")
    built = {}
    for masses in sizes:
        start = time.perf_counter()
        puppet = LatexPuppet.froggy(masses=masses)
        build = time.perf_counter() - start
        built[masses] = puppet
        rows = []
        for name, integrator in (("pd", ProjectiveDynamics(iterations=PD_ITERATIONS)),
                                 ("ie", ImplicitEuler(tolerance=1e-3, max_iterations=200))):
            puppet.integrator = integrator
            puppet.reset()
            closed = puppet.mouth_gap()
            times, gaps = [], []
            for frame in range(frames):
                t0 = time.perf_counter()
                puppet.step(DT, glove(frame))
                times.append(time.perf_counter() - t0)
                gaps.append(puppet.mouth_gap())
            rows.append(stats(times[2:]))
            if name == "pd":
                opened = max(gaps)
        puppet.integrator = ProjectiveDynamics(iterations=PD_ITERATIONS)
        puppet.reset()
        print(f"{masses:6d} {puppet.model.node_count:7d} {puppet.model.spring_count:8d} "
              f"{len(puppet.tetrahedra):6d} {build:6.1f}s {rows[0]:>27} {rows[1]:>27} "
              f"{closed * 1000:5.1f}->{opened * 1000:5.1f} mm")
    return built


def accuracy(puppet: LatexPuppet, frames: int) -> None:
    print(f"\n2b. Accuracy at {puppet.model.node_count} masses: mouth gap over the glove loop "
          f"against implicit Euler solved tightly (CG tolerance 1e-4)")
    runs = {}
    for name, integrator in (("ImplicitEuler, tol 1e-4", ImplicitEuler(tolerance=1e-4,
                                                                       max_iterations=500)),
                             ("ImplicitEuler, tol 1e-3", ImplicitEuler(tolerance=1e-3,
                                                                       max_iterations=200)),
                             ("ProjectiveDynamics, 4 it.", ProjectiveDynamics(iterations=4)),
                             ("ProjectiveDynamics, 6 it.", ProjectiveDynamics(iterations=6)),
                             ("ProjectiveDynamics, 10 it.", ProjectiveDynamics(iterations=10))):
        puppet.integrator = integrator
        puppet.reset()
        times, gaps = [], []
        for frame in range(frames):
            t0 = time.perf_counter()
            puppet.step(DT, glove(frame))
            times.append(time.perf_counter() - t0)
            gaps.append(puppet.mouth_gap())
        runs[name] = np.array(gaps)
        reference = runs["ImplicitEuler, tol 1e-4"]
        rms = np.sqrt(np.mean((runs[name] - reference) ** 2)) * 1000
        print(f"  {name:28s} {stats(times[2:])}  max gap {runs[name].max() * 1000:6.1f} mm, "
              f"rms vs reference {rms:5.2f} mm")
    puppet.integrator = ProjectiveDynamics(iterations=PD_ITERATIONS)
    puppet.reset()


# --- 3. rendering ------------------------------------------------------------------------------

def rendering(puppet: LatexPuppet, frames: int) -> None:
    from mop.render.scene3d import Scene3D
    print(f"\n3. Rendering the deformed frog: {len(puppet.faces)} triangles, "
          f"{len(puppet.rest_vertices)} vertices, 720x576, EGL (Mesa llvmpipe, no GPU)")
    puppet.reset()
    surfaces = []
    for frame in range(frames):
        puppet.step(DT, glove(frame))
        surfaces.append(puppet.surface().copy())

    def run(antialias: bool, mode: str) -> list[float]:
        times = []
        with Scene3D(size=(720, 576), background="chroma", antialias=antialias) as scene:
            handle = scene.add(puppet)
            for _k, x in enumerate(surfaces):
                t0 = time.perf_counter()
                if mode == "update":
                    scene.update(handle, x)
                else:  # rebuild: new GPU buffers every frame (what the scene avoids)
                    item = scene._items[handle]
                    item.refresh(x)
                    with scene._context:
                        item.release()
                        item.upload(scene._context, scene._program)
                scene.render()
                times.append(time.perf_counter() - t0)
        return times[2:]

    print(f"  update vertex buffer, no multisampling  {stats(run(False, 'update'))}")
    print(f"  update vertex buffer, 4x multisampling  {stats(run(True, 'update'))}")
    print(f"  rebuild the mesh each frame, no MSAA    {stats(run(False, 'rebuild'))}")
    print(f"  pyrender stock OffscreenRenderer        {stats(_pyrender_stock(puppet, frames))}")
    _simulate_and_render(puppet, frames)


def _pyrender_stock(puppet: LatexPuppet, frames: int) -> list[float]:
    """Seconds per frame of pyrender's stock renderer (4x MSAA, colour + depth read-back) on
    the rest mesh, for reference."""
    import pyrender
    scene = pyrender.Scene(bg_color=(0, 0.7, 0.25, 1.0))
    scene.add(pyrender.Mesh.from_trimesh(__import__("trimesh").Trimesh(
        puppet.rest_vertices, puppet.faces, process=False)))
    camera_pose = np.eye(4)
    camera_pose[2, 3] = 0.5
    scene.add(pyrender.PerspectiveCamera(yfov=0.55), pose=camera_pose)
    scene.add(pyrender.DirectionalLight(intensity=3.0), pose=camera_pose)
    stock = pyrender.OffscreenRenderer(720, 576)
    times = []
    for _ in range(min(frames, 20)):
        t0 = time.perf_counter()
        stock.render(scene, flags=pyrender.RenderFlags.RGBA)
        times.append(time.perf_counter() - t0)
    stock.delete()
    return times[2:]


def _simulate_and_render(puppet: LatexPuppet, frames: int) -> None:
    """Simulation and rendering per frame, one after the other and pipelined on two cores."""
    from mop.render.scene3d import Scene3D
    puppet.reset()
    with Scene3D(size=(720, 576), background="chroma") as scene:
        handle = scene.add(puppet)
        times = []
        for frame in range(frames):
            t0 = time.perf_counter()
            puppet.step(DT, glove(frame))
            scene.update(handle)
            scene.render()
            times.append(time.perf_counter() - t0)
        print(f"  simulate + render, one after the other  {stats(times[2:])}  "
              f"({puppet.model.node_count} masses)")

        # pipelined: the next frame simulates on a worker thread while this one renders
        puppet.reset()
        ready = threading.Event()
        shown = np.empty_like(puppet.surface())
        times = []

        def simulate(frame):
            puppet.step(DT, glove(frame))
            ready.set()

        puppet.step(DT, glove(0))
        for frame in range(1, frames):
            t0 = time.perf_counter()
            shown[...] = puppet.surface()
            ready.clear()
            worker = threading.Thread(target=simulate, args=(frame,))
            worker.start()
            scene.update(handle, shown)
            scene.render()
            worker.join()
            times.append(time.perf_counter() - t0)
        print(f"  simulate + render, pipelined (2 cores)  {stats(times[2:])}")


# --- 4. decimation quality -----------------------------------------------------------------------

def decimation(quick: bool) -> None:
    from characters.latex import decimate as dec
    from characters.latex.surface import clean_surface, load_mesh
    print("\n4. Decimation (4.1: quadric + lambda * roundness, normal-flip rejection) vs plain "
          "quadric decimation (fast-simplification)")
    print(f"{'mesh':>8} {'faces':>6} {'method':>22} {'R* mean':>8} {'R* min':>7} {'R*<0.5':>7} "
          f"{'Hausdorff':>10} {'/diag':>7} {'time':>7}")
    meshes = [("froggy", FROGGY, 1200)]
    try:
        import pybullet_data
        meshes.insert(0, ("duck", Path(pybullet_data.getDataPath()) / "duck.obj", 400))
    except ImportError:
        pass
    samples = 5000 if quick else 20000
    for name, path, target in meshes:
        loaded = load_mesh(path)
        clean = clean_surface(loaded.vertices, loaded.faces)
        v, f = clean.vertices, clean.faces
        dec.decimate(v, f, target_vertices=len(v) - 10)  # compile outside the timings
        for label, lam in (("ours, lambda 0.5", 0.5), ("ours, lambda 0 (quadric)", 0.0)):
            t0 = time.perf_counter()
            result = dec.decimate(v, f, target_vertices=target, roundness_weight=lam)
            seconds = time.perf_counter() - t0
            q = dec.quality(v, f, v[result.kept], result.faces, samples=samples)
            print(f"{name:>8} {len(result.faces):6d} {label:>22} {q.roundness_mean:8.3f} "
                  f"{q.roundness_min:7.3f} {q.sliver_share:7.1%} {q.hausdorff:10.5f} "
                  f"{q.hausdorff_relative:7.2%} {seconds:6.2f}s")
        t0 = time.perf_counter()
        rv, rf = dec.quadric_reference(v, f, target_faces=len(result.faces))
        seconds = time.perf_counter() - t0
        q = dec.quality(v, f, rv, rf, samples=samples)
        print(f"{name:>8} {len(rf):6d} {'fast-simplification':>22} {q.roundness_mean:8.3f} "
              f"{q.roundness_min:7.3f} {q.sliver_share:7.1%} {q.hausdorff:10.5f} "
              f"{q.hausdorff_relative:7.2%} {seconds:6.2f}s")


# --- pictures ----------------------------------------------------------------------------------

def pictures(out: Path) -> None:
    from PIL import Image, ImageDraw
    from mop.render.scene3d import Scene3D
    out.mkdir(parents=True, exist_ok=True)
    puppet = LatexPuppet.froggy(masses=3000)
    size = (640, 512)
    for name, bend in (("rest", 0.0), ("open", 1.0)):
        puppet.reset()
        for _ in range(30):
            puppet.step(DT, {finger: bend for finger in FINGERS})
        with Scene3D(size=size, camera="three_quarter", background=(236, 238, 240),
                     antialias=True) as scene:
            scene.add(puppet)
            image = Image.fromarray(scene.render())
        draw = ImageDraw.Draw(image)
        draw.text((12, 10), f"Froggy, glove {'open' if bend else 'at rest'}: mouth gap "
                            f"{puppet.mouth_gap() * 1000:.0f} mm ({puppet.model.node_count} "
                            f"masses, {len(puppet.faces)} triangles)", fill=(20, 20, 20))
        path = out / f"latex_froggy_{name}.png"
        image.convert("RGB").save(path, optimize=True)
        print(f"wrote {path} ({path.stat().st_size // 1024} KB)")
    cutaway(puppet, out / "latex_layers.png")


def cutaway(puppet: LatexPuppet, path: Path) -> None:
    """The tetrahedra behind the x = 0 plane, coloured by their outermost node layer, seen
    from the cut side, with the skin of the far half."""
    from PIL import Image, ImageDraw
    from mop.render.scene3d import Look, Scene3D
    x = puppet.model.rest_positions
    tets = puppet.tetrahedra
    keep = x[tets].mean(1)[:, 0] < 0.0
    tets = tets[keep]
    outer = puppet.layer[tets].min(1)
    colours = {0: (96, 170, 70), 1: (240, 205, 90), 2: (205, 70, 80)}
    faces = np.concatenate([tets[:, [0, 2, 1]], tets[:, [0, 1, 3]], tets[:, [0, 3, 2]],
                            tets[:, [1, 2, 3]]])
    face_colour = np.concatenate([np.array([colours[int(k)] for k in outer])] * 4)
    # show each face once, with the colour of its outermost tetrahedron
    key = np.sort(faces, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    faces, face_colour = faces[first], face_colour[first]
    vertices = x[faces].reshape(-1, 3)
    tri = np.arange(len(vertices)).reshape(-1, 3)
    rgba = np.concatenate([np.repeat(face_colour, 3, axis=0),
                           np.full((len(vertices), 1), 255)], axis=1).astype(np.uint8)
    skin = puppet.surface_faces[x[puppet.surface_faces].mean(1)[:, 0] < 0]
    camera = "side"
    with Scene3D(size=(640, 512), camera=camera, background=(236, 238, 240),
                 antialias=True) as scene:
        scene.add(vertices, tri, colors=rgba, look=Look((1, 1, 1), roughness=0.8,
                                                        double_sided=True))
        scene.add(x, skin, colors=None, look=Look((0.45, 0.7, 0.35), roughness=0.5,
                                                   use_vertex_colors=False, double_sided=True))
        scene.frame()
        image = Image.fromarray(scene.render())
    draw = ImageDraw.Draw(image)
    counts = np.bincount(puppet.layer, minlength=3)
    labels = [(0, f"touching the latex skin ({counts[0]} skin nodes)"),
              (1, f"foam layer ({counts[1]} nodes)"), (2, f"hand cavity ({counts[2]} nodes)")]
    for row, (layer, text) in enumerate(labels):
        y = 12 + 20 * row
        draw.rectangle([12, y, 26, y + 14], fill=colours[layer])
        draw.text((34, y + 1), text, fill=(20, 20, 20))
    draw.text((12, 490), "cut at x = 0: tetrahedra coloured by their outermost node layer",
              fill=(20, 20, 20))
    image.convert("RGB").save(path, optimize=True)
    print(f"wrote {path} ({path.stat().st_size // 1024} KB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes, fewer frames")
    parser.add_argument("--pictures", action="store_true", help="write docs/img/latex_*.png")
    parser.add_argument("--only", choices=("paper", "frog", "render", "decimate", "pictures"),
                        help="run one section")
    args = parser.parse_args()
    frames = 20 if args.quick else 60
    if args.only in (None, "paper"):
        paper_sizes(frames)
    built = {}
    if args.only in (None, "frog", "render"):
        sizes = (2000, 3700) if args.quick else (2000, 3700, 5700, 10000, 20000)
        if args.only == "render":
            sizes = (3700,)
        built = frog_sizes(sizes, frames)
    if args.only is None:
        accuracy(built[10000] if 10000 in built else built[3700], 100 if not args.quick else 40)
    if args.only in (None, "render"):
        rendering(built[3700], frames)
    if args.only in (None, "decimate"):
        decimation(args.quick)
    if args.pictures or args.only == "pictures":
        pictures(ROOT / "docs" / "img")


if __name__ == "__main__":
    main()
