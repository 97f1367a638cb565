"""The scene schema as JSON Schema (draft 2020-12), for editors: Taplo / Even Better TOML complete and check
scene files against it.

Generated from the data in :mod:`couplekit.scene.schema` (the definition :func:`~couplekit.scene.schema.read_table`
validates against), so it holds no second copy of any key. ``couplekit schema`` prints it;
``docs/scene.schema.json`` is its committed rendering (a test keeps the file current; regenerate with
``couplekit schema --out docs/scene.schema.json``).

It checks what one key decides alone (type, range, choices, list length), required keys, unknown keys
(``additionalProperties: false``), the shape keys of each geometry ``type`` and each inflow ``shape``.
What needs several keys at once (the grid, the time-step limits, bodies inside the domain, ...) only
``couplekit validate`` checks; docs/scene-schema.md lists it.

Only keywords that mean the same in drafts 7 and 2020-12 are used (no ``prefixItems``, no
``unevaluatedProperties``), so editors whose validator predates 2020-12 read it alike.
"""

from __future__ import annotations

import json
from typing import Any

from .. import __version__
from .schema import (
    BODY_KEYS,
    FACES,
    GEOMETRY_COMMON_KEYS,
    GEOMETRY_KEYS,
    GEOMETRY_SUBTRACT,
    GEOMETRY_SUBTRACT_DOC,
    INFLOW_KEYS,
    OUTLET_KEYS,
    REQUIRED,
    SAND_WALL_KEYS,
    SECTIONS,
    TOP_LEVEL,
    Key,
)

__all__ = ["SCHEMA_ID", "scene_json_schema", "render_json"]

SCHEMA_ID = f"urn:couplekit:scene:{__version__}"
"""The ``$id`` of the scene schema (a URN: the schema is found by path, not fetched)."""

_DIALECT = "https://json-schema.org/draft/2020-12/schema"

_TABLE_TEXT = {
    "scene": "Name and description of the scene.",
    "domain": "The simulation box and its grid. Required. Give dx or resolution.",
    "domain.boundary": "Boundary kind of each face of the box; every face defaults to a wall.",
    "time": "Time step and frames. Required.",
    "scheduler": "How the fluid and the sand are stepped (default: lockstep).",
    "fluid": "Present: the scene has a fluid (LBM two-phase water and air).",
    "sand": 'Material of the sand bodies (used when a body has kind = "sand").',
    "sand.walls": "The sand's wall on each face of the box (faces not named use sand.wall_friction).",
    "sand.walls.face": "How the sand meets this face of the box.",
    "outputs": "What each frame writes, and where.",
    "effects": "Switches for ablations.",
    "stirring": "A swirling body force on the water (paper Fig. 11).",
    "bodies": "Water bodies, sand bodies and obstacles; each has a kind and a geometry table.",
    "inflows": "Velocity inlets over a whole face, or outlets (jets) in a face.",
    "geometry": "The shape of a body: type and the keys of that type; transforms scale, rotate, translate.",
}


def _description(key: Key) -> str:
    """The key's documentation, with its unit and admissible range (JSON Schema has no unit keyword)."""
    text = key.doc
    extras = []
    if key.unit:
        extras.append(f"unit: {key.unit}")
    if key.range_text() and not key.choices:
        extras.append(f"allowed: {key.range_text()}")
    if key.default is REQUIRED:
        extras.append("required")
    return text + (f" ({'; '.join(extras)})" if extras else "")


def _bounds(key: Key) -> dict[str, Any]:
    """minimum / maximum (exclusive where the key's bound is open) of a number or of each component."""
    out: dict[str, Any] = {}
    if key.lo is not None:
        out["exclusiveMinimum" if key.lo_open else "minimum"] = key.lo
    if key.hi is not None:
        out["exclusiveMaximum" if key.hi_open else "maximum"] = key.hi
    return out


def _value_schema(key: Key) -> dict[str, Any]:
    """The JSON Schema of one key's value, by its kind (the kinds of :class:`~couplekit.scene.schema.Key`)."""
    k = key.kind
    if k == "float":
        return {"type": "number", **_bounds(key)}
    if k == "int":
        return {"type": "integer", **_bounds(key)}
    if k == "int_or_auto":
        return {"anyOf": [{"type": "integer", **_bounds(key)}, {"const": "auto"}]}
    if k == "bool":
        return {"type": "boolean"}
    if k == "str":
        return {"type": "string"}
    if k == "choice":
        return {"type": "string", "enum": list(key.choices)}
    if k in ("vec3", "ivec3", "floats"):
        n = 3 if k != "floats" else key.length
        item = {"type": "integer" if k == "ivec3" else "number", **_bounds(key)}
        out: dict[str, Any] = {"type": "array", "items": item}
        if n:
            out.update(minItems=n, maxItems=n)
        return out
    if k == "strs":
        return {"type": "array", "items": {"type": "string", "enum": list(key.choices)}}
    if k == "grid":
        row = {"type": "array", "minItems": 2, "items": {"type": "number"}}
        return {"type": "array", "minItems": 2, "items": row}
    raise ValueError(f"key {key.name!r} has kind {k!r}, which scene_json_schema cannot render; add it to _value_schema")


def _key_schema(key: Key) -> dict[str, Any]:
    out = {"description": _description(key), **_value_schema(key)}
    if key.default is not REQUIRED and key.default is not None:
        out["default"] = key.default
    return out


