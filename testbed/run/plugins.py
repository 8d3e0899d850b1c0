"""Pilots, link models and control laws of the user's own, named in a scenario file.

A scenario names a callable of the user's as ``"FILE.py:NAME"`` (a Python file: relative to the
scenario file's folder, or to the working directory in ``--set``, or absolute) or
``"MODULE:NAME"`` (a module Python can import: installed, or on ``PYTHONPATH``)::

    [pilot]
    kind = "python"
    factory = "my_pilots.py:StepPilot"
    args = { at_s = 15.0, surge = 0.5 }

    [link]
    preset = "s100"
    model = "my_links.py:halved_after"
    model_args = { at_s = 50.0 }

    [vehicle.control]
    depth = "my_laws.py:PdDepth"
    depth_args = { kp = 60.0 }

Each run calls its factories afresh, so a pilot, model or law that keeps state starts clean in
every run, trial and sweep point: a pilot factory as ``factory(**args)``; a link model factory
as ``factory(config, **model_args)``, ``config`` the run's
:class:`~testbed.channel.config.LinkConfig` (the preset with the ``[link]`` keys applied); a
control law factory as ``factory(**depth_args)`` or ``factory(**attitude_args)``. Each, when it
has a parameter named ``rng``, is also given ``rng=``: a ``numpy.random.Generator`` of the run's
seed of its own (:func:`~testbed.run.plugin_calls.factory_generator`), so one seed makes one
result and trials of consecutive seeds draw differently; its arguments may not hold ``rng``. The
pilot must have ``sample(t_s) -> PilotSample`` (:class:`~testbed.operator.pilots.Pilot`), the
model ``airtime_s`` and ``error_model`` (:class:`~testbed.channel.model.LinkModel`), a law
``reset`` and ``update`` (:class:`~testbed.vehicle.control_laws.DepthLaw`,
:class:`~testbed.vehicle.control_laws.AttitudeLaw`). What a pilot, model or law raises during a
run, or returns that a run cannot use, is a one-line error naming it, the call and the error
(:class:`~testbed.operator.pilots.PilotError`, ``LinkModelError``, ``ControlLawError``).

Loading a scenario imports the target and binds the arguments to its signature, so a missing
file, a name the module lacks or an argument the factory does not take is a one-line error
naming the key before anything runs. A factory that fails when a run calls it is one line too,
naming the scenario's file, or ``--set`` and the overrides that changed the call
(:func:`~testbed.run.plugin_calls.set_keys`: the target, its arguments, or for a link model the
link's keys). This module finds, imports and checks the targets; :mod:`testbed.run.plugin_calls`
calls them for a run.

A file is imported once per process, as a module named
``testbed_user_<stem>_<8 hex digits of its path>``, with its folder first on the import path
while it runs (as ``python FILE.py`` has it), so its module-level imports find the modules
beside it; their files are hashed with it (:func:`target_files`). Sweep workers import it
themselves, so it must be readable where they run.

This runs the user's own code from a file the user named, as ``python my_pilots.py`` would;
nothing received from a link, a socket or a browser is ever imported or evaluated.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import math
import re
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any, cast

from testbed.config import USER_MODULE_PREFIX, ConfigError

__all__ = [
    "PYTHON_SUFFIX",
    "RNG_PARAMETER",
    "TABLE_VALUE_KEYS",
    "check_arguments",
    "check_finite",
    "check_no_rng",
    "check_target",
    "load_factory",
    "takes_rng",
    "target_file",
    "target_files",
]

PYTHON_SUFFIX = ".py"
"""The suffix that makes a target's module part a file path rather than a module name."""

TABLE_VALUE_KEYS = frozenset(
    {"pilot.args", "link.model_args", "vehicle.control.depth_args", "vehicle.control.attitude_args"}
)
"""Scenario keys whose value is one table, a factory's keyword arguments: a sweep's ``[set]``
sets such a table whole (``"link.model_args" = {}`` clears the scenario's), never merged key by
key."""

RNG_PARAMETER = "rng"
"""The parameter a factory names to be given its generator; an arguments table may not hold it."""

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*")
_MODULES: dict[Path, ModuleType] = {}
_FILES: dict[str, list[str]] = {}
"""The files behind each imported target's module (:func:`target_files`), by resolved path (a
file) or module name."""


def target_file(target: str) -> str | None:
    """The file path of a ``"FILE.py:NAME"`` target, None for ``"MODULE:NAME"`` or a malformed
    one."""
    module, colon, _ = target.rpartition(":")
    return module if colon and module.endswith(PYTHON_SUFFIX) else None


