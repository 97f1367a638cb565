"""`subtract` in a geometry table (couplekit.scene.model.Geometry.subtract): shapes cut out of a body, as the
colander's holes of paper 000 Fig. 4 and the ring wall of Fig. 5 need. The cut shape is what the solvers see
(obstacle cells, seeded particles), validation names a broken entry by its index, and the JSON Schema takes
the same lists."""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.scene import Scene, SceneError
from couplekit.scene.geometry import sdf_on_grid
from couplekit.scene.jsonschema import scene_json_schema

RING = """
[domain]
size = [1.0, 1.0, 0.4]
dx = 0.02

[time]
dt = 1e-4

[[bodies]]
kind = "sand"
[bodies.geometry]
type = "cylinder"
center = [0.5, 0.5, 0.1]
radius = 0.3
height = 0.12
subtract = [{ type = "cylinder", center = [0.5, 0.5, 0.1], radius = 0.2, height = 0.3 }]

[[bodies]]
kind = "obstacle"
[bodies.geometry]
type = "box"
min = [0.0, 0.0, 0.3]
max = [1.0, 1.0, 0.34]
subtract = [{ type = "cylinder", center = [0.5, 0.5, 0.32], radius = 0.05, height = 0.1 }]
"""


def test_subtracted_shape_is_the_difference():
    scene = Scene.loads(RING)
    ring = scene.bodies[0].geometry.shape(scene.domain)
    d = ring.sdf(np.array([[0.5, 0.5, 0.1], [0.75, 0.5, 0.1], [0.95, 0.5, 0.1]]))
    assert d[0] > 0 and d[1] < 0 and d[2] > 0  # the hole, the wall, outside
    plate = scene.bodies[1].geometry.shape(scene.domain)
    assert plate.sdf(np.array([[0.5, 0.5, 0.32]]))[0] > 0 > plate.sdf(np.array([[0.7, 0.5, 0.32]]))[0]


def test_solvers_see_the_hole():
    """The obstacle cells, sampled as couplekit.assembly.build_fluid samples them, have the plate's hole open:
    the cells whose centres lie within the hole's radius."""
    scene = Scene.loads(RING)
    dom = scene.domain
    solid = sdf_on_grid(scene.bodies[1].geometry.shape(dom, 0.25 * dom.dx), dom.resolution, dom.dx) < 0
    k = 15  # cell centre z = 0.31, inside the plate
    ys, xs = np.nonzero(~solid[k])
    r = np.hypot((xs + 0.5) * 0.02 - 0.5, (ys + 0.5) * 0.02 - 0.5)
    assert len(xs) > 0 and r.max() < 0.05
    assert solid[k].sum() == 50 * 50 - len(xs)


def test_entries_are_checked_as_geometry_tables():
    bad = RING.replace("height = 0.1 }]", "height = 0.1, radus = 1 }, 3]")
    with pytest.raises(SceneError) as err:
        Scene.loads(bad)
    text = str(err.value)
    assert "bodies[1].geometry.subtract[0].radus" in text and "did you mean 'radius'" in text
    assert "bodies[1].geometry.subtract[1]" in text
    with pytest.raises(SceneError, match=r"bodies\[0\].geometry.subtract: must be a non-empty list"):
        Scene.loads(
            RING.replace(
                'subtract = [{ type = "cylinder", center = [0.5, 0.5, 0.1], radius = 0.2, height = 0.3 }]',
                "subtract = []",
            )
        )


def test_a_sand_body_wholly_cut_away_is_refused():
    gone = RING.replace("radius = 0.2, height = 0.3", "radius = 0.4, height = 0.3")
    with pytest.raises(SceneError, match=r"bodies\[0\]\.geometry"):
        Scene.loads(gone)


def test_json_schema_takes_subtract_lists():
    jsonschema = pytest.importorskip("jsonschema", reason="the test extra installs jsonschema")
    import tomllib

    v = jsonschema.Draft202012Validator(scene_json_schema())
    data = tomllib.loads(RING)
    assert not list(v.iter_errors(data))
    data["bodies"][1]["geometry"]["subtract"][0]["radus"] = 1.0
    assert list(v.iter_errors(data))


def _water_scene(geometry: dict) -> dict:
    return {
        "domain": {"size": [0.16, 0.16, 0.16], "dx": 0.01},
        "time": {"dt": 2e-4, "frames": 1},
        "fluid": {"water_lattice_viscosity": 1e-3, "air_lattice_viscosity": 1e-2},
        "bodies": [{"kind": "water", "geometry": geometry}],
    }


HALF = {"type": "box", "min": [0.08, 0.0, 0.0], "max": [0.16, 0.16, 0.06]}


@pytest.mark.parametrize(
    "water",
    [
        {"type": "box", "min": [0.0, 0.0, 0.0], "max": [0.16, 0.16, 0.06], "subtract": [HALF]},
        {"type": "box", "min": [0.0, 0.0, 0.0], "max": [0.16, 0.16, 0.06], "subtract": [{**HALF, "max": [0.16, 0.16, 0.16]}]},
        {"type": "heightfield", "heights": [[0.06] * 17] * 17, "x_range": [0.0, 0.16], "y_range": [0.0, 0.16],
         "subtract": [{**HALF, "max": [0.16, 0.16, 0.16]}]},
    ],
)  # fmt: skip
def test_water_takes_its_subtract(water):
    """A probe (session 25): a water box or height field with its right half subtracted started full (1536.6 cells
    of φ, the uncut volume): the initial φ's shortcuts for those two shapes dropped the cuts. Now the water lies
    in x < 0.08 m only. A cut level with the water's top, or reaching the walls, is pushed out as the water is, so
    no sheet of φ ≈ 0.5 lies on the cut's flush faces: the flush cut and the one up to the lid give the same φ."""
    from couplekit.assembly import initial_phi

    phi = initial_phi(Scene.from_dict(_water_scene(water)))
    cols = phi.sum(axis=(0, 1))  # by x
    assert cols[:3].min() > 0.99 * 96 and cols[-4:].max() < 0.01 * 256  # the left half full, the right empty
    flush = initial_phi(Scene.from_dict(_water_scene({**water, "subtract": [HALF]})))
    if water["type"] == "box":
        # the same to the interface's far tail: there the distance runs to whichever cut face is nearer (the flush
        # cut's pushed-out top at 0.16 m or the other's at 0.26 m), φ < 5e-3 either way
        np.testing.assert_allclose(phi, flush, atol=5e-3)


def test_water_wholly_cut_away_is_refused():
    """A probe (session 25): a water sphere less a larger concentric one was valid and started with 272 cells of
    φ, all interface tail; sand bodies had this refusal already."""
    ball = {"type": "sphere", "center": [0.08, 0.08, 0.08], "radius": 0.04}
    with pytest.raises(SceneError, match=r"bodies\[0\].geometry.subtract.*wholly removed"):
        Scene.from_dict(_water_scene({**ball, "subtract": [{**ball, "radius": 0.05}]}))
    Scene.from_dict(_water_scene({**ball, "subtract": [{**ball, "radius": 0.02}]}))  # a hollow ball is water
