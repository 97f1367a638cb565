"""The sweep file: read it, check every key, and expand it into points (one scene dict each).

:func:`load_sweep` reads a TOML sweep file and :func:`parse_sweep` checks its structure (a
:class:`SweepError` names every bad key as a dotted path in the sweep file, e.g. ``sweep.grid."time.dt"``, and
the fix), applies the overrides of every point to the base scene and validates each point's scene with
:meth:`couplekit.scene.Scene.from_dict`. A point whose scene is refused is kept with ``invalid`` set to the
:class:`~couplekit.scene.SceneError` text (it is recorded, never run); a refused reference scene is a
:class:`SweepError`, since every point is compared with it.

``sweep.frames`` replaces the base scene's ``time.frames`` in every point (and the reference); a sweep that
gives ``sweep.frames`` and also sets ``time.frames`` in a set, grid, case or reference is refused, since
``sweep.frames`` would silently replace those values too (a point named ``time.frames=2`` would run
``sweep.frames`` frames).

:attr:`SweepSpec.base` names where the base scene comes from (the resolved path of the ``sweep.base`` file, or
the inline ``[base]`` of the sweep file): with :attr:`SweepSpec.name` it identifies the sweep, so that a sweep
folder holding another sweep's results is refused (:mod:`couplekit.sweep.runner`).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import hashlib
import itertools
import json
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..backend import max_threads
from ..scene import Scene, SceneError
from ..scene.schema import Problem, ProblemError, read_toml
from .keys import KeyPathError, check_key, drop_replaced, flatten_keys, parse_key, set_key

__all__ = [
    "BACKENDS",
    "FINAL_STATUSES",
    "OUTPUT_DEFAULTS",
    "REFERENCE_ID",
    "SweepError",
    "SweepPoint",
    "SweepSpec",
    "load_sweep",
    "parse_sweep",
    "point_fingerprint",
]

SWEEP_KEYS = ("name", "base", "frames", "backend", "threads", "set", "grid", "cases", "reference")
"""Keys of the ``[sweep]`` table."""
CASE_KEYS = ("name", "set", "grid")
"""Keys of one ``[[sweep.cases]]`` entry."""
BACKENDS = ("auto", "cuda", "cpu", "numpy")
FINAL_STATUSES = ("done", "diverged", "invalid")
"""Statuses a resumed sweep does not run again ("error" and "interrupted" points run again)."""
OUTPUT_DEFAULTS: dict[str, Any] = {
    "outputs.preview": False,
    "outputs.vtk": False,
    "outputs.ply": False,
    "outputs.surface": False,
}
"""Applied to the base scene of every point before the sweep's own overrides: a sweep writes no PNG, VTK,
PLY or surface-mesh files unless its ``set``/``grid``/``reference`` turn them on."""
REFERENCE_ID = "reference"
"""The id (and name and case) of the reference point."""


class SweepError(ProblemError):
    """A sweep file was refused; ``problems`` lists every :class:`~couplekit.scene.Problem` found (their keys
    are dotted paths in the sweep file, e.g. ``sweep.grid."time.dt"``)."""

    def __init__(self, problems: list[Problem], source: str = "sweep file"):
        super().__init__(problems, source)


@dataclass(frozen=True)
class SweepPoint:
    """One run of a sweep.

    ``id``: a short hash of the sorted overrides (``"reference"`` for the reference); ``name``: the case name
    and the grid values (``"subcycle scheduler.substeps=4"``); ``overrides``: every dotted key the sweep set for
    this point and its value; ``scene``: the point's whole scene dict; ``frames``: frames to run;
    ``invalid``: the scene error text when the scene is refused (the point is not run)."""

    id: str
    name: str
    case: str
    overrides: dict[str, Any]
    scene: dict[str, Any] = field(repr=False)
    frames: int | None
    invalid: str | None = None


@dataclass(frozen=True)
class SweepSpec:
    """A checked, expanded sweep: ``points`` (in file order), the optional ``reference`` point, ``keys`` (every
    overridden dotted key, the order of the results table's columns), ``scene_dir`` (where the scenes'
    relative files resolve), and how to run (``backend``, ``threads`` per point, ``frames`` override).

    ``base``: where the base scene comes from, the resolved path of the ``sweep.base`` file or ``"the inline
    [base] of <sweep file name>"`` (empty when unknown). With ``name`` it identifies the sweep: a sweep folder
    whose ``sweep.json`` records another name or base belongs to another sweep, and is refused."""

    name: str
    source: str
    scene_dir: str
    backend: str
    threads: int
    frames: int | None
    points: tuple[SweepPoint, ...]
    reference: SweepPoint | None
    keys: tuple[str, ...]
    base: str = ""

    def all_points(self) -> list[SweepPoint]:
        """The reference (when there is one) first, then the points."""
        return ([self.reference] if self.reference is not None else []) + list(self.points)

    def describe(self) -> str:
        """One line: name, points, invalid points, reference."""
        invalid = sum(p.invalid is not None for p in self.points)
        return (
            f"sweep {self.name}: {len(self.points)} point{'s' if len(self.points) != 1 else ''}"
            + (f" ({invalid} invalid)" if invalid else "")
            + (" and a reference" if self.reference is not None else "")
        )


@dataclass
class _Case:
    name: str
    set: dict[str, Any]
    grid: dict[str, list]
    where: str  # "sweep.cases[i]", or "sweep" for the implicit case of a file without cases


# ------------------------------------------------------------------------------------------------ reading
def load_sweep(path: str | Path) -> SweepSpec:
    """Read, check and expand a TOML sweep file; raises :class:`SweepError` naming every bad key and the fix."""
    path = Path(path)
    data = read_toml(path, SweepError)
    return parse_sweep(data, base_dir=path.parent, source=str(path), default_name=path.stem)


def parse_sweep(
    data: dict[str, Any], base_dir: str | Path = ".", source: str = "sweep", default_name: str = "sweep"
) -> SweepSpec:
    """Check a sweep given as a dict (the TOML structure) and expand it into points.

    ``base_dir``: where ``sweep.base`` (and an inline ``[base]`` scene's files) resolve; ``source``: the name
    in messages; ``default_name``: the sweep's name when ``sweep.name`` is not given."""
    problems: list[Problem] = []
    sweep = _sweep_table(data, problems)
    name = _optional(sweep, "name", str, default_name, problems)
    frames = _optional(sweep, "frames", int, None, problems, lo=1)
    threads = _optional(sweep, "threads", int, 1, problems, lo=1)
    if threads > max_threads():  # each point's backend would refuse it (a probe: far more ended in a segfault)
        problems.append(
            Problem(
                "sweep.threads",
                f"{threads} is more than the {max_threads()} OpenMP threads couplekit starts on this machine",
                f"set sweep.threads to at most {os.cpu_count()} (the cores) divided among the workers",
            )
        )
        threads = 1
    backend = _optional(sweep, "backend", str, "auto", problems)
    if backend not in BACKENDS and not any(p.key == "sweep.backend" for p in problems):
        problems.append(Problem("sweep.backend", f"unknown backend {backend!r}", f"use one of {', '.join(BACKENDS)}"))
    if isinstance(name, str) and (not name or "/" in name or "\\" in name):
        problems.append(Problem("sweep.name", f"{name!r} cannot name a folder", 'use a short name such as "dt_sweep"'))
    base = _read_base(data, sweep, Path(base_dir), problems)
    global_set = _overrides(sweep.get("set", {}), "sweep.set", problems)
    global_grid = _grid(sweep.get("grid", {}), "sweep.grid", problems)
    cases = _cases(sweep.get("cases"), problems)
    reference = _overrides(sweep["reference"], "sweep.reference", problems) if "reference" in sweep else None
    if problems or base is None:
        raise SweepError(problems, source)

    base_scene, scene_dir, base_file = base
    base_label = str(base_file) if base_file is not None else f"the inline [base] of {Path(source).name}"
    _check_key_names(base_scene, global_set, global_grid, cases, reference, problems)
    _check_overlaps(global_set, global_grid, cases, problems)
    _check_frames(frames, global_set, global_grid, cases, reference, problems)
    _check_output_folder(global_set, global_grid, cases, reference, problems)
    if problems:
        raise SweepError(problems, source)

    points = _expand(base_scene, global_set, global_grid, cases, frames, problems)
    ref_point = None
    if reference is not None:
        ref_point = _reference_point(base_scene, global_set, reference, frames, problems)
    _check_duplicates(points, problems)
    if problems:
        raise SweepError(problems, source)

    points = [_validated(p, scene_dir, f"{source}: point {p.name!r}") for p in points]
    if ref_point is not None:
        ref_point = _validated_reference(ref_point, scene_dir, source)
    keys = _column_keys(global_set, global_grid, cases, reference)
    return SweepSpec(
        name=name, source=source, scene_dir=str(scene_dir), backend=backend, threads=threads, frames=frames,
        points=tuple(points), reference=ref_point, keys=keys, base=base_label,
    )  # fmt: skip


def point_fingerprint(point: SweepPoint, backend: str) -> str:
    """A hash of what determines a point's result (its scene, frames and backend): a resumed sweep runs a
    point again when its stored fingerprint differs (e.g. the base scene file was edited)."""
    text = json.dumps({"scene": point.scene, "frames": point.frames, "backend": backend}, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


# ------------------------------------------------------------------------------------------------ tables
def _type_name(v: Any) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a table"}
    return names.get(type(v), type(v).__name__)


def _toml(v: Any) -> str:
    """``v`` written as a TOML value (for fixes)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def _unknown_keys(table: dict, known: tuple[str, ...], where: str, problems: list[Problem]) -> None:
    for key in table:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1)
            fix = f"did you mean {close[0]!r}?" if close else f"remove it; the keys of [{where}] are {', '.join(known)}"
            problems.append(Problem(f"{where}.{key}", "unknown key", fix))


def _sweep_table(data: Any, problems: list[Problem]) -> dict[str, Any]:
    if not isinstance(data, dict):
        problems.append(Problem("(file)", "a sweep file must be a TOML table", "start from examples/sweeps/"))
        return {}
    for key in data:
        if key not in ("sweep", "base"):
            problems.append(
                Problem(
                    key, "unknown top-level table", "a sweep file holds [sweep] and, optionally, an inline [base] scene"
                )
            )
    sweep = data.get("sweep")
    if sweep is None:
        problems.append(Problem("sweep", "is required", "add a [sweep] table with base = ... and a [sweep.grid]"))
        return {}
    if not isinstance(sweep, dict):
        problems.append(Problem("sweep", f"must be a table, got {_type_name(sweep)}", "write it as [sweep]"))
        return {}
    _unknown_keys(sweep, SWEEP_KEYS, "sweep", problems)
    return sweep


def _optional(table: dict, key: str, kind: type, default: Any, problems: list[Problem], lo: int | None = None) -> Any:
    """``table[key]`` checked to be a ``kind`` (>= ``lo``), or ``default`` when absent."""
    if key not in table:
        return default
    value = table[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        what, example = {str: ("a string", '"text"'), int: ("an integer", "4")}[kind]
        problems.append(
            Problem(
                f"sweep.{key}",
                f"must be {what}, got {_type_name(value)} ({value!r})",
                f"write e.g. {key} = {example}",
            )
        )
        return default
    if lo is not None and value < lo:
        problems.append(Problem(f"sweep.{key}", f"must be >= {lo}, got {value}", f"set sweep.{key} to {lo} or more"))
        return default
    return value


def _read_base(
    data: dict, sweep: dict, base_dir: Path, problems: list[Problem]
) -> tuple[dict, Path, Path | None] | None:
    """(base scene dict, directory its files resolve against, the resolved scene file or None for an inline
    ``[base]``), checked with Scene.from_dict."""
    inline, ref = data.get("base"), sweep.get("base")
    if inline is not None and ref is not None:
        problems.append(
            Problem("sweep.base", "both sweep.base and an inline [base] scene are given", "keep one of them")
        )
        return None
    if inline is None and ref is None:
        problems.append(
            Problem(
                "sweep.base", "no base scene", 'add base = "path/to/scene.toml" to [sweep], or an inline [base] table'
            )
        )
        return None
    if inline is not None:
        found = _inline_base(inline, base_dir, problems)
    else:
        found = _base_file(ref, base_dir, problems)
    if found is None:
        return None
    scene, scene_dir, key, what, file = found
    try:
        Scene.from_dict(copy.deepcopy(scene), base_dir=scene_dir, source_name=what)
    except SceneError as exc:
        problems.extend(Problem(key, f"{what} is invalid: {p.key}: {p.message}", p.fix) for p in exc.problems)
        return None
    return scene, scene_dir, file


def _inline_base(
    inline: Any, base_dir: Path, problems: list[Problem]
) -> tuple[dict, Path, str, str, Path | None] | None:
    """(scene, scene dir, sweep-file key, description, None: no scene file) of an inline ``[base]`` table."""
    if not isinstance(inline, dict):
        problems.append(
            Problem("base", f"must be a table, got {_type_name(inline)}", "write the scene under [base.*] tables")
        )
        return None
    return inline, base_dir, "base", "the inline [base] scene", None


def _base_file(ref: Any, base_dir: Path, problems: list[Problem]) -> tuple[dict, Path, str, str, Path | None] | None:
    """(scene, scene dir, sweep-file key, description, resolved path) of the scene file ``sweep.base`` names."""
    if not isinstance(ref, str):
        problems.append(Problem("sweep.base", f"must be a string, got {_type_name(ref)}", 'write base = "scene.toml"'))
        return None
    path = Path(ref) if Path(ref).is_absolute() else base_dir / ref
    if not path.is_file():
        problems.append(
            Problem(
                "sweep.base",
                f"the base scene {path} does not exist",
                "give a scene file path relative to the sweep file",
            )
        )
        return None
    try:
        scene = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        problems.append(Problem("sweep.base", f"cannot read the base scene {path}: {exc}", "fix the scene file"))
        return None
    return scene, path.parent, "sweep.base", f"the base scene {path}", path.resolve()


def _overrides(table: Any, where: str, problems: list[Problem]) -> dict[str, Any]:
    """A table of dotted key -> value (``set``, ``reference``)."""
    if not isinstance(table, dict):
        problems.append(
            Problem(
                where,
                f"must be a table of dotted keys, got {_type_name(table)}",
                f'write [{where}] with lines "time.dt" = 1e-4',
            )
        )
        return {}
    return flatten_keys(table)


def _grid(table: Any, where: str, problems: list[Problem]) -> dict[str, list]:
    """A table of dotted key -> non-empty list of distinct values."""
    out = {}
    for key, values in _overrides(table, where, problems).items():
        at = f'{where}."{key}"'
        if not isinstance(values, list):
            problems.append(
                Problem(
                    at,
                    f"must be a list of values, got {_type_name(values)} ({_toml(values)})",
                    f'write "{key}" = [{_toml(values)}], or move it to the set table',
                )
            )
        elif not values:
            problems.append(
                Problem(
                    at,
                    "is an empty list (the sweep would have no points)",
                    f'give at least one value, e.g. "{key}" = [...], or remove it',
                )
            )
        else:
            twice = [v for i, v in enumerate(values) if v in values[:i]]
            if twice:
                problems.append(Problem(at, f"lists {_toml(twice[0])} more than once", "give each value once"))
            else:
                out[key] = values
    return out


def _cases(raw: Any, problems: list[Problem]) -> list[_Case]:
    if raw is None:
        return [_Case("", {}, {}, "sweep")]
    if not isinstance(raw, list) or not raw or not all(isinstance(c, dict) for c in raw):
        problems.append(
            Problem(
                "sweep.cases",
                "must be a non-empty array of tables",
                'write each case as [[sweep.cases]] with name = "..."',
            )
        )
        return []
    cases = []
    for i, table in enumerate(raw):
        where = f"sweep.cases[{i}]"
        _unknown_keys(table, CASE_KEYS, where, problems)
        name = table.get("name", "")
        if not isinstance(name, str):
            problems.append(
                Problem(f"{where}.name", f"must be a string, got {_type_name(name)}", 'write name = "lockstep"')
            )
            name = ""
        elif not name and len(raw) > 1:
            problems.append(
                Problem(
                    f"{where}.name",
                    "is required when there are several cases",
                    'add name = "..." (it names the points)',
                )
            )
        cases.append(
            _Case(
                name,
                _overrides(table.get("set", {}), f"{where}.set", problems),
                _grid(table.get("grid", {}), f"{where}.grid", problems),
                where,
            )
        )
    seen: set[str] = set()
    for c in cases:
        if c.name and c.name in seen:
            problems.append(
                Problem(f"{c.where}.name", f"an earlier case is named {c.name!r} too", "give every case its own name")
            )
        seen.add(c.name)
    return cases


# ------------------------------------------------------------------------------------------------ keys
def _tables(global_set, global_grid, cases, reference) -> list[tuple[str, dict[str, Any]]]:
    """(where, table) of every override table of the file."""
    out = [("sweep.set", global_set), ("sweep.grid", global_grid)]
    for c in cases:
        out += [(f"{c.where}.set", c.set), (f"{c.where}.grid", c.grid)]
    if reference is not None:
        out.append(("sweep.reference", reference))
    return out


def _check_key_names(base: dict, global_set, global_grid, cases, reference, problems: list[Problem]) -> None:
    """Every dotted key names a scene table or key, and its indexes lie within the base's lists (the points
    are checked again as they are built, since an override may replace a whole list)."""
    for where, table in _tables(global_set, global_grid, cases, reference):
        for key, value in table.items():
            at = f'{where}."{key}"'
            try:
                check_key(key, base)
                set_key(copy.deepcopy(base), key, None)  # the path exists (indexes within the lists)
            except KeyPathError as exc:
                problems.append(Problem(at, exc.message, exc.fix))
                continue
            if key == "outputs.diagnostics" and (value is False or (isinstance(value, list) and False in value)):
                problems.append(
                    Problem(at, "a sweep reads every point's diagnostics.jsonl", "remove it (the diagnostics stay on)")
                )


def _check_overlaps(global_set, global_grid, cases, problems: list[Problem]) -> None:
    """In each case, a key is varied or fixed in one place only (the global set is the default of all)."""
    for c in cases:
        for key in c.grid:
            if key in global_grid:
                problems.append(
                    Problem(f'{c.where}.grid."{key}"', "is also varied in sweep.grid", "vary it in one of the two")
                )
            if key in c.set:
                problems.append(
                    Problem(f'{c.where}.grid."{key}"', f"is also fixed in {c.where}.set", "keep it in one of the two")
                )
        for key in c.set:
            if key in global_grid:
                problems.append(
                    Problem(
                        f'{c.where}.set."{key}"',
                        "is varied in sweep.grid, so every point of this case would be the same",
                        "move the grid of this key into the cases that vary it",
                    )
                )
    for key in global_grid:
        if key in global_set:
            problems.append(Problem(f'sweep.grid."{key}"', "is also fixed in sweep.set", "keep it in one of the two"))


def _sets_key(key: str, value: Any, grid: bool, table: str, name: str) -> bool:
    """Whether the override ``key = value`` (a grid's list of values when ``grid``) sets ``table.name`` (as the
    dotted key, or inside a value for ``table``)."""
    try:
        parts = parse_key(key)
    except KeyPathError:
        return False
    if parts == (table, name):
        return True
    values = value if grid and isinstance(value, list) else [value]
    return parts == (table,) and any(isinstance(v, dict) and name in v for v in values)


def _check_frames(frames, global_set, global_grid, cases, reference, problems: list[Problem]) -> None:
    """``sweep.frames`` replaces ``time.frames`` in every point, so a table that sets ``time.frames`` too is
    refused: its values would be silently replaced (points named ``time.frames=2`` running ``sweep.frames``)."""
    if frames is None:
        return
    for where, table in _tables(global_set, global_grid, cases, reference):
        grid = where.endswith(".grid")
        for key, value in table.items():
            if not _sets_key(key, value, grid, "time", "frames"):
                continue
            drop = "drop time.frames from the grid" if grid else f"drop time.frames from {where}"
            problems.append(
                Problem(
                    f'{where}."{key}"',
                    f"sets time.frames, but sweep.frames = {frames} replaces time.frames in every point, so each "
                    f"would run {frames} frame{'s' if frames != 1 else ''} whatever this says",
                    f"remove sweep.frames (every point then runs its own time.frames), or {drop}",
                )
            )


def _check_output_folder(global_set, global_grid, cases, reference, problems: list[Problem]) -> None:
    """A sweep writes each point's run into ``<out>/points/<id>/run``: a table setting ``outputs.directory`` is
    refused, since the value would be silently ignored (a probe, session 25)."""
    for where, table in _tables(global_set, global_grid, cases, reference):
        for key, value in table.items():
            if _sets_key(key, value, where.endswith(".grid"), "outputs", "directory"):
                problems.append(
                    Problem(
                        f'{where}."{key}"',
                        "sets outputs.directory, but a sweep writes each point's run into <out>/points/<id>/run, so "
                        "it would be ignored",
                        f"drop it from {where}; choose where the sweep writes with couplekit sweep --out DIR",
                    )
                )


# ------------------------------------------------------------------------------------------------ points
def format_value(v: Any) -> str:
    """A value as it appears in point names: ``0.0001``, ``4``, ``subcycle``, ``true``, ``[0, 0, -1]``."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return v
    if isinstance(v, float):
        return repr(v)
    return json.dumps(v)


def point_id(overrides: dict[str, Any]) -> str:
    """A short stable hash of the sorted overrides."""
    text = json.dumps(sorted(overrides.items()), sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def _apply(base: dict, layers: list[tuple[str, dict[str, Any]]], problems: list[Problem]) -> dict[str, Any] | None:
    """The base scene with the output defaults and every (where, overrides) layer applied in order."""
    scene = copy.deepcopy(base)
    for key, value in OUTPUT_DEFAULTS.items():
        set_key(scene, key, value)
    ok = True
    for where, overrides in layers:
        for key, value in overrides.items():
            try:
                set_key(scene, key, copy.deepcopy(value))
            except KeyPathError as exc:
                at = f'{where}."{key}"'
                if not any(p.key == at for p in problems):
                    problems.append(Problem(at, exc.message, exc.fix))
                ok = False
    drop_replaced(
        scene, [key for _, overrides in layers for key in overrides]
    )  # an SI viscosity replaces the base's lattice one
    return scene if ok else None


def _expand(base, global_set, global_grid, cases, frames, problems: list[Problem]) -> list[SweepPoint]:
    points = []
    for c in cases:
        grid = {**global_grid, **c.grid}
        for values in itertools.product(*grid.values()):
            chosen = dict(zip(grid, values, strict=True))
            layers = [("sweep.set", global_set), (f"{c.where}.set", c.set)]
            layers.append(("sweep.grid", {k: v for k, v in chosen.items() if k in global_grid}))
            layers.append((f"{c.where}.grid", {k: v for k, v in chosen.items() if k in c.grid}))
            scene = _apply(base, layers, problems)
            if scene is None:
                continue
            overrides = {**global_set, **c.set, **chosen}
            label = " ".join([c.name] * bool(c.name) + [f"{k}={format_value(v)}" for k, v in chosen.items()])
            points.append(SweepPoint(point_id(overrides), label or "base", c.name, overrides, scene, frames))
    return points


def _reference_point(base, global_set, reference, frames, problems: list[Problem]) -> SweepPoint | None:
    scene = _apply(base, [("sweep.set", global_set), ("sweep.reference", reference)], problems)
    if scene is None:
        return None
    overrides = {**global_set, **reference}
    return SweepPoint(REFERENCE_ID, REFERENCE_ID, REFERENCE_ID, overrides, scene, frames)


def _check_duplicates(points: list[SweepPoint], problems: list[Problem]) -> None:
    seen: dict[str, SweepPoint] = {}
    for p in points:
        if p.id in seen:
            problems.append(
                Problem(
                    "sweep.cases",
                    f"points {seen[p.id].name!r} and {p.name!r} have the same overrides {p.overrides}",
                    "make every case differ in its set or grid (or drop the duplicate case)",
                )
            )
        seen[p.id] = p


def _validated(point: SweepPoint, scene_dir: Path, source_name: str) -> SweepPoint:
    """``point`` with ``frames`` filled in from its scene, or ``invalid`` set when the scene is refused."""
    try:
        scene = Scene.from_dict(copy.deepcopy(point.scene), base_dir=scene_dir, source_name=source_name)
    except SceneError as exc:
        return _replace(point, invalid=str(exc))
    except Exception as exc:  # a scene that breaks the checker must not stop the other points
        return _replace(point, invalid=f"{source_name}: the scene could not be checked: {type(exc).__name__}: {exc}")
    return _replace(point, frames=point.frames if point.frames is not None else scene.time.frames)


def _validated_reference(point: SweepPoint, scene_dir: Path, source: str) -> SweepPoint:
    """The reference point checked like the others, except that a refused reference is a :class:`SweepError`
    (every point is compared with it)."""
    try:
        scene = Scene.from_dict(copy.deepcopy(point.scene), base_dir=scene_dir, source_name=f"{source}: the reference")
    except SceneError as exc:
        problems = [
            Problem("sweep.reference", f"the reference scene is refused: {p.key}: {p.message}", p.fix)
            for p in exc.problems
        ]
        raise SweepError(problems, source) from None
    return _replace(point, frames=point.frames if point.frames is not None else scene.time.frames)


def _replace(point: SweepPoint, **changes: Any) -> SweepPoint:
    return dataclasses.replace(point, **changes)


def _column_keys(global_set, global_grid, cases, reference) -> tuple[str, ...]:
    """Overridden keys in column order: the grids, then the cases' sets, the global set, the reference."""
    keys: list[str] = list(global_grid)
    for c in cases:
        keys += list(c.grid)
    for c in cases:
        keys += list(c.set)
    keys += list(global_set) + list(reference or {})
    return tuple(dict.fromkeys(keys))


def is_final(status: str | None) -> bool:
    """Whether a point with this status is finished (a resumed sweep does not run it again)."""
    return status in FINAL_STATUSES


def finite_or_none(x: Any) -> Any:
    """``x`` with non-finite floats replaced by None (for strict JSON)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_or_none(v) for v in x]
    return x