def _table(keys: list[Key], description: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """A table of ``keys`` (and the sub-tables in ``extra``): no other key, the required ones required."""
    out: dict[str, Any] = {
        "type": "object",
        "description": description,
        "properties": {k.name: _key_schema(k) for k in keys} | (extra or {}),
        "additionalProperties": False,
    }
    required = [k.name for k in keys if k.default is REQUIRED]
    if required:
        out["required"] = required
    return out


def _geometry(gtype: str) -> dict[str, Any]:
    """One geometry type's table: the common keys with ``type`` fixed to ``gtype``, and the type's keys."""
    out = _table(GEOMETRY_COMMON_KEYS + GEOMETRY_KEYS[gtype], f'{_TABLE_TEXT["geometry"]} This is type = "{gtype}".')
    out["properties"]["type"] = {**out["properties"]["type"], "const": gtype}
    out["properties"][GEOMETRY_SUBTRACT] = {
        "type": "array",
        "minItems": 1,
        "description": GEOMETRY_SUBTRACT_DOC,
        "items": {"$ref": "#/$defs/geometry"},
    }
    return out


def _choice_key(keys: list[Key], name: str) -> Key:
    return next(k for k in keys if k.name == name)


def _inflow() -> dict[str, Any]:
    """One [[inflows]] entry: its keys, and per shape the outlet keys it needs and those it takes not."""
    shape = _choice_key(INFLOW_KEYS, "shape")
    every = sorted({k for keys in OUTLET_KEYS.values() for k in keys})
    rules = []
    for name, needs in OUTLET_KEYS.items():
        cond: dict[str, Any] = {"properties": {"shape": {"const": name}}}
        if name != shape.default:  # an absent shape is the default one
            cond["required"] = ["shape"]
        then: dict[str, Any] = {}
        if needs:
            then["required"] = list(needs)
        unwanted = [k for k in every if k not in needs]
        if unwanted:
            then["not"] = {"anyOf": [{"required": [k]} for k in unwanted]}
        rules.append({"if": cond, "then": then})
    return {"allOf": [{"$ref": "#/$defs/inflow_keys"}, *rules], "description": _TABLE_TEXT["inflows"]}


def scene_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scene file, as parsed from TOML: every table and key of
    :mod:`couplekit.scene.schema` with its description (unit and range included), type, range, choices and
    default; required keys; no unknown keys; a geometry table per ``type`` (``oneOf``, each branch listing all
    its keys, so an editor completes the keys of every type) and the outlet keys per inflow ``shape``."""
    defs: dict[str, Any] = {}
    properties: dict[str, Any] = {}
    for name in TOP_LEVEL:
        if name == "bodies":
            properties[name] = {"type": "array", "description": _TABLE_TEXT[name], "items": {"$ref": "#/$defs/body"}}
        elif name == "inflows":
            properties[name] = {"type": "array", "description": _TABLE_TEXT[name], "items": {"$ref": "#/$defs/inflow"}}
        elif name == "domain":
            boundary = _table(SECTIONS["domain.boundary"], _TABLE_TEXT["domain.boundary"])
            properties[name] = _table(SECTIONS[name], _TABLE_TEXT[name], {"boundary": boundary})
        elif name == "sand":
            wall = _table(SAND_WALL_KEYS, _TABLE_TEXT["sand.walls.face"])
            walls = {
                "type": "object",
                "description": _TABLE_TEXT["sand.walls"],
                "properties": {face: wall for face in FACES},
                "additionalProperties": False,
            }
            properties[name] = _table(SECTIONS[name], _TABLE_TEXT[name], {"walls": walls})
        elif name in SECTIONS:
            properties[name] = _table(SECTIONS[name], _TABLE_TEXT.get(name, f"The [{name}] table."))
        else:
            raise ValueError(f"top-level table {name!r} has no key list in couplekit.scene.schema")
    geometry_ref = {"$ref": "#/$defs/geometry"}
    defs["body"] = _table(BODY_KEYS, _TABLE_TEXT["bodies"], {"geometry": geometry_ref})
    defs["body"]["required"] = [*defs["body"].get("required", []), "geometry"]
    defs["geometry"] = {
        "description": _TABLE_TEXT["geometry"],
        "type": "object",
        "required": ["type"],
        "oneOf": [{"$ref": f"#/$defs/geometry_{g}"} for g in GEOMETRY_KEYS],
    }
    for gtype in GEOMETRY_KEYS:
        defs[f"geometry_{gtype}"] = _geometry(gtype)
    defs["inflow_keys"] = _table(INFLOW_KEYS, _TABLE_TEXT["inflows"])
    defs["inflow"] = _inflow()
    return {
        "$schema": _DIALECT,
        "$id": SCHEMA_ID,
        "title": "couplekit scene",
        "description": (
            f"A couplekit {__version__} scene file (TOML, SI units; z is up). Generated from "
            "couplekit.scene.schema by `couplekit schema`; `couplekit validate` also checks what needs several "
            "keys at once (docs/scene-schema.md)."
        ),
        "type": "object",
        "properties": properties,
        "required": ["domain", "time"],
        "additionalProperties": False,
        "$defs": defs,
    }


def render_json() -> str:
    """:func:`scene_json_schema` as the text of ``docs/scene.schema.json`` (2-space indent, final newline)."""
    return json.dumps(scene_json_schema(), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    print(render_json(), end="")
