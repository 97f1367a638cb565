"""The source term S_φ (Eq. 45) in the real two-phase fluid solver: a small-scale volume ablation in the
spirit of paper Fig. 14, with the sand prescribed (a ball of ε ≤ 0.5 moving down through air into a
water pool at a constant 0.02 cells/step; no MPM, no drag) so that only the phase-field bookkeeping is
tested.  Fluid volume V = Σ ε̃ φ.

* without S_φ the water is not displaced by the sand: V drops by about the sand volume entering it
  (paper Fig. 14a: "drastic loss");
* with S_φ, V holds to well under 1 % (paper: "up to 5 %" without the controller at their scale);
* with S_φ and the volume controller (Eq. 52) computed on the ε̃-weighted sums,
  γ = clamp((V0 − Σ ε̃ φ) / Σ ε̃ S, ±η), V holds to 0.1 %: FluidSolver's own controller (η = 2), whose
  sums are ε-weighted in mixtures.  With its former plain sums (Σφ, ΣS) it cancelled the source term and
  the drift returned to the no-source −2.5 %; the "plain" case keeps that measured failure visible.

Viscosity 0.1 (lattice), as first written: the ν = 0.02 instability that once made it necessary was the
unfiltered stored pressure, not the sand (tests/coupling/test_coupling_pressure_stability.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.coupling import CouplingParams, KernelOps
from couplekit.fluid.grid import Boundaries
from couplekit.fluid.phasefield import volume_controller_gamma
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.units import Units

SHAPE = (22, 12, 12)
UNITS = Units(dx=0.005, dt=1e-4)
RADIUS, SPEED, STEPS = 3.0, 0.02, 700


def _run(cpu1, mode: str) -> np.ndarray:
    nz, ny, nx = SHAPE
    padded = tuple(s + 2 for s in SHAPE)
    zz, yy, xx = np.meshgrid(np.arange(nz) + 0.5, np.arange(ny) + 0.5, np.arange(nx) + 0.5, indexing="ij")
    phi0 = (0.5 * (1 - np.tanh(2 * (zz - 11.0) / 4.0))).astype(np.float32)  # water below z = 11
    eta = 2.0 if mode == "controller" else 0.0
    params = FluidParams(rho_h=1.0, rho_l=0.01, nu_h=0.1, nu_l=0.1, mobility=0.02, width=4.0, eta=eta)
    fluid = FluidSolver(cpu1, SHAPE, params, boundaries=Boundaries.channel("xyz"), phi=phi0, mixture=True)
    ops = KernelOps(cpu1, CouplingParams(), two_phase=True)
    ef = np.ones(padded, np.float32)
    ef_prev = np.ones(padded, np.float32)
    grid_v = np.zeros((3, *SHAPE), np.float32)
    source = np.zeros(padded, np.float32)
    inside = (slice(1, -1),) * 3
    volumes = []
    v0 = None
    for n in range(STEPS):
        d = np.sqrt((xx - nx / 2) ** 2 + (yy - ny / 2) ** 2 + (zz - (18.0 - SPEED * n)) ** 2)
        eps = 0.5 * np.clip(RADIUS + 0.5 - d, 0.0, 1.0)
        grid_vol = (eps * UNITS.dx**3).astype(np.float32)
        ops.fractions(grid_vol, fluid.phi, None, None, ef, None, None, UNITS.dx, (False,) * 3)
        grid_v[2] = np.where(eps > 0, -SPEED * UNITS.dx / UNITS.dt, 0.0)
        ops.sand_velocity(grid_v, fluid.sand_velocity, UNITS, (False,) * 3)
        fluid.fluid_fraction[...] = ef
        e = ef[inside].astype(np.float64)
        volume = float((e * fluid.phi[inside]).sum())
        if v0 is None:
            v0 = volume
            fluid.reset_volume_reference()  # V0 = Σ ε φ once ε is known (the solver starts with ε ≡ 1)
            assert fluid.volume0 == pytest.approx(v0, rel=1e-9)
        if mode != "none":
            ops.phase_source(ef, ef_prev, fluid.phi, fluid.velocity, fluid.flags, None, source)
            gamma = 1.0
            if mode == "plain":  # the controller on the unweighted sums Σφ, ΣS (the former solver's)
                plain = float(fluid.phi[inside][fluid.flags[inside] == 0].sum())
                gamma = volume_controller_gamma(float(phi0.sum()), plain, float(source[inside].sum()), 2.0)
            fluid.source_term[...] = gamma * source
        fluid.step(1)
        ef_prev[...] = ef
        volumes.append(float((e * fluid.phi[inside]).sum()))
    assert np.isfinite(volumes).all()
    return np.array(volumes) / v0 - 1.0


@pytest.mark.parametrize(
    "mode, low, high",
    [
        ("none", 0.01, 1.0),
        pytest.param("plain", 0.01, 1.0, marks=pytest.mark.slow),  # measured 2.65 % (CI budget: slow only)
        ("source", 0.0, 0.01),
        ("controller", 0.0, 0.001),
    ],
)
def test_fluid_volume_with_and_without_the_source_term(cpu1, mode, low, high):
    drift = np.abs(_run(cpu1, mode))
    print(f"{mode}: final drift {drift[-1]:.4%}, max {drift.max():.4%}")
    if mode in ("none", "plain"):
        assert drift[-1] > low, f"{mode}: the sand should cost water volume, drift {drift[-1]:.3%}"
    else:
        assert drift.max() < high, f"{mode}: max drift {drift.max():.3%}"
