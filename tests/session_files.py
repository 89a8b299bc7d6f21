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
