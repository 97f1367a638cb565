"""Coupled validation scenes built in Python at CPU-friendly sizes (paper 000 Figs. 8, 10, 13, 14):
a sand ball dropped into (or released inside) a water pool under air, a uniform suspension settling in a
closed water column, a saturated sand bed, and a dry sand plug under a water layer (wetting front).

Each builder writes a scene dict (the TOML structure, :func:`scene_dict`) and builds it through
:func:`couplekit.assembly.assemble`, the path every scene takes, so seeding, particle volumes, defaults and the
scheduler mean what they mean in a scene file. It returns a :class:`CoupledScene`: the FluidSolver, SandSolver,
SandFluidCoupler and the scheduler that advances them (the scene's ``[scheduler]``: ``scheduler=`` a table,
lockstep by default), plus the measurements the tests and benchmarks use. Conventions: z is up, shapes are
``(nz, ny, nx)``, SI in, lattice inside.

Choices (not in the paper; stated here once):

* Particles: 8 per cell (2 per axis), no jitter, on the seeding sub-lattice; sand fraction (``packing_fraction``)
  0.55 < ε_max: the sand density is the grain density of Eq. 31's balance, and sand of the water's density is
  neutrally buoyant, as paper Fig. 8's 950 kg/m³ ball "slightly lower than that of water" floats back up
  (:mod:`couplekit.assembly`).
* The water starts at rest with its hydrostatic pressure integrated through every column, the air included
  (``fluid.initial_pressure = "column"``: the plug's and bed's pores hold trapped air that carries the water
  above), and the water–air interface is the tanh profile of width ξ of the water bodies' signed distance
  (text after Eq. 48).
* Fluid walls on every face (a closed tank); the sand's domain walls are "separate" with friction 0.5,
  2 node layers thick (1 for the bodies that fill the cross-section: bed, plug, suspension, so that the
  sand reaches the first cell and water cannot bypass it along the walls: ``sand.wall_layers``).
* Lattice viscosities of paper Table 1 (ν_h = 1e-4 water, ν_l = 1e-2 air) unless given; surface tension
  0.073 N/m; density ratio 800:1; volume controller η = 2; no fluid closures unless given (the paper's
  collision; scene files default to the closures, docs/fluid-stability.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..backend import Backend
from ..units import Units

__all__ = [
    "CoupledScene",
    "bed_under_partition",
    "build_scene",
    "dry_plug_under_water",
    "saturated_bed",
    "sand_ball_into_water",
    "scene_dict",
    "uniform_suspension",
]

G = 9.81
RHO_W = 1000.0
RHO_AIR = 1000.0 / 800.0


@dataclass
class CoupledScene:
    """A built coupled scene and what it is measured by (see the module docstring)."""

    fluid: object
    sand: object
    coupler: object
    units: Units
    scheduler: object = field(repr=False)
    water_level: float = 0.0  # initial water surface height, m (0: no free surface)
    info: dict = field(default_factory=dict)
    scene: object = field(default=None, repr=False)
    """The validated :class:`~couplekit.scene.Scene` the solvers were assembled from."""

    def step(self, n: int = 1) -> None:
        """``n`` steps of the scene's scheduler (lockstep: Algorithm 1)."""
        self.scheduler.step(n)

    # ------------------------------------------------------------------ measurements
    def sand_positions(self) -> np.ndarray:
        """Particle positions (3, P), m, host float64."""
        return self.sand.backend.to_host(self.sand.x).astype(np.float64)

    def sand_centre(self) -> np.ndarray:
        """Mean particle position (x, y, z), m."""
        return self.sand_positions().mean(axis=1)

    def sand_mean_velocity(self) -> np.ndarray:
        """Mean particle velocity (x, y, z), m/s."""
        return self.sand.backend.to_host(self.sand.v).astype(np.float64).mean(axis=1)

    def max_lattice_speed(self) -> float:
        """Largest fluid speed in lattice units over fluid cells."""
        return float(self.fluid.diagnostics()["max_lattice_speed"])

    def finite(self) -> bool:
        """Every fluid population, velocity, pressure and particle position and velocity is finite."""
        be = self.fluid.backend
        arrays = [self.fluid.f, self.fluid.velocity, self.fluid.p, self.sand.x, self.sand.v]
        if self.fluid.h is not None:
            arrays.append(self.fluid.h)
        return all(np.isfinite(be.to_host(a)).all() for a in arrays)

    def fluid_volume_drift(self) -> float:
        """Relative change of V = Σ ε̃ φ + bound water since the coupler's first step (Eq. 52's V)."""
        return float(self.fluid.diagnostics()["fluid_volume_drift"])

    def water_volume(self) -> float:
        """Free water Σ ε̃ φ plus bound water Σ r_p V_p / V_cell, in cells (independent of the solver's sums)."""
        be = self.fluid.backend
        e = be.to_host(self.fluid.fluid_fraction)[1:-1, 1:-1, 1:-1].astype(np.float64)
        phi = be.to_host(self.fluid.phi)[1:-1, 1:-1, 1:-1].astype(np.float64)
        fluid = be.to_host(self.fluid.flags)[1:-1, 1:-1, 1:-1] == 0
        free = float((e * phi)[fluid].sum())
        bound = 0.0
        if self.coupler.retention:
            r = be.to_host(self.coupler.moisture_ratio).astype(np.float64)
            bound = float((r * be.to_host(self.sand.volume)).sum()) / self.units.dx**3
        return free + bound


