"""Validation of scalar parameters, written once.

Parameter dataclasses (generator, benchmark, scene, trial) and keyword arguments check their
numbers with these functions, so every message has the same form ("NAME: expected X, found Y")
and every class raises its own error type.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

from dataset_gen.errors import Dg16mError


def check_integer(
    name: str, value: Any, *, minimum: int = 0, error: type[Exception] = Dg16mError
) -> int:
    """``value`` as an int if it is an integer (not a bool) >= ``minimum``; else ``error``."""
    if isinstance(value, bool) or not isinstance(value, (int,)) or value < minimum:
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

    Bools are rejected (``True`` is not a mass).
    """
    ok = (
        not isinstance(value, bool)
        and isinstance(value, (int, float))
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
