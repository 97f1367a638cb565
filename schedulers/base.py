"""What every coupling scheduler shares: the solvers it was given, the effects they decide, per-stage timing,
the sand-only and fluid steps, substep statistics and a checkpointable state.

A scheduler advances ``fluid`` (FluidSolver or None), ``sand`` (SandSolver or None) and ``coupler``
(SandFluidCoupler of exactly these two, required when both are given) by calling their stages; the subclasses
decide the order and how often each solver steps (:mod:`.lockstep`, :mod:`.subcycle`, :mod:`.multirate`).
One :meth:`Scheduler.step` is one fluid (coupling) step Δt of ``[time] dt``; a sand-only scene's step is Δt of
simulated time however the scheduler divides it.

Timing (``timing=True``): each stage is bracketed by ``backend.synchronize()`` (a no-op on the CPU) and
``time.perf_counter``; the GPU pays one synchronisation per stage for it, so production runs may pass
``timing=False``, which runs the same calls without the proxy or the clock. A stage that runs several times in
one step (the sand stages of a sub-cycled step) adds up. The fluid's sub-stages are FluidSolver.step itself
(one code path): the scheduler times them through a thin proxy around the fluid's ops objects.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import numpy as np

from ..arguments import whole_count

__all__ = ["Scheduler", "SAND_STAGES", "FLUID_STAGES", "SubstepLimitError"]

SAND_STAGES = ("mpm_p2g", "mpm_grid_update", "mpm_g2p")
FLUID_STAGES = (
    "lbm_boundaries",
    "lbm_pressure",
    "lbm_pressure_filter",
    "volume_controller",
    "phase_field_collide_stream",
    "lbm_collide_stream",
    "phase_field_macroscopic",
    "lbm_other",
)

# FluidSolver ops methods -> stage
_FLUID_OPS = {
    "halo_copy": "lbm_boundaries",
    "halo_pull": "lbm_boundaries",
    "fold": "lbm_boundaries",
    "outflow_fix": "lbm_boundaries",
    "macro_pressure": "lbm_pressure",
    "pressure_filter": "lbm_pressure_filter",
    "collide_stream": "lbm_collide_stream",
}
_PHASE_OPS = {
    "volume_sums": "volume_controller",
    "mixture_sums": "volume_controller",
    "collide_stream": "phase_field_collide_stream",
    "macroscopic": "phase_field_macroscopic",
    "gradients": "phase_field_macroscopic",
}
_PHASE_STAGES = ("volume_controller", "phase_field_collide_stream", "phase_field_macroscopic")


class SubstepLimitError(ValueError):
    """The sand would need more substeps than the scheduler's cap allows (``scheduler.max_substeps``)."""


class _TimedOps:
    """Proxy of an ops object: the listed methods add their (synchronised) wall time to a stage while the
    scheduler is inside the fluid step; everything else passes through untouched."""

    def __init__(self, inner, stages: dict[str, str], scheduler: Scheduler):
        self._inner, self._stages, self._scheduler = inner, stages, scheduler

    def __getattr__(self, name: str):
        attr = getattr(self._inner, name)
        stage = self._stages.get(name)
        if stage is None or not callable(attr):
            return attr
        sched = self._scheduler

        def timed(*args, **kwargs):
            if not sched._in_fluid:
                return attr(*args, **kwargs)
            t0 = sched._clock()
            try:
                return attr(*args, **kwargs)
            finally:
                sched._add(stage, sched._clock() - t0)

        return timed


