"""Parameter sweeps: many runs of one scene over a grid of parameter values, run on Dask.

>>> from couplekit.sweep import load_sweep, run_sweep, load_results
>>> spec = load_sweep("examples/sweeps/tiny_substeps.toml")   # SweepError names every bad key and the fix
>>> rows = run_sweep(spec, "runs/sweeps/tiny_substeps")        # a LocalCluster; address="HOST:PORT" for a cluster
>>> load_results("runs/sweeps/tiny_substeps")                 # the results table, one dict per point

A sweep file (TOML, docs/sweeps.md) names a base scene, dotted-key overrides for every point (``[sweep.set]``),
a grid (``[sweep.grid]``: the product over lists of values), optional cases (``[[sweep.cases]]``, each with its
own set and grid) and an optional reference run (``[sweep.reference]``) that every point is compared with.

* :mod:`.spec` — :func:`load_sweep`, :func:`parse_sweep`, :class:`SweepSpec`, :class:`SweepPoint`,
  :class:`SweepError`;
* :mod:`.keys` — dotted scene keys (``time.dt``, ``bodies[0].density``): parsing, schema check, setting;
* :mod:`.runner` — :func:`run_sweep` (Dask, resumable) and :func:`run_point` (the task);
* :mod:`.metrics` — error metrics against the reference and stability flags;
* :mod:`.table` — the results table (Parquet, CSV, JSON) and :func:`load_results`.
"""

from __future__ import annotations

from .keys import KeyPathError, check_key, parse_key, set_key
from .metrics import ERROR_METRICS, LATTICE_SPEED_LIMIT, compare_with_reference, stability
from .runner import DaskUnavailableError, require_dask, run_point, run_sweep
from .spec import (
    BACKENDS,
    FINAL_STATUSES,
    OUTPUT_DEFAULTS,
    REFERENCE_ID,
    SweepError,
    SweepPoint,
    SweepSpec,
    is_final,
    load_sweep,
    parse_sweep,
)
from .table import build_rows, load_results, write_results

__all__ = [
    "BACKENDS",
    "DaskUnavailableError",
    "ERROR_METRICS",
    "FINAL_STATUSES",
    "KeyPathError",
    "LATTICE_SPEED_LIMIT",
    "OUTPUT_DEFAULTS",
    "REFERENCE_ID",
    "SweepError",
    "SweepPoint",
    "SweepSpec",
    "build_rows",
    "check_key",
    "compare_with_reference",
    "is_final",
    "load_results",
    "load_sweep",
    "parse_key",
    "parse_sweep",
    "require_dask",
    "run_point",
    "run_sweep",
    "set_key",
    "stability",
    "write_results",
]
