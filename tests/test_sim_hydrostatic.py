"""Simulation starts the water hydrostatic: the pressure profile itself, and tanks at rest that stay at rest."""

from __future__ import annotations

import numpy as np
import pytest

import couplekit.fluid.hydrostatic as hydrostatic
from couplekit.scene import Scene
from couplekit.simulation import Simulation, hydrostatic_pressure

DX, DT = 0.005, 1e-4
G_LAT = 9.81 * DT**2 / DX  # 1.96e-5


def test_profile_is_the_cell_centred_integral_of_rho_g():
    """Single phase, gravity −z: p_k = |g| (nz − k − ½) (cells counted from the top face); gravity +x
    integrates from the x = 0 face; two-phase: the slope is ρ(φ)|g| on each side of the interface;
    no profile for oblique gravity, none for gravity along a periodic axis."""
    shape = (6, 3, 4)
    p = hydrostatic_pressure(shape, (0.0, 0.0, -G_LAT))
    k = np.arange(6)
    np.testing.assert_allclose(p[:, 1, 2], G_LAT * (6 - k - 0.5), rtol=1e-6)
    p = hydrostatic_pressure(shape, (G_LAT, 0.0, 0.0))
    np.testing.assert_allclose(p[2, 1, :], G_LAT * (np.arange(4) + 0.5), rtol=1e-6)
    phi = np.zeros((20, 2, 2), np.float32)
    phi[:10] = 1.0
    p = hydrostatic_pressure(phi.shape, (0.0, 0.0, -G_LAT), phi, rho_l=1 / 800)
    slope = -np.diff(p[:, 0, 0].astype(np.float64))
    np.testing.assert_allclose(slope[12:], G_LAT / 800, rtol=1e-4)
    np.testing.assert_allclose(slope[:8], G_LAT, rtol=1e-4)
    np.testing.assert_allclose(p[0, 0, 0], G_LAT * (10 / 800 + 9.5), rtol=1e-5)
    assert hydrostatic_pressure(shape, (0.0, -G_LAT, -G_LAT)) is None
    assert hydrostatic_pressure(shape, (0.0, 0.0, -G_LAT), boundary={"z_min": "periodic"}) is None
    assert hydrostatic_pressure(shape, (0.0, 0.0, 0.0)) is None


def test_hanging_water_is_not_carried_by_the_air_under_it():
    """A block of water in the air (Fig. 17's poured water) adds nothing to the pressure under or beside it:
    the air keeps its own hydrostatic profile in every column, so no pressure step at the edge of the block's
    column (integrated straight through, the floor under it carried its weight and Fig. 17's small variant blew
    the air out sideways at 5.75 m/s in the first step, NaN by step 7). A pool under the same block is still
    carried in full."""
    nz, rho_l = 30, 1 / 800
    phi = np.zeros((nz, 8, 8), np.float32)
    phi[18:24, 2:6, 2:6] = 1.0  # the hanging block
    p = hydrostatic_pressure(phi.shape, (0.0, 0.0, -G_LAT), phi, rho_l=rho_l).astype(np.float64)
    air = G_LAT * rho_l * (nz - np.arange(nz) - 0.5)
    for y, x in ((3, 3), (0, 0), (3, 0)):
        np.testing.assert_allclose(p[:18, y, x], air[:18], rtol=1e-5)
    phi[:6] = 1.0  # a pool 6 cells deep under it: its weight is carried, the block's is not
    p = hydrostatic_pressure(phi.shape, (0.0, 0.0, -G_LAT), phi, rho_l=rho_l).astype(np.float64)
    pool = air + G_LAT * (1 - rho_l) * np.clip(6 - np.arange(nz) - 0.5, 0, None)
    np.testing.assert_allclose(p[:6, 3, 3], pool[:6], rtol=1e-5)
    np.testing.assert_allclose(p[:6, 3, 3], p[:6, 0, 0], rtol=1e-6)


