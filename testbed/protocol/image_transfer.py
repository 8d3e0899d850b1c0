"""Image transfer over the narrow link: chunking, image CRC, selective repeat (REFERENCE §1.5).

Two sans-IO state machines, one per end. They never see frames, clocks or random numbers: the
nodes copy header fields in and out of :class:`~testbed.protocol.messages.OperatorMessage`
(byte 0: image sequence bit expected · cancel image · first missing chunk) and
:class:`~testbed.protocol.messages.VehicleMessage` (byte 0 first/last chunk flags; byte 13:
image sequence bit · cancel · chunk index; then the chunk).

* :class:`~testbed.protocol.image_sender.ImageSender`, on the vehicle, holds at most one image:
  the encoded bytes followed by their CRC-16/XMODEM (big-endian), cut into chunks of
  ``chunk_bytes`` (40 B by default, 1..150), at most 64 of them because the index has 6 bits
  (:func:`max_image_bytes`).
* :class:`~testbed.protocol.image_assembler.ImageAssembler`, on the operator, asks for the chunks
  it misses, checks the image CRC and hands out the image; its ``prefix()`` gives the contiguous
  bytes received so far for progressive decoding (less one byte until the length is known, so
  that it is always a true prefix of the image, never a CRC byte).

**Selective repeat** (the default). The operator drives; one bit names the image:

.. code-block:: text

    operator (ImageAssembler)                vehicle (ImageSender)
    expects F, holds nothing                 wants_image → load(A): A takes bit F, chunks 0..2
    [F · - · 0] ───────────────────────────► send A0
                ◄─────────────────────────── [first · F · 0 · A0]
    [F · - · 1] ──────────────X (order lost, no reply)
    [F · - · 1] ───────────────────────────► send A1
                ◄────────────X (reply lost)
    [F · - · 1] ───────────────────────────► send A1
                ◄─────────────────────────── [F · 1 · A1]
    [F · - · 2] ───────────────────────────► send A2
                ◄─────────────────────────── [last · F · 2 · A2]
    CRC(A0 A1 A2) ok: A completed, expect T
    [T · - · 0] ───────────────────────────► T ≠ F: A acknowledged → wants_image
                                             load(B): B takes bit T (the bit asked for)
                ◄─────────────────────────── [first · T · 0 · B0]
    cancel(): drop B's chunks
    [T · cancel · 0] ──────────────────────► drop B → wants_image; reply is a cancel notice
                ◄─────────────────────────── [T · cancel · no data]
    notice seen: stop cancelling, still expect T
    [T · - · 0] ───────────────────────────► load(C): C takes T, send C0

Rules, and why:

* Both ends start at bit False. A loaded image takes the bit of the last request (False before
  any), so a request whose bit differs from the held image's acknowledges it: the vehicle drops
  it and ``ImageSender.wants_image`` turns True. A restarted or confused operator therefore
  resynchronises the vehicle by asking for what it expects.
* The operator keeps every chunk of the expected bit, in any order, and asks for the first index
  it misses; the chunk flagged *last* gives the image length. With every chunk in, the image CRC
  decides: success hands out the image and toggles the expected bit; failure drops all chunks
  and starts again from chunk 0 (counted). Chunks of another bit are ignored.
* A chunk that cannot belong to a well-formed image (a non-last chunk shorter or longer than
  ``chunk_bytes``, a last chunk making the image shorter than its CRC, a first flag that
  disagrees with index 0) is dropped and counted. A chunk that contradicts what is held (another
  length, other bytes at a held index) restarts the image from that chunk, counted: the vehicle
  changed image under the same bit, and the newest chunk is the one to trust.
* A request beyond the image's last chunk is answered with the last chunk: its *last* flag tells
  the operator the real length, which drops whatever it held beyond it (a chunk at index modulo
  the count would repeat a chunk the operator holds and carry no news).
* Cancel: the operator sets *cancel* in every request until it sees a reply with *cancel* set.
  The vehicle answers every cancelling request with such a notice (the request's bit, no data),
  drops any image it holds and wants a new one, which takes the same bit: the bit means "the
  image I expect", cancelled or not. A notice lost on the way is repeated on the next request
  (dropping an image loaded meanwhile); a notice for the expected bit that arrives after the
  cancel ended drops the partial image too, since the vehicle dropped its image again.
* A reply built without a fresh request (hold-channel streaming) continues with the next chunk,
  wrapping after the last.
* Garbled remote data — any flags, any index, any bytes — becomes an ``AssemblyEvent`` and
  a counter, never an exception; the image CRC is the last line against a frame that passed its
  own CRC with wrong content.

**Paper mode** (``selective_repeat=False``; both ends must agree): the vehicle streams chunks
0, 1, 2, … one per reply whatever the operator asks, and after the last chunk wants the next
image, which takes the other bit. The operator completes an image only when it receives every
chunk in order; a gap spoils the image (counted once per image it saw part of; an image lost
whole is not seen and not counted; a tail lost is noticed when the next image shows up). This is
the 2017–2019 behaviour, where one lost packet lost the image.

This module holds the protocol's rules (above) and what both ends share: the chunk layout
(:data:`IMAGE_CRC_SIZE`, :data:`MAX_CHUNKS`, :func:`max_image_bytes`) and the settings they
must agree on (:class:`TransferEnd`). The ends are :mod:`~testbed.protocol.image_sender` and
:mod:`~testbed.protocol.image_assembler`, each read beside the rules here.

Standard library only; no I/O, no clock.
"""

