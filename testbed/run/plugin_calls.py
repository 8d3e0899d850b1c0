"""Calling the user's factories for a run: the pilot, link model and control laws a scenario
names (:mod:`testbed.run.plugins`, which finds, imports and checks them), made afresh for each
run with their generators of the run's seed, and a factory's failure as one line naming where
its call came from: the scenario's file, or the ``--set`` keys that changed it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from testbed.config import ConfigError, parse_override, shown
from testbed.run.plugins import RNG_PARAMETER, check_no_rng, load_factory, takes_rng

if TYPE_CHECKING:
    from testbed.channel.config import LinkConfig
    from testbed.channel.model import LinkModel
    from testbed.operator.pilots import Pilot
    from testbed.run.scenario_config import Scenario
    from testbed.vehicle.control_laws import AttitudeLaw, DepthLaw

__all__ = [
    "GENERATOR_CHILDREN",
    "call_factory",
    "factory_generator",
    "make_link_model",
    "pilot_generator",
    "scenario_control_laws",
    "scenario_link_model",
    "scenario_pilot",
    "set_keys",
]

GENERATOR_CHILDREN = {
    "pilot.factory": 2,
    "link.model": 3,
    "vehicle.control.depth": 4,
    "vehicle.control.attitude": 5,
}
"""The child of ``SeedSequence(seed)`` whose generator each factory that takes ``rng`` is given,
by the key naming the factory. Children 0 and 1 are the link's and the vehicle's own
(``SeedSequence(seed).spawn(2)`` in every run mode); ``spawn(n)``'s first ``k`` children are
``spawn(k)``'s, so giving a factory its generator changes no other draw, and each factory's
draws are the same whichever others the scenario names."""


def call_factory(
    factory: Callable[..., Any],
    positional: tuple[Any, ...],
    kwargs: Mapping[str, Any],
    where: str,
    key: str,
    args_key: str,
    named: Sequence[str] = (),
) -> Any:
    """``factory(*positional, **kwargs)``; an exception it raises becomes a one-line
    :class:`ConfigError` naming ``where``, then the ``--set`` keys that changed the call
    (``named``, :func:`set_keys`) if any, and ``key`` and, when it was given any, the key of its
    keyword arguments ``args_key`` with them."""
    try:
        return factory(*positional, **kwargs)
    except (Exception, SystemExit) as error:  # sys.exit in a factory: its error, not our exit
        given = {k: v for k, v in kwargs.items() if k != RNG_PARAMETER}
        with_args = f" with {args_key} = {shown(given)}" if given else ""
        if named and key not in named:
            head, called = ", ".join(named), f" (calling {key}{with_args})"
        else:
            head, called = ", ".join(named) or key, f" (called{with_args})" if given else ""
        raise ConfigError(f"{where}: {head}{called}: {type(error).__name__}: {error}") from None


def _within(key: str, table: str) -> bool:
    """Whether the dotted ``key`` is ``table`` or inside it."""
    return key == table or key.startswith(f"{table}.")


def set_keys(scenario: Scenario, keys: Iterable[str]) -> list[str]:
    """The dotted keys of ``scenario``'s ``--set`` overrides that are in force and set one of
    ``keys``, a table holding one, or a key inside one (an override of a table replaces what
    those before it set inside it), in order: what changed a factory's call from the file's."""
    wanted = tuple(keys)
    found: list[str] = []
    for text in scenario.overrides:
        dotted = ".".join(parse_override(text)[0])
        found = [earlier for earlier in found if not _within(earlier, dotted)]
        if any(_within(dotted, key) or _within(key, dotted) for key in wanted):
            found.append(dotted)
    return found


def _where(scenario: Scenario, named: list[str]) -> str:
    """What a message about a factory's call names as its source: ``--set`` when overrides
    changed it (``named``), else the scenario's file (or ``package:<id>``)."""
    return "--set" if named else scenario.source


def factory_generator(seed: int, key: str) -> np.random.Generator:
    """The generator a run of seed ``seed`` gives the factory named at scenario key ``key``
    (``"pilot.factory"``, ``"link.model"``, ``"vehicle.control.depth"`` or
    ``"vehicle.control.attitude"``) when it takes ``rng``: child
    ``GENERATOR_CHILDREN[key]`` of ``SeedSequence(seed)`` (:data:`GENERATOR_CHILDREN`)."""
    child = GENERATOR_CHILDREN[key]
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(child + 1)[child])


def pilot_generator(seed: int) -> np.random.Generator:
    """The generator a run of seed ``seed`` gives a pilot factory that takes ``rng``: the third
    child of ``SeedSequence(seed)`` (:func:`factory_generator`)."""
    return factory_generator(seed, "pilot.factory")


def _arguments(
    factory: Callable[..., Any], args: Mapping[str, Any], seed: int, key: str
) -> dict[str, Any]:
    """``args``, with ``rng`` the generator of ``seed`` for the factory named at ``key`` when
    it takes one (:func:`factory_generator`)."""
    kwargs = dict(args)
    if takes_rng(factory):
        kwargs[RNG_PARAMETER] = factory_generator(seed, key)
    return kwargs


