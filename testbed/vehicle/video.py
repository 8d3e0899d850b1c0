"""The vehicle's side of image feedback: capture on demand, code within the budget, chunk.

:class:`ImageSource` sits between the vehicle's camera and the replies. For each order the
vehicle answers, the node hands it the order (:meth:`ImageSource.on_order`: the image request in
the header, and the coder settings if the order is an ``ImageSettings``), then asks for the chunk
of this reply (:meth:`ImageSource.reply_chunk`). When the operator has acknowledged the image
being sent (or none is loaded yet), a new frame is captured, coded with
:func:`testbed.imaging.encode` within ``min(budget, 64·chunk − 2)`` bytes with the operator's
region of interest, and loaded into an :class:`~testbed.protocol.ImageSender`. As in the paper,
the vehicle captures only when the previous image is done: an image shows the scene when it
was taken, and its age on arrival is the transfer time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from testbed.imaging import encode
from testbed.protocol import (
    ImageSender,
    ImageSettings,
    OperatorMessage,
    OutgoingChunk,
    max_image_bytes,
)

__all__ = ["CodedImage", "ImageSource"]


@dataclass(frozen=True, slots=True)
class CodedImage:
    """An image the source captured and coded.

    Attributes:
        number: capture count, from 0.
        t_s: capture time [s] (simulation clock).
        pixels: (h, w) uint8 grey, as captured.
        encoded: the coded stream (CRC not included), at most the budget.
        settings: the coder settings it was coded with.
    """

    number: int
    t_s: float
    pixels: np.ndarray
    encoded: bytes
    settings: ImageSettings


Capture = Callable[[], "tuple[float, np.ndarray] | None"]
"""Returns (capture time [s], (h, w) uint8 grey pixels), or None if no frame can be had now."""


class ImageSource:
    """Captures, codes and chunks images for the replies (see the module docstring).

    Args:
        capture: the camera: (time [s], pixels) or None when it cannot capture now.
        width_px: camera image width [px] (the default settings' ROI is the whole image).
        height_px: camera image height [px].
        chunk_bytes: image bytes per reply [B], 1..150.
        selective_repeat: the transfer mode (both ends must agree).
        settings: the coder settings the vehicle is configured with, used until the operator's
            first ``ImageSettings`` order arrives (a deployment configures both ends alike, so
            a lost settings order does not change the first images); None = the whole budget
            and no region of interest.
        on_image: called with each new :class:`CodedImage` (recording).

    Attributes:
        settings: the coder settings for the next image (the operator's latest
            ``ImageSettings``; before any, the configured ones).
        sender: the chunking state machine.
    """

    def __init__(
        self,
        capture: Capture,
        *,
        width_px: int,
        height_px: int,
        chunk_bytes: int = 40,
        selective_repeat: bool = True,
        settings: ImageSettings | None = None,
        on_image: Callable[[CodedImage], None] | None = None,
    ) -> None:
        self._capture = capture
        self._on_image = on_image
        self.sender = ImageSender(chunk_bytes, selective_repeat=selective_repeat)
        self._limit = max_image_bytes(chunk_bytes)
        right, bottom = min(width_px - 1, 1023), min(height_px - 1, 1023)
        whole = ImageSettings(0, 0, right, bottom, 0, True, self._limit)
        self.settings = whole if settings is None else settings
        self.images = 0
        self.current: CodedImage | None = None

    def on_order(self, message: OperatorMessage) -> None:
        """Take an order the vehicle answers: its image request, and its settings if any."""
        if isinstance(message.order, ImageSettings):
            self.settings = message.order
        self.sender.on_request(
            message.image_seq_bit, message.cancel_image, message.first_missing_chunk
        )

    def reply_chunk(self) -> OutgoingChunk | None:
        """The image chunk for the reply being built (capturing a new image if one is due)."""
        if self.sender.wants_image:
            self._load_next()
        return self.sender.next_chunk()

    def _load_next(self) -> None:
        captured = self._capture()
        if captured is None:
            return
        t_s, pixels = captured
        settings = self.settings
        budget = min(settings.budget_bytes, self._limit)
        roi = (settings.x0, settings.y0, settings.x1, settings.y1)
        shift = settings.roi_shift
        encoded = encode(pixels, budget, roi if shift else None, shift)
        if not encoded:
            return
        self.sender.load(encoded)
        image = CodedImage(self.images, t_s, pixels, encoded, settings)
        self.images += 1
        self.current = image
        if self._on_image is not None:
            self._on_image(image)
