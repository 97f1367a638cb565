"""``Simulation``: a scene turned into solvers, stepped, written out, checkpointed and restarted exactly.

>>> import couplekit as ck
>>> sim = ck.Simulation(ck.Scene.load("examples/sand_drop_small.toml"), backend="auto")
>>> sim.run(frames=20, out="runs/sand_drop")     # progress bar; .vti/.vtp/.pvd, PLY, PNG, diagnostics, HDF5
>>> sim.fields(), sim.particles(), sim.diagnostics()
>>> sim.save("x.h5"); sim2 = ck.Simulation.load("x.h5")   # bitwise restart on the cpu backend

Scenes: fluid-only (:class:`couplekit.fluid.solver.FluidSolver`, one or two phases, obstacles as
bounce-back cells, whole-face inflows and outflows), sand-only (:class:`couplekit.sand.solver.SandSolver`,
obstacles as an SDF collider), and both, coupled by :class:`couplekit.coupling.coupler.SandFluidCoupler`
(drag, buoyancy, the phase-field source term, water retention). Every scene is stepped by
:class:`couplekit.schedulers.lockstep.LockstepScheduler` (paper Algorithm 1: one MPM step per LBM step, same
Δt), which times every stage: :meth:`Simulation.stage_times`, :meth:`Simulation.cost_report`, a cost line at
the end of :meth:`Simulation.run` and ``step_seconds`` in the diagnostics. Refused with
:class:`CouplingUnavailableError`: what the coupler cannot do yet (drag or buoyancy switched off).  Sand
bodies with and without retention in one scene (``bodies[*].retention``, paper Fig. 10) pass per-particle
flags to the coupler: only the retentive sand has retention capacity and gains bound water.

Water jets carrying sand (``inflows[*].sand_fraction`` > 0, paper Fig. 1): :class:`couplekit.sand.emission.
InflowEmitter` (:attr:`Simulation.emitter`) appends a layer of particles after every step in which a jet has
advanced one particle spacing, so the sand flux is sand_fraction × area × normal speed and the jet's sand
fraction is sand_fraction; a scene whose only sand comes from jets starts with an empty SandSolver and the
coupled solvers from the first step. Its accumulators are part of the checkpoint (group ``emission``), and a
resumed run grows the particle arrays to the checkpoint's count, so the restart stays bitwise. Sand bodies may have different densities
(``bodies[*].density``, paper Fig. 8): each particle carries its body's.

Seeding (as :mod:`couplekit.coupling.scenes` does): a sand body gets ``particles_per_cell`` particles per
cell, each of volume V_p = ε0 dx³ / particles_per_cell with ε0 = ``sand.packing_fraction`` (default 0.6, at
most ε_max = 0.64) and mass ϱ V_p with ϱ the body's ``density``. So a body's sand fraction (Eq. 25) is ε0 and
ϱ is the grain density, the ϱ of paper Eq. 31's balance (sand weight ϱ ε V_cell g against the buoyancy
ρ_f ε V_cell g): sand lighter than water rises, as paper Fig. 8's 950 kg/m³ ball does. (With V_p = dx³ /
particles_per_cell, ε would clamp at ε_max while the mass stayed ϱ V_cell, and the neutral density would be
0.64 ρ_w.)

The fluid starts hydrostatic when gravity lies along one non-periodic axis (:func:`hydrostatic_pressure`:
p = ∫ ρ(φ) g along each column, in lattice units), so water at rest stays at rest instead of ringing with the
pressure wave of a start from p = 0.

Before anything is allocated the constructor prints the backend and why it was chosen, and a memory
estimate; a scene that will not fit the device (or the host's available memory) is refused
(:class:`InsufficientMemoryError`). After every frame the fields are checked for NaN/Inf; on a hit the
frame is replayed step by step from the last good state to name the first bad step, the field and the cell
(:class:`SimulationDiverged`), and ``run`` writes that last good state as a checkpoint.
"""

from __future__ import annotations

import math
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .backend import Backend, get_backend
from .lattice import CS2
from .scene import Scene
from .scene.geometry import Union, sdf_on_grid

__all__ = [
    "Simulation",
    "SimulationDiverged",
    "CouplingUnavailableError",
    "InsufficientMemoryError",
    "memory_estimate",
    "hydrostatic_pressure",
    "RunResult",
]

_FACE = {"x_min": "x-", "x_max": "x+", "y_min": "y-", "y_max": "y+", "z_min": "z-", "z_max": "z+"}
_SAND_FACE = {"x_min": "-x", "x_max": "+x", "y_min": "-y", "y_max": "+y", "z_min": "-z", "z_max": "+z"}


class CouplingUnavailableError(NotImplementedError):
    """The scene needs fluid–sand coupling, which is not built yet."""


class InsufficientMemoryError(MemoryError):
    """The memory estimate of a scene exceeds what the device (or host) has available."""


class SimulationDiverged(FloatingPointError):
    """A NaN or Inf appeared: ``step`` (first bad step), ``solver``, ``field``, ``index`` (cell (x, y, z) or
    particle number)."""

    def __init__(self, step: int, solver: str, field: str, index: tuple, value: float, where: str):
        self.step, self.solver, self.field, self.index, self.value = step, solver, field, index, value
        super().__init__(f"non-finite value {value} in {solver} field {field!r} at {where} {index} after step {step}")


