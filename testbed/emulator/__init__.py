"""The PTY modem emulator (two pseudo-terminals joined in real time by the channel model) and
its modem personalities."""

from __future__ import annotations

from testbed.emulator.ptys import ModemEmulator, PortCounters

__all__ = ["ModemEmulator", "PortCounters"]
