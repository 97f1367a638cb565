"""``Simulation``: a scene turned into solvers, stepped, written out, checkpointed and restarted exactly.

>>> import couplekit as ck
>>> sim = ck.Simulation(ck.Scene.load("examples/sand_drop_small.toml"), backend="auto")
>>> sim.run(frames=20, out="runs/sand_drop")     # progress bar; .vti/.vtp/.pvd, PLY, PNG, diagnostics, HDF5
>>> sim.fields(), sim.particles(), sim.diagnostics()
>>> sim.save("x.h5"); sim2 = ck.Simulation.load("x.h5")   # bitwise restart on the cpu backend

The solvers come from :func:`couplekit.assembly.assemble`, the one path from a scene to running solvers
(seeding, initial pressure, boundaries, the scheduler: its docstring): fluid-only
(:class:`couplekit.fluid.solver.FluidSolver`), sand-only (:class:`couplekit.sand.solver.SandSolver`) and
coupled scenes (:class:`couplekit.coupling.coupler.SandFluidCoupler`: drag, buoyancy, the phase-field source
term, water retention). ``Simulation`` holds their state and runs them: stepping, the run loop, outputs and
checkpoints. The scene's ``[scheduler]`` table (or ``Simulation(..., scheduler=...)``) chooses how they are
stepped (:mod:`couplekit.schedulers`: lockstep, paper Algorithm 1, by default; sub-cycled or multi-rate sand),
and the scheduler times every stage: :meth:`Simulation.stage_times`, :meth:`Simulation.cost_report`, a cost
line at the end of :meth:`Simulation.run`, ``step_seconds`` and the sand steps per step in the diagnostics.
Refused with :class:`CouplingUnavailableError`: what the coupler cannot do yet (drag or buoyancy switched
off).

Water jets carrying sand (``inflows[*].sand_fraction`` > 0, paper Fig. 1): :class:`couplekit.sand.emission.
InflowEmitter` (:attr:`Simulation.emitter`) appends a layer of particles after every step in which a jet has
advanced one particle spacing, so the sand flux is sand_fraction × area × normal speed and the jet's sand
fraction is sand_fraction; a scene whose only sand comes from jets starts with an empty SandSolver and the
coupled solvers from the first step. Its accumulators are part of the checkpoint (group ``emission``), and a
resumed run grows the particle arrays to the checkpoint's count, so the restart stays bitwise. Sand bodies may have different densities
(``bodies[*].density``, paper Fig. 8): each particle carries its body's.

Before anything is allocated the constructor prints the backend and why it was chosen, and a memory
estimate; a scene that will not fit the device (or the host's available memory) is refused
(:class:`InsufficientMemoryError`). After every frame the fields are checked for NaN/Inf; on a hit the
frame is replayed step by step from the last good state to name the first bad step, the field and the cell
(:class:`SimulationDiverged`), and ``run`` writes that last good state as a checkpoint.
"""

from __future__ import annotations

import math
import os
import signal
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from . import __version__
from .arguments import callable_or_none, flag, whole_count
from .assembly import CouplingUnavailableError, assemble, check_run, memory_estimate, refuse_unsupported
from .backend import Backend, get_backend
from .fluid.hydrostatic import hydrostatic_pressure
from .lattice import CS2
from .sand.solver import TimeStepError
from .scene import Scene
from .schedulers import SubstepLimitError

if TYPE_CHECKING:
    from .io import DiagnosticsLog

__all__ = [
    "Simulation",
    "SimulationDiverged",
    "CouplingUnavailableError",
    "InsufficientMemoryError",
    "memory_estimate",
    "hydrostatic_pressure",
    "RunResult",
    "with_scheduler",
    "with_settings",
    "parse_setting",
]

_refuse_unsupported = refuse_unsupported  # the name the CLI used before couplekit.assembly


def with_scheduler(scene: Scene, scheduler: str | dict) -> Scene:
    """``scene`` with its ``[scheduler]`` table replaced (and validated again, so the limits of the new scheme
    are checked): ``scheduler`` is a table (dict of the ``[scheduler]`` keys) or a spec string
    (:func:`couplekit.schedulers.spec_table`: ``"lockstep"``, ``"subcycle:8"``, ``"subcycle:auto:linear"``,
    ``"multirate:4"``)."""
    from .schedulers import spec_table

    table = spec_table(scheduler) if isinstance(scheduler, str) else dict(scheduler)
    data = scene.to_dict()
    data["scheduler"] = table
    return Scene.from_dict(data, source_name=f"scene {scene.name!r} with [scheduler] {table}")


def parse_setting(text: str) -> tuple[str, Any]:
    """``"KEY=VALUE"`` (``couplekit run --set``) -> (dotted key, value): VALUE is read as a TOML value (``3``,
    ``0.5``, ``true``, ``[1, 2]``, ``"text"``), or taken as a plain string where it is not one
    (``fluid.storage=fp16``). ValueError, naming the fix, without an ``=`` or a key."""
    import tomllib

    key, sep, value = text.partition("=")
    key, value = key.strip(), value.strip()
    if not sep or not key:
        raise ValueError(f"--set {text!r}: write KEY=VALUE, e.g. --set outputs.preview=false or --set time.frames=5")
    try:
        return key, tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        return key, value
    except RecursionError:  # nested beyond the parser's stack (thousands of brackets)
        raise ValueError(f"--set {key}: the value is nested too deeply to be a scene value") from None


def _count(name: str, value: Any, least: int = 0) -> int:
    """``value`` as a whole number >= ``least`` (:func:`couplekit.arguments.whole_count`)."""
    return whole_count(name, value, least, what="steps or frames")


