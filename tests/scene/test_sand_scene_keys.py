"""The sand scene keys of issue 17: ``bodies[].saturation``, ``[sand.walls]`` per face and ``sand.grain_diameter``.

Validation (each refusal names its key), and that each value reaches the solver the Python API would build:
the particles' saturation, the sand's :class:`~couplekit.sand.boundaries.DomainWalls`, the coupler's
:class:`~couplekit.coupling.params.CouplingParams` and initial moisture. The physics of the walls and of the
saturation is in tests/sand/test_scene_walls_saturation.py; the grain-area drag's settling speed against its
closed form in tests/coupling/test_coupling_drag.py (parametrized over the paper's area and a grain diameter).
"""

from __future__ import annotations

import numpy as np
import pytest
from sim_scenes import tiny_coupled, tiny_sand

from couplekit.assembly import assemble, sand_walls
from couplekit.coupling.params import CouplingParams
from couplekit.sand.boundaries import DomainWalls, Wall, pack_walls
from couplekit.scene import Scene
from couplekit.scene.schema import SceneError


@pytest.fixture(scope="module")
def cpu(cpu_backend):
    return cpu_backend


def _refused(data: dict) -> dict[str, str]:
    """The problems of a scene that must be refused, by dotted key."""
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data)
    return {p.key: p.message for p in info.value.problems}


def _air_box(**body) -> dict:
    """A 16³ two-phase box of air (no water body) with one retaining sand block 8 x 8 x 6 cells."""
    return {
        "domain": {"size": [0.08, 0.08, 0.08], "dx": 0.005},
        "time": {"dt": 2e-5, "frame_duration": 2e-5, "frames": 1},
        "fluid": {"water_lattice_viscosity": 1e-2, "air_lattice_viscosity": 1e-1},
        "sand": {"density": 1500.0, "youngs_modulus": 1e5},
        "bodies": [
            {
                "kind": "sand",
                "retention": True,
                **body,
                "geometry": {"type": "box", "min": [0.02] * 3, "max": [0.06, 0.06, 0.05]},
            }
        ],
        "outputs": {"preview": False},
    }


# ------------------------------------------------------------------------------------------ [sand.walls]
def test_without_sand_walls_every_face_is_the_old_separating_wall():
    """No [sand.walls]: the walls are what assembly built before the table existed (every face 'separate' with
    sand.wall_friction), so existing scenes run unchanged (the examples' particles after 3 steps were compared
    bit for bit with the main branch when the table was added)."""
    d = tiny_sand()
    d["sand"]["wall_friction"] = 0.7
    d["sand"]["wall_layers"] = 3
    scene = Scene.from_dict(d)
    assert set(scene.sand.walls) == {"x_min", "x_max", "y_min", "y_max", "z_min", "z_max"}
    old = DomainWalls.uniform("separate", 0.7, bound=3)
    assert sand_walls(scene) == old
    np.testing.assert_array_equal(pack_walls(sand_walls(scene)), pack_walls(old))


def test_per_face_walls_reach_the_right_solver_faces(cpu):
    d = tiny_sand()
    d["sand"]["wall_friction"] = 0.7
    d["sand"]["walls"] = {
        "x_min": {"kind": "slip"},
        "x_max": {"kind": "sticky"},
        "y_min": {"friction": 0.2},
        "z_max": {"friction": 0.0},
        "z_min": {"kind": "separate"},
    }
    sand = assemble(Scene.from_dict(d), cpu, timing=False).sand
    want = (
        Wall("slip"),  # -x
        Wall("sticky"),  # +x
        Wall("separate", 0.2),  # -y
        Wall("separate", 0.7),  # +y: not named, sand.wall_friction
        Wall("separate", 0.7),  # -z: named without friction, sand.wall_friction
        Wall("separate", 0.0),  # +z: frictionless, the sand may lift off
    )
    assert sand.walls.faces == want
    np.testing.assert_array_equal(np.asarray(sand._walls), pack_walls(DomainWalls(want, 2)))


