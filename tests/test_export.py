"""mop.export: writers for every format (round trips), compositing, interruption, errors."""
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from mop.export import (CHROMA_GREEN, OverColourBGR, compose_layers, open_writer,
                        over_colour, parse_background, write_frames)

cv2 = pytest.importorskip("cv2")


def _frames(rng, count=5, size=(40, 30)):
    """Moving soft shapes with every alpha level: (H, W, 4) uint8 straight alpha."""
    width, height = size
    ys, xs = np.mgrid[0:height, 0:width]
    frames = []
    for k in range(count):
        frame = np.zeros((height, width, 4), np.uint8)
        r = np.hypot(xs - 10 - 3 * k, ys - 15)
        frame[:, :, 0] = 200
        frame[:, :, 1] = (40 + 5 * xs).clip(0, 255)
        frame[:, :, 2] = (255 - 6 * ys).clip(0, 255)
        frame[:, :, 3] = np.clip(255 * (12 - r) / 4, 0, 255).astype(np.uint8)
        frame[2:6, 25:35] = (*rng.integers(0, 256, 3), 255)
        frames.append(frame)
    return frames


def _read_video(path):
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame[:, :, ::-1])
    return frames


def test_parse_background():
    assert parse_background(None) is None
    assert parse_background("transparent") is None
    assert parse_background("chroma") == CHROMA_GREEN == (0, 177, 64)
    assert parse_background("#FF8000") == (255, 128, 0)
    assert parse_background("#f80") == (255, 136, 0)
    assert parse_background((1, 2, 3)) == (1, 2, 3)
    for bad in ("#12345", "pink-ish", "#gggggg"):
        with pytest.raises(ValueError, match="background must be 'transparent', 'chroma'"):
            parse_background(bad)
    with pytest.raises(ValueError, match="3 ints in 0..255"):
        parse_background((0, 0, 300))
    with pytest.raises(TypeError, match="string or an .r, g, b. triple"):
        parse_background(3.5)


def test_over_colour_matches_float_formula(rng):
    rgba = rng.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    colour = (10, 200, 77)
    a = rgba[:, :, 3:4] / 255.0
    expected = np.round(rgba[:, :, :3] * a + np.array(colour) * (1 - a)).astype(int)
    assert np.abs(over_colour(rgba, colour).astype(int) - expected).max() <= 1
    assert np.array_equal(over_colour(rgba[:, :, :3], colour), rgba[:, :, :3])  # RGB is opaque


def test_over_colour_bgr_matches_over_colour_in_one_buffer(rng):
    colour = (10, 200, 77)
    flatten = OverColourBGR(colour, (33, 21))
    first = rng.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    out = flatten(first)
    assert out.shape == (21, 33, 3)
    assert np.array_equal(out[:20, :30], over_colour(first, colour)[:, :, ::-1])
    assert np.all(out[20:] == colour[::-1]) and np.all(out[:, 30:] == colour[::-1])
    second = rng.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    assert flatten(second) is out                      # the same buffer, overwritten
    assert np.array_equal(out[:20, :30], over_colour(second, colour)[:, :, ::-1])
    with pytest.raises(ValueError, match="larger than"):
        flatten(np.zeros((22, 30, 4), np.uint8))
    with pytest.raises(ValueError, match="needs a colour"):
        OverColourBGR("transparent", (4, 4))


def test_video_repeat_appends_the_last_frame(tmp_path, rng):
    frames = _frames(rng, 3)
    with open_writer(tmp_path / "r.mkv", fps=25, size=(40, 30), background="#102030") as w:
        with pytest.raises(ValueError, match="nothing to repeat"):
            w.repeat()
        w.write(frames[0])
        w.write(frames[1])
        w.repeat()
        w.repeat()
        w.write(frames[2])
        assert w.frames_written == 5
    with pytest.raises(ValueError, match="closed"):
        w.repeat()
    back = _read_video(tmp_path / "r.mkv")
    expected = [over_colour(frames[k], "#102030") for k in (0, 1, 1, 1, 2)]
    assert len(back) == 5
    assert all(np.array_equal(read, want) for read, want in zip(back, expected))


