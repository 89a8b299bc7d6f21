"""Preparing demonstrations (normalisation, gaps, alignment of an action with its motion),
training a follower from several demonstrations, and the confusability feedback."""
import numpy as np
import pytest

from followers.defaults import default_sigma, pooled_sigma

from followers import (Confusability, FollowerBank, align, confusability, fill_gaps,
                       fit_normaliser, normalise, resample, time_warp, train_follower, train_hmm)


def smooth_template(rng, T, D, scale=1.0):
    steps = rng.normal(size=(T + 8, D))
    smooth = np.stack([np.convolve(steps[:, d], np.ones(8) / 8, "valid") for d in range(D)], 1)
    return np.cumsum(smooth, axis=0)[:T] * scale + rng.normal(scale=3.0, size=D)


# ---- preparing demonstrations -------------------------------------------------------------------

def test_normalise_shares_one_normaliser_and_round_trips(rng):
    a = rng.normal(loc=[5, -2, 0], scale=[1, 10, 0.1], size=(50, 3))
    b = rng.normal(loc=[5, -2, 0], scale=[1, 10, 0.1], size=(30, 3))
    b[3, 1] = np.nan
    (na, nb), normaliser = normalise([a, b])
    stacked = np.vstack([na, nb])
    np.testing.assert_allclose(np.nanmean(stacked, axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(np.nanstd(stacked, axis=0), 1, atol=1e-12)
    assert np.isnan(nb[3, 1])
    np.testing.assert_allclose(normaliser.inverse(na), a, atol=1e-12)
    constant = fit_normaliser(np.ones((10, 2)), how="range")
    np.testing.assert_array_equal(constant.scale, [1.0, 1.0])
    with pytest.raises(ValueError, match="'zscore' or 'range'"):
        fit_normaliser(a, how="minmax")
    with pytest.raises(ValueError, match=r"must be \(\.\.\., 3\), one value a channel, "
                                         r"got shape \(4,\)"):
        normaliser(np.zeros(4))


def test_fill_gaps_interpolates_linearly():
    values = np.array([[0.0, 1.0], [np.nan, 2.0], [np.nan, np.nan], [3.0, 4.0], [np.nan, 5.0]])
    filled = fill_gaps(values)
    np.testing.assert_allclose(filled[:, 0], [0, 1, 2, 3, 3])
    np.testing.assert_allclose(filled[:, 1], [1, 2, 3, 4, 5])
    with pytest.raises(ValueError, match="gap of 2 frames"):
        fill_gaps(values, max_gap=1)
    with pytest.raises(ValueError, match="no finite sample"):
        fill_gaps(np.full((3, 1), np.nan))


def test_align_action_and_motion_of_different_rates():
    """A 2 s action at 50 Hz and its motion at 30 Hz: after alignment frame t of one pairs with
    frame t of the other, both spanning the same time."""
    t_action = np.arange(101) / 50.0
    t_motion = np.arange(61) / 30.0
    action = np.stack([np.sin(t_action), t_action], axis=1)
    motion = np.cos(3 * t_motion)
    a, m = align(action, motion, action_rate=50, motion_rate=30)
    assert a.shape == (101, 2) and m.shape == (101,)
    np.testing.assert_allclose(m, np.cos(3 * t_action), atol=2e-3)  # linear interpolation error
    a2, m2 = align(action, motion, length="motion")
    assert a2.shape == (61, 2) and m2.shape == (61,)
    np.testing.assert_allclose(a2[:, 1], t_motion, atol=1e-12)
    with pytest.raises(ValueError, match="not captured together"):
        align(action, motion, action_rate=50, motion_rate=10)
    with pytest.raises(ValueError, match="both action_rate and motion_rate"):
        align(action, motion, action_rate=50)


def test_resample_and_time_warp_agree_with_the_clock():
    ramp = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(resample(ramp, 11), np.linspace(0, 1, 11), atol=1e-12)
    warped, position = time_warp(ramp, 2.0, hold=5)
    assert len(warped) == 51 + 5
    np.testing.assert_allclose(warped, position, atol=1e-12)  # a ramp is its own position
    assert position[-6:].min() == 1.0
    with pytest.raises(ValueError, match="speed must be > 0"):
        time_warp(ramp, 0.0)


# ---- training from several demonstrations -------------------------------------------------------

def test_baum_welch_keeps_left_to_right_topology_and_improves(rng):
    truth = smooth_template(rng, 60, 2)
    demos = [time_warp(truth, s, jitter=0.1, rng=rng)[0] + rng.normal(scale=0.1, size=(1, 2))
             for s in (0.8, 0.9, 1.0, 1.1, 1.25)]
    demos = [d + rng.normal(scale=0.1, size=d.shape) for d in demos]
    trained = train_hmm(demos, states=60, iterations=8)
    A = trained.transitions
    i, j = np.nonzero(A > 0)
    assert np.all(j >= i) and np.all(j <= i + 2)  # only stay, next, skip one
    np.testing.assert_allclose(A.sum(axis=1), 1.0)
    history = trained.log_likelihoods
    assert np.all(np.diff(history) >= -1e-6 * np.abs(history[1:]))
    assert history[-1] > history[0]
    assert trained.means.shape == trained.sigma.shape == (60, 2)
    # the trained spread reflects the demonstrations' noise (0.1), not the range of motion
    assert 0.05 < np.median(trained.sigma) < 0.5


def _dense_baum_welch(demos, means, var, A):
    """One Baum-Welch update written plainly: dense (S, S) matrices, logs throughout."""
    S = means.shape[0]
    logA = np.log(np.where(A > 0, A, 1e-300))
    logA[A == 0] = -np.inf
    weight, first, second, moves, total = np.zeros(S), 0.0, 0.0, np.zeros((S, S)), 0.0
    for x in demos:
        N = len(x)
        logB = np.array([[-0.5 * np.sum(np.log(2 * np.pi * var[i]) + (x[t] - means[i]) ** 2
                                        / var[i]) for i in range(S)] for t in range(N)])
        alpha, beta = np.full((N, S), -np.inf), np.zeros((N, S))
        alpha[0, 0] = logB[0, 0]
        for t in range(1, N):
            alpha[t] = np.logaddexp.reduce(alpha[t - 1][:, None] + logA, axis=0) + logB[t]
        for t in range(N - 2, -1, -1):
            beta[t] = np.logaddexp.reduce(logA + (logB[t + 1] + beta[t + 1])[None, :], axis=1)
        ll = np.logaddexp.reduce(alpha[-1])
        gamma = np.exp(alpha + beta - ll)
        for t in range(N - 1):
            moves += np.exp(alpha[t][:, None] + logA + (logB[t + 1] + beta[t + 1])[None, :] - ll)
        weight += gamma.sum(axis=0)
        first = first + gamma.T @ x
        second = second + gamma.T @ x ** 2
        total += ll
    new_means = first / weight[:, None]
    new_var = second / weight[:, None] - new_means ** 2
    return total, new_means, new_var, moves / moves.sum(axis=1, keepdims=True)


def test_baum_welch_matches_a_dense_reference_and_hmmlearn(rng):
    """The banded log-space update equals a plain dense one, and its log-likelihood equals
    hmmlearn's forward algorithm on the same model."""
    from followers.training import _banded, _dense, baum_welch, left_to_right
    S, D = 6, 2
    demos = [rng.normal(size=(n, D)).cumsum(axis=0) for n in (12, 15, 9)]
    means, var = rng.normal(size=(S, D)), rng.uniform(0.5, 2.0, size=(S, D))
    A = left_to_right(S, skips=1)
    log_a = _banded(A, 3)
    np.testing.assert_allclose(_dense(log_a), A, atol=1e-15)
    ours_means, ours_var = means.copy(), var.copy()
    history = baum_welch(demos, ours_means, ours_var, log_a, 1, 1e-12)
    total, ref_means, ref_var, ref_A = _dense_baum_welch(demos, means, var, A)
    assert history[0] == pytest.approx(total, rel=1e-12)
    np.testing.assert_allclose(ours_means, ref_means, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ours_var, ref_var, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(_dense(log_a), ref_A, rtol=1e-9, atol=1e-15)
    hmmlearn = pytest.importorskip("hmmlearn.hmm")
    model = hmmlearn.GaussianHMM(n_components=S, covariance_type="diag", init_params="",
                                 implementation="log")
    model.startprob_, model.transmat_ = np.eye(S)[0], A
    model.means_, model.covars_ = means, var
    assert history[0] == pytest.approx(model.score(np.vstack(demos), [len(d) for d in demos]),
                                       rel=1e-10)


def test_trained_follower_follows_a_new_performance(rng):
    truth = smooth_template(rng, 80, 3)
    demos = [time_warp(truth, s, jitter=0.1, rng=rng)[0] for s in (0.85, 1.0, 1.2)]
    demos = [d + rng.normal(scale=0.1, size=d.shape) for d in demos]
    follower = train_follower(demos, iterations=5)
    performance, position = time_warp(truth, 1.6)
    performance = performance + rng.normal(scale=0.1, size=performance.shape)
    trace = follower.follow(performance)
    # the trained template has its own timing: compare where the end and the middle land
    assert trace.progress[-1] > 0.95
    assert np.all(np.diff(trace.progress) > -0.05)
    assert np.median(np.abs(trace.progress - position)) < 0.08


def test_trained_follower_carries_its_demonstrations(rng):
    """The template is the takes aligned and averaged (no Baum-Welch update by default), and
    the takes' spread around it widens the follower's sigma and, in a bank, the action's."""
    truth = smooth_template(rng, 60, 2)
    demos = [time_warp(truth, s, jitter=0.1, rng=rng)[0] for s in (0.8, 1.0, 1.25)]
    demos = [d + rng.normal(scale=0.2, size=d.shape) for d in demos]
    follower = train_follower(demos)
    np.testing.assert_array_equal(follower.template, train_hmm(demos, iterations=0).means)
    assert follower.length == int(np.median([len(d) for d in demos]))
    carried = follower.demonstrations
    assert carried.count == 3 and np.array_equal(carried.template, follower.template)
    assert not follower.sigma_given and (carried.spread > 0).all()
    base = default_sigma(follower.template, pooled=demos)
    np.testing.assert_allclose(follower.sigma, np.sqrt(
        base ** 2 + follower.config.spread_weight * carried.spread ** 2), rtol=1e-12)
    other = smooth_template(rng, 50, 2)
    bank = FollowerBank({"trained": follower, "other": other})
    config = bank.config
    following = config.following_scale * pooled_sigma(demos + [other], config.follower)
    np.testing.assert_allclose(bank.sigma("trained"), np.sqrt(
        following ** 2 + config.follower.spread_weight * carried.spread ** 2), rtol=1e-12)
    np.testing.assert_allclose(bank.sigma("other"), np.broadcast_to(following, other.shape))
    refined = train_follower(demos, iterations=3)
    assert not np.allclose(refined.template, follower.template)


def test_training_rejects_bad_input(rng):
    with pytest.raises(ValueError, match="same channels"):
        train_hmm([np.zeros((20, 2)), np.zeros((20, 3))])
    with pytest.raises(ValueError, match="cannot be crossed"):
        train_hmm([rng.normal(size=(10, 2))], states=50)
    with pytest.raises(ValueError, match="at least one demonstration"):
        train_hmm([])
    with pytest.raises(ValueError, match="iterations must be >= 0"):
        train_hmm([rng.normal(size=(10, 2))], iterations=-1)


# ---- confusability ------------------------------------------------------------------------------

def test_confusability_flags_the_near_duplicate(rng):
    templates = {n: smooth_template(rng, 70, 4, scale=1.5) for n in ("wave", "nod", "clap")}
    templates["wave again"] = templates["wave"] + rng.normal(scale=0.05, size=(70, 4))
    result = confusability(templates)
    assert isinstance(result, Confusability)
    assert result.names == tuple(templates)
    assert result.matrix.shape == (4, 4)
    assert np.all(np.diag(result.matrix) > 0.9)
    assert set(result.most_confusable()[:2]) == {"wave", "wave again"}
    distinct = result.matrix[np.ix_([1, 2], [0, 1, 2])]
    assert distinct[0, 0] < 0.2 and distinct[0, 2] < 0.2 and distinct[1, 0] < 0.2
    np.testing.assert_allclose(result.decisions.sum(axis=1), 1.0)
    # the same from an existing bank
    again = confusability(FollowerBank(templates))
    np.testing.assert_allclose(again.matrix, result.matrix)


@pytest.mark.slow
def test_confusability_picture(tmp_path, rng):
    pytest.importorskip("matplotlib")
    templates = {n: smooth_template(rng, 40, 2) for n in ("a", "b")}
    path = tmp_path / "confusability.png"
    confusability(templates).save(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
