"""Phase-field grid layout and parameters shared by the kernel ops and the NumPy reference.

Every field is padded with one ghost layer on every side: interior extents ``(nz, ny, nx)``, stored
extents ``(nz + 2, ny + 2, nx + 2)``, interior cell ``(x, y, z)`` at padded index ``[z + 1, y + 1, x + 1]``.
See :mod:`couplekit.fluid.phasefield` for the full storage and streaming convention.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..lattice import CS2_7

Periodic = tuple[bool, bool, bool]
"""Periodicity of the (x, y, z) axes; a non-periodic axis has no-flux walls at both ends."""


def padded_shape(shape: Sequence[int]) -> tuple[int, int, int]:
    """Stored extents ``(nz + 2, ny + 2, nx + 2)`` of a field with interior extents ``shape = (nz, ny, nx)``."""
    nz, ny, nx = (int(s) for s in shape)
    if min(nz, ny, nx) < 1:
        raise ValueError(f"interior extents must be >= 1, got {tuple(shape)}")
    return nz + 2, ny + 2, nx + 2


def interior_shape(padded: Sequence[int]) -> tuple[int, int, int]:
    """Interior extents ``(nz, ny, nx)`` of a padded field whose last three extents are ``padded``."""
    nz, ny, nx = (int(s) - 2 for s in tuple(padded)[-3:])
    if min(nz, ny, nx) < 1:
        raise ValueError(f"padded extents must be >= 3, got {tuple(padded)[-3:]}")
    return nz, ny, nx


def interior(a: np.ndarray) -> np.ndarray:
    """View of the interior cells of a padded field (last three axes)."""
    return a[..., 1:-1, 1:-1, 1:-1]


def as_periodic(periodic: bool | Sequence[bool]) -> Periodic:
    """Normalise a periodicity flag (one bool for all axes, or (x, y, z))."""
    if isinstance(periodic, (bool, np.bool_)):
        return (bool(periodic),) * 3
    flags = tuple(bool(p) for p in periodic)
    if len(flags) != 3:
        raise ValueError(f"periodic must be one bool or three (x, y, z), got {periodic!r}")
    return flags  # type: ignore[return-value]


FLUID, WALL, INFLOW, OUTFLOW = 0, 1, 2, 3
"""Cell flags, the values of :mod:`couplekit.fluid.grid` (the flow's flags array is passed as is)."""


def pad_flags(solid: np.ndarray | None, shape: Sequence[int], periodic: bool | Sequence[bool]) -> np.ndarray:
    """Padded uint8 cell flags for walls on the non-periodic faces and obstacles ``solid`` (or ``None``).

    Interior obstacle cells and every ghost cell of a non-periodic axis are ``WALL``; a ghost cell of
    periodic axes only takes the flag of its wrapped image.  This is what
    :func:`couplekit.fluid.grid.build_flags` gives for periodic and wall faces.
    """
    nz, ny, nx = (int(s) for s in shape)
    m = np.zeros((nz, ny, nx), dtype=np.uint8) if solid is None else np.asarray(solid).astype(bool) * np.uint8(WALL)
    if m.shape != (nz, ny, nx):
        raise ValueError(f"solid mask has shape {m.shape}, expected the interior shape {(nz, ny, nx)}")
    px, py, pz = as_periodic(periodic)
    out = m.astype(np.uint8)
    for axis, per in enumerate((pz, py, px)):
        width = [(0, 0)] * 3
        width[axis] = (1, 1)
        out = np.pad(out, width, mode="wrap") if per else np.pad(out, width, constant_values=WALL)
    return np.ascontiguousarray(out, dtype=np.uint8)


def check_flags(flags: np.ndarray, periodic: bool | Sequence[bool]) -> None:
    """Refuse flags whose ghost cells on a non-periodic axis are FLUID (h would stream into the void)."""
    px, py, pz = as_periodic(periodic)
    f = np.asarray(flags)
    faces = []
    if not px:
        faces += [f[:, :, 0], f[:, :, -1]]
    if not py:
        faces += [f[:, 0, :], f[:, -1, :]]
    if not pz:
        faces += [f[0], f[-1]]
    if any((face == FLUID).any() for face in faces):
        raise ValueError("flags: a ghost cell of a non-periodic axis is FLUID; mark it WALL, INFLOW or OUTFLOW")


def relaxation_rate(mobility: float) -> float:
    """omega_h = 1 / tau_h with tau_h = M / cs^2 + 1/2 on D3Q7 (cs^2 = 1/4): mobility M = cs^2 (tau_h - 1/2)."""
    if mobility <= 0:
        raise ValueError(f"mobility must be > 0, got {mobility}")
    return 1.0 / (mobility / CS2_7 + 0.5)


def continuum_coefficients(sigma: float, width: float) -> tuple[float, float]:
    """(beta, kappa) of the chemical potential (Eq. 22) in the continuum: beta = 12 sigma / W, kappa = 3 sigma W / 2
    (Jacqmin 1999; notes §1c): the flat profile phi = (1 + tanh(2 s / W)) / 2 has mu = 0 and excess free energy
    kappa * integral(phi'^2) = sigma."""
    if width <= 0:
        raise ValueError(f"interface width must be > 0, got {width}")
    if sigma < 0:
        raise ValueError(f"surface tension must be >= 0, got {sigma}")
    return 12.0 * sigma / width, 1.5 * sigma * width


SURFACE_TENSION_FIT = (0.112, 0.897)
"""(a, b) of :func:`discrete_surface_tension_factor`, 1 − a/W − b/W², fitted to the flat-interface limit of the
Laplace jump measured with the continuum coefficients (session 21; docs/fluid-stability.md, "Surface tension
at the interface widths the scenes use")."""


def discrete_surface_tension_factor(width: float) -> float:
    """The surface tension this lattice gives with the continuum coefficients, as a fraction of sigma (the limit
    of a flat interface): 1 − 0.112/W − 0.897/W² for W >= 3, the value at W = 3 below (not measured there).

    Measured with cylinders of radius 16, 24 and 32 cells in a periodic slab (1000:1, ν = 0.05, the jump averaged
    over the last 1500 of 4000 steps) and extrapolated in 1/R: 0.863, 0.912, 0.940, 0.956, 0.972 of sigma at
    W = 3, 4, 5, 6, 8 (the fit: 0.863, 0.916, 0.942, 0.956, 0.972). Part of it is the central-difference gradient's
    −1.0667/W² in kappa * sum(grad phi^2) (tests/fluid/test_phasefield_physics.py), the rest the lattice's
    profile; a drop at R = 24 cells and W = 4 had 0.918 of its Laplace jump."""
    a, b = SURFACE_TENSION_FIT
    w = max(float(width), 3.0)
    return 1.0 - a / w - b / (w * w)


def chemical_potential_coefficients(sigma: float, width: float) -> tuple[float, float]:
    """(beta, kappa) of the chemical potential (Eq. 22) for surface tension sigma and interface width W: the
    continuum ones (:func:`continuum_coefficients`) divided by :func:`discrete_surface_tension_factor`, so that
    a flat interface carries sigma on the lattice (with the continuum ones it carried 0.91 sigma at W = 4). Both
    scale alike: the profile's width (sqrt(8 kappa / beta)) and mu = 0 on it are the continuum's."""
    beta, kappa = continuum_coefficients(sigma, width)
    s = discrete_surface_tension_factor(width)
    return beta / s, kappa / s


def volume_controller_gamma(v0: float, volume: float, source_sum: float, eta: float) -> float:
    """Correction factor gamma(t) of the global volume controller, Eq. 52.

    gamma = clamp((V0 - V) / sum_x S_phi, [-eta, eta]); the corrected source is gamma * S_phi, so one step
    changes the volume by gamma * sum_x S_phi.  ``eta = 0`` switches the controller off (returns 1: the
    source is applied as it is).  With sum_x S_phi = 0 there is nothing to scale and gamma = 0.
    """
    if eta < 0:
        raise ValueError(f"eta must be >= 0 (0 = controller off), got {eta}")
    if eta == 0:
        return 1.0
    if source_sum == 0.0:
        return 0.0
    return float(np.clip((v0 - volume) / source_sum, -eta, eta))


def tanh_profile(s: np.ndarray, width: float) -> np.ndarray:
    """Equilibrium flat-interface profile phi = (1 + tanh(2 s / W)) / 2, s = signed distance into phase 1."""
    return 0.5 * (1.0 + np.tanh(2.0 * np.asarray(s, dtype=np.float64) / width))
