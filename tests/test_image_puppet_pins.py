"""Automatic pins from a silhouette's skeleton: every limb tip gets a pin, named by where it
points, an anchor in the body; used by `mop puppet --auto-pins` and shown by `--show-mesh`."""
import json

import numpy as np
import pytest

import picture_kit as kit
from characters import ImagePuppet, Motion
from characters.image.skeleton import propose_pins

cv2 = pytest.importorskip("cv2")

def _worst_tip(mask, tips) -> float:
    return kit.worst_tip(propose_pins(mask), mask, tips)


def test_every_star_point_and_stick_limb_gets_a_pin(rng):
    for _ in range(8):
        star, tips = kit.star(rng, size=int(rng.integers(200, 600)),
                              points=int(rng.integers(4, 9)))
        assert _worst_tip(star, tips) <= 0.05
        stick, tips = kit.stick_figure(rng, size=int(rng.integers(200, 600)))
        assert _worst_tip(stick, tips) <= 0.05


@pytest.mark.realdata
@pytest.mark.parametrize("scale", [0.5, 1.0, 2.5])
@pytest.mark.parametrize("flip", [False, True], ids=["facing right", "facing left"])
def test_every_horse_limb_gets_a_pin(scale, flip):
    pytest.importorskip("skimage")
    horse = kit.horse()
    tips = (kit.HORSE_TIPS + 0.5) * scale - 0.5
    horse = cv2.resize(horse.astype(np.uint8), None, fx=scale, fy=scale,
                       interpolation=cv2.INTER_NEAREST) > 0
    if flip:
        horse = np.ascontiguousarray(horse[:, ::-1])
        tips[:, 0] = horse.shape[1] - 1 - tips[:, 0]
    assert _worst_tip(horse, tips) <= 0.05


def test_names_say_where_and_the_body_is_anchored(rng):
    stick, tips = kit.stick_figure(rng, size=400)
    pins = {pin.name: pin for pin in propose_pins(stick)}
    assert set(pins) == {"body", "top", "left", "right", "bottom_1", "bottom_2"}
    assert pins["body"].fixed and not any(p.fixed for n, p in pins.items() if n != "body")
    head, left_hand, right_hand, left_foot, right_foot = tips
    for name, tip in (("top", head), ("left", left_hand), ("right", right_hand),
                      ("bottom_1", left_foot), ("bottom_2", right_foot)):
        assert np.linalg.norm(np.subtract(pins[name].xy, tip)) <= 0.05 * 400, name
    # the anchor is in the trunk, between the shoulders and the hips
    x, y = pins["body"].xy
    assert stick[int(round(y)), int(round(x))] and head[1] < y < left_foot[1]


def test_a_round_shape_has_no_limbs():
    disc = np.zeros((300, 300), np.uint8)
    cv2.circle(disc, (150, 150), 100, 1, -1)
    assert [pin.name for pin in propose_pins(disc.astype(bool))] == ["body"]


def _stick_picture(rng, tmp_path):
    from PIL import Image
    stick, tips = kit.stick_figure(rng, size=240)
    picture = np.where(stick[:, :, None], np.array([40, 60, 150], np.uint8),
                       np.array([245, 240, 230], np.uint8))
    path = tmp_path / "stick.png"
    Image.fromarray(picture).save(path)
    return path, tips


def test_auto_pins_drive_a_puppet(rng, tmp_path):
    path, tips = _stick_picture(rng, tmp_path)
    puppet = ImagePuppet.from_image(path, mode="arap")
    names = puppet.add_auto_pins()
    assert names[0] == "body" and puppet.pins["body"].fixed
    assert set(puppet.target_names) == {"top", "left", "right", "bottom_1", "bottom_2"}
    head = puppet.vertices[puppet.pins["top"].index]
    puppet.step(0.04, {"top": head + (30.0, 0.0)})
    moved = puppet.surface() - puppet.vertices
    assert np.linalg.norm(moved[puppet.pins["top"].index] - (30.0, 0.0)) < 1e-6
    assert np.abs(moved[list(puppet.pins["body"].region)]).max() < 1e-6


@pytest.mark.slow
def test_cli_shows_and_uses_automatic_pins(rng, tmp_path, capsys, monkeypatch):
    from mop.cli import main
    path, _ = _stick_picture(rng, tmp_path)
    monkeypatch.chdir(tmp_path)
    assert main(["puppet", str(path), "--show-mesh"]) == 0
    printed = capsys.readouterr().out
    assert "pins --auto-pins would use: body (" in printed and "top (" in printed
    assert (tmp_path / "stick.mesh.png").stat().st_size > 0
    puppet = ImagePuppet.from_image(path)
    puppet.add_auto_pins()
    head = puppet.vertices[puppet.pins["top"].index]
    motion = Motion({"top": ([0.0, 0.4], [head, head + (25.0, -10.0)])})
    motion.save(tmp_path / "nod.json")
    out = tmp_path / "nod.mkv"
    assert main(["puppet", str(path), "--auto-pins", "--motion", str(tmp_path / "nod.json"),
                 "--out", str(out), "--fps", "10"]) == 0
    assert "automatic pins: body (" in capsys.readouterr().out
    capture = cv2.VideoCapture(str(out))
    frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    capture.release()
    assert frames == 5
    # a motion naming a pin the silhouette has no limb for says which pins there are
    (tmp_path / "tail.json").write_text(json.dumps(
        {"format": "mop.motion", "version": 1,
         "channels": {"tail": {"times": [0, 1], "values": [[1, 1], [2, 2]]}}}))
    assert main(["puppet", str(path), "--auto-pins", "--motion", str(tmp_path / "tail.json"),
                 "--out", str(tmp_path / "tail.mkv")]) == 1
    assert "the motion drives ['tail']" in capsys.readouterr().err
