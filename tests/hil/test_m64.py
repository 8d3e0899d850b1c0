"""Water Linked Modem-M64 adapter against scripted modem sentences.

Independent truth: a bit-by-bit CRC-8 and the catalogue check value 0xF4 (CRC-8/SMBUS, the
``crc-8`` of crcmod used by waterlinked/modem-python), and sentences written by hand in the
documented ``wrp,8,<8 raw bytes>*xx`` LF form (REFERENCE §1.12).
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.hil import CRC8_CHECK_VALUE, M64_PACKET_SIZE, M64Adapter, crc8, m64_sentence
from testbed.protocol import Frame, FrameDecoder, encode_frame

PAYLOADS = [b"\r\n\n\rw*,", bytes(range(30)), b"ok"]
FRAMES = [encode_frame(p) for p in PAYLOADS]


def crc8_bitwise(data: bytes) -> int:
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x107) if crc & 0x80 else crc << 1
    return crc & 0xFF


def packets(frame: bytes) -> list[bytes]:
    return [frame[i : i + 8].ljust(8, b"\0") for i in range(0, len(frame), 8)]


def wrp(packet: bytes, checksum: bool = True, eol: bytes = b"\n") -> bytes:
    body = b"wrp,8," + packet
    return body + (b"*%02x" % crc8_bitwise(body) if checksum else b"") + eol


def modem_stream(frames: list[bytes]) -> bytes:
    out = b"wrv,1,0,2\r\nwrq,a\n"
    for k, frame in enumerate(frames):
        for packet in packets(frame):
            out += wrp(packet, checksum=k % 2 == 0, eol=b"\r\n" if k else b"\n")
    return out


def payloads(stream: bytes) -> list[bytes]:
    return [e.payload for e in FrameDecoder().feed(stream) if isinstance(e, Frame)]


def test_crc8_check_value() -> None:
    assert crc8(b"123456789") == CRC8_CHECK_VALUE == crc8_bitwise(b"123456789") == 0xF4
    assert crc8(b"wcq,8,HelloSea") == crc8_bitwise(b"wcq,8,HelloSea")


def test_sentences() -> None:
    assert m64_sentence("s", [b"a", b"4"]) == b"wcs,a,4\n"
    assert m64_sentence("v") == b"wcv\n"
    assert m64_sentence("q", [b"8", b"HelloSea"], checksum=True) == (
        b"wcq,8,HelloSea*%02x\n" % crc8_bitwise(b"wcq,8,HelloSea")
    )


def test_writes_fragment_frames_into_padded_8_byte_packets() -> None:
    adapter = M64Adapter(checksum=True)
    writes = adapter.writes(FRAMES[1])  # 36 B → 5 packets
    assert len(writes) == 5
    raw = b""
    for w in writes:
        assert w.data.startswith(b"wcq,8,") and w.data.endswith(b"\n")
        body, crc_text = w.data[:-4], w.data[-3:-1]
        assert w.data[-4:-3] == b"*" and int(crc_text, 16) == crc8_bitwise(body)
        raw += body[6:]
        assert len(body[6:]) == M64_PACKET_SIZE
    assert raw == FRAMES[1] + bytes(4)


def test_counted_reads_with_cr_lf_in_raw_bytes() -> None:
    adapter = M64Adapter()
    out = adapter.feed(modem_stream(FRAMES))
    assert out == b"".join(FRAMES)  # padding dropped
    assert payloads(out) == PAYLOADS
    assert adapter.packets_in == sum(len(packets(f)) for f in FRAMES)
    assert adapter.padding_bytes == sum(-len(f) % 8 for f in FRAMES)
    assert adapter.acks == 1 and adapter.replies == 1 and adapter.last_reply == b"wrv,1,0,2"
    assert adapter.crc_errors == adapter.parse_errors == adapter.garbage_bytes == 0


def test_split_at_every_byte_boundary() -> None:
    stream = modem_stream(FRAMES)
    for cut in range(len(stream) + 1):
        adapter = M64Adapter()
        assert adapter.feed(stream[:cut]) + adapter.feed(stream[cut:]) == b"".join(FRAMES), cut


def test_crc_error_drops_the_packet_and_costs_one_frame() -> None:
    stream = bytearray(modem_stream(FRAMES))
    first = packets(FRAMES[0])[1]
    at = bytes(stream).index(first)
    stream[at] ^= 0x01  # one flipped bit in the second packet of frame 0 (checksummed)
    adapter = M64Adapter()
    out = adapter.feed(bytes(stream))
    assert adapter.crc_errors == 1
    assert payloads(out) == PAYLOADS[1:]


def test_lost_packet_costs_only_its_frame() -> None:
    stream = b"".join(wrp(p) for p in packets(FRAMES[1])[:2] + packets(FRAMES[1])[3:])
    stream += b"".join(wrp(p) for p in packets(FRAMES[2]))
    adapter = M64Adapter()
    assert payloads(adapter.feed(stream)) == [PAYLOADS[2]]


def test_garbage_between_sentences_is_counted() -> None:
    adapter = M64Adapter()
    out = adapter.feed(b"\x00\x01noise" + modem_stream(FRAMES[:1]) + b"xyz")
    assert payloads(out) == PAYLOADS[:1]
    assert adapter.garbage_bytes == len(b"\x00\x01noise") + len(b"xyz")
    assert adapter.parse_errors == 0


def test_nack_and_malformed_sentences() -> None:
    adapter = M64Adapter()
    adapter.feed(b"wrq,n\nwxq\nwrq,a*00\n")
    assert adapter.nacks == 1
    assert adapter.parse_errors == 1  # "wxq": bad direction
    assert adapter.crc_errors == 1


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=40) | st.just(b"wrp,8,"), max_size=8))
def test_never_raises(chunks: list[bytes]) -> None:
    adapter = M64Adapter()
    out = b"".join(adapter.feed(c) for c in chunks)
    assert len(out) <= sum(map(len, chunks))


def with_crc(body: bytes) -> bytes:
    return body + b"*%02x\n" % crc8_bitwise(body)


def test_setup_queries_configures_and_flushes_like_water_linkeds_library() -> None:
    adapter = M64Adapter(role="b", channel=6)
    expected = [b"\n", with_crc(b"wcv"), with_crc(b"wcn"), with_crc(b"wcs,b,6"), with_crc(b"wcf")]
    assert [w.data for w in adapter.setup()] == expected
    plain = M64Adapter(checksum=False)  # no role: the modem's settings are left alone
    assert [w.data for w in plain.setup()] == [b"\n", b"wcv\n", b"wcn\n", b"wcf\n"]
    # The answers are counted as replies and never reach the frame decoder.
    answers = b"wrv,1,0,2\n" + with_crc(b"wrn,8") + b"wrs,a\nwrf,a\n"
    assert adapter.feed(answers) == b""
    assert adapter.replies == 4 and adapter.last_reply == b"wrf,a"


def test_setup_rejects_a_bad_role_or_channel() -> None:
    with pytest.raises(ValueError):
        M64Adapter(role="c")
    with pytest.raises(ValueError):
        M64Adapter(role="a", channel=0)
    with pytest.raises(ValueError):
        M64Adapter(channel=8)
