"""Regenerate the demo's takes: `python3 recordings/make_demo_takes.py [FOLDER]`.

Two synthetic but plausible performers, deterministic (fixed seeds, no clock, no randomness
beyond `numpy.random.default_rng(SEED)`), so running this again gives takes with the same
content (frames, channels, motions, metadata):

- `glove`: a five-finger data glove (bends 0 = open .. 1 = fist) sampled at 50 Hz. Its actions:
  `chomp` (all fingers close and open together, the thumb against them) plays the frog's mouth
  (the latex puppet's five finger regions); `ripple` (a wave running from index to pinky) waves
  the cut-out's right hand (the image puppet `momo`, a pin).
- `hand`: a hand tracker giving the hand's position x, y, z [m] at 30 Hz. Its actions: `circle`
  (the hand draws a circle) makes the caterpillar rear up, look round and snap (the medial
  object `medial_caterpillar`, four joints); `lift` (the hand
  rises and falls) raises the cut-out's left hand and head (the same image puppet as `ripple`,
  on its own pins: two performers drive one character).

Each action is recorded once as a take with its paired motion (that is what trains the
followers); then one longer take per performer (`glove_show`, `hand_show`) performs the actions
at other speeds (0.8x .. 1.3x), with rests and sensor noise: that is what `mop demo` replays.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

SEED = 20240611
GLOVE_RATE, HAND_RATE = 50.0, 30.0
FINGERS = ("thumb", "index", "middle", "ring", "pinky")
HAND = ("x", "y", "z")
GLOVE_REST = np.array([0.15, 0.1, 0.1, 0.12, 0.15])
HAND_REST = np.array([0.0, -0.05, 0.45])

# each action: (duration [s], function of phase u in [0, 1] -> (D,) performer values)


def _bump(u, centre, width):
    """A smooth 0..1..0 bump (raised cosine) centred at `centre` of half-width `width`."""
    s = np.clip((u - centre) / width, -1.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * s))


def glove_chomp(u):
    close = np.sin(np.pi * u) ** 2            # open -> fist -> open, twice as sharp in the middle
    close = close ** 0.8
    values = GLOVE_REST[:, None] + np.outer([0.55, 0.8, 0.85, 0.8, 0.7], close)
    return values.T


def glove_ripple(u):
    rows = []
    for k, finger_centre in enumerate([0.18, 0.3, 0.5, 0.7, 0.82]):
        amplitude = 0.25 if k == 0 else 0.75
        rows.append(GLOVE_REST[k] + amplitude * _bump(u, finger_centre, 0.2))
    return np.stack(rows, axis=1)


def hand_circle(u):
    angle = 2.0 * np.pi * u
    x = 0.11 * np.sin(angle)
    y = -0.05 + 0.11 * (1.0 - np.cos(angle))
    z = 0.45 + 0.02 * np.sin(2 * angle)
    return np.stack([x, y, z], axis=1)


def hand_lift(u):
    lift = np.sin(np.pi * u) ** 2
    return np.stack([0.03 * np.sin(2 * np.pi * u), -0.05 + 0.24 * lift, 0.45 - 0.05 * lift],
                    axis=1)


ACTIONS = {
    # name: (performer, duration [s], values(u))
    "chomp": ("glove", 2.0, glove_chomp),
    "ripple": ("glove", 2.4, glove_ripple),
    "circle": ("hand", 2.4, hand_circle),
    "lift": ("hand", 1.8, hand_lift),
}
PERFORMERS = {"glove": (FINGERS, GLOVE_RATE, GLOVE_REST, 0.012),
              "hand": (HAND, HAND_RATE, HAND_REST, 0.003)}

# the shows: (action or None for rest, speed or rest duration [s])
SHOWS = {
    "glove_show": [(None, 0.5), ("chomp", 1.0), (None, 0.4), ("ripple", 0.85), (None, 0.4),
                   ("chomp", 1.3), (None, 0.3), ("ripple", 1.2), (None, 0.5)],
    "hand_show": [(None, 0.3), ("circle", 0.9), (None, 0.5), ("lift", 1.0), (None, 0.4),
                  ("circle", 1.25), (None, 0.3), ("lift", 0.8), (None, 0.5)],
}


def cutout_pins() -> dict[str, np.ndarray]:
    """Rest positions [px] of the shipped image character's pins (characters/assets/momo)."""
    import json

    import characters
    path = Path(characters.__file__).resolve().parent / "assets" / "momo.pins.json"
    document = json.loads(path.read_text())
    return {name: np.array(pin["xy"], dtype=float) for name, pin in document["pins"].items()}


def _motion_keys(duration, count=25):
    return np.linspace(0.0, duration, count), np.linspace(0.0, 1.0, count)


