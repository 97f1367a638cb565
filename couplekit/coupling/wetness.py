"""A particle's wetness in [0, 1], for renderers that colour wet and dry sand.

The saturation S_p the coupler gathers to each particle (paper 000, the text after Eq. 28, and Eq. 59 with
retention) is a *water volume fraction of the cell*: S_p = Σ_i (R_i + ε̃_i φ_i) w_ip, with R the bound water
(0 without retention), ε̃ the fluid fraction and φ the liquid phase field. In sand packed at ε_max it ranges
from 0 (dry) to 1 − ε_max = 0.36 (every pore full of water); in loose sand or in open water it can reach 1.
Paper 000 (§5.1) renders a particle wet when S_p > (1 − ε_max)/2 = 0.18.

The wetness rescales S to the pore space of packed sand::

    wetness = clamp(S_p / (1 − ε_max), 0, 1)

so 0 is dry, ½ is exactly the paper's wet threshold, and 1 means the pores of close-packed sand are full (or
the particle is in water). A particle outside the grid (saturation NaN, see
:meth:`couplekit.coupling.reference.ReferenceOps.particle_moisture`) counts as dry (0), so the attribute is
always a number in [0, 1] that a colour ramp can use as it is.
"""

from __future__ import annotations

import numpy as np

__all__ = ["wetness", "WET_THRESHOLD"]

WET_THRESHOLD = 0.5
"""The wetness of paper 000's wet threshold S = (1 − ε_max)/2 (§5.1)."""


def wetness(saturation: np.ndarray, eps_max: float = 0.64) -> np.ndarray:
    """clamp(S / (1 − ε_max), 0, 1) per particle as float32 (NaN → 0); see the module docstring."""
    if not 0.0 < eps_max < 1.0:
        raise ValueError(f"eps_max must lie in (0, 1) (the sand's maximum packing fraction), got {eps_max}")
    s = np.asarray(saturation, dtype=np.float64) / (1.0 - eps_max)
    return np.clip(np.nan_to_num(s, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0).astype(np.float32)
