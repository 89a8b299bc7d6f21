"""From a `SessionConfig` to a running `Session`: takes, followers, puppets, renderers, outputs.

This is the one place that composes `capture`, `followers` and `characters`; everything the loop
needs is built here, once, before the first frame.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .config import (REPLAY_PREFIX, Background, CharacterConfig, Normalise, PerformerConfig,
                     SessionConfig, SessionError)
from .feeds import SourceFeed, TakeFeed
from .loop import CharacterRuntime, Mode, PerformerRuntime, Session, Track

log = logging.getLogger(__name__)



@dataclass
class Overrides:
    """What the command line may change without editing the session file."""
    replay: Mapping[str, str] = field(default_factory=dict)   # performer -> take name or spec
    video: str | None = None
    png: str | None = None
    osc: tuple[str, int] | None = None
    preview: int | None = None
    preview_host: str | None = None
    loop_takes: bool = False
    render: bool = True
    transparent: bool = False     # draw on a transparent background whatever the file says


# --------------------------------------------------------------------------------------------
# takes


@dataclass(frozen=True)
class TakeData:
    """The parts of a take the session uses.

    times : (K,) float [s]; values : (K, D) float (raw, NaN = missing); channels : D names;
    motion : characters.Motion | None; take : the mop.takes.Take itself."""
    name: str
    times: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    motion: Any
    take: Any = None

    def template(self, fps: float) -> np.ndarray:
        """The action aligned to its motion's duration (MOP 3.1.3) and sampled at `fps`:
        (T, D) float; without alignment metadata the whole recording maps onto the motion."""
        if self.take is not None:
            return self.take.aligned(fps)[1]
        return resample(self.times, self.values, fps)


def open_store(path: Path):
    """The session's take store (a `mop.takes.TakeStore` folder)."""
    from mop.takes import TakeStore
    if not Path(path).is_dir():
        raise FileNotFoundError(f"take folder not found: {path}")
    return TakeStore(path, create=False)


def take_data(store, name: str, *, where: str = "") -> TakeData:
    """Read one take's action stream and motion from the store."""
    try:
        take = store.load(name)
    except KeyError:
        names = store.names()
        raise SessionError(f"{where}take {name!r} is not in {store.path}; it has "
                           f"{', '.join(names) or 'no takes'}") from None
    return TakeData(name=name, times=np.asarray(take.times, dtype=np.float64),
                    values=np.asarray(take.values, dtype=np.float64),
                    channels=tuple(take.channels), motion=take.motion, take=take)


def resample(times: np.ndarray, values: np.ndarray, fps: float) -> np.ndarray:
    """A stream resampled at `fps`, linearly: (round(duration * fps) + 1, D). NaN stays NaN
    around missing samples only where np.interp carries it."""
    times = times - times[0]
    count = int(round(times[-1] * fps)) + 1
    grid = np.arange(count) / fps
    out = np.empty((count, values.shape[1]))
    for column in range(values.shape[1]):
        out[:, column] = np.interp(grid, times, values[:, column])
    return out


# --------------------------------------------------------------------------------------------
# followers


def normalisation(templates: list[np.ndarray], how: Normalise) -> tuple[np.ndarray, np.ndarray]:
    """(shift (D,), scale (D,)) so that (x - shift) / scale is what `how` asks, fitted on every
    template of one performer together (followers.preprocessing.fit_normaliser)."""
    if how is Normalise.NONE:
        width = templates[0].shape[1]
        return np.zeros(width), np.ones(width)
    from followers.preprocessing import fit_normaliser
    normaliser = fit_normaliser(list(templates), how=how.value)
    return np.asarray(normaliser.shift, dtype=np.float64), np.asarray(normaliser.scale,
                                                                      dtype=np.float64)


def performer_templates(config: SessionConfig, performer: PerformerConfig,
                        takes: Mapping[str, TakeData], *, where: str):
    """{action name: (T, D) normalised template, or a list of them for an action of several
    takes}, channel names, shift, scale for one performer.

    Each template is its take's action, aligned to the motion and sampled at the session rate:
    the bank then steps once per session frame."""
    actions = config.actions_of(performer.name)
    if not actions:
        raise SessionError(f"{where}: performers.{performer.name}: no [[actions]] name this "
                           f"performer; expected at least one")
    raw: dict[str, list[np.ndarray]] = {}
    channels = performer.channels
    for action in actions:
        if action.action in raw:
            continue
        raw[action.action] = []
        for name in action.demonstrations:
            data = takes[name]
            wanted = channels or data.channels
            missing = [c for c in wanted if c not in data.channels]
            if missing:
                key = "channels" if performer.channels else "source"
                raise SessionError(
                    f"{where}: performers.{performer.name}.{key}: take {name!r} has no "
                    f"channel {missing[0]!r}; it has {', '.join(data.channels)}")
            if not channels:
                channels = data.channels
            index = [data.channels.index(c) for c in channels]
            raw[action.action].append(data.template(config.fps)[:, index])
    shift, scale = normalisation([v for values in raw.values() for v in values],
                                 performer.normalise)
    templates = {name: [(v - shift) / scale for v in values] if len(values) > 1
                 else (values[0] - shift) / scale for name, values in raw.items()}
    return templates, tuple(channels), shift, scale


