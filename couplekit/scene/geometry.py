"""Shapes as signed distance functions (negative inside), with transforms, sampled on the grid.

Every shape has ``sdf(points)`` for points ``(N, 3)`` (metres, columns x, y, z) and ``bounds()``, the
axis-aligned box ``(lo, hi)`` that contains it. Primitives (box, sphere, cylinder) are exact SDFs
(Quílez's formulas); :class:`Transformed` applies a uniform scale, a rotation and a translation, which keep
an SDF exact (the distance scales with the uniform scale); :class:`Inverted` swaps inside and outside.
The box of a transformed shape is the shape's own :meth:`Shape.transformed_bounds` (the tight box of the
moved solid where the shape knows it: a sphere, a cylinder, a mesh's vertices; the moved corners of its box
otherwise, larger by up to √3 but never too small); nested transforms compose into one.
Height fields and triangle meshes are in :mod:`couplekit.scene.mesh`.

:func:`sdf_on_grid` samples a shape at the cell centres of a grid, returning ``(nz, ny, nx)`` float32 (the
layout of every field: x contiguous).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "Shape",
    "Box",
    "Sphere",
    "Cylinder",
    "Transformed",
    "Inverted",
    "Union",
    "Difference",
    "overlapping",
    "rotation_matrix",
    "cell_centres",
    "sdf_on_grid",
]


class Shape:
    """A solid given by its signed distance (negative inside)."""

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (N,) float64 of points (N, 3)."""
        raise NotImplementedError

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi): an axis-aligned box containing the solid."""
        raise NotImplementedError

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi): an axis-aligned box containing the solid mapped by x -> scale · rotation · x + translation
        (``rotation`` a 3×3 matrix). This fallback moves the 8 corners of :meth:`bounds`: always large enough,
        exact for a box, up to √3 times too large for a round solid; shapes that know better override it."""
        return _moved_corners(self.bounds(), scale, rotation, translation)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        return self.sdf(points)


