"""`mop puppet IMAGE --motion MOTION --out OUT`: turn a picture into an elastic puppet, play a
motion on its pins and write the rendered frames (MP4, MKV, GIF or PNG sequence).

Pins come from --auto-pins (proposed from the silhouette's skeleton: a `body` anchor and a pin
at each limb's tip, named by where it points: `top`, `left_1`, ...), else from --pins
PINS.json, else from a "pins" section inside the motion file, else from a sidecar
IMAGE.pins.json next to the picture. `--show-mesh` alone draws the mesh with the pins
--auto-pins would use. A pins file is
{"pins": {"hand": {"xy": [x, y]}, "feet": {"xy": [x, y], "fixed": true}}} in picture pixels
({"hand": [x, y]} is accepted too). Motion channels name driven pins and give their positions in
picture pixels over time (characters.Motion JSON).
"""
from __future__ import annotations

import logging
import sys
import time
from pathlib import Path


def register(subparsers) -> None:
    from mop.commands._args import MAX_FRAMES, positive, rate, seconds_or_zero

    parser = subparsers.add_parser(
        "puppet", help="animate a picture as an elastic puppet and render it",
        description="Animate a picture of a character as an elastic 2D puppet: background "
                    "removal, a triangle mesh, pins driven by a motion, texture-mapped frames.")
    parser.add_argument("image", type=Path, help="picture of a character: a cut-out with "
                        "alpha, a photo on a plain or unevenly lit background, or a pen "
                        "drawing on paper")
    parser.add_argument("--motion", type=Path, help="motion JSON whose channels drive the pins")
    parser.add_argument("--out", type=Path, help="output: .mp4, .mkv (lossless), .avi, .webm, "
                        ".gif, or a folder / name_%%05d.png for PNG frames with alpha")
    parser.add_argument("--show-mesh", type=Path, metavar="PNG", nargs="?", const=True,
                        help="also save a picture of the mesh and pins over the image "
                             "(default name: IMAGE.mesh.png in the current folder)")
    parser.add_argument("--pins", type=Path, metavar="PINS.json",
                        help="pin positions (default: the motion's 'pins', or IMAGE.pins.json)")
    parser.add_argument("--auto-pins", action="store_true",
                        help="pins proposed from the silhouette: a fixed 'body' anchor and a "
                             "driven pin at each limb's tip (top, bottom_1, left, ...)")
    parser.add_argument("--kind", choices=("auto", "alpha", "plain", "photo", "drawing"),
                        default="auto", help="how to find the character: its alpha channel, "
                        "a plain background colour, a photo's unevenly lit background, a pen "
                        "drawing's outline (default: decided from the picture)")
    parser.add_argument("--close-gaps", type=positive, default=None, metavar="PX",
                        help="close gaps in a drawing's outline up to this wide (default: "
                             "three stroke widths)")
    parser.add_argument("--material", default="rubber",
                        help="liquid, fabric, rubber (default) or rigid")
    parser.add_argument("--mode", choices=("springs", "arap"), default="springs",
                        help="springs: mass-spring dynamics (default); arap: as-rigid-as-"
                             "possible posing")
    parser.add_argument("--background", default=None,
                        help="transparent, #rrggbb or chroma (default: transparent if the "
                             "format keeps alpha, else white)")
    parser.add_argument("--fps", type=rate, default=25.0, help="frames per second (25)")
    parser.add_argument("--duration", type=seconds_or_zero, default=None,
                        help="seconds to render (default: the motion's duration)")
    parser.add_argument("--max-frames", type=int, default=MAX_FRAMES, metavar="N",
                        help=f"refuse to render more frames than this (default {MAX_FRAMES:,}, "
                             f"an hour at 25 fps)")
    parser.add_argument("--cell-size", type=positive, default=None,
                        help="mesh cell size in picture pixels (default: 1/24 of the character)")
    parser.add_argument("--tolerance", type=float, default=None,
                        help="background colour tolerance, 0..255 (default: automatic)")
    parser.set_defaults(func=run)


def load_pins(path: Path) -> dict:
    """A pins JSON file -> {name: {"xy": (x, y), "fixed": bool}} (strict: `mop.sidecars`)."""
    from mop.sidecars import read_pins
    return {name: {"xy": pin.xy, "fixed": pin.fixed} for name, pin in read_pins(path).items()}


def parse_pins(pins, where: str) -> dict:
    from mop.sidecars import parse_pins as parse
    return {name: {"xy": pin.xy, "fixed": pin.fixed}
            for name, pin in parse(pins, where=where).items()}


def run(args) -> int:
    from PIL import Image

    from mop.render.image2d import puppet_preview

    _check_arguments(args)
    motion, pins = _motion_and_pins(args)
    puppet = _build(args, pins)
    if args.show_mesh is not None:
        path = (Path(args.image.stem + ".mesh.png") if args.show_mesh is True
                else args.show_mesh)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(puppet_preview(puppet)).save(path)
        print(f"wrote mesh preview {path}")
    if args.out is not None:
        _render_motion(args, puppet, motion)
    return 0


