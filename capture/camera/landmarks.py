"""Landmarks -> performer channels: the geometry behind the markerless trackers.

Each function takes the landmarks a MediaPipe model returns (as arrays; the face also as a
mapping of the points it reads, `face_values`) and writes named channel values into an output
vector, NaN for what cannot be measured. The trackers in `capture.camera.markerless` call
these once per frame; tests call them on landmarks built with known angles.

Conventions (the same for every camera tracker):
- positions are fractions of the image: x from the left edge (0) to the right edge (1), y from
  the top edge (0) to the bottom edge (1);
- "left" and "right" are the performer's own (their left eye is on the image's right in an
  unmirrored camera picture);
- in-plane angles are positive counter-clockwise as the picture is seen.

Face (MediaPipe face mesh, 468 or 478 points; x, y, z in pixels, z on the x scale):
    jaw_open      inner-lip gap / 0.45 eye spans, clipped to 0..1 (0 = lips together)
    mouth_wide    mouth width (corner to corner) from 0.45 to 0.85 eye spans -> 0..1
    smile         mouth corners above the lips' centre, from -0.02 to +0.10 eye spans -> 0..1
    brow_left/right  brow height above the upper lid, from 0.10 to 0.25 eye spans -> 0..1
    blink_left/right 1 - (eye opening ratio - 0.08) / (0.25 - 0.08), clipped to 0..1 (the
                  opening ratio: mean lid gap / eye width)
    head_yaw      [deg] the face turns towards the image's right: positive
    head_pitch    [deg] the face turns up: positive
    head_roll     [deg] the head tilts counter-clockwise in the picture: positive
    head_x, head_y  the point between the eyes, as image fractions
    head_scale    face width (cheek to cheek, 3D) / image width
An "eye span" is the 3D distance between the outer eye corners: dividing by it makes the
ratios independent of how far the performer sits and of turning the head. The ranges were set
on two portraits (a neutral face reads about 0.3 on mouth_wide and brows, 0 on blinks); a
performer's own range is what a performer calibration is for.

Hand (MediaPipe hands, 21 points; image points as fractions, world points in metres):
    thumb, index, middle, ring, pinky  bend 0 (straight) .. 1 (curled into a fist): the sum of
                  the finger's joint flexions over 250 degrees (thumb: 140 degrees, its two
                  outer joints)
    pinch         1 when thumb and index tips touch (<= 0.2 palm lengths apart), 0 when they
                  are >= 0.8 palm lengths apart
    wrist_x, wrist_y  the wrist, as image fractions
    roll          [rad] the hand turned about its long axis: 0 with the palm to the camera,
                  positive when the thumb side turns towards the camera (either hand)

Pose (MediaPipe pose, 33 points; image points as fractions with a visibility each, world points
in metres):
    shoulder_left/right  [deg] upper arm from the torso: 0 hanging down, 90 level, 180 up
    elbow_left/right     [deg] 0 straight, growing as the elbow bends
    wrist_left/right     [deg] hand against forearm: 0 straight
    lean                 [deg] the shoulder line tilted counter-clockwise in the picture:
                         positive (a webcam at a desk rarely sees the hips)
    hand_left.x, hand_left.y, hand_right.x, hand_right.y  the wrists, as image fractions
                         (a wrist is given with its elbow seen)
A channel is NaN when one of the points it needs is not visible (visibility < 0.5, or placed
outside the picture).
"""
from __future__ import annotations

import math

import numpy as np

# -- face ------------------------------------------------------------------------------------

FACE_CHANNELS = ("jaw_open", "mouth_wide", "smile", "brow_left", "brow_right", "blink_left",
                 "blink_right", "head_yaw", "head_pitch", "head_roll", "head_x", "head_y",
                 "head_scale")

