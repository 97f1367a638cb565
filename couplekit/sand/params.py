"""Sand material parameters (:class:`SandParams`) and the constitutive constants the ops consume.

Defaults and their sources:

* Hardening h0 = 35°, h1 = 9°, h2 = 0.2, h3 = 10°: paper 000 §4.2 (after Klár et al. 2016), giving a
  friction angle that starts at 25°, peaks at 48.3° (q = 6.11) and settles to 35°.
* Density 2200 kg/m³ of the sand *material* (grain packing included), Young's modulus 3.537e5 Pa and
  Poisson ratio 0.3: the sand of Klár et al. 2016 as carried by the public re-implementations
  (notes/mpm-method.md §4).  Paper 000 does not report E; its time steps bound c_p to ≲ 17 m/s,
  i.e. E of order 1e5 Pa (same note), which this default satisfies (c_p = 14.7 m/s).
* Cohesion c_C(S) (paper 000 Eq. 28): "the piecewise linear function used in Su et al. 2023".  **Its
  breakpoints could not be found** (only the abstract of Su et al. 2023 is public; notes/mpm-method.md
  §2.5, open item 1).  The default is a trapezoid in paper 000's saturation S (water volume per cell
  volume, 0 … 1 − ε_max = 0.36): 0 when dry (Fig. 17 needs dry sand to collapse at once), rising to
  ``cohesion_max`` at S1 = 0.05, flat up to S2 = 0.18 (paper 000's own "wet" threshold (1 − ε_max)/2), and
  back to 0 at S3 = 0.36 (pores full: capillary bridges vanish, as GIC's Γ(sr) curve and Tampubolon
  2017's saturation-weakening do).  ``cohesion_max`` = 1000 Pa: capillary cohesion of moist sand is of
  order 1 kPa (tensile strength ≈ 2.3 kPa at S = 0.3, Andreotti et al. 2013 via notes §2.5), and a
  10 cm vertical wet cut needs c_C ≈ 400 Pa at φ = 25° (Rankine), so 1000 Pa lets decimetre blocks
  stand (Fig. 17).  These are choices, not published values; replace them when Su 2023 is read.

Consequence of the hardening, measured (tests/sand/test_validation.py): the sand hardens while it flows
(a collapsing column's particles end at a mean φ_F of 31–41°), and a Drucker–Prager deposit stands at its
friction angle, so column-collapse runouts fall 44–53 % short of Lube et al. 2004.  A constant 20°
(``hardening=False, h0=20``) reproduces Lube's scaling within 20 % at aspect ratios 0.5 and 2, and with
``viscosity=1.5`` (Pa s) it does so on every grid tested (R0 = 6–16 cells, planar L0 = 8–24): without a rate
dependence the collapse does not converge with the grid (issue 16, docs/sand-validation.md).  The default
viscosity is 0 (the paper's rate-independent Klár return).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..arguments import is_real

__all__ = ["SandParams", "ConstitutiveModel", "friction_angle_range"]


def friction_angle_range(h0: float, h1: float, h2: float, h3: float) -> tuple[float, float]:
    """(lowest, highest) in degrees of the friction angle φ_F(q) = h0 + (h1 q − h3) exp(−h2 q) of Klar et al.'s
    hardening over plastic strains q >= 0 (h2 >= 0), for any signs of h0, h1, h3: φ_F(0) = h0 − h3, the limit h0
    as q grows (h2 > 0), and its one stationary point q* = 1/h2 + h3/h1 where q* > 0; with h2 = 0 a line,
    unbounded unless h1 = 0. One rule for SandParams and the scene's ``sand.hardening`` check (assuming
    h1, h3 >= 0 had let [10, -20, 0.2, 0] pass although the angle falls to −26.8 degrees)."""
    values = [h0 - h3]
    if h2 > 0:
        values.append(h0)
        if h1 != 0:
            q = 1.0 / h2 + h3 / h1
            if q > 0:
                values.append(h0 + (h1 * q - h3) * math.exp(-h2 * q))
    elif h1 != 0:  # h2 = 0: the angle changes without bound with the plastic strain
        values.append(math.copysign(math.inf, h1))
    return float(min(values)), float(max(values))


@dataclass(frozen=True)
class SandParams:
    """Material of one sand body (SI units).

    density: mass per volume of the sand material, kg/m³ (particle mass = density × particle volume).
    youngs_modulus (Pa), poisson_ratio: Hencky elasticity.
    h0, h1, h3 (degrees), h2: Klár hardening, φ_F(q) = h0 + (h1 q − h3) exp(−h2 q).
    cohesion_max (Pa), cohesion_s1/s2/s3: trapezoid c_C(S) of Eq. 28 (see the module docstring).
    plasticity: False gives a purely elastic Hencky solid (for validation).
    hardening: False keeps φ_F = h0 (then h0 is the constant friction angle).
    cohesion: False compiles cohesion out; None (default) turns it on when cohesion_max > 0.
    volume_correction: Tampubolon et al. 2017 volume correction.
    viscosity: viscoplastic overstress η (Pa s) of the Drucker–Prager flow, Duvaut–Lions form: the deviatoric
        stress may exceed the cone by 2 η D (D the deviatoric rate of deformation; η γ̇ in simple shear),
        relaxing with t_r = η / μ.  0 (default) is the rate-independent return of Klár et al. 2016.
        Constant-friction plasticity is ill-posed in transient flow, so a collapse does not converge with
        the grid without it (docs/sand-validation.md: 1.5 Pa s makes the planar runout converge at 8–24
        cells, 0 lets it grow 1.43 → 1.92).
    """

    density: float = 2200.0
    youngs_modulus: float = 3.537e5
    poisson_ratio: float = 0.3
    h0: float = 35.0
    h1: float = 9.0
    h2: float = 0.2
    h3: float = 10.0
    cohesion_max: float = 1000.0
    cohesion_s1: float = 0.05
    cohesion_s2: float = 0.18
    cohesion_s3: float = 0.36
    plasticity: bool = True
    hardening: bool = True
    cohesion: bool | None = None
    volume_correction: bool = True
    viscosity: float = 0.0
    extra: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        problems = []
        numeric = (
            "density", "youngs_modulus", "poisson_ratio", "h0", "h1", "h2", "h3", "cohesion_max",
            "cohesion_s1", "cohesion_s2", "cohesion_s3", "viscosity",
        )  # fmt: skip
        for name in numeric:  # each a finite real number (bool is not): NaN passed every "> 0" test below
            value = getattr(self, name)
            if not is_real(value):
                problems.append(f"{name} must be a finite number, got {value!r} ({type(value).__name__})")
            elif not math.isfinite(value):
                problems.append(f"{name} must be a finite number, got {value!r}")
        if problems:
            raise ValueError("invalid SandParams: " + "; ".join(problems))
        if not self.density > 0:
            problems.append(f"density must be > 0 kg/m³, got {self.density}")
        if not self.youngs_modulus > 0:
            problems.append(f"youngs_modulus must be > 0 Pa, got {self.youngs_modulus}")
        if not -1.0 < self.poisson_ratio < 0.5:
            problems.append(f"poisson_ratio must be in (-1, 0.5), got {self.poisson_ratio}")
        if self.cohesion_max < 0:
            problems.append(f"cohesion_max must be >= 0 Pa, got {self.cohesion_max}")
        if not 0 < self.cohesion_s1 <= self.cohesion_s2 < self.cohesion_s3:
            problems.append(
                "cohesion breakpoints must satisfy 0 < cohesion_s1 <= cohesion_s2 < cohesion_s3, got "
                f"{self.cohesion_s1}, {self.cohesion_s2}, {self.cohesion_s3}"
            )
        if self.h2 < 0:
            problems.append(f"h2 must be >= 0, got {self.h2}")
        elif self.plasticity:  # a purely elastic solid has no friction angle
            lo, hi = self.friction_angle_range()
            if not self.hardening and not 0.0 < lo < 90.0:
                problems.append(
                    f"h0 = {self.h0:g} degrees is the constant friction angle (hardening=False); it must be in "
                    "(0, 90) degrees, e.g. 30"
                )
            elif not (0.0 < lo and hi < 90.0):
                problems.append(
                    f"h0, h1, h2, h3 = {self.h0:g}, {self.h1:g}, {self.h2:g}, {self.h3:g} make the friction angle "
                    f"h0 + (h1 q - h3) exp(-h2 q) range over [{lo:.3g}, {hi:.3g}] degrees as the plastic strain q "
                    "grows; it must stay within (0, 90) degrees (the paper's sand: 35, 9, 0.2, 10, 25 to 48 degrees)"
                )
        if not self.viscosity >= 0:
            problems.append(f"viscosity must be >= 0 Pa s, got {self.viscosity}")
        if problems:
            raise ValueError("invalid SandParams: " + "; ".join(problems))

    def friction_angle_range(self) -> tuple[float, float]:
        """(lowest, highest) friction angle in degrees over plastic strains q >= 0: h0 without hardening, else
        :func:`friction_angle_range` of (h0, h1, h2, h3)."""
        if not self.hardening:
            return float(self.h0), float(self.h0)
        return friction_angle_range(self.h0, self.h1, self.h2, self.h3)

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2 (1 + ν))."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lam(self) -> float:
        """Lamé λ = E ν / ((1 + ν)(1 − 2ν))."""
        nu = self.poisson_ratio
        return self.youngs_modulus * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))

    @property
    def p_wave_speed(self) -> float:
        """c_p = sqrt((λ + 2μ) / ρ), m/s: the fastest elastic wave (sets the time-step limit)."""
        return math.sqrt((self.lam + 2.0 * self.mu) / self.density)

    def cohesion_on(self) -> bool:
        """Whether the cohesion term is compiled in."""
        return bool(self.cohesion_max > 0) if self.cohesion is None else bool(self.cohesion)

    def model(self) -> ConstitutiveModel:
        """The constants and switches the constitutive ops take."""
        return ConstitutiveModel(
            mu=self.mu,
            lam=self.lam,
            h0=math.radians(self.h0),
            h1=math.radians(self.h1),
            h2=self.h2,
            h3=math.radians(self.h3),
            cohesion_max=self.cohesion_max,
            s1=self.cohesion_s1,
            s2=self.cohesion_s2,
            s3=self.cohesion_s3,
            plasticity=self.plasticity,
            hardening=self.hardening,
            cohesion=self.cohesion_on(),
            volume_correction=self.volume_correction,
            viscosity=self.viscosity,
        )


@dataclass(frozen=True)
class ConstitutiveModel:
    """Constitutive constants in kernel units (angles in radians) plus the compile-time switches."""

    mu: float
    lam: float
    h0: float
    h1: float
    h2: float
    h3: float
    cohesion_max: float
    s1: float
    s2: float
    s3: float
    plasticity: bool = True
    hardening: bool = True
    cohesion: bool = False
    volume_correction: bool = True
    viscosity: float = 0.0

    def plastic_fraction(self, dt: float | None) -> float:
        """The fraction 1 / (1 + t_r / Δt) of the Drucker–Prager (Case III) return applied in one step of Δt,
        t_r = η / μ (Duvaut–Lions viscoplastic overstress 2 η D; the kernels' ``keep``).  1 (rate-independent)
        without viscosity, or when no Δt is given (``dt`` None or <= 0)."""
        if not self.viscosity > 0 or dt is None or not dt > 0:
            return 1.0
        return 1.0 / (1.0 + self.viscosity / (self.mu * dt))

    def defines(self) -> dict[str, int]:
        """Preprocessor switches of mpm_model.cuh."""
        return {
            "MPM_PLASTICITY": int(self.plasticity),
            "MPM_HARDENING": int(self.hardening),
            "MPM_COHESION": int(self.cohesion),
            "MPM_VOLUME_CORRECTION": int(self.volume_correction),
        }

    def scalars(self) -> tuple[np.float32, ...]:
        """(mu, lambda, h0, h1, h2, h3, c_max, S1, S2, S3) as float32, the kernels' argument order."""
        vals = (self.mu, self.lam, self.h0, self.h1, self.h2, self.h3, self.cohesion_max, self.s1, self.s2, self.s3)
        return tuple(np.float32(v) for v in vals)

    def friction_angle(self, q: np.ndarray) -> np.ndarray:
        """φ_F(q) in radians (Klár et al. 2016 hardening, or h0 when hardening is off)."""
        q = np.asarray(q, dtype=np.float64)
        if not self.hardening:
            return np.full_like(q, self.h0)
        return self.h0 + (self.h1 * q - self.h3) * np.exp(-self.h2 * q)

    def cohesion_of(self, s: np.ndarray) -> np.ndarray:
        """c_C(S) in Pa (0 when cohesion is off)."""
        s = np.asarray(s, dtype=np.float64)
        if not self.cohesion:
            return np.zeros_like(s)
        up = s / self.s1
        down = (self.s3 - s) / (self.s3 - self.s2)
        return self.cohesion_max * np.clip(np.minimum(np.minimum(up, 1.0), down), 0.0, 1.0)


def dp_alpha(phi: np.ndarray) -> np.ndarray:
    """Drucker–Prager coefficient α = sqrt(2/3) · 2 sin φ / (3 − sin φ) (φ in radians)."""
    s = np.sin(phi)
    return math.sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s)