def motion_for(action: str) -> dict:
    """The motion paired with an action: {channel: (times (K,), values (K, c))}.

    Channel names are the motion's own; the session file maps them onto each character's
    targets (finger regions, joints, pins)."""
    duration = ACTIONS[action][1]
    times, u = _motion_keys(duration)
    if action == "chomp":
        # the frog's mouth: the thumb region pulls the jaw down, the fingers lift the head
        close = np.sin(np.pi * u) ** 2
        return {"thumb": (times, close[:, None]),
                "index": (times, (0.9 * close)[:, None]),
                "middle": (times, close[:, None]),
                "ring": (times, (0.9 * close)[:, None]),
                "pinky": (times, (0.7 * close)[:, None])}
    if action == "circle":
        # the caterpillar rears up, looks round and snaps (joint angles [rad] of its sections)
        angle = 2.0 * np.pi * u
        rear = np.sin(np.pi * u) ** 2
        return {"front": (times, (0.45 * rear)[:, None]),
                "head": (times, (0.4 * np.sin(angle))[:, None]),
                "jaw": (times, (0.45 * np.sin(2 * angle).clip(0, None))[:, None]),
                "tail": (times, (-0.25 * rear)[:, None])}
    pins = cutout_pins()
    if action == "ripple":
        # the cut-out's right hand waves: up, side to side twice, down [picture px]
        swing = np.sin(4.0 * np.pi * u) * np.sin(np.pi * u)
        lift = np.sin(np.pi * u) ** 2
        hand = pins["right_hand"] + np.stack([40.0 * swing - 10.0 * lift, -85.0 * lift], axis=1)
        return {"right_hand": (times, hand)}
    if action == "lift":
        # the cut-out raises its left hand and stretches its head up
        lift = np.sin(np.pi * u) ** 2
        hand = pins["left_hand"] + np.stack([-15.0 * lift, -95.0 * lift], axis=1)
        head = pins["head"] + np.stack([-12.0 * np.sin(2 * np.pi * u), -30.0 * lift], axis=1)
        return {"left_hand": (times, hand), "head": (times, head)}
    raise KeyError(action)


def action_stream(action: str, rng: np.random.Generator, *, speed: float = 1.0):
    """(times (K,), values (K, D)) of one performance of `action` at `speed` x its pace."""
    performer, duration, shape = ACTIONS[action]
    _, rate, _, noise = PERFORMERS[performer]
    count = int(round(duration / speed * rate)) + 1
    u = np.linspace(0.0, 1.0, count)
    values = shape(u) + rng.normal(0.0, noise, (count, len(PERFORMERS[performer][0])))
    return np.arange(count) / rate, values


def show_stream(show: str, rng: np.random.Generator):
    """(times (K,), values (K, D)) of a whole show: actions at several speeds and rests."""
    performer = "glove" if show.startswith("glove") else "hand"
    channels, rate, rest, noise = PERFORMERS[performer]
    pieces = []
    for action, amount in SHOWS[show]:
        if action is None:
            count = int(round(amount * rate))
            drift = np.sin(np.linspace(0, np.pi, count))[:, None] * 0.01
            pieces.append(rest + drift + rng.normal(0.0, noise, (count, len(channels))))
        else:
            _, values = action_stream(action, rng, speed=amount)
            pieces.append(values[1:])
    values = np.concatenate(pieces)
    return np.arange(len(values)) / rate, values


def build(folder: Path) -> list[str]:
    """Write every demo take into the take folder `folder`; returns the take names."""
    from characters import Motion
    from mop.takes import ACTION_STREAM, ActionStream, Take, TakeStore

    store = TakeStore(folder)
    names = []
    rng = np.random.default_rng(SEED)
    takes = []
    for action, (performer, _, _) in ACTIONS.items():
        channels, rate, _, _ = PERFORMERS[performer]
        times, values = action_stream(action, rng)
        takes.append((f"{performer}_{action}", performer, action, times, values,
                      Motion(motion_for(action)), {}))
    for show in SHOWS:
        performer = "glove" if show.startswith("glove") else "hand"
        times, values = show_stream(show, rng)
        steps = [[step[0] or "rest", step[1]] for step in SHOWS[show]]
        takes.append((show, performer, "show", times, values, None, {"show": steps}))
    for name, performer, action, times, values, motion, extra in takes:
        channels, rate, _, _ = PERFORMERS[performer]
        stream = ActionStream(times, values, channels, rate=rate,
                              device={"kind": "synthetic", "performer": performer})
        take = Take(performer, action, {ACTION_STREAM: stream}, motion=motion, rate=25.0,
                    device=f"synthetic:{performer}", created="2024-06-11T00:00:00+00:00",
                    extra={"generator": "recordings/make_demo_takes.py", "seed": SEED,
                           "synthetic": True, **extra})
        store.save(take, name=name, overwrite=True)
        names.append(name)
    return names


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "demo"
    for written in build(target):
        print(f"wrote take {written} into {target}")
