"""Rendering image puppets: the numba rasteriser against a slow NumPy reference, exact coverage,
backgrounds, round trips through every export format, and the `mop puppet` command."""
import json
from pathlib import Path

import numpy as np
import pytest

import characters
from characters import ImagePuppet, Motion
from mop.export import CHROMA_GREEN, open_writer, over_colour
from mop.render.image2d import ImageRenderer, draw_mesh_preview, puppet_preview

cv2 = pytest.importorskip("cv2")
DATA = Path(characters.__file__).parent / "assets"


@pytest.fixture(scope="module")
def small_puppet():
    """Momo at 192x192: quick to render with the slow reference."""
    from PIL import Image
    picture = np.asarray(Image.open(DATA / "momo.png").resize((192, 192), Image.LANCZOS))
    return ImagePuppet.from_image(picture)


def _smooth_deformation(vertices, rng, amplitude=6.0):
    """A random smooth warp (no folds) plus a small jitter so no vertex sits on a pixel grid."""
    phase = rng.uniform(0, 2 * np.pi, 4)
    x, y = vertices[:, 0], vertices[:, 1]
    dx = amplitude * np.sin(y / 37.0 + phase[0]) + 0.5 * amplitude * np.cos(x / 23.0 + phase[1])
    dy = amplitude * np.cos(x / 41.0 + phase[2]) + 0.5 * amplitude * np.sin(y / 29.0 + phase[3])
    return vertices + np.stack([dx, dy], 1) + rng.uniform(-0.3, 0.3, vertices.shape)


def _reference_render(texture, texture_xy, screen_xy, triangles, size, colour):
    """Per triangle, every pixel centre's barycentric coordinates, bilinear float sampling of
    the premultiplied texture and the "over" operator in float. Also returns a mask of pixels
    too close to an edge to call (excluded from comparisons)."""
    width, height = size
    tex = texture.astype(np.float64)
    tex[:, :, :3] *= tex[:, :, 3:4] / 255.0
    out = np.zeros((height, width, 4))
    if colour is not None:
        out[:, :, :3] = colour
        out[:, :, 3] = 255.0
    ambiguous = np.zeros((height, width), bool)
    ys, xs = np.mgrid[0:height, 0:width]
    for tri in triangles:
        p = screen_xy[tri]
        d = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
        w1 = ((xs - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (ys - p[0, 1])) / d
        w2 = ((p[1, 0] - p[0, 0]) * (ys - p[0, 1]) - (xs - p[0, 0]) * (p[1, 1] - p[0, 1])) / d
        w0 = 1 - w1 - w2
        inside = (w0 > 0) & (w1 > 0) & (w2 > 0)
        ambiguous |= (np.minimum(np.minimum(np.abs(w0), np.abs(w1)), np.abs(w2)) < 1e-3) & \
            (w0 > -1e-3) & (w1 > -1e-3) & (w2 > -1e-3)
        t = texture_xy[tri]
        s = w0 * t[0, 0] + w1 * t[1, 0] + w2 * t[2, 0]
        u = w0 * t[0, 1] + w1 * t[1, 1] + w2 * t[2, 1]
        s = np.clip(s[inside], 0, tex.shape[1] - 1)
        u = np.clip(u[inside], 0, tex.shape[0] - 1)
        i0, j0 = np.floor(s).astype(int), np.floor(u).astype(int)
        i1, j1 = np.minimum(i0 + 1, tex.shape[1] - 1), np.minimum(j0 + 1, tex.shape[0] - 1)
        fx, fy = (s - i0)[:, None], (u - j0)[:, None]
        sample = ((1 - fx) * (1 - fy) * tex[j0, i0] + fx * (1 - fy) * tex[j0, i1]
                  + (1 - fx) * fy * tex[j1, i0] + fx * fy * tex[j1, i1])
        dst = out[inside]
        out[inside] = sample + dst * (1 - sample[:, 3:4] / 255.0)
    return out, ambiguous


@pytest.mark.parametrize("background", ["#3060a0", "transparent"])
@pytest.mark.slow
def test_rasteriser_matches_slow_reference(small_puppet, rng, background):
    puppet = small_puppet
    screen = _smooth_deformation(puppet.vertices, rng)
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles, size=(192, 192),
                             background=background)
    fast = renderer.render(screen).astype(np.float64)
    colour = None if background == "transparent" else np.array([0x30, 0x60, 0xa0], float)
    slow, ambiguous = _reference_render(puppet.image, puppet.vertices, screen,
                                        puppet.triangles, (192, 192), colour)
    clear = ~ambiguous
    assert clear.mean() > 0.9
    if colour is None:
        # compare premultiplied colour (straight colour is ill-defined where alpha is ~0)
        fast[:, :, :3] *= fast[:, :, 3:4] / 255.0
    assert np.abs(fast[clear] - slow[clear]).max() <= 2.5
    assert np.abs(fast[clear] - slow[clear]).mean() < 0.3


