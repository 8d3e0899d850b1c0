"""Image transfer over the narrow link: chunking, image CRC, selective repeat (REFERENCE §1.5).

Two sans-IO state machines, one per end. They never see frames, clocks or random numbers: the
nodes copy header fields in and out of :class:`~testbed.protocol.messages.OperatorMessage`
(byte 0: image sequence bit expected · cancel image · first missing chunk) and
:class:`~testbed.protocol.messages.VehicleMessage` (byte 0 first/last chunk flags; byte 13:
image sequence bit · cancel · chunk index; then the chunk).

* :class:`ImageSender`, on the vehicle, holds at most one image: the encoded bytes followed by
  their CRC-16/XMODEM (big-endian), cut into chunks of ``chunk_bytes`` (40 B by default, 1..150),
  at most 64 of them because the index has 6 bits (:func:`max_image_bytes`).
* :class:`ImageAssembler`, on the operator, asks for the chunks it misses, checks the image CRC
  and hands out the image; :meth:`ImageAssembler.prefix` gives the contiguous bytes received so
  far for progressive decoding (less one byte until the length is known, so that it is always
  a true prefix of the image, never a CRC byte).

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
  it and :attr:`ImageSender.wants_image` turns True. A restarted or confused operator therefore
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
* Garbled remote data — any flags, any index, any bytes — becomes an :class:`AssemblyEvent` and
  a counter, never an exception; the image CRC is the last line against a frame that passed its
  own CRC with wrong content.

**Paper mode** (``selective_repeat=False``; both ends must agree): the vehicle streams chunks
0, 1, 2, … one per reply whatever the operator asks, and after the last chunk wants the next
image, which takes the other bit. The operator completes an image only when it receives every
chunk in order; a gap spoils the image (counted once per image it saw part of; an image lost
whole is not seen and not counted; a tail lost is noticed when the next image shows up). This is
the 2017–2019 behaviour, where one lost packet lost the image.

Standard library only; no I/O, no clock.

Size: the sender and the assembler are the two ends of one protocol (chunk layout, image CRC, the
alternating bit, both modes); the module stays whole, over 500 lines, so each rule's two ends
read together.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .crc import crc16
from .messages import DEFAULT_CHUNK_SIZE, MAX_CHUNK_INDEX, MAX_CHUNK_SIZE

__all__ = [
    "IMAGE_CRC_SIZE",
    "MAX_CHUNKS",
    "AssemblyCounters",
    "AssemblyEvent",
    "ImageAssembler",
    "ImageSender",
    "OutgoingChunk",
    "SenderCounters",
    "max_image_bytes",
]

IMAGE_CRC_SIZE = 2
"""CRC-16/XMODEM appended big-endian to every encoded image [B]."""

MAX_CHUNKS = MAX_CHUNK_INDEX + 1
"""Chunks per image: the index has 6 bits."""


def _check_chunk_bytes(chunk_bytes: int) -> int:
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
    return MAX_CHUNKS * _check_chunk_bytes(chunk_bytes) - IMAGE_CRC_SIZE


@dataclass(frozen=True, slots=True)
class OutgoingChunk:
    """Image fields of the reply being built: header byte 0 flags, byte 13 and the chunk.

    Attributes:
        first: header byte 0 bit 7, the chunk starts an image (index 0).
        last: header byte 0 bit 6, the chunk ends the image.
        image_seq_bit: byte 13 bit 7, the bit of the image the chunk belongs to.
        cancel: byte 13 bit 6, a cancel notice (no data).
        index: byte 13 bits 5..0, the chunk index, 0..63.
        data: the chunk, 1..``chunk_bytes`` bytes (empty in a cancel notice).
    """

    first: bool
    last: bool
    image_seq_bit: bool
    cancel: bool
    index: int
    data: bytes


@dataclass(frozen=True, slots=True)
class SenderCounters:
    """What an :class:`ImageSender` has done since it was made.

    Attributes:
        images_loaded: images passed to :meth:`ImageSender.load`.
        images_done: images acknowledged by the operator (selective repeat) or streamed to their
            last chunk (paper mode).
        images_cancelled: images dropped on the operator's cancel.
        chunks_sent: replies that carried a chunk.
        cancels_sent: cancel notices sent.
        requests_beyond_end: replies to a request past the last chunk (the last chunk was sent).
    """

    images_loaded: int = 0
    images_done: int = 0
    images_cancelled: int = 0
    chunks_sent: int = 0
    cancels_sent: int = 0
    requests_beyond_end: int = 0


class _TransferEnd:
    """What both ends share: the chunk size and the transfer mode (they must agree)."""

    def __init__(self, chunk_bytes: int, selective_repeat: bool) -> None:
        self._chunk_bytes = _check_chunk_bytes(chunk_bytes)
        self._selective_repeat = bool(selective_repeat)

    @property
    def chunk_bytes(self) -> int:
        """Chunk size [B]."""
        return self._chunk_bytes

    @property
    def selective_repeat(self) -> bool:
        """True for selective repeat, False for paper-mode streaming."""
        return self._selective_repeat


class ImageSender(_TransferEnd):
    """Vehicle side: one image at a time, chunk by chunk (see the module docstring).

    Per reply cycle the node calls :meth:`on_request` with the order's header, then loads a new
    image if :attr:`wants_image`, then builds the reply from :meth:`next_chunk`.

    Args:
        chunk_bytes: chunk size [B], 1..150.
        selective_repeat: serve the chunk the operator asks for (True) or stream chunks in order
            whatever it asks (False, paper mode).

    Raises:
        ValueError: ``chunk_bytes`` out of range.
    """

    def __init__(
        self, chunk_bytes: int = DEFAULT_CHUNK_SIZE, *, selective_repeat: bool = True
    ) -> None:
        super().__init__(chunk_bytes, selective_repeat)
        self._chunks: tuple[bytes, ...] = ()
        self._image_bit = False
        self._next_bit = False
        self._index = 0  # selective repeat: chunk asked for; paper mode: stream position
        self._cancel_notice: bool | None = None
        self._tally = dict.fromkeys(SenderCounters.__dataclass_fields__, 0)

    @property
    def wants_image(self) -> bool:
        """No image is held (none yet, acknowledged, streamed out or cancelled): load one."""
        return not self._chunks

    @property
    def image_seq_bit(self) -> bool | None:
        """Sequence bit of the image held, None when there is none."""
        return self._image_bit if self._chunks else None

    @property
    def chunk_count(self) -> int:
        """Chunks of the image held, 0 when there is none."""
        return len(self._chunks)

    @property
    def counters(self) -> SenderCounters:
        """A snapshot of the counters."""
        return SenderCounters(**self._tally)

    def load(self, encoded: bytes) -> None:
        """Take a new encoded image (already truncated to the byte budget) and chunk it.

        The image takes the sequence bit the operator last asked for (selective repeat) or the
        bit after the previous image's (paper mode); False for the first.

        Args:
            encoded: the encoded image, at most :func:`max_image_bytes` bytes.

        Raises:
            RuntimeError: an image is still held (:attr:`wants_image` is False).
            ValueError: the image and its CRC do not fit 64 chunks.
        """
        if self._chunks:
            raise RuntimeError("load() while an image is still being sent (wants_image is False)")
        data = bytes(encoded)
        limit = max_image_bytes(self._chunk_bytes)
        if len(data) > limit:
            raise ValueError(
                f"image is {len(data)} B; at {self._chunk_bytes}-B chunks at most {limit} B fit"
            )
        framed = data + crc16(data).to_bytes(IMAGE_CRC_SIZE, "big")
        size = self._chunk_bytes
        self._chunks = tuple(framed[i : i + size] for i in range(0, len(framed), size))
        self._image_bit = self._next_bit
        if not self._selective_repeat:
            self._next_bit = not self._image_bit
            self._index = 0
        self._tally["images_loaded"] += 1

    def on_request(self, image_seq_bit: bool, cancel: bool, first_missing: int) -> None:
        """Take the image fields of an operator order's header (remote data: never raises).

        Args:
            image_seq_bit: the bit of the image the operator expects.
            cancel: the operator abandons that image.
            first_missing: the first chunk index it misses (0..63 on the wire).
        """
        bit = bool(image_seq_bit)
        if self._selective_repeat:
            if self._chunks and bit != self._image_bit:
                self._chunks = ()
                self._tally["images_done"] += 1
            self._next_bit = bit
            self._index = max(0, first_missing)
        if cancel:
            if self._chunks:
                self._chunks = ()
                self._tally["images_cancelled"] += 1
            self._cancel_notice = bit
        else:
            self._cancel_notice = None

    def next_chunk(self) -> OutgoingChunk | None:
        """The image fields of the reply being built now.

        Returns:
            A cancel notice if the last request cancelled, else the chunk to send, or None when
            no image is held (the reply then carries no chunk).
        """
        if self._cancel_notice is not None:
            bit, self._cancel_notice = self._cancel_notice, None
            self._tally["cancels_sent"] += 1
            return OutgoingChunk(False, False, bit, True, 0, b"")
        if not self._chunks:
            return None
        last = len(self._chunks) - 1
        index = self._index
        if index > last:
            self._tally["requests_beyond_end"] += 1
            index = last
        chunk = OutgoingChunk(
            index == 0, index == last, self._image_bit, False, index, self._chunks[index]
        )
        self._tally["chunks_sent"] += 1
        if self._selective_repeat:
            self._index = (index + 1) % len(self._chunks)
        elif index == last:
            self._chunks = ()
            self._tally["images_done"] += 1
        else:
            self._index = index + 1
        return chunk


class AssemblyEvent(enum.Enum):
    """What :meth:`ImageAssembler.on_chunk` made of a reply's image fields."""

    IGNORED = "ignored"
    """No image data, another sequence bit, or a data chunk while cancelling."""
    DUPLICATE = "duplicate"
    """A chunk already held, same bytes."""
    PROGRESS = "progress"
    """A new chunk kept; the image is not complete yet."""
    COMPLETED = "completed"
    """The image is complete and its CRC checks: :attr:`ImageAssembler.last_image`."""
    CRC_FAILED = "crc_failed"
    """Every chunk arrived but the image CRC fails: dropped, restarting from chunk 0."""
    SPOILED = "spoiled"
    """Paper mode: a chunk was missed, the image is lost."""
    CANCELLED = "cancelled"
    """A cancel notice for the expected image: partial chunks dropped."""
    INCONSISTENT = "inconsistent"
    """A malformed chunk (dropped) or one contradicting those held (image restarted from it)."""


