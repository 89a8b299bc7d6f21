"""Still input is no action: the still stage of a bank (synthetic actions whose still
stretches are known)."""
import numpy as np
import pytest

from followers import BankConfig, FollowerBank, time_warp
from followers.still import still_mask

NOISE = 0.01


def gesture(T=100, phase=0.0):
    """A two-channel gesture that moves throughout."""
    t = np.linspace(0.0, 1.0, T)
    return np.stack([np.sin(2 * np.pi * t + phase) + 2 * t,
                     np.cos(3 * np.pi * t + phase) * (1 - t)], axis=1)


def noisy(values, rng):
    return values + rng.normal(scale=NOISE, size=values.shape)


@pytest.fixture
def actions(rng):
    paused = gesture(100, 1.0)
    paused = np.vstack([paused[:50], np.repeat(paused[49:50], 30, axis=0), paused[50:]])
    return {"wave": noisy(gesture(), rng), "turn": noisy(paused, rng),
            "rest": noisy(np.full((80, 2), [0.5, -0.5]), rng)}


def test_still_mask_is_the_range_over_the_window(rng):
    X = rng.normal(size=(60, 3))
    X[20:40] = X[20] + rng.uniform(-0.05, 0.05, size=(20, 3))
    X[30, 1] = np.nan
    band = np.array([0.1, 0.1, 0.2])
    frames = 5
    reference = np.zeros(60, dtype=bool)
    for i in range(frames - 1, 60):
        window = X[i - frames + 1:i + 1]
        reference[i] = (not np.isnan(window).any()) and bool(np.all(
            window.max(axis=0) - window.min(axis=0) <= band))
    np.testing.assert_array_equal(still_mask(X, frames, band), reference)
    assert reference[24] and not reference[34]  # still, and a missing value is not
    assert not still_mask(X, 0, band).any()


def test_holding_still_after_a_gesture_is_no_action_soon(actions, rng):
    """A wave, then the performer holds still where it ended: without the stage the bank goes
    on showing the wave; with it the wave is shown to its end and "no action" from at most
    ``still_frames`` frames into the hold."""
    hold = noisy(np.repeat(actions["wave"][-1:], 60, axis=0), rng)
    performance = np.vstack([noisy(actions["wave"], rng), hold])
    plain = FollowerBank(actions).follow(performance)["action"]
    assert np.all(plain[-30:] == 0)
    frames = 10
    bank = FollowerBank(actions, config=BankConfig(still_frames=frames))
    shown = bank.follow(performance)["action"]
    assert np.mean(shown[60:100] == 0) > 0.9          # the wave itself is shown
    assert np.all(shown[100 + frames:] == -1)          # the hold is no action


def test_a_still_action_and_a_pause_inside_a_gesture_stay(actions, rng):
    """Holding the rest pose is the "rest" action; the pause the "turn" action makes halfway
    (in its template too) is part of it and keeps being shown."""
    bank = FollowerBank(actions, config=BankConfig(still_frames=10))
    rest = bank.follow(noisy(actions["rest"], rng))["action"]
    assert np.all(rest[20:] == 2)
    turn = bank.follow(noisy(actions["turn"], rng))["action"]
    assert np.all(turn[60:130] == 1), turn[60:130]


def test_step_says_what_follow_says(actions, rng):
    performance = np.vstack([noisy(actions["wave"], rng),
                             noisy(np.repeat(actions["wave"][-1:], 40, axis=0), rng),
                             noisy(actions["turn"], rng)])
    bank = FollowerBank(actions, config=BankConfig(still_frames=8))
    traced = bank.follow(performance)["action"]
    assert (traced == -1).any()
    bank.reset()
    stepped = np.array([bank.step(x).index for x in performance])
    np.testing.assert_array_equal(stepped, traced)
    names = [bank.step(x).action for x in performance[:5]]
    assert all(n is None or n in bank.actions for n in names)


def test_still_settings_are_checked():
    with pytest.raises(ValueError, match="still_frames must be >= 0"):
        BankConfig(still_frames=-1)
    with pytest.raises(TypeError, match="still_frames must be an int"):
        BankConfig(still_frames=2.5)


@pytest.mark.parametrize("speed", [0.8, 0.6, 0.5])
def test_a_slow_turning_point_is_not_taken_for_a_stop(rng, speed):
    """A jaw opening and closing (one channel) performed slower than demonstrated stays at its
    top for longer than the still window, while the template passes it in a moment: the shown
    action must stay there."""
    t = np.arange(50) / 49
    chomp = np.stack([0.5 - 0.5 * np.cos(2 * np.pi * t), np.zeros(50)], axis=1)
    tilt = np.stack([np.zeros(50), np.sin(2 * np.pi * t)], axis=1)
    bank = FollowerBank({"chomp": noisy(chomp, rng), "tilt": noisy(tilt, rng)},
                        config=BankConfig(still_frames=10))
    performance = noisy(time_warp(chomp, speed)[0], rng)
    top = np.abs(performance[:, 0] - 1) < 0.1
    assert still_mask(performance, 10, bank._still.band)[top].any()   # it is still there
    action = bank.follow(performance)["action"]
    middle = action[len(action) // 4: 3 * len(action) // 4]
    assert np.all(middle == 0)


def test_a_swaying_hold_stays_no_action(actions, rng):
    """A performer standing after the wave sways now and then by more than the band but
    within ``RELEASE`` times it: once shown as no action, the hold stays no action."""
    frames = 10
    bank = FollowerBank(actions, config=BankConfig(still_frames=frames))
    band = bank._still.band
    hold = noisy(np.repeat(actions["wave"][-1:], 80, axis=0), rng)
    sway = np.zeros(80)
    sway[30:36] = sway[55:60] = 1.5 * band[0]       # beyond the band, within 2x
    hold[:, 0] += sway
    performance = np.vstack([noisy(actions["wave"], rng), hold])
    assert not still_mask(performance, frames, band)[100 + 30:100 + 70].all()
    shown = bank.follow(performance)["action"]
    assert np.all(shown[100 + frames:] == -1), shown[100:]
    bank.reset()
    np.testing.assert_array_equal([bank.step(x).index for x in performance], shown)


def test_a_pause_held_far_longer_than_demonstrated_is_no_action(actions, rng):
    """The "turn" action pauses 30 frames halfway; held 150 frames there, the pause is
    shown as the turn for up to twice its demonstrated length, then as no action, and the
    turn comes back within 15 frames of the performer moving on at frame 229 (10 by the
    band alone, 4 more for leaving the wider band)."""
    turn = actions["turn"]
    performance = noisy(np.vstack([turn[:60], np.repeat(turn[60:61], 150, axis=0),
                                   turn[61:]]), rng)
    bank = FollowerBank(actions, config=BankConfig(still_frames=10))
    shown = bank.follow(performance)["action"]
    assert np.all(shown[60:100] == 1), shown[60:100]
    assert np.all(shown[160:210] == -1), shown[160:210]
    assert np.all(shown[244:] == 1), shown[229:]
