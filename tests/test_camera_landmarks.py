"""The geometry of the markerless trackers (`capture.camera.landmarks`) and the One Euro filter,
checked on landmarks built here with known angles, openings and positions (the answer is known
exactly), and the filter against a slow one-channel transcription of the published algorithm."""
import math

import numpy as np
import pytest

from capture.camera import landmarks as lm
from capture.camera.smoothing import OneEuroConfig, OneEuroFilter

W, H = 640, 480


# -- face ------------------------------------------------------------------------------------

def rotation(yaw, pitch, roll):
    """Viewer axes (x right, y up, z towards the viewer): yaw turns the face to the viewer's
    right, then pitch turns it up, then roll turns it counter-clockwise."""
    y, p, r = np.radians([yaw, pitch, roll])
    turn = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    nod = np.array([[1, 0, 0], [0, math.cos(p), math.sin(p)], [0, -math.sin(p), math.cos(p)]])
    tilt = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
    return tilt @ nod @ turn


def synthetic_face(*, yaw=0.0, pitch=0.0, roll=0.0, span_px=80.0, centre=(300.0, 200.0),
                   lip_gap=0.0, mouth_width=0.6, lift=0.0, eye_opening=0.3, brow=0.15):
    """(478, 3) face mesh landmarks [px] of a face whose every measure is given: in face
    units of one eye span (outer eye corner to outer eye corner), before turning it."""
    face = np.zeros((478, 3))
    eye_width = 0.35
    for outer, inner, lids, sign in ((33, 133, lm._LIDS_R, -1), (263, 362, lm._LIDS_L, 1)):
        face[outer] = (sign * 0.5, 0, 0)
        face[inner] = (sign * 0.15, 0, 0)
        for k, (upper, lower) in enumerate(lids):
            x = sign * (0.25 + 0.05 * (k - 1))
            face[upper] = (x, eye_opening * eye_width / 2, 0.02)
            face[lower] = (x, -eye_opening * eye_width / 2, 0.02)
    for brow_points, sign in ((lm._BROW_R, -1), (lm._BROW_L, 1)):
        for k, index in enumerate(brow_points):
            face[index] = (sign * (0.2 + 0.05 * k), eye_opening * eye_width / 2 + brow, 0.05)
    face[lm._FOREHEAD] = (0, 0.8, 0)
    face[lm._NOSE_BASE] = (0, -0.6, 0)
    face[13] = (0, -0.9 + lip_gap / 2, 0.1)
    face[14] = (0, -0.9 - lip_gap / 2, 0.1)
    face[61] = (-mouth_width / 2, -0.9 + lift, 0.05)
    face[291] = (mouth_width / 2, -0.9 + lift, 0.05)
    face[234] = (-0.9, 0, -0.3)
    face[454] = (0.9, 0, -0.3)
    viewer = face @ rotation(yaw, pitch, roll).T * span_px
    # viewer axes -> image axes (y down, z away from the camera), pixels
    return np.c_[centre[0] + viewer[:, 0], centre[1] - viewer[:, 1], -viewer[:, 2]]


@pytest.mark.parametrize("yaw, pitch, roll", [(0, 0, 0), (25, 0, 0), (0, -20, 0), (0, 0, 35),
                                              (-30, 15, -20), (40, -25, 60)])
def test_head_angles_are_recovered_exactly(yaw, pitch, roll):
    values = lm.face_channels(synthetic_face(yaw=yaw, pitch=pitch, roll=roll), W, H)
    channel = dict(zip(lm.FACE_CHANNELS, values))
    assert channel["head_yaw"] == pytest.approx(yaw, abs=1e-9)
    assert channel["head_pitch"] == pytest.approx(pitch, abs=1e-9)
    assert channel["head_roll"] == pytest.approx(roll, abs=1e-9)


def test_face_channels_read_only_the_points_a_tracker_unpacks(rng):
    face = synthetic_face(yaw=10, roll=5, lip_gap=0.1)
    scrambled = rng.normal(0, 500, face.shape)
    scrambled[list(lm.FACE_POINTS)] = face[list(lm.FACE_POINTS)]
    np.testing.assert_array_equal(lm.face_channels(scrambled, W, H),
                                  lm.face_channels(face, W, H))


