"""The markerless trackers (MediaPipe) on real photographs turned into short videos by known
transformations, written with OpenCV (FFV1 in .mkv, lossless; MJPEG, as a webcam sends it, for
the tests played in real time) and read back through the camera source: scikit-image's
astronaut and matplotlib's Grace Hopper, each a face and an upper body.

- in-plane rotation: head_roll follows the known angle within 3 degrees;
- translation and scale: head_x / head_y move with the known displacement, head_scale with the
  known scale;
- the lower face warped open: jaw_open rises step by step (also in a greyscale photograph);
- the face covered, then no one there: NaN and status "not seen", then found again; a card over
  a close face NaN from its first frame, a card over the mouth not;
- a face far from the camera (under a tenth of the frame): found and measured all the same;
- a fast move: a jump read where the face went; a blurred face found again when sharp;
- leaving across the edge: NaN once an outer eye corner is out, found again where it is;
- a second face passing behind, smaller, or beside, larger: the tracked face is kept;
- the body rotated: the pose tracker's lean follows; no hand in either picture: NaN;
- the palm search, while no hand is tracked, on one frame in `search_every`;
- One Euro smoothing on a noisy picture; `mop record` from a camera; the demo's glove performer
  given `camera:...:hands`; the shipped webcam session's takes followed.
"""
import math
import re
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
pytest.importorskip("mediapipe", reason="the markerless trackers need mop[vision]")
pytest.importorskip("skimage.data", reason="the astronaut photograph comes with scikit-image")

from capture import Status  # noqa: E402
from capture.camera.landmarks import (FACE_CHANNELS, HAND_CHANNELS,  # noqa: E402
                                      POSE_CHANNELS)
from camera_pictures import (ROOT, H, W, card_over, carried, head_cut,  # noqa: E402
                             layered, motion_blur, pictures, place, placement, track,
                             track_statuses, write_video)

pytestmark = [pytest.mark.realdata, pytest.mark.slow]   # videos through MediaPipe: minutes

FACE = {name: k for k, name in enumerate(FACE_CHANNELS)}
astronaut, face_points, jaw_warp = pictures.astronaut, pictures.face_points, pictures.jaw_warp


def webcam_video(path, frames, fps=30.0):
    """A video as a webcam sends it (MJPEG), for the tests played in real time: a frame takes
    about 2 ms to decode, where lossless FFV1 takes about 26, more than a reader on a busy
    machine keeps up with at 30 fps."""
    import cv2
    path = Path(path).with_suffix(".avi")
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (W, H))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def grace_hopper():
    from matplotlib import cbook
    with cbook.get_sample_data("grace_hopper.jpg") as file:
        data = np.frombuffer(file.read(), np.uint8)
    return cv2.imdecode(data, cv2.IMREAD_COLOR)


PHOTOS = {"astronaut": astronaut, "grace_hopper": grace_hopper}


@pytest.fixture(scope="module", params=sorted(PHOTOS))
def photo(request):
    return PHOTOS[request.param]()


def test_head_roll_follows_an_in_plane_rotation_within_3_degrees(tmp_path, photo):
    # the head turns gradually, as a performer's would: 0 -> 30 -> -30 -> 0 degrees
    angles = np.r_[[0.0] * 3, np.linspace(0, 30, 11), np.linspace(30, -30, 21),
                   np.linspace(-30, 0, 11)]
    values = track(tmp_path, [place(photo, placement(photo, angle=a)) for a in angles])
    roll = values[:, FACE["head_roll"]]
    assert np.isfinite(roll).all()
    # the photo's own tilt is the reference: the head's roll in the unturned picture
    turned = roll - roll[:3].mean()
    assert np.abs(turned - angles).max() <= 3.0
    # turning the picture is not turning the head sideways or opening the mouth
    assert np.ptp(values[:, FACE["head_yaw"]]) < 8.0
    assert np.ptp(values[:, FACE["jaw_open"]]) < 0.1


