"""`mop demo`: perform the shipped demo session from its recorded takes, to demo.mp4."""
from __future__ import annotations

import sys
from pathlib import Path


def register(subparsers) -> None:
    from mop.commands._args import port, seconds_or_zero

    parser = subparsers.add_parser(
        "demo", help="perform the shipped demo (two replayed performers, three characters)",
        description="Replays the shipped demo takes (recordings/demo): a data-glove performer "
                    "and a hand-tracker performer drive a latex frog, a medial creature and a "
                    "paper cut-out (two performers share the cut-out). Writes the video and "
                    "prints the timing. Needs no hardware.")
    parser.add_argument("--out", default="demo.mp4", metavar="PATH",
                        help="video file (.mp4, .mkv, .gif) or a folder of PNGs (default "
                             "demo.mp4)")
    parser.add_argument("--session", default=None, metavar="TOML",
                        help="another session file to perform instead of the shipped one")
    parser.add_argument("--preview", type=port, default=None, metavar="PORT",
                        help="also serve the live preview page (0 = any free port); implies "
                             "real time")
    parser.add_argument("--realtime", action="store_true", help="play in real time")
    parser.add_argument("--transparent", action="store_true",
                        help="draw on a transparent background (a PNG folder --out keeps the "
                             "alpha)")
    parser.add_argument("--still", default=None, metavar="PNG",
                        help="also save one frame as a PNG (see --still-at)")
    parser.add_argument("--still-at", type=seconds_or_zero, default=4.0, metavar="SECONDS",
                        help="session time of the --still frame (default 4.0)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(func=run)


def demo_session_path() -> Path:
    import mop
    root = Path(mop.__file__).resolve().parent.parent
    path = root / "sessions" / "demo.toml"
    if not path.exists():
        raise FileNotFoundError(
            f"the demo session is not at {path}: `mop demo` runs from a source checkout "
            f"(pip install -e .), where sessions/ and recordings/ sit beside the packages")
    return path


class StillOutput:
    """Saves the frame rendered at a given session time as a PNG."""

    def __init__(self, path: Path, at: float, fps: int):
        self.path = Path(path)
        self.at, self.fps = at, fps
        self.frame_number = int(round(at * fps))
        self.frames = 0

    def recipe(self):
        """Rebuilt where the pictures are made (the render process)."""
        return (StillOutput, (self.path, self.at, self.fps), {})

    def write(self, frame, state, *, repeat: bool = False) -> None:
        if frame is not None and state is not None and state["frame"] == self.frame_number:
            from PIL import Image
            self.path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(frame, "RGBA").save(self.path, optimize=True)
            self.frames = 1

    def close(self) -> None:
        pass


def run(args) -> int:
    import time

    from mop.commands.perform import perform
    from mop.session import Mode, load_session
    from mop.session.build import Overrides

    from mop.commands._args import say_if_kernels_compile

    started = time.monotonic()
    say_if_kernels_compile()
    config = load_session(args.session or demo_session_path())
    extra = []
    if args.still:
        extra.append(StillOutput(Path(args.still), args.still_at, config.fps))
    live = args.realtime or args.preview is not None
    overrides = Overrides(video=args.out, preview=args.preview, transparent=args.transparent)
    session, report, interrupted = perform(
        config, mode=Mode.LIVE if live else Mode.REPLAY, overrides=overrides, quiet=args.quiet,
        extra_outputs=extra)
    print(report.format())
    for output in session.outputs:
        path = getattr(output, "path", None)
        if path is not None and output.frames:
            print(f"wrote {path} ({output.frames} frames)")
    print(f"demo done in {time.monotonic() - started:.1f} s")
    if interrupted:
        print("interrupted: every output was finalised", file=sys.stderr)
        return 130
    for output in extra:
        if not output.frames:
            from mop.commands._args import CommandError
            raise CommandError(f"--still-at {args.still_at:g}: the session ended at "
                               f"{report.frames / config.fps:.2f} s before that frame; no "
                               f"still was written to {output.path}")
    return 0
