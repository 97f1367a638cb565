"""Dotted scene keys of a sweep: ``time.dt``, ``domain.boundary.x_min``, ``bodies[0].density``,
``bodies[1].geometry.radius``, ``inflows[0].velocity``.

:func:`parse_key` splits a key into its parts, :func:`check_key` checks it against the scene schema
(:mod:`couplekit.scene.schema`: the tables and their keys) and :func:`set_key` writes a value into a scene
dict. Errors are :class:`KeyPathError` with a message and a fix, turned into sweep-file problems by
:mod:`couplekit.sweep.spec`.
"""

from __future__ import annotations

import difflib
import re
from typing import Any

from ..faces import SCENE_FACES
from ..scene.schema import (
    BODY_KEYS,
    GEOMETRY_COMMON_KEYS,
    GEOMETRY_KEYS,
    INFLOW_KEYS,
    SAND_WALL_KEYS,
    SECTIONS,
    TOP_LEVEL,
)

__all__ = ["KeyPathError", "parse_key", "check_key", "set_key", "flatten_keys", "ALTERNATIVE_KEYS", "drop_replaced"]

_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[[0-9]+\])*)")
_INDEX = re.compile(r"\[([0-9]+)\]")
_LIST_TABLES = {"bodies": [k.name for k in BODY_KEYS] + ["geometry"], "inflows": [k.name for k in INFLOW_KEYS]}


class KeyPathError(ValueError):
    """A dotted key that does not address a scene value: ``message`` says why, ``fix`` what to write."""

    def __init__(self, message: str, fix: str):
        self.message, self.fix = message, fix
        super().__init__(f"{message}. Fix: {fix}")


def parse_key(key: str) -> tuple[str | int, ...]:
    """The parts of a dotted key: ``"bodies[0].geometry.radius"`` -> ``("bodies", 0, "geometry", "radius")``."""
    if not isinstance(key, str) or not key:
        raise KeyPathError(f"{key!r} is not a dotted key", 'write a key such as "time.dt" or "bodies[0].density"')
    parts: list[str | int] = []
    for segment in key.split("."):
        m = _SEGMENT.fullmatch(segment)
        if m is None:
            raise KeyPathError(
                f"{segment!r} is not a key name with optional [index] suffixes",
                'write names joined by dots, list entries as name[i] (e.g. "bodies[0].density")',
            )
        parts.append(m.group(1))
        parts.extend(int(i) for i in _INDEX.findall(m.group(2)))
    return tuple(parts)


def _names(parts: tuple[str | int, ...]) -> list[str]:
    return [p for p in parts if isinstance(p, str)]


def _unknown(name: str, known: list[str], where: str, what: str = "key") -> KeyPathError:
    close = difflib.get_close_matches(name, known, n=1)
    fix = f"did you mean {close[0]!r}?" if close else f"use one of {', '.join(known)}"
    return KeyPathError(f"{where} has no {what} {name!r}", fix)


def _geometry_keys(scene: dict, parts: tuple[str | int, ...]) -> list[str]:
    """Keys a ``bodies[i].geometry`` table may hold: the common ones and those of its ``type``."""
    common = [k.name for k in GEOMETRY_COMMON_KEYS]
    try:
        kind = scene[parts[0]][parts[1]]["geometry"]["type"]
    except (KeyError, IndexError, TypeError):
        kind = None
    if kind in GEOMETRY_KEYS:
        return common + [k.name for k in GEOMETRY_KEYS[kind]]
    return common + sorted({k.name for keys in GEOMETRY_KEYS.values() for k in keys})


