"""Writing rendered frames to files, and compositing RGBA frames.

One small API for every renderer in mop (2D image puppets, 3D puppets, sessions):

    from mop.export import open_writer
    with open_writer("out.mp4", fps=25, size=(width, height), background="#ffffff") as writer:
        for frame in frames:            # (height, width, 4) uint8 RGBA, straight alpha
            writer.write(frame)

The format follows the path:

| path                          | format                                   | alpha        |
|-------------------------------|------------------------------------------|--------------|
| `*.mp4`                       | MPEG-4 part 2 (`mp4v`) via OpenCV, lossy | composited   |
| `*.mkv`                       | FFV1 via OpenCV, lossless                | composited   |
| `*.avi` / `*.webm`            | Motion-JPEG / VP8 via OpenCV, lossy      | composited   |
| `*.gif`                       | animated GIF via Pillow, 255 colours     | 1-bit        |
| a folder, or `name_%05d.png`  | numbered PNG files via Pillow            | kept (RGBA)  |

Frames are RGBA with straight (not premultiplied) alpha; RGB frames (H, W, 3) are taken as
opaque. `background` is "transparent", "#rrggbb", "chroma" (chroma-key green #00b140) or an
(r, g, b) triple; formats without alpha composite over it (default white) and formats with alpha
keep transparency unless a colour is given. Video codecs need even sizes: an odd width or
height is padded by one background pixel on the right / bottom.

Interrupting is safe: `close()` (called by the context manager, and at interpreter exit for a
writer left open) finalises the file, so a render stopped with Ctrl-C leaves a playable file
with the frames written so far.

Nothing fails silently: OpenCV's encoder does not report a failed write, so a video writer
checks the free space of its file system every `SPACE_CHECK_FRAMES` frames and, on `close()`,
reads the finished file back (it opens, and its last frame decodes); a full disk or a file that
does not read back raises `OSError` naming the file (`errno.ENOSPC` for a full disk).

PNG frames are written to a temporary name and renamed, so there is never a truncated frame;
a folder that already holds numbered frames is refused (`overwrite=True` removes them first),
so that two renders never mix. GIF frames are kept in memory (one byte per pixel) until
`close()`; use a video or PNG sequence for long renders. `os.devnull` drops the frames.
"""
from __future__ import annotations

import errno
import os
import re
import weakref
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

CHROMA_GREEN = (0, 177, 64)   # the usual broadcast chroma-key green
DEFAULT_OPAQUE_BACKGROUND = (255, 255, 255)
CHROMA_BLUE = (0, 71, 187)    # the usual broadcast chroma-key blue
_NAMED = {"white": (255, 255, 255), "black": (0, 0, 0), "chroma": CHROMA_GREEN,
          "green": CHROMA_GREEN, "blue": CHROMA_BLUE}


# --- colours and compositing -------------------------------------------------------------

def parse_background(background) -> tuple[int, int, int] | None:
    """mop's one colour parser. "transparent" / None -> None; "chroma" (key green), "blue" (key
    blue), "white", "black", "#rrggbb", "#rgb" or an (r, g, b) triple of ints in 0..255 ->
    (r, g, b)."""
    if background is None:
        return None
    if isinstance(background, str):
        text = background.strip().lower()
        if text in ("transparent", "none", "alpha"):
            return None
        if text in _NAMED:
            return _NAMED[text]
        if re.fullmatch(r"#[0-9a-f]{6}", text):
            return tuple(int(text[i:i + 2], 16) for i in (1, 3, 5))
        if re.fullmatch(r"#[0-9a-f]{3}", text):
            return tuple(17 * int(c, 16) for c in text[1:])
        raise ValueError(f"background must be 'transparent', 'chroma', 'blue', 'white', 'black' "
                         f"or a colour '#rrggbb', got {background!r}")
    try:
        values = [int(v) for v in background]
    except (TypeError, ValueError):
        raise TypeError(f"background must be a string or an (r, g, b) triple, got "
                        f"{background!r}") from None
    if len(values) != 3 or min(values) < 0 or max(values) > 255:
        raise ValueError(f"background colour must be 3 ints in 0..255, got {background!r}")
    return tuple(values)


def _as_rgba(frame, name: str = "frame") -> np.ndarray:
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"{name} must be a numpy array (H, W, 4) uint8, got "
                        f"{type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise TypeError(f"{name} must be uint8 RGBA, got dtype {frame.dtype}")
    if frame.ndim != 3 or frame.shape[2] not in (3, 4):
        raise ValueError(f"{name} must have shape (H, W, 4) (RGBA) or (H, W, 3) (RGB), got "
                         f"{frame.shape}")
    if frame.shape[2] == 3:
        return np.dstack([frame, np.full(frame.shape[:2], 255, np.uint8)])
    return frame


