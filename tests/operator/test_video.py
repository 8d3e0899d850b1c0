"""The operator's image console: progressive view, completion, settings resent until acked."""

from __future__ import annotations

import itertools

import numpy as np

from testbed.imaging import decode, encode
from testbed.imaging.scenes import pool_scene
from testbed.operator.video import ImageConsole
from testbed.protocol import (
    AssemblyEvent,
    ImageSender,
    ImageSettings,
    Mode,
    VehicleMessage,
    VehicleState,
)

STATE = VehicleState(True, False, False, False, True, Mode.DEPTH_HOLD, 0, 0, 0, 0, 0, 0)


def reply(chunk: object | None, ack: bool = False) -> VehicleMessage:
    state = VehicleState(True, ack, False, False, True, Mode.DEPTH_HOLD, 0, 0, 0, 0, 0, 0)
    if chunk is None:
        return VehicleMessage(False, False, state, False, False, 0, b"")
    return VehicleMessage(
        chunk.first, chunk.last, state, chunk.image_seq_bit, chunk.cancel, chunk.index, chunk.data
    )


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(float) - b.astype(float)) ** 2))
    return 10.0 * np.log10(255.0**2 / mse)


def test_view_sharpens_chunk_by_chunk_and_the_completed_image_is_the_coders() -> None:
    image = pool_scene(160, 120, np.random.default_rng(1))
    encoded = encode(image, 600)
    sender = ImageSender(40)
    console = ImageConsole(chunk_bytes=40)
    assert console.view is None
    quality: list[float] = []
    events = []
    while True:
        sender.on_request(*console.request())
        if sender.wants_image:
            sender.load(encoded)
        chunk = sender.next_chunk()
        event = console.on_reply(reply(chunk))
        events.append(event)
        if event is AssemblyEvent.COMPLETED:
            break
        view = console.view
        assert view is not None and view.shape == image.shape
        # the view is exactly the coder's picture of the bytes received so far
        np.testing.assert_array_equal(view, decode(console.assembler.prefix()))
        quality.append(psnr(image, view))
    assert events.count(AssemblyEvent.PROGRESS) == len(events) - 1 == 15  # 602 B in 16 chunks
    assert all(b >= a - 1e-9 for a, b in itertools.pairwise(quality))
    assert quality[-1] > quality[0] + 5.0
    assert console.completed == encoded
    np.testing.assert_array_equal(console.completed_view, decode(encoded))
    np.testing.assert_array_equal(console.view, decode(encoded))  # nothing of the next yet


def test_settings_are_resent_until_a_reply_acknowledges_them() -> None:
    first = ImageSettings(0, 0, 0, 0, 0, True, 1200)
    later = ImageSettings(10, 10, 50, 50, 4, True, 600)
    console = ImageConsole(schedule=[(0.0, first), (30.0, later)])
    assert console.settings_due(0.0) == first
    console.settings_sent_with(True)
    console.order_sent()  # lost: no reply before the next order
    assert console.settings_due(0.6) == first
    console.settings_sent_with(False)
    console.on_reply(reply(None, ack=True))  # answers an older order: not an ack
    assert console.settings_due(1.2) == first
    console.settings_sent_with(True)
    console.on_reply(reply(None, ack=True))
    assert console.settings_due(1.8) is None
    assert (console.settings_sent, console.settings_acknowledged) == (3, 1)
    assert console.settings_due(29.9) is None
    assert console.settings_due(30.0) == later


def test_an_image_larger_than_the_console_allows_decodes_to_nothing() -> None:
    image = pool_scene(160, 120, np.random.default_rng(1))
    encoded = encode(image, 200)
    for max_pixels, shape in ((160 * 120, (120, 160)), (160 * 120 - 1, (0, 0))):
        sender = ImageSender(40)
        console = ImageConsole(chunk_bytes=40, max_pixels=max_pixels)
        event = None
        while event is not AssemblyEvent.COMPLETED:
            sender.on_request(*console.request())
            if sender.wants_image:
                sender.load(encoded)
            event = console.on_reply(reply(sender.next_chunk()))
        assert console.completed == encoded  # the bytes arrive either way
        assert console.completed_view is not None and console.completed_view.shape == shape