def test_rest_render_is_the_cutout(small_puppet):
    puppet = small_puppet
    for background in ("transparent", "#ffffff", "chroma"):
        renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles,
                                 size=(192, 192), background=background)
        frame = renderer.render(puppet.vertices)
        if background == "transparent":
            alpha = puppet.image[:, :, 3]
            assert np.array_equal(frame[:, :, 3], alpha), "the feathered alpha edge is kept"
            opaque = alpha == 255
            assert np.array_equal(frame[opaque], puppet.image[opaque])
            partial = (alpha > 0) & (alpha < 255)
            # straight colour after premultiplied storage: within rounding of 255 / alpha
            error = np.abs(frame[partial, :3].astype(int) - puppet.image[partial, :3])
            assert np.all(error <= np.ceil(128.0 / alpha[partial])[:, None] + 1)
        else:
            expected = over_colour(puppet.image, background)
            assert np.abs(frame[:, :, :3].astype(int) - expected).max() <= 1
            assert np.all(frame[:, :, 3] == 255)
    outside = puppet.image[:, :, 3] == 0
    assert np.all(frame[outside, :3] == CHROMA_GREEN)


def test_every_pixel_covered_exactly_once(small_puppet, rng):
    """A half-transparent flat texture: overlapping (double-drawn) pixels would get alpha
    192 and gaps 0 inside; exact coverage leaves 128 everywhere the mesh is."""
    puppet = small_puppet
    flat = np.zeros_like(puppet.image)
    flat[...] = (200, 100, 50, 128)
    renderer = ImageRenderer(flat, puppet.vertices, puppet.triangles, size=(192, 192))
    for screen in (puppet.vertices, _smooth_deformation(puppet.vertices, rng, 8.0)):
        alpha = renderer.render(screen)[:, :, 3]
        assert set(np.unique(alpha)) <= {0, 128}
        covered = np.zeros((192, 192), np.uint8)
        for tri in screen[puppet.triangles]:
            cv2.fillConvexPoly(covered, np.round(tri * 16).astype(np.int32), 1, shift=4)
        # (beyond the frame's edge is not covered: a triangle edge just inside the last row
        # leaves that row's pixel centres out)
        interior = cv2.erode(covered, np.ones((3, 3), np.uint8),
                             borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
        assert np.all(alpha[interior] == 128), "no gaps inside the mesh"


def test_render_follows_the_mesh(small_puppet):
    """Translating the mesh by whole pixels translates the picture exactly."""
    puppet = small_puppet
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles, size=(192, 192))
    rest = renderer.render(puppet.vertices)
    moved = renderer.render(puppet.vertices + (7, -5))
    assert np.array_equal(moved[10:187, 7:], rest[15:192, :185])


def test_renderer_input_checks(small_puppet):
    puppet = small_puppet
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles, size=(64, 48))
    with pytest.raises(ValueError, match=r"vertices must have shape \(\d+, 2\)"):
        renderer.render(puppet.vertices[:-1])
    with pytest.raises(ValueError, match=r"frame must be \(48, 64, 4\) uint8"):
        renderer.render_into(puppet.vertices, np.zeros((64, 48, 4), np.uint8))
    with pytest.raises(ValueError, match="texture must be"):
        ImageRenderer(puppet.image[:, :, :3], puppet.vertices, puppet.triangles, size=(8, 8))
    with pytest.raises(ValueError, match="background must be"):
        ImageRenderer(puppet.image, puppet.vertices, puppet.triangles, size=(8, 8),
                      background="plaid")


def test_mesh_preview_shows_pins(small_puppet):
    puppet = ImagePuppet.from_image(small_puppet.image)
    index = puppet.add_pin((96, 40), name="head")
    anchor = puppet.add_pin((75, 176), name="foot", fixed=True)
    preview = puppet_preview(puppet)
    assert preview.shape == (192, 192, 3) and preview.dtype == np.uint8
    x, y = np.round(puppet.vertices[index]).astype(int)
    assert tuple(preview[y, x]) == (240, 120, 20)           # driven pin: orange disc
    x, y = np.round(puppet.vertices[anchor]).astype(int)
    assert tuple(preview[y, x]) == (20, 70, 200)            # anchor: blue square
    plain = draw_mesh_preview(puppet.image, puppet.vertices, puppet.triangles)
    assert not np.array_equal(plain, preview)


