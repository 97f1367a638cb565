"""Running a sweep on Dask: one task per point, results written as they finish, resumable.

:func:`run_point` is the task (a module-level function of plain dicts, so that any Dask worker with couplekit
installed can unpickle it); :func:`run_sweep` validates the sweep, refuses an output folder that holds another
sweep's results, skips points already finished in the output folder, submits the rest to a ``LocalCluster``
(or the scheduler at ``address``), writes every finished point to ``<out>/points/<id>.json`` at once, and
writes the results table at the end.

A sweep folder belongs to the sweep its ``sweep.json`` records: the sweep's ``name`` and ``base`` (where its
base scene comes from, :attr:`SweepSpec.base`) identify it. Running another sweep there (another name or base
scene) would overwrite the points the two share (same overrides, same id) and replace the results table, so
it is refused with a :class:`~couplekit.sweep.SweepError` before anything is written. Everything else may
change between runs of the same sweep: points added to or dropped from a grid or a case, an edited base scene
file, other ``frames``, ``backend`` or ``threads`` (finished points whose scene, frames or backend changed
run again).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import socket
import sys
import time
import traceback
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TextIO

from ..scene.schema import Problem
from .spec import (
    REFERENCE_ID,
    SweepError,
    SweepPoint,
    SweepSpec,
    finite_or_none,
    is_final,
    load_sweep,
    point_fingerprint,
)
from .table import build_rows, write_results

__all__ = ["DaskUnavailableError", "require_dask", "run_point", "run_sweep", "point_task"]

INSTALL_HINT = "pip install 'couplekit[sweep]'"


class DaskUnavailableError(ImportError):
    """dask.distributed (the ``sweep`` extra) is not installed."""


def require_dask() -> None:
    """Raise :class:`DaskUnavailableError` (saying how to install it) when dask.distributed cannot be imported."""
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        raise DaskUnavailableError(
            f"sweeps run on dask.distributed, which is not installed ({exc}): {INSTALL_HINT}"
        ) from None


# ------------------------------------------------------------------------------------------------ the task
def point_task(spec: SweepSpec, point: SweepPoint, out: Path) -> dict[str, Any]:
    """The plain-dict task of ``point`` (what :func:`run_point` receives on a worker)."""
    return {
        "id": point.id,
        "name": point.name,
        "case": point.case,
        "overrides": point.overrides,
        "scene": point.scene,
        "scene_dir": spec.scene_dir,
        "source_name": f"{spec.source}: point {point.name!r}",
        "frames": point.frames,
        "backend": spec.backend,
        "threads": spec.threads,
        "run_dir": str(out / "points" / point.id / "run"),
        "fingerprint": point_fingerprint(point, spec.backend),
    }


def _record(task: Mapping[str, Any], status: str, error: str | None = None, **fields: Any) -> dict[str, Any]:
    rec = {k: task[k] for k in ("id", "name", "case", "overrides", "fingerprint")}
    rec.update(status=status, error=error, wall_s=None, setup_s=None, steps=None, frames=None)
    rec.update(diagnostics=[], cost={}, host=None, run_dir=None)
    rec.update(fields)
    return rec


def _relative_run_dir(run_dir: Path) -> str:
    """``points/<id>/run``: the run folder relative to the sweep folder."""
    return str(Path(*run_dir.parts[-3:]))


def run_point(task: dict[str, Any]) -> dict[str, Any]:
    """Run one sweep point (a Dask task): build the scene, run it into ``task["run_dir"]`` and return its result.

    The result holds ``id``, ``name``, ``case``, ``overrides``, ``status`` ("done", "diverged", "interrupted",
    or "error" for any exception, with ``error`` and ``traceback``), ``wall_s`` (seconds of
    ``Simulation.run``), ``setup_s`` (building the solvers), ``steps``, ``frames``, ``diagnostics`` (the
    per-frame records of ``diagnostics.jsonl``), ``cost`` (``Simulation.cost_report()``), ``host``. It never
    raises for a failing point."""
    from ..io import read_diagnostics
    from ..scene import Scene, SceneError
    from ..simulation import Simulation

    run_dir = Path(task["run_dir"])
    host = socket.gethostname()
    try:
        scene = Scene.from_dict(task["scene"], base_dir=task["scene_dir"], source_name=task["source_name"])
    except SceneError as exc:  # it validated where the sweep was read: a file the scene names is missing here?
        return _record(task, "error", f"the scene is refused on worker {host}: {exc}", host=host)
    try:
        if run_dir.exists():
            shutil.rmtree(run_dir)  # a clean folder: no files left by an earlier, failed run of this point
        t0 = time.perf_counter()
        sim = Simulation(scene, backend=task["backend"], threads=task["threads"], log=None)
        setup = time.perf_counter() - t0
        t0 = time.perf_counter()
        result = sim.run(frames=task["frames"], out=run_dir, progress=False, summary=False)  # no PNG (spec.py)
        wall = time.perf_counter() - t0
        log = run_dir / "diagnostics.jsonl"
        return _record(
            task,
            result.status,
            result.get("error"),
            wall_s=wall,
            setup_s=setup,
            steps=result.get("steps"),
            frames=result.get("frames"),
            diagnostics=read_diagnostics(log) if log.is_file() else [],
            cost=sim.cost_report(),
            host=host,
            run_dir=_relative_run_dir(run_dir),
        )
    except Exception as exc:
        return _record(task, "error", f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(), host=host)


def _crashed(task: Mapping[str, Any], exc: BaseException) -> dict[str, Any]:
    """The record of a point whose task did not return (its worker died, the scheduler went away)."""
    return _record(task, "error", f"the task failed on the cluster: {type(exc).__name__}: {exc}")


def _invalid(spec: SweepSpec, point: SweepPoint) -> dict[str, Any]:
    task = {
        "id": point.id,
        "name": point.name,
        "case": point.case,
        "overrides": point.overrides,
        "fingerprint": point_fingerprint(point, spec.backend),
    }
    return _record(task, "invalid", point.invalid)


# ------------------------------------------------------------------------------------------------ point files
def _point_file(out: Path, point_id: str) -> Path:
    return out / "points" / f"{point_id}.json"


def write_point(out: Path, record: Mapping[str, Any]) -> dict[str, Any]:
    """Write ``<out>/points/<id>.json`` (atomically; non-finite floats as null); returns the record as read back."""
    clean = finite_or_none(dict(record))
    path = _point_file(out, clean["id"])
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(clean, indent=1) + "\n")
    os.replace(tmp, path)
    return json.loads(path.read_text())


def read_point(out: Path, point_id: str) -> dict[str, Any] | None:
    """The stored result of a point, or None (no file, or a file that cannot be read)."""
    path = _point_file(out, point_id)
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


# ------------------------------------------------------------------------------------------------ the cluster
@contextlib.contextmanager
def _open_client(
    address: str | None, workers: int | None, threads: int, client: Any = None
) -> Iterator[tuple[Any, str]]:
    """(dask Client, description): ``client`` as given, the scheduler at ``address``, or a new LocalCluster."""
    if client is not None:
        yield client, "the given Dask client"
        return
    from distributed import Client, LocalCluster

    if address:
        with Client(address) as c:
            yield c, f"the scheduler at {address}"
        return
    n = workers or max(1, (os.cpu_count() or 1) // max(1, threads))
    with (
        LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster,
        Client(cluster) as c,
    ):
        yield c, f"a LocalCluster of {n} worker process{'es' if n != 1 else ''}"


# ------------------------------------------------------------------------------------------------ reporting
class _Reporter:
    """Progress lines on ``stream`` (stderr by default); silent when ``enabled`` is false."""

    def __init__(self, enabled: bool, stream: TextIO | None):
        self.enabled, self.stream = enabled, stream

    def __call__(self, line: str) -> None:
        if self.enabled:
            stream = self.stream if self.stream is not None else sys.stderr
            stream.write(line + "\n")
            stream.flush()


def _first_line(text: str | None, limit: int = 200) -> str:
    line = (text or "").strip().splitlines()[:1]
    line = line[0] if line else ""
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _first_problem(scene_error: str) -> str:
    """The first ``  - key: message`` line of a SceneError text (or its first line)."""
    lines = [ln.strip()[2:] for ln in scene_error.splitlines() if ln.strip().startswith("- ")]
    return _first_line(lines[0] if lines else scene_error)


def _finished_line(i: int, n: int, rec: Mapping[str, Any]) -> str:
    status, wall = rec.get("status"), rec.get("wall_s")
    text = f"[{i}/{n}] {rec['name']}: {status}"
    if isinstance(wall, (int, float)):
        text += f" in {wall:.3g} s"
    if status != "done" and rec.get("error"):
        text += f": {_first_line(rec['error'])}"
    return text


def _summary(rows: list[dict[str, Any]]) -> str:
    counts: dict[str, int] = {}
    for row in rows:
        counts[row["status"]] = counts.get(row["status"], 0) + 1
    return ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))


# ------------------------------------------------------------------------------------------------ the sweep
def _as_spec(sweep: str | Path | SweepSpec) -> SweepSpec:
    return sweep if isinstance(sweep, SweepSpec) else load_sweep(sweep)


def _write_plan(out: Path, spec: SweepSpec) -> None:
    """``<out>/sweep.json`` (atomically): the sweep's name, source and base scene (what identifies it, see
    :func:`_check_folder`), and the expanded sweep (every point's id, name, overrides, frames, validity)."""
    plan = {
        "name": spec.name,
        "source": spec.source,
        "base": spec.base,
        "backend": spec.backend,
        "threads": spec.threads,
        "keys": list(spec.keys),
        "points": [
            {
                "id": p.id,
                "name": p.name,
                "case": p.case,
                "overrides": p.overrides,
                "frames": p.frames,
                "invalid": p.invalid,
            }
            for p in spec.all_points()
        ],
    }
    tmp = out / "sweep.json.tmp"
    tmp.write_text(json.dumps(finite_or_none(plan), indent=1) + "\n")
    os.replace(tmp, out / "sweep.json")


def _differ(recorded: str, current: str) -> tuple[str, str]:
    """Two base scenes as shown in a message: their file names, or the whole paths when those are the same."""
    a, b = Path(recorded).name, Path(current).name
    return (a, b) if a != b else (recorded, current)


def _check_folder(out: Path, spec: SweepSpec) -> None:
    """Refuse ``out`` (a :class:`SweepError` naming the folder, what differs and the fix) when its ``sweep.json``
    records another sweep: another ``name``, or another ``base`` scene (a ``sweep.json`` written before the
    base was recorded is compared by name only). A ``sweep.json`` that cannot be read is refused too, since
    whose results the folder holds is then unknown. Nothing is written here."""
    path = out / "sweep.json"
    if not path.exists():
        return
    try:
        plan = json.loads(path.read_text())
        why = "it is not a JSON object"
    except (OSError, ValueError) as exc:
        plan, why = None, f"{type(exc).__name__}: {exc}"
    fix = f"run this sweep into a new folder (a new --out), or delete {out} to replace what it holds"
    if not isinstance(plan, dict):
        problem = f"{out} holds a sweep.json that cannot be read ({why}), so whose results the folder holds is unknown"
        raise SweepError([Problem("(folder)", problem, fix)], spec.source)
    differs = []
    name, base = plan.get("name"), plan.get("base")
    if isinstance(name, str) and name != spec.name:
        differs.append(f"sweep.name {name!r}, not {spec.name!r}")
    if isinstance(base, str) and base and spec.base and base != spec.base:
        differs.append("base scene {}, not {}".format(*_differ(base, spec.base)))
    if differs:
        problem = (
            f"{out} holds the results of another sweep ({'; '.join(differs)}): running this one there would "
            "overwrite the points they share and replace its results table"
        )
        raise SweepError([Problem("(folder)", problem, fix)], spec.source)


def _plan_runs(spec: SweepSpec, out: Path, say: _Reporter) -> tuple[dict[str, dict], list[dict]]:
    """(records already final, tasks to run): invalid points are recorded now, finished ones are skipped."""
    records: dict[str, dict] = {}
    tasks: list[dict] = []
    skipped = changed = 0
    for point in spec.all_points():
        if point.invalid is not None:
            records[point.id] = write_point(out, _invalid(spec, point))
            say(f"invalid: {point.name}: {_first_problem(point.invalid)}")
            continue
        task = point_task(spec, point, out)
        old = read_point(out, point.id)
        if old is not None and is_final(old.get("status")):
            if old.get("fingerprint") == task["fingerprint"]:
                records[point.id] = old
                skipped += 1
                continue
            changed += 1
        tasks.append(task)
    if skipped:
        say(
            f"skipped {skipped} point{'s' if skipped != 1 else ''} already finished in {out} (delete points/<id>.json to run one again)"
        )
    if changed:
        say(
            f"running {changed} finished point{'s' if changed != 1 else ''} again: their scene, frames or backend changed"
        )
    return records, tasks


def _run_tasks(
    tasks: list[dict], out: Path, records: dict[str, dict], say: _Reporter, address, workers, threads, client
) -> None:
    """Submit ``tasks`` (the reference first) and record each point as it finishes."""
    from distributed import as_completed

    with _open_client(address, workers, threads, client) as (c, where):
        say(
            f"running {len(tasks)} point{'s' if len(tasks) != 1 else ''} on {where} ({threads} OpenMP thread{'s' if threads != 1 else ''} each)"
        )
        futures = {}
        for task in tasks:
            key = f"couplekit-sweep-{task['id']}-{uuid.uuid4().hex[:8]}"
            priority = 1 if task["id"] == REFERENCE_ID else 0
            futures[c.submit(run_point, task, key=key, pure=False, priority=priority)] = task
        try:
            for i, future in enumerate(as_completed(futures), 1):
                task = futures[future]
                try:
                    rec = future.result()
                except Exception as exc:  # the worker died or the scheduler went away: record it, go on
                    rec = _crashed(task, exc)
                rec = write_point(out, rec)
                records[rec["id"]] = rec
                say(_finished_line(i, len(tasks), rec))
        except BaseException:
            c.cancel(list(futures))
            raise


def run_sweep(
    sweep: str | Path | SweepSpec,
    out: str | Path | None = None,
    address: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    *,
    threads: int | None = None,
    backend: str | None = None,
    client: Any = None,
    stream: TextIO | None = None,
) -> list[dict[str, Any]]:
    """Run every point of a sweep (a sweep file path or a :class:`SweepSpec`) and return the results rows.

    out: the sweep folder (default ``runs/sweeps/<name>``): ``points/<id>.json`` per point, ``points/<id>/run``
    its run outputs, ``sweep.json`` (the expanded sweep), ``results.parquet`` (or ``.csv``) and ``results.json``.
    address: ``HOST:PORT`` of a running Dask scheduler; default a ``LocalCluster`` of ``workers`` processes
    (default cpu_count // threads) with one thread each. client: an open ``distributed.Client`` to use instead.
    threads, backend: replace the sweep file's. progress: one line per finished point on ``stream`` (stderr).

    Points already finished in ``out`` (a JSON file with status done, diverged or invalid, for the same scene)
    are not run again; no cluster is started when nothing is left to run. A point that fails is recorded
    with status "error" and the others go on. Raises :class:`~couplekit.sweep.SweepError` for a malformed
    sweep, and before anything is written when ``out`` holds another sweep's results (its ``sweep.json``
    records another sweep name or base scene: give this sweep its own folder, or delete that one), and
    :class:`DaskUnavailableError` when dask.distributed is missing.
    """
    spec = _as_spec(sweep)
    spec = dataclasses.replace(spec, threads=threads or spec.threads, backend=backend or spec.backend)
    out = Path(out if out is not None else Path("runs") / "sweeps" / spec.name).resolve()
    _check_folder(out, spec)  # another sweep's folder is refused before anything is written into it
    (out / "points").mkdir(parents=True, exist_ok=True)
    say = _Reporter(progress, stream)
    say(f"{spec.describe()}; folder {out}")
    _write_plan(out, spec)
    records, tasks = _plan_runs(spec, out, say)
    if tasks:
        require_dask()
        try:
            _run_tasks(tasks, out, records, say, address, workers, spec.threads, client)
        except KeyboardInterrupt:  # the points finished so far go into the table too (a probe, session 25)
            table = write_results(out, build_rows(spec, records))
            say(f"{spec.name}: interrupted; {len(records)} of {len(spec.all_points())} points in {table}")
            raise
    reference = records.get(REFERENCE_ID)
    if spec.reference is not None and reference is not None and reference.get("status") != "done":
        say(f"warning: the reference run ended {reference.get('status')!r}; errors are measured on the frames it has")
    rows = build_rows(spec, records)
    table = write_results(out, rows)
    say(f"{spec.name}: {_summary(rows)}; results in {table}")
    return rows
