"""Raw and S100 adapters against scripted byte streams.

Independent truth: the frames we encoded ourselves, the S100Stream pacing rule (45 B pieces
spaced 45·8/2400 = 0.15 s, REFERENCE §1.10) and a frame decoder fed the stream.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.hil import S100_MAX_WRITE, RawAdapter, S100Adapter
from testbed.protocol import Frame, FrameDecoder, encode_frame

PAYLOADS = [b"\r\n\r\nUUU\x05\r\n", bytes(range(120)), b"", b"+++\x00not a status line", b"x" * 40]
FRAMES = [encode_frame(p) for p in PAYLOADS]


def modem_stream(frames: list[bytes]) -> bytes:
    """What an S100 delivers: each frame + CR LF, with status lines between and inside frames."""
    out = b"+++MODEM READY\r\n"
    for k, frame in enumerate(frames):
        packet = frame + b"\r\n"
        cut = min(len(packet) // 2, S100_MAX_WRITE)
        out += packet[:cut] + b"+++ACK %d\r\n" % k + packet[cut:]
    return out


def decode(stream: bytes) -> list[bytes]:
    decoder = FrameDecoder()
    return [e.payload for e in decoder.feed(stream) if isinstance(e, Frame)]


def test_raw_adapter_is_transparent() -> None:
    adapter = RawAdapter()
    assert [w.data for w in adapter.writes(FRAMES[1])] == [FRAMES[1]]
    assert adapter.feed(b"\x00\xffabc") == b"\x00\xffabc"
    assert adapter.counters() == {"bytes_in": 5}


def test_s100_writes_follow_the_45_byte_rule_and_pacing() -> None:
    adapter = S100Adapter(pace_bps=2400)
    writes = adapter.writes(FRAMES[1])  # 126 B frame + CR LF = 128 B
    assert [len(w.data) for w in writes] == [45, 45, 38]
    assert b"".join(w.data for w in writes) == FRAMES[1] + b"\r\n"
    assert writes[0].hold_s == pytest.approx(0.15)  # REFERENCE §1.10: 45·8/2400
    assert writes[-1].hold_s == pytest.approx(38 * 8 / 2400)


def test_s100_with_rtscts_writes_one_piece() -> None:
    writes = S100Adapter(rtscts=True).writes(FRAMES[1])
    assert [w.data for w in writes] == [FRAMES[1] + b"\r\n"]
    assert writes[0].hold_s == 0.0


def test_s100_strips_status_lines_and_terminators_whole() -> None:
    adapter = S100Adapter()
    out = adapter.feed(modem_stream(FRAMES))
    assert out == b"".join(FRAMES)
    assert adapter.status_lines == len(FRAMES) + 1
    assert adapter.terminators == len(FRAMES)
    assert adapter.last_status == b"ACK %d" % (len(FRAMES) - 1)
    assert decode(out) == PAYLOADS


def test_s100_split_at_every_byte_boundary() -> None:
    stream = modem_stream(FRAMES)
    for cut in range(len(stream) + 1):
        adapter = S100Adapter()
        out = adapter.feed(stream[:cut]) + adapter.feed(stream[cut:])
        assert out == b"".join(FRAMES), cut


def test_s100_byte_by_byte_and_random_chunks() -> None:
    stream = modem_stream(FRAMES)
    adapter = S100Adapter()
    assert b"".join(adapter.feed(stream[i : i + 1]) for i in range(len(stream))) == b"".join(FRAMES)
    rng = np.random.default_rng(7)
    for _ in range(20):
        cuts = np.sort(rng.integers(0, len(stream), size=6))
        pieces = np.split(np.frombuffer(stream, dtype=np.uint8), cuts)
        adapter = S100Adapter()
        assert b"".join(adapter.feed(p.tobytes()) for p in pieces) == b"".join(FRAMES)


def test_s100_garbage_is_passed_to_the_decoder_and_counted_there() -> None:
    garbage = b"\x00\x13garbage\xff\r\n+++\x01\x02"
    stream = garbage + modem_stream(FRAMES[:2]) + garbage
    adapter = S100Adapter()
    decoder = FrameDecoder()
    events = decoder.feed(adapter.feed(stream))
    assert [e.payload for e in events if isinstance(e, Frame)] == PAYLOADS[:2]
    assert decoder.garbage_bytes >= len(garbage)


def test_s100_missing_terminator_is_counted_and_harmless() -> None:
    adapter = S100Adapter()
    out = adapter.feed(FRAMES[0] + FRAMES[4] + b"\r\n")
    assert decode(out) == [PAYLOADS[0], PAYLOADS[4]]
    assert adapter.missing_terminators == 1
    assert adapter.terminators == 1


def test_s100_overlong_plus_line_is_data() -> None:
    text = b"+++" + b"a" * 250 + b"\r\n"
    adapter = S100Adapter()
    assert adapter.feed(text) == text
    assert adapter.status_lines == 0


def test_s100_payload_that_looks_like_a_status_line_is_lost_not_fatal() -> None:
    # Documented limitation: "+++<printable>" CR LF is taken for a status line even mid-frame.
    adapter = S100Adapter()
    out = adapter.feed(encode_frame(b"+++AT\r\n") + b"\r\n" + FRAMES[4] + b"\r\n")
    assert decode(out) == [PAYLOADS[4]]
    assert adapter.status_lines == 1


def test_s100_rejects_bad_settings() -> None:
    with pytest.raises(ValueError):
        S100Adapter(pace_bps=0)
    with pytest.raises(ValueError):
        S100Adapter(preamble_len=2)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=80), max_size=6))
def test_s100_never_raises_and_never_invents_bytes(chunks: list[bytes]) -> None:
    adapter = S100Adapter()
    out = b"".join(adapter.feed(c) for c in chunks)
    assert len(out) <= sum(map(len, chunks))


def test_transparent_modems_need_no_setup() -> None:
    assert RawAdapter().setup() == []
    assert S100Adapter().setup() == S100Adapter(rtscts=True).setup() == []
