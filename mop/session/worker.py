"""The render worker: pictures beside the simulation, never in its way.

The loop follows and simulates every frame; after each frame it hands the worker a snapshot (a
copy of every character's deformed surface, or of what it follows: a latex puppet's surface
nodes, `snapshot_parts`; and the frame's state). The worker draws each
character's layer from the snapshot, composes the stage and writes the picture to every frame
output (video, PNG, the preview's JPEG) - one write per session frame, in order.

- Live: the newest snapshot wins. When a render is slower than a frame, the snapshots the
  worker never got to are written as repeats of the last picture, so a video always has one
  frame per session frame (the show's duration) and the loop never waits for pictures.
- Lossless (replay): every snapshot is drawn, in order, so the same takes give the same
  pictures. The loop runs up to SLOTS - 1 frames ahead of the pictures and waits only when
  every slot is taken: loop and pictures overlap on two cores, and the show takes as long as
  the slower of the two, not their sum.

Two workers with the same behaviour:

- `RenderProcess` (the default): a process of its own, which rebuilds the layer renderers
  (`renderer.recipe()`, or the renderer itself pickled) and the frame outputs
  (`output.recipe()`) and reads the surfaces from shared memory. Measured on two cores, a
  render thread doubles the loop's simulation time (moderngl holds the GIL while it draws and
  reads back, and the loop's compiled kernels wait for it at every call); a process does not
  touch it. Live, it runs at a lower priority (nice +10: the loop wins a shared core); a
  replay's render process keeps the session's priority (its pictures are the output). Outputs
  without a recipe (yours) still get every frame, in the session's process, from shared
  memory.
- `RenderWorker`: a thread, for renderers that cannot be rebuilt elsewhere (the 3D layers' GL
  contexts move to it: the building thread releases them first).
"""
from __future__ import annotations

import logging
import os
import pickle
import threading
import time
import traceback

import numpy as np

log = logging.getLogger(__name__)

STATE_RING = 1024   # states kept for frames written as repeats
SLOTS = 4           # snapshots: one being drawn, one being filled, the others waiting
FRAME_SLOTS = 4     # composed frames on their way back to the session's own outputs
RENDER_NICE = 10    # the render process's nice increment: the loop wins a shared core


def snapshot_parts(puppet):
    """(take, skin): what a snapshot copies of a puppet after each frame (`take()`, an array)
    and what draws its surface from that copy (`skin(copy, out)`; None: the copy is the
    surface). A puppet whose drawn surface follows fewer numbers (a latex puppet's visual mesh
    follows its surface nodes: `pose()` and `skin`) hands over those: a smaller copy, and the
    mesh is computed beside the loop, not in it."""
    skin, pose = getattr(puppet, "skin", None), getattr(puppet, "pose", None)
    if skin is not None and callable(pose):
        return pose, skin
    return puppet.surface, None


class FrozenPuppet:
    """What a layer renderer reads of a puppet, frozen at one frame: `surface()` and
    `state.x` give the copy (or, with a skin, the surface drawn from it when asked for);
    anything else (faces, colours, the picture) is the puppet's."""

    def __init__(self, puppet, copy: np.ndarray, skin=None):
        self._puppet = puppet
        self._copy = copy
        self._skin = skin
        self._surface = copy if skin is None else np.empty(skin.shape)
        self.state = self

    @property
    def x(self) -> np.ndarray:
        return self.surface()

    def surface(self) -> np.ndarray:
        if self._skin is not None:
            self._skin(self._copy, self._surface)
        return self._surface

    def __getattr__(self, name):
        if self._puppet is None:
            raise AttributeError(name)
        return getattr(self._puppet, name)


class MeshShape:
    """A puppet's drawing data at rest, picklable: what a 3D layer needs to be built again in
    the render process (`surface()`, `faces`, `vertex_colors`)."""

    def __init__(self, puppet):
        self._surface = np.array(puppet.surface(), dtype=np.float64, copy=True)
        self.faces = np.asarray(puppet.faces)
        colours = getattr(puppet, "vertex_colors", None)
        self.vertex_colors = None if colours is None else np.asarray(colours)

    def surface(self) -> np.ndarray:
        return self._surface


