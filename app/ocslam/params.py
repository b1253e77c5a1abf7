"""Config fields with their metadata: :func:`param` declares one (range, step, unit, help, live-tunable,
choices), :func:`coerce_value` converts and checks a value for it, :func:`validate_section` checks every field
of a section. The sections themselves are in :mod:`app.ocslam.config`; the same metadata validates YAML files
and CLI overrides and builds the GUI sliders, so the three can never disagree.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import field
from typing import Any


class ConfigError(ValueError):
    """A configuration value or file is invalid. The message names the offending key."""


def param(
    default: Any,
    *,
    min: float | None = None,
    max: float | None = None,
    step: float | None = None,
    unit: str = "",
    help: str = "",
    live: bool = False,
    choices: Sequence[Any] | None = None,
    items: Any = None,
    length: int | None = None,
) -> Any:
    """Declare a config field with its metadata (range, step, unit, help, live-tunable, choices).

    List fields: ``items`` is the type of every element (``float``: finite numbers, ``str``) or a
    sequence of the allowed elements; ``length`` a required number of elements."""
    meta = {
        "min": min,
        "max": max,
        "step": step,
        "unit": unit,
        "help": help,
        "live": live,
        "choices": tuple(choices) if choices is not None else None,
        "items": items if items is None or isinstance(items, type) else tuple(items),
        "length": length,
    }
    if isinstance(default, (list, dict, set)):
        return field(default_factory=lambda: type(default)(default), metadata=meta)
    return field(default=default, metadata=meta)


def coerce_value(section: str, f: dataclasses.Field, value: Any) -> Any:
    """Convert ``value`` to the field's type and check its range/choices; raise :class:`ConfigError`."""
    key = f"{section}.{f.name}"
    meta = f.metadata
    default = f.default if f.default is not dataclasses.MISSING else None
    ftype = type(default) if default is not None else None
    try:
        if ftype is bool:
            if isinstance(value, str):
                low = value.strip().lower()
                if low in ("1", "true", "yes", "on"):
                    value = True
                elif low in ("0", "false", "no", "off"):
                    value = False
                else:
                    raise ValueError(value)
            elif isinstance(value, (bool, int)) and value in (0, 1, True, False):
                value = bool(value)
            else:
                raise ValueError(value)
        elif ftype is int:
            if isinstance(value, bool):
                raise ValueError(value)
            if isinstance(value, float) and not value.is_integer():
                raise ValueError(value)
            value = int(value)
        elif ftype is float:
            if isinstance(value, bool):
                raise ValueError(value)
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(value)
        elif ftype is str:
            if not isinstance(value, str):
                raise ValueError(value)
        elif ftype in (list, tuple) or (default is None and f.default_factory is not dataclasses.MISSING):
            if isinstance(value, tuple):
                value = list(value)
            if not isinstance(value, list):
                raise ValueError(value)
    except (TypeError, ValueError):
        tname = ftype.__name__ if ftype else ("list" if f.default_factory is not dataclasses.MISSING else "value")
        raise ConfigError(f"{key}: expected a {tname}, got {value!r}") from None
    if isinstance(value, list):
        value = _check_items(key, value, meta.get("items"), meta.get("length"))
    if meta.get("choices") is not None and value not in meta["choices"]:
        raise ConfigError(f"{key}: {value!r} is not one of {list(meta['choices'])}")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        lo, hi = meta.get("min"), meta.get("max")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise ConfigError(f"{key}: {value!r} is outside [{lo}, {hi}]{(' ' + meta['unit']) if meta.get('unit') else ''}")
    return value


def _check_items(key: str, value: list, items: Any, length: int | None) -> list:
    """A list field's elements, checked like scalars (see :func:`param`); :class:`ConfigError` otherwise."""
    if length is not None and len(value) != length:
        raise ConfigError(f"{key}: expected a list of {length} elements, got {value!r}")
    out = []
    for i, v in enumerate(value):
        if items is float:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
                raise ConfigError(f"{key}[{i}]: expected a finite number, got {v!r}")
            v = float(v)
        elif items is str:
            if not isinstance(v, str):
                raise ConfigError(f"{key}[{i}]: expected a string, got {v!r}")
        elif isinstance(items, tuple) and v not in items:
            raise ConfigError(f"{key}[{i}]: {v!r} is not one of {list(items)}")
        out.append(v)
    return out


def validate_section(section: str, obj: Any) -> None:
    """Check every field of a section instance; raise :class:`ConfigError` on the first bad one."""
    for f in dataclasses.fields(obj):
        setattr(obj, f.name, coerce_value(section, f, getattr(obj, f.name)))
