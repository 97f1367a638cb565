"""Outlets in scene files: ``[[inflows]]`` with ``shape = "rect" | "disc"`` (couplekit issue 6).

Validation refuses, naming the key: an outlet outside its face, on a periodic face, covering no cell, on a
face whose boundary is 'inflow', missing or extra keys, overlapping outlets. A valid outlet becomes INFLOW
ghost cells of the fluid exactly where its cells are, the rest of the face keeping its boundary.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.fluid.grid import INFLOW, OUTFLOW, WALL, face_plane_index
from couplekit.fluid.inflow import region_mask
from couplekit.scene import Scene
from couplekit.scene.schema import SceneError
from couplekit.simulation import Simulation

DX = 0.0025


def _jet_scene(*inflows: dict, boundary: dict | None = None) -> dict:
    """A 12 × 8 × 16 two-phase box of air (a thin water layer on the floor), outflow at the top."""
    return {
        "scene": {"name": "outlet_jet"},
        "domain": {"size": [12 * DX, 8 * DX, 16 * DX], "dx": DX, "boundary": {"z_max": "outflow", **(boundary or {})}},
        "time": {"dt": 2e-5, "frame_duration": 1e-4, "frames": 1},
        "fluid": {"water_lattice_viscosity": 1e-2, "air_lattice_viscosity": 1e-2, "surface_tension": 0.0},
        "inflows": list(inflows),
        "outputs": {"preview": False},
    }


def _keys(d: dict) -> list[str]:
    with pytest.raises(SceneError) as e:
        Scene.from_dict(d)
    return e.value.keys


def test_outlet_errors_name_the_key():
    rect = {"face": "z_min", "velocity": [0, 0, 0.5], "shape": "rect", "center": [0.015, 0.01], "size": [0.01, 0.005]}
    # outside the face: x from 0.025 to 0.035 on a 0.03 m face
    assert "inflows[0].center" in _keys(_jet_scene({**rect, "center": [0.03, 0.01]}))
    # on a periodic face
    keys = _keys(_jet_scene(rect, boundary={"z_min": "periodic", "z_max": "periodic"}))
    assert "inflows[0].face" in keys
    # zero area: the sides must be > 0 (schema), and a sliver between cell centres covers no cell
    assert "inflows[0].size[0]" in _keys(_jet_scene({**rect, "size": [0.0, 0.005]}))
    assert "inflows[0].size" in _keys(_jet_scene({**rect, "center": [0.0025, 0.0025], "size": [0.001, 0.001]}))
    assert "inflows[0].radius" in _keys(
        _jet_scene(
            {"face": "z_min", "velocity": [0, 0, 0.5], "shape": "disc", "center": [0.0025, 0.0025], "radius": 5e-4}
        )
    )
    # an outlet on a face whose boundary is 'inflow'
    assert "domain.boundary.z_min" in _keys(_jet_scene(rect, boundary={"z_min": "inflow"}))
    # missing and extra keys
    assert "inflows[0].size" in _keys(_jet_scene({k: v for k, v in rect.items() if k != "size"}))
    assert "inflows[0].radius" in _keys(_jet_scene({**rect, "radius": 0.003}))
    assert "inflows[0].center" in _keys(
        _jet_scene({"face": "z_min", "velocity": [0, 0, 0.5], "center": [0.015, 0.01]}, boundary={"z_min": "inflow"})
    )
    # overlapping outlets
    assert "inflows[1].center" in _keys(_jet_scene(rect, {**rect, "center": [0.016, 0.011]}))
    # a whole-face inflow and an outlet on one face
    keys = _keys(_jet_scene({"face": "z_min", "velocity": [0, 0, 0.5]}, rect, boundary={"z_min": "inflow"}))
    assert "inflows[1].face" in keys
    # the velocity must still point in
    assert "inflows[0].velocity" in _keys(_jet_scene({**rect, "velocity": [0, 0, -0.5]}))


def test_outlets_become_inflow_ghosts_and_the_rest_keeps_its_kind():
    """A rect and a disc outlet on the z_min wall and a disc on the x_max outflow face: the fluid's flags are
    INFLOW exactly at the rasterised cells, WALL / OUTFLOW elsewhere on those faces; the ghost velocity is the
    inflow velocity in lattice units and the carried φ is 1 for water, 0 for wind."""
    scene = Scene.from_dict(
        _jet_scene(
            {"face": "z_min", "velocity": [0, 0, 0.5], "shape": "rect", "center": [0.01, 0.01], "size": [0.01, 0.005]},
            {"face": "z_min", "velocity": [0, 0, 0.25], "shape": "disc", "center": [0.024, 0.01], "radius": 0.0045},
            {
                "face": "x_max",
                "kind": "wind",
                "velocity": [-0.5, 0, 0],
                "shape": "disc",
                "center": [0.01, 0.02],
                "radius": 0.004,
            },
            boundary={"x_max": "outflow"},
        )
    )
    sim = Simulation(scene, "numpy", log=None)
    fl = sim.fluid
    flags = np.asarray(fl.flags)
    shape = scene.domain.shape
    rect = region_mask(shape, DX, "z-", "rect", (0.01, 0.01), size=(0.01, 0.005))
    disc = region_mask(shape, DX, "z-", "disc", (0.024, 0.01), radius=0.0045)
    side = region_mask(shape, DX, "x+", "disc", (0.01, 0.02), radius=0.004)
    assert rect.sum() == 8 and disc.sum() > 0 and side.sum() > 0
    lo, xp = face_plane_index(shape, "z-"), face_plane_index(shape, "x+")
    np.testing.assert_array_equal(flags[lo], np.where(rect | disc, INFLOW, WALL))
    np.testing.assert_array_equal(flags[xp], np.where(side, INFLOW, OUTFLOW))
    vel = np.asarray(fl.velocity)
    u = sim.units.to_lattice(1.0, "velocity")
    np.testing.assert_allclose(vel[(2, *lo)][rect], 0.5 * u, rtol=1e-6)
    np.testing.assert_allclose(vel[(2, *lo)][disc], 0.25 * u, rtol=1e-6)
    np.testing.assert_allclose(vel[(0, *xp)][side], -0.5 * u, rtol=1e-6)
    # the carried phase: water ramps up from the air it faces (inflow front), wind stays air
    sim.step(1)
    assert np.all(np.asarray(fl.phi)[xp][side] == 0.0)
    assert np.all(np.asarray(fl.phi)[lo][rect] > 0.0)


def test_water_jet_scene_from_an_outlet_runs():
    """The scene path end to end on the cpu backend: a water jet (0.5 m/s = 0.004 in lattice units) from
    a 4 × 2-cell outlet into air at 800:1 for 150 steps: finite, and the water volume grows (the front ramp
    lets water in from the first steps)."""
    d = _jet_scene(
        {"face": "z_min", "velocity": [0, 0, 0.5], "shape": "rect", "center": [0.015, 0.01], "size": [0.01, 0.005]}
    )
    sim = Simulation(Scene.from_dict(d), "cpu", log=None)
    v0 = sim.diagnostics()["fluid_volume"]
    sim.step(150)
    diag = sim.diagnostics()
    assert np.isfinite(diag["max_lattice_speed"]) and diag["max_lattice_speed"] < 0.3, diag
    assert diag["fluid_volume"] > v0
    assert np.isfinite(sim.fields()["velocity"]).all()
