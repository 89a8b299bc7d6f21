"""The session loop: one clock steps every performer and character; pictures are drawn beside it.

Per frame k (session time t = k / fps), in order, for every frame of the show:

1. capture   each performer's feed gives its input at the frame's time (a take sampled at t; a
             live source resampled from what arrived, a fixed latency before the frame was due);
2. follow    the performer's follower bank steps on the selected, normalised values;
3. simulate  every character's tracks turn (action, progress) into targets - the motion sampled
             at progress x duration, cross-faded over `blend` seconds when the action changes,
             and when the action ends, what its binding says (`after`: rest, hold or loop) -
             and the puppet steps by 1 / fps;
4. send      state outputs (OSC, the preview's state) get the frame's state;
5. pictures  the render worker (`mop.session.worker`) gets a copy of every surface; it draws,
             composes and writes the frame outputs (video, PNG, preview picture) in its thread.

Live mode keeps the wall clock: frame k is due at start + k / fps. A frame that is late is still
followed and simulated, and the next ones run back to back until the loop has caught up (their
input is taken at their own times, so nothing is seen sped up); only pictures are dropped, and a
dropped picture goes to the video as a repeat. When the loop is more than `max_lag` seconds
behind, the machine cannot keep the rate: the session clock slips (the show goes on from now,
the input of the slipped time is not followed) and the report and the preview say so.
Replay mode runs as fast as it can on the session clock and renders every frame: the same takes
give the same frames.
"""
from __future__ import annotations

import enum
import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .config import After
from .feeds import ENDED, OK
from .timing import SessionReport, StageClock

log = logging.getLogger(__name__)


class Mode(str, enum.Enum):
    LIVE = "live"       # wall clock; pictures are dropped rather than falling behind
    REPLAY = "replay"   # session clock; as fast as possible; deterministic


