"""Domain faces and regions on them, shared by the fluid's inflows, the sand's emission and scene validation.

A neutral module (no solver imports it from another solver): the fluid's velocity inlets
(:mod:`couplekit.fluid.inflow`, :mod:`couplekit.fluid.grid`), the sand emitted at those inlets
(:mod:`couplekit.sand.emission`) and the checks of a scene (:mod:`couplekit.scene.model`) all describe faces and
outlets the same way, here.

Face names: one public naming, the scenes' ``x_min, x_max, y_min, y_max, z_min, z_max`` (:data:`SCENE_FACES`).
Every API that takes a face accepts it: scene files, :class:`couplekit.fluid.grid.Boundaries` and
:class:`~couplekit.fluid.grid.InflowRegion`, :meth:`couplekit.sand.boundaries.DomainWalls.from_dict`, and every
function here; :meth:`~couplekit.fluid.grid.Boundaries.scene_faces` returns faces by that name. The solvers'
internal spellings stay accepted as aliases (renaming them would touch the fluid grid's ghost layout, the sand
emission and their tests): ``x-, x+, …`` (:data:`FACE_NAMES`, what the fluid grid stores; :func:`solver_face`
converts to it) and the sand walls' ``-x, +x, …`` (:func:`wall_face`); :func:`scene_face` converts any of the
three to the public name.

Coordinates on a face are its two in-plane axes in x, y, z order (:data:`PLANE_AXES`): ``(y, z)`` on an x face,
``(x, z)`` on a y face, ``(x, y)`` on a z face, measured from the domain's origin corner, like every position
of a scene (the domain is ``[0, size_x] × [0, size_y] × [0, size_z]``; cell ``i`` spans ``[i dx, (i + 1) dx]``).

The plane of a face, in array order, has the shape :func:`face_plane_shape`: ``(ny, nx)`` for a z face,
``(nz, nx)`` for a y face, ``(nz, ny)`` for an x face (rows = the second in-plane axis, columns = the first).

Rasterisation of an outlet (:func:`region_mask`): a rectangle takes the cells whose centre ``u`` satisfies
``lo <= u < hi`` on both axes (half-open, so a rectangle whose sides are whole multiples of dx covers exactly
``size / dx`` cells per axis, wherever its edges fall); a disc takes the cells whose centre lies strictly inside
the circle. The discrete area (cells × dx²) is what a flux ``u_n × area`` uses; :func:`region_area` gives both.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "FACE_NAMES",
    "SCENE_FACES",
    "PLANE_AXES",
    "SHAPES",
    "scene_face",
    "solver_face",
    "wall_face",
    "face_plane_shape",
    "face_extent",
    "region_bounds",
    "region_mask",
    "region_area",
]

FACE_NAMES = ("x-", "x+", "y-", "y+", "z-", "z+")
"""Face names of the solvers."""

SCENE_FACES = ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")
"""Face names of scene files, in the order of :data:`FACE_NAMES`."""

_SOLVER_FACE = dict(zip(SCENE_FACES, FACE_NAMES, strict=True))

PLANE_AXES = {"x": (1, 2), "y": (0, 2), "z": (0, 1)}
"""In-plane axes (0 = x, 1 = y, 2 = z) of a face, by the face's normal axis, in x, y, z order."""

SHAPES = ("rect", "disc")
"""Outlet shapes."""


_WALL_FACE = {f[1] + f[0]: f for f in FACE_NAMES}  # the sand walls' "-x" -> "x-"
_SCENE_FACE = dict(zip(FACE_NAMES, SCENE_FACES, strict=True))


def solver_face(name: str) -> str:
    """The fluid grid's name (``x-`` …) of a face given in any naming (``x_min``, ``x-`` or ``-x``)."""
    if name in _SOLVER_FACE:
        return _SOLVER_FACE[name]
    if name in FACE_NAMES:
        return name
    if name in _WALL_FACE:
        return _WALL_FACE[name]
    raise ValueError(
        f"unknown face {name!r}; faces are {', '.join(SCENE_FACES)} (the aliases {', '.join(FACE_NAMES)} and "
        f"{', '.join(_WALL_FACE)} are accepted too)"
    )


def scene_face(name: str) -> str:
    """The public name (``x_min`` …) of a face given in any naming (``x_min``, ``x-`` or ``-x``)."""
    return _SCENE_FACE[solver_face(name)]


def wall_face(name: str) -> str:
    """The sand walls' name (``-x`` …, :class:`couplekit.sand.boundaries.DomainWalls`) of a face given in any
    naming (``x_min``, ``x-`` or ``-x``)."""
    face = solver_face(name)
    return face[1] + face[0]


def face_plane_shape(shape: tuple[int, int, int], face: str) -> tuple[int, int]:
    """Shape of the plane of ``face`` (interior cells only) in array order: ``(ny, nx)`` for ``z±``,
    ``(nz, nx)`` for ``y±``, ``(nz, ny)`` for ``x±`` (the shape of an outlet mask)."""
    nz, ny, nx = (int(s) for s in shape)
    return {"x": (nz, ny), "y": (nz, nx), "z": (ny, nx)}[face[0]]


def face_extent(size: tuple[float, float, float], face: str) -> tuple[float, float]:
    """In-plane extent (m) of ``face`` (``x-``/``x+``/… or ``x_min``/…) of a domain of ``size`` (x, y, z)."""
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
    """Boolean mask of shape :func:`face_plane_shape` ``(grid, face)`` of the face's cells inside the outlet.

    ``grid``: interior shape ``(nz, ny, nx)``; ``dx``: cell size (m); ``face``: either naming;
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
