"""OSC performers over UDP: a receiving socket on 127.0.0.1 by default, parsed with python-osc.

An address -> channels mapping says which OSC messages fill which channels; each datagram that
carries at least one mapped message becomes one Frame (channels of other addresses hold their
last value, NaN until first received). Without a mapping the source listens like Wekinator:
port 6448, address /wek/inputs. Give the channels (`?channels=a,b,c` or a count; a session
passes its performer's channel names) whenever they are known: without them the count is learnt
from the first `LEARN_RUN` consecutive messages that agree on it, at most `max_channels`
(default 256), so one hostile packet cannot fix 10,000 channels.

Datagrams are taken apart here (bundles walked, at most `MAX_BUNDLE_DEPTH` deep, type tags
checked) and each message parsed with `pythonosc.osc_message.OscMessage`, on our own socket
rather than through python-osc's server, because that server silently drops packets it cannot
parse and python-osc's bundle parser reports odd contents on the root logger (a flood of
"Could not identify content type" lines on stderr under junk). Here garbage, wrong argument
counts and non-numeric arguments are counted (`stats.malformed`, with the reason in
`stats.problems`) and skipped. Datagrams the kernel dropped because the receive buffer was full
are counted too (Linux SO_RXQ_OVFL) in `stats.dropped`; the kernel reports them with the
next datagram that does arrive. Nothing is ever sent back to the sender.
To let performers on other machines join, bind host="0.0.0.0" explicitly.

Time stamps: a frame is stamped with its datagram's arrival on the capture clock, unless the
datagram is a bundle with a time tag (what `mop send` sends: the time the sender captured the
frame). Then the sender's spacing is kept, free of the network's and the scheduler's jitter:
each sender's tags are mapped onto the capture clock by one offset, its first stamped
datagram's arrival minus its tag, taken again when a tag would map more than `EARLY` seconds
after its arrival (that first datagram came late) or more than `LATE` seconds before it (the
sender's clock jumped or it restarted).
"""
from __future__ import annotations

import logging
import math
import socket
import struct
from typing import Mapping, Sequence

import numpy as np

from .clock import MonotonicClock
from .source import ThreadedSource

log = logging.getLogger(__name__)

WEKINATOR_PORT = 6448
WEKINATOR_ADDRESS = "/wek/inputs"
LEARN_RUN = 3             # consecutive messages that must agree on a learnt channel count
MAX_CHANNELS = 256        # the most channels a source learns by itself
MAX_BUNDLE_DEPTH = 8      # bundles nested deeper than this are refused
_BUNDLE = b"#bundle\x00"
_TYPE_TAGS = frozenset("ifdsbrhtmTFN[]")   # what python-osc parses without a warning
NTP_UNIX = 2208988800     # [s] from the OSC (NTP) epoch, 1900, to the Unix epoch, 1970
EARLY = 0.05              # [s] a tag mapped this far after its arrival moves the offset
LATE = 0.25               # [s] a tag mapped this far before its arrival moves the offset


class _Malformed(ValueError):
    """A datagram that is not valid OSC; the message says why."""


def time_tag(data: bytes) -> float | None:
    """The time tag of a bundle [s since the Unix epoch], or None (a message, or a bundle to be
    applied "immediately")."""
    if len(data) < 16 or not data.startswith(_BUNDLE):
        return None
    seconds, fraction = struct.unpack(">II", data[8:16])
    if seconds == 0 and fraction <= 1:
        return None
    return seconds - NTP_UNIX + fraction / 4294967296.0


class SenderClocks:
    """Senders' time tags -> the capture clock (see the module): one offset per sender."""

    def __init__(self):
        self.offsets: dict = {}
        self.anchors = 0          # offsets taken (first datagrams, late ones, clock jumps)

    def map(self, sender, tag: float, arrival: float) -> float:
        offset = self.offsets.get(sender)
        if offset is not None:
            t = tag + offset
            if arrival - LATE <= t <= arrival + EARLY:
                return t
        self.offsets[sender] = arrival - tag
        self.anchors += 1
        return arrival