def test_head_position_and_scale_follow_translation_and_scale(tmp_path, photo):
    path = ([(0.0, 0.0, 1.0)] * 3
            + [(dx, dy, 1.0) for dx, dy in zip(np.linspace(0, 120, 10), np.linspace(0, -60, 10))]
            + [(120.0, -60.0, s) for s in np.linspace(1.0, 0.75, 8)]
            + [(120 - 200 * t, -60 + 90 * t, 0.75 + 0.5 * t) for t in np.linspace(0, 1, 12)])
    matrices = [placement(photo, scale=s, dx=dx, dy=dy) for dx, dy, s in path]
    values = track(tmp_path, [place(photo, m) for m in matrices])
    assert np.isfinite(values).all()
    # where the tracker puts the head in the first frames, carried by each known placement
    first = np.array([values[:3, FACE["head_x"]].mean() * W, values[:3, FACE["head_y"]].mean() * H])
    expected = carried(first, matrices)
    found = np.c_[values[:, FACE["head_x"]] * W, values[:, FACE["head_y"]] * H]
    error = np.linalg.norm(found - expected, axis=1)
    assert error.max() < 4.0                                  # [px]; measured <= 1.4
    scale = np.array([s for _, _, s in path])
    measured = values[:, FACE["head_scale"]] / values[:3, FACE["head_scale"]].mean()
    assert np.abs(measured / scale - 1).max() < 0.08          # measured <= 0.051
    assert np.ptp(values[:, FACE["head_roll"]]) < 3.0


def test_jaw_open_rises_as_the_lower_face_is_warped_open(tmp_path, photo):
    assert_jaw_opens(tmp_path, photo)


def test_jaw_open_rises_on_a_greyscale_photograph_too(tmp_path):
    # the mouth is painted grey there: a red one in a grey face, the mesh read as lips (jaw_open
    # per step 0.02, 0.02, 0.24, 0.32, 0.42, 0.36, 0.36 on this portrait)
    grey = cv2.cvtColor(cv2.cvtColor(grace_hopper(), cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
    assert_jaw_opens(tmp_path, grey)


def assert_jaw_opens(tmp_path, photo):
    still = place(photo, placement(photo))
    points = face_points(still)             # where the mouth is: to place the warp
    span = np.linalg.norm(points[263] - points[33])          # outer eye corners [px]
    # up to a gap of 0.3 eye spans (a mouth well open), in 7 steps, 3 frames each
    openings = np.repeat(np.linspace(0, 0.3 * span, 7), 3)
    warp = jaw_warp(points)
    values = track(tmp_path, [pictures.open_jaw(still, opening=d, **warp) for d in openings])
    jaw = values[:, FACE["jaw_open"]].reshape(7, 3)
    assert np.isfinite(jaw).all()
    steps = np.median(jaw, axis=1)
    assert np.all(np.diff(steps) > 0), steps
    # the inner lips part by 0.3 eye spans more: jaw_open (full at 0.45 spans) rises by ~0.67
    assert steps[-1] - steps[0] > 0.4
    assert np.ptp(values[:, FACE["head_roll"]]) < 3.0


def test_covered_or_absent_face_is_nan_and_not_seen_then_found_again(tmp_path, photo):
    still = place(photo, placement(photo))
    covered = card_over(still, face_points(still))            # a grey card over the face
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)       # no one there
    back = place(photo, placement(photo, dx=-60, dy=20))       # back, somewhere else
    frames = [still] * 4 + [covered] * 10 + [empty] * 10 + [back] * 4
    values, statuses = track_statuses(tmp_path / "cover.mkv", frames, tracker="face")
    assert np.isfinite(values[:4]).all()
    assert np.isnan(values[4:24]).all()
    # read in the middle of the covered and of the empty stretches, the source says why
    assert statuses[8] is Status.NOT_SEEN and statuses[18] is Status.NOT_SEEN
    assert statuses[1] is Status.OK
    # found again on the first frame back, where it now is
    assert np.isfinite(values[24:]).all()
    assert values[24, FACE["head_x"]] * W == pytest.approx(values[0, FACE["head_x"]] * W - 60,
                                                           abs=4)
    assert values[24, FACE["head_y"]] * H == pytest.approx(values[0, FACE["head_y"]] * H + 20,
                                                           abs=4)


def test_a_card_over_a_close_face_is_nan_from_its_first_frame_one_over_the_mouth_is_not(
        tmp_path, photo):
    # close to the camera, a blank card with the head's outline round it: the mesh, tracking,
    # went on reading a face in it at MediaPipe's tracking confidence 0.5 (1-3 frames here,
    # every frame on some portraits)
    still = place(photo, placement(photo, scale=1.6))
    points = face_points(still)
    covered = card_over(still, points)
    mouth = card_over(still, points, top=points[2, 1])       # from the nose down
    values = track(tmp_path, [still] * 4 + [covered] * 6 + [still] * 4 + [mouth] * 6)
    assert np.isnan(values[4:10]).all()
    assert np.isfinite(values[:4]).all() and np.isfinite(values[10:]).all()


def test_a_face_far_from_the_camera_is_found_in_a_window_and_measured(tmp_path, photo):
    # the performer close, gone, then far away (a face under a tenth of the frame's width,
    # below what the face mesh's own detector finds) walking across and back a little
    near = [(0.0, 0.0, 1.0)] * 3
    far = [(-150 + 25 * k, 60 - 5 * k, 0.4 - 0.004 * k) for k in range(12)]
    matrices = [placement(photo, scale=s, dx=dx, dy=dy) for dx, dy, s in near + far]
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)
    frames = [place(photo, m) for m in matrices[:3]] + [empty] * 3 + [
        place(photo, m) for m in matrices[3:]]
    values = track(tmp_path, frames, search_every=1)         # the far search on every frame
    assert np.isfinite(values[:3]).all() and np.isnan(values[3:6]).all()
    small = values[6:]
    assert np.isfinite(small).all()
    assert (small[:, FACE["head_scale"]] < 0.1).all()         # face width / frame width
    # position and size against the known placements, as for a near face
    first = np.array([values[:3, FACE["head_x"]].mean() * W, values[:3, FACE["head_y"]].mean() * H])
    expected = carried(first, matrices)[3:]
    found = np.c_[small[:, FACE["head_x"]] * W, small[:, FACE["head_y"]] * H]
    assert np.linalg.norm(found - expected, axis=1).max() < 3.0           # [px]
    scale = np.array([s for _, _, s in far])
    measured = small[:, FACE["head_scale"]] / values[:3, FACE["head_scale"]].mean()
    assert np.abs(measured / scale - 1).max() < 0.1
    assert np.abs(small[:, FACE["head_roll"]] - values[:3, FACE["head_roll"]].mean()).max() < 4
    # without the far search the small face is not found at all
    assert np.isnan(track(tmp_path, frames, far=False)[6:]).all()
    # by default the far search runs on the frame the face is lost and the next (frames 3, 4),
    # then on one frame in three (7, 10): a far face coming into view between two searches
    # (frame 8) is found two frames later
    late = track(tmp_path, frames[:6] + [empty] * 2 + frames[6:])
    assert np.isnan(late[3:10]).all() and np.isfinite(late[10:]).all()


