"""Session files for the session tests, built on the shipped demo takes (recordings/demo).

Characters are the shipped image puppet (momo) and medial caterpillar: both build in well under a
second once their numba kernels are cached, so the tests stay fast. Two performers, three
characters of two kinds; momo is driven by both performers on separate pins."""
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TAKES = ROOT / "recordings" / "demo"


def session_text(*, hand_source="replay:hand_show", glove_source="replay:glove_show",
                 size=(320, 180), background="#1d2330", extra=""):
    return f"""
[session]
fps = 25
blend = 0.3
size = [{size[0]}, {size[1]}]
background = "{background}"
takes = "{TAKES}"

[performers.glove]
source = "{glove_source}"
channels = ["thumb", "index", "middle", "ring", "pinky"]

[performers.hand]
source = "{hand_source}"
channels = ["x", "y", "z"]
stale_after = 0.4

[characters.momo]
kind = "image"
asset = "momo"
position = [0.3, 0.5]
scale = 0.9

[characters.creature]
kind = "medial"
asset = "medial_caterpillar"
position = [0.72, 0.35]
scale = 0.6

[characters.worm]
kind = "medial"
asset = "medial_caterpillar"
position = [0.72, 0.75]
scale = 0.5
colour = "#80c0e0"

[[actions]]
take = "glove_ripple"
performer = "glove"
character = "momo"

[[actions]]
take = "hand_lift"
performer = "hand"
character = "momo"

[[actions]]
take = "hand_circle"
performer = "hand"
character = "creature"

[[actions]]
take = "glove_chomp"
performer = "glove"
character = "worm"
channels = {{ thumb = "jaw", index = "head", middle = "front" }}
{extra}
"""


def write_session(folder: Path, name="show.toml", **options) -> Path:
    path = Path(folder) / name
    path.write_text(session_text(**options))
    return path


def mop_command(*arguments) -> list[str]:
    return [sys.executable, "-m", "mop.cli", *map(str, arguments)]


def mop_process(*arguments, **options) -> subprocess.Popen:
    environment = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(mop_command(*arguments), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=environment, cwd=ROOT,
                            **options)


def free_udp_port() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def show_takes(folder: Path, shows: dict, *, seed: int = 4321) -> Path:
    """A take folder with the demo's takes and show takes made with the demo's generator:
    shows = {name: (performer, [(action or None for a rest, speed or rest seconds), ...])}.
    Returns the folder; each show take keeps its script in its metadata ("show")."""
    import shutil

    import numpy as np

    sys.path.insert(0, str(ROOT / "recordings"))
    import make_demo_takes as demo
    from mop.takes import ACTION_STREAM, ActionStream, Take, TakeStore
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for take in TAKES.glob("*.sqlite"):
        shutil.copy(take, folder / take.name)
    store = TakeStore(folder)
    rng = np.random.default_rng(seed)
    for name, (performer, script) in shows.items():
        channels, rate, rest, noise = demo.PERFORMERS[performer]
        pieces = []
        for action, amount in script:
            if action is None:
                pieces.append(rest + rng.normal(0.0, noise, (int(round(amount * rate)),
                                                            len(channels))))
            else:
                pieces.append(demo.action_stream(action, rng, speed=amount)[1][1:])
        values = np.concatenate(pieces)
        stream = ActionStream(np.arange(len(values)) / rate, values, channels, rate=rate,
                              device={"kind": "synthetic", "performer": performer})
        steps = [[action or "rest", amount] for action, amount in script]
        store.save(Take(performer, "show", {ACTION_STREAM: stream}, rate=25.0,
                        device=f"synthetic:{performer}", extra={"show": steps}),
                   name=name, overwrite=True)
    return folder


def script_times(performer: str, script) -> list[tuple[str | None, float, float]]:
    """[(action or None, start [s], end [s])] of a show script as `show_takes` renders it."""
    sys.path.insert(0, str(ROOT / "recordings"))
    import make_demo_takes as demo
    rate = demo.PERFORMERS[performer][1]
    out, t = [], 0.0
    for action, amount in script:
        if action is None:
            frames = int(round(amount * rate))
        else:
            frames = int(round(demo.ACTIONS[action][1] / amount * rate))
        out.append((action, t, t + frames / rate))
        t += frames / rate
    return out
