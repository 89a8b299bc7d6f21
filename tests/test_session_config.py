"""Session files: defaults + overlay into frozen objects; every error names the file and key."""
import dataclasses
import textwrap

import pytest

from mop.session.config import (Background, CharacterKind, Normalise, SessionError,
                                load_session, parse_session)

GOOD = """
[session]
fps = 50
blend = 0.25
takes = "takes.sqlite"
background = "chroma"

[performers.left]
source = "replay:left_show"
channels = ["thumb", "index"]
normalise = "range"

[performers.right]
source = "osc:127.0.0.1:9000/hand"

[characters.frog]
kind = "latex"
asset = "froggy"
position = [0.25, 0.5]

[characters.cat]
kind = "image"
asset = "cat.png"
colour = "#ff8800"

[[actions]]
take = "open"
performer = "left"
character = "frog"

[[actions]]
take = "wave"
performer = "right"
character = "cat"
channels = { hand = "paw" }

[[actions]]
take = "nod"
performer = "left"
character = "cat"
channels = ["head"]

[outputs]
video = "out/show.mp4"
osc = "127.0.0.1:9100"
preview = 8765
"""


def write(tmp_path, text, name="show.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_good_file_is_parsed_into_frozen_typed_objects(tmp_path):
    config = load_session(write(tmp_path, GOOD))
    assert config.fps == 50 and config.blend == 0.25 and config.size == (960, 540)
    assert config.background is Background.CHROMA and config.background_colour == (0, 177, 64)
    assert config.takes == (tmp_path / "takes.sqlite").resolve()
    left, right = config.performers
    assert left.channels == ("thumb", "index") and left.normalise is Normalise.RANGE
    assert right.channels == () and right.normalise is Normalise.ZSCORE  # from the defaults
    frog, cat = config.characters
    assert frog.kind is CharacterKind.LATEX and frog.position == (0.25, 0.5)
    assert cat.position == (0.5, 0.5) and cat.colour == (255, 136, 0)
    assert config.actions[1].channels == (("hand", "paw"),)
    assert config.actions[2].channels == (("head", "head"),)
    assert [a.take for a in config.actions_of("left")] == ["open", "nod"]
    assert config.outputs.osc == ("127.0.0.1", 9100) and config.outputs.preview == 8765
    assert config.outputs.video == str((tmp_path / "out/show.mp4").resolve())
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.fps = 25
    with pytest.raises(TypeError):
        frog.options["x"] = 1


@pytest.mark.parametrize("old, new, key, expected", [
    ('fps = 50', 'fps = 24', "session.fps", "one of 25, 30, 50, 60"),
    ('fps = 50', 'fps = "50"', "session.fps", "an integer"),
    ('blend = 0.25', 'blend = -1.0', "session.blend", "a number in [0, 10]"),
    ('kind = "latex"', 'kind = "lattex"', "characters.frog.kind", "one of 'image', 'latex'"),
    ('position = [0.25, 0.5]', 'position = [0.25]', "characters.frog.position",
     "a list of 2 numbers"),
    ('colour = "#ff8800"', 'colour = "orange"', "characters.cat.colour", "a colour '#rrggbb'"),
    ('normalise = "range"', 'normalise = "minmax"', "performers.left.normalise",
     "one of 'none', 'zscore', 'range'"),
    ('channels = ["thumb", "index"]', 'channels = "thumb"', "performers.left.channels",
     "a list of channel names"),
    ('source = "osc:127.0.0.1:9000/hand"', 'sauce = "osc:x"', "performers.right.sauce",
     "unknown key"),
    ('performer = "right"', 'performer = "middle"', "actions[1].performer",
     "one of the performers 'left', 'right'"),
    ('character = "frog"', 'character = "toad"', "actions[0].character",
     "one of the characters"),
    ('osc = "127.0.0.1:9100"', 'osc = "localhost"', "outputs.osc", "'host:port'"),
    ('video = "out/show.mp4"', 'video = "out/show.mov"', "outputs.video", ".mp4, .mkv, .gif"),
    ('take = "open"', 'tak = "open"', "actions[0].tak", "unknown key"),
    ('channels = { hand = "paw" }', 'channels = ["head"]', "actions[2].channels",
     "already driven by performer 'right'"),
    ('channels = ["head"]', 'channels = ["head"]\nafter = "freeze"', "actions[2].after",
     "one of 'rest', 'hold', 'loop'"),
    ('take = "nod"', 'take = "nod"\nname = "open"', "actions[2].name",
     "already has an action 'open' from take 'open'"),
    ('source = "replay:left_show"', 'source = "replay:left_show"\nlatency = 2',
     "performers.left.latency", "a number in [0, 1]"),
])
def test_malformed_file_names_file_key_and_expectation(tmp_path, old, new, key, expected):
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(SessionError) as caught:
        load_session(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {key}")
    assert expected in message


def test_missing_required_keys_and_tables(tmp_path):
    without_kind = GOOD.replace('kind = "latex"\n', "")
    with pytest.raises(SessionError, match=r"characters\.frog\.kind: expected one of .*required"):
        load_session(write(tmp_path, without_kind))
    with pytest.raises(SessionError, match=r"performers: expected at least one"):
        parse_session({"session": {"takes": "x"}, "characters": {}, "actions": []})
    with pytest.raises(SessionError, match=r"^show.toml: actions: expected at least one"):
        parse_session({"performers": {"a": {"source": "replay:x"}},
                       "characters": {"c": {"kind": "image", "asset": "a.png"}}},
                      where="show.toml")


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(SessionError, match=r"show.toml: not valid TOML"):
        load_session(write(tmp_path, "[session\nfps = 25"))
    with pytest.raises(FileNotFoundError, match="session file not found"):
        load_session(tmp_path / "nowhere.toml")


def test_action_names_after_and_sources_beside_the_session_file(tmp_path):
    (tmp_path / "clips").mkdir()
    (tmp_path / "clips" / "hand.mkv").write_bytes(b"")
    (tmp_path / "glove.toml").write_bytes(b"")
    text = (GOOD.replace('source = "osc:127.0.0.1:9000/hand"',
                         'source = "camera:clips/hand.mkv:aruco?ids=3"')
            .replace('source = "replay:left_show"', 'source = "hid:glove.toml@/dev/hidraw3"')
            .replace('take = "wave"', 'take = "wave"\nname = "hello"\nafter = "hold"'))
    config = load_session(write(tmp_path, text))
    left, right = config.performers
    assert right.source == f"camera:{(tmp_path / 'clips' / 'hand.mkv').resolve()}:aruco?ids=3"
    assert left.source == f"hid:{(tmp_path / 'glove.toml').resolve()}@/dev/hidraw3"
    wave = config.actions[1]
    assert wave.action == "hello" and wave.after.value == "hold"
    assert config.actions[0].action == "open" and config.actions[0].after.value == "rest"
    # a missing file too (its error then names where it was looked for); a camera index, a
    # profile name and other kinds stay as given
    missing = GOOD.replace('source = "osc:127.0.0.1:9000/hand"', 'source = "camera:gone.mp4"')
    assert load_session(write(tmp_path, missing)).performers[1].source == (
        f"camera:{(tmp_path / 'gone.mp4').resolve()}")
    for spec in ("camera:0:aruco", "hid:p5", "hid:generic@/dev/hidraw3", "osc:127.0.0.1:9/x"):
        other = GOOD.replace('source = "osc:127.0.0.1:9000/hand"', f'source = "{spec}"')
        assert load_session(write(tmp_path, other)).performers[1].source == spec


def test_an_action_of_several_takes(tmp_path):
    """`takes = [...]`: the follower learns from them all; the motion plays from `take`, the
    first of them unless given; a bad list names the key."""
    text = GOOD.replace('take = "open"', 'takes = ["open", "open_2", "open_3"]')
    config = load_session(write(tmp_path, text))
    first = config.actions[0]
    assert first.take == "open" and first.action == "open"
    assert first.demonstrations == ("open", "open_2", "open_3")
    assert config.actions[1].demonstrations == ("wave",)
    given = GOOD.replace('take = "open"', 'take = "open_2"\ntakes = ["open", "open_2"]')
    assert load_session(write(tmp_path, given)).actions[0].take == "open_2"
    for bad in ('[]', '["open", "open"]', '"open"', '["open", 3]'):
        with pytest.raises(SessionError, match=r"actions\[0\]\.takes.*a list of take names"):
            load_session(write(tmp_path, GOOD.replace('take = "open"', f"takes = {bad}")))
    with pytest.raises(SessionError, match=r"actions\[0\]\.take"):
        load_session(write(tmp_path, GOOD.replace('take = "open"', 'name = "open"')))
