"""Grid boundary conditions of the sand solver: domain walls, analytic colliders, an SDF-grid collider.

Every condition acts on the grid velocity relative to the boundary, v_rel = v − v_obj(x_i), with n the
solid's outward normal (into the sand); notes/mpm-method.md §1.4, the surface modes of taichi_elements:

* ``"sticky"``: v_rel = 0 (no-slip);
* ``"slip"``: the normal component is removed, always;
* ``"separate"``: when v_rel·n < 0 the normal component is removed and the tangential speed is reduced
  by ``friction``·|v_rel·n| (Coulomb, clamped at 0); sand may leave the wall freely.

Domain walls occupy ``bound`` node layers at each face of the grid (2 by default: the quadratic stencil
reaches one node beyond the particle's cell).  Colliders are half-spaces, spheres, axis-aligned boxes and
y-axis capped cylinders with a linear and an angular velocity; a moving collider's centre is advanced by
the solver each step (x_c += Δt v_lin).  ``inverted=True`` makes the solid the *outside* of the shape
(a container).  A :class:`SdfCollider` takes any SDF callable ``sdf(points (N, 3), t) -> (N,)`` (negative
inside the solid); it is sampled on the nodes once, or every step when ``moving=True``.  Several solids of
different friction in one SDF collider (:meth:`SdfCollider.union`) keep their own: the friction of the solid
nearest each node (smallest SDF) is sampled next to the SDF, and the grid update reads it per node.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..faces import wall_face

__all__ = ["MODES", "Wall", "DomainWalls", "Collider", "SdfCollider", "pack_walls", "pack_colliders"]

MODES = {"sticky": 0, "slip": 1, "separate": 2}
COLLIDER_STRIDE = 16  # floats per collider in the kernel table (kernels/mpm_grid.cu)
_SHAPES = {"halfspace": 0, "sphere": 1, "box": 2, "cylinder": 3}
FACES = ("-x", "+x", "-y", "+y", "-z", "+z")


def _mode(mode: str) -> int:
    if mode not in MODES:
        raise ValueError(f"unknown boundary mode {mode!r}; choose one of {', '.join(MODES)}")
    return MODES[mode]


@dataclass(frozen=True)
class Wall:
    """One face of the domain: mode (sticky / slip / separate) and Coulomb friction (separate only)."""

    mode: str = "separate"
    friction: float = 0.0

    def __post_init__(self) -> None:
        _mode(self.mode)
        if self.friction < 0:
            raise ValueError(f"wall friction must be >= 0, got {self.friction}")


@dataclass(frozen=True)
class DomainWalls:
    """The six faces of the grid box, in the order -x, +x, -y, +y, -z, +z (z is up by convention of the
    scenes, but gravity is a free vector)."""

    faces: tuple[Wall, Wall, Wall, Wall, Wall, Wall] = (Wall(),) * 6
    bound: int = 2

    @classmethod
    def uniform(cls, mode: str = "separate", friction: float = 0.0, bound: int = 2) -> DomainWalls:
        """Every face the same."""
        return cls((Wall(mode, friction),) * 6, bound)

    @classmethod
    def from_dict(cls, spec: dict[str, Wall], default: Wall = Wall(), bound: int = 2) -> DomainWalls:
        """Faces named ``x_min``, ``x_max``, … (the scenes' naming) or ``-x``, ``+x``, … (or ``x-``, …); missing
        faces get ``default``."""
        named: dict[str, Wall] = {}
        for name, wall in spec.items():
            try:
                key = wall_face(name)
            except ValueError as exc:
                raise ValueError(f"unknown wall face: {exc}") from None
            if key in named:
                raise ValueError(f"wall face {name!r} given twice (as {key} and under another name)")
            named[key] = wall
        return cls(tuple(named.get(f, default) for f in FACES), bound)

    def __post_init__(self) -> None:
        if len(self.faces) != 6:
            raise ValueError("DomainWalls needs exactly six faces (-x, +x, -y, +y, -z, +z)")
        if self.bound < 1:
            raise ValueError(f"bound must be >= 1 node layer, got {self.bound}")


@dataclass
class Collider:
    """An analytic rigid collider.

    shape: ``"halfspace"`` (params = unit normal pointing out of the solid), ``"sphere"`` (params =
    (radius,)), ``"box"`` (params = half extents), ``"cylinder"`` (axis along y; params = (radius,
    half height)).  centre: a point of the plane / the centre, m.  velocity, angular_velocity: rigid motion
    (m/s, rad/s about the centre).  inverted: solid outside the shape (container).
    """

    shape: str
    centre: Sequence[float]
    params: Sequence[float]
    mode: str = "separate"
    friction: float = 0.0
    velocity: Sequence[float] = (0.0, 0.0, 0.0)
    angular_velocity: Sequence[float] = (0.0, 0.0, 0.0)
    inverted: bool = False

    def __post_init__(self) -> None:
        if self.shape not in _SHAPES:
            raise ValueError(f"unknown collider shape {self.shape!r}; choose one of {', '.join(_SHAPES)}")
        _mode(self.mode)
        if self.friction < 0:
            raise ValueError(f"collider friction must be >= 0, got {self.friction}")
        self.centre = np.asarray(self.centre, dtype=np.float64).reshape(3)
        p = np.zeros(3)
        given = np.asarray(self.params, dtype=np.float64).ravel()
        p[: given.size] = given
        if self.shape == "halfspace":
            norm = np.linalg.norm(p)
            if norm == 0:
                raise ValueError("a halfspace collider needs a non-zero normal in params")
            p = p / norm
        elif np.any(p[: {"sphere": 1, "box": 3, "cylinder": 2}[self.shape]] <= 0):
            raise ValueError(f"{self.shape} collider sizes must be > 0, got {given.tolist()}")
        self.params = p
        self.velocity = np.asarray(self.velocity, dtype=np.float64).reshape(3)
        self.angular_velocity = np.asarray(self.angular_velocity, dtype=np.float64).reshape(3)

    @property
    def moving(self) -> bool:
        return bool(np.any(self.velocity != 0) or np.any(self.angular_velocity != 0))

    def row(self) -> np.ndarray:
        """The kernel's 16-float record."""
        return np.concatenate(
            [
                [_SHAPES[self.shape], MODES[self.mode], self.friction, float(self.inverted)],
                self.centre,
                self.params,
                self.velocity,
                self.angular_velocity,
            ]
        ).astype(np.float32)


@dataclass
class SdfCollider:
    """A collider given by a signed-distance callable, sampled on the grid nodes.

    sdf(points, t): points (N, 3) in metres, t the simulated time; returns (N,) distances, negative inside
    the solid.  velocity: the solid's (uniform) velocity, used by the boundary condition.  moving: resample
    every step (otherwise once); ``moving_until``: the time after which the SDF no longer changes, so the
    solver resamples it until its first sample at or after that time and then stops (default: never stops).
    """

    sdf: Callable[[np.ndarray, float], np.ndarray]
    mode: str = "separate"
    friction: float = 0.0
    velocity: Sequence[float] = (0.0, 0.0, 0.0)
    moving: bool = False
    moving_until: float = float("inf")
    _params: np.ndarray = field(init=False, repr=False)
    _parts: tuple = field(default=(), init=False, repr=False)

    def __post_init__(self) -> None:
        _mode(self.mode)
        if not self.friction >= 0:
            raise ValueError(f"collider friction must be >= 0, got {self.friction}")
        self.velocity = np.asarray(self.velocity, dtype=np.float64).reshape(3)
        self._params = np.array([MODES[self.mode], self.friction, *self.velocity], dtype=np.float32)

    @classmethod
    def union(
        cls,
        sdfs: Sequence[Callable[[np.ndarray, float], np.ndarray]],
        frictions: Sequence[float],
        mode: str = "separate",
        velocity: Sequence[float] = (0.0, 0.0, 0.0),
        moving: bool = False,
        moving_until: float = float("inf"),
    ) -> SdfCollider:
        """One collider of several solids (SDF the minimum of theirs), each with its own Coulomb friction: at a
        node the friction of the solid whose SDF is smallest there (:meth:`sample`). With equal frictions it is
        the plain collider of that friction (no per-node field)."""
        sdfs, frictions = list(sdfs), [float(f) for f in frictions]
        if not sdfs or len(sdfs) != len(frictions):
            raise ValueError(f"union needs one friction per solid, got {len(sdfs)} solids, {len(frictions)} frictions")
        if any(not f >= 0 for f in frictions):
            raise ValueError(f"collider frictions must be >= 0, got {frictions}")

        def sdf(points, t):
            return np.min([np.asarray(s(points, t), dtype=np.float64) for s in sdfs], axis=0)

        friction = frictions[0] if len(set(frictions)) == 1 else max(frictions)
        collider = cls(sdf, mode, friction, velocity, moving, moving_until)
        if len(set(frictions)) > 1:
            collider._parts = tuple(zip(sdfs, frictions, strict=True))
        return collider

    def changes_after(self, t: float) -> bool:
        """Whether a sample taken at time ``t`` may be out of date later (a moving SDF not yet at rest)."""
        return self.moving and t < self.moving_until

    @property
    def per_node_friction(self) -> bool:
        """The friction differs between the solids: :meth:`sample` returns it per point."""
        return bool(self._parts)

    def sample(self, points: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray | None]:
        """(SDF (N,), friction (N,) or None) at ``points`` (N, 3): the friction of the solid with the smallest
        SDF at each point, None when one friction holds everywhere (the kernel then reads ``friction``)."""
        if not self._parts:
            return np.asarray(self.sdf(points, t), dtype=np.float64), None
        d = np.stack([np.asarray(s(points, t), dtype=np.float64) for s, _ in self._parts])
        nearest = np.argmin(d, axis=0)  # the first of equal distances, as np.min takes it
        mu = np.array([f for _, f in self._parts], dtype=np.float64)[nearest]
        return d[nearest, np.arange(d.shape[1])], mu

    def params(self) -> np.ndarray:
        """(mode, friction, vx, vy, vz) for the kernel."""
        return self._params


def pack_walls(walls: DomainWalls) -> np.ndarray:
    """(12,) float32: mode, friction per face."""
    return np.array([v for w in walls.faces for v in (MODES[w.mode], w.friction)], dtype=np.float32)


def pack_colliders(colliders: Sequence[Collider]) -> np.ndarray:
    """(max(K, 1) * 16,) float32 table (one zero row when there are none, so the pointer is valid)."""
    if not colliders:
        return np.zeros(COLLIDER_STRIDE, dtype=np.float32)
    return np.concatenate([c.row() for c in colliders]).astype(np.float32)


def node_positions(shape: tuple[int, int, int], dx: float, z0: int = 0, z1: int | None = None) -> np.ndarray:
    """(nz*ny*nx, 3) node positions (x, y, z) in linear-index order; node (i, j, k) at ((i+½)dx, …); of the z
    layers z0 .. z1 - 1 only when given (a slab)."""
    nz, ny, nx = shape
    z, y, x = np.meshgrid(np.arange(z0, nz if z1 is None else z1), np.arange(ny), np.arange(nx), indexing="ij")
    return (np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1) + 0.5) * dx
