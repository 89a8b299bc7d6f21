"""The markerless face tracker's accuracy on real photographs under known transformations.

    python3 benchmarks/markerless.py            # both portraits, every case (a few minutes)
    python3 benchmarks/markerless.py --quick    # the astronaut only

Each case turns a portrait (scikit-image's astronaut, matplotlib's Grace Hopper) into a
lossless video by known transformations (recordings/make_webcam_takes.py does the picture
making) and reads it back through the camera source, `camera:VIDEO:face`, every frame tracked:

- roll: the picture turned 0 -> 30 -> -30 -> 0 degrees, then to +-45: `head_roll` against the
  known angle (the unturned picture's roll is the reference);
- move: moved up to 200 px and scaled 0.75 -> 1.25: `head_x`, `head_y` [px] and `head_scale`
  against the known placement;
- far: the portrait at 0.4 of its size (a face a twentieth to a tenth of the frame wide), walking
  across, after a few empty frames: found, position and size errors; also with `far=false`;
- jaw: the lower face warped open in 7 steps up to 0.3 eye spans: `jaw_open` per step;
- cover: a grey card over the face, then no one, then the face back elsewhere.

The Haar face tracker (`camera:VIDEO:haar`) reads the roll and move videos too: how many frames
it finds a face in, the plain reference for "found".
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "recordings"))

from capture import open_source  # noqa: E402
from capture.camera.landmarks import FACE_CHANNELS  # noqa: E402

W, H = 640, 480
FACE = {name: k for k, name in enumerate(FACE_CHANNELS)}


def grace_hopper():
    import cv2
    from matplotlib import cbook
    with cbook.get_sample_data("grace_hopper.jpg") as file:
        return cv2.imdecode(np.frombuffer(file.read(), np.uint8), cv2.IMREAD_COLOR)


def read(pictures, folder: Path, frames, tracker="face", **options) -> np.ndarray:
    path = pictures.write_video(folder / f"{tracker}.mkv", frames)
    with open_source(f"camera:{path}:{tracker}", realtime=False, **options) as source:
        return np.array([frame.values for frame in source])


def found(values) -> str:
    """Frames with a face (the first channel: a face's position, Haar's box)."""
    return f"{int(np.isfinite(values[:, 0]).sum())}/{len(values)}"


def placed_errors(values, matrices) -> tuple[np.ndarray, np.ndarray]:
    """Position error [px] and relative size error of each frame against the known placements,
    the first matrix's frames (the first three) being the reference."""
    first = np.array([values[:3, FACE["head_x"]].mean() * W,
                      values[:3, FACE["head_y"]].mean() * H])
    in_photo = np.linalg.solve(matrices[0][:, :2], first - matrices[0][:, 2])
    expected = np.array([m[:, :2] @ in_photo + m[:, 2] for m in matrices])
    where = np.c_[values[:, FACE["head_x"]] * W, values[:, FACE["head_y"]] * H]
    scale = np.sqrt([abs(np.linalg.det(m[:, :2]) / np.linalg.det(matrices[0][:, :2]))
                     for m in matrices])
    size = values[:, FACE["head_scale"]] / values[:3, FACE["head_scale"]].mean()
    return np.linalg.norm(where - expected, axis=1), np.abs(size / scale - 1)


def case_roll(pictures, photo, folder):
    angles = np.r_[[0.0] * 3, np.linspace(0, 30, 11), np.linspace(30, -30, 21),
                   np.linspace(-30, 0, 11), np.linspace(0, 45, 10), np.linspace(45, -45, 19)]
    frames = [pictures.place(photo, pictures.placement(photo, angle=a)) for a in angles]
    values = read(pictures, folder, frames)
    error = np.abs(values[:, FACE["head_roll"]] - values[:3, FACE["head_roll"]].mean() - angles)
    within = np.abs(angles) <= 30
    return (f"found {found(values)} (haar {found(read(pictures, folder, frames, 'haar'))}); "
            f"|roll error| within 30 deg: max {np.nanmax(error[within]):.2f}, median "
            f"{np.nanmedian(error[within]):.2f} deg; within 45 deg: max {np.nanmax(error):.2f}")