def over_colour(rgba: np.ndarray, colour, out: np.ndarray | None = None) -> np.ndarray:
    """RGBA (H, W, 4) uint8 straight alpha composited over a plain colour -> (H, W, 3) uint8.

    colour : anything `parse_background` takes except transparent. out : optional (H, W, 3)
    uint8 buffer to write into."""
    from mop.render.compose import blend_over
    rgba = _as_rgba(rgba)
    rgb = parse_background(colour)
    if rgb is None:
        raise ValueError("over_colour needs a colour, got 'transparent'")
    canvas = np.empty(rgba.shape, np.uint8)
    canvas[:, :, :3] = rgb
    canvas[:, :, 3] = 255
    blend_over(canvas, np.ascontiguousarray(rgba), 0, 0, opaque=True)
    if out is None:
        return canvas[:, :, :3].copy()
    np.copyto(out, canvas[:, :, :3])
    return out


class OverColourBGR:
    """RGBA frames over one colour into a reused (H', W', 3) uint8 BGR buffer (OpenCV's
    order), the same arithmetic as `over_colour` with nothing allocated per frame: a frame
    costs a copy of the colour, the compiled blend and one channel conversion.

    colour : (r, g, b); size : (width, height) [px] of the buffer, at least the frame's (the
    frame goes top-left, the rest stays the colour: video codecs' padding). Calling it with an
    (h, w, 4) RGBA frame returns the buffer, overwritten by the next call."""

    def __init__(self, colour, size: tuple[int, int]):
        import cv2
        rgb = parse_background(colour)
        if rgb is None:
            raise ValueError("OverColourBGR needs a colour, got 'transparent'")
        width, height = self.size = _check_size(size)
        self._blank = np.empty((height, width, 4), np.uint8)
        self._blank[:, :, :3] = rgb
        self._blank[:, :, 3] = 255
        self._canvas = np.empty_like(self._blank)
        self._bgr = np.empty((height, width, 3), np.uint8)
        self._convert = cv2.cvtColor
        self._code = cv2.COLOR_RGBA2BGR
        from mop.render.compose import blend_over
        self._blend = blend_over

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        height, width = self._canvas.shape[:2]
        if frame.shape[0] > height or frame.shape[1] > width:
            raise ValueError(f"frame has shape {frame.shape}, larger than the ({height}, "
                             f"{width}) buffer")
        np.copyto(self._canvas, self._blank)
        self._blend(self._canvas, np.ascontiguousarray(frame), 0, 0, opaque=True)
        return self._convert(self._canvas, self._code, dst=self._bgr)


def compose_layers(layers: Iterable, *, size: tuple[int, int],
                   background="transparent") -> np.ndarray:
    """Several RGBA layers composed back to front into one frame.

    layers : iterable of (H, W, 4) uint8 arrays (placed at the top-left corner) or pairs
        (rgba, (x, y)) placing the layer's top-left corner at pixel (x, y); parts outside the
        frame are clipped. size : (width, height) [px] of the frame.
    Returns (height, width, 4) uint8 RGBA, straight alpha (alpha 255 over a colour)."""
    from mop.render.compose import blend_over
    width, height = _check_size(size)
    colour = parse_background(background)
    out = np.zeros((height, width, 4), np.uint8)
    if colour is not None:
        out[:, :, :3] = colour
        out[:, :, 3] = 255
    for index, layer in enumerate(layers):
        x0 = y0 = 0
        if isinstance(layer, tuple):
            layer, (x0, y0) = layer
            x0, y0 = int(round(x0)), int(round(y0))
        layer = np.ascontiguousarray(_as_rgba(layer, f"layer {index}"))
        blend_over(out, layer, x0, y0, opaque=colour is not None)
    return out


def _check_size(size) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in size)
    except (TypeError, ValueError):
        raise TypeError(f"size must be (width, height) in pixels, got {size!r}") from None
    if width < 1 or height < 1:
        raise ValueError(f"size must be (width, height) >= 1 pixel, got {size!r}")
    return width, height


# --- writers -----------------------------------------------------------------------------

