"""Rest, hold and loop: what characters do when their performer stops, on takes with pauses.

The show takes are made with the demo's generator (other seeds and speeds than the shipped
shows): gestures at 0.75x-1.3x their pace with two-second pauses between them."""
import numpy as np
import pytest

from mop.session import load_session
from mop.session.build import Overrides, build_session
from session_files import script_times, show_takes

pytestmark = pytest.mark.slow   # whole sessions built and replayed

SCRIPT = [(None, 1.0), ("chomp", 1.0), (None, 2.0), ("ripple", 0.75), (None, 2.0),
          ("chomp", 1.3), (None, 2.0)]
TIMES = script_times("glove", SCRIPT)


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    return show_takes(tmp_path_factory.mktemp("takes"), {"glove_pauses": ("glove", SCRIPT)})


def session_file(folder, takes, after):
    path = folder / f"pauses_{after}.toml"
    path.write_text(f"""
[session]
fps = 25
blend = 0.3
size = [320, 180]
takes = "{takes}"

[performers.glove]
source = "replay:glove_pauses"
channels = ["thumb", "index", "middle", "ring", "pinky"]

[characters.momo]
kind = "image"
asset = "momo"

[characters.worm]
kind = "medial"
asset = "medial_caterpillar"

[[actions]]
take = "glove_ripple"
performer = "glove"
character = "momo"
name = "wave"

[[actions]]
take = "glove_chomp"
performer = "glove"
character = "worm"
name = "bite"
after = "{after}"
channels = {{ thumb = "jaw", index = "head", middle = "front" }}
""")
    return path


class States:
    def __init__(self):
        self.states = []

    def send(self, state):
        self.states.append(state)

    def close(self):
        pass


def perform(tmp_path, takes, after):
    log = States()
    session = build_session(load_session(session_file(tmp_path, takes, after)),
                            overrides=Overrides(render=False), extra_outputs=[log])
    session.run()
    return session, log.states


def frames_in(states, start, end):
    return [s for s in states if start <= s["t"] < end]


def test_a_performer_who_stops_is_no_action_within_half_a_second(tmp_path, takes):
    _, states = perform(tmp_path, takes, "rest")
    names = {"chomp": "bite", "ripple": "wave"}
    for index, (action, start, end) in enumerate(TIMES):
        shown = [s["performers"]["glove"]["action"] for s in frames_in(states, start, end)]
        if action is None:
            if index == 0:
                continue                  # before the first gesture the bank may hover
            pause = shown[int(0.5 * 25):]
            assert pause and all(a is None for a in pause), (start, shown)
        else:
            # the gesture is recognised under its [[actions]] name (the take's is not shown)
            inside = shown[int(0.5 * 25):]
            assert np.mean([a == names[action] for a in inside]) >= 0.9, (action, shown)


@pytest.mark.parametrize("after", ["rest", "hold", "loop"])
def test_what_a_character_does_when_its_action_ends(tmp_path, takes, after):
    session, states = perform(tmp_path, takes, after)
    worm = session.characters[1]
    motion = worm.tracks[0].motions["bite"][0]
    dt = 1 / 25
    for action, start, end in TIMES[1:]:
        if action is not None:
            continue
        # after the performer stopped (0.5 s) and the blend (0.3 s) ran its course
        pause = frames_in(states, start + 0.85, end)
        tracks = [s["characters"]["worm"]["tracks"][0] for s in pause]
        targets = [s["characters"]["worm"]["targets"] for s in pause]
        if start < TIMES[3][1]:                   # the pause after the first bite
            if after == "rest":
                assert all(t["state"] == "rest" and t["action"] is None for t in tracks)
                assert all(target == {} for target in targets)     # let go: at rest
            elif after == "hold":
                assert all(t["state"] == "hold" and t["action"] == "bite" for t in tracks)
                assert all(target == targets[0] for target in targets)
                end_pose = motion.sample(motion.duration)
                assert targets[0]["jaw"] == pytest.approx(end_pose["thumb"], abs=0.05)
            else:
                assert all(t["state"] == "loop" and t["action"] == "bite" for t in tracks)
                progress = np.array([t["progress"] for t in tracks])
                step = np.mod(np.diff(progress), 1.0)
                assert step == pytest.approx(dt / motion.duration, abs=1e-9)
                assert len(set(np.round(progress, 3))) == len(progress)   # it keeps moving
        # momo's wave always rests (the default): its targets are let go in every pause
        assert all(s["characters"]["momo"]["targets"] == {} for s in pause)