def case_move(pictures, photo, folder):
    path = ([(0.0, 0.0, 1.0)] * 3
            + [(dx, dy, 1.0) for dx, dy in zip(np.linspace(0, 120, 10), np.linspace(0, -60, 10))]
            + [(120.0, -60.0, s) for s in np.linspace(1.0, 0.75, 8)]
            + [(120 - 200 * t, -60 + 90 * t, 0.75 + 0.5 * t) for t in np.linspace(0, 1, 12)])
    matrices = [pictures.placement(photo, scale=s, dx=dx, dy=dy) for dx, dy, s in path]
    frames = [pictures.place(photo, m) for m in matrices]
    values = read(pictures, folder, frames)
    position, size = placed_errors(values, matrices)
    return (f"found {found(values)} (haar {found(read(pictures, folder, frames, 'haar'))}); "
            f"position error max {np.nanmax(position):.2f} px, median "
            f"{np.nanmedian(position):.2f}; size error max {100 * np.nanmax(size):.1f} %")


def case_far(pictures, photo, folder):
    path = [(0.0, 0.0, 1.0)] * 3 + [(-150 + 25 * k, 60 - 5 * k, 0.4 - 0.004 * k)
                                    for k in range(12)]
    matrices = [pictures.placement(photo, scale=s, dx=dx, dy=dy) for dx, dy, s in path]
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)
    frames = ([pictures.place(photo, m) for m in matrices[:3]] + [empty] * 3
              + [pictures.place(photo, m) for m in matrices[3:]])
    values = read(pictures, folder, frames)
    kept = np.r_[values[:3], values[6:]]
    position, size = placed_errors(kept, matrices)
    plain = read(pictures, folder, frames, far=False)[6:]
    return (f"face {np.nanmin(values[6:, FACE['head_scale']]):.3f}-"
            f"{np.nanmax(values[6:, FACE['head_scale']]):.3f} of the frame wide: found "
            f"{found(values[6:])} (far=false {found(plain)}); position error max "
            f"{np.nanmax(position[3:]):.2f} px; size error max {100 * np.nanmax(size[3:]):.1f} %")


def case_jaw(pictures, photo, folder):
    still = pictures.place(photo, pictures.placement(photo))
    points = pictures.face_points(still)
    span = np.linalg.norm(points[263] - points[33])
    openings = np.repeat(np.linspace(0, 0.3 * span, 7), 3)
    warp = pictures.jaw_warp(points)
    values = read(pictures, folder, [pictures.open_jaw(still, opening=d, **warp)
                                     for d in openings])
    steps = np.median(values[:, FACE["jaw_open"]].reshape(7, 3), axis=1)
    rising = "rising at every step" if np.all(np.diff(steps) > 0) else "NOT monotonic"
    return f"jaw_open per step {np.round(steps, 2).tolist()} ({rising})"


def case_cover(pictures, photo, folder):
    still = pictures.place(photo, pictures.placement(photo))
    points = pictures.face_points(still)
    covered = still.copy()
    x0, y0 = points.min(axis=0).astype(int) - 10
    x1, y1 = points.max(axis=0).astype(int) + 10
    covered[max(y0, 0):y1, max(x0, 0):x1] = (90, 90, 90)
    empty = np.full((H, W, 3), (90, 100, 110), np.uint8)
    back = pictures.place(photo, pictures.placement(photo, dx=-60, dy=20))
    values = read(pictures, folder, [still] * 4 + [covered] * 10 + [empty] * 10 + [back] * 4)
    moved = np.hypot(values[24, FACE["head_x"]] * W - (values[0, FACE["head_x"]] * W - 60),
                     values[24, FACE["head_y"]] * H - (values[0, FACE["head_y"]] * H + 20))
    return (f"NaN on {int(np.isnan(values[4:24]).all(axis=1).sum())}/20 covered or empty "
            f"frames; found again on the first frame back: "
            f"{bool(np.isfinite(values[24]).all())}, {moved:.2f} px from where it was put")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the astronaut only")
    args = parser.parse_args()
    from capture.camera.markerless import models_status
    status = models_status()
    if not status["installed"]:
        print(f"skipped: {status['error']}")
        return 0
    import make_webcam_takes as pictures
    photos = {"astronaut": pictures.astronaut}
    if not args.quick:
        photos["grace_hopper"] = grace_hopper
    print(f"markerless face tracker accuracy ({status['distribution']}), 640x480 FFV1 videos "
          f"read through camera:VIDEO:face, every frame tracked")
    cases = {"roll": case_roll, "move": case_move, "far": case_far, "jaw": case_jaw,
             "cover": case_cover}
    with tempfile.TemporaryDirectory() as folder:
        for name, load in photos.items():
            photo = load()
            print(f"\n{name}")
            for case, run in cases.items():
                print(f"  {case:<6} {run(pictures, photo, Path(folder))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
