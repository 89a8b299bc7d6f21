"""A performer's calibration take end to end: `mop record --calibrate` from a replayed source
into the take folder (SQLite), read back, and a session whose performer names it follows that
performer's input as the author's."""
import re
import shutil

import numpy as np
import pytest

from mop.cli import main
from mop.session import Mode, load_session
from mop.session.build import Overrides, build_session
from session_files import TAKES, session_text

GAIN = np.array([0.6, 1.4, 0.8, 1.25, 1.1])      # another performer's glove, per finger
OFFSET = np.array([0.2, -0.15, 0.1, 0.05, -0.3])


def another_performer(values):
    return values * GAIN + OFFSET


def session_file(tmp_path, folder, extra_performer=""):
    text = session_text(glove_source="replay:alice_show").replace(
        f'takes = "{TAKES}"', f'takes = "{folder}"').replace(
        "[performers.glove]\n", f"[performers.glove]\n{extra_performer}")
    path = tmp_path / "show.toml"
    path.write_text(text)
    return path


def glove_bank(path):
    session = build_session(load_session(path), mode=Mode.REPLAY,
                            overrides=Overrides(render=False))
    runtime = next(p for p in session.performers if p.name == "glove")
    return runtime.bank, runtime.shift, runtime.scale


@pytest.mark.slow
def test_a_recorded_calibration_maps_another_performer_onto_the_author(tmp_path, capsys):
    from mop.takes import ActionStream, Take, TakeStore, calibration_of, is_calibration
    folder = tmp_path / "recordings"
    shutil.copytree(TAKES, folder)
    store = TakeStore(folder)
    show = store.load("glove_show")
    rate = 50.0
    # a calibration as the glove's performer does it: the rest pose for 2 s, then the range
    author = np.vstack([np.repeat(show.values[:1], int(2 * rate), axis=0), show.values[:125]])
    inputs = TakeStore(tmp_path / "input")
    for name, values in (("author", author), ("alice", another_performer(author))):
        inputs.save(Take("someone", "input", {"action": ActionStream(
            np.arange(len(values)) / rate, values, show.channels, rate)}), name=name)
    store.save(Take("alice", "show", {"action": ActionStream(
        show.times, another_performer(show.values), show.channels, rate)},
        extra={"show": True}), name="alice_show")

    # a session naming a calibration before the author has one says what to record
    path = session_file(tmp_path, folder, 'calibration = "alice_show"\n')
    with pytest.raises(ValueError, match=r"performers\.glove\.calibration: the author 'glove' "
                                         r".*mop record --calibrate --performer glove"):
        glove_bank(path)

    for performer, name in (("glove", "author"), ("alice", "alice")):
        assert main(["record", "--performer", performer, "--calibrate", "--duration", "4.3",
                     "--source", f"replay:{tmp_path / 'input' / name}", "--recordings",
                     str(folder), "--countdown", "0"]) == 0
        out = capsys.readouterr().out
        assert f"calibration of {performer}: rest and range" in out
        assert f'calibration = "{performer}-calibration-001"' in out
    # alice's take said how she differs from the glove's author, per finger
    gains = re.search(r"onto glove \(glove-calibration-001\): gain (.*)", out).group(1)
    np.testing.assert_allclose([float(g.split()[1]) for g in gains.split(", ")], 1 / GAIN,
                               atol=0.01)
    assert main(["record", "--performer", "alice", "--calibrate", "--action", "wave",
                 "--source", "replay:x", "--recordings", str(folder)]) == 1
    assert "--calibrate records the take of action 'calibration'" in capsys.readouterr().err
    take = store.load("alice-calibration-001")
    assert is_calibration(take) and take.motion is None and take.action == "calibration"
    assert take.times.size >= 0.9 * len(author)
    assert main(["takes", "--recordings", str(folder), "show", "alice-calibration-001"]) == 0
    assert "a calibration take: the rest pose" in capsys.readouterr().out
    measured = calibration_of(take)
    np.testing.assert_allclose(measured.rest, another_performer(show.values[0]), atol=1e-9)
    # not a demonstration: `mop record`'s templates and the consistency report skip it
    from mop.takes import performer_templates
    assert not performer_templates(store, "alice", rate=25.0)
    with pytest.raises(ValueError, match="'alice_show' is not a calibration take"):
        glove_bank(path)

    # the session maps alice's glove onto the author's: the same normalised input, the same
    # actions, where her input as it comes is followed as something else
    plain_bank, shift, scale = glove_bank(session_file(tmp_path, folder))
    path = session_file(tmp_path, folder, 'calibration = "alice-calibration-001"\n')
    bank, alice_shift, alice_scale = glove_bank(path)
    ours = (show.values - shift) / scale
    theirs = (another_performer(show.values) - alice_shift) / alice_scale
    assert np.abs(theirs - ours).max() < 0.05 * np.abs(ours).max()
    truth = plain_bank.follow(ours)["action"]
    calibrated = bank.follow(theirs)["action"]
    as_it_comes = plain_bank.follow((another_performer(show.values) - shift) / scale)["action"]
    agree = np.mean(calibrated == truth)
    assert agree >= 0.95 and agree > np.mean(as_it_comes == truth) + 0.1
    assert main(["perform", str(path), "--duration", "1", "--no-render", "--quiet"]) == 0
    # or from the command line, for whoever steps in at the show
    plain = session_file(tmp_path, folder)
    assert main(["perform", str(plain), "--calibration", "glove=alice-calibration-001",
                 "--duration", "1", "--no-render", "--quiet"]) == 0
    from mop.commands.perform import with_calibrations
    config = with_calibrations(load_session(plain), ["glove=alice-calibration-001"])
    session = build_session(config, mode=Mode.REPLAY, overrides=Overrides(render=False))
    runtime = next(p for p in session.performers if p.name == "glove")
    np.testing.assert_array_equal(runtime.shift, alice_shift)
    capsys.readouterr()
    assert main(["perform", str(plain), "--calibration", "alice=alice-calibration-001",
                 "--duration", "1", "--no-render", "--quiet"]) == 1
    assert "--calibration: no performer 'alice'" in capsys.readouterr().err
    assert main(["perform", str(plain), "--calibration", "glove=glove_show", "--duration",
                 "1", "--no-render", "--quiet"]) == 1
    assert "'glove_show' is not a calibration take" in capsys.readouterr().err