# face mesh indices; "right" is the performer's right (the image's left)
_EYE_R = (33, 133)           # outer, inner corner
_EYE_L = (263, 362)
_LIDS_R = ((159, 145), (158, 153), (160, 144))    # (upper, lower) lid pairs
_LIDS_L = ((386, 374), (385, 380), (387, 373))
_BROW_R, _BROW_L = (105, 66, 107), (334, 296, 336)
_UPPER_LID_R, _UPPER_LID_L = 159, 386
_LIP_INNER = (13, 14)        # upper, lower
_MOUTH_CORNERS = (61, 291)   # right, left
_FOREHEAD, _NOSE_BASE = 10, 2
_CHEEKS = (234, 454)
EYE_CORNERS = (_EYE_R[0], _EYE_L[0])    # outer: their distance (the eye span) is the face's measure

# every face mesh point the face channels read (a tracker need not unpack the others)
FACE_POINTS = tuple(sorted({*_EYE_R, *_EYE_L, *(k for pair in _LIDS_R + _LIDS_L for k in pair),
                            *_BROW_R, *_BROW_L, *_LIP_INNER, *_MOUTH_CORNERS, _FOREHEAD,
                            _NOSE_BASE, *_CHEEKS}))

# ranges mapped onto 0..1, in eye spans (see the module docstring)
JAW_OPEN_FULL = 0.45
MOUTH_WIDE_RANGE = (0.45, 0.85)
SMILE_RANGE = (-0.02, 0.10)
BROW_RANGE = (0.10, 0.25)
EYE_OPEN_RANGE = (0.08, 0.25)     # eye opening ratio of a closed .. an open eye


def _ramp(value: float, low: float, high: float) -> float:
    return min(max((value - low) / (high - low), 0.0), 1.0)


# The face's geometry is plain Python on the few points it reads: right after MediaPipe has
# run, numpy's many small calls cost about 0.5 ms a frame (its code out of the caches), these
# about 0.05 ms.

def _mid(*points) -> tuple[float, float, float]:
    n = len(points)
    return (sum(p[0] for p in points) / n, sum(p[1] for p in points) / n,
            sum(p[2] for p in points) / n)


def _viewer(a, b) -> tuple[float, float, float]:
    """b -> a in viewer axes (image y and z flipped)."""
    return (a[0] - b[0], b[1] - a[1], b[2] - a[2])


def _unit3(v) -> tuple[float, float, float]:
    norm = math.hypot(*v)
    return (v[0] / norm, v[1] / norm, v[2] / norm) if norm > 0 else (math.nan,) * 3


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def face_frame(points) -> tuple[tuple[float, float, float], ...]:
    """The face's axes (across, up, out) as rows, in a viewer frame (x right, y up, z towards
    the camera): across the eyes (to the performer's left), up the face, out of the face.

    points : face mesh landmarks [px] by index (an (N >= 468, 3) array or a mapping of the
    FACE_POINTS to (x, y, z)), image axes (y down, z away)."""
    p = points
    across = _unit3(_viewer(_mid(p[_EYE_L[0]], p[_EYE_L[1]]), _mid(p[_EYE_R[0]], p[_EYE_R[1]])))
    up = _viewer(p[_FOREHEAD], p[_NOSE_BASE])
    along = _dot(up, across)
    up = _unit3((up[0] - across[0] * along, up[1] - across[1] * along,
                 up[2] - across[2] * along))
    out = (across[1] * up[2] - across[2] * up[1], across[2] * up[0] - across[0] * up[2],
           across[0] * up[1] - across[1] * up[0])
    return across, up, out


def head_angles(frame) -> tuple[float, float, float]:
    """(yaw, pitch, roll) [deg] of a face frame (rows: across, up, out; viewer axes).

    The face's rotation is taken as yaw (about the vertical), then pitch (about the horizontal),
    then roll (about the camera's axis): turning the picture by an angle then adds exactly that
    angle to the roll and leaves yaw and pitch as they were. Roll does not change the axes'
    depth (z) components, which give yaw and pitch; the up axis' direction in the picture gives
    roll."""
    across, up, out = frame
    yaw = math.degrees(math.atan2(-across[2], out[2]))
    pitch = math.degrees(math.asin(min(max(-up[2], -1.0), 1.0)))
    roll = math.degrees(math.atan2(-up[0], up[1]))
    return yaw, pitch, roll


