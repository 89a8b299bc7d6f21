"""Regenerate the webcam example's takes: `python3 recordings/make_webcam_takes.py [FOLDER]`.

The performer is a real photograph, scikit-image's astronaut, made to act by known
transformations of the picture, and read by the real face tracker (`camera:VIDEO:face`, needs
`mop[vision]` and scikit-image):

- `chomp`: the lower face warped open and shut again (the inner lips part by up to 0.3 eye
  spans) plays the frog's mouth (the latex puppet's five finger regions, the demo's chomp);
- `tilt`: the head tilted 15 degrees to each side plays the cut-out's head (the image puppet
  `momo`, its head pin swings from side to side).

Each action is one take (video -> face channels at the video's 25 fps, paired with its
motion); `face_show` performs them again at other speeds with rests, for
`mop perform sessions/webcam.toml --replay face=face_show`. MediaPipe on the CPU gives the same
values for the same pictures, so running this again gives the same takes.

`--picture PNG` also draws the README's picture: a frame of the show beside the characters at
that moment.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

WIDTH, HEIGHT, FPS = 640, 480, 25.0
ACTIONS = {"chomp": 2.0, "tilt": 2.4}        # duration [s] at the demonstration's pace
SHOW = [(None, 0.6), ("chomp", 1.0), (None, 0.4), ("tilt", 1.25), (None, 0.4), ("chomp", 0.8),
        (None, 0.3), ("tilt", 0.9), (None, 0.6)]
TILT_DEGREES = 15.0
OPENING_SPANS = 0.3


# -- pictures -------------------------------------------------------------------------------

def astronaut():
    from skimage import data
    return np.ascontiguousarray(data.astronaut()[..., ::-1])          # RGB -> BGR


def placement(photo, *, angle=0.0, scale=1.0, dx=0.0, dy=0.0, size=(WIDTH, HEIGHT)):
    """(2, 3) affine: the photo fitted into the frame, turned `angle` degrees counter-clockwise
    about its centre, scaled by `scale`, moved by (dx, dy) px."""
    import cv2
    h, w = photo.shape[:2]
    width, height = size
    matrix = cv2.getRotationMatrix2D((w / 2, h / 2), angle, scale * min(width / w, height / h))
    matrix[:, 2] += (width / 2 - w / 2 + dx, height / 2 - h / 2 + dy)
    return matrix


def place(photo, matrix, size=(WIDTH, HEIGHT)):
    import cv2
    return cv2.warpAffine(photo, matrix, size, flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)


def face_points(image):
    """(478, 2) face mesh landmarks [px] of one picture (to place the jaw warp)."""
    import cv2
    from mediapipe.python.solutions import face_mesh
    height, width = image.shape[:2]
    with face_mesh.FaceMesh(static_image_mode=True, refine_landmarks=True) as mesh:
        result = mesh.process(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
    if not result.multi_face_landmarks:
        raise ValueError("no face in the picture")
    return np.array([(p.x * width, p.y * height)
                     for p in result.multi_face_landmarks[0].landmark])


def jaw_warp(points) -> dict:
    """Where to open a face's jaw (see `open_jaw`), from its face mesh landmarks [px]."""
    return {"mouth": (points[[61, 291], 0].mean(), points[[13, 14], 1].mean()),
            "chin": points[152, 1], "corners": points[[61, 291], 0],
            "cheeks": points[[234, 454], 0]}


