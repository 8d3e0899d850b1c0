"""What a run records of its images, and the ``images`` section of ``metrics.json``.

The vehicle node logs each image it captures (its number, capture time, the true pixels and the
encoded size) and which image each reply frame carried; the operator node logs each image it
completes (the frame that finished it and the decoded pixels) and its transfer counters. The
image number never travels: the operator's record is matched to the capture through the frame
id of the chunk that completed it (recording only, as for commands and odometry).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["CapturedImage", "ImageLog", "ReceivedImage", "image_metrics", "psnr_db"]


@dataclass(frozen=True, slots=True)
class CapturedImage:
    """An image the vehicle captured and coded.

    Attributes:
        number: capture count, from 0.
        t_s: capture time [s].
        pixels: (h, w) uint8 grey, as rendered.
        encoded_bytes: coded size within the budget [B] (without the 2-B image CRC).
    """

    number: int
    t_s: float
    pixels: np.ndarray
    encoded_bytes: int


@dataclass(frozen=True, slots=True)
class ReceivedImage:
    """An image the operator completed (all chunks in, image CRC checked).

    Attributes:
        number: the captured image's number (from the completing frame's id; -1 if unknown).
        t_s: completion time [s].
        pixels: (h, w) uint8 grey, decoded.
        encoded_bytes: the image's coded size [B] (CRC excluded).
    """

    number: int
    t_s: float
    pixels: np.ndarray
    encoded_bytes: int


@dataclass(slots=True)
class ImageLog:
    """Append-only image record of one run.

    Attributes:
        captured: image number → the captured image.
        reply_images: downlink frame id → number of the image whose chunk the reply carried.
        received: completed images in completion order.
        counters: transfer counters (``chunks_sent``, ``chunks_received``, ``crc_failures``,
            ``spoiled``, ``duplicates``, ``settings_sent``, ``settings_applied``).
    """

    captured: dict[int, CapturedImage] = field(default_factory=dict)
    reply_images: dict[int, int] = field(default_factory=dict)
    received: list[ReceivedImage] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)

    def count(self, key: str, n: int = 1) -> None:
        """Add ``n`` to counter ``key``."""
        self.counters[key] = self.counters.get(key, 0) + n


def psnr_db(reference: np.ndarray, image: np.ndarray) -> float:
    """Peak signal-to-noise ratio of ``image`` against ``reference`` [dB], 8-bit peak 255.

    Identical images give ``inf``; images of different shapes give NaN.
    """
    if reference.shape != image.shape:
        return math.nan
    error = reference.astype(np.float64) - image.astype(np.float64)
    mse = float(np.mean(error * error))
    return math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse)


def image_metrics(log: ImageLog, sim_s: float) -> dict[str, Any]:
    """The ``images`` section of ``metrics.json``.

    Keys: ``captured``, ``completed``, ``per_minute`` (completed per minute of simulated time),
    ``latency_s`` {``mean``, ``p95``, ``max``} from capture to completion, ``bytes_delivered``
    (coded bytes of the completed images), ``psnr_db`` {``mean``, ``min``} of each completed
    image against its capture (finite values; a lossless image counts as 99 dB), and the
    transfer counters.
    """
    latencies: list[float] = []
    psnrs: list[float] = []
    for image in log.received:
        source = log.captured.get(image.number)
        if source is None:
            continue
        latencies.append(image.t_s - source.t_s)
        psnrs.append(min(99.0, psnr_db(source.pixels, image.pixels)))
    nan = math.nan
    latency = np.asarray(latencies, dtype=float)
    quality = np.asarray([p for p in psnrs if math.isfinite(p)], dtype=float)
    return {
        "captured": len(log.captured),
        "completed": len(log.received),
        "per_minute": 60.0 * len(log.received) / sim_s if sim_s > 0 else nan,
        "latency_s": {
            "mean": float(latency.mean()) if latency.size else nan,
            "p95": float(np.percentile(latency, 95)) if latency.size else nan,
            "max": float(latency.max()) if latency.size else nan,
        },
        "bytes_delivered": sum(image.encoded_bytes for image in log.received),
        "psnr_db": {
            "mean": float(quality.mean()) if quality.size else nan,
            "min": float(quality.min()) if quality.size else nan,
        },
        **{key: log.counters[key] for key in sorted(log.counters)},
    }
