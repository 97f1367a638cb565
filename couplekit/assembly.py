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


def stability_cautions(scene: Scene) -> list[str]:
    """Set-ups a scene may ask for that were measured to diverge, or lie beyond what was measured, one line each
    (empty when none): printed by ``couplekit validate`` and logged when a run starts. Not refusals: the paper's
    own collision is one. Besides :func:`_input_cautions` (a density ratio beyond the measured one, a liquid let
    into a box with no outflow):

    * The odd-moment rate floor off (``fluid.odd_lambda = 0``, or too small to act) where the fluid's lowest
      lattice viscosity is below ``FluidParams.odd_nu_max`` (5e-4) and there are no-slip edges (walls on two
      axes, an obstacle, or an outlet's rim): the paper's collision is linearly unstable at bounce-back edges and
      corners there (docs/fluid-stability.md: at ν = 1e-4 the linearised step grows ×e every ~150 steps, a
      still 800:1 tank blew up near step 2500; ν = 1e-3 is stable). Flat walls on one axis only and periodic
      faces are stable."""
    fl = scene.fluid
    out = _frame_caution(scene)
    if fl is None:
        return out
    out += _input_cautions(scene)
    prm = fluid_params(scene, scene.units())
    two = fl.phases == 2
    nu_ref = prm.odd_reference_viscosity(two)
    if prm.odd_floor_acts(two) or nu_ref >= prm.odd_nu_max:
        return out
    wall_axes = {face[0] for face, kind in scene.domain.boundary.items() if kind in ("wall", "inflow")}
    obstacles = any(b.kind == "obstacle" for b in scene.bodies)
    outlets = any(i.shape != "face" for i in scene.inflows)
    if len(wall_axes) < 2 and not obstacles and not outlets:
        return out
    where = "walls on two axes" if len(wall_axes) >= 2 else ("an obstacle" if obstacles else "an outlet in a wall")
    steps = scene.time.frames * scene.time.steps_per_frame
    floor = (
        "fluid.odd_lambda = 0"
        if fl.odd_lambda == 0
        else f"fluid.odd_lambda = {fl.odd_lambda:g} (too small to act here)"
    )
    return out + [
        f"{floor} at lattice viscosity {nu_ref:g} (< {prm.odd_nu_max:g}) with no-slip edges ({where}): the paper's "
        f"collision is linearly unstable at bounce-back edges and corners at this viscosity (it grows by a factor e about "
        f"every 150 steps at 1e-4; a still tank diverged near step 2500; this scene runs {steps:,} steps); "
        "keep fluid.odd_lambda = 0.015 with fluid.smagorinsky = 0.1 (the scene defaults) unless you mean to run "
        "the paper's collision (docs/fluid-stability.md)"
    ]


MEASURED_DENSITY_RATIO = 1000.0
"""The largest density ratio the two-phase validations ran at (the static drop of
tests/fluid/test_two_phase_validation.py, 1000:1; the paper's scenes are 800:1)."""


FP16_RESOLUTION = 2.0**-11
"""Half a binary16 ulp relative to the value (fluid.storage = 'fp16' rounds each stored f − w to nearest)."""


def _fp16_gravity_caution(scene: Scene) -> list[str]:
    """fp16 storage rounds each stored f − w to ~2^-11 of itself every step (docs/precision.md). Gravity adds
    ~3 w_q c_q·g to a population per step, while f_q − w_q ~ 3 w_q c_q·u where the fluid moves at lattice speed u:
    above u ≈ g / 2^-11 the increment is under half a binary16 step and is rounded away, so gravity stops
    accelerating the flow there (a body-force-driven channel at ν = 0.01, 16 cells across, stalled at 0.81× its
    speed with fp16, 0.5 % off with fp32). A caution when the scene's fastest expected flow is above that speed."""
    units = scene.units()
    g_lat = float(np.linalg.norm(fluid_params(scene, units).gravity))  # the fluid's (fluid.gravity or domain's)
    if g_lat <= 0:
        return []
    speed, _ = scene.expected_max_speed()
    u_lat = units.to_lattice(speed, "velocity")
    u_lost = g_lat / FP16_RESOLUTION
    if u_lat <= u_lost:
        return []
    return [
        f"fluid.storage = 'fp16': gravity adds {g_lat:.2g} (lattice units) to the flow's velocity per step, under "
        f"half a binary16 step of the stored populations wherever the fluid moves faster than {u_lost:.2g} "
        f"(this scene expects up to {u_lat:.2g}): there each step's gravity is rounded away, and slow gravity-driven "
        "flow stalls (a body-forced channel reached 0.81x its speed); use fluid.storage = 'fp32' where that "
        "matters (docs/precision.md)"
    ]


