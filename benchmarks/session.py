"""Session loop cost for 1x1, 2x3 and 4x8 performers x characters (replay mode, one core),
and the shipped demo performed live.

    python3 benchmarks/session.py [--frames 150] [--mix image,demo] [--render]
    python3 benchmarks/session.py --live [--busy] [--seconds 11]
    python3 benchmarks/session.py --writer

For each size it builds a session on the shipped demo takes (each performer replays the glove or
the hand show; each character is bound to one performer's action) and prints, per frame:
median (and p90) milliseconds of each stage — capture, follow, simulate, render (with --render)
— the frame excluding rendering, and the input-to-pose latency (from reading the newest input
to the puppets holding the pose it asked for). Two character mixes:

- image: every character is the shipped cut-out (momo, 401 vertices) — the lightest real puppet;
- demo: the demo's kinds in turn (momo, the medial caterpillar, the latex frog at 1000 masses).

Plain reference, same process: the same banks and puppets stepped in a bare loop (no feeds, no
blending, no bookkeeping); "overhead" is the session frame minus that reference, i.e. what the
session itself adds. Targets: 4x8 frame without rendering <= 10 ms on one core;
input-to-pose latency well under MOP's 11.4 ms.

--live performs sessions/demo.toml (2 performers x 3 characters: the latex frog, the cut-out,
the medial caterpillar, 960x540) in real time on both cores, writing an MP4, as
`mop perform sessions/demo.toml --realtime --out demo.mp4` does; with --busy a spinning
process holds the second core. It prints the pictures dropped (target <= 5 % with the machine
otherwise idle) and the input-to-pose latency (target p90 <= 10 ms), against the same show
performed live without pictures (the loop alone) in the same run. --pictures thread,process
compares the two render workers (`mop.session.worker`).

--writer times one 960x540 MP4 frame on one core as the session's video output writes it
(`mop.export` VideoFileWriter: a new frame, and a dropped render's repeat) against a plain
reference in the same run: `over_colour`, a reversed-channel copy to BGR, OpenCV's write.
"""
from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

# benchmarks/capture.py would shadow the capture package: drop this folder from the path
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TAKES = ROOT / "recordings" / "demo"
SIZES = ((1, 1), (2, 3), (4, 8))

# what a character of each kind plays, per performer kind: (take, {motion channel: target})
BINDINGS = {
    ("image", "glove"): ("glove_ripple", {}),
    ("image", "hand"): ("hand_lift", {}),
    ("medial", "glove"): ("glove_chomp", {"thumb": "jaw", "index": "head", "middle": "front"}),
    ("medial", "hand"): ("hand_circle", {}),
    ("latex", "glove"): ("glove_chomp", {}),
    ("latex", "hand"): ("hand_circle", {"front": "thumb", "tail": "index"}),
}
ASSETS = {"image": "momo", "medial": "medial_caterpillar", "latex": "froggy"}


