"""One path from a scene to running solvers: :func:`assemble` turns a :class:`~couplekit.scene.Scene` into the
fluid solver, the sand solver, the coupler joining them, the emitter of sand-carrying jets and the scheduler
that steps them (the scene's ``[scheduler]`` table).

:class:`couplekit.simulation.Simulation`, the CLI, the benchmarks, sweeps and the validation scenes built in
Python (:mod:`couplekit.coupling.scenes`, as scene dicts) all go through here, so a body, a particle volume or a
default means the same thing everywhere.

Conventions (stated once):

* **Seeding.** A sand body gets ``particles_per_cell`` = k³ particles per cell on the sub-lattice of spacing
  dx/k (:func:`couplekit.sand.seeding.seed_sdf`), each of grain volume V_p = ε0 (dx/k)³ with ε0 =
  ``sand.packing_fraction`` (default 0.6, at most ε_max = 0.64), and mass ϱ V_p with ϱ the body's
  ``density``. So a body's sand fraction (Eq. 25) is ε0 and ϱ is the grain density, the ϱ of paper Eq. 31's
  balance (sand weight ϱ ε V_cell g against the buoyancy ρ_f ε V_cell g): sand lighter than water rises, as
  paper Fig. 8's 950 kg/m³ ball does. (With V_p = (dx/k)³, ε would clamp at ε_max while the mass stayed
  ϱ V_cell, and the neutral density would be 0.64 ρ_w.)
* **Saturation and walls.** A body's ``saturation`` is its particles' initial saturation (dry: 0); sand-only
  scenes keep it, coupled ones start a retaining body with the bound water r_p = S / ε0
  (:func:`initial_moisture`). The sand's walls are ``[sand.walls]`` per face, 'separate' with
  ``sand.wall_friction`` where it names none (:func:`sand_walls`).
* **Initial pressure** (``fluid.initial_pressure``): hydrostatic when gravity lies along one non-periodic axis
  (:func:`couplekit.fluid.hydrostatic.hydrostatic_pressure`), so water at rest stays at rest instead of ringing
  with the pressure wave of a start from p = 0: ``"resting"`` carries the weight of water resting on the floor
  (water hanging in the air adds nothing), ``"column"`` every column straight through (a water layer over
  trapped air), ``"zero"`` starts from p = 0.
* **Time steps.** ``[time] dt`` is the fluid's (the coupling) step; the sand steps dt (lockstep), dt / k
  (sub-cycled, k fixed; with ``substeps = "auto"`` the scheduler sets it every step) or m dt (multi-rate),
  :func:`couplekit.schedulers.sand_step`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import replace as dataclass_replace
from typing import TYPE_CHECKING, Any

import numpy as np

from .backend import Backend
from .faces import solver_face, wall_face
from .fluid import hydrostatic
from .scene import Scene
from .scene.geometry import Union, sdf_on_grid
from .schedulers import folds_sand_velocity
from .units import Units

if TYPE_CHECKING:
    from .fluid.solver import FluidParams

__all__ = [
    "Assembly",
    "CouplingUnavailableError",
    "assemble",
    "build_coupler",
    "build_fluid",
    "build_sand",
    "build_scheduler",
    "check_run",
    "initial_moisture",
    "memory_estimate",
    "refuse_unsupported",
    "retention_flags",
    "sand_walls",
]


class CouplingUnavailableError(NotImplementedError):
    """The scene needs fluid–sand coupling, which is not built yet."""


@dataclass
class Assembly:
    """The solvers of a scene and the scheduler that steps them (:func:`assemble`).

    ``fluid_params``: the lattice-unit :class:`~couplekit.fluid.solver.FluidParams` the fluid was built with
    (None without a fluid); ``retentive``: per-particle water-retention flags of the seeded sand (None
    without sand)."""

    scene: Scene
    backend: Backend
    units: Units
    fluid: Any
    sand: Any
    coupler: Any
    emitter: Any
    scheduler: Any
    fluid_params: Any = None
    retentive: np.ndarray | None = None


def refuse_unsupported(scene: Scene) -> None:
    """Refuse, before allocation, what the coupler cannot do yet (CouplingUnavailableError naming the key)."""
    problems = []
    if scene.has_sand and scene.has_fluid:
        for key in ("drag", "buoyancy"):
            if not getattr(scene.effects, key):
                problems.append(f"effects.{key} = false: the coupler has no switch for it")
    if problems:
        raise CouplingUnavailableError(
            f"scene {scene.name!r} needs what the coupling module does not do yet: " + "; ".join(problems)
        )


def check_run(scene: Scene, available: tuple[float, str] | None = None) -> dict[str, float]:
    """Raise what :class:`couplekit.simulation.Simulation` refuses a scene for before it allocates anything,
    with the same messages, so that ``couplekit validate`` reports what ``couplekit run`` would refuse:
    :func:`refuse_unsupported` (CouplingUnavailableError), then the memory estimate against ``available``
    memory (bytes, what; default the host's, :func:`couplekit.simulation.available_memory`: ``run`` on the cuda
    backend compares with free GPU memory instead) as InsufficientMemoryError, whose ``estimate`` holds the
    estimate. Returns the estimate.

    A scene whose grids alone (fluid and sand grid, no particles) exceed the memory is refused on that bound
    when it has a sand jet on a face of more than ``LIMITS['max_outlet_face_cells']`` cells: the full estimate
    would lay out the jet's emission sites to count them, gigabytes before the comparison."""
    from .backend import get_backend
    from .faces import face_plane_shape
    from .scene.model import LIMITS
    from .simulation import InsufficientMemoryError, _gib, available_memory

    refuse_unsupported(scene)
    avail, what = available if available is not None else available_memory(get_backend("numpy"))
    shape = scene.domain.shape
    big_jet = any(
        i.sand_fraction > 0
        and math.prod(face_plane_shape(shape, solver_face(i.face))) > LIMITS["max_outlet_face_cells"]
        for i in scene.inflows
    )
    if big_jet:  # a lower bound: the scene without the sand of its jets
        import dataclasses

        jetless = tuple(dataclasses.replace(i, sand_fraction=0.0) for i in scene.inflows)
        est = memory_estimate(dataclasses.replace(scene, inflows=jetless))
    else:
        est = memory_estimate(scene)
    if est["total"] > 0.9 * avail:  # Simulation.__init__'s test and message
        exc = InsufficientMemoryError(
            f"scene {scene.name!r} needs about {_gib(est['total'])} but only {_gib(avail)} of {what} is free: "
            "use a coarser domain.dx, fewer sand.particles_per_cell, or a larger device"
        )
        exc.estimate = est
        raise exc
    return est


