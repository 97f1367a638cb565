"""The hydrostatic start of a fluid at rest: the pressure that balances gravity (a tank at rest stays at rest).

Used by the scene assembly (:mod:`couplekit.assembly`, ``fluid.initial_pressure``) and by tests that build
solvers directly.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hydrostatic_pressure"]


def hydrostatic_pressure(
    shape: tuple[int, int, int],
    gravity: tuple[float, float, float],
    phi: np.ndarray | None = None,
    rho_l: float = 1.0,
    boundary: dict[str, str] | None = None,
    interface_width: float = 4.0,
    resting_only: bool = True,
) -> np.ndarray | None:
    """The hydrostatic pressure (nz, ny, nx) of a fluid at rest in FluidSolver's lattice units (water ρ = 1,
    ``gravity`` the lattice acceleration), or None when there is none to set: no gravity, gravity not along
    one axis, or periodic faces (``boundary``, scene face names) along it.

    Per column along gravity, from the face gravity points away from (p = 0 there): p_k = |g| (Σ_{k' above k}
    ρ_k' + ρ_k / 2), the cell-centred integral of ρ g, with ρ = ρ_l + (1 − ρ_l) φ of the two-phase mixture
    (``phi``; None: single-phase water, ρ = 1). Then −∇p/ρ + g = 0 to second order (Eq. 15's pressure and
    gravity terms) and a tank at rest starts at rest, without the pressure wave a start from p = 0 sends
    through it (the water falls by g Δt in the first step, the floor stops it, and it rings with a speed of
    order |g| H / c_s). Obstacles are integrated through with the φ they were given (the water's SDF ignores
    them): right under a submerged obstacle, irrelevant inside one.

    ``resting_only`` (default): only water that rests on the floor is carried: per column, the water's excess weight (ρ − ρ_l) g counts up
    to the top of the segment of cells with φ ≥ ½ that starts at the floor, plus 2 ``interface_width`` + 1
    cells of the interface above it. Water that hangs in the air (a drop, a poured block)
    adds nothing, so the air under and beside it keeps its own hydrostatic pressure: integrated straight
    through, the weight of a hanging block sat on the floor under it, and the step in pressure at the edge of
    its column blew the air out sideways (Fig. 17's poured block: 5.75 m/s in the first step, NaN by step 7).
    ``resting_only=False`` integrates every column straight through (``fluid.initial_pressure = "column"``):
    right for a water layer that spans the domain over trapped air (a dry sand plug under water in a closed
    tank, whose pore air carries the layer's weight).
    """
    g = np.asarray(gravity, np.float64)
    axes = np.flatnonzero(g)
    if len(axes) != 1:
        return None
    a = int(axes[0])  # 0 = x, 1 = y, 2 = z
    if boundary and boundary.get(f"{'xyz'[a]}_min") == "periodic":
        return None
    if phi is None:
        rho = np.ones(tuple(shape), np.float64)
    else:
        rho = rho_l + (1.0 - rho_l) * np.clip(np.asarray(phi, np.float64), 0.0, 1.0)
    r = np.moveaxis(rho, 2 - a, 0)  # array axes are (z, y, x)
    down = slice(None, None, -1) if g[a] < 0 else slice(None)  # from the face gravity points away from
    rd = r[down]
    n = rd.shape[0]
    # height (cells from the floor) of the water segment resting on the floor, plus the interface's tail
    water_up = (rd >= 0.5 * (1.0 + rho_l))[::-1]  # from the floor up
    resting = np.cumprod(water_up, axis=0).sum(axis=0)
    top = resting + int(np.ceil(2.0 * interface_width)) + 1
    level = np.arange(n)[::-1].reshape((n,) + (1,) * (rd.ndim - 1))  # height of each cell of rd above the floor
    weight = rho_l + np.where(level < top, rd - rho_l, 0.0) if resting_only else rd
    above = np.cumsum(weight, axis=0) - 0.5 * weight
    return np.moveaxis((abs(g[a]) * above)[down], 0, 2 - a).astype(np.float32)
