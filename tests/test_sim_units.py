"""``Simulation.fields()`` and ``Simulation.diagnostics()`` report SI units; lattice values only on request.

* fields: velocity m/s, pressure Pa (the hydrostatic start's gradient is ρ_w g), density kg/m³; ``lattice=True``
  gives the solver's own values;
* diagnostics: the fluid's momentum Σ ε ρ u dV (kg m/s), the sand's Σ m v and their total; the solver's lattice
  sums keep a ``lattice_`` prefix. In a periodic box without gravity the drag hands the sand's momentum to the
  water (each step, what the sand loses is the impulse the coupler gave the fluid, to float32 round-off), and
  the total is not conserved: paper 000's buoyancy (Eq. 31) is hydrostatic, so the sand never feels the
  dynamic pressure whose share −ε∇p the fluid feels (strict xfail below, the measured numbers in its docstring).
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.scene import Scene
from couplekit.simulation import Simulation

FACES = ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")


def _tank() -> dict:
    """A walled 8x6x16 two-phase tank, water up to z = 3 cm (12 cells), starting hydrostatic."""
    return {
        "scene": {"name": "units_tank"},
        "domain": {"size": [0.02, 0.015, 0.04], "dx": 0.0025},
        "time": {"dt": 2e-5, "frame_duration": 1e-4, "frames": 1},
        "fluid": {"water_lattice_viscosity": 1e-2, "air_lattice_viscosity": 1e-1, "surface_tension": 0.0},
        "bodies": [{"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.02, 0.015, 0.03]}}],
        "outputs": {"preview": False},
    }


def _exchange_box() -> dict:
    """A periodic 12³ box of water without gravity holding a sand ball that moves at (0.5, 0, −0.3) m/s."""
    return {
        "scene": {"name": "units_exchange"},
        "domain": {
            "size": [0.06, 0.06, 0.06],
            "dx": 0.005,
            "gravity": [0.0, 0.0, 0.0],
            "boundary": {f: "periodic" for f in FACES},
        },
        "time": {"dt": 1e-4, "frame_duration": 1e-3, "frames": 1},
        "fluid": {"phases": 1, "water_lattice_viscosity": 0.01},
        "sand": {"density": 2000.0, "youngs_modulus": 1e5, "periodic_walls": True},
        "bodies": [
            {
                "kind": "sand",
                "velocity": [0.5, 0.0, -0.3],
                "geometry": {"type": "sphere", "center": [0.03, 0.03, 0.03], "radius": 0.012},
            }
        ],
        "outputs": {"preview": False},
    }


def test_fields_are_si_and_lattice_on_request():
    sim = Simulation(Scene.from_dict(_tank()), "cpu", log=None)
    sim.step(3)
    si, lat = sim.fields(), sim.fields(lattice=True)
    u = sim.units
    raw = sim.fluid.fields()
    for k in ("velocity", "pressure", "density", "phi", "solid"):
        np.testing.assert_array_equal(lat[k], raw[k], err_msg=k)
    np.testing.assert_allclose(si["velocity"], lat["velocity"] * u.dx / u.dt, rtol=1e-6)
    np.testing.assert_allclose(si["pressure"], lat["pressure"] * 1000.0 * (u.dx / u.dt) ** 2, rtol=1e-6)
    water, air = si["phi"] > 0.999, si["phi"] < 1e-3
    assert np.allclose(si["density"][water], 1000.0, rtol=1e-3) and np.allclose(si["density"][air], 1.25, rtol=1e-2)
    # hydrostatic: dp/dz = −ρ_w g in the water (Pa/m), 2 % as the two-layer validation
    column = si["pressure"][:, 3, 4].astype(np.float64)
    k = np.arange(1, 5)  # water cells away from the floor and 7 or more cells below the surface (φ > 0.999)
    assert water[k, 3, 4].all()
    slope = np.polyfit(k * u.dx, column[k], 1)[0]
    assert abs(slope / (-1000.0 * 9.81) - 1) < 0.02, slope


def test_diagnostics_report_si_momentum_and_the_drag_hands_it_from_sand_to_water():
    sim = Simulation(Scene.from_dict(_exchange_box()), "cpu", log=None)
    # the drag force kept in a buffer of its own, so that it can be read after the step (lockstep otherwise keeps
    # it in the fluid velocity's buffer, which the collision overwrites with u: SandFluidCoupler.fold_sand_velocity)
    sim.coupler.fold_sand_velocity(False)
    u = sim.units
    impulse_si = u.scale("force_density") * u.dx**3 * u.dt  # one step of a lattice force density in one cell, N s
    d0 = before = sim.diagnostics()
    assert d0["fluid_momentum_x"] == 0.0 and d0["sand_momentum_x"] > 0
    for key in ("lattice_momentum_x", "lattice_kinetic_energy", "total_momentum_z"):
        assert key in d0
    assert "momentum_x" not in d0 and "kinetic_energy" not in d0  # the lattice sums only under their prefix
    for _ in range(6):
        sim.step(1)
        after = sim.diagnostics()
        drag = sim.backend.to_host(sim.fluid.force)[:, 1:-1, 1:-1, 1:-1].astype(np.float64).sum(axis=(1, 2, 3))
        for i, a in enumerate("xyz"):
            assert after[f"total_momentum_{a}"] == pytest.approx(
                after[f"fluid_momentum_{a}"] + after[f"sand_momentum_{a}"], rel=1e-12, abs=1e-15
            )
            lost = before[f"sand_momentum_{a}"] - after[f"sand_momentum_{a}"]
            # the sand loses what the drag gives the water: float32 sums of the particles' m v, 1e-4 of P_sand
            assert abs(lost - drag[i] * impulse_si) <= 1e-4 * abs(d0["sand_momentum_x"]), (a, lost, drag[i])
        before = after
    p0 = d0["sand_momentum_x"]
    assert after["fluid_momentum_x"] > 0.05 * p0  # the water is dragged along ...
    assert d0["sand_momentum_x"] - after["sand_momentum_x"] > 0.05 * p0  # ... by the sand, which slows
    assert after["fluid_momentum_z"] < 0 and after["sand_momentum_z"] > d0["sand_momentum_z"]


@pytest.mark.xfail(
    strict=True,
    reason="known defect: the sand feels only hydrostatic buoyancy (paper Eq. 31), not the dynamic pressure "
    "whose share −ε∇p the fluid feels, so fluid + sand momentum is not conserved where ε varies",
)
def test_total_momentum_is_conserved_in_a_periodic_box_without_gravity():
    """What the issue asks: the total is conserved to 5 % of the momentum exchanged. Measured (6 steps, this
    box, sand momentum 4.5e-3 kg m/s in x): the sand loses 4.1e-4, the water gains 8.1e-4: the total grows by
    0.97 × what was exchanged, the fluid's pressure force −Σ ε ∇p̄ at the ball's edge (the mixture pressure of Eq. 39 answers the
    slip (u − v)·∇ε there) acting on the water with no reaction on the sand."""
    sim = Simulation(Scene.from_dict(_exchange_box()), "cpu", log=None)
    d0 = sim.diagnostics()
    sim.step(6)
    d = sim.diagnostics()
    exchanged = d0["sand_momentum_x"] - d["sand_momentum_x"]
    assert abs(d["total_momentum_x"] - d0["total_momentum_x"]) <= 0.05 * exchanged