def _refuse_unsupported(scene: Scene) -> None:
    """Refuse, before allocation, what the coupler cannot do yet (CouplingUnavailableError naming the key)."""
    problems = []
    if scene.has_sand:
        if scene.has_fluid:
            for key in ("drag", "buoyancy"):
                if not getattr(scene.effects, key):
                    problems.append(f"effects.{key} = false: the coupler has no switch for it")
    if problems:
        raise CouplingUnavailableError(
            f"scene {scene.name!r} needs what the coupling module does not do yet: " + "; ".join(problems)
        )


def hydrostatic_pressure(
    shape: tuple[int, int, int],
    gravity: tuple[float, float, float],
    phi: np.ndarray | None = None,
    rho_l: float = 1.0,
    boundary: dict[str, str] | None = None,
    interface_width: float = 4.0,
) -> np.ndarray | None:
    """The hydrostatic pressure (nz, ny, nx) of a fluid at rest in FluidSolver's lattice units (water ρ = 1,
    ``gravity`` the lattice acceleration), or None when there is none to set: no gravity, gravity not along
    one axis, or periodic faces (``boundary``, scene face names) along it.

    Per column along gravity, from the face gravity points away from (p = 0 there): p_k = |g| (Σ_{k' above k}
    ρ_k' + ρ_k / 2), the cell-centred integral of ρ g, with ρ = ρ_l + (1 − ρ_l) φ of the two-phase mixture
    (``phi``; None: single-phase water, ρ = 1). Then −∇p/ρ + g = 0 to second order (Eq. 15's pressure and
    gravity terms) and a tank at rest starts at rest, without the pressure wave a start from p = 0 sends
    through it (the water falls by g Δt in the first step, the floor stops it, and it rings with a speed of
    order |g| H / c_s). Obstacles are integrated through with the φ they were given (the water's SDF ignores
    them): right under a submerged obstacle, irrelevant inside one.

    Only water that rests on the floor is carried: per column, the water's excess weight (ρ − ρ_l) g counts up
    to the top of the segment of cells with φ ≥ ½ that starts at the floor, plus 2 ``interface_width`` + 1
    cells of the interface above it. Water that hangs in the air (a drop, a poured block)
    adds nothing, so the air under and beside it keeps its own hydrostatic pressure: integrated straight
    through, the weight of a hanging block sat on the floor under it, and the step in pressure at the edge of
    its column blew the air out sideways (Fig. 17's poured block: 5.75 m/s in the first step, NaN by step 7).
    """
    g = np.asarray(gravity, np.float64)
    axes = np.flatnonzero(g)
    if len(axes) != 1:
        return None
    a = int(axes[0])  # 0 = x, 1 = y, 2 = z
    if boundary and boundary.get(f"{'xyz'[a]}_min") == "periodic":
        return None
    if phi is None:
        rho = np.ones(tuple(shape), np.float64)
    else:
        rho = rho_l + (1.0 - rho_l) * np.clip(np.asarray(phi, np.float64), 0.0, 1.0)
    r = np.moveaxis(rho, 2 - a, 0)  # array axes are (z, y, x)
    down = slice(None, None, -1) if g[a] < 0 else slice(None)  # from the face gravity points away from
    rd = r[down]
    n = rd.shape[0]
    # height (cells from the floor) of the water segment resting on the floor, plus the interface's tail
    water_up = (rd >= 0.5 * (1.0 + rho_l))[::-1]  # from the floor up
    resting = np.cumprod(water_up, axis=0).sum(axis=0)
    top = resting + int(np.ceil(2.0 * interface_width)) + 1
    level = np.arange(n)[::-1].reshape((n,) + (1,) * (rd.ndim - 1))  # height of each cell of rd above the floor
    carried = np.where(level < top, rd - rho_l, 0.0)
    above = np.cumsum(rho_l + carried, axis=0) - 0.5 * (rho_l + carried)
    return np.moveaxis((abs(g[a]) * above)[down], 0, 2 - a).astype(np.float32)


# ---------------------------------------------------------------------------------------------- memory
_FLUID_FLOATS_PER_CELL = 27 + 3 + 3 + 1 + 1  # f, velocity, wall velocity, p, pbar
_PHASE_FLOATS_PER_CELL = 7 + 1 + 3 + 1 + 1  # h, phi, grad phi, mu, source term
_SAND_FLOATS_PER_NODE = 1 + 3 + 1 + 3 + 3 + 1  # mass, momentum, volume, velocity, f_ext, sdf
_SAND_FLOATS_PER_PARTICLE = 3 + 3 + 9 + 9 + 6 + 1 + 1 + 1 + 1 + 1  # x v C F tau q vc saturation mass volume