_SAND_PARAM_KEYS = {"cohesion_max": "cohesion", "poisson_ratio": "poisson_ratio", "density": "density"}
"""SandParams names a builder's ``sand_params`` may set, and the [sand] key each is."""


def _box(lo, hi) -> dict:
    return {"type": "box", "min": [float(v) for v in lo], "max": [float(v) for v in hi]}


def scene_dict(
    shape: tuple[int, int, int],
    units: Units,
    sand_geometry: dict,
    *,
    density: float,
    water: dict | None,
    sand_fraction: float = 0.55,
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0),
    nu_h: float = 1e-4,
    nu_l: float = 1e-2,
    surface_tension: float = 0.073,
    eta: float = 2.0,
    source_term: bool = True,
    retention: bool = False,
    absorption_rate: float = 0.001,
    youngs_modulus: float = 3.5e5,
    fluid_gravity: float | None = None,
    periodic_xy: bool = False,
    wall_layers: int = 2,
    sand_params: dict | None = None,
    smagorinsky: float = 0.0,
    odd_lambda: float | None = None,
    obstacles: list[dict] | None = None,
    scheduler: dict | None = None,
) -> dict:
    """The scene dict of a closed tank (``shape`` cells, ``units``) holding the sand body ``sand_geometry``
    (a geometry table, SI) of sand fraction ``sand_fraction`` and grain ``density`` moving at ``velocity`` m/s,
    and the water body ``water`` (a geometry table; ``None``: single-phase water everywhere) under air.

    ``fluid_gravity``: the fluid's vertical acceleration in m/s² (default −g; the settling test replaces it by
    the mean pressure gradient of a closed column, see :func:`uniform_suspension`). ``periodic_xy``: periodic
    fluid faces in x and y (the sand meets walls there, ``sand.periodic_walls``); ``wall_layers``: node layers
    of the sand's domain walls (the sand must keep that many cells from each face); ``sand_params``: further
    SandParams fields by their SandParams names (``cohesion_max``, ``poisson_ratio``); ``smagorinsky``,
    ``odd_lambda``: the fluid's closures (docs/fluid-stability.md; None = the paper's rate 1);
    ``retention``, ``absorption_rate``: water retention (Eqs. 53–58, R_a); ``obstacles``: geometry tables of
    fixed solids (a partition wall); ``scheduler``: a ``[scheduler]`` table. The rest: module docstring."""
    nz, ny, nx = shape
    dx = units.dx
    two_phase = water is not None
    sand = {
        "density": float(density),
        "youngs_modulus": float(youngs_modulus),
        "packing_fraction": float(sand_fraction),
        "particles_per_cell": 8,
        "jitter": 0.0,
        "wall_layers": int(wall_layers),
        "retention": bool(retention),
        "absorption_rate": float(absorption_rate),
    }
    for name, value in (sand_params or {}).items():
        if name not in _SAND_PARAM_KEYS:
            raise ValueError(f"sand_params: {name!r} is not one of {', '.join(_SAND_PARAM_KEYS)}")
        sand[_SAND_PARAM_KEYS[name]] = float(value)
    fluid = {
        "phases": 2 if two_phase else 1,
        "water_lattice_viscosity": float(nu_h),
        "air_lattice_viscosity": float(nu_l if two_phase else nu_h),
        "surface_tension": float(surface_tension) if two_phase else 0.0,
        "controller_eta": float(eta) if two_phase else 0.0,
        "smagorinsky": float(smagorinsky),
        "odd_lambda": 0.0 if odd_lambda is None else float(odd_lambda),
        "initial_pressure": "column",
        "air_density": RHO_AIR,
        "water_density": RHO_W,
    }
    if fluid_gravity is not None:
        fluid["gravity"] = [0.0, 0.0, float(fluid_gravity)]
    boundary = {}
    if periodic_xy:
        boundary = {f: "periodic" for f in ("x_min", "x_max", "y_min", "y_max")}
        sand["periodic_walls"] = True
    bodies = [{"kind": "sand", "name": "sand", "velocity": [float(v) for v in velocity], "geometry": sand_geometry}]
    if two_phase:
        bodies.append({"kind": "water", "name": "water", "geometry": water})
    bodies += [{"kind": "obstacle", "name": f"obstacle {i}", "geometry": g} for i, g in enumerate(obstacles or [])]
    d = {
        "scene": {"name": "coupled validation scene"},
        "domain": {"size": [nx * dx, ny * dx, nz * dx], "dx": dx, "gravity": [0.0, 0.0, -G], "boundary": boundary},
        "time": {"dt": units.dt, "frame_duration": units.dt, "frames": 1},
        "fluid": fluid,
        "sand": sand,
        "bodies": bodies,
        "effects": {"source_term": bool(source_term)},
        "outputs": {"preview": False, "vtk": False, "ply": False},
    }
    if scheduler:
        d["scheduler"] = dict(scheduler)
    return d