NARROW_INTERFACE_RATIO = 400.0
"""The largest density ratio at which a water ball moving at lattice speed 0.04 ran at interface width 2
(:func:`narrow_interface_caution`)."""

NARROW_INTERFACE_SPEED = 0.01
"""The lattice speed a water ball ran at through air at 800:1 and interface width 2 (:func:`narrow_interface_caution`)."""


def narrow_interface_caution(scene: Scene) -> list[str]:
    """An interface narrower than :data:`couplekit.scene.model.OUTLET_MIN_INTERFACE_WIDTH` cells at a density
    ratio above :data:`NARROW_INTERFACE_RATIO` in a scene whose fastest expected flow is above
    :data:`NARROW_INTERFACE_SPEED` (lattice): a moving interface that sharp diverges at 800:1.

    Measured (session 30; tests/fluid/test_narrow_interface.py): a water ball of radius 6 cells moving through
    still air in a periodic 24 × 24 × 32 box with the scenes' fluid (lattice viscosities 1e-4 / 1e-2, their
    closures, M = 0.02, σ = 0.0728 N/m at dx = 1 cm, dt = 1 ms), 1000 steps: at 800:1 width 2 diverges at lattice
    speed 0.02 (by step 200; runs at 0.01, also with radius 4), width 2.25 at 0.04 (by step 220; runs at 0.02 and
    0.03); widths 2.4 and 2.5 run at 0.04, 2.5 at 0.06 (0.08 diverges by step 80, as a Mach limit would); at
    width 2, 400:1 and 200:1 run at 0.04. On a case not measured for it, Fig. 16's water-only dam break (small
    variant, lattice speed 0.084 at its end at width 4) diverges by step 800 of 960 at width 2 and runs to its end at 2.5 (and 4).
    Water outlets, whose speed is known, are refused below that width
    (:func:`couplekit.scene.model.water_outlet_speed_limit`); elsewhere the speed is an estimate
    (``Scene.expected_max_speed``), hence a caution."""
    from .scene.model import OUTLET_MIN_INTERFACE_WIDTH

    fl = scene.fluid
    ratio = fl.water_density / fl.air_density
    if fl.phases != 2 or fl.interface_width >= OUTLET_MIN_INTERFACE_WIDTH or ratio <= NARROW_INTERFACE_RATIO:
        return []
    speed, _ = scene.expected_max_speed()
    u_lat = scene.units().to_lattice(speed, "velocity")
    if u_lat <= NARROW_INTERFACE_SPEED:
        return []
    return [
        f"fluid.interface_width = {fl.interface_width:g} cells at {ratio:.3g}:1 with flow expected up to lattice "
        f"speed {u_lat:.2g}: an interface this sharp is under-resolved once it moves (a water ball moving through "
        f"air at 800:1 diverged at lattice speed 0.02 at width 2 and 0.04 at width 2.25, and ran at 0.06 at width "
        f"2.5); set fluid.interface_width >= {OUTLET_MIN_INTERFACE_WIDTH:g} (4, the default, is the validated one)"
    ]


EXAMPLE_MOBILITY = 0.02
"""The phase-field mobility (lattice) every shipped example and validation runs at (the scene default)."""

EXAMPLE_INTERFACE_WIDTH = 4.0
"""The interface width (cells) every shipped example but Fig. 1's small variant (6) runs at (the scene default)."""

MOBILITY_IMPACT_LIMITS: dict[float, tuple[float, float]] = {
    2.5: (1.0, 2.0),
    3.0: (2.75, 4.0),
    4.0: (4.0, 5.5),
    5.0: (4.0, 8.0),
    6.0: (8.0, 11.0),
    8.0: (8.0, 11.0),
}
"""Interface width (cells) → (largest u/M that ran, smallest u/M that diverged), u the lattice speed and M the
lattice mobility, for a water ball of radius 6 cells thrown at a wall through still air at 800:1 (the scenes'
fluid; session 32, tests/fluid/test_mobility_limit.py has the whole map). :func:`mobility_caution` reads the
second number at the widest measured width not above the scene's."""