def test_a_fast_move_reads_the_face_where_it_went_and_a_blurred_one_is_back_when_sharp(
        tmp_path):
    # the face jumps 300 px in one frame, back, then through a frame blurred along the move
    # (41 px): the jump is read at once, where the face went, as it reads there when still; the
    # blurred face is lost on that frame and found on the next (the far search runs after a face
    # is lost, also after a frame searched in vain: it came back 2 frames later)
    photo = astronaut()
    xs = [-150, -150, 150, 150, 150, -150, 0, 150, 150]
    matrices = [placement(photo, scale=0.6, dx=dx) for dx in xs]
    frames = [place(photo, m) for m in matrices]
    frames[6] = motion_blur(frames[6], 41)
    values = track(tmp_path, frames)
    found = np.isfinite(values[:, 0])
    assert found[:6].all() and found[7:].all(), np.flatnonzero(~found)
    first = np.array([values[0, FACE["head_x"]] * W, values[0, FACE["head_y"]] * H])
    error = np.linalg.norm(np.c_[values[:, FACE["head_x"]] * W, values[:, FACE["head_y"]] * H]
                           - carried(first, matrices), axis=1)
    assert error[found].max() < 4.0                            # [px]
    # the frame after each jump against the still frame after it (measured <= 0.08, 1.1 deg)
    for jumped in (2, 5, 7):
        still = jumped + 1 if jumped != 5 else 0
        assert np.abs(values[jumped, :7] - values[still, :7]).max() < 0.2
        assert np.abs(values[jumped, 7:10] - values[still, 7:10]).max() < 4.0