def build_scene(
    backend: Backend,
    shape: tuple[int, int, int],
    units: Units,
    sand_geometry: dict,
    *,
    water_depth: float | None,
    water: dict | None = None,
    timing: bool = False,
    **kw,
) -> CoupledScene:
    """Assemble the tank of :func:`scene_dict` on ``backend``: water up to ``water_depth`` m over the whole floor
    (``None``: single-phase water everywhere), or the water body ``water``. ``timing``: time every stage.
    ``kw``: :func:`scene_dict`."""
    from ..assembly import assemble
    from ..scene import Scene

    nz, ny, nx = shape
    dx = units.dx
    if water is None and water_depth is not None:
        water = _box((0.0, 0.0, 0.0), (nx * dx, ny * dx, water_depth))
    d = scene_dict(shape, units, sand_geometry, water=water, **kw)
    scene = Scene.from_dict(d, source_name="coupled validation scene")
    asm = assemble(scene, backend, timing=timing, warm_up_steps=0)
    info = {"shape": list(shape), "dx": dx, "dt": units.dt, "density": kw["density"], "particles": int(asm.sand.n_particles),
            "sand_fraction": kw.get("sand_fraction", 0.55), "nu_h": kw.get("nu_h", 1e-4), "nu_l": kw.get("nu_l", 1e-2),
            "scheduler": scene.scheduler.describe()}  # fmt: skip
    return CoupledScene(asm.fluid, asm.sand, asm.coupler, asm.units, asm.scheduler, float(water_depth or 0.0), info,
                        scene)  # fmt: skip


