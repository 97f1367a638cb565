"""``sand.absorption_time``: Eq. 55's absorption coefficient given in seconds (session 30).

Table 1 gives R_a per lattice step, and Eq. 55 binds R_a r_max ε of water per step, so at half the time step a
scene with the same R_a binds water twice as fast per second (measured on Fig. 17's small variant at 0.33 s: mean
particle moisture 0.018 at its dt, 0.039 at dt/2). With ``absorption_time`` = τ the scene's R_a is dt / τ, and the
bound water's history in seconds does not depend on dt.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.scene.model import Scene
from couplekit.simulation import Simulation


def _block(dx: float, dt: float, absorption: dict) -> dict:
    """A closed 16 × 8 × 12-cell box, water up to 8 cells, a 4 × 4 × 4-cell sand block resting in it (the same
    physical scene at every dx, dt: SI viscosity)."""
    n = 0.005 / dx  # cells per 5 mm
    box = [16 * 0.005, 8 * 0.005, 12 * 0.005]
    return {
        "scene": {"name": "absorbing_block"},
        "domain": {"size": box, "dx": dx},
        "time": {"dt": dt, "frame_duration": dt, "frames": 1},
        "fluid": {"water_viscosity": 2.5e-4, "air_viscosity": 2.5e-3, "surface_tension": 0.0},
        "sand": {"density": 1500.0, "youngs_modulus": 1e5, "retention": True, **absorption},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [box[0], box[1], 0.04]}},
            {"kind": "sand", "geometry": {"type": "box", "min": [0.01, 0.01, 0.01], "max": [0.03, 0.03, 0.03]}},
        ],
        "outputs": {"preview": False},
    }, n


def _bound(d: dict, times: tuple[float, ...]) -> list[float]:
    """Bound water Σ r_p V_p (m³) at ``times`` (s)."""
    sim = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    be, dt, out = sim.fluid.backend, d["time"]["dt"], []
    for t in times:
        sim.step(round(t / dt) - sim.fluid.step_count)
        r = be.to_host(sim.coupler.moisture_ratio).astype(np.float64)
        out.append(float((r * be.to_host(sim.sand.volume).astype(np.float64)).sum()))
    return out


def test_absorption_time_sets_the_per_step_rate_from_dt():
    """R_a = dt / absorption_time, refused with absorption_rate and below one step."""
    d, _ = _block(0.005, 1e-4, {"absorption_time": 0.02})
    assert Scene.from_dict(d).sand.absorption_rate == pytest.approx(0.005)
    d["time"]["dt"] = 5e-5
    assert Scene.from_dict(d).sand.absorption_rate == pytest.approx(0.0025)


@pytest.mark.parametrize("dx", [0.005, 0.0025])
def test_bound_water_in_seconds_does_not_depend_on_dt_with_absorption_time(dx):
    """The block at dt and dt/2 (dx = 5 mm: 1e-4, 5e-5 s; 2.5 mm: 5e-5, 2.5e-5 s), bound water after 30 and 60
    of the larger steps (3 and 6 ms at 5 mm; under 60 % of the capacity, where Eq. 55's rate limits the uptake): with R_a = 0.005 per step it is 2x at
    dt/2 (measured 2.000x at both resolutions); with absorption_time = dt / 0.005 (R_a = 0.005 at the larger dt)
    within 3 % (measured 1.0001x: the block's pores are full of water, so the uptake is Eq. 55's rate alone)."""
    dt = 1e-4 * dx / 0.005
    times = (30 * dt, 60 * dt)
    per_step = [_bound(_block(dx, h, {"absorption_rate": 0.005})[0], times) for h in (dt, dt / 2)]
    timed = [_bound(_block(dx, h, {"absorption_time": dt / 0.005})[0], times) for h in (dt, dt / 2)]
    for k in range(len(times)):
        assert per_step[1][k] / per_step[0][k] > 1.8, per_step
        assert abs(timed[1][k] / timed[0][k] - 1.0) < 0.03, timed
