"""The hands tracker (MediaPipe hands) on real photographs of hands, turned into short videos by
known transformations as the face's are (tests/test_camera_markerless.py): OpenCV's sample
pictures in Debian's `opencv-doc` (a test dependency: `scripts/setup.sh --test` installs it).

- an open left hand, palm to the camera (two photographs: a hand on a grey wall, a dark hand on
  black in a window): turned in the picture's plane, its wrist follows the known rotation while
  its roll (about the hand's own long axis) and its bends stay put; moved and scaled, its wrist
  follows the known displacement;
- mirrored, the same hand is the performer's other hand, with the same roll and bends; both in
  one picture, each keeps its side while they move;
- covered by a card, then no one there: NaN and status "not seen", then found again within the
  palm search's schedule (`search_every`);
- a hand gripping a board (OpenCV's calibration picture right04) bends its middle and ring
  fingers more than the open hands.
- a hand that jumps (the picture cut from one open hand to the other) is one hand, not two.
The core assertions run with `model="full"` (the default) and `model="lite"`.
"""
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
pytest.importorskip("mediapipe", reason="the markerless trackers need mop[vision]")

from capture import Status, open_source  # noqa: E402
from capture.camera.landmarks import HAND_CHANNELS  # noqa: E402
from camera_pictures import (H, W, card_over, carried, place, placement, track,  # noqa: E402
                             write_video)

pytestmark = [pytest.mark.realdata, pytest.mark.slow]   # videos through MediaPipe

DOCS = Path("/usr/share/doc/opencv-doc")
PHOTOS = {   # name: (file under DOCS, the hand MediaPipe reads in it)
    "wall": ("opencv4/html/Histogram_Comparison_Source_0.jpg", "left"),
    "dark": ("opencv4/html/Hull_Original_Image.jpg", "left"),
    "grip": ("examples/data/right04.jpg", "left"),
}
OPEN = ("wall", "dark")
HAND = {name: k for k, name in enumerate(HAND_CHANNELS)}
BENDS = slice(0, 5)
SIZE = len(HAND_CHANNELS)
# tolerances, from the figures measured on the two open hands (full model / lite); the lite
# model's roll is not held to them: it moves more than the full one's tolerance allows
WRIST_PX = 14.0       # [px] the wrist against its known place: measured <= 10.1 / 7.0
ROLL_SPREAD = 8.0     # [deg] roll's range while the picture turns or moves: <= 5.2 / 10.1
BEND_SPREAD = 0.15    # each bend's range, likewise: <= 0.103 / 0.143
MIRROR_ROLL = 5.0     # [deg] a hand's roll against its mirror image's: <= 2.6 / 5.9
MIRROR_BENDS = 0.08   # index .. pinky bends against the mirror image's: <= 0.043 / 0.061


def photograph(name):
    path = DOCS / PHOTOS[name][0]
    if not path.is_file():
        pytest.skip(f"{path} is missing: the hand photographs come with Debian's opencv-doc "
                    f"(apt-get install opencv-doc; scripts/setup.sh --test does it)")
    return cv2.imread(str(path))


def side_of(values, side):
    """The channels of one hand (N, 9): the performer's right hand takes the glove's names (the
    first nine columns), the left the prefixed ones."""
    return values[:, :SIZE] if side == "right" else values[:, SIZE:]


def other(side):
    return "right" if side == "left" else "left"


