"""Packet boundaries on real links: where each adapter says a received packet ends, and the
endpoint's decoder giving up a mis-framed candidate there (as ``LinkPort._receive`` does in
simulation at the end of a transmission).

* S100 / raw: the idle line ends a packet (:meth:`idle`), detected by the transport from an
  empty read at least ``packet_gap_s`` after the last bytes;
* EvoLogics: the last instant message of each frame (shorter than 64 B, or completing the
  frame's announced length);
* M64: the last 8-byte packet of each frame (completing its announced length), a packet
  outside any frame, and before a packet starting a new frame while the last one is short.
"""

from __future__ import annotations

import queue
import time

from testbed.hil import (
    SENDIM_MAX,
    EvoLogicsAdapter,
    LinkEndpoint,
    M64Adapter,
    RawAdapter,
    Received,
    S100Adapter,
    Segment,
    SerialTransport,
    packet_gap_s,
)
from testbed.protocol import CorruptFrame, Frame, FrameDecoder, encode_frame

ORDER = encode_frame(b"order!!")  # 13 B


def corrupted(frame: bytes, length: int = 200) -> bytes:
    out = bytearray(frame)
    out[3] = length
    return bytes(out)


def recvim(data: bytes) -> bytes:
    body = b"RECVIM,%d,1,2,noack,1125,-46,191,0.0000," % len(data) + data
    return b"+++AT:%d:" % len(body) + body + b"\r\n"


def wrp_all(frame: bytes) -> bytes:
    packets = [frame[i : i + 8].ljust(8, b"\0") for i in range(0, len(frame), 8)]
    return b"".join(b"wrp,8," + p + b"\n" for p in packets)


def ends(segments: list[Segment]) -> list[int]:
    """Offsets in the joined stream after which a packet ends."""
    out, pos = [], 0
    for s in segments:
        pos += len(s.data)
        if s.end:
            out.append(pos)
    return out


def test_gap_is_20_ms_or_four_byte_times() -> None:
    assert packet_gap_s(9600) == 0.02
    assert packet_gap_s(1200) == 40 / 1200


def test_transparent_adapters_end_packets_on_the_idle_line_only() -> None:
    s100 = S100Adapter()
    assert ends(s100.receive(ORDER + b"\r\n")) == []
    assert s100.receive(ORDER + b"\r") == [Segment(ORDER)]  # CR held for its LF
    assert s100.idle() == [Segment(b"", end=True)]  # the held CR was the terminator
    assert s100.receive(b"++") == []  # held: a status line may follow
    assert s100.idle() == [Segment(b"++", end=True)]  # it did not: data after all
    # a corrupted length byte's tracking stops at the packet end: the next CR LF is stripped
    s100.receive(corrupted(ORDER) + b"\r\n")
    s100.idle()
    assert s100.receive(ORDER + b"\r\n") == [Segment(ORDER)]
    raw = RawAdapter()
    assert raw.receive(ORDER) == [Segment(ORDER)] and raw.idle() == [Segment(b"", end=True)]


def test_evologics_ends_a_packet_after_the_last_message_of_each_frame() -> None:
    adapter = EvoLogicsAdapter(1)
    long = encode_frame(bytes(range(100)))  # 106 B: two messages, 64 + 42
    stream = recvim(ORDER) + recvim(long[:SENDIM_MAX]) + recvim(long[SENDIM_MAX:])
    assert ends(adapter.receive(stream)) == [13, 13 + len(long)]
    exact = encode_frame(bytes(58))  # 64 B: one full message, complete by its length
    assert ends(adapter.receive(recvim(exact))) == [64]
    # a frame whose last message was lost ends when the next frame starts
    segments = adapter.receive(recvim(long[:SENDIM_MAX]) + recvim(ORDER))
    assert ends(segments) == [SENDIM_MAX, SENDIM_MAX + 13]
    assert adapter.idle() == []
    assert adapter.feed(recvim(ORDER)) == ORDER


