"""Water that reaches one end of a periodic axis meets the air at the other end through the wrap: the initial φ
carries the resolved interface across it (assembly._periodic_images), where it had been a one-cell jump that went
non-finite within a few steps at 800:1; a body spanning the whole periodic axis has no interface along it; and
FluidSolver's sharp-interface check looks across the wrap too."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid import SharpInterfaceWarning
from couplekit.fluid.grid import Boundaries, Face
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.scene import Scene
from couplekit.simulation import Simulation

AXES = "xyz"


def _scene(axis: str, n: int, width: float, lo: float = 0.0, hi: float = 0.5, dx: float = 0.01) -> dict:
    """A walled n × n × (n + 8) box, periodic along ``axis``; water the box ``lo`` .. ``hi`` (fractions of the
    length) along ``axis`` and the lower 0.45 of z otherwise (all of z when the axis is z: then the layer
    is along z)."""
    size = [n * dx, n * dx, (n + 8) * dx]
    a = AXES.index(axis)
    mn, mx = [0.0, 0.0, 0.0], [size[0], size[1], 0.45 * size[2]]
    if axis == "z":
        mx[2] = size[2]
    mn[a], mx[a] = lo * size[a], hi * size[a]
    return {
        "scene": {"name": f"periodic_{axis}"},
        "domain": {"size": size, "dx": dx, "boundary": {f"{axis}_min": "periodic", f"{axis}_max": "periodic"}},
        "time": {"dt": 2e-4, "frame_duration": 2e-3},
        "fluid": {"water_lattice_viscosity": 5e-4, "air_lattice_viscosity": 1e-2, "interface_width": width},
        "bodies": [{"kind": "water", "geometry": {"type": "box", "min": mn, "max": mx}}],
        "outputs": {"preview": False},
    }


def _phi(d: dict) -> np.ndarray:
    return Simulation(Scene.from_dict(d), "cpu", log=None).fields()["phi"]


def _profile(s: np.ndarray, width: float) -> np.ndarray:
    """φ of Eq. 48's equilibrium at signed distance s (cells, negative in the water)."""
    return 0.5 * (1.0 - np.tanh(2.0 * s / width))


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize(("n", "width"), [(13, 4.0), (20, 3.0), (24, 6.0)])
def test_the_interface_crosses_the_wrap_as_the_equilibrium_profile(axis, n, width):
    """Along the periodic axis φ is the equilibrium profile of the distance to the nearer of the water's two
    faces, the one inside the box (at half its length) and the one at the wrap (at 0 ≡ L): within float32 of
    it in every cell, the wrap's neighbours included."""
    phi = _phi(_scene(axis, n, width))
    a = 2 - AXES.index(axis)  # array axis (z, y, x)
    line = np.moveaxis(phi, a, -1)[(1,) * (phi.ndim - 1)].astype(np.float64)  # a line along the axis, in water
    length = line.size
    centre = np.arange(length) + 0.5
    half = 0.5 * length
    inside = centre < half
    # distance to the nearer face: faces at 0 (≡ L) and at L/2
    s = np.where(inside, -np.minimum(centre, half - centre), np.minimum(centre - half, length - centre))
    np.testing.assert_allclose(line, _profile(s, width), atol=2e-6)
    # the wrap's jump is the resolved one: at most tanh(1/ξ), as between any two neighbours
    assert abs(line[0] - line[-1]) <= np.tanh(1.0 / width) + 1e-6


@pytest.mark.parametrize("axis", "xy")
def test_water_spanning_the_periodic_axis_has_no_interface_along_it(axis):
    """A layer spanning the periodic axis: no interface at the wrap, φ the same at both ends and along the axis
    (the layer's surface only, in z)."""
    phi = _phi(_scene(axis, 13, 4.0, lo=0.0, hi=1.0))
    a = 2 - AXES.index(axis)
    spread = np.ptp(phi, axis=a)
    assert spread.max() < 1e-6
    assert phi[1].min() > 0.999  # the bottom layer is water


@pytest.mark.parametrize("axis", "xz")
@pytest.mark.parametrize("n", [13, 17])
def test_water_at_one_end_of_a_periodic_axis_stays_finite(axis, n):
    """The probe's case (13 × 13 × 21, water from x = 0 to the middle, x periodic: NaN at step 6 before) and its
    z-periodic and larger twins run 80 steps with finite, modest speeds (a dam break either way round the wrap)."""
    sim = Simulation(Scene.from_dict(_scene(axis, n, 4.0)), "cpu", log=None)
    for _ in range(4):
        sim.step(20)
        d = sim.diagnostics()
        assert np.isfinite(d["max_speed"]) and d["max_speed"] < 1.0, d["max_speed"]
    assert abs(d["fluid_volume_drift"]) < 1e-4


def test_the_sharp_interface_check_looks_across_the_wrap():
    """FluidSolver given φ = 1 in the first half of a periodic x axis and 0 in the second, with a resolved
    profile at the middle but a one-cell jump at the wrap, warns at 800:1; with walls on x it does not (the jump
    is then against a wall)."""
    shape = (6, 6, 16)  # (nz, ny, nx)
    x = np.arange(16) + 0.5
    phi = np.broadcast_to(_profile(x - 8.0, 4.0), shape).astype(np.float32).copy()
    phi[..., 0] = 1.0  # water up to the wrap, air beyond it: a jump of ~1 between cells 0 and 15
    params = FluidParams(rho_h=1.0, rho_l=1 / 800.0, nu_h=1e-2, nu_l=1e-2)
    cpu = get_backend("cpu")
    periodic_x = Boundaries({k: Face("wall") for k in ("y-", "y+", "z-", "z+")})
    with pytest.warns(SharpInterfaceWarning, match=r"jumps by 1\.00"):
        FluidSolver(cpu, shape, params, periodic_x, phi=phi)
    walls = Boundaries({k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")})
    with warnings.catch_warnings():
        warnings.simplefilter("error", SharpInterfaceWarning)
        FluidSolver(cpu, shape, params, walls, phi=phi)
