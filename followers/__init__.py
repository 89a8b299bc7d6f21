"""Action followers: a recorded action becomes a left-to-right HMM that tells, frame by frame,
how far along that action a performer is (MOP, section 3.2); a bank of them recognises which
action is being performed.

Names are resolved lazily so that ``import followers`` stays cheap (numba compiles, from its
cache, only when a follower is first built)."""
from importlib import import_module

_EXPORTS = {
    # one follower
    "Follower": "followers.follower",
    "FollowerOutput": "followers.follower",
    "FollowerTrace": "followers.follower",
    # transition models
    "TransitionModel": "followers.transitions",
    "transition_model": "followers.transitions",
    # the bank of one performer
    "FollowerBank": "followers.bank",
    "BankOutput": "followers.bank",
    # preparing demonstrations (MOP 3.1.3)
    "ChannelNormaliser": "followers.preprocessing",
    "fit_normaliser": "followers.preprocessing",
    "normalise": "followers.preprocessing",
    "align": "followers.preprocessing",
    "resample": "followers.preprocessing",
    "fill_gaps": "followers.preprocessing",
    "time_warp": "followers.preprocessing",
    # defaults estimated from templates
    "default_sigma": "followers.defaults",
    "default_window": "followers.defaults",
    # training from several demonstrations
    "train_hmm": "followers.training",
    "train_follower": "followers.training",
    "TrainedModel": "followers.training",
    # feedback after recording
    "confusability": "followers.confusion",
    "Confusability": "followers.confusion",
    # published gesture recordings (.ts files)
    "read_ts": "followers.datasets",
    "aeon_dataset": "followers.datasets",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'followers' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value
