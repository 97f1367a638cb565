"""The scene JSON Schema (couplekit.scene.jsonschema, docs/scene.schema.json): a valid 2020-12 schema, current
with the schema data, accepting every shipped scene and refusing the malformed scenes of the validation tests
that one key decides, each of which couplekit's own validator refuses as well (the same verdict)."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path

import pytest
from test_scene_validation import _DELETE, MALFORMED, _set, fluid_scene, sand_scene

from couplekit.cli import main
from couplekit.scene import Scene, SceneError
from couplekit.scene.jsonschema import render_json, scene_json_schema
from couplekit.scene.schema import INFLOW_KEYS, OUTLET_KEYS, SECTIONS

ROOT = Path(__file__).resolve().parents[2]
SCENE_FILES = sorted((ROOT / "examples").glob("*.toml")) + sorted((ROOT / "benchmarks" / "scenes").glob("*.toml"))


def _jsonschema():
    return pytest.importorskip("jsonschema", reason="the test extra installs jsonschema")


@pytest.fixture(scope="module")
def validator():
    jsonschema = _jsonschema()
    schema = scene_json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)  # a schema error fails here, not as a verdict
    return jsonschema.Draft202012Validator(schema)


def _base(name: str) -> dict:
    return copy.deepcopy(fluid_scene() if name == "fluid" else sand_scene())


# the malformed scenes one key decides: unknown key or table, wrong type, out of range, missing required key,
# bad choice, bad geometry type, a key the geometry type does not take, a list of the wrong length
SCHEMA_REFUSES = [
    ("domain.sise", [1, 1, 1]),
    ("extra", {"a": 1}),
    ("domain.size", _DELETE),
    ("domain.size", "big"),
    ("domain.size", [0.1, 0.05]),
    ("domain.size", [0.1, -0.05, 0.1]),
    ("domain.dx", "0.01"),
    ("domain.boundary.x_min", "perodic"),
    ("time.dt", _DELETE),
    ("time.dt", -1e-5),
    ("time.frames", 2.5),
    ("time.frames", 0),
    ("time.mach_limit", 2.0),
    ("fluid.phases", 3),
    ("fluid.water_density", -1000.0),
    ("fluid.surface_tension", True),
    ("fluid.controller_eta", -1.0),
    ("fluid.viscosity", 1e-4),
    ("bodies.0.kind", "lava"),
    ("bodies.0.geometry", _DELETE),
    ("bodies.0.geometry.type", "cone"),
    ("bodies.1.geometry.radius", 0.0),
    ("bodies.1.geometry.centre", [0, 0, 0]),
    ("bodies.2.geometry.file", "nowhere.obj"),
    ("inflows.0.sand_fraction", 0.9),
    ("outputs.fields", ["phi", "vorticity"]),
    ("outputs.vtk", "yes"),
    ("effects.gravity", False),
    ("sand.poisson_ratio", 0.5),
    ("sand.hardening", [35.0, 9.0, 0.2]),
    ("bodies.0.geometry.type", "mesh"),
]

# the malformed scenes that need several keys at once: only `couplekit validate` refuses them
# (docs/scene-schema.md lists these checks)
VALIDATE_ONLY = [
    ("domain.dx", 0.003),  # a whole number of cells
    ("domain.resolution", [40, 20, 40]),  # both dx and resolution
    ("domain.boundary.y_min", "periodic"),  # periodic needs both faces
    ("domain.boundary.z_max", "inflow"),  # an inflow face needs an [[inflows]] entry
    ("time.dt", 5e-4),  # lattice Mach number
    ("fluid.air_density", 2000.0),  # not below water_density
    ("fluid.water_lattice_viscosity", 1e-7),  # the relaxation-time limits
    ("bodies.0.geometry.max", [0.2, 0.05, 0.03]),  # outside the domain
    ("bodies.1.density", 1500.0),  # only sand bodies take a density
    ("inflows.0.velocity", [-0.2, 0, 0]),  # must point into the domain
    ("sand.particles_per_cell", 10),  # not a cube
    ("sand.cohesion_saturation", [0.2, 0.1, 0.3]),  # ordered breakpoints
    ("bodies", []),  # nothing to simulate
]


def _scene(path: str, value) -> dict:
    """The scene of the MALFORMED case of test_scene_validation.py that sets ``path`` to ``value``."""
    for base, p, v, _key, _words in MALFORMED:
        if p == path and (v is value or (_DELETE not in (v, value) and repr(v) == repr(value))):
            d = _base(base)
            _set(d, p, v)
            return d
    raise AssertionError(f"test_scene_validation.MALFORMED has no case {path} = {value!r}; update this list")


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_shipped_scene_is_valid(validator, path):
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    errors = [f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(data)]
    assert not errors, "\n".join(errors)


def test_the_validation_tests_base_scenes_are_valid(validator):
    for d in (fluid_scene(), sand_scene()):
        Scene.from_dict(d)
        validator.validate(d)


@pytest.mark.parametrize(("path", "value"), SCHEMA_REFUSES, ids=[f"{p}={v!r}"[:50] for p, v in SCHEMA_REFUSES])
def test_malformed_scene_refused_by_schema_and_validator(validator, path, value):
    d = _scene(path, value)
    assert not validator.is_valid(d), f"the JSON Schema accepts {path} = {value!r}"
    with pytest.raises(SceneError):
        Scene.from_dict(d)


@pytest.mark.parametrize(("path", "value"), VALIDATE_ONLY, ids=[f"{p}={v!r}"[:50] for p, v in VALIDATE_ONLY])
def test_checks_across_keys_are_left_to_validate(validator, path, value):
    """What docs/scene-schema.md says only `couplekit validate` checks: the schema accepts it, validate not."""
    d = _scene(path, value)
    validator.validate(d)
    with pytest.raises(SceneError):
        Scene.from_dict(d)


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"shape": "rect", "center": [0.025, 0.05]}, "inflows[0].size"),  # rect needs center and size
        ({"shape": "disc", "center": [0.025, 0.05], "size": [0.01, 0.01]}, "inflows[0].radius"),
        ({"radius": 0.01}, "inflows[0].radius"),  # a whole-face inflow takes no outlet keys
        ({"shape": "slot"}, "inflows[0].shape"),
    ],
)
def test_inflow_shape_keys(validator, change, key):
    d = fluid_scene()
    d["inflows"][0].update(change)
    assert not validator.is_valid(d)
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert key in err.value.keys, str(err.value)


def test_a_key_of_another_geometry_type_is_refused(validator):
    d = sand_scene()
    d["bodies"][0]["geometry"]["radius"] = 0.01  # a box has no radius
    assert not validator.is_valid(d)
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert "bodies[0].geometry.radius" in err.value.keys


def test_outlet_shapes_are_the_shape_choices():
    shape = next(k for k in INFLOW_KEYS if k.name == "shape")
    assert tuple(OUTLET_KEYS) == shape.choices


def test_schema_carries_the_keys_documentation():
    schema = scene_json_schema()
    dt = schema["properties"]["time"]["properties"]["dt"]
    assert dt["type"] == "number" and dt["exclusiveMinimum"] == 0.0
    assert "unit: s" in dt["description"] and "time" in schema["required"]
    for name, keys in SECTIONS.items():
        table = schema["properties"]["domain"]["properties"]["boundary"] if name == "domain.boundary" else None
        table = table or schema["properties"][name]
        assert table["additionalProperties"] is False
        for key in keys:
            assert table["properties"][key.name]["description"].startswith(key.doc), f"{name}.{key.name}"


def test_committed_schema_is_current():
    """docs/scene.schema.json is the rendering of the schema (regenerate: couplekit schema --out docs/scene.schema.json)."""
    committed = (ROOT / "docs" / "scene.schema.json").read_text(encoding="utf-8")
    assert committed == render_json(), (
        "docs/scene.schema.json is stale: run couplekit schema --out docs/scene.schema.json"
    )


def test_cli_schema_prints_and_writes(tmp_path, capsys):
    assert main(["schema"]) == 0
    assert capsys.readouterr().out == render_json()
    out = tmp_path / "scene.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == render_json()
    assert main(["schema", "--out", str(tmp_path / "missing" / "x.json")]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_draft_7_validators_give_the_same_verdicts():
    """The schema uses only keywords that mean the same in draft 7, for editors whose validator predates 2020-12."""
    jsonschema = _jsonschema()
    schema = scene_json_schema()
    new, old = jsonschema.Draft202012Validator(schema), jsonschema.Draft7Validator(schema)
    scenes = [tomllib.loads(p.read_text(encoding="utf-8")) for p in SCENE_FILES]
    scenes += [_scene(path, value) for path, value in SCHEMA_REFUSES + VALIDATE_ONLY]
    assert [old.is_valid(d) for d in scenes] == [new.is_valid(d) for d in scenes]


@pytest.mark.parametrize(
    ("walls", "valid"),
    [
        ({"z_min": {"friction": 0.3}, "x_min": {"kind": "slip"}}, True),
        ({"z_mn": {"friction": 0.3}}, False),  # no such face
        ({"z_min": {"kind": "glue"}}, False),  # no such kind
        ({"z_min": {"friction": -0.1}}, False),  # out of range
        ({"z_min": {"fricton": 0.3}}, False),  # no such key
    ],
)
def test_sand_walls_per_face(validator, walls, valid):
    """[sand.walls]: the schema and validate give the same verdict per face entry."""
    d = sand_scene()
    d.setdefault("sand", {})["walls"] = walls
    assert validator.is_valid(d) == valid
    if valid:
        Scene.from_dict(d)
    else:
        with pytest.raises(SceneError):
            Scene.from_dict(d)