def assemble(
    scene: Scene,
    backend: Backend,
    *,
    log: Callable[[str], Any] | None = None,
    timing: bool = True,
    warm_up_steps: int = 1,
) -> Assembly:
    """Build every solver of ``scene`` on ``backend`` and the scheduler of its ``[scheduler]`` table.

    ``log``: where notes go (None: nowhere); ``timing``: time every stage (the scheduler's); ``warm_up_steps``:
    the first steps left out of the cost report (they load or compile the kernels)."""
    refuse_unsupported(scene)
    say = log or (lambda s: None)
    units = scene.units()
    coupled = scene.has_fluid and scene.has_sand
    fluid = fluid_params = sand = coupler = emitter = retentive = None
    if scene.has_fluid:
        fluid, fluid_params = build_fluid(scene, backend, units, coupled, say)
    if scene.has_sand:
        sand, retentive = build_sand(scene, backend, say)
    if coupled:
        coupler = build_coupler(scene, sand, fluid, units, retentive)
    if scene.emits_sand:
        from .sand.emission import InflowEmitter

        emitter = InflowEmitter.from_scene(scene, coupler=coupler)
    scheduler = build_scheduler(scene, fluid, sand, coupler, timing=timing, warm_up_steps=warm_up_steps)
    return Assembly(scene, backend, units, fluid, sand, coupler, emitter, scheduler, fluid_params, retentive)


# ---------------------------------------------------------------------------------------------- fluid
def _shapes_of(scene: Scene, kind: str) -> Union | None:
    dom = scene.domain
    shapes = [b.geometry.shape(dom, 0.25 * dom.dx) for b in scene.bodies if b.kind == kind]
    return Union(shapes) if shapes else None


def _water_shape(scene: Scene, periodic: tuple[bool, bool, bool] = (False, False, False)) -> Union | None:
    """Water bodies for the initial φ. A box face, or a height field's side or base, lying on the domain
    boundary is pushed out by 10 cells, so water that fills the shape up to a wall has no interface (a tanh
    drop) along that wall. On a ``periodic`` (x, y, z) axis only a shape that reaches both ends is pushed out (it
    continues across the wrap); one that reaches one end has its interface there, across the wrap from the
    cells at the other end (:func:`_periodic_images`)."""
    from .scene.mesh import HeightField, load_heights

    dom = scene.domain
    size, pad = np.asarray(dom.size), 10 * dom.dx
    wraps = np.asarray(periodic, bool)
    band = (5.0 * scene.fluid.interface_width + 2.0) * dom.dx  # φ < 1e-8 beyond (as _periodic_images)
    shapes = []
    for b in scene.bodies:
        if b.kind != "water":
            continue
        g = b.geometry
        if _plain_box(g):
            box = _padded_box(g, size, pad, wraps)
            shapes.append(_cut(box, g, dom, size, pad, wraps, band, host=(box.lo, box.hi)))
        elif g.type == "heightfield" and g.scale == 1.0 and not any(g.rotate) and not any(g.translate) and not g.invert:
            p = g.params
            h = np.asarray(p["heights"], float) if p.get("heights") is not None else load_heights(p["file"])
            (x0, x1), (y0, y1) = p["x_range"], p["y_range"]
            base = p.get("base")
            tol = 1e-9 * size.max()
            base = -pad if base is None or base <= tol else base
            # the edge heights repeated beyond each side on the boundary, at the grid's own spacing (the
            # height field's samples are evenly spaced), for at least `pad`
            sx, sy = (x1 - x0) / (h.shape[1] - 1), (y1 - y0) / (h.shape[0] - 1)
            nx_pad, ny_pad = int(np.ceil(pad / sx)), int(np.ceil(pad / sy))
            push_x = not wraps[0] or (x0 <= tol and x1 >= size[0] - tol)
            push_y = not wraps[1] or (y0 <= tol and y1 >= size[1] - tol)
            if x0 <= tol and push_x:
                h, x0 = np.concatenate([np.repeat(h[:, :1], nx_pad, axis=1), h], axis=1), x0 - nx_pad * sx
            if x1 >= size[0] - tol and push_x:
                h, x1 = np.concatenate([h, np.repeat(h[:, -1:], nx_pad, axis=1)], axis=1), x1 + nx_pad * sx
            if y0 <= tol and push_y:
                h, y0 = np.concatenate([np.repeat(h[:1], ny_pad, axis=0), h], axis=0), y0 - ny_pad * sy
            if y1 >= size[1] - tol and push_y:
                h, y1 = np.concatenate([h, np.repeat(h[-1:], ny_pad, axis=0)], axis=0), y1 + ny_pad * sy
            shapes.append(_cut(HeightField(h, (x0, x1), (y0, y1), base, 0.25 * dom.dx), g, dom, size, pad, wraps, band))
        elif g.subtract:  # the cuts with the interface's band (see _cut)
            base = dataclass_replace(g, subtract=()).shape(dom, 0.25 * dom.dx)
            shapes.append(_cut(base, g, dom, size, pad, wraps, band))
        else:
            shapes.append(g.shape(dom, 0.25 * dom.dx))
    return Union(shapes) if shapes else None