def mobility_caution(scene: Scene) -> list[str]:
    """A phase-field mobility below the examples' (:data:`EXAMPLE_MOBILITY`), or an interface narrower than theirs
    (:data:`EXAMPLE_INTERFACE_WIDTH`, down to the 2.5 cells below which :func:`narrow_interface_caution` speaks), at
    a density ratio above :data:`NARROW_INTERFACE_RATIO`, in a scene whose expected lattice speed u makes u/M at
    least the ratio at which a moving interface was measured to diverge (:data:`MOBILITY_IMPACT_LIMITS`).

    Why: the conservative phase field keeps its tanh profile by the mobility's sharpening flux, ∝ M/ξ; a flow that
    strains the interface faster than that (an impact squeezing the air between water and a wall) tears the
    profile, φ leaves [0, 1] and the 800:1 density jump diverges within a few dozen steps. Measured (session 32,
    the ball of :data:`MOBILITY_IMPACT_LIMITS`, 600 steps): at width 4 it ran to u/M = 4 at M = 0.04, 0.02, 0.01
    and 0.005 and diverged from 5.5 (M = 0.02, u = 0.11) and 8 (M = 0.01, 0.005); at M = 0.0025 it diverged even
    at u = 0.02. A ball moving through open air tolerates about twice the ratio (width 4: ran to 8, diverged at
    11). On cases not measured for it, Fig. 6's raindrop (small variant, u/M = 7.6 expected at M = 0.02 and width 4,
    where it runs) diverged by step 70 at M = 0.01 and 0.0075 and at width 3, and at Δt/4 with M = 0.005.
    The examples' own (M, width) = (0.02, 4) run up to u/M = 8.1 expected (estimates are upper bounds: the
    raindrop's impact peaks at 0.124, u/M = 6.2), so they and wider, more mobile interfaces are not cautioned."""
    fl = scene.fluid
    if fl.phases != 2 or fl.water_density / fl.air_density <= NARROW_INTERFACE_RATIO:
        return []
    width, mobility = fl.interface_width, fl.mobility
    if width < min(MOBILITY_IMPACT_LIMITS) or (mobility >= EXAMPLE_MOBILITY and width >= EXAMPLE_INTERFACE_WIDTH):
        return []
    measured = max(w for w in MOBILITY_IMPACT_LIMITS if w <= width)
    ran, diverged = MOBILITY_IMPACT_LIMITS[measured]
    speed, source = scene.expected_max_speed()
    u_lat = scene.units().to_lattice(speed, "velocity")
    if u_lat / mobility < diverged:
        return []
    ratio = u_lat / mobility
    departs = []
    if mobility < EXAMPLE_MOBILITY:
        departs.append(f"fluid.mobility = {mobility:g} (examples: {EXAMPLE_MOBILITY:g})")
    if width < EXAMPLE_INTERFACE_WIDTH:
        departs.append(f"fluid.interface_width = {width:g} (examples: {EXAMPLE_INTERFACE_WIDTH:g})")
    return [
        f"{' and '.join(departs)} with flow expected up to lattice speed {u_lat:.2g} ({source}): u/M = {ratio:.3g}, "
        f"where a water ball hitting a wall through air at 800:1 diverged (width {measured:g}: ran to u/M = {ran:g}, "
        f"diverged from {diverged:g}); the phase field cannot hold so sharp an interface against such a flow. Keep "
        f"the examples' fluid.mobility = {EXAMPLE_MOBILITY:g} and fluid.interface_width = {EXAMPLE_INTERFACE_WIDTH:g} "
        f"(they run such flows), or lower time.dt to <= {scene.time.dt * ran / ratio:.3g} s (u/M = {ran:g}; u/M "
        "falls with dt) (docs/fluid-stability.md, 'The mobility a moving interface needs')"
    ]


