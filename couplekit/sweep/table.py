"""The results table of a sweep: one row per point (and the reference), written as ``results.parquet``
(``results.csv`` where pyarrow is not installed) and ``results.json``; :func:`load_results` reads it back.

Columns: ``id``, ``name``, ``case``, ``status``, ``error``; one column per overridden dotted key (named by the
key; a value that is not a number, string or boolean, e.g. a vector, is stored as JSON text in the Parquet and
CSV files); ``wall_s`` (seconds of ``Simulation.run``), ``setup_s`` (building the solvers), ``steps``, ``frames``,
``matched_frames`` and the error metrics against the reference (:mod:`couplekit.sweep.metrics`),
``unstable``, ``max_lattice_speed``, ``sand_steps_per_step`` (mean over the frames), ``cost_<stage>_ms`` (mean
milliseconds per step of each stage, :meth:`couplekit.simulation.Simulation.cost_report`), ``host`` and
``run_dir`` (relative to the sweep folder).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .metrics import ERROR_METRICS, compare_with_reference, no_comparison, series_mean, stability
from .spec import REFERENCE_ID, SweepSpec, finite_or_none

__all__ = ["build_rows", "write_results", "load_results", "FLOAT_COLUMNS"]

FLOAT_COLUMNS = ("wall_s", "setup_s", *ERROR_METRICS, "max_lattice_speed", "sand_steps_per_step")
"""Columns that are floats (NaN where not measured), besides the ``cost_*_ms`` columns."""


def _cost_columns(records: Sequence[Mapping[str, Any]]) -> list[str]:
    stages: dict[str, None] = {}
    for rec in records:
        for stage in rec.get("cost") or {}:
            stages[stage] = None
    return [f"cost_{stage}_ms" for stage in stages]


def _float(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def _row(
    spec: SweepSpec, rec: Mapping[str, Any], reference: Mapping[str, Any] | None, cost_columns: list[str]
) -> dict[str, Any]:
    series = rec.get("diagnostics") or []
    status = rec.get("status")
    row: dict[str, Any] = {k: rec.get(k) for k in ("id", "name", "case", "status", "error")}
    overrides = rec.get("overrides") or {}
    row.update({key: overrides.get(key) for key in spec.keys})
    row.update(
        wall_s=_float(rec.get("wall_s")),
        setup_s=_float(rec.get("setup_s")),
        steps=rec.get("steps"),
        frames=rec.get("frames"),
    )
    ref_series = (reference or {}).get("diagnostics") or []
    row.update(compare_with_reference(series, ref_series) if series and ref_series else no_comparison())
    if series or status == "diverged":
        row.update(stability(series, status or ""))
    else:
        row.update(unstable=None, max_lattice_speed=math.nan)
    row["sand_steps_per_step"] = series_mean(series, "sand_steps_per_step")
    cost = rec.get("cost") or {}
    for column in cost_columns:
        stage = column[len("cost_") : -len("_ms")]
        row[column] = 1e3 * _float(cost[stage].get("mean")) if stage in cost else math.nan
    row["host"] = rec.get("host")
    row["run_dir"] = rec.get("run_dir")
    return row


def build_rows(spec: SweepSpec, records: Mapping[str, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The table rows of ``records`` (point id -> point result), in the sweep's order (reference first)."""
    ordered = [records[p.id] for p in spec.all_points() if p.id in records]
    reference = records.get(REFERENCE_ID) if spec.reference is not None else None
    costs = _cost_columns(ordered)
    return [_row(spec, rec, reference, costs) for rec in ordered]


# ------------------------------------------------------------------------------------------------ writing
def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _column_kind(values: Sequence[Any]) -> str:
    """'null', 'bool', 'int', 'float', 'str' or 'json' (anything else, stored as JSON text)."""
    present = [v for v in values if v is not None]
    if not present:
        return "null"
    if all(isinstance(v, bool) for v in present):
        return "bool"
    if all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return "int"
    if all(_is_number(v) for v in present):
        return "float"
    if all(isinstance(v, str) for v in present):
        return "str"
    return "json"


def _cell(v: Any, kind: str) -> Any:
    if v is None:
        return None
    if kind == "float":
        return float(v)
    if kind == "json":
        return json.dumps(v)
    return v


def _columns(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[Any]]:
    names = list(dict.fromkeys(k for row in rows for k in row))
    out = {}
    for name in names:
        values = [row.get(name) for row in rows]
        kind = _column_kind(values)
        out[name] = [_cell(v, kind) for v in values]
    return out


def _write_parquet(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = _columns(rows)
    pq.write_table(pa.table({name: pa.array(values) for name, values in columns.items()}), path)


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    columns = _columns(rows)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(list(columns))
        for i in range(len(rows)):
            writer.writerow(["" if values[i] is None else values[i] for values in columns.values()])


def write_results(out: str | Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write ``results.parquet`` (``results.csv`` without pyarrow) and ``results.json`` into ``out``; returns
    the path of the table file."""
    out = Path(out)
    (out / "results.json").write_text(json.dumps([finite_or_none(dict(r)) for r in rows], indent=1) + "\n")
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        path = out / "results.csv"
        _write_csv(path, rows)
        return path
    path = out / "results.parquet"
    _write_parquet(path, rows)
    return path


def _nan_for_missing(row: dict[str, Any]) -> dict[str, Any]:
    for key, value in row.items():
        if value is None and (key in FLOAT_COLUMNS or key.startswith("cost_")):
            row[key] = math.nan
    return row


def load_results(out: str | Path) -> list[dict[str, Any]]:
    """The rows of a sweep's results table (``results.parquet`` when pyarrow can read it, else
    ``results.json``); NaN where a float was not measured."""
    out = Path(out)
    parquet = out / "results.parquet"
    if parquet.is_file():
        try:
            import pyarrow.parquet as pq
        except ImportError:
            pass
        else:
            return [_nan_for_missing(r) for r in pq.read_table(parquet).to_pylist()]
    path = out / "results.json"
    if not path.is_file():
        raise FileNotFoundError(f"{out} holds no sweep results (results.parquet or results.json): run the sweep first")
    return [_nan_for_missing(r) for r in json.loads(path.read_text())]