def _plain_box(g) -> bool:
    """Whether geometry ``g`` is an axis-aligned box (translated at most: no scale, rotation or inversion)."""
    return g.type == "box" and g.scale == 1.0 and not any(g.rotate) and not g.invert


def _padded_box(g, size: np.ndarray, pad: float, wraps: np.ndarray, host=None):
    """The plain box ``g`` (without its own ``subtract``) with each face lying on the domain boundary pushed out
    by ``pad``, except on a periodic axis it reaches one end of only (:func:`_water_shape`). ``host``: (lo, hi) of
    the water box ``g`` is cut out of; a face of the cut level with or beyond the host's face on the same side is
    pushed out too (the difference is the same set; level faces left a sheet of φ ≈ 0.5 in the difference's
    distance, max(d_water, −d_cut))."""
    from .scene.geometry import Box

    lo = np.asarray(g.params["min"], float) + np.asarray(g.translate)
    hi = np.asarray(g.params["max"], float) + np.asarray(g.translate)
    tol = 1e-9 * size.max()
    at_lo, at_hi = lo <= tol, hi >= size - tol
    spans = at_lo & at_hi
    push_lo, push_hi = at_lo & (spans | ~wraps), at_hi & (spans | ~wraps)
    if host is not None:
        push_lo |= lo <= np.asarray(host[0], float) + tol
        push_hi |= hi >= np.asarray(host[1], float) - tol
    return Box(np.where(push_lo, lo - pad, lo), np.where(push_hi, hi + pad, hi))


def _cut(shape, g, dom, size: np.ndarray, pad: float, wraps: np.ndarray, band: float, host=None):
    """``shape`` (a water body's box or height field, pushed out at the walls) less its geometry's ``subtract``
    shapes, as :meth:`couplekit.scene.model.Geometry.shape` builds them; a plain box among them is pushed out at
    the walls as the water is, so that cutting water away up to a wall leaves no interface along that wall (the
    cut's face 0.5 cell beyond the last cell centre left a layer of φ ≈ 0.4 there). Both shortcuts of
    :func:`_water_shape` dropped the cuts before: a water box with its half subtracted started full (a probe,
    session 25). A cut of another shape that reaches a wall keeps that thin layer. ``host``: the water box's
    (lo, hi), see :func:`_padded_box`. The cuts are evaluated within ``band`` (m) outside ``shape`` too
    (:class:`~couplekit.scene.geometry.Difference`'s ``near``), so the base shape's surface over a cut-away part
    leaves no tanh tail there."""
    from .scene.geometry import Difference

    if not g.subtract:
        return shape
    cuts = [
        _padded_box(c, size, pad, wraps, host) if _plain_box(c) and not c.subtract else c.shape(dom, 0.25 * dom.dx)
        for c in g.subtract
    ]
    return Difference(shape, cuts, near=band)


def _periodic_images(d: np.ndarray, shape, scene: Scene, periodic: tuple[bool, bool, bool]) -> np.ndarray:
    """The water's signed distance ``d`` (cells, (nz, ny, nx)) with the shape's periodic images: on a periodic
    axis the copies shifted by ± the domain's length, whose surfaces are the interfaces across the wrap.

    Why: without them water that reaches one end of a periodic axis met the air at the other end as a
    one-cell jump of φ across the wrap, which goes non-finite within a few steps at 800:1 (a box of water from
    x = 0 in a 13 × 13 × 21 box periodic in x: NaN at step 6). The union of the images is the minimum of their
    distances. An image changes φ only within a few interface widths of the end it lies beyond: it is
    evaluated on the ``5 ξ + 2`` cells there (beyond 5 ξ the profile differs from 0 or 1 by < 1e-8), and on
    their intersections for the images shifted along two or three axes."""
    import itertools

    dom = scene.domain
    res = np.asarray(dom.resolution)  # (nx, ny, nz)
    band = int(np.ceil(5 * scene.fluid.interface_width)) + 2
    axes = [a for a in range(3) if periodic[a]]
    out = d.copy()
    for signs in itertools.product((-1, 0, 1), repeat=len(axes)):
        if not any(signs):
            continue
        shift = np.zeros(3)
        ranges = [np.arange(n) for n in res]
        for a, sgn in zip(axes, signs, strict=True):
            if sgn == 0:
                continue
            shift[a] = sgn * dom.size[a]
            # the image beyond the high end (+L) is near the last cells, the one beyond the low end near the first
            ranges[a] = np.arange(max(res[a] - band, 0), res[a]) if sgn > 0 else np.arange(min(band, res[a]))
        z, y, x = np.meshgrid(ranges[2], ranges[1], ranges[0], indexing="ij")
        pts = (np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1) + 0.5) * dom.dx
        img = (shape.sdf(pts - shift) / dom.dx).reshape(z.shape)
        sub = np.ix_(ranges[2], ranges[1], ranges[0])
        out[sub] = np.minimum(out[sub], img)
    return out