def performer_calibration(config: SessionConfig, performer: PerformerConfig, store,
                          channels: tuple[str, ...], *, where: str):
    """The `followers.calibration.ChannelMap` from the performer's calibration take onto the
    author's (the reference: `calibration_reference`, or the newest calibration take of the
    performer who recorded the performer's first action take), or None when the performer
    names no calibration take."""
    if performer.calibration is None:
        return None
    from followers.calibration import calibrate
    from mop.takes import TakeError, calibration_of, newest_calibration
    key = f"{where}: performers.{performer.name}."
    reference = performer.calibration_reference
    if reference is None:
        first = config.actions_of(performer.name)[0].demonstrations[0]
        author = store.load(first).performer
        reference = newest_calibration(store, author, channels)
        if reference is None:
            raise SessionError(f"{key}calibration: the author {author!r} (who recorded take "
                               f"{first!r}) has no calibration take with channels "
                               f"{', '.join(channels)} to map onto; record one with `mop "
                               f"record --calibrate --performer {author} --source ...` or name "
                               f"it in calibration_reference")
    measured = {}
    for field_name, name in (("calibration", performer.calibration),
                             ("calibration_reference", reference)):
        try:
            measured[field_name] = calibration_of(store.load(name), channels)
        except (TakeError, KeyError, OSError) as error:
            raise SessionError(f"{key}{field_name}: {error}") from None
    return calibrate(measured["calibration"], measured["calibration_reference"])


def build_bank(templates: Mapping[str, np.ndarray], performer: PerformerConfig,
               fps: float | None = None):
    """The performer's bank; with ``fps``, input still for the performer's ``still_after``
    is no action (``BankConfig.still_frames``)."""
    from followers import BankConfig, FollowerBank
    options = {}
    if fps is not None:
        options["config"] = BankConfig(still_frames=int(round(performer.still_after * fps)))
    if performer.sigma is not None:
        options["sigma"] = performer.sigma
    if performer.window is not None:
        options["window"] = performer.window
    return FollowerBank(dict(templates), **options)


# --------------------------------------------------------------------------------------------
# characters


def build_character(character: CharacterConfig, *, frame_height: int):
    """(puppet, renderer) for one character of the session."""
    from . import puppets
    return puppets.build(character, frame_height=frame_height)


# --------------------------------------------------------------------------------------------
# the whole session


def session_takes(config: SessionConfig, store) -> dict[str, TakeData]:
    """{take name: TakeData} of every take the session's [[actions]] name."""
    where = str(config.path) if config.path else "<session>"
    takes: dict[str, TakeData] = {}
    for index, action in enumerate(config.actions):
        for name in (action.take, *action.takes):
            if name not in takes:
                key = "take" if name == action.take else "takes"
                takes[name] = take_data(store, name, where=f"{where}: actions[{index}].{key}: ")
    return takes


def build_characters(config: SessionConfig, takes: Mapping[str, TakeData], *,
                     characters: Mapping[str, tuple[Any, Any]] | None = None,
                     say: Callable[[str], None] = lambda text: None) -> list[CharacterRuntime]:
    """Every character with its tracks, each binding checked on the built puppet: its take
    has a motion, the motion has the channels, the character has the targets, and each target
    takes the motion's values (one puppet step per binding, then back to rest). `mop perform`
    and `mop train` check a session with this same function."""
    where = str(config.path) if config.path else "<session>"
    built = []
    for character in config.characters:
        if characters is not None and character.name in characters:
            puppet, renderer = characters[character.name]
        else:
            say(f"building {character.kind.value} character {character.name}")
            puppet, renderer = build_character(character, frame_height=config.size[1])
        try:
            tracks = _tracks(config, character, puppet, takes, where=where)
        except BaseException:
            close = getattr(renderer, "close", None)
            if close is not None:
                close()
            raise
        built.append(CharacterRuntime(character.name, puppet, renderer,
                                      position=character.position, tracks=tracks))
    return built


