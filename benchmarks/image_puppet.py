"""Image puppet figures: build, simulation step and render times for a 512x512 and a
2048x2048 picture, baked playback fps, baked-vs-simulated deviation, and the renderer choice
(numba scanline rasteriser vs pyrender/EGL on the same mesh, same process).

    python benchmarks/image_puppet.py [--quick]

Pictures: the shipped sample character (characters/assets/momo.png, 512x512) and the same picture
upscaled to 2048x2048 (meshed on a 1024 copy, rendered at full size). Motion: its 4 s wave
(characters/assets/momo_wave.json) at 25 fps. Times are wall-clock medians and 90th percentiles on
one core (numba kernels are single-threaded), plus the minimum (closest to an idle machine when
others share it); the first call (compilation) is excluded.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import characters  # noqa: E402
from characters import ImagePuppet, Motion  # noqa: E402
from mop.render.image2d import ImageRenderer  # noqa: E402

DATA = Path(characters.__file__).parent / "assets"
FPS = 25.0


def timed(function, repeats: int) -> np.ndarray:
    """Seconds per call over `repeats` calls (after one warm-up call)."""
    function()
    times = np.empty(repeats)
    for i in range(repeats):
        start = time.perf_counter()
        function()
        times[i] = time.perf_counter() - start
    return times


def line(label: str, seconds: np.ndarray, extra: str = "") -> None:
    print(f"  {label:<36s} median {1e3 * np.median(seconds):7.2f} ms  p90 "
          f"{1e3 * np.percentile(seconds, 90):7.2f} ms  min {1e3 * seconds.min():7.2f} ms {extra}")


def load_puppet(picture, mode="springs"):
    data = json.loads((DATA / "momo_wave.json").read_text())
    scale = picture.shape[1] / 512 if isinstance(picture, np.ndarray) else 1.0
    puppet = ImagePuppet.from_image(picture, mode=mode)
    for name, pin in data["pins"].items():
        puppet.add_pin(np.asarray(pin["xy"]) * scale, name=name, fixed=pin.get("fixed", False))
    channels = {name: (ch["times"], np.asarray(ch["values"]) * scale)
                for name, ch in data["channels"].items()}
    return puppet, Motion(channels, interpolation=data.get("interpolation", "linear"))


class PyrenderReference:
    """The alternative: the same textured mesh drawn by pyrender (OpenGL via EGL, orthographic,
    unlit). Vertex positions live in GPU buffers built with the mesh, so a deformed frame means
    a new mesh node; `static` re-renders an unchanged scene (the fixed per-frame cost)."""

    def __init__(self, puppet):
        if not hasattr(np, "infty"):
            np.infty = np.inf  # pyrender 0.1.45 on NumPy 2
        import pyrender
        from PIL import Image
        self.pyrender = pyrender
        height, width = puppet.mask.shape
        texture = pyrender.Texture(source=Image.fromarray(puppet.image), source_channels="RGBA",
                                   sampler=pyrender.Sampler(magFilter=9729, minFilter=9729))
        self.material = pyrender.MetallicRoughnessMaterial(baseColorTexture=texture,
                                                           alphaMode="BLEND", doubleSided=True)
        self.uv = np.c_[puppet.uv[:, 0], 1.0 - puppet.uv[:, 1]]
        self.triangles = puppet.triangles
        self.scene = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[1, 1, 1])
        camera = pyrender.OrthographicCamera(xmag=width / 2, ymag=height / 2, znear=0.1, zfar=10)
        pose = np.eye(4)
        pose[:3, 3] = [width / 2 - 0.5, -(height / 2 - 0.5), 5.0]
        self.scene.add(camera, pose=pose)
        self.node = self.scene.add(self._mesh(puppet.vertices))
        self.renderer = pyrender.OffscreenRenderer(width, height)
        self.flags = pyrender.RenderFlags.RGBA | pyrender.RenderFlags.FLAT

    def _mesh(self, vertices):
        positions = np.c_[vertices[:, 0], -vertices[:, 1], np.zeros(len(vertices))]
        return self.pyrender.Mesh([self.pyrender.Primitive(
            positions=positions, texcoord_0=self.uv, indices=self.triangles,
            material=self.material)])

    def render(self, vertices):
        self.scene.remove_node(self.node)
        self.node = self.scene.add(self._mesh(vertices))
        return self.renderer.render(self.scene, flags=self.flags)[0]

    def static(self):
        return self.renderer.render(self.scene, flags=self.flags)[0]

    def close(self):
        self.renderer.delete()


def bench_size(picture, label: str, repeats: int, *, compare_gl: bool) -> None:
    print(f"\n{label}")
    build = timed(lambda: ImagePuppet.from_image(picture), max(3, repeats // 10))
    puppet, motion = load_puppet(picture)
    height, width = puppet.mask.shape
    print(f"  mesh: {len(puppet.vertices)} vertices, {len(puppet.triangles)} triangles, "
          f"{len(puppet.springs)} springs, cell {puppet.cell_size:.1f} px, mesh scale "
          f"{puppet.mesh_scale:g}")
    line("build (from_image)", build)

    frame_times = np.arange(int(motion.duration * FPS) + 1) / FPS
    samples = [motion.sample(t) for t in frame_times]
    state = {"k": 0}

    def step():
        state["k"] = (state["k"] % (len(samples) - 1)) + 1
        if state["k"] == 1:
            puppet.reset()
        puppet.step(1 / FPS, samples[state["k"]])

    line("springs step (1/25 s, rubber)", timed(step, repeats),
         f"({puppet._integrator.substeps} Verlet substeps)")
    arap_puppet, _ = load_puppet(picture, mode="arap")
    arap_step = timed(lambda: arap_puppet.step(1 / FPS, samples[np.random.randint(
        len(samples))]), repeats)
    line("arap step (same pin set)", arap_step)
    refactor = timed(lambda: arap_puppet._arap.systems.__func__(arap_puppet._arap, np.sort(
        np.random.choice(len(arap_puppet.vertices), 40, replace=False))), 5)
    line("arap factorisation (new pin set)", refactor)

    shapes = puppet.simulate(motion, fps=FPS)
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles,
                             size=(width, height), background="transparent")
    frame = np.empty((height, width, 4), np.uint8)
    state["k"] = 0

    def render():
        state["k"] = (state["k"] + 1) % len(shapes)
        renderer.render_into(shapes[state["k"]], frame)

    ours = timed(render, repeats)
    line("render (numba rasteriser, RGBA)", ours,
         f"= {1 / np.median(ours):.0f} fps ({1 / ours.min():.0f} best)")
    copy = timed(lambda: np.copyto(frame, renderer._blank), repeats)
    line("  reference: clearing the frame", copy,
         f"(render = {np.median(ours) / np.median(copy):.0f}x a frame copy)")
    if compare_gl:
        try:
            gl = PyrenderReference(puppet)
        except Exception as error:  # no EGL / pyrender here: say so, keep going
            print(f"  pyrender reference unavailable: {type(error).__name__}: {error}")
        else:
            state["k"] = 0

            def gl_render():
                state["k"] = (state["k"] + 1) % len(shapes)
                gl.render(shapes[state["k"]])

            gl_times = timed(gl_render, max(5, repeats // 4))
            gl_static = timed(gl.static, max(5, repeats // 4))
            line("  pyrender/EGL, deformed mesh", gl_times,
                 f"= {np.median(gl_times) / np.median(ours):.1f}x ours")
            line("  pyrender/EGL, unchanged scene", gl_static,
                 f"= {np.median(gl_static) / np.median(ours):.1f}x ours")
            reference = renderer.render(shapes[10])
            difference = np.abs(gl.render(shapes[10]).astype(int) - reference)
            print(f"  pyrender vs ours on one frame: mean |difference| {difference.mean():.2f} "
                  f"levels (0..255)")
            gl.close()

    for interval in (0.2, 0.1, 0.05):
        baked = puppet.bake(motion, fps=FPS, max_interval=interval)
        print(f"  baked, keys <= {interval:.2f} s apart: {baked.key_count} keys for "
              f"{len(shapes)} frames, deviation from simulation max {baked.deviation_max:.2f} px,"
              f" mean {baked.deviation_mean:.2f} px")
    baked = puppet.bake(motion, fps=FPS, max_interval=0.1)
    blended = np.empty_like(puppet.vertices)
    state["k"] = 0

    def playback():
        state["k"] = (state["k"] + 1) % len(frame_times)
        baked.shape_at(frame_times[state["k"]], blended)
        renderer.render_into(blended, frame)

    play = timed(playback, repeats)
    line("baked playback (blend + render)", play,
         f"= {1 / np.median(play):.0f} fps ({1 / play.min():.0f} best)")

    def simulated_playback():
        step()
        renderer.render_into(puppet.state.x, frame)

    live = timed(simulated_playback, repeats)
    line("simulated playback (step + render)", live,
         f"= {1 / np.median(live):.0f} fps ({np.median(live) / np.median(play):.1f}x baked)")


def make_pictures(folder: Path) -> None:
    """The README pictures: the built mesh with pins, frames of a pulled puppet, materials and
    modes side by side, and a real photograph cut out over a noisy green background."""
    from PIL import Image, ImageDraw

    from mop.export import over_colour
    from mop.render.image2d import draw_mesh_preview, puppet_preview

    folder.mkdir(parents=True, exist_ok=True)
    puppet, _ = load_puppet(str(DATA / "momo.png"))
    Image.fromarray(puppet_preview(puppet)).save(folder / "image_mesh.png", optimize=True)

    def pulled(material="rubber", mode="springs"):
        p = ImagePuppet.from_image(DATA / "momo.png", material=material, mode=mode)
        p.add_pin((196, 470), name="left_foot", fixed=True)
        p.add_pin((316, 470), name="right_foot", fixed=True)
        p.add_pin((446, 172), name="right_hand")
        hand = p.vertices[p.pins["right_hand"].index]
        goal = hand + (0.3 * 415 * np.array([0.8, -0.6]))   # 30% of the character's size
        motion = Motion({"right_hand": ([0.0, 0.4, 2.0], [hand, goal, goal])})
        return p, p.simulate(motion, fps=FPS), hand, goal

    def tile(p, shape, label, goal=None, size=256):
        renderer = ImageRenderer(p.image, p.vertices, p.triangles, size=(640, 512),
                                 background="#ffffff")
        frame = renderer.render(shape + (40, 0))[:, :, :3]
        image = Image.fromarray(frame).resize((size * 640 // 512, size), Image.LANCZOS)
        pen = ImageDraw.Draw(image)
        if goal is not None:
            x, y = (goal + (40, 0)) * size / 512
            pen.ellipse([x - 4, y - 4, x + 4, y + 4], outline=(230, 110, 20), width=2)
        pen.text((6, 4), label, fill=(30, 30, 30))
        return image

    def strip(tiles):
        width = sum(t.width for t in tiles)
        out = Image.new("RGB", (width, tiles[0].height), (255, 255, 255))
        x = 0
        for t in tiles:
            out.paste(t, (x, 0))
            x += t.width
        return out

    p, shapes, hand, goal = pulled()
    frames = [tile(p, shapes[k], f"t = {k / FPS:.2f} s", goal) for k in (0, 5, 10, 15, 25, 45)]
    strip(frames).save(folder / "image_pull.png", optimize=True)

    tiles = []
    for material in ("liquid", "fabric", "rubber", "rigid"):
        p, shapes, _, goal = pulled(material)
        tiles.append(tile(p, shapes[12], f"{material}, t = 0.48 s", goal))
    p, shapes, _, goal = pulled(mode="arap")
    tiles.append(tile(p, shapes[12], "arap", goal))
    strip(tiles).save(folder / "image_materials.png", optimize=True)

    # a real photograph (public-domain portrait shipped with matplotlib) cut out of a noisy
    # green background: picture, kept mask outline, mesh
    import cv2
    import matplotlib.cbook as cbook
    from characters.image.background import load_image
    photo = load_image(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))
    height, width = photo.shape[:2]
    truth = np.zeros((height, width), np.uint8)
    cv2.ellipse(truth, (width // 2, height // 2 - 10), (width // 3, height // 2 - 40), 0, 0, 360,
                1, -1)
    rng = np.random.default_rng(4)
    background = np.clip(np.array([40, 200, 60]) + rng.normal(0, 8, photo.shape), 0, 255)
    picture = np.where(truth[:, :, None] > 0, photo, background).astype(np.uint8)
    cut = ImagePuppet.from_image(picture)
    preview = draw_mesh_preview(cut.image, cut.vertices, cut.triangles, contour=cut.contour,
                                dim=0.15)
    panel = np.concatenate([picture, over_colour(cut.image, "#ffffff"), preview], axis=1)
    Image.fromarray(panel).resize((panel.shape[1] // 2, panel.shape[0] // 2),
                                  Image.LANCZOS).save(folder / "image_photo.png", optimize=True)
    for name in ("image_mesh", "image_pull", "image_materials", "image_photo"):
        size = (folder / f"{name}.png").stat().st_size // 1024
        print(f"wrote {folder / name}.png ({size} KB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--no-gl", action="store_true", help="skip the pyrender comparison")
    parser.add_argument("--pictures", type=Path, metavar="DIR",
                        help="only write the README pictures into DIR (docs/img)")
    args = parser.parse_args()
    if args.pictures:
        make_pictures(args.pictures)
        return
    from PIL import Image
    repeats = 30 if args.quick else 200
    small = np.asarray(Image.open(DATA / "momo.png"))
    big = np.asarray(Image.open(DATA / "momo.png").resize((2048, 2048), Image.LANCZOS))
    print(f"image puppet benchmark (numba threads {os.environ['NUMBA_NUM_THREADS']}, "
          f"{os.cpu_count()} cpus, {repeats} repeats)")
    bench_size(small, "512x512 picture", repeats, compare_gl=not args.no_gl)
    bench_size(big, "2048x2048 picture (meshed at 1024, rendered at 2048)", max(10, repeats // 5),
               compare_gl=not args.no_gl)


if __name__ == "__main__":
    main()
