"""The seam for a link model of your own: how long a transmission is on the air, and what a
receiver's bit errors are.

A :class:`~testbed.channel.medium.Medium` asks its :class:`LinkModel` two things and does the
rest itself (the MAC's queues and gaps, propagation, range, collisions, outages, the trace and
the counters, which every link shares):

- :meth:`LinkModel.airtime_s`: the time a transmission of ``size_bytes`` starting at ``t_s``
  keeps the sender busy after the modem's intrinsic delay [s] — a bit rate that changes over
  time, a rate adaptation, a per-packet overhead;
- :meth:`LinkModel.error_model`: one receiver's :class:`ErrorModel`, made once per attached
  modem with that receiver's own generator, which must be its only source of randomness (one
  seed, one result).

:class:`StandardLink` is the preset's own model (``bitrate_bps``; independent errors at the
copy's BER plus the preset's Gilbert–Elliott chain), used when none is given. Give yours to
:func:`~testbed.run.runner.run_scenario` (``link_model=``) or
:func:`~testbed.channel.probe.run_probe` (``testbed link``'s probe); a run records its class
in ``metrics.json`` (``inputs.link_model``). docs/channel.md, "A link model of your own".
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from testbed.config import ConfigError, described_class, shown_error, shown_line

from .config import LinkConfig
from .errors import BitErrors

__all__ = [
    "ErrorModel",
    "LinkModel",
    "LinkModelError",
    "StandardLink",
    "checked_airtime_s",
    "checked_corrupt",
    "made_error_model",
    "model_name",
    "wanted_keywords",
]


class LinkModelError(ConfigError):
    """A link model broke its contract (one of its methods raised, an air time that is not a
    finite number > 0, received bytes that are not the sent ones' length with the flipped bits
    counted): the model's class and file, the method and what was wrong named in one line (the
    command line's ``testbed: error: ...``, exit 2). One a method raised is caused by that
    exception (its traceback, for the Python API)."""

    @classmethod
    def raised(
        cls, model: object, call: str, error: BaseException, what: str = "link model"
    ) -> LinkModelError:
        """The error for ``model``'s ``call`` (e.g. ``"state(12.5)"``) having raised ``error``;
        ``what`` names ``model``'s part (``"link model's error model"`` for a receiver's)."""
        return cls(f"{what} {described_class(model)}: {call} raised {shown_error(error)}")

    @classmethod
    def airtime(cls, model: object, size_bytes: int, t_s: float, value: object) -> LinkModelError:
        """The error for ``model.airtime_s(size_bytes, t_s)`` having returned ``value``."""
        return cls(
            f"link model {described_class(model)}: airtime_s({size_bytes}, {t_s!r}) returned "
            f"{value!r}: expected a finite time > 0 [s]"
        )

    @classmethod
    def received(cls, errors: object, size_bytes: int, t_s: float, value: object) -> LinkModelError:
        """The error for ``errors.corrupt(data, p, t_s)`` of ``size_bytes`` bytes having
        returned ``value``."""
        shown = shown_line(value)
        return cls(
            f"link model's error model {described_class(errors)}: corrupt(<{size_bytes} B>, p, "
            f"{t_s!r}) returned {shown}: expected (bytes of the same length, the number of "
            "bits that differ from the sent ones)"
        )

    @classmethod
    def state(cls, model: object, t_s: float, value: object, why: str) -> LinkModelError:
        """The error for ``model.state(t_s)`` having returned ``value`` (``why``: what was
        wrong with it)."""
        shown = shown_line(value)
        return cls(f"link model {described_class(model)}: state({t_s!r}) returned {shown}: {why}")


def wanted_keywords(function: Callable[..., object], offered: tuple[str, ...]) -> tuple[str, ...]:
    """Which of the ``offered`` keyword arguments ``function`` takes (by name, or all of them
    through ``**kwargs``): a model's law is called with the context it asks for only
    (:class:`LinkModel`), so a law written without it keeps working."""
    try:
        parameters = inspect.signature(function).parameters
    except (TypeError, ValueError):  # a built-in without a signature: nothing extra
        return ()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return offered
    return tuple(name for name in offered if name in parameters)


def checked_airtime_s(model: LinkModel, size_bytes: int, t_s: float, **context: object) -> float:
    """``model.airtime_s(size_bytes, t_s, **context)`` [s], checked: a finite number > 0.

    Raises:
        LinkModelError: anything else (NaN, a string, None, ≤ 0, infinite), or the call raised.
    """
    try:
        value = model.airtime_s(size_bytes, t_s, **context)
    except Exception as error:
        raise LinkModelError.raised(model, f"airtime_s({size_bytes}, {t_s!r})", error) from error
    try:
        fits = 0.0 < value < math.inf  # NaN too
    except TypeError:  # not a number at all
        fits = False
    if not fits or isinstance(value, bool):
        raise LinkModelError.airtime(model, size_bytes, t_s, value)
    return float(value)