def _compose_reference(layers, size, colour):
    width, height = size
    out = np.zeros((height, width, 4))
    if colour is not None:
        out[:, :, :3] = np.array(colour) / 255.0
        out[:, :, 3] = 1.0
    for layer, (x0, y0) in layers:
        for y in range(layer.shape[0]):
            for x in range(layer.shape[1]):
                if 0 <= y + y0 < height and 0 <= x + x0 < width:
                    src = layer[y, x] / 255.0
                    dst = out[y + y0, x + x0]
                    alpha = src[3] + dst[3] * (1 - src[3])
                    rgb = (src[:3] * src[3] + dst[:3] * dst[3] * (1 - src[3])) / alpha \
                        if alpha > 0 else np.zeros(3)
                    out[y + y0, x + x0] = [*rgb, alpha]
    return np.round(out * 255)


@pytest.mark.parametrize("background", ["transparent", "#204060"])
def test_compose_layers_matches_reference(rng, background):
    layers = [(rng.integers(0, 256, (12, 15, 4), dtype=np.uint8), (-3, 4)),
              (rng.integers(0, 256, (10, 10, 4), dtype=np.uint8), (8, 10)),
              (rng.integers(0, 256, (6, 30, 4), dtype=np.uint8), (5, -2))]
    result = compose_layers(layers, size=(20, 16), background=background)
    expected = _compose_reference(layers, (20, 16), parse_background(background))
    assert result.shape == (16, 20, 4)
    assert np.abs(result.astype(int) - expected).max() <= 1
    # a bare array is placed at the top-left corner; fully transparent pixels have no colour
    layer = layers[1][0]
    single = compose_layers([layer], size=(10, 10))
    assert np.array_equal(single[:, :, 3], layer[:, :, 3])
    seen = layer[:, :, 3] > 0
    assert np.abs(single[seen, :3].astype(int) - layer[seen, :3]).max() <= 1
    assert np.all(single[~seen, :3] == 0)


@pytest.mark.parametrize("name", ["out.mp4", "out.mkv", "out.avi", "out.webm"])
@pytest.mark.parametrize("background", ["#ffffff", "chroma"])
def test_video_round_trip(tmp_path, rng, name, background):
    # 4x larger frames: mp4v stores colour at half resolution, tiny frames would be unfair
    frames = [np.kron(f, np.ones((4, 4, 1), np.uint8)) for f in _frames(rng)]
    path = write_frames(tmp_path / name, frames, fps=25, background=background)
    back = _read_video(path)
    assert len(back) == len(frames)
    for original, read in zip(frames, back):
        expected = over_colour(original, background)
        if name.endswith(".mkv"):
            assert np.array_equal(read, expected)
        else:
            error = np.mean((read.astype(float) - expected) ** 2)
            assert 10 * np.log10(255 ** 2 / error) > 30.0


def test_odd_sizes_are_padded_with_background(tmp_path, rng):
    frames = _frames(rng, 2, size=(41, 31))
    path = write_frames(tmp_path / "odd.mkv", frames, fps=10, background="#102030")
    back = _read_video(path)
    assert back[0].shape == (32, 42, 3)
    assert np.array_equal(back[0][:31, :41], over_colour(frames[0], "#102030"))
    assert np.all(back[0][31, :] == (16, 32, 48)) and np.all(back[0][:, 41] == (16, 32, 48))


def test_gif_round_trip(tmp_path, rng):
    from PIL import Image
    frames = _frames(rng)
    write_frames(tmp_path / "t.gif", frames, fps=25)
    gif = Image.open(tmp_path / "t.gif")
    assert gif.n_frames == len(frames)
    assert gif.info["duration"] == 40
    for k, original in enumerate(frames):
        gif.seek(k)
        read = np.asarray(gif.convert("RGBA")).astype(int)
        assert np.array_equal(read[:, :, 3] == 255, original[:, :, 3] >= 128)
        solid = original[:, :, 3] >= 128
        assert np.abs(read[solid, :3] - original[solid, :3]).mean() < 3.0
    write_frames(tmp_path / "o.gif", frames, fps=25, background="chroma")
    opaque = Image.open(tmp_path / "o.gif").convert("RGB")
    assert np.abs(np.asarray(opaque).astype(int) - over_colour(frames[0], "chroma")).mean() < 3


