"""`mop takes list|show|export|delete`: the recorded takes of a recordings folder."""
from __future__ import annotations

import os
import sys
from pathlib import Path

DEFAULT_FOLDER = "recordings"


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "takes", help="list, show, export or delete recorded takes",
        description="Manages the takes (recorded action + motion pairs) in a recordings folder.")
    parser.add_argument("--recordings", default=DEFAULT_FOLDER, metavar="DIR",
                        help=f"the take folder (default: {DEFAULT_FOLDER})")
    actions = parser.add_subparsers(dest="takes_command", metavar="ACTION")
    listing = actions.add_parser("list", help="one line per take")
    listing.add_argument("--performer", help="only this performer's takes")
    show = actions.add_parser("show", help="everything about one take")
    show.add_argument("name")
    show.add_argument("--salvage", action="store_true",
                      help="show what can be read from a damaged take file")
    export = actions.add_parser("export", help="write a take as .npz or CSV")
    export.add_argument("name")
    export.add_argument("--format", choices=("npz", "csv"), default=None,
                        help="default: from the --out suffix, else npz")
    export.add_argument("--out", default=None, metavar="PATH",
                        help="output file or folder (default: NAME.npz / NAME.csv in the "
                             "current folder)")
    export.add_argument("--salvage", action="store_true",
                        help="export what can be read from a damaged take file")
    export.add_argument("--force", action="store_true", help="replace existing output files")
    repair = actions.add_parser(
        "repair", help="make damaged or interrupted take files whole",
        description="Folds the WAL a killed recording left beside a take back into its file, "
                    "moves aside a WAL that belongs to another file, and salvages a damaged "
                    "file (the original is kept as NAME.sqlite.damaged).")
    repair.add_argument("names", nargs="*", metavar="NAME",
                        help="the takes to repair (default: every take in the folder)")
    delete = actions.add_parser("delete", help="delete a take file")
    delete.add_argument("name")
    delete.add_argument("--yes", action="store_true", help="do not ask for confirmation")
    parser.set_defaults(func=run, takes_parser=parser)


def run(args) -> int:
    from mop.takes import TakeStore

    command = getattr(args, "takes_command", None)
    if command is None:
        args.takes_parser.print_help()
        return 2
    folder = Path(args.recordings)
    if not folder.is_dir():
        raise FileNotFoundError(f"take folder not found: {folder}")
    store = TakeStore(folder, create=False)
    return {"list": _list, "show": _show, "export": _export, "delete": _delete,
            "repair": _repair}[command](store, args)


def _list(store, args) -> int:
    infos = store.list(performer=args.performer)
    if not infos:
        print(f"no takes in {store.path}" + (f" by {args.performer}" if args.performer else ""))
        return 0
    width = max(len(i.name) for i in infos)
    print(f"{'name':<{width}}  {'performer':<10} {'action':<12} {'seconds':>7} {'frames':>6}"
          f"  channels")
    for info in infos:
        if info.problem and info.performer == "?":
            print(f"{info.name:<{width}}  DAMAGED: {info.problem}")
            continue
        note = "" if info.complete else "  (interrupted)"
        channels = ", ".join(info.channels)
        if len(channels) > 40:
            channels = channels[:37] + "..."
        print(f"{info.name:<{width}}  {info.performer:<10} {info.action:<12} "
              f"{info.duration:>7.2f} {info.frames:>6}  {len(info.channels)}: {channels}{note}")
    return 0