def fluid_params(scene: Scene, units: Units) -> FluidParams:
    """The :class:`~couplekit.fluid.solver.FluidParams` (lattice units) of a fluid scene: the one translation of
    ``[fluid]`` and ``[effects]`` into the solver's parameters, with the defaults FluidParams documents as a
    scene's (:meth:`~couplekit.fluid.solver.FluidParams.scene_defaults`)."""
    from .fluid.solver import FluidParams

    fl, dom, eff = scene.fluid, scene.domain, scene.effects
    two = fl.phases == 2
    gravity = dom.gravity if fl.gravity is None else fl.gravity
    return FluidParams.scene_defaults(
        rho_h=1.0,
        rho_l=fl.air_density / fl.water_density if two else 1.0,
        nu_h=fl.water_lattice_viscosity,
        nu_l=fl.air_lattice_viscosity if two else fl.water_lattice_viscosity,
        gravity=tuple(units.to_lattice(g, "acceleration") for g in gravity),
        sigma=units.to_lattice(fl.surface_tension, "surface_tension") if two and eff.surface_tension else 0.0,
        mobility=fl.mobility,
        width=fl.interface_width,
        eta=fl.controller_eta if eff.volume_controller else 0.0,
        odd_lambda=fl.odd_lambda,
        odd_ramp=fl.odd_ramp,
        smagorinsky=fl.smagorinsky,
    )


def odd_ramp_applies(scene: Scene) -> bool:
    """Whether the scene's fluid runs the ramped odd-rate floor (``fluid.odd_ramp`` > 0 where the floor acts:
    :meth:`FluidParams.odd_floor_acts`), i.e. whether the solver holds the ramp's weights."""
    from .fluid.solver import FluidParams

    fl = scene.fluid
    if fl is None or not fl.odd_ramp > 0:
        return False
    two = fl.phases == 2
    nu_l = fl.air_lattice_viscosity if two else fl.water_lattice_viscosity
    return FluidParams(nu_h=fl.water_lattice_viscosity, nu_l=nu_l, odd_lambda=fl.odd_lambda).odd_floor_acts(two)


def fluid_boundaries(scene: Scene, units: Units):
    """The fluid's :class:`~couplekit.fluid.grid.Boundaries` (faces, and the outlets as inflow regions) and its
    solid mask (the obstacles' cells, ``None`` without obstacles) of ``scene``."""
    from .faces import region_mask
    from .fluid.grid import Boundaries, Face, InflowRegion

    dom = scene.domain
    inflow = {i.face: i for i in scene.inflows if i.shape == "face"}
    faces, regions = {}, []
    for name, kind in dom.boundary.items():
        if kind == "inflow":
            i = inflow[name]
            vel = tuple(units.to_lattice(v, "velocity") for v in i.velocity)
            faces[solver_face(name)] = Face("inflow", vel, 1.0 if i.kind == "water" else 0.0)
        else:
            faces[solver_face(name)] = Face(kind)
    for i in scene.inflows:  # outlets: inflow on part of a wall / outflow face (couplekit.faces)
        if i.shape != "face":
            vel = tuple(units.to_lattice(v, "velocity") for v in i.velocity)
            face = solver_face(i.face)
            mask = region_mask(dom.shape, dom.dx, face, i.shape, i.center, i.size, i.radius)
            regions.append(InflowRegion(face, mask, vel, 1.0 if i.kind == "water" else 0.0))
    obstacles = _shapes_of(scene, "obstacle")
    solid = sdf_on_grid(obstacles, dom.resolution, dom.dx) < 0 if obstacles else None
    return Boundaries(faces, tuple(regions)), solid


def check_odd_ramp_gaps(scene: Scene) -> None:
    """ValueError (:func:`couplekit.fluid.odd_ramp.check_gaps`'s message, the one ``run`` stops with) when the
    scene ramps the odd-rate floor (:func:`odd_ramp_applies`) and its walls, obstacles or open faces leave a gap
    narrower than the ramp accepts; ``couplekit validate`` calls it, so the file is refused before a run."""
    if not odd_ramp_applies(scene):
        return
    from .fluid.grid import build_flags
    from .fluid.odd_ramp import check_gaps

    boundaries, solid = fluid_boundaries(scene, scene.units())
    flags = build_flags(scene.domain.shape, boundaries, solid)[0]
    periodic = boundaries.periodic_axes
    check_gaps(flags, periodic, scene.fluid.odd_ramp)


def initial_phi(scene: Scene, periodic: tuple[bool, bool, bool] = (False, False, False)) -> np.ndarray:
    """The two-phase fluid's initial φ (nz, ny, nx) float32: the tanh profile (after Eq. 48) of the water bodies'
    signed distance (:func:`_water_shape`), with their images across the ``periodic`` axes; zeros without water."""
    dom, fl = scene.domain, scene.fluid
    water = _water_shape(scene, periodic)
    if water is None:
        return np.zeros(dom.shape, np.float32)
    d_cells = sdf_on_grid(water, dom.resolution, dom.dx).astype(np.float64) / dom.dx
    if any(periodic):
        d_cells = _periodic_images(d_cells, water, scene, periodic)
    return (0.5 * (1.0 - np.tanh(2.0 * d_cells / fl.interface_width))).astype(np.float32)