def checked_corrupt(
    errors: ErrorModel, data: bytes, p_independent: float, t_s: float, **context: object
) -> tuple[bytes, int]:
    """``errors.corrupt(data, p_independent, t_s, **context)``, checked: bytes of ``data``'s
    length and the count of the bits in which they differ from ``data`` (counted here, and
    held to the model's own count).

    Raises:
        LinkModelError: anything else, or the call raised.
    """
    try:
        value = errors.corrupt(data, p_independent, t_s, **context)
    except Exception as error:
        call = f"corrupt(<{len(data)} B>, p, {t_s!r})"
        raise LinkModelError.raised(errors, call, error, "link model's error model") from error
    if type(value) is tuple and len(value) == 2:
        received, count = value
        if type(received) is bytes and len(received) == len(data):
            flipped = 0
            if received is not data:
                difference = int.from_bytes(received, "big") ^ int.from_bytes(data, "big")
                flipped = difference.bit_count()
            if isinstance(count, int | np.integer) and int(count) == flipped:
                return received, flipped
    raise LinkModelError.received(errors, len(data), t_s, value)


def made_error_model(model: LinkModel, rng: np.random.Generator, receiver: str) -> ErrorModel:
    """``model.error_model(rng)`` for the receiving node ``receiver`` (given as
    ``receiver=`` when the model asks for it, :func:`wanted_keywords`), checked to have a
    ``corrupt`` method.

    Raises:
        LinkModelError: the call raised, or made something without ``corrupt``.
    """
    try:
        if wanted_keywords(model.error_model, ("receiver",)):
            errors = model.error_model(rng, receiver=receiver)  # type: ignore[call-arg]
        else:
            errors = model.error_model(rng)
    except Exception as error:
        raise LinkModelError.raised(model, f"error_model(rng) for the {receiver}", error) from error
    if not callable(getattr(errors, "corrupt", None)):
        raise LinkModelError(
            f"link model {described_class(model)}: error_model(rng) for the {receiver} returned "
            f"{shown_line(errors)}: expected an error model with corrupt(data, p, t_s)"
        )
    return errors


class ErrorModel(Protocol):
    """One receiver's bit errors.

    ``corrupt`` may also take, by name, keyword arguments of the copy's context (it is given
    those it names, or all through ``**kwargs``): ``sender`` (the sending node's name, e.g.
    ``"operator"``) and ``distance_m`` (sender to receiver at the transmission's start [m]).
    """

    def corrupt(self, data: bytes, p_independent: float, t_s: float) -> tuple[bytes, int]:
        """The bytes of one copy as received and how many bits were flipped.

        Args:
            data: the bytes as sent.
            p_independent: the copy's independent bit error probability (the link's BER at
                the distance it crossed; a model may use it or not).
            t_s: the time the copy is received [s].
        """
        ...


class LinkModel(Protocol):
    """What a link model decides (module docstring).

    Context it may ask for by naming it (see :func:`wanted_keywords`): ``airtime_s`` a
    ``sender`` (the sending node's name: an uplink and a downlink of their own rates), and
    ``error_model`` a ``receiver`` (the receiving node's name).

    A model may also define ``state(t_s) -> Mapping[str, float]``, the figures of its own to
    record beside a run (``link_state.csv``: :mod:`testbed.run.link_log`); the medium never
    calls it.
    """

    def airtime_s(self, size_bytes: int, t_s: float) -> float:
        """Time on the air of ``size_bytes`` bytes sent at ``t_s`` [s], > 0, the modem's
        intrinsic delay not included."""
        ...

    def error_model(self, rng: np.random.Generator) -> ErrorModel:
        """A new receiver's bit errors, drawing only from ``rng``."""
        ...


@dataclass(frozen=True, slots=True)
class StandardLink:
    """The preset's model: a constant bit rate, and independent errors plus the preset's
    Gilbert–Elliott burst chain (:class:`~testbed.channel.errors.BitErrors`)."""

    config: LinkConfig

    def airtime_s(self, size_bytes: int, t_s: float) -> float:
        """``size_bytes · (8 / bitrate_bps)`` [s], whatever the time."""
        return size_bytes * (8.0 / self.config.bitrate_bps)

    def error_model(self, rng: np.random.Generator) -> BitErrors:
        """The preset's independent and burst errors."""
        return BitErrors(self.config.burst, rng)


def model_name(model: object) -> str:
    """``module.QualifiedName`` of a model's class, for the record."""
    cls = type(model)
    return f"{cls.__module__}.{cls.__qualname__}"