def test_sand_walls_refusals_name_the_face_and_key():
    d = tiny_sand()
    d["sand"]["walls"] = {
        "z_mn": {"friction": 0.3},
        "x_min": {"kind": "slip", "friction": 0.2},
        "x_max": {"kind": "slippery"},
        "y_min": {"friction": -1.0},
        "y_max": 0.3,
    }
    problems = _refused(d)
    assert set(problems) == {
        "sand.walls.z_mn",
        "sand.walls.x_min.friction",
        "sand.walls.x_max.kind",
        "sand.walls.y_min.friction",
        "sand.walls.y_max",
    }
    assert "unknown face" in problems["sand.walls.z_mn"]
    assert "only 'separate' faces" in problems["sand.walls.x_min.friction"]
    d["sand"]["walls"] = "slip"
    assert "sand.walls" in _refused(d)


# ------------------------------------------------------------------------------------------ saturation
def test_body_saturation_is_seeded_into_its_particles_only(cpu):
    d = tiny_sand()
    wet = dict(d["bodies"][0], saturation=0.1)
    dry = {"kind": "sand", "geometry": {"type": "box", "min": [0.012, 0.012, 0.012], "max": [0.02, 0.02, 0.02]}}
    d["bodies"] = [wet, dry]
    scene = Scene.from_dict(d)
    assert [b.saturation for b in scene.bodies] == [0.1, None]
    sand = assemble(scene, cpu, timing=False).sand
    s = sand.particles()["saturation"]
    n_wet = 4 * 4 * 3 * 8  # the first body: 4 x 4 x 3 cells, 8 particles each, seeded first
    assert s.size > n_wet
    np.testing.assert_array_equal(s[:n_wet], np.float32(0.1))
    np.testing.assert_array_equal(s[n_wet:], 0.0)
    sand.step(5)  # nothing changes it in a sand-only scene
    np.testing.assert_array_equal(sand.particles()["saturation"][:n_wet], np.float32(0.1))


def test_no_saturation_key_seeds_dry_sand_as_before(cpu):
    sand = assemble(Scene.from_dict(tiny_sand()), cpu, timing=False).sand
    np.testing.assert_array_equal(sand.particles()["saturation"], 0.0)


def test_saturation_refusals():
    d = tiny_sand()
    d["bodies"][0]["saturation"] = 0.45  # pores of sand packed at 0.6 hold 0.4
    d["bodies"][1]["saturation"] = 0.1  # an obstacle
    problems = _refused(d)
    assert "pores" in problems["bodies[0].saturation"]
    assert "only sand bodies" in problems["bodies[1].saturation"]
    d["bodies"][0]["saturation"] = 1.5
    d["bodies"][1].pop("saturation")
    assert "<= 1" in _refused(d)["bodies[0].saturation"]


def test_saturation_with_a_fluid_needs_retention_within_capacity():
    """With a fluid the coupler recomputes the saturation from the water each step (Eq. 59): refused on a body
    that does not retain water, and above the retention capacity r_max ε0."""
    d = tiny_coupled(retention=False)
    d["bodies"][-1]["saturation"] = 0.1
    assert "does not retain water" in _refused(d)["bodies[3].saturation"]
    d = tiny_coupled(retention=True)
    d["bodies"][-1]["saturation"] = 0.17  # r = 0.17 / 0.6 = 0.283 > max_moisture 0.28
    assert "capacity" in _refused(d)["bodies[3].saturation"]
    d["bodies"][-1]["saturation"] = 0.16
    Scene.from_dict(d)


def test_saturation_with_a_fluid_starts_as_bound_water(cpu):
    """A retaining body of saturation S starts with moisture ratio r = S / ε0, so the coupler's saturation
    (bound water R = r ε of a packed node, no free water in air) reads S inside the body after a step."""
    a = assemble(Scene.from_dict(_air_box(saturation=0.1)), cpu, timing=False)
    r = a.backend.to_host(a.coupler.moisture_ratio)
    np.testing.assert_allclose(r, 0.1 / 0.6, rtol=1e-6)
    a.scheduler.step(2)
    p = a.sand.particles()
    inner = np.all((p["x"] > 0.03) & (p["x"] < 0.05), axis=0) & (p["x"][2] < 0.04)  # a cell from the surface
    assert inner.sum() > 100
    np.testing.assert_allclose(p["saturation"][inner], 0.1, rtol=0.03)


def test_saturation_without_cohesion_is_noted(cpu):
    d = tiny_sand()
    d["bodies"][0]["saturation"] = 0.1
    d["effects"] = {"cohesion": False}
    notes = []
    assemble(Scene.from_dict(d), cpu, timing=False, log=notes.append)
    assert any("saturation has no effect" in n for n in notes), notes