def _small_drop_cautions(scene: Scene) -> list[str]:
    """A water body smaller than its own interface on every axis (under 2 interface widths across): the phase
    field's tanh profile (``build_fluid``) holds far more water than the body (a probe's sphere of 0.2 cell took
    ~800x its volume, one of 2 cells 3.6x). The initial water of such a body, summed on its cells, against its
    volume (sub-cell points inside); a caution above 1.25x."""
    dom, w = scene.domain, scene.fluid.interface_width
    out = []
    for i, b in enumerate(scene.bodies):
        if b.kind != "water":
            continue
        try:
            shape = b.geometry.shape(dom, 0.25 * dom.dx)
            lo, hi = (np.asarray(v, np.float64) for v in shape.bounds())
        except Exception:  # a shape that does not build is validation's problem
            continue
        if np.any(hi - lo >= 2 * w * dom.dx):
            continue
        pad = 2 * w * dom.dx
        a = np.floor((lo - pad) / dom.dx).astype(int)
        z = np.ceil((hi + pad) / dom.dx).astype(int)
        axes = [(np.arange(a[k], z[k]) + 0.5) * dom.dx for k in range(3)]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        phi = 0.5 * (1.0 - np.tanh(2.0 * np.asarray(shape.sdf(pts)) / (dom.dx * w)))
        fine = [(np.arange(4 * a[k], 4 * z[k]) + 0.5) * dom.dx / 4 for k in range(3)]
        sub = np.stack(np.meshgrid(*fine, indexing="ij"), axis=-1).reshape(-1, 3)
        volume = float((np.asarray(shape.sdf(sub)) < 0).sum()) / 64  # in cells
        ratio = float(phi.sum()) / volume if volume > 0 else np.inf
        if ratio > 1.25:
            across = float((hi - lo).max() / dom.dx)
            amount = f"{ratio:.3g}x its volume of water" if np.isfinite(ratio) else f"{phi.sum():.3g} cells of water"
            out.append(
                f"bodies[{i}] (water) is only {across:.3g} cells across, less than 2 interface widths "
                f"(fluid.interface_width = {w:g} cells): the phase field's interface profile starts it with "
                f"{amount}; make it at least {2 * w:g} cells across (or lower domain.dx)"
            )
    return out


def _frame_caution(scene: Scene) -> list[str]:
    """A frame is a whole number of steps (round(frame_duration / dt), at least 1); a caution when that is more
    than 2 % off the frame_duration asked for (the shipped examples are within 1.0 %) (a probe: 5e-5 s at dt = 2e-5 s ran frames of 4e-5 s, silently)."""
    t = scene.time
    got = t.steps_per_frame * t.dt
    if abs(got - t.frame_duration) <= 0.02 * t.frame_duration:
        return []
    return [
        f"time.frame_duration = {t.frame_duration:g} s is {t.frame_duration / t.dt:.3g} steps of dt = {t.dt:g} s: "
        f"frames are {t.steps_per_frame} steps ({got:g} s, {100 * (got / t.frame_duration - 1):+.0f} %); make "
        "time.frame_duration a multiple of time.dt"
    ]


def _multirate_frame_caution(scene: Scene) -> list[str]:
    """A multi-rate block of m fluid steps takes its one sand step at its first fluid step, so inside a block the
    sand is ahead of the fluid's clock by up to m − 1 steps. Where m does not divide the steps of a frame, frames
    fall inside blocks and show (and their diagnostics stamp) the sand that far ahead of the frame's time (a probe:
    m = 3, 5 steps per frame, the sand's velocity that of t + dt at t); a caution naming the divisors that align.
    Sand steps longer than a frame are refused (couplekit.scene.model)."""
    sch, n = scene.scheduler, scene.time.steps_per_frame
    if sch.kind != "multirate" or sch.sand_every <= 1 or n % sch.sand_every == 0 or sch.sand_every > n:
        return []
    m = sch.sand_every
    fit = [d for d in range(2, m) if n % d == 0]
    fix = f"scheduler.sand_every = {fit[-1]} divides them" if fit else f"no sand_every in 2..{m} divides them"
    return [
        f"scheduler.sand_every = {m} does not divide the {n} fluid steps of a frame: frames inside a block show the "
        f"sand up to {m - 1} fluid steps ({(m - 1) * scene.time.dt:.3g} s) ahead of the frame's time (a block's sand "
        f"step is taken at its first fluid step); {fix}, or make time.frame_duration a multiple of {m} steps"
    ]


