"""OSC performers over UDP: a receiving socket on 127.0.0.1 by default, parsed with python-osc.

An address -> channels mapping says which OSC messages fill which channels; each datagram that
carries at least one mapped message becomes one Frame (channels of other addresses hold their
last value, NaN until first received). Without a mapping the source listens like Wekinator:
port 6448, address /wek/inputs, as many channels as the first message has arguments.

Packets are parsed with `pythonosc.osc_packet.OscPacket` on our own socket rather than through
python-osc's server, because that server silently drops packets it cannot parse; here garbage,
wrong argument counts and non-numeric arguments are counted (`stats.malformed`, with the reason in
`stats.problems`) and skipped. Datagrams the kernel dropped because the receive buffer was full
are counted too (Linux SO_RXQ_OVFL) in `stats.dropped`; the kernel reports them with the
next datagram that does arrive. Nothing is ever sent back to the sender.
To let performers on other machines join, bind host="0.0.0.0" explicitly.
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
_SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)   # Linux; the constant is missing in Python


def _osc_parser():
    try:
        from pythonosc import osc_packet
    except ImportError:
        raise ImportError("OSC sources need python-osc: pip install 'mop[capture]'") from None
    return osc_packet


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
    """

    kind = "osc"

    def __init__(self, host: str = "127.0.0.1", port: int = WEKINATOR_PORT,
                 mapping: Mapping[str, Sequence[str] | int | None] | None = None, *,
                 address: str | None = None, channels: Sequence[str] | int | None = None,
                 clock: MonotonicClock | None = None, spec: str = "",
                 receive_buffer: int = 1 << 20, wait: bool = True, **options):
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
            messages = [timed.message for timed in parser.OscPacket(data).messages]
        except Exception as error:    # ParseError, and whatever else garbage provokes
            self._problem(f"unparseable packet from {sender[0]}: {error}", malformed=True)
            return False
        applied = False
        for message in messages:
            address = message.address
            if self._learn is not None and address == self._learn:
                self._learn_channels(address, len(message.params))
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

    def _learn_channels(self, address: str, count: int) -> None:
        if count < 1:
            return
        names = _names_for(address, count)
        self._slices[address] = slice(0, count)
        self._channels = tuple(names)
        self._state = np.full(count, np.nan)
        self._scratch = np.empty(count)
        self._learn = None
        log.info("OSC %s: %d channels learnt from the first message", address, count)
