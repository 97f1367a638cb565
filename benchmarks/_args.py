"""Argument types shared by the benchmark scripts (not a benchmark itself).

Each factory returns an argparse ``type=`` function that raises :class:`argparse.ArgumentTypeError` with the
allowed range, so that a bad value is refused by argparse itself: usage, one line naming the option, exit
status 2, before anything runs or is written."""

from __future__ import annotations

import argparse
import math
import re


def _bounds(lo, hi, lo_open: bool, hi_open: bool) -> str:
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def int_in(lo: int, hi: int | None = None, why: str = ""):
    """An integer ``lo <= v`` (``<= hi`` too when given); ``why`` is added to the message."""
    note = f" ({why})" if why else ""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = None
        if v is None or v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"must be an integer {_bounds(lo, hi, False, False)}{note}, got {text!r}")
        return v

    return parse


def float_in(lo: float, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False, why: str = ""):
    """A finite number in the range ``lo`` … ``hi`` (``hi`` None: unbounded above), open ends as flagged."""
    note = f" ({why})" if why else ""

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        ok = math.isfinite(v) and (v > lo if lo_open else v >= lo)
        if ok and hi is not None:
            ok = v < hi if hi_open else v <= hi
        if not ok:
            raise argparse.ArgumentTypeError(
                f"must be a number {_bounds(lo, hi, lo_open, hi_open)}{note}, got {text!r}"
            )
        return v

    return parse


def positive_float(why: str = ""):
    return float_in(0.0, lo_open=True, why=why)


def shape3(min_extent: int, sep: str = ",", label: str = "nz,ny,nx"):
    """Three integers ``>= min_extent`` separated by ``sep`` (e.g. ``24,16,16``), returned as a tuple."""

    def parse(text: str) -> tuple[int, int, int]:
        parts = text.split(sep)
        try:
            shape = tuple(int(v) for v in parts)
        except ValueError:
            shape = ()
        if len(shape) != 3 or min(shape) < min_extent:
            raise argparse.ArgumentTypeError(f"must be three integers {label}, each >= {min_extent}, got {text!r}")
        return shape

    return parse


def one_of(kind: str, names) -> callable:
    """One of ``names`` (an ``unknown KIND`` message listing them otherwise)."""
    names = list(names)

    def parse(text: str) -> str:
        if text not in names:
            raise argparse.ArgumentTypeError(f"unknown {kind} {text!r}; valid: {', '.join(map(repr, names))}")
        return text

    return parse


def float_list(lo: float, *, lo_open: bool = True, why: str = ""):
    """Comma-separated numbers, each as :func:`float_in` (``lo``, unbounded above)."""
    one = float_in(lo, lo_open=lo_open, why=why)

    def parse(text: str) -> list[float]:
        try:
            return [one(v) for v in text.split(",")]
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"each comma-separated value {exc}") from None

    return parse


def name_list(kind: str, names):
    """Comma-separated names, each one of ``names``."""
    one = one_of(kind, names)

    def parse(text: str) -> list[str]:
        return [one(v) for v in text.split(",")]

    return parse


def cuda_arch(text: str) -> str:
    """An nvcc real architecture such as ``sm_80``."""
    if not re.fullmatch(r"sm_\d{2,3}[a-z]?", text):
        raise argparse.ArgumentTypeError(f"must be an nvcc architecture such as sm_80 or sm_90, got {text!r}")
    return text


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (a SceneError lists its problems over several)."""
    return " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