def _input_cautions(scene: Scene) -> list[str]:
    """Cautions about what a scene asks of the fluid beyond what was measured or what can have a steady state:
    a density ratio beyond :data:`MEASURED_DENSITY_RATIO`; a water body smaller than its interface
    (:func:`_small_drop_cautions`); a moving interface narrower than 2.5 cells at 800:1
    (:func:`narrow_interface_caution`); a mobility or interface width below the examples' against a flow that
    tears the interface (:func:`mobility_caution`); multi-rate blocks that do not fit a frame (:func:`_multirate_frame_caution`);
    a single-phase fluid let in through an inflow with no
    outflow face (the liquid has nowhere to go: its pressure rises for as long as the inflow runs); sand kept only
    one cell off the walls (:func:`_wall_layer_caution`); an absorption rate beyond the measured one
    (:func:`_absorption_caution`); sand that falls onto the water at a lattice speed below the examples'
    (:func:`sand_entry_caution`)."""
    fl, out = scene.fluid, []
    if fl.storage == "fp16":
        out += _fp16_gravity_caution(scene)
    if fl.phases == 2 and fl.water_density / fl.air_density > MEASURED_DENSITY_RATIO:
        out.append(
            f"fluid.water_density / fluid.air_density = {fl.water_density / fl.air_density:.3g} is beyond the "
            f"{MEASURED_DENSITY_RATIO:g}:1 the two-phase validations ran at (the paper's scenes: 800:1): the "
            "interface may not hold; check it on a small variant first"
        )
    if fl.phases == 2:
        out += _small_drop_cautions(scene)
        out += narrow_interface_caution(scene)
        out += mobility_caution(scene)
    out += _multirate_frame_caution(scene)
    out += _wall_layer_caution(scene)
    out += _absorption_caution(scene)
    out += sand_entry_caution(scene)
    if fl.phases == 1 and scene.inflows and "outflow" not in scene.domain.boundary.values():
        out.append(
            "a single-phase fluid enters through inflows[0] but no face is an outflow: the liquid has nowhere to "
            "go, so its pressure and density rise for as long as the inflow runs (weakly compressible LBM); make "
            'a face an outflow (domain.boundary.<face> = "outflow") unless the run is short'
        )
    return out


def _wall_layer_caution(scene: Scene) -> list[str]:
    """``sand.wall_layers = 1`` in a scene coupling sand to a fluid: a bed whose grains reach the first cell off a
    wall leaves a thin fringe of sand (fraction ~0.01-0.02) in the wall's first cell, and where that fringe meets a
    floor-wall edge the water grows a current after ~3000 steps, driven by Eq. 39's porosity-slip term (measured,
    docs/fluid-stability.md: a 20 x 12 x 12 bed at ν_h = 1e-3, lattice speed 8e-5 to 8e-3 from step 3000 to 6000,
    growing; the same bed at the default 2 stays at 5e-5 for 7000 steps)."""
    if scene.sand is None or scene.sand.wall_layers != 1 or not scene.has_sand:
        return []
    steps = scene.time.frames * scene.time.steps_per_frame
    return [
        f"sand.wall_layers = 1 lets sand rest in the first cell off a wall: where that thin fringe meets a "
        "floor-wall edge the water grows a spurious current after ~3000 steps (docs/fluid-stability.md; this "
        f"scene runs {steps:,} steps); keep 2 (the default) unless water must not pass between the sand and the "
        "walls"
    ]


MEASURED_ABSORPTION_RATE = 0.03
"""The largest ``sand.absorption_rate`` measured to run (a probe, session 25: a dry bed under a pool, dx = 1 cm,
finite for 2000 steps at 0.03; at 0.05 non-finite at step 327, 0.1 at step 171; the paper's scenes 0.001-0.003)."""


def _absorption_caution(scene: Scene) -> list[str]:
    """Water retention at an absorption rate above :data:`MEASURED_ABSORPTION_RATE`: the uptake drains the
    water that seeps into a dry bed's pores about as fast as it arrives, φ there falls below 0, and the air in
    those pores, still under the water's pressure gradient, accelerates until the run diverges (measured at
    0.05: lattice speed 0.034 at step 300, 1.5 at 325, NaN at 327, in cells of φ ≈ −0.01)."""
    if scene.sand is None or True not in sand_retention_flags(scene):
        return []
    rate, tau = scene.sand.absorption_rate, scene.sand.absorption_time
    if rate <= MEASURED_ABSORPTION_RATE:
        return []
    given = (
        f"sand.absorption_time = {tau:g} s gives R_a = time.dt / absorption_time = {rate:.3g} per step, which"
        if tau is not None
        else f"sand.absorption_rate = {rate:g}"
    )
    return [
        f"{given} is above the {MEASURED_ABSORPTION_RATE:g} measured to run: a dry bed under "
        "water went non-finite at 0.05 (step 327) and 0.1 (step 171), its drained pores' air accelerating; the "
        "paper's scenes use 0.001-0.003 (docs/examples.md, Fig. 10)"
    ]


SAND_ENTRY_LATTICE_SPEED = 0.01
"""The smallest lattice speed U Δt/Δx at which the example scenes' sand meets the water surface (Fig. 8's balls,
0.0102 by :func:`sand_entry_speeds`' free fall; Figs. 2, 13, 14: 0.016-0.033): the scenes were checked there
(:func:`sand_entry_caution`)."""


