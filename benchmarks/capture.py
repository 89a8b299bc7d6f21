"""Capture benchmarks: frame latency per source kind, tracker speed at 640x480, HID parsing, and
the take store's write throughput and commit intervals.

    python3 benchmarks/capture.py            # everything (about two minutes)
    python3 benchmarks/capture.py --quick    # shorter runs
    python3 benchmarks/capture.py --only markerless   # one section (see --help)

The markerless trackers (face, hands, pose: MediaPipe) are timed pinned to one core, per
640x480 frame: wall and CPU time of `process()`, next to MediaPipe's own `process()` on the same
RGB frame (the plain reference: what the model costs without our conversion and geometry), and
the live path's latency from a frame's grab to its Frame in `read()`, next to grabbing,
decoding and tracking inline in one thread.

Latency is "arrival -> Frame": from the moment the data reached this process (the OS read
returned; that moment is the frame's timestamp) to the moment `source.read()` hands the Frame to
the caller, on a reader that waits in `read()`. For OSC the send -> Frame time over loopback is
shown too, next to a plain socket receiving the same packets in the same process. The HID figure
runs the real hidapi path on a umockdev-simulated /dev/hidraw node (skipped without umockdev).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import socket
import sqlite3
import struct
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from capture import open_source  # noqa: E402
from capture.store import StoreWriter  # noqa: E402


def stats_ms(seconds) -> str:
    values = np.asarray(seconds, dtype=float) * 1e3
    return (f"median {np.median(values):7.3f} ms  p90 {np.percentile(values, 90):7.3f} ms  "
            f"max {values.max():7.3f} ms  (n={values.size})")


def section(title: str) -> None:
    print(f"\n== {title}")


# -- latency --------------------------------------------------------------------------------

def osc_packet(value: float) -> bytes:
    """/x with one double (t sent) and one float: built by hand to keep the sender cheap."""
    return b"/x\x00\x00,df\x00" + struct.pack(">df", value, 0.0)


def bench_osc(duration: float) -> None:
    section("OSC over loopback UDP (500 packets/s)")
    period = 1 / 500

    # plain reference: a bare socket, read in a thread, same pacing
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.5)
    plain = []

    def listen():
        while True:
            try:
                data = receiver.recv(256)
            except socket.timeout:
                return
            plain.append(time.monotonic() - struct.unpack(">d", data[8:16])[0])

    thread = threading.Thread(target=listen)
    thread.start()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    address = receiver.getsockname()
    end = time.monotonic() + duration
    while time.monotonic() < end:
        sender.sendto(osc_packet(time.monotonic()), address)
        time.sleep(period)
    thread.join()
    receiver.close()

    source = open_source("osc:127.0.0.1:0/x?channels=2")
    sent_to_frame, arrival_to_frame = [], []

    def consume():
        while not source.closed:
            frame = source.read(timeout=0.2)
            if frame is None:
                continue
            now = time.monotonic()
            sent_to_frame.append(now - frame.values[0])
            arrival_to_frame.append(now - frame.t)

    thread = threading.Thread(target=consume)
    thread.start()
    end = time.monotonic() + duration
    while time.monotonic() < end:
        sender.sendto(osc_packet(time.monotonic()), ("127.0.0.1", source.port))
        time.sleep(period)
    time.sleep(0.2)
    stats = source.stats
    source.close()
    thread.join()
    print(f"  plain socket  send -> recv : {stats_ms(plain)}")
    print(f"  OscSource     send -> Frame: {stats_ms(sent_to_frame)}   "
          f"ratio of medians {np.median(sent_to_frame) / np.median(plain):.2f}")
    print(f"  OscSource  arrival -> Frame: {stats_ms(arrival_to_frame)}")
    print(f"  frames {stats.frames}, dropped {stats.dropped}, malformed {stats.malformed}")


def bench_replay(duration: float, folder: Path) -> None:
    section("replay of a stored take in real time (200 Hz)")
    count = int(duration * 200)
    path = folder / "bench.sqlite"
    with StoreWriter(path, overwrite=True) as writer:
        writer.add_stream("action", [f"c{i}" for i in range(16)], rate=200.0)
        writer.append_many("action", np.arange(count) / 200.0, np.zeros((count, 16)))
    late = []
    with open_source(f"replay:{path}") as source:
        for frame in source:
            late.append(time.monotonic() - frame.t)
    print(f"  scheduled -> Frame: {stats_ms(late)}")


def bench_camera(duration: float, folder: Path) -> None:
    import cv2
    section("video file as a camera (640x480 at 30 fps, colour tracker)")
    frames = int(duration * 30)
    path = folder / "bench.mkv"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30.0, (640, 480))
    for k in range(frames):
        image = np.full((480, 640, 3), 40, np.uint8)
        cv2.circle(image, (100 + 4 * (k % 100), 240), 20, (0, 0, 255), -1)
        writer.write(image)
    writer.release()
    late = []
    with open_source(f"camera:{path}:color") as source:
        for frame in source:
            late.append(time.monotonic() - frame.t)
    print(f"  grab -> Frame (includes decoding and tracking): {stats_ms(late)}")


HID_CHILD = textwrap.dedent("""\
    import json, sys, time
    import numpy as np
    from capture import open_source
    source = open_source("hid:spacemouse")
    late, deadline = [], time.monotonic() + float(sys.argv[1]) + 10
    while len(late) < int(sys.argv[2]) and time.monotonic() < deadline:
        frame = source.read(timeout=0.2)
        if frame is not None:
            late.append(time.monotonic() - frame.t)
    source.close()
    print(json.dumps(late[5:]))   # the first reports were queued while the child started
    """)


def bench_hid(duration: float, folder: Path) -> None:
    section("HID through hidapi's hidraw backend on a umockdev-simulated node (100 reports/s)")
    if not (shutil.which("umockdev-run") and shutil.which("gcc")):
        print("  skipped: umockdev-run or gcc not installed (apt-get install umockdev gcc)")
        return
    shim = folder / "hidraw_shim.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-O2", "-o", str(shim),
                    str(ROOT / "tests" / "data" / "hid" / "hidraw_shim.c"), "-ldl"], check=True)
    usb = "/devices/pci0000:00/0000:00:14.0/usb1/1-2"
    hid = f"{usb}/1-2:1.0/0003:046D:C626.0001"
    descriptor = "05010908A101A10285010930093109321A00802AFF7F750F9503810200C0C0"
    (folder / "device.umockdev").write_text(
        f"P: {usb}\nN: bus/usb/001/004\nE: DEVNAME=/dev/bus/usb/001/004\n"
        f"E: DEVTYPE=usb_device\nE: DRIVER=usb\nE: SUBSYSTEM=usb\nA: idVendor=046d\n"
        f"A: idProduct=c626\nA: bcdDevice=0100\nA: manufacturer=3Dconnexion\n"
        f"A: product=SpaceNavigator\n\n"
        f"P: {usb}/1-2:1.0\nE: DEVTYPE=usb_interface\nE: DRIVER=usbhid\nE: SUBSYSTEM=usb\n"
        f"A: bInterfaceNumber=00\n\n"
        f"P: {hid}\nE: DRIVER=hid-generic\nE: HID_ID=0003:0000046D:0000C626\n"
        f"E: HID_NAME=3Dconnexion SpaceNavigator\nE: HID_PHYS=usb-0000:00:14.0-2/input0\n"
        f"E: HID_UNIQ=\nE: SUBSYSTEM=hid\nH: report_descriptor={descriptor}\n\n"
        f"P: {hid}/hidraw/hidraw0\nN: hidraw0\nL: device=../../../0003:046D:C626.0001\n"
        f"E: DEVNAME=/dev/hidraw0\nE: MAJOR=241\nE: MINOR=0\nE: SUBSYSTEM=hidraw\n")
    count = int(duration * 100)
    lines = []
    for k in range(count):
        report = bytes([7, 1]) + struct.pack("<3h", k % 300, -(k % 300), 0)   # length-framed
        escaped = bytearray()
        for byte in report:
            escaped += b"^`" if byte == 0x5E else (bytes([0x5E, byte + 64]) if byte < 32
                                                   else bytes([byte]))
        lines.append(b"r 10 " + bytes(escaped))
    (folder / "reports.script").write_bytes(b"\n".join(lines) + b"\n")
    (folder / "child.py").write_text(HID_CHILD)
    env = dict(os.environ, MOP_HID_DESCRIPTOR=descriptor, MOP_HID_FRAMED="1",
               PYTHONPATH=str(ROOT))
    done = subprocess.run(
        ["umockdev-run", "-d", str(folder / "device.umockdev"), "-s",
         f"/dev/hidraw0={folder / 'reports.script'}", "--", "sh", "-c",
         f'LD_PRELOAD="{shim}:$LD_PRELOAD" exec "{sys.executable}" "{folder / "child.py"}" '
         f'{duration} {count}'], env=env, capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        print(f"  failed: {done.stderr[-500:]}")
        return
    late = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"  arrival -> Frame: {stats_ms(late)}")


# -- trackers ---------------------------------------------------------------------------------

def tracker_frames():
    import cv2
    from matplotlib import cbook
    frames = {}
    image = np.full((480, 640, 3), 110, np.uint8)
    marker = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 0, 120)
    image[160:340, 230:410] = 255          # a quiet zone of 2 marker cells
    image[190:310, 260:380] = marker[..., None]
    frames["aruco"] = image
    image = np.full((480, 640, 3), 40, np.uint8)
    for colour, x in (((0, 0, 255), 150), ((0, 255, 0), 300), ((255, 0, 0), 450)):
        cv2.circle(image, (x, 240), 25, colour, -1)
    frames["color"] = image
    photo = cv2.imread(str(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False)))
    photo = cv2.resize(photo, None, fx=0.75, fy=0.75)
    image = np.full((480, 640, 3), 90, np.uint8)
    photo = photo[:480]
    image[:photo.shape[0], 120:120 + photo.shape[1]] = photo
    frames["haar"] = image
    image = np.full((480, 640, 3), (60, 50, 40), np.uint8)
    cv2.circle(image, (320, 280), 60, (120, 160, 220), -1)
    for angle in (-45, -15, 15, 45, -100):
        r = math.radians(angle)
        cv2.line(image, (int(320 + 50 * math.sin(r)), int(280 - 50 * math.cos(r))),
                 (int(320 + 150 * math.sin(r)), int(280 - 150 * math.cos(r))),
                 (120, 160, 220), 22)
    frames["silhouette"] = image
    return frames


def astronaut_frame(scale: float = 1.0):
    """scikit-image's astronaut (a face and an upper body) fitted into 640x480, BGR; scale < 1:
    smaller, about its centre (0.4: a face a twentieth of the frame wide)."""
    import cv2
    from skimage import data
    photo = np.ascontiguousarray(data.astronaut()[..., ::-1])
    k = scale * 480 / 512
    matrix = np.array([[k, 0, 320 - 256 * k], [0, k, 240 - 256 * k]])
    return cv2.warpAffine(photo, matrix, (640, 480), borderMode=cv2.BORDER_REPLICATE)


def bench_trackers(repeats: int) -> None:
    import cv2
    from capture.camera.trackers import make_tracker
    section("camera trackers at 640x480 (process() per frame, one core)")
    reference = []
    frame = tracker_frames()["color"]
    gray = np.empty(frame.shape[:2], np.uint8)
    for _ in range(repeats):
        start = time.perf_counter()
        cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY, dst=gray)
        reference.append(time.perf_counter() - start)
    base = np.median(reference)
    print(f"  {'plain cvtColor BGR->gray':<26} {1e3 * base:8.3f} ms")
    for name, image in tracker_frames().items():
        tracker = make_tracker(name, **({"ids": [0]} if name == "aruco" else {}))
        values = tracker.process(image)          # warm up (allocations, cascades)
        found = int(np.count_nonzero(~np.isnan(values)))
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            tracker.process(image)
            times.append(time.perf_counter() - start)
        median = np.median(times)
        print(f"  {name:<26} {1e3 * median:8.3f} ms  p90 {1e3 * np.percentile(times, 90):8.3f} ms"
              f"  {1 / median:7.1f} fps  ({median / base:6.1f}x cvtColor; "
              f"{found}/{values.size} channels found)")


def _timed_in_turns(calls, repeats: int, turns: int = 4) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per (call, argument): (wall [s], CPU [s] of the whole process, MediaPipe's threads
    included) per call; the calls take turns, a few frames each, in alternating order, so that
    a change in the machine's load falls on all of them alike."""
    times = [([], []) for _ in calls]
    for turn in range(turns):
        order = list(enumerate(calls))
        for k, (call, argument) in order[::-1] if turn % 2 else order:
            wall, cpu = times[k]
            for _ in range(-(-repeats // turns)):
                start, start_cpu = time.perf_counter(), time.process_time()
                call(argument)
                wall.append(time.perf_counter() - start)
                cpu.append(time.process_time() - start_cpu)
    return [(np.array(wall), np.array(cpu)) for wall, cpu in times]


def _mediapipe_alone(tracker):
    """MediaPipe's own solution as the tracker sets it up, for its `process()`: the tracker's
    own for face; for hands a plain Hands graph (the tracker's graph takes one more input, when
    to search for palms, which `process()` does not give); for pose a plain Pose graph (the
    tracker's runs the landmark model without its segmentation head)."""
    if tracker.name == "face":
        return tracker._solution, None
    from mediapipe.python.solutions import hands, pose
    from capture.camera.markerless import native_notices
    with native_notices():
        if tracker.name == "hands":
            solution = hands.Hands(
                static_image_mode=False, max_num_hands=tracker.max_hands,
                model_complexity=1 if tracker.model == "full" else 0,
                min_detection_confidence=tracker.min_detection,
                min_tracking_confidence=tracker.min_tracking)
        else:
            solution = pose.Pose(
                static_image_mode=False, model_complexity=1, smooth_landmarks=False,
                enable_segmentation=False, min_detection_confidence=tracker.min_detection,
                min_tracking_confidence=tracker.min_tracking)
        solution.process(np.zeros((64, 64, 3), np.uint8))       # its models load here
    return solution, solution


def _time_markerless(name: str, options: dict, picture: str, image: np.ndarray,
                     repeats: int) -> float:
    """One tracker's wall and CPU time per frame, in turns with MediaPipe alone. Returns the
    median CPU time [s] of the frames with a search (see `searched`) if any, else of all."""
    import cv2
    from capture.camera.trackers import make_tracker
    targets = {"face": 5.0, "hands": 15.0, "pose": 15.0}
    rgb = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    tracker = make_tracker(name, **options)
    reference, own = _mediapipe_alone(tracker)
    for _ in range(5):
        values = tracker.process(image)
        reference.process(rgb)
    searched = []

    def track(image):
        tracker.process(image)
        searched.append(getattr(tracker, "searched", True))
    # against the model without our colour conversion and geometry: MediaPipe's own
    # process() on the same frame, in turns
    (wall, cpu), (plain_wall, plain_cpu) = _timed_in_turns(
        [(track, image), (reference.process, rgb)], repeats)
    tracker.close()
    if own is not None:
        own.close()
    label = name + "".join(f" {k}={v}" for k, v in options.items()) + picture
    found = int(np.count_nonzero(np.isfinite(values)))
    print(f"  {label:<32} wall {1e3 * np.median(wall):6.2f} ms (p90 "
          f"{1e3 * np.percentile(wall, 90):6.2f})  CPU {1e3 * np.median(cpu):6.2f} ms"
          f"  | MediaPipe alone: wall {1e3 * np.median(plain_wall):6.2f} ms, CPU "
          f"{1e3 * np.median(plain_cpu):6.2f} ms  | target {targets[name]:.0f} ms"
          f"  ({found}/{values.size} channels found)")
    searched = np.array(searched)
    if searched.any() and not searched.all():
        print(f"  {'':<32} CPU on the {searched.sum()} frames of {searched.size} with a search "
              f"(hands: the palm detector, face: the far search): "
              f"{1e3 * np.median(cpu[searched]):6.2f} ms, on the others "
              f"{1e3 * np.median(cpu[~searched]):6.2f} ms")
    return float(np.median(cpu[searched])) if searched.any() else float(np.median(cpu))


def bench_hand_landmarks(repeats: int, searches: dict) -> None:
    """The hand landmark model on one hand's crop of the frame (what each tracked hand costs
    a frame), cut out of MediaPipe's hands graph: its own nodes, image and hand rectangle in.
    The astronaut has no hand: the model runs all the same (it then says "no hand"). With
    `searches` {"full": s, "lite": s}, a palm search's CPU time with each model, what a frame
    with one hand in view costs."""
    import cv2
    import mediapipe
    from mediapipe.framework import calculator_pb2
    from mediapipe.framework.formats import rect_pb2
    from mediapipe.python import solution_base
    from mediapipe.python._framework_bindings import validated_graph_config
    from capture.camera.markerless import native_notices
    graph = validated_graph_config.ValidatedGraphConfig()
    graph.initialize(binary_graph_path=os.path.join(
        Path(mediapipe.__file__).parent.parent,
        "mediapipe/modules/hand_landmark/hand_landmark_tracking_cpu.binarypb"))
    whole = calculator_pb2.CalculatorGraphConfig.FromString(graph.binary_config)
    config = calculator_pb2.CalculatorGraphConfig(
        input_stream=["IMAGE:image_for_landmarks", "ROI:single_hand_rect"],
        output_stream=["LANDMARKS:handlandmarkcpu__landmarks"],
        input_side_packet=["MODEL_COMPLEXITY:model_complexity"],
        node=[node for node in whole.node if node.name.startswith("handlandmarkcpu__")])
    rgb = cv2.cvtColor(astronaut_frame(), cv2.COLOR_BGR2RGB)
    crop = rect_pb2.NormalizedRect(x_center=0.5, y_center=0.7, width=0.3, height=0.4,
                                   rotation=0.3)
    models = {}
    for label, complexity in (("full", 1), ("lite", 0)):
        with native_notices():
            models[label] = solution_base.SolutionBase(
                graph_config=config, side_inputs={"model_complexity": complexity})
    inputs = {"image_for_landmarks": rgb, "single_hand_rect": crop}
    with native_notices():                # the models load on the first frame
        for model in models.values():
            for _ in range(5):
                model.process(inputs)
    timed = _timed_in_turns([(model.process, inputs) for model in models.values()], repeats)
    for (label, model), (_, cpu) in zip(models.items(), timed):
        model.close()
        print(f"  hand landmark model {label}, one hand's crop: CPU {1e3 * np.median(cpu):6.2f}"
              f" ms a tracked hand a frame")
    for (label, search), (_, cpu) in zip(searches.items(), timed):
        hand = np.median(cpu)
        print(f"  one hand in view, max_hands=2, model={label} (the sum of the parts above): "
              f"{1e3 * hand:6.2f} ms a frame, {1e3 * (hand + search):6.2f} ms on the frames "
              f"with a palm search (search_every=1: every frame), on average "
              f"{1e3 * (hand + search / 3):6.2f} ms with search_every=3")


def bench_graphs(repeats: int, folder: Path) -> None:
    """Where MediaPipe's graphs spend a 640x480 frame, calculator by calculator: MediaPipe's
    own profiler (switched on in each graph's configuration), wall time inside each
    calculator summed over the frames. Shares hold under load; milliseconds grow with it."""
    import collections
    from mediapipe.framework import calculator_profile_pb2
    from mediapipe.python import solution_base
    from capture.camera.markerless import models_status
    from capture.camera.trackers import make_tracker
    section("MediaPipe's graphs calculator by calculator (its profiler), 640x480, one core")
    if not models_status()["installed"]:
        print("  skipped: MediaPipe's models are not installed")
        return
    build = solution_base.SolutionBase._initialize_graph_interface

    def profiled(self, *args, **kwargs):
        config = build(self, *args, **kwargs)
        config.profiler_config.enable_profiler = True
        config.profiler_config.trace_enabled = True        # writes the profiles to files
        config.profiler_config.trace_log_path = str(logs) + "/"
        config.profiler_config.trace_log_interval_count = 5
        config.profiler_config.trace_log_count = 1000
        return config
    affinity = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {max(affinity)})
    image = astronaut_frame()
    try:
        for name, options in (("face", {}), ("hands", {"search_every": 1}), ("pose", {})):
            logs = folder / f"profile_{name}"
            logs.mkdir()
            solution_base.SolutionBase._initialize_graph_interface = profiled
            try:
                tracker = make_tracker(name, **options)
            finally:
                solution_base.SolutionBase._initialize_graph_interface = build
            for _ in range(3 * repeats + 5):
                tracker.process(image)
            tracker.close()                   # the last profiles are written on closing
            total, calls = collections.Counter(), collections.Counter()
            for path in logs.glob("*.binarypb"):
                profile = calculator_profile_pb2.GraphProfile.FromString(path.read_bytes())
                for calculator in profile.calculator_profiles:
                    total[calculator.name] += calculator.process_runtime.total
                    calls[calculator.name] += sum(calculator.process_runtime.count)
            whole = sum(total.values())
            model = sum(t for k, t in total.items() if k.endswith("InferenceCalculator"))
            print(f"  {name}: {100 * model / whole:4.1f} % of the time inside calculators in "
                  f"the models' inference")
            for calculator, t in total.most_common(4):
                print(f"    {100 * t / whole:5.1f} %  {t / 1e3 / calls[calculator]:6.3f} ms a call"
                      f"  {calculator.split('__')[-1]} ({calculator.split('__')[0]})")
    finally:
        os.sched_setaffinity(0, affinity)


def bench_markerless(repeats: int, duration: float, folder: Path) -> None:
    import cv2
    from capture.camera.markerless import models_status
    from capture.camera.trackers import make_tracker
    section("markerless trackers at 640x480 on one core (MediaPipe)")
    status = models_status()
    if not status["installed"]:
        print(f"  skipped: {status['error']}")
        return
    affinity = os.sched_getaffinity(0)
    core = max(affinity)
    os.sched_setaffinity(0, {core})
    try:
        print(f"  {status['distribution']}; pinned to CPU {core}; medians over {repeats} "
              f"frames after 5 warm-up frames (astronaut photo; hands: no hand in it, so the "
              f"palm detector searches every frame it is let, the worst case)")
        near = astronaut_frame()
        pictures = {"": near, " (a far face)": astronaut_frame(0.4),
                    " (no one)": np.full_like(near, 100)}
        variants = [("face", {}, ""), ("face", {"refine": False}, ""),
                    ("face", {}, " (a far face)"), ("face", {"search_every": 1}, " (no one)"),
                    ("face", {}, " (no one)"), ("face", {"far": False}, " (no one)"),
                    ("hands", {"search_every": 1}, ""), ("hands", {}, ""),
                    ("hands", {"model": "lite", "search_every": 1}, ""), ("pose", {}, "")]
        times = [_time_markerless(name, options, picture, pictures[picture], repeats)
                 for name, options, picture in variants]
        # the palm search's time with each model, searching every frame
        bench_hand_landmarks(repeats, {
            "full": times[variants.index(("hands", {"search_every": 1}, ""))],
            "lite": times[variants.index(("hands", {"model": "lite", "search_every": 1}, ""))]})
        print("  live path: a 30 fps MJPEG file played in real time through the camera source "
              "(reader thread + tracker thread); grab -> Frame in read()")
        frames = int(duration * 30)
        # MJPEG, as a webcam sends it: about 2 ms a frame to decode here (lossless FFV1: 26 ms,
        # more than the tracking it would be measuring)
        path = folder / "markerless.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
        for k in range(frames):
            writer.write(np.roll(near, k % 20, axis=1))
        writer.release()
        for name in ("face", "hands", "pose"):
            late = []
            with open_source(f"camera:{path}:{name}") as source:
                for frame in source:
                    late.append(time.monotonic() - frame.t)
                timing = source.timing()
            # reference: grab, decode and track inline in one thread, every frame
            tracker = make_tracker(name)
            capture = cv2.VideoCapture(str(path))
            inline = []
            while True:
                start = time.monotonic()
                ok, picture = capture.read()
                if not ok:
                    break
                tracker.process(picture)
                inline.append(time.monotonic() - start)
            capture.release()
            tracker.close()
            # past the first five frames, unless the reader passed over nearly all of them
            settled = late[5:] if len(late) > 5 else late
            if not settled:
                print(f"  {name:<6} no frame tracked; {timing['skipped']} frames skipped")
                continue
            print(f"  {name:<6} grab -> Frame {stats_ms(settled)}; {timing['fps']:.1f} fps "
                  f"tracked of 30, {timing['skipped']} frames skipped")
            print(f"  {'':<6} inline grab + decode + track: median "
                  f"{1e3 * np.median(inline[5:]):7.3f} ms  (live / inline "
                  f"{np.median(settled) / np.median(inline[5:]):.2f})")
    finally:
        os.sched_setaffinity(0, affinity)


def bench_hid_parse(repeats: int) -> None:
    from capture.hid.parse import parse_into, parse_report_reference, parse_status_reference
    from capture.hid.profile import load_profile
    profile = load_profile("dualshock4")
    section(f"HID report parsing (DualShock 4 USB report, {len(profile.channels)} channels and "
            f"{len(profile.status)} status values)")
    report = bytes([1]) + bytes(range(1, 31)) + bytes(33)   # byte 31 = 0: a controller
    state = np.full(len(profile.channels), np.nan)
    status = np.full(len(profile.status), np.nan)
    parse_into(profile, report, state, status)
    fast, slow = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        parse_into(profile, report, state, status)
        fast.append(time.perf_counter() - start)
        start = time.perf_counter()
        parse_report_reference(profile, report)
        parse_status_reference(profile, report)
        slow.append(time.perf_counter() - start)
    print(f"  numba kernel      {1e6 * np.median(fast):7.2f} us  p90 "
          f"{1e6 * np.percentile(fast, 90):7.2f} us")
    print(f"  Python reference  {1e6 * np.median(slow):7.2f} us  "
          f"(kernel {np.median(slow) / np.median(fast):.1f}x faster)")


# -- take store -------------------------------------------------------------------------------

def bench_store(duration: float, folder: Path) -> None:
    section("take store (SQLite WAL, 32 channels per frame, background commits every 50 ms)")
    width = 32
    row = np.random.default_rng(0).normal(size=width)
    # plain reference: every row in one transaction, no WAL, no thread
    count = 20000
    path = folder / "plain.sqlite"
    if path.exists():
        path.unlink()
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE frames (stream INTEGER, seq INTEGER, t REAL, data BLOB, "
               "PRIMARY KEY (stream, seq)) WITHOUT ROWID")
    blob = row.astype("<f8").tobytes()
    start = time.perf_counter()
    db.executemany("INSERT INTO frames VALUES (1, ?, ?, ?)",
                   ((k, k * 1e-3, blob) for k in range(count)))
    db.commit()
    plain = count / (time.perf_counter() - start)
    db.close()

    writer = StoreWriter(folder / "burst.sqlite", overwrite=True)
    writer.add_stream("action", [f"c{i}" for i in range(width)])
    start = time.perf_counter()
    appended = 0
    while time.perf_counter() - start < duration:
        for _ in range(200):
            writer.append("action", appended * 1e-3, row)
            appended += 1
    writer.close()
    elapsed = time.perf_counter() - start          # until everything is committed
    s = writer.stats
    print(f"  plain sqlite, one transaction : {plain:10.0f} frames/s")
    print(f"  StoreWriter.append, flat out  : {appended / elapsed:10.0f} frames/s committed "
          f"({appended / elapsed / plain:.2f}x plain), {s.commits} commits, worst commit "
          f"interval {1e3 * s.worst_commit_interval:.1f} ms, oldest unsaved frame "
          f"{1e3 * s.worst_unsaved_age:.1f} ms")

    writer = StoreWriter(folder / "paced.sqlite", overwrite=True)
    writer.add_stream("action", [f"c{i}" for i in range(width)])
    rate = 1000.0
    start = time.monotonic()
    k = 0
    while (now := time.monotonic()) - start < duration:
        due = start + k / rate
        if now < due:
            time.sleep(due - now)
        writer.append("action", time.monotonic(), row)
        k += 1
    writer.close()
    s = writer.stats
    print(f"  paced at {rate:.0f} frames/s for {duration:.0f} s: {s.commits} commits, worst commit "
          f"interval {1e3 * s.worst_commit_interval:.1f} ms, oldest unsaved frame "
          f"{1e3 * s.worst_unsaved_age:.1f} ms, commit time {stats_ms(s.commit_seconds)}")


def draw_trackers(path: Path) -> None:
    """What each tracker sees and finds on the benchmark frames, as one PNG (3 panels a row)."""
    import cv2
    from capture.camera.trackers import default_camera_matrix, make_tracker
    from capture.camera.markerless import models_status
    panels = []
    frames = tracker_frames()
    if models_status()["installed"]:
        frames.update(face=astronaut_frame(), pose=astronaut_frame())
    for name, image in frames.items():
        tracker = make_tracker(name, **({"ids": [0]} if name == "aruco" else {}))
        for _ in range(3 if name in ("face", "pose") else 1):    # MediaPipe settles on a frame
            values = dict(zip(tracker.channels, tracker.process(image)))
        canvas = image.copy()
        if name == "aruco":
            camera = default_camera_matrix(640, 480)
            t = np.array([values[f"aruco0.{a}"] for a in "xyz"])
            r = np.array([values[f"aruco0.r{a}"] for a in "xyz"])
            cv2.drawFrameAxes(canvas, camera, np.zeros(5), r, t, 0.04, 3)
            label = f"aruco0 at ({t[0]:+.3f}, {t[1]:+.3f}, {t[2]:.3f}) m"
        elif name == "color":
            for colour in ("red", "green", "blue"):
                x, y = values[f"{colour}.x"] * 640, values[f"{colour}.y"] * 480
                cv2.drawMarker(canvas, (int(x), int(y)), (255, 255, 255), cv2.MARKER_CROSS, 30, 2)
            label = "largest blob per colour"
        elif name == "haar":
            cx, cy = values["face.x"] * 640, values["face.y"] * 480
            w, h = values["face.w"] * 640, values["face.h"] * 480
            cv2.rectangle(canvas, (int(cx - w / 2), int(cy - h / 2)),
                          (int(cx + w / 2), int(cy + h / 2)), (0, 255, 0), 2)
            for eye in ("eye_left", "eye_right"):
                if not math.isnan(values[f"{eye}.x"]):
                    ex = cx - w / 2 + values[f"{eye}.x"] * w
                    ey = cy - h / 2 + values[f"{eye}.y"] * h
                    cv2.circle(canvas, (int(ex), int(ey)), 8, (0, 255, 255), 2)
            label = f"face box, eyes found, smile {values['smile']:.0f}"
        elif name == "face":
            points = tracker.last_points()
            for x, y, _ in points[::3]:
                cv2.circle(canvas, (int(x), int(y)), 1, (0, 255, 255), -1)
            cx, cy = values["head_x"] * 640, values["head_y"] * 480
            up = math.radians(values["head_roll"])
            cv2.arrowedLine(canvas, (int(cx), int(cy)), (int(cx - 90 * math.sin(up)),
                                                         int(cy - 90 * math.cos(up))),
                            (0, 255, 0), 2, tipLength=0.2)
            label = (f"jaw {values['jaw_open']:.2f} smile {values['smile']:.2f} roll "
                     f"{values['head_roll']:+.1f}")
        elif name == "pose":
            points, visibility = tracker.last_points()
            chain = (15, 13, 11, 12, 14, 16)           # wrist, elbow, shoulder, across, back
            xy = [(int(points[k, 0] * 640), int(points[k, 1] * 480)) for k in chain]
            for (a, b), ka, kb in zip(zip(xy[:-1], xy[1:]), chain[:-1], chain[1:]):
                if min(visibility[ka], visibility[kb]) >= 0.5:
                    cv2.line(canvas, a, b, (0, 255, 0), 3)
            label = (f"shoulders {values['shoulder_left']:.0f}/{values['shoulder_right']:.0f}"
                     f" deg, lean {values['lean']:+.1f}")
        else:
            mask = tracker.mask(image)
            contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            contour = max(contours, key=cv2.contourArea)
            cv2.drawContours(canvas, [cv2.convexHull(contour)], -1, (0, 255, 255), 2)
            label = (f"openness {values['hand.openness']:.2f}, gaps "
                     f"{values['hand.gaps']:.0f}")
        cv2.putText(canvas, f"{name}: {label}", (10, 465), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                    (255, 255, 255), 2, cv2.LINE_AA)
        panels.append(cv2.resize(canvas, (400, 300), interpolation=cv2.INTER_AREA))
    while len(panels) % 3:
        panels.append(np.zeros_like(panels[0]))
    mosaic = np.vstack([np.hstack(panels[k:k + 3]) for k in range(0, len(panels), 3)])
    path.parent.mkdir(parents=True, exist_ok=True)
    from PIL import Image       # a 256-colour palette: a third of the size, looks the same
    Image.fromarray(mosaic[..., ::-1]).quantize(colors=256).save(path, optimize=True)
    print(f"\nwrote {path} ({path.stat().st_size // 1024} KB)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    parser.add_argument("--picture", default=None, metavar="PNG",
                        help="also draw what the trackers find (docs/img/capture_trackers.png)")
    sections = ("osc", "hid", "camera", "replay", "trackers", "markerless", "graphs", "parse",
                "store")
    parser.add_argument("--only", nargs="+", choices=sections, default=sections,
                        metavar="SECTION", help=f"run only these sections: {', '.join(sections)}")
    args = parser.parse_args()
    duration = 1.0 if args.quick else 3.0
    repeats = 20 if args.quick else 60
    print(f"mop capture benchmarks ({os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f}; figures are noisy on a shared machine)")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        runs = {"osc": lambda: bench_osc(duration), "hid": lambda: bench_hid(duration, folder),
                "camera": lambda: bench_camera(duration, folder),
                "replay": lambda: bench_replay(duration, folder),
                "trackers": lambda: bench_trackers(repeats),
                "markerless": lambda: bench_markerless(repeats, duration, folder),
                "graphs": lambda: bench_graphs(repeats, folder),
                "parse": lambda: bench_hid_parse(repeats * 20),
                "store": lambda: bench_store(duration, folder)}
        for name in sections:
            if name in args.only:
                runs[name]()
    if args.picture:
        draw_trackers(Path(args.picture))
    return 0


if __name__ == "__main__":
    sys.exit(main())
