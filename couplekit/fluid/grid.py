"""The padded LBM grid: cell flags, wall velocities and the periodic ghost lists.

Every fluid field is stored with one ghost layer on each side: an interior grid ``(nz, ny, nx)`` is held in
arrays of spatial shape ``(nz + 2, ny + 2, nx + 2)`` (linear index ``x + Px*(y + Py*z)``, x contiguous), so
that the neighbour ``x + c_j`` of every interior cell is a constant offset and needs no wrap. Interior cell
``(z, y, x)`` (0-based) lives at padded index ``(z + 1, y + 1, x + 1)``.

Cell flags (``uint8``, one per padded cell):

* ``FLUID`` (0): a cell that is updated (interior), or a periodic ghost whose image is fluid;
* ``WALL`` (1): half-way bounce-back; the wall velocity is read from the velocity field at that cell
  (zero for a stationary wall, the face velocity for a moving wall);
* ``INFLOW`` (2): velocity inlet, handled for the flow exactly as a moving wall with the inflow velocity
  (Ladd's momentum-corrected bounce-back); the phase value it carries lives in ``phi`` at that cell;
* ``OUTFLOW`` (3): zero-gradient outflow ghost: before an odd AA step it is filled with the populations of
  its nearest interior cell, after it the populations it would have pushed are copied likewise
  (:func:`outflow_lists`); waves leave with a weak reflection.

Faces are described by :class:`Face` objects; a ghost cell beyond several faces (an edge or corner ghost)
takes the strongest non-periodic kind among them (wall > inflow > outflow); a ghost whose every outside axis
is periodic is a *periodic ghost*: it copies its interior image before a stage that reads it
(:func:`periodic_lists`).

An inflow on *part* of a face (a jet from an outlet in a wall) is an :class:`InflowRegion`: a boolean mask over
the face's ghost cells (one per interior cell of the face, :func:`face_plane_shape`), with a velocity and a
phase value per cell; those ghosts become INFLOW, the rest of the face keeps the face's own kind. Edge and
corner ghosts are never part of a region.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..faces import SCENE_FACES, face_plane_shape, solver_face

FLUID, WALL, INFLOW, OUTFLOW = 0, 1, 2, 3
_KINDS = {"periodic": None, "wall": WALL, "inflow": INFLOW, "outflow": OUTFLOW}
_PRIORITY = {WALL: 3, INFLOW: 2, OUTFLOW: 1}


@dataclass(frozen=True)
class Face:
    """Boundary condition of one domain face.

    ``kind``: ``"periodic"`` (both faces of an axis must be), ``"wall"`` (no-slip, half-way bounce-back; a
    non-zero ``velocity`` makes it a moving wall), ``"inflow"`` (velocity inlet carrying phase value
    ``phi``), ``"outflow"`` (zero-gradient, non-reflecting-ish). ``velocity`` is in lattice units (x, y, z).
    """

    kind: str = "periodic"
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    phi: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise ValueError(f"face kind {self.kind!r} is not one of {', '.join(_KINDS)}")
        if len(self.velocity) != 3:
            raise ValueError(f"face velocity must have 3 components, got {self.velocity!r}")


@dataclass(frozen=True, eq=False)
class InflowRegion:
    """A velocity inlet on part of one face: the face ghosts where ``mask`` is True become INFLOW.

    ``face``: ``x_min, x_max, …`` (or the alias ``x-, x+, …``, which ``face`` holds after construction; must
    not be periodic); ``mask``: boolean array of the face's plane
    shape (:func:`face_plane_shape`: ``(ny, nx)`` for a z face, ``(nz, nx)`` for a y face, ``(nz, ny)`` for an
    x face; index ``[i, j]`` is the ghost facing interior cell ``i, j`` of those axes); ``velocity``: lattice
    units (x, y, z), either 3 numbers or a per-cell array ``(3, *mask.shape)``; ``phi``: the phase value it
    carries (1 water, 0 air), a number or a per-cell array of the mask's shape. Cells outside the mask keep
    the face's own kind (:class:`Face`), e.g. a wall around a jet's outlet.
    """

    face: str
    mask: np.ndarray
    velocity: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0)
    phi: float | np.ndarray = 1.0

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "face", solver_face(self.face))  # any naming; stored as x- … (the grid's)
        except ValueError as exc:
            raise ValueError(f"inflow region on an unknown face: {exc}") from None
        mask = np.asarray(self.mask)
        if mask.ndim != 2 or mask.dtype != bool:
            raise ValueError(f"inflow region mask must be a 2-D boolean array, got {mask.dtype} {mask.shape}")
        if not mask.any():
            raise ValueError(f"inflow region on face {self.face} covers no cell (empty mask)")
        vel = np.asarray(self.velocity, np.float64)
        if vel.shape != (3,) and vel.shape != (3,) + mask.shape:
            raise ValueError(f"inflow region velocity must have shape (3,) or {(3,) + mask.shape}, got {vel.shape}")
        phi = np.asarray(self.phi, np.float64)
        if phi.shape not in ((), mask.shape):
            raise ValueError(f"inflow region phi must be a number or an array of shape {mask.shape}, got {phi.shape}")

    def cell_velocity(self) -> np.ndarray:
        """The velocity ``(3, *mask.shape)`` of every cell of the plane (float64)."""
        vel = np.asarray(self.velocity, np.float64)
        if vel.shape == (3,):
            vel = vel[:, None, None]
        return np.broadcast_to(vel, (3,) + np.asarray(self.mask).shape)

    def cell_phi(self) -> np.ndarray:
        """The carried phase value of every cell of the plane (float64)."""
        return np.broadcast_to(np.asarray(self.phi, np.float64), np.asarray(self.mask).shape)


@dataclass(frozen=True)
class Boundaries:
    """The six faces of the box, by name ``x_min, x_max, y_min, y_max, z_min, z_max`` (the scenes' naming; the
    aliases ``x-, x+, …`` are accepted and are what ``faces`` holds after construction), and inflow regions on
    parts of non-periodic faces (:class:`InflowRegion`; they must not overlap).

    Default: every face not given is **periodic** (``Boundaries()`` is a fully periodic box), unlike a scene,
    whose faces default to ``"wall"`` (``domain.boundary``): :meth:`scene_defaults` gives the scene's box.
    """

    faces: dict[str, Face] = field(default_factory=dict)
    regions: tuple[InflowRegion, ...] = ()

    def face(self, name: str) -> Face:
        """The face called ``name`` (``x_min`` … or ``x-`` …; periodic unless set)."""
        return self.faces.get(solver_face(name), Face())

    @property
    def periodic_axes(self) -> tuple[bool, bool, bool]:
        """Whether the x, y and z axes are periodic (both faces of an axis are, or neither)."""
        return tuple(self.face(a + "-").kind == "periodic" for a in "xyz")  # type: ignore[return-value]

    def scene_faces(self) -> dict[str, Face]:
        """All six faces by their public names ``x_min, x_max, …`` (periodic where not set)."""
        return {name: self.face(name) for name in SCENE_FACES}

    @classmethod
    def scene_defaults(cls) -> Boundaries:
        """The box a scene gets when ``domain.boundary`` sets nothing: a stationary no-slip wall on every face."""
        return cls({name: Face("wall") for name in SCENE_FACES})

    def __post_init__(self) -> None:
        named: dict[str, Face] = {}
        for name, face in self.faces.items():
            key = solver_face(name)  # ValueError naming the faces for an unknown one
            if key in named:
                raise ValueError(f"face {name!r} given twice (as {key} and under another name)")
            named[key] = face
        object.__setattr__(self, "faces", named)
        for axis in "xyz":
            lo, hi = self.face(axis + "-").kind, self.face(axis + "+").kind
            if (lo == "periodic") != (hi == "periodic"):
                raise ValueError(f"axis {axis}: periodic must be set on both faces ({axis}- is {lo}, {axis}+ is {hi})")
        for r in self.regions:
            if self.face(r.face).kind == "periodic":
                raise ValueError(f"inflow region on face {r.face}, which is periodic: make the face a wall or outflow")

    @classmethod
    def channel(cls, walls: str = "y", moving: dict[str, tuple[float, float, float]] | None = None) -> Boundaries:
        """Walls on the faces of the axes in ``walls`` (e.g. ``"y"`` or ``"xyz"``), periodic elsewhere; ``moving``:
        wall velocities (lattice units) by face name (``y_max`` or ``y+``)."""
        moving = {solver_face(k): v for k, v in (moving or {}).items()}
        faces = {}
        for axis in walls:
            for side in "-+":
                name = axis + side
                faces[name] = Face("wall", moving.get(name, (0.0, 0.0, 0.0)))
        return cls(faces)


def padded_shape(shape: tuple[int, int, int]) -> tuple[int, int, int]:
    """Spatial shape of a field of interior ``shape = (nz, ny, nx)`` with its ghost layer."""
    return tuple(int(s) + 2 for s in shape)


INTERIOR = (slice(1, -1), slice(1, -1), slice(1, -1))
"""Index of the interior cells inside a padded spatial array."""


def face_plane_index(shape: tuple[int, int, int], face: str) -> tuple[slice | int, ...]:
    """Index of the ghost plane of ``face`` without its edges in a padded spatial array (a basic index, so
    ``a[face_plane_index(...)]`` is a view of shape :func:`face_plane_shape`)."""
    nz, ny, nx = (int(s) for s in shape)
    axis = "zyx".index(face[0])
    ghost = 0 if face[1] == "-" else (nz, ny, nx)[axis] + 1
    index: list[slice | int] = [slice(1, -1)] * 3
    index[axis] = ghost
    return tuple(index)


def build_flags(
    shape: tuple[int, int, int], boundaries: Boundaries, solid: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flags ``(Pz, Py, Px) uint8``, wall velocities ``(3, Pz, Py, Px) float32`` and ghost phase values.

    ``solid``: optional interior boolean mask ``(nz, ny, nx)`` of stationary obstacle cells. Returns
    ``(flags, wall_velocity, wall_phi)``; ``wall_phi`` holds the inflow phase value at inflow cells (else 0).
    """
    nz, ny, nx = shape
    pz, py, px = padded_shape(shape)
    flags = np.zeros((pz, py, px), np.uint8)
    wall_u = np.zeros((3, pz, py, px), np.float32)
    wall_phi = np.zeros((pz, py, px), np.float32)
    if solid is not None:
        solid = np.asarray(solid, bool)
        if solid.shape != tuple(shape):
            raise ValueError(f"solid mask has shape {solid.shape}, the grid is {tuple(shape)}")
        flags[INTERIOR][solid] = WALL
    sizes = {"x": nx, "y": ny, "z": nz}
    zz, yy, xx = np.meshgrid(np.arange(pz), np.arange(py), np.arange(px), indexing="ij")
    coords = {"x": xx, "y": yy, "z": zz}
    best = np.zeros((pz, py, px), np.int8)  # priority of the chosen non-periodic face, 0 = none
    outside_any = np.zeros((pz, py, px), bool)
    for axis in "xyz":
        c, n = coords[axis], sizes[axis]
        for side, mask in (("-", c == 0), ("+", c == n + 1)):
            outside_any |= mask
            face = boundaries.face(axis + side)
            kind = _KINDS[face.kind]
            if kind is None:
                continue
            take = mask & (_PRIORITY[kind] > best)
            best[take] = _PRIORITY[kind]
            flags[take] = kind
            for d in range(3):
                wall_u[d][take] = face.velocity[d]
            wall_phi[take] = face.phi if kind == INFLOW else 0.0
    _apply_regions(shape, boundaries.regions, flags, wall_u, wall_phi)
    # periodic ghosts: flag of their image
    periodic_ghost = outside_any & (best == 0)
    src = _wrap_index(shape, zz[periodic_ghost], yy[periodic_ghost], xx[periodic_ghost])
    flags[periodic_ghost] = flags.reshape(-1)[src]
    return flags, wall_u, wall_phi


