"""What an author meets writing sessions: pins sidecars, show takes, sources beside the session
file, a video-file performer, transparent frames, one validation for train and perform, names."""
import json
import logging
import re
import shutil
import time

import numpy as np
import pytest

from mop.cli import main
from mop.session import Mode, load_session
from mop.session.build import Overrides, build_session
from session_files import ROOT, TAKES, session_text, write_session

MOMO = ROOT / "characters" / "assets" / "momo.png"


def test_a_short_pins_sidecar_works_in_sessions_as_in_mop_puppet(tmp_path):
    from mop.session.config import CharacterConfig, CharacterKind
    from mop.session.puppets import build
    picture = tmp_path / "momo.png"
    shutil.copy(MOMO, picture)
    sidecar = tmp_path / "momo.pins.json"
    sidecar.write_text(json.dumps({"right_hand": [446, 172], "head": [256, 110],
                                   "left_foot": {"xy": [196, 470], "fixed": True}}))
    character = CharacterConfig(name="momo", kind=CharacterKind.IMAGE, asset=str(picture))
    puppet, layer = build(character, frame_height=180)
    assert sorted(puppet.target_names) == ["head", "right_hand"]
    assert puppet.pins["left_foot"].fixed and not puppet.pins["head"].fixed
    assert main(["puppet", str(picture), "--show-mesh", str(tmp_path / "mesh.png")]) == 0
    # one parser, one strictness: a quoted boolean is refused, naming the file and the pin
    sidecar.write_text(json.dumps({"pins": {"head": {"xy": [256, 110], "fixed": "false"}}}))
    with pytest.raises(TypeError, match=r"momo\.pins\.json: pin .head.: .fixed. must be true"):
        build(character, frame_height=180)
    assert main(["puppet", str(picture), "--show-mesh", str(tmp_path / "mesh.png")]) == 1


@pytest.mark.slow
def test_record_show_stores_a_performance_that_perform_replays(tmp_path, capsys):
    from mop.takes import ActionStream, Take, TakeStore, performer_templates
    performer = TakeStore(tmp_path / "input")
    times = np.arange(60) / 50.0                           # 1.2 s of one channel at 50 Hz
    performer.save(Take("someone", "input", {"action": ActionStream(
        times, np.sin(times)[:, None], ("bend",), 50.0)}), name="input")
    folder = tmp_path / "recordings"
    shutil.copytree(TAKES, folder)
    assert main(["record", "--performer", "glove", "--show", "--source",
                 f"replay:{tmp_path / 'input' / 'input'}", "--recordings", str(folder),
                 "--countdown", "0"]) == 0           # until the source ends (or Ctrl-C)
    out = capsys.readouterr().out
    assert "source replay:" in out and ": 1 channel (bend)" in out
    assert "confusability" not in out and "a show take" in out
    store = TakeStore(folder)
    name = next(n for n in store.names() if n.startswith("glove-show"))
    take = store.load(name)
    assert take.motion is None and take.action == "show" and take.complete
    assert 50 <= take.times.size <= 60
    # a show take is a performance, never a demonstration
    assert name not in performer_templates(store, "glove", rate=25.0, channels=("bend",))
    assert main(["record", "--performer", "glove", "--action", "wave", "--source", "replay:x",
                 "--recordings", str(folder)]) == 1
    assert "--motion: give the motion" in capsys.readouterr().err
    # replayed by perform like any take (here with the demo's glove takes, 5 channels)
    assert main(["record", "--performer", "glove", "--show", "--duration", "0.6", "--source",
                 f"replay:{TAKES / 'glove_show'}", "--recordings", str(folder), "--name",
                 "glove_short", "--countdown", "0"]) == 0
    session = write_session(tmp_path)
    assert main(["perform", str(session), "--replay", f"glove=replay:{folder / 'glove_short'}",
                 "hand=hand_show", "--duration", "1", "--no-render", "--quiet"]) == 0
    assert "performer glove: ended" in capsys.readouterr().out


def test_a_failing_source_says_why_in_the_report_and_the_state(tmp_path):
    path = write_session(tmp_path, hand_source="camera:clips/missing.mkv:color")
    config = load_session(path)
    assert config.performer("hand").source == (
        f"camera:{(tmp_path / 'clips' / 'missing.mkv').resolve()}:color")
    states = []

    class States:
        def send(self, state):
            states.append(state)

        def close(self):
            pass

    session = build_session(config, mode=Mode.LIVE, overrides=Overrides(render=False),
                            extra_outputs=[States()])
    report = session.run(duration=0.3)
    hand = states[-1]["performers"]["hand"]
    assert hand["status"] == "failed" and "video file not found" in hand["message"]
    assert str(tmp_path / "clips" / "missing.mkv") in hand["message"]
    line = next(line for line in report.format().splitlines() if "performer hand" in line)
    assert "failed (FileNotFoundError: video file not found:" in line
    assert states[-1]["mode"] == "live"