def sand_entry_speeds(scene: Scene) -> list[tuple[int, float, float]]:
    """(body index, fall h in m, speed U in m/s) of each sand body released above a water body's top (under it
    along gravity, where gravity lies along an axis): U = |v0| + sqrt(2 g h), h from the sand's lowest point to the
    highest water top under it (the bodies' bounding boxes; drag in the air ignored, so U is an upper bound: Fig. 8's
    balls measure ~2.7 m/s where this gives 3.2). Two-phase fluids only; empty without gravity."""
    from .scene.model import depth_range

    fl, dom = scene.fluid, scene.domain
    if fl is None or fl.phases != 2:
        return []
    g = np.asarray(dom.gravity, dtype=np.float64)  # the sand falls under domain.gravity (fluid.gravity is the fluid's)
    gmag = float(np.linalg.norm(g))
    if gmag == 0:
        return []
    down = g / gmag
    along = np.flatnonzero(np.abs(down) > 1e-12)
    across = [a for a in range(3) if a != along[0]] if along.size == 1 else []

    def extent(body):  # (lo, hi, depth of the top, depth of the bottom) along gravity
        lo, hi = (np.asarray(v, dtype=np.float64) for v in body.geometry.bounds(dom))
        return (lo, hi, *depth_range(lo, hi, down))

    waters = [extent(b) for b in scene.bodies if b.kind == "water"]
    out = []
    for i, body in enumerate(scene.bodies):
        if body.kind != "sand":
            continue
        lo, hi, _, bottom = extent(body)
        tops = [w_top for w_lo, w_hi, w_top, _ in waters if all(w_hi[a] > lo[a] and w_lo[a] < hi[a] for a in across)]
        if not tops or min(tops) <= bottom:
            continue  # no water under it, or it starts at or in the water
        h = min(tops) - bottom
        out.append((i, h, float(np.linalg.norm(body.velocity)) + math.sqrt(2.0 * gmag * h)))
    return out


def sand_entry_caution(scene: Scene) -> list[str]:
    """A sand body that falls onto the water and meets its surface at a lattice speed U Δt/Δx below
    :data:`SAND_ENTRY_LATTICE_SPEED`: at so small a time step for its Δx the porosity-slip term of Eq. 39 pumps
    water up through sand in the surface's interface and the sand comes back out of the water
    (docs/fluid-stability.md, 'The slip term at a small time step'; not fixed). Measured with the physical
    viscosities kept (session 31; U from :func:`sand_entry_speeds`): Fig. 13's small ball sinks from 0.108 m to
    0.043 m by 0.2 s at its file's Δt (lattice 0.0176), to 0.052 at Δt/2 (0.0088) and rises to 0.110, above the
    surface at 0.08, at Δt/4 (0.0044); Fig. 8's three balls' mean height at 0.8 s is 0.649 m at its Δt (0.0102) and
    0.883, above the surface at 0.80, at Δt/2 (0.0051); the floating ring of Fig. 2 (0.0162 at its Δt) bobs at
    0.0028 and rises out at 0.0014; `tests/coupling/test_surface_pumping.py`'s slab sinks at 0.0115 and rises out
    at 0.0010."""
    units = scene.units()
    slow = [e for e in sand_entry_speeds(scene) if units.to_lattice(e[2], "velocity") < SAND_ENTRY_LATTICE_SPEED]
    if not slow:
        return []
    _, h, speed = min(slow, key=lambda e: e[2])  # the slowest: the time step that lifts it lifts all
    dx = scene.domain.dx
    names = ", ".join(f"bodies[{j}] ({scene.bodies[j].name!r})" for j, _, _ in slow)
    one = len(slow) == 1
    return [
        f"{names} {'falls' if one else 'fall'} onto the water and {'meets' if one else 'meet'} it at "
        f"{'' if one else 'as little as '}{speed:.3g} m/s (a fall of {h:.3g} m, no drag), lattice speed "
        f"{units.to_lattice(speed, 'velocity'):.2g} (U time.dt / dx), "
        f"below the {SAND_ENTRY_LATTICE_SPEED:g} the example scenes were checked at: at so small a time step for this "
        "dx, sand at the water surface is pumped back out of it (Fig. 13's ball ends above the surface at 0.0044, "
        "Fig. 8's balls at 0.0051; docs/fluid-stability.md, 'The slip term at a small time step'); use time.dt >= "
        f"{SAND_ENTRY_LATTICE_SPEED * dx / speed:.3g} s if the other time-step limits allow it, or refine dx and dt "
        "together"
    ]


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
