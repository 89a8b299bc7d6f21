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
    results, several = [], []
    for performer in config.performers:
        templates, channels, _, _ = performer_templates(config, performer, takes,
                                                        where=str(config.path))
        start = time.perf_counter()
        bank = build_bank(templates, performer)
        seconds = time.perf_counter() - start
        print(f"performer {performer.name}: {count(len(templates), 'action')} on "
              f"{count(len(channels), 'channel')} ({', '.join(channels)}), "
              f"{performer.normalise.value} normalisation, bank built in {1e3 * seconds:.1f} ms")
        for name in templates:
            drives = [a.character for a in config.actions_of(performer.name)
                      if a.action == name]
            frames = bank.template(name).shape[0]
            seconds = (frames - 1) / config.fps
            print(f"  {name:<16} {frames:>4} frames ({seconds:.2f} s at {config.fps} "
                  f"fps) -> {', '.join(drives)}")
            say_consistency(bank, name, config.actions_of(performer.name))
        from followers import confusability
        result = confusability(bank)
        names, matrix = list(result.names), result.matrix
        results.append((performer.name, result))
        several.append((performer.name, bank))
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
    consistency = target.with_name(target.stem.replace("-confusability", "")
                                   + "-consistency.png")
    if plot_consistency(several, consistency):
        print(f"wrote {consistency}")
    return 0


def takes_of(name, bindings) -> tuple[str, ...]:
    """The take names of action ``name`` among a performer's bindings."""
    return next(b.demonstrations for b in bindings if b.action == name)


def say_consistency(bank, name, bindings) -> None:
    """One line per action of several takes: each take's distance from their average (in
    the action's channel spreads), and the outlier if one take strays."""
    demos = bank.demonstrations(name)
    if demos.count < 2:
        return
    names = takes_of(name, bindings)
    distances = ", ".join(f"{t} {d:.2f}" for t, d in zip(names, demos.distances))
    odd = demos.outlier()
    verdict = (f"; {names[odd]} strays from the others (record it again or leave it out)"
               if odd is not None else "; consistent")
    print(f"    {demos.count} takes, distance from their average: {distances}{verdict}")


def plot_consistency(banks, path: Path) -> bool:
    """Per performer, per action of several takes, each take's distance from their average
    (the outlier in red), into a PNG; False (nothing drawn) when no action has several."""
    rows = [(performer, name, bank.demonstrations(name)) for performer, bank in banks
            for name in bank.actions if bank.demonstrations(name).count > 1]
    if not rows:
        return False
    import numpy as np
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(len(rows), 1, figsize=(6.4, 1.2 + 1.3 * len(rows)),
                                squeeze=False)
    for axis, (performer, name, demos) in zip(axes[:, 0], rows):
        odd = demos.outlier()
        colours = ["tab:red" if i == odd else "tab:blue" for i in range(demos.count)]
        axis.barh(np.arange(demos.count), demos.distances, color=colours)
        axis.set_yticks(np.arange(demos.count), [f"take {i + 1}" for i in range(demos.count)])
        axis.invert_yaxis()
        axis.set_title(f"{performer}: {name}" + (f" (take {odd + 1} strays)"
                                                 if odd is not None else ""), fontsize=10)
    axes[-1, 0].set_xlabel("distance from the takes' average [channel spreads]")
    figure.suptitle("How consistent each action's takes are")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return True


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