def face_channels(points: np.ndarray, width: int, height: int,
                  out: np.ndarray | None = None) -> np.ndarray:
    """The face channels (FACE_CHANNELS) of one face.

    points : (N >= 468, 3) float [px]: x, y in pixels of the image, z on the x scale (face mesh
        landmarks times (width, height, width)); only the rows FACE_POINTS are read; width,
        height : the image size [px].
    Returns out (13,) float."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[0] < 468 or points.shape[1] < 3:
        raise ValueError(f"face_channels needs (468 or 478, 3) landmarks, got {points.shape}")
    rows = points[list(FACE_POINTS), :3].tolist()
    return face_values(dict(zip(FACE_POINTS, rows)), width, height, out)


def face_values(points, width: int, height: int,
                out: np.ndarray | None = None) -> np.ndarray:
    """`face_channels` on a mapping {index: (x, y, z)} of (at least) the FACE_POINTS, as a
    tracker unpacks them."""
    if out is None:
        out = np.empty(len(FACE_CHANNELS))
    p = points
    dist = math.dist
    span = dist(p[_EYE_L[0]], p[_EYE_R[0]])
    if not span > 0:
        out[:] = np.nan
        return out
    frame = face_frame(p)
    up = frame[1]
    # heights along the face's up axis [eye spans]: the mouth corners above the lips' centre,
    # each brow above its upper lid
    lift = _dot(_viewer(_mid(*(p[k] for k in _MOUTH_CORNERS)),
                        _mid(*(p[k] for k in _LIP_INNER))), up) / span
    brow_left = _dot(_viewer(_mid(*(p[k] for k in _BROW_L)), p[_UPPER_LID_L]), up) / span
    brow_right = _dot(_viewer(_mid(*(p[k] for k in _BROW_R)), p[_UPPER_LID_R]), up) / span
    out[0] = min(dist(*(p[k] for k in _LIP_INNER)) / span / JAW_OPEN_FULL, 1.0)
    out[1] = _ramp(dist(*(p[k] for k in _MOUTH_CORNERS)) / span, *MOUTH_WIDE_RANGE)
    out[2] = _ramp(lift, *SMILE_RANGE)
    out[3] = _ramp(brow_left, *BROW_RANGE)
    out[4] = _ramp(brow_right, *BROW_RANGE)
    opening_left = (sum(dist(p[a], p[b]) for a, b in _LIDS_L) / 3
                    / dist(p[_EYE_L[0]], p[_EYE_L[1]]))
    opening_right = (sum(dist(p[a], p[b]) for a, b in _LIDS_R) / 3
                     / dist(p[_EYE_R[0]], p[_EYE_R[1]]))
    out[5] = 1.0 - _ramp(opening_left, *EYE_OPEN_RANGE)
    out[6] = 1.0 - _ramp(opening_right, *EYE_OPEN_RANGE)
    out[7:10] = head_angles(frame)
    between = _mid(p[_EYE_R[0]], p[_EYE_R[1]], p[_EYE_L[0]], p[_EYE_L[1]])
    out[10] = between[0] / width
    out[11] = between[1] / height
    out[12] = dist(*(p[k] for k in _CHEEKS)) / width
    return out


# -- hands ------------------------------------------------------------------------------------

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
HAND_CHANNELS = FINGERS + ("pinch", "wrist_x", "wrist_y", "roll")

_WRIST = 0
# each finger's chain of points from the wrist (or the thumb's base) to its tip
_CHAINS = {"thumb": (1, 2, 3, 4), "index": (0, 5, 6, 7, 8), "middle": (0, 9, 10, 11, 12),
           "ring": (0, 13, 14, 15, 16), "pinky": (0, 17, 18, 19, 20)}
FULL_BEND = {"thumb": 140.0, "index": 250.0, "middle": 250.0, "ring": 250.0, "pinky": 250.0}
PINCH_RANGE = (0.2, 0.8)     # thumb-index tip distance in palm lengths: touching .. apart


def _sub(a, b) -> tuple[float, float, float]:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _cross(a, b) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _square_to(v, axis) -> tuple[float, float, float]:
    """v less its part along the unit vector axis, made a unit vector."""
    along = _dot(v, axis)
    return _unit3((v[0] - axis[0] * along, v[1] - axis[1] * along, v[2] - axis[2] * along))


def _angle3(a, b) -> float:
    """[deg] between two vectors; NaN if either is zero."""
    na, nb = math.hypot(*a), math.hypot(*b)
    if not (na > 0 and nb > 0):
        return math.nan
    return math.degrees(math.acos(min(max(_dot(a, b) / (na * nb), -1.0), 1.0)))


def flexion(chain) -> float:
    """[deg] the summed bend of a chain of points (K, 3): the angles between consecutive
    segments (0 for a straight chain)."""
    chain = chain.tolist() if isinstance(chain, np.ndarray) else chain
    total = 0.0
    for a, b, c in zip(chain, chain[1:], chain[2:]):
        total += _angle3(_sub(b, a), _sub(c, b))
    return total


def hand_roll(world, *, is_left: bool) -> float:
    """[rad] the hand turned about its long axis (wrist -> middle knuckle): 0 with the palm to
    the camera, positive when the thumb side turns towards the camera.

    world : (21, 3) float [m], camera axes (x right, y down, z away from the camera)."""
    world = world.tolist() if isinstance(world, np.ndarray) else world
    long_axis = _unit3(_sub(world[9], world[_WRIST]))
    # pinky knuckle -> index knuckle: the thumb side
    across = _square_to(_sub(world[5], world[17]), long_axis)
    facing = _square_to((0.0, 0.0, -1.0), long_axis)      # towards the camera
    # with the palm to the camera, `across` is perpendicular to the view; it turns towards
    # the camera (facing) as the thumb side comes forward
    side = _dot(across, _cross(long_axis, facing))
    # palm to the camera, the right hand's thumb points to the image's right, the left's to
    # its left: one sign for both hands
    if is_left:
        side = -side
    return math.atan2(_dot(across, facing), side)


def hand_channels(image: np.ndarray, world: np.ndarray, *, is_left: bool,
                  out: np.ndarray | None = None) -> np.ndarray:
    """The channels of one hand (HAND_CHANNELS).

    image : (21, 2+) float, x and y as fractions of the image; world : (21, 3) float [m],
    camera axes; is_left : the performer's left hand. Returns out (9,) float."""
    if out is None:
        out = np.empty(len(HAND_CHANNELS))
    world = np.asarray(world, dtype=np.float64)
    image = np.asarray(image, dtype=np.float64)
    if world.shape != (21, 3) or image.ndim != 2 or image.shape[0] != 21:
        raise ValueError(f"hand_channels needs (21, 3) landmarks, got {image.shape} and "
                         f"{world.shape}")
    points = world.tolist()       # plain Python from here: see the face's geometry
    for slot, finger in enumerate(FINGERS):
        bend = flexion([points[k] for k in _CHAINS[finger]])
        out[slot] = min(max(bend / FULL_BEND[finger], 0.0), 1.0)
    palm = math.dist(points[9], points[_WRIST])
    tips = math.dist(points[4], points[8])
    out[5] = 1.0 - _ramp(tips / palm, *PINCH_RANGE) if palm > 0 else math.nan
    out[6], out[7] = image[_WRIST, 0], image[_WRIST, 1]
    out[8] = hand_roll(points, is_left=is_left)
    return out


