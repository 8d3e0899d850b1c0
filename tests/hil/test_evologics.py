"""EvoLogics S2C data-mode adapter against scripted modem replies.

Independent truth: frames we encoded, and modem events written out by hand in the documented
``+++AT<cmd>:<len>:<body>`` CR LF form (REFERENCE §1.11).
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.hil import SENDIM_MAX, EvoLogicsAdapter, parse_received_message
from testbed.protocol import Frame, FrameDecoder, encode_frame

FRAME = encode_frame(b"a,b,,c\r\n+++AT:3:x\r\n" + bytes(range(90)))  # 115 B: two messages


def wrap(body: bytes, cmd: bytes = b"") -> bytes:
    return b"+++AT" + cmd + b":%d:" % len(body) + body + b"\r\n"


def recvim(data: bytes) -> bytes:
    return wrap(b"RECVIM,%d,1,2,noack,1125,-46,191,0.0000," % len(data) + data)


def modem_stream(frame: bytes) -> bytes:
    pieces = [frame[i : i + SENDIM_MAX] for i in range(0, len(frame), SENDIM_MAX)]
    return (
        wrap(b"OK", b"*SENDIM")
        + wrap(b"SENDSTART,3,im,182272,0")
        + b"".join(recvim(p) for p in pieces)
        + wrap(b"DELIVEREDIM,3")
        + wrap(b"BUSY BACKOFF STATE", b"*SENDIM")
    )


def test_writes_are_sendim_commands_of_at_most_64_bytes() -> None:
    adapter = EvoLogicsAdapter(3, ack=True, message_hold_s=0.5)
    writes = adapter.writes(FRAME)
    assert len(writes) == 2
    data = b""
    for w in writes:
        assert w.hold_s == 0.5
        assert w.data.endswith(b"\n")
        head, _, rest = w.data[:-1].partition(b",")
        length, addr, flag, piece = rest.split(b",", 3)
        assert head == b"+++AT*SENDIM" and addr == b"3" and flag == b"ack"
        assert int(length) == len(piece) <= SENDIM_MAX
        data += piece
    assert data == FRAME


def test_command_escape() -> None:
    assert EvoLogicsAdapter(1).command("AT?MODE") == b"+++AT?MODE\n"


def test_recvim_with_commas_and_line_ends_in_data() -> None:
    adapter = EvoLogicsAdapter(2)
    out = adapter.feed(modem_stream(FRAME))
    assert out == FRAME
    assert [e.payload for e in FrameDecoder().feed(out) if isinstance(e, Frame)] == [
        b"a,b,,c\r\n+++AT:3:x\r\n" + bytes(range(90))
    ]
    assert adapter.messages_in == 2
    assert adapter.event_counts == {
        "OK": 1,
        "SENDSTART": 1,
        "RECVIM": 2,
        "DELIVEREDIM": 1,
        "BUSY": 1,
    }
    assert adapter.parse_errors == 0


def test_split_at_every_byte_boundary() -> None:
    stream = modem_stream(FRAME)
    for cut in range(len(stream) + 1):
        adapter = EvoLogicsAdapter(2)
        assert adapter.feed(stream[:cut]) + adapter.feed(stream[cut:]) == FRAME, cut
        assert adapter.messages_in == 2


def test_byte_by_byte() -> None:
    stream = modem_stream(FRAME)
    adapter = EvoLogicsAdapter(2)
    assert b"".join(adapter.feed(stream[i : i + 1]) for i in range(len(stream))) == FRAME


def test_garbage_and_malformed_wrappers_are_counted() -> None:
    adapter = EvoLogicsAdapter(2)
    bad = b"+++ATxx:zz:" + b"+++AT:5:abc\r\n\r\n"  # non-numeric length; wrong length
    out = adapter.feed(bad + modem_stream(FRAME))
    decoder = FrameDecoder()
    assert [e for e in decoder.feed(out) if isinstance(e, Frame)] != []
    assert adapter.parse_errors == 2
    assert adapter.messages_in == 2


def test_transparent_burst_data_passes_through() -> None:
    frame = encode_frame(bytes(range(90)))
    adapter = EvoLogicsAdapter(2)
    assert adapter.feed(frame[:10] + wrap(b"RECVSTART") + frame[10:]) == frame
    assert adapter.transparent_bytes == len(frame)


def test_parse_received_message_variants() -> None:
    assert parse_received_message(b"RECVIM,3,1,2,ack,10,-40,180,0.0,a,b") == (
        b"RECVIM",
        [b"3", b"1", b"2", b"ack", b"10", b"-40", b"180", b"0.0"],
        b"a,b",
    )
    for body in (b"RECVIMS,2,1,2,123456,10,-40,180,0.0,xy", b"RECVPBM,2,1,2,10,-40,180,0.0,xy"):
        parsed = parse_received_message(body)
        assert parsed is not None and parsed[2] == b"xy"
    assert parse_received_message(b"RECVIM,4,1,2,ack,10,-40,180,0.0,a,b") is None
    assert parse_received_message(b"RECVIM,3,1,2,10,-40,180,0.0,a,b") is None
    assert parse_received_message(b"DELIVEREDIM,3") is None


def test_bad_recvim_is_a_parse_error() -> None:
    adapter = EvoLogicsAdapter(2)
    assert adapter.feed(wrap(b"RECVIM,9,1,2,ack,1,2,3,4,short")) == b""
    assert adapter.parse_errors == 1


def test_rejects_bad_address() -> None:
    with pytest.raises(ValueError):
        EvoLogicsAdapter(0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=60) | st.just(b"+++AT:"), max_size=8))
def test_never_raises(chunks: list[bytes]) -> None:
    adapter = EvoLogicsAdapter(2)
    out = b"".join(adapter.feed(c) for c in chunks)
    assert len(out) <= sum(map(len, chunks))


def test_setup_drops_stale_messages_and_sets_the_local_address() -> None:
    assert [w.data for w in EvoLogicsAdapter(1).setup()] == [b"+++ATZ4\n"]
    adapter = EvoLogicsAdapter(1, local_address=2, line_end=b"\r\n")
    assert [w.data for w in adapter.setup()] == [b"+++ATZ4\r\n", b"+++AT!AL2\r\n"]
    # The modem's answers to the setup are events, counted, and never payload.
    assert adapter.feed(wrap(b"OK", b"Z4") + wrap(b"OK", b"!AL")) == b""
    assert adapter.event_counts == {"OK": 2}
    with pytest.raises(ValueError):
        EvoLogicsAdapter(1, local_address=255)
