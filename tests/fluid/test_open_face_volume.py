"""The volume controller (Eq. 52) follows what inflow and outflow faces let in and out.

Without that, the controller's target stays at the starting volume and, with sand present, it scales the
sand's source term towards removing the jet's water. Since session 29 the target moves by the flux the phase
field's step actually passed through the open faces, Σφ(after) − Σφ(before) − γ Σ S_φ
(couplekit.fluid.solver.FluidSolver._open_face_step), not by an estimate from the face cells (Σ φ_b u_b·n at inflow
ghosts, Σ φ min(u·n_in, 0) behind outflow ghosts), which missed the Allen–Cahn sharpening and diffusive fluxes an
outflow link carries: under Fig. 2's 12 m/s wind without sand (dx = 15 mm) it counted 4.7 units of water leaving
per 100 steps while Σφ changed by +0.18 … −0.09, and the target fell 7 % below the water in 0.6 s (drift +4.6 %;
tests/fluid/test_outflow_backflow.py runs that wind).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from fluid_states import JET_SHAPE, JET_SPEED, water_jet_into_air

from couplekit.backend import get_backend


@pytest.fixture(scope="module")
def cpu():
    return get_backend("cpu", threads=1)


def test_controller_lets_the_jet_in(cpu):
    """The jet of test_two_phase_validation (8 × 8 × 32, water at u_in = 0.02 into air, 800:1, outflow
    downstream) with the controller on (η = 2). Without sand the controller has no source term to scale, so the
    water enters at the inflow rate (measured 0.997 u_in·A; bound 0.9–1.02 as there) and the target moves with
    it. Fluid-only, the target is Σφ itself (the transport's flux through the faces is all that changes Σφ), so
    the drift is 0 to round-off; a target fixed at the start would read 62 %."""
    n, u_in = JET_SHAPE, JET_SPEED
    solver = water_jet_into_air(cpu, eta=2.0)
    v0 = solver.diagnostics()["fluid_volume"]
    solver.step(200)
    d = solver.diagnostics()
    inflow = (d["fluid_volume"] - v0) / (u_in * n[0] * n[1] * 200)
    assert 0.9 < inflow < 1.02, f"water inflow {inflow:.3f} u_in A with the controller on"
    assert abs(d["fluid_volume_drift"]) < 1e-9, d["fluid_volume_drift"]
    assert solver.volume0 > v0 + 0.5 * u_in * n[0] * n[1] * 200  # the target moved with the jet


def _volume_sums_per_step(solver, steps: int = 10) -> float:
    """How many times ``solver.step`` calls the phase field's volume sums per step (after 2 steps, which take the
    open faces' first sum)."""
    solver.step(2)
    calls = []
    sums = solver.pf_ops.volume_sums
    solver.pf_ops.volume_sums = lambda *a, **k: (calls.append(1), sums(*a, **k))[1]
    try:
        solver.step(steps)
    finally:
        solver.pf_ops.volume_sums = sums
    return len(calls) / steps


def test_without_a_source_term_the_controller_sums_nothing(cpu):
    """A fluid alone has no S_φ for Eq. 52's γ to scale (γ = 0): a step sums φ only for an open face's
    bookkeeping (one reduction per step with the jet's faces, none in a closed box), and γ reads 0 as Eq. 52 gives
    it for Σ S = 0. Before session 30 a closed box summed Σφ every step for the controller (bitwise the same
    results: Fig. 16's water-only dam break, Fig. 14's and Fig. 16's sand dam break without the source term,
    60 steps)."""
    from couplekit.fluid.solver import FluidParams, FluidSolver

    jet = water_jet_into_air(cpu, eta=2.0)
    assert _volume_sums_per_step(jet) == 1 and jet.gamma == 0.0
    n = (12, 12, 12)  # the same fluid in a closed box: a drop at rest
    z, y, x = np.meshgrid(*(np.arange(k) + 0.5 for k in n), indexing="ij")
    phi0 = 0.5 * (1 + np.tanh(2 * (4 - np.sqrt((x - 6) ** 2 + (y - 6) ** 2 + (z - 6) ** 2)) / 4.0))
    params = FluidParams(rho_h=1.0, rho_l=1 / 800, nu_h=0.01, nu_l=0.01, sigma=1e-4, width=4.0, eta=2.0)
    closed = FluidSolver(cpu, n, params, phi=phi0)
    assert _volume_sums_per_step(closed) == 0 and closed.gamma == 0.0


def test_the_target_continues_across_a_restart(cpu):
    """The target's bookkeeping keeps the last step's Σφ between steps; a solver restored from a state (a
    checkpoint) sums it again: the jet run 100 + 150 steps and the same run restored at step 100 into a solver
    that had run 30 steps of its own reach the same target and volume (bitwise: the same sums of the same φ)."""
    solver = water_jet_into_air(cpu, eta=2.0)
    solver.step(100)
    state = solver.state()
    solver.step(150)
    restored = water_jet_into_air(cpu, eta=2.0)
    restored.step(30)  # its own last Σφ, which the restored state must not inherit
    restored.load_state(state)
    restored.step(150)
    assert restored.volume0 == solver.volume0
    assert restored.diagnostics()["fluid_volume"] == solver.diagnostics()["fluid_volume"]


def _slab_run(top: str, dt: float, dx: float = 0.01, samples: int = 4, every: int = 50):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "coupling"))
    from test_surface_pumping import _slab

    from couplekit.scene import Scene
    from couplekit.simulation import Simulation

    d = _slab(dt).scene.to_dict()
    d["domain"]["dx"] = dx
    d["domain"].setdefault("boundary", {})["z_max"] = top
    sim = Simulation(Scene.from_dict(d), backend="cpu", log=None)
    sim.step(1)  # the coupler sets the target on its first step, once the fluid fraction is known
    v0 = sim.fluid.volume0
    gammas, drifts = [], []
    for _ in range(samples):
        sim.step(every)
        gammas.append(sim.fluid.gamma)
        drifts.append(sim.fluid.diagnostics()["fluid_volume_drift"])
    return sim.fluid.volume0 - v0, np.array(gammas), np.array(drifts)