def with_settings(scene: Scene | str | Path, settings: Mapping[str, Any], base_dir: str | Path | None = None) -> Scene:
    """``scene`` with the dotted keys of ``settings`` (``{"outputs.preview": False, "bodies[1].density": 900}``,
    the keys of a sweep: docs/sweeps.md) set, and validated again; a relative mesh or height file among the
    values resolves against ``base_dir`` (``couplekit run --set`` gives the scene file's folder). A key the
    scene format does not have raises :class:`~couplekit.sweep.KeyPathError` (a ValueError) naming the nearest
    key; a value it refuses raises :class:`~couplekit.scene.SceneError`. ``scene`` may be a scene file's path
    (then ``base_dir`` defaults to its folder)."""
    if isinstance(scene, (str, Path)):
        base_dir = Path(scene).parent if base_dir is None else base_dir
        scene = Scene.load(scene)
    elif not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene or a scene file's path, got {type(scene).__name__}")
    base_dir = "." if base_dir is None else base_dir
    if not isinstance(settings, Mapping):
        raise TypeError(f"settings must be a mapping of dotted keys to values, got {type(settings).__name__}")
    data = scene.to_dict()
    shown = apply_settings(data, settings)
    return Scene.from_dict(data, base_dir=base_dir, source_name=f"scene {scene.name!r} with {shown}")


def apply_settings(data: dict, settings: Mapping[str, Any]) -> str:
    """Write the dotted keys of ``settings`` into the scene dict ``data`` (in place, in order; a key the scene
    format does not have raises :class:`~couplekit.sweep.KeyPathError`) and return them as ``"key = value, ..."``
    for messages. A key that says what the scene already gives in another form replaces it
    (:func:`couplekit.sweep.keys.drop_replaced`: an SI viscosity the lattice one, absorption_time the rate, dx the
    resolution). :func:`with_settings` applies them to a validated scene's dict; ``couplekit run --set`` to a
    scene file's own table when the file alone does not validate."""
    from .sweep.keys import check_key, drop_replaced, set_key

    for key, value in settings.items():
        check_key(key, data)
        set_key(data, key, value)
    drop_replaced(data, settings)  # fluid.water_viscosity set: the file's water_lattice_viscosity goes
    return ", ".join(f"{k} = {v!r}" for k, v in settings.items())


class InsufficientMemoryError(MemoryError):
    """The memory estimate of a scene exceeds what the device (or host) has available."""


