"""Inflow regions in metres: a rectangle or a disc on a domain face, rasterised to an :class:`InflowRegion` mask.

A jet issuing from an outlet in a wall (paper 000 Fig. 1's rectangular outlet) is a velocity inlet over part
of a face: :func:`region_mask` marks the face's ghost cells whose centres lie inside the outlet, and the rest
of the face keeps its own kind (:class:`~couplekit.fluid.grid.InflowRegion`).

Coordinates on a face are its two in-plane axes in x, y, z order (:data:`PLANE_AXES`): ``(y, z)`` on an x face,
``(x, z)`` on a y face, ``(x, y)`` on a z face, measured from the domain's origin corner, like every position
of a scene (the domain is ``[0, size_x] × [0, size_y] × [0, size_z]``; cell ``i`` spans ``[i dx, (i + 1) dx]``).

Rasterisation: a rectangle takes the cells whose centre ``u`` satisfies ``lo <= u < hi`` on both axes
(half-open, so a rectangle whose sides are whole multiples of dx covers exactly ``size / dx`` cells per axis,
wherever its edges fall); a disc takes the cells whose centre lies strictly inside the circle. The discrete
area (cells × dx²) is what the flux ``u_n × area`` uses; :func:`region_area` gives both.
"""

from __future__ import annotations

import math

import numpy as np

from .grid import face_plane_shape

__all__ = ["PLANE_AXES", "SHAPES", "face_extent", "region_bounds", "region_mask", "region_area"]

PLANE_AXES = {"x": (1, 2), "y": (0, 2), "z": (0, 1)}
"""In-plane axes (0 = x, 1 = y, 2 = z) of a face, by the face's normal axis, in x, y, z order."""

SHAPES = ("rect", "disc")
"""Outlet shapes."""


def face_extent(size: tuple[float, float, float], face: str) -> tuple[float, float]:
    """In-plane extent (m) of ``face`` (``x-``/``x+``/… ) of a domain of ``size`` (x, y, z)."""
    a, b = PLANE_AXES[face[0]]
    return float(size[a]), float(size[b])


def region_bounds(
    shape: str, center: tuple[float, float], size: tuple[float, float] | None = None, radius: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box ``(lo, hi)`` (2,) of an outlet in face coordinates (m)."""
    c = np.asarray(center, np.float64)
    if shape == "rect":
        half = 0.5 * np.asarray(size, np.float64)
    elif shape == "disc":
        half = np.full(2, float(radius))
    else:
        raise ValueError(f"outlet shape must be one of {SHAPES}, got {shape!r}")
    return c - half, c + half


def region_mask(
    grid: tuple[int, int, int],
    dx: float,
    face: str,
    shape: str,
    center: tuple[float, float],
    size: tuple[float, float] | None = None,
    radius: float | None = None,
) -> np.ndarray:
    """Boolean mask of shape :func:`~couplekit.fluid.grid.face_plane_shape` ``(grid, face)`` of the face ghosts
    inside the outlet.

    ``grid``: interior shape ``(nz, ny, nx)``; ``dx``: cell size (m); ``face``: ``x-, x+, y-, y+, z-, z+``;
    ``shape``: ``"rect"`` (``size`` = its two side lengths) or ``"disc"`` (``radius``); ``center``: (m) in
    face coordinates (module docstring). May be empty (the caller decides whether that is an error).
    """
    rows, cols = face_plane_shape(grid, face)  # array order: rows = second in-plane axis, cols = first
    u = (np.arange(cols) + 0.5) * dx  # first in-plane axis (x on a z face)
    v = (np.arange(rows) + 0.5) * dx
    uu, vv = np.meshgrid(u, v, indexing="xy")  # (rows, cols)
    cu, cv = float(center[0]), float(center[1])
    if shape == "rect":
        lo, hi = region_bounds(shape, center, size)
        eps = 1e-9 * dx  # a side on a cell centre: the half-open rule decides, not the round-off
        return (uu >= lo[0] - eps) & (uu < hi[0] - eps) & (vv >= lo[1] - eps) & (vv < hi[1] - eps)
    if shape == "disc":
        return (uu - cu) ** 2 + (vv - cv) ** 2 < float(radius) ** 2
    raise ValueError(f"outlet shape must be one of {SHAPES}, got {shape!r}")


def region_area(
    shape: str, mask: np.ndarray, dx: float, size: tuple[float, float] | None = None, radius: float | None = None
) -> tuple[float, float]:
    """``(discrete, geometric)`` outlet area (m²): cells × dx², and the rectangle's or disc's own area."""
    geometric = float(np.prod(size)) if shape == "rect" else math.pi * float(radius) ** 2
    return float(np.count_nonzero(mask)) * dx * dx, geometric