def memory_estimate(scene: Scene) -> dict[str, float]:
    """Bytes the solvers will allocate for ``scene`` (an estimate from the array sizes, before allocation).

    Particles are bounded by the sand bodies' bounding boxes × particles per cell (an upper bound), plus the
    particles the sand-carrying inflows emit over the scene's duration (``emitted_particles``,
    :func:`couplekit.sand.emission.expected_particles`)."""
    nx, ny, nz = scene.domain.resolution
    padded = (nx + 2) * (ny + 2) * (nz + 2)
    out = {"fluid": 0.0, "sand_grid": 0.0, "particles": 0.0, "particle_count": 0.0}
    if scene.fluid is not None:
        floats = _FLUID_FLOATS_PER_CELL + (_PHASE_FLOATS_PER_CELL if scene.fluid.phases == 2 else 0)
        out["fluid"] = padded * (4 * floats + 1)  # + 1 byte of flags
    if scene.has_sand:
        out["sand_grid"] = 4.0 * _SAND_FLOATS_PER_NODE * nx * ny * nz
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
        out["particles"] = 4.0 * _SAND_FLOATS_PER_PARTICLE * count
    if scene.fluid is not None and scene.has_sand:
        # fluid mixture inputs (fluid_fraction, sand_velocity, force) and the coupler's fields
        flags = {b.retention if b.retention is not None else scene.sand.retention for b in scene.bodies
                 if b.kind == "sand"}  # fmt: skip
        retention, mixed = True in flags, len(flags) > 1  # mixed: + retentive fraction grid and flags
        out["coupling"] = padded * 4.0 * (7 + 1 + 3 + 1) + nx * ny * nz * 4.0 * (1 + (3 + mixed if retention else 0))
        out["particles"] += 4.0 * count * ((1 + mixed) if retention else 0)
    if scene.fluid is not None and getattr(scene, "stirring", None) is not None:
        # the stirring force's buffer, plus the force input a fluid-only scene would not have
        out["stirring"] = padded * 4.0 * (3 if scene.has_sand else 6)
    out["total"] = (
        out["fluid"] + out["sand_grid"] + out["particles"] + out.get("coupling", 0.0) + out.get("stirring", 0.0)
    )
    return out


def available_memory(backend: Backend) -> tuple[float, str]:
    """(bytes, what): free device memory on cuda, MemAvailable of the host otherwise."""
    if backend.name == "cuda":
        import cupy

        free, _total = cupy.cuda.runtime.memGetInfo()
        return float(free), "free GPU memory"
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0, "available host memory"
    except OSError:
        pass
    return math.inf, "host memory (unknown)"


def _gib(b: float) -> str:
    return f"{b / 2**30:.3g} GiB" if b >= 2**28 else f"{b / 2**20:.3g} MiB"


# ---------------------------------------------------------------------------------------------- results
class RunResult(dict):
    """What :meth:`Simulation.run` did: ``status`` ("done", "interrupted", "diverged"), ``frames``,
    ``steps``, ``out`` (folder), ``checkpoint`` (last checkpoint written), ``error`` (for "diverged")."""

    @property
    def status(self) -> str:
        return self["status"]


