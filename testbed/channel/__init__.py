"""simpy link models: bitrate, delay, bit errors, bursts, collisions, buffers, presets.

The link is simpy's ``Cable`` shape: a :class:`Medium` apart from the nodes, each node holding a
:class:`Modem` made by :meth:`Medium.attach`. Frames are bytes, always; the receiver's decoder
(:class:`testbed.protocol.FrameDecoder`) must catch corrupted ones, as on a real modem.

- :mod:`~testbed.channel.config` — :class:`LinkConfig` and the packaged presets
  (``s100``, ``m64``, ``s2c``, ``tether``) loaded by :func:`load_link_config`.
- :mod:`~testbed.channel.medium` — :class:`Medium`, :class:`Modem`, :class:`Delivery`,
  :func:`decode_delivery` (every simulated receiver's decoding rule).
- :mod:`~testbed.channel.errors` — independent and Gilbert–Elliott bit errors.
- :mod:`~testbed.channel.model` — the seam for a link model of your own (:class:`LinkModel`:
  air time and a receiver's bit errors; :class:`StandardLink`, the preset's).
- :mod:`~testbed.channel.mac` — token passing (the paper's) and free access, as simpy processes.
- :mod:`~testbed.channel.trace` — typed link events, and what became of each frame
  (:func:`frame_outcomes`, :func:`transmissions`, :func:`direction_counts`).
- :mod:`~testbed.channel.probe` — the one-way probe behind ``testbed link``.

Depends on :mod:`testbed.protocol`, :mod:`testbed.config`, simpy and numpy only.
"""

from __future__ import annotations

from .config import GilbertElliott, LinkConfig, Propagation, load_link_config, preset_names
from .delivery import Delivery, ModemCounters, decode_delivery
from .mac import (
    TELEROBOTICS_2018,
    TELEROBOTICS_2019,
    TELEROBOTICS_2021,
    Fixed,
    FromFrameSize,
    IpgPolicy,
    run_periodic_sender,
    run_token_master,
    run_token_slave,
)
from .medium import Medium, Modem, Position
from .model import ErrorModel, LinkModel, StandardLink
from .outcomes import (
    RECEPTION_OUTCOMES,
    DirectionCounts,
    FrameOutcome,
    Transmission,
    direction_counts,
    frame_outcomes,
    transmissions,
    worst_outcome,
)
from .probe import ProbeResult, run_probe
from .trace import EventKind, LinkEvent, Trace

__all__ = [
    "RECEPTION_OUTCOMES",
    "TELEROBOTICS_2018",
    "TELEROBOTICS_2019",
    "TELEROBOTICS_2021",
    "Delivery",
    "DirectionCounts",
    "ErrorModel",
    "EventKind",
    "Fixed",
    "FrameOutcome",
    "FromFrameSize",
    "GilbertElliott",
    "IpgPolicy",
    "LinkConfig",
    "LinkEvent",
    "LinkModel",
    "Medium",
    "Modem",
    "ModemCounters",
    "Position",
    "ProbeResult",
    "Propagation",
    "StandardLink",
    "Trace",
    "Transmission",
    "decode_delivery",
    "direction_counts",
    "frame_outcomes",
    "load_link_config",
    "preset_names",
    "run_periodic_sender",
    "run_probe",
    "run_token_master",
    "run_token_slave",
    "transmissions",
    "worst_outcome",
]