def hand_points(image):
    """(21, 2) hand landmarks [px] of one picture (to place a card over the hand)."""
    from mediapipe.python.solutions import hands
    with hands.Hands(static_image_mode=True, max_num_hands=1) as model:
        result = model.process(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
    if not result.multi_hand_landmarks:
        raise ValueError("no hand in the picture")
    points = result.multi_hand_landmarks[0].landmark
    return np.array([(p.x * W, p.y * H) for p in points])


def wrist_error(values, matrices, side):
    """[px] per frame: the wrist found against where the first frames put it, carried by each
    known placement."""
    found = side_of(values, side)[:, [HAND["wrist_x"], HAND["wrist_y"]]] * (W, H)
    expected = carried(found[:3].mean(axis=0), matrices)
    return np.linalg.norm(found - expected, axis=1)


@pytest.fixture(scope="module", params=OPEN)
def open_hand(request):
    return request.param, photograph(request.param)


@pytest.mark.parametrize("model", ["full", "lite"])
def test_turned_in_the_picture_the_wrist_follows_and_roll_and_bends_stay(
        tmp_path, open_hand, model):
    name, photo = open_hand
    side = PHOTOS[name][1]
    angles = np.r_[[0.0] * 3, np.linspace(0, 30, 7), np.linspace(30, -30, 13),
                   np.linspace(-30, 0, 7)]
    matrices = [placement(photo, angle=a) for a in angles]
    values = track(tmp_path, [place(photo, m) for m in matrices], tracker="hands", model=model)
    hand = side_of(values, side)
    assert np.isfinite(hand).all()
    assert np.isnan(side_of(values, other(side))).all()        # one hand, on its side throughout
    assert wrist_error(values, matrices, side).max() < WRIST_PX
    # roll is about the hand's long axis: turning the picture is not turning the hand; an open
    # hand with its palm to the camera reads near 0 (a sign error on one hand reads near 180)
    roll = np.degrees(hand[:, HAND["roll"]])
    assert np.abs(roll).max() < 45.0
    if model == "full":
        assert np.ptp(roll) < ROLL_SPREAD
    assert np.ptp(hand[:, BENDS], axis=0).max() < BEND_SPREAD


@pytest.mark.parametrize("model", ["full", "lite"])
def test_moved_and_scaled_the_wrist_follows_and_the_bends_stay(tmp_path, open_hand, model):
    name, photo = open_hand
    side = PHOTOS[name][1]
    path = ([(0.0, 0.0, 1.0)] * 3
            + [(dx, dy, 1.0) for dx, dy in zip(np.linspace(0, 100, 8), np.linspace(0, -40, 8))]
            + [(100.0, -40.0, s) for s in np.linspace(1.0, 0.7, 6)]
            + [(100 - 180 * t, -40 + 70 * t, 0.7 + 0.4 * t) for t in np.linspace(0, 1, 8)])
    matrices = [placement(photo, scale=s, dx=dx, dy=dy) for dx, dy, s in path]
    values = track(tmp_path, [place(photo, m) for m in matrices], tracker="hands", model=model)
    hand = side_of(values, side)
    assert np.isfinite(hand).all() and np.isnan(side_of(values, other(side))).all()
    assert wrist_error(values, matrices, side).max() < WRIST_PX
    assert np.ptp(hand[:, BENDS], axis=0).max() < BEND_SPREAD
    if model == "full":
        assert np.ptp(hand[:, HAND["roll"]]) < np.radians(ROLL_SPREAD)


def mirrored(picture):
    return np.ascontiguousarray(picture[:, ::-1])


@pytest.mark.parametrize("model", ["full", "lite"])
def test_a_mirrored_hand_is_the_other_hand_and_two_hands_keep_their_sides(
        tmp_path, open_hand, model):
    name, photo = open_hand
    side = PHOTOS[name][1]
    still = place(photo, placement(photo))
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)
    # the hand, gone, its mirror image (the other hand, turned the same way), then both side by
    # side, moving together to the right and back: the photo's hand on the left
    pair = np.hstack([still, mirrored(still)])
    both = [place(pair, placement(pair, scale=0.9, dx=dx))
            for dx in np.r_[np.linspace(0, 60, 5), np.linspace(60, -60, 7)]]
    frames = [still] * 3 + [empty] + [mirrored(still)] * 3 + both
    # the palm search on every frame: each hand found on its first frame in view
    values = track(tmp_path, frames, tracker="hands", model=model, search_every=1)
    hand, twin = side_of(values, side), side_of(values, other(side))
    assert np.isfinite(hand[:3]).all() and np.isnan(twin[:3]).all()
    assert np.isnan(hand[4:7]).all() and np.isfinite(twin[4:7]).all()
    # the same hand turned the same way: the same roll and finger bends (the thumb's differs
    # by up to 0.18), the wrist across the picture
    roll = np.degrees(np.median(hand[:3, HAND["roll"]]) - np.median(twin[4:7, HAND["roll"]]))
    assert abs(roll) < 45.0                   # the other hand's sign wrong: about 150 apart
    if model == "full":
        assert abs(roll) < MIRROR_ROLL
    fingers = np.median(hand[:3, 1:5], axis=0) - np.median(twin[4:7, 1:5], axis=0)
    assert np.abs(fingers).max() < MIRROR_BENDS
    wrist = np.median(hand[:3, HAND["wrist_x"]]) + np.median(twin[4:7, HAND["wrist_x"]])
    assert wrist == pytest.approx(1.0, abs=WRIST_PX / W)
    # both in view: each on its side of the picture, on every frame
    assert np.isfinite(values[7:]).all()
    assert (hand[7:, HAND["wrist_x"]] < 0.5).all() and (twin[7:, HAND["wrist_x"]] > 0.5).all()