# ---------------------------------------------------------------------------------------------- simulation
class Simulation:
    """Solvers built from a :class:`~couplekit.scene.Scene` (or a scene file path).

    backend: ``"auto"``, ``"cuda"``, ``"cpu"``, ``"numpy"`` or a :class:`Backend`; threads: OpenMP threads
    of the cpu backend; log: where the start-up report goes (``None`` for silence); check_memory: refuse
    a scene whose estimate exceeds the available memory; timing: time every stage of every step
    (:meth:`stage_times`, :meth:`cost_report`; on a GPU this costs one synchronisation per stage).

    Every scene is stepped by a :class:`couplekit.schedulers.lockstep.LockstepScheduler` (:attr:`scheduler`):
    fluid-only and sand-only scenes run their solver's stages, coupled scenes paper Algorithm 1.
    """

    def __init__(
        self,
        scene: Scene | str | Path,
        backend: str | Backend | None = "auto",
        threads: int | None = None,
        log: Callable[[str], Any] | None = print,
        check_memory: bool = True,
        timing: bool = True,
    ):
        self.scene = scene if isinstance(scene, Scene) else Scene.load(scene)
        sc = self.scene
        self._log = log or (lambda s: None)
        self._preview_failed = False
        self.coupled = sc.has_fluid and sc.has_sand
        _refuse_unsupported(sc)
        self.backend = backend if isinstance(backend, Backend) else get_backend(backend, threads=threads)
        self._log(self.backend.describe())
        self._log(sc.summary())
        est = memory_estimate(sc)
        avail, what = available_memory(self.backend)
        counts = ("total", "particle_count", "emitted_particles")
        parts = ", ".join(f"{k} {_gib(v)}" for k, v in est.items() if k not in counts and v)
        self._log(f"memory estimate: {_gib(est['total'])} ({parts}); {what}: {_gib(avail)}")
        if est.get("emitted_particles"):
            self._log(
                f"sand jets: about {est['emitted_particles']:,.0f} particles emitted over {sc.time.frames} frames "
                f"(of {est['particle_count']:,.0f} in all)"
            )
        if check_memory and est["total"] > 0.9 * avail:
            raise InsufficientMemoryError(
                f"scene {sc.name!r} needs about {_gib(est['total'])} but only {_gib(avail)} of {what} is free: "
                "use a coarser domain.dx, fewer sand.particles_per_cell, or a larger device"
            )
        self.memory = est
        self.units = sc.units()
        self.steps_per_frame = sc.time.steps_per_frame
        self.step_count = 0
        self.fluid = self.sand = self.coupler = self.scheduler = self.emitter = None
        self._timing = bool(timing)
        self._rebuild()

    # ------------------------------------------------------------------------------------ building
    def _shape_of(self, kind: str) -> Union | None:
        shapes = [
            b.geometry.shape(self.scene.domain, 0.25 * self.scene.domain.dx)
            for b in self.scene.bodies
            if b.kind == kind
        ]
        return Union(shapes) if shapes else None

    def _water_shape(self) -> Union | None:
        """Water bodies for the initial φ. A box face, or a height field's side or base, lying on the domain
        boundary is pushed out by 10 cells, so water that fills the shape up to a wall has no interface (a
        tanh drop) along that wall."""
        from .scene.geometry import Box
        from .scene.mesh import HeightField, load_heights

        dom = self.scene.domain
        size, pad = np.asarray(dom.size), 10 * dom.dx
        shapes = []
        for b in self.scene.bodies:
            if b.kind != "water":
                continue
            g = b.geometry
            if g.type == "box" and g.scale == 1.0 and not any(g.rotate) and not g.invert:
                lo = np.asarray(g.params["min"], float) + np.asarray(g.translate)
                hi = np.asarray(g.params["max"], float) + np.asarray(g.translate)
                tol = 1e-9 * size.max()
                lo = np.where(lo <= tol, lo - pad, lo)
                hi = np.where(hi >= size - tol, hi + pad, hi)
                shapes.append(Box(lo, hi))
            elif (
                g.type == "heightfield"
                and g.scale == 1.0
                and not any(g.rotate)
                and not any(g.translate)
                and not g.invert
            ):
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
                if x0 <= tol:
                    h, x0 = np.concatenate([np.repeat(h[:, :1], nx_pad, axis=1), h], axis=1), x0 - nx_pad * sx
                if x1 >= size[0] - tol:
                    h, x1 = np.concatenate([h, np.repeat(h[:, -1:], nx_pad, axis=1)], axis=1), x1 + nx_pad * sx
                if y0 <= tol:
                    h, y0 = np.concatenate([np.repeat(h[:1], ny_pad, axis=0), h], axis=0), y0 - ny_pad * sy
                if y1 >= size[1] - tol:
                    h, y1 = np.concatenate([h, np.repeat(h[-1:], ny_pad, axis=0)], axis=0), y1 + ny_pad * sy
                shape = HeightField(h, (x0, x1), (y0, y1), base, 0.25 * dom.dx)
                shapes.append(shape)
            else:
                shapes.append(g.shape(dom, 0.25 * dom.dx))
        return Union(shapes) if shapes else None

    def _build_fluid(self):
        from .fluid.grid import Boundaries, Face, InflowRegion
        from .fluid.inflow import region_mask
        from .fluid.solver import FluidParams, FluidSolver

        sc, u = self.scene, self.units
        fl, dom, eff = sc.fluid, sc.domain, sc.effects
        two = fl.phases == 2
        prm = FluidParams(
            rho_h=1.0,
            rho_l=fl.air_density / fl.water_density if two else 1.0,
            nu_h=fl.water_lattice_viscosity,
            nu_l=fl.air_lattice_viscosity if two else fl.water_lattice_viscosity,
            gravity=tuple(u.to_lattice(g, "acceleration") for g in dom.gravity),
            sigma=u.to_lattice(fl.surface_tension, "surface_tension") if two and eff.surface_tension else 0.0,
            mobility=fl.mobility,
            width=fl.interface_width,
            eta=fl.controller_eta if eff.volume_controller else 0.0,
            odd_lambda=fl.odd_lambda,
            smagorinsky=fl.smagorinsky,
        )
        inflow = {i.face: i for i in sc.inflows if i.shape == "face"}
        faces, regions = {}, []
        for name, kind in dom.boundary.items():
            if kind == "inflow":
                i = inflow[name]
                vel = tuple(u.to_lattice(v, "velocity") for v in i.velocity)
                faces[_FACE[name]] = Face("inflow", vel, 1.0 if i.kind == "water" else 0.0)
            else:
                faces[_FACE[name]] = Face(kind)
        for i in sc.inflows:  # outlets: inflow on part of a wall / outflow face (couplekit.fluid.inflow)
            if i.shape != "face":
                vel = tuple(u.to_lattice(v, "velocity") for v in i.velocity)
                mask = region_mask(dom.shape, dom.dx, _FACE[i.face], i.shape, i.center, i.size, i.radius)
                regions.append(InflowRegion(_FACE[i.face], mask, vel, 1.0 if i.kind == "water" else 0.0))
        obstacles = self._shape_of("obstacle")
        solid = sdf_on_grid(obstacles, dom.resolution, dom.dx) < 0 if obstacles else None
        phi = velocity = None
        if two:
            water = self._water_shape()
            if water is None:
                phi = np.zeros(dom.shape, np.float32)
            else:
                d_cells = sdf_on_grid(water, dom.resolution, dom.dx).astype(np.float64) / dom.dx
                phi = (0.5 * (1.0 - np.tanh(2.0 * d_cells / fl.interface_width))).astype(
                    np.float32
                )  # text after Eq. 48
            for b in sc.bodies:
                if b.kind == "water" and any(b.velocity):
                    if velocity is None:
                        velocity = np.zeros((3, *dom.shape))
                    inside = sdf_on_grid(b.geometry.shape(dom, 0.25 * dom.dx), dom.resolution, dom.dx) < 0
                    for c in range(3):
                        velocity[c][inside] = u.to_lattice(b.velocity[c], "velocity")
        pressure = hydrostatic_pressure(
            dom.shape, prm.gravity, phi if two else None, prm.rho_l, dom.boundary, fl.interface_width
        )
        if pressure is None and any(prm.gravity):
            self._log("note: no hydrostatic start (gravity not along one non-periodic axis): the fluid starts at p = 0")
        self._fluid_params = prm
        fluid = FluidSolver(
            self.backend,
            dom.shape,
            prm,
            Boundaries(faces, tuple(regions)),
            solid=solid,
            phi=phi,
            velocity=velocity,
            pressure=pressure,
            mixture=self.coupled,
            external_force=self.coupled or sc.stirring is not None,
        )
        if sc.stirring is not None:  # the swirl of [stirring], added to the force input (couplekit.scene.forces)
            from .scene.forces import StirringForce

            StirringForce(sc.stirring, dom, u).attach(fluid)
        return fluid

    def _build_sand(self):
        from .sand.boundaries import DomainWalls, SdfCollider, Wall
        from .sand.params import SandParams
        from .sand.seeding import seed_sdf
        from .sand.solver import SandSolver

        sc = self.scene
        sd, dom, eff = sc.sand, sc.domain, sc.effects
        bodies = [b for b in sc.bodies if b.kind == "sand"]
        if not self.coupled and any(b.retention if b.retention is not None else sd.retention for b in bodies):
            self._log("note: water retention has no effect in a sand-only scene (no water to retain)")
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
        )
        xs, vols, vels, dens, retains = [], [], [], [], []
        size = np.asarray(dom.size)
        for i, b in enumerate(bodies):
            shape = b.geometry.shape(dom, 0.25 * dom.dx)
            lo, hi = shape.bounds()
            lo, hi = np.maximum(lo, 0.0), np.minimum(hi, size)
            seeded = seed_sdf(shape.sdf, lo, hi, dom.dx, sd.particles_per_axis, sd.jitter, sd.seed + i)
            if seeded.count == 0:
                raise ValueError(f"sand body {b.name!r} is thinner than the particle spacing: no particle seeded")
            xs.append(seeded.x)
            vols.append(sd.packing_fraction * seeded.volume)  # grain volume: ε0 of the sub-cell (module doc)
            vels.append(np.repeat(np.asarray(b.velocity, np.float64)[:, None], seeded.count, axis=1))
            dens.append(np.full(seeded.count, b.density or sd.density))  # per-body grain density
            retains.append(np.full(seeded.count, b.retention if b.retention is not None else sd.retention))
        # per-particle water retention (bodies[*].retention, paper Fig. 10): the coupler's retentive flags
        self._sand_retentive = np.concatenate(retains) if retains else np.zeros(0, bool)
        if not xs:  # the sand only enters through inflows (couplekit.sand.emission)
            xs, vols, vels, dens = [np.zeros((3, 0))], [np.zeros(0)], [np.zeros((3, 0))], [np.zeros(0)]
        walls = DomainWalls.from_dict({_SAND_FACE[f]: Wall("separate", sd.wall_friction) for f in dom.boundary})
        obstacles = [b for b in sc.bodies if b.kind == "obstacle"]
        collider = None
        if obstacles:
            union = Union([b.geometry.shape(dom, 0.25 * dom.dx) for b in obstacles])
            friction = max(b.friction if b.friction is not None else sd.wall_friction for b in obstacles)
            collider = SdfCollider(lambda p, t, s=union: s.sdf(p), mode="separate", friction=friction)
        return SandSolver(
            self.backend,
            dom.shape,
            dom.dx,
            sc.time.dt,
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
            allow_empty=sc.emits_sand,
        )

    # ------------------------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Simulated time, s (step count × dt)."""
        return self.step_count * self.scene.time.dt

    @property
    def frame(self) -> int:
        """Completed frames."""
        return self.step_count // self.steps_per_frame

    @property
    def effects(self) -> dict[str, bool]:
        """Which effects are on (DESIGN 'Effects'): decided by the scene's content and its [effects] table."""
        sc, fl = self.scene, self.scene.fluid
        two = bool(fl and fl.phases == 2)
        sand = self.sand is not None
        return {
            "fluid": fl is not None,
            "phase_field": two,
            "surface_tension": bool(two and self.fluid and self.fluid.surface_tension),
            "volume_controller": bool(two and self._fluid_params.eta > 0) if self.fluid else False,
            "obstacles": any(b.kind == "obstacle" for b in sc.bodies),
            "inflows": bool(sc.inflows),
            "stirring": sc.stirring is not None,
            "sand": sand,
            "sand_emission": self.emitter is not None,
            "cohesion": bool(sand and self.sand.params.cohesion_on),
            "hardening": bool(sand and self.sand.params.hardening),
            "coupling": self.coupler is not None,
            "drag": self.coupler is not None,
            "buoyancy": self.coupler is not None,
            "source_term": bool(self.coupler is not None and two and sc.effects.source_term),
            "retention": bool(self.coupler is not None and self.coupler.retention),
        }

    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps (every solver in the scene) through :attr:`scheduler`."""
        n = int(n)
        if self.emitter is None:
            self.scheduler.step(n)
            self.step_count += n
            return
        for _ in range(n):  # sand jets: the layers completed by this step enter after it (sand.emission)
            self.scheduler.step(1)
            self.step_count += 1
            self.emitter.advance(self.sand, self.scene.time.dt)

    def stage_times(self) -> dict[str, float]:
        """Seconds spent in each stage of the last step, in execution order
        (:meth:`couplekit.schedulers.lockstep.LockstepScheduler.stage_times`; empty with ``timing=False``)."""
        return self.scheduler.stage_times()

    def cost_report(self) -> dict[str, dict[str, float]]:
        """Per stage over every timed step since the solvers were built (or :meth:`reset_timing`), except the
        first step of fresh solvers, which loads (or compiles) the kernels: ``total`` s, ``mean`` s per step,
        ``fraction`` of the step."""
        return self.scheduler.cost_report()

    def reset_timing(self) -> None:
        """Forget the accumulated stage times (e.g. after warm-up steps that compiled the kernels)."""
        self.scheduler.reset_timing()

    def cost_summary(self, top: int | None = None) -> str:
        """One line: mean ms per step and share of each stage (most expensive first), over the timed steps."""
        rep = self.cost_report()
        if not rep:
            return "stage costs: not timed"
        total = sum(r["mean"] for r in rep.values())
        items = sorted(rep.items(), key=lambda kv: -kv[1]["mean"])[: top or len(rep)]
        parts = ", ".join(f"{k} {1e3 * r['mean']:.3g} ({100 * r['fraction']:.0f}%)" for k, r in items)
        return f"stage costs, ms/step over {self.scheduler._timed_steps} steps (total {1e3 * total:.3g}): {parts}"

    def fields(self) -> dict[str, np.ndarray]:
        """Host NumPy grid fields: velocity (m/s), pressure (lattice), density, phi, solid (fluid);
        sand_fraction, sand_velocity (m/s) (sand). Shapes (nz, ny, nx) and (3, nz, ny, nx)."""
        out: dict[str, np.ndarray] = {}
        if self.fluid is not None:
            f = self.fluid.fields()
            f["velocity"] = f["velocity"] * (self.scene.domain.dx / self.scene.time.dt)
            out.update(f)
        if self.sand is not None:
            s = self.sand.fields()
            out["sand_fraction"] = s["sand_fraction"]
            out["sand_velocity"] = s["velocity"]
        if self.coupler is not None:
            out.update(self.coupler.fields())
        return out

    def particles(self) -> dict[str, np.ndarray]:
        """Host NumPy particle arrays: x, v (3, P) in m and m/s; saturation, friction_angle, mass, volume (P,).
        Empty when the scene has no sand."""
        if self.sand is None:
            return {}
        p = self.sand.particles()
        out = {k: p[k] for k in ("x", "v", "saturation", "friction_angle", "mass", "volume") if k in p}
        if self.coupler is not None and self.coupler.retention:
            out["moisture"] = self.backend.to_host(self.coupler.moisture_ratio)
        return out

    def diagnostics(self) -> dict[str, float]:
        """Floats: time, step, frame; fluid_volume, fluid_volume_drift, max_lattice_speed, mach, max_speed,
        momentum_x/y/z, kinetic_energy (fluid, lattice units); sand_mass, sand_momentum_x/y/z,
        sand_kinetic_energy, sand_max_speed (SI); step_seconds (wall time of the last step's stages, when
        timed)."""
        out = {"time": self.time, "step": float(self.step_count), "frame": float(self.frame)}
        times = self.stage_times()
        if times:
            out["step_seconds"] = float(sum(times.values()))
        if self.fluid is not None:
            d = self.fluid.diagnostics()
            d.pop("step", None)
            out.update(d)
            out["mach"] = d["max_lattice_speed"] / math.sqrt(CS2)
            out["max_speed"] = d["max_lattice_speed"] * self.scene.domain.dx / self.scene.time.dt
        if self.sand is not None:
            for k, v in self.sand.diagnostics().items():
                if k not in ("time", "step"):
                    out[f"sand_{k}"] = v
        return out

    # ------------------------------------------------------------------------------------ NaN / Inf
    def _solver_arrays(self) -> list[tuple[str, str, np.ndarray, str]]:
        arrays = []
        if self.fluid is not None:
            for name, a in self.fluid.fields().items():
                if a.dtype.kind == "f":
                    arrays.append(("fluid", name, a, "cell (x, y, z)"))
        if self.sand is not None:
            p = self.sand.particles()
            for name in ("x", "v", "F"):
                arrays.append(("sand", name, p[name], "particle"))
        return arrays

    def check_finite(self) -> None:
        """Raise :class:`SimulationDiverged` naming the field and cell (or particle) of a NaN/Inf."""
        for solver, name, a, where in self._solver_arrays():
            bad = ~np.isfinite(a)
            if bad.any():
                idx = np.unravel_index(int(np.argmax(bad)), a.shape)
                value = float(a[idx])
                if where == "particle":
                    index: tuple = (int(idx[-1]),)
                else:
                    z, y, x = (int(i) for i in idx[-3:])
                    index = (x, y, z)
                raise SimulationDiverged(self.step_count, solver, name, index, value, where)

    def _states(self) -> dict[str, dict[str, np.ndarray]]:
        out = {}
        if self.fluid is not None:
            out["fluid"] = self.fluid.state()
        if self.sand is not None:
            out["sand"] = self.sand.state()
        if self.coupler is not None:
            out["coupler"] = self.coupler.state()
        if self.emitter is not None:
            out["emission"] = self.emitter.state()
        return out

    def _load_states(self, states: dict[str, dict[str, np.ndarray]], step: int) -> None:
        for name, solver in (("fluid", self.fluid), ("sand", self.sand)):
            if solver is not None:
                if name not in states:
                    raise ValueError(f"the checkpoint has no {name} state, the scene needs one")
                if name == "sand" and self.emitter is not None:
                    solver.load_state(states[name], resize=True)  # the jets emitted particles since the start
                else:
                    solver.load_state(states[name])
        if self.emitter is not None:
            if "emission" not in states:
                raise ValueError("the checkpoint has no emission state, the scene has sand-carrying inflows")
            self.emitter.load_state(states["emission"])
            if self.coupler is not None:
                from .sand.emission import match_particle_count

                match_particle_count(self.coupler, self.sand.n_particles)
        if self.coupler is not None:
            st = states.get("coupler")
            if st is None:
                raise ValueError("the checkpoint has no coupler state, the scene is coupled")
            self.coupler.load_state(st)
        self.step_count = int(step)

    def _rebuild(self) -> None:
        """Fresh solvers (scratch arrays outside the solver state, e.g. ghost layers, may hold NaN)."""
        self.fluid = self._build_fluid() if self.scene.has_fluid else None
        self.sand = self._build_sand() if self.scene.has_sand else None
        self.coupler = self._build_coupler() if self.coupled else None
        from .sand.emission import InflowEmitter

        self.emitter = InflowEmitter.from_scene(self.scene, coupler=self.coupler) if self.scene.emits_sand else None
        from .schedulers.lockstep import LockstepScheduler

        self.scheduler = LockstepScheduler(
            self.fluid,
            self.sand,
            self.coupler,
            source_term=self.scene.effects.source_term,
            timing=self._timing,
            warm_up_steps=1,
        )

    def _build_coupler(self):
        from .coupling.coupler import SandFluidCoupler
        from .coupling.params import CouplingParams

        sd = self.scene.sand
        retention = any(
            b.retention if b.retention is not None else sd.retention for b in self.scene.bodies if b.kind == "sand"
        )
        params = CouplingParams(retention=retention, r_max=sd.max_moisture, absorption_rate=sd.absorption_rate)
        # retention on some bodies only: per-particle flags (all flags true = the one-setting model, bitwise)
        flags = getattr(self, "_sand_retentive", None)
        retentive = flags if retention and flags is not None and flags.size == self.sand.n_particles else None
        return SandFluidCoupler(self.sand, self.fluid, self.units, params, retentive=retentive)

    def _locate_divergence(self, good: dict, good_step: int, exc: SimulationDiverged) -> SimulationDiverged:
        """Replay from the last good state one step at a time to find the first non-finite step."""
        target = self.step_count
        self._rebuild()
        self._load_states(good, good_step)
        try:
            while self.step_count < target:
                self.step(1)
                self.check_finite()
        except SimulationDiverged as first:
            return first
        return exc

    # ------------------------------------------------------------------------------------ checkpoints
    def save(self, path: str | Path) -> Path:
        """Write an HDF5 checkpoint (scene, solver states, counters) for an exact restart."""
        from .io.checkpoint import save_checkpoint

        meta = {"step": self.step_count, "time": self.time, "backend": self.backend.name, "couplekit": __version__}
        return save_checkpoint(path, self.scene.to_dict(), self._states(), meta)

    @classmethod
    def load(
        cls, path: str | Path, backend: str | Backend | None = "auto", threads: int | None = None, log=print
    ) -> Simulation:
        """Rebuild the scene of a checkpoint and restore its state (bitwise on the backend that wrote it)."""
        from .io.checkpoint import load_checkpoint

        scene_dict, states, meta = load_checkpoint(path)
        sim = cls(
            Scene.from_dict(scene_dict, source_name=f"scene of {path}"), backend=backend, threads=threads, log=log
        )
        sim._load_states(states, int(meta["step"]))
        if meta.get("backend") != sim.backend.name and log:
            log(f"note: checkpoint written by the {meta.get('backend')} backend, resumed on {sim.backend.name}")
        return sim

    # ------------------------------------------------------------------------------------ run
    def write_frame(self, out: Path, indexes: dict, log_file) -> None:
        """Write the outputs of the current frame (per the scene's [outputs])."""
        from .io import render_preview, write_fields_vti, write_particles_ply, write_particles_vtp

        o, frame, t = self.scene.outputs, self.frame, self.time
        fields = {k: v for k, v in self.fields().items() if k in o.fields}
        parts = self.particles()
        extra = {k: v for k, v in parts.items() if k != "x"}
        if o.vtk:
            if fields:
                indexes["fields"].add(
                    t, write_fields_vti(out / f"fields_{frame:04d}.vti", fields, self.scene.domain.dx)
                )
            if parts:
                indexes["particles"].add(t, write_particles_vtp(out / f"particles_{frame:04d}.vtp", parts["x"], extra))
        if o.ply and parts:
            write_particles_ply(out / f"particles_{frame:04d}.ply", parts["x"], extra)
        if o.preview and frame % o.preview_every == 0 and not self._preview_failed:
            try:
                render_preview(
                    out / f"preview_{frame:04d}.png",
                    self.scene.domain.size,
                    self.scene.domain.dx,
                    self.fields(),
                    parts,
                    title=f"{self.scene.name}  frame {frame}  t = {t:.4g} s",
                )
            except Exception as exc:  # a missing OpenGL/EGL library must not stop the simulation
                self._preview_failed = True
                self._log(
                    f"warning: PNG previews disabled ({type(exc).__name__}: {exc}); the VTK/PLY outputs are "
                    "unaffected. Headless rendering needs EGL: apt-get install libegl1 libegl-mesa0 libgl1"
                )
        if log_file is not None:
            log_file.write(self.diagnostics())

    def run(
        self,
        frames: int | None = None,
        out: str | Path | None = None,
        progress: bool = True,
        stream=None,
        stop: Callable[[], bool] | None = None,
    ) -> RunResult:
        """Simulate until ``frames`` frames are complete (default ``time.frames``), writing outputs into
        ``out`` (default ``outputs.directory`` or ``runs/<name>``).

        Each frame: step, NaN/Inf check, outputs, diagnostics line, progress bar; checkpoints every
        ``outputs.checkpoint_every`` frames and at the end (``checkpoint.h5``). Ctrl-C (SIGINT) or ``stop()``
        returning True ends the run cleanly between steps with ``interrupted.h5``. On NaN/Inf the last good
        state is written to ``last_good.h5`` and the report to ``diverged.txt``.
        """
        from .io import DiagnosticsLog, PvdIndex
        from .io.progress import ProgressBar

        sc = self.scene
        total = int(frames if frames is not None else sc.time.frames)
        out = Path(out or sc.outputs.directory or Path("runs") / sc.name)
        out.mkdir(parents=True, exist_ok=True)
        resumed = self.step_count > 0
        indexes = {"fields": PvdIndex(out / "fields.pvd"), "particles": PvdIndex(out / "particles.pvd")}
        log_file = DiagnosticsLog(out / "diagnostics.jsonl", append=resumed) if sc.outputs.diagnostics else None
        self._log(f"effects on: {', '.join(k for k, v in self.effects.items() if v)}")
        self._log(f"writing to {out}")
        bar = ProgressBar(total, self.frame, stream=stream) if progress else None
        interrupted = {"flag": False}
        previous = None
        if threading_main():

            def _on_sigint(signum, frame):
                interrupted["flag"] = True

            previous = signal.signal(signal.SIGINT, _on_sigint)
        result = RunResult(status="done", out=str(out), checkpoint=None, steps=0)
        steps_done = 0
        chunk = max(1, min(self.steps_per_frame, 10))
        try:
            if self.step_count == 0:
                self.check_finite()
                self.write_frame(out, indexes, log_file)
            good, good_step = self._states(), self.step_count
            while self.frame < total:
                target = (self.frame + 1) * self.steps_per_frame
                while self.step_count < target:
                    if interrupted["flag"] or (stop is not None and stop()):
                        path = self.save(out / "interrupted.h5")
                        self._log(f"\ninterrupted at step {self.step_count} (frame {self.frame}); checkpoint {path}")
                        result.update(status="interrupted", checkpoint=str(path))
                        return result
                    n = min(chunk, target - self.step_count)
                    self.step(n)
                    steps_done += n
                try:
                    self.check_finite()
                except SimulationDiverged as exc:
                    first = self._locate_divergence(good, good_step, exc)
                    self._rebuild()
                    self._load_states(good, good_step)
                    path = self.save(out / "last_good.h5")
                    report = f"{first}\nlast good state: step {good_step} (frame {good_step // self.steps_per_frame}), saved to {path}\n"
                    (out / "diverged.txt").write_text(report)
                    self._log("\n" + report.strip())
                    result.update(status="diverged", checkpoint=str(path), error=str(first))
                    return result
                good, good_step = self._states(), self.step_count
                self.write_frame(out, indexes, log_file)
                every = sc.outputs.checkpoint_every
                if every and self.frame % every == 0 and self.frame < total:
                    result["checkpoint"] = str(self.save(out / "checkpoint.h5"))
                if bar is not None:
                    d = self.diagnostics()
                    info = {k: d[k] for k in ("fluid_volume_drift", "mach", "sand_max_speed") if k in d}
                    bar.update(self.frame, steps_done, info)
            result["checkpoint"] = str(self.save(out / "checkpoint.h5"))
            return result
        finally:
            result.update(frames=self.frame, steps=steps_done)
            if bar is not None:
                bar.close()
            if steps_done:
                self._log(self.cost_summary())
            if log_file is not None:
                log_file.close()
            if previous is not None:
                signal.signal(signal.SIGINT, previous)

    def __repr__(self) -> str:
        parts = [f"Simulation({self.scene.name!r}, backend={self.backend.name}, step={self.step_count}"]
        if self.sand is not None:
            parts.append(f"{self.sand.n_particles} particles")
        return ", ".join(parts) + ")"


def threading_main() -> bool:
    """True in the main thread of the main interpreter (where signal handlers can be set)."""
    import threading

    return threading.current_thread() is threading.main_thread()