def build_session(config: SessionConfig, *, mode: Mode | str = Mode.REPLAY,
                  overrides: Overrides | None = None,
                  characters: Mapping[str, tuple[Any, Any]] | None = None,
                  store=None, source_opener: Callable[[str], Any] | None = None,
                  extra_outputs=(), progress: Callable[[str], None] | None = None) -> Session:
    """Build everything a session needs and return it, ready to `run()`.

    characters : {name: (puppet, renderer)} to use instead of building from the assets;
    store : a take store to use instead of opening `config.takes`;
    source_opener : spec -> capture source (default `capture.open_source`)."""
    overrides = overrides or Overrides()
    mode = Mode(mode)
    where = str(config.path) if config.path else "<session>"
    say = progress or (lambda text: None)
    store = open_store(config.takes) if store is None else store
    takes = session_takes(config, store)

    performers = []
    for performer in config.performers:
        say(f"training the followers of {performer.name}")
        templates, channels, shift, scale = performer_templates(config, performer, takes,
                                                                where=where)
        mapped = performer_calibration(config, performer, store, channels, where=where)
        if mapped is not None:
            # the performer's input onto the author's range and rest, inside the normalisation
            shift, scale = mapped.fold(shift, scale)
            for note in mapped.notes:
                say(f"calibration of {performer.name}: {note}")
        bank = build_bank(templates, performer, config.fps)
        spec = overrides.replay.get(performer.name, performer.source)
        feed = _feed(spec, performer, store, config, mode=mode, loop=overrides.loop_takes,
                     opener=source_opener, where=where)
        runtime = PerformerRuntime(performer.name, feed, bank, channels=channels, shift=shift,
                                   scale=scale, actions=tuple(templates),
                                   still_frames=int(round(performer.still_after * config.fps)))
        performers.append(runtime)

    built = build_characters(config, takes, characters=characters, say=say)

    stage = None
    if overrides.render:
        from mop.render.compose import Stage
        stage = Stage(config.size, None if _transparent(config, overrides)
                      else config.background_colour)

    outputs = _outputs(config, overrides)
    outputs.extend(extra_outputs)
    session = Session(performers, built, fps=config.fps, mode=mode, stage=stage,
                      outputs=outputs, tail=config.blend, name=config.name)
    for output in outputs:
        if hasattr(output, "session"):
            output.session = session
    return session


def _feed(spec: str, performer: PerformerConfig, store, config: SessionConfig, *, mode: Mode,
          loop: bool, opener, where: str):
    """replay:NAME (a take of the session's folder) or replay:PATH (a take file) is read on the
    session's own clock (deterministic, faster than real time in replay mode); any other spec
    is a live capture source."""
    if spec.startswith(REPLAY_PREFIX):
        name = spec[len(REPLAY_PREFIX):]
        key = f"{where}: performers.{performer.name}.source: "
        if name not in store:
            path = Path(name)
            if not path.is_absolute() and config.path is not None:
                path = config.path.parent / path
            folder, stem = path.parent, path.name.removesuffix(".sqlite")
            if folder.is_dir() and (folder / f"{stem}.sqlite").is_file():
                from mop.takes import TakeStore
                data = take_data(TakeStore(folder, create=False), stem, where=key)
                return TakeFeed(data.times, data.values, data.channels, name=stem, loop=loop)
        data = take_data(store, name, where=key)
        return TakeFeed(data.times, data.values, data.channels, name=name, loop=loop)
    if opener is None:
        from capture import open_source as opener
    if spec.startswith("osc:") and performer.channels and "channels=" not in spec:
        # an OSC stream's channels are the performer's: never learnt from a stranger's packet
        spec += ("&" if "?" in spec else "?") + "channels=" + ",".join(performer.channels)
    return SourceFeed(lambda: opener(spec), name=performer.name,
                      stale_after=performer.stale_after, latency=performer.latency,
                      period=1.0 / config.fps)


