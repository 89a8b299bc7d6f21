"""`mop train SESSION`: build every performer's followers and show how confusable the actions are."""
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


def confusion_matrix(templates) -> tuple[list[str], "object"]:
    """(names, (A, A) float matrix) from followers.confusability, whatever container it uses."""
    import numpy as np
    from followers import confusability
    result = confusability(dict(templates))
    names = list(templates)
    matrix = getattr(result, "matrix", result)
    names = list(getattr(result, "names", names))
    return names, np.asarray(matrix, dtype=float)


def run(args) -> int:
    import numpy as np

    from mop.session import load_session
    from mop.session.build import build_bank, open_store, performer_templates, take_data

    config = load_session(args.session)
    store = open_store(config.takes)
    takes = {a.take: take_data(store, a.take) for a in config.actions}
    results = []
    for performer in config.performers:
        templates, channels, _, _ = performer_templates(config, performer, takes,
                                                        where=str(config.path))
        start = time.perf_counter()
        build_bank(templates, performer)
        seconds = time.perf_counter() - start
        print(f"performer {performer.name}: {len(templates)} actions on {len(channels)} channels "
              f"({', '.join(channels)}), {performer.normalise.value} normalisation, "
              f"bank built in {1e3 * seconds:.1f} ms")
        for name, template in templates.items():
            drives = [f"{a.character}" for a in config.actions_of(performer.name)
                      if a.take == name]
            print(f"  {name:<16} {template.shape[0]:>4} frames ({template.shape[0] / config.fps:.2f}"
                  f" s at {config.fps} fps) -> {', '.join(drives)}")
        names, matrix = confusion_matrix(templates)
        results.append((performer.name, names, matrix))
        width = max(len(n) for n in names) + 2
        print("  confusability (row: demonstration, column: follower):")
        print("  " + " " * width + "".join(f"{n[:10]:>11}" for n in names))
        for name, row in zip(names, matrix):
            print(f"  {name:<{width}}" + "".join(f"{v:>11.3f}" for v in row))
        off = matrix.copy()
        np.fill_diagonal(off, -np.inf)
        if off.size > 1 and np.isfinite(off).any():
            i, j = np.unravel_index(np.argmax(off), off.shape)
            print(f"  most confusable: {names[i]} looks like {names[j]} ({matrix[i, j]:.3f})")
    target = Path(args.plot) if args.plot else Path(f"{Path(args.session).stem}-confusability.png")
    plot_matrices(results, target)
    print(f"wrote {target}")
    return 0


def plot_matrices(results, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 3.8),
                                squeeze=False)
    for axis, (performer, names, matrix) in zip(axes[0], results):
        image = axis.imshow(matrix, cmap="magma", vmin=0.0, vmax=max(1.0, float(matrix.max())))
        axis.set_xticks(range(len(names)), names, rotation=30, ha="right")
        axis.set_yticks(range(len(names)), names)
        axis.set_xlabel("follower")
        axis.set_ylabel("demonstration")
        axis.set_title(f"performer {performer}")
        for (i, j), value in __import__("numpy").ndenumerate(matrix):
            axis.text(j, i, f"{value:.2f}", ha="center", va="center",
                      color="white" if value < 0.6 * max(1.0, matrix.max()) else "black")
        figure.colorbar(image, ax=axis, fraction=0.046)
    figure.suptitle("How confusable the actions are")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
