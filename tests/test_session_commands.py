"""`mop train`, `mop plot` and `mop demo` on the shipped demo session and takes."""
import argparse
import re
import sys

import numpy as np
import pytest

from mop.cli import main
from session_files import ROOT, TAKES

DEMO = ROOT / "sessions" / "demo.toml"
sys.path.insert(0, str(ROOT / "recordings"))
import make_demo_takes  # noqa: E402  (the generator of the shipped takes)


@pytest.mark.slow
def test_train_prints_and_plots_confusability(tmp_path, capsys):
    from followers import confusability
    from mop.session import load_session
    from mop.session.build import open_store, performer_templates, take_data
    picture = tmp_path / "confusion.png"
    assert main(["train", str(DEMO), "--plot", str(picture)]) == 0
    text = capsys.readouterr().out
    # the printed matrix is the one followers.confusability gives for the session's templates
    config = load_session(DEMO)
    store = open_store(config.takes)
    takes = {a.take: take_data(store, a.take) for a in config.actions}
    templates, *_ = performer_templates(config, config.performer("hand"), takes, where="")
    expected = confusability(templates)
    for name, row in zip(expected.names, expected.matrix):
        printed = re.search(rf"^  {name}\s+([\d.]+)\s+([\d.]+)$", text, re.M)
        assert printed, text
        assert [float(v) for v in printed.groups()] == pytest.approx(row, abs=5e-4)
    assert "hand_circle" in text and "-> creature" in text and "-> momo" in text
    from PIL import Image
    width, height = Image.open(picture).size
    assert width > 600 and height > 200


def runs(labels):
    """Collapse consecutive repeats: [a, a, None, b] -> [a, b] (None dropped)."""
    out = []
    for label in labels:
        if label is not None and (not out or out[-1] != label):
            out.append(label)
    return out


@pytest.mark.parametrize("show", ["glove_show", "hand_show"])
@pytest.mark.slow
def test_plot_follows_a_show_in_the_order_it_was_performed(tmp_path, show, capsys):
    from mop.commands import plot
    out = tmp_path / f"{show}.png"
    assert main(["plot", show, "--session", str(DEMO), "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000
    args = argparse.Namespace(take=show, session=str(DEMO), performer=None, takes=None, fps=25)
    bank, fps, channels, shift, scale, actions, target = plot.bank_for(args)
    from mop.session.build import resample
    values = resample(target.times, target.values, fps)
    trace = plot.follow(bank, (values - shift) / scale, actions)
    performer = show.split("_")[0]
    script = [f"{performer}_{action}" for action, _ in make_demo_takes.SHOWS[show]
              if action is not None]
    # a rest before an action can look like that action's first frames; what matters is that
    # every performed action is recognised, in order
    recognised = runs(trace["action"])
    assert recognised[-len(script):] == script or runs(script) == recognised[-len(runs(script)):]
    progress = trace["progress"][np.isfinite(trace["progress"])]
    assert progress.min() >= 0 and progress.max() == pytest.approx(1.0, abs=0.02)


@pytest.mark.slow
def test_plot_without_session_uses_the_takes_with_motions(tmp_path, capsys):
    out = tmp_path / "trace.png"
    assert main(["plot", "hand_show", "--takes", str(TAKES), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert re.search(r"hand_circle \d+, hand_lift \d+", text)
    assert main(["plot", "nothing_here", "--takes", str(TAKES)]) == 1


def test_demo_takes_regenerate_with_the_same_content(tmp_path):
    from mop.takes import TakeStore
    make_demo_takes.build(tmp_path)
    shipped, fresh = TakeStore(TAKES), TakeStore(tmp_path)
    assert shipped.names() == fresh.names()
    for name in shipped.names():
        a, b = shipped.load(name), fresh.load(name)
        assert a.channels == b.channels and a.performer == b.performer
        np.testing.assert_array_equal(a.times, b.times)
        np.testing.assert_array_equal(a.values, b.values)
        assert a.motion == b.motion
        assert a.metadata() == b.metadata()