def _split_datagram(data: bytes, depth: int = 0) -> list[bytes]:
    """The OSC messages (as datagrams) inside one datagram: itself, or a bundle's elements,
    walked recursively. Raises _Malformed with the reason."""
    if data.startswith(_BUNDLE):
        if depth >= MAX_BUNDLE_DEPTH:
            raise _Malformed(f"bundles nested more than {MAX_BUNDLE_DEPTH} deep")
        if len(data) < 16:
            raise _Malformed("a bundle shorter than its 16-byte header")
        messages, index = [], 16
        while index < len(data):
            if index + 4 > len(data):
                raise _Malformed("a bundle element's size is cut off")
            size = int.from_bytes(data[index:index + 4], "big", signed=True)
            index += 4
            if size <= 0 or size % 4 or index + size > len(data):
                raise _Malformed(f"a bundle element of {size} bytes in {len(data) - index} "
                                 f"remaining")
            messages.extend(_split_datagram(data[index:index + size], depth + 1))
            index += size
        return messages
    if not data.startswith(b"/"):
        raise _Malformed(f"neither an OSC message nor a bundle (starts with {data[:8]!r})")
    end = data.find(b"\x00")
    tags_at = (end // 4 + 1) * 4 if end >= 0 else len(data)
    tags_end = data.find(b"\x00", tags_at)
    if end < 0 or tags_end < 0 or data[tags_at:tags_at + 1] != b",":
        raise _Malformed("a message without a type tag string")
    tags = data[tags_at + 1:tags_end].decode("ascii", "replace")
    unknown = set(tags) - _TYPE_TAGS
    if unknown:
        raise _Malformed(f"unsupported OSC argument type(s) {''.join(sorted(unknown))!r}")
    return [data]
_SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)   # Linux; the constant is missing in Python


def _osc_parser():
    try:
        from pythonosc import osc_message
    except ImportError:
        raise ImportError("OSC sources need python-osc: pip install 'mop[capture]'") from None
    return osc_message


def _names_for(address: str, count: int) -> list[str]:
    stem = address.rstrip("/").rsplit("/", 1)[-1] or "osc"
    return [f"{stem}.{i}" for i in range(count)]


