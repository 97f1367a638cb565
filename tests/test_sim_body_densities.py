"""Sand bodies of different densities in one scene (paper 000 Fig. 8): each particle carries its body's
density (SandSolver ``densities=``), and in one tank the light ball rises while the heavy one sinks."""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.sand import SandParams
from couplekit.sand.seeding import seed_box
from couplekit.sand.solver import SandSolver, TimeStepError, elastic_dt_limit
from couplekit.scene import Scene
from couplekit.simulation import Simulation


def test_sand_solver_per_particle_density():
    """mass = density × volume per particle; the elastic Δt limit is that of the lightest particle (the
    fastest P wave, c_p ∝ ϱ^-1/2); one number broadcasts; non-positive densities are refused."""
    be = get_backend("numpy")
    params = SandParams(density=1500.0, youngs_modulus=1e5)
    seeded = seed_box((0.02, 0.02, 0.02), (0.04, 0.04, 0.04), 0.005, ppc=2)
    n = seeded.count
    rho = np.where(np.arange(n) % 2 == 0, 600.0, 1500.0)
    sand = SandSolver(be, (12, 12, 12), 0.005, 1e-4, params, seeded.x, seeded.volume, densities=rho)
    np.testing.assert_allclose(sand.particles()["mass"], rho * seeded.volume, rtol=1e-6)
    light = elastic_dt_limit(SandParams(density=600.0, youngs_modulus=1e5), 0.005)
    assert sand.max_stable_dt() == pytest.approx(light, rel=1e-12)
    assert light < elastic_dt_limit(params, 0.005)
    with pytest.raises(TimeStepError):
        SandSolver(be, (12, 12, 12), 0.005, 1.01 * light, params, seeded.x, seeded.volume, densities=rho)
    one = SandSolver(be, (12, 12, 12), 0.005, 1e-4, params, seeded.x, seeded.volume, densities=2000.0)
    np.testing.assert_allclose(one.particles()["mass"], 2000.0 * seeded.volume, rtol=1e-6)
    default = SandSolver(be, (12, 12, 12), 0.005, 1e-4, params, seeded.x, seeded.volume)
    np.testing.assert_allclose(default.particles()["mass"], 1500.0 * seeded.volume, rtol=1e-6)
    with pytest.raises(ValueError, match="densities must be > 0"):
        SandSolver(be, (12, 12, 12), 0.005, 1e-4, params, seeded.x, seeded.volume, densities=-rho)


def _two_balls() -> dict:
    """A closed 18 x 10 x 24 tank (dx = 1 cm, Δt = 2e-4 s) of water to 18 cells under air, two submerged
    balls (radius 3 cells, centres 9 cells up): 600 kg/m³ at x = 5 cm, 1500 kg/m³ at x = 13 cm; the scene's
    sand.density (1200) is the default that both bodies override. Water viscosity 1e-3 (lattice), as in
    tests/test_seeding_buoyancy.py."""

    def ball(x: float, density: float) -> dict:
        geo = {"type": "sphere", "center": [x, 0.05, 0.09], "radius": 0.03}
        return {"kind": "sand", "name": f"ball {density:g}", "density": density, "geometry": geo}

    return {
        "scene": {"name": "two_balls"},
        "domain": {"size": [0.18, 0.10, 0.24], "dx": 0.01},
        "time": {"dt": 2e-4, "frame_duration": 0.01, "frames": 4},
        "fluid": {"water_lattice_viscosity": 1e-3, "air_lattice_viscosity": 1e-2, "surface_tension": 0.073},
        "sand": {"density": 1200.0, "youngs_modulus": 1e5},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.18, 0.10, 0.18]}},
            ball(0.05, 600.0),
            ball(0.13, 1500.0),
        ],
        "outputs": {"preview": False},
    }


def test_two_balls_of_different_densities_in_one_tank():
    """Each particle's mass is its body's density × its grain volume; after 400 steps (0.08 s) the 600 kg/m³
    ball has risen and the 1500 kg/m³ one sunk, each by at least 30 % of its drag-free distance
    ½ |ϱ − ρ_w| g t² / ϱ (21 and 10.5 mm) and at most 102 % of it (the same bounds and reasons as
    tests/test_seeding_buoyancy.py, where each ball is alone)."""
    sim = Simulation(Scene.from_dict(_two_balls()), backend="cpu", log=None)
    p = sim.particles()
    light = p["x"][0] < 0.09
    vol = p["volume"]
    np.testing.assert_allclose(p["mass"][light], 600.0 * vol[light], rtol=1e-6)
    np.testing.assert_allclose(p["mass"][~light], 1500.0 * vol[~light], rtol=1e-6)
    z0 = {k: p["x"][2][m].mean() for k, m in (("light", light), ("heavy", ~light))}
    sim.step(400)
    x = sim.particles()["x"]
    assert np.isfinite(x).all()
    t = 400 * 2e-4
    for key, mask, rho in (("light", light, 600.0), ("heavy", ~light, 1500.0)):
        dz = float(x[2][mask].mean() - z0[key])
        free = -0.5 * (rho - 1000.0) * 9.81 / rho * t**2
        print(f"{rho:g}: dz {1e3 * dz:.2f} mm ({dz / free:.2f} of drag-free)")
        assert 0.3 < dz / free < 1.02, (rho, dz, free)
    assert (x[0][light] < 0.09).all()  # the balls stay apart