def _points(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {p.shape}")
    return p


def _moved_corners(
    box: tuple[np.ndarray, np.ndarray], scale: float, rotation: np.ndarray, translation: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned box of the 8 corners of ``box`` mapped by x -> scale · rotation · x + translation."""
    lo, hi = box
    corners = np.array(
        [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    world = (corners * scale) @ np.asarray(rotation, dtype=np.float64).T + translation
    return world.min(axis=0), world.max(axis=0)


class Box(Shape):
    """Axis-aligned box [lo, hi]."""

    def __init__(self, lo: Sequence[float], hi: Sequence[float]):
        self.lo = np.asarray(lo, dtype=np.float64).reshape(3)
        self.hi = np.asarray(hi, dtype=np.float64).reshape(3)
        if np.any(self.hi <= self.lo):
            raise ValueError(
                f"box max must exceed min on every axis, got min={self.lo.tolist()}, max={self.hi.tolist()}"
            )

    def sdf(self, points: np.ndarray) -> np.ndarray:
        p = _points(points)
        c, h = 0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo)
        q = np.abs(p - c) - h
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        return outside + inside

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()


class Sphere(Shape):
    """Ball of ``radius`` about ``center``."""

    def __init__(self, center: Sequence[float], radius: float):
        self.center = np.asarray(center, dtype=np.float64).reshape(3)
        self.radius = float(radius)
        if not self.radius > 0:
            raise ValueError(f"sphere radius must be > 0, got {radius}")

    def sdf(self, points: np.ndarray) -> np.ndarray:
        return np.linalg.norm(_points(points) - self.center, axis=1) - self.radius

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.center - self.radius, self.center + self.radius

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        # a ball stays a ball: the moved centre ± the scaled radius, whatever the rotation
        c = scale * (np.asarray(rotation, dtype=np.float64) @ self.center) + translation
        r = scale * self.radius
        return c - r, c + r


class Cylinder(Shape):
    """Capped cylinder: ``radius``, ``height`` along ``axis`` ("x", "y" or "z"), centred at ``center``."""

    def __init__(self, center: Sequence[float], radius: float, height: float, axis: str = "z"):
        self.center = np.asarray(center, dtype=np.float64).reshape(3)
        self.radius, self.height = float(radius), float(height)
        if axis not in ("x", "y", "z"):
            raise ValueError(f"cylinder axis must be x, y or z, got {axis!r}")
        if not (self.radius > 0 and self.height > 0):
            raise ValueError("cylinder radius and height must be > 0")
        self.axis = "xyz".index(axis)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        p = _points(points) - self.center
        along = p[:, self.axis]
        radial = np.linalg.norm(np.delete(p, self.axis, axis=1), axis=1)
        d = np.stack([radial - self.radius, np.abs(along) - 0.5 * self.height], axis=1)
        return np.minimum(d.max(axis=1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        half = np.full(3, self.radius)
        half[self.axis] = 0.5 * self.height
        return self.center - half, self.center + half

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        # the hull of the two end discs: each disc (radius ρ, unit normal a) reaches ρ·sqrt(1 − a_i²) along axis
        # i from its centre, and the cylinder's extreme along any axis lies on an end disc's rim
        rot = np.asarray(rotation, dtype=np.float64)
        c = scale * (rot @ self.center) + translation
        a = rot[:, self.axis]
        a = a / np.linalg.norm(a)
        ends = np.stack([c - 0.5 * scale * self.height * a, c + 0.5 * scale * self.height * a])
        reach = scale * self.radius * np.sqrt(np.maximum(1.0 - a * a, 0.0))
        return ends.min(axis=0) - reach, ends.max(axis=0) + reach


def rotation_matrix(degrees_xyz: Sequence[float]) -> np.ndarray:
    """R = Rz · Ry · Rx: rotate about x, then y, then z (angles in degrees, right-handed)."""
    ax, ay, az = (math.radians(float(a)) for a in degrees_xyz)
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


class Transformed(Shape):
    """``shape`` scaled by ``scale`` (uniform), then rotated (degrees about x, y, z), then translated.

    World point p maps to the shape's frame as q = Rᵀ (p − t) / s, and sdf(p) = s · shape.sdf(q): exact,
    since a uniform scale multiplies every distance by s and rigid motions keep distances.
    """

    def __init__(
        self,
        shape: Shape,
        scale: float = 1.0,
        rotate: Sequence[float] = (0.0, 0.0, 0.0),
        translate: Sequence[float] = (0.0, 0.0, 0.0),
    ):
        if not scale > 0:
            raise ValueError(f"scale must be > 0, got {scale}")
        self.shape, self.scale = shape, float(scale)
        self.rotation = rotation_matrix(rotate)
        self.translation = np.asarray(translate, dtype=np.float64).reshape(3)

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) in the shape's own frame."""
        return ((_points(points) - self.translation) @ self.rotation) / self.scale

    def sdf(self, points: np.ndarray) -> np.ndarray:
        return self.scale * self.shape.sdf(self.to_local(points))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        # the shape's own box of its moved solid (tight for spheres, cylinders and meshes), not the box of its
        # rotated box (up to √3 times larger: rotated bodies that fit the domain were refused)
        return self.shape.transformed_bounds(self.scale, self.rotation, self.translation)

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        # x -> s·R·(s₀·R₀·x + t₀) + t = (s·s₀)·(R·R₀)·x + (s·R·t₀ + t): one transform of the inner shape
        rot = np.asarray(rotation, dtype=np.float64)
        return self.shape.transformed_bounds(
            scale * self.scale, rot @ self.rotation, scale * (rot @ self.translation) + translation
        )


class Inverted(Shape):
    """The complement of ``shape`` (e.g. a container whose walls are everything outside a box)."""

    def __init__(self, shape: Shape, domain_lo: Sequence[float], domain_hi: Sequence[float]):
        self.shape = shape
        self.domain = (np.asarray(domain_lo, float), np.asarray(domain_hi, float))

    def sdf(self, points: np.ndarray) -> np.ndarray:
        return -self.shape.sdf(points)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.domain[0].copy(), self.domain[1].copy()


class Union(Shape):
    """The union of shapes: the minimum of their SDFs (exact outside, a lower bound on |d| inside)."""

    def __init__(self, shapes: Sequence[Shape]):
        if not shapes:
            raise ValueError("a union needs at least one shape")
        self.shapes = list(shapes)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        return np.min([s.sdf(points) for s in self.shapes], axis=0)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        b = [s.bounds() for s in self.shapes]
        return np.min([x[0] for x in b], axis=0), np.max([x[1] for x in b], axis=0)

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        b = [s.transformed_bounds(scale, rotation, translation) for s in self.shapes]
        return np.min([x[0] for x in b], axis=0), np.max([x[1] for x in b], axis=0)


class Difference(Shape):
    """``shape`` less the ``cutters`` (e.g. a sand body less the obstacles it overlaps): inside where ``shape`` is
    and no cutter is. The sign is exact; the distance is max(d_shape, −d_cutters) (a bound) where d_shape <
    ``near`` and ``shape``'s beyond. The cutters are evaluated only there: ``near`` = 0 (inside ``shape``) is what
    seeding needs; a water body's diffuse initial φ takes a band of its interface's width outside too, or the
    base shape's surface over a cut-away part would keep its tanh tail there (couplekit.assembly._cut)."""

    def __init__(self, shape: Shape, cutters: Sequence[Shape], near: float = 0.0):
        self.shape, self.cutters, self.near = shape, list(cutters), float(near)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        p = _points(points)
        d = np.array(self.shape.sdf(p), dtype=np.float64)
        inside = d < self.near
        if self.cutters and inside.any():
            q = p[inside]
            cut = np.min([c.sdf(q) for c in self.cutters], axis=0)
            d[inside] = np.maximum(d[inside], -cut)
        return d

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.shape.bounds()

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return self.shape.transformed_bounds(scale, rotation, translation)


def overlapping(shape: Shape, others: Sequence[Shape]) -> list[Shape]:
    """The shapes of ``others`` whose bounding boxes meet ``shape``'s (e.g. the obstacles a sand body may
    overlap: the only ones :class:`Difference` needs)."""
    lo, hi = shape.bounds()
    out = []
    for o in others:
        olo, ohi = o.bounds()
        if np.all(olo <= hi) and np.all(ohi >= lo):
            out.append(o)
    return out


def cell_centres(resolution: Sequence[int], dx: float) -> np.ndarray:
    """Cell-centre points (nz*ny*nx, 3) in linear-index order (x fastest); cell (i, j, k) at ((i+½)dx, …)."""
    nx, ny, nz = (int(n) for n in resolution)
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    return (np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1) + 0.5) * float(dx)


def sdf_on_grid(shape: Shape, resolution: Sequence[int], dx: float, chunk: int = 1 << 20) -> np.ndarray:
    """``shape``'s SDF at the cell centres of a grid of ``resolution`` (nx, ny, nz): (nz, ny, nx) float32."""
    nx, ny, nz = (int(n) for n in resolution)
    pts = cell_centres(resolution, dx)
    out = np.empty(pts.shape[0], dtype=np.float32)
    for s in range(0, pts.shape[0], chunk):
        out[s : s + chunk] = shape.sdf(pts[s : s + chunk])
    return out.reshape(nz, ny, nx)
