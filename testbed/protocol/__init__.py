"""Sans-IO core of the narrow-band teleoperation protocol (Centelles et al.; REFERENCE §1).

Three layers, none of which does I/O, reads a clock or draws random numbers:

* :mod:`~testbed.protocol.crc` — CRC-16/XMODEM.
* :mod:`~testbed.protocol.framing` — payload ⇄ frame (preamble · length · payload · CRC) and the
  :class:`FrameDecoder` that recovers frames from any byte stream.
* :mod:`~testbed.protocol.orders` and :mod:`~testbed.protocol.messages` — the operator and
  vehicle payload layouts.

On top of the messages, the image transfer (chunking, image CRC, selective repeat): its rules and
chunk layout in :mod:`~testbed.protocol.image_transfer`, its two state machines in
:mod:`~testbed.protocol.image_sender` (:class:`ImageSender`, the vehicle's) and
:mod:`~testbed.protocol.image_assembler` (:class:`ImageAssembler`, the operator's).

Sending is ``encode_frame(message.encode())``; receiving is ``decoder.feed(data)`` followed by
``decode_vehicle_message(frame.payload)`` (or ``decode_operator_message``) for each
:class:`Frame`. Remote garbage becomes :class:`CorruptFrame` / :class:`MalformedPayload` values;
only local misuse raises (:class:`ValueError`).

Depends on the standard library only.
"""

from __future__ import annotations

from .crc import CRC16_CHECK_VALUE, crc16
from .framing import (
    DEFAULT_PREAMBLE_LEN,
    MAX_PAYLOAD,
    PREAMBLE_LENGTHS,
    START_BYTE,
    CorruptFrame,
    CorruptReason,
    Frame,
    FrameDecoder,
    FrameEvent,
    encode_frame,
    frame_overhead,
)
from .image_assembler import AssemblyCounters, AssemblyEvent, ImageAssembler
from .image_sender import ImageSender, OutgoingChunk, SenderCounters
from .image_transfer import IMAGE_CRC_SIZE, MAX_CHUNKS, max_image_bytes
from .messages import (
    DEFAULT_CHUNK_SIZE,
    MAX_CHUNK_INDEX,
    MAX_CHUNK_SIZE,
    OPERATOR_HEADER_SIZE,
    STATE_SIZE,
    VEHICLE_HEADER_SIZE,
    MalformedPayload,
    OperatorMessage,
    VehicleMessage,
    VehicleState,
    decode_operator_message,
    decode_vehicle_message,
    order_type_of,
)
from .orders import (
    AXIS_SCALE,
    ORDER_TYPES,
    DisableKeepHeading,
    EndEffectorGoTo,
    GoTo,
    HoldChannel,
    ImageSettings,
    KeepHeading,
    Mode,
    Move,
    NoOrder,
    Order,
    OrderIncoming,
)

__all__ = [
    "AXIS_SCALE",
    "CRC16_CHECK_VALUE",
    "DEFAULT_CHUNK_SIZE",
    "DEFAULT_PREAMBLE_LEN",
    "IMAGE_CRC_SIZE",
    "MAX_CHUNKS",
    "MAX_CHUNK_INDEX",
    "MAX_CHUNK_SIZE",
    "MAX_PAYLOAD",
    "OPERATOR_HEADER_SIZE",
    "ORDER_TYPES",
    "PREAMBLE_LENGTHS",
    "START_BYTE",
    "STATE_SIZE",
    "VEHICLE_HEADER_SIZE",
    "AssemblyCounters",
    "AssemblyEvent",
    "CorruptFrame",
    "CorruptReason",
    "DisableKeepHeading",
    "EndEffectorGoTo",
    "Frame",
    "FrameDecoder",
    "FrameEvent",
    "GoTo",
    "HoldChannel",
    "ImageAssembler",
    "ImageSender",
    "ImageSettings",
    "KeepHeading",
    "MalformedPayload",
    "Mode",
    "Move",
    "NoOrder",
    "OperatorMessage",
    "Order",
    "OrderIncoming",
    "OutgoingChunk",
    "SenderCounters",
    "VehicleMessage",
    "VehicleState",
    "crc16",
    "decode_operator_message",
    "decode_vehicle_message",
    "encode_frame",
    "frame_overhead",
    "max_image_bytes",
    "order_type_of",
]
