"""Error metrics of a sweep point against the reference run, and stability flags, from the per-frame
diagnostics series (``diagnostics.jsonl``, :meth:`couplekit.simulation.Simulation.diagnostics`).

Frames are compared at the simulated times both runs have (``time`` equal within 1e-9 relative; the frame
times are the same when every ``time.dt`` divides ``time.frame_duration``, since a frame is a whole number of
steps). The initial frame (t = 0) is left out: it is the starting state, not a result of the time stepping.
Entries that are missing, None or NaN in either run are skipped per metric; a metric with no usable frame is
NaN.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["ERROR_METRICS", "LATTICE_SPEED_LIMIT", "compare_with_reference", "stability", "series_mean"]

Record = dict[str, Any]

ERROR_METRICS = (
    "error_centroid_path",
    "error_sand_front",
    "error_sand_top",
    "error_fluid_volume",
    "error_free_surface",
    "error_kinetic_energy",
)
"""The error columns of the results table."""

LATTICE_SPEED_LIMIT = 0.3
"""A run whose ``max_lattice_speed`` exceeds this (lattice units) is flagged ``unstable``."""

_CENTROID = ("sand_centroid_x", "sand_centroid_y", "sand_centroid_z")
_TIME_RTOL = 1e-9


def _number(record: Record, key: str) -> float | None:
    """A finite float of the record, or None."""
    v = record.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def matched_frames(series: Sequence[Record], reference: Sequence[Record]) -> list[tuple[Record, Record]]:
    """(point record, reference record) pairs at the same simulated time, t = 0 left out."""
    pairs = []
    ref = [(t, r) for r in reference if (t := _number(r, "time")) is not None and t > 0.0]
    for rec in series:
        t = _number(rec, "time")
        if t is None or t <= 0.0:
            continue
        match = next((r for tr, r in ref if math.isclose(t, tr, rel_tol=_TIME_RTOL, abs_tol=0.0)), None)
        if match is not None:
            pairs.append((rec, match))
    return pairs


def _rms(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else math.nan


def _differences(pairs: list[tuple[Record, Record]], diff: Callable[[Record, Record], float | None]) -> list[float]:
    out = []
    for rec, ref in pairs:
        d = diff(rec, ref)
        if d is not None and math.isfinite(d):
            out.append(d)
    return out


def _scalar_diff(key: str, relative: bool = False) -> Callable[[Record, Record], float | None]:
    def diff(rec: Record, ref: Record) -> float | None:
        a, b = _number(rec, key), _number(ref, key)
        if a is None or b is None:
            return None
        if relative:
            return (a - b) / b if b != 0.0 else None
        return a - b

    return diff


def _centroid_distance(rec: Record, ref: Record) -> float | None:
    a = [_number(rec, k) for k in _CENTROID]
    b = [_number(ref, k) for k in _CENTROID]
    if None in a or None in b:
        return None
    return math.dist(a, b)  # type: ignore[arg-type]


def _kinetic_energy_error(pairs: list[tuple[Record, Record]]) -> float:
    """RMS difference of total_kinetic_energy_si over the RMS of the reference's values (same frames)."""
    key = "total_kinetic_energy_si"
    usable = [
        (a, b) for rec, ref in pairs if (a := _number(rec, key)) is not None and (b := _number(ref, key)) is not None
    ]
    if not usable:
        return math.nan
    diff = _rms([a - b for a, b in usable])
    scale = _rms([b for _, b in usable])
    if scale == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return diff / scale


def compare_with_reference(series: Sequence[Record], reference: Sequence[Record]) -> dict[str, float | int]:
    """The error metrics of one run's diagnostics ``series`` against the ``reference`` series, and
    ``matched_frames`` (frames compared).

    ``error_centroid_path``: RMS over frames of the distance between the sand centroids (m);
    ``error_sand_front``, ``error_sand_top``, ``error_free_surface``: RMS differences (m);
    ``error_fluid_volume``: RMS of the relative difference of ``fluid_volume``; ``error_kinetic_energy``: RMS
    difference of ``total_kinetic_energy_si`` over the reference's RMS value."""
    pairs = matched_frames(series, reference)
    return {
        "matched_frames": len(pairs),
        "error_centroid_path": _rms(_differences(pairs, _centroid_distance)),
        "error_sand_front": _rms(_differences(pairs, _scalar_diff("sand_front"))),
        "error_sand_top": _rms(_differences(pairs, _scalar_diff("sand_top"))),
        "error_fluid_volume": _rms(_differences(pairs, _scalar_diff("fluid_volume", relative=True))),
        "error_free_surface": _rms(_differences(pairs, _scalar_diff("free_surface_height"))),
        "error_kinetic_energy": _kinetic_energy_error(pairs),
    }


def no_comparison() -> dict[str, float | int]:
    """The metric columns of a point that has no reference (or no series) to compare: NaN, 0 frames."""
    return {"matched_frames": 0, **{k: math.nan for k in ERROR_METRICS}}


def series_max(series: Sequence[Record], key: str) -> float:
    """Largest finite value of ``key`` over the frames (NaN when none has it)."""
    values = [v for r in series if (v := _number(r, key)) is not None]
    return max(values) if values else math.nan


def series_mean(series: Sequence[Record], key: str, skip_initial: bool = True) -> float:
    """Mean finite value of ``key`` over the frames (the initial frame, step 0, left out by default)."""
    values = [
        v for r in series if (v := _number(r, key)) is not None and not (skip_initial and _number(r, "step") == 0.0)
    ]
    return sum(values) / len(values) if values else math.nan


def stability(series: Sequence[Record], status: str) -> dict[str, Any]:
    """``unstable`` (the run diverged, or ``max_lattice_speed`` exceeded :data:`LATTICE_SPEED_LIMIT`) and
    ``max_lattice_speed`` (max over the frames; NaN for a scene without fluid)."""
    speed = series_max(series, "max_lattice_speed")
    return {"unstable": status == "diverged" or (speed > LATTICE_SPEED_LIMIT), "max_lattice_speed": speed}