def test_a_covered_or_absent_hand_is_nan_and_not_seen_then_found_again(tmp_path, open_hand):
    name, photo = open_hand
    side = PHOTOS[name][1]
    still = place(photo, placement(photo))
    points = hand_points(still)
    covered = card_over(still, points)                          # a grey card over the hand
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)        # no one there
    back = place(photo, placement(photo, dx=-60, dy=-20))       # back, somewhere else
    frames = [still] * 4 + [covered] * 6 + [empty] * 6 + [back] * 5
    for every in (3, 1):
        path = write_video(tmp_path / f"cover{every}.mkv", frames)
        rows, statuses = [], []
        with open_source(f"camera:{path}:hands", realtime=False, queue_size=1,
                         search_every=every) as source:
            for frame in source:
                rows.append(frame.values)
                statuses.append(source.status)
        hand = side_of(np.array(rows), side)
        assert len(hand) == len(frames)
        assert np.isfinite(hand[:4]).all()
        # the wrist is MediaPipe's wrist point (the other tests follow it from where it starts)
        wrist = hand[0, [HAND["wrist_x"], HAND["wrist_y"]]] * (W, H)
        assert np.linalg.norm(wrist - points[0]) < WRIST_PX
        assert np.isnan(hand[4:16]).all()
        assert statuses[1] is Status.OK
        assert statuses[7] is Status.NOT_SEEN and statuses[13] is Status.NOT_SEEN
        # found again within the palm search's schedule: a search on one frame in `every`
        back_at = 16 + np.flatnonzero(np.isfinite(hand[16:, 0]))[0]
        assert back_at - 16 <= every - 1
        assert np.isfinite(hand[back_at:]).all()
        moved = hand[back_at, [HAND["wrist_x"], HAND["wrist_y"]]] - hand[0, [HAND["wrist_x"],
                                                                                HAND["wrist_y"]]]
        assert moved * (W, H) == pytest.approx((-60, -20), abs=WRIST_PX)


def test_a_hand_gripping_a_board_bends_its_middle_fingers_more_than_an_open_hand(tmp_path):
    # the full model only: the lite one finds no hand in the gripping hand's picture
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)
    frames = []
    for name in ("grip",) + OPEN:            # an empty frame after each: one hand at a time
        photo = photograph(name)
        frames += [place(photo, placement(photo))] * 3 + [empty]
    values = track(tmp_path, frames, tracker="hands", search_every=1)
    hands = side_of(values, "left").reshape(3, 4, SIZE)[:, :3]
    assert np.isfinite(hands).all() and np.isnan(side_of(values, "right")).all()
    middle_ring = np.median(hands[:, :, 2:4], axis=1)
    # measured: gripping 0.67-0.68, open 0.20-0.33
    assert (middle_ring[0] - middle_ring[1:] > 0.2).all(), middle_ring


def test_a_hand_that_jumps_is_not_counted_twice(tmp_path):
    # the picture cut from one open hand to the other, in about the same place: the palm search
    # finds the new hand while the tracking from the last frame still reads one in its old box
    # (the graph keeps both when the boxes overlap too little); the two coincide, finger for
    # finger, and MediaPipe calls both "Left": one hand, not a right hand besides it
    frames = [place(photograph(name), placement(photograph(name))) for name in OPEN]
    values = track(tmp_path, [frames[0]] * 3 + [frames[1]] * 3, tracker="hands")
    assert np.isfinite(side_of(values, "left")).all()
    assert np.isnan(side_of(values, "right")).all()