def build_fluid(scene: Scene, backend: Backend, units: Units, coupled: bool, log: Callable[[str], Any]):
    """The :class:`~couplekit.fluid.solver.FluidSolver` of ``scene`` and its FluidParams (lattice units):
    boundaries and outlets, obstacles as bounce-back cells, the initial φ of the water bodies and their
    velocity, the initial pressure (module docstring), and the stirring force."""
    from .fluid.solver import FluidSolver, OddFloorInactiveWarning

    fl, dom = scene.fluid, scene.domain
    two = fl.phases == 2
    prm = fluid_params(scene, units)
    boundaries, solid = fluid_boundaries(scene, units)
    phi = velocity = None
    if two:
        phi = initial_phi(scene, boundaries.periodic_axes)
        for b in scene.bodies:
            if b.kind == "water" and any(b.velocity):
                if velocity is None:
                    velocity = np.zeros((3, *dom.shape))
                inside = sdf_on_grid(b.geometry.shape(dom, 0.25 * dom.dx), dom.resolution, dom.dx) < 0
                for c in range(3):
                    velocity[c][inside] = units.to_lattice(b.velocity[c], "velocity")
    pressure = None
    if fl.initial_pressure != "zero":
        pressure = hydrostatic.hydrostatic_pressure(
            dom.shape, prm.gravity, phi if two else None, prm.rho_l, dom.boundary, fl.interface_width,
            resting_only=fl.initial_pressure == "resting",
        )  # fmt: skip
        if pressure is None and any(prm.gravity):
            log("note: no hydrostatic start (gravity not along one non-periodic axis): the fluid starts at p = 0")
    with warnings.catch_warnings():  # a scene's odd_lambda default is on at every viscosity: a note, not a warning
        warnings.simplefilter("ignore", OddFloorInactiveWarning)
        fluid = FluidSolver(
            backend,
            dom.shape,
            prm,
            boundaries,
            solid=solid,
            phi=phi,
            velocity=velocity,
            pressure=pressure,
            mixture=coupled,
            external_force=coupled or scene.stirring is not None,
            source_term=coupled and scene.effects.source_term,
            storage=fl.storage,
            # lockstep folds Eq. 39's sand terms into the pressure update and keeps the force in the velocity's
            # buffer (SandFluidCoupler.fold_sand_velocity)
            sand_velocity=not folds_sand_velocity(scene.scheduler.kind),
            force_in_velocity=coupled and folds_sand_velocity(scene.scheduler.kind),
        )
    from .cautions import stability_cautions  # cautions reads the scene through this module's helpers

    for line in stability_cautions(scene):
        log(f"caution: {line}")
    if prm.odd_lambda > 0 and not fluid.odd_floor_active:
        log(
            f"note: fluid.odd_lambda = {prm.odd_lambda:g} does nothing at this viscosity (lowest "
            f"{prm.odd_reference_viscosity(two):g} >= {min(2 * prm.odd_lambda / 3, prm.odd_nu_max):g} in lattice "
            "units): the odd moments relax at the paper's rate 1"
        )
    if scene.stirring is not None:  # the swirl of [stirring], added to the force input (couplekit.scene.forces)
        from .scene.forces import StirringForce

        StirringForce(scene.stirring, dom, units).attach(fluid)
    return fluid, prm


# ---------------------------------------------------------------------------------------------- sand
def retention_flags(scene: Scene) -> list[bool]:
    """Per sand body (in scene order): does it retain water (``bodies[*].retention``, else ``sand.retention``)."""
    sd = scene.sand
    return [b.retention if b.retention is not None else sd.retention for b in scene.bodies if b.kind == "sand"]


def sand_retention_flags(scene: Scene) -> set[bool]:
    """Whether each kind of sand in the scene retains water: the bodies' flags (:func:`retention_flags`) and, when
    inflows emit sand, ``sand.retention`` for the emitted particles (they have no body to override it)."""
    flags = set(retention_flags(scene))
    if scene.emits_sand:
        flags.add(bool(scene.sand.retention))
    return flags