def _apply_regions(
    shape: tuple[int, int, int],
    regions: tuple[InflowRegion, ...],
    flags: np.ndarray,
    wall_u: np.ndarray,
    wall_phi: np.ndarray,
) -> None:
    """Mark the ghost cells of every inflow region INFLOW with its per-cell velocity and phase value."""
    taken: dict[str, np.ndarray] = {}
    for r in regions:
        plane = face_plane_shape(shape, r.face)
        mask = np.asarray(r.mask, bool)
        if mask.shape != plane:
            raise ValueError(f"inflow region mask on face {r.face} has shape {mask.shape}, the face has {plane}")
        used = taken.setdefault(r.face, np.zeros(plane, bool))
        if (used & mask).any():
            raise ValueError(f"inflow regions overlap on face {r.face} ({int((used & mask).sum())} cells)")
        used |= mask
        index = face_plane_index(shape, r.face)
        flags[index][mask] = INFLOW
        vel = r.cell_velocity()
        for d in range(3):
            wall_u[(d, *index)][mask] = vel[d][mask]
        wall_phi[index][mask] = r.cell_phi()[mask]


def _wrap_index(shape: tuple[int, int, int], z: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    nz, ny, nx = shape
    pz, py, px = padded_shape(shape)
    wz = (z - 1) % nz + 1
    wy = (y - 1) % ny + 1
    wx = (x - 1) % nx + 1
    return (wx + px * (wy + py * wz)).astype(np.int64)


def periodic_lists(shape: tuple[int, int, int], boundaries: Boundaries) -> tuple[np.ndarray, np.ndarray]:
    """``(ghost, image)``: padded linear indices (int64) of every periodic ghost cell and of its interior image."""
    nz, ny, nx = shape
    pz, py, px = padded_shape(shape)
    zz, yy, xx = np.meshgrid(np.arange(pz), np.arange(py), np.arange(px), indexing="ij")
    outside = np.zeros((pz, py, px), bool)
    nonperiodic = np.zeros((pz, py, px), bool)
    for axis, c, n in (("x", xx, nx), ("y", yy, ny), ("z", zz, nz)):
        for side, mask in (("-", c == 0), ("+", c == n + 1)):
            outside |= mask
            if boundaries.face(axis + side).kind != "periodic":
                nonperiodic |= mask
    ghost = outside & ~nonperiodic
    idx = (xx + px * (yy + py * zz))[ghost].astype(np.int64)
    return idx, _wrap_index(shape, zz[ghost], yy[ghost], xx[ghost])


def periodic_link_boxes(shape: tuple[int, int, int], boundaries: Boundaries) -> np.ndarray:
    """The periodic ghosts' populations that the odd (pull / push) step exchanges with the interior, as boxes:
    int32 rows ``(x0, x1, y0, y1, z0, z1, ox, oy, oz, q)``, every padded cell (x, y, z) of the inclusive box a
    periodic ghost g of :func:`periodic_lists` whose direction q has g − c_q interior, its image g + (ox, oy, oz).

    Exactly the (ghost, q) pairs of the fold (:meth:`couplekit.fluid.reference.ReferenceOps.fold`) and of the
    pull's reads (:meth:`~couplekit.fluid.reference.ReferenceOps.halo_pull`): a face ghost's 9 directions that
    point out of the interior (its other 18 are read by no stage), an edge's 3, a corner's 1.  As boxes, the
    kernel copies whole rows of x for the ghosts of the y and z faces (kernels/lbm_halo.cu, lbm_halo_boxes),
    where the list loop touched all 27 populations of each ghost one cell at a time."""
    from ..lattice import C27

    ext = (shape[2], shape[1], shape[0])  # (nx, ny, nz)
    rows = []
    # per axis: the ghost at 0, the interior, the ghost at n + 1
    for pos in np.ndindex(3, 3, 3):
        if pos == (1, 1, 1):
            continue
        if any(
            p != 1 and boundaries.face("xyz"[a] + ("-" if p == 0 else "+")).kind != "periodic"
            for a, p in enumerate(pos)
        ):
            continue
        for q in range(1, 27):
            box, off = [], []
            for a, p in enumerate(pos):
                n, c = ext[a], int(C27[q, a])
                if p == 0:  # ghost at 0: g − c interior only for c = −1; image at n
                    lo = hi = 0 if c == -1 else None
                    off.append(n)
                elif p == 2:  # ghost at n + 1: c = +1; image at 1
                    lo = hi = n + 1 if c == 1 else None
                    off.append(-n)
                else:  # interior: x − c within 1..n
                    lo, hi = max(1, 1 + c), min(n, n + c)
                    off.append(0)
                if lo is None or lo > hi:
                    break
                box += [lo, hi]
            else:
                rows.append(box + off + [q])
    return np.asarray(rows, np.int32).reshape(-1, 10)


@dataclass(frozen=True)
class LinkBoxes:
    """The kernels' form of :func:`periodic_link_boxes` (:func:`link_box_arrays`): ``rows`` flattened (int32),
    ``start`` the prefix sums of the boxes' cell counts (int64, one more than the boxes), ``total`` the cell
    count; the arrays host or backend ones (:meth:`on`).  Immutable: :meth:`copy` returns it."""

    rows: Any
    start: Any
    total: int

    def on(self, backend) -> LinkBoxes:
        """The same boxes with their arrays on ``backend``."""
        return LinkBoxes(backend.asarray(self.rows), backend.asarray(self.start), self.total)

    def copy(self) -> LinkBoxes:
        return self


def link_box_arrays(boxes: np.ndarray) -> LinkBoxes:
    """:class:`LinkBoxes` of the rows of :func:`periodic_link_boxes`."""
    counts = np.prod(boxes[:, 1:6:2].astype(np.int64) - boxes[:, 0:6:2] + 1, axis=1)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return LinkBoxes(np.ascontiguousarray(boxes.reshape(-1), np.int32), start, int(start[-1]))


SLIP_WALL_LAYERS = 1
"""The layers of cells next to a wall, an inflow or a solid cell (along any of the 26 lattice directions) that
get no porosity-slip term in the pressure update (Eq. 39) with the paper's collision (odd moments at rate 1)."""

SLIP_WALL_LAYERS_ODD_FLOOR = 3
"""The same where the odd-rate floor acts (``FluidParams.odd_lambda``, the scenes' default below ν = 5e-4):
there a porosity edge within two cells of a wall grows a mode (``ReferenceOps.macro_pressure`` says why 3)."""


def slip_wall_layers(odd_floor: bool) -> int:
    """The layers next to walls without the slip term of Eq. 39, with (``odd_floor``) or without the odd-rate
    floor acting (:data:`SLIP_WALL_LAYERS_ODD_FLOOR`, :data:`SLIP_WALL_LAYERS`)."""
    return SLIP_WALL_LAYERS_ODD_FLOOR if odd_floor else SLIP_WALL_LAYERS


def wrap_interior(a: np.ndarray, axis: int, cells: int) -> np.ndarray:
    """The padded array ``a``'s interior along ``axis`` (its ghost layers dropped) with ``cells`` layers of it
    wrapped onto both sides: what a periodic axis shows a stencil or a distance that reaches ``cells`` deep."""
    inner = np.take(a, np.arange(1, a.shape[axis] - 1), axis=axis)
    pad = [(0, 0)] * a.ndim
    pad[axis] = (cells, cells)
    return np.pad(inner, pad, mode="wrap")


def slip_cells(flags: np.ndarray, periodic: tuple[bool, bool, bool], layers: int = SLIP_WALL_LAYERS) -> np.ndarray:
    """Padded uint8 mask of the fluid cells with no wall, inflow or solid cell within Chebyshev distance
    ``layers`` (every cell there a stencil cell: fluid or outflow ghost), the cells where Eq. 39 keeps its slip
    term (u − v)·∇ε.

    ``periodic``: whether the x, y, z axes are periodic (their faces wrap; the other faces' ghost layer, a wall,
    inflow or outflow, counts as extending outward). ``layers = 1`` gives the cells whose 26 neighbours are
    all stencil cells."""
    from scipy.ndimage import minimum_filter1d

    d = int(layers)
    stencil = ((flags == FLUID) | (flags == OUTFLOW)).astype(np.uint8)
    ext = stencil
    if d > 0:
        for axis, wraps in zip((2, 1, 0), periodic, strict=True):  # x, y, z = array axes 2, 1, 0
            if wraps:
                ext = wrap_interior(ext, axis, d)
            else:
                pad = [(0, 0)] * 3
                pad[axis] = (d - 1, d - 1)
                ext = np.pad(ext, pad, mode="edge")
        for axis in range(3):
            ext = minimum_filter1d(ext, size=2 * d + 1, axis=axis, mode="nearest")
        ext = ext[d - 1 : ext.shape[0] - d + 1, d - 1 : ext.shape[1] - d + 1, d - 1 : ext.shape[2] - d + 1]
    out = np.zeros(flags.shape, np.uint8)
    out[INTERIOR] = ext[INTERIOR] & (flags[INTERIOR] == FLUID)
    return out


def stencil_cell(flags: np.ndarray) -> np.ndarray:
    """Where a neighbour's own scalar value enters the stencils: fluid cells and outflow ghosts."""
    return (flags == FLUID) | (flags == OUTFLOW)


def _at(a: np.ndarray, pad: int, ox: int, oy: int, oz: int) -> np.ndarray:
    """``a`` (already padded by ``pad`` more layers) at x + (ox, oy, oz) for every cell x of the unpadded array."""
    pz, py, px = (s - 2 * pad for s in a.shape)
    return a[pad + oz : pad + oz + pz, pad + oy : pad + oy + py, pad + ox : pad + ox + px]


def flat_wall_cells(flags: np.ndarray, axes: tuple[bool, bool, bool] = (True, True, True)) -> np.ndarray:
    """Where the pressure filter may take the three-point wall rule (:func:`three_point_links`): the interior
    cells x in a flat stretch of wall layer, as a padded bool mask. For one axis a and side s, the 9 neighbours
    x + r with r_a = s are non-stencil cells (not FLUID, not OUTFLOW) and the other 17 are stencil cells, and the
    same holds, with the same a and s, for the four neighbours x ± e_t along the two other axes: x is at least
    two cells from any edge or corner of the wall (measured: with the rule also in the face cells beside an edge,
    the edges' period-2 oscillation grew 3× faster and a column collapse diverged at its corner,
    docs/fluid-stability.md). ``axes``: the wall-normal axes a considered (x, y, z; :func:`wall_rule_axes`)."""
    from ..lattice import C27

    stencil = np.pad(stencil_cell(flags), 1, constant_values=False)
    inner = np.zeros(flags.shape, bool)
    inner[INTERIOR] = True
    out = np.zeros(flags.shape, bool)
    for a in range(3):
        if not axes[a]:
            continue
        for side in (1, -1):
            flat = inner.copy()
            for c in C27[1:]:
                flat &= _at(stencil, 1, *c) == (c[a] != side)
            if not flat.any():
                continue
            fb = np.pad(flat, 1, constant_values=False)
            for t in range(3):
                if t != a:
                    for sg in (1, -1):
                        e = [0, 0, 0]
                        e[t] = sg
                        flat = flat & _at(fb, 1, *e)
            out |= flat
    return out


def wall_rule_axes(gravity) -> tuple[bool, bool, bool]:
    """The wall-normal axes whose flat wall layers take the filter's three-point rule (:func:`three_point_links`):
    those along which gravity acts (a floor and a ceiling; every axis without gravity). Measured: on the side
    walls of a tank the rule raised the steady residual current beside a submerged sand bed 2.3× (1.1e-3
    against 4.7e-4 lattice speed over 20,000 steps, tests/coupling/test_submerged_bed_at_rest.py), while on its
    floor and ceiling alone it left it at 5.0e-4; Fig. 4's mode sits at the ceiling (docs/fluid-stability.md)."""
    g = [float(v) for v in gravity]
    if not any(g):
        return (True, True, True)
    return (g[0] != 0.0, g[1] != 0.0, g[2] != 0.0)


def three_point_links(flags: np.ndarray, axes: tuple[bool, bool, bool] = (True, True, True)) -> np.ndarray:
    """The links of the pressure filter's three-point wall rule, as a padded uint32 mask: bit j of cell x is
    set where the filter's wall neighbour x + c_j takes p(x) + p(x − c_j) − p(x − 2c_j) instead of the two-point
    extrapolation 2 p(x) − p(x − c_j) (Eq. 40's wall rule, :func:`couplekit.fluid.reference.local_average`).

    That is where x is an interior FLUID cell of :func:`flat_wall_cells`, x + c_j is a WALL, and x − c_j,
    x − 2c_j and the six axis neighbours of x − 2c_j are stencil cells inside the padded grid. Both rules are
    exact for a linear (hydrostatic) profile; the three-point one filters the wall layer's wall-normal period-2
    mode a(−1)^k to a/3 as in the interior, which the two-point one leaves unfiltered (Fig. 4's colander
    diverged from that mode at its ceiling, docs/fluid-stability.md). Not at INFLOW neighbours, nor with
    x − 2c_j beside a non-stencil cell: narrow outlet jets diverged with either (the same page). ``axes``: the
    walls' normal axes that take the rule (:func:`wall_rule_axes`)."""
    from ..lattice import C27

    out = np.zeros(flags.shape, np.uint32)
    # only the candidate cells (a few per wall cell) are tested, by index: the whole grid per link cost seconds
    # and hundreds of MB at a paper scene's 51 M cells
    zz, yy, xx = (i + 3 for i in np.nonzero(flat_wall_cells(flags, axes) & (flags == FLUID)))
    stencil = np.pad(stencil_cell(flags), 3, constant_values=False)  # outside the padded grid: not a stencil cell
    wall = np.pad(flags == WALL, 3, constant_values=False)
    bits = np.zeros(zz.shape, np.uint32)
    for j in range(1, 27):
        cx, cy, cz = (int(v) for v in C27[j])
        ok = wall[zz + cz, yy + cy, xx + cx] & stencil[zz - cz, yy - cy, xx - cx]
        for ox, oy, oz in ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
            ok &= stencil[zz + oz - 2 * cz, yy + oy - 2 * cy, xx + ox - 2 * cx]
        bits |= ok.astype(np.uint32) << np.uint32(j)
    out[zz - 3, yy - 3, xx - 3] = bits
    return out


def outflow_lists(shape: tuple[int, int, int], flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(ghost, src)``: padded indices (int64) of every OUTFLOW ghost and of its nearest interior cell."""
    nz, ny, nx = shape
    pz, py, px = padded_shape(shape)
    zz, yy, xx = np.nonzero(flags == OUTFLOW)
    border = (zz == 0) | (zz == pz - 1) | (yy == 0) | (yy == py - 1) | (xx == 0) | (xx == px - 1)
    zz, yy, xx = zz[border], yy[border], xx[border]
    sz, sy, sx = np.clip(zz, 1, nz), np.clip(yy, 1, ny), np.clip(xx, 1, nx)
    ghost = (xx + px * (yy + py * zz)).astype(np.int64)
    return ghost, (sx + px * (sy + py * sz)).astype(np.int64)


def padded_coords(idx: np.ndarray, pshape: tuple[int, int, int]) -> np.ndarray:
    """(3, n) int64 padded (x, y, z) of the flat padded indices ``idx`` (layout: the module docstring)."""
    pz, py, px = pshape
    z, rem = np.divmod(np.asarray(idx, np.int64), px * py)
    y, x = np.divmod(rem, px)
    return np.stack([x, y, z])


def ghost_faces(idx: np.ndarray, pshape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """For padded indices ``idx`` of ghost cells: their inward normals (3, k) (a sum of unit vectors at edges
    and corners) and the padded index of the nearest interior cell of each."""
    pz, py, px = pshape
    x, y, z = padded_coords(idx, pshape)
    inward = np.zeros((3, np.size(idx)))
    for d, (c, n) in enumerate(((x, px), (y, py), (z, pz))):
        inward[d] = (c == 0).astype(float) - (c == n - 1).astype(float)
    near = np.clip(x, 1, px - 2) + px * (np.clip(y, 1, py - 2) + py * np.clip(z, 1, pz - 2))
    return inward, near


def outflow_directions(
    shape: tuple[int, int, int], ghost: np.ndarray, periodic_axes: tuple[bool, bool, bool]
) -> np.ndarray:
    """(3, n) int8: each outflow ghost's outward normal (:func:`ghost_faces`; its offset from its interior cell of
    :func:`outflow_lists`) on the axes it lies outside a non-periodic face (±1), 0 on the others: the directions in
    which the outflow takes backflow out (``ReferenceOps.outflow_fill``).  An edge ghost of an outflow face and a
    periodic face keeps only the outflow face's axis: across the periodic seam the fluid may flow either way."""
    outward = -ghost_faces(ghost, padded_shape(shape))[0]
    outward[np.asarray(periodic_axes, bool)] = 0
    return outward.astype(np.int8)


def wall_links(flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cell, dir)``: every link from an interior FLUID cell ``c`` whose neighbour ``c − c_dir`` is a WALL or
    INFLOW cell, as padded index (int64) and D3Q27 direction (int32), sorted by direction, then cell: the list
    kernels (lbm_wall_prefill / lbm_wall_bounce) then walk each population stream in address order (each link
    owns its slots, so the order changes no result)."""
    from ..lattice import C27

    pz, py, px = flags.shape
    fluid = np.zeros(flags.shape, bool)
    fluid[INTERIOR] = flags[INTERIOR] == FLUID
    cells, dirs = [], []
    zz, yy, xx = np.nonzero(fluid)
    for j in range(1, 27):
        cx, cy, cz = C27[j]
        nb = flags[zz - cz, yy - cy, xx - cx]
        hit = (nb == WALL) | (nb == INFLOW)
        cells.append((xx + px * (yy + py * zz))[hit])
        dirs.append(np.full(int(hit.sum()), j, np.int32))
    # by direction (the loop above), and within a direction by cell: np.nonzero's C order is the index order
    return np.concatenate(cells).astype(np.int64), np.concatenate(dirs).astype(np.int32)


def wall_link_mates(cell: np.ndarray, direction: np.ndarray, padded: tuple[int, int, int]) -> np.ndarray:
    """The second velocity cell w' of each wall link (``cell`` c, ``direction`` j of :func:`wall_links`): the
    link's wall velocity is the mean of u(w) and u(w') (``reference.link_wall_velocity``), where w = c − c_j and
    w' is c's own ghost across the face that w lies beyond, c − c_j projected on that face's normal, when w is in
    exactly one of the domain's ghost layers; otherwise (an edge or corner ghost, an interior solid cell) w' = w.
    Computed once per flags array for the list kernels (lbm_wall_prefill / lbm_wall_bounce), which read it
    instead of decoding w into (x, y, z) with three 64-bit divisions per link and call (measured on Fig. 13
    small's 35,364 links, one thread: 0.29 ms per call before, 0.14 ms with w' given; three calls per odd step)."""
    from ..lattice import C27

    pz, py, px = padded
    cell = np.asarray(cell, np.int64)
    c = C27[np.asarray(direction)].astype(np.int64)  # (n, 3): x, y, z
    w = cell - (c[:, 0] + px * c[:, 1] + px * py * c[:, 2])
    wz, wy, wx = w // (px * py), (w // px) % py, w % px
    gx, gy, gz = (wx == 0) | (wx == px - 1), (wy == 0) | (wy == py - 1), (wz == 0) | (wz == pz - 1)
    one = (gx.astype(int) + gy + gz) == 1
    shift = np.where(gx, c[:, 0], np.where(gy, c[:, 1] * px, c[:, 2] * px * py))
    return np.where(one, cell - shift, w).astype(np.int64)


def inflow_front_ramp(distance: np.ndarray, width: float) -> np.ndarray:
    """Fraction (0 → 1) of the way from the initial to the carried phase value of an inflow cell, after the
    inflow has pushed fluid ``distance`` cells in (normal speed × time).

    The equilibrium interface profile ½(1 + tanh(2 s/ξ)) of the conservative Allen–Cahn equation (Eq. 46)
    over s ∈ [−ξ, ξ], rescaled to go exactly from 0 at distance 0 to 1 at distance 2ξ: the inflow value is
    what an interface of width ξ entering at the inflow speed would show at the face. A non-positive
    distance (an inflow that does not push fluid in) gives 1 at once: nothing enters, so no front forms.
    """
    d = np.asarray(distance, np.float64)
    t2 = np.tanh(2.0)
    s = (np.tanh(2.0 * (d - width) / width) + t2) / (2.0 * t2)
    return np.where((d <= 0.0) | (d >= 2.0 * width), 1.0, np.clip(s, 0.0, 1.0))
