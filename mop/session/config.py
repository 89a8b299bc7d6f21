"""Session files: performers, characters, actions and outputs, parsed once into frozen objects.

A session file is TOML. Its tables overlay the defaults shipped in `defaults.toml` beside this
module: `[session]` and `[outputs]` key by key, and each `[performers.NAME]`,
`[characters.NAME]` and `[[actions]]` entry is completed from `[performer_defaults]`,
`[character_defaults]` and `[action_defaults]`. Every error names the file, the key and what was
expected, e.g. ``demo.toml: characters.frog.kind: expected one of 'image', 'latex', 'medial',
got 'lattex'``.

Example::

    [session]
    fps = 25
    takes = "../recordings/demo_takes.sqlite"

    [performers.left]
    source = "replay:left_performance"      # any capture spec; replay:TAKE reads the take store
    channels = ["thumb", "index", "middle", "ring", "pinky"]

    [characters.frog]
    kind = "latex"
    asset = "froggy"                         # a shipped asset name or a path
    position = [0.25, 0.55]

    [[actions]]
    take = "frog_open"                       # a take in the store: its action trains the follower
    # takes = ["frog_open", "frog_open_2"]   # or several takes of it: the follower learns all
    performer = "left"                       # whose action it is
    character = "frog"                       # whose motion it drives
"""
from __future__ import annotations

import enum
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from characters.sidecar import read_toml
from mop.export import parse_background

DEFAULTS_PATH = Path(__file__).with_name("defaults.toml")
FRAME_RATES = (25, 30, 50, 60)
REPLAY_PREFIX = "replay:"   # a performer source that replays a take of the session's store
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
_COLOUR = re.compile(r"^#[0-9a-fA-F]{6}$")


class CharacterKind(str, enum.Enum):
    """The puppet kinds a session file may name: one per package under `characters/`, each with
    a builder registered in `mop.session.puppets` (tests/test_puppet_kinds.py checks both)."""
    IMAGE = "image"
    LATEX = "latex"
    MEDIAL = "medial"


class Normalise(str, enum.Enum):
    """How a performer's channels are scaled before the follower sees them. The statistics come
    from that performer's templates, so live input and templates are scaled alike."""
    NONE = "none"
    ZSCORE = "zscore"   # (x - mean) / std per channel
    RANGE = "range"     # (x - min) / (max - min) per channel


class Background(str, enum.Enum):
    COLOUR = "colour"
    CHROMA = "chroma"
    TRANSPARENT = "transparent"


@dataclass(frozen=True)
class PerformerConfig:
    """One performer: where their input comes from and how it is prepared for the followers.

    `channels` selects source channels by name (empty = all, in the source's order)."""
    name: str
    source: str
    channels: tuple[str, ...] = ()
    normalise: Normalise = Normalise.ZSCORE
    sigma: float | None = None
    window: int | None = None
    stale_after: float = 0.5
    latency: float = 0.05
    still_after: float = 0.4
    calibration: str | None = None
    calibration_reference: str | None = None


@dataclass(frozen=True)
class CharacterConfig:
    """One character on stage. `position` is its centre as fractions of the frame's (width,
    height); `scale` its height as a fraction of the frame height."""
    name: str
    kind: CharacterKind
    asset: str
    material: str | None = None
    position: tuple[float, float] = (0.5, 0.5)
    scale: float = 0.8
    colour: tuple[int, int, int] | None = None
    options: Mapping[str, Any] = field(default_factory=dict)


class After(str, enum.Enum):
    """What a character does when its action ends and nothing else drives it."""
    REST = "rest"    # blend back to the rest pose over the session's `blend` time
    HOLD = "hold"    # keep the end pose
    LOOP = "loop"    # keep playing the motion, from where it was, at its own speed


@dataclass(frozen=True)
class ActionBinding:
    """A take whose action (performed by `performer`) plays its motion on `character`.

    `name` is the action's name (shown in the preview, sent over OSC; default the take's name);
    `channels` maps motion channel -> the character's target name (empty = every channel of the
    take's motion under its own name); `after` says what the character does when the action
    ends; `takes` are several takes of the action (its follower learns from them all, and
    `take`, the one whose motion plays, is the first of them unless given)."""
    take: str
    performer: str
    character: str
    channels: tuple[tuple[str, str], ...] = ()
    name: str = ""
    after: After = After.REST
    takes: tuple[str, ...] = ()

    @property
    def action(self) -> str:
        return self.name or self.take

    @property
    def demonstrations(self) -> tuple[str, ...]:
        """The takes the action's follower learns from (`takes`, or `take` alone)."""
        return self.takes or (self.take,)