def _show(store, args) -> int:
    import numpy as np

    from mop.takes import TakeError, calibration_of, is_calibration

    from . import count
    try:
        take = store.load(args.name, salvage=args.salvage)
    except KeyError:
        raise FileNotFoundError(f"no take {args.name!r} in {store.path}; see `mop takes list`"
                                ) from None
    except TakeError as error:
        print(f"mop takes show: error: {error}", file=sys.stderr)
        return 1
    print(f"take {take.name}  ({store.file(take.name)})")
    print(f"  performer   {take.performer}")
    print(f"  action      {take.action}")
    print(f"  recorded    {take.created or '?'}" + ("" if take.complete else
                                                     "  (INTERRUPTED: ends at its last commit)"))
    held = float(take.times[-1] - take.times[0]) if take.times.size > 1 else 0.0
    if take.complete:
        print(f"  length      {take.duration:.2f} s")
    else:
        print(f"  length      {held:.2f} s captured of the planned {take.duration:.2f} s")
    print(f"  device      {take.device or '?'}")
    print(f"  rate        {take.rate:g} Hz (templates)")
    for name, stream in take.streams.items():
        n = stream.times.size
        span = float(stream.times[-1] - stream.times[0]) if n > 1 else 0.0
        missing = int(np.count_nonzero(np.isnan(stream.values)))
        rate = f"{stream.rate:g} Hz nominal" if stream.rate > 0 else "rate not known"
        print(f"  stream {name!r}: {count(n, 'frame')} over {span:.3f} s ({rate}), "
              f"{count(len(stream.channels), 'channel')}, {count(missing, 'missing value')}")
        for column, channel in enumerate(stream.channels):
            values = stream.values[:, column] if n else np.zeros(0)
            finite = values[np.isfinite(values)]
            if finite.size:
                print(f"      {channel:<18} min {finite.min():>10.4g}  max {finite.max():>10.4g}"
                      f"  mean {finite.mean():>10.4g}")
            else:
                print(f"      {channel:<18} (no value)")
    if take.motion is not None:
        print(f"  motion      {count(len(take.motion.channel_names), 'channel')}, "
              f"{take.motion.duration:.3f} s: {', '.join(take.motion.channel_names)}")
    elif is_calibration(take):
        print("  motion      none (a calibration take: the rest pose, then every channel's "
              "range)")
        try:
            measured = calibration_of(take)
            for name, rest, low, high in zip(measured.channels, measured.rest, measured.low,
                                             measured.high):
                print(f"      {name:<18} rest {rest:>10.4g}  range {low:>10.4g} .. {high:.4g}")
        except TakeError as error:
            print(f"  problem     {error}")
    else:
        print("  motion      none (a show take: a performance, not a demonstration)")
    if take.alignment:
        print("  alignment   " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                           for k, v in take.alignment.items()))
    if take.calibration:
        print(f"  calibration {take.calibration}")
    for problem in take.problems:
        print(f"  problem     {problem}")
    return 0


def _export(store, args) -> int:
    format = args.format
    out = Path(args.out) if args.out else None
    is_folder = out is not None and (out.is_dir() or args.out.endswith(("/", os.sep)))
    if format is None:
        format = out.suffix.lstrip(".") if out is not None and not is_folder \
            and out.suffix in (".npz", ".csv") else "npz"
    if out is None:
        out = Path(f"{args.name}.{format}")
    elif is_folder:
        out = out / f"{args.name}.{format}"
    try:
        written = store.export(args.name, out, format=format, salvage=args.salvage,
                               overwrite=args.force)
    except KeyError:
        raise FileNotFoundError(f"no take {args.name!r} in {store.path}; see `mop takes list`"
                                ) from None
    for path in written:
        print(f"wrote {path}")
    return 0


def _repair(store, args) -> int:
    from mop.takes import check_name

    names = [check_name(name) for name in args.names] or store.names()
    if not names:
        print(f"no takes in {store.path}")
        return 0
    failed = 0
    for name in names:
        try:
            done = store.repair(name)
        except KeyError:
            print(f"{name}: no such take in {store.path}", file=sys.stderr)
            failed += 1
            continue
        except (ValueError, OSError) as error:
            print(f"{name}: cannot be repaired: {error}", file=sys.stderr)
            failed += 1
            continue
        for line in done or ["healthy: nothing to do"]:
            print(f"{name}: {line}")
    return 1 if failed else 0


def _delete(store, args) -> int:
    path = store.file(args.name)
    if not path.is_file():
        raise FileNotFoundError(f"no take {args.name!r} in {store.path}")
    if not args.yes:
        if not sys.stdin.isatty():
            raise ValueError(f"refusing to delete {path} without --yes (no terminal to ask)")
        answer = input(f"delete {path}? [y/N] ").strip().lower()
        if answer not in ("y", "yes"):
            print("kept")
            return 1
    store.delete(args.name)
    print(f"deleted {path}")
    return 0