from __future__ import annotations

from .messages import DEFAULT_CHUNK_SIZE, MAX_CHUNK_INDEX, MAX_CHUNK_SIZE

__all__ = [
    "IMAGE_CRC_SIZE",
    "MAX_CHUNKS",
    "TransferEnd",
    "check_chunk_bytes",
    "max_image_bytes",
]

IMAGE_CRC_SIZE = 2
"""CRC-16/XMODEM appended big-endian to every encoded image [B]."""

MAX_CHUNKS = MAX_CHUNK_INDEX + 1
"""Chunks per image: the index has 6 bits."""


def check_chunk_bytes(chunk_bytes: int) -> int:
    """Check a chunk size: an int in 1..150 [B].

    Returns:
        ``chunk_bytes``.

    Raises:
        ValueError: not an int, or out of range.
    """
    if (
        isinstance(chunk_bytes, bool)
        or not isinstance(chunk_bytes, int)
        or not 1 <= chunk_bytes <= MAX_CHUNK_SIZE
    ):
        raise ValueError(f"chunk_bytes must be an int in 1..{MAX_CHUNK_SIZE}, got {chunk_bytes!r}")
    return chunk_bytes


def max_image_bytes(chunk_bytes: int = DEFAULT_CHUNK_SIZE) -> int:
    """Largest encoded image that fits 64 chunks with its CRC [B] (2558 B at 40-B chunks).

    Args:
        chunk_bytes: chunk size [B], 1..150.

    Raises:
        ValueError: ``chunk_bytes`` out of range.
    """
    return MAX_CHUNKS * check_chunk_bytes(chunk_bytes) - IMAGE_CRC_SIZE


class TransferEnd:
    """What both ends share: the chunk size and the transfer mode (they must agree).

    Raises:
        ValueError: ``chunk_bytes`` out of range.
    """

    def __init__(self, chunk_bytes: int, selective_repeat: bool) -> None:
        self._chunk_bytes = check_chunk_bytes(chunk_bytes)
        self._selective_repeat = bool(selective_repeat)

    @property
    def chunk_bytes(self) -> int:
        """Chunk size [B]."""
        return self._chunk_bytes

    @property
    def selective_repeat(self) -> bool:
        """True for selective repeat, False for paper-mode streaming."""
        return self._selective_repeat