def test_m64_ends_a_packet_after_the_last_packet_of_each_frame() -> None:
    adapter = M64Adapter(checksum=False)
    assert ends(adapter.receive(wrp_all(ORDER))) == [13]  # two packets, one end
    assert ends(adapter.receive(wrp_all(ORDER)[:15])) == []  # first packet only
    # its second packet lost: the next frame's first packet ends it first (the 8 bytes of the
    # first packet went out in the call before)
    assert ends(adapter.receive(wrp_all(ORDER))) == [0, 13]
    # a corrupted length byte claims 206 B; the next frame's start ends it
    bad = adapter.receive(wrp_all(corrupted(ORDER)) + wrp_all(ORDER))
    assert ends(bad) == [16, 29]
    assert adapter.idle() == []


def test_s100_frames_longer_than_a_packet_cross_in_45_byte_pieces() -> None:
    """A 60-B frame (an image reply) leaves in 45-B pieces, only the last with CR LF: the idle
    line after a piece is no frame's end, so the frame decodes whole; the packet after it ends
    as any other (the next frame is decoded, a mis-framed one given up)."""
    reply = encode_frame(bytes(range(54)))  # 60 B
    sender, receiver = S100Adapter(), S100Adapter()
    pieces = [w.data for w in sender.writes(reply)]
    assert [len(p) for p in pieces] == [45, 17]
    segments: list[Segment] = []
    for piece in pieces:
        segments += receiver.receive(piece) + receiver.idle()
    assert ends(segments) == [60]  # one packet end, after the whole frame
    assert b"".join(s.data for s in segments) == reply
    decoder = FrameDecoder()
    events = [e for s in segments for e in decoder.feed_packet(s.data, packet_end=s.end)]
    assert events == [Frame(bytes(range(54)))]
    # a 45-B packet that is not inside a longer frame still ends where the line went idle
    stray = receiver.receive(b"x" * 45) + receiver.idle()
    assert stray[-1].end


def test_the_endpoint_gives_up_a_mis_framed_candidate_at_a_packet_end() -> None:
    class Inbox:
        adapter = RawAdapter()

        def __init__(self) -> None:
            self.inbox: queue.Queue[Received] = queue.Queue()

    transport = Inbox()
    endpoint = LinkEndpoint(transport)  # type: ignore[arg-type]
    transport.inbox.put(Received(corrupted(ORDER), 0))
    transport.inbox.put(Received(ORDER, 0))
    assert endpoint.poll() == []  # without a packet end, the good order waits behind
    transport.inbox.put(Received(b"", 0, end=True))
    events = endpoint.poll()
    assert [e for e in events if isinstance(e, Frame)] == [Frame(b"order!!")]
    assert [type(e) for e in events].count(CorruptFrame) == 1 == endpoint.corrupt_frames
    handed: list[Frame] = []
    transport.inbox.put(Received(corrupted(ORDER), 0, end=True))
    transport.inbox.put(Received(ORDER, 0, end=True))
    assert endpoint.deliver(handed.append) == 1 and handed == [Frame(b"order!!")]


class ScriptedPort:
    """Returns its chunks, then empty reads after a short wait (an idle line)."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.chunks = list(chunks)

    def read(self, size: int = 1) -> bytes:
        if self.chunks:
            return self.chunks.pop(0)
        time.sleep(0.005)
        return b""

    def write(self, data: bytes) -> int:
        return len(data)

    @property
    def in_waiting(self) -> int:
        return 0

    def close(self) -> None:
        pass


def test_the_transport_ends_a_packet_once_the_line_has_been_idle_for_the_gap() -> None:
    port = ScriptedPort([corrupted(ORDER)])
    transport = SerialTransport(
        "fake", RawAdapter(), baudrate=9600, port_factory=lambda: port, packet_gap_s=0.05
    )
    try:
        first = transport.inbox.get(timeout=2.0)
        t0 = time.monotonic()
        end = transport.inbox.get(timeout=2.0)
        waited = time.monotonic() - t0
    finally:
        transport.close()
    assert first.data == corrupted(ORDER) and not first.end
    assert end == Received(b"", end.read_ns, end=True)
    assert 0.03 <= waited < 1.0  # the gap (less the time to read the first), never at once
    assert transport.packet_ends == 1  # one idle line, one end
