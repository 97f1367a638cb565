"""The volume controller's residual put back at the interface (FluidSolver._interface_correction).

Eq. 52's γ can only scale S_φ; in a mixture whose sand is (nearly) still, S_φ is ~0 and γ sits at its bound
while the transport's porosity error drifts the water (Fig. 17).  The residual r = V0 − V − γ Σ ε̃ S is then
added as β φ(1 − φ), β = r / Σ ε̃ φ(1 − φ), |β| ≤ 0.01.  Checked here on the fluid solver alone (no sand
motion, S_φ = 0, a porous block across a drop's interface):

* a volume deficit is closed in one step when it is small (|β| under its bound), to float32 rounding;
* the change is localised at the interface: the bulk phases (φ = 0 and 1) are untouched;
* a large deficit is taken up at the bound (β = 0.01 per step), never faster;
* with the controller not at its bound the step is the plain Eq. 52 step, bit for bit;
* a fluid-only two-phase solver (no mixture) never applies it, nor a mixture with an open (outflow) face,
  whose V0 follows an estimate of the water let out.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.fluid.grid import Boundaries, Face
from couplekit.fluid.solver import FluidParams, FluidSolver

SHAPES = [(12, 10, 14), (18, 14, 20)]  # two resolutions: a drop of radius 0.3 n_x


def _solver(cpu, shape, mixture=True, eta=2.0, boundaries=None):
    nz, ny, nx = shape
    z, y, x = np.meshgrid(np.arange(nz) + 0.5, np.arange(ny) + 0.5, np.arange(nx) + 0.5, indexing="ij")
    r = np.sqrt((x - nx / 2) ** 2 + (y - ny / 2) ** 2 + (z - nz / 2) ** 2)
    phi = 0.5 * (1.0 - np.tanh(2.0 * (r - 0.3 * nx) / 4.0))
    params = FluidParams(rho_h=1.0, rho_l=0.01, nu_h=0.05, nu_l=0.05, mobility=0.02, width=4.0, eta=eta)
    boundaries = boundaries or Boundaries.channel("xyz")
    fluid = FluidSolver(cpu, shape, params, boundaries=boundaries, phi=phi, mixture=mixture)
    if mixture:
        eps = np.ones(shape, np.float32)
        eps[:, :, : nx // 2] = 0.4  # a porous half, across the drop's interface
        fluid.fluid_fraction[1:-1, 1:-1, 1:-1] = eps
        fluid.source_term[...] = 0.0
        fluid.reset_volume_reference()
    return fluid


def _interior(a):
    return np.asarray(a[1:-1, 1:-1, 1:-1], dtype=np.float64)


@pytest.mark.parametrize("shape", SHAPES, ids=["n14", "n20"])
def test_small_deficit_is_closed_at_the_interface(cpu, shape):
    plain = _solver(cpu, shape)
    plain.step(1)  # the same step without a deficit: the controller has nothing to do
    fluid = _solver(cpu, shape)
    v = fluid._volume()
    phi0 = np.clip(_interior(fluid.phi), 0, 1)
    deficit = 1e-3 * v
    fluid.volume0 = v + deficit  # as if the transport had lost 0.1 % of the water
    fluid.step(1)
    gained = fluid._volume() - v
    # the plain step changes V by float32 rounding only (Σφ conserved, ε fixed, S = 0); with the deficit V
    # gains it (float32 sums of a few thousand cells: 1e-6 of V)
    assert abs(plain._volume() - v) < 1e-6 * v
    assert gained == pytest.approx(deficit, abs=1e-6 * v)
    # where it went: the difference to the plain step follows φ(1 − φ) (streamed one step: correlation, not
    # equality), it is water added everywhere (≥ 0 up to rounding) and nearly nothing in the bulk phases
    diff = _interior(fluid.phi) - _interior(plain.phi)
    shape_fn = phi0 * (1 - phi0)
    assert np.corrcoef(diff.ravel(), shape_fn.ravel())[0, 1] > 0.95
    assert diff.min() > -1e-6
    bulk = shape_fn < 0.02 * shape_fn.max()
    assert diff[bulk].max() < 0.1 * diff.max()


@pytest.mark.parametrize("shape", SHAPES[:1], ids=["n14"])
def test_large_deficit_is_taken_at_the_bound(cpu, shape):
    fluid = _solver(cpu, shape)
    v = fluid._volume()
    phi = np.clip(_interior(fluid.phi), 0, 1)
    weight = float((phi * (1 - phi) * _interior(fluid.fluid_fraction)).sum())
    fluid.volume0 = v + 1.0 * weight  # would need β = 1
    fluid.step(1)
    gained = fluid._volume() - v
    assert gained == pytest.approx(FluidSolver.INTERFACE_CORRECTION_MAX * weight, rel=2e-3)


def test_unclamped_controller_step_is_the_plain_step(cpu):
    """With a source term the controller's γ can scale (|γ| < η), the correction does nothing: bitwise equal
    to the same step run with the correction switched off."""
    shape = SHAPES[0]
    runs = []
    for on in (True, False):
        fluid = _solver(cpu, shape)
        rng = np.random.default_rng(1)
        s = (1e-4 * rng.standard_normal(fluid.source_term.shape)).astype(np.float32) + np.float32(2e-4)
        fluid.source_term[...] = s
        fluid.volume0 = fluid._volume() + 0.5 * float(_interior(s * fluid.fluid_fraction).sum())  # γ = 0.5
        if not on:
            fluid._interface_correction = lambda volume, source_sum, f=fluid: f.gamma
        fluid.step(1)
        assert 0 < fluid.gamma < fluid.params.eta
        runs.append(fluid.backend.to_host(fluid.h).copy())
    assert np.array_equal(runs[0], runs[1])


def test_fluid_only_two_phase_has_no_correction(cpu):
    fluid = _solver(cpu, SHAPES[0], mixture=False)
    v = fluid._volume()
    fluid.volume0 = v + 1.0
    fluid.step(1)
    assert fluid._volume() == pytest.approx(v, abs=1e-4)


def test_open_box_has_no_correction(cpu):
    faces = {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-")}
    faces["z+"] = Face("outflow")
    runs = []
    for offset in (0.0, 1.0):  # a deficit or none: the same step
        fluid = _solver(cpu, SHAPES[0], boundaries=Boundaries(faces))
        fluid.volume0 = fluid._volume() + offset
        fluid.step(1)
        runs.append(fluid.backend.to_host(fluid.h).copy())
    assert np.array_equal(runs[0], runs[1])
