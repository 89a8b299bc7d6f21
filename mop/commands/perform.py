"""`mop perform SESSION`: run a session live (or replayed from takes) to its outputs."""
from __future__ import annotations

import signal
import sys
import time

from . import count


def register(subparsers) -> None:
    from mop.commands._args import MAX_FRAMES, port, seconds

    parser = subparsers.add_parser(
        "perform", help="perform a session: performers drive characters, live or from takes",
        description="Run a session file: every performer's input is followed, the recognised "
                    "actions play their motions on the characters, and the frames go to the "
                    "outputs. Ctrl-C stops and finalises every output. Send SIGUSR1 to print "
                    "the timing so far.")
    parser.add_argument("session", help="the session file (.toml)")
    parser.add_argument("--replay", nargs="*", metavar="PERFORMER=TAKE", default=None,
                        help="replay mode: run as fast as possible from takes (deterministic); "
                             "PERFORMER=TAKE replays that take for that performer instead of "
                             "their source; without pairs every performer must already be "
                             "a replay: source")
    parser.add_argument("--calibration", nargs="+", metavar="PERFORMER=TAKE", default=(),
                        help="who performs now: map PERFORMER's input onto the author's with "
                             "their calibration take (mop record --calibrate), as the "
                             "session's calibration = TAKE does")
    parser.add_argument("--realtime", action="store_true",
                        help="keep real time even when every performer is replayed")
    parser.add_argument("--loop", action="store_true",
                        help="loop replayed takes (a show that runs until Ctrl-C)")
    parser.add_argument("--duration", type=seconds, default=None, metavar="SECONDS",
                        help="stop after this much session time")
    parser.add_argument("--out", default=None, metavar="PATH",
                        help="video file (.mp4, .mkv, .avi, .webm, .gif) or a folder for PNG "
                             "frames (with alpha: --transparent)")
    parser.add_argument("--png", default=None, metavar="FOLDER",
                        help="also write a PNG sequence (frame N = session frame N)")
    parser.add_argument("--transparent", action="store_true",
                        help="draw on a transparent background: PNG frames keep the alpha "
                             "(a video gets the session's background colour)")
    parser.add_argument("--preview", type=port, default=None, metavar="PORT",
                        help="serve the live preview page on this port (0 = any free port)")
    parser.add_argument("--preview-host", default=None, metavar="HOST",
                        help="address for the preview page (default 127.0.0.1)")
    parser.add_argument("--osc-out", default=None, metavar="HOST:PORT",
                        help="send every character's state as OSC to this address")
    parser.add_argument("--no-render", action="store_true",
                        help="follow and simulate only (OSC out, timing), no pictures")
    parser.add_argument("--max-frames", type=int, default=MAX_FRAMES, metavar="N",
                        help=f"in replay mode, refuse a --duration that renders more frames "
                             f"(default {MAX_FRAMES:,}, an hour at 25 fps)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(func=run)


def with_calibrations(config, pairs):
    """The session with each PERFORMER=TAKE of ``pairs`` as that performer's calibration."""
    import dataclasses
    chosen = {}
    for pair in pairs:
        performer, sep, take = pair.partition("=")
        if not sep or not performer or not take:
            raise ValueError(f"--calibration expects PERFORMER=TAKE, got {pair!r}")
        chosen[performer] = take
    names = [p.name for p in config.performers]
    for performer in chosen:
        if performer not in names:
            raise ValueError(f"--calibration: no performer {performer!r} in {config.path}; "
                             f"the session has {', '.join(names)}")
    performers = type(config.performers)(
        dataclasses.replace(p, calibration=chosen[p.name]) if p.name in chosen else p
        for p in config.performers)
    return dataclasses.replace(config, performers=performers)


def parse_replay(pairs) -> dict[str, str]:
    replay = {}
    for pair in pairs or ():
        performer, sep, take = pair.partition("=")
        if not sep or not performer or not take:
            raise ValueError(f"--replay expects PERFORMER=TAKE, got {pair!r}")
        replay[performer] = take if take.startswith("replay:") else f"replay:{take}"
    return replay


def perform(config, *, mode, overrides, duration=None, quiet=False, out=None,
            extra_outputs=()):
    """Build and run a session with Ctrl-C and SIGUSR1 handling; returns (report, interrupted).
    Progress lines go to `out` (default: the sys.stderr of the moment of the call)."""
    from mop.session.build import build_session

    out = sys.stderr if out is None else out

    def say(text):
        if not quiet:
            print(text, file=out, flush=True)

    session = build_session(config, mode=mode, overrides=overrides, progress=say,
                            extra_outputs=extra_outputs)
    for output in session.outputs:
        url = getattr(output, "url", None)
        if url:
            print(f"preview: {url}", file=out, flush=True)

    interrupted = []

    def on_interrupt(signum, frame):
        if interrupted:  # a second Ctrl-C: stop at once (outputs are still closed on the way)
            raise KeyboardInterrupt
        interrupted.append(signum)
        session.request_stop()

    def on_report(signum, frame):
        print(session.report().format(), file=out, flush=True)

    last = [time.monotonic()]

    def progress(current):
        now = time.monotonic()
        if current.frame_index == 1:
            say(f"the show is on (warm-up {current.warmup_seconds:.1f} s)")
            last[0] = now
        if not quiet and now - last[0] >= 1.0:
            last[0] = now
            states = ", ".join(f"{name} {p['status']}:{p['action'] or 'rest'}"
                               f"@{p['progress']:.2f}" for name, p in
                               current.state()["performers"].items())
            print(f"frame {current.frame_index} t={current.t:.1f}s dropped={current.dropped} "
                  f"{states}", file=out, flush=True)

    previous_int = signal.signal(signal.SIGINT, on_interrupt)
    previous_usr1 = signal.signal(signal.SIGUSR1, on_report) if hasattr(signal, "SIGUSR1") else None
    try:
        say(f"performing {config.name}: {count(len(config.performers), 'performer')}, "
            f"{count(len(config.characters), 'character')}, {session.mode_label}, "
            f"{config.fps} fps")
        report = session.run(duration=duration, progress=progress)
    finally:
        signal.signal(signal.SIGINT, previous_int)
        if previous_usr1 is not None:
            signal.signal(signal.SIGUSR1, previous_usr1)
    return session, report, bool(interrupted)


def run(args) -> int:
    from mop.session import Mode, load_session
    from mop.session.build import Overrides
    from mop.session.config import REPLAY_PREFIX, parse_host_port

    from mop.commands._args import say_if_kernels_compile

    config = with_calibrations(load_session(args.session), args.calibration)
    say_if_kernels_compile()
    replay = parse_replay(args.replay)
    names = [p.name for p in config.performers]
    for performer in replay:
        if performer not in names:
            raise ValueError(f"--replay: no performer {performer!r} in {config.path}; the "
                             f"session has {', '.join(names)}")
    if args.replay is not None and not args.realtime:
        live = [p for p in config.performers
                if not replay.get(p.name, p.source).startswith(REPLAY_PREFIX)]
        if live:
            raise ValueError(f"--replay: performer {live[0].name!r} has a live source "
                             f"({live[0].source}); give --replay {live[0].name}=TAKE, or "
                             f"--realtime to follow it live")
    if args.no_render and (args.out or args.png):
        raise ValueError("--out and --png need pictures: leave out --no-render")
    mode = Mode.REPLAY if args.replay is not None and not args.realtime else Mode.LIVE
    if mode is Mode.REPLAY and args.duration is not None and not args.no_render:
        # as fast as the machine goes: a long --duration is hours of rendering
        from mop.commands._args import check_frame_budget
        check_frame_budget(int(args.duration * config.fps), fps=config.fps,
                           limit=args.max_frames)
    if mode is Mode.REPLAY and args.loop and args.duration is None:
        raise ValueError("--loop replays the takes forever, and without --realtime as fast as "
                         "the machine goes (a video without end): give --duration SECONDS, or "
                         "--realtime for a show that runs until Ctrl-C")
    osc = parse_host_port(args.osc_out, key="--osc-out") if args.osc_out else None
    out = args.out
    overrides = Overrides(replay=replay, video=out, png=args.png, osc=osc,
                          preview=args.preview, preview_host=args.preview_host,
                          loop_takes=args.loop, render=not args.no_render,
                          transparent=args.transparent)
    session, report, interrupted = perform(config, mode=mode, overrides=overrides,
                                           duration=args.duration, quiet=args.quiet)
    if interrupted:
        print("interrupted: every output was finalised", file=sys.stderr)
    print(report.format())
    for output in session.outputs:
        path = getattr(output, "path", None) or getattr(output, "folder", None)
        if path is not None:
            print(f"wrote {path} ({output.frames} frames)")
    return 130 if interrupted else 0