def scenario_pilot(scenario: Scenario, seed: int) -> Pilot:
    """The pilot ``scenario`` configures, made afresh for a run of seed ``seed``: a packaged one
    (:meth:`~testbed.run.sections.PilotSection.pilot`), or the user's (module docstring).

    Raises:
        ConfigError: the factory failed, or made something without ``sample`` (naming
            ``pilot.factory``).
    """
    section = scenario.pilot
    if section.kind != "python":
        return section.pilot()
    key, args_key = "pilot.factory", "pilot.args"
    named = set_keys(scenario, (key, args_key))
    where = _where(scenario, named)
    factory = load_factory(section.factory, _where(scenario, set_keys(scenario, (key,))), key)
    kwargs = _arguments(factory, section.args, seed, key)
    pilot = call_factory(factory, (), kwargs, where, key, args_key, named)
    if not callable(getattr(pilot, "sample", None)):
        raise ConfigError(
            f"{where}: {key}: {section.factory} made a {type(pilot).__name__}, not a "
            "pilot (expected an object with sample(t_s) -> PilotSample)"
        )
    return cast("Pilot", pilot)


def scenario_link_model(scenario: Scenario, seed: int) -> LinkModel | None:
    """The link model ``scenario`` names in ``link.model``, made afresh for a run of seed
    ``seed`` (module docstring), or None for the preset's own.

    Raises:
        ConfigError: the factory failed, or made something that is not a link model (naming
            ``link.model``).
    """
    link = scenario.link
    if not link.model:
        return None
    keys = ("link.model", "link.model_args")
    config_keys = [f"link.{f.name}" for f in dataclasses.fields(link.channel)]
    named = set_keys(scenario, (*keys, "link.preset", *config_keys))
    where = _where(scenario, named)
    return make_link_model(link.model, link.model_args, link.channel, where, keys, named, seed=seed)


def make_link_model(
    target: str,
    args: Mapping[str, Any],
    channel: LinkConfig,
    where: str,
    keys: tuple[str, str],
    named: Sequence[str] = (),
    *,
    seed: int,
) -> LinkModel:
    """``NAME(channel, **args)`` of the callable ``target`` names (``"FILE.py:NAME"`` or
    ``"MODULE:NAME"``), with ``rng=`` the generator of ``seed`` for ``link.model``
    (:func:`factory_generator`) when it takes one, checked to be a link model; messages name
    ``where`` and ``keys`` (the target's key and its arguments'), and first the ``--set`` keys
    ``named`` that changed the call (the model, its arguments or the config:
    :func:`call_factory`).

    Raises:
        ConfigError: ``args`` hold ``rng``, the target does not load, the factory failed, or it
            made something without ``airtime_s`` and ``error_model``.
    """
    key, args_key = keys
    check_no_rng(args, where, args_key)
    factory = load_factory(target, where, key)
    kwargs = _arguments(factory, args, seed, "link.model")
    model = call_factory(factory, (channel,), kwargs, where, key, args_key, named)
    laws = ("airtime_s", "error_model")
    missing = [name for name in laws if not callable(getattr(model, name, None))]
    if missing:
        raise ConfigError(
            f"{where}: {key}: {target} made a {type(model).__name__} without "
            f"{' and '.join(missing)} (expected a testbed.channel.model.LinkModel)"
        )
    return cast("LinkModel", model)


_LAW_CONTRACTS = {
    "depth": "a DepthLaw: reset() and update(target, depth, imu, dt_s) -> (3,) body force [N]",
    "attitude": (
        "an AttitudeLaw: reset() and update(target, imu, dt_s, axes) -> (3,) body torque [N·m]"
    ),
}
"""What a depth or attitude law must have (:mod:`testbed.vehicle.control_laws`), for messages."""


def scenario_control_laws(
    scenario: Scenario, seed: int
) -> tuple[DepthLaw | None, AttitudeLaw | None]:
    """``(depth law, attitude law)`` that ``[vehicle.control]`` names, made afresh for a run of
    seed ``seed`` (module docstring): each ``NAME(**<name>_args)`` (with ``rng=`` its generator,
    :func:`factory_generator`, when it takes one), or None for the packaged PID. Call it
    before building the vehicle, and put them in its
    :class:`~testbed.vehicle.resources.Controllers` (``depth_law``, ``attitude_law``) before
    its first frame.

    Raises:
        ConfigError: a factory failed, or made something without ``reset`` and ``update``
            (naming ``vehicle.control.depth`` or ``vehicle.control.attitude``).
    """
    section = scenario.control_laws
    made: dict[str, Any] = {}
    for name, target in section.targets().items():
        key, args_key = f"vehicle.control.{name}", f"vehicle.control.{name}_args"
        named = set_keys(scenario, (key, args_key))
        where = _where(scenario, named)
        factory = load_factory(target, _where(scenario, set_keys(scenario, (key,))), key)
        args = _arguments(factory, getattr(section, f"{name}_args"), seed, key)
        law = call_factory(factory, (), args, where, key, args_key, named)
        missing = [m for m in ("reset", "update") if not callable(getattr(law, m, None))]
        if missing:
            raise ConfigError(
                f"{where}: {key}: {target} made a {type(law).__name__} without "
                f"{' and '.join(missing)} (expected {_LAW_CONTRACTS[name]})"
            )
        made[name] = law
    return cast("DepthLaw | None", made.get("depth")), cast(
        "AttitudeLaw | None", made.get("attitude")
    )
