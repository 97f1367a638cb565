"""A standing gravity wave at 800:1 and the paper's ν_h = 1e-4, with the scenes' closures, must not gain energy.

Found on the Fig. 8 small variant (docs/fluid-stability.md, "Energy of a standing wave"): with the odd-moment
rate following each cell's viscosity (0.02 in water, 1 in air, a jump inside the interface) a standing wave
held 2.4× its own energy a quarter period in and kept gaining; with one rate for the whole fluid
(:func:`couplekit.fluid.reference.odd_rates`, one rate wherever the flow is resolved) it oscillates and decays.

Here, in lattice units, the Fig. 8 small variant's pool in a slice: a 30 × 4 × 40 tank (walls on x and z,
periodic y), water 16 cells deep with the surface z = 16 + cos(2π x / 30) (the tank's second sloshing mode,
amplitude 1 cell), interface width 4, gravity 5e-6 (Fig. 8 small: 9.81 m/s² × (1.6e-4 s)² / 0.05 m), period
2π / sqrt(g k tanh(k h)) = 6148 steps. The wave's energy is its potential energy ½ ρ_h g ∫ η² dx dy
= ½ g · ½ · 30 · 4. Asserted: over the first half period the kinetic energy peaks below 1.2× that, and over the
second half period no higher than over the first. Measured, as multiples of the wave's energy, the peaks of
four half periods: 0.84, 0.54, 0.32, 0.19 (one rate, Guo forcing of the odd moments); 0.81, 0.48, 0.26, 0.15
with one rate and the former forcing; 3.8, 16.5, 43, 158 with the former per-cell rate.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid.grid import Boundaries
from couplekit.fluid.phasefield_layout import tanh_profile
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.simulation import hydrostatic_pressure

G, NX, NY, NZ, DEPTH, MODE = 5e-6, 30, 4, 40, 16.0, 2
WAVE_ENERGY = 0.5 * G * 0.5 * NX * NY  # ½ ρ_h g a² A / 2 with a = 1 cell, ρ_h = 1
K = MODE * np.pi / NX
PERIOD = 2 * np.pi / np.sqrt(G * K * np.tanh(K * DEPTH))


@pytest.fixture(scope="module")
def cpu():
    return get_backend("cpu", threads=1)


def _kinetic_energy_history(cpu, steps: int, every: int) -> np.ndarray:
    rho_h, rho_l = 1.0, 1.0 / 800.0
    x = np.arange(NX) + 0.5
    z = np.arange(NZ) + 0.5
    surface = DEPTH + np.cos(K * x)
    phi = tanh_profile(surface[None, :] - z[:, None], 4.0)  # (z, x): signed distance ≈ vertical (slope ≤ 0.07)
    phi = np.broadcast_to(phi[:, None, :], (NZ, NY, NX)).astype(np.float32).copy()
    p = hydrostatic_pressure(phi.shape, (0.0, 0.0, -G), phi, rho_l=rho_l, interface_width=4.0)
    params = FluidParams(
        rho_h=rho_h, rho_l=rho_l, nu_h=1e-4, nu_l=1e-2, gravity=(0.0, 0.0, -G), width=4.0,
        odd_lambda=0.015, smagorinsky=0.1,
    )  # fmt: skip
    solver = FluidSolver(cpu, (NZ, NY, NX), params, boundaries=Boundaries.channel("xz"), phi=phi, pressure=p)
    energy = []
    for _ in range(steps // every):
        solver.step(every)
        energy.append(solver.diagnostics()["kinetic_energy"])
    return np.asarray(energy)


def test_standing_wave_does_not_gain_energy(cpu):
    every = 50
    half = int(PERIOD / 2) // every * every
    ke = _kinetic_energy_history(cpu, 2 * half, every)
    assert np.all(np.isfinite(ke))
    first, second = ke[: half // every].max(), ke[half // every :].max()
    assert first < 1.2 * WAVE_ENERGY, f"first peak {first / WAVE_ENERGY:.2f} x the wave's energy"
    assert second <= first, f"second peak {second / WAVE_ENERGY:.2f} x, first {first / WAVE_ENERGY:.2f} x"