# -- pose -------------------------------------------------------------------------------------

POSE_CHANNELS = ("shoulder_left", "shoulder_right", "elbow_left", "elbow_right", "wrist_left",
                 "wrist_right", "lean", "hand_left.x", "hand_left.y", "hand_right.x",
                 "hand_right.y")
# pose indices, the performer's left / right
_SHOULDER = {"left": 11, "right": 12}
_ELBOW = {"left": 13, "right": 14}
_WRIST_POSE = {"left": 15, "right": 16}
_PINKY = {"left": 17, "right": 18}
_INDEX = {"left": 19, "right": 20}
_HIP = {"left": 23, "right": 24}
VISIBLE = 0.5


def pose_channels(image: np.ndarray, visibility: np.ndarray, world: np.ndarray, *,
                  aspect: float = 0.75, out: np.ndarray | None = None) -> np.ndarray:
    """The pose channels (POSE_CHANNELS).

    image : (33, 2+) float, x and y as fractions of the image; visibility : (33,) float 0..1;
    world : (33, 3) float [m], camera axes (x right, y down, z away); aspect : image height /
    width (to measure the shoulder line's angle in pixels). Returns out (11,)."""
    if out is None:
        out = np.empty(len(POSE_CHANNELS))
    image = np.asarray(image, dtype=np.float64)
    world = np.asarray(world, dtype=np.float64)
    visibility = np.asarray(visibility, dtype=np.float64)
    if image.shape[0] != 33 or world.shape != (33, 3) or visibility.shape != (33,):
        raise ValueError(f"pose_channels needs 33 landmarks, got {image.shape}, {world.shape}, "
                         f"{visibility.shape}")
    # plain Python from here (see the face's geometry); the model also places points beyond
    # the picture's edges: those are not seen either
    image, world = image[:, :2].tolist(), world.tolist()
    seen = [v >= VISIBLE and 0.0 <= x <= 1.0 and 0.0 <= y <= 1.0
            for v, (x, y) in zip(visibility.tolist(), image)]
    out[:] = np.nan
    left, right = _SHOULDER["left"], _SHOULDER["right"]
    shoulders = _mid(world[left], world[right])
    if seen[_HIP["left"]] and seen[_HIP["right"]]:
        down = _sub(_mid(world[_HIP["left"]], world[_HIP["right"]]), shoulders)
    else:
        # hips out of the picture: the image's down, square to the shoulder line
        line = _unit3(_sub(world[left], world[right]))
        down = (-line[0] * line[1], 1.0 - line[1] * line[1], -line[2] * line[1])
    for slot, side in enumerate(("left", "right")):
        shoulder, elbow, wrist = _SHOULDER[side], _ELBOW[side], _WRIST_POSE[side]
        upper_arm = _sub(world[elbow], world[shoulder])
        forearm = _sub(world[wrist], world[elbow])
        if seen[shoulder] and seen[elbow]:
            out[slot] = _angle3(upper_arm, down)
        if seen[shoulder] and seen[elbow] and seen[wrist]:
            out[2 + slot] = _angle3(upper_arm, forearm)
        if seen[elbow] and seen[wrist] and seen[_PINKY[side]] and seen[_INDEX[side]]:
            hand = _mid(world[_PINKY[side]], world[_INDEX[side]])
            out[4 + slot] = _angle3(forearm, _sub(hand, world[wrist]))
        if seen[elbow] and seen[wrist]:
            # a wrist without its elbow is a guess: with the arm beyond the picture the model
            # places the wrist just inside its edge, with a visibility over 0.5
            out[7 + 2 * slot], out[8 + 2 * slot] = image[wrist]
    if seen[left] and seen[right]:
        # the performer's right shoulder is on the image's left; y points down, so a line
        # turned counter-clockwise rises to the right
        dx, dy = image[left][0] - image[right][0], image[left][1] - image[right][1]
        out[6] = math.degrees(math.atan2(-dy * aspect, dx))
    return out
