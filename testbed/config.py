"""Frozen configuration dataclasses built from TOML data, with strict checking.

Every configurable part of the testbed (link presets, vehicle models, thruster layouts and,
later, whole scenarios) is a frozen dataclass. This module turns a TOML mapping into one:
unknown keys are rejected, values are checked against the field's annotated type, and range
checks in a dataclass's ``__post_init__`` (raised as :class:`FieldError`) come back as one-line
:class:`ConfigError` messages naming the file and the dotted key. ``--set a.b=value`` overrides
are applied to the mapping before it is built, so they get exactly the same checks.

This module is a leaf: standard library only, importable from every layer.
"""

from __future__ import annotations

import copy
import dataclasses
import inspect
import math
import reprlib
import tomllib
import types
import typing
from collections.abc import Callable, Hashable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")

__all__ = [
    "CSV_NUMBER_FORMAT",
    "CSV_SIGNIFICANT_DIGITS",
    "ConfigError",
    "FieldError",
    "apply_overrides",
    "build",
    "check",
    "check_range",
    "check_ranges",
    "load_toml",
    "named_table",
    "parse_override",
    "read_text",
    "shown",
    "to_float",
    "user_file",
]


_BRIEF = reprlib.Repr()  # Python 3.11's takes no arguments
_BRIEF.maxlevel, _BRIEF.maxdict, _BRIEF.maxlist, _BRIEF.maxtuple = 2, 4, 6, 6
_BRIEF.maxstring = _BRIEF.maxother = 60


def shown(value: Any) -> str:
    """``repr(value)`` cut short for a one-line message (a 200 000-point array pasted where a
    table belongs made a 21-MB "line"): at most six items of a list, four of a dict, two levels,
    60 characters of a string, with ``...`` where something was left out."""
    return _BRIEF.repr(value)


CSV_SIGNIFICANT_DIGITS = 6
"""Significant digits of the numbers a run writes to its CSV files (``series.csv``,
``arm.csv``, ``link_state.csv``); a reader of them (the recorded pilot) takes a written time
to stand for any instant that rounds to it at this many digits."""
CSV_NUMBER_FORMAT = f".{CSV_SIGNIFICANT_DIGITS}g"
"""The format spec of those numbers (``f"{value:{CSV_NUMBER_FORMAT}}"``)."""


def shown_line(value: object) -> str:
    """``repr(value)`` cut to 80 characters (77 and ``...``), for a plug-in's return value in a
    one-line message."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def shown_error(error: BaseException) -> str:
    """``Type: message`` of an exception a user's plug-in raised, whitespace folded and cut to
    300 characters (297 and ``...``), for a one-line message."""
    text = " ".join(f"{type(error).__name__}: {error}".split())
    return text if len(text) <= 300 else text[:297] + "..."


def described_class(obj: object) -> str:
    """``QualifiedName (its source file)`` of ``obj``'s class (a user's pilot, link model or
    law), or the name alone when it has no file (a built-in class, or one defined in a REPL or
    ``python -c``)."""
    cls = type(obj)
    try:
        where = inspect.getsourcefile(cls)
    except (TypeError, OSError):
        where = None
    return cls.__qualname__ if where is None else f"{cls.__qualname__} ({where})"


class ConfigError(ValueError):
    """A user's configuration mistake. ``str(err)`` is a one-line message naming file and key."""


class FieldError(ValueError):
    """Raised by a config dataclass's ``__post_init__`` for a bad value of one field.

    Args:
        key: the field name (relative to the dataclass being built).
        message: what is wrong, e.g. ``"must be > 0, got -3"``.
    """

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message


USER_MODULE_PREFIX = "testbed_user_"
"""The name prefix of the modules the testbed imports from a user's Python file (a pilot or link
model named in a scenario, :mod:`testbed.run.plugins`): the command line lets Ctrl-C land in
their code, as in its own."""