class SimulationDiverged(FloatingPointError):
    """A NaN or Inf appeared: ``step`` (first bad step), ``solver``, ``field``, ``index`` (cell (x, y, z) or
    particle number)."""

    def __init__(self, step: int, solver: str, field: str, index: tuple, value: float, where: str):
        self.step, self.solver, self.field, self.index, self.value = step, solver, field, index, value
        super().__init__(f"non-finite value {value} in {solver} field {field!r} at {where} {index} after step {step}")


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
    ``steps``, ``out`` (folder), ``checkpoint`` (last checkpoint written), ``error`` (for "diverged": the first
    non-finite value, or the sand time-step limit that stopped the run before it went non-finite), ``signal``
    (for "interrupted": "SIGINT" or "SIGTERM", None when ``stop()`` ended it)."""

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

    ``scheduler``: replaces the scene's ``[scheduler]`` table (a dict, or a spec string such as
    ``"subcycle:8"``; :func:`with_scheduler`), checked like the scene's own.

    The solvers are built by :func:`couplekit.assembly.assemble` and stepped by :attr:`scheduler`
    (:mod:`couplekit.schedulers`): fluid-only and sand-only scenes run their solver's stages, coupled scenes
    paper Algorithm 1 in the scheduler's rhythm.
    """

    def __init__(
        self,
        scene: Scene | str | Path | Mapping[str, Any],
        backend: str | Backend | None = "auto",
        threads: int | None = None,
        log: Callable[[str], Any] | None = print,
        check_memory: bool = True,
        timing: bool = True,
        scheduler: str | dict | None = None,
    ):
        if isinstance(scene, Mapping):  # a scene dict, as Scene.from_dict takes it
            scene = Scene.from_dict(dict(scene))
        elif not isinstance(scene, (Scene, str, Path)):
            raise TypeError(f"scene must be a Scene, a scene file's path or a scene dict, got {type(scene).__name__}")
        self.scene = scene if isinstance(scene, Scene) else Scene.load(scene)
        if scheduler is not None and not isinstance(scheduler, (str, Mapping)):
            raise TypeError(
                f"scheduler must be a spec string ('subcycle:4') or a [scheduler] table (dict), got {type(scheduler).__name__}"
            )
        if scheduler is not None:
            self.scene = with_scheduler(self.scene, scheduler)
        sc = self.scene
        self._log = callable_or_none("log", log, "taking one line of text (e.g. print)") or (lambda s: None)
        check_memory, timing = flag("check_memory", check_memory), flag("timing", timing)
        self._preview_failed = False
        self._preview_scale: tuple[float, float] | None = None  # the run's fixed sand-speed colours (preview_scale)
        self._preview_colour: tuple[str, float | None] | None = None  # (colour_by, r_max), preview_colouring
        self.coupled = sc.has_fluid and sc.has_sand
        refuse_unsupported(sc)
        self.backend = backend if isinstance(backend, Backend) else get_backend(backend, threads=threads)
        self._log(self.backend.describe())
        self._log(sc.summary())
        avail, what = available_memory(self.backend)
        # the refusal `couplekit validate` reports too (couplekit.assembly.check_run: one test, one message)
        est = check_run(sc, (avail, what)) if check_memory else memory_estimate(sc)
        counts = ("total", "particle_count", "emitted_particles")
        parts = ", ".join(f"{k} {_gib(v)}" for k, v in est.items() if k not in counts and v)
        self._log(f"memory estimate: {_gib(est['total'])} ({parts}); {what}: {_gib(avail)}")
        if est.get("emitted_particles"):
            self._log(
                f"sand jets: about {est['emitted_particles']:,.0f} particles emitted over {sc.time.frames} frames "
                f"(of {est['particle_count']:,.0f} in all)"
            )
        self.memory = est
        self.units = sc.units()
        self.steps_per_frame = sc.time.steps_per_frame
        self.step_count = 0
        self._resumed = False  # set by load(): run() then appends to an output folder instead of refusing it
        self._run_folder: Path | None = None  # the folder of the last run(): a later run() into it continues there
        self.fluid = self.sand = self.coupler = self.scheduler = self.emitter = None
        self._timing = bool(timing)
        self._cost_mark: tuple[dict[str, float], int] = ({}, 0)  # stage totals at the last frame (frame_stage_costs)
        self._rebuild(quiet=False)
        self._sand_origin = self._sand_centroid()

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
        """Advance ``n`` time steps of ``time.dt`` (every solver in the scene) through :attr:`scheduler`; ``n`` a
        whole number ≥ 0 (anything else is refused: a negative count once moved the step and the time backwards
        and every output after it carried the wrong time)."""
        n = _count("n", n)
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
        """One line: mean ms per step and share of each stage (most expensive first), over the timed steps,
        and the sand steps per step (sub-cycled and multi-rate schedulers)."""
        rep = self.cost_report()
        if top is not None:
            top = whole_count("top", top, least=1, what="stages")
        if not rep:
            return "stage costs: not timed"
        total = sum(r["mean"] for r in rep.values())
        items = sorted(rep.items(), key=lambda kv: -kv[1]["mean"])[: top or len(rep)]
        parts = ", ".join(f"{k} {1e3 * r['mean']:.3g} ({100 * r['fraction']:.0f}%)" for k, r in items)
        line = f"stage costs, ms/step over {self.scheduler._timed_steps} steps (total {1e3 * total:.3g}): {parts}"
        if self.sand is not None and self.scheduler.kind != "lockstep":
            st = self.scheduler.sand_steps()
            line += f"; {self.scheduler.describe()}: {st['mean']:.3g} sand steps per step ({st['total']:.0f} in all)"
        return line

    def frame_stage_costs(self) -> dict[str, float]:
        """``stage_<name>_ms``: mean milliseconds per time step of each stage over the timed steps since the last
        frame was written (the per-frame stage costs of the diagnostics log; empty before the first timed step of
        a frame, and with ``timing=False``)."""
        rep = self.cost_report()
        marks, marked = self._cost_mark
        if self.scheduler._timed_steps < marked:  # reset_timing() since the mark
            marks, marked = {}, 0
        n = self.scheduler._timed_steps - marked
        if n <= 0:
            return {}
        return {f"stage_{s}_ms": 1e3 * (r["total"] - marks.get(s, 0.0)) / n for s, r in rep.items()}

    def _mark_stage_costs(self) -> None:
        """Start a new frame of :meth:`frame_stage_costs`."""
        self._cost_mark = ({s: r["total"] for s, r in self.cost_report().items()}, self.scheduler._timed_steps)

    def fields(self, lattice: bool = False) -> dict[str, np.ndarray]:
        """Host NumPy grid fields, in SI units (``lattice=True``: the solvers' lattice units).

        Arrays are in array order ``(nz, ny, nx)`` (index ``[k, j, i]`` is the cell whose centre is
        ``((i + ½) dx, (j + ½) dx, (k + ½) dx)``), vectors ``(3, nz, ny, nx)`` with components in ``(x, y, z)``
        order. Fluid scenes:

        ===================== ====================================================== ==========================
        field                 SI (default)                                           ``lattice=True``
        ===================== ====================================================== ==========================
        ``velocity``          fluid velocity, m/s (0 in solid cells; Eq. 13's, of    Δx/Δt
                              the last collision: half a step behind the
                              populations, :meth:`diagnostics`)
        ``pressure``          gauge pressure p of Eqs. 39–40, Pa (p = 0: the         ρ_w (Δx/Δt)²
                              reference level of the start, the top of a
                              hydrostatic column or the initial state)
        ``density``           ρ(φ) of Eq. 4, kg/m³                                   ρ_w (water = 1)
        ``phi``               water fraction φ (1 water, 0 air; two-phase), 1        same
        ``solid``             obstacle cells (bool)                                  same
        ===================== ====================================================== ==========================

        Sand scenes add ``sand_fraction`` ε (1) and ``sand_velocity`` (MPM grid velocity, m/s; lattice:
        Δx/Δt); coupled scenes ``fluid_fraction`` (1 − ε, 1), ``water`` (the water fraction of Eq. 59, 1) and
        with retention ``bound_water`` (bound water per cell volume, 1). ρ_w is the scene's water density
        (:meth:`couplekit.scene.Scene.units`); the conversion is :meth:`couplekit.units.Units.to_si`.
        :meth:`write_frame` writes these SI fields into the ``.vti`` files (docs/units-and-conventions.md).
        """
        lattice = flag("lattice", lattice)  # "no" would be true: the units must be asked for exactly
        u = self.units
        speed = 1.0 if lattice else u.scale("velocity")
        out: dict[str, np.ndarray] = {}
        if self.fluid is not None:
            f = self.fluid.fields()
            if not lattice:
                f["velocity"] = f["velocity"] * speed
                f["pressure"] = (f["pressure"].astype(np.float64) * u.scale("pressure")).astype(np.float32)
                f["density"] = f["density"] * np.float32(u.rho)
            out.update(f)
        if self.sand is not None:
            s = self.sand.fields()
            if self.coupler is None:  # coupled: the coupler's ε (its eps_max), below, as the drag computes it
                out["sand_fraction"] = s["sand_fraction"]
            out["sand_velocity"] = s["velocity"] if not lattice else s["velocity"] / u.scale("velocity")
        if self.coupler is not None:
            out.update(self.coupler.fields())
        return out

    def particles(self) -> dict[str, np.ndarray]:
        """Host NumPy particle arrays: x, v (3, P) in m and m/s; saturation, friction_angle, mass, volume (P,);
        wetness (P,) in [0, 1] (:func:`couplekit.coupling.wetness.wetness`); with retention moisture (P,).
        Every name, unit and meaning: docs/outputs.md. Empty when the scene has no sand."""
        if self.sand is None:
            return {}
        p = self.sand.particles()
        out = {k: p[k] for k in ("x", "v", "saturation", "friction_angle", "mass", "volume") if k in p}
        if self.coupler is not None and self.coupler.retention:
            out["moisture"] = self.backend.to_host(self.coupler.moisture_ratio)
        if "saturation" in out:
            from .coupling.wetness import wetness
            from .sand import EPS_MAX

            eps_max = self.coupler.params.eps_max if self.coupler is not None else EPS_MAX
            out["wetness"] = wetness(out["saturation"], eps_max)
        return out

    def diagnostics(self) -> dict[str, float]:
        """Floats, in SI units unless the name says ``lattice``: time (s), step, frame; step_seconds (wall time
        of the last step's stages, when timed) and ``stage_<name>_ms`` (:meth:`frame_stage_costs`: each stage's
        mean ms per step over the frame).

        Fluid: ``fluid_volume`` (water volume in cells, Σ φ, with sand Σ ε φ + bound water; Δx³ = 1),
        ``fluid_volume_drift`` (relative to the start, moved by what inflow and outflow faces let in and out),
        ``max_lattice_speed`` (Δx/Δt), ``mach``, ``max_speed``
        (m/s), two-phase ``max_water_speed`` and ``max_air_speed`` (m/s: the fastest cell with φ ≥ ½ and with
        φ < ½; the air beside water is often the fastest, docs/fluid-stability.md 'The air beside water'), ``fluid_momentum_x/y/z`` (Σ ε ρ u dV, kg m/s: ε the fluid fraction where there is sand, else 1;
        u = Σ_j f_j c_j, the velocity of the populations the drag exchange sees; the Eq. 13 velocity of
        :meth:`fields` is the last collision's, half a step behind it: from rest under a uniform body force g,
        (N − ½) g Δt after N steps where Σ f c gives N g Δt), ``fluid_kinetic_energy_si`` (½ Σ ε ρ |u|² dV with
        the :meth:`fields` velocity, J, so half a step behind the momentum), ``free_surface_height`` (two-phase, m); and the solver's lattice
        sums ``lattice_momentum_x/y/z`` (Σ ρ u over every fluid cell, not weighted by ε) and
        ``lattice_kinetic_energy`` (½ Σ ρ |u|²), in lattice units (ρ_w = Δx = Δt = 1), as
        :meth:`couplekit.fluid.solver.FluidSolver.diagnostics` gives them.

        Sand: sand_mass (kg), ``sand_momentum_x/y/z`` (Σ m v, kg m/s), sand_kinetic_energy (J), sand_max_speed
        (m/s); ``sand_dt`` (the sand's Δt, s) and ``sand_steps_per_step`` (sand steps per time step over the
        current frame: k sub-cycled, 1/m multi-rate, 1 lockstep; 0 before the first step, as at a run's frame 0)
        with ``substeps_min`` and ``substeps_max``.

        Both: ``total_momentum_x/y/z`` (fluid + sand momentum, kg m/s: what gravity, walls, inflows and
        stirring change and the drag exchange between fluid and sand does not) and
        ``total_kinetic_energy_si`` (fluid + sand, J).

        Measurements (:mod:`couplekit.metrics`, SI): ``sand_centroid_x/y/z`` (m), ``sand_front`` (runout from
        the initial centroid's vertical, m), ``sand_top`` (height of the pile, m). Units and names:
        docs/units-and-conventions.md."""
        from . import metrics

        sc = self.scene
        out = {"time": self.time, "step": float(self.step_count), "frame": float(self.frame)}
        times = self.stage_times()
        if times:
            out["step_seconds"] = float(sum(times.values()))
        out.update(self.frame_stage_costs())
        total_ke = 0.0
        total_momentum = np.zeros(3)
        if self.fluid is not None:
            d = self.fluid.diagnostics()
            d.pop("step", None)
            for k in ("momentum_x", "momentum_y", "momentum_z", "kinetic_energy"):
                out["lattice_" + k] = d.pop(k)  # lattice sums over every fluid cell (the solver's)
            for phase in ("water", "air"):  # two-phase: the fastest cell of each phase, in m/s
                if f"max_lattice_speed_{phase}" in d:
                    out[f"max_{phase}_speed"] = d.pop(f"max_lattice_speed_{phase}") * sc.domain.dx / sc.time.dt
            out.update(d)
            out["mach"] = d["max_lattice_speed"] / math.sqrt(CS2)
            out["max_speed"] = d["max_lattice_speed"] * sc.domain.dx / sc.time.dt
            f = self.fluid.fields()
            eps = None
            if self.fluid.fluid_fraction is not None:
                eps = self.backend.to_host(self.fluid.fluid_fraction)[1:-1, 1:-1, 1:-1]
            velocity = f["velocity"] * (sc.domain.dx / sc.time.dt)
            out["fluid_kinetic_energy_si"] = metrics.kinetic_energy(
                velocity, f["density"] * self.units.rho, sc.domain.dx, eps
            )
            total_ke += out["fluid_kinetic_energy_si"]
            momentum = self._fluid_momentum(f["density"], eps)
            total_momentum += momentum
            for axis, m in zip("xyz", momentum, strict=True):
                out[f"fluid_momentum_{axis}"] = float(m)
            if "phi" in f:
                out["free_surface_height"] = metrics.free_surface_height(
                    f["phi"], sc.domain.dx, sc.domain.gravity, f["solid"]
                )
        if self.sand is not None:
            for k, v in self.sand.diagnostics().items():
                if k not in ("time", "step"):
                    out[f"sand_{k}"] = v
            total_ke += out["sand_kinetic_energy"]
            total_momentum += [out[f"sand_momentum_{axis}"] for axis in "xyz"]
            x = self.backend.to_host(self.sand.x)
            out.update(metrics.sand_metrics(x, self._sand_origin, sc.domain.gravity, sc.domain.size))
            st = self.scheduler.sand_steps()
            out["sand_dt"] = float(self.sand.dt)
            out["sand_steps_per_step"] = st["frame_mean"]
            out["substeps_min"], out["substeps_max"] = st["frame_min"], st["frame_max"]
        out["total_kinetic_energy_si"] = total_ke
        for axis, m in zip("xyz", total_momentum, strict=True):
            out[f"total_momentum_{axis}"] = float(m)
        return out

    def _fluid_momentum(self, density: np.ndarray, eps: np.ndarray | None) -> np.ndarray:
        """Σ ε ρ u dV (3,) in kg m/s of the fluid: ``density`` the lattice ρ(φ) (interior), ``eps`` the fluid
        fraction (interior; None: 1), u = Σ_j f_j c_j of the current populations (the velocity the drag
        exchange reads, :meth:`couplekit.fluid.solver.FluidSolver.current_velocity`)."""
        fl = self.fluid
        u = self.backend.to_host(fl.current_velocity())[(slice(None), slice(1, -1), slice(1, -1), slice(1, -1))]
        w = density.astype(np.float64) * fl._fluid_host
        if eps is not None:
            w = w * eps
        lattice = np.einsum("dzyx,zyx->d", u.astype(np.float64), w)
        return lattice * self.units.scale("mass") * self.units.scale("velocity")

    def _sand_centroid(self) -> np.ndarray | None:
        """Mean particle position (m) now, None without particles (the origin of ``sand_front``)."""
        if self.sand is None or self.sand.n_particles == 0:
            return None
        return self.backend.to_host(self.sand.x).astype(np.float64).mean(axis=1)

    # ------------------------------------------------------------------------------------ NaN / Inf
    def _solver_arrays(self) -> list[tuple[str, str, np.ndarray, str]]:
        """(solver, name, host array, layout) of every array :meth:`check_finite` reads: the fluid's fields and
        its populations (the state a restart continues from, padded with ghosts), every particle array."""
        arrays = []
        if self.fluid is not None:
            for name, a in self.fluid.fields().items():
                if a.dtype.kind == "f":
                    arrays.append(("fluid", name, a, "cell (x, y, z)"))
            for name in ("f", "h"):
                a = getattr(self.fluid, name)
                if a is not None:
                    arrays.append(("fluid", name, self.backend.to_host(a), "padded cell (x, y, z)"))
        if self.sand is not None:
            for name, a in self.sand.particles().items():
                if a.dtype.kind == "f" and a.ndim >= 1 and a.shape[-1] == self.sand.n_particles:
                    arrays.append(("sand", name, a, "particle"))
        return arrays

    def check_finite(self) -> None:
        """Raise :class:`SimulationDiverged` naming the field and cell (or particle) of a NaN/Inf in any fluid
        field or population or any particle array."""
        for solver, name, a, where in self._solver_arrays():
            bad = ~np.isfinite(a)
            if bad.any():
                idx = np.unravel_index(int(np.argmax(bad)), a.shape)
                value = float(a[idx])
                if where == "particle":
                    index: tuple = (int(idx[-1]),)
                else:
                    z, y, x = (int(i) for i in idx[-3:])
                    shift = 1 if where.startswith("padded") else 0  # padded arrays: interior cell i at i + 1
                    index = (x - shift, y - shift, z - shift)
                    where = "cell (x, y, z)"
                raise SimulationDiverged(self.step_count, solver, name, index, value, where)

    def _states(self, statistics: bool = False) -> dict[str, dict[str, np.ndarray]]:
        """{solver: state} of every solver and the scheduler: what an exact restart needs (and the sand's grid
        of the last step, :meth:`couplekit.sand.solver.SandSolver.state`); ``statistics``: also the frame's
        sand-step statistics (:meth:`couplekit.schedulers.base.Scheduler.state`), as :meth:`save` and the run
        loop's last good state keep them, so that a loaded simulation's :meth:`diagnostics` are the saver's."""
        out = {}
        if self.fluid is not None:
            out["fluid"] = self.fluid.state()
        if self.sand is not None:
            out["sand"] = self.sand.state()
        if self.coupler is not None:
            out["coupler"] = self.coupler.state()
        if self.emitter is not None:
            out["emission"] = self.emitter.state()
        sched = self.scheduler.state(statistics=statistics)
        if sched:
            out["scheduler"] = sched
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
        self.scheduler.restart_at(step)
        self.scheduler.load_state(states.get("scheduler", {}))
        self.step_count = int(step)

    def _rebuild(self, quiet: bool = True) -> None:
        """Fresh solvers (scratch arrays outside the solver state, e.g. ghost layers, may hold NaN). ``quiet``:
        the scene's notes and cautions are not logged again (the constructor's first build logs them; a probe saw
        each caution again per rebuild after a divergence)."""
        log = (lambda _line: None) if quiet else self._log
        asm = assemble(self.scene, self.backend, log=log, timing=self._timing, warm_up_steps=1)
        self.assembly = asm
        self.fluid, self.sand, self.coupler = asm.fluid, asm.sand, asm.coupler
        self.emitter, self.scheduler = asm.emitter, asm.scheduler
        self._fluid_params = asm.fluid_params

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
        """Write an HDF5 checkpoint (scene, solver states, counters) for an exact restart. It also holds what
        the restart does not need but :meth:`fields` and :meth:`diagnostics` report, so that a loaded
        simulation reports what the saving one did: the sand grid of the last step (``sand_fraction``,
        ``sand_velocity``; :meth:`couplekit.sand.solver.SandSolver.state`, sparse) and the frame's sand-step
        statistics (:meth:`couplekit.schedulers.base.Scheduler.state`). Stage timings are not kept."""
        from .io.checkpoint import save_checkpoint

        if not isinstance(path, (str, os.PathLike)):
            raise TypeError(f"path must be a file path (a str or a pathlib.Path), got {type(path).__name__}")
        meta = {"step": self.step_count, "time": self.time, "backend": self.backend.name, "couplekit": __version__}
        if self.fluid is not None:
            # also in the stored scene (fluid.storage) and in the dtype of fluid/f and fluid/h
            meta["fluid_storage"] = self.fluid.storage
        return save_checkpoint(path, self.scene.to_dict(), self._states(statistics=True), meta)

    @classmethod
    def load(
        cls,
        path: str | Path,
        backend: str | Backend | None = "auto",
        threads: int | None = None,
        log: Callable[[str], Any] | None = print,
    ) -> Simulation:
        """Rebuild the scene of a checkpoint and restore its state (bitwise on the backend that wrote it).

        Refused with :class:`couplekit.io.CheckpointError` naming the file and the defect: a damaged or foreign
        file (:func:`couplekit.io.load_checkpoint` verifies every dataset's checksum), a stored scene this
        couplekit refuses, a state that does not fit the scene, or a state holding NaN/Inf (a restart from it
        would diverge at once; use an earlier checkpoint)."""
        from .io.checkpoint import CheckpointError, load_checkpoint
        from .scene import SceneError

        scene_dict, states, meta = load_checkpoint(path)
        try:
            scene = Scene.from_dict(scene_dict, source_name=f"scene of {path}")
        except SceneError as exc:
            raise CheckpointError(f"{path}: the scene it stores is refused by this couplekit:\n{exc}") from None
        sim = cls(scene, backend=backend, threads=threads, log=log)
        try:
            sim._load_states(states, int(meta["step"]))
        except (KeyError, ValueError, TypeError) as exc:
            what = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            raise CheckpointError(f"{path}: its state does not fit its scene: {what}") from None
        try:
            sim.check_finite()
        except SimulationDiverged as exc:
            raise CheckpointError(
                f"{path}: the checkpoint holds a non-finite value ({exc}); a restart would diverge at once: "
                "resume from an earlier checkpoint"
            ) from None
        if meta.get("backend") != sim.backend.name and log:
            log(f"note: checkpoint written by the {meta.get('backend')} backend, resumed on {sim.backend.name}")
        sim._resumed = True  # run() appends to the folder even for a checkpoint of step 0 (Ctrl-C before a step)
        return sim

    # ------------------------------------------------------------------------------------ run
    def preview_scale(self) -> tuple[float, float]:
        """(0, top) m/s: the sand-speed colour scale of every preview of this simulation, decided once from the
        scene (:func:`couplekit.io.preview.preview_speed_range`: ``time.max_speed``, else the scene's speed
        estimate) and logged, so that all frames share it."""
        if self._preview_scale is None:
            from .io.preview import preview_speed_range

            self._preview_scale, why = preview_speed_range(self.scene)
            if (self.sand is not None or self.scene.emits_sand) and self.preview_colouring()[0] == "speed":
                self._log(f"previews: sand speed coloured 0 to {self._preview_scale[1]:.3g} m/s in every frame ({why})")
        return self._preview_scale

    def preview_colouring(self) -> tuple[str, float | None]:
        """(colour_by, moisture_max) of this simulation's previews (:func:`couplekit.io.preview.render_preview`),
        decided once from the scene's ``outputs.preview_colour`` and logged: 'auto' colours by wetness where
        sand meets water (a coupled two-phase scene), else by speed; the wetness is the retained water r_p on
        the fixed scale 0 to r_max with retention, else the wet/dry classification S_r,p > (1 − ε_max)/2."""
        if self._preview_colour is None:
            choice = self.scene.outputs.preview_colour
            wet_possible = self.coupler is not None and self.coupler.two_phase
            mode = "wetness" if choice == "wetness" or (choice == "auto" and wet_possible) else "speed"
            r_max = (
                self.coupler.params.r_max
                if mode == "wetness" and self.coupler is not None and self.coupler.retention
                else None
            )
            self._preview_colour = (mode, r_max)
            if self.sand is not None or self.scene.emits_sand:
                if mode == "wetness":
                    how = f"retained water r_p, 0 to {r_max:.3g}" if r_max else "wet where S_r,p > (1 - eps_max)/2"
                    self._log(f"previews: sand coloured by wetness ({how}), dry sand light, wet sand dark")
        return self._preview_colour

    def write_frame(self, out: Path, indexes: dict, log_file: DiagnosticsLog | None) -> None:
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
        if o.surface and (o.surface_format or o.vtk):
            self._write_surface(out, indexes, frame, t)
        if o.preview and frame % o.preview_every == 0 and not self._preview_failed:
            colour_by, moisture_max = self.preview_colouring()
            try:
                render_preview(
                    out / f"preview_{frame:04d}.png",
                    self.scene.domain.size,
                    self.scene.domain.dx,
                    self.fields(),
                    parts,
                    title=f"{self.scene.name}  frame {frame}  t = {t:.4g} s",
                    speed_range=self.preview_scale(),
                    colour_by=colour_by,
                    moisture_max=moisture_max,
                )
            except Exception as exc:  # a missing OpenGL/EGL library must not stop the simulation
                self._preview_failed = True
                self._log(
                    f"warning: PNG previews disabled ({type(exc).__name__}: {exc}); the VTK/PLY outputs are "
                    "unaffected. Headless rendering needs EGL: apt-get install libegl1 libegl-mesa0 libgl1"
                )
        if log_file is not None:
            log_file.write(self.diagnostics())
        self.scheduler.frame_sand_steps()  # the next frame's substep statistics start here
        self._mark_stage_costs()  # and its stage costs

    def _write_surface(self, out: Path, indexes: dict, frame: int, t: float) -> None:
        """The water surface mesh of this frame (``outputs.surface``; :mod:`couplekit.io.surface`):
        surface_NNNN.<fmt> for each of ``outputs.surface_format`` and, with ``outputs.vtk``, surface_NNNN.vtp
        indexed by surface.pvd. Nothing without a phase field (no fluid or a single-phase one)."""
        from .io import PvdIndex
        from .io.surface import water_surface, write_surface

        if self.fluid is None or not self.fluid.two_phase:
            return
        f = self.fluid.fields()
        mesh = water_surface(f["phi"], self.scene.domain.dx, f["solid"])
        for fmt in self.scene.outputs.surface_format:
            write_surface(out / f"surface_{frame:04d}.{fmt}", mesh)
        if self.scene.outputs.vtk:
            if "surface" not in indexes:
                indexes["surface"] = PvdIndex(out / "surface.pvd")
            indexes["surface"].add(t, write_surface(out / f"surface_{frame:04d}.vtp", mesh))

    def run(
        self,
        frames: int | None = None,
        out: str | Path | None = None,
        progress: bool = True,
        stream: TextIO | None = None,
        stop: Callable[[], bool] | None = None,
        overwrite: bool = False,
        summary: bool = True,
    ) -> RunResult:
        """Simulate until ``frames`` frames are complete (default ``time.frames``), writing outputs into
        ``out`` (default ``outputs.directory`` or ``runs/<name>``).

        Each frame: step, NaN/Inf check, outputs, diagnostics line, progress bar; checkpoints every
        ``outputs.checkpoint_every`` frames and at the end (``checkpoint.h5``). Ctrl-C (SIGINT), SIGTERM (what
        batch schedulers and ``timeout`` send) or ``stop()`` returning True ends the run cleanly between steps with
        ``interrupted.h5`` (the result's ``signal`` names the signal). On NaN/Inf the last good
        state (the last one that passed the check) is written to ``last_good.h5`` and the report to
        ``diverged.txt``. At the end, also after a divergence or an interrupt, the diagnostics are drawn into
        ``summary.png`` (:func:`couplekit.io.plots.plot_run`; a plotting failure is only a warning; not with
        ``summary=False``, as sweep points run: their figures are drawn together by ``couplekit compare``).

        The folder is checked first (:func:`couplekit.io.outputs.prepare_output`): one holding an earlier run's
        outputs is refused unless this run resumes from a checkpoint (it appends), continues this simulation's
        own last run() in the same folder, or ``overwrite`` deletes them. A resume from a frame before the folder's
        last is refused too (it would replace the later frames), unless ``overwrite`` deletes those frames' files.
        A simulation stepped with :meth:`step` before its first run() is a new run: it does not append to (and so
        cut short) an earlier run's folder.
        """
        from .io import DiagnosticsLog, PvdIndex
        from .io.outputs import default_output, prepare_output, write_run_marker
        from .io.progress import ProgressBar

        sc = self.scene
        total = _count("frames", frames, least=1) if frames is not None else int(sc.time.frames)
        # every argument checked before the folder is touched (a probe: overwrite="no" deleted an earlier run)
        progress, overwrite, summary = (
            flag("progress", progress),
            flag("overwrite", overwrite),
            flag("summary", summary),
        )
        callable_or_none("stop", stop, "of no arguments returning True to stop")
        if stream is not None and not callable(getattr(stream, "write", None)):
            raise TypeError(f"stream must be a text stream with a write method (or None), got {type(stream).__name__}")
        if out is not None and not isinstance(out, (str, os.PathLike)):
            raise TypeError(f"out must be a folder path (a str or a pathlib.Path) or None, got {type(out).__name__}")
        folder = Path(out or sc.outputs.directory or default_output(sc.name))
        # a checkpoint's run appends; so does this simulation's own earlier run() into the same folder
        resumed = self._resumed or (self.step_count > 0 and self._run_folder == _resolved(folder))
        scene_dict = sc.to_dict()
        out = prepare_output(
            folder, resume=resumed, overwrite=overwrite, scene=scene_dict, frame=self.frame if resumed else None
        )
        self._run_folder = _resolved(out)
        write_run_marker(out, scene_dict)
        missing = [k for k in sc.outputs.fields if k not in self.fields()]
        if missing and sc.outputs.vtk:
            self._log(
                f"note: outputs.fields lists {', '.join(missing)}, which this scene does not produce (it produces "
                f"{', '.join(sorted(self.fields())) or 'no grid fields'}): not written"
            )
        indexes = {"fields": PvdIndex(out / "fields.pvd"), "particles": PvdIndex(out / "particles.pvd")}
        log_file = (
            DiagnosticsLog(out / "diagnostics.jsonl", append=resumed, until_step=self.step_count)
            if sc.outputs.diagnostics
            else None
        )
        self._log(f"effects on: {', '.join(k for k, v in self.effects.items() if v)}")
        self._log(f"writing to {out}")
        bar = ProgressBar(total, self.frame, stream=stream) if progress else None
        interrupted = {"flag": False}
        previous = None
        if threading_main():

            def _on_signal(signum, frame):
                interrupted["flag"] = True
                interrupted["signal"] = signal.Signals(signum).name

            previous = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        result = RunResult(status="done", out=str(out), checkpoint=None, steps=0)
        steps_done = 0
        chunk = max(1, min(self.steps_per_frame, 10))
        try:
            try:
                self.check_finite()  # a state from a checkpoint too: the last good state must be a checked one
            except SimulationDiverged as exc:  # nothing good to keep: the scene's numbers overflow float32, say
                report = (
                    f"{exc}\nthe initial state is not finite, so nothing was run: a scene value too large or too "
                    "small for float32 arithmetic (a density, size or time step), or a damaged checkpoint\n"
                )
                (out / "diverged.txt").write_text(report)
                self._log(report.strip())
                result.update(status="diverged", checkpoint=None, error=str(exc))
                return result
            if self.step_count == 0:
                self.write_frame(out, indexes, log_file)
            good, good_step = self._states(statistics=True), self.step_count
            while self.frame < total:
                target = (self.frame + 1) * self.steps_per_frame
                while self.step_count < target:
                    if interrupted["flag"] or (stop is not None and stop()):
                        path = self.save(out / "interrupted.h5")
                        self._log(f"\ninterrupted at step {self.step_count} (frame {self.frame}); checkpoint {path}")
                        result.update(status="interrupted", checkpoint=str(path), signal=interrupted.get("signal"))
                        return result
                    n = min(chunk, target - self.step_count)
                    try:
                        self.step(n)
                    except (TimeStepError, SubstepLimitError) as exc:
                        # the sand would outrun its step (particle CFL) or the substep cap: refused before it
                        # could go non-finite; kept like a divergence, so the run's outputs are not lost
                        at = self.step_count
                        path = self._keep_last_good(out, good, good_step)
                        report = (
                            f"stopped at step {at}: {exc}\n(a stability limit of the sand's time step: the run "
                            f"was stopped before it could go non-finite)\nlast good state: step {good_step} "
                            f"(frame {good_step // self.steps_per_frame}), saved to {path}\n"
                        )
                        (out / "diverged.txt").write_text(report)
                        self._log("\n" + report.strip())
                        result.update(status="diverged", checkpoint=str(path), error=str(exc))
                        return result
                    steps_done += n
                    if bar is not None and steps_done == n:  # the first steps loaded or compiled the kernels
                        bar.warmed(steps_done)
                try:
                    self.check_finite()
                except SimulationDiverged as exc:
                    first = self._locate_divergence(good, good_step, exc)
                    path = self._keep_last_good(out, good, good_step)
                    report = f"{first}\nlast good state: step {good_step} (frame {good_step // self.steps_per_frame}), saved to {path}\n"
                    (out / "diverged.txt").write_text(report)
                    self._log("\n" + report.strip())
                    result.update(status="diverged", checkpoint=str(path), error=str(first))
                    return result
                self.write_frame(out, indexes, log_file)
                # after the frame is written: its sand-step statistics are closed, so that a resume from
                # last_good.h5 starts the next frame's as checkpoint.h5 does (write_frame changes no solver)
                good, good_step = self._states(statistics=True), self.step_count
                every = sc.outputs.checkpoint_every
                if every and self.frame % every == 0 and self.frame < total:
                    result["checkpoint"] = str(self.save(out / "checkpoint.h5"))
                if bar is not None:
                    d = self.diagnostics()
                    info = {k: d[k] for k in ("fluid_volume_drift", "mach", "sand_max_speed") if k in d}
                    bar.update(self.frame, steps_done, info)
            result["checkpoint"] = str(self.save(out / "checkpoint.h5"))
            self._drop_passed_interrupt(out)
            return result
        finally:
            result.update(frames=self.frame, steps=steps_done)
            if bar is not None:
                bar.close()
            if steps_done:
                self._log(self.cost_summary())
            if log_file is not None:
                log_file.close()
                if summary and (steps_done or result.status != "done"):
                    self._write_summary_plot(out)
                elif summary:  # a finished checkpoint resumed: its diagnostics are in the folder it ran in
                    self._log(f"nothing left to run: the state is at frame {self.frame} of {total}; no summary.png")
            for sig, handler in (previous or {}).items():
                signal.signal(sig, handler)

    def _drop_passed_interrupt(self, out: Path) -> None:
        """Remove the folder's ``interrupted.h5`` once a finished run's ``checkpoint.h5`` is at or past its step: a
        resumed run that finished left it behind, offered as a state to resume from (a probe, session 24). One at a
        later step (a resume from an older checkpoint that stopped short of it) or one that cannot be read is kept."""
        from .io.checkpoint import CheckpointError, checkpoint_meta

        stale = out / "interrupted.h5"
        if not stale.is_file():
            return
        try:
            step = int(checkpoint_meta(stale)["step"])
        except (CheckpointError, KeyError, TypeError, ValueError):
            return
        if step <= self.step_count:
            stale.unlink()
            self._log(f"removed {stale}: step {step}, passed by this run's checkpoint.h5 (step {self.step_count})")

    def _keep_last_good(self, out: Path, good: dict, good_step: int) -> Path:
        """Back to the last checked state (fresh solvers, its arrays) and save it as ``last_good.h5``."""
        self._rebuild()
        self._load_states(good, good_step)
        return self.save(out / "last_good.h5")

    def _write_summary_plot(self, out: Path) -> None:
        """``summary.png`` of the run's diagnostics (:func:`couplekit.io.plots.plot_run`), also after a divergence
        or an interrupt; a failure to plot is a warning, never the run's failure."""
        try:
            from .io.plots import plot_run

            plot_run(out)
        except Exception as exc:  # matplotlib missing or broken, a full disk: the run's own outputs are written
            self._log(f"warning: summary.png not written ({type(exc).__name__}: {exc}); the diagnostics are in "
                      f"{out / 'diagnostics.jsonl'}; draw them later with couplekit plot {out}")  # fmt: skip

    def __repr__(self) -> str:
        parts = [f"Simulation({self.scene.name!r}, backend={self.backend.name}, step={self.step_count}"]
        if self.sand is not None:
            parts.append(f"{self.sand.n_particles} particles")
        return ", ".join(parts) + ")"


def _resolved(path: Path) -> Path:
    """``path`` made absolute (symlinks resolved where they exist), to compare run folders."""
    return Path(path).expanduser().resolve()


def threading_main() -> bool:
    """True in the main thread of the main interpreter (where signal handlers can be set)."""
    import threading

    return threading.current_thread() is threading.main_thread()