def smoothstep(s: float) -> float:
    """0 -> 0, 1 -> 1 with zero slope at both ends: a cross-fade without a kink."""
    s = min(max(s, 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


@dataclass
class FollowState:
    """What one performer's bank said this frame (None action = nothing recognised).

    progress in [0, 1]; variance [progress units squared]; log_likelihood since the bank's
    reset; fit: the recent per-channel log-likelihood the bank's rejection compares."""
    action: str | None = None
    progress: float = 0.0
    variance: float = 0.0
    log_likelihood: float = 0.0
    fit: float = 0.0

    def as_dict(self) -> dict:
        return {"action": self.action, "progress": self.progress, "variance": self.variance,
                "log_likelihood": self.log_likelihood, "fit": self.fit}


# A shown action whose progress moved less than this in the still window has stopped: chosen on
# the demo's action takes alone, played at 0.5x-2x between rests made of their own end frames
# and noise level: the followers' progress advanced at least 0.038 in 0.4 s during a gesture,
# at most 0.015 once the gesture had ended.
STILL_PROGRESS = 0.03


class PerformerRuntime:
    """One performer: feed -> channel selection -> normalisation -> follower bank.

    channels : the D channel names the bank expects, picked by name from the feed's channels
    (empty = the feed's channels as they come); shift, scale : (D,) float, so the bank sees
    x = (values[selected] - shift) / scale; still_frames : a shown action whose progress moved
    less than STILL_PROGRESS over this many frames is shown as no action (the performer stopped;
    0 = never)."""

    def __init__(self, name: str, feed, bank, *, channels: Sequence[str] = (), shift=None,
                 scale=None, actions: Sequence[str] = (), still_frames: int = 0):
        self.name = name
        self.feed = feed
        self.bank = bank
        self.channels = tuple(channels)
        self.shift = None if shift is None else np.asarray(shift, dtype=np.float64)
        self.scale = None if scale is None else np.asarray(scale, dtype=np.float64)
        self.actions = tuple(actions)
        self.values: np.ndarray | None = None
        self.state = FollowState()
        self.status = feed.status
        self.was_ok = feed.status == OK
        self.seen: set[str] = set()
        self.steps = 0               # bank steps since the input was last (re)joined
        self.outliers = 0            # frames with a channel far outside the templates (absurd)
        self.problem = ""            # why the input cannot be followed right now, if it cannot
        self._reported = ""
        self._feed_channels: tuple[str, ...] | None = None
        self._select: np.ndarray | None = None
        self._x = np.empty(len(self.channels))
        self._following = False
        self._last = None
        self.still = False
        self._recent_progress = np.zeros(max(int(still_frames), 0))
        self._recent_action = np.zeros(max(int(still_frames), 0), dtype=np.int64)

    def _selection(self) -> np.ndarray | None:
        """Indices of the wanted channels in the feed's (resolved again when they change: a
        live source only says what it carries once it is open)."""
        channels = tuple(self.feed.channels)
        if channels != self._feed_channels:
            if not self.channels or channels == self.channels:
                self._select = None
            else:
                missing = [c for c in self.channels if c not in channels]
                if missing:
                    raise ValueError(
                        f"performer {self.name!r}: the source has no channel {missing[0]!r}; "
                        f"it has {', '.join(channels) or 'none'}")
                self._select = np.array([channels.index(c) for c in self.channels])
            self._feed_channels = channels
        return self._select

    def prepare(self, values: np.ndarray) -> np.ndarray:
        """Selected, normalised feature vector (D,) float for the bank; NaN stays NaN."""
        select = self._selection()
        if select is not None:
            x = np.take(values, select, out=self._x)
        else:
            if self._x.shape != values.shape:
                self._x = np.empty(values.shape)
            x = self._x
            x[...] = values
        if self.shift is not None:
            x -= self.shift
            x /= self.scale
        return x

    def follow(self) -> None:
        if self.values is None or self.status != OK:
            if self._following:
                self.bank.reset()
                self._following = False
                self.steps = 0
            self.still = False
            self.state = FollowState()
            return
        try:
            x = self.prepare(self.values)
        except ValueError as error:  # e.g. the source does not carry the channels asked for
            self.problem = str(error)
            self.state = FollowState()
            return
        self.problem = ""
        out = self.bank.step(x)
        self._following = True
        self.steps += 1
        self._last = out
        if getattr(out, "outlier", False):
            self.outliers += 1
        self.still = self._stopped(out)
        state = self.state
        state.action = None if self.still else out.action
        state.progress = float(out.progress)
        state.variance = float(out.variance)
        state.log_likelihood = float(out.log_likelihood)
        state.fit = float(getattr(out, "fit", 0.0))
        if out.action is not None:
            self.seen.add(out.action)

    def _stopped(self, out) -> bool:
        """True when the bank has shown one action over the still window (or no action on
        some of its frames: the bank's own still stage) and the progress moved less than
        STILL_PROGRESS: the performer stopped (or holds the end)."""
        window = self._recent_progress.size
        if window == 0:
            return False
        slot = (self.steps - 1) % window
        self._recent_progress[slot] = out.progress
        self._recent_action[slot] = -1 if out.action is None else int(getattr(out, "index", 0))
        if self.steps < window or out.action is None:
            return False
        actions, progress = self._recent_action, self._recent_progress
        shown = actions.max()
        return bool(np.all((actions == shown) | (actions < 0))
                    and progress.max() - progress.min() < STILL_PROGRESS)

    def posterior(self) -> dict[str, float]:
        """{action: probability} from the bank's last step (empty while not following)."""
        if not self._following:
            return {}
        return dict(getattr(self._last, "posterior", None) or {})

    def warm_up(self) -> None:
        """Step the bank once and forget it (compiles what a first step compiles)."""
        width = len(self.channels) or int(getattr(self.bank, "channels", 0) or 0)
        if width:
            self.bank.step(np.zeros(width))
            self.bank.reset()


class Track:
    """One performer's hold on one character: which action plays which motion on which targets.

    motions : {action: (Motion, ((motion channel, target name), ...))}
    rest : {target: (c,) float} the values a target relaxes towards before it is let go;
    after : {action: After} what the character does when that action ends (default rest)."""

    def __init__(self, performer: str, motions: Mapping[str, tuple[Any, tuple]],
                 rest: Mapping[str, np.ndarray], *, blend: float,
                 after: Mapping[str, After | str] | None = None):
        self.performer = performer
        self.motions = dict(motions)
        self.rest = {k: float(np.ravel(v)[0]) if np.size(v) == 1 else np.asarray(v, float)
                     for k, v in rest.items()}
        self.blend = float(blend)
        self.after = {name: After(value) for name, value in (after or {}).items()}
        self.current: str | None = None
        self.mode = "rest"           # "active" (performed), "hold", "loop" or "rest"
        self.progress = 0.0
        self.weight = 1.0
        self.blend_from: dict[str, np.ndarray] = {}
        self.blend_start = -math.inf
        self.last: dict[str, np.ndarray] = {}
        self._last_t = 0.0

    @property
    def targets(self) -> set[str]:
        return {target for _, channels in self.motions.values() for _, target in channels}

    def reset(self) -> None:
        self.current = None
        self.mode = "rest"
        self.blend_from = {}
        self.last = {}
        self.blend_start = -math.inf

    def _next(self, t: float, state: FollowState) -> tuple[str | None, str, float]:
        """(action, mode, progress) this frame: the performed action when it is one of this
        track's, else what the ended action's `after` says."""
        if state.action in self.motions:
            return state.action, "active", min(max(state.progress, 0.0), 1.0)
        current = self.current
        after = self.after.get(current, After.REST) if current is not None else After.REST
        if after is After.HOLD:
            return current, "hold", self.progress
        if after is After.LOOP:
            motion = self.motions[current][0]
            step = (t - self._last_t) / motion.duration if motion.duration > 0 else 0.0
            return current, "loop", math.fmod(self.progress + step, 1.0)
        return None, "rest", 0.0

    def update(self, t: float, state: FollowState, out: dict) -> None:
        """Write this track's targets for session time t [s] into `out` {target: float or (c,)
        float} (one-component channels as floats)."""
        action, mode, progress = self._next(t, state)
        self._last_t = t
        # a cross-fade starts when the motion changes, or when a held or looping motion is
        # performed again (its progress starts over); ending into hold or loop goes on smoothly
        changed = action != self.current or (mode == "active" and self.mode in ("hold", "loop"))
        if changed:
            self.blend_from = self.last
            self.blend_start = t
        self.current, self.mode, self.progress = action, mode, progress
        weight = 1.0 if self.blend <= 0 else smoothstep((t - self.blend_start) / self.blend)
        self.weight = weight
        goal: dict[str, np.ndarray] = {}
        if action is not None:
            motion, channels = self.motions[action]
            sample = motion.sample(progress * motion.duration)
            for channel, target in channels:
                value = sample[channel]
                # a one-component channel (finger bend, joint angle) is a plain float target
                goal[target] = float(value[0]) if len(value) == 1 else np.asarray(
                    value, dtype=np.float64)
        emitted: dict[str, np.ndarray] = {}
        if weight < 1.0:
            for target, start in self.blend_from.items():
                end = goal.get(target, self.rest.get(target))
                if end is None:
                    continue
                emitted[target] = (1.0 - weight) * start + weight * end
        for target, value in goal.items():
            emitted.setdefault(target, value)
        self.last = emitted
        out.update(emitted)


class CharacterRuntime:
    """One character: its puppet, its renderer, its place, and the tracks that drive it."""

    def __init__(self, name: str, puppet, renderer, *, position=(0.5, 0.5),
                 tracks: Sequence[Track] = ()):
        self.name = name
        self.puppet = puppet
        self.renderer = renderer
        self.position = tuple(position)
        self.tracks = list(tracks)
        self.targets: dict[str, np.ndarray] = {}
        self.timing = f"simulate {name}"      # its part of the loop's simulate stage

    def warm_up(self, dt: float, *, draw: bool = True) -> None:
        """Step the puppet on its rest targets and (`draw`) draw it once, then put it back at
        rest (compiles what a first frame compiles; a puppet without reset() is not stepped)."""
        reset = getattr(self.puppet, "reset", None)
        if reset is not None:
            rest: dict[str, Any] = {}
            for track in self.tracks:
                rest.update(track.rest)
            self.puppet.step(dt, rest)
            self.puppet.step(dt, {})
            reset()
        if draw and self.renderer is not None:
            self.renderer.render(self.puppet)


def _frame_outputs(outputs) -> list:
    return [o for o in outputs if callable(getattr(o, "write", None))]


def _state_outputs(outputs) -> list:
    return [o for o in outputs if callable(getattr(o, "send", None))]


class Session:
    """Performers x characters x outputs on one clock. Build one with `mop.session.build`;
    this class only runs what it is given.

    performers : PerformerRuntime; characters : CharacterRuntime (drawn in this order);
    stage : mop.render.compose.Stage or None (no pictures); outputs : objects with
    `send(state)` (called in the loop, every frame) and/or `write(frame (H, W, 4) uint8, state,
    *, repeat: bool)` (called by the render worker, once per frame, in order; `repeat` when the
    frame's render was dropped and the previous picture stands in); both have `close()`.
    max_lag [s]: how far live mode may fall behind the wall clock before the session clock
    slips (see the module docstring); pictures: "process" (a render process, the default) or
    "thread" (see `mop.session.worker`; renderers that cannot be rebuilt in a process are drawn
    in a thread anyway)."""

    def __init__(self, performers: Sequence[PerformerRuntime],
                 characters: Sequence[CharacterRuntime], *, fps: int = 25,
                 mode: Mode | str = Mode.REPLAY, stage=None, outputs: Sequence = (),
                 tail: float = 0.0, name: str = "session", max_lag: float = 0.5,
                 pictures: str = "process"):
        self.name = name
        self.performers = list(performers)
        self.characters = list(characters)
        self.fps = int(fps)
        self.dt = 1.0 / self.fps
        self.mode = Mode(mode)
        self.stage = stage
        self.outputs = list(outputs)
        self.tail = float(tail)
        self.max_lag = float(max_lag)
        if pictures not in ("process", "thread"):
            raise ValueError(f"pictures must be 'process' or 'thread', got {pictures!r}")
        self.pictures = pictures
        self.frame_index = 0
        self.t = 0.0
        self.clock = StageClock()
        for character in self.characters:
            self.clock.track(character.timing)
        self.events: list[dict] = []
        self.ended_at: float | None = None
        self.wall_start: float | None = None
        self.wall_seconds = 0.0
        self.warmup_seconds = 0.0
        self.closed = False
        self.stop_requested = False
        self.late_frames = 0          # live: frames that started more than a period late
        self.max_late = 0.0           # [s] the most a frame started late
        self.slipped = 0.0            # [s] the session clock gave up to keep up
        self.slips = 0
        self.lag = 0.0                # [s] how late the last frame started
        self.worker = None
        self._warm = False
        self._start = 0.0
        self._by_name = {p.name: p for p in self.performers}
        self._state_outputs = _state_outputs(self.outputs)
        self._frame_outputs = _frame_outputs(self.outputs)

    # counters the report and the preview show -----------------------------------------------
    @property
    def rendered(self) -> int:
        return 0 if self.worker is None else self.worker.rendered

    @property
    def dropped(self) -> int:
        """Frames whose picture was not drawn (a repeat of the previous one stands in)."""
        return 0 if self.worker is None else self.worker.repeated

    @property
    def frame(self) -> np.ndarray | None:
        return None if self.stage is None or self.rendered == 0 else self.stage.frame

    # one frame ---------------------------------------------------------------------------
    def step(self, *, due: float | None = None) -> None:
        """Follow and simulate one frame at session time `self.t` (due at `due` on the capture
        clock, live; default now), send its state, and hand its pictures to the worker."""
        t = self.t
        clock = time.perf_counter
        start = clock()
        for performer in self.performers:
            performer.values = performer.feed.poll(t, due=due)
            status = performer.feed.status
            if status != performer.status:
                self._event(performer, status, performer.feed.message)
                performer.status = status
        captured = clock()
        for performer in self.performers:
            performer.follow()
            if performer.problem != performer._reported:
                performer._reported = performer.problem
                if performer.problem:
                    self.events.append({"t": t, "performer": performer.name, "status": "failed",
                                        "message": performer.problem})
                    log.warning("performer %s: %s", performer.name, performer.problem)
        followed = clock()
        add = self.clock.add
        begun = followed
        for character in self.characters:
            targets = character.targets
            targets.clear()
            for track in character.tracks:
                track.update(t, self._by_name[track.performer].state, targets)
            character.puppet.step(self.dt, targets)
            ended = clock()
            add(character.timing, 1e3 * (ended - begun))
            begun = ended
        simulated = begun
        state = self.state() if self._state_outputs or self.worker is not None else None
        for output in self._state_outputs:
            output.send(state)
        if self.worker is not None:
            self.worker.submit(self.frame_index, state)
        done = clock()
        add("capture", 1e3 * (captured - start))
        add("follow", 1e3 * (followed - captured))
        add("simulate", 1e3 * (simulated - followed))
        add("send", 1e3 * (done - simulated))
        add("total", 1e3 * (done - start))
        add("input_to_pose", 1e3 * (simulated - start))
        self.frame_index += 1
        self.t = self.frame_index * self.dt

    def _event(self, performer: PerformerRuntime, status: str, message: str) -> None:
        """Note a change of a performer's input status (shown in the report and the preview)."""
        if status == OK:
            text = f"back (was {performer.status})" if performer.was_ok else "receiving"
            performer.was_ok = True
        else:
            text = f"{status}: {message}" if message else status
        self._note(performer.name, status, text)
        if status not in (OK, ENDED):
            log.warning("performer %s %s at t=%.2f s", performer.name, text, self.t)

    def _note(self, who: str, status: str, message: str) -> None:
        self.events.append({"t": self.t, "performer": who, "status": status,
                            "message": message})
        if len(self.events) > 1000:      # a flapping source must not grow this forever
            del self.events[:100]

    # the whole show ----------------------------------------------------------------------
    def request_stop(self) -> None:
        """Ask the loop to stop after the current frame (safe from a signal handler)."""
        self.stop_requested = True

    @property
    def finished(self) -> bool:
        """True once every performer's input has ended (live sources never end) and the
        characters had `tail` seconds to settle."""
        if self.stop_requested:
            return True
        if not self.performers or any(p.feed.status != ENDED for p in self.performers):
            self.ended_at = None
            return False
        if self.ended_at is None:
            self.ended_at = self.t
        return self.t - self.ended_at >= self.tail

    def warm_up(self, *, draw: bool = True) -> None:
        """Before the clock starts: step every bank and puppet once and (`draw`) draw every
        character, then put them back, so that nothing compiles or builds during the show."""
        if self._warm:
            return
        started = time.monotonic()
        for performer in self.performers:
            performer.warm_up()
        for character in self.characters:
            character.warm_up(self.dt, draw=draw)
        if self.stage is not None and draw:
            self.stage.clear()
            for character in self.characters:
                self.stage.place(character.renderer.render(character.puppet), character.position)
        self._warm = True
        self.warmup_seconds = time.monotonic() - started

    def run(self, *, duration: float | None = None, progress=None) -> SessionReport:
        """Run until the inputs end, `duration` [s] of session time passes, or Ctrl-C; the
        outputs are closed in every case. `progress(session)` is called once per frame."""
        try:
            preparing = time.monotonic()
            self.worker = self._make_worker()
            if self.worker is None or not self.worker.separate:
                self.warm_up()
                if self.worker is not None:
                    self.worker.start()
            else:                     # the render process builds while this one warms up
                self.worker.start()
                self.warm_up(draw=False)
                self.worker.wait_ready()
            self.wall_start = time.monotonic()
            self.warmup_seconds = self.wall_start - preparing
            if self.mode is Mode.REPLAY:
                while not self.finished and (duration is None or self.t < duration):
                    self.step()
                    if progress is not None:
                        progress(self)
            else:
                self._run_live(duration, progress)
        finally:
            self.wall_seconds = time.monotonic() - (self.wall_start or time.monotonic())
            self.close()
        return self.report()

    def _make_worker(self):
        """The render worker for this run, or None when there are no pictures to make."""
        if self.stage is None or not self._frame_outputs:
            return None
        from .worker import NotPortable, RenderProcess, RenderWorker
        options = dict(lossless=self.mode is Mode.REPLAY, clock=self.clock)
        if self.pictures == "process":
            try:
                return RenderProcess(self.stage, self.characters, self._frame_outputs,
                                     **options)
            except NotPortable as why:
                log.info("%s; the pictures are drawn in a thread", why)
        return RenderWorker(self.stage, self.characters, self._frame_outputs, **options)

    def _run_live(self, duration, progress) -> None:
        period = self.dt
        monotonic = time.monotonic
        self._start = monotonic()
        while not self.finished and (duration is None or self.t < duration):
            due = self._start + self.frame_index * period
            wait = due - monotonic()
            if wait > 0:
                time.sleep(wait)
            late = monotonic() - due
            self.lag = max(late, 0.0)
            if late > period:
                self.late_frames += 1
                self.max_late = max(self.max_late, late)
            if late > self.max_lag:
                self._slip(late)
                due += late
            self.step(due=due)
            if progress is not None:
                progress(self)

    def _slip(self, late: float) -> None:
        """The loop is `late` seconds behind: the machine cannot keep the rate. The session
        clock moves on to now; the input of the time in between is not followed."""
        self._start += late
        self.slipped += late
        self.slips += 1
        self._note("session", "behind", f"the simulation could not keep {self.fps} fps: "
                   f"{late:.2f} s behind real time, that much input was not followed")
        log.warning("session %s: %.2f s behind real time; the clock slipped", self.name, late)

    def close(self) -> None:
        """Finish the pictures, finalise every output (idempotent): a video stopped by Ctrl-C
        still plays, with one picture per frame performed."""
        if self.closed:
            return
        self.closed = True
        errors = []
        if self.worker is not None:
            try:
                self.worker.finish(self.frame_index)
            except Exception as error:  # close the outputs anyway, then report
                errors.append(error)
        for output in self.outputs:
            try:
                output.close()
            except Exception as error:  # close the others anyway, then report
                errors.append(error)
        for performer in self.performers:
            try:
                performer.feed.close()
            except Exception:
                log.debug("closing feed of %s", performer.name, exc_info=True)
        for character in self.characters:
            close = getattr(character.renderer, "close", None)
            if close is not None:
                close()
        if errors:
            raise errors[0]

    # reporting ---------------------------------------------------------------------------
    @property
    def mode_label(self) -> str:
        """"live", "replay" or "replay in real time" (takes on the wall clock)."""
        if self.mode is Mode.REPLAY:
            return "replay"
        replayed = all(hasattr(p.feed, "duration") for p in self.performers)
        return "replay in real time" if replayed and self.performers else "live"

    def state(self) -> dict:
        """Everything a viewer may want about now: performers, characters, timing."""
        return {
            "session": self.name, "frame": self.frame_index, "t": self.t,
            "mode": self.mode_label, "fps": self.fps,
            "performers": {p.name: {"status": "failed" if p.problem else p.status,
                                    "message": p.problem or p.feed.message,
                                    "input_frame": p.steps - 1 if p.steps else None,
                                    "still": p.still, "outliers": p.outliers,
                                    **p.state.as_dict(), "posterior": p.posterior()}
                           for p in self.performers},
            "characters": {c.name: {
                "tracks": [{"performer": tr.performer, "action": tr.current, "state": tr.mode,
                            "progress": tr.progress, "blend": tr.weight}
                           for tr in c.tracks],
                "targets": {k: np.atleast_1d(v).tolist() for k, v in c.targets.items()}}
                for c in self.characters},
        }

    def counters(self) -> dict:
        """How the show keeps up right now (for the preview): pictures drawn and dropped, how
        late the last frame started [s], the time the clock slipped [s]."""
        return {"rendered": self.rendered, "dropped": self.dropped, "behind": self.lag,
                "slipped": self.slipped, "late_frames": self.late_frames}

    def report(self) -> SessionReport:
        wall = self.wall_seconds if self.closed or self.wall_start is None else (
            time.monotonic() - self.wall_start)
        return SessionReport(
            frames=self.frame_index, rendered=self.rendered, dropped=self.dropped, fps=self.fps,
            wall_seconds=wall, stages=self.clock.summary(), events=list(self.events),
            performers={p.name: {"status": p.status, "message": p.problem or p.feed.message,
                                 "frames": p.feed.frames,
                                 "latency": getattr(p.feed, "latency", None),
                                 "actions_seen": sorted(p.seen),
                                 "outliers": p.outliers} for p in self.performers},
            mode=self.mode_label, pictures=self.worker is not None,
            late_frames=self.late_frames, max_late=self.max_late, slipped=self.slipped,
            slips=self.slips, warmup_seconds=self.warmup_seconds)