def test_face_values_need_only_the_points_a_tracker_unpacks():
    face = synthetic_face(yaw=-15, pitch=8, roll=20, lip_gap=0.2, lift=0.03)
    points = {k: tuple(face[k]) for k in lm.FACE_POINTS}
    np.testing.assert_array_equal(lm.face_values(points, W, H), lm.face_channels(face, W, H))


def test_turning_the_picture_adds_to_the_roll_only():
    turned = lm.face_channels(synthetic_face(yaw=20, pitch=-10, roll=25), W, H)
    still = lm.face_channels(synthetic_face(yaw=20, pitch=-10, roll=0), W, H)
    index = {name: k for k, name in enumerate(lm.FACE_CHANNELS)}
    assert turned[index["head_roll"]] - still[index["head_roll"]] == pytest.approx(25)
    for name in ("head_yaw", "head_pitch", "jaw_open", "mouth_wide", "smile", "blink_left",
                 "brow_right", "head_scale"):
        assert turned[index[name]] == pytest.approx(still[index[name]], abs=1e-9), name


def test_face_measures_in_eye_spans_whatever_the_size_and_turn():
    for span_px, yaw, roll in ((60.0, 0.0, 0.0), (150.0, 30.0, -15.0)):
        values = lm.face_channels(synthetic_face(
            span_px=span_px, yaw=yaw, roll=roll, centre=(400, 150), lip_gap=0.18,
            mouth_width=0.65, lift=0.04, eye_opening=0.165, brow=0.2), W, H)
        channel = dict(zip(lm.FACE_CHANNELS, values))
        assert channel["jaw_open"] == pytest.approx(0.18 / 0.45)
        assert channel["mouth_wide"] == pytest.approx((0.65 - 0.45) / 0.4)
        assert channel["smile"] == pytest.approx((0.04 + 0.02) / 0.12)
        assert channel["blink_left"] == pytest.approx(1 - (0.165 - 0.08) / 0.17)
        assert channel["blink_right"] == pytest.approx(channel["blink_left"])
        assert channel["brow_left"] == pytest.approx((0.2 - 0.1) / 0.15)
        assert channel["head_x"] == pytest.approx(400 / W)
        assert channel["head_y"] == pytest.approx(150 / H)
        assert channel["head_scale"] == pytest.approx(1.8 * span_px / W)


def test_face_ranges_clip_to_0_1():
    wide_open = lm.face_channels(synthetic_face(lip_gap=0.9, eye_opening=0.0, brow=0.5,
                                                mouth_width=1.2, lift=0.3), W, H)
    channel = dict(zip(lm.FACE_CHANNELS, wide_open))
    for name in ("jaw_open", "blink_left", "blink_right", "brow_left", "mouth_wide", "smile"):
        assert channel[name] == 1.0
    with pytest.raises(ValueError, match="468 or 478"):
        lm.face_channels(np.zeros((21, 3)), W, H)


# -- hands -----------------------------------------------------------------------------------

def synthetic_hand(bends, *, side="right", roll=0.0, thumb=(0.0, 0.0), pinch_gap=None):
    """(image (21, 3), world (21, 3) [m]) of a hand held up, palm to the camera, turned by
    `roll` [rad] about its long axis (thumb side towards the camera for roll > 0).

    bends : {finger: (mcp, pip, dip) flexion [deg]}, fingers curling towards the palm;
    thumb : (mcp, ip) flexion [deg]; pinch_gap : [m] put the thumb tip this far from the index
    tip (towards the camera) instead."""
    long_axis = np.array([0.0, -1.0, 0.0])                 # fingers up (camera y points down)
    sideways = 1.0 if side == "right" else -1.0            # the thumb's side in the picture
    across = np.array([sideways * math.cos(roll), 0.0, -math.sin(roll)])
    palm = np.cross(across, long_axis) * sideways          # the way the palm faces
    world = np.zeros((21, 3))
    knuckles = {"index": (5, 0.03), "middle": (9, 0.0), "ring": (13, -0.02),
                "pinky": (17, -0.04)}
    for finger, (base, offset) in knuckles.items():
        world[base] = 0.09 * long_axis + offset * across
        direction = world[base] / np.linalg.norm(world[base])
        # bending turns the direction towards the palm, in the plane of the two
        bend_axis = np.cross(direction, palm)
        angle = 0.0
        for k, (flex, length) in enumerate(zip(bends.get(finger, (0, 0, 0)),
                                               (0.04, 0.025, 0.02))):
            angle += math.radians(flex)
            step = direction * math.cos(angle) + palm * math.sin(angle)
            world[base + k + 1] = world[base + k] + length * step
        assert np.allclose(bend_axis @ palm, 0)
    world[1] = 0.02 * long_axis + 0.03 * across
    world[2] = world[1] + 0.035 * (0.6 * long_axis + 0.8 * across)
    direction = (world[2] - world[1]) / np.linalg.norm(world[2] - world[1])
    angle = 0.0
    for k, flex in enumerate(thumb):
        angle += math.radians(flex)
        world[3 + k] = world[2 + k] + 0.03 * (direction * math.cos(angle) + palm * math.sin(angle))
    if pinch_gap is not None:
        world[4] = world[8] + pinch_gap * np.array([0, 0, -1.0])
    image = np.c_[0.5 + world[:, 0] * 2, 0.6 + world[:, 1] * 2, world[:, 2]]
    return image, world


