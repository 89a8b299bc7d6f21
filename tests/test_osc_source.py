"""OSC source on real loopback UDP: address -> channel mapping, Wekinator defaults, garbage
and malformed messages counted and survived, NaN, kernel drops counted, status."""
import socket
import struct
import time

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from capture import Status, open_source
from capture.osc import OscSource


def message(address, *args) -> bytes:
    builder = OscMessageBuilder(address)
    for arg in args:
        builder.add_arg(arg)
    return builder.build().dgram


def nil_message(address, *args) -> bytes:
    """An OSC message whose type tags are written by hand (N = nil)."""
    def pad(data):
        return data + b"\0" * (4 - len(data) % 4)
    tags = "," + "".join("N" if a is None else "f" for a in args)
    payload = b"".join(struct.pack(">f", a) for a in args if a is not None)
    return pad(address.encode()) + pad(tags.encode()) + payload


@pytest.fixture
def sender():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    yield sock
    sock.close()


def drain(source, count, timeout=3.0):
    frames, deadline = [], time.monotonic() + timeout
    while len(frames) < count and time.monotonic() < deadline:
        frame = source.read(timeout=0.05)
        if frame is not None:
            frames.append(frame)
    return frames


def wait_for(predicate, timeout=3.0):
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.01)
    return predicate()


def test_mapping_fills_channels_and_holds_the_others(sender):
    with OscSource("127.0.0.1", 0, {"/glove/bend": ["thumb", "index", "middle"],
                                    "/glove/pos": 2}) as source:
        assert source.channels == ("thumb", "index", "middle", "pos.0", "pos.1")
        target = ("127.0.0.1", source.port)
        sender.sendto(message("/glove/bend", 0.1, 0.2, 0.3), target)
        sender.sendto(message("/glove/pos", 1.5, -2), target)
        sender.sendto(message("/glove/bend", 0.4, 0.5, 0.6), target)
        frames = drain(source, 3)
    values = np.array([f.values for f in frames])
    np.testing.assert_allclose(values[0], [0.1, 0.2, 0.3, np.nan, np.nan], rtol=1e-6)
    np.testing.assert_allclose(values[1], [0.1, 0.2, 0.3, 1.5, -2.0], rtol=1e-6)
    np.testing.assert_allclose(values[2], [0.4, 0.5, 0.6, 1.5, -2.0], rtol=1e-6)
    assert [f.seq for f in frames] == [0, 1, 2]
    assert frames[0].t <= frames[1].t <= frames[2].t


def test_wekinator_inputs_out_of_the_box(sender):
    with open_source("osc:127.0.0.1:0") as source:     # /wek/inputs, channels learnt
        assert source.channels == ()
        target = ("127.0.0.1", source.port)
        # the count is learnt from LEARN_RUN (3) consecutive messages that agree on it
        for first_value in (-1.0, 0.0, 1.0):
            sender.sendto(message("/wek/inputs", first_value, 2.0, 3.0, 4.0), target)
        first = drain(source, 1)[0]
        assert source.channels == ("inputs.0", "inputs.1", "inputs.2", "inputs.3")
        np.testing.assert_array_equal(first.values, [1, 2, 3, 4])
        sender.sendto(message("/wek/inputs", 1.0, 2.0), target)   # wrong count now
        sender.sendto(message("/wek/inputs", 5, 6, 7, 8), target)  # ints are fine
        second = drain(source, 1)[0]
        np.testing.assert_array_equal(second.values, [5, 6, 7, 8])
        assert wait_for(lambda: source.stats.malformed == 1)
        assert "2 arguments, expected 4" in source.stats.last_error or any(
            "2 arguments, expected 4" in p for p in source.stats.problems)


def test_spec_with_address_and_channel_count(sender):
    with open_source("osc:127.0.0.1:0/glove?channels=5") as source:
        assert source.channels == tuple(f"glove.{i}" for i in range(5))
        assert source.describe()["mapping"] == {"/glove": list(source.channels)}


def test_garbage_and_malformed_packets_are_counted_and_survived(sender, rng):
    with OscSource("127.0.0.1", 0, address="/glove", channels=2) as source:
        target = ("127.0.0.1", source.port)
        good = message("/glove", 1.0, 2.0)
        sender.sendto(b"\x00\x01garbage" + rng.bytes(13), target)       # not OSC
        sender.sendto(good[:-3], target)                                   # truncated
        sender.sendto(message("/glove", 1.0, "two"), target)               # a string
        sender.sendto(message("/glove", 1.0, 2.0, 3.0), target)            # 3 args, not 2
        sender.sendto(b"", target)                                          # empty datagram
        sender.sendto(message("/elsewhere", 1.0), target)                  # not mapped
        sender.sendto(good, target)
        frames = drain(source, 1)
        assert wait_for(lambda: source.stats.malformed == 5)
        stats = source.stats
        assert len(frames) == 1 and frames[0].values.tolist() == [1.0, 2.0]
        assert stats.frames == 1 and stats.unmapped == 1
        assert source.status is Status.OK
        assert any("unparseable packet" in p for p in stats.problems)
        assert any("non-numeric argument str" in p for p in stats.problems)
        # nothing is sent back to the sender (python-osc servers answer with handler results)
        sender.settimeout(0.2)
        with pytest.raises(socket.timeout):
            sender.recv(1024)