class Pictures:
    """Draws frames and writes every session frame to the outputs, in order: the part the
    thread and the process share. `report(stage, milliseconds)` gets the timing."""

    def __init__(self, stage, layers, outputs, *, report=None):
        self.stage = stage
        self.layers = list(layers)          # (renderer, position) in drawing order
        self.outputs = list(outputs)
        self.report = report
        self.rendered = 0
        self.repeated = 0
        self.written = 0                    # session frames handed to the outputs
        self.picture: np.ndarray | None = None

    def draw(self, index: int, frozen, state_of) -> None:
        """Draw frame `index` from `frozen` puppets (one per layer); the frames before it that
        were never drawn are written first, as repeats of the last picture."""
        if self.picture is not None:
            self.repeat_until(index, state_of)
        started = time.perf_counter()
        stage = self.stage
        stage.clear()
        for (renderer, position), puppet in zip(self.layers, frozen):
            stage.place(renderer.render(puppet), position)
        self.rendered += 1
        if self.report is not None:
            self.report("render", 1e3 * (time.perf_counter() - started))
        self.picture = stage.frame
        self.repeat_until(index, state_of)   # the first picture stands in for those before it
        self.write(stage.frame, state_of(index), repeat=False)

    def repeat_until(self, end: int, state_of) -> None:
        """Frames written..end-1 as repeats of the last picture."""
        while self.written < end and self.picture is not None:
            self.write(self.picture, state_of(self.written), repeat=True)

    def write(self, frame, state, *, repeat: bool) -> None:
        started = time.perf_counter()
        for output in self.outputs:
            output.write(frame, state, repeat=repeat)
        self.written += 1
        self.repeated += repeat
        if self.report is not None:
            self.report("output", 1e3 * (time.perf_counter() - started))


def release_contexts(characters) -> None:
    """Let another thread draw these characters: renderers holding a GL context current in
    this thread release it (renderers without one have nothing to release)."""
    for character in characters:
        release = getattr(character.renderer, "release", None)
        if release is not None:
            release()


class _States:
    """The states of the last STATE_RING frames, for the frames written as repeats."""

    def __init__(self):
        self._ring: list[tuple[int, dict | None]] = [(-1, None)] * STATE_RING

    def put(self, index: int, state: dict | None) -> None:
        self._ring[index % STATE_RING] = (index, state)

    def get(self, index: int) -> dict:
        stored, state = self._ring[index % STATE_RING]
        return state if stored == index and state is not None else {"frame": index}


# --------------------------------------------------------------------------------------------
# the thread