def test_finger_bends_are_the_joint_flexions_over_a_full_bend():
    bends = {"index": (10, 20, 10), "middle": (60, 90, 50), "ring": (90, 110, 80),
             "pinky": (0, 0, 0)}
    for side in ("right", "left"):
        image, world = synthetic_hand(bends, side=side, thumb=(30, 40))
        values = dict(zip(lm.HAND_CHANNELS,
                          lm.hand_channels(image, world, is_left=side == "left")))
        assert values["index"] == pytest.approx(40 / 250)
        assert values["middle"] == pytest.approx(200 / 250)
        assert values["ring"] == pytest.approx(1.0)              # 280 degrees: clipped
        assert values["pinky"] == pytest.approx(0.0, abs=1e-6)
        assert values["thumb"] == pytest.approx(70 / 140)
        assert values["wrist_x"] == pytest.approx(0.5) and values["wrist_y"] == pytest.approx(0.6)


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("roll", [0.0, 0.4, -0.7, 1.2])
def test_hand_roll_about_its_long_axis(side, roll):
    image, world = synthetic_hand({}, side=side, roll=roll)
    values = dict(zip(lm.HAND_CHANNELS, lm.hand_channels(image, world, is_left=side == "left")))
    assert values["roll"] == pytest.approx(roll, abs=1e-9)
    # fingers' bends do not depend on how the hand is turned
    assert values["index"] == pytest.approx(0.0, abs=1e-6)


def test_pinch_from_the_tips_distance_in_palm_lengths():
    palm = 0.09                                  # wrist to middle knuckle [m]
    for gap, expected in ((0.0, 1.0), (0.2 * palm, 1.0), (0.5 * palm, 0.5), (0.9 * palm, 0.0)):
        image, world = synthetic_hand({}, pinch_gap=gap)
        values = dict(zip(lm.HAND_CHANNELS, lm.hand_channels(image, world, is_left=False)))
        assert values["pinch"] == pytest.approx(expected)


def test_hand_channels_share_the_glove_profiles_finger_names():
    from capture.hid.profile import available_profiles
    glove = available_profiles()["p5"]
    names = {field.channel for report in glove.reports for field in report.fields}
    assert set(lm.FINGERS) <= names
    assert lm.HAND_CHANNELS[:5] == lm.FINGERS


def test_hands_keep_their_sides():
    from capture.camera.markerless import assign_sides
    nobody = {"right": None, "left": None}
    assert assign_sides([], nobody) == []
    assert assign_sides([("left", 0.95, (0.7, 0.5)), ("right", 0.9, (0.3, 0.5))],
                        nobody) == ["left", "right"]
    # both called right: the surer keeps it
    assert assign_sides([("right", 0.6, (0.7, 0.5)), ("right", 0.9, (0.3, 0.5))],
                        nobody) == ["left", "right"]
    # a lone hand, unsure, where the left hand was a frame ago: still the left hand
    last = {"right": None, "left": (0.72, 0.5)}
    assert assign_sides([("right", 0.6, (0.7, 0.52))], last) == ["left"]
    # ... but sure of itself, or far from where the left one was, it is what it says
    assert assign_sides([("right", 0.95, (0.7, 0.52))], last) == ["right"]
    last = {"right": (0.3, 0.5), "left": (0.72, 0.5)}
    assert assign_sides([("right", 0.6, (0.32, 0.5))], last) == ["right"]
    # partly out of the picture, its wrist beyond the edge: read from a part, unsure however
    # sure MediaPipe says it is
    last = {"right": None, "left": (0.98, 0.5)}
    assert assign_sides([("right", 0.95, (1.08, 0.5))], last) == ["left"]
    assert assign_sides([("right", 0.95, (0.9, 0.5))], last) == ["right"]


