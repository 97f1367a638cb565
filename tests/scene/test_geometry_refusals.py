"""Scenes whose geometry would silently do something other than it says are refused, naming the key and the fix
(each found by probing untuned scenes): a sand jet emitted into an obstacle, an obstacle the fluid cannot see,
a sand height field down in the MPM walls, a sand body its own ``subtract`` removes; and what they must not
refuse (the same scenes made right, a water height field with the default base)."""

from __future__ import annotations

import copy

import pytest

from couplekit.scene import Scene, SceneError

DOMAIN = {"size": [0.12, 0.12, 0.12], "dx": 0.005}
TIME = {"dt": 1e-4, "frames": 1, "frame_duration": 0.001}


def _jet_scene(plate_min_x: float) -> dict:
    """A sand-carrying outlet in the x_min wall and a plate in front of it from ``plate_min_x`` (2 cells thick)."""
    return {
        "domain": {**DOMAIN, "boundary": {"x_min": "wall"}},
        "time": TIME,
        "sand": {"particles_per_cell": 8, "jitter": 0.0},
        "fluid": {"phases": 2, "interface_width": 4},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.12, 0.12, 0.03]}},
            {
                "kind": "obstacle",
                "geometry": {"type": "box", "min": [plate_min_x, 0.03, 0.05], "max": [plate_min_x + 0.01, 0.09, 0.11]},
            },
        ],
        "inflows": [
            {
                "face": "x_min",
                "shape": "rect",
                "center": [0.06, 0.08],
                "size": [0.03, 0.02],
                "velocity": [1.0, 0, 0],
                "sand_fraction": 0.3,
            }
        ],
    }


@pytest.mark.parametrize("plate_min_x", [0.0, 0.01])
def test_a_sand_jet_emitted_into_an_obstacle_is_refused(plate_min_x):
    """Particles are emitted 2 cells (sand.wall_layers) inside the face: a plate over the outlet or in front of it
    within that depth held them inside the solid, or pushed them out through the face until they went NaN."""
    with pytest.raises(SceneError) as err:
        Scene.from_dict(_jet_scene(plate_min_x))
    text = str(err.value)
    assert "inflows[0]" in text and "bodies[1]" in text and "sand_fraction = 0" in text


def test_a_sand_jet_clear_of_obstacles_is_valid():
    Scene.from_dict(_jet_scene(0.03))  # 6 cells from the face: clear
    water_jet = _jet_scene(0.01)  # a plate 2 cells off the face, over an outlet carrying no sand: water flows past
    water_jet["inflows"][0]["sand_fraction"] = 0.0
    del water_jet["sand"]
    Scene.from_dict(water_jet)


@pytest.mark.parametrize("sand_fraction", [0.0, 0.3])
def test_an_outlet_wholly_behind_an_obstacle_is_refused(sand_fraction):
    """A probe (session 25): a water outlet whose every cell in front lay inside an obstacle validated and ran with
    nothing entering. Refused whatever the jet carries; partly covered, it is valid (water enters beside the
    plate)."""
    d = _jet_scene(0.0)  # the plate on the face covers the whole outlet
    d["inflows"][0]["sand_fraction"] = sand_fraction
    if not sand_fraction:
        del d["sand"]
    with pytest.raises(SceneError, match=r"inflows\[0\].*every cell in front of the inflow.*nothing would enter"):
        Scene.from_dict(d)
    d["bodies"][1]["geometry"]["max"][1] = 0.06  # the plate now ends half-way across the outlet
    if not sand_fraction:
        Scene.from_dict(d)


def _partition(thickness: float, dx: float = 0.005) -> dict:
    half = 0.06
    return {
        "domain": {**DOMAIN, "dx": dx},
        "time": TIME,
        "fluid": {},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [half - 0.002, 0.12, 0.1]}},
            {
                "kind": "obstacle",
                "name": "partition",
                "geometry": {
                    "type": "box",
                    "min": [half - thickness / 2, 0, 0],
                    "max": [half + thickness / 2, 0.12, 0.12],
                },
            },
        ],
    }


