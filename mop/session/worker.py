"""The render worker: pictures beside the simulation, never in its way.

The loop follows and simulates every frame; after each frame it hands the worker a snapshot
(a copy of every character's deformed surface and the frame's state). The worker thread draws
each character's layer from the snapshot, composes the stage and writes the picture to every
frame output (video, PNG, the preview's JPEG) - one write per session frame, in order.

- Live: the newest snapshot wins. When a render is slower than a frame, the snapshots the
  worker never got to are written as repeats of the last picture, so a video always has one
  frame per session frame (the show's duration) and the loop never waits for pictures.
- Lossless (replay): every snapshot is rendered; the loop waits when the worker is a frame
  behind, so the same takes give the same pictures.

Why a thread: OpenCV's encoders, pyrender's GL calls (ctypes) and the compiled compositing
release the GIL, so on two cores the pictures take the core the simulation does not use.
The 3D layers' GL contexts move to the worker: the building thread releases them first.
"""
from __future__ import annotations

import logging
import threading
import time

import numpy as np

log = logging.getLogger(__name__)

STATE_RING = 1024   # states kept for frames written as repeats


class FrozenPuppet:
    """What a layer renderer reads of a puppet, frozen at one frame: `surface()` and
    `state.x` give the copy; anything else (faces, colours, the picture) is the puppet's."""

    def __init__(self, puppet, surface: np.ndarray):
        self._puppet = puppet
        self._surface = surface
        self.state = self

    @property
    def x(self) -> np.ndarray:
        return self._surface

    def surface(self) -> np.ndarray:
        return self._surface

    def __getattr__(self, name):
        return getattr(self._puppet, name)


class Snapshot:
    """One frame's pictures-to-be: index, every character's surface copy, the state."""

    def __init__(self, characters):
        self.index = -1
        self.state: dict | None = None
        self.surfaces = [np.array(c.puppet.surface(), dtype=np.float64, copy=True)
                         for c in characters]
        self.frozen = [FrozenPuppet(c.puppet, s) for c, s in zip(characters, self.surfaces)]

    def fill(self, index: int, characters, state: dict | None) -> None:
        self.index = index
        self.state = state
        for surface, character in zip(self.surfaces, characters):
            np.copyto(surface, character.puppet.surface())


def release_contexts(characters) -> None:
    """Let another thread draw these characters: renderers holding a GL context current in
    this thread release it (renderers without one have nothing to release)."""
    for character in characters:
        release = getattr(character.renderer, "release", None)
        if release is not None:
            release()


class RenderWorker:
    """Draws snapshots and feeds the frame outputs, in a thread.

    stage : mop.render.compose.Stage; characters : CharacterRuntime (drawn in this order);
    outputs : objects with `write(frame, state, *, repeat)`; lossless : render every frame
    (replay) instead of the newest (live); clock : the session's StageClock ("render" and
    "output" milliseconds are added from this thread)."""

    def __init__(self, stage, characters, outputs, *, lossless: bool, clock=None):
        self.stage = stage
        self.characters = list(characters)
        self.outputs = list(outputs)
        self.lossless = lossless
        self.clock = clock
        self.rendered = 0
        self.repeated = 0
        self.written = 0          # session frames handed to the outputs (rendered + repeats)
        self.error: BaseException | None = None
        self._pool = [Snapshot(self.characters) for _ in range(3)]
        self._pending: Snapshot | None = None
        self._states: list[tuple[int, dict | None]] = [(-1, None)] * STATE_RING
        self._condition = threading.Condition()
        self._stopping = False
        self._end = 0
        self._picture: np.ndarray | None = None
        self._thread: threading.Thread | None = None

    # the loop's side ---------------------------------------------------------------------
    def start(self) -> None:
        release_contexts(self.characters)
        self._thread = threading.Thread(target=self._run, name="mop-render", daemon=True)
        self._thread.start()

    def submit(self, index: int, state: dict | None) -> None:
        """Hand over frame `index` (copies the surfaces now). Live: never waits; a snapshot
        not yet taken is replaced. Lossless: waits while the previous one is not taken."""
        if self.error is not None:
            raise self.error
        with self._condition:
            self._states[index % STATE_RING] = (index, state)
            if self.lossless:
                while self._pending is not None and self.error is None:
                    self._condition.wait(0.5)
                if self.error is not None:
                    raise self.error
            snapshot = self._pool.pop() if self._pool else Snapshot(self.characters)
        snapshot.fill(index, self.characters, state)
        with self._condition:
            if self._pending is not None:          # live: the worker never got to it
                self._pool.append(self._pending)
            self._pending = snapshot
            self._condition.notify_all()

    def finish(self, frames: int) -> None:
        """Write every frame up to `frames` (repeats where no render came), stop the thread.
        Raises what went wrong in the worker."""
        with self._condition:
            self._stopping = True
            self._end = frames
            self._condition.notify_all()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self.error is not None:
            raise self.error

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # the worker's side -------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while True:
                with self._condition:
                    while self._pending is None and not self._stopping:
                        self._condition.wait()
                    snapshot, self._pending = self._pending, None
                    self._condition.notify_all()
                if snapshot is None:
                    break
                try:
                    self._draw(snapshot)
                finally:
                    with self._condition:
                        self._pool.append(snapshot)
            if self._picture is not None:
                self._repeat_until(self._end)
        except BaseException as error:  # re-raised in the loop's thread by submit / finish
            self.error = error
            log.debug("render worker failed", exc_info=True)
            with self._condition:
                self._condition.notify_all()
        finally:
            release_contexts(self.characters)

    def _state_of(self, index: int, fallback: dict | None) -> dict | None:
        stored, state = self._states[index % STATE_RING]
        return state if stored == index else fallback

    def _repeat_until(self, end: int) -> None:
        """Frames written..end-1 as repeats of the last picture."""
        while self.written < end:
            self._write(self._picture, self._state_of(self.written, None), repeat=True)

    def _draw(self, snapshot: Snapshot) -> None:
        if self._picture is not None:   # the frames the worker never got to: the last picture
            self._repeat_until(snapshot.index)
        started = time.perf_counter()
        stage = self.stage
        stage.clear()
        for character, frozen in zip(self.characters, snapshot.frozen):
            stage.place(character.renderer.render(frozen), character.position)
        frame = stage.frame
        self.rendered += 1
        if self.clock is not None:
            self.clock.add("render", 1e3 * (time.perf_counter() - started))
        # the first picture also stands in for the frames before it, if any
        self._picture = frame
        self._repeat_until(snapshot.index)
        self._write(frame, snapshot.state, repeat=False)

    def _write(self, frame, state, *, repeat: bool) -> None:
        started = time.perf_counter()
        for output in self.outputs:
            output.write(frame, state, repeat=repeat)
        self.written += 1
        if repeat:
            self.repeated += 1
        if self.clock is not None:
            self.clock.add("output", 1e3 * (time.perf_counter() - started))
