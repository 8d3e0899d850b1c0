"""The vehicle's image source: capture on demand, the operator's settings, the budget cap."""

from __future__ import annotations

import numpy as np

from testbed.imaging import decode, encode
from testbed.imaging.scenes import pool_scene
from testbed.protocol import ImageSettings, Move, OperatorMessage, max_image_bytes
from testbed.vehicle.video import CodedImage, ImageSource

IMAGE = pool_scene(160, 120, np.random.default_rng(2))


def order(
    seq_bit: bool, first_missing: int, settings: ImageSettings | None = None
) -> OperatorMessage:
    body = settings if settings is not None else Move(0, 0, 0, 0)
    return OperatorMessage(seq_bit, False, first_missing, True, False, body)


def test_captures_only_when_an_image_is_due_and_codes_with_the_latest_settings() -> None:
    calls: list[float] = []
    made: list[CodedImage] = []

    def capture() -> tuple[float, np.ndarray]:
        calls.append(float(len(calls)))
        return calls[-1], IMAGE

    source = ImageSource(capture, width_px=160, height_px=120, on_image=made.append)
    settings = ImageSettings(40, 30, 119, 89, 4, True, 400)
    source.on_order(order(False, 0, settings))
    chunk = source.reply_chunk()
    assert chunk is not None and chunk.first and chunk.index == 0
    assert len(calls) == 1 and made[0].settings == settings
    assert made[0].encoded == encode(IMAGE, 400, (40, 30, 119, 89), 4)
    for index in range(1, 5):  # the rest of the same image: no new capture
        source.on_order(order(False, index))
        source.reply_chunk()
    assert len(calls) == 1
    source.on_order(order(True, 0))  # the operator completed it: the next one is captured
    source.reply_chunk()
    assert len(calls) == 2 and made[1].number == 1


def test_budget_beyond_64_chunks_is_capped_and_no_roi_without_shift() -> None:
    source = ImageSource(lambda: (0.0, IMAGE), width_px=160, height_px=120, chunk_bytes=10)
    source.on_order(order(False, 0, ImageSettings(0, 0, 10, 10, 0, True, 5000)))
    source.reply_chunk()
    assert source.current is not None
    assert source.current.encoded == encode(IMAGE, max_image_bytes(10))  # 638 B, no ROI
    np.testing.assert_array_equal(decode(source.current.encoded), decode(encode(IMAGE, 638)))


def test_a_camera_that_cannot_capture_yet_sends_no_chunk() -> None:
    source = ImageSource(lambda: None, width_px=160, height_px=120)
    source.on_order(order(False, 0))
    assert source.reply_chunk() is None
    assert source.sender.wants_image