@pytest.mark.parametrize("target,names", [
    ("seq", [f"frame_{k:06d}.png" for k in range(3)]),
    ("seq/", [f"frame_{k:06d}.png" for k in range(3)]),
    ("shot_%04d.png", [f"shot_{k:04d}.png" for k in range(3)]),
    ("take_###.png", [f"take_{k:03d}.png" for k in range(3)]),
])
def test_png_sequence_keeps_alpha(tmp_path, rng, target, names):
    from PIL import Image
    frames = _frames(rng, 3)
    with open_writer(tmp_path / target, fps=25, size=(40, 30)) as writer:
        for frame in frames:
            writer.write(frame)
    folder = writer.path
    assert sorted(p.name for p in folder.iterdir()) == names
    for frame, name in zip(frames, names):
        assert np.array_equal(np.asarray(Image.open(folder / name)), frame)


def test_writer_errors(tmp_path, rng):
    frame = _frames(rng, 1)[0]
    with pytest.raises(ValueError, match="cannot tell the video format of .*out.mov"):
        open_writer(tmp_path / "out.mov", fps=25, size=(40, 30))
    with pytest.raises(ValueError, match="single PNG name.*out_%05d.png"):
        open_writer(tmp_path / "out.png", fps=25, size=(40, 30))
    with pytest.raises(ValueError, match=".mp4 video has no alpha channel"):
        open_writer(tmp_path / "out.mp4", fps=25, size=(40, 30), background="transparent")
    with pytest.raises(ValueError, match="fps must be > 0"):
        open_writer(tmp_path / "out.mkv", fps=0, size=(40, 30))
    with pytest.raises(ValueError, match="size must be .width, height. >= 1"):
        open_writer(tmp_path / "out.mkv", fps=25, size=(0, 30))
    writer = open_writer(tmp_path / "out.mkv", fps=25, size=(40, 30))
    with pytest.raises(ValueError, match=r"frame has shape \(30, 39, 4\), this writer expects "
                                         r"\(30, 40, 4\)"):
        writer.write(frame[:, :39])
    with pytest.raises(TypeError, match="uint8 RGBA, got dtype float64"):
        writer.write(frame.astype(float))
    with pytest.raises(TypeError, match="must be a numpy array"):
        writer.write(frame.tolist())
    writer.write(frame[:, :, :3])      # RGB frames are taken as opaque
    writer.close()
    writer.close()                     # closing twice is fine
    with pytest.raises(ValueError, match="is closed"):
        writer.write(frame)
    assert writer.frames_written == 1


_INTERRUPTED = textwrap.dedent("""
    import signal, sys, time
    import numpy as np
    # as in a terminal: a test run started in the background inherits SIGINT ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from mop.export import open_writer
    path, style = sys.argv[1], sys.argv[2]
    writer = open_writer(path, fps=25, size=(64, 48), background="#202020")

    def loop():
        index = 0
        while True:
            frame = np.zeros((48, 64, 4), np.uint8)
            frame[:, :, 0] = (index * 20) % 256
            frame[:, :, 3] = 255
            writer.write(frame)
            index += 1
            print(index, flush=True)
            time.sleep(0.005)

    if style == "with":
        with writer:
            loop()
    else:
        loop()   # no with-block: the writer is closed at interpreter exit
""")


@pytest.mark.parametrize("name", ["clip.mp4", "clip.gif"])
@pytest.mark.parametrize("style", ["with", "bare"])
@pytest.mark.slow
def test_ctrl_c_leaves_a_playable_file(tmp_path, name, style):
    from PIL import Image
    script = tmp_path / "render.py"
    script.write_text(_INTERRUPTED)
    path = tmp_path / name
    process = subprocess.Popen([sys.executable, str(script), str(path), style],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    written = 0
    for line in process.stdout:
        written = int(line)
        if written >= 8:
            break
    process.send_signal(signal.SIGINT)
    _, errors = process.communicate(timeout=30)
    assert "KeyboardInterrupt" in errors
    if name.endswith(".mp4"):
        frames = _read_video(path)
        assert len(frames) >= written
        assert frames[0].shape == (48, 64, 3)
        assert abs(int(frames[3][10, 10, 0]) - 60) <= 6, "frames are in order"
    else:
        gif = Image.open(path)
        assert gif.n_frames >= written