@dataclass(frozen=True, slots=True)
class AssemblyCounters:
    """What an :class:`ImageAssembler` has seen since it was made.

    Attributes:
        images_completed: images whose CRC checked.
        bytes_completed: encoded bytes in those images (CRC excluded) [B].
        crc_failures: complete images whose CRC failed.
        spoiled: paper mode: images lost to a missed chunk.
        duplicates: chunks received again with the same bytes.
        inconsistent: malformed or contradicting chunks.
        cancelled: cancel notices honoured.
        chunks_received: calls to :meth:`ImageAssembler.on_chunk`.
    """

    images_completed: int = 0
    bytes_completed: int = 0
    crc_failures: int = 0
    spoiled: int = 0
    duplicates: int = 0
    inconsistent: int = 0
    cancelled: int = 0
    chunks_received: int = 0


class _Stream(enum.Enum):
    """Paper mode: the state of the image being streamed."""

    IDLE = enum.auto()
    ASSEMBLING = enum.auto()
    SPOILED = enum.auto()


class ImageAssembler(_TransferEnd):
    """Operator side: gathers chunks, checks the image CRC (see the module docstring).

    Per cycle the node puts :meth:`request` in the next order's header and passes each reply's
    image fields to :meth:`on_chunk`.

    Args:
        chunk_bytes: chunk size the vehicle uses [B], 1..150.
        selective_repeat: keep chunks in any order and ask for the first missing (True) or
            accept only an in-order stream (False, paper mode).

    Raises:
        ValueError: ``chunk_bytes`` out of range.
    """

    def __init__(
        self, chunk_bytes: int = DEFAULT_CHUNK_SIZE, *, selective_repeat: bool = True
    ) -> None:
        super().__init__(chunk_bytes, selective_repeat)
        self._expected = False  # paper mode: the bit of the image being streamed
        self._parts: dict[int, bytes] = {}
        self._last_index: int | None = None
        self._cancelling = False
        self._stream = _Stream.IDLE
        self._last_image: bytes | None = None
        self._tally = dict.fromkeys(AssemblyCounters.__dataclass_fields__, 0)

    @property
    def cancelling(self) -> bool:
        """A cancel is under way (requests carry *cancel* until the vehicle's notice)."""
        return self._cancelling

    @property
    def last_image(self) -> bytes | None:
        """The most recent completed image, CRC removed; None before the first."""
        return self._last_image

    @property
    def counters(self) -> AssemblyCounters:
        """A snapshot of the counters."""
        return AssemblyCounters(**self._tally)

    def request(self) -> tuple[bool, bool, int]:
        """Image fields for the next order's header.

        Returns:
            (image sequence bit expected, cancel image, index of the first missing chunk 0..63).
        """
        if self._cancelling:
            return self._expected, True, 0
        index = 0
        while index in self._parts:
            index += 1
        return self._expected, False, min(index, MAX_CHUNK_INDEX)

    def cancel(self) -> None:
        """Abandon the image being assembled (e.g. new image settings); drops its chunks."""
        self._drop_partial()
        self._cancelling = True

    def prefix(self) -> bytes:
        """The longest run of bytes from chunk 0 surely image data, for progressive decoding.

        It is always a prefix of the encoded image (CRC excluded). Until the last chunk is held
        the image length is unknown and the run's final byte could be the first CRC byte (the CRC
        may straddle two chunks), so that one byte is held back; once the last chunk is held, a
        run that reached the CRC would have completed the image, so nothing is held back.
        """
        run: list[bytes] = []
        while len(run) in self._parts:
            run.append(self._parts[len(run)])
        data = b"".join(run)
        return data if self._last_index is not None else data[:-1]

    def on_chunk(
        self, first: bool, last: bool, image_seq_bit: bool, cancel: bool, index: int, data: bytes
    ) -> AssemblyEvent:
        """Take the image fields of a reply (remote data: never raises).

        Args:
            first: header byte 0 bit 7, first chunk of an image.
            last: header byte 0 bit 6, last chunk of the image.
            image_seq_bit: byte 13 bit 7.
            cancel: byte 13 bit 6, a cancel notice.
            index: byte 13 bits 5..0, the chunk index.
            data: the chunk bytes (empty when the reply carries none).

        Returns:
            What became of it.
        """
        self._tally["chunks_received"] += 1
        bit = bool(image_seq_bit)
        if cancel:
            if self._cancelling or bit == self._expected:
                self._drop_partial()
                self._cancelling = False
                self._tally["cancelled"] += 1
                return AssemblyEvent.CANCELLED
            return AssemblyEvent.IGNORED
        if self._cancelling or not data:
            return AssemblyEvent.IGNORED
        chunk = bytes(data)
        if not self._well_formed(bool(first), bool(last), index, len(chunk)):
            self._tally["inconsistent"] += 1
            return AssemblyEvent.INCONSISTENT
        if self._selective_repeat:
            return self._keep(bool(last), bit, index, chunk)
        return self._follow(bool(last), bit, index, chunk)

    def _well_formed(self, first: bool, last: bool, index: int, size: int) -> bool:
        """Whether a chunk can belong to some image (index, flags and size agree)."""
        if not isinstance(index, int) or not 0 <= index <= MAX_CHUNK_INDEX:
            return False
        if first != (index == 0):
            return False
        if last:
            return size <= self._chunk_bytes and index * self._chunk_bytes + size >= IMAGE_CRC_SIZE
        return size == self._chunk_bytes and index < MAX_CHUNK_INDEX

    def _keep(self, last: bool, bit: bool, index: int, chunk: bytes) -> AssemblyEvent:
        """Selective repeat: store a well-formed chunk of any index."""
        if bit != self._expected:
            return AssemblyEvent.IGNORED
        held = self._parts.get(index)
        known_last = self._last_index
        if known_last is not None:
            contradicts = index > known_last or (index == known_last) != last
        else:
            contradicts = last and any(i > index for i in self._parts)
        if contradicts or (held is not None and held != chunk):
            self._drop_partial()
            self._tally["inconsistent"] += 1
            event = AssemblyEvent.INCONSISTENT
        elif held is not None and (not last or known_last == index):
            self._tally["duplicates"] += 1
            return AssemblyEvent.DUPLICATE
        else:
            event = AssemblyEvent.PROGRESS
        self._parts[index] = chunk
        if last:
            self._last_index = index
        if self._last_index is not None and len(self._parts) == self._last_index + 1:
            return self._finish(self._last_index, toggle=True)
        return event

    def _follow(self, last: bool, bit: bool, index: int, chunk: bytes) -> AssemblyEvent:
        """Paper mode: accept only the next chunk of the image being streamed."""
        assembling = self._stream is _Stream.ASSEMBLING
        if index == 0:
            if assembling:
                self._tally["spoiled"] += 1
            self._drop_partial()
            self._expected = bit
            self._stream = _Stream.ASSEMBLING
        elif not (assembling and bit == self._expected and index == len(self._parts)):
            if self._stream is _Stream.SPOILED and bit == self._expected:
                return AssemblyEvent.SPOILED  # more of an image already counted as lost
            # The image being assembled missed a chunk, and/or a new image lost its head.
            spoiled_now = int(assembling) + int(not (assembling and bit == self._expected))
            self._tally["spoiled"] += spoiled_now
            self._drop_partial()
            self._expected = bit
            self._stream = _Stream.SPOILED
            return AssemblyEvent.SPOILED
        self._parts[index] = chunk
        if last:
            return self._finish(index, toggle=False)
        return AssemblyEvent.PROGRESS

    def _finish(self, last_index: int, *, toggle: bool) -> AssemblyEvent:
        """Chunks 0..``last_index`` are in: check the image CRC, then start afresh either way."""
        whole = b"".join(self._parts[i] for i in range(last_index + 1))
        self._drop_partial()
        if crc16(whole) != 0:
            self._tally["crc_failures"] += 1
            return AssemblyEvent.CRC_FAILED
        image = whole[:-IMAGE_CRC_SIZE]
        self._last_image = image
        self._tally["images_completed"] += 1
        self._tally["bytes_completed"] += len(image)
        if toggle:
            self._expected = not self._expected
        return AssemblyEvent.COMPLETED

    def _drop_partial(self) -> None:
        self._parts.clear()
        self._last_index = None
        self._stream = _Stream.IDLE