def build_sand(scene: Scene, backend: Backend, log: Callable[[str], Any]):
    """The :class:`~couplekit.sand.solver.SandSolver` of ``scene`` (bodies seeded as the module docstring says,
    walls on every face, obstacles as one SDF collider, the sand's Δt from the scheduler) and the particles'
    retention flags.

    No particle is seeded inside an obstacle: a body is seeded less the obstacles it overlaps
    (:class:`~couplekit.scene.geometry.Difference`; validation refuses a body left without particles). Each
    obstacle keeps its own friction: the SDF collider of all of them samples, per grid node, the friction of the
    obstacle nearest the node (:meth:`~couplekit.sand.boundaries.SdfCollider.union`)."""
    from .sand.boundaries import SdfCollider
    from .sand.params import SandParams
    from .sand.seeding import seed_sdf
    from .sand.solver import SandSolver, TimeStepError
    from .scene.geometry import Difference, overlapping
    from .schedulers import SubstepLimitError, sand_step

    sd, dom, eff, sch = scene.sand, scene.domain, scene.effects, scene.scheduler
    bodies = [b for b in scene.bodies if b.kind == "sand"]
    flags = retention_flags(scene)
    if not scene.has_fluid and any(flags):
        log("note: water retention has no effect in a sand-only scene (no water to retain)")
    if not scene.has_fluid and sd.grain_diameter is not None:
        log("note: sand.grain_diameter has no effect in a sand-only scene (it sets the fluid's drag on the sand)")
    h0, h1, h2, h3 = sd.hardening
    s1, s2, s3 = sd.cohesion_saturation
    params = SandParams(
        density=sd.density,
        youngs_modulus=sd.youngs_modulus,
        poisson_ratio=sd.poisson_ratio,
        h0=h0,
        h1=h1,
        h2=h2,
        h3=h3,
        cohesion_max=sd.cohesion if eff.cohesion else 0.0,
        cohesion_s1=s1,
        cohesion_s2=s2,
        cohesion_s3=s3,
        hardening=eff.hardening,
        viscosity=sd.viscosity,
    )
    xs, vols, vels, dens, retains, sats = [], [], [], [], [], []
    size = np.asarray(dom.size)
    obstacles = [b for b in scene.bodies if b.kind == "obstacle"]
    solids = [b.geometry.solver_shape(dom) for b in obstacles]
    for i, b in enumerate(bodies):
        shape = b.geometry.solver_shape(dom)
        lo, hi = shape.bounds()
        lo, hi = np.maximum(lo, 0.0), np.minimum(hi, size)
        cutters = overlapping(shape, solids)
        sdf = Difference(shape, cutters).sdf if cutters else shape.sdf  # particles only outside the obstacles
        seeded = seed_sdf(sdf, lo, hi, dom.dx, sd.particles_per_axis, sd.jitter, sd.seed + i)
        if seeded.count == 0:  # validation refuses this (couplekit.scene.model._check_seeding)
            raise ValueError(
                f"sand body {b.name!r} gets no particle: it is thinner than the particle spacing, or inside obstacles"
            )
        xs.append(seeded.x)
        vols.append(sd.packing_fraction * seeded.volume)  # grain volume: ε0 of the sub-cell (module docstring)
        vels.append(np.repeat(np.asarray(b.velocity, np.float64)[:, None], seeded.count, axis=1))
        dens.append(np.full(seeded.count, b.density or sd.density))  # per-body grain density
        retains.append(np.full(seeded.count, flags[i]))
        sats.append(np.full(seeded.count, b.saturation or 0.0))  # bodies[*].saturation, dry by default
    retentive = np.concatenate(retains) if retains else np.zeros(0, bool)
    if not xs:  # the sand only enters through inflows (couplekit.sand.emission)
        xs, vols, vels, dens = [np.zeros((3, 0))], [np.zeros(0)], [np.zeros((3, 0))], [np.zeros(0)]
    saturation = _initial_saturation(scene, sats, params, log)
    walls = sand_walls(scene)
    collider = None
    frictions = [b.friction if b.friction is not None else sd.wall_friction for b in obstacles]
    sdfs = [lambda p, t, s=s: s.sdf(p) for s in solids]
    containers = [b for b in bodies if b.container_until is not None]
    for b in containers:  # frictionless: a frictional wall would carry part of the block's weight (Janssen)
        sdfs.append(_container_sdf(b.geometry.solver_shape(dom).bounds(), b.container_until))
        frictions.append(0.0)
    if sdfs:
        # resampled every step only until the last container is gone (then the SDF is the obstacles' alone)
        until = max((b.container_until for b in containers), default=float("inf"))
        collider = SdfCollider.union(sdfs, frictions, mode="separate", moving=bool(containers), moving_until=until)
    auto = sch.kind == "subcycle" and sch.substeps == "auto"
    # with substeps = "auto" the scheduler sets the sand's step every step; it starts at the smallest it may take
    dt = scene.time.dt / sch.max_substeps if auto else sand_step(sch.kind, scene.time.dt, sch.substeps, sch.sand_every)
    try:
        sand = _sand_solver(SandSolver, backend, scene, dt, params, xs, vols, vels, dens, walls, collider, saturation)
    except TimeStepError as exc:
        if not auto:
            raise
        raise SubstepLimitError(
            f"the sand's initial state needs more than scheduler.max_substeps = {sch.max_substeps} substeps of "
            f"time.dt = {scene.time.dt:g} s ({exc}); raise scheduler.max_substeps, or lower time.dt"
        ) from None
    return sand, retentive


def sand_walls(scene: Scene):
    """The sand's :class:`~couplekit.sand.boundaries.DomainWalls` of ``scene``: per face the kind and friction
    of ``[sand.walls]``, 'separate' with ``sand.wall_friction`` on the faces it does not name (every face, as
    before the table existed, when it is absent)."""
    from .sand.boundaries import DomainWalls, Wall

    sd = scene.sand
    faces = {}
    for f in scene.domain.boundary:
        w = sd.walls.get(f)
        faces[wall_face(f)] = Wall("separate", sd.wall_friction) if w is None else Wall(w.kind, w.friction)
    return DomainWalls.from_dict(faces, bound=sd.wall_layers)


def _container_sdf(bounds, until: float):
    """SDF of the invisible container of a sand body (``bodies[i].container_until``, paper 000 Fig. 17): the
    solid is everything outside the vertical prism over the body's bounding box ``bounds`` (lo, hi), at times
    t < ``until``; from ``until`` on there is no solid (SDF 1e3 m). The array is computed once per state and
    reused (the collider is resampled every step while a container may still be removed)."""
    lo, hi = (np.asarray(b, dtype=np.float64)[:2] for b in bounds)
    cache: dict = {}

    def sdf(points, t):
        pts = np.asarray(points, dtype=np.float64)
        key = (t < until, pts.shape)
        if key not in cache:
            cache.clear()
            if t >= until:
                cache[key] = np.full(pts.shape[0], 1e3)
            else:  # distance to the nearest side wall, positive inside (the sand's side)
                xy = pts[:, :2]
                cache[key] = np.minimum(xy - lo, hi - xy).min(axis=1)
        return cache[key]

    return sdf