def test_bundles_apply_every_message_in_one_frame(sender):
    with OscSource("127.0.0.1", 0, {"/a": 1, "/b": 1}) as source:
        bundle = OscBundleBuilder(IMMEDIATELY)
        bundle.add_content(_built("/a", 3.0))
        bundle.add_content(_built("/b", 4.0))
        sender.sendto(bundle.build().dgram, ("127.0.0.1", source.port))
        frames = drain(source, 1)
    assert frames[0].values.tolist() == [3.0, 4.0]


def _built(address, value):
    builder = OscMessageBuilder(address)
    builder.add_arg(value)
    return builder.build()


def test_nan_and_nil_arguments_are_missing_values_and_counted(sender):
    with OscSource("127.0.0.1", 0, address="/x", channels=3) as source:
        target = ("127.0.0.1", source.port)
        sender.sendto(message("/x", float("nan"), 1.0, float("inf")), target)
        sender.sendto(nil_message("/x", 2.0, None, 3.0), target)
        frames = drain(source, 2)
        values = np.array([f.values for f in frames])
        assert np.isnan(values[0, 0]) and values[0, 1] == 1.0 and np.isnan(values[0, 2])
        assert values[1, 0] == 2.0 and np.isnan(values[1, 1]) and values[1, 2] == 3.0
        assert source.stats.nan_values == 3
        assert source.stats.malformed == 0


def test_status_stalls_without_packets_and_recovers(sender):
    with OscSource("127.0.0.1", 0, address="/x", channels=1, stall_timeout=0.15) as source:
        assert wait_for(lambda: source.status is Status.STALLED, 2.0)
        sender.sendto(message("/x", 1.0), ("127.0.0.1", source.port))
        drain(source, 1)
        assert source.status is Status.OK
        assert wait_for(lambda: source.status is Status.STALLED, 2.0)
    assert source.status is Status.DISCONNECTED


def test_a_port_in_use_is_a_clear_error():
    with OscSource("127.0.0.1", 0, address="/x", channels=1) as first:
        with pytest.raises(OSError, match=rf"cannot listen on 127.0.0.1:{first.port}"):
            OscSource("127.0.0.1", first.port, address="/x", channels=1)


def test_kernel_drops_are_counted_so_nothing_goes_unaccounted(sender):
    sent = 20000
    with OscSource("127.0.0.1", 0, address="/x", channels=1, receive_buffer=4096,
                   queue_size=sent) as source:
        target = ("127.0.0.1", source.port)
        packets = [message("/x", float(i)) for i in range(sent)]
        for packet in packets:
            sender.sendto(packet, target)
        # the kernel reports drops with the next datagram that gets through
        time.sleep(0.3)
        sender.sendto(message("/x", float(sent)), target)
        sent += 1
        assert wait_for(lambda: source.stats.frames + source.stats.dropped == sent, 10.0), \
            source.stats
        frames = drain(source, source.stats.frames)
        stats = source.stats
    assert stats.dropped > 0              # a 4 KiB buffer cannot take 20000 packets at once
    received = np.array([f.values[0] for f in frames])
    assert received.size == stats.frames
    assert np.all(np.diff(received) > 0)  # what arrived is in order, without duplicates


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="start with '/'"):
        OscSource("127.0.0.1", 0, {"glove": 2})
    with pytest.raises(ValueError, match="no channel count"):
        OscSource("127.0.0.1", 0, {"/a": None, "/b": 2})
    with pytest.raises(ValueError, match="port must be 0..65535"):
        OscSource("127.0.0.1", 70000)
    with pytest.raises(ValueError, match="port must be a number"):
        open_source("osc:127.0.0.1:abc/x")


def _bundle(*contents: bytes) -> bytes:
    """A bundle around raw element datagrams (sizes as given, contents unchecked)."""
    head = b"#bundle\x00" + b"\x00" * 7 + b"\x01"
    return head + b"".join(len(c).to_bytes(4, "big") + c for c in contents)