def session_table(performers: int, characters: int, mix: str) -> dict:
    kinds = ["image"] if mix == "image" else ["image", "medial", "latex"]
    table = {"session": {"fps": 25, "blend": 0.3, "size": [640, 360], "takes": str(TAKES)},
             "performers": {}, "characters": {}, "actions": []}
    performer_kinds = []
    for p in range(performers):
        kind = "glove" if p % 2 == 0 else "hand"
        performer_kinds.append(kind)
        table["performers"][f"p{p}"] = {"source": f"replay:{kind}_show"}
    for c in range(characters):
        kind = kinds[c % len(kinds)]
        p = c % performers
        character = {"kind": kind, "asset": ASSETS[kind],
                     "position": [(c % 4 + 0.5) / 4, (c // 4 + 0.5) / 2], "scale": 0.45}
        if kind == "latex":
            character["options"] = {"masses": 1000}
        table["characters"][f"c{c}"] = character
        take, channels = BINDINGS[(kind, performer_kinds[p])]
        action = {"take": take, "performer": f"p{p}", "character": f"c{c}"}
        if channels:
            action["channels"] = channels
        table["actions"].append(action)
    return table


def bare_reference(session, frames: int) -> float:
    """Median ms per frame of the same banks and puppets stepped without the session."""
    inputs = []
    for performer in session.performers:
        feed = performer.feed
        rows = [np.array(feed.poll(k / session.fps)) for k in range(frames)]
        inputs.append([performer.prepare(row) for row in rows])
    targets = []
    for character in session.characters:
        sample = {}
        for track in character.tracks:
            motion, channels = next(iter(track.motions.values()))
            values = motion.sample(0.5 * motion.duration)
            for channel, target in channels:
                value = values[channel]
                sample[target] = float(value[0]) if len(value) == 1 else value
        targets.append(sample)
    for performer in session.performers:
        performer.bank.reset()
    for character in session.characters:
        character.puppet.reset()
    times = []
    for k in range(frames):
        start = time.perf_counter()
        for performer, rows in zip(session.performers, inputs):
            performer.bank.step(rows[k])
        for character, sample in zip(session.characters, targets):
            character.puppet.step(session.dt, sample)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


class NullOutput:
    """A frame output that keeps nothing: the pictures are drawn by the render worker."""

    def write(self, frame, state, *, repeat=False):
        pass

    def close(self):
        pass


def measure(performers: int, characters: int, mix: str, frames: int, render: bool) -> dict:
    from mop.session import Mode, parse_session
    from mop.session.build import Overrides, build_session
    config = parse_session(session_table(performers, characters, mix), where="benchmark")
    session = build_session(config, mode=Mode.REPLAY, overrides=Overrides(render=render),
                            extra_outputs=[NullOutput()] if render else ())
    session.run(duration=(frames + 0.5) / config.fps)
    stages = session.report().stages
    reference = bare_reference(session, frames)
    excluding = np.array([0.0])
    counts = min(stages["capture"]["count"], session.clock.capacity)
    parts = [session.clock.values(name)[:counts] for name in ("capture", "follow", "simulate")]
    excluding = parts[0] + parts[1] + parts[2]
    return {"stages": stages, "frame": float(np.median(excluding)),
            "frame_p90": float(np.percentile(excluding, 90)), "reference": reference}


def perform_live(seconds: float, pictures: bool, worker: str = "process") -> dict:
    """The shipped demo performed live for `seconds`: the session's report as a dict, with the
    CPU milliseconds per frame of the show (every thread, and the render process from its
    first picture on) as "cpu_ms"."""
    import resource
    import tempfile

    from mop.session import Mode, load_session
    from mop.session.build import Overrides, build_session
    config = load_session(ROOT / "sessions" / "demo.toml")
    with tempfile.TemporaryDirectory() as folder:
        video = str(Path(folder) / "demo.mp4") if pictures else None
        session = build_session(config, mode=Mode.LIVE,
                                overrides=Overrides(video=video, render=pictures))
        session.pictures = worker
        session.warm_up()
        before = resource.getrusage(resource.RUSAGE_SELF)
        report = session.run(duration=seconds).to_dict()
        after = resource.getrusage(resource.RUSAGE_SELF)
        cpu = (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
               + getattr(session.worker, "cpu_seconds", 0.0))
        report["cpu_ms"] = 1e3 * cpu / max(report["frames"], 1)
    return report


def busy_core():
    """A process spinning on the last core (None with a single core)."""
    import subprocess
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    if len(cores) < 2:
        return None
    process = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    os.sched_setaffinity(process.pid, {cores[-1]})
    return process


def live(seconds: float, busy: bool, workers: list[str]) -> None:
    spinner = busy_core() if busy else None
    try:
        print(f"the shipped demo performed live for {seconds:g} s, "
              f"{len(os.sched_getaffinity(0))} cores"
              f"{', the second held by a spinning process' if spinner else ''}")
        print(f"{'run':<29}{'frames':>7}{'dropped':>9}{'%':>7}{'late':>6}{'slipped':>9}"
              f"{'simulate':>10}{'in->pose':>10}{'p90':>7}{'render':>8}{'cpu/frame':>11}")
        runs = [("loop alone (no pictures)", False, "process")] + [
            (f"pictures + MP4, {worker}", True, worker) for worker in workers]
        for name, pictures, worker in runs:
            report = perform_live(seconds, pictures, worker)
            stages, frames = report["stages"], max(report["frames"], 1)
            render = stages.get("render", {}).get("median", float("nan"))
            print(f"{name:<29}{report['frames']:>7}{report['dropped']:>9}"
                  f"{100.0 * report['dropped'] / frames:>7.1f}{report['late_frames']:>6}"
                  f"{report['slipped']:>9.2f}{stages['simulate']['median']:>10.2f}"
                  f"{stages['input_to_pose']['median']:>10.2f}"
                  f"{stages['input_to_pose']['p90']:>7.2f}{render:>8.1f}"
                  f"{report['cpu_ms']:>11.1f}", flush=True)
            parts = ", ".join(f"{name[9:]} {row['median']:.2f} (p90 {row['p90']:.2f})"
                              for name, row in stages.items() if name.startswith("simulate "))
            print(f"{'':<4}simulate per character, median ms: {parts}", flush=True)
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    print("ms; cpu/frame: the process's CPU time (every thread) per frame; a frame has "
          "40 ms of each core")
    print("targets: pictures dropped <= 5 % (machine otherwise idle); input-to-pose p90 "
          "<= 10 ms")


def writer_cost(repeats: int = 60) -> None:
    """Median milliseconds of one 960x540 MP4 frame, written three ways (see the module)."""
    import tempfile

    import cv2

    from mop.export import open_writer, over_colour
    rng = np.random.default_rng(0)
    colour = (29, 35, 48)                       # the demo's background
    frame = np.empty((540, 960, 4), np.uint8)
    frame[:, :, :3], frame[:, :, 3] = colour, 255
    frame[100:400, 100:500] = rng.integers(0, 256, (300, 400, 4))   # a translucent character
    bgr = np.empty((540, 960, 3), np.uint8)

    def median(write) -> float:
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            write()
            times.append(time.perf_counter() - start)
        return 1e3 * float(np.median(times))

    def plain(encoder):
        bgr[...] = over_colour(frame, colour)[:, :, ::-1]
        encoder.write(bgr)

    with tempfile.TemporaryDirectory() as folder:
        encoder = cv2.VideoWriter(str(Path(folder) / "plain.mp4"),
                                  cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (960, 540))
        reference = median(lambda: plain(encoder))
        encoder.release()
        with open_writer(Path(folder) / "demo.mp4", fps=25, size=(960, 540),
                         background=colour) as writer:
            new = median(lambda: writer.write(frame))
            again = median(writer.repeat)
    print(f"one 960x540 MP4 frame, median of {repeats}, one core (ms)")
    print(f"{'plain reference (over_colour, BGR copy, write)':<48}{reference:>7.2f}")
    print(f"{'VideoFileWriter.write':<48}{new:>7.2f}{reference / new:>7.1f}x")
    print(f"{'VideoFileWriter.repeat (a dropped render)':<48}{again:>7.2f}"
          f"{reference / again:>7.1f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--live", action="store_true",
                        help="perform the shipped demo live (both cores; see the module)")
    parser.add_argument("--busy", action="store_true",
                        help="with --live: a spinning process holds the second core")
    parser.add_argument("--seconds", type=float, default=11.0,
                        help="with --live: how long the show runs")
    parser.add_argument("--pictures", default="process",
                        help="with --live: render worker(s) to measure, 'process' and/or "
                             "'thread', comma-separated")
    parser.add_argument("--writer", action="store_true",
                        help="time one MP4 frame as the video output writes it")
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--mix", default="image,demo", help="image, demo or both")
    parser.add_argument("--render", action="store_true",
                        help="also render (OpenGL for 3D kinds: slow without a GPU)")
    parser.add_argument("--cores", type=int, default=1, help="CPU cores to run on (default 1)")
    args = parser.parse_args()
    if args.live:
        live(args.seconds, args.busy, args.pictures.split(","))
        return
    if hasattr(os, "sched_setaffinity") and args.cores:
        os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[:args.cores]))
    if args.writer:
        writer_cost()
        return
    print(f"session benchmark: {args.frames} frames at 25 fps, replay mode, "
          f"{len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else '?'} core(s)"
          f"{', rendering 640x360' if args.render else ', no rendering'}")
    header = (f"{'mix':<6}{'P x C':>6}{'capture':>9}{'follow':>8}{'simulate':>10}"
              f"{'frame':>8}{'p90':>7}{'bare':>7}{'overhead':>9}{'in->pose':>10}{'p90':>7}"
              + (f"{'render':>8}{'loop':>7}" if args.render else ""))
    for mix in args.mix.split(","):
        print()
        print(header)
        rows = []
        for performers, characters in SIZES:
            result = measure(performers, characters, mix, args.frames, args.render)
            stages = result["stages"]
            rows.append((performers, characters, result))
            line = (f"{mix:<6}{performers:>3}x{characters:<2}"
                    f"{stages['capture']['median']:>9.3f}{stages['follow']['median']:>8.3f}"
                    f"{stages['simulate']['median']:>10.3f}{result['frame']:>8.3f}"
                    f"{result['frame_p90']:>7.2f}{result['reference']:>7.2f}"
                    f"{result['frame'] - result['reference']:>9.3f}"
                    f"{stages['input_to_pose']['median']:>10.3f}"
                    f"{stages['input_to_pose']['p90']:>7.2f}")
            if args.render:
                line += (f"{stages['render']['median']:>8.2f}"
                         f"{stages['total']['median']:>7.2f}")
            print(line, flush=True)
        base = rows[0][2]
        for performers, characters, result in rows[1:]:
            stages, first = result["stages"], base["stages"]
            print(f"  {performers}x{characters} vs 1x1: follow x"
                  f"{stages['follow']['median'] / max(first['follow']['median'], 1e-9):.1f} "
                  f"(performers x{performers}), simulate x"
                  f"{stages['simulate']['median'] / max(first['simulate']['median'], 1e-9):.1f}"
                  f" (characters x{characters}), frame x"
                  f"{result['frame'] / max(base['frame'], 1e-9):.1f}; per character "
                  f"{stages['simulate']['median'] / characters:.2f} ms, per performer "
                  f"{stages['follow']['median'] / performers:.3f} ms")
    compose()
    print("\ntargets: 4x8 frame (capture + follow + simulate) <= 10 ms on one core; "
          "input-to-pose well under MOP's 11.4 ms")


def numpy_over_opaque(canvas, layer, x0, y0):
    """Plain reference: the same integer mix in whole-array NumPy (temporaries per call)."""
    h, w = layer.shape[:2]
    dst = canvas[y0:y0 + h, x0:x0 + w, :3]
    alpha = layer[..., 3:4].astype(np.uint16)
    mixed = layer[..., :3] * alpha
    mixed += dst * (255 - alpha)
    mixed += 127
    mixed //= 255
    dst[...] = mixed


def compose(repeats: int = 60) -> None:
    """Composing the demo's frame: clear 960x540 and place three mostly transparent character
    layers (a 3D layer of 390x390 and two of 432x432, each with an opaque disc covering about
    a third of it and an anti-aliased rim), compiled against the NumPy reference."""
    from mop.render.compose import Stage, blend_over
    stage = Stage((960, 540), (29, 35, 48))
    layers = []
    for size in (390, 432, 432):
        yy, xx = np.mgrid[:size, :size]
        radius = np.hypot(xx - size / 2, yy - size / 2) / (size * 0.33)
        layer = np.zeros((size, size, 4), np.uint8)
        layer[..., :3] = (200, 120, 60)
        layer[..., 3] = np.clip((1.0 - radius) * 40 * 255, 0, 255).astype(np.uint8)
        layers.append((layer, (20 + 244 * len(layers), 40)))  # inside the frame
    blank = stage.clear().copy()

    def compiled():
        stage.clear()
        for layer, (x0, y0) in layers:
            blend_over(stage.frame, layer, x0, y0, opaque=True)

    def reference():
        stage.frame[..., :3] = blank[..., :3]
        stage.frame[..., 3] = 255
        for layer, (x0, y0) in layers:
            numpy_over_opaque(stage.frame, layer, x0, y0)

    compiled()
    fast = stage.frame.copy()
    reference()
    same = np.array_equal(fast, stage.frame)
    times = {"compiled": [], "numpy": []}
    for _ in range(repeats):
        for name, run in (("compiled", compiled), ("numpy", reference)):
            start = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - start)
    fast_ms, slow_ms = (1e3 * float(np.median(times[k])) for k in ("compiled", "numpy"))
    print(f"\ncompose the demo's frame (clear 960x540 + 3 layers): {fast_ms:.2f} ms compiled, "
          f"{slow_ms:.2f} ms NumPy reference (x{slow_ms / fast_ms:.0f}); identical pixels: {same}")


if __name__ == "__main__":
    main()