def _initial_saturation(scene: Scene, sats: list, params, log: Callable[[str], Any]) -> np.ndarray | None:
    """The seeded particles' saturation (``bodies[*].saturation``), None when every body is dry (the solver's
    default, zeros). With a fluid the coupler recomputes it every step; the body retains water and starts
    holding it as bound water (:func:`initial_moisture`)."""
    if not any(b.saturation for b in scene.bodies if b.kind == "sand"):
        return None
    if not params.cohesion_on():
        log(
            "note: bodies[*].saturation has no effect: the sand is cohesionless (effects.cohesion = false or "
            "sand.cohesion = 0), and saturation acts through the cohesion only"
        )
    return np.concatenate(sats)


def initial_moisture(scene: Scene, sand) -> np.ndarray | float:
    """Initial moisture ratio r_p of the coupler's retention (paper 000 Eq. 58): a body seeded with saturation
    S holds it as bound water, r_p = S / ε0 (ε0 = ``sand.packing_fraction``: bound water R = r ε of a packed
    node, so the coupler's saturation R + ε̃ φ starts at S in dry air); 0 (dry) without saturation."""
    if not any(b.saturation for b in scene.bodies if b.kind == "sand"):
        return 0.0
    s = sand.backend.to_host(sand.saturation).astype(np.float64)
    return np.where(np.isfinite(s), s, 0.0) / scene.sand.packing_fraction


def _sand_solver(SandSolver, backend, scene, dt, params, xs, vols, vels, dens, walls, collider, saturation=None):
    sd, dom = scene.sand, scene.domain
    return SandSolver(
        backend,
        dom.shape,
        dom.dx,
        dt,
        params,
        np.concatenate(xs, axis=1),
        np.concatenate(vols),
        velocities=np.concatenate(vels, axis=1),
        densities=np.concatenate(dens),
        gravity=dom.gravity,
        walls=walls,
        sdf_collider=collider,
        cfl=sd.cfl,
        elastic_cfl=sd.elastic_cfl,
        allow_empty=scene.emits_sand,
        saturation=saturation,
        keep_saturation=scene.has_fluid,  # the coupling's moisture (Eq. 59), cohesion or not
    )


# ---------------------------------------------------------------------------------------------- coupling
def build_coupler(scene: Scene, sand, fluid, units: Units, retentive: np.ndarray | None):
    """The :class:`~couplekit.coupling.coupler.SandFluidCoupler` of ``scene``: retention on when any sand body
    retains, per-particle flags when only some do (all flags true = the one-setting model, bitwise)."""
    from .coupling.coupler import SandFluidCoupler
    from .coupling.params import CouplingParams

    sd = scene.sand
    retention = True in sand_retention_flags(scene)  # a body's sand, or the emitted sand (sand.retention)
    params = CouplingParams(
        retention=retention,
        r_max=sd.max_moisture,
        absorption_rate=sd.absorption_rate,
        grain_diameter=sd.grain_diameter,
    )
    flags = retentive if retention and retentive is not None and retentive.size == sand.n_particles else None
    moisture = initial_moisture(scene, sand) if retention else 0.0
    emitted = bool(sd.retention) if scene.emits_sand else None
    return SandFluidCoupler(sand, fluid, units, params, moisture=moisture, retentive=flags, emitted_retentive=emitted)


def build_scheduler(scene: Scene, fluid, sand, coupler, *, timing: bool = True, warm_up_steps: int = 1):
    """The scheduler of the scene's ``[scheduler]`` table over these solvers (:func:`couplekit.schedulers.
    make_scheduler`); a fluid-only scene is stepped in lockstep."""
    from .schedulers import make_scheduler

    sch = scene.scheduler
    return make_scheduler(
        sch.kind,
        fluid,
        sand,
        coupler,
        dt=scene.time.dt,
        substeps=sch.substeps,
        max_substeps=sch.max_substeps,
        interpolation=sch.interpolation,
        sand_every=sch.sand_every,
        source_term=scene.effects.source_term,
        timing=timing,
        warm_up_steps=warm_up_steps,
    )


# ---------------------------------------------------------------------------------------------- memory
_FLUID_FLOATS_PER_CELL = 27 + 3 + 1 + 1  # f, velocity (the walls' velocities in the wall cells), p, pbar
_PHASE_FLOATS_PER_CELL = 7 + 1  # h, phi (grad phi and mu: computed in the collides); + the source term in coupled
# scenes with it on (FluidSolver; effect_memory counts each effect's fields)
_SAND_FLOATS_PER_NODE = 1 + 3 + 1  # mass, momentum (overwritten by the velocity: SandSolver.grid_v), sdf; + the
# volume with sand of more than one density (SandSolver.node_volume: else the mass over the density)
_SAND_FLOATS_PER_PARTICLE = 3 + 3 + 9 + 9 + 6 + 1 + 1 + 1 + 1 + 1  # x v C F tau q vc saturation mass volume