@dataclass(frozen=True)
class OutputsConfig:
    video: str | None = None
    png: str | None = None
    osc: tuple[str, int] | None = None
    preview: int | None = None
    preview_host: str = "127.0.0.1"


@dataclass(frozen=True)
class SessionConfig:
    """A whole session, parsed and checked. Paths are absolute (resolved against the file)."""
    path: Path | None
    name: str
    fps: int
    blend: float
    size: tuple[int, int]
    background: Background
    background_colour: tuple[int, int, int]
    chroma_key: tuple[int, int, int]
    takes: Path
    performers: tuple[PerformerConfig, ...]
    characters: tuple[CharacterConfig, ...]
    actions: tuple[ActionBinding, ...]
    outputs: OutputsConfig

    def performer(self, name: str) -> PerformerConfig:
        for performer in self.performers:
            if performer.name == name:
                return performer
        raise KeyError(name)

    def character(self, name: str) -> CharacterConfig:
        for character in self.characters:
            if character.name == name:
                return character
        raise KeyError(name)

    def actions_of(self, performer: str) -> tuple[ActionBinding, ...]:
        return tuple(a for a in self.actions if a.performer == performer)


class SessionError(ValueError):
    """A session file that cannot be used; the message names the file and the key."""


# --------------------------------------------------------------------------------------------
# parsing


class _Reader:
    """Typed access to one TOML table, with errors that name the file and the dotted key."""

    def __init__(self, where: str, table: Mapping[str, Any], prefix: str):
        self.where = where
        self.table = table
        self.prefix = prefix

    def key(self, name: str) -> str:
        return f"{self.prefix}.{name}" if self.prefix else name

    def fail(self, name: str, expected: str, got: Any = ...) -> SessionError:
        got_text = "" if got is ... else f", got {got!r}"
        return SessionError(f"{self.where}: {self.key(name)}: expected {expected}{got_text}")

    def check_keys(self, allowed) -> None:
        for name in self.table:
            if name not in allowed:
                raise SessionError(
                    f"{self.where}: {self.key(name)}: unknown key; expected one of "
                    f"{', '.join(sorted(allowed))}")

    def raw(self, name: str, required: bool = False):
        if name not in self.table:
            if required:
                raise self.fail(name, "a value (the key is required)")
            return None
        return self.table[name]

    def string(self, name: str, *, required: bool = False,
               empty_is_none: bool = True) -> str | None:
        value = self.raw(name, required)
        if value is None:
            return None
        if not isinstance(value, str):
            raise self.fail(name, "a string", value)
        if empty_is_none and value == "":
            if required:
                raise self.fail(name, "a non-empty string", value)
            return None
        return value

    def number(self, name: str, *, low: float = -math.inf, high: float = math.inf,
               integer: bool = False, required: bool = False) -> float | int | None:
        value = self.raw(name, required)
        if value is None:
            return None
        kind = "an integer" if integer else "a number"
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (
                integer and not isinstance(value, int)):
            raise self.fail(name, kind, value)
        if not (low <= value <= high) or (isinstance(value, float) and not math.isfinite(value)):
            raise self.fail(name, f"{kind} in [{low:g}, {high:g}]", value)
        return value

    def numbers(self, name: str, count: int, *, low=-math.inf, high=math.inf,
                integer=False) -> tuple | None:
        value = self.raw(name)
        if value is None:
            return None
        kind = "integers" if integer else "numbers"
        if (not isinstance(value, list) or len(value) != count or any(
                isinstance(v, bool) or not isinstance(v, (int, float))
                or (integer and not isinstance(v, int)) or not (low <= v <= high) for v in value)):
            raise self.fail(name, f"a list of {count} {kind} in [{low:g}, {high:g}]", value)
        return tuple(value)

    def names(self, name: str) -> tuple[str, ...]:
        value = self.raw(name)
        if value is None:
            return ()
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.fail(name, "a list of channel names", value)
        if len(set(value)) != len(value):
            raise self.fail(name, "channel names without repeats", value)
        return tuple(value)

    def choice(self, name: str, enum_type) -> Any:
        value = self.raw(name)
        options = [member.value for member in enum_type]
        if value not in options:
            raise self.fail(name, "one of " + ", ".join(repr(o) for o in options), value)
        return enum_type(value)

    def colour(self, name: str, *, allow_empty: bool = True) -> tuple[int, int, int] | None:
        value = self.raw(name)
        if value is None or (allow_empty and value == ""):
            return None
        if not isinstance(value, str) or not _COLOUR.match(value):
            raise self.fail(name, "a colour '#rrggbb'", value)
        return parse_background(value)

    def sub(self, name: str) -> "_Reader":
        value = self.raw(name)
        if value is None:
            value = {}
        if not isinstance(value, Mapping):
            raise self.fail(name, "a table", value)
        return _Reader(self.where, value, self.key(name))


