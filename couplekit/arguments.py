"""Checks of plain arguments that the solvers, the schedulers and :class:`couplekit.simulation.Simulation` share:
one rule for what a count of steps is and what a number is, one message for each."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

__all__ = ["is_real", "whole_count", "flag", "callable_or_none"]


def is_real(value: Any) -> bool:
    """A real number that is not a bool (``True`` is not a viscosity): int, float, NumPy integer or float."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def whole_count(name: str, value: Any, least: int = 0, what: str = "steps") -> int:
    """``value`` as a whole number >= ``least``, else a TypeError / ValueError naming ``name``: a float or NumPy
    integer with a whole value is a count; ``True``, ``2.9``, ``"3"``, NaN and ``-1`` are not (``int(n)`` once took
    2 steps for 2.9 and none for -1). ``what``: what is counted, for the message."""
    if not is_real(value):
        raise TypeError(f"{name} must be a whole number of {what}, got {value!r} ({type(value).__name__})")
    if not float(value).is_integer():
        raise ValueError(f"{name} must be a whole number, got {value!r}")
    if value < least:
        raise ValueError(f"{name} must be {least} or more, got {value!r}")
    return int(value)


def flag(name: str, value: Any) -> bool:
    """``value`` as a bool, else a TypeError naming ``name``: only ``True``/``False`` (NumPy's too). A string such
    as ``"no"`` is truthy, so ``overwrite="no"`` once deleted an earlier run."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r} ({type(value).__name__})")
    return bool(value)


def callable_or_none(name: str, value: Any, what: str) -> Any:
    """``value`` if it is callable or None, else a TypeError naming ``name`` and ``what`` it is called with."""
    if value is not None and not callable(value):
        raise TypeError(f"{name} must be a function {what} (or None), got {value!r} ({type(value).__name__})")
    return value