@pytest.mark.parametrize("dx", [0.005, 0.004])
def test_an_obstacle_the_fluid_cannot_see_is_refused(dx):
    """A wall between two cell centres (0.8 dx, centred on a cell face) is no solid cell: water flowed through
    the partition.  At twice that thickness it covers a layer of cells and is valid."""
    with pytest.raises(SceneError, match=r"bodies\[1\]\.geometry: the obstacle covers no cell centre"):
        Scene.from_dict(_partition(0.8 * dx, dx))
    Scene.from_dict(_partition(2.0 * dx, dx))


def _heightfield(kind: str, base: float | None) -> dict:
    span = [0.01, 0.11] if kind == "sand" else [0.0, 0.12]  # sand keeps off the side walls too
    geometry = {"type": "heightfield", "heights": [[0.03, 0.04], [0.03, 0.04]], "x_range": span, "y_range": span}
    if base is not None:
        geometry["base"] = base
    d = {"domain": DOMAIN, "time": TIME, "bodies": [{"kind": kind, "geometry": geometry}]}
    if kind == "water":
        d["fluid"] = {}
    return d


def test_a_water_height_field_takes_the_default_base():
    """The documented default base (one cell below the domain) was refused for every water height field as
    reaching outside the domain."""
    default = Scene.from_dict(_heightfield("water", None))
    assert default.bodies[0].geometry.params.get("base") is None
    Scene.from_dict(_heightfield("water", 0.0))


def test_a_sand_height_field_needs_its_base_above_the_mpm_walls():
    with pytest.raises(SceneError, match=r"bodies\[0\]\.geometry\.base: .*set geometry\.base = 0\.01"):
        Scene.from_dict(_heightfield("sand", None))
    Scene.from_dict(_heightfield("sand", 0.01))


def test_a_sand_body_removed_by_its_own_subtract_says_so():
    """It was reported as 'thinner than the particle spacing', with a fix (more particles) that cannot help."""
    d = {
        "domain": DOMAIN,
        "time": TIME,
        "bodies": [
            {
                "kind": "sand",
                "geometry": {
                    "type": "box",
                    "min": [0.02, 0.02, 0.02],
                    "max": [0.10, 0.10, 0.10],
                    "subtract": [{"type": "sphere", "center": [0.06, 0.06, 0.06], "radius": 0.1}],
                },
            }
        ],
    }
    with pytest.raises(SceneError, match=r"geometry\.subtract: .*wholly removed by its own geometry\.subtract"):
        Scene.from_dict(d)
    partly = copy.deepcopy(d)
    partly["bodies"][0]["geometry"]["subtract"][0]["radius"] = 0.03
    Scene.from_dict(partly)


def test_validate_and_run_set_can_fix_an_invalid_file(tmp_path, capsys):
    """--set applies to the file's own table before it is validated: a time step that breaks the sand's limit in
    the file is fixed by --set time.dt (it was refused with the value the option replaces); a --set that does
    not fix it is refused naming the setting."""
    from couplekit.cli import main

    scene = tmp_path / "s.toml"
    scene.write_text(
        "[domain]\nsize = [0.12, 0.12, 0.12]\ndx = 0.005\n[time]\ndt = 1e-2\nframes = 1\nframe_duration = 0.001\n"
        '[[bodies]]\nkind = "sand"\n[bodies.geometry]\ntype = "sphere"\ncenter = [0.06, 0.06, 0.06]\nradius = 0.03\n'
    )
    assert main(["validate", str(scene)]) == 2
    capsys.readouterr()
    assert main(["validate", str(scene), "--set", "time.dt=1e-4"]) == 0
    assert "valid" in capsys.readouterr().out
    assert main(["validate", str(scene), "--set", "time.dt=2e-2"]) == 2
    assert "with time.dt = 0.02" in capsys.readouterr().err
    assert main(["run", str(scene), "--set", "time.dt=1e-4", "--out", str(tmp_path / "o"), "--backend", "numpy",
                 "--no-progress"]) == 0  # fmt: skip


def test_bench_with_an_unknown_backend_is_an_error_not_a_traceback(tmp_path, capsys):
    from couplekit.cli import main

    assert main(["bench", "--tiny", "--backend", "bogus", "--out", str(tmp_path / "b")]) == 2
    assert "--backend bogus" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()