def check_key(key: str, scene: dict) -> tuple[str | int, ...]:
    """Check that ``key`` names a table or key of the scene schema; returns its parts.

    ``scene`` (the base scene dict) gives the geometry type of ``bodies[i].geometry.*`` keys. Indexes are
    checked by :func:`set_key`; trailing indexes into a list value (``bodies[0].velocity[2]``) are allowed.
    """
    parts = parse_key(key)
    top = parts[0]
    if top not in TOP_LEVEL:
        raise _unknown(str(top), list(TOP_LEVEL), "a scene", "table")
    if top in _LIST_TABLES:
        return _check_list_entry_key(parts, scene)
    names = _names(parts)
    if len(parts) > 1 and isinstance(parts[1], int):
        raise KeyPathError(f"[{top}] is a table, not a list", f'write "{top}.<key>" without an index')
    section = names[0]
    if names[:2] == ["sand", "walls"]:  # [sand.walls]: a table of faces, each a table of SAND_WALL_KEYS
        return _check_sand_wall_key(parts, names)
    for name in names[1:]:
        if section in SECTIONS and any(k.name == name for k in SECTIONS[section]):
            _only_indexes_after(parts, parts.index(name))
            return parts
        if f"{section}.{name}" in SECTIONS:
            section = f"{section}.{name}"
            continue
        known = [k.name for k in SECTIONS.get(section, [])] + [
            s.split(".")[-1] for s in SECTIONS if s.startswith(section + ".")
        ]
        raise _unknown(name, known, f"[{section}]")
    return parts  # the whole table


def _check_sand_wall_key(parts: tuple[str | int, ...], names: list[str]) -> tuple[str | int, ...]:
    """``sand.walls``, ``sand.walls.<face>`` or ``sand.walls.<face>.<key>`` (docs/scene-reference.md)."""
    if len(names) >= 3 and names[2] not in SCENE_FACES:
        raise _unknown(names[2], list(SCENE_FACES), "[sand.walls]", "face")
    if len(names) >= 4:
        known = [k.name for k in SAND_WALL_KEYS]
        if names[3] not in known:
            raise _unknown(names[3], known, f"[sand.walls.{names[2]}]")
        _only_indexes_after(parts, parts.index(names[3]))
    return parts


def _only_indexes_after(parts: tuple[str | int, ...], at: int) -> None:
    """Below the value of the key ``parts[at]`` only indexes may follow (``domain.size[2]``), no names."""
    extra = [p for p in parts[at + 1 :] if isinstance(p, str)]
    if extra:
        raise KeyPathError(
            f"{parts[at]!r} is a value, not a table, so it has no key {extra[0]!r}", f"end the key at {parts[at]}"
        )


def _check_list_entry_key(parts: tuple[str | int, ...], scene: dict) -> tuple[str | int, ...]:
    top = str(parts[0])
    if len(parts) == 1:
        return parts  # the whole list
    if not isinstance(parts[1], int):
        raise KeyPathError(f"{top} is a list of tables", f'address one entry by its index, e.g. "{top}[0].{parts[1]}"')
    if len(parts) == 2:
        return parts  # one whole entry
    name = parts[2]
    if not isinstance(name, str) or name not in _LIST_TABLES[top]:
        raise _unknown(str(name), _LIST_TABLES[top], f"{top}[{parts[1]}]")
    if name != "geometry":
        _only_indexes_after(parts, 2)
        return parts
    if len(parts) > 3:
        if not isinstance(parts[3], str):
            raise KeyPathError(f"{top}[{parts[1]}].geometry is a table, not a list", "drop the index after geometry")
        known = _geometry_keys(scene, parts)
        if parts[3] not in known:
            raise _unknown(parts[3], known, f"{top}[{parts[1]}].geometry")
        _only_indexes_after(parts, 3)
    return parts


def _describe(value: Any) -> str:
    names = {bool: "a boolean", int: "a number", float: "a number", str: "a string", list: "a list", dict: "a table"}
    return names.get(type(value), type(value).__name__)