def check_target(target: str) -> str | None:
    """What is wrong with the form of ``target`` (``"FILE.py:NAME"`` or ``"MODULE:NAME"``), or
    None."""
    module, colon, name = target.rpartition(":")
    if not colon or not module or not _NAME.fullmatch(name):
        return f"expected 'FILE.py:NAME' or 'MODULE:NAME', got {target!r}"
    if not module.endswith(PYTHON_SUFFIX) and not _NAME.fullmatch(module):
        return f"{module!r} is neither a .py file nor a module name"
    return None


def load_factory(target: str, where: str, key: str) -> Callable[..., Any]:
    """The callable ``target`` names, imported (once per process for a file).

    Raises:
        ConfigError: ``"<where>: <key>: ..."`` for a malformed target, a missing or unreadable
            file, a module that fails to import (its exception's type and message), a missing
            name, or a name that is not callable.
    """
    problem = check_target(target)
    if problem is not None:
        raise ConfigError(f"{where}: {key}: {problem}")
    module_part, _, name = target.rpartition(":")
    if target_file(target) and not Path(module_part).is_file():
        raise ConfigError(f"{where}: {key}: no such file: {Path(module_part).resolve()}")
    try:  # a FileNotFoundError from here on is the module's own (a data file it opens)
        module = _import_file(Path(module_part)) if target_file(target) else None
        if module is None:
            module = _import_module(module_part)
    except (Exception, SystemExit) as error:  # the user's module failed (or called sys.exit at
        message = f"{type(error).__name__}: {error}"  # import): its own error, in one line
        if isinstance(error, ModuleNotFoundError) and error.name == module_part:
            message += f" (a file is named as '{module_part}{PYTHON_SUFFIX}:{name}')"
        raise ConfigError(f"{where}: {key}: importing {module_part} failed: {message}") from None
    found: Any = module
    for part in name.split("."):
        if not hasattr(found, part):
            raise ConfigError(f"{where}: {key}: {module_part} has no {name!r}")
        found = getattr(found, part)
    if not callable(found):
        raise ConfigError(f"{where}: {key}: {name!r} in {module_part} is not callable")
    return cast(Callable[..., Any], found)


def _import_file(path: Path) -> ModuleType:
    """The module of the Python file at ``path``, executed the first time it is asked for, with
    its folder first on the import path while it runs (as ``python FILE.py`` has it), so that
    its imports find the modules beside it; the files of those are kept for
    :func:`target_files`. A module of that name imported before (from elsewhere) is Python's
    as ever: the one already loaded."""
    resolved = path.resolve()
    module = _MODULES.get(resolved)
    if module is not None:
        return module
    digest = hashlib.sha256(str(resolved).encode()).hexdigest()[:8]
    stem = re.sub(r"\W", "_", resolved.stem)
    name = f"{USER_MODULE_PREFIX}{stem}_{digest}"
    spec = importlib.util.spec_from_file_location(name, resolved)
    if spec is None or spec.loader is None:
        raise ImportError(f"not a Python module: {resolved}")
    module = importlib.util.module_from_spec(spec)
    before = set(sys.modules)
    sys.modules[name] = module  # before it runs: a dataclass looks its module up
    sys.path.insert(0, str(resolved.parent))
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    finally:
        sys.path.remove(str(resolved.parent))
    _MODULES[resolved] = module
    _FILES[str(resolved)] = [str(resolved), *_files_beside(resolved.parent, before)]
    return module


def _import_module(name: str) -> ModuleType:
    """``importlib.import_module(name)``, keeping its file and those of the modules beside it
    that it imported for :func:`target_files` (the first time)."""
    before = set(sys.modules)
    module = importlib.import_module(name)
    origin = getattr(module, "__file__", None)
    if origin is not None and name not in _FILES:
        folder = Path(origin).resolve().parent
        _FILES[name] = [str(Path(origin).resolve()), *_files_beside(folder, before)]
    return module


def _files_beside(folder: Path, before: set[str]) -> list[str]:
    """The files in ``folder`` of the modules imported since ``before`` (a set of
    ``sys.modules``' names), sorted."""
    files = set()
    for name in set(sys.modules) - before:
        origin = getattr(sys.modules[name], "__file__", None)
        if origin is not None and Path(origin).resolve().parent == folder:
            files.add(str(Path(origin).resolve()))
    return sorted(files)


