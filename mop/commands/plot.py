"""`mop plot TAKE`: draw how a follower bank follows one take (progress, variance, likelihoods)."""
from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    from mop.commands._args import MAX_FRAMES, whole_rate

    parser = subparsers.add_parser(
        "plot", help="draw a follower trace of a take to a PNG",
        description="Feeds a take's action stream, frame by frame at the session rate, to a "
                    "follower bank and draws: the input channels; the recognised action's "
                    "progress with its +-2 sigma band; each action's posterior and "
                    "log-likelihood. The bank is a session performer's (--session) or, "
                    "without one, every take in the store with a motion and the same channels.")
    parser.add_argument("take", help="the take to follow (its name in the take store)")
    parser.add_argument("--session", default=None, help="use this session's store and followers")
    parser.add_argument("--performer", default=None,
                        help="which performer's followers (default: the one whose channels "
                             "match the take)")
    parser.add_argument("--takes", default=None, metavar="FOLDER",
                        help="the take store when no session is given (default: the demo's)")
    parser.add_argument("--fps", type=whole_rate, default=25,
                        help="follower rate without a session (default 25)")
    parser.add_argument("--max-frames", type=int, default=MAX_FRAMES, metavar="N",
                        help=f"refuse takes that give more frames (default {MAX_FRAMES:,})")
    parser.add_argument("--out", default=None, metavar="PNG",
                        help="output picture (default: TAKE-trace.png)")
    parser.set_defaults(func=run)


def bank_for(args):
    """(bank, fps, channels, shift, scale, action names) for the take to be plotted."""
    from mop.session import load_session
    from mop.session.build import (build_bank, normalisation, open_store,
                                   performer_calibration, performer_templates, resample,
                                   take_data)
    from mop.session.config import Normalise, PerformerConfig

    if args.session:
        config = load_session(args.session)
        store = open_store(config.takes)
        target = take_data(store, args.take)
        takes = {t: take_data(store, t) for a in config.actions
                 for t in (a.take, *a.takes)}
        candidates = [p for p in config.performers
                      if args.performer in (None, p.name)]
        if args.performer and not candidates:
            raise ValueError(f"--performer: no performer {args.performer!r} in {config.path}")
        for performer in candidates:
            templates, channels, shift, scale = performer_templates(config, performer, takes,
                                                                    where=str(config.path))
            if set(channels) <= set(target.channels):
                mapped = performer_calibration(config, performer, store, channels,
                                               where=str(config.path))
                if mapped is not None:      # as `mop perform` follows this performer
                    shift, scale = mapped.fold(shift, scale)
                return (build_bank(templates, performer, config.fps), config.fps, channels,
                        shift, scale, list(templates), target)
        raise ValueError(f"no performer of {config.path} uses the channels of take "
                         f"{args.take!r} ({', '.join(target.channels)})")
    folder = Path(args.takes) if args.takes else default_store()
    store = open_store(folder)
    target = take_data(store, args.take)
    templates = {}
    for name in store_names(store):
        data = take_data(store, name)
        if data.motion is None or data.channels != target.channels:
            continue
        templates[name] = resample(data.times, data.values, args.fps)
    if not templates:
        raise ValueError(f"no take in {folder} has a motion and the channels of {args.take!r} "
                         f"({', '.join(target.channels)}): nothing to follow it with")
    shift, scale = normalisation(list(templates.values()), Normalise.ZSCORE)
    templates = {k: (v - shift) / scale for k, v in templates.items()}
    performer = PerformerConfig(name="plot", source="")
    return (build_bank(templates, performer, args.fps), args.fps, target.channels, shift, scale,
            list(templates), target)


def default_store() -> Path:
    import mop
    return Path(mop.__file__).resolve().parent.parent / "recordings" / "demo"


def store_names(store) -> list[str]:
    return [getattr(item, "name", item) for item in store.list()]


def follow(bank, values, actions):
    """Step the bank over values (T, D) from a fresh start: what it said at each step."""
    import numpy as np
    result = bank.follow(values)
    names = list(bank.actions)
    shown = result["action"]
    return {
        "action": [names[k] if k >= 0 else None for k in shown],
        "progress": np.where(shown >= 0, result["progress"], np.nan),
        "variance": np.where(shown >= 0, result["variance"], np.nan),
        "posterior": {a: result["posteriors"][:, names.index(a)] for a in actions},
        "log_likelihood": {a: result["log_likelihoods"][:, names.index(a)] for a in actions},
    }


def run(args) -> int:
    from mop.commands._args import check_frame_budget
    from mop.session.build import resample

    bank, fps, channels, shift, scale, actions, target = bank_for(args)
    index = [target.channels.index(c) for c in channels]
    span = float(target.times[-1] - target.times[0]) if len(target.times) > 1 else 0.0
    check_frame_budget(int(span * fps) + 1, fps=fps, limit=args.max_frames)
    raw = resample(target.times, target.values[:, index], fps)
    trace = follow(bank, (raw - shift) / scale, actions)
    out = Path(args.out) if args.out else Path(f"{args.take}-trace.png")
    draw(out, args.take, raw, channels, trace, actions, fps)
    recognised = [a for a in trace["action"] if a is not None]
    counts = {a: recognised.count(a) for a in actions}
    print(f"followed {args.take}: {len(raw)} frames at {fps} fps; frames per recognised action: "
          + ", ".join(f"{a} {n}" for a, n in counts.items())
          + f", none {len(raw) - len(recognised)}")
    print(f"wrote {out}")
    return 0


def draw(path: Path, title, raw, channels, trace, actions, fps) -> list[list[str]]:
    """Draw the trace to `path`; returns each panel's legend entries (top to bottom)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = np.arange(len(raw)) / fps
    colours = {a: plt.cm.tab10(i % 10) for i, a in enumerate(actions)}
    figure, axes = plt.subplots(4, 1, figsize=(9, 8.5), sharex=True,
                                gridspec_kw={"height_ratios": [1.2, 1.4, 1, 1]})
    for k, name in enumerate(channels):
        axes[0].plot(t, raw[:, k], lw=1, label=name)
    axes[0].set_ylabel("input")
    axes[0].legend(loc="upper right", fontsize=7, ncol=min(len(channels), 6))
    progress, sigma = trace["progress"], np.sqrt(trace["variance"])
    for action in actions:
        mask = np.array([a == action for a in trace["action"]])
        if not mask.any():
            continue
        p = np.where(mask, progress, np.nan)
        s = np.where(mask, sigma, np.nan)
        axes[1].fill_between(t, p - 2 * s, p + 2 * s, color=colours[action], alpha=0.25, lw=0)
        axes[1].plot(t, p, color=colours[action], lw=1.5, label=action)
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].set_ylabel("progress ± 2σ")
    axes[1].legend(loc="upper right", fontsize=8)
    for action in actions:
        axes[2].plot(t, trace["posterior"][action], color=colours[action], lw=1.2, label=action)
        axes[3].plot(t, trace["log_likelihood"][action], color=colours[action], lw=1.2,
                     label=action)
    axes[2].set_ylabel("posterior")
    axes[2].set_ylim(-0.05, 1.05)
    axes[2].legend(loc="upper right", fontsize=8, ncol=min(len(actions), 4))
    axes[3].set_ylabel("log-likelihood")
    axes[3].legend(loc="lower left", fontsize=8, ncol=min(len(actions), 4))
    axes[3].set_xlabel("time [s]")
    figure.suptitle(f"follower trace of {title}")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    legends = [[text.get_text() for text in axis.get_legend().get_texts()]
               if axis.get_legend() is not None else [] for axis in axes]
    plt.close(figure)
    return legends