def _step_into(container: Any, part: str | int, done: str, create: bool, new: Any = None, absent: bool = False) -> Any:
    """The child ``part`` of ``container`` (the path so far is ``done``); a missing one is created as ``new``
    (a table by default; a list when the key indexes into it next). ``absent``: ``container`` is a list the
    scene does not give (created just now: the scene takes that key's default)."""
    if isinstance(part, int):
        if not isinstance(container, list):
            raise KeyPathError(f"{done} is {_describe(container)}, not a list", f"drop the index [{part}]")
        if absent:
            raise KeyPathError(
                f"{done} is not in the scene (it takes its default), so [{part}] has no entry to set",
                f"set the whole list instead, e.g. --set '{done}=[...]' (the scene reference gives the default)",
            )
        if part >= len(container):
            raise KeyPathError(
                f"{done} has {len(container)} entr{'y' if len(container) == 1 else 'ies'}, so [{part}] is beyond it",
                f"use an index from 0 to {len(container) - 1}"
                if container
                else f"add entries to {done} in the base scene",
            )
        return container[part]
    if not isinstance(container, dict):
        raise KeyPathError(f"{done} is {_describe(container)}, not a table", f"end the key at {done}")
    if part not in container and create:
        container[part] = {} if new is None else new
    return container[part]


def _join(done: str, part: str | int) -> str:
    return f"{done}[{part}]" if isinstance(part, int) else (f"{done}.{part}" if done else part)


def set_key(scene: dict, key: str, value: Any) -> None:
    """Write ``value`` at dotted ``key`` into the scene dict ``scene`` (in place).

    A table the scene does not have yet is created (``scheduler.kind`` on a scene without ``[scheduler]``);
    an index beyond a list, or a key below a value that is not a table, raises :class:`KeyPathError`.
    """
    parts = parse_key(key)
    container: Any = scene
    done = ""
    absent = False  # the container was created just now (the scene does not give it)
    for i, part in enumerate(parts[:-1]):
        indexed = isinstance(parts[i + 1], int)
        missing = isinstance(part, str) and isinstance(container, dict) and part not in container
        # a missing key that the next part indexes is a list (the index then has no entry: reported)
        container = _step_into(container, part, done, create=True, new=[] if indexed else {}, absent=absent)
        absent = missing and indexed
        done = _join(done, part)
    last = parts[-1]
    if isinstance(last, int):
        _step_into(container, last, done, create=False, absent=absent)  # checks the bounds
        container[last] = value
    else:
        if not isinstance(container, dict):
            raise KeyPathError(f"{done} is {_describe(container)}, not a table", f"end the key at {done}")
        container[last] = value


ALTERNATIVE_KEYS: tuple[tuple[str, str], ...] = (
    ("domain.dx", "domain.resolution"),
    ("fluid.water_viscosity", "fluid.water_lattice_viscosity"),
    ("fluid.air_viscosity", "fluid.air_lattice_viscosity"),
    ("sand.absorption_rate", "sand.absorption_time"),
)
"""Pairs of keys that say one thing two ways (the scene takes one of each pair: SI or lattice viscosity, a
per-step or a per-second absorption, a spacing or a cell count): a setting of one replaces the other
(:func:`drop_replaced`)."""


def drop_replaced(scene: dict, keys) -> None:
    """Remove from the scene dict ``scene`` (in place) the other key of each :data:`ALTERNATIVE_KEYS` pair of which
    ``keys`` (the dotted keys just set) name exactly one: ``--set fluid.water_viscosity=1e-6`` on a file that gives
    ``water_lattice_viscosity`` sets the water's viscosity instead of being refused as giving both (session 31:
    docs/sweeps.md's own example was refused so at every point). Where ``keys`` name both, both stay, and the
    scene's validation refuses the pair."""
    given = set(keys)
    for a, b in ALTERNATIVE_KEYS:
        if (a in given) == (b in given):
            continue
        table, name = (b if a in given else a).split(".")
        section = scene.get(table)
        if isinstance(section, dict):
            section.pop(name, None)


def flatten_keys(table: dict, prefix: str = "") -> dict[str, Any]:
    """``{"time": {"dt": 1}}`` (unquoted dotted TOML keys) -> ``{"time.dt": 1}``; quoted keys pass through.

    Lists (grid values, vectors, lists of tables) are leaves."""
    out: dict[str, Any] = {}
    for name, value in table.items():
        key = f"{prefix}.{name}" if prefix else str(name)
        if isinstance(value, dict) and value:
            out.update(flatten_keys(value, key))
        else:
            out[key] = value
    return out