def check(condition: bool, key: str, message: str) -> None:
    """Raise :class:`FieldError` for ``key`` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise FieldError(key, message)


def _bound(value: float) -> str:
    return f"{value:g}"


def check_range(
    value: float,
    key: str,
    low: float,
    high: float,
    unit: str = "",
    *,
    low_open: bool = False,
    high_open: bool = False,
    allow_inf: bool = False,
) -> None:
    """Field check: ``value`` is a finite number in the interval from ``low`` to ``high``.

    The interval is closed unless ``low_open`` / ``high_open``; ``high = math.inf`` leaves it
    unbounded above (the value must still be finite). With ``allow_inf``, ``+inf`` is accepted
    too (fields where it means "no limit"). NaN is always rejected. The message is one line,
    e.g. ``must be in [12, 20] V, got 25``.

    Raises:
        FieldError: for ``key``.
    """
    if allow_inf and value == math.inf:
        return
    ok = (
        math.isfinite(value)
        and (low < value if low_open else low <= value)
        and (value < high if high_open else value <= high)
    )
    if ok:
        return
    suffix = f" {unit}" if unit else ""
    if math.isinf(high):
        finite = "" if allow_inf else " and finite"
        interval = f"{'>' if low_open else '≥'} {_bound(low)}{suffix}{finite}"
    else:
        left = "(" if low_open else "["
        right = ")" if high_open else "]"
        interval = f"in {left}{_bound(low)}, {_bound(high)}{right}{suffix}"
    extra = " (or inf)" if allow_inf and not math.isinf(high) else ""
    raise FieldError(key, f"must be {interval}{extra}, got {value}")


def check_ranges(
    values: Iterable[float],
    key: str,
    low: float,
    high: float,
    unit: str = "",
    **options: bool,
) -> None:
    """:func:`check_range` on each element of a tuple field (keys ``key[0]``, ``key[1]``, …)."""
    for i, value in enumerate(values):
        check_range(value, f"{key}[{i}]", low, high, unit, **options)


def to_float(value: Any, source: str, key: str) -> float:
    """A decoded document's number as a float (TOML and JSON integers included).

    Raises:
        ConfigError: not a number (a bool is not), or an integer beyond any float (those
            formats' integers have no bound): ``"<source>: <key>: ..."``.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{source}: {key}: expected a number, got {shown(value)}")
    try:
        return float(value)
    except OverflowError:  # only an int overflows
        bits = int(value).bit_length()
        raise ConfigError(
            f"{source}: {key}: a {bits}-bit integer, beyond any float (±1.8e308)"
        ) from None


MAX_CONFIG_CHARS = 16 * 2**20
"""The longest configuration file read [characters]: the largest packaged one is ≈ 7 kB. A path
to a device that never ends (``/dev/zero``) was read until the process was killed for memory."""


def read_text(path: str | Path) -> str:
    """A configuration file's text (UTF-8), at most :data:`MAX_CONFIG_CHARS` characters.

    Raises:
        ConfigError: the file is missing, unreadable or longer than that (message names the
            file).
    """
    path = Path(path)
    try:
        with path.open(encoding="utf-8") as handle:
            text = handle.read(MAX_CONFIG_CHARS + 1)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot read: {err}") from None
    if len(text) > MAX_CONFIG_CHARS:
        raise ConfigError(
            f"{path}: cannot read: longer than {MAX_CONFIG_CHARS} characters, "
            "not a configuration file"
        )
    return text


_PARSED: dict[str, dict[str, Any]] = {}
"""TOML texts parsed in this process, by text (:func:`load_toml`)."""

_PARSED_KEPT = 256
"""Texts :data:`_PARSED` keeps (the oldest go first)."""


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file into a dict (a new one each call, the caller's to change).

    The file is read every time; a text parsed before in this process is not parsed again
    (a sweep's check loads a scenario, its model, layout and preset once per grid point).

    Raises:
        ConfigError: the file is missing, unreadable or not valid TOML (message names the file).
    """
    path = Path(path)
    text = read_text(path)
    parsed = _PARSED.get(text)
    if parsed is None:
        try:
            parsed = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"{path}: malformed TOML: {err}") from None
        if len(_PARSED) >= _PARSED_KEPT:
            del _PARSED[next(iter(_PARSED))]
        _PARSED[text] = parsed
    return copy.deepcopy(parsed)


_BUILT: dict[tuple[Hashable, ...], Any] = {}
"""Immutable values built from files' texts in this process (:func:`built_from_text`)."""


def built_from_text(kind: str, path: str | Path, make: Callable[[], T], *extra: Hashable) -> T:
    """``make()``, the immutable ``kind`` value built from the file at ``path`` (with ``extra``
    options), built once per text of the file in this process: the file is read every time, so
    an edit is seen; the same text is not built and checked again (a sweep's check loads a
    scenario's model and layout once per grid point, a scenario with overrides twice).

    ``make`` must be a pure function of the file's text and ``extra``, returning a value
    nothing changes (frozen dataclasses of tuples). An error it raises is raised each time.
    """
    key = (kind, str(path), read_text(path), *extra)
    if key in _BUILT:
        return typing.cast(T, _BUILT[key])
    value = make()
    if len(_BUILT) >= _PARSED_KEPT:
        del _BUILT[next(iter(_BUILT))]
    _BUILT[key] = value
    return value


def user_file(name: str, known: Iterable[str], what: str, suffix: str = ".toml") -> Path | None:
    """Where a named data file comes from: None for a packaged ``name`` (one of ``known``), else
    the user's own file at the path ``name``.

    ``name`` is a path when it ends in ``suffix`` or holds a path separator; a path must name an
    existing file ending in ``suffix``. Every data file a user may name (link presets, vehicle
    models, thruster layouts, arm models, TPIK configurations, missions) is resolved here, so
    their messages agree; callers prefix the file (or ``--set``) and the key.

    Raises:
        ConfigError: a path to no file (``thruster configuration file not found:
            /abs/my-frame.toml``: the path made absolute, from the working directory), to a
            directory or to a file not ending in ``suffix``; or neither a path nor a packaged
            name (the message lists the packaged ones); ``what`` says what the files hold
            (e.g. "vehicle model").
    """
    names = list(known)
    if name in names:
        return None
    path = Path(name)
    if path.suffix != suffix and "/" not in name and "\\" not in name:
        raise ConfigError(
            f"unknown {what} {name!r} (packaged: {', '.join(names)}; or a path to a {suffix} file)"
        )
    if path.suffix == suffix and path.is_file():
        return path
    where = path.absolute()
    if not path.exists():
        raise ConfigError(f"{what} file not found: {where}")
    if not path.is_file():
        raise ConfigError(f"{what} file {where}: not a file")
    raise ConfigError(f"{what} file {where}: must end in {suffix}")


def named_table(tables: Mapping[str, Any], name: str, source: str, what: str) -> dict[str, Any]:
    """``tables[name]``, a TOML file's table of that name.

    Raises:
        ConfigError: no such table (the message names the file and the known ones), or not
            a table; ``what`` says what the tables hold (e.g. "ISMC gains").
    """
    table = tables.get(name)
    if table is None:
        known = ", ".join(sorted(tables))
        raise ConfigError(f"{source}: {name}: no {what} of this name (known: {known})")
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: {name}: expected a table")
    return dict(table)


def parse_override(text: str) -> tuple[list[str], Any]:
    """Split ``"a.b=value"`` into ``(["a", "b"], value)``.

    The value is read as a TOML value (``1e-4``, ``true``, ``[1, 2]``, ``"x"``); anything that
    does not parse as TOML is taken as a bare string, so ``preset=s100`` works unquoted.

    Raises:
        ConfigError: no ``=`` or an empty key.
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part.strip() for part in key.split(".")):
        raise ConfigError(f"--set {text!r}: expected KEY=VALUE with a dotted key")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return [part.strip() for part in key.split(".")], value


def apply_overrides(data: Mapping[str, Any], overrides: Iterable[str]) -> dict[str, Any]:
    """Return a deep copy of ``data`` with each ``KEY=VALUE`` override applied.

    Keys that do not exist yet are created; :func:`build` then rejects those the schema does not
    know, with the same message as a bad key in the file.
    """
    result = _deep_copy(data)
    for text in overrides:
        path, value = parse_override(text)
        node = result
        for part in path[:-1]:
            child = node.get(part)
            if not isinstance(child, dict):
                child = {}
                node[part] = child
            node = child
        node[path[-1]] = value
    return result


def build(
    cls: type[T], data: Mapping[str, Any], *, source: str = "<config>", prefix: str = ""
) -> T:
    """Build the frozen dataclass ``cls`` from ``data``, checking keys, types and ranges.

    Args:
        cls: a dataclass type whose fields are annotated with supported types: ``bool``, ``int``,
            ``float``, ``str``, ``Literal[...]``, ``X | None``, ``tuple[X, ...]``, fixed
            ``tuple[X, Y]``, nested dataclasses, and ``dict[str, X]``.
        data: the mapping (e.g. from :func:`load_toml`). Missing keys take the field default.
        source: the file name (or ``--set``) used in error messages.
        prefix: dotted key prefix of ``data`` within the file, for messages.

    Raises:
        ConfigError: unknown key, missing required key, wrong type, or a :class:`FieldError`
            from the dataclass's own checks; the message names ``source`` and the dotted key.
    """
    return typing.cast(T, _build_dataclass(cls, data, source, prefix))


def _build_dataclass(cls: type[Any], data: Any, source: str, prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: {prefix.rstrip('.') or '<root>'}: expected a table")
    fields, hints = _schema(cls)
    unknown = sorted(set(data) - set(fields))
    if unknown:
        known = ", ".join(sorted(fields))
        raise ConfigError(f"{source}: {prefix}{unknown[0]}: unknown key (known: {known})")
    kwargs: dict[str, Any] = {}
    for name, field in fields.items():
        key = f"{prefix}{name}"
        if name not in data:
            no_default = field.default is dataclasses.MISSING
            if no_default and field.default_factory is dataclasses.MISSING:
                raise ConfigError(f"{source}: {key}: required key missing")
            continue
        kwargs[name] = _convert(hints[name], data[name], source, key)
    try:
        return cls(**kwargs)
    except FieldError as err:
        raise ConfigError(f"{source}: {prefix}{err.key}: {err.message}") from None


_Schema = tuple[dict[str, "dataclasses.Field[Any]"], dict[str, Any]]
_SCHEMAS: dict[type[Any], _Schema] = {}


def _schema(cls: type[Any]) -> _Schema:
    """The init fields of dataclass ``cls`` by name and its resolved type hints (cached:
    resolving the string annotations dominates the cost of a build)."""
    schema = _SCHEMAS.get(cls)
    if schema is None:
        fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
        schema = _SCHEMAS[cls] = (fields, typing.get_type_hints(cls))
    return schema


def _convert(tp: Any, value: Any, source: str, key: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _build_dataclass(tp, value, source, f"{key}.")
    if origin is typing.Literal:
        if value not in args:
            choices = ", ".join(repr(a) for a in args)
            raise ConfigError(f"{source}: {key}: expected one of {choices}, got {shown(value)}")
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, source, key)
            except ConfigError as err:
                errors.append(err)
        raise errors[0]
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{source}: {key}: expected an array, got {shown(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, source, f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{source}: {key}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _convert(a, v, source, f"{key}[{i}]")
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{source}: {key}: expected a table, got {shown(value)}")
        return {str(k): _convert(args[1], v, source, f"{key}.{k}") for k, v in value.items()}
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{source}: {key}: expected true or false, got {shown(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{source}: {key}: expected an integer, got {shown(value)}")
        return value
    if tp is float:
        number = to_float(value, source, key)
        if math.isnan(number):
            raise ConfigError(f"{source}: {key}: expected a number, got nan")
        return number
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{source}: {key}: expected a string, got {shown(value)}")
        return value
    if tp is Any:
        return value
    raise TypeError(f"config field {key}: unsupported annotation {tp!r}")  # programming error


def _deep_copy(data: Mapping[str, Any]) -> dict[str, Any]:
    return {k: _deep_copy(v) if isinstance(v, Mapping) else v for k, v in data.items()}