def _check_arguments(args) -> None:
    if args.out is None and args.show_mesh is None:
        raise ValueError("nothing to do: give --out OUT (with --motion) and/or --show-mesh PNG")
    if args.out is not None and args.motion is None:
        raise ValueError("--out needs --motion MOTION.json to know how the pins move")
    if not args.fps > 0:
        raise ValueError(f"--fps must be > 0, got {args.fps}")
    if args.auto_pins and args.pins is not None:
        raise ValueError("give either --auto-pins or --pins PINS.json, not both")


def _motion_and_pins(args):
    """The motion (or None) and the pins: --pins, else the motion file's 'pins', else the
    image's sidecar; None when the pins are to be proposed."""
    from characters import Motion
    from mop.sidecars import read_json

    motion = None
    pins = None
    if args.motion is not None:
        motion = Motion.load(args.motion)
        data = read_json(args.motion, "motion file")
        if isinstance(data, dict) and "pins" in data and not args.auto_pins:
            pins = parse_pins(data["pins"], f"{args.motion}: pins")
    if args.pins is not None:
        pins = load_pins(args.pins)
    if pins is None and not args.auto_pins:
        sidecar = args.image.with_name(args.image.stem + ".pins.json")
        if sidecar.exists():
            pins = load_pins(sidecar)
    if pins is None and not args.auto_pins and motion is not None and motion.channel_names:
        raise ValueError(f"the motion drives pins {motion.channel_names} but no pin positions "
                         f"were given: use --auto-pins, --pins PINS.json, a 'pins' section in "
                         f"the motion file, or {args.image.stem}.pins.json next to the image")
    return motion, pins


def _build(args, pins):
    """The puppet from the picture, with the pins given or proposed; says what it found."""
    from characters import ImagePuppet

    started = time.perf_counter()
    # the notes are printed below, once: the library's warning line of each would repeat them
    library = logging.getLogger("characters.image.puppet")
    level = library.level
    library.setLevel(logging.ERROR)
    try:
        puppet = ImagePuppet.from_image(args.image, cell_size=args.cell_size,
                                        tolerance=args.tolerance, material=args.material,
                                        mode=args.mode, kind=args.kind,
                                        close_gaps=args.close_gaps)
    finally:
        library.setLevel(level)
    for name, pin in (pins or {}).items():
        puppet.add_pin(pin["xy"], name=name, fixed=pin["fixed"])
    proposed = pins is None and (args.auto_pins or args.out is None)
    if proposed:
        puppet.add_auto_pins()
    print(f"built {puppet} in {time.perf_counter() - started:.2f} s (found as {puppet.kind})")
    for note in puppet.notes:
        print(f"note: {note}")
    if proposed:
        listed = ", ".join(f"{name} ({pin.requested[0]:.0f}, {pin.requested[1]:.0f})"
                           + (" fixed" if pin.fixed else "")
                           for name, pin in puppet.pins.items())
        print(f"{'automatic pins' if args.auto_pins else 'pins --auto-pins would use'}: "
              f"{listed}")
    return puppet


def _render_motion(args, puppet, motion) -> None:
    """Simulate the puppet along the motion and write every frame to --out."""
    import numpy as np
    from tqdm import tqdm

    from mop.commands._args import WorkEstimate, check_frame_budget
    from mop.export import open_writer
    from mop.render.image2d import ImageRenderer

    puppet.check_motion(motion)
    duration = motion.duration if args.duration is None else float(args.duration)
    if not duration >= 0:
        raise ValueError(f"--duration must be >= 0 s, got {duration}")
    frame_count = int(np.floor(duration * args.fps + 1e-9)) + 1
    check_frame_budget(frame_count, fps=args.fps, limit=args.max_frames)
    estimate = WorkEstimate(frame_count, f"rendering {args.out}")
    height, width = puppet.mask.shape
    renderer = ImageRenderer(puppet.image, puppet.vertices, puppet.triangles,
                             size=(width, height), background=args.background or "transparent")
    frame = np.empty((height, width, 4), np.uint8)
    simulate_time = render_time = 0.0
    # on a terminal the bar is redrawn in place; in a log, a line every 5 s
    with open_writer(args.out, fps=args.fps, size=(width, height),
                     background=args.background) as writer, \
            tqdm(total=frame_count, desc=f"rendering {args.out.name}", unit="frame",
                 file=sys.stderr, mininterval=0.1 if sys.stderr.isatty() else 5.0) as progress:
        puppet.reset()
        for index in range(frame_count):
            tick = time.perf_counter()
            targets = motion.sample(index / args.fps)
            if index > 0 or puppet.mode.value == "arap":
                puppet.step(1.0 / args.fps, targets)
            tock = time.perf_counter()
            renderer.render_into(puppet.state.x, frame)
            writer.write(frame)
            simulate_time += tock - tick
            render_time += time.perf_counter() - tock
            progress.update(1)
            estimate.update(index + 1)
    print(f"wrote {args.out}: {frame_count} frames {width}x{height} at {args.fps:g} fps "
          f"(simulation {1e3 * simulate_time / frame_count:.2f} ms/frame, render+encode "
          f"{1e3 * render_time / frame_count:.2f} ms/frame)")