class FrameWriter:
    """Base class of the writers returned by `open_writer`. Use as a context manager.

    path : where frames go; fps : frames per second; size : (width, height) [px];
    background : (r, g, b) | None (transparent); frames_written : int."""

    keeps_alpha = False

    def __init__(self, path: Path, *, fps: float, size: tuple[int, int], background):
        self.path = path
        self.fps = float(fps)
        self.size = size
        self.background = background
        self.frames_written = 0
        self._closed = False
        self._resource: dict = {}
        # closes the file at interpreter exit if the writer was left open (e.g. Ctrl-C
        # outside a with-block); the callback holds the resource, not the writer
        self._finalizer = weakref.finalize(self, type(self)._finish, self._resource)

    def write(self, frame: np.ndarray) -> None:
        """Append one frame: (height, width, 4) uint8 RGBA straight alpha, or (height, width, 3)."""
        if self._closed:
            raise ValueError(f"writer for {self.path} is closed")
        frame = _as_rgba(frame)
        width, height = self.size
        if frame.shape[:2] != (height, width):
            raise ValueError(f"frame has shape {frame.shape}, this writer expects "
                             f"({height}, {width}, 4) for size (width={width}, height={height})")
        self._write(frame)
        self.frames_written += 1

    def close(self) -> None:
        """Finalise the file. Safe to call more than once."""
        if not self._closed:
            self._closed = True
            self._finalizer()

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({str(self.path)!r}, fps={self.fps:g}, size={self.size}, "
                f"{self.frames_written} frames)")

    def _write(self, frame: np.ndarray) -> None:
        raise NotImplementedError

    @staticmethod
    def _finish(resource: dict) -> None:
        raise NotImplementedError


SPACE_CHECK_FRAMES = 25   # a video writer looks at its disk's free space this often


def free_bytes(folder: Path) -> int:
    """Bytes this process may still write on the file system holding `folder` (root may use
    the blocks reserved for it)."""
    stats = os.statvfs(folder)
    blocks = stats.f_bfree if hasattr(os, "geteuid") and os.geteuid() == 0 else stats.f_bavail
    return blocks * stats.f_frsize


def disk_full_error(path: Path, frames: int) -> OSError:
    return OSError(errno.ENOSPC, f"no space left on the disk after {frames} frames: the video "
                                 f"is incomplete; free some space and render again", str(path))


def verify_video(path: Path, frames: int) -> None:
    """Read a finished video back: it opens, has `frames` frames and its last frame decodes.
    Raises OSError naming the file (ENOSPC when its disk is full)."""
    import cv2

    path = Path(path)
    size = path.stat().st_size if path.exists() else 0
    problem = None
    if frames == 0:
        return
    if size == 0:
        problem = "the file is empty"
    else:
        capture = cv2.VideoCapture(str(path))
        try:
            if not capture.isOpened():
                problem = "it cannot be opened (an unfinished or damaged file)"
            else:
                counted = capture.get(cv2.CAP_PROP_FRAME_COUNT)
                if counted > 0 and abs(counted - frames) > max(1.0, 0.01 * frames):
                    problem = f"it holds {counted:.0f} frames, {frames} were written"
                else:
                    capture.set(cv2.CAP_PROP_POS_FRAMES, frames - 1)
                    if not capture.read()[0]:
                        problem = "its last frame does not decode (the file is cut short)"
        finally:
            capture.release()
    if problem is None:
        return
    try:
        full = free_bytes(path.parent) == 0
    except OSError:
        full = False
    if full:
        raise disk_full_error(path, frames)
    raise OSError(errno.EIO, f"the finished video does not read back: {problem} ({frames} "
                             f"frames, {size} bytes)", str(path))