def test_one_hand_found_twice_is_one_hand():
    from capture.camera.markerless import one_per_hand
    # 21 image points [px]: the wrist at the origin, the middle knuckle (9) 100 px up
    hand = np.c_[np.tile(np.linspace(-40, 40, 5), 5)[:21] + 0.0,
                 -np.repeat(np.linspace(0, 200, 5), 5)[:21]]
    hand[0], hand[9] = (0.0, 0.0), (0.0, -100.0)
    assert one_per_hand([hand], [0.9]) == [0]
    # the same hand read twice, the second's wrist 60 px off (as tracked in a stale box): the
    # surer one stays, whichever comes first
    ghost = hand + 3.0
    ghost[0] += (0.0, 60.0)
    assert one_per_hand([hand, ghost], [0.88, 0.68]) == [0]
    assert one_per_hand([ghost, hand], [0.68, 0.88]) == [1]
    # two hands side by side, or one across the other's fingers: both stay
    assert one_per_hand([hand, hand + (120.0, 0.0)], [0.9, 0.9]) == [0, 1]
    assert one_per_hand([hand, hand + (0.0, -60.0)], [0.9, 0.9]) == [0, 1]


# -- pose ------------------------------------------------------------------------------------

def synthetic_body(*, raise_left=30.0, elbow_left=45.0, wrist_left=20.0, raise_right=90.0,
                   elbow_right=0.0, turn=0.0):
    """(image (33, 3), visibility (33,), world (33, 3) [m]) of a body facing the camera with
    the arms in its frontal plane: shoulders raised by `raise_*` from hanging, elbows and
    wrists bent by `elbow_*`, `wrist_*` [deg]; the picture turned `turn` degrees
    counter-clockwise."""
    world = np.zeros((33, 3))
    world[lm._SHOULDER["left"]] = (0.2, -0.5, 0)
    world[lm._SHOULDER["right"]] = (-0.2, -0.5, 0)
    world[lm._HIP["left"]] = (0.15, 0, 0)
    world[lm._HIP["right"]] = (-0.15, 0, 0)
    for side, raise_, elbow, wrist, out in (("left", raise_left, elbow_left, wrist_left, 1),
                                            ("right", raise_right, elbow_right, 0.0, -1)):
        angle = math.radians(raise_)
        direction = np.array([out * math.sin(angle), math.cos(angle), 0])
        world[lm._ELBOW[side]] = world[lm._SHOULDER[side]] + 0.3 * direction
        angle += math.radians(elbow)
        direction = np.array([out * math.sin(angle), math.cos(angle), 0])
        world[lm._WRIST_POSE[side]] = world[lm._ELBOW[side]] + 0.25 * direction
        angle += math.radians(wrist)
        direction = np.array([out * math.sin(angle), math.cos(angle), 0])
        for point in (lm._PINKY[side], lm._INDEX[side]):
            world[point] = world[lm._WRIST_POSE[side]] + 0.08 * direction
    t = math.radians(turn)
    # counter-clockwise in the picture, whose y points down
    spin = np.array([[math.cos(t), math.sin(t), 0], [-math.sin(t), math.cos(t), 0], [0, 0, 1]])
    world = world @ spin.T
    # a 640 x 480 picture (aspect 0.75), 0.5 of its width per metre
    image = np.c_[0.5 + world[:, 0] * 0.5, 0.6 + world[:, 1] * 0.5 / 0.75, world[:, 2]]
    return image, np.ones(33), world


