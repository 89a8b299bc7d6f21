"""Trackers: one camera image in, one (D,) vector of channel values out (NaN = not found).

Markerless (MediaPipe, `pip install 'mop[vision]'`; see `capture.camera.markerless`):
- "face" `FaceMeshTracker`: mouth, brows, blinks, head angles, position and size.
- "hands" `HandsTracker`: the glove's five finger bends, pinch, wrist position and roll, per hand.
- "pose" `PoseTracker`: shoulder, elbow and wrist angles, lean, the hands' positions.

OpenCV only (`pip install 'mop[capture]'`), defined here:
- "aruco" `ArucoTracker`: pose of ArUco markers (position [m] and rotation vector [rad] per
  marker id) with `cv2.solvePnP(..., SOLVEPNP_IPPE_SQUARE)`.
- "color" `ColorBlobTracker`: coloured markers or a colour glove: the largest HSV blob of each
  colour -> position (normalised image coordinates) and area.
- "haar" `HaarFaceTracker`: the face box (Haar cascade), the two eyes inside it, and a smile
  flag: a face tracker for installs without MediaPipe.
- "silhouette" (or "hand") `SilhouetteTracker`: a hand silhouette: contour, convex hull and
  convexity defects -> position, area, openness and the number of gaps between spread fingers;
  it also reads a hand's shadow or a lit hand on a dark ground, which MediaPipe does not.

Each tracker allocates its working images once (for the first frame size) and reuses them.
OpenCV is imported when a tracker is built; MediaPipe when a markerless tracker is.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from .base import Tracker, _cv2, _image
from .markerless import FaceMeshTracker, HandsTracker, PoseTracker


def default_camera_matrix(width: int, height: int, *, focal_length: float | None = None
                          ) -> np.ndarray:
    """Pinhole intrinsics when no calibration is given: focal length = image width [px]
    (about a 53 degree horizontal field of view), principal point at the image centre.
    Returns (3, 3) float64."""
    f = float(width if focal_length is None else focal_length)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0, 0, 1.0]])


class ArucoTracker(Tracker):
    """ArUco marker poses.

    Channels per id: aruco<id>.x, .y, .z [m] (marker centre in the camera frame: x right,
    y down, z forward) and .rx, .ry, .rz [rad] (rotation vector, marker to camera).

    Parameters (keyword-only)
    -------------------------
    ids : marker ids to report (others are ignored).
    marker_length : [m] side of the black square.
    dictionary : an OpenCV predefined dictionary name, e.g. "DICT_4X4_50".
    camera_matrix : (3, 3) intrinsics [px]; dist_coeffs : (k,) distortion. Without them
        `default_camera_matrix` is used (set focal_length [px] to adjust it).
    corner_refinement : "subpix" (default; about 3x more accurate positions than "none" on
        rendered markers at the same cost), "none", "contour" or "apriltag" (most accurate,
        about twice as slow).
    """
    name = "aruco"

    def __init__(self, *, ids: Sequence[int] = (0,), marker_length: float = 0.05,
                 dictionary: str = "DICT_4X4_50", camera_matrix=None, dist_coeffs=None,
                 focal_length: float | None = None, corner_refinement: str = "subpix"):
        cv2 = _cv2()
        self.ids = tuple(int(i) for i in ids)
        if not self.ids:
            raise ValueError("ArucoTracker needs at least one marker id")
        if not marker_length > 0:
            raise ValueError(f"marker_length must be > 0 m, got {marker_length!r}")
        code = getattr(cv2.aruco, dictionary, None)
        if not isinstance(dictionary, str) or code is None or not dictionary.startswith("DICT_"):
            raise ValueError(f"unknown ArUco dictionary {dictionary!r}; e.g. DICT_4X4_50, "
                             f"DICT_5X5_100, DICT_6X6_250")
        self.dictionary = dictionary
        self.marker_length = float(marker_length)
        self.focal_length = focal_length
        methods = {"none": cv2.aruco.CORNER_REFINE_NONE, "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
                   "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
                   "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG}
        if corner_refinement not in methods:
            raise ValueError(f"corner_refinement must be one of {sorted(methods)}, got "
                             f"{corner_refinement!r}")
        self.corner_refinement = corner_refinement
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = methods[corner_refinement]
        self._detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(code),
                                                 parameters)
        self.camera_matrix = None if camera_matrix is None else np.asarray(camera_matrix,
                                                                           np.float64)
        if self.camera_matrix is not None and self.camera_matrix.shape != (3, 3):
            raise ValueError(f"camera_matrix must be (3, 3), got {self.camera_matrix.shape}")
        self.dist_coeffs = (np.zeros(5) if dist_coeffs is None
                            else np.asarray(dist_coeffs, np.float64).ravel())
        half = self.marker_length / 2.0
        # corner order of the detector: top-left, top-right, bottom-right, bottom-left
        self._object = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0],
                                 [-half, -half, 0]], np.float64)
        self._index = {marker: k for k, marker in enumerate(self.ids)}
        self.channels = tuple(f"aruco{m}.{axis}" for m in self.ids
                              for axis in ("x", "y", "z", "rx", "ry", "rz"))
        self._gray: np.ndarray | None = None
        self._flag = cv2.SOLVEPNP_IPPE_SQUARE

    def describe(self) -> dict:
        return {"tracker": self.name, "ids": list(self.ids), "marker_length": self.marker_length,
                "dictionary": self.dictionary, "corner_refinement": self.corner_refinement,
                "camera_matrix": None if self.camera_matrix is None
                else self.camera_matrix.tolist(), "dist_coeffs": self.dist_coeffs.tolist()}

    def process(self, image: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        image = _image(image)
        height, width = image.shape[:2]
        if self._gray is None or self._gray.shape != (height, width):
            self._gray = np.empty((height, width), np.uint8)
            if self.camera_matrix is None:
                self._matrix = default_camera_matrix(width, height,
                                                     focal_length=self.focal_length)
            else:
                self._matrix = self.camera_matrix
        cv2.cvtColor(image, cv2.COLOR_BGR2GRAY, dst=self._gray)
        out = np.full(len(self.channels), np.nan)
        corners, ids, _ = self._detector.detectMarkers(self._gray)
        if ids is None:
            return out
        for marker_corners, marker in zip(corners, ids.ravel()):
            slot = self._index.get(int(marker))
            if slot is None:
                continue
            ok, rvec, tvec = cv2.solvePnP(self._object, marker_corners.reshape(4, 2).astype(
                np.float64), self._matrix, self.dist_coeffs, flags=self._flag)
            if ok:
                out[6 * slot:6 * slot + 3] = tvec.ravel()
                out[6 * slot + 3:6 * slot + 6] = rvec.ravel()
        return out


DEFAULT_COLORS: dict[str, list[tuple[tuple[int, int, int], tuple[int, int, int]]]] = {
    # OpenCV HSV: hue 0..179, saturation and value 0..255; red wraps around hue 0
    "red": [((0, 120, 70), (8, 255, 255)), ((172, 120, 70), (179, 255, 255))],
    "yellow": [((22, 120, 100), (34, 255, 255))],
    "green": [((45, 100, 60), (80, 255, 255))],
    "blue": [((100, 120, 60), (128, 255, 255))],
}


class ColorBlobTracker(Tracker):
    """The largest blob of each colour: <colour>.x, <colour>.y (centroid, 0..1 across the image
    width / height) and <colour>.area (fraction of the image). NaN when a colour is not seen.

    colors : {name: [(hsv_low, hsv_high), ...]} OpenCV HSV ranges (hue 0..179), default red,
        yellow, green, blue; or a list of names from the defaults.
    min_area : [fraction of the image] smaller blobs are ignored.
    """
    name = "color"

    def __init__(self, *, colors: Mapping | Sequence[str] | None = None,
                 min_area: float = 2e-4):
        if colors is None:
            colors = DEFAULT_COLORS
        elif isinstance(colors, str):
            colors = [c for c in colors.split(",") if c]
        if not isinstance(colors, Mapping):
            unknown = [c for c in colors if c not in DEFAULT_COLORS]
            if unknown:
                raise ValueError(f"unknown colours {unknown}; named colours are "
                                 f"{sorted(DEFAULT_COLORS)} (or pass HSV ranges)")
            colors = {c: DEFAULT_COLORS[c] for c in colors}
        self.colors: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        for name, ranges in colors.items():
            checked = []
            for low, high in ranges:
                low = np.array(low, np.uint8)
                high = np.array(high, np.uint8)
                if low.shape != (3,) or high.shape != (3,):
                    raise ValueError(f"colour {name!r}: HSV bounds must be 3 numbers each")
                checked.append((low, high))
            if not checked:
                raise ValueError(f"colour {name!r} has no HSV range")
            self.colors[str(name)] = checked
        if not 0 <= min_area < 1:
            raise ValueError(f"min_area is a fraction of the image in [0, 1), got {min_area!r}")
        self.min_area = float(min_area)
        self.channels = tuple(f"{c}.{k}" for c in self.colors for k in ("x", "y", "area"))
        self._hsv = self._mask = self._part = None

    def describe(self) -> dict:
        return {"tracker": self.name, "min_area": self.min_area,
                "colors": {c: [(lo.tolist(), hi.tolist()) for lo, hi in r]
                           for c, r in self.colors.items()}}

    def process(self, image: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        image = _image(image)
        height, width = image.shape[:2]
        if self._hsv is None or self._hsv.shape[:2] != (height, width):
            self._hsv = np.empty((height, width, 3), np.uint8)
            self._mask = np.empty((height, width), np.uint8)
            self._part = np.empty((height, width), np.uint8)
        cv2.cvtColor(image, cv2.COLOR_BGR2HSV, dst=self._hsv)
        out = np.full(len(self.channels), np.nan)
        pixels = float(height * width)
        for k, ranges in enumerate(self.colors.values()):
            cv2.inRange(self._hsv, ranges[0][0], ranges[0][1], dst=self._mask)
            for low, high in ranges[1:]:
                cv2.inRange(self._hsv, low, high, dst=self._part)
                cv2.bitwise_or(self._mask, self._part, dst=self._mask)
            # the largest outer contour picks the blob (much cheaper than labelling every
            # component); its pixels' moments inside its bounding box give centroid and area
            contours, _ = cv2.findContours(self._mask, cv2.RETR_EXTERNAL,
                                           cv2.CHAIN_APPROX_SIMPLE)
            if not contours:
                continue
            blob = max(contours, key=cv2.contourArea)
            x, y, w, h = cv2.boundingRect(blob)
            moments = cv2.moments(self._mask[y:y + h, x:x + w], binaryImage=True)
            count = moments["m00"]
            if count == 0 or count / pixels < self.min_area:
                continue
            out[3 * k] = (x + moments["m10"] / count) / width
            out[3 * k + 1] = (y + moments["m01"] / count) / height
            out[3 * k + 2] = count / pixels
        return out


class HaarFaceTracker(Tracker):
    """The largest face (Haar cascade), its eyes and a smile flag.

    Channels: face.x, face.y (box centre, 0..1 of the image), face.w, face.h (box size, 0..1
    of the image width / height); eye_left.x, eye_left.y, eye_right.x, eye_right.y (eye centres,
    0..1 within the face box; left / right as seen in the image, each searched in its half of
    the upper face); smile (1 when the smile cascade fires in the lower half of the face, else
    0). NaN when not found (Haar eye detection often misses one eye behind glasses).

    detect_width : [px] faces are searched on a copy scaled to this width (speed). Once a face
        is found, the next frame is searched near it first, at about its size (`reset()`
        forgets it).
    feature_width : [px] eyes and smile are searched on the face box scaled to this width.
    """
    name = "haar"

    def __init__(self, *, detect_width: int = 320, min_face: float = 0.12,
                 face_neighbors: int = 5, eye_neighbors: int = 4, smile_neighbors: int = 20,
                 feature_width: int = 120):
        cv2 = _cv2()
        root = cv2.data.haarcascades

        def cascade(name):
            classifier = cv2.CascadeClassifier(root + name)
            if classifier.empty():
                raise ImportError(f"OpenCV has no Haar cascade {name} (OpenCV 5 wheels ship "
                                  f"none: install opencv-contrib-python-headless<5)")
            return classifier

        self._face = cascade("haarcascade_frontalface_default.xml")
        # one cascade per side of the face: the person's right eye is on the image's left
        self._eye_image_left = cascade("haarcascade_righteye_2splits.xml")
        self._eye_image_right = cascade("haarcascade_lefteye_2splits.xml")
        self._smile = cascade("haarcascade_smile.xml")
        if detect_width < 80:
            raise ValueError(f"detect_width must be >= 80 px, got {detect_width}")
        self.detect_width = int(detect_width)
        self.min_face = float(min_face)
        self.face_neighbors = int(face_neighbors)
        self.eye_neighbors = int(eye_neighbors)
        self.smile_neighbors = int(smile_neighbors)
        if feature_width < 60:
            raise ValueError(f"feature_width must be >= 60 px, got {feature_width}")
        self.feature_width = int(feature_width)
        self._face_image: np.ndarray | None = None
        self._previous: tuple[int, int, int, int] | None = None   # last face, detect scale
        self.channels = ("face.x", "face.y", "face.w", "face.h", "eye_left.x", "eye_left.y",
                         "eye_right.x", "eye_right.y", "smile")
        self._gray = self._small = None

    def reset(self) -> None:
        """Forget the last face (the next frame is searched whole)."""
        self._previous = None

    def _search_near_previous(self, small_size) -> list:
        """Faces near last frame's face, at about its size: a face moves little between
        frames, and this scans far fewer windows than the whole image. [] when there was no
        face or it is not there any more (then the whole image is searched)."""
        if self._previous is None:
            return []
        x, y, w, h = self._previous
        margin = w // 2
        x0, y0 = max(0, x - margin), max(0, y - margin)
        x1 = min(small_size[0], x + w + margin)
        y1 = min(small_size[1], y + h + margin)
        region = self._small[y0:y1, x0:x1]
        low, high = max(24, int(w * 0.75)), int(w * 1.35)
        if region.shape[0] < low or region.shape[1] < low:
            return []
        faces = self._face.detectMultiScale(region, scaleFactor=1.1,
                                            minNeighbors=self.face_neighbors,
                                            minSize=(low, low), maxSize=(high, high))
        return [(fx + x0, fy + y0, fw, fh) for fx, fy, fw, fh in faces]

    def describe(self) -> dict:
        return {"tracker": self.name, "detect_width": self.detect_width,
                "min_face": self.min_face, "face_neighbors": self.face_neighbors,
                "eye_neighbors": self.eye_neighbors, "smile_neighbors": self.smile_neighbors,
                "feature_width": self.feature_width}

    def process(self, image: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        image = _image(image)
        height, width = image.shape[:2]
        factor = min(1.0, self.detect_width / width)
        small_size = (max(1, round(width * factor)), max(1, round(height * factor)))
        if self._gray is None or self._gray.shape != (height, width):
            self._gray = np.empty((height, width), np.uint8)
            self._small = np.empty((small_size[1], small_size[0]), np.uint8)
        cv2.cvtColor(image, cv2.COLOR_BGR2GRAY, dst=self._gray)
        cv2.resize(self._gray, small_size, dst=self._small, interpolation=cv2.INTER_AREA)
        out = np.full(len(self.channels), np.nan)
        faces = self._search_near_previous(small_size)
        if len(faces) == 0:
            smallest = max(24, int(self.min_face * small_size[0]))
            faces = self._face.detectMultiScale(self._small, scaleFactor=1.15,
                                                minNeighbors=self.face_neighbors,
                                                minSize=(smallest, smallest))
        if len(faces) == 0:
            self._previous = None
            return out
        best = max(faces, key=lambda f: f[2] * f[3])
        self._previous = tuple(int(v) for v in best)
        x, y, w, h = (float(v) / factor for v in best)
        out[0:4] = ((x + w / 2) / width, (y + h / 2) / height, w / width, h / height)
        x0, y0 = max(0, int(round(x))), max(0, int(round(y)))
        x1, y1 = min(width, int(round(x + w))), min(height, int(round(y + h)))
        if x1 - x0 < 20 or y1 - y0 < 20:
            return out
        # eyes and smile are searched on the face scaled to a fixed size: the cascades then
        # scan a handful of scales whatever the face's size in the image
        fw = self.feature_width
        fh = max(20, round(fw * (y1 - y0) / (x1 - x0)))
        if self._face_image is None or self._face_image.shape != (fh, fw):
            self._face_image = np.empty((fh, fw), np.uint8)
        face = self._face_image
        cv2.resize(self._gray[y0:y1, x0:x1], (fw, fh), dst=face, interpolation=cv2.INTER_AREA)
        upper = face[: fh * 11 // 20]
        half = fw // 2
        size = dict(minSize=(fw // 10,) * 2, maxSize=(half, half))
        for slot, cascade, part, left in ((4, self._eye_image_left, upper[:, :half], 0),
                                          (6, self._eye_image_right, upper[:, half:], half)):
            eyes = cascade.detectMultiScale(part, scaleFactor=1.1,
                                            minNeighbors=self.eye_neighbors, **size)
            if len(eyes):
                ex, ey, ew, eh = max(eyes, key=lambda e: e[2] * e[3])
                out[slot:slot + 2] = ((left + ex + ew / 2) / fw, (ey + eh / 2) / fh)
        lower = face[fh // 2:]
        smiles = self._smile.detectMultiScale(lower, scaleFactor=1.2,
                                              minNeighbors=self.smile_neighbors,
                                              minSize=(fw // 4, max(5, fh // 10)))
        out[8] = 1.0 if len(smiles) else 0.0
        return out


class SilhouetteTracker(Tracker):
    """A hand silhouette: the largest region of skin colour (or of bright / dark pixels).

    Channels: hand.x, hand.y (centroid, 0..1 of the image), hand.area (fraction of the image),
    hand.openness (1 - area / convex hull area: about 0.05 for a fist, 0.3+ for a spread hand),
    hand.gaps (convexity defects deeper than `gap_depth` x the hand's equivalent radius and
    narrower than `gap_angle` degrees: the valleys between spread fingers, 4 for an open hand).

    segmentation : "skin" (YCrCb range, default), "bright" or "dark" (Otsu threshold of the
        grey image, for a lit hand on a dark background or a shadow on a bright one).
    """
    name = "silhouette"

    def __init__(self, *, segmentation: str = "skin", skin_low=(0, 135, 85),
                 skin_high=(255, 180, 135), min_area: float = 0.005, gap_depth: float = 0.3,
                 gap_angle: float = 110.0):
        if segmentation not in ("skin", "bright", "dark"):
            raise ValueError(f"segmentation must be 'skin', 'bright' or 'dark', got "
                             f"{segmentation!r}")
        self.segmentation = segmentation
        self.skin_low = np.array(skin_low, np.uint8)
        self.skin_high = np.array(skin_high, np.uint8)
        if not 0 < min_area < 1:
            raise ValueError(f"min_area is a fraction of the image in (0, 1), got {min_area!r}")
        self.min_area = float(min_area)
        self.gap_depth = float(gap_depth)
        if not 0 < gap_angle < 180:
            raise ValueError(f"gap_angle must be in (0, 180) degrees, got {gap_angle!r}")
        self.gap_angle = float(gap_angle)
        self._gap_cosine = math.cos(math.radians(gap_angle))
        self.channels = ("hand.x", "hand.y", "hand.area", "hand.openness", "hand.gaps")
        self._work = self._mask = None
        self._kernel = np.ones((3, 3), np.uint8)

    def describe(self) -> dict:
        return {"tracker": self.name, "segmentation": self.segmentation,
                "skin_low": self.skin_low.tolist(), "skin_high": self.skin_high.tolist(),
                "min_area": self.min_area, "gap_depth": self.gap_depth,
                "gap_angle": self.gap_angle}

    def mask(self, image: np.ndarray) -> np.ndarray:
        """(H, W) uint8 0/255: the pixels taken as hand (before choosing the largest region)."""
        cv2 = _cv2()
        image = _image(image)
        height, width = image.shape[:2]
        if self._mask is None or self._mask.shape != (height, width):
            self._mask = np.empty((height, width), np.uint8)
            self._work = np.empty((height, width, 3), np.uint8)
            self._gray = np.empty((height, width), np.uint8)
        if self.segmentation == "skin":
            cv2.cvtColor(image, cv2.COLOR_BGR2YCrCb, dst=self._work)
            cv2.inRange(self._work, self.skin_low, self.skin_high, dst=self._mask)
        else:
            cv2.cvtColor(image, cv2.COLOR_BGR2GRAY, dst=self._gray)
            kind = cv2.THRESH_BINARY if self.segmentation == "bright" else cv2.THRESH_BINARY_INV
            cv2.threshold(self._gray, 0, 255, kind | cv2.THRESH_OTSU, dst=self._mask)
        cv2.morphologyEx(self._mask, cv2.MORPH_OPEN, self._kernel, dst=self._mask)
        return self._mask

    def process(self, image: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        mask = self.mask(image)
        height, width = mask.shape
        out = np.full(len(self.channels), np.nan)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if not contours:
            return out
        contour = max(contours, key=cv2.contourArea)
        area = cv2.contourArea(contour)
        if area < self.min_area * width * height:
            return out
        moments = cv2.moments(contour)
        hull_points = cv2.convexHull(contour)
        hull_area = cv2.contourArea(hull_points)
        out[0] = moments["m10"] / moments["m00"] / width
        out[1] = moments["m01"] / moments["m00"] / height
        out[2] = area / (width * height)
        out[3] = 1.0 - area / hull_area if hull_area > 0 else 0.0
        out[4] = 0.0
        hull = cv2.convexHull(contour, returnPoints=False)
        if hull is not None and len(hull) > 3:
            hull = np.sort(hull.ravel())[::-1].reshape(-1, 1).astype(np.int32)
            try:
                defects = cv2.convexityDefects(contour, hull)
            except cv2.error:       # self-intersecting hull order on odd contours
                defects = None
            if defects is not None:
                defects = defects.reshape(-1, 4)
                radius = math.sqrt(area / math.pi)
                depth = defects[:, 3] / 256.0
                start = contour[defects[:, 0], 0].astype(np.float64)
                end = contour[defects[:, 1], 0].astype(np.float64)
                far = contour[defects[:, 2], 0].astype(np.float64)
                a = start - far
                b = end - far
                cosine = (a * b).sum(1) / np.maximum(
                    np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-9)
                # a valley between two fingers is deep and narrow; the shallow, wide dents
                # beside the outermost fingers are not gaps
                out[4] = float(np.count_nonzero((depth > self.gap_depth * radius)
                                                & (cosine > self._gap_cosine)))
        return out


TRACKERS: dict[str, type[Tracker]] = {
    "face": FaceMeshTracker,
    "hands": HandsTracker,
    "pose": PoseTracker,
    "aruco": ArucoTracker,
    "color": ColorBlobTracker,
    "colour": ColorBlobTracker,
    "haar": HaarFaceTracker,
    "silhouette": SilhouetteTracker,
    "hand": SilhouetteTracker,
}
ALIASES = {"colour": "color", "hand": "silhouette"}
MARKERLESS = ("face", "hands", "pose")


def tracker_names() -> list[str]:
    """The tracker names a camera spec takes (aliases left out)."""
    return [name for name in TRACKERS if name not in ALIASES]


def make_tracker(name: str | Tracker, **options) -> Tracker:
    """A tracker by name ("face", "hands", "pose", "aruco", "color", "haar", "silhouette")
    with keyword options."""
    if isinstance(name, Tracker):
        if options:
            raise ValueError("options are for trackers given by name")
        return name
    cls = TRACKERS.get(name)
    if cls is None:
        raise ValueError(f"unknown camera tracker {name!r}; available: "
                         f"{', '.join(tracker_names())}")
    try:
        return cls(**options)
    except TypeError as error:
        raise TypeError(f"tracker {name!r}: {error}") from None