def _merge(defaults: Mapping[str, Any], user: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(defaults)
    merged.update(user)
    return merged


def parse_host_port(text: str, *, where: str = "", key: str = "") -> tuple[str, int]:
    """'host:port' -> (host, port); the error names `where` and `key` when given."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        label = f"{where}: {key}: " if where or key else ""
        raise SessionError(f"{label}expected 'host:port' with a port in 1..65535, got {text!r}")
    return host, int(port)


def load_session(path: str | Path) -> SessionConfig:
    """Read a session file and the shipped defaults into one frozen `SessionConfig`."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"session file not found: {path}")
    try:
        user = read_toml(path, "session file")
    except ValueError as error:
        raise SessionError(str(error)) from None
    return parse_session(user, where=str(path), base=path.resolve().parent, path=path.resolve())


def parse_session(user: Mapping[str, Any], *, where: str = "<session>",
                  base: Path | None = None, path: Path | None = None) -> SessionConfig:
    """Overlay a session table (as read from TOML) on the defaults and check every key."""
    with open(DEFAULTS_PATH, "rb") as handle:
        defaults = tomllib.load(handle)
    base = Path.cwd() if base is None else base
    top = _Reader(where, user, "")
    top.check_keys({"session", "performers", "characters", "actions", "outputs"})
    stage = _parse_stage(top, defaults, base, path)
    performers = _parse_performers(top, defaults, base)
    characters = _parse_characters(top, defaults, base)
    actions = _parse_actions(top, defaults, performers, characters)
    return SessionConfig(
        path=path, **stage, performers=tuple(performers), characters=tuple(characters),
        actions=tuple(actions), outputs=_parse_outputs(top, defaults, base))


def _parse_stage(top: _Reader, defaults: dict, base: Path, path: Path | None) -> dict:
    """The [session] table: name, rate, blend, size, background, takes."""
    where = top.where
    session = _Reader(where, _merge(defaults["session"], top.sub("session").table), "session")
    session.check_keys(set(defaults["session"]) | {"name"})
    fps = session.number("fps", integer=True)
    if fps not in FRAME_RATES:
        raise session.fail("fps", "one of " + ", ".join(map(str, FRAME_RATES)), fps)
    blend = float(session.number("blend", low=0.0, high=10.0))
    size = session.numbers("size", 2, low=16, high=8192, integer=True)
    if size is None or size[0] % 2 or size[1] % 2:
        raise session.fail("size", "[width, height] in even pixels (video codecs need them)",
                           session.raw("size"))
    background_text = session.string("background", empty_is_none=False)
    chroma_key = session.colour("chroma_key", allow_empty=False)
    if background_text == "chroma":
        background, background_colour = Background.CHROMA, chroma_key
    elif background_text == "transparent":
        background, background_colour = Background.TRANSPARENT, (0, 0, 0)
    else:
        colour = session.colour("background", allow_empty=False) if background_text else None
        if colour is None:
            raise session.fail("background", "'#rrggbb', 'chroma' or 'transparent'",
                               background_text)
        background, background_colour = Background.COLOUR, colour
    takes = (base / session.string("takes", required=True)).resolve()
    name = session.string("name") or (path.stem if path else "session")

    return dict(name=name, fps=fps, blend=blend, size=size, background=background,
                background_colour=background_colour, chroma_key=chroma_key, takes=takes)


def _parse_performers(top: _Reader, defaults: dict, base: Path) -> list[PerformerConfig]:
    where = top.where
    performers = []
    table = top.sub("performers")
    if not table.table:
        raise top.fail("performers", "at least one [performers.NAME] table")
    for performer_name in table.table:
        if not _NAME.match(performer_name):
            raise table.fail(performer_name, "a name of letters, digits, '_' or '-'",
                             performer_name)
        entry = _Reader(where, _merge(defaults["performer_defaults"],
                                      table.sub(performer_name).table),
                        f"performers.{performer_name}")
        entry.check_keys(set(defaults["performer_defaults"]) | {"source"})
        source = entry.string("source", required=True)
        sigma = entry.number("sigma", low=0.0)
        window = entry.number("window", low=0, integer=True)
        performers.append(PerformerConfig(
            name=performer_name,
            source=resolve_source(source, base),
            channels=entry.names("channels"),
            normalise=entry.choice("normalise", Normalise),
            sigma=float(sigma) if sigma else None,
            window=int(window) if window else None,
            stale_after=float(entry.number("stale_after", low=0.01, high=60.0)),
            latency=float(entry.number("latency", low=0.0, high=1.0)),
            still_after=float(entry.number("still_after", low=0.0, high=60.0)),
            calibration=entry.string("calibration"),
            calibration_reference=entry.string("calibration_reference")))

    return performers


def _parse_characters(top: _Reader, defaults: dict, base: Path) -> list[CharacterConfig]:
    where = top.where
    characters = []
    table = top.sub("characters")
    if not table.table:
        raise top.fail("characters", "at least one [characters.NAME] table")
    for character_name in table.table:
        if not _NAME.match(character_name):
            raise table.fail(character_name, "a name of letters, digits, '_' or '-'",
                             character_name)
        entry = _Reader(where, _merge(defaults["character_defaults"],
                                      table.sub(character_name).table),
                        f"characters.{character_name}")
        entry.check_keys(set(defaults["character_defaults"]) | {"kind", "asset", "options"})
        if "kind" not in entry.table:
            raise entry.fail("kind", "one of 'image', 'latex', 'medial' (the key is required)")
        kind = entry.choice("kind", CharacterKind)
        asset = entry.string("asset", required=True)
        asset_path = base / asset
        if asset_path.exists():
            asset = str(asset_path.resolve())
        options = entry.sub("options").table
        characters.append(CharacterConfig(
            name=character_name, kind=kind, asset=asset,
            material=entry.string("material"),
            position=entry.numbers("position", 2, low=-1.0, high=2.0),
            scale=float(entry.number("scale", low=0.01, high=4.0)),
            colour=entry.colour("colour"),
            options=MappingProxyType(dict(options))))

    return characters


def _parse_actions(top: _Reader, defaults: dict, performers, characters) -> list[ActionBinding]:
    where = top.where
    performer_names = [p.name for p in performers]
    character_names = [c.name for c in characters]
    actions = []
    raw_actions = top.raw("actions")
    if not isinstance(raw_actions, list) or not raw_actions:
        raise top.fail("actions", "at least one [[actions]] table", raw_actions)
    for index, raw in enumerate(raw_actions):
        if not isinstance(raw, Mapping):
            raise top.fail(f"actions[{index}]", "a table", raw)
        entry = _Reader(where, _merge(defaults["action_defaults"], raw), f"actions[{index}]")
        entry.check_keys(set(defaults["action_defaults"])
                         | {"take", "takes", "performer", "character", "name"})
        several = entry.raw("takes")
        if several is not None and (
                not isinstance(several, list) or not several
                or not all(isinstance(v, str) and v for v in several)
                or len(set(several)) != len(several)):
            raise entry.fail("takes", "a list of take names without repeats", several)
        several = tuple(several or ())
        take = entry.string("take", required=not several) or several[0]
        action_name = entry.string("name") or ""
        performer_name = entry.string("performer", required=True)
        if performer_name not in performer_names:
            raise entry.fail("performer", "one of the performers " + ", ".join(
                map(repr, performer_names)), performer_name)
        character_name = entry.string("character", required=True)
        if character_name not in character_names:
            raise entry.fail("character", "one of the characters " + ", ".join(
                map(repr, character_names)), character_name)
        raw_channels = entry.raw("channels")
        if isinstance(raw_channels, Mapping):
            if not all(isinstance(k, str) and isinstance(v, str) and v
                       for k, v in raw_channels.items()):
                raise entry.fail("channels", "a table of motion channel = \"target name\"",
                                 raw_channels)
            channels = tuple(raw_channels.items())
        else:
            channels = tuple((name, name) for name in entry.names("channels"))
        actions.append(ActionBinding(take=take, performer=performer_name,
                                     character=character_name, channels=channels,
                                     name=action_name, after=entry.choice("after", After),
                                     takes=several))
    _check_bindings(where, actions)

    return actions


def _parse_outputs(top: _Reader, defaults: dict, base: Path) -> OutputsConfig:
    where = top.where
    outputs = _Reader(where, _merge(defaults["outputs"], top.sub("outputs").table), "outputs")
    outputs.check_keys(set(defaults["outputs"]))
    osc_text = outputs.string("osc")
    preview = outputs.number("preview", low=0, high=65535, integer=True)
    video = outputs.string("video")
    png = outputs.string("png")
    config_outputs = OutputsConfig(
        video=str((base / video).resolve()) if video else None,
        png=str((base / png).resolve()) if png else None,
        osc=parse_host_port(osc_text, where=where, key="outputs.osc") if osc_text else None,
        preview=preview or None,
        preview_host=outputs.string("preview_host", required=True))
    if video and Path(video).suffix.lower() not in (".mp4", ".mkv", ".gif", ".avi", ".webm"):
        raise outputs.fail("video", "a path ending in .mp4, .mkv, .gif, .avi or .webm", video)

    return config_outputs


def resolve_source(spec: str, base: Path) -> str:
    """A source spec naming a file by a relative path (camera:clip.mp4[:tracker],
    hid:profiles/glove.toml[@device]) made absolute against the session file's folder, as assets
    and takes are; anything else as given (a camera index, a profile name, a network address)."""
    kind, sep, rest = spec.partition(":")
    if not sep or kind not in ("camera", "hid") or not rest:
        return spec
    body, mark, query = rest.partition("?")
    if kind == "camera":
        head, colon, tail = body.rpartition(":")
        device, suffix = (head, colon + tail) if colon and tail.isalpha() else (body, "")
        if not device or device.isdigit():
            return spec
    else:
        device, at, selector = body.partition("@")
        suffix = at + selector
        if not (device.endswith(".toml") or "/" in device):
            return spec                    # a shipped profile's name
    if Path(device).is_absolute():
        return spec
    return f"{kind}:{(base / device).resolve()}{suffix}{mark}{query}"


def _check_bindings(where: str, actions: list[ActionBinding]) -> None:
    """Several performers may drive one character, each on its own channels: two performers
    writing the same target of one character would fight, so that is refused. An action's
    name stands for one take of its performer, and a take has one name."""
    named: dict[tuple[str, str], tuple[str, int]] = {}
    taken: dict[tuple[str, str], tuple[str, int]] = {}
    for index, action in enumerate(actions):
        by_name = named.setdefault((action.performer, action.action), (action.take, index))
        if by_name[0] != action.take:
            raise SessionError(
                f"{where}: actions[{index}].name: performer {action.performer!r} already has an "
                f"action {action.action!r} from take {by_name[0]!r} (actions[{by_name[1]}]); "
                f"expected one take per action name")
        by_take = taken.setdefault((action.performer, action.take), (action.action, index))
        if by_take[0] != action.action:
            raise SessionError(
                f"{where}: actions[{index}].name: take {action.take!r} of performer "
                f"{action.performer!r} is already named {by_take[0]!r} (actions[{by_take[1]}]); "
                f"expected one name per take")
    owner: dict[tuple[str, str], tuple[str, int]] = {}
    for index, action in enumerate(actions):
        for _, target in action.channels:
            key = (action.character, target)
            previous = owner.get(key)
            if previous is not None and previous[0] != action.performer:
                raise SessionError(
                    f"{where}: actions[{index}].channels: target {target!r} of character "
                    f"{action.character!r} is already driven by performer {previous[0]!r} "
                    f"(actions[{previous[1]}]); expected each performer on its own channels")
            owner.setdefault(key, (action.performer, index))