def test_a_face_leaving_across_the_edge_is_nan_once_an_eye_corner_is_out(tmp_path, photo):
    # the face moves out across the right edge by a fraction of its width, is gone, comes back;
    # an outer eye corner leaves at about 0.2: the mesh then guesses the half out of view
    # (blinks up to 0.64, brows +0.5, yaw 16 degrees astray at 0.3-0.6 out)
    still = place(photo, placement(photo))
    points = face_points(still)
    centre, width = points[[234, 454], 0].mean(), np.ptp(points[[234, 454], 0])
    outs = [0.0, 0.0, 0.1, 0.3, 0.5, 1.2, 1.2, 0.3, 0.0]
    matrices = [placement(photo, dx=W - width * (0.5 - out) - centre) for out in outs]
    values = track(tmp_path, [place(photo, m) for m in matrices])
    assert np.isfinite(values[:3]).all() and np.isfinite(values[-1]).all()
    # a tenth out: read as at the edge (measured <= 0.11 and 2.9 degrees)
    assert np.abs(values[2, :7] - values[0, :7]).max() < 0.2
    assert np.abs(values[2, 7:10] - values[0, 7:10]).max() < 6.0
    # 0.3 and 0.5 out, gone, 0.3 in again: NaN ("not seen"); back: where it is, no stale face
    assert np.isnan(values[3:-1]).all()
    first = np.array([values[0, FACE["head_x"]] * W, values[0, FACE["head_y"]] * H])
    back = np.array([values[-1, FACE["head_x"]] * W, values[-1, FACE["head_y"]] * H])
    assert np.linalg.norm(back - carried(first, matrices)[-1]) < 4.0


def face_width(photo):
    """The photo's face width [px] placed in the frame (cheek to cheek)."""
    points = face_points(place(photo, placement(photo)))
    return np.ptp(points[[234, 454], 0])


@pytest.mark.parametrize("name, other", [("astronaut", "grace_hopper"),
                                         ("grace_hopper", "astronaut")])
def test_the_face_stays_with_the_performer_while_another_passes_or_is_larger(tmp_path, name,
                                                                           other):
    # a head cut out of the other photograph passes behind the performer, its face 0.6 times
    # the performer's, from right to left, then stands beside them, 1.5 times larger, for three
    # frames: the mesh follows the face it tracks (its own detector runs only when no face is
    # tracked; detecting on every frame, the astronaut's puppet went to Grace Hopper)
    photo, other = PHOTOS[name](), PHOTOS[other]()
    performer = (photo, head_cut(photo), placement(photo, dx=-80))
    mask = head_cut(other)
    ratio = face_width(photo) / face_width(other)

    def passer(x, size):
        return other, mask, placement(other, scale=size * ratio, dx=x)

    frames = ([layered(performer)] * 2
              + [layered(passer(x, 0.6), performer) for x in (260, 120, -100, -240)]
              + [layered(performer, passer(230, 1.5))] * 3 + [layered(performer)])
    values = track(tmp_path, frames)
    assert np.isfinite(values).all()
    x = values[:, FACE["head_x"]] * W
    assert np.ptp(x) < 4.0                                     # [px]; measured <= 1
    assert np.ptp(values[:, FACE["head_scale"]]) / values[0, FACE["head_scale"]] < 0.05


def test_pose_lean_follows_a_rotated_body_and_no_hand_is_nan(tmp_path, photo):
    angles = np.r_[[0.0] * 3, np.linspace(0, 25, 6), np.linspace(25, -25, 11)]
    values = track(tmp_path, [place(photo, placement(photo, angle=a)) for a in angles],
                   tracker="pose")
    lean = values[:, POSE_CHANNELS.index("lean")]
    assert np.isfinite(lean).all()
    # the shoulders are read less precisely than a face (a space suit's collar, a uniform):
    # the lean follows the turn, with a smaller gain (measured 0.53 and 0.84)
    slope, _ = np.polyfit(angles, lean, 1)
    assert 0.4 < slope < 1.3
    assert np.corrcoef(angles, lean)[0, 1] > 0.85
    # a wrist is given where it is seen, in the picture
    wrists = values[:, POSE_CHANNELS.index("hand_left.x"):]
    assert np.all(np.isnan(wrists) | ((wrists >= 0) & (wrists <= 1)))
    hands = track(tmp_path, [place(photo, placement(photo))] * 5, tracker="hands")
    assert hands.shape[1] == 2 * len(HAND_CHANNELS) and np.isnan(hands).all()