def target_files(target: str) -> list[str]:
    """The files behind ``target`` whose content a run depends on: the named file (or the
    module's), and the modules beside it that its import loaded (a helper it imports later, in
    a function, is not seen), once :func:`load_factory` imported it in this process; else the
    named file alone (a module: none)."""
    module_part = target.rpartition(":")[0]
    if target_file(target) is not None:
        path = str(Path(module_part).resolve())
        return list(_FILES.get(path, [path]))
    return list(_FILES.get(module_part, []))


def takes_rng(factory: Callable[..., Any]) -> bool:
    """Whether ``factory`` has a parameter named ``rng`` (it is then given its generator of the
    run's seed, :func:`~testbed.run.plugin_calls.factory_generator`)."""
    try:
        return RNG_PARAMETER in inspect.signature(factory).parameters
    except (TypeError, ValueError):  # no signature to read (some builtins)
        return False


def check_arguments(
    factory: Callable[..., Any],
    target: str,
    positional: tuple[Any, ...],
    kwargs: Mapping[str, Any],
    where: str,
    keys: tuple[str, str, str],
) -> None:
    """Check ``kwargs``' numbers are finite (:func:`check_finite`) and hold no ``rng``
    (:func:`check_no_rng`), and bind ``positional`` and ``kwargs`` to ``factory``'s signature
    without calling it (with the ``rng`` the run gives when it has that parameter).

    Args:
        factory: the callable ``target`` names.
        target: as the scenario gives it, for messages.
        positional: what the run passes first (a link model's config).
        kwargs: the keyword arguments.
        where: the file (or ``--set``), for messages.
        keys: the target's key, the arguments' key and the call's shape for messages
            (``("link.model", "link.model_args", "(config, **model_args)")``).

    Raises:
        ConfigError: ``"<where>: <key>: ..."`` naming a number that is not finite, an ``rng``
            in the arguments, or what does not bind (the target's key when it cannot take the
            positional arguments; the arguments' key for a keyword it does not take, or one it
            needs that is missing).
    """
    target_key, key, shape = keys
    check_finite(kwargs, where, key)
    check_no_rng(kwargs, where, key)
    if takes_rng(factory):
        kwargs = {**kwargs, RNG_PARAMETER: None}
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):
        return  # nothing to check against: the call will tell
    try:
        signature.bind_partial(*positional)
    except TypeError as error:
        raise ConfigError(f"{where}: {target_key}: {target} cannot take {shape}: {error}") from None
    taken = [name for name, _ in zip(signature.parameters, positional, strict=False)]
    twice = [name for name in taken if name in kwargs]
    if twice:  # e.g. a link model factory without the config parameter it is called with first
        raise ConfigError(
            f"{where}: {target_key}: {target} cannot take {shape}: its parameter {twice[0]!r} "
            f"is given the run's {shape[1:].split(',')[0]} first, and {key} names it too"
        )
    try:
        signature.bind(*positional, **kwargs)
    except TypeError as error:
        raise ConfigError(f"{where}: {key}: {target}: {error}") from None


def check_finite(value: Any, where: str, key: str) -> None:
    """Refuse a NaN or an infinity anywhere in ``value``, a factory's arguments (``key``) as TOML
    gives them: tables and arrays are looked into.

    A scenario's numeric keys refuse NaN, and infinity unless they say it means "no limit"
    (:func:`testbed.config.check_range`); what a factory's argument means is the factory's,
    so the default holds. It also keeps the record true: ``metrics.json`` is strict JSON, where
    a non-finite number can only be written as ``null``.

    Raises:
        ConfigError: ``"<where>: <key>.<name>: must be a finite number, got nan"`` (``[i]`` for
            an array's element).
    """
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{where}: {key}: must be a finite number, got {value}")
    if isinstance(value, Mapping):
        for name, item in value.items():
            check_finite(item, where, f"{key}.{name}")
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            check_finite(item, where, f"{key}[{i}]")


def check_no_rng(kwargs: Mapping[str, Any], where: str, key: str) -> None:
    """Refuse a factory's arguments (``key``) that hold ``rng``: the run gives it (its seed's
    generator, :func:`~testbed.run.plugin_calls.factory_generator`), whether or not the factory
    takes it.

    Raises:
        ConfigError: ``"<where>: <key>.rng: the run gives rng (its seed's generator)"``.
    """
    if RNG_PARAMETER in kwargs:
        raise ConfigError(
            f"{where}: {key}.{RNG_PARAMETER}: the run gives rng (its seed's generator)"
        )