@pytest.mark.parametrize("dx, dt", [(0.01, 5.8e-4), (0.01, 2.9e-4), (0.005, 2.9e-4), (0.005, 1.45e-4)])
def test_an_outflow_ceiling_that_air_crosses_leaves_the_controller_as_in_a_closed_box(dx, dt):
    """A coupled scene (tests/coupling/test_surface_pumping.py's 600 kg/m³ slab sinking into a 10-cell pool,
    12 × 12 × 20 cells, the sand's source term S_φ acting) with its ceiling an outflow face instead of a wall:
    only air leaves, so the controller must work as in the closed box. γ sampled every 50 steps (4 samples),
    |γ_open − γ_closed| measured at Δt = 5.8e-4 s: 0.0037, 0.0019, 0.0014, 0.0013 (with the former estimate of the
    face flux, which counted the air's φ u·n leaving while the face let water in: 0.011, 0.0081, 0.0079, 0.011); at
    2.9e-4 s: 0.0097, 0.0030, 0.0015, 0.0015 (former: 0.033, 0.016, 0.012, 0.012). The drifts (1.4e-5 and 2.7e-6 at
    the end) agree within 0.2e-6 at both (former: 3.4e-7 apart at 2.9e-4 s, 0.6 of the closed box's). The face
    lets out the little φ the air carries (−0.0028 and −0.00084 of 1440) and lets nothing in: with the phase
    field's former outflow rule it let in +0.081 and +0.079 (its sharpening flux drew the air's φ in from the
    zero-gradient ghost; docs/fluid-stability.md, 'The volume target at open faces'). Bounds: |Δγ| ≤ 0.004 over the
    last two samples (after the first 100 steps' transient); drifts within 10 % + 1e-7 of the closed box's; the
    water that crossed the face ≤ 0 and above −1e-5 of the pool.

    At dx = 5 mm (24 × 24 × 40 cells, the same box and bodies; Δt 2.9e-4 and 1.45e-4 s): |Δγ| 0.0043, 0.0019,
    0.00077, 0.00062 and 0.016, 0.0040, 0.0018, 0.00098; drifts within 1.1e-7. The ceiling is 20 cells above the
    water there, the air's φ at it below what the float64 sums of float32 φ resolve: what crossed, +3.8e-5 and
    +2.7e-5 of 11478, is round-off, bounded by 1e-8 of the pool instead of the sign."""
    pool = (0.12 / dx) ** 2 * (0.1 / dx)  # cells below the undisturbed surface: 1440 at dx = 1 cm
    dv_closed, g_closed, d_closed = _slab_run("wall", dt, dx)
    dv_open, g_open, d_open = _slab_run("outflow", dt, dx)
    assert dv_closed == 0.0
    assert np.abs(g_open - g_closed)[2:].max() <= 4e-3, (g_closed, g_open)
    assert np.all(np.abs(d_open - d_closed) <= 0.1 * np.abs(d_closed) + 1e-7), (d_closed, d_open)
    if dx == 0.01:
        assert -1e-5 * pool < dv_open <= 0.0, dv_open
    else:
        assert abs(dv_open) <= 1e-8 * pool, dv_open