class VideoFileWriter(FrameWriter):
    """MP4 (mp4v), MKV (FFV1), AVI (MJPG) or WebM (VP8) through OpenCV; frames composited over
    the background. The free space is checked while writing and the file is read back on
    `close()` (see the module docstring)."""

    FOURCC = {".mp4": "mp4v", ".mkv": "FFV1", ".avi": "MJPG", ".webm": "VP80"}

    def __init__(self, path: Path, *, fps, size, background):
        super().__init__(path, fps=fps, size=size, background=background)
        try:
            import cv2
        except ImportError:
            raise ImportError("writing video needs OpenCV: pip install 'mop[video]'") from None
        width, height = size
        self.padded = (width + width % 2, height + height % 2)
        fourcc = cv2.VideoWriter_fourcc(*self.FOURCC[path.suffix.lower()])
        writer = cv2.VideoWriter(str(path), fourcc, self.fps, self.padded)
        if not writer.isOpened():
            raise ValueError(f"OpenCV could not open {path} for writing with codec "
                             f"{self.FOURCC[path.suffix.lower()]}")
        self._resource["writer"] = writer
        self._flatten = OverColourBGR(self.background, self.padded)
        self._bgr = None                      # the last frame as encoded

    def _write(self, frame):
        self._bgr = self._flatten(frame)
        self._encode()

    def repeat(self) -> None:
        """Append the last frame again: its encoded picture is kept, so nothing is converted
        (a live session's dropped render)."""
        if self._closed:
            raise ValueError(f"writer for {self.path} is closed")
        if self._bgr is None:
            raise ValueError(f"nothing to repeat: no frame was written to {self.path} yet")
        self._encode()
        self.frames_written += 1

    def _encode(self) -> None:
        self._resource["writer"].write(self._bgr)
        if (self.frames_written + 1) % SPACE_CHECK_FRAMES == 0 \
                and free_bytes(self.path.parent) == 0:
            # the encoder's writes are failing unseen: stop now, the file is finalised as far
            # as it goes and the error names it
            self.close(verify=False)
            raise disk_full_error(self.path, self.frames_written + 1)

    def close(self, *, verify: bool = True) -> None:
        """Finalise the file and read it back (verify=False skips the reading)."""
        if self._closed:
            return
        super().close()
        if verify:
            verify_video(self.path, self.frames_written)

    def __exit__(self, exc_type, *exc) -> None:
        # on an error already on its way out, finalise without masking it
        self.close(verify=exc_type is None)

    @staticmethod
    def _finish(resource):
        writer = resource.pop("writer", None)
        if writer is not None:
            writer.release()


