"""The vehicle's end of the image transfer: :class:`ImageSender` chunks one image at a time.

It takes an encoded image, appends its CRC-16/XMODEM and cuts it into chunks
(:mod:`~testbed.protocol.image_transfer` states the protocol's rules, the chunk layout and the
cancel), then serves the chunk each operator order asks for (selective repeat) or streams them in
order (paper mode). The node copies the order's image fields into :meth:`ImageSender.on_request`
and the fields of :class:`OutgoingChunk` into the reply's header. The operator's end is
:mod:`~testbed.protocol.image_assembler`.

Standard library only; no I/O, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

from .crc import crc16
from .image_transfer import IMAGE_CRC_SIZE, TransferEnd, max_image_bytes
from .messages import DEFAULT_CHUNK_SIZE

__all__ = ["ImageSender", "OutgoingChunk", "SenderCounters"]


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


class ImageSender(TransferEnd):
    """Vehicle side: one image at a time, chunk by chunk (the rules: :mod:`.image_transfer`).

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