def test_arm_angles_and_lean_from_a_known_body():
    image, visibility, world = synthetic_body(turn=12.0)
    values = dict(zip(lm.POSE_CHANNELS, lm.pose_channels(image, visibility, world,
                                                         aspect=0.75)))
    assert values["shoulder_left"] == pytest.approx(30.0)
    assert values["shoulder_right"] == pytest.approx(90.0)
    assert values["elbow_left"] == pytest.approx(45.0)
    assert values["elbow_right"] == pytest.approx(0.0, abs=1e-6)
    assert values["wrist_left"] == pytest.approx(20.0)
    assert values["lean"] == pytest.approx(12.0)
    wrist = lm._WRIST_POSE["left"]
    assert (values["hand_left.x"], values["hand_left.y"]) == pytest.approx(tuple(image[wrist, :2]))


def test_pose_channels_are_nan_for_what_is_not_seen():
    image, visibility, world = synthetic_body()
    visibility[lm._ELBOW["right"]] = 0.2
    visibility[[lm._HIP["left"], lm._HIP["right"]]] = 0.0     # hips below the picture
    image[lm._WRIST_POSE["left"], 1] = 1.05                   # placed beyond the bottom edge
    values = dict(zip(lm.POSE_CHANNELS, lm.pose_channels(image, visibility, world,
                                                         aspect=0.75)))
    assert math.isnan(values["shoulder_right"]) and math.isnan(values["elbow_right"])
    assert math.isnan(values["elbow_left"]) and math.isnan(values["hand_left.y"])
    # a wrist in view without its elbow is not given (a guess where the arm is out of view)
    assert math.isnan(values["hand_right.x"]) and math.isnan(values["hand_right.y"])
    # without hips the arm is measured from the picture's down, square to the shoulders
    assert values["shoulder_left"] == pytest.approx(30.0)
    assert np.isfinite(values["lean"])


# -- One Euro ---------------------------------------------------------------------------------

def one_euro_reference(times, values, min_cutoff, beta, d_cutoff):
    """The One Euro filter for one channel, written out step by step as published."""
    def alpha(cutoff, dt):
        tau = 1.0 / (2 * math.pi * cutoff)
        return 1.0 / (1.0 + tau / dt)
    out = [values[0]]
    x_hat, dx_hat = values[0], 0.0
    for k in range(1, len(values)):
        dt = times[k] - times[k - 1]
        dx = (values[k] - x_hat) / dt
        dx_hat = alpha(d_cutoff, dt) * dx + (1 - alpha(d_cutoff, dt)) * dx_hat
        cutoff = min_cutoff + beta * abs(dx_hat)
        x_hat = alpha(cutoff, dt) * values[k] + (1 - alpha(cutoff, dt)) * x_hat
        out.append(x_hat)
    return np.array(out)


def test_one_euro_matches_the_reference_per_channel(rng):
    times = np.cumsum(rng.uniform(0.02, 0.05, 200))
    signal = np.c_[np.sin(times * 3) + rng.normal(0, 0.05, 200),
                   30 * np.cos(times) + rng.normal(0, 2.0, 200)]
    config = OneEuroConfig(min_cutoff=1.2, beta=0.7, d_cutoff=1.0)
    scale = np.array([1.0, 30.0])
    smoother = OneEuroFilter(scale, config)
    got = np.array([smoother.filter(t, row) for t, row in zip(times, signal)])
    for k in range(2):
        # a channel's scale divides its speed: the same as beta / scale for that channel
        expected = one_euro_reference(times, signal[:, k], 1.2, 0.7 / scale[k], 1.0)
        np.testing.assert_allclose(got[:, k], expected, rtol=1e-12, atol=1e-12)
    assert np.std(np.diff(got[:, 0])) < np.std(np.diff(signal[:, 0]))


def test_one_euro_passes_nan_and_starts_afresh():
    smoother = OneEuroFilter([1.0, 1.0])
    assert np.allclose(smoother.filter(0.0, np.array([0.0, 5.0])), [0.0, 5.0])
    step = smoother.filter(0.04, np.array([1.0, np.nan]))
    assert 0.0 < step[0] < 1.0 and math.isnan(step[1])
    # the second channel comes back far away: no pull from where it was lost
    assert smoother.filter(0.08, np.array([1.0, -3.0]))[1] == -3.0
    # time going back (a file looping) starts everything afresh
    assert np.allclose(smoother.filter(0.0, np.array([7.0, 7.0])), [7.0, 7.0])
    with pytest.raises(ValueError, match="min_cutoff"):
        OneEuroConfig(min_cutoff=0)
    with pytest.raises(ValueError, match="beta"):
        OneEuroConfig(beta=-1)
