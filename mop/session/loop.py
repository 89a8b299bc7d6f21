"""The session loop: one clock steps every performer, character and output.

Per frame (session time t = frame / fps):

1. capture   each performer's feed gives its newest values without blocking;
2. follow    the performer's follower bank steps on the selected, normalised values;
3. simulate  every character's tracks turn (action, progress) into targets — the motion sampled
             at progress x duration, cross-faded over `blend` seconds when the action changes,
             relaxing to rest when there is none — and the puppet steps by 1 / fps;
4. render    each character draws its layer and the stage composes them;
5. output    video, PNG, OSC, preview.

Live mode keeps real time: a frame that starts more than one period late skips render (the
outputs repeat the last picture) and frames further behind are skipped whole; replay mode runs as
fast as it can on the session clock, so the same takes give the same frames.
"""
from __future__ import annotations

import enum
import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .feeds import ENDED, OK
from .timing import SessionReport, StageClock

log = logging.getLogger(__name__)


class Mode(str, enum.Enum):
    LIVE = "live"       # wall clock; render frames are dropped rather than falling behind
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


class PerformerRuntime:
    """One performer: feed -> channel selection -> normalisation -> follower bank.

    channels : the D channel names the bank expects, picked by name from the feed's channels
    (empty = the feed's channels as they come); shift, scale : (D,) float, so the bank sees
    x = (values[selected] - shift) / scale."""

    def __init__(self, name: str, feed, bank, *, channels: Sequence[str] = (), shift=None,
                 scale=None, actions: Sequence[str] = ()):
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
        self.message = ""
        self.seen: set[str] = set()
        self.problem = ""            # why the input cannot be followed right now, if it cannot
        self._reported = ""
        self._feed_channels: tuple[str, ...] | None = None
        self._select: np.ndarray | None = None
        self._x = np.empty(len(self.channels))
        self._following = False
        self._last = None

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
        self._last = out
        state = self.state
        state.action = out.action
        state.progress = float(out.progress)
        state.variance = float(out.variance)
        state.log_likelihood = float(out.log_likelihood)
        state.fit = float(getattr(out, "fit", 0.0))
        if out.action is not None:
            self.seen.add(out.action)

    def posterior(self) -> dict[str, float]:
        """{action: probability} from the bank's last step (empty while not following)."""
        if not self._following:
            return {}
        return dict(getattr(self._last, "posterior", None) or {})


class Track:
    """One performer's hold on one character: which action plays which motion on which targets.

    motions : {action: (Motion, ((motion channel, target name), ...))}
    rest : {target: (c,) float} the values a target relaxes towards before it is let go."""

    def __init__(self, performer: str, motions: Mapping[str, tuple[Any, tuple]],
                 rest: Mapping[str, np.ndarray], *, blend: float):
        self.performer = performer
        self.motions = dict(motions)
        self.rest = {k: float(np.ravel(v)[0]) if np.size(v) == 1 else np.asarray(v, float)
                     for k, v in rest.items()}
        self.blend = float(blend)
        self.current: str | None = None
        self.progress = 0.0
        self.weight = 1.0
        self.blend_from: dict[str, np.ndarray] = {}
        self.blend_start = -math.inf
        self.last: dict[str, np.ndarray] = {}

    @property
    def targets(self) -> set[str]:
        return {target for _, channels in self.motions.values() for _, target in channels}

    def reset(self) -> None:
        self.current = None
        self.blend_from = {}
        self.last = {}
        self.blend_start = -math.inf

    def update(self, t: float, state: FollowState, out: dict) -> None:
        """Write this track's targets for session time t [s] into `out` {target: float or (c,)
        float} (one-component channels as floats)."""
        active = state.action if state.action in self.motions else None
        if active != self.current:
            self.blend_from = self.last
            self.blend_start = t
            self.current = active
        weight = 1.0 if self.blend <= 0 else smoothstep((t - self.blend_start) / self.blend)
        self.weight = weight
        goal: dict[str, np.ndarray] = {}
        if active is None:
            self.progress = 0.0
        else:
            motion, channels = self.motions[active]
            self.progress = min(max(state.progress, 0.0), 1.0)
            sample = motion.sample(self.progress * motion.duration)
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