def sand_ball_into_water(
    backend: Backend,
    shape: tuple[int, int, int] = (32, 24, 24),
    *,
    dx: float = 0.005,
    dt: float = 1e-4,
    density: float = 1500.0,
    radius: float = 4.0,
    centre_height: float | None = None,
    water_depth: float | None = None,
    impact_speed: float = 0.0,
    **kw,
) -> CoupledScene:
    """Paper Figs. 8/13/14 at small scale: a sand ball of ``radius`` cells, centred at ``centre_height``
    cells (default: 1.5 radii above the water), over a pool ``water_depth`` cells deep (default: 45 % of
    the height), moving down at ``impact_speed`` m/s.  ``kw``: :func:`build_scene`."""
    nz, ny, nx = shape
    depth = 0.45 * nz if water_depth is None else float(water_depth)
    zc = depth + 1.5 * radius + 1.0 if centre_height is None else float(centre_height)
    units = Units(dx=dx, dt=dt)
    ball = {"type": "sphere", "center": [0.5 * nx * dx, 0.5 * ny * dx, zc * dx], "radius": radius * dx}
    scene = build_scene(backend, shape, units, ball, density=density, water_depth=depth * dx,
                        velocity=(0.0, 0.0, -abs(impact_speed)), **kw)  # fmt: skip
    scene.info.update(scene="sand_ball_into_water", radius_cells=radius, centre_cells=zc, depth_cells=depth,
                      impact_speed=impact_speed)  # fmt: skip
    return scene


def uniform_suspension(
    backend: Backend,
    shape: tuple[int, int, int] = (24, 10, 10),
    *,
    dx: float = 0.005,
    dt: float = 1e-4,
    density: float = 1500.0,
    sand_fraction: float = 0.3,
    layer: tuple[float, float] = (7.0, 15.0),
    **kw,
) -> CoupledScene:
    """A uniform suspension: a sand layer filling the cross-section between heights ``layer`` (cells) of a
    water column, periodic in x and y for the fluid.

    The fluid's gravity is replaced by the mean pressure gradient of a closed column, an upward
    acceleration a_f = (ϱ − ρ) ε g / (ρ (1 − ε)) per unit fluid mass in the layer's average (applied to all
    the water, whose mass over the layer's cross-section is what carries it): with it the total external
    force on fluid + sand is zero, as in a container whose floor carries the mixture's weight, so the
    suspension reaches a steady slip where node drag = weight − buoyancy (Eq. 31).  Without it a periodic
    box accelerates as a whole and the slip tends to the reduced-mass value instead.
    """
    nz, ny, nx = shape
    units = Units(dx=dx, dt=dt)
    # the layer less one cell at each side wall (the sand's 1-layer walls there)
    layer_box = _box((dx, dx, layer[0] * dx), ((nx - 1) * dx, (ny - 1) * dx, layer[1] * dx))
    # net sand weight per cell volume over the column, carried by the water of the column
    sand_cells = float((nx - 2) * (ny - 2) * (layer[1] - layer[0]))
    water_cells = nx * ny * nz - sand_fraction * sand_cells
    a_f = (density - RHO_W) * sand_fraction * sand_cells * G / (RHO_W * water_cells)
    scene = build_scene(backend, shape, units, layer_box, density=density, water_depth=None,
                        sand_fraction=sand_fraction, fluid_gravity=a_f, periodic_xy=True, wall_layers=1,
                        **kw)  # fmt: skip
    scene.info.update(scene="uniform_suspension", layer_cells=list(layer), fluid_acceleration=a_f)
    return scene


def saturated_bed(
    backend: Backend,
    shape: tuple[int, int, int] = (24, 16, 16),
    *,
    dx: float = 0.005,
    dt: float = 1e-4,
    density: float = 2500.0,
    bed_height: float = 8.0,
    water_depth: float = 16.0,
    **kw,
) -> CoupledScene:
    """A fully saturated sand bed ``bed_height`` cells deep at the bottom of a pool ``water_depth`` cells
    deep (paper: "full saturation" among the hard cases).  ``kw``: :func:`build_scene`."""
    nz, ny, nx = shape
    units = Units(dx=dx, dt=dt)
    bed = _box((dx, dx, dx), ((nx - 1) * dx, (ny - 1) * dx, bed_height * dx))
    kw.setdefault("wall_layers", 1)
    scene = build_scene(backend, shape, units, bed, density=density, water_depth=water_depth * dx, **kw)
    scene.info.update(scene="saturated_bed", bed_cells=bed_height, depth_cells=water_depth)
    return scene


