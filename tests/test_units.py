"""SI <-> lattice conversion and the lattice checks."""

from __future__ import annotations

import math

import pytest

from couplekit.units import DIMENSIONS, Units, check_relaxation, relaxation_time

FIG8 = Units(dx=0.005, dt=1.6e-5)  # paper 000, Table 1, Fig. 8


@pytest.mark.parametrize("quantity", sorted(DIMENSIONS))
def test_round_trip(quantity):
    for value in (1e-7, 0.37, 9.81, 2.5e4):
        back = FIG8.to_si(FIG8.to_lattice(value, quantity), quantity)
        assert back == pytest.approx(value, rel=1e-14)


def test_known_conversions():
    # gravity: g dt²/dx = 9.81 * (1.6e-5)² / 0.005
    assert FIG8.to_lattice(9.81, "acceleration") == pytest.approx(9.81 * 1.6e-5**2 / 0.005, rel=1e-14)
    # water's kinematic viscosity 1e-6 m²/s -> ν dt/dx²
    assert FIG8.viscosity(1e-6) == pytest.approx(1e-6 * 1.6e-5 / 0.005**2, rel=1e-14)
    # Table 1 viscosities are already lattice values
    assert FIG8.viscosity(1e-4, unit="lattice") == 1e-4
    # a density equal to the reference density is 1 on the lattice
    assert FIG8.to_lattice(1000.0, "density") == pytest.approx(1.0)
    # surface tension of water 0.072 N/m -> σ dt² / (ρ dx³)
    assert FIG8.to_lattice(0.072, "surface_tension") == pytest.approx(0.072 * 1.6e-5**2 / (1000 * 0.005**3))
    # pressure: 1 lattice unit of pressure = ρ (dx/dt)²
    assert FIG8.scale("pressure") == pytest.approx(1000 * (0.005 / 1.6e-5) ** 2)


def test_mach_and_max_dt():
    u = Units(dx=0.01, dt=1e-3)
    assert u.mach(1.0) == pytest.approx(0.1 * math.sqrt(3))
    dt = u.max_dt(1.0, mach_limit=0.3)
    assert Units(dx=0.01, dt=dt).mach(1.0) == pytest.approx(0.3)
    u.check_mach(1.0)  # Mach 0.17: fine
    with pytest.raises(ValueError, match="use dt <="):
        u.check_mach(3.0, what="the jet")


def test_relaxation_time():
    assert relaxation_time(1 / 6) == pytest.approx(1.0)  # τ = 3ν + 1/2
    assert check_relaxation(1e-4) == pytest.approx(0.5003)
    with pytest.raises(ValueError, match="must be > 0"):
        check_relaxation(0.0, what="fluid.nu_h")


@pytest.mark.parametrize(
    "kwargs", [{"dx": 0.0, "dt": 1.0}, {"dx": 1.0, "dt": -1.0}, {"dx": 1, "dt": 1, "rho": float("nan")}]
)
def test_bad_units_refused(kwargs):
    with pytest.raises(ValueError, match="must be a positive finite number"):
        Units(**kwargs)


def test_unknown_quantity():
    with pytest.raises(ValueError, match="unknown quantity"):
        FIG8.scale("temperature")
