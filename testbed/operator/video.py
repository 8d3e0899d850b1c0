"""The operator's side of image feedback: ask for chunks, show what arrived, send coder settings.

:class:`ImageConsole` wraps an :class:`~testbed.protocol.ImageAssembler`: its request goes in
every order's header, each reply's image fields go back into it, and the console keeps
:attr:`ImageConsole.view`, the best picture the bytes so far allow — the partial image decoded
progressively as chunks arrive, then the whole image once its CRC checks (a partial image is
shown, never thrown away). It also holds the operator's coder settings: the scenario's at the
start and later changes at their times, each sent as an ``ImageSettings`` order and sent again
until a reply acknowledges it (the reply echoes the order sequence bit of the order it answers).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from testbed.imaging import MAX_PIXELS, decode
from testbed.protocol import AssemblyEvent, ImageAssembler, ImageSettings, VehicleMessage

__all__ = ["ImageConsole"]


class ImageConsole:
    """Chunk requests, progressive view and coder settings of the operator.

    Args:
        chunk_bytes: image bytes per reply [B], as the vehicle uses.
        selective_repeat: the transfer mode (both ends must agree).
        schedule: (time [s], settings) to send, in time order; the first is usually at 0.
        max_pixels: the largest image (width × height) it will decode — the camera's size when
            known; a stream whose header claims more decodes to nothing
            (:func:`testbed.imaging.decode`), so garbled headers cost no work.

    Attributes:
        chunks_received: replies that carried image data.
        completed: the latest completed image's stream (CRC removed), None before any.
        completed_view: the latest completed image, decoded; None before any.
        assembler: the chunk state machine.
    """

    def __init__(
        self,
        *,
        chunk_bytes: int = 40,
        selective_repeat: bool = True,
        schedule: Sequence[tuple[float, ImageSettings]] = (),
        max_pixels: int = MAX_PIXELS,
    ) -> None:
        self._max_pixels = max_pixels
        self.assembler = ImageAssembler(chunk_bytes, selective_repeat=selective_repeat)
        self._schedule = list(schedule)
        self._pending: ImageSettings | None = None
        self._sent_with_bit: bool | None = None
        self.completed: bytes | None = None
        self.completed_view: np.ndarray | None = None
        self.settings_sent = 0
        self.settings_acknowledged = 0
        self.chunks_received = 0
        self._partial: tuple[int, np.ndarray] | None = None

    def request(self) -> tuple[bool, bool, int]:
        """Image fields for the next order's header (see ``ImageAssembler.request``)."""
        return self.assembler.request()

    def settings_due(self, now_s: float) -> ImageSettings | None:
        """Settings to send as this gap's order: the newest one due and not yet acknowledged."""
        while self._schedule and self._schedule[0][0] <= now_s:
            self._pending = self._schedule.pop(0)[1]
            self._sent_with_bit = None
        return self._pending

    def settings_sent_with(self, order_seq_bit: bool) -> None:
        """The pending settings went out in an order with this sequence bit."""
        self._sent_with_bit = order_seq_bit
        self.settings_sent += 1

    def order_sent(self) -> None:
        """Another order went out: a later reply no longer acknowledges the settings."""
        self._sent_with_bit = None

    def on_reply(self, message: VehicleMessage) -> AssemblyEvent:
        """Take a reply: its order acknowledgement and its image chunk.

        Returns:
            What became of the chunk.
        """
        if (
            self._pending is not None
            and self._sent_with_bit is not None
            and message.state.order_ack_bit == self._sent_with_bit
        ):
            self._pending = self._sent_with_bit = None
            self.settings_acknowledged += 1
        self.chunks_received += bool(message.chunk)
        event = self.assembler.on_chunk(
            message.first_chunk,
            message.last_chunk,
            message.image_seq_bit,
            message.cancel_image,
            message.chunk_index,
            message.chunk,
        )
        if event is AssemblyEvent.COMPLETED:
            self.completed = self.assembler.last_image
            if self.completed is not None:
                self.completed_view = decode(self.completed, max_pixels=self._max_pixels)
        return event

    @property
    def view(self) -> np.ndarray | None:
        """(h, w) uint8 grey: the newest picture — the image being assembled, decoded from the
        bytes received so far (it sharpens as chunks arrive), or, until its header is in, the
        last completed image; None before any. Decoded when read and cached, so a batch run
        that never looks pays nothing.
        """
        prefix = self.assembler.prefix()
        if not prefix:
            return self.completed_view
        if self._partial is None or self._partial[0] != len(prefix):
            self._partial = (len(prefix), decode(prefix, max_pixels=self._max_pixels))
        picture = self._partial[1]
        return picture if picture.size else self.completed_view
