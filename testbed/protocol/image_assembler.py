"""The operator's end of the image transfer: :class:`ImageAssembler` gathers one image's chunks.

It asks for the first chunk it misses (selective repeat) or follows an in-order stream (paper
mode), checks the image CRC and hands out the image; :meth:`ImageAssembler.prefix` gives the
bytes surely received so far for progressive decoding. The rules it follows (the alternating
bit, malformed and contradicting chunks, the cancel) are stated in
:mod:`~testbed.protocol.image_transfer`; the vehicle's end is
:mod:`~testbed.protocol.image_sender`. Remote data becomes an :class:`AssemblyEvent` and a
counter, never an exception.

Standard library only; no I/O, no clock.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .crc import crc16
from .image_transfer import IMAGE_CRC_SIZE, TransferEnd
from .messages import DEFAULT_CHUNK_SIZE, MAX_CHUNK_INDEX

__all__ = ["AssemblyCounters", "AssemblyEvent", "ImageAssembler"]


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


class ImageAssembler(TransferEnd):
    """Operator side: gathers chunks, checks the image CRC (the rules: :mod:`.image_transfer`).

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
