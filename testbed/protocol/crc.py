"""CRC-16/XMODEM, the frame check sequence of the teleoperation protocol.

Parameters (REFERENCE §1.1, dccomms ``src/Checksum.cpp``): polynomial 0x1021, MSB first, initial
value 0x0000, no input or output reflection, no final XOR; check value ``crc16(b"123456789") ==
0x31C3``. It is *not* CRC-16/CCITT-FALSE (init 0xFFFF, check 0x29B1) nor KERMIT (reflected).

The frame check sequence is appended big-endian. Because the CRC has no final XOR, the CRC over
``data + fcs`` is zero exactly when ``fcs == crc16(data)``, which is how the frame decoder checks
a frame in one pass.

The C implementation in :func:`binascii.crc_hqx` computes exactly this CRC. This module holds no
state and does no I/O.
"""

from __future__ import annotations

import binascii

__all__ = ["CRC16_CHECK_VALUE", "crc16"]

CRC16_CHECK_VALUE = 0x31C3
"""CRC-16/XMODEM of the ASCII string ``"123456789"`` (the catalogue check value)."""


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16/XMODEM of ``data``.

    Args:
        data: the bytes to check.
        crc: running CRC from a previous call, so that ``crc16(b, crc16(a)) == crc16(a + b)``;
            0 (the XMODEM initial value) to start.

    Returns:
        The 16-bit CRC, 0..0xFFFF.

    Raises:
        ValueError: ``crc`` is outside 0..0xFFFF (local misuse).
    """
    if not 0 <= crc <= 0xFFFF:
        raise ValueError(f"crc must be in 0..0xFFFF, got {crc}")
    return binascii.crc_hqx(data, crc)