class Scheduler:
    """Base of the coupling schedulers (module docstring): checks the solvers, times stages, keeps substep
    statistics. Subclasses implement :meth:`_coupled_step` and :meth:`_sand_only_step` and list their
    coupled stages in :attr:`coupled_stages`.

    ``source_term``: apply the phase-field source S_φ (Eq. 45); False for the paper's Fig. 14 ablation.
    ``dt``: the coupling step Δt in s (see :attr:`dt`). ``timing``: time every stage; :meth:`stage_times` is the cost of each stage in the last step,
    :meth:`cost_report` the totals and means over all timed steps but the first ``warm_up_steps`` (steps that
    load or compile kernels, which are not a cost of the scene).
    """

    kind = "base"
    coupled_stages: tuple[str, ...] = ()
    folds_sand_velocity = False
    """Whether every fluid step follows its own step's coupling stages, so that the fluid need keep no sand velocity
    (:meth:`couplekit.coupling.coupler.SandFluidCoupler.fold_sand_velocity`; lockstep)."""

    def __init__(
        self,
        fluid=None,
        sand=None,
        coupler=None,
        source_term: bool = True,
        timing: bool = True,
        warm_up_steps: int = 0,
        dt: float | None = None,
    ):
        if fluid is None and sand is None:
            raise ValueError(f"{type(self).__name__} needs a fluid, a sand solver, or both")
        if fluid is not None and sand is not None:
            if coupler is None:
                raise ValueError("a scene with fluid and sand needs their SandFluidCoupler")
            if coupler.fluid is not fluid or coupler.sand is not sand:
                raise ValueError("the coupler joins other solvers than the ones given")
        elif coupler is not None:
            raise ValueError("a coupler needs both a fluid and a sand solver")
        self.fluid, self.sand, self.coupler = fluid, sand, coupler
        self.source_term = bool(source_term)
        if coupler is not None:
            # every scheduler computes S_φ before each fluid step and ends it with coupler.finish(): last step's
            # porosity can live in S_φ's buffer (SandFluidCoupler.share_source_buffer); without the source term
            # it needs a buffer of its own, and S_φ stays 0
            coupler.share_source_buffer(self.source_term)
            coupler.fold_sand_velocity(self.folds_sand_velocity)
        self.timing = bool(timing)
        self.warm_up_steps = int(warm_up_steps)
        self.backend = (fluid or sand).backend
        if dt is None:
            dt = coupler.units.dt if coupler is not None else sand.dt if sand is not None else 1.0
        self.dt = float(dt)
        """The coupling step Δt in s: the LBM step of a coupled scene (``units.dt``), a sand-only scene's step
        (default: the sand's Δt at construction)."""
        self.steps = 0
        """Steps this scheduler has advanced (since construction)."""
        self._step_offset = 0
        self._in_fluid = False
        self._last: dict[str, float] = {}
        self._total: dict[str, float] = {}
        self._timed_steps = 0
        self._sand_steps_total = 0.0
        self._counted_steps = 0
        self._frame_sand: list[float] = []
        self.last_sand_steps = 0.0
        """Sand (MPM) steps taken in the last step: k for a sub-cycled step, 1 or 0 for a multi-rate one."""
        if self.timing and fluid is not None:
            if not isinstance(fluid.ops, _TimedOps):
                fluid.ops = _TimedOps(fluid.ops, _FLUID_OPS, self)
            if fluid.two_phase and not isinstance(fluid.pf_ops, _TimedOps):
                fluid.pf_ops = _TimedOps(fluid.pf_ops, _PHASE_OPS, self)

    # ------------------------------------------------------------------ what runs
    @property
    def effects(self) -> dict[str, bool]:
        """Which parts of Algorithm 1 this scheduler runs (decided by the solvers it was given)."""
        coupled = self.coupler is not None
        two_phase = bool(self.fluid is not None and self.fluid.two_phase)
        return {
            "fluid": self.fluid is not None,
            "sand": self.sand is not None,
            "coupling": coupled,
            "source_term": coupled and two_phase and self.source_term,
            "retention": coupled and bool(self.coupler.retention),
            "phase_field": two_phase,
        }

    def stages(self) -> tuple[str, ...]:
        """The stages one step runs, in order (fluid sub-stages as FluidSolver.step calls them)."""
        eff = self.effects
        out: list[str] = []
        if eff["coupling"]:
            out += [s for s in self.coupled_stages if s != "retention_source" or eff["source_term"]]
        elif eff["sand"]:
            out += list(SAND_STAGES)
        if eff["fluid"]:
            out += [s for s in FLUID_STAGES if eff["phase_field"] or s not in _PHASE_STAGES]
        if eff["coupling"]:
            out.append("coupling_finish")
        return tuple(out)

    def describe(self) -> str:
        """One line: the scheme and its parameters."""
        return self.kind

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` coupling steps of Δt; ``n`` a whole number >= 0 (as
        :meth:`couplekit.simulation.Simulation.step`)."""
        for _ in range(whole_count("n", n)):
            self._last = {}
            if self.coupler is not None:
                self._coupled_step()
            else:
                if self.sand is not None:
                    self._sand_only_step()
                if self.fluid is not None:
                    self._fluid_step()
            self.steps += 1
            self._counted_steps += 1
            self._sand_steps_total += self.last_sand_steps
            self._frame_sand.append(self.last_sand_steps)
            if self.timing and self.steps > self.warm_up_steps:
                self._timed_steps += 1
                for k, v in self._last.items():
                    self._total[k] = self._total.get(k, 0.0) + v

    def _coupled_step(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _sand_only_step(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _mpm_step(self) -> None:
        """The three MPM stages of one sand step (no fluid), then the particle CFL check."""
        sand, stage = self.sand, self._stage
        with stage("mpm_p2g"):
            sand.p2g()
        with stage("mpm_grid_update"):
            sand.grid_update()
        with stage("mpm_g2p"):
            sand.g2p()
        self._check_sand_dt()

    def _check_sand_dt(self) -> None:
        sand = self.sand
        if sand.cfl_check_every and sand.steps % sand.cfl_check_every == 0:
            sand.set_dt(sand.dt)  # re-checks the particle CFL limit, as SandSolver.step does

    def _fluid_step(self) -> None:
        if not self.timing:
            self.fluid.step(1)
            return
        before = sum(self._last.get(s, 0.0) for s in FLUID_STAGES)
        t0 = self._clock()
        self._in_fluid = True
        try:
            self.fluid.step(1)
        finally:
            self._in_fluid = False
        total = self._clock() - t0
        inner = sum(self._last.get(s, 0.0) for s in FLUID_STAGES) - before
        self._add("lbm_other", max(total - inner, 0.0))

    # ------------------------------------------------------------------ substeps
    def sand_steps(self) -> dict[str, float]:
        """Sand steps per coupling step: ``total`` since construction (or the restart), ``mean`` per step, and
        over the steps since the last :meth:`frame_sand_steps` call ``frame_mean``, ``frame_min``,
        ``frame_max``."""
        frame = self._frame_sand or [self.last_sand_steps]
        counted = self._counted_steps
        return {
            "total": self._sand_steps_total,
            "mean": self._sand_steps_total / max(counted, 1),
            "frame_mean": float(np.mean(frame)),
            "frame_min": float(np.min(frame)),
            "frame_max": float(np.max(frame)),
        }

    def frame_sand_steps(self) -> dict[str, float]:
        """:meth:`sand_steps`, then start a new frame's statistics."""
        out = self.sand_steps()
        self._frame_sand = []
        return out

    # ------------------------------------------------------------------ checkpoint
    def state(self, statistics: bool = False) -> dict[str, np.ndarray]:
        """What a bitwise restart needs of the scheduler beyond its step count (host arrays; empty for the
        lockstep and multi-rate schedulers). Solver states are the solvers' own; the step count is the
        simulation's (:meth:`restart_at`).

        ``statistics`` (a checkpoint, :meth:`couplekit.simulation.Simulation.save`): with a sand solver, also
        the sand-step statistics of the current frame (:meth:`sand_steps`' ``frame_mean``, ``frame_min``,
        ``frame_max``: the diagnostics' ``sand_steps_per_step``, ``substeps_min``, ``substeps_max``). The
        restart does not need them (they are bookkeeping of the frames, so two runs of the same steps but
        other frame boundaries keep equal states without them), but without them a loaded simulation reported
        0 until its first step and a multi-rate frame's mean restarted counting. Stored as
        ``last_sand_steps`` and a histogram of the frame's steps, ``frame_sand_values`` (the distinct
        sand-step counts, float64) and ``frame_sand_counts`` (int64): a few numbers however long the frame.
        The sand-step counts are whole numbers, so the order the histogram drops does not change their mean
        (float64 sums of whole numbers are exact). ``total`` and ``mean`` count from the restart
        (:meth:`restart_at`); the stage timings are wall-clock and are not stored."""
        if not statistics or self.sand is None:
            return {}
        values, counts = np.unique(np.asarray(self._frame_sand, np.float64), return_counts=True)
        return {
            "last_sand_steps": np.array(float(self.last_sand_steps)),
            "frame_sand_values": values,
            "frame_sand_counts": counts.astype(np.int64),
        }

    def load_state(self, st: dict) -> None:
        """Restore a :meth:`state`; what it lacks (a checkpoint written before the statistics were saved, or
        before schedulers had a state) stays as built."""
        if "last_sand_steps" in st:
            self.last_sand_steps = float(np.asarray(st["last_sand_steps"]))
        if "frame_sand_values" in st and "frame_sand_counts" in st:
            values = np.asarray(st["frame_sand_values"], np.float64).reshape(-1)
            counts = np.asarray(st["frame_sand_counts"]).reshape(-1)
            if values.shape != counts.shape or counts.dtype.kind not in "iu" or (counts < 0).any():
                raise ValueError("scheduler state: frame_sand_values and frame_sand_counts do not match")
            self._frame_sand = [float(x) for x in np.repeat(values, counts)]

    def restart_at(self, steps: int) -> None:
        """A restart from a checkpoint written after ``steps`` steps: :attr:`step_index` continues from there (a
        multi-rate block's phase follows it); :attr:`steps` and the statistics count from the restart."""
        self._step_offset = int(steps) - self.steps

    @property
    def step_index(self) -> int:
        """Steps of the run so far, a restart's earlier steps included."""
        return self._step_offset + self.steps

    # ------------------------------------------------------------------ timing
    # the stage timers' clock; a benchmark on a shared host may set ``time.process_time`` (CPU time of the
    # process: the time other processes take the core away does not count; with one OpenMP thread)
    clock = staticmethod(time.perf_counter)

    def _clock(self) -> float:
        self.backend.synchronize()
        return self.clock()

    def _add(self, stage: str, seconds: float) -> None:
        self._last[stage] = self._last.get(stage, 0.0) + seconds

    @contextmanager
    def _stage(self, name: str):
        if not self.timing:
            yield
            return
        t0 = self._clock()
        try:
            yield
        finally:
            self._add(name, self._clock() - t0)

    def stage_times(self) -> dict[str, float]:
        """Seconds spent in each stage during the last step, in execution order (empty with ``timing=False``)."""
        return {s: self._last[s] for s in self.stages() if s in self._last}

    def cost_report(self) -> dict[str, dict[str, float]]:
        """Per stage over all timed steps: ``total`` s, ``mean`` s per step, ``fraction`` of the step."""
        grand = sum(self._total.values()) or 1.0
        n = max(self._timed_steps, 1)
        return {
            s: {"total": self._total[s], "mean": self._total[s] / n, "fraction": self._total[s] / grand}
            for s in self.stages()
            if s in self._total
        }

    def reset_timing(self) -> None:
        """Forget the accumulated stage times (e.g. after warm-up steps that compiled the kernels)."""
        self._last, self._total, self._timed_steps = {}, {}, 0

    def detach(self) -> None:
        """Remove the timing proxies from the fluid's ops (the solvers stay usable on their own)."""
        fluid = self.fluid
        if fluid is not None:
            if isinstance(fluid.ops, _TimedOps):
                fluid.ops = fluid.ops._inner
            if fluid.two_phase and isinstance(fluid.pf_ops, _TimedOps):
                fluid.pf_ops = fluid.pf_ops._inner
