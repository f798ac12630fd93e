"""The settings tree as data: written whole into ``scenario.json`` (``source.settings``) and
printed by ``vid2sim settings``; read back from ``--config settings.yaml``.

A settings file is a partial tree: any branch of :class:`~vid2sim.app.settings.Settings`
with any of its fields, e.g.::

    tracker:
      high_score: 0.5
    ranging:
      lane_width_m: 3.3
      priors:
        car: {width_m: 1.8}

Everything not named keeps its default (or the value of the command's own option). An
unknown name, a value of the wrong type, a non-finite number or a value a stage refuses is
an input error naming the setting.
"""

from __future__ import annotations

import dataclasses
import math
import re
import typing
from collections.abc import Mapping
from enum import Enum
from pathlib import Path
from typing import Any

import yaml

from vid2sim.app.settings import Settings
from vid2sim.base.errors import FormatError, ImpossibleValueError
from vid2sim.base.fileio import read_input_text

#: Branches of the tree that say where things are or how fast they run, not what a scenario
#: holds: not recorded in a scenario (it stays byte-identical across machines) and not
#: accepted from a settings file (the command's options and environment set them).
NOT_RECORDED = frozenset({
    "detector.model_dir", "detector.threads", "osm_cache_dir", "progress",
    # the layout re-assembles with the tree's own `assemble` (Settings.layout_config)
    "layout.assemble",
})
#: Parts of a setting's name that make a negative value physically impossible: spreads,
#: noise, sizes, durations, rates, pixel counts (offsets, log-probabilities and scores may be
#: negative and carry none of these).
NON_NEGATIVE = re.compile(r"(std|sigma|noise|width|height|length|_s$|_hz$|_px$|_frames$)")
#: Largest settings file [bytes]: the whole default tree is about 12 kB.
MAX_SETTINGS_BYTES = 1024 * 1024


# --------------------------------------------------------------------------- tree -> data


def settings_tree(settings: Settings) -> dict[str, Any]:
    """The whole tree as JSON-ready data: nested dicts of the config classes' fields,
    tuples as lists, enums as their values, non-finite numbers as the strings ``"inf"``,
    ``"-inf"`` (exact: floats are not rounded)."""
    return _plain(settings, "")


def _plain(value: Any, where: str) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name), _join(where, f.name))
                for f in dataclasses.fields(value) if _join(where, f.name) not in NOT_RECORDED}
    if isinstance(value, Mapping):
        return {str(k.value if isinstance(k, Enum) else k): _plain(v, _join(where, str(k)))
                for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v, where) for v in value]
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def settings_yaml(settings: Settings) -> str:
    """The tree as a YAML settings file (what ``vid2sim settings`` prints)."""
    return yaml.safe_dump(settings_tree(settings), sort_keys=False, default_flow_style=False,
                          width=100)


def changed_settings(settings: Settings, base: Settings | None = None) -> dict[str, Any]:
    """The leaves of ``settings`` that differ from ``base`` (the defaults), as dotted names
    -> values: what a report shows first."""
    out: dict[str, Any] = {}
    _diff(settings_tree(settings), settings_tree(base or Settings()), "", out)
    return out


