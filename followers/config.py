"""Every tuning number of the followers, in two frozen dataclasses.

``FollowerConfig`` holds what one follower needs (its chain, its default sigma and window, its
outlier cap, what it reports); ``BankConfig`` what a bank adds on top (its emission scales,
its recognition score, the evidence behind its posterior, its rejection) and the
``FollowerConfig`` of its followers. Each field carries one line of documentation and its
unit (``describe()`` lists them); a config is validated when it is made, so a bad value is an
error that names the field, never a follower that misbehaves later.

    from followers import Follower, FollowerBank, FollowerConfig, BankConfig
    f = Follower(template, config=FollowerConfig(outlier_sigmas=3.0))
    bank = FollowerBank(templates, config=BankConfig(switch_margin=1.0))
    BankConfig().replace(reject_margin=-1.0)      # a changed copy, validated again
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

TRANSITION_KINDS = ("speed", "mop", "skip")
SPEED_PRIORS = ("uniform", "log-uniform")


def _f(default, unit: str, doc: str, *, low=None, high=None, low_open=False, high_open=False,
       finite=True, choices=None):
    """A config field: its default, unit and one line of documentation, and its valid range
    (``low``/``high`` bounds, open or closed; ``finite=False`` lets +-inf through)."""
    return field(default=default, metadata={
        "unit": unit, "doc": doc, "low": low, "high": high, "low_open": low_open,
        "high_open": high_open, "finite": finite, "choices": choices})


def _check(owner: str, spec: dataclasses.Field, value) -> None:
    meta = spec.metadata
    name = f"{owner}.{spec.name}"
    if meta["choices"] is not None:
        if value not in meta["choices"]:
            raise ValueError(f"{name} must be one of {meta['choices']}, got {value!r}")
        return
    kind = type(spec.default)
    if kind is bool:
        if not isinstance(value, bool):
            raise TypeError(f"{name} must be True or False, got {value!r}")
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (
            kind is int and not isinstance(value, int)):
        raise TypeError(f"{name} must be {'an int' if kind is int else 'a number'} "
                        f"[{meta['unit']}], got {value!r}")
    if math.isnan(value):
        raise ValueError(f"{name} must be a number [{meta['unit']}], got {value}")
    if meta["finite"] and math.isinf(value):
        raise ValueError(f"{name} must be a finite number [{meta['unit']}], got {value}")
    low, high = meta["low"], meta["high"]
    if low is not None and (value < low or (meta["low_open"] and value == low)):
        raise ValueError(f"{name} must be {'>' if meta['low_open'] else '>='} {low} "
                         f"[{meta['unit']}], got {value}")
    if high is not None and (value > high or (meta["high_open"] and value == high)):
        raise ValueError(f"{name} must be {'<' if meta['high_open'] else '<='} {high} "
                         f"[{meta['unit']}], got {value}")


class _Config:
    """Validation, description and copying shared by both configs."""

    def __post_init__(self):
        self.validate()

    def validate(self) -> None:
        """Raise ValueError / TypeError naming the first field out of its range."""
        for spec in dataclasses.fields(self):
            if "doc" in spec.metadata:
                _check(type(self).__name__, spec, getattr(self, spec.name))
        self._validate_together()

    def _validate_together(self) -> None:
        pass

    def replace(self, **changes):
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def describe(cls) -> list[tuple[str, object, str, str]]:
        """(name, default, unit, documentation) of every tuning field, in order."""
        return [(s.name, s.default, s.metadata["unit"], s.metadata["doc"])
                for s in dataclasses.fields(cls) if "doc" in s.metadata]


@dataclass(frozen=True)
class FollowerConfig(_Config):
    """Tuning numbers of one follower (see ``describe()``). The defaults are a lone
    ``Follower``'s with the ``"speed"`` chain; ``FollowerConfig.preset("mop")`` is the paper's
    chain to the letter and ``BankConfig().follower`` what a bank's followers use."""

    transitions: str = _f("speed", "name", "the chain: 'speed' (0.5x-2x performers), 'mop' (the "
                          "paper's 0.5/0.5 chain) or 'skip' (skips of 0-3 states)",
                          choices=TRANSITION_KINDS)
    resolution: int = _f(4, "states per template frame", "HMM states per template frame of the "
                         "'speed' chain (the template linearly upsampled)", low=1)
    speed_min: float = _f(0.4, "x template speed", "slowest speed level", low=0.0,
                          low_open=True)
    speed_max: float = _f(2.5, "x template speed", "fastest speed level", low=0.0,
                          low_open=True)
    speed_levels: int = _f(11, "levels", "speed levels, log-spaced from speed_min to speed_max",
                           low=1)
    speed_jitter: float = _f(0.015, "probability per frame", "chance of moving to each "
                             "neighbouring speed level", low=0.0, high=0.5)
    speed_prior: str = _f("uniform", "name", "speed at a repetition's start: 'uniform' in speed "
                          "or 'log-uniform' (every level alike)", choices=SPEED_PRIORS)
    restart: float = _f(1e-3, "probability per frame", "a new repetition begins out of the last "
                        "state (the current one is over)", low=0.0, high=1.0, high_open=True)
    restart_anywhere: float = _f(0.0, "probability per frame", "a new repetition begins out of "
                                 "any state", low=0.0, high=1.0, high_open=True)
    sigma_fraction: float = _f(0.25, "x channel spread", "default sigma: this times each "
                               "channel's standard deviation over the templates", low=0.0,
                               low_open=True)
    sigma_floor: float = _f(0.05, "x RMS spread", "a channel's spread counts at least this times "
                            "the RMS spread over channels", low=0.0, low_open=True)
    window_fraction: float = _f(0.2, "x template length", "default window half-width",
                                low=0.0, low_open=True)
    window_min: int = _f(8, "states", "smallest default window half-width", low=1)
    outlier_sigmas: float = _f(5.0, "sigmas", "a channel further than this from a state counts as "
                               "this far (inf: plain Gaussian)", low=0.0, low_open=True,
                               finite=False)
    outlier_span: float = _f(3.0, "template ranges", "a value further than this beyond the "
                             "templates' range of its channel is an outlier: left out", low=0.0,
                             low_open=True, finite=False)
    prune_mass: float = _f(1e-8, "probability", "states at the edges of the posterior holding less "
                           "are dropped (0: the fixed window only)", low=0.0, high=1.0,
                           high_open=True)
    adapt_sigma: bool = _f(True, "on/off", "learn the emission scale online when sigma is "
                           "estimated (a given sigma is used as given)")
    adapt_memory: float = _f(30.0, "frames", "time constant of that learned scale", low=0.0,
                             low_open=True)
    adapt_prior: float = _f(0.2, "frames", "weight of scale 1 at each reset", low=0.0)
    adapt_lowest: float = _f(0.1, "x sigma", "smallest learned scale", low=0.0, high=1.0,
                             low_open=True)
    adapt_highest: float = _f(2.0, "x sigma", "largest learned scale", low=1.0)
    subframe: bool = _f(True, "on/off", "report the position between template frames, not only "
                        "which state")
    subframe_tilt: float = _f(10.0, "nats per frame", "steepest prior slope across a state's cell "
                              "when placing the position inside it", low=0.0, low_open=True)
    tempo_variance: bool = _f(True, "on/off", "scale the reported variance by the performer's "
                              "tempo (a lone follower's 'speed' chain)")
    tempo_exponent: float = _f(0.2, "power", "variance x tempo ** this", low=0.0)
    tempo_memory: float = _f(10.0, "frames", "time constant of the tempo estimate", low=0.0,
                             low_open=True)
    residual_memory: float = _f(20.0, "frames", "time constant of the residual's "
                                "autocorrelation, which widens the reported variance "
                                "(followers.intervals)", low=0.0, low_open=True)
    residual_cap: float = _f(20.0, "x variance", "the reported variance is widened at most "
                             "this much (1: not at all)", low=1.0)
    residual_temper: float = _f(2.0, "x emission variance", "the recursion's emission variance "
                                "(an estimated sigma) is widened by the residual's correlation, "
                                "at most this much (1: not at all; followers.intervals)",
                                low=1.0)
    spread_weight: float = _f(0.3, "x spread squared", "with several demonstrations, their "
                              "spread around the averaged template enters each state's "
                              "emission variance with this weight", low=0.0)

    def _validate_together(self) -> None:
        if not self.speed_min < self.speed_max:
            raise ValueError(f"FollowerConfig needs speed_min < speed_max, got {self.speed_min} "
                             f"and {self.speed_max}")
        if self.transitions != "speed" and self.resolution != 1:
            raise ValueError(f"FollowerConfig.resolution applies to 'speed' transitions only, got "
                             f"{self.resolution} with {self.transitions!r}")

    @classmethod
    def preset(cls, transitions: str = "speed") -> FollowerConfig:
        """A lone follower's settings for a chain: ``"speed"`` (the defaults), ``"mop"`` (the
        paper to the letter: no restart, no outlier cap, no pruning, fixed sigma, the state
        distribution's moments, unwidened) or ``"skip"`` (one state per frame, no tempo
        scaling, untempered: the tempering was chosen and measured on the speed chain)."""
        if transitions == "mop":
            return cls(transitions="mop", resolution=1, restart=0.0, outlier_sigmas=math.inf,
                       prune_mass=0.0, adapt_sigma=False, subframe=False, tempo_variance=False,
                       residual_cap=1.0, residual_temper=1.0)
        if transitions == "skip":
            return cls(transitions="skip", resolution=1, tempo_variance=False,
                       residual_temper=1.0)
        return cls(transitions=transitions)

    @classmethod
    def bank_preset(cls, transitions: str = "speed") -> FollowerConfig:
        """The settings of a bank's followers: one state per template frame (the bank's
        per-frame budget), the slower speed jitter, a fixed sigma, no tempo scaling."""
        base = cls.preset(transitions)
        if transitions == "speed":
            base = base.replace(resolution=1, speed_jitter=0.01)
        return base.replace(adapt_sigma=False, tempo_variance=False, residual_temper=1.0)