def test_one_hostile_packet_cannot_fix_the_channel_count(sender):
    with OscSource("127.0.0.1", 0, address="/in") as source:
        target = ("127.0.0.1", source.port)
        sender.sendto(message("/in", *([1.0] * 10000)), target)     # one hostile packet
        for value in (1.0, 2.0):
            sender.sendto(message("/in", value, value), target)
        sender.sendto(message("/in", 7.0, 7.0, 7.0), target)        # breaks the run
        for value in (3.0, 4.0, 5.0, 6.0):
            sender.sendto(message("/in", value, value), target)
        frames = drain(source, 2)
        assert source.channels == ("in.0", "in.1")
        assert [f.values.tolist() for f in frames] == [[5.0, 5.0], [6.0, 6.0]]
        assert source.stats.malformed == 1
        assert any("10000 arguments" in p for p in source.stats.problems)


def test_malformed_bundles_are_counted_not_logged(sender, caplog, capfd):
    import logging
    good = message("/glove", 1.0, 2.0)
    nested = good
    for _ in range(12):
        nested = _bundle(nested)
    junk = [
        _bundle(b"\x00\x00\x00\x00"),                   # neither message nor bundle inside
        _bundle(good[:8]),                               # a message cut short
        _bundle(good) + b"\x00\x00\x01\x00",            # an element larger than what is left
        _bundle()[:16] + (-4).to_bytes(4, "big", signed=True) + good,   # a negative size
        nested,                                          # 12 bundles deep
        _bundle(b"/glove\x00\x00,Iq\x00"),              # type tags python-osc warns about
        b"#bundle\x00\x00",                              # a header cut short
    ]
    with caplog.at_level(logging.DEBUG):
        with OscSource("127.0.0.1", 0, address="/glove", channels=2) as source:
            target = ("127.0.0.1", source.port)
            for _ in range(50):
                for packet in junk:
                    sender.sendto(packet, target)
                time.sleep(0.002)
            sender.sendto(_bundle(good, message("/glove", 3.0, 4.0)), target)  # a good bundle
            frames = drain(source, 1)
            assert wait_for(lambda: source.stats.malformed == 50 * len(junk))
            assert frames[0].values.tolist() == [3.0, 4.0]
            assert source.status is Status.OK
    assert not [r for r in caplog.records if r.name == "root"]
    assert "Could not identify" not in capfd.readouterr().err


def _stamped(address, value, tag):
    bundle = OscBundleBuilder(tag)
    bundle.add_content(_built(address, value))
    return bundle.build().dgram


def test_time_tagged_bundles_keep_the_senders_spacing_not_the_arrivals(sender):
    """Frames tagged 40 ms apart and sent each 0-30 ms after its time (the sender's and the
    network's jitter) keep the tags' spacing on the capture clock, anchored at the first one's
    arrival; plain messages keep their arrival times."""
    from capture.osc import time_tag
    rng = np.random.default_rng(5)
    base = time.time() - 3600.0                # the sender's clock: far from ours
    with OscSource("127.0.0.1", 0, address="/x", channels=1) as source:
        target = ("127.0.0.1", source.port)
        arrivals, start = [], time.monotonic()
        for k in range(8):
            time.sleep(max(start + 0.04 * k + float(rng.uniform(0.0, 0.03)) - time.monotonic(),
                           0.0))
            arrivals.append(time.monotonic())
            sender.sendto(_stamped("/x", float(k), base + 0.04 * k), target)
        frames = drain(source, 8)
        sender.sendto(message("/x", 9.0), target)
        plain = drain(source, 1)[0]
    assert time_tag(_stamped("/x", 0.0, base)) == pytest.approx(base, abs=1e-6)
    assert [f.values[0] for f in frames] == [float(k) for k in range(8)]
    times = np.array([f.t for f in frames])
    assert np.allclose(np.diff(times), 0.04, atol=1e-5)
    assert abs(times[0] - arrivals[0]) < 0.05 and source.senders.anchors == 1
    assert np.ptp(np.diff(arrivals)) > 0.01          # the arrivals were irregular
    assert plain.t == pytest.approx(time.monotonic(), abs=1.0) and plain.t > times[-1] - 0.1


def test_a_sender_whose_clock_jumps_is_anchored_again(sender):
    base = time.time()
    with OscSource("127.0.0.1", 0, address="/x", channels=1) as source:
        target = ("127.0.0.1", source.port)
        sender.sendto(_stamped("/x", 1.0, base), target)
        first = drain(source, 1)[0]
        sender.sendto(_stamped("/x", 2.0, base - 30.0), target)     # its clock went back
        second = drain(source, 1)[0]
    assert source.senders.anchors == 2
    assert second.t >= first.t and second.t == pytest.approx(time.monotonic(), abs=1.0)