def open_jaw(image, *, mouth, chin, corners, cheeks, opening):
    """The lower face warped open by `opening` px: below the lip line the face moves down, by
    a lens-shaped gap between the mouth corners (filled with a dark mouth) that widens into a
    jaw-wide shift at the chin and fades out down the neck.

    mouth : (x, y) [px] the lips' meeting point; chin : y [px]; corners : (x_right, x_left)
    mouth corners; cheeks : (x_right, x_left) the face's sides. The mouth is dark red, dark
    grey in a picture without colour (the face mesh reads a red mouth in a grey face as lips:
    on greyscale portraits jaw_open then stalls or falls as the mouth opens)."""
    import cv2
    height, width = image.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    cx, my = mouth
    half_mouth = (corners[1] - corners[0]) / 2
    half_face = (cheeks[1] - cheeks[0]) / 2
    u = np.clip(np.abs(xs - cx) / half_mouth, 0, 1)
    gap = opening * np.sqrt(1 - u ** 2)
    across = np.clip(1.6 - 1.3 * np.abs(xs - cx) / half_face, 0, 1)
    jaw = opening * across * across * (3 - 2 * across)
    below = ys - my
    t = np.clip(below / (chin - my), 0, 1)
    shift = gap * (1 - t) + jaw * t
    neck = chin + 1.5 * (chin - my)
    shift = np.where(ys > chin, jaw * np.clip((neck - ys) / (neck - chin), 0, 1), shift)
    shift = np.where(below < 0, 0, shift)
    warped = cv2.remap(image, xs, (ys - shift).astype(np.float32), cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    inside = ((below >= 0) & (below < gap)).astype(np.float32)
    edge = np.clip(np.minimum(below, gap - below), 0, 1.5) / 1.5
    alpha = (inside * edge)[..., None]
    dark = np.array([35, 25, 70], np.float32)        # BGR: the inside of a mouth
    lower = image[int(my):int(chin), max(int(cheeks[0]), 0):int(cheeks[1])].astype(np.int16)
    if np.ptp(lower, axis=2).mean() < 4:             # a greyscale picture: a grey mouth
        dark[:] = dark @ np.float32([0.114, 0.587, 0.299])
    return (warped * (1 - alpha) + dark * alpha).astype(np.uint8)


def write_video(path, frames, fps=FPS):
    import cv2
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (width, height))
    if not writer.isOpened():
        raise OSError(f"OpenCV cannot write {path}")
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


# -- the performance ----------------------------------------------------------------------------

class Performer:
    """The astronaut, able to open her jaw and tilt her head by known amounts."""

    def __init__(self):
        self.photo = astronaut()
        self.still = place(self.photo, placement(self.photo))
        points = face_points(self.still)
        self.span = float(np.linalg.norm(points[263] - points[33]))    # eye corners [px]
        self.warp = jaw_warp(points)

    def frame(self, *, opening=0.0, tilt=0.0):
        """opening : jaw gap [eye spans]; tilt : [deg] counter-clockwise."""
        image = self.still
        if opening > 0:
            image = open_jaw(image, opening=opening * self.span, **self.warp)
        if tilt:
            import cv2
            centre = self.warp["mouth"][0], self.warp["mouth"][1] - 0.8 * self.span
            matrix = cv2.getRotationMatrix2D(centre, tilt, 1.0)
            image = cv2.warpAffine(image, matrix, (WIDTH, HEIGHT), flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)
        return image

    def act(self, action, speed=1.0):
        count = int(round(ACTIONS[action] / speed * FPS)) + 1
        u = np.linspace(0.0, 1.0, count)
        if action == "chomp":
            return [self.frame(opening=OPENING_SPANS * np.sin(np.pi * k) ** 2) for k in u]
        return [self.frame(tilt=TILT_DEGREES * np.sin(2 * np.pi * k)) for k in u]

    def rest(self, seconds):
        return [self.still] * int(round(seconds * FPS))


def motion_for(action):
    """{channel: (times, values)}: the frog's chomp (the demo's), the cut-out's head swing."""
    import json
    duration = ACTIONS[action]
    times = np.linspace(0.0, duration, 25)
    u = np.linspace(0.0, 1.0, 25)
    if action == "chomp":
        close = np.sin(np.pi * u) ** 2
        return {"thumb": (times, close[:, None]), "index": (times, (0.9 * close)[:, None]),
                "middle": (times, close[:, None]), "ring": (times, (0.9 * close)[:, None]),
                "pinky": (times, (0.7 * close)[:, None])}
    pins = json.loads((ROOT / "characters" / "assets" / "momo.pins.json").read_text())["pins"]
    head = np.array(pins["head"]["xy"], dtype=float)
    swing = np.sin(2 * np.pi * u)
    # the head follows the performer's: counter-clockwise tilt -> the top moves left
    return {"head": (times, head + np.stack([-40.0 * swing, 6.0 * np.abs(swing)], axis=1))}