class RenderWorker:
    """Draws snapshots and feeds the frame outputs, in a thread.

    stage : mop.render.compose.Stage; characters : CharacterRuntime (drawn in this order);
    outputs : objects with `write(frame, state, *, repeat)`; lossless : render every frame
    (replay) instead of the newest (live); clock : the session's StageClock ("render" and
    "output" milliseconds are added from this thread)."""

    def __init__(self, stage, characters, outputs, *, lossless: bool, clock=None):
        self.characters = list(characters)
        self.lossless = lossless
        self.error: BaseException | None = None
        self.pictures = Pictures(stage, [(c.renderer, c.position) for c in self.characters],
                                 outputs, report=None if clock is None else clock.add)
        parts = [snapshot_parts(c.puppet) for c in self.characters]
        self._takes = [take for take, _ in parts]
        self._surfaces = [[np.array(take(), dtype=np.float64, copy=True) for take in self._takes]
                          for _ in range(SLOTS)]
        self._frozen = [[FrozenPuppet(c.puppet, s, skin)
                         for c, s, (_, skin) in zip(self.characters, slot, parts)]
                        for slot in self._surfaces]
        self._free = list(range(SLOTS))
        self._pending: list[tuple[int, int]] = []          # (slot, frame index), oldest first
        self._states = _States()
        self._condition = threading.Condition()
        self._stopping = False
        self._end = 0
        self._thread: threading.Thread | None = None

    separate = False          # draws with this process's renderers (warm them up here first)
    rendered = property(lambda self: self.pictures.rendered)
    repeated = property(lambda self: self.pictures.repeated)
    written = property(lambda self: self.pictures.written)

    # the loop's side ---------------------------------------------------------------------
    def start(self) -> None:
        for output in self.pictures.outputs:
            opener = getattr(output, "open", None)
            if opener is not None:
                opener()
        release_contexts(self.characters)
        self._thread = threading.Thread(target=self._run, name="mop-render", daemon=True)
        self._thread.start()

    def wait_ready(self, timeout: float = 0.0) -> None:
        pass

    def submit(self, index: int, state: dict | None) -> None:
        """Hand over frame `index` (copies the surfaces now). Live: never waits; a snapshot
        not yet taken is replaced. Lossless: queued; waits only while every slot is taken."""
        if self.error is not None:
            raise self.error
        with self._condition:
            self._states.put(index, state)
            if self.lossless:
                while not self._free and self.error is None:
                    self._condition.wait(0.5)
                if self.error is not None:
                    raise self.error
            elif self._pending:                    # live: the worker never got to it
                self._free.extend(slot for slot, _ in self._pending)
                self._pending.clear()
            slot = self._free.pop()
        for surface, take in zip(self._surfaces[slot], self._takes):
            np.copyto(surface, take())
        with self._condition:
            self._pending.append((slot, index))
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

    # the worker's side -------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while True:
                with self._condition:
                    while not self._pending and not self._stopping:
                        self._condition.wait()
                    taken = self._pending.pop(0) if self._pending else None
                    self._condition.notify_all()
                if taken is None:
                    break
                slot, index = taken
                try:
                    self.pictures.draw(index, self._frozen[slot], self._states.get)
                finally:
                    with self._condition:
                        self._free.append(slot)
                        self._condition.notify_all()
            self.pictures.repeat_until(self._end, self._states.get)
        except BaseException as error:  # re-raised in the loop's thread by submit / finish
            self.error = error
            log.debug("render worker failed", exc_info=True)
            with self._condition:
                self._condition.notify_all()
        finally:
            release_contexts(self.characters)


# --------------------------------------------------------------------------------------------
# the process


class NotPortable(Exception):
    """A renderer that cannot be rebuilt in the render process (the thread draws it)."""


def _portable(renderer, name: str):
    """What rebuilds `renderer` in the render process: its recipe (factory, args, kwargs), or
    the renderer itself when it pickles."""
    recipe = getattr(renderer, "recipe", None)
    spec = recipe() if recipe is not None else renderer
    try:
        pickle.dumps(spec)
    except Exception as error:
        raise NotPortable(f"the renderer of {name!r} ({type(renderer).__name__}) cannot be "
                          f"rebuilt in the render process: {error}") from None
    return spec


def _rebuild(spec):
    if isinstance(spec, tuple) and len(spec) == 3 and callable(spec[0]):
        factory, args, kwargs = spec
        return factory(*args, **kwargs)
    return spec


# control block (shared integers): the end, each slot's state and frame, each frame slot's state
_END = 0
_STATE, _INDEX = 1, 1 + SLOTS
_FRAME_STATE = 1 + 2 * SLOTS
_CONTROL = _FRAME_STATE + FRAME_SLOTS
FREE, FILLING, WAITING, DRAWING = 0, 1, 2, 3


