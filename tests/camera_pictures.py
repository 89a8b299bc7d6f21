"""Pictures and videos for the markerless trackers' tests: a photograph placed in a 640x480
frame by a known affine transformation (recordings/make_webcam_takes.py, which makes the
webcam example's takes the same way), written as a lossless video and read back through the
camera source."""
import importlib.util
from pathlib import Path

import numpy as np

from capture import open_source

ROOT = Path(__file__).resolve().parent.parent
W, H = 640, 480


def _load_pictures():
    """The picture making of the webcam example's takes (recordings/make_webcam_takes.py):
    the photo's placement, the jaw warp, lossless video writing."""
    path = ROOT / "recordings" / "make_webcam_takes.py"
    spec = importlib.util.spec_from_file_location("make_webcam_takes", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


pictures = _load_pictures()
placement, place, write_video = pictures.placement, pictures.place, pictures.write_video


def carried(first, matrices):
    """(N, 2) [px] where a point seen at `first` [px] in the picture placed by matrices[0] is in
    the picture placed by each matrix."""
    in_photo = np.linalg.solve(matrices[0][:, :2], np.asarray(first) - matrices[0][:, 2])
    return np.array([m[:, :2] @ in_photo + m[:, 2] for m in matrices])


def track(tmp_path, frames, tracker="face", **options):
    """Write the frames as a lossless video, read it back through the camera source."""
    path = write_video(tmp_path / f"{tracker}.mkv", frames)
    with open_source(f"camera:{path}:{tracker}", realtime=False, **options) as source:
        values = np.array([frame.values for frame in source])
        assert source.ended and values.shape == (len(frames), len(source.channels))
    return values


def track_statuses(path, frames, tracker="hands", **options):
    """The tracker's values (N, channels) and the source's status on each frame, one frame
    queued at a time (the reader at most two frames ahead of what is read)."""
    path = write_video(path, frames)
    rows, statuses = [], []
    with open_source(f"camera:{path}:{tracker}", realtime=False, queue_size=1,
                     **options) as source:
        for frame in source:
            rows.append(frame.values)
            statuses.append(source.status)
    assert len(rows) == len(frames)
    return np.array(rows), statuses


def card_over(picture, points, top=None):
    """A copy of the picture with a grey card over the landmarks (10 px beyond them), from
    `top` [px] down when given."""
    covered = picture.copy()
    (x0, y0), (x1, y1) = points.min(axis=0).astype(int) - 10, points.max(axis=0).astype(int) + 10
    y0 = max(y0, 0) if top is None else int(top)
    covered[y0:y1, max(x0, 0):x1] = (90, 90, 90)
    return covered


def cut_out(picture):
    """(h, w) uint8 mask, 1 on the picture's largest coloured region (a hand on a grey or black
    ground: saturation over 60, value over 40), to lay the hand over other pictures."""
    import cv2
    hsv = cv2.cvtColor(picture, cv2.COLOR_BGR2HSV)
    mask = ((hsv[..., 1] > 60) & (hsv[..., 2] > 40)).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask)
    largest = 1 + np.argmax(stats[1:, cv2.CC_STAT_AREA])
    return cv2.morphologyEx((labels == largest).astype(np.uint8), cv2.MORPH_CLOSE,
                            np.ones((5, 5), np.uint8))


GROUND = (90, 100, 110)     # BGR: the plain ground the cut-out pictures are laid on


def layered(*layers):
    """A frame of cut-out pictures on a plain ground, each (picture, mask, matrix) placed by its
    affine matrix, the later ones over the earlier."""
    import cv2
    frame = np.full((H, W, 3), GROUND, np.float32)
    for picture, mask, matrix in layers:
        alpha = cv2.warpAffine(mask.astype(np.float32), matrix, (W, H))[..., None]
        frame = place(picture, matrix) * alpha + frame * (1 - alpha)
    return frame.astype(np.uint8)


def head_cut(picture):
    """(h, w) uint8 mask, 1 on an ellipse round the picture's face (its face mesh: forehead to
    chin, cheek to cheek, enlarged), to lay a head over other pictures."""
    import cv2
    points = pictures.face_points(picture)
    centre = (points[10] + points[152]) / 2
    axes = (0.75 * np.linalg.norm(points[454] - points[234]),
            0.85 * np.linalg.norm(points[152] - points[10]))
    mask = np.zeros(picture.shape[:2], np.uint8)
    cv2.ellipse(mask, tuple(int(v) for v in centre), tuple(int(v) for v in axes), 0, 0, 360, 1, -1)
    return mask


def motion_blur(picture, length):
    """The picture smeared along x over `length` px, as a fast move across the camera does."""
    import cv2
    kernel = np.zeros((length, length), np.float32)
    kernel[length // 2] = 1.0 / length
    return cv2.filter2D(picture, -1, kernel)
