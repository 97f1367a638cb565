"""Where the odd-moment rate floor acts when it is ramped in from the walls (``FluidParams.odd_ramp``).

The scenes' floor (``FluidParams.odd_lambda``, :func:`couplekit.fluid.reference.odd_rates`) keeps the odd
central moments relaxing at r_floor ≈ 0.02 at ν = 1e-4 in every cell. It is there for the no-slip walls: at
the paper's rate 1 their edges and corners grow a mode at low viscosity (docs/fluid-stability.md, "Why").
Away from the walls it slows the odd moments for nothing, and there it throws a 600 kg/m³ ball of 1.7 cells
up off the water at interface width 4 (docs/examples.md, Fig. 8). With a ramp of D cells the rate is

    r_o = r_floor + (1 − r_floor) s,   s = ½ − ½ cos(π t),   t = clip((d − ½) / D, 0, 1),

d the distance (cells) of the cell centre from the nearest boundary cell's face: the cells touching a wall
keep the floor (s = 0) and the cells more than D + ½ cells in relax at the paper's rate 1 (s = 1). The ramp
is smooth because a floor that switches from one cell to the next was measured unstable (spectral radius
1.0004–1.006 of the step linearised at rest on a 7 × 7 walled box, ``reference.odd_rates``).

Boundary cells are every non-fluid cell that is not a periodic ghost: walls, solid obstacle cells, inflow
ghosts (outlets in a wall included) and outflow ghosts (conservative: the floor there costs nothing).

Measured (``benchmarks/odd_floor_ramp.py linear``, the step linearised at rest, walls on x and y, periodic z,
ν = 1e-4; results/odd_floor_ramp.json): with D = 3 the spectral radius is 1 (as with the floor everywhere) in
boxes of 6, 8, 9, 10, 11 and 12 cells between the walls, but 1.0011 at 5 and 1.0000019 at 7 cells, and a
channel 5 cells wide between walls 12 apart the other way grows too (1.00034, a period-2 mode). So a
ramp needs every gap between boundary cells along each axis to be at least :data:`MIN_GAP_CELLS` cells:
:func:`narrow_gap` finds a narrower one, and :class:`~couplekit.fluid.solver.FluidSolver` refuses the ramp
when a gap is narrower (the fix: no ramp, i.e. the floor everywhere, or a wider gap).
"""

from __future__ import annotations

import numpy as np

from .grid import FLUID, INTERIOR, wrap_interior

MIN_GAP_CELLS = 8
"""The narrowest fluid gap between boundary cells along an axis at which the ramp is accepted (module docstring)."""


def boundary_mask(flags: np.ndarray, periodic: tuple[bool, bool, bool], extend: int) -> np.ndarray:
    """Padded-grid mask of the boundary cells (non-fluid, not periodic ghosts), with every periodic axis
    (x, y, z) replaced by its interior wrapped ``extend`` cells onto both sides, so that distances and gaps
    see the boundary cells across the periodic faces. Shape: the padded shape with 2 (``extend`` − 1) more
    cells on each periodic axis."""
    mask = flags != FLUID
    for axis, wraps in zip((2, 1, 0), periodic, strict=True):  # x, y, z = array axes 2, 1, 0
        if wraps:
            mask = wrap_interior(mask, axis, extend)
    return mask


def _crop(a: np.ndarray, periodic: tuple[bool, bool, bool], extend: int) -> np.ndarray:
    """The padded grid's part of an array over :func:`boundary_mask`'s grid (its interior along wrapped axes
    with one ghost layer of zeros, like the padded grid)."""
    out = a
    for axis, wraps in zip((2, 1, 0), periodic, strict=True):
        if wraps:
            n = out.shape[axis] - 2 * extend
            out = np.take(out, np.arange(extend - 1, extend + n + 1), axis=axis)
    return out


def ramp_weights(flags: np.ndarray, periodic: tuple[bool, bool, bool], cells: float) -> np.ndarray:
    """The weight s of the paper's rate 1 in every padded cell (float32; 0 in the non-fluid cells): the cosine
    ramp of the module docstring over ``cells`` = D > 0 cells from the nearest boundary cell."""
    from scipy.ndimage import distance_transform_edt

    D = float(cells)
    if not D > 0:
        raise ValueError(f"the odd-rate ramp needs a length > 0 cells, got {cells!r}")
    extend = int(np.ceil(D)) + 2
    boundary = boundary_mask(flags, periodic, extend)
    if not boundary.any():  # all periodic, no solid: rate 1 everywhere
        s = np.ones(flags.shape, np.float32)
        s[flags != FLUID] = 0.0
        return s
    # Euclidean distance between cell centres to the nearest boundary cell; the face of that cell is ½ nearer
    d = distance_transform_edt(~boundary) - 0.5
    t = np.clip((d - 0.5) / D, 0.0, 1.0)
    s = _crop(0.5 - 0.5 * np.cos(np.pi * t), periodic, extend).astype(np.float32)
    s[flags != FLUID] = 0.0
    return s


def narrow_gap(
    flags: np.ndarray, periodic: tuple[bool, bool, bool], below: int = MIN_GAP_CELLS
) -> tuple[int, str, tuple[int, int, int]] | None:
    """The narrowest run of fluid cells between two boundary cells along x, y or z, if one is narrower than
    ``below`` cells: ``(cells, axis, (x, y, z))`` with the interior index of one cell of it; else ``None``.
    Runs across periodic faces count (the wrap is ``below`` cells deep, enough to see them whole)."""
    boundary = boundary_mask(flags, periodic, int(below))
    fluid = flags[INTERIOR] == FLUID
    big = np.iinfo(np.int32).max
    best: tuple[int, str, tuple[int, int, int]] | None = None
    for axis, name in ((2, "x"), (1, "y"), (0, "z")):
        b = np.moveaxis(boundary, axis, -1)
        length = b.shape[-1]
        pos = np.arange(length, dtype=np.int32)
        last = np.maximum.accumulate(np.where(b, pos, np.int32(-1)), axis=-1)
        nxt = np.minimum.accumulate(np.where(b, pos, np.int32(length))[..., ::-1], axis=-1)[..., ::-1]
        bounded = ~b & (last >= 0) & (nxt < length)
        gap = np.moveaxis(np.where(bounded, nxt - last - 1, big).astype(np.int32), -1, axis)
        gap = np.where(fluid, _crop(gap, periodic, int(below))[INTERIOR], big)
        k = int(np.argmin(gap))
        g = int(gap.reshape(-1)[k])
        if g < below and (best is None or g < best[0]):
            z, y, x = np.unravel_index(k, gap.shape)
            best = (g, name, (int(x), int(y), int(z)))
    return best


def check_gaps(flags: np.ndarray, periodic: tuple[bool, bool, bool], cells: float) -> None:
    """Refuse the ramp where a gap between boundary cells is narrower than :data:`MIN_GAP_CELLS` (module
    docstring): ValueError naming the gap, where it is and the fix."""
    gap = narrow_gap(flags, periodic)
    if gap is not None:
        g, axis, (x, y, z) = gap
        raise ValueError(
            f"odd_ramp = {cells:g}: the fluid is {g} cells wide along {axis} at interior cell (x, y, z) = "
            f"({x}, {y}, {z}) between walls, solid cells or open faces; the ramped odd-rate floor needs gaps of at "
            f"least {MIN_GAP_CELLS} cells (narrower ones grow a mode, docs/fluid-stability.md). Set odd_ramp = 0 "
            "(the floor everywhere) or widen the gap"
        )
