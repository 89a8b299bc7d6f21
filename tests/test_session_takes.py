"""An action of several takes in a session (`takes = [...]`): the follower learns from them all,
and `mop train` says how consistent they are (the shipped demo takes, and copies of one of
them performed again: slower, faster, and one upside down)."""
import dataclasses
import shutil

import numpy as np
import pytest

from mop.cli import main
from session_files import TAKES, write_session


def again(take, speed, rng, *, flip=False):
    """``take`` performed again: its action stream at ``speed`` (the same samples over a
    stretched clock, cut to the motion's duration) with a little noise; ``flip``: upside
    down."""
    stream = take.streams["action"]
    values = stream.values + rng.normal(scale=0.02 * np.nanstd(stream.values, axis=0),
                                        size=stream.values.shape)
    if flip:
        values = 2 * np.nanmean(values, axis=0) - values
    times = stream.times / speed
    keep = times <= stream.times[-1]
    streams = dict(take.streams)
    streams["action"] = dataclasses.replace(stream, times=times[keep], values=values[keep])
    return dataclasses.replace(take, streams=streams, name="")


@pytest.fixture
def several(tmp_path, rng):
    from mop.takes import TakeStore
    folder = tmp_path / "takes"
    shutil.copytree(TAKES, folder)
    store = TakeStore(folder, create=False)
    lift = store.load("hand_lift")
    for name, speed, flip in (("hand_lift_2", 0.9, False), ("hand_lift_3", 1.1, False),
                              ("hand_lift_odd", 1.0, True)):
        store.save(again(lift, speed, rng, flip=flip), name=name)
    text = write_session(tmp_path).read_text().replace(str(TAKES), str(folder))
    text = text.replace('[[actions]]\ntake = "hand_lift"\nperformer = "hand"\ncharacter = "momo"',
                        '[[actions]]\ntakes = ["hand_lift", "hand_lift_2", "hand_lift_3", '
                        '"hand_lift_odd"]\nperformer = "hand"\ncharacter = "momo"')
    path = tmp_path / "several.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_the_follower_learns_every_take_and_the_outlier_is_named(several):
    from mop.session import load_session
    from mop.session.build import build_bank, open_store, performer_templates, session_takes
    config = load_session(several)
    takes = session_takes(config, open_store(config.takes))
    performer = config.performer("hand")
    templates, *_ = performer_templates(config, performer, takes, where="")
    assert len(templates["hand_lift"]) == 4 and templates["hand_circle"].ndim == 2
    bank = build_bank(templates, performer)
    lift = bank.demonstrations("hand_lift")
    assert lift.count == 4 and lift.outlier() == 3
    assert bank.demonstrations("hand_circle").count == 1


@pytest.mark.slow
def test_train_reports_consistency_and_draws_it(several, tmp_path, capsys):
    picture = tmp_path / "show-confusability.png"
    assert main(["train", str(several), "--plot", str(picture)]) == 0
    text = capsys.readouterr().out
    assert "4 takes, distance from their average: hand_lift " in text
    assert "hand_lift_odd strays from the others" in text
    consistency = tmp_path / "show-consistency.png"
    assert consistency.stat().st_size > 5_000


@pytest.mark.slow
def test_a_session_bank_takes_its_still_stage_from_still_after(several):
    """build_bank with the session's rate sets the bank's still stage from still_after (0.4 s
    at 25 fps: 10 frames); without a rate the stage is off."""
    from mop.session import load_session
    from mop.session.build import build_bank, open_store, performer_templates, session_takes
    config = load_session(several)
    performer = config.performer("glove")
    templates, *_ = performer_templates(config, performer,
                                        session_takes(config, open_store(config.takes)),
                                        where="")
    bank = build_bank(templates, performer, config.fps)
    assert bank.config.still_frames == round(performer.still_after * config.fps) == 10
    assert build_bank(templates, performer).config.still_frames == 0
