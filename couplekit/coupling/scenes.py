"""Coupled validation scenes built in Python at CPU-friendly sizes (paper 000 Figs. 8, 10, 13, 14):
a sand ball dropped into (or released inside) a water pool under air, a uniform suspension settling in a
closed water column, a saturated sand bed, and a dry sand plug under a water layer (wetting front).

Each builder returns a :class:`CoupledScene`: the FluidSolver, SandSolver, SandFluidCoupler and the
:class:`couplekit.schedulers.lockstep.LockstepScheduler` that advances them, plus the measurements the
tests and benchmarks use.  Conventions: z is up, shapes are ``(nz, ny, nx)``, SI in, lattice inside.

Choices (not in the paper; stated here once):

* Particle volume V_p = ε0 (dx/k)³ for k³ particles per cell, so a body's sand fraction is ε0 < ε_max and
  its mass ϱ ε0 V_cell: the sand density is the grain density of Eq. 31's balance, and sand of the water's
  density is neutrally buoyant, as paper Fig. 8's 950 kg/m³ ball "slightly lower than that of water"
  floats back up.  (With V_p = (dx/k)³, ε clamps at ε_max = 0.64 while the mass keeps ϱ V_cell: then the
  neutral density would be 0.64 ρ_w = 640 kg/m³.)
* The water starts at rest with its hydrostatic pressure (including the air column above it), and the
  water–air interface is the tanh profile of width ξ (text after Eq. 48).
* Fluid walls on every face (a closed tank); the sand's domain walls are "separate" with friction 0.5,
  2 node layers thick (1 for the bodies that fill the cross-section: bed, plug, suspension, so that the
  sand reaches the first cell and water cannot bypass it along the walls).
* Lattice viscosities of paper Table 1 (ν_h = 1e-4 water, ν_l = 1e-2 air) unless given; surface tension
  0.073 N/m; density ratio 800:1; volume controller η = 2.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..backend import Backend
from ..fluid.grid import Boundaries
from ..fluid.phasefield_layout import tanh_profile
from ..fluid.solver import FluidParams, FluidSolver
from ..sand import SandParams
from ..sand.boundaries import DomainWalls
from ..sand.seeding import Seeded, seed_box, seed_sphere
from ..sand.solver import SandSolver
from ..units import Units
from .coupler import SandFluidCoupler
from .params import CouplingParams

__all__ = [
    "CoupledScene",
    "bed_under_partition",
    "build_scene",
    "dry_plug_under_water",
    "saturated_bed",
    "sand_ball_into_water",
    "uniform_suspension",
]

G = 9.81
RHO_W = 1000.0
RHO_AIR = 1000.0 / 800.0


@dataclass
class CoupledScene:
    """A built coupled scene and what it is measured by (see the module docstring)."""

    fluid: FluidSolver
    sand: SandSolver
    coupler: SandFluidCoupler
    units: Units
    scheduler: object = field(repr=False)
    water_level: float = 0.0  # initial water surface height, m (0: no free surface)
    info: dict = field(default_factory=dict)

    def step(self, n: int = 1) -> None:
        """``n`` lockstep steps (Algorithm 1)."""
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


def _hydrostatic(phi: np.ndarray, rho_l: float, g_lat: float) -> np.ndarray:
    """p(z) = Σ_{z' above} ρ(φ) |g| (lattice), integrated down from the lid, per column."""
    rho = rho_l + (1.0 - rho_l) * np.clip(phi.astype(np.float64), 0.0, 1.0)
    above = np.cumsum(rho[::-1], axis=0)[::-1] - 0.5 * rho  # cell-centred integral from the top
    return (abs(g_lat) * above).astype(np.float32)


def build_scene(
    backend: Backend,
    shape: tuple[int, int, int],
    units: Units,
    seeded: Seeded,
    *,
    density: float,
    water_depth: float | None,
    sand_fraction: float = 0.55,
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0),
    nu_h: float = 1e-4,
    nu_l: float = 1e-2,
    surface_tension: float = 0.073,
    eta: float = 2.0,
    source_term: bool = True,
    coupling: CouplingParams | None = None,
    youngs_modulus: float = 3.5e5,
    moisture: float = 0.0,
    fluid_gravity: float | None = None,
    timing: bool = False,
    periodic_xy: bool = False,
    wall_layers: int = 2,
    sand_params: dict | None = None,
    smagorinsky: float = 0.0,
    odd_lambda: float | None = None,
    solid: np.ndarray | None = None,
) -> CoupledScene:
    """The common builder: a closed tank (``shape`` cells, ``units``) of water up to ``water_depth`` m
    (``None``: single-phase water everywhere) under air, and the sand particles ``seeded`` (positions in m)
    with sand fraction ``sand_fraction`` and grain ``density``, moving at ``velocity`` m/s.

    ``fluid_gravity``: the fluid's vertical acceleration in m/s² (default −g; the settling test replaces it
    by the mean pressure gradient of a closed column, see :func:`uniform_suspension`).  ``periodic_xy``:
    periodic fluid faces in x and y; ``wall_layers``: node layers of the sand's domain walls (particles must
    start inside them); ``sand_params``: further SandParams fields (e.g. cohesion); ``smagorinsky``,
    ``odd_lambda``: the fluid's closures (FluidParams; docs/fluid-stability.md; None = FluidParams' default).  The rest: module docstring.
    ``solid``: (nz, ny, nx) mask of the fluid's stationary obstacle cells (e.g. a partition wall), or None.
    """
    nz, ny, nx = shape
    dx = units.dx
    g_fluid = -G if fluid_gravity is None else float(fluid_gravity)
    g_lat = units.to_lattice(g_fluid, "acceleration")
    two_phase = water_depth is not None
    rho_l = RHO_AIR / RHO_W if two_phase else 1.0
    zc = (np.arange(nz) + 0.5) * dx
    phi = None
    if two_phase:
        width = 4.0
        prof = tanh_profile((water_depth - zc) / dx, width)
        phi = np.broadcast_to(prof[:, None, None], shape).astype(np.float32).copy()
        pressure = _hydrostatic(phi, rho_l, g_lat)
    else:
        pressure = _hydrostatic(np.ones(shape, np.float32), 1.0, g_lat)
    sigma = units.to_lattice(surface_tension, "surface_tension") if two_phase else 0.0
    params = FluidParams(rho_h=1.0, rho_l=rho_l, nu_h=nu_h, nu_l=nu_l if two_phase else nu_h, gravity=(0.0, 0.0, g_lat),
                         sigma=sigma, eta=eta if two_phase else 0.0, smagorinsky=smagorinsky,
                         **({} if odd_lambda is None else {"odd_lambda": odd_lambda}))  # fmt: skip
    bounds = Boundaries.channel("z" if periodic_xy else "xyz")
    fluid = FluidSolver(backend, shape, params, boundaries=bounds, phi=phi, pressure=pressure, mixture=True,
                        external_force=True, solid=solid)  # fmt: skip
    ppc = round((dx**3 / float(seeded.volume[0])) ** (1.0 / 3.0))
    vol = sand_fraction * dx**3 / ppc**3
    vel = np.repeat(np.asarray(velocity, np.float64)[:, None], seeded.count, axis=1)
    sand = SandSolver(backend, shape, dx, units.dt, SandParams(density=density, youngs_modulus=youngs_modulus, **(sand_params or {})),
                      seeded.x, vol, velocities=vel, gravity=(0.0, 0.0, -G),
                      walls=DomainWalls.uniform("separate", 0.5, wall_layers))  # fmt: skip
    coupler = SandFluidCoupler(sand, fluid, units, coupling or CouplingParams(), moisture=moisture)
    from ..schedulers.lockstep import LockstepScheduler

    sched = LockstepScheduler(fluid, sand, coupler, source_term=source_term, timing=timing)
    info = {"shape": list(shape), "dx": dx, "dt": units.dt, "density": density, "particles": int(seeded.count),
            "sand_fraction": sand_fraction, "nu_h": nu_h, "nu_l": nu_l}  # fmt: skip
    return CoupledScene(fluid, sand, coupler, units, sched, float(water_depth or 0.0), info)


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
    seeded = seed_sphere((0.5 * nx * dx, 0.5 * ny * dx, zc * dx), radius * dx, dx, ppc=2)
    scene = build_scene(backend, shape, units, seeded, density=density, water_depth=depth * dx,
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
    seeded = seed_box((0.0, 0.0, layer[0] * dx), (nx * dx, ny * dx, layer[1] * dx), dx, ppc=2)
    keep = (seeded.x[0] > dx) & (seeded.x[0] < (nx - 1) * dx) & (seeded.x[1] > dx) & (seeded.x[1] < (ny - 1) * dx)
    seeded = Seeded(seeded.x[:, keep], seeded.volume[keep])
    # net sand weight per cell volume over the column, carried by the water of the column
    sand_cells = float(keep.sum()) * 0.125
    water_cells = nx * ny * nz - sand_fraction * sand_cells
    a_f = (density - RHO_W) * sand_fraction * sand_cells * G / (RHO_W * water_cells)
    scene = build_scene(backend, shape, units, seeded, density=density, water_depth=None,
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
    seeded = seed_box((dx, dx, dx), ((nx - 1) * dx, (ny - 1) * dx, bed_height * dx), dx, ppc=2)
    kw.setdefault("wall_layers", 1)
    scene = build_scene(backend, shape, units, seeded, density=density, water_depth=water_depth * dx, **kw)
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
    seeded = seed_box((dx, dx, plug[0] * dx), ((nx - 1) * dx, (ny - 1) * dx, plug[1] * dx), dx, ppc=2)
    coupling = CouplingParams(retention=retention, absorption_rate=absorption_rate)
    kw.setdefault("wall_layers", 1)
    scene = build_scene(backend, shape, units, seeded, density=density, water_depth=water[1] * dx,
                        coupling=coupling, **kw)  # fmt: skip
    # only the layer above the plug is water at the start: the plug's pores hold air
    zc = np.arange(nz) + 0.5
    prof = tanh_profile(water[1] - zc, 4.0) * tanh_profile(zc - water[0], 4.0)
    _set_phase(scene.fluid, np.broadcast_to(prof[:, None, None], shape).astype(np.float32))
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
    seeded = seed_box((dx, dx, dx), ((nx - 1) * dx, (ny - 1) * dx, bed * dx), dx, ppc=2)
    xc = np.arange(nx) + 0.5
    zc = np.arange(nz) + 0.5
    solid = np.zeros(shape, bool)
    wall_x = (xc > partition[0]) & (xc < partition[1])
    wall_z = (zc > bed) & (zc < partition_top)
    solid[wall_z[:, None, None] & wall_x[None, None, :] & np.ones((1, ny, 1), bool)] = True
    # the fluid's floor and side walls one cell in: the MPM walls keep the sand out of the outer node layer,
    # so those cells hold only the B-spline tail of the bed (eps ~ 0.01) and were a bypass channel along the
    # floor (max |u| 0.13 there, measured) around the bed
    solid[0] = True
    solid[:, 0] = solid[:, ny - 1] = True
    coupling = CouplingParams(retention=retention, absorption_rate=absorption_rate)
    kw.setdefault("wall_layers", 1)
    scene = build_scene(backend, shape, units, seeded, density=density, water_depth=water_top * dx,
                        coupling=coupling, solid=solid, **kw)  # fmt: skip
    # water only left of the wall and above the bed: the bed's pores hold air at the start
    ramp_z = tanh_profile(water_top - zc, 4.0) * tanh_profile(zc - bed, 4.0)
    ramp_x = tanh_profile(partition[0] - xc, 4.0)
    prof = ramp_z[:, None, None] * ramp_x[None, None, :] * np.ones((1, ny, 1))
    _set_phase(scene.fluid, prof.astype(np.float32))
    scene.info.update(scene="bed_under_partition", bed_cells=bed, partition_cells=list(partition),
                      partition_top=partition_top, water_top=water_top, retention=retention)  # fmt: skip
    return scene


def _set_phase(fluid: FluidSolver, phi: np.ndarray) -> None:
    """Replace the phase field of a fresh two-phase solver (populations at equilibrium with the fluid at rest)
    and its reference volume."""
    be = fluid.backend
    host = be.to_host(fluid.phi)
    host[1:-1, 1:-1, 1:-1] = phi
    fluid.phi = be.asarray(host)
    fluid.pf_ops.set_equilibrium(fluid.h, fluid.phi, fluid.velocity, fluid.flags, fluid.step_count)
    fluid._phase_macroscopic()
    rho = fluid.params.rho_l + (1.0 - fluid.params.rho_l) * np.clip(phi.astype(np.float64), 0.0, 1.0)
    g = abs(fluid.params.gravity[2])
    above = np.cumsum(rho[::-1], axis=0)[::-1] - 0.5 * rho
    p = be.to_host(fluid.p)
    p[1:-1, 1:-1, 1:-1] = g * above
    fluid.p = be.asarray(p.astype(np.float32))
    fluid.reset_volume_reference()