def test_the_pose_landmarks_are_the_full_models_to_the_bit(photo):
    """The pose tracker runs the wheel's full landmark model without its segmentation head:
    on the photo turned and moved frame by frame (tracked from frame to frame, the body found
    again after an empty frame), its landmarks, visibilities and channels are those of
    MediaPipe's own Pose graph with the whole model, exactly."""
    import mediapipe
    from mediapipe.python import packet_getter
    from mediapipe.python.solutions import pose
    from capture.camera.landmarks import pose_channels
    from capture.camera.markerless import MODELS, landmarks_only, native_notices
    from capture.camera.trackers import make_tracker
    empty = np.full((H, W, 3), 100, np.uint8)
    frames = [place(photo, placement(photo, angle=a, dx=4 * a, dy=-2 * a))
              for a in (0, 0, 5, 10, 15, 20, 10, 0, -10, -20)]
    frames[6:6] = [empty]
    tracker = make_tracker("pose")
    # the model the tracker's graph runs is the one without the mask's operators
    model = packet_getter.get_bytes(tracker._solution._input_side_packets["pose_landmark_model"])
    assert model == landmarks_only(str(Path(mediapipe.__file__).parent / "modules"
                                       / MODELS["pose"][1]))
    with native_notices():
        whole = pose.Pose(static_image_mode=False, model_complexity=1, smooth_landmarks=False,
                          enable_segmentation=False)
    seen = 0
    for frame in frames:
        values = tracker.process(frame)
        result = whole.process(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
        assert tracker.seen == (result.pose_landmarks is not None)
        if not tracker.seen:
            assert np.isnan(values).all()
            continue
        seen += 1
        points, visibility = tracker.last_points()
        image = np.array([(p.x, p.y, p.z) for p in result.pose_landmarks.landmark])
        shown = np.array([p.visibility for p in result.pose_landmarks.landmark])
        world = np.array([(p.x, p.y, p.z) for p in result.pose_world_landmarks.landmark])
        assert np.array_equal(points, image) and np.array_equal(visibility, shown)
        expected = pose_channels(image, shown, world, aspect=H / W)
        assert np.array_equal(values, expected, equal_nan=True)
    assert seen == len(frames) - 1
    tracker.close()
    whole.close()


def test_the_pose_model_without_its_mask_keeps_every_other_output():
    """`landmarks_only` on the wheel's pose landmark model: the mask's operators gone, the
    five outputs in their places (the mask a 1x1x1x1 constant), every other tensor as it was."""
    import mediapipe
    from mediapipe.tasks.metadata import schema_py_generated as schema
    from capture.camera.markerless import MODELS, landmarks_only
    path = Path(mediapipe.__file__).parent / "modules" / MODELS["pose"][1]

    def graph(data):
        return schema.ModelT.InitFromObj(schema.Model.GetRootAsModel(data, 0)).subgraphs[0]
    whole, lean = graph(path.read_bytes()), graph(landmarks_only(str(path)))
    assert 0 < len(whole.operators) - len(lean.operators) < len(whole.operators) / 4
    assert list(lean.outputs) == list(whole.outputs) and list(lean.inputs) == list(whole.inputs)
    shapes = [list(g.tensors[t].shape) for g in (whole, lean) for t in g.outputs]
    assert shapes[2] == [1, 256, 256, 1] and shapes[7] == [1, 1, 1, 1]
    assert shapes[:2] + shapes[3:5] == shapes[5:7] + shapes[8:]
    kept = {tuple(op.outputs) for op in lean.operators}
    assert kept <= {tuple(op.outputs) for op in whole.operators}
    with pytest.raises(ValueError, match="no output 5"):
        landmarks_only(str(path), drop=5)


def test_the_palm_search_runs_one_frame_in_search_every_while_no_hand_is_tracked():
    """No hand in the picture: the palm detector (observed in MediaPipe's graph) searches the
    first frame, then one frame in `search_every`; after a reset, the next frame; with
    search_every=1 every frame, as MediaPipe's own graph does. Nothing is found on any."""
    from capture.camera.trackers import make_tracker
    frame = place(astronaut(), placement(astronaut()))
    for every, expected in ((3, "S..S..S..S"), (1, "SSSSSSSSSS"), (4, "S...S...S.")):
        tracker = make_tracker("hands", search_every=every)
        searched = ""
        for _ in range(10):
            assert np.isnan(tracker.process(frame)).all()
            searched += "S" if tracker.searched else "."
        assert searched == expected
        tracker.reset()
        tracker.process(frame)
        assert tracker.searched and tracker.describe()["search_every"] == every
        tracker.close()
    with pytest.raises(ValueError, match="search_every"):
        make_tracker("hands", search_every=0)


def test_smoothing_steadies_a_still_noisy_face_and_follows_a_turn(tmp_path, rng):
    photo = astronaut()
    angles = np.r_[[0.0] * 20, np.linspace(0, 20, 8), [20.0] * 12]
    frames = []
    for angle in angles:
        frame = place(photo, placement(photo, angle=angle)).astype(np.int16)
        frame += rng.normal(0, 6, frame.shape).astype(np.int16)      # sensor noise
        frames.append(np.clip(frame, 0, 255).astype(np.uint8))
    raw = track(tmp_path, frames)
    smooth = track(tmp_path, frames, smooth=True)
    roll_raw, roll_smooth = raw[:, FACE["head_roll"]], smooth[:, FACE["head_roll"]]
    still = slice(5, 20)
    assert np.std(roll_smooth[still]) < np.std(roll_raw[still])
    # after the turn, the smoothed roll settles where the raw one is
    assert abs(roll_smooth[-1] - np.median(roll_raw[-6:])) < 1.5
    assert not math.isnan(roll_smooth[0])


def test_mop_record_takes_a_face_from_a_camera(tmp_path, capsys):
    from characters import Motion
    from mop.cli import main
    from mop.takes import TakeStore

    photo = astronaut()
    video = webcam_video(tmp_path / "nod", [place(photo, placement(photo, angle=a))
                                            for a in np.linspace(-10, 10, 25)])
    Motion({"jaw": ([0.0, 1.0], [0.0, 1.0])}).save(tmp_path / "m.json")
    folder = tmp_path / "recordings"
    assert main(["record", "--performer", "ana", "--action", "tilt", "--motion",
                 str(tmp_path / "m.json"), "--source", f"camera:{video}:face?loop=true",
                 "--recordings", str(folder), "--countdown", "0", "--preview", "none"]) == 0
    assert "stored take ana-tilt-001" in capsys.readouterr().out
    take = TakeStore(folder).load("ana-tilt-001")
    assert take.channels == FACE_CHANNELS and take.device.startswith("camera:")
    assert take.calibration["frame_size"] == [W, H]
    # the picture turns from -10 to +10 degrees (plus the photo's own tilt, about -3): however
    # many frames a busy machine tracked in the second, each is a face tilted that way
    roll = take.values[:, FACE["head_roll"]]
    assert len(roll) >= 2 and np.isfinite(roll).all()
    assert np.all((roll > -16) & (roll < 10))
    tracking = take.extra["source_stats"]["tracking"]
    assert tracking["fps"] > 0 and tracking["latency_ms"] > 0


def test_a_calibration_take_from_a_camera_names_what_the_camera_did_not_see(tmp_path, capsys):
    # the astronaut's body, still then leaning: the pose tracker sees the shoulder line, not
    # the left wrist (out of the picture); the take calibrates what it saw
    from mop.cli import main
    from mop.takes import TakeStore, calibration_of

    photo = astronaut()
    angles = np.r_[[0.0] * 30, np.linspace(0, 20, 10), [20.0] * 10, np.linspace(20, -20, 10),
                   [-20.0] * 10]
    video = write_video(tmp_path / "lean.mkv", [place(photo, placement(photo, angle=a))
                                                for a in angles])
    folder = tmp_path / "recordings"
    assert main(["record", "--performer", "ana", "--calibrate", "--duration", "60",
                 "--source", f"camera:{video}:pose?realtime=false", "--recordings",
                 str(folder), "--countdown", "0"]) == 0
    out = capsys.readouterr().out
    assert 'calibration = "ana-calibration-001"' in out
    assert re.search(r"\n  lean +rest .* range ", out)
    unseen = re.findall(r"\n  (\S+) +not calibrated: .*fewer than", out)
    take = TakeStore(folder).load("ana-calibration-001")
    assert len(take.times) >= 0.9 * len(angles)      # the file read to its end
    # the report names exactly the channels the take holds too few values of, in all or in its
    # rest part (whether the pose model places a wrist just inside the picture varies between
    # runs; a file read as fast as it tracks is stamped as it is read, so how many frames fall
    # in the rest part depends on the machine's load), never the lean
    from followers.calibration import MIN_FRAMES, REST_SECONDS
    finite = np.isfinite(np.asarray(take.values))
    resting = take.times <= take.times[0] + REST_SECONDS
    short = [name for k, name in enumerate(take.channels)
             if min(finite[:, k].sum(), finite[resting, k].sum()) < MIN_FRAMES]
    assert sorted(unseen) == sorted(short) and "lean" not in unseen
    lean = calibration_of(take, ["lean"])
    assert lean.high[0] - lean.low[0] > 25            # [deg]: the picture leant +-20
    # a session's performer bound to a channel the take did not see is told which
    unseen_channel = short[0] if short else "elbow_left"
    if not short:                                      # the model saw everything: hide one
        take.stream.values[:, take.channels.index(unseen_channel)] = np.nan
    with pytest.raises(Exception, match=f"fewer than .* '{unseen_channel}'"):
        calibration_of(take, ["lean", unseen_channel])


def test_a_glove_performer_takes_a_camera_as_it_is(tmp_path):
    """The demo's glove performer (hid:p5-style channels thumb .. pinky, followers trained on
    the glove takes) with `camera:...:hands` as its source: the session is not touched, the
    channels are found by name; with no hand in the picture the glove's characters rest."""
    from mop.session import Mode, load_session
    from mop.session.build import Overrides, build_session
    from session_files import write_session

    photo = astronaut()
    video = webcam_video(tmp_path / "hands", [place(photo, placement(photo))] * 10)
    path = write_session(tmp_path, glove_source=f"camera:{video}:hands?loop=true")
    session = build_session(load_session(path), mode=Mode.LIVE,
                            overrides=Overrides(render=False))
    states = []
    session.run(duration=1.5, progress=lambda current: states.append(current.state()))
    glove = [state["performers"]["glove"] for state in states]
    assert glove[-1]["status"] == "ok"              # frames arrive: a camera, not a failure
    assert all(state["action"] is None for state in glove[-10:])


def test_the_webcam_sessions_face_is_followed_through_its_show():
    """sessions/webcam.toml replayed from its show take (the face tracker's reading of the
    astronaut made to act): in the second half of every chomp and tilt of the show, the
    follower never names the other action and names this one on most frames (the rest are "no
    action": the bank's still-input stage, where the face's one moving channel turns and stays
    for a moment). Stand-in puppets: the characters are not what is tested."""
    from mop.session import Mode, load_session
    from mop.session.build import Overrides, build_session
    from mop.takes import TakeStore
    from session_standin import StripPuppet

    config = load_session(ROOT / "sessions" / "webcam.toml")
    characters = {"frog": (StripPuppet(("thumb", "index", "middle", "ring", "pinky")), None),
                  "momo": (StripPuppet(("head",)), None)}
    replay = Overrides(render=False, replay={"face": "replay:face_show"})
    session = build_session(config, mode=Mode.REPLAY, characters=characters, overrides=replay)
    timeline = []
    session.run(duration=15.0, progress=lambda current: timeline.append(
        (current.t, current.state()["performers"]["face"]["action"])))
    show = TakeStore(ROOT / "recordings" / "webcam").load("face_show").extra["show"]
    durations = pictures.ACTIONS          # [s] each action at the demonstration's pace
    start = 0.0
    for action, amount in show:
        length = amount if action == "rest" else durations[action] / amount
        if action != "rest":
            late = [name for t, name in timeline if start + length / 2 <= t < start + length]
            assert late and set(late) <= {f"face_{action}", None}, (action, start, late)
            assert late.count(f"face_{action}") >= 0.8 * len(late), (action, start, late)
        start += length


def test_trackers_start_and_restart_without_writing_to_the_terminal(capfd):
    # MediaPipe writes C++ log lines to fd 2 whenever a graph starts (about 75 in a benchmark
    # run); the trackers send them to logging (see native_notices)
    from capture.camera.trackers import make_tracker
    blank = np.full((H, W, 3), 90, np.uint8)
    capfd.readouterr()
    for name in ("face", "hands", "pose"):
        tracker = make_tracker(name)
        tracker.process(blank)
        tracker.reset()
        tracker.process(blank)
        tracker.close()
    assert capfd.readouterr().err == ""