def track(frames, folder: Path, name: str):
    """(times (K,) [s] on the video's clock, values (K, 13)) of the face tracker."""
    from capture import open_source
    path = write_video(folder / f"{name}.mkv", frames)
    with open_source(f"camera:{path}:face", realtime=False) as source:
        values = np.array([frame.values for frame in source])
        channels = source.channels
    return np.arange(len(values)) / FPS, values, channels


def build(target: Path, *, picture: Path | None = None) -> list[str]:
    from characters import Motion
    from mop.takes import ACTION_STREAM, ActionStream, Take, TakeStore

    performer = Performer()
    store = TakeStore(target)
    names = []
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        takes = [(f"face_{action}", action, performer.act(action), Motion(motion_for(action)),
                  {}) for action in ACTIONS]
        show = []
        for action, amount in SHOW:
            show += performer.rest(amount) if action is None else performer.act(action, amount)
        steps = [[action or "rest", amount] for action, amount in SHOW]
        takes.append(("face_show", "show", show, None, {"show": steps}))
        for name, action, frames, motion, extra in takes:
            times, values, channels = track(frames, scratch, name)
            stream = ActionStream(times, values, channels, rate=FPS,
                                  device={"kind": "camera", "tracker": "face"})
            take = Take("face", action, {ACTION_STREAM: stream}, motion=motion, rate=25.0,
                        device="camera:astronaut.mkv:face",
                        calibration={"frame_size": [WIDTH, HEIGHT]},
                        created="2026-11-26T00:00:00+00:00",
                        extra={"generator": "recordings/make_webcam_takes.py",
                               "photograph": "skimage.data.astronaut", **extra})
            store.save(take, name=name, overwrite=True)
            names.append(name)
        if picture is not None:
            draw_picture(picture, show, target)
    return names


PICTURE_TIMES = (1.5, 4.6)     # [s] of the show: in the first chomp, in the first tilt


def draw_picture(path: Path, show, takes: Path, times=PICTURE_TIMES) -> None:
    """Frames of the show beside the session's characters at the same moments, one row each."""
    import cv2

    from mop.commands.demo import StillOutput
    from mop.session import Mode, load_session
    from mop.session.build import Overrides, build_session

    config = load_session(ROOT / "sessions" / "webcam.toml")
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        stills = [StillOutput(Path(scratch) / f"{k}.png", t, config.fps)
                  for k, t in enumerate(times)]
        session = build_session(config, mode=Mode.REPLAY, overrides=Overrides(
            render=True, replay={"face": f"replay:{takes / 'face_show'}"}),
            extra_outputs=stills)
        session.run(duration=max(times) + 0.2)
        for still, t in zip(stills, times):
            stage = cv2.imread(str(still.path), cv2.IMREAD_COLOR)
            height = stage.shape[0]
            camera = cv2.resize(show[int(round(t * FPS))], (height * WIDTH // HEIGHT, height),
                                interpolation=cv2.INTER_AREA)
            cv2.putText(camera, f"camera:0:face  t = {t:.1f} s", (12, 32),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.9, (255, 255, 255), 2, cv2.LINE_AA)
            rows.append(np.hstack([camera, stage]))
    picture = np.vstack(rows)
    picture = cv2.resize(picture, (picture.shape[1] // 2, picture.shape[0] // 2),
                         interpolation=cv2.INTER_AREA)
    path.parent.mkdir(parents=True, exist_ok=True)
    from PIL import Image       # a 256-colour palette: a third of the size, looks the same
    Image.fromarray(picture[..., ::-1]).quantize(colors=256).save(path, optimize=True)
    print(f"wrote {path}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", default=str(ROOT / "recordings" / "webcam"))
    parser.add_argument("--picture", default=None, metavar="PNG",
                        help="also draw the README picture (docs/img/webcam_session.png)")
    args = parser.parse_args()
    target = Path(args.folder)
    for written in build(target, picture=Path(args.picture) if args.picture else None):
        print(f"wrote take {written} into {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
