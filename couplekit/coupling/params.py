"""Coupling parameters (:class:`CouplingParams`) and the node-level closed forms that validate them.

Defaults and their sources (paper 000 = Xiao et al. 2026, notes = /work/shared/notes/mpm-method.md):

* ``drag_coefficient`` c = 0.39 and ``drag_exponent`` χ = 3.7: paper 000 §4.3 (after Gao et al. 2018;
  notes §3.1 identifies them with the Re → ∞ limits of Di Felice's correlation).
* ``eps_max`` = 0.64: maximum packing of Eq. 25 (random close packing, Baranau and Tallarek 2014).
* ``grain_diameter`` = None: the drag area of paper 000 §4.3, the cross-section of ONE ball holding all of
  the node's sand, A = π (3 V_s / 4π)^(2/3).  With it a node settles like a single sphere of diameter
  D = (6 ε V_cell / π)^(1/3), so the settling speed grows like √dx and does not depend on the grain size
  (notes §3.2: at dx = 5 mm about 10× faster than one 0.2 mm grain).  Give a grain diameter (m) to use the
  total cross-section of the node's grains instead, A = 1.5 V_s / d (N = V_s / (π d³/6) spheres of area
  π d²/4): then the node settles like one grain, independent of dx.  The paper's form stays the default
  because it reproduces the paper.
* ``retention`` = False; ``absorption_rate`` R_a = 0.001 per lattice step (paper 000 Table 1 uses 0.001
  and 0.003, "in dimensionless space").
* ``r_max`` = 0.28: **not given in paper 000** (nor a value we could find in the GIC paper).  Chosen so that a
  node packed at ε_max holds, at capacity, r_max ε_max = 0.18 = (1 − ε_max)/2 of its volume as bound
  water: exactly paper 000's threshold for rendering sand "wet" (§5.1), i.e. sand at retention capacity
  counts as wet and half of its pores stay open to free water.  It must stay below (1 − ε_max)/ε_max
  (bound water filling every pore), which is checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["CouplingParams", "node_terminal_velocity", "drag_area"]


@dataclass(frozen=True)
class CouplingParams:
    """Sand–fluid coupling constants (see the module docstring for the defaults' sources).

    drag_coefficient, drag_exponent: c and χ of w = ½ c (1 − ε)^(−χ) ρ A |u − v| (paper 000 §4.3).
    eps_max: maximum sand volume fraction (Eq. 25).
    grain_diameter: None for the paper's one-ball drag area; a diameter in metres for the grain-area option.
    retention: water retention (Eqs. 53–58) on/off; r_max: capacity ratio; absorption_rate: R_a per step.
    """

    drag_coefficient: float = 0.39
    drag_exponent: float = 3.7
    eps_max: float = 0.64
    grain_diameter: float | None = None
    retention: bool = False
    r_max: float = 0.28
    absorption_rate: float = 0.001

    def __post_init__(self) -> None:
        problems = []
        if not self.drag_coefficient > 0:
            problems.append(f"drag_coefficient must be > 0, got {self.drag_coefficient}")
        if not self.drag_exponent >= 0:
            problems.append(f"drag_exponent must be >= 0, got {self.drag_exponent}")
        if not 0 < self.eps_max < 1:
            problems.append(f"eps_max must be in (0, 1), got {self.eps_max}")
        if self.grain_diameter is not None and not self.grain_diameter > 0:
            problems.append(f"grain_diameter must be > 0 m or None (paper's ball area), got {self.grain_diameter}")
        if 0 < self.eps_max < 1:
            limit = (1.0 - self.eps_max) / self.eps_max
            if not 0 <= self.r_max < limit:
                problems.append(
                    f"r_max must be in [0, (1 - eps_max)/eps_max = {limit:.4g}) so bound water cannot fill the "
                    f"pores, got {self.r_max}"
                )
        if not 0 <= self.absorption_rate <= 1:
            problems.append(f"absorption_rate must be in [0, 1] per lattice step, got {self.absorption_rate}")
        if problems:
            raise ValueError("invalid CouplingParams: " + "; ".join(problems))

    def grain_diameter_lattice(self, dx: float) -> float:
        """Grain diameter in cells for the kernels (0 selects the paper's ball area)."""
        return 0.0 if self.grain_diameter is None else float(self.grain_diameter) / float(dx)


def drag_area(eps_sand: float, cell_volume: float, grain_diameter: float | None = None) -> float:
    """Drag cross-section of a node holding sand volume ε V_cell: one ball (paper) or all its grains."""
    volume = eps_sand * cell_volume
    if grain_diameter is None:
        return math.pi * (3.0 * volume / (4.0 * math.pi)) ** (2.0 / 3.0)
    return 1.5 * volume / grain_diameter


def node_terminal_velocity(
    sand_density: float,
    fluid_density: float,
    gravity: float,
    eps_sand: float,
    dx: float,
    params: CouplingParams | None = None,
) -> float:
    """Steady slip speed |u − v| of a uniform suspension node (SI), from drag = weight − buoyancy.

    (ϱ − ρ) ε V g = ½ c (1 − ε)^(−χ) ρ A v²  ⇒  v = sqrt(2 (ϱ − ρ) ε V g (1 − ε)^χ / (c ρ A)).
    With the paper's ball area this is sqrt(4 (ϱ − ρ) g D (1 − ε)^χ / (3 c ρ)), D = (6 ε dx³/π)^(1/3)
    (notes §3.2); with the grain area D becomes the grain diameter.  Returns the magnitude (the sand falls
    when ϱ > ρ, rises otherwise).
    """
    p = params or CouplingParams()
    volume = dx**3
    area = drag_area(eps_sand, volume, p.grain_diameter)
    weight = abs(sand_density - fluid_density) * eps_sand * volume * abs(gravity)
    return math.sqrt(2.0 * weight * (1.0 - eps_sand) ** p.drag_exponent / (p.drag_coefficient * fluid_density * area))