class OscSource(ThreadedSource):
    """Frames from OSC messages arriving on a UDP port.

    Parameters
    ----------
    host, port : where to listen (default 127.0.0.1:6448, Wekinator's input port; port 0 picks
        a free port, see `.port`).
    mapping : {address: channel names | channel count | None}; None (or a count) names the
        channels "<last address segment>.<i>"; None learns the count from the first message
        (only with a single address). Default {address: channels}.
    address : the single address when no mapping is given (default /wek/inputs).
    channels : names or count for that address (default: learnt from the first message).
    receive_buffer : [bytes] kernel receive buffer asked for (bursts beyond it are dropped by
        the kernel and counted).
    max_channels : the most channels learnt from messages when the count is not given.
    """

    kind = "osc"

    def __init__(self, host: str = "127.0.0.1", port: int = WEKINATOR_PORT,
                 mapping: Mapping[str, Sequence[str] | int | None] | None = None, *,
                 address: str | None = None, channels: Sequence[str] | int | None = None,
                 clock: MonotonicClock | None = None, spec: str = "",
                 receive_buffer: int = 1 << 20, max_channels: int = MAX_CHANNELS,
                 wait: bool = True, **options):
        if mapping is None:
            mapping = {address or WEKINATOR_ADDRESS: channels}
        elif address is not None or channels is not None:
            raise ValueError("give either mapping= or address=/channels=, not both")
        if not mapping:
            raise ValueError("the OSC mapping is empty: give at least one address")
        self._slices: dict[str, slice] = {}
        names: list[str] = []
        learn = [a for a, c in mapping.items() if c is None]
        if learn and len(mapping) > 1:
            raise ValueError(f"OSC addresses {learn} have no channel count; with several "
                             f"addresses every one needs its channel names or count")
        for address_, wanted in mapping.items():
            if not isinstance(address_, str) or not address_.startswith("/"):
                raise ValueError(f"OSC addresses start with '/', got {address_!r}")
            if wanted is None:
                continue
            if isinstance(wanted, int) and not isinstance(wanted, bool):
                if wanted < 1:
                    raise ValueError(f"{address_}: channel count must be >= 1, got {wanted}")
                wanted = _names_for(address_, wanted)
            wanted = [str(w) for w in wanted]
            self._slices[address_] = slice(len(names), len(names) + len(wanted))
            names.extend(wanted)
        if len(set(names)) != len(names):
            raise ValueError(f"OSC channel names must be unique, got {names}")
        self._learn = learn[0] if learn else None
        self._learn_run = (0, 0)     # (count seen, consecutive messages with that count)
        self.max_channels = int(max_channels)
        if self.max_channels < 1:
            raise ValueError(f"max_channels must be >= 1, got {max_channels}")
        self.host = host
        self.port = int(port)
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be 0..65535, got {port}")
        self.receive_buffer = int(receive_buffer)
        super().__init__(names, 0.0, clock=clock, spec=spec or f"osc:{host}:{port}", **options)
        self._state = np.full(len(names), np.nan)
        self._scratch = np.empty(max(len(names), 1))
        self._socket: socket.socket | None = None
        self._kernel_drops = 0
        self._parser = _osc_parser()
        self.senders = SenderClocks()
        self._start(wait=wait)

    @property
    def mapping(self) -> dict[str, tuple[str, ...]]:
        """{address: channel names} as currently known."""
        return {a: self.channels[s] for a, s in self._slices.items()}

    def describe(self) -> dict:
        info = super().describe()
        info.update(host=self.host, port=self.port,
                    mapping={a: list(c) for a, c in self.mapping.items()})
        return info

    # -- device -----------------------------------------------------------------------------
    def _open_device(self) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.receive_buffer)
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_RXQ_OVFL, 1)
                self._count_overflow = True
            except OSError:
                self._count_overflow = False
            sock.bind((self.host, self.port))
            sock.settimeout(0.05)
        except OSError as error:
            sock.close()
            raise OSError(f"cannot listen on {self.host}:{self.port}: {error}") from None
        self.port = sock.getsockname()[1]
        self._socket = sock

    def _close_device(self) -> None:
        sock, self._socket = self._socket, None
        if sock is not None:
            sock.close()

    def _pump(self, timeout: float) -> None:
        sock = self._socket
        try:
            data, ancillary, _, sender = sock.recvmsg(65535, socket.CMSG_SPACE(4))
        except socket.timeout:
            return
        t = self.clock.now()
        for level, kind, payload in ancillary:
            if level == socket.SOL_SOCKET and kind == _SO_RXQ_OVFL and len(payload) >= 4:
                total = struct.unpack("=I", payload[:4])[0]
                if total > self._kernel_drops:
                    self._count(dropped=total - self._kernel_drops)
                    self._kernel_drops = total
        if self._handle(data, sender):
            tag = time_tag(data)
            if tag is not None:
                t = self.senders.map(sender, tag, t)
            self._emit(t, self._state.copy())

    # -- parsing ----------------------------------------------------------------------------
    def _handle(self, data: bytes, sender) -> bool:
        """Apply one datagram to the state; True when some mapped message was applied."""
        parser = self._parser
        if len(data) % 4:
            # OSC packets are multiples of 4 bytes; python-osc would read a cut-off last
            # argument from the bytes that are there
            self._problem(f"packet from {sender[0]} is {len(data)} bytes, not a multiple of 4 "
                          f"(cut off?)", malformed=True)
            return False
        try:
            messages = [parser.OscMessage(part) for part in _split_datagram(data)]
        except _Malformed as error:
            self._problem(f"unparseable packet from {sender[0]}: {error}", malformed=True)
            return False
        except Exception as error:    # ParseError, and whatever else garbage provokes
            self._problem(f"unparseable packet from {sender[0]}: {error}", malformed=True)
            return False
        applied = False
        for message in messages:
            address = message.address
            if self._learn is not None and address == self._learn:
                if not self._learn_from(address, len(message.params)):
                    continue
            target = self._slices.get(address)
            if target is None:
                self._count(unmapped=1)
                self._problem(f"unmapped address {address}")
                continue
            params = message.params
            width = target.stop - target.start
            if len(params) != width:
                self._problem(f"{address}: {len(params)} arguments, expected {width}",
                              malformed=True)
                continue
            # checked into a reused scratch row first, so a bad argument changes nothing
            values = self._scratch[:width]
            bad = False
            for i, value in enumerate(params):
                if isinstance(value, (bool, int, float)):
                    values[i] = float(value)
                elif value is None:             # OSC nil: explicitly missing
                    values[i] = math.nan
                else:
                    bad = True
                    break
            if bad:
                self._problem(f"{address}: non-numeric argument {type(value).__name__}",
                              malformed=True)
                continue
            self._state[target] = values
            applied = True
        return applied

    def _learn_from(self, address: str, count: int) -> bool:
        """One message towards learning the channel count; True once it is learnt."""
        if not 1 <= count <= self.max_channels:
            self._problem(f"{address}: {count} arguments; a source learns 1..{self.max_channels}"
                          f" channels (give ?channels= to say how many)", malformed=True)
            return False
        seen, run = self._learn_run
        run = run + 1 if count == seen else 1
        self._learn_run = (count, run)
        if run < LEARN_RUN:
            self._problem(f"{address}: learning the channel count ({count} in {run} of "
                          f"{LEARN_RUN} messages)")
            return False
        self._learn_channels(address, count)
        return True

    def _learn_channels(self, address: str, count: int) -> None:
        if count < 1:
            return
        names = _names_for(address, count)
        self._slices[address] = slice(0, count)
        self._channels = tuple(names)
        self._state = np.full(count, np.nan)
        self._scratch = np.empty(count)
        self._learn = None
        log.info("OSC %s: %d channels learnt from %d messages that agreed", address, count,
                 LEARN_RUN)