def _diff(a: Any, b: Any, where: str, out: dict[str, Any]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in a:
            _diff(a[k], b.get(k), _join(where, k), out)
    elif a != b:
        out[where] = a


def _join(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name


# --------------------------------------------------------------------------- data -> tree


def load_settings(path: Path, base: Settings | None = None) -> Settings:
    """``base`` (default: the defaults) with the settings of the YAML file ``path``.

    Raises
    ------
    FormatError
        The file is not YAML, not a mapping, or names a setting the tree does not have.
    ImpossibleValueError
        A value of the wrong type, not finite, or refused by :meth:`Settings.check`.
    """
    path = Path(path)
    text = read_input_text(path, max_bytes=MAX_SETTINGS_BYTES)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise FormatError(path, f"not YAML{where}", "write it as `vid2sim settings` prints "
                          "it") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise FormatError(path, "a settings file is a mapping of stage names to settings",
                          "see `vid2sim settings`")
    settings = apply_settings(base or Settings(), data, path)
    try:
        settings.check()
    except ImpossibleValueError as exc:
        raise ImpossibleValueError(path, exc.problem, exc.hint) from None
    return settings


def apply_settings(base: Settings, data: Mapping[str, Any], path: Path | None = None
                   ) -> Settings:
    """``base`` with the partial tree ``data`` applied (see :func:`load_settings`)."""
    return _apply(base, data, "", path)


def _apply(obj: Any, data: Any, where: str, path: Path | None) -> Any:
    if not isinstance(data, Mapping):
        raise ImpossibleValueError(path, f"setting {where}: expected a mapping of its "
                                   f"fields, got {data!r}")
    names = {f.name for f in dataclasses.fields(obj)}
    hints = _hints(type(obj))
    changes = {}
    for key, value in data.items():
        name = _join(where, str(key))
        if key not in names or name in NOT_RECORDED:
            close = [n for n in sorted(names) if n[:3] == str(key)[:3]]
            raise FormatError(path, f"unknown setting {name}",
                              f"did you mean {', '.join(_join(where, c) for c in close)}?"
                              if close else "see `vid2sim settings` for the tree")
        changes[key] = _value(getattr(obj, key), value, name, path, hints.get(key))
    return dataclasses.replace(obj, **changes) if changes else obj


def _value(current: Any, value: Any, where: str, path: Path | None, hint: Any) -> Any:
    if dataclasses.is_dataclass(current) and not isinstance(current, type):
        return _apply(current, value, where, path)
    if isinstance(current, Mapping):
        return _mapping(current, value, where, path)
    if current is None:
        current = _example_of(hint, value, where, path)
        if current is None:
            return None
    if value is None:
        if _allows_none(hint):
            return None
        raise ImpossibleValueError(path, f"setting {where}: a value is needed")
    out = _scalar(current, value, where, path)
    leaf = where.rsplit(".", 1)[-1]
    numbers = out if isinstance(out, tuple) else (out,)
    if NON_NEGATIVE.search(leaf) and any(isinstance(x, (int, float)) and not isinstance(x, bool)
                                         and x < 0 for x in numbers):
        raise ImpossibleValueError(path, f"setting {where}: {value!r} is negative",
                                   "a spread, size, duration or rate is >= 0")
    return out


def _mapping(current: Mapping, value: Any, where: str, path: Path | None) -> dict:
    if not isinstance(value, Mapping):
        raise ImpossibleValueError(path, f"setting {where}: expected a mapping, got {value!r}")
    by_name = {str(k.value if isinstance(k, Enum) else k): k for k in current}
    out = dict(current)
    for k, v in value.items():
        if str(k) not in by_name:
            raise FormatError(path, f"unknown setting {_join(where, str(k))}",
                              f"one of {', '.join(sorted(by_name))}")
        key = by_name[str(k)]
        out[key] = _value(current[key], v, _join(where, str(k)), path, None)
    return out


def _scalar(current: Any, value: Any, where: str, path: Path | None) -> Any:
    def wrong(expected: str) -> ImpossibleValueError:
        return ImpossibleValueError(path, f"setting {where}: expected {expected}, got {value!r}")

    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise wrong("true or false")
        return value
    if isinstance(current, Enum):
        try:
            return type(current)(value)
        except ValueError:
            raise wrong(f"one of {', '.join(str(m.value) for m in type(current))}") from None
    if isinstance(current, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise wrong("a whole number")
        return value
    if isinstance(current, float):
        number = _number(value)
        if number is None:
            raise wrong("a number")
        if math.isnan(number):
            raise wrong("a number (not NaN)")
        if math.isinf(number) and math.isfinite(current):
            raise wrong("a finite number")
        return number
    if isinstance(current, tuple):
        if not isinstance(value, (list, tuple)) or (current and len(value) != len(current)):
            raise wrong(f"a list of {len(current)} values" if current else "a list")
        return tuple(_scalar(c, v, where, path) for c, v in zip(current, value, strict=True)) \
            if current else tuple(value)
    if isinstance(current, str):
        if not isinstance(value, str):
            raise wrong("text")
        return value
    if isinstance(current, Path):
        return Path(str(value))
    raise wrong(type(current).__name__)


def _number(value: Any) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str) and value.strip().lower() in ("inf", "+inf", "-inf"):
        return float(value.strip().lower())
    return None


def _hints(cls: type) -> dict[str, Any]:
    try:
        return typing.get_type_hints(cls)
    except (NameError, TypeError):  # a hint only importable for type checkers
        return {}


def _allows_none(hint: Any) -> bool:
    return hint is None or type(None) in typing.get_args(hint)


def _example_of(hint: Any, value: Any, where: str, path: Path | None) -> Any:
    """A value of the type a None-valued field takes, from its hint (``float | None`` ->
    0.0), so a new value can be checked against it; None when ``value`` is None."""
    if value is None:
        return None
    for t in (typing.get_args(hint) or (hint,)):
        if t in (float, int, str, bool):
            return t()
    if isinstance(value, (bool, int, float, str)):
        return 0.0 if isinstance(value, (int, float)) and not isinstance(value, bool) \
            else value
    raise ImpossibleValueError(path, f"setting {where}: cannot set {value!r} here")
