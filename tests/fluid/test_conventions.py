"""One set of conventions: the solver's defaults are explicit next to a scene's, the odd-rate floor says when it
acts, and every API takes the scenes' face names (``x_min`` …) with the older spellings as aliases."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from couplekit.assembly import assemble
from couplekit.backend import get_backend
from couplekit.faces import SCENE_FACES, scene_face, solver_face, wall_face
from couplekit.fluid import Boundaries, FluidParams, FluidSolver, OddFloorInactiveWarning
from couplekit.fluid.grid import Face, InflowRegion
from couplekit.sand.boundaries import DomainWalls, Wall
from couplekit.scene import Scene


def _default_scene(phases: int = 2) -> Scene:
    """A scene whose [fluid] table and domain.boundary set nothing but what FluidParams cannot default (SI
    gravity and surface tension)."""
    return Scene.from_dict(
        {
            "domain": {"size": [0.04, 0.04, 0.04], "dx": 0.005, "gravity": [0.0, 0.0, 0.0]},
            "time": {"dt": 1e-4},
            "fluid": {"phases": phases, "surface_tension": 0.0},
            "bodies": [{"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.04, 0.04, 0.02]}}],
            "outputs": {"preview": False},
        }
    )


def test_scene_defaults_are_the_fluid_a_scene_gets():
    notes = []
    asm = assemble(_default_scene(), get_backend("numpy"), log=notes.append)
    assert asm.fluid_params == FluidParams.scene_defaults()
    assert asm.fluid.boundaries.scene_faces() == Boundaries.scene_defaults().scene_faces()
    # ... and they differ from the bare constructors, which the docstrings say
    assert FluidParams() != FluidParams.scene_defaults()
    assert all(f.kind == "periodic" for f in Boundaries().scene_faces().values())
    assert all(f.kind == "wall" for f in Boundaries.scene_defaults().scene_faces().values())
    assert asm.fluid.odd_floor_active and not notes  # ν_h = 1e-4: the scene's floor acts, nothing to note
    assert FluidParams.scene_defaults(nu_h=0.02).nu_h == 0.02
    with pytest.raises(TypeError, match="no field"):
        FluidParams.scene_defaults(viscosity=0.1)


@pytest.mark.parametrize(
    ("nu_h", "nu_l", "two_phase", "acts"),
    [(1e-4, 1e-2, True, True), (1e-3, 1e-2, True, False), (1e-2, 1e-4, True, True), (1e-2, 1e-4, False, False)],
)
def test_odd_floor_acts_only_below_its_viscosity_threshold(nu_h, nu_l, two_phase, acts):
    prm = FluidParams(nu_h=nu_h, nu_l=nu_l, odd_lambda=0.015)
    assert prm.odd_floor_acts(two_phase) is acts
    assert not FluidParams(nu_h=nu_h, nu_l=nu_l).odd_floor_acts(two_phase)  # odd_lambda = 0: never
    phi = np.ones((4, 4, 4), np.float32) if two_phase else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        solver = FluidSolver(get_backend("numpy"), (4, 4, 4), prm, phi=phi)
    assert solver.odd_floor_active is acts
    inactive = [w for w in caught if issubclass(w.category, OddFloorInactiveWarning)]
    assert len(inactive) == (0 if acts else 1)
    if inactive:
        assert "does nothing" in str(inactive[0].message) and "odd_lambda = 0" in str(inactive[0].message)


def test_a_scene_notes_an_inactive_floor_instead_of_warning():
    d = _default_scene().to_dict()
    d["fluid"]["water_lattice_viscosity"] = 1e-2
    notes = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", OddFloorInactiveWarning)
        asm = assemble(Scene.from_dict(d), get_backend("numpy"), log=notes.append)
    assert not asm.fluid.odd_floor_active
    assert any("odd_lambda = 0.015 does nothing" in n for n in notes), notes


def test_every_face_api_takes_the_scene_names_and_the_old_spellings():
    assert [solver_face(f) for f in SCENE_FACES] == ["x-", "x+", "y-", "y+", "z-", "z+"]
    assert [scene_face(f) for f in ("x-", "+y", "z_max")] == ["x_min", "y_max", "z_max"]
    assert [wall_face(f) for f in ("x_min", "x+", "-z")] == ["-x", "+x", "-z"]
    by_scene = Boundaries({"x_min": Face("wall"), "x_max": Face("outflow")})
    by_alias = Boundaries({"x-": Face("wall"), "x+": Face("outflow")})
    assert by_scene == by_alias and by_scene.face("x_max").kind == by_scene.face("x+").kind == "outflow"
    assert Boundaries.channel("y", moving={"y_max": (0.01, 0, 0)}) == Boundaries.channel("y", {"y+": (0.01, 0, 0)})
    region = InflowRegion("z_min", np.ones((4, 4), bool), (0, 0, 0.01))
    assert region.face == "z-"
    walls = {"x_min": Wall("slip", 0.3), "z_max": Wall("sticky")}
    assert DomainWalls.from_dict(walls) == DomainWalls.from_dict({"-x": Wall("slip", 0.3), "+z": Wall("sticky")})
    with pytest.raises(ValueError, match="x_min, x_max"):
        Boundaries({"left": Face("wall")})
    with pytest.raises(ValueError, match="given twice"):
        Boundaries({"x_min": Face("wall"), "x-": Face("wall"), "x+": Face("wall")})
    with pytest.raises(ValueError, match="x_min, x_max"):
        DomainWalls.from_dict({"bottom": Wall()})