def _tank(phases: int) -> dict:
    """A closed 12 x 12 x 24 tank (dx = 5 mm, Δt = 1e-4 s): single-phase water, or water to 14 cells under
    air (800:1, σ = 0.073 N/m)."""
    bodies = []
    if phases == 2:
        bodies = [{"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.06, 0.06, 0.07]}}]
    return {
        "scene": {"name": f"tank_{phases}"},
        "domain": {"size": [0.06, 0.06, 0.12], "dx": DX},
        "time": {"dt": DT, "frame_duration": 1e-3, "frames": 1},
        "fluid": {
            "phases": phases,
            "water_lattice_viscosity": 1e-3,
            "air_lattice_viscosity": 1e-2,
            "surface_tension": 0.073,
        },
        "bodies": bodies,
        "outputs": {"preview": False},
    }


def _speeds(sim: Simulation, steps: int) -> np.ndarray:
    """Largest lattice speed of each z layer over the run (sampled every 50 steps)."""
    worst = np.zeros(sim.fluid.shape[0])
    for _ in range(steps // 50):
        sim.step(50)
        u = sim.fluid.fields()["velocity"]
        worst = np.maximum(worst, np.sqrt((u.astype(np.float64) ** 2).sum(axis=0)).max(axis=(1, 2)))
    return worst


def test_single_phase_tank_stays_at_rest(monkeypatch):
    """300 steps of water at rest in a closed tank (24 cells tall): max lattice speed < 4e-5.

    Scale: a start from p = 0 lets the water fall by g Δt in the first step; the floor stops it and a
    pressure wave of speed amplitude ~ g_lat H / c_s = 8e-4 rings through the tank (measured max 2.3e-4
    over these steps: the wave is damped and spread). With the hydrostatic start what is left is the
    discretisation of the walls (measured 1.1e-5). The bound sits between, a factor ~4 from each; the
    same tank started from p = 0 is run too and must exceed it.

    If this fails after a change of the fluid's collision or forcing, the balance of gravity against the
    pressure gradient at rest got worse: do not widen the bound without finding out why (an odd-moment
    relaxation change tried in the working tree gave 4.7e-5 here, growing at the lid and floor)."""
    hydro = _speeds(Simulation(Scene.from_dict(_tank(1)), backend="cpu", log=None), 300).max()
    monkeypatch.setattr(hydrostatic, "hydrostatic_pressure", lambda *a, **k: None)  # what the assembly calls
    cold = _speeds(Simulation(Scene.from_dict(_tank(1)), backend="cpu", log=None), 300).max()
    print(f"single phase: hydrostatic start {hydro:.2e}, from p = 0 {cold:.2e}")
    assert hydro < 4e-5 < cold


@pytest.mark.parametrize("steps", [300])
def test_two_phase_tank_stays_at_rest(steps):
    """Water (14 cells) under air at 800:1, 300 steps: in the water bulk (more than 3 cells below the
    interface, 10 layers) max lattice speed < 3e-5, everywhere < 1.5e-4.

    Measured: bulk 1.1e-5 (from p = 0: 6.9e-5), everywhere 8.9e-5 (from p = 0: 1.4e-4). What remains
    with the hydrostatic start is the fluid solver's own discrete imbalance in the interface's air tail:
    its central pressure gradient of the cell-centred profile differs from ρ_k g by g Δ²ρ / 4, which the
    air's 1/800 density amplifies (measured: with gravity off the same interface moves at < 1e-5). The
    bounds are ~3x and ~1.7x the measured values; 1.5e-4 is a lattice Mach number of 2.6e-4."""
    sim = Simulation(Scene.from_dict(_tank(2)), backend="cpu", log=None)
    worst = _speeds(sim, steps)
    print(f"two phase: bulk {worst[:10].max():.2e}, all {worst.max():.2e}")
    assert worst[:10].max() < 3e-5
    assert worst.max() < 1.5e-4