def _warped(mask, rest, screen, triangles, size):
    """Reference: the mask carried by the deformed mesh, every output pixel sampled at the
    rest position its triangle maps it to (where a pull folds the mesh over itself, the pixel
    is the character's if any triangle over it maps it into the mask, as every triangle is
    drawn); beyond the mesh, by the nearest triangle's map extended, where that lands beyond
    the rest mesh too (so a mesh that cut the silhouette would show against it)."""
    width, height = size
    label = np.zeros((height, width), np.int32)
    for index, tri in enumerate(screen[triangles]):
        cv2.fillConvexPoly(label, np.round(tri * 16).astype(np.int32), index + 1, shift=4)
    footprint = np.zeros(mask.shape, np.uint8)
    for tri in rest[triangles]:
        cv2.fillConvexPoly(footprint, np.round(tri * 16).astype(np.int32), 1, shift=4)
    _, nearest = cv2.distanceTransformWithLabels((label == 0).astype(np.uint8), cv2.DIST_L2,
                                                 3, labelType=cv2.DIST_LABEL_PIXEL)
    sources = np.flatnonzero((label != 0).ravel())
    owner = label.ravel()[sources[nearest.ravel() - 1]] - 1
    owner = np.where(label.ravel() > 0, label.ravel() - 1, owner)
    ys, xs = np.mgrid[0:height, 0:width]
    points = np.stack([xs.ravel(), ys.ravel()], 1).astype(float)
    a, b, c = (screen[triangles[owner, k]] for k in range(3))
    d = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    w1 = ((points[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
          - (c[:, 0] - a[:, 0]) * (points[:, 1] - a[:, 1])) / d
    w2 = ((b[:, 0] - a[:, 0]) * (points[:, 1] - a[:, 1])
          - (points[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / d
    ra, rb, rc = (rest[triangles[owner, k]] for k in range(3))
    source = ra + w1[:, None] * (rb - ra) + w2[:, None] * (rc - ra)
    col = np.clip(np.round(source[:, 0]).astype(int), 0, mask.shape[1] - 1)
    row = np.clip(np.round(source[:, 1]).astype(int), 0, mask.shape[0] - 1)
    inside_picture = ((source[:, 0] > -0.5) & (source[:, 0] < mask.shape[1] - 0.5)
                      & (source[:, 1] > -0.5) & (source[:, 1] < mask.shape[0] - 0.5))
    consistent = (label.ravel() > 0) | (footprint[row, col] == 0)
    reference = (mask[row, col] & inside_picture & consistent).reshape(height, width)
    for tri, source_tri in zip(screen[triangles], rest[triangles]):
        covered = np.zeros((height, width), np.uint8)
        cv2.fillConvexPoly(covered, np.round(tri * 16).astype(np.int32), 1, shift=4)
        ys, xs = np.nonzero(covered)
        if len(ys) == 0:
            continue
        to_rest = cv2.getAffineTransform(tri.astype(np.float32), source_tri.astype(np.float32))
        here = np.stack([xs, ys, np.ones_like(xs)], 1).astype(float) @ to_rest.T
        col = np.round(here[:, 0]).astype(int)
        row = np.round(here[:, 1]).astype(int)
        keep = (col >= 0) & (col < mask.shape[1]) & (row >= 0) & (row < mask.shape[0])
        reference[ys[keep], xs[keep]] |= mask[row[keep], col[keep]]
    return reference


@pytest.mark.realdata
@pytest.mark.parametrize("size, mesh_size", [(360, 1024), (1200, 400)],
                         ids=["meshed at full size", "meshed downscaled"])
def test_pulled_puppet_edge_follows_the_silhouette(rng, size, mesh_size):
    """A photo cut out and pulled by a limb: the rendered alpha matches the puppet's mask
    carried by the mesh, at the edge within the feather (and one analysed pixel when the
    mesh was built on a downscaled copy), and nowhere cut along the grid's cells (the mesh
    holds every pixel with alpha)."""
    pytest.importorskip("skimage")
    import picture_kit as kit
    height = size * 3 // 4
    photo = cv2.resize(kit.photo("chelsea"), (size, height), interpolation=cv2.INTER_CUBIC)
    truth = kit.creature(rng, height, size)
    picture = kit.photo_on_background(rng, photo, truth, colour=(60, 100, 190), gradient=0.3,
                                      noise=4.0, quality=85)
    # cells several times wider than the edge's allowed offset, whatever the silhouette's
    # size, so that an edge cut along them would show
    allowed = 1.5 + max(1.0, size / 640)
    puppet = ImagePuppet.from_image(picture, mode="arap", max_mesh_size=mesh_size,
                                    cell_size=4 * allowed)
    names = puppet.add_auto_pins()
    limb = [name for name in names if not puppet.pins[name].fixed][0]
    start = puppet.vertices[puppet.pins[limb].index]
    outward = start - puppet.vertices[puppet.pins["body"].index]
    target = start + 0.15 * size * outward / np.linalg.norm(outward)
    puppet.step(0.04, {limb: target})
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles,
                             size=(size, height), background="transparent")
    alpha = renderer.render(puppet.surface())[:, :, 3]
    reference = _warped(puppet.mask, puppet.vertices, puppet.surface(), puppet.triangles,
                        (size, height))
    # the feather ramps inward (a mask's edge pixel has alpha 0.4): the drawn silhouette is
    # where alpha reaches a quarter
    rendered = alpha >= 64
    assert kit.iou(rendered, reference) >= 0.98
    # every disagreement lies at the reference's edge, none a cell away
    # (the frame's border counts as edge: a pulled limb may reach it)
    edge = reference & ~cv2.erode(reference.astype(np.uint8), np.ones((3, 3)),
                                  borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    to_edge = cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 5)
    assert to_edge[rendered != reference].max() <= allowed, to_edge[rendered != reference].max()
    assert puppet.cell_size > 3 * allowed
    # and the silhouette is never cut by the mesh: no visible pixel shares a side with the
    # outside of the deformed mesh (the mesh keeps a margin around every pixel with alpha;
    # where a pull stretches the feather, a visible pixel may touch the outside at a corner)
    covered = np.zeros((height, size), np.uint8)
    for tri in puppet.surface()[puppet.triangles]:
        cv2.fillConvexPoly(covered, np.round(tri * 16).astype(np.int32), 1, shift=4)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    beside_outside = cv2.dilate(1 - covered, cross).astype(bool)
    assert not np.any(rendered & beside_outside)


# --- round trips through every export format ---------------------------------------------

def _read_video(path):
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame[:, :, ::-1])
    capture.release()
    return frames


def _pulled_frames(puppet, count=4):
    puppet = ImagePuppet.from_image(puppet.image)
    puppet.add_pin((96, 40), name="head")
    puppet.add_pin((75, 176), name="foot", fixed=True)
    head = puppet.vertices[puppet.pins["head"].index]
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles, size=(192, 192))
    frames = []
    for k in range(count):
        puppet.step(0.04, {"head": head + (8.0 * k, -4.0 * k)})
        frames.append(renderer.render(puppet.surface()))
    return frames


def _psnr(a, b):
    error = np.mean((a.astype(float) - b.astype(float)) ** 2)
    return 10 * np.log10(255.0 ** 2 / max(error, 1e-12))


@pytest.mark.parametrize("target", ["clip.mp4", "clip.mkv", "clip.gif", "frames/"])
@pytest.mark.slow
def test_render_round_trips_through_export(small_puppet, tmp_path, target):
    from PIL import Image
    frames = _pulled_frames(small_puppet)
    path = tmp_path / target
    background = None if target in ("clip.gif", "frames/") else "#ffffff"
    with open_writer(path, fps=25, size=(192, 192), background=background) as writer:
        for frame in frames:
            writer.write(frame)
    if target.endswith((".mp4", ".mkv")):
        back = _read_video(path)
        assert len(back) == len(frames)
        for original, read in zip(frames, back):
            expected = over_colour(original, "#ffffff")
            if target.endswith(".mkv"):
                assert np.array_equal(read, expected), "FFV1 is lossless"
            else:
                assert _psnr(read, expected) > 30.0
    elif target.endswith(".gif"):
        gif = Image.open(path)
        assert gif.n_frames == len(frames)
        for k, original in enumerate(frames):
            gif.seek(k)
            read = np.asarray(gif.convert("RGBA"))
            assert np.array_equal(read[:, :, 3] > 0, original[:, :, 3] >= 128), "1-bit alpha"
            solid = original[:, :, 3] == 255
            assert np.abs(read[solid, :3].astype(int) - original[solid, :3]).mean() < 4.0
    else:
        files = sorted(path.glob("*.png"))
        assert [f.name for f in files] == [f"frame_{k:06d}.png" for k in range(len(frames))]
        for original, file in zip(frames, files):
            assert np.array_equal(np.asarray(Image.open(file)), original), "PNG keeps RGBA"


# --- the command line ----------------------------------------------------------------------

def _small_assets(tmp_path):
    from PIL import Image
    Image.open(DATA / "momo.png").resize((128, 128), Image.LANCZOS).save(tmp_path / "momo.png")
    data = json.loads((DATA / "momo_wave.json").read_text())
    pins = {name: {**pin, "xy": [v / 4 for v in pin["xy"]]} for name, pin in data["pins"].items()}
    channels = {name: {"times": ch["times"][:5],
                       "values": [[v / 4 for v in row] for row in ch["values"][:5]]}
                for name, ch in data["channels"].items()}
    motion = {"format": "mop.motion", "version": 1, "channels": channels}
    (tmp_path / "wave.json").write_text(json.dumps(motion))
    (tmp_path / "pins.json").write_text(json.dumps({"pins": pins}))
    return tmp_path / "momo.png", tmp_path / "wave.json", tmp_path / "pins.json", pins


@pytest.mark.slow
def test_cli_renders_a_motion(tmp_path, capsys):
    from mop.cli import main
    image, motion, pins, _ = _small_assets(tmp_path)
    out = tmp_path / "out.mkv"
    code = main(["puppet", str(image), "--motion", str(motion), "--pins", str(pins),
                 "--out", str(out), "--show-mesh", str(tmp_path / "mesh.png"),
                 "--background", "chroma", "--fps", "10"])
    assert code == 0
    printed = capsys.readouterr()
    assert "wrote" in printed.out and "rendering out.mkv" in printed.err
    frames = _read_video(out)
    duration = Motion.load(motion).duration
    assert len(frames) == int(duration * 10) + 1
    assert frames[0].shape == (128, 128, 3)
    assert tuple(frames[0][0, 0]) == CHROMA_GREEN
    assert (tmp_path / "mesh.png").stat().st_size > 0
    # ARAP mode, pins from a sidecar next to the image, PNG frames with alpha
    (tmp_path / "momo.pins.json").write_text(pins.read_text())
    code = main(["puppet", str(image), "--motion", str(motion), "--mode", "arap",
                 "--out", str(tmp_path / "seq_%03d.png"), "--duration", "0.5", "--fps", "10"])
    assert code == 0
    assert len(list(tmp_path.glob("seq_*.png"))) == 6


@pytest.mark.slow
def test_cli_bad_input_messages(tmp_path, capsys):
    from mop.cli import main
    image, motion, pins, pin_table = _small_assets(tmp_path)
    # no pins anywhere
    assert main(["puppet", str(image), "--motion", str(motion), "--out",
                 str(tmp_path / "a.mp4")]) == 1
    assert "the motion drives pins" in capsys.readouterr().err
    # the motion names a pin the pins file lacks
    partial = {k: v for k, v in pin_table.items() if k != "head"}
    (tmp_path / "partial.json").write_text(json.dumps({"pins": partial}))
    assert main(["puppet", str(image), "--motion", str(motion), "--pins",
                 str(tmp_path / "partial.json"), "--out", str(tmp_path / "a.mp4")]) == 1
    assert "the motion drives ['head'] but this puppet has no driven pin" in \
        capsys.readouterr().err
    # a pin outside the character
    outside = dict(pin_table, head={"xy": [2, 2]})
    (tmp_path / "outside.json").write_text(json.dumps({"pins": outside}))
    assert main(["puppet", str(image), "--motion", str(motion), "--pins",
                 str(tmp_path / "outside.json"), "--out", str(tmp_path / "a.mp4")]) == 1
    assert "pin 'head' at (2, 2) is outside the character" in capsys.readouterr().err
    # a uniform picture
    from PIL import Image
    Image.new("RGB", (64, 64), (10, 20, 30)).save(tmp_path / "flat.png")
    assert main(["puppet", str(tmp_path / "flat.png"), "--show-mesh",
                 str(tmp_path / "m.png")]) == 1
    assert "image is uniform" in capsys.readouterr().err
    # transparency asked of a format without alpha
    assert main(["puppet", str(image), "--motion", str(motion), "--pins", str(pins),
                 "--out", str(tmp_path / "a.mp4"), "--background", "transparent"]) == 1
    assert ".mp4 video has no alpha channel" in capsys.readouterr().err
    assert main(["puppet", str(image), "--out", str(tmp_path / "a.mp4")]) == 1
    assert "--out needs --motion" in capsys.readouterr().err
