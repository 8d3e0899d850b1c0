"""Modem personalities for the emulator: the modem side of a serial modem protocol, sans-IO.

A personality is what a real modem does between its serial port and the water: it parses what
the user writes, answers commands, keeps a transmit queue, and formats what it receives as the
modem would. It never does I/O and never reads a clock (times are passed in). The emulator
(:mod:`testbed.emulator.ptys`) feeds it the bytes written on a port, pulls the next
:class:`AirPacket` whenever the simulated link is free, and hands it what the link delivered.

Written from the vendors' documented serial interfaces (REFERENCE §1.11, §1.12), independently
of :mod:`testbed.hil`, whose adapters are the system these personalities test.

* :class:`EvoLogicsPersonality` — EvoLogics S2C in data mode. Commands arrive escaped as
  ``+++AT<command>`` + line end; replies and events go out as ``+++AT<name>:<len>:<body>`` CR LF.
  ``AT*SENDIM,<len>,<dst>,<ack|noack|force>,<data>`` queues an instant message (≤ 64 B),
  received ones come out as ``RECVIM,<len>,<src>,<dst>,<ack|noack>,<duration_us>,<rssi>,
  <integrity>,<velocity>,<data>``. Bytes outside escapes are burst data for the remote address.
* :class:`M64Personality` — Water Linked Modem-M64: ``w c <cmd>[,options][*xx]`` LF sentences,
  8-byte packets queued with ``wcq,8,<8 raw bytes>`` and delivered as ``wrp,8,<8 bytes>*xx``.

Decisions where the references are silent (also in the README):

* A copy the link delivers with bit errors is dropped and counted, never reported: both modems
  protect their packets with their own checksum, and a real CRC misses a damaged packet with a
  probability (≈ 2⁻¹⁶) negligible here. ``--set ber=...`` therefore shows as lost messages.
* What goes on the air is the payload only (8·len / bitrate of airtime); the modem's addressing
  (source, destination, ack flag; M64 role and channel) rides alongside as the packet's header,
  its cost taken as part of the preset's intrinsic delay. An EvoLogics acknowledgement is a
  1-byte packet.
* EvoLogics reply names: the command up to its first comma (``+++AT*SENDIM:2:OK``,
  ``+++ATZ4:2:OK``); events have an empty name (``+++AT:<len>:RECVIM,...``). Errors:
  ``ERROR WRONG FORMAT`` (bad parameters), ``ERROR UNKNOWN COMMAND``, ``ERROR BUFFER FULL``.
* M64 answers: ``wr?`` for an unknown, malformed or bad-checksum sentence; ``wr<cmd>,n`` for a
  known command with bad options or a full queue; answers carry ``*xx`` when the command did,
  and ``wrp`` sentences when the user's last sentence did (and before any). No A/B ping-pong:
  each modem sends its queue as the half-duplex link allows.
"""

from __future__ import annotations

from .base import (
    EVOLOGICS_IM_MAX,
    M64_PAYLOAD,
    AirPacket,
    EvoLogicsHeader,
    M64Header,
    ModemPersonality,
)
from .evologics import EvoLogicsPersonality
from .m64 import M64Personality, m64_crc8

__all__ = [
    "EVOLOGICS_IM_MAX",
    "M64_PAYLOAD",
    "AirPacket",
    "EvoLogicsHeader",
    "EvoLogicsPersonality",
    "M64Header",
    "M64Personality",
    "ModemPersonality",
    "m64_crc8",
]
