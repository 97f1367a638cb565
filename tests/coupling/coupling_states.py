"""Random but valid coupling states for the kernel-vs-reference tests (shared by tests/coupling)."""

from __future__ import annotations

import numpy as np

from couplekit.coupling import CouplingParams
from couplekit.units import Units

SHAPE = (5, 6, 7)  # (nz, ny, nx), small and with three different extents so axis mix-ups show
UNITS = Units(dx=0.005, dt=1.6e-5)  # paper 000 Fig. 8 (dx = 5 mm, dt = 1.6e-5 s)
GRAVITY = (0.0, 0.0, -9.81)
RHO_H, RHO_L = 1.0, 1.25e-3  # lattice densities of water and air (800:1)


def padded(shape=SHAPE) -> tuple[int, int, int]:
    return tuple(s + 2 for s in shape)


def fluid_flags(rng: np.random.Generator, shape=SHAPE, walls: str = "z", obstacles: int = 3) -> np.ndarray:
    """Padded uint8 flags: walls (1) on the faces of the axes in ``walls``, periodic ghosts (0) elsewhere,
    plus a few interior obstacle cells."""
    flags = np.zeros(padded(shape), np.uint8)
    if "z" in walls:
        flags[0], flags[-1] = 1, 1
    if "y" in walls:
        flags[:, 0], flags[:, -1] = 1, 1
    if "x" in walls:
        flags[:, :, 0], flags[:, :, -1] = 1, 1
    nz, ny, nx = shape
    for _ in range(obstacles):
        flags[1 + rng.integers(nz), 1 + rng.integers(ny), 1 + rng.integers(nx)] = 1
    return flags


def grid_state(rng: np.random.Generator, params: CouplingParams, shape=SHAPE, units: Units = UNITS) -> dict:
    """MPM grid after P2G (SI) and the fluid fields (lattice, padded), with empty, sparse, packed and
    over-packed (ε > ε_max) nodes; bound water from empty to above capacity; φ slightly outside [0, 1]."""
    cell = units.dx**3
    eps_raw = rng.uniform(0.0, 0.9, shape)
    eps_raw[rng.random(shape) < 0.2] = 0.0
    density = rng.uniform(600.0, 2500.0, shape)
    grid_vol = (eps_raw * cell).astype(np.float32)
    grid_m = (density * eps_raw * cell).astype(np.float32)
    v = rng.uniform(-0.5, 0.5, (3, *shape))
    grid_mv = (grid_m * v).astype(np.float32)
    eps_c = np.minimum(params.eps_max, eps_raw)
    bound = (rng.uniform(0.0, 1.1, shape) * params.r_max * eps_c).astype(np.float32)
    pz, py, px = padded(shape)
    # last step's porosity: around the current one, sometimes below it (limits Eq. 55's free water)
    eps_prev = (rng.uniform(0.3, 1.0, (pz, py, px))).astype(np.float32)
    phi = rng.uniform(-0.05, 1.05, (pz, py, px)).astype(np.float32)
    u = rng.uniform(-0.05, 0.05, (3, pz, py, px)).astype(np.float32)
    return {
        "grid_vol": grid_vol,
        "grid_m": grid_m,
        "grid_mv": grid_mv,
        "bound": bound,
        "eps_prev": eps_prev,
        "phi": phi,
        "u": u,
        "flags": fluid_flags(rng, shape),
    }


def particles(rng: np.random.Generator, count: int, shape=SHAPE, dx: float = UNITS.dx) -> dict:
    """Particles strictly inside the band where their 3×3×3 stencil stays on the grid."""
    nz, ny, nx = shape
    hi = np.array([nx, ny, nz], float)[:, None] - 1.0
    x = (rng.uniform(1.0, 1.0, (3, count)) + rng.random((3, count)) * (hi - 1.0)) * dx
    return {
        "x": x.astype(np.float32),
        "r": rng.uniform(0.0, 0.3, count).astype(np.float32),
        "vol": (rng.uniform(0.1, 0.2, count) * dx**3).astype(np.float32),
    }
