"""`mop record`: record a demonstration: the performer acts along with a motion while their
input is captured; the action-motion pair is stored as a take. `--show` records a show take
instead: a performance with no motion paired, for `mop perform --replay` and sessions.
`--calibrate` records a performer's calibration take: the rest pose held for 2 s, then every
channel moved through its range; a session's `calibration = TAKE` maps that performer's input
onto the author's (`followers.calibration`).

Headless: the motion "plays" as a countdown and a progress bar in the terminal, and a preview
video of the motion (its channels as curves with a moving cursor) is written with OpenCV, to
watch beside the performer. The action is captured for the motion's duration, time-aligned to
it (MOP 3.1.3: the captured interval is normalised onto the motion's duration), written while
capturing (crash-safe), and right after, the new action is compared with the performer's other
takes: how confusable it is with them (`followers.confusability`).
"""
from __future__ import annotations

import math
import re
import sys
from pathlib import Path

from . import count

PREVIEW_SIZE = (640, 360)
PREVIEW_FPS = 25
MAX_TAKE_SECONDS = 600.0    # a demonstration is seconds long; a longer motion is a mistake
CALIBRATION_SECONDS = 8.0   # a calibration take: the rest pose, then the range
REST_SECONDS = 2.0          # its rest part (followers.calibration.REST_SECONDS)
LATE_SECONDS = 2.0          # how long after the end a take waits for frames of its time


def register(subparsers) -> None:
    from mop.commands._args import positive, rate, seconds, seconds_or_zero

    parser = subparsers.add_parser(
        "record", help="record a take: act along with a motion while a source is captured",
        description="Plays a motion (countdown and progress in the terminal, plus a preview "
                    "video), captures the performer's source for the motion's duration, "
                    "time-aligns action and motion, stores the take, and reports how confusable "
                    "the new action is with the performer's other takes. With --show: records "
                    "a show take (a performance, no motion) for --duration or until Ctrl-C.")
    parser.add_argument("--performer", required=True, help="who performs")
    parser.add_argument("--action", default=None,
                        help="the action's name (e.g. wave; default 'show' with --show)")
    parser.add_argument("--motion", default=None, metavar="MOTION",
                        help="the motion to act along with: a motion .json file, or the name of "
                             "a take whose motion to reuse")
    parser.add_argument("--show", action="store_true",
                        help="record a show take: a whole performance, no motion, no "
                             "confusability report (replay it with mop perform --replay)")
    parser.add_argument("--calibrate", action="store_true",
                        help="record a calibration take: hold the rest pose for the first "
                             f"{REST_SECONDS:g} s, then move every channel through its whole "
                             "range until the end (a session's calibration = TAKE uses it)")
    parser.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                        help="length of a --show take (default: until Ctrl-C) or of a "
                             f"--calibrate take (default {CALIBRATION_SECONDS:g} s)")
    parser.add_argument("--source", required=True, metavar="SPEC",
                        help="what to capture, e.g. hid:p5, camera:0:face, camera:0:hands, "
                             "camera:0:pose, camera:0:aruco, osc:127.0.0.1:9000/glove, "
                             "replay:recordings/NAME")
    parser.add_argument("--recordings", default="recordings", metavar="DIR",
                        help="the take folder (default: recordings)")
    parser.add_argument("--name", default=None, help="the take's name (default: "
                                                     "PERFORMER-ACTION-NNN)")
    parser.add_argument("--rate", type=rate, default=50.0,
                        help="session rate [Hz] the take's template is sampled at (default 50)")
    parser.add_argument("--countdown", type=seconds_or_zero, default=3.0,
                        help="seconds of countdown before the motion starts (default 3)")
    parser.add_argument("--preview", default=None, metavar="VIDEO",
                        help="where to write the motion preview video (default: "
                             "out/preview-ACTION.mp4; 'none' to skip)")
    parser.add_argument("--max-duration", type=positive, default=MAX_TAKE_SECONDS,
                        metavar="SECONDS",
                        help=f"refuse motions longer than this (default {MAX_TAKE_SECONDS:g} s)")
    parser.add_argument("--wait", type=seconds, default=5.0,
                        help="seconds to wait for the source's first frame (default 5)")
    parser.set_defaults(func=run)


# -- the preview video ------------------------------------------------------------------------