def memory_estimate(scene: Scene) -> dict[str, float]:
    """Bytes the solvers will allocate for ``scene`` (an estimate from the array sizes, before allocation).

    Particles are bounded by the sand bodies' bounding boxes × particles per cell (an upper bound), plus the
    particles the sand-carrying inflows emit over the scene's duration (``emitted_particles``,
    :func:`couplekit.sand.emission.expected_particles`). ``scheduler``: the sub-cycling scheduler's buffers
    (fluid view, force, porosity, sand velocity and absorbed-water sums; with linear interpolation last step's
    fluid velocity; multi-rate with m > 1: the exchange velocity's own buffer)."""
    nx, ny, nz = scene.domain.resolution
    cells = nx * ny * nz
    padded = (nx + 2) * (ny + 2) * (nz + 2)
    out = {"fluid": 0.0, "sand_grid": 0.0, "particles": 0.0, "particle_count": 0.0}
    if scene.fluid is not None:
        floats = _FLUID_FLOATS_PER_CELL
        if scene.fluid.phases == 2:
            source = scene.has_sand and scene.effects.source_term
            floats += _PHASE_FLOATS_PER_CELL + int(source)
        floats += int(odd_ramp_applies(scene))  # the ramp's weights (FluidSolver.odd_ramp)
        out["fluid"] = padded * (4 * floats + 1)  # + 1 byte of flags
        if scene.fluid.storage == "fp16":  # f and h in 2 B instead of 4 (couplekit.fluid.storage)
            populations = 27 + (7 if scene.fluid.phases == 2 else 0)
            out["fp16_saving"] = padded * 2.0 * populations
            out["fluid"] -= out["fp16_saving"]
    if scene.has_sand:
        densities = {b.density or scene.sand.density for b in scene.bodies if b.kind == "sand"}
        densities |= {scene.sand.density} if scene.emits_sand else set()
        out["sand_grid"] = 4.0 * (_SAND_FLOATS_PER_NODE + int(len(densities) > 1)) * cells
        count = 0.0
        for b in scene.bodies:
            if b.kind == "sand":
                lo, hi = b.geometry.bounds(scene.domain)
                count += float(np.prod(np.maximum(hi - lo, 0.0))) / scene.domain.dx**3 * scene.sand.particles_per_cell
        if scene.emits_sand:
            from .sand.emission import InflowEmitter, expected_particles

            duration = scene.time.frames * scene.time.steps_per_frame * scene.time.dt
            out["emitted_particles"] = expected_particles(InflowEmitter.from_scene(scene), duration)
            count += out["emitted_particles"]
        out["particle_count"] = count
        # q and the saturation are not allocated when their effects are off (SandSolver; the saturation stays
        # in a coupled scene, as the coupling's moisture, and with seeded saturation)
        floats = _SAND_FLOATS_PER_PARTICLE - (0 if scene.effects.hardening else 1)
        seeded = any(b.saturation for b in scene.bodies if b.kind == "sand")
        cohesive = scene.effects.cohesion and scene.sand.cohesion > 0
        floats -= 0 if (cohesive or scene.has_fluid or seeded) else 1
        out["particles"] = 4.0 * floats * count
    retention = False
    if scene.fluid is not None and scene.has_sand:
        # fluid mixture inputs (fluid_fraction, sand_velocity, force) and the coupler's fields
        flags = sand_retention_flags(scene)
        retention, mixed = True in flags, len(flags) > 1  # mixed: + retentive fraction grid and flags
        # padded: the fluid's ε (1) and, except in lockstep (which folds Eq. 39's sand terms into the pressure
        # update and keeps the force in the fluid velocity's buffer), its sand velocity and force (6); the coupler's
        # last ε (1, unless it lives in the source term's buffer, counted with the fluid; its exchange velocity
        # shares the sand velocity's buffer, or in lockstep the fluid velocity's; the sand and water fractions are
        # recomputed, SandFluidCoupler), the cells of Eq. 39's slip term (1 byte); interior: with retention the
        # bound water R, R', dR (+ the retentive sand's fraction with per-body retention)
        shared = scene.fluid.phases == 2 and scene.effects.source_term
        unfolded = 0 if folds_sand_velocity(scene.scheduler.kind) else 6
        out["coupling"] = padded * (4.0 * (1 + unfolded + (0 if shared else 1)) + 1) + cells * 4.0 * (
            (3 + mixed) if retention else 0
        )
        out["particles"] += 4.0 * count * ((1 + mixed) if retention else 0)
        if scene.scheduler.kind == "multirate" and scene.scheduler.sand_every > 1:
            out["scheduler"] = 4.0 * padded * 3  # the exchange velocity's own buffer (own_fluid_velocity)
        if scene.scheduler.kind == "subcycle":
            linear = scene.scheduler.interpolation == "linear"
            out["scheduler"] = 4.0 * (padded * (3 + 3 + 1 + (3 if linear else 0)) + cells * (3 + retention))
    if scene.fluid is not None and getattr(scene, "stirring", None) is not None:
        # the stirring's fields (its acceleration, radius and mask grids, the summed force, the stirred box's
        # density; the force input a fluid-only scene would not have): one table, couplekit.effect_memory
        from .effect_memory import effect_memory

        out["stirring"] = effect_memory(scene)["stirring"]["bytes_total"]
    out["total"] = (
        out["fluid"]
        + out["sand_grid"]
        + out["particles"]
        + out.get("coupling", 0.0)
        + out.get("stirring", 0.0)
        + out.get("scheduler", 0.0)
    )
    return out