class RenderProcess:
    """Draws snapshots and feeds the frame outputs in a process of its own (see the module).

    Same interface as RenderWorker; frame outputs with `recipe()` run in the render process
    (their counts come back when it finishes), the others in this process."""

    separate = True           # builds and warms its own renderers

    def __init__(self, stage, characters, outputs, *, lossless: bool, clock=None):
        self.characters = list(characters)
        self.lossless = lossless
        self.clock = clock
        self.error: BaseException | None = None
        self.rendered = self.repeated = self.written = 0
        self.cpu_seconds = 0.0      # the render process's CPU time from ready to done
        self._layers = [_portable(c.renderer, c.name) for c in self.characters]
        self._stage = (tuple(stage.frame.shape[1::-1]), stage.background)
        self._remote, self._local = [], []
        for output in outputs:
            recipe = getattr(output, "recipe", None)
            recipe = None if recipe is None else recipe()
            if recipe is not None:
                self._remote.append((output, recipe))
            else:
                self._local.append(output)
        parts = [snapshot_parts(c.puppet) for c in self.characters]
        self._takes = [take for take, _ in parts]
        self._skins = [skin for _, skin in parts]
        self._surfaces = [np.array(take(), dtype=np.float64, copy=True) for take in self._takes]
        self._states = _States()
        self._ready = threading.Event()
        self._done = threading.Event()
        self._process = self._reader = None
        self._memory = []

    # the loop's side ---------------------------------------------------------------------
    def start(self) -> None:
        import multiprocessing
        from multiprocessing import shared_memory
        for output in self._local:
            opener = getattr(output, "open", None)
            if opener is not None:
                opener()
        context = multiprocessing.get_context("spawn")   # no GL or threads carried over
        layout = [(s.shape, s.nbytes) for s in self._surfaces]
        snapshot_bytes = max(1, sum(size for _, size in layout))
        surfaces = shared_memory.SharedMemory(create=True, size=SLOTS * snapshot_bytes)
        self._memory.append(surfaces)
        self._views = _slot_views(surfaces.buf, layout, snapshot_bytes)
        width, height = self._stage[0]
        frames = None
        if self._local:
            frames = shared_memory.SharedMemory(create=True, size=FRAME_SLOTS * height * width
                                                * 4)
            self._memory.append(frames)
            self._frames = np.ndarray((FRAME_SLOTS, height, width, 4), np.uint8, frames.buf)
        self._condition = context.Condition()
        self._control = context.RawArray("q", _CONTROL)
        self._control[_END] = -1
        ours, theirs = context.Pipe()
        self._pipe = ours
        spec = {"stage": self._stage, "layers": self._layers,
                "positions": [c.position for c in self.characters],
                "rest": self._surfaces, "skins": self._skins, "layout": layout,
                "snapshot_bytes": snapshot_bytes,
                "surfaces": surfaces.name, "frames": None if frames is None else frames.name,
                "outputs": [recipe for _, recipe in self._remote], "lossless": self.lossless}
        self._process = context.Process(target=_child, name="mop-render",
                                        args=(spec, theirs, self._condition, self._control),
                                        daemon=True)
        self._process.start()
        theirs.close()
        self._reader = threading.Thread(target=self._read, name="mop-render-reader",
                                        daemon=True)
        self._reader.start()

    def wait_ready(self, timeout: float = 300.0) -> None:
        """Wait until the render process has built its renderers and outputs and drawn once
        (raises what went wrong there)."""
        deadline = time.monotonic() + timeout
        while not self._ready.wait(0.2):
            if self.error is not None:
                raise self.error
            if not self._process.is_alive() or time.monotonic() > deadline:
                self._dead("while starting")
        if self.error is not None:
            raise self.error

    def _dead(self, when: str):
        code = self._process.exitcode
        self.error = self.error or RuntimeError(
            f"the render process stopped {when} (exit code {code})" if code is not None
            else f"the render process did not answer {when}")
        raise self.error

    def submit(self, index: int, state: dict | None) -> None:
        """Hand over frame `index` (copies the surfaces into shared memory now). Live: never
        waits; a snapshot not yet taken is replaced. Lossless: queued; waits only while every
        slot is taken."""
        if self.error is not None:
            raise self.error
        control = self._control
        with self._condition:
            self._states.put(index, state)
            if self.lossless:
                while _slot_in(control, FREE) == -1:
                    self._condition.wait(0.5)
                    if self.error is not None:
                        raise self.error
                    if not self._process.is_alive():
                        self._dead("during the show")
            else:                                  # live: a snapshot not yet taken goes
                waiting = _slot_in(control, WAITING)
                if waiting != -1:
                    control[_STATE + waiting] = FREE
            slot = _slot_in(control, FREE)
            control[_STATE + slot] = FILLING
        for view, take in zip(self._views[slot], self._takes):
            np.copyto(view, take())
        with self._condition:
            control[_INDEX + slot] = index
            control[_STATE + slot] = WAITING
            self._condition.notify_all()

    def finish(self, frames: int) -> None:
        """Write every frame up to `frames` (repeats where no render came), stop the process.
        Raises what went wrong there."""
        try:
            if self._process is not None:
                with self._condition:
                    self._control[_END] = frames
                    self._condition.notify_all()
                while not self._done.wait(0.5):
                    if not self._process.is_alive():
                        self._done.wait(1.0)      # its last words may still be in the pipe
                        if not self._done.is_set():
                            self._dead("before it finished")
                        break
                self._process.join(timeout=10)
            if self._reader is not None:
                self._reader.join(timeout=10)
        finally:
            if self._process is not None and self._process.is_alive():
                self._process.kill()
            for memory in self._memory:
                memory.close()
                memory.unlink()
            self._memory = []
        if self.error is not None:
            raise self.error

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.is_alive()

    # what the render process says (a thread that mostly waits) ------------------------------
    def _read(self) -> None:
        add = None if self.clock is None else self.clock.add
        while True:
            try:
                message = self._pipe.recv()
            except (EOFError, OSError):
                break
            kind = message[0]
            if kind == "drawn":
                _, self.rendered, self.repeated, self.written, render_ms, output_ms = message
                if add is not None:
                    add("render", render_ms)
                    for milliseconds in output_ms:
                        add("output", milliseconds)
            elif kind == "frame":
                self._write_here(*message[1:])
            elif kind == "jpeg":
                _, position, number, data = message
                self._remote_output(position).publish(number, data)
            elif kind == "ready":
                self._ready.set()
            elif kind == "error":
                self.error = message[1]
                self._ready.set()
            elif kind == "done":
                (_, self.rendered, self.repeated, self.written, counts,
                 self.cpu_seconds) = message
                for (output, _), count in zip(self._remote, counts):
                    if count is not None:
                        output.frames = count
                self._done.set()
                break

    def _remote_output(self, position: int):
        return self._remote[position][0]

    def _write_here(self, slot: int, index: int, repeat: bool) -> None:
        """A composed frame for the outputs of this process; then the slot is free again."""
        try:
            if self.error is None:
                frame = self._frames[slot]
                for output in self._local:
                    output.write(frame, self._states.get(index), repeat=repeat)
        except BaseException as error:
            self.error = error
        finally:
            with self._condition:
                self._control[_FRAME_STATE + slot] = FREE
                self._condition.notify_all()


