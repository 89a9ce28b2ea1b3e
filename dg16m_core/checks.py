"""Validation of scalar parameters, written once.

Parameter dataclasses (generator, benchmark, scene, trial) and keyword arguments check their
numbers with these functions, so every message has the same form ("NAME: expected X, found Y")
and every class raises its own error type.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

import numpy as np

from dg16m_core.errors import Dg16mError


def check_integer(
    name: str, value: Any, *, minimum: int = 0, error: type[Exception] = Dg16mError
) -> int:
    """``value`` as an int if it is an integer (not a bool) >= ``minimum``; else ``error``.

    Python and numpy integers are accepted and returned as ``int``.
    """
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, numbers.Integral)
        or value < minimum
    ):
        raise error(f"{name}: expected an integer >= {minimum}, found {value!r}")
    return int(value)


def check_number(
    name: str,
    value: Any,
    *,
    allow_zero: bool = False,
    error: type[Exception] = Dg16mError,
) -> float:
    """``value`` as a float if it is a finite number > 0 (>= 0 with ``allow_zero``); else ``error``.

    Python and numpy numbers are accepted and returned as ``float``; bools and strings are
    rejected (``True`` is not a mass).
    """
    ok = (
        not isinstance(value, (bool, np.bool_))
        and isinstance(value, numbers.Real)
        and math.isfinite(value)
        and (value > 0 or (allow_zero and value == 0))
    )
    if not ok:
        expected = "a finite number >= 0" if allow_zero else "a positive finite number"
        raise error(f"{name}: expected {expected}, found {value!r}")
    return float(value)


def check_fields(
    instance: Any,
    *,
    error: type[Exception],
    integers: dict[str, int] | None = None,
    zero_allowed: tuple[str, ...] = (),
    skip: tuple[str, ...] = (),
) -> None:
    """Check every field of a parameter dataclass.

    Fields named in ``integers`` must be integers >= the given minimum; fields in ``skip`` are
    left alone (strings, nested dataclasses, flags); every other field must be a positive finite
    number (>= 0 when named in ``zero_allowed``).
    """
    integers = integers or {}
    for f in fields(instance):
        if f.name in skip:
            continue
        value = getattr(instance, f.name)
        if f.name in integers:
            check_integer(f.name, value, minimum=integers[f.name], error=error)
        else:
            check_number(f.name, value, allow_zero=f.name in zero_allowed, error=error)


def known_fields(
    cls: type, data: Mapping[str, Any], *, what: str, error: type[Exception]
) -> dict[str, Any]:
    """``data`` as keyword arguments of the dataclass ``cls``, after checking that it is a
    mapping whose keys are all fields of ``cls`` (else ``error``, naming the unknown keys).

    Used by every ``from_dict`` of the parameter classes (scene, trial protocol, benchmark).
    """
    if not isinstance(data, Mapping):
        raise error(f"{what}: expected a mapping, found {type(data).__name__}")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise error(f"{what}: expected keys among {sorted(known)}, found unknown {unknown}")
    return dict(data)
