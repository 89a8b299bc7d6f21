"""Image puppet figures: build, simulation step and render times for a 512x512 and a
2048x2048 picture, baked playback fps, baked-vs-simulated deviation, the renderer choice
(numba scanline rasteriser vs pyrender/EGL on the same mesh, same process), and the build time
of a 12-megapixel photo (a phone's) against reading its JPEG and a flat-colour key.

    python benchmarks/image_puppet.py [--quick] [--only photo | accuracy]
    python benchmarks/image_puppet.py --pictures docs/img      # the guide's pictures

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


def timed(function, repeats: int, clock=time.perf_counter) -> np.ndarray:
    """Seconds per call over `repeats` calls (after one warm-up call). With
    `clock=time.process_time`: CPU seconds of this process (all threads), what the wall time
    would be on an idle core when other work shares the machine."""
    function()
    times = np.empty(repeats)
    for i in range(repeats):
        start = clock()
        function()
        times[i] = clock() - start
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


def phone_photo(folder: Path) -> Path:
    """A 12-megapixel JPEG (4000x3000, quality 90) like a phone's: a real photograph
    (scikit-image's coffee, upscaled) cut to a character's silhouette over a backdrop lit
    30 % brighter on one side, with sensor noise (the pictures the tests build)."""
    import cv2
    from PIL import Image
    kit = picture_kit()
    rng = np.random.default_rng(7)
    photo = cv2.resize(kit.photo("coffee"), (4000, 3000), interpolation=cv2.INTER_CUBIC)
    truth = kit.creature(rng, 3000, 4000)
    picture = kit.photo_on_background(rng, photo, truth, colour=(70, 150, 90), gradient=0.3,
                                      noise=5.0, quality=None)
    path = folder / "phone_photo.jpg"
    Image.fromarray(picture).save(path, quality=90)
    return path


def picture_kit():
    """tests/picture_kit.py: photos on uneven light and pen drawings with known silhouettes."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import picture_kit as kit
    return kit


def bench_photo(repeats: int) -> None:
    """Build time of a 12-megapixel photo, from the array and from the JPEG file."""
    import tempfile

    from characters.image.background import load_image, remove_background
    with tempfile.TemporaryDirectory() as folder:
        path = phone_photo(Path(folder))
        picture = load_image(path)
        height, width = picture.shape[:2]
        print(f"\n{width}x{height} photo ({width * height / 1e6:.0f} megapixels, JPEG "
              f"{path.stat().st_size / 1e6:.1f} MB), target: build <= 1 s")
        read = timed(lambda: load_image(path), repeats)
        build = timed(lambda: ImagePuppet.from_image(picture), repeats)
        build_cpu = np.median(timed(lambda: ImagePuppet.from_image(picture), repeats,
                                    clock=time.process_time))
        from_file = timed(lambda: ImagePuppet.from_image(path), repeats)
        cut = timed(lambda: remove_background(picture), repeats)
        plain = timed(lambda: remove_background(picture, kind="plain"), repeats)
    puppet = ImagePuppet.from_image(picture)
    print(f"  found as {puppet.kind}; mesh {len(puppet.vertices)} vertices (meshed at "
          f"{puppet.mesh_scale:.3f} x), texture {width}x{height}")
    line("build (from_image, array)", build, f"(CPU {1e3 * build_cpu:.0f} ms)")
    line("  of which the cut-out", cut, f"({np.median(cut) / np.median(build):.0%})")
    line("build from the JPEG file", from_file)
    line("  reference: reading the JPEG alone", read,
         f"(build from file = {np.median(from_file) / np.median(read):.1f}x)")
    line("  reference: a flat-colour key instead", plain,
         f"(the light field and GrabCut cost {np.median(cut) / np.median(plain):.1f}x it)")


def bench_accuracy(seeds: range) -> None:
    """Cut-out and automatic-pin accuracy on the pictures the tests build, over several seeds:
    photographs cut to silhouettes over backdrops lit 25-50 % unevenly (noise, JPEG 65-80),
    pen outlines on paper (vignette, noise, JPEG), a creature casting a soft shadow on its
    backdrop, textures on a grey backdrop of their own mean, stars, stick figures and the
    horse. Both the photographs and outline shapes used for tuning and those held out are
    reported."""
    import time

    from characters.image.background import remove_background
    from characters.image.skeleton import propose_pins
    kit = picture_kit()
    photos = {name: kit.photo(name) for name in kit.TUNING_PHOTOS + kit.HELD_OUT_PHOTOS}
    photo_iou = {"tuning": [], "held out": []}
    drawing_iou = {"tuning": [], "held out": []}
    details_inside = [0, 0]
    started = time.perf_counter()
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for name, photo in photos.items():
            group = "held out" if name in kit.HELD_OUT_PHOTOS else "tuning"
            height, width = photo.shape[:2]
            for _, truth in kit.silhouettes(rng, height, width):
                picture = kit.photo_on_background(
                    rng, photo, truth, colour=kit.backdrop_colour(rng),
                    gradient=rng.uniform(0.25, 0.5), noise=rng.uniform(3, 8),
                    quality=int(rng.integers(65, 81)))
                photo_iou[group].append(kit.iou(remove_background(picture).mask, truth))
        for ink in kit.INK_NAMES:
            for shape in kit.TUNING_OUTLINES + kit.HELD_OUT_OUTLINES:
                group = "held out" if shape in kit.HELD_OUT_OUTLINES else "tuning"
                outline = kit.outline_shape(rng, shape, 400, 400)
                picture, truth, details = kit.pen_drawing(
                    rng, 400, 400, outline=outline, ink=ink,
                    line_width=int(rng.integers(2, 6)), quality=int(rng.integers(65, 81)),
                    vignette=rng.uniform(0.2, 0.4))
                mask = remove_background(picture).mask
                drawing_iou[group].append(kit.iou(mask, truth))
                details_inside[0] += bool(np.all(mask[details]))
                details_inside[1] += 1
    print(f"\ncut-out accuracy, seeds {seeds.start}-{seeds.stop - 1} "
          f"({time.perf_counter() - started:.0f} s)")
    for what, table, target in (("photos", photo_iou, 0.95), ("drawings", drawing_iou, 0.92)):
        for group, values in table.items():
            values = np.array(values)
            print(f"  {what:8s} {group:8s} n={len(values):3d}  IoU mean {values.mean():.4f}  "
                  f"min {values.min():.4f}  >= {target}: {(values >= target).sum()} of "
                  f"{len(values)}")
    print(f"  drawings: details inside the puppet {details_inside[0]} of {details_inside[1]}")
    for group, names in (("tuning", kit.TUNING_PHOTOS), ("held out", ("coffee",))):
        taken, met = [], 0
        for name in names:
            for seed in seeds:
                picture, truth, shadow = kit.shadow_case(np.random.default_rng(seed),
                                                         photos[name])
                mask = remove_background(picture).mask
                taken.append((mask & shadow).sum() / shadow.sum())
                met += kit.iou(mask, truth) >= 0.95 and taken[-1] <= 0.02
        print(f"  shadows  {group:8s} n={len(taken):3d}  shadow taken mean "
              f"{100 * np.mean(taken):.2f} %  max {100 * np.max(taken):.2f} %  IoU >= 0.95 "
              f"and <= 2 % taken: {met} of {len(taken)}")
    other = []
    for name in kit.OTHER_PHOTOS:
        photo = kit.photo(name)
        for seed in range(100, 103):
            rng = np.random.default_rng(seed)
            for _, truth in kit.silhouettes(rng, *photo.shape[:2]):
                picture = kit.photo_on_background(
                    rng, photo, truth, colour=kit.backdrop_colour(rng),
                    gradient=rng.uniform(0.25, 0.5), noise=rng.uniform(3, 8),
                    quality=int(rng.integers(65, 81)))
                other.append(kit.iou(remove_background(picture).mask, truth))
    other = np.array(other)
    print(f"  photos   other    n={len(other):3d}  IoU mean {other.mean():.4f}  min "
          f"{other.min():.4f}  >= 0.95: {(other >= 0.95).sum()} of {len(other)} "
          f"({len(kit.OTHER_PHOTOS)} more pictures, seeds 100-102)")
    textured, warned = [], []
    for name in kit.TEXTURES:
        for seed in range(100, 103):
            for _, picture, truth in kit.texture_on_its_mean(np.random.default_rng(seed), name):
                cutout = remove_background(picture)
                textured.append(kit.iou(cutout.mask, truth))
                warned.append(any("may be wrong" in note for note in cutout.notes))
    textured, warned = np.array(textured), np.array(warned)
    print(f"  textures on grey of their mean n={len(textured)}  IoU mean {textured.mean():.4f}  "
          f">= 0.95: {(textured >= 0.95).sum()}; said they may be wrong: {warned.sum()} "
          f"(of the {(textured < 0.95).sum()} under 0.95: {warned[textured < 0.95].sum()}; "
          f"{', '.join(kit.TEXTURES)}, seeds 100-102)")
    worst = {"star": 0.0, "stick figure": 0.0}
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for _ in range(10):
            for name, (mask, tips) in (("star", kit.star(rng, size=int(rng.integers(200, 600)),
                                                          points=int(rng.integers(4, 9)))),
                                       ("stick figure", kit.stick_figure(
                                           rng, size=int(rng.integers(200, 600))))):
                worst[name] = max(worst[name], kit.worst_tip(propose_pins(mask), mask, tips))
    horse = kit.horse()
    worst["horse"] = kit.worst_tip(propose_pins(horse), horse, kit.HORSE_TIPS)
    print("  automatic pins, the farthest limb tip from its pin (x the figure's size): "
          + ", ".join(f"{name} {value:.3f}" for name, value in worst.items())
          + f" (target <= 0.05; {10 * len(seeds)} stars and stick figures)")


def make_pictures(folder: Path) -> None:
    """The guide's pictures: frames of a pulled puppet, materials and modes side by side,
    each kind of input and what it becomes, automatic pins."""
    from PIL import Image, ImageDraw

    folder.mkdir(parents=True, exist_ok=True)

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

    input_kinds(folder)
    automatic_pins(folder)
    for name in ("image_pull", "image_materials", "image_inputs", "image_pins"):
        size = (folder / f"{name}.png").stat().st_size // 1024
        print(f"wrote {folder / name}.png ({size} KB)")


def _tiles_row(tiles, size=200):
    """Pictures (H, W, 3) uint8 side by side, each fitted into a size x size square."""
    import cv2
    row = []
    for tile in tiles:
        scale = size / max(tile.shape[:2])
        fitted = cv2.resize(tile, (round(tile.shape[1] * scale), round(tile.shape[0] * scale)),
                            interpolation=cv2.INTER_AREA)
        square = np.full((size, size, 3), 255, np.uint8)
        top, left = (size - fitted.shape[0]) // 2, (size - fitted.shape[1]) // 2
        square[top:top + fitted.shape[0], left:left + fitted.shape[1]] = fitted
        row.append(square)
    return np.concatenate(row, axis=1)


def _save_small(picture: np.ndarray, path: Path) -> None:
    """A PNG of 256 colours (a third of the size; the guide's pictures do not need more)."""
    from PIL import Image
    Image.fromarray(picture).quantize(256, method=Image.Quantize.MEDIANCUT).save(
        path, optimize=True)


def _checker(shape, cell=12) -> np.ndarray:
    ys, xs = np.indices(shape[:2])
    light = ((ys // cell + xs // cell) % 2).astype(bool)
    return np.where(light[:, :, None], 235, 200).astype(np.uint8).repeat(3, axis=2)


def _became(puppet) -> np.ndarray:
    """The cut-out over a checkerboard (transparency shows)."""
    alpha = puppet.image[:, :, 3:4].astype(np.float32) / 255.0
    return (puppet.image[:, :, :3] * alpha + _checker(puppet.image.shape) * (1 - alpha)).astype(
        np.uint8)


def _mesh_close_up(puppet) -> np.ndarray:
    """The mesh preview cropped to the mesh, with a margin."""
    from mop.render.image2d import puppet_preview
    preview = puppet_preview(puppet)
    low = np.floor(puppet.vertices.min(axis=0) - 0.05 * puppet.mask.shape[1]).astype(int)
    high = np.ceil(puppet.vertices.max(axis=0) + 0.05 * puppet.mask.shape[1]).astype(int)
    low = np.maximum(low, 0)
    return np.ascontiguousarray(preview[low[1]:high[1], low[0]:high[0]])


def input_kinds(folder: Path) -> None:
    """image_inputs.png: each kind of picture (rows) as given, what it becomes (the cut-out
    over a checkerboard) and its mesh with the automatic pins."""
    import cv2

    from characters.image.background import load_image
    kit = picture_kit()
    rng = np.random.default_rng(11)
    rows = []
    photo = kit.photo("astronaut")
    truth = kit.creature(rng, 512, 512)
    rows.append(("a photo, lamp on one side (gradient 40 %)", kit.photo_on_background(
        rng, photo, truth, colour=(200, 170, 90), gradient=0.4, noise=6, quality=70)))
    cat = kit.photo("chelsea")
    truth = kit._fill(kit.blob(rng, *cat.shape[:2]), *cat.shape[:2])
    rows.append(("a toy on a table, its shadow", kit.photo_on_background(
        rng, cat, truth, colour=(120, 150, 200), gradient=0.3, noise=5, quality=75,
        shadow=0.45)))
    outline = kit.outline_shape(rng, "bear", 400, 400)
    drawing, _, _ = kit.pen_drawing(rng, 400, 400, outline=outline, ink="brown", line_width=3,
                                    vignette=0.35, quality=70)
    rows.append(("a pen drawing on paper, vignette", drawing))
    outline = kit.outline_shape(rng, "ghost", 400, 400)
    gapped, _, _ = kit.pen_drawing(rng, 400, 400, outline=outline, ink="blue", line_width=3,
                                   vignette=0.3, quality=75, gap=40)
    rows.append(("an outline left open: the strokes alone", gapped))
    momo = load_image(DATA / "momo.png")
    rows.append(("a cartoon on a flat colour", momo))
    rows.append(("a cut-out with alpha", ImagePuppet.from_image(momo).image))
    tiles = []
    for label, picture in rows:
        puppet = ImagePuppet.from_image(picture)
        puppet.add_auto_pins()
        shown = picture if picture.shape[2] == 3 else _became(ImagePuppet.from_image(picture))
        tile = _tiles_row([shown, _became(puppet), _mesh_close_up(puppet)], size=220)
        cv2.putText(tile, f"{label} -> {puppet.kind}", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42,
                    (20, 20, 20), 1, cv2.LINE_AA)
        tiles.append(tile)
    _save_small(np.concatenate(tiles, axis=0), folder / "image_inputs.png")


def automatic_pins(folder: Path) -> None:
    """image_pins.png: the automatic pins of a star, a stick figure and a horse."""
    from mop.render.image2d import puppet_preview
    kit = picture_kit()
    rng = np.random.default_rng(2)
    masks = [kit.star(rng, size=360)[0], kit.stick_figure(rng, size=360)[0], kit.horse()]
    previews = []
    for mask in masks:
        picture = np.where(mask[:, :, None], np.array([70, 90, 160], np.uint8),
                           np.array([250, 250, 250], np.uint8))
        puppet = ImagePuppet.from_image(picture)
        puppet.add_auto_pins()
        previews.append(puppet_preview(puppet))
    _save_small(_tiles_row(previews, size=300), folder / "image_pins.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--no-gl", action="store_true", help="skip the pyrender comparison")
    parser.add_argument("--pictures", type=Path, metavar="DIR",
                        help="only write the guide's pictures into DIR (docs/img)")
    parser.add_argument("--only", choices=("photo", "accuracy"),
                        help="only the 12-megapixel photo's build time, or only the cut-out's "
                             "and automatic pins' accuracy")
    args = parser.parse_args()
    if args.pictures:
        make_pictures(args.pictures)
        return
    from PIL import Image
    repeats = 30 if args.quick else 200
    if args.only == "photo":
        bench_photo(5 if args.quick else 15)
        return
    if args.only == "accuracy":
        bench_accuracy(range(2) if args.quick else range(10))
        return
    small = np.asarray(Image.open(DATA / "momo.png"))
    big = np.asarray(Image.open(DATA / "momo.png").resize((2048, 2048), Image.LANCZOS))
    print(f"image puppet benchmark (numba threads {os.environ['NUMBA_NUM_THREADS']}, "
          f"{os.cpu_count()} cpus, {repeats} repeats)")
    bench_size(small, "512x512 picture", repeats, compare_gl=not args.no_gl)
    bench_size(big, "2048x2048 picture (meshed at 1024, rendered at 2048)", max(10, repeats // 5),
               compare_gl=not args.no_gl)
    bench_photo(5 if args.quick else 15)


if __name__ == "__main__":
    main()