# ------------------------------------------------------------------------------------------ grain_diameter
@pytest.mark.parametrize("grain", [None, 2e-4])
def test_grain_diameter_reaches_the_coupler_as_the_api_builds_it(cpu, grain):
    d = _air_box()
    if grain is not None:
        d["sand"]["grain_diameter"] = grain
    scene = Scene.from_dict(d)
    assert scene.sand.grain_diameter == grain
    coupler = assemble(scene, cpu, timing=False).coupler
    sd = scene.sand
    direct = CouplingParams(
        retention=True, r_max=sd.max_moisture, absorption_rate=sd.absorption_rate, grain_diameter=grain
    )
    assert coupler.params == direct
    assert coupler.params.grain_diameter_lattice(scene.domain.dx) == (0.0 if grain is None else grain / 0.005)


def test_grain_diameter_refusals_and_sand_only_note(cpu):
    d = _air_box()
    d["sand"]["grain_diameter"] = 0.01  # two cells
    assert "larger than a cell" in _refused(d)["sand.grain_diameter"]
    d["sand"]["grain_diameter"] = 0.0
    assert "> 0" in _refused(d)["sand.grain_diameter"]
    s = tiny_sand()
    s["sand"]["grain_diameter"] = 2e-4
    notes = []
    assemble(Scene.from_dict(s), cpu, timing=False, log=notes.append)
    assert any("grain_diameter has no effect" in n for n in notes), notes


def _block_on_floor(container_until=None):
    """tiny_sand's box without the obstacle: a dry block 2 cm wide and 4 cm tall on the floor (its sand solver)."""
    d = tiny_sand()
    block = {"kind": "sand", "geometry": {"type": "box", "min": [0.02, 0.02, 0.01], "max": [0.04, 0.04, 0.05]}}
    if container_until is not None:
        block["container_until"] = container_until
    d["bodies"] = [block]
    return d


def _top(sand) -> float:
    """99th percentile of the particles' height, m."""
    return float(np.percentile(sand.particles()["x"][2], 99))


def test_container_holds_the_block_until_its_time_then_it_collapses(cpu):
    """bodies[i].container_until (paper Fig. 17's invisible container): side walls on the body's bounding box
    until that time, none after. Without one the dry block slumps at once (measured top 0.0487 -> 0.031 m by
    0.06 s); in a container removed at 0.03 s it keeps its top and width to then (measured 0.0489 m, no particle
    beyond its box) and has collapsed to 0.0255 m by 0.1 s."""
    free = assemble(Scene.from_dict(_block_on_floor()), cpu, timing=False).sand
    h0 = _top(free)
    free.step(300)  # 0.06 s
    assert _top(free) < 0.8 * h0
    held = assemble(Scene.from_dict(_block_on_floor(0.03)), cpu, timing=False).sand
    held.step(150)  # 0.03 s
    assert _top(held) > 0.98 * h0
    assert np.abs(held.particles()["x"][:2] - 0.03).max() <= 0.01
    held.step(350)  # to 0.1 s
    assert _top(held) < 0.6 * h0


def test_container_refused_on_other_bodies():
    d = tiny_sand()
    d["bodies"][1]["container_until"] = 0.1  # the obstacle
    assert "only sand bodies" in _refused(d)["bodies[1].container_until"]
    d["bodies"][1].pop("container_until")
    d["bodies"][0]["container_until"] = 0.0
    assert "bodies[0].container_until" in _refused(d)


# ------------------------------------------------------------------------------------------ sand.viscosity
def test_sand_viscosity_reaches_the_sand_solver_and_refuses_bad_values(cpu):
    """``sand.viscosity`` (Pa s, default 0: the paper's rate-independent return) is the SandParams.viscosity
    of the assembled solver, and a negative, NaN or non-number value is refused naming the key."""
    d = tiny_sand()
    assert assemble(Scene.from_dict(d), cpu, timing=False).sand.params.viscosity == 0.0
    d["sand"]["viscosity"] = 1.5
    scene = Scene.from_dict(d)
    assert scene.sand.viscosity == 1.5
    assert assemble(scene, cpu, timing=False).sand.params.viscosity == 1.5
    for bad in (-1.0, float("nan"), "thick"):
        d["sand"]["viscosity"] = bad
        assert "sand.viscosity" in _refused(d), bad