class GifWriter(FrameWriter):
    """Animated GIF through Pillow: 255 colours per frame plus one transparent index."""

    keeps_alpha = True

    def __init__(self, path: Path, *, fps, size, background):
        super().__init__(path, fps=fps, size=size, background=background)
        self._resource.update(path=path, frames=[], duration=max(20, round(1000.0 / self.fps)),
                              transparent=background is None)

    def _write(self, frame):
        from PIL import Image
        if self.background is None:
            rgb = np.ascontiguousarray(frame[:, :, :3])
            quantised = Image.fromarray(rgb).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
            indices = np.asarray(quantised).copy()
            indices[frame[:, :, 3] < 128] = 255
            palette = quantised.getpalette()[:255 * 3]
            palette += [0, 0, 0] * (256 - len(palette) // 3)
        else:
            rgb = over_colour(frame, self.background)
            quantised = Image.fromarray(rgb).quantize(colors=256, method=Image.Quantize.MEDIANCUT)
            indices = np.asarray(quantised)
            palette = quantised.getpalette()
        image = Image.fromarray(indices, mode="P")
        image.putpalette(palette)
        self._resource["frames"].append(image)

    @staticmethod
    def _finish(resource):
        frames = resource.pop("frames", None)
        if not frames:
            return
        options = dict(save_all=True, append_images=frames[1:], duration=resource["duration"],
                       loop=0, optimize=False)
        if resource["transparent"]:
            options.update(transparency=255, disposal=2)
        frames[0].save(resource["path"], format="GIF", **options)


class PngSequenceWriter(FrameWriter):
    """Numbered RGBA PNG files (straight alpha); a colour background makes them opaque."""

    keeps_alpha = True

    def __init__(self, path: Path, *, fps, size, background, pattern: str,
                 overwrite: bool = False):
        super().__init__(path, fps=fps, size=size, background=background)
        self.pattern = pattern
        if path.exists() and not path.is_dir():
            raise ValueError(f"{path} is a file: PNG frames go into a folder")
        path.mkdir(parents=True, exist_ok=True)
        # frames of an earlier render would mix with these ones: refuse, or remove them
        old = self.existing_frames()
        if old and not overwrite:
            raise FileExistsError(f"{path} already holds {len(old)} frame(s) named like "
                                  f"{old[0].name}: remove them or choose another folder, so "
                                  f"that old and new frames do not mix")
        for frame in old:
            frame.unlink()

    def existing_frames(self) -> list[Path]:
        """Files in the folder that this writer's numbering would produce."""
        prefix, suffix = re.split(r"%0?\d*d", self.pattern, maxsplit=1)
        return sorted(p for p in self.path.iterdir()
                      if p.name.startswith(prefix) and p.name.endswith(suffix)
                      and p.name[len(prefix):len(p.name) - len(suffix)].isdigit())

    def frame_path(self, index: int) -> Path:
        return self.path / (self.pattern % index)

    def _write(self, frame):
        from PIL import Image
        if self.background is not None:
            image = Image.fromarray(over_colour(frame, self.background))
        else:
            image = Image.fromarray(np.ascontiguousarray(frame), mode="RGBA")
        target = self.frame_path(self.frames_written)
        partial = target.with_name(target.name + ".part")
        try:
            image.save(partial, format="PNG", compress_level=1)
        except OSError as error:
            partial.unlink(missing_ok=True)     # never a half-written frame left behind
            raise OSError(error.errno, f"frame {self.frames_written} could not be written "
                                       f"({error.strerror or error}); the {self.frames_written} "
                                       f"frames before it are complete", str(target)) from None
        os.replace(partial, target)

    @staticmethod
    def _finish(resource):
        pass


def _png_target(path: Path) -> tuple[Path, str] | None:
    """(folder, %-pattern) if the path names a PNG sequence, else None."""
    text = str(path)
    if path.suffix.lower() == ".png":
        name = path.name
        if re.search(r"%0?\d*d", name):
            return path.parent, name
        match = re.search(r"#+", name)
        if match:
            digits = len(match.group(0))
            return path.parent, name[:match.start()] + f"%0{digits}d" + name[match.end():]
        return None
    if path.is_dir() or text.endswith(("/", os.sep)) or path.suffix == "":
        return path, "frame_%06d.png"
    return None


class NullWriter(FrameWriter):
    """Frames to os.devnull: rendered, counted and dropped (a timing run)."""

    keeps_alpha = True

    def _write(self, frame):
        pass

    @staticmethod
    def _finish(resource):
        pass


def open_writer(path, *, fps: float, size: tuple[int, int], background=None,
                overwrite: bool = False) -> FrameWriter:
    """Open a frame writer; the format follows the path (see the module docstring).

    path : str | Path (os.devnull drops the frames); fps : float > 0; size : (width, height)
        [px] of every frame;
    background : "transparent" | "#rrggbb" | "chroma" | (r, g, b) | None (transparent where
        the format keeps alpha, white otherwise).
    overwrite : a PNG folder that already holds numbered frames is an error (FileExistsError)
        unless True, when the old frames are removed first.
    """
    path = Path(path)
    fps = float(fps)
    if not (fps > 0 and np.isfinite(fps)):
        raise ValueError(f"fps must be > 0, got {fps}")
    size = _check_size(size)
    colour = parse_background(background)
    if path.exists() and not path.is_dir() and not path.is_file():
        if os.path.exists(os.devnull) and os.path.samefile(path, os.devnull):
            return NullWriter(path, fps=fps, size=size, background=colour)
        raise ValueError(f"{path} is not a regular file or folder (a device or pipe): write "
                         f"video to a file, or PNG frames to a folder")
    suffix = path.suffix.lower()
    if suffix in VideoFileWriter.FOURCC:
        if colour is None:
            if background is not None:
                raise ValueError(f"{suffix} video has no alpha channel: give a background colour "
                                 f"or 'chroma', or write a PNG sequence to keep transparency")
            colour = DEFAULT_OPAQUE_BACKGROUND
        path.parent.mkdir(parents=True, exist_ok=True)
        return VideoFileWriter(path, fps=fps, size=size, background=colour)
    if suffix == ".gif":
        path.parent.mkdir(parents=True, exist_ok=True)
        return GifWriter(path, fps=fps, size=size, background=colour)
    png = _png_target(path)
    if png is not None:
        return PngSequenceWriter(png[0], fps=fps, size=size, background=colour, pattern=png[1],
                                 overwrite=overwrite)
    if suffix == ".png":
        raise ValueError(f"{path} is a single PNG name: for a PNG sequence give a folder or a "
                         f"numbered name such as {path.stem}_%05d.png or {path.stem}_#####.png")
    raise ValueError(f"cannot tell the video format of {path}: use .mp4 (mp4v), .mkv (lossless "
                     f"FFV1), .avi (MJPG), .webm (VP8), .gif, or a folder / name_%05d.png for "
                     f"PNG frames")


def write_frames(path, frames: Sequence[np.ndarray], *, fps: float, background=None) -> Path:
    """Write a list of RGBA frames in one call; returns the path."""
    frames = list(frames)
    if not frames:
        raise ValueError("no frames to write")
    height, width = frames[0].shape[:2]
    with open_writer(path, fps=fps, size=(width, height), background=background) as writer:
        for frame in frames:
            writer.write(frame)
    return Path(path)
