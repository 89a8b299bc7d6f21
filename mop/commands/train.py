"""`mop train SESSION`: build every performer's followers and show how confusable the actions
are."""
from __future__ import annotations

import time
from pathlib import Path


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "train", help="build a session's followers; report and plot how confusable actions are",
        description="Builds every performer's follower bank from the session's takes and prints, "
                    "per performer, the actions with their lengths and a confusability matrix "
                    "(how strongly each action's follower accepts the other actions' "
                    "demonstrations); the matrices are also drawn to a PNG.")
    parser.add_argument("session", help="the session file (.toml)")
    parser.add_argument("--plot", default=None, metavar="PNG",
                        help="where to draw the matrices (default: SESSION-confusability.png "
                             "in the current folder)")
    parser.set_defaults(func=run)


def bank_options(performer) -> dict:
    options = {}
    if performer.sigma is not None:
        options["sigma"] = performer.sigma
    if performer.window is not None:
        options["window"] = performer.window
    return options


def run(args) -> int:
    import numpy as np

    from mop.session import load_session
    from mop.session.build import (build_bank, build_characters, open_store,
                                   performer_templates, session_takes)

    from . import count

    config = load_session(args.session)
    store = open_store(config.takes)
    takes = session_takes(config, store)
    # the bindings are checked on the characters as `mop perform` checks them
    for character in build_characters(config, takes):
        close = getattr(character.renderer, "close", None)
        if close is not None:
            close()
        print(f"character {character.name}: " + ("; ".join(
            f"{track.performer} drives {', '.join(sorted(track.targets))}"
            for track in character.tracks) or "driven by no action"))
    results = []
    for performer in config.performers:
        templates, channels, _, _ = performer_templates(config, performer, takes,
                                                        where=str(config.path))
        start = time.perf_counter()
        build_bank(templates, performer)
        seconds = time.perf_counter() - start
        print(f"performer {performer.name}: {count(len(templates), 'action')} on "
              f"{count(len(channels), 'channel')} ({', '.join(channels)}), "
              f"{performer.normalise.value} normalisation, bank built in {1e3 * seconds:.1f} ms")
        for name, template in templates.items():
            drives = [a.character for a in config.actions_of(performer.name)
                      if a.action == name]
            seconds = (template.shape[0] - 1) / config.fps
            print(f"  {name:<16} {template.shape[0]:>4} frames ({seconds:.2f} s at {config.fps} "
                  f"fps) -> {', '.join(drives)}")
        from followers import confusability
        result = confusability(templates, **bank_options(performer))
        names, matrix = list(result.names), result.matrix
        results.append((performer.name, result))
        width = max(len(n) for n in names) + 2
        print("  confusability (row: demonstration performed, column: follower accepting it):")
        print("  " + " " * width + "".join(f"{n:>{width}}" for n in names))
        for name, row in zip(names, matrix):
            print(f"  {name:<{width}}" + "".join(f"{v:>{width}.3f}" for v in row))
        if len(names) > 1:
            shown, taken_for, value = result.most_confusable()
            print(f"  most confusable: {shown} is accepted by {taken_for}'s follower on "
                  f"{value:.0%} of its frames")
        recognised = np.diag(result.decisions[:, :len(names)])
        print("  recognised as itself by the bank: " + ", ".join(
            f"{n} {v:.0%}" for n, v in zip(names, recognised)))
    target = Path(args.plot) if args.plot else Path(f"{Path(args.session).stem}-confusability.png")
    plot_matrices(results, target)
    print(f"wrote {target}")
    return 0


def plot_matrices(results, path: Path) -> None:
    """One confusability matrix per performer, side by side, into a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    widest = max(len(result.names) for _, result in results)
    size = 1.6 + 0.75 * widest
    figure, axes = plt.subplots(1, len(results), figsize=((size + 1.6) * len(results), size + 0.4),
                                squeeze=False)
    for axis, (performer, result) in zip(axes[0], results):
        result.plot(axis, title=f"performer {performer}")
    figure.suptitle("How confusable the actions are (acceptance per follower)")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)
