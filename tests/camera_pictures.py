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


def card_over(picture, points, top=None):
    """A copy of the picture with a grey card over the landmarks (10 px beyond them), from
    `top` [px] down when given."""
    covered = picture.copy()
    (x0, y0), (x1, y1) = points.min(axis=0).astype(int) - 10, points.max(axis=0).astype(int) + 10
    y0 = max(y0, 0) if top is None else int(top)
    covered[y0:y1, max(x0, 0):x1] = (90, 90, 90)
    return covered