def dry_plug_under_water(
    backend: Backend,
    shape: tuple[int, int, int] = (24, 8, 8),
    *,
    dx: float = 0.005,
    dt: float = 1e-4,
    density: float = 1500.0,
    plug: tuple[float, float] = (1.0, 12.0),
    water: tuple[float, float] = (12.0, 20.0),
    retention: bool = True,
    absorption_rate: float = 0.01,
    **kw,
) -> CoupledScene:
    """Paper Fig. 10 at small scale: a dry sand plug filling the cross-section between heights ``plug``
    (cells), a water layer on top of it (``water`` cells), air in the plug's pores and above the water.
    The water seeps into the plug; with ``retention`` the sand absorbs part of it (Eqs. 53–58)."""
    nz, ny, nx = shape
    units = Units(dx=dx, dt=dt)
    plug_box = _box((dx, dx, plug[0] * dx), ((nx - 1) * dx, (ny - 1) * dx, plug[1] * dx))
    # only the layer above the plug is water at the start: the plug's pores hold air
    layer = _box((0.0, 0.0, water[0] * dx), (nx * dx, ny * dx, water[1] * dx))
    kw.setdefault("wall_layers", 1)
    scene = build_scene(backend, shape, units, plug_box, density=density, water_depth=water[1] * dx, water=layer,
                        retention=retention, absorption_rate=absorption_rate, **kw)  # fmt: skip
    scene.info.update(scene="dry_plug_under_water", plug_cells=list(plug), water_cells=list(water), retention=retention)
    return scene


def bed_under_partition(
    backend: Backend,
    shape: tuple[int, int, int] = (16, 6, 28),
    *,
    dx: float = 0.005,
    dt: float = 1e-4,
    density: float = 1500.0,
    bed: float = 5.0,
    partition: tuple[float, float] = (8.0, 20.0),
    partition_top: float = 13.0,
    water_top: float = 12.0,
    retention: bool = True,
    absorption_rate: float = 0.01,
    **kw,
) -> CoupledScene:
    """Paper Fig. 10's geometry in a closed tank where the pores' air can leave: a dry sand bed ``bed`` cells
    deep on the floor, a partition wall (fluid obstacle) over it from x = ``partition`` cells, from the bed
    up to ``partition_top`` (the tank is higher: air passes over the wall), water up to ``water_top`` on
    the left of the wall only.  The water enters the bed on the left and seeps horizontally under the wall;
    the air it displaces rises in the right chamber and returns over the wall, so the front's advance under
    the wall is not limited by the air (unlike :func:`dry_plug_under_water`).  The fluid's floor (z = 0) and
    side walls (y = 0, ny − 1) are solid cells, so no sand-free channel runs along them.  ``kw``:
    :func:`build_scene`."""
    nz, ny, nx = shape
    units = Units(dx=dx, dt=dt)
    bed_box = _box((dx, dx, dx), ((nx - 1) * dx, (ny - 1) * dx, bed * dx))
    size = (nx * dx, ny * dx, nz * dx)
    obstacles = [
        _box((partition[0] * dx, 0.0, bed * dx), (partition[1] * dx, size[1], partition_top * dx)),
        # the fluid's floor (z = 0) and side walls (y = 0, ny - 1) one cell in: the MPM walls keep the sand out
        # of the outer node layer, so those cells hold only the B-spline tail of the bed (eps ~ 0.01) and were a
        # bypass channel along the floor (max |u| 0.13 there, measured) around the bed
        _box((0.0, 0.0, 0.0), (size[0], size[1], dx)),
        _box((0.0, 0.0, 0.0), (size[0], dx, size[2])),
        _box((0.0, size[1] - dx, 0.0), size),
    ]
    # water only left of the wall and above the bed: the bed's pores hold air at the start
    left = _box((0.0, 0.0, bed * dx), (partition[0] * dx, size[1], water_top * dx))
    kw.setdefault("wall_layers", 1)
    scene = build_scene(backend, shape, units, bed_box, density=density, water_depth=water_top * dx, water=left,
                        retention=retention, absorption_rate=absorption_rate, obstacles=obstacles, **kw)  # fmt: skip
    scene.info.update(scene="bed_under_partition", bed_cells=bed, partition_cells=list(partition),
                      partition_top=partition_top, water_top=water_top, retention=retention)  # fmt: skip
    return scene