def test_a_video_file_performer_starts_at_the_first_frame_the_show_asks_for(tmp_path):
    cv2 = pytest.importorskip("cv2")
    from capture import open_source
    path = tmp_path / "clip.mkv"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10.0, (160, 120))
    for k in range(12):
        frame = np.full((120, 160, 3), 40, np.uint8)
        cv2.circle(frame, (20 + 10 * k, 60), 8, (0, 0, 255), -1)      # red, moving right
        writer.write(frame)
    writer.release()
    with open_source(f"camera:{path}:color") as source:
        time.sleep(0.6)              # a build or a countdown: 6 frames' worth at 10 fps
        asked = time.monotonic()
        frames = []
        while len(frames) < 4:
            frame = source.read(timeout=1.0)
            assert frame is not None
            frames.append(frame)
        x = source.channels.index("red.x")
        positions = [round(f.values[x] * 160) for f in frames]
        assert positions == [20, 30, 40, 50]                  # from the clip's first frame
        assert frames[0].t >= asked - 0.005                    # played from the first ask
        assert np.diff([f.t for f in frames]) == pytest.approx(0.1, abs=0.03)


def picture(path):
    from PIL import Image
    with Image.open(path) as image:
        return image.mode, np.asarray(image)


@pytest.mark.slow
def test_transparent_frames_and_the_warning_for_video(tmp_path, caplog):
    path = write_session(tmp_path)                    # an opaque colour background
    opaque, clear = tmp_path / "opaque", tmp_path / "clear"
    build_session(load_session(path), overrides=Overrides(png=str(opaque))).run(duration=0.2)
    build_session(load_session(path), overrides=Overrides(png=str(clear), transparent=True)
                  ).run(duration=0.2)
    first = sorted(opaque.glob("*.png"))[0]
    assert picture(first)[0] == "RGB"                    # composited over the colour
    pictures = sorted(clear.glob("*.png"))
    assert len(pictures) == 5
    alpha = picture(pictures[-1])[1][..., 3]
    assert alpha[0, 0] == 0 and alpha.max() == 255
    assert main(["perform", str(path), "--replay", "--duration", "0.2", "--transparent",
                 "--png", str(tmp_path / "cli"), "--quiet"]) == 0
    assert picture(sorted((tmp_path / "cli").glob("*.png"))[0])[1][0, 0, 3] == 0
    see_through = write_session(tmp_path, name="clear.toml", background="transparent")
    with caplog.at_level(logging.WARNING, logger="mop.session.build"):
        build_session(load_session(see_through), overrides=Overrides(
            video=str(tmp_path / "show.mp4"))).run(duration=0.1)
    assert any("video has no alpha" in record.message for record in caplog.records)


@pytest.mark.parametrize("change, message", [
    (('thumb = "jaw"', 'thumb = "chin"'),
     r"actions\[3\]\.channels: character 'worm' has no target 'chin'"),
    (('take = "hand_lift"\nperformer = "hand"\ncharacter = "momo"',
      'take = "hand_lift"\nperformer = "hand"\ncharacter = "momo"\nchannels = { head = "jaw" }'),
     r"actions\[1\]\.channels: character 'momo' has no target 'jaw'"),
    (('take = "hand_circle"\nperformer = "hand"\ncharacter = "creature"',
      'take = "hand_circle"\nperformer = "hand"\ncharacter = "momo"\n'
      'channels = { front = "left_hand" }'),
     r"show\.toml: actions\[2\]\.channels: take 'hand_circle', character 'momo': motion "
     r"channel 'front' gives 1 value\(s\) per frame, which target 'left_hand' does not take"),
])
def test_train_refuses_what_perform_refuses_naming_file_and_key(tmp_path, capsys, change,
                                                                message):
    path = tmp_path / "show.toml"
    text = session_text()
    assert change[0] in text
    path.write_text(text.replace(*change))
    assert main(["train", str(path), "--plot", str(tmp_path / "c.png")]) == 1
    assert re.search(message, capsys.readouterr().err)
    assert main(["perform", str(path), "--replay", "--duration", "0.1", "--no-render"]) == 1
    assert re.search(message, capsys.readouterr().err)


def test_plot_panels_name_every_action(tmp_path):
    import argparse

    from mop.commands import plot
    from mop.session.build import resample
    args = argparse.Namespace(take="glove_show", session=str(ROOT / "sessions" / "demo.toml"),
                              performer=None, takes=None, fps=25)
    bank, fps, channels, shift, scale, actions, target = plot.bank_for(args)
    values = resample(target.times, target.values, fps)
    trace = plot.follow(bank, (values - shift) / scale, actions)
    legends = plot.draw(tmp_path / "trace.png", "glove_show", values, channels, trace, actions,
                        fps)
    assert legends[0] == list(channels)
    for panel in legends[1:]:                 # progress, posterior, log-likelihood
        assert sorted(panel) == sorted(actions)


def test_the_preview_and_report_name_what_kind_of_show_it_is(tmp_path):
    path = write_session(tmp_path)
    session = build_session(load_session(path), mode=Mode.LIVE,
                            overrides=Overrides(render=False))
    assert session.mode_label == "replay in real time"
    report = session.run(duration=0.2)
    assert "replay in real time" in report.format().splitlines()[0]
    from mop.commands import count
    assert (count(1, "channel"), count(5, "channel"), count(0, "frame")) == (
        "1 channel", "5 channels", "0 frames")
