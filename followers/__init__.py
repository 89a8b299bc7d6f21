"""Action followers: a recorded action becomes a left-to-right HMM that tells, frame by frame,
how far along that action a performer is (MOP, section 3.2); a bank of them recognises which
action is being performed.

Names are resolved lazily so that ``import followers`` stays cheap (numba compiles, from its
cache, only when a follower is first built)."""
import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    # one follower
    "follower": ["Follower", "FollowerOutput", "FollowerTrace"],
    # transition models
    "transitions": ["TransitionModel", "transition_model"],
    # every tuning number
    "config": ["FollowerConfig", "BankConfig"],
    # the bank of one performer
    "bank": ["FollowerBank"],
    # what a bank says, per frame and over a take
    "bank_output": ["BankOutput", "BankTrace"],
    # preparing demonstrations (MOP 3.1.3)
    "preprocessing": ["ChannelNormaliser", "fit_normaliser", "normalise", "align", "resample",
                      "fill_gaps", "time_warp"],
    # defaults estimated from templates
    "defaults": ["default_sigma", "default_window"],
    # several takes of one action as one template and its spread
    "demos": ["combine", "Demonstrations"],
    # another performer's input mapped onto the author's (a calibration take each)
    "calibration": ["Calibration", "ChannelMap", "measure", "calibrate"],
    # training from several demonstrations
    "training": ["train_hmm", "train_follower", "TrainedModel"],
    # feedback after recording
    "confusion": ["confusability", "Confusability"],
    # published gesture recordings (.ts files)
    "datasets": ["read_ts", "aeon_dataset"],
})