@dataclass(frozen=True)
class BankConfig(_Config):
    """Tuning numbers of a bank (see ``describe()``), and its followers' ``follower``."""

    follower: FollowerConfig = field(default_factory=FollowerConfig.bank_preset)
    following_scale: float = _f(2.5, "x default sigma", "sigma of the forward recursion "
                                "(alignment, progress)", low=0.0, low_open=True)
    recognition_scale: float = _f(1.5, "x default sigma", "sigma of the recognition score "
                                  "(posterior, rejection)", low=0.0, low_open=True)
    recognition_floor: float = _f(0.5, "x template spread", "the recognition sigma is at least "
                                  "this times each template's own channel spread", low=0.0)
    exact_floor: float = _f(0.25, "x default sigma", "smallest sigma of the exact-repetition "
                            "component (its template's own noise otherwise)", low=0.0,
                            high=1.0, low_open=True)
    mixture_start: float = _f(0.8, "weight", "weight of the exact-repetition component at each "
                              "reset (0: none)", low=0.0, high=1.0, high_open=True)
    learn_mixture: bool = _f(True, "on/off", "learn that weight from the performance (off: "
                             "fixed)")
    mixture_memory: float = _f(10.0, "frames", "time constant of the learned weight", low=0.0,
                               low_open=True)
    mixture_prior: float = _f(5.0, "frames", "weight of the starting value at each reset",
                              low=0.0)
    mixture_lowest: float = _f(0.2, "weight", "smallest learned weight", low=0.0, high=1.0)
    mixture_highest: float = _f(0.95, "weight", "largest learned weight", low=0.0, high=1.0,
                                high_open=True)
    outline_states: int = _f(10, "states", "states of each action's outline model", low=1)
    outline_weight: float = _f(0.1, "weight", "the outline model's share of the posterior's "
                               "evidence (0: the followers alone)", low=0.0)
    outline_own_variance: float = _f(0.01, "x template variance", "added to each outline "
                                     "state's variance", low=0.0)
    outline_floor: float = _f(1e-3, "x pooled spread squared", "added to each outline state's "
                              "variance", low=0.0, low_open=True)
    outline_restart: float = _f(1e-3, "probability per frame", "an outline model starts over "
                                "at its first state", low=0.0, high=1.0, high_open=True)
    outline_fit_margin: float = _f(1.0, "nats per channel", "in the rejection's fit a frame "
                                   "counts as its outline model's score less this, if better "
                                   "(inf: the follower's alone)", low=0.0, finite=False)
    memory: float = _f(math.inf, "frames", "time constant of the posterior's evidence (inf: "
                       "nothing forgotten)", low=0.0, low_open=True, finite=False)
    evidence_cap: float = _f(6.0, "nats", "one frame counts at most this against an action",
                             low=0.0, low_open=True)
    lead_cap: float = _f(60.0, "nats", "no action trails the leader by more", low=0.0,
                         low_open=True)
    lead_cap_at_end: float = _f(40.0, "nats", "the same while the leader's follower is at its "
                                "end", low=0.0, low_open=True)
    end_fraction: float = _f(0.95, "progress", "from here a follower has performed its action",
                             low=0.0, high=1.0, low_open=True)
    switch_margin: float = _f(2.0, "nats", "another action takes over when its evidence beats "
                              "the active one's by this", low=0.0)
    reject_margin: float = _f(0.0, "nats per channel per frame", "an action is accepted while "
                              "its fit beats the background model by this (-inf: never reject)",
                              high=math.inf, high_open=True, finite=False)
    reject_hysteresis: float = _f(0.1, "nats per channel per frame", "entering needs this more, "
                                  "leaving this less", low=0.0)
    fit_memory: float = _f(10.0, "frames", "time constant of the rejection's fit", low=0.0,
                           low_open=True)
    fit_floor: float = _f(-1.0, "nats per channel", "one frame counts at most this low in the "
                          "fit")
    active_restart: float = _f(1e-4, "probability per frame", "the shown action's follower "
                               "begins a new repetition from anywhere (the others: the chain's "
                               "restart)", low=0.0, high=1.0, high_open=True)
    max_bytes: float = _f(4e9, "bytes", "largest model and state a bank may allocate; a larger "
                          "bank is refused, naming its size", low=0.0, low_open=True)
    frame_budget: float = _f(0.04, "seconds", "a bank whose step takes longer (measured once "
                             "when it is large) says so in the log", low=0.0, low_open=True)
    still_frames: int = _f(0, "frames", "input still this long is no action unless the shown "
                           "action holds still there (followers.still; 0: off; a session sets "
                           "it from its still_after)", low=0)
    still_band: float = _f(0.25, "x channel spread", "still: every channel stays within this "
                           "times its spread over every take", low=0.0)

    def _validate_together(self) -> None:
        if not isinstance(self.follower, FollowerConfig):
            raise TypeError(f"BankConfig.follower must be a FollowerConfig, got "
                            f"{type(self.follower).__name__}")
        if not self.mixture_lowest <= self.mixture_highest:
            raise ValueError(f"BankConfig needs mixture_lowest <= mixture_highest, got "
                             f"{self.mixture_lowest} and {self.mixture_highest}")