def _slot_in(control, state: int) -> int:
    """The snapshot slot in `state` holding the earliest frame, or -1 (call it holding the
    condition)."""
    found = -1
    for slot in range(SLOTS):
        if control[_STATE + slot] == state and (
                found == -1 or control[_INDEX + slot] < control[_INDEX + found]):
            found = slot
    return found


def _slot_views(buffer, layout, snapshot_bytes) -> list[list[np.ndarray]]:
    """[slot][character] (V, d) float64 views into the shared surfaces."""
    views = []
    for slot in range(SLOTS):
        offset = slot * snapshot_bytes
        row = []
        for shape, size in layout:
            row.append(np.ndarray(shape, np.float64, buffer, offset))
            offset += size
        views.append(row)
    return views


class _ToSession:
    """In the render process: a frame output that hands composed frames back to the session's
    process (for the outputs that live there), through shared frame slots."""

    def __init__(self, frames: np.ndarray, pipe, condition, control):
        self.frames, self.pipe, self.condition, self.control = frames, pipe, condition, control

    def write(self, frame, state, *, repeat: bool = False) -> None:
        control = self.control
        with self.condition:
            while True:
                slot = next((k for k in range(FRAME_SLOTS)
                             if control[_FRAME_STATE + k] == FREE), None)
                if slot is not None:
                    break
                self.condition.wait(0.5)
            control[_FRAME_STATE + slot] = FILLING
        np.copyto(self.frames[slot], frame)
        self.pipe.send(("frame", slot, int(state["frame"]), bool(repeat)))

    def close(self) -> None:
        pass


def _child(spec, pipe, condition, control) -> None:
    """The render process: build, say ready, draw what the session hands over, finish."""
    memories: list = []
    outputs: list = []
    try:
        if not spec["lossless"]:
            _lower_priority()
        pictures, frozen, timings = _build_child(spec, pipe, condition, control, memories,
                                                 outputs)
        pipe.send(("ready",))
        ready = time.process_time()
        _draw_until_the_end(pictures, frozen, timings, pipe, condition, control)
        for output in outputs:
            output.close()
        pipe.send(("done", pictures.rendered, pictures.repeated, pictures.written,
                   [getattr(output, "frames", None) for output in outputs],
                   time.process_time() - ready))
    except BaseException as error:
        _say_error(error, pipe)
        for output in outputs:
            try:
                output.close()
            except Exception:
                log.debug("closing an output after an error", exc_info=True)
    finally:
        for memory in memories:
            memory.close()


