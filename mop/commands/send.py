"""`mop send SOURCE --to HOST:PORT`: a performer on another machine joins a session over OSC.

Run on the performer's machine: it opens any capture source (a glove, a camera tracker, a
replayed take) and sends every frame as one OSC message `ADDRESS f f f ...` (all channels, NaN
for missing) to the machine that runs `mop perform`, whose session names the performer's source
`osc:0.0.0.0:PORT/ADDRESS?channels=a,b,c`. Each message travels in a bundle whose time tag is
the time the frame was captured (this machine's clock): the receiving session keeps the
frames' spacing as captured, whatever the network and the two schedulers add (see
`capture.osc`)."""
from __future__ import annotations

import signal
import sys
import time


def register(subparsers) -> None:
    from mop.commands._args import seconds

    parser = subparsers.add_parser(
        "send", help="send a performer's input to a session on another machine (OSC)",
        description="Opens a capture source (hid:..., camera:..., osc:..., replay:PATH) and "
                    "sends each frame as one OSC message to HOST:PORT, where `mop perform` "
                    "listens with a performer source osc:0.0.0.0:PORT/ADDRESS?channels=...")
    parser.add_argument("source", help="capture source spec, e.g. hid:p5 or "
                                       "replay:recordings/demo/hand_show")
    parser.add_argument("--to", required=True, metavar="HOST:PORT",
                        help="where the session listens")
    parser.add_argument("--address", default="/mop/input", help="OSC address (default "
                                                                "/mop/input)")
    parser.add_argument("--duration", type=seconds, default=None, metavar="SECONDS",
                        help="stop after this long")
    parser.add_argument("--quiet", action="store_true")
    parser.set_defaults(func=run)


def run(args) -> int:
    from pythonosc.osc_bundle_builder import OscBundleBuilder
    from pythonosc.osc_message_builder import OscMessageBuilder
    from pythonosc.udp_client import UDPClient

    from capture import open_source
    from mop.session.config import parse_host_port

    host, port = parse_host_port(args.to, key="--to")
    if not args.address.startswith("/"):
        raise ValueError(f"--address must start with '/', got {args.address!r}")
    try:
        client = UDPClient(host, port)
    except OSError as error:        # e.g. a host name that does not resolve
        raise OSError(f"--to {host}:{port}: {error.strerror or error}") from None
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    sent = 0
    started = time.monotonic()
    to_wall = time.time() - started      # the capture clock (monotonic) -> the time tags
    with open_source(args.source) as source:
        if not args.quiet:
            channels = ", ".join(source.channels) or "channels learnt on the first frame"
            print(f"sending {args.source} ({channels}) to {host}:{port}{args.address}",
                  file=sys.stderr, flush=True)
        try:
            while not stop and (args.duration is None
                                or time.monotonic() - started < args.duration):
                frame = source.read(timeout=0.2)
                if frame is None:
                    status = getattr(source.status, "value", source.status)
                    if status == "disconnected" and not getattr(source, "loop", True):
                        break
                    continue
                message = OscMessageBuilder(address=args.address)
                for value in frame.values:
                    message.add_arg(float(value), "f")
                bundle = OscBundleBuilder(captured_at(frame.t) + to_wall)
                bundle.add_content(message.build())
                client.send(bundle.build())
                sent += 1
        except KeyboardInterrupt:
            pass
    if not args.quiet:
        print(f"sent {sent} frames", file=sys.stderr)
    if sent == 0:
        from mop.commands._args import CommandError
        status = getattr(source.status, "value", source.status)
        raise CommandError(f"{args.source} gave no frame to send (status {status})")
    return 0


def captured_at(t: float) -> float:
    """A frame's capture time on the capture clock: its own stamp, or now for a source that
    does not stamp on that clock (e.g. a take read as fast as it goes)."""
    now = time.monotonic()
    return t if now - 60.0 <= t <= now + 0.1 else now