def write_motion_preview(motion, path, *, fps: float = PREVIEW_FPS,
                         size: tuple[int, int] = PREVIEW_SIZE) -> Path:
    """A video of the motion: each channel component as a curve over the whole clip, a cursor
    at the current time, and a progress bar. Written with OpenCV (.mp4: mp4v, .avi: MJPG,
    .mkv: FFV1). Returns the path."""
    import cv2
    import numpy as np

    from mop.export import open_writer

    path = Path(path)
    if path.suffix.lower() not in (".mp4", ".avi", ".mkv", ".webm"):
        raise ValueError(f"preview video must be .mp4, .avi, .mkv or .webm, got {path}")
    width, height = size
    duration = max(motion.duration, 1.0 / fps)
    frames = int(np.ceil(duration * fps)) + 1
    grid = np.linspace(0.0, duration, 200)
    sampled = motion.sample_many(grid)
    rows = []
    for name, block in sampled.items():
        block = np.asarray(block, dtype=np.float64).reshape(grid.size, -1)
        for k in range(block.shape[1]):
            rows.append((name if block.shape[1] == 1 else f"{name}.{k}", block[:, k]))
    rows = rows[:10]   # a readable preview; the take keeps every channel
    left, right, top, bottom = 110, 20, 20, 40
    plot_w = width - left - right
    lane = (height - top - bottom) / max(len(rows), 1)
    background = np.zeros((height, width, 3), np.uint8)
    background[:] = (30, 30, 30)
    colours = [(80, 200, 255), (120, 255, 120), (255, 160, 80), (200, 120, 255),
               (80, 255, 255), (255, 255, 120)]
    for k, (label, values) in enumerate(rows):
        low, high = float(np.min(values)), float(np.max(values))
        span = high - low if high > low else 1.0
        y0 = top + k * lane
        ys = y0 + lane * 0.85 - (values - low) / span * lane * 0.7
        xs = left + grid / duration * plot_w
        points = np.stack([xs, ys], axis=1).round().astype(np.int32)
        cv2.polylines(background, [points], False, colours[k % len(colours)], 2, cv2.LINE_AA)
        cv2.putText(background, label[:14], (8, int(y0 + lane * 0.6)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (220, 220, 220), 1, cv2.LINE_AA)
    # drawn in OpenCV's BGR order; the checked writer takes RGB (and reads the file back)
    rgb = np.empty_like(background)
    with open_writer(path, fps=fps, size=(width, height), background="black") as writer:
        frame = np.empty_like(background)
        for index in range(frames):
            t = min(index / fps, duration)
            np.copyto(frame, background)
            x = int(round(left + t / duration * plot_w))
            cv2.line(frame, (x, top), (x, height - bottom), (255, 255, 255), 1)
            bar = int(round(t / duration * (width - 2 * 8)))
            cv2.rectangle(frame, (8, height - 24), (8 + bar, height - 12), (90, 200, 90), -1)
            cv2.putText(frame, f"{t:5.2f} / {duration:.2f} s", (width - 170, height - 28),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.5, (230, 230, 230), 1, cv2.LINE_AA)
            np.copyto(rgb, frame[:, :, ::-1])
            writer.write(rgb)
    return path


# -- confusability ------------------------------------------------------------------------------

def _zscored(arrays):
    """A function z-scoring by every channel's mean and spread over ``arrays``, as a session
    would, so that no channel dominates by its units."""
    import numpy as np
    stacked = np.concatenate(arrays, axis=0)
    shift = np.nanmean(stacked, axis=0)
    scale = np.nanstd(stacked, axis=0)
    scale = np.where(np.isfinite(scale) & (scale > 1e-12), scale, 1.0)
    shift = np.where(np.isfinite(shift), shift, 0.0)
    return lambda values: (values - shift) / scale


def consistency_report(takes: list, new_name: str) -> list[str]:
    """Lines saying how consistent the takes of the new take's action are, ``takes`` its
    (take name, (T, D) array) pairs (followers.combine); none for a first take."""
    if len(takes) < 2:
        return []
    from followers import combine
    scaled = _zscored([values for _, values in takes])
    demos = combine([scaled(values) for _, values in takes])
    names = [take_name for take_name, _ in takes]
    lines = [f"{len(takes)} takes of this action; distance of each from their average "
             f"(channel spreads): " + ", ".join(
                 f"{n}{' (new)' if n == new_name else ''} {d:.2f}"
                 for n, d in zip(names, demos.distances))]
    odd = demos.outlier()
    if odd is not None:
        lines.append(f"  {names[odd]} strays from the others: record it again, or leave it out "
                     f"of the session's takes = [...]")
    return lines


def confusability_report(templates: dict, new_name: str) -> list[str]:
    """Lines saying how confusable action `new_name` is with the others, from
    followers.confusability over a bank of ``templates`` ({name: (T, D) array, or a list of
    them for an action of several takes}) (imported here, lazily: mop is the only package
    that may call into followers). Channels are z-scored over all the takes first."""
    if len(templates) < 2:
        return ["confusability: this is the performer's first action on these channels; "
                "nothing to compare yet"]
    import numpy as np

    from followers import FollowerBank, confusability
    arrays = [v for values in templates.values()
              for v in (values if isinstance(values, list) else [values])]
    scaled = _zscored(arrays)
    result = confusability(FollowerBank({
        name: [scaled(v) for v in values] if isinstance(values, list) else scaled(values)
        for name, values in templates.items()}))
    names = list(getattr(result, "names", templates))
    matrix = np.asarray(getattr(result, "matrix", result), dtype=float)
    if matrix.shape != (len(names), len(names)) or new_name not in names:
        return [f"confusability: unexpected result {type(result).__name__} "
                f"{getattr(matrix, 'shape', '')}"]
    k = names.index(new_name)
    lines = [f"confusability of {new_name} with the performer's other actions (share of "
             f"frames a follower accepts a demonstration, 0..1):",
             f"  its own follower accepts it on {matrix[k, k]:.0%} of frames"]
    decisions = getattr(result, "decisions", None)
    if decisions is not None and np.shape(decisions) == (len(names), len(names) + 1):
        lines[-1] += (f"; the bank picks it on {decisions[k, k]:.0%}, nothing on "
                      f"{decisions[k, -1]:.0%}")
    others = sorted((j for j in range(len(names)) if j != k),
                    key=lambda j: -max(matrix[k, j], matrix[j, k]))
    for j in others:
        worst = max(matrix[k, j], matrix[j, k])
        flag = "  <- too close: make one of them more distinct" if worst >= 0.5 else ""
        lines.append(f"  {names[j]:<24} accepts the new action {matrix[k, j]:.2f}; the new "
                     f"follower accepts it {matrix[j, k]:.2f}{flag}")
    return lines


def calibration_report(take, store=None) -> list[str]:
    """What a calibration take measured, per channel, against the newest calibration of each
    other performer in ``store`` with those channels, and how to use it."""
    from followers.calibration import calibrate
    from mop.takes import TakeError, calibration_of, newest_calibration
    # a channel too seldom seen to measure (a camera's other hand, an elbow out of the
    # picture) is named, not measured: a session whose performer does not use it can use the
    # take; with none measurable the take's own error is raised
    unseen = {}
    for channel in take.channels:
        try:
            calibration_of(take, [channel])
        except TakeError as error:
            unseen[channel] = str(error).split(": ", 1)[-1]
    measured = calibration_of(take, [c for c in take.channels if c not in unseen] or None)
    lines = [f"calibration of {take.performer}: rest and range (2nd-98th percentile) per "
             f"channel"]
    for name, rest, low, high in zip(measured.channels, measured.rest, measured.low,
                                     measured.high):
        still = "  (did not move: only its rest will be matched)" if not high > low else ""
        lines.append(f"  {name:<24} rest {rest:10.4g}   range {low:10.4g} .. {high:<10.4g}"
                     f"{still}")
    others = sorted({info.performer for info in store.list()} - {take.performer}) \
        if store is not None else []
    for channel, why in unseen.items():
        lines.append(f"  {channel:<24} not calibrated: {why}")
    for other in others:
        name = newest_calibration(store, other, measured.channels)
        if name is None:
            continue
        try:
            reference = calibration_of(store.load(name), measured.channels)
        except TakeError as error:
            lines.append(f"  onto {other} ({name}): {error}")
            continue
        mapped = calibrate(measured, reference)
        lines.append(f"  onto {other} ({name}): gain " + ", ".join(
            f"{c} {g:.2f}" for c, g in zip(measured.channels, mapped.gain)))
    lines.append(f"use it in a session: [performers.NAME] calibration = \"{take.name}\" (the "
                 f"author records one too, with the same channels)")
    return lines


# -- the command ------------------------------------------------------------------------------

def _load_motion(spec: str, store):
    from characters import Motion
    path = Path(spec)
    if path.suffix.lower() == ".json":
        return Motion.load(path)
    if spec in store:
        take = store.load(spec)
        if take.motion is None:
            raise ValueError(f"take {spec!r} has no motion to reuse")
        return take.motion
    raise FileNotFoundError(f"--motion {spec!r}: neither a motion .json file nor a take in "
                            f"{store.path}")


def _progress(action: str, duration: float | None):
    """A bar over the take's seconds (the seconds so far when it runs until Ctrl-C), with the
    frame count and the source's status after it: redrawn in place on a terminal, a line per
    second in a log."""
    from tqdm import tqdm
    bar = ("{desc} [{bar:30}] {n:5.2f} / {total:.2f} s  {postfix}" if duration is not None
           else "{desc} {n:7.2f} s (Ctrl-C ends the take)  {postfix}")
    return tqdm(total=duration, desc=f"  {action}", file=sys.stdout, bar_format=bar,
                mininterval=0.1 if sys.stdout.isatty() else 1.0)


def run(args) -> int:
    # errors (a device that is not there or went silent, a full disk) are one line from mop.cli
    return _record(args)


def _storage_failure(error: OSError, recorder) -> Exception:
    """The one message for a take file that could not be written: what stays, what to do."""
    import errno

    from mop.commands._args import CommandError

    what = "no space left on the disk" if error.errno == errno.ENOSPC else \
        (error.strerror or str(error))
    kept = recorder.frames_kept
    if kept == 0:
        recorder.discard()
        return CommandError(f"{recorder.path}: {what}; nothing was recorded, so no take was "
                            f"kept")
    return CommandError(f"{recorder.path}: {what} during the take; the {kept} frames recorded "
                        f"before are kept as take {recorder.name} (marked interrupted: `mop "
                        f"takes show {recorder.name}`)")


def _plan(args, store) -> tuple:
    """(motion or None, duration [s] or None = until Ctrl-C, preview path or None) from the
    arguments, checked before anything is opened."""
    if not args.rate > 0:
        raise ValueError(f"--rate must be > 0 Hz, got {args.rate}")
    if args.countdown < 0:
        raise ValueError(f"--countdown must be >= 0 s, got {args.countdown}")
    if args.show and args.calibrate:
        raise ValueError("--show and --calibrate are two kinds of take: give one")
    if args.calibrate:
        from mop.takes import CALIBRATION_ACTION
        if args.action not in (None, CALIBRATION_ACTION):
            raise ValueError(f"--calibrate records the take of action "
                             f"{CALIBRATION_ACTION!r}: leave out --action")
        if args.motion is not None:
            raise ValueError("--calibrate records the rest pose and the range without a motion: "
                             "leave out --motion")
        duration = CALIBRATION_SECONDS if args.duration is None else args.duration
        if not (duration > REST_SECONDS and duration < float("inf")):
            raise ValueError(f"--duration of a calibration take must be a number of seconds > "
                             f"{REST_SECONDS:g} (the rest pose), got {duration}")
        return None, duration, None
    if args.show:
        if args.motion is not None:
            raise ValueError("--show records a performance without a motion: leave out --motion")
        duration = args.duration
        if duration is not None and not (duration > 0 and duration < float("inf")):
            raise ValueError(f"--duration must be a number of seconds > 0, got {duration}")
        return None, duration, None
    if args.motion is None:
        raise ValueError("--motion: give the motion to act along with (a motion .json file or "
                         "a take's name), or --show to record a show take without one")
    if args.duration is not None:
        raise ValueError("--duration is for --show takes: a demonstration lasts as long as "
                         "its motion")
    motion = _load_motion(args.motion, store)
    duration = float(motion.duration)
    if not duration > 0:
        raise ValueError(f"the motion lasts {duration} s; nothing to act along with")
    if duration > args.max_duration:
        raise ValueError(f"the motion lasts {duration:.6g} s: a take that long (and its "
                         f"{int(duration * PREVIEW_FPS):,}-frame preview) is refused; the limit "
                         f"is {args.max_duration:g} s: use a shorter motion, or lift the limit "
                         f"with --max-duration {math.ceil(duration)}")

    preview = None
    if (args.preview or "").lower() != "none":
        # the action name is free text: only its safe characters make the default file name
        safe = re.sub(r"[^A-Za-z0-9._-]+", "_", args.action).strip("._-") or "action"
        preview = Path(args.preview or f"out/preview-{safe}.mp4")
        write_motion_preview(motion, preview)
        print(f"motion preview: {preview} ({duration:.2f} s, "
              f"{count(len(motion.channel_names), 'channel')}) - play it beside you while "
              f"recording")
    return motion, duration, preview


def _capture(source, recorder, start: float, duration: float | None, label: str) -> None:
    """Append the frames of [start, start + duration] (or until Ctrl-C when duration is None)
    to the recorder, with a progress bar."""
    clock = source.clock
    end = start + duration if duration is not None else float("inf")
    with _progress(label, duration) as progress:
        try:
            while (now := clock.now()) < end:
                frame = source.read(timeout=min(0.05, max(end - now, 0.001)))
                if frame is not None and start <= frame.t <= end:
                    recorder.append_frame(frame, channels=source.channels)
                elif frame is None and source.ended:
                    end = clock.now()      # a file or a take played to its end ends the take
                    break
                elapsed = clock.now() - start
                rate = getattr(source, "frame_rate", None)   # a camera: what its tracker keeps up
                progress.set_postfix_str(f"frames {recorder.frames}  "
                                         f"{f'{rate:.0f} fps  ' if rate else ''}"
                                         f"{source.status.value}", refresh=False)
                progress.n = min(elapsed, duration or elapsed)   # set, not summed: no drift
                progress.update(0)
        except KeyboardInterrupt:
            if duration is not None:
                raise
            end = clock.now()             # a show recorded until Ctrl-C ends here
        _late_frames(source, recorder, start, end)
        progress.set_postfix_str(f"frames {recorder.frames}", refresh=False)
        progress.n = min(end - start, duration if duration is not None else end - start)
        progress.refresh()
    if duration is not None and end < start + duration:
        print(f"  the source ended after {end - start:.2f} of {duration:.2f} s; the take holds "
              f"what it sent", flush=True)


def _late_frames(source, recorder, start: float, end: float) -> None:
    """Append the frames of the take that arrive after its end: a tracker running behind (a
    camera on a busy machine) delivers them late. Reads until a frame from after the end
    arrives, the source ends, or LATE_SECONDS pass."""
    import time
    deadline = time.monotonic() + LATE_SECONDS
    while time.monotonic() < deadline:
        frame = source.read(timeout=0.05)
        if frame is None:
            if source.ended:
                return
            continue
        if frame.t > end:
            return
        if frame.t >= start:
            recorder.append_frame(frame, channels=source.channels)


def _countdown(source, seconds: float, action: str) -> float:
    """Count down `seconds` aloud, dropping what the source sends meanwhile; the start time."""
    clock = source.clock
    end_countdown = clock.now() + seconds
    shown = None
    while (left := end_countdown - clock.now()) > 0:
        second = int(left) + 1
        if second != shown:
            print(f"  {action} starts in {second}...", flush=True)
            shown = second
        source.read(timeout=min(left, 0.05))   # keep the queue fresh; frames not kept
    while source.read(timeout=0) is not None:
        pass
    return clock.now()


def _record(args) -> int:
    from capture import open_source
    from mop.takes import CALIBRATION_ACTION, CALIBRATION_KEY, TakeStore, check_name

    action = args.action or ("show" if args.show else
                             CALIBRATION_ACTION if args.calibrate else None)
    if not action:
        raise ValueError("--action: name the action (e.g. wave)")
    if args.name:
        check_name(args.name)
    store = TakeStore(args.recordings)
    motion, duration, preview = _plan(args, store)

    source = open_source(args.source)
    recorder = None
    try:
        _greet(source, args)
        start = _countdown(source, args.countdown, action)
        info = source.describe()
        # what later processing of this take needs to interpret its numbers
        calibration = {key: info[key] for key in ("camera_matrix", "dist_coeffs",
                                                  "marker_length", "units", "frame_size")
                       if info.get(key) is not None}
        extra = {"show": True} if args.show else \
            {CALIBRATION_KEY: {"rest_seconds": REST_SECONDS}} if args.calibrate else \
            {"preview": str(preview) if preview else None}
        recorder = store.record(performer=args.performer, action=action,
                                channels=source.channels or None, motion=motion,
                                rate=args.rate, device=args.source, device_info=info,
                                calibration=calibration, stream_rate=source.rate,
                                name=args.name, start=start, extra=extra)
        length = f"for {duration:.2f} s" if duration is not None else "until Ctrl-C"
        if args.calibrate:
            print(f"  hold still in your rest pose for {REST_SECONDS:g} s, then move every "
                  f"channel through its whole range until the end", flush=True)
        print(f"  GO - recording {recorder.name} {length}", flush=True)
        _capture(source, recorder, start, duration, action)
        stats = source.stats
        source_stats = {"frames": stats.frames, "dropped": stats.dropped,
                        "malformed": stats.malformed, "nan_values": stats.nan_values}
        if hasattr(source, "timing"):           # a camera: how its tracker kept up
            source_stats["tracking"] = source.timing()
        recorder.update(source_stats=source_stats)
        if recorder.frames < 2:
            recorder.discard()
            raise OSError(f"{args.source}: only {count(recorder.frames, 'frame')} arrived "
                          f"during the take; nothing stored")
        # time alignment (MOP 3.1.3): the captured interval [0, duration] of the recorder's
        # clock is what pairs with the whole motion; Take.aligned() normalises it. A show take
        # pairs with nothing.
        alignment = None if motion is None else {
            "method": "duration", "action_start": 0.0, "action_end": duration,
            "motion_duration": duration}
        name = recorder.finish(alignment=alignment)
    except BaseException as error:
        if recorder is not None:
            recorder.abort()            # no-op when it was finished or discarded already
            if isinstance(error, KeyboardInterrupt):
                print(f"\ninterrupted: the partial take is kept as {recorder.name} (marked "
                      f"interrupted); delete it with `mop takes delete {recorder.name}`",
                      file=sys.stderr)
            elif isinstance(error, OSError) and error.filename == str(recorder.path):
                raise _storage_failure(error, recorder) from error
        raise
    finally:
        source.close()

    return _report_take(args, store, name, motion, stats)


def _greet(source, args) -> None:
    """Wait for the source's first frame, then say what it delivers."""
    first = source.read(timeout=args.wait)
    if first is None:
        raise OSError(f"{args.source}: no frame within {args.wait:g} s (status "
                      f"{source.status.value}); is the performer's input running?")
    names = ", ".join(source.channels[:8]) + (", ..." if len(source.channels) > 8 else "")
    print(f"source {args.source}: {count(len(source.channels), 'channel')} ({names})")
    if getattr(source, "smoothing", None) is not None:
        print("  note: smoothing is on; the take keeps smoothed values, not raw ones "
              "(leave smooth off to record raw takes)")


def _report_take(args, store, name, motion, stats) -> int:
    """What was stored, then the calibration's report, or how the take agrees with the
    performer's other takes of its action and how it could be confused with other actions."""
    from mop.takes import performer_templates

    take = store.load(name)
    missing = int(take.values.size - (take.values == take.values).sum())
    print(f"stored take {name}: {count(take.times.size, 'frame')} "
          f"({take.times[-1] - take.times[0]:.2f} s), {count(len(take.channels), 'channel')}, "
          f"{count(missing, 'missing value')}, {stats.malformed} malformed inputs skipped, "
          f"{stats.dropped} dropped -> {store.file(name)}")
    if args.calibrate:
        for line in calibration_report(take, store):
            print(line)
        return 0
    if motion is None:
        print(f"a show take: replay it with `mop perform SESSION --replay "
              f"{args.performer}=replay:{store.file(name)}`")
        return 0
    templates = performer_templates(store, args.performer, rate=args.rate,
                                    channels=take.channels)
    templates[name] = take.aligned(args.rate)[1]
    # numbered takes of one action are one action with several takes
    action_of = {info.name: info.action for info in store.list(performer=args.performer)}
    action_of[name] = args.action
    actions: dict = {}
    for take_name, values in templates.items():
        actions.setdefault(action_of.get(take_name, take_name), []).append((take_name, values))
    for line in consistency_report(actions[args.action], name):
        print(line)
    grouped = {action: [v for _, v in pairs] if len(pairs) > 1 else pairs[0][1]
               for action, pairs in actions.items()}
    for line in confusability_report(grouped, args.action):
        print(line)
    return 0
