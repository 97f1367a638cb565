"""Physical measurements of a simulation's state, in SI units: where the sand is, how far it has run out, where
the water surface is, how much kinetic energy the fluid and the sand hold.

:meth:`couplekit.simulation.Simulation.diagnostics` reports them every frame (``diagnostics.jsonl``), and the
coupling-scheme sweeps (:mod:`couplekit.sweep`) compare runs by them. "Up" is against gravity (z when there is
none); heights are measured from the domain face gravity points to.
"""

from __future__ import annotations

import numpy as np

__all__ = ["up_axis", "sand_metrics", "free_surface_height", "kinetic_energy"]


def up_axis(gravity) -> tuple[int, float]:
    """(axis 0/1/2 = x/y/z, sign) of "up": against the largest gravity component (z, +1 without gravity)."""
    g = np.asarray(gravity, np.float64)
    if not np.any(g):
        return 2, 1.0
    a = int(np.argmax(np.abs(g)))
    return a, -float(np.sign(g[a]))


def sand_metrics(x: np.ndarray, origin: np.ndarray | None, gravity, size) -> dict[str, float]:
    """Sand positions ``x`` (3, P) in m → ``sand_centroid_x/y/z`` (mean position), ``sand_front`` (the 99th
    percentile of the particles' horizontal distance from the vertical line through ``origin``, the initial
    centroid: the runout, robust to a few stray particles) and ``sand_top`` (99th percentile of the height above
    the floor). Empty sand gives NaN."""
    names = ("sand_centroid_x", "sand_centroid_y", "sand_centroid_z", "sand_front", "sand_top")
    if x.shape[1] == 0:
        return {k: float("nan") for k in names}
    x = np.asarray(x, np.float64)
    c = x.mean(axis=1)
    a, sign = up_axis(gravity)
    o = c if origin is None or not np.all(np.isfinite(origin)) else np.asarray(origin, np.float64)
    horizontal = [d for d in range(3) if d != a]
    r = np.sqrt(sum((x[d] - o[d]) ** 2 for d in horizontal))
    height = x[a] if sign > 0 else float(size[a]) - x[a]
    return dict(
        zip(
            names,
            (*(float(v) for v in c), float(np.percentile(r, 99.0)), float(np.percentile(height, 99.0))),
            strict=True,
        )
    )


def free_surface_height(phi: np.ndarray, dx: float, gravity, solid: np.ndarray | None = None) -> float:
    """Mean height (m, above the floor) of the water surface: per column along "up", the topmost crossing of
    φ = ½ (linear between cell centres), averaged over the columns that hold water; NaN when none does.
    ``phi`` (nz, ny, nx); solid cells count as dry."""
    a, sign = up_axis(gravity)
    wet = np.asarray(phi, np.float64) >= 0.5
    if solid is not None:
        wet &= ~np.asarray(solid, bool)
    ph = np.moveaxis(np.asarray(phi, np.float64), 2 - a, 0)  # (n_up, ...) array axes are (z, y, x)
    wet = np.moveaxis(wet, 2 - a, 0)
    if sign < 0:
        ph, wet = ph[::-1], wet[::-1]
    n = ph.shape[0]
    has = wet.any(axis=0)
    if not has.any():
        return float("nan")
    top = n - 1 - np.argmax(wet[::-1], axis=0)  # index of the topmost wet cell per column
    idx = np.clip(top, 0, n - 1)
    below = np.take_along_axis(ph, idx[None], axis=0)[0]
    above = np.take_along_axis(ph, np.clip(idx + 1, 0, n - 1)[None], axis=0)[0]
    frac = np.where((idx + 1 < n) & (below > above), (below - 0.5) / np.where(below > above, below - above, 1.0), 0.5)
    height = (idx + 0.5 + np.clip(frac, 0.0, 1.0)) * dx
    return float(height[has].mean())


def kinetic_energy(velocity: np.ndarray, density: np.ndarray, dx: float, weight: np.ndarray | None = None) -> float:
    """½ Σ w ρ |u|² dx³ (J): ``velocity`` (3, nz, ny, nx) in m/s, ``density`` kg/m³, ``weight`` the fluid
    fraction ε of a mixture (None: 1)."""
    u2 = (np.asarray(velocity, np.float64) ** 2).sum(axis=0)
    w = np.asarray(density, np.float64) if weight is None else np.asarray(density, np.float64) * weight
    return float(0.5 * (w * u2).sum() * dx**3)