def _lower_priority() -> None:
    """The session's loop comes first: on a shared core the render process yields to it (and
    its GL driver threads, started later, inherit this)."""
    try:
        os.nice(RENDER_NICE)
    except OSError:
        log.debug("could not lower the render process's priority", exc_info=True)


def _build_child(spec, pipe, condition, control, memories, outputs):
    """In the render process: the stage, the layer renderers and the outputs from `spec`,
    drawn once (compiles and builds what a first frame would). Returns (Pictures, the frozen
    puppets of each snapshot slot, its _Timings)."""
    from multiprocessing import shared_memory

    from mop.render.compose import Stage
    surfaces = shared_memory.SharedMemory(name=spec["surfaces"])
    memories.append(surfaces)
    views = _slot_views(surfaces.buf, spec["layout"], spec["snapshot_bytes"])
    size, background = spec["stage"]
    stage = Stage(size, background)
    layers = [(_rebuild(layer), tuple(position))
              for layer, position in zip(spec["layers"], spec["positions"])]
    for position, recipe in enumerate(spec["outputs"]):
        output = _rebuild(recipe)
        if hasattr(output, "connect"):
            output.connect(lambda number, data, position=position: pipe.send(
                ("jpeg", position, number, data)))
        outputs.append(output)
    if spec["frames"] is not None:
        frames = shared_memory.SharedMemory(name=spec["frames"])
        memories.append(frames)
        outputs.append(_ToSession(np.ndarray((FRAME_SLOTS, size[1], size[0], 4), np.uint8,
                                             frames.buf), pipe, condition, control))
    for output in outputs:
        opener = getattr(output, "open", None)
        if opener is not None:
            opener()
    timings = _Timings()
    pictures = Pictures(stage, layers, outputs, report=timings.add)
    stage.clear()
    skins = spec["skins"]
    for (renderer, position), surface, skin in zip(layers, spec["rest"], skins):
        stage.place(renderer.render(FrozenPuppet(None, surface, skin)), position)
    frozen = [[FrozenPuppet(None, view, skin) for view, skin in zip(slot, skins)]
              for slot in views]
    return pictures, frozen, timings


class _Timings:
    """Render and output milliseconds of the render process, sent to the session per frame."""

    def __init__(self):
        self.render: list[float] = []
        self.output: list[float] = []

    def add(self, stage: str, milliseconds: float) -> None:
        (self.render if stage == "render" else self.output).append(milliseconds)

    def take(self) -> tuple[float, list[float]]:
        render, output = (self.render[-1] if self.render else 0.0), self.output
        self.render, self.output = [], []
        return render, output


def _draw_until_the_end(pictures, frozen, timings, pipe, condition, control) -> None:
    """Draw each snapshot the session hands over (the newest one, live) until the session
    says how many frames the show had; then write the frames still missing as repeats."""
    parent = os.getppid()

    def state_of(index):
        return {"frame": index}

    while True:
        with condition:
            while _slot_in(control, WAITING) == -1 and control[_END] == -1:
                condition.wait(1.0)
                if os.getppid() != parent:
                    return                   # the session is gone
            slot = _slot_in(control, WAITING)
            if slot == -1:
                break
            control[_STATE + slot] = DRAWING
            index = control[_INDEX + slot]
            condition.notify_all()
        try:
            pictures.draw(index, frozen[slot], state_of)
        finally:
            with condition:
                control[_STATE + slot] = FREE
                condition.notify_all()
        render_ms, output_ms = timings.take()
        pipe.send(("drawn", pictures.rendered, pictures.repeated, pictures.written,
                   render_ms, output_ms))
    pictures.repeat_until(control[_END], state_of)


def _say_error(error: BaseException, pipe) -> None:
    """Hand what went wrong in the render process to the session (which raises it)."""
    try:
        pickle.dumps(error)
    except Exception:
        error = RuntimeError(f"in the render process: {type(error).__name__}: {error}\n"
                             f"{traceback.format_exc()}")
    try:
        pipe.send(("error", error))
    except OSError:
        pass