def _tracks(config: SessionConfig, character: CharacterConfig, puppet,
            takes: Mapping[str, TakeData], *, where: str) -> list[Track]:
    by_performer: dict[str, dict[str, tuple]] = {}
    after: dict[str, dict[str, str]] = {}
    rest: dict[str, dict[str, np.ndarray]] = {}
    owner: dict[str, tuple[str, int]] = {}
    target_names = set(getattr(puppet, "target_names", ()))
    for index, action in enumerate(config.actions):
        if action.character != character.name:
            continue
        key = f"{where}: actions[{index}]"
        motion = takes[action.take].motion
        if motion is None:
            raise SessionError(f"{key}.take: take {action.take!r} has no motion to play")
        channels = action.channels or tuple((c, c) for c in motion.channel_names)
        for channel, target in channels:
            if channel not in motion.channel_names:
                raise SessionError(f"{key}.channels: the motion of take {action.take!r} has no "
                                   f"channel {channel!r}; it has "
                                   f"{', '.join(motion.channel_names)}")
            if target_names and target not in target_names:
                raise SessionError(f"{key}.channels: character {character.name!r} has no target "
                                   f"{target!r}; expected one of "
                                   f"{', '.join(sorted(target_names))}")
            previous = owner.get(target)
            if previous is not None and previous[0] != action.performer:
                raise SessionError(
                    f"{key}.channels: target {target!r} of character {character.name!r} is "
                    f"already driven by performer {previous[0]!r} (actions[{previous[1]}]); "
                    f"expected each performer on its own channels")
            owner.setdefault(target, (action.performer, index))
        start = motion.sample(0.0)
        _try_targets(puppet, start, channels, dt=1.0 / config.fps,
                     what=f"{key}.channels: take {action.take!r}, character "
                          f"{character.name!r}")
        performer_rest = rest.setdefault(action.performer, {})
        for channel, target in channels:
            performer_rest.setdefault(target, start[channel])
        by_performer.setdefault(action.performer, {})[action.action] = (motion, tuple(channels))
        after.setdefault(action.performer, {})[action.action] = action.after
    return [Track(performer, motions, rest[performer], blend=config.blend,
                  after=after[performer])
            for performer, motions in by_performer.items()]


def _try_targets(puppet, sample: Mapping[str, np.ndarray], channels, *, dt: float,
                 what: str) -> None:
    """Step the puppet once per bound target with the motion's first values, then put it back
    at rest: a target that cannot take what the motion gives (a bend where a position is
    expected, say) is refused here, naming the binding, not in the middle of the show."""
    reset = getattr(puppet, "reset", None)
    if reset is None:
        return
    try:
        for channel, target in channels:
            value = np.asarray(sample[channel], dtype=np.float64)
            given = float(value[0]) if value.size == 1 else value
            try:
                puppet.step(dt, {target: given})
            except (ValueError, TypeError) as error:
                raise SessionError(f"{what}: motion channel {channel!r} gives {value.size} "
                                   f"value(s) per frame, which target {target!r} does not "
                                   f"take: {error}") from None
    finally:
        reset()


def _transparent(config: SessionConfig, overrides: Overrides) -> bool:
    return overrides.transparent or config.background is Background.TRANSPARENT


def _outputs(config: SessionConfig, overrides: Overrides) -> list:
    """Video and PNG writers (each in a thread of its own), OSC, the preview. PNG frames keep
    the alpha of a transparent stage; a video has none: it gets the session's colour behind the
    characters, or black when the file itself says transparent (a warning says so)."""
    from .outputs import VIDEO_SUFFIXES, BackgroundOutput, OscOutput, PngOutput, VideoOutput
    outputs = []
    transparent = _transparent(config, overrides)
    pngs = [overrides.png or config.outputs.png]
    video = overrides.video or config.outputs.video
    if video and Path(video).suffix.lower() not in VIDEO_SUFFIXES:
        pngs.insert(0, video)                  # --out FOLDER: a PNG sequence
        video = None
    if video:
        if config.background is Background.TRANSPARENT:
            log.warning("%s: the session's background is transparent and video has no alpha: "
                        "the characters are shown over black; write PNG frames (--png FOLDER) "
                        "to keep the alpha, or set [session] background to a colour", video)
            background = (0, 0, 0)
        else:
            background = config.background_colour
        outputs.append(BackgroundOutput(VideoOutput(video, fps=config.fps, size=config.size,
                                                    background=background)))
    for png in filter(None, pngs):
        outputs.append(BackgroundOutput(PngOutput(
            png, fps=config.fps, size=config.size,
            background=None if transparent else config.background_colour)))
    osc = overrides.osc or config.outputs.osc
    if osc:
        outputs.append(OscOutput(*osc))
    # --preview 0 asks for any free port; in a session file 0 means no preview
    preview = overrides.preview if overrides.preview is not None else config.outputs.preview
    if preview is not None:
        from .preview import PreviewOutput
        outputs.append(PreviewOutput(host=overrides.preview_host or config.outputs.preview_host,
                                     port=preview))
    return outputs
