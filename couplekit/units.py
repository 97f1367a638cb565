"""SI <-> lattice unit conversion and the lattice stability checks.

A lattice unit system is fixed by three scales: the grid spacing ``dx`` (m), the time step ``dt`` (s) and a
reference density ``rho`` (kg/m³, default 1000: water is density 1 on the lattice). Every mechanical
quantity then converts by its dimensions: a quantity of dimension L^a T^b M^c has the lattice scale
``dx^a · dt^b · (rho·dx³)^c``.

>>> u = Units(dx=0.005, dt=1.6e-5)           # paper 000, Fig. 8
>>> u.to_lattice(9.81, "acceleration")        # gravity in lattice units
>>> u.viscosity(1e-4, unit="lattice")         # Table 1 gives viscosities in lattice units already

The lattice checks: the flow speed must stay well below the lattice speed of sound (Mach number
``u_lat / c_s``, ``c_s = 1/√3``), and the BGK-equivalent relaxation time ``τ = ν_lat / c_s² + 1/2`` must
exceed 1/2 (positive viscosity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .lattice import CS2

# dimensions (length, time, mass) of the quantities the scenes use
DIMENSIONS: dict[str, tuple[int, int, int]] = {
    "length": (1, 0, 0),
    "time": (0, 1, 0),
    "mass": (0, 0, 1),
    "velocity": (1, -1, 0),
    "acceleration": (1, -2, 0),
    "viscosity": (2, -1, 0),  # kinematic, m²/s
    "density": (-3, 0, 1),
    "pressure": (-1, -2, 1),  # also stress and Young's modulus, Pa
    "surface_tension": (0, -2, 1),  # N/m
    "force": (1, -2, 1),
    "force_density": (-2, -2, 1),  # N/m³
    "volume": (3, 0, 0),
    "frequency": (0, -1, 0),
}

MACH_LIMIT = 0.3
"""Default largest admissible lattice Mach number u_lat / c_s (compressibility error grows as Ma²)."""


@dataclass(frozen=True)
class Units:
    """A lattice unit system: grid spacing ``dx`` [m], time step ``dt`` [s], reference density ``rho`` [kg/m³]."""

    dx: float
    dt: float
    rho: float = 1000.0

    def __post_init__(self) -> None:
        for name in ("dx", "dt", "rho"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"Units.{name} must be a positive finite number, got {value!r}")

    def scale(self, quantity: str) -> float:
        """SI value of one lattice unit of ``quantity`` (a key of :data:`DIMENSIONS`)."""
        try:
            a, b, c = DIMENSIONS[quantity]
        except KeyError:
            raise ValueError(f"unknown quantity {quantity!r}; known: {', '.join(DIMENSIONS)}") from None
        return self.dx**a * self.dt**b * (self.rho * self.dx**3) ** c

    def to_lattice(self, value: float, quantity: str) -> float:
        """Convert an SI value of ``quantity`` to lattice units."""
        return value / self.scale(quantity)

    def to_si(self, value: float, quantity: str) -> float:
        """Convert a lattice value of ``quantity`` to SI units."""
        return value * self.scale(quantity)

    def viscosity(self, value: float, unit: str = "SI") -> float:
        """Kinematic viscosity in lattice units; ``unit="lattice"`` passes a lattice value through (Table 1)."""
        if unit == "lattice":
            return float(value)
        if unit == "SI":
            return self.to_lattice(value, "viscosity")
        raise ValueError(f"viscosity unit must be 'SI' or 'lattice', got {unit!r}")

    def mach(self, speed: float) -> float:
        """Lattice Mach number u_lat / c_s of an SI speed."""
        return abs(self.to_lattice(speed, "velocity")) / math.sqrt(CS2)

    def max_dt(self, speed: float, mach_limit: float = MACH_LIMIT) -> float:
        """Largest dt for which an SI ``speed`` stays at or below ``mach_limit``."""
        if speed <= 0:
            return math.inf
        return mach_limit * math.sqrt(CS2) * self.dx / speed

    def check_mach(self, speed: float, what: str = "the fastest expected flow", mach_limit: float = MACH_LIMIT) -> None:
        """Refuse a time step for which ``speed`` [m/s] exceeds the lattice Mach limit, naming the fix."""
        ma = self.mach(speed)
        if ma > mach_limit:
            raise ValueError(
                f"{what} ({speed:g} m/s) is Mach {ma:.3g} on the lattice (limit {mach_limit}); "
                f"use dt <= {self.max_dt(speed, mach_limit):.3g} s or a larger dx"
            )


def relaxation_time(nu_lattice: float) -> float:
    """BGK-equivalent relaxation time τ = ν/c_s² + 1/2 of a lattice kinematic viscosity."""
    return nu_lattice / CS2 + 0.5


def check_relaxation(nu_lattice: float, what: str = "viscosity") -> float:
    """Return τ of ``nu_lattice``; refuse ν ≤ 0 (τ ≤ 1/2 is unstable), naming the fix."""
    if not (math.isfinite(nu_lattice) and nu_lattice > 0):
        raise ValueError(
            f"{what} is {nu_lattice:g} in lattice units; it must be > 0 (τ = ν/c_s² + 1/2 > 1/2). "
            "Increase the viscosity, or reduce dx²/dt"
        )
    return relaxation_time(nu_lattice)
