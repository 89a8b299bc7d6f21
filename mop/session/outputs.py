"""Where a session's frames and states go: video, PNG sequence, OSC, the live preview.

Frame outputs have `write(frame, state, *, repeat)`: the render worker calls it once per session
frame, in order, with the composed (H, W, 4) uint8 RGBA picture (straight alpha; the worker
reuses the buffer, so copy what you keep); `repeat` is True when this frame's render was dropped
and `frame` is the previous picture (a video repeats it to keep its duration; a PNG sequence
does not write it again). State outputs have `send(state)`: the loop calls it every frame, right
after the simulation (OSC). Both have `close()`.
"""
from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)


VIDEO_SUFFIXES = (".mp4", ".mkv", ".avi", ".webm", ".gif")


def _dropped(path: Path) -> bool:
    """os.devnull: `mop.export.open_writer` counts the frames and drops them."""
    return path.exists() and os.path.exists(os.devnull) and os.path.samefile(path, os.devnull)


class VideoOutput:
    """MP4 / MKV / GIF / AVI / WebM through `mop.export.open_writer`, opened by `open()` (or the
    first write) where the pictures are made: in the render process, usually (`recipe()`).

    background : (r, g, b) drawn under transparent pixels (video has no alpha)."""

    def __init__(self, path: str | Path, *, fps: int, size: tuple[int, int],
                 background: tuple[int, int, int] | None = (0, 0, 0)):
        self.path = Path(path)
        self.options = dict(fps=fps, size=tuple(size), background=background)
        self.writer = None
        self.frames = 0
        self._check()

    def _check(self) -> None:
        """What can be said before the writer opens (in the render process, usually)."""
        if _dropped(self.path):
            return
        if self.path.suffix.lower() not in VIDEO_SUFFIXES:
            raise ValueError(f"{self.path}: expected a video file ending in "
                             f"{', '.join(VIDEO_SUFFIXES)}")

    def recipe(self):
        return (type(self), (self.path,), self.options)

    def open(self) -> None:
        if self.writer is None:
            from mop.export import open_writer
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.writer = open_writer(self.path, **self.options)

    def write(self, frame, state, *, repeat: bool = False) -> None:
        if frame is None:
            return
        self.open()
        again = getattr(self.writer, "repeat", None) if repeat and self.frames else None
        if again is not None:
            again()                 # the picture it encoded last, not converted again
        else:
            self.writer.write(frame)
        self.frames += 1

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


class PngOutput(VideoOutput):
    """A folder of frame_000000.png ... with alpha (RGBA, unless a `background` colour is given),
    through `mop.export.open_writer`: file N is session frame N. A repeated (dropped) frame is a
    hard link to the file before it (a copy where links are not possible): no PNG is encoded
    twice."""

    def __init__(self, folder: str | Path, *, fps: int, size: tuple[int, int],
                 background: tuple[int, int, int] | None = None):
        self.folder = Path(folder)
        super().__init__(folder, fps=fps, size=size, background=background)

    def _check(self) -> None:
        if self.path.exists() and not self.path.is_dir() and not _dropped(self.path):
            raise ValueError(f"{self.path}: expected a folder for the PNG frames")

    def open(self) -> None:
        if self.writer is None:
            from mop.export import open_writer
            self.writer = open_writer(self.folder, **self.options)

    def write(self, frame, state, *, repeat: bool = False) -> None:
        self.open()
        writer = self.writer
        if not repeat or writer.frames_written == 0:
            super().write(frame, state)
            return
        previous = writer.frame_path(writer.frames_written - 1)
        target = writer.frame_path(writer.frames_written)
        target.unlink(missing_ok=True)
        try:
            os.link(previous, target)
        except OSError:
            shutil.copyfile(previous, target)
        writer.frames_written += 1
        self.frames += 1