class Session:
    """Performers x characters x outputs on one clock. Build one with `mop.session.build`;
    this class only runs what it is given.

    performers : PerformerRuntime; characters : CharacterRuntime (drawn in this order);
    stage : mop.render.compose.Stage or None (no rendering); outputs : objects with
    `write(frame (H, W, 4) uint8 | None, state: dict, *, repeat: bool)` and `close()`."""

    def __init__(self, performers: Sequence[PerformerRuntime],
                 characters: Sequence[CharacterRuntime], *, fps: int = 25,
                 mode: Mode | str = Mode.REPLAY, stage=None, outputs: Sequence = (),
                 tail: float = 0.0, name: str = "session"):
        self.name = name
        self.performers = list(performers)
        self.characters = list(characters)
        self.fps = int(fps)
        self.dt = 1.0 / self.fps
        self.mode = Mode(mode)
        self.stage = stage
        self.outputs = list(outputs)
        self.tail = float(tail)
        self.frame_index = 0
        self.t = 0.0
        self.clock = StageClock()
        self.rendered = 0
        self.dropped = 0
        self.events: list[dict] = []
        self.frame: np.ndarray | None = None
        self.ended_at: float | None = None
        self.wall_start: float | None = None
        self.wall_seconds = 0.0
        self.closed = False
        self.stop_requested = False
        self._by_name = {p.name: p for p in self.performers}

    # one frame ---------------------------------------------------------------------------
    def step(self, *, render: bool = True) -> None:
        """Advance one frame at session time `self.t`."""
        t = self.t
        clock = time.perf_counter
        start = clock()
        for performer in self.performers:
            performer.values = performer.feed.poll(t)
            status = performer.feed.status
            if status != performer.status:
                message = performer.feed.message
                self._event(performer, status, message)
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
        for character in self.characters:
            targets = character.targets
            targets.clear()
            for track in character.tracks:
                track.update(t, self._by_name[track.performer].state, targets)
            character.puppet.step(self.dt, targets)
        simulated = clock()
        rendered = simulated
        frame = None
        if render and self.stage is not None:
            self.stage.clear()
            for character in self.characters:
                self.stage.place(character.renderer.render(character.puppet), character.position)
            frame = self.stage.frame
            self.frame = frame
            self.rendered += 1
            rendered = clock()
        elif self.stage is not None:
            self.dropped += 1
        if self.outputs:
            state = self.state()
            for output in self.outputs:
                output.write(frame if frame is not None else self.frame, state,
                             repeat=frame is None)
        done = clock()
        add = self.clock.add
        add("capture", 1e3 * (captured - start))
        add("follow", 1e3 * (followed - captured))
        add("simulate", 1e3 * (simulated - followed))
        if frame is not None:
            add("render", 1e3 * (rendered - simulated))
        add("output", 1e3 * (done - rendered))
        add("total", 1e3 * (done - start))
        add("input_to_pose", 1e3 * (simulated - start))
        add("input_to_output", 1e3 * (done - start))
        self.frame_index += 1
        self.t = self.frame_index * self.dt

    def _event(self, performer: PerformerRuntime, status: str, message: str) -> None:
        """Note a change of a performer's input status (shown in the report and the preview)."""
        if status == OK:
            text = f"back (was {performer.status})" if performer.was_ok else "receiving"
            performer.was_ok = True
        else:
            text = f"{status}: {message}" if message else status
        self.events.append({"t": self.t, "performer": performer.name, "status": status,
                            "message": text})
        if status not in (OK, ENDED):
            log.warning("performer %s %s at t=%.2f s", performer.name, text, self.t)

    # the whole show ----------------------------------------------------------------------
    def request_stop(self) -> None:
        """Ask the loop to stop after the current frame (safe from a signal handler)."""
        self.stop_requested = True

    @property
    def finished(self) -> bool:
        """True once every performer's take has ended (live sources never end) and the
        characters had `tail` seconds to settle."""
        if self.stop_requested:
            return True
        if not self.performers or any(p.feed.status != ENDED for p in self.performers):
            self.ended_at = None
            return False
        if self.ended_at is None:
            self.ended_at = self.t
        return self.t - self.ended_at >= self.tail

    def run(self, *, duration: float | None = None, progress=None) -> SessionReport:
        """Run until the takes end, `duration` [s] of session time passes, or Ctrl-C; the
        outputs are closed in every case. `progress(session)` is called once per frame."""
        self.wall_start = time.monotonic()
        try:
            if self.mode is Mode.REPLAY:
                while not self.finished and (duration is None or self.t < duration):
                    self.step()
                    if progress is not None:
                        progress(self)
            else:
                self._run_live(duration, progress)
        finally:
            self.wall_seconds = time.monotonic() - self.wall_start
            self.close()
        return self.report()

    def _run_live(self, duration, progress) -> None:
        period = self.dt
        start = time.monotonic()
        while not self.finished and (duration is None or self.t < duration):
            due = start + self.frame_index * period
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            late = time.monotonic() - due
            if late > 3 * period:
                # Far behind: skip whole frames so the show stays in real time.
                skipped = int(late / period) - 1
                self.dropped += skipped
                self.frame_index += skipped
                self.t = self.frame_index * self.dt
            self.step(render=late < period)
            if progress is not None:
                progress(self)

    def close(self) -> None:
        """Finalise every output (idempotent): a video stopped by Ctrl-C still plays."""
        if self.closed:
            return
        self.closed = True
        errors = []
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
    def state(self) -> dict:
        """Everything a viewer may want about now: performers, characters, timing."""
        return {
            "session": self.name, "frame": self.frame_index, "t": self.t,
            "mode": self.mode.value, "fps": self.fps,
            "performers": {p.name: {"status": "failed" if p.problem else p.status,
                                    "message": p.problem or p.feed.message,
                                    **p.state.as_dict(), "posterior": p.posterior()}
                           for p in self.performers},
            "characters": {c.name: {
                "tracks": [{"performer": tr.performer, "action": tr.current,
                            "progress": tr.progress, "blend": tr.weight}
                           for tr in c.tracks],
                "targets": {k: np.atleast_1d(v).tolist() for k, v in c.targets.items()}}
                for c in self.characters},
            "dropped": self.dropped, "rendered": self.rendered,
        }

    def report(self) -> SessionReport:
        wall = self.wall_seconds if self.closed or self.wall_start is None else (
            time.monotonic() - self.wall_start)
        return SessionReport(
            frames=self.frame_index, rendered=self.rendered, dropped=self.dropped, fps=self.fps,
            wall_seconds=wall, stages=self.clock.summary(), events=list(self.events),
            performers={p.name: {"status": p.status, "frames": p.feed.frames,
                                 "actions_seen": sorted(p.seen)} for p in self.performers})
