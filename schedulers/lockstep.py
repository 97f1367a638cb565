"""Lockstep scheduler: paper 000's Algorithm 1, one MPM step per LBM step with the same Δt, timing every
stage.

One step of a coupled scene (a SandSolver, a FluidSolver and the SandFluidCoupler joining them), stage names
as reported by :meth:`LockstepScheduler.stage_times`:

====================================  =================================================================
stage                                 Algorithm 1 line (paper 000 equations)
====================================  =================================================================
``mpm_p2g``                           MPM_ParticlesToGrid (Eq. 24)
``fluid_velocity``                    u = Σ f c of the current populations for the exchange (Eq. 13,
                                      no force shift; SandFluidCoupler docstring)
``volume_fractions``                  ComputeVolumeFractions (Eqs. 25, 33, 54; with retention the
                                      bound-water P2G, Eq. 53, and absorption, Eqs. 55–56)
``retention_source``                  UpdateWaterRetentionAndSource: S_φ (Eqs. 45, 57)
``drag_buoyancy``                     the total force on the sand (buoyancy Eq. 31, implicit drag §4.3)
``mpm_grid_update``                   MPM_UpdateGridMomenta (Eqs. 26, 29, boundaries)
``moisture``                          saturation for cohesion (Eq. 59), moisture ratio (Eq. 58)
``mpm_g2p``                           MPM_GridToParticlesAndAdvect (Eq. 30)
``sand_velocity``                     the sand grid velocity handed to the fluid (input of Eq. 39)
``lbm_boundaries``                    ghost / periodic / outflow copies of the fluid step
``lbm_pressure``                      UpdatePressureField (Eq. 39)
``lbm_pressure_filter``               ApplyFilter (Eq. 40)
``volume_controller``                 Σ ε φ and Σ ε S_φ for γ (Eq. 52)
``phase_field_collide_stream``        PhaseFieldCollision + Streaming (Eqs. 48, 45, 57)
``lbm_collide_stream``                ComputeCouplingAndBodyForces + FluidCollision + FluidStreaming
                                      (Eqs. 15–20, 9, 10; the forces are fused into the collision)
``phase_field_macroscopic``           Update phase field φ (Eq. 47), ∇φ and μ for the next step
``lbm_other``                         the rest of FluidSolver.step (Python glue)
``coupling_finish``                   this step's porosity becomes last step's
====================================  =================================================================

The fluid stages are FluidSolver.step itself (one code path): the scheduler times them through a thin
proxy around the fluid's ops objects.  FluidSolver runs the fluid collision before the phase-field
collision, the reverse of Algorithm 1's listing; nothing differs, because within a step neither reads what
the other writes: both use φ^n, and the phase field advects with the velocity u^n of Eq. 13 (the Guo-shifted
velocity the fluid collision writes, computed from the pre-collision populations — Algorithm 1's "Update
velocity field u" of LBM stage 1).

Effects are decided by the scene through what is passed: no sand → no coupler, only the fluid stages (no
coupling stage runs and no coupling field exists); no fluid → only the three MPM stages; a single-phase
fluid → no source term; no retention → the coupler allocates no bound-water field and skips its stages
(CouplingParams.retention).  ``source_term=False`` switches S_φ off for an ablation (paper Fig. 14);
with retention that also leaves the absorbed water dR in the phase field (Eq. 57 is part of S_φ), so the
ablation is meant for scenes without retention.

Timing (``timing=True``): each stage is bracketed by ``backend.synchronize()`` (a no-op on the CPU) and
``time.perf_counter``; the GPU pays one synchronisation per stage for it, so production runs may pass
``timing=False``, which runs the same calls without the proxy or the clock.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

__all__ = ["LockstepScheduler", "COUPLED_STAGES", "FLUID_STAGES", "SAND_STAGES"]

SAND_STAGES = ("mpm_p2g", "mpm_grid_update", "mpm_g2p")
COUPLED_STAGES = (
    "mpm_p2g",
    "fluid_velocity",
    "volume_fractions",
    "retention_source",
    "drag_buoyancy",
    "mpm_grid_update",
    "moisture",
    "mpm_g2p",
    "sand_velocity",
)
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
    "fold": "lbm_boundaries",
    "outflow_fix": "lbm_boundaries",
    "macro_pressure": "lbm_pressure",
    "pressure_filter": "lbm_pressure_filter",
    "collide_stream": "lbm_collide_stream",
}
_PHASE_OPS = {
    "volume_sums": "volume_controller",
    "collide_stream": "phase_field_collide_stream",
    "macroscopic": "phase_field_macroscopic",
    "gradients": "phase_field_macroscopic",
}


class _TimedOps:
    """Proxy of an ops object: the listed methods add their (synchronised) wall time to a stage while the
    scheduler is inside the fluid step; everything else passes through untouched."""

    def __init__(self, inner, stages: dict[str, str], scheduler: LockstepScheduler):
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


class LockstepScheduler:
    """Paper Algorithm 1: ``fluid`` (FluidSolver or None), ``sand`` (SandSolver or None) and ``coupler``
    (SandFluidCoupler of exactly these two, required when both are given) advanced together, one MPM step
    per LBM step.

    ``source_term``: apply the phase-field source S_φ (Eq. 45); False for the paper's Fig. 14 ablation.
    ``timing``: time every stage (module docstring).  :meth:`stage_times` is the cost of each stage in the
    last step, :meth:`cost_report` the totals and means over all timed steps but the first
    ``warm_up_steps`` (steps that load or compile kernels, which are not a cost of the scene).
    """

    def __init__(
        self,
        fluid=None,
        sand=None,
        coupler=None,
        source_term: bool = True,
        timing: bool = True,
        warm_up_steps: int = 0,
    ):
        if fluid is None and sand is None:
            raise ValueError("LockstepScheduler needs a fluid, a sand solver, or both")
        if fluid is not None and sand is not None:
            if coupler is None:
                raise ValueError("a scene with fluid and sand needs their SandFluidCoupler")
            if coupler.fluid is not fluid or coupler.sand is not sand:
                raise ValueError("the coupler joins other solvers than the ones given")
            if sand.dt != coupler.units.dt:
                raise ValueError(f"lockstep needs the MPM step {sand.dt} s equal to the LBM step {coupler.units.dt} s")
        elif coupler is not None:
            raise ValueError("a coupler needs both a fluid and a sand solver")
        self.fluid, self.sand, self.coupler = fluid, sand, coupler
        self.source_term = bool(source_term)
        self.timing = bool(timing)
        self.warm_up_steps = int(warm_up_steps)
        self.backend = (fluid or sand).backend
        self.steps = 0
        self._in_fluid = False
        self._last: dict[str, float] = {}
        self._total: dict[str, float] = {}
        self._timed_steps = 0
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
            out += [s for s in COUPLED_STAGES if s != "retention_source" or eff["source_term"]]
        elif eff["sand"]:
            out += list(SAND_STAGES)
        if eff["fluid"]:
            phase = ("volume_controller", "phase_field_collide_stream", "phase_field_macroscopic")
            out += [s for s in FLUID_STAGES if eff["phase_field"] or s not in phase]
        if eff["coupling"]:
            out.append("coupling_finish")
        return tuple(out)

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` lockstep steps."""
        for _ in range(int(n)):
            self._last = {}
            if self.coupler is not None:
                self._coupled_step()
            else:
                if self.sand is not None:
                    self._sand_step()
                if self.fluid is not None:
                    self._fluid_step()
            self.steps += 1
            if self.timing and self.steps > self.warm_up_steps:
                self._timed_steps += 1
                for k, v in self._last.items():
                    self._total[k] = self._total.get(k, 0.0) + v

    def _coupled_step(self) -> None:
        c, sand = self.coupler, self.sand
        stage = self._stage
        with stage("mpm_p2g"):
            sand.p2g()
        with stage("fluid_velocity"):
            c.fluid_velocity()
        with stage("volume_fractions"):
            c.fractions()
        if c.two_phase and self.source_term:
            with stage("retention_source"):
                c.phase_source()
        with stage("drag_buoyancy"):
            c.exchange()
        with stage("mpm_grid_update"):
            sand.grid_update()
        with stage("moisture"):
            c.moisture()
        with stage("mpm_g2p"):
            sand.g2p()
        with stage("sand_velocity"):
            c.sand_velocity()
        self._fluid_step()
        with stage("coupling_finish"):
            c.finish()
        self._check_sand_dt()

    def _sand_step(self) -> None:
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

    # ------------------------------------------------------------------ timing
    def _clock(self) -> float:
        self.backend.synchronize()
        return time.perf_counter()

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