class OscOutput:
    """Each frame, one OSC bundle (one UDP datagram, so nothing is reordered or half-sent) with:

    /mop/frame                       i frame, f t [s]
    /mop/performer/NAME              s status, s action ("" = none), f progress, f variance,
                                     f log-likelihood, i input frame (the bank's step since
                                     the input was (re)joined; -1 = not following)
    /mop/character/NAME/action       s action ("" = rest), s performer, s state ("active",
                                     "hold", "loop" or "rest") — one per track
    /mop/character/NAME/progress     f progress in [0, 1], f blend weight — one per track
    /mop/character/NAME/target/T     f... the control target T (1, 2 or 3 floats)
    """

    def __init__(self, host: str, port: int):
        try:
            from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
            from pythonosc.osc_message_builder import OscMessageBuilder
            from pythonosc.udp_client import UDPClient
        except ImportError:
            raise ImportError("OSC out needs python-osc: pip install 'mop[capture]'") from None
        self._bundle = OscBundleBuilder
        self._message = OscMessageBuilder
        self._immediately = IMMEDIATELY
        self.client = UDPClient(host, int(port))
        self.address = (host, int(port))
        self.sent = 0
        self.failed = 0

    def _add(self, bundle, address: str, *args) -> None:
        message = self._message(address=address)
        for arg in args:
            message.add_arg(arg)
        bundle.add_content(message.build())

    def build(self, state: dict):
        """The OSC bundle (pythonosc OscBundle) for one frame's state."""
        bundle = self._bundle(self._immediately)
        self._add(bundle, "/mop/frame", int(state["frame"]), float(state["t"]))
        for name, performer in state["performers"].items():
            step = performer.get("input_frame")
            self._add(bundle, f"/mop/performer/{name}", performer["status"],
                      performer["action"] or "", float(performer["progress"]),
                      float(performer["variance"]), float(performer["log_likelihood"]),
                      -1 if step is None else int(step))
        for name, character in state["characters"].items():
            for track in character["tracks"]:
                self._add(bundle, f"/mop/character/{name}/action", track["action"] or "",
                          track["performer"], track.get("state", "active"))
                self._add(bundle, f"/mop/character/{name}/progress", float(track["progress"]),
                          float(track["blend"]))
            for target, value in character["targets"].items():
                self._add(bundle, f"/mop/character/{name}/target/{target}",
                          *(float(v) for v in value))
        return bundle.build()

    def send(self, state: dict) -> None:
        try:
            self.client.send(self.build(state))
            self.sent += 1
        except OSError as error:  # nobody listening is not fatal to a show; count it
            self.failed += 1
            if self.failed == 1:
                log.warning("OSC out to %s:%d failed: %s", *self.address, error)

    def close(self) -> None:
        sock = getattr(self.client, "_sock", None)  # UDPClient has no public close()
        if sock is not None:
            sock.close()


class BackgroundOutput:
    """Runs another output's writes in a thread of its own, in order, so encoding a frame
    overlaps drawing the next one (OpenCV's encoder and Pillow's release the GIL).

    `write` copies the frame into one of `queue_size` + 2 reused buffers (a repeat reuses the
    previous copy) and queues it; with `queue_size` frames waiting it blocks, so a slow disk
    slows the pictures down rather than eating memory. `close` drains the queue, then closes
    the inner output; an error of the inner output is raised by the next write or by close."""

    def __init__(self, inner, *, queue_size: int = 4):
        import queue
        import threading
        self.inner = inner
        self.queue_size = queue_size
        self.queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self.free: queue.Queue = queue.Queue()
        self.error: BaseException | None = None
        self._last = None
        self._held: dict[int, int] = {}        # buffer id -> queued writes still reading it
        self._lock = threading.Lock()
        self.thread = None
        self.closed = False

    def recipe(self):
        """Rebuilt around the inner output's recipe (None when the inner has none)."""
        inner = getattr(self.inner, "recipe", None)
        inner = None if inner is None else inner()
        return None if inner is None else (_in_background, (inner, self.queue_size), {})

    def open(self) -> None:
        import threading
        opener = getattr(self.inner, "open", None)
        if opener is not None:
            opener()
        if self.thread is None:
            self.thread = threading.Thread(target=self._work,
                                           name=f"mop-{type(self.inner).__name__}", daemon=True)
            self.thread.start()

    @property
    def frames(self) -> int:
        return self.inner.frames

    @frames.setter
    def frames(self, count: int) -> None:
        self.inner.frames = count

    @property
    def path(self):
        return getattr(self.inner, "path", None) or getattr(self.inner, "folder", None)

    def _work(self) -> None:
        while True:
            item = self.queue.get()
            if item is None:
                return
            frame, state, repeat = item
            if self.error is None:
                try:
                    self.inner.write(frame, state, repeat=repeat)
                except BaseException as error:  # reported by the next write or close
                    self.error = error
            if frame is not None:
                self._release(frame)

    def _release(self, frame) -> None:
        with self._lock:
            key = id(frame)
            self._held[key] -= 1
            if self._held[key] == 0 and frame is not self._last:
                del self._held[key]
                self.free.put(frame)

    def _copy(self, frame, repeat: bool):
        """A buffer holding `frame`: the previous copy for a repeat, else a free or new one."""
        import queue
        with self._lock:
            last = self._last
            if repeat and last is not None and last.shape == frame.shape:
                self._held[id(last)] += 1
                return last
        try:
            buffer = self.free.get_nowait()
        except queue.Empty:
            buffer = None
        if buffer is None or buffer.shape != frame.shape:
            buffer = np.empty_like(frame)
        np.copyto(buffer, frame)
        with self._lock:
            previous, self._last = self._last, buffer
            self._held[id(buffer)] = self._held.get(id(buffer), 0) + 1
            if previous is not None and self._held.get(id(previous)) == 0:
                del self._held[id(previous)]
                self.free.put(previous)
        return buffer

    def write(self, frame, state, *, repeat: bool = False) -> None:
        if self.error is not None:
            raise self.error
        if self.thread is None:
            self.open()
        self.queue.put((None if frame is None else self._copy(frame, repeat), state, repeat))

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self.thread is not None:
            self.queue.put(None)
            self.thread.join()
        self.inner.close()
        if self.error is not None:
            raise self.error


def _in_background(recipe, queue_size: int) -> BackgroundOutput:
    """A BackgroundOutput around the output `recipe` builds (in the render process)."""
    factory, args, kwargs = recipe
    return BackgroundOutput(factory(*args, **kwargs), queue_size=queue_size)
