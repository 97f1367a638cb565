"""Multi-rate scheduler: one MPM step of m Δt every m LBM steps of Δt, for scenes whose sand is the slow
process (a settled bed under flowing water, sand resting on the floor of a pool).

The converse of :mod:`.subcycle`: the fluid takes its own step and the sand steps once per block of m fluid
steps (``[scheduler] sand_every = m``), exchanging over its whole step. A block:

* first fluid step of the block: the lockstep stages in Algorithm 1's order, with the sand's Δt = m Δt:
  ``mpm_p2g``, ``fluid_velocity``, ``volume_fractions`` (the absorption of m fluid steps, retention),
  ``retention_source``, ``drag_buoyancy`` (implicit over m Δt; the fluid receives −J/m per fluid step),
  ``mpm_grid_update``, ``moisture``, ``mpm_g2p``, ``sand_velocity``, the fluid step, ``coupling_finish``;
* the m − 1 other fluid steps: the sand and its fraction, velocity and drag force are held; ``fluid_velocity``
  and ``retention_source`` recompute S_φ for the fluid's own motion (Eq. 45's u·∇ε̃ term: with ε̃ unchanged
  since the last step, its (ε̃ − ε̃_prev) part is zero, and the absorbed water dR was handed over in the first
  step), then the fluid step and ``coupling_finish``.  Because Σ f c is computed while the sand velocity is
  held, m > 1 gives the coupler's exchange velocity a buffer of its own (12 B per cell; lockstep and m = 1
  keep it in the fluid's sand-velocity buffer, :class:`~couplekit.coupling.coupler.SandFluidCoupler`).

Conservation: the drag force −J/m applied over the block's m fluid steps gives the fluid exactly the −J the
sand took, so fluid + sand momentum changes by round-off only; the porosity changes once per block and the
source term carries Σ ε̃ φ + bound water across that change as in lockstep. m = 1 is the lockstep step, bit for
bit with lockstep's split fold off (``SandFluidCoupler.fold_sand_velocity(False)``; to round-off with it on, the
default: docs/schedulers.md). The sand's Δt m Δt must meet its elastic and particle CFL limits (validated by the scene, key
``scheduler.sand_every``).
"""

from __future__ import annotations

import math

from .base import Scheduler
from .lockstep import COUPLED_STAGES, algorithm1_step

__all__ = ["MultirateScheduler"]


class MultirateScheduler(Scheduler):
    """One MPM step of ``sand_every`` × Δt per ``sand_every`` LBM steps (module docstring). The sand solver
    must be built with Δt = ``sand_every`` × ``dt`` (``dt``: the fluid step, default ``coupler.units.dt``;
    required for a sand-only scene). Other arguments: :class:`~couplekit.schedulers.base.Scheduler`."""

    kind = "multirate"
    coupled_stages = COUPLED_STAGES

    def __init__(
        self,
        fluid=None,
        sand=None,
        coupler=None,
        sand_every: int = 2,
        source_term: bool = True,
        timing: bool = True,
        warm_up_steps: int = 0,
        dt: float | None = None,
    ):
        if sand is None:
            raise ValueError("multi-rate stepping needs a sand solver (a fluid-only scene has one rate)")
        if isinstance(sand_every, bool) or not isinstance(sand_every, int) or sand_every < 1:
            raise ValueError(f"sand_every must be an integer >= 1, got {sand_every!r}")
        if coupler is None and dt is None:
            raise ValueError("a sand-only multi-rate scene needs the step dt (the sand steps sand_every × dt)")
        super().__init__(fluid, sand, coupler, source_term, timing, warm_up_steps, dt)
        self.sand_every = int(sand_every)
        if coupler is not None and self.sand_every > 1:
            # the block's other steps compute Σ f c for S_φ while the fluid still needs the sand velocity of
            # the block's sand step: the two cannot share a buffer (SandFluidCoupler module docstring)
            coupler.own_fluid_velocity()
        if not math.isclose(sand.dt, self.sand_every * self.dt, rel_tol=1e-9):
            raise ValueError(f"the sand's step {sand.dt} s is not sand_every × dt = {self.sand_every} × {self.dt} s")

    def describe(self) -> str:
        return f"multirate: one sand step of {self.sand_every} fluid steps"

    def _sand_due(self) -> bool:
        return self.step_index % self.sand_every == 0

    def _sand_only_step(self) -> None:
        due = self._sand_due()
        if due:
            self._mpm_step()
        self.last_sand_steps = 1.0 if due else 0.0

    def _coupled_step(self) -> None:
        c, stage = self.coupler, self._stage
        if self._sand_due():
            algorithm1_step(self, share=float(self.sand_every))
            if c.retention and self.sand_every > 1:
                c.d_bound[...] = 0.0  # the block's absorbed water is in this step's source term only
            self.last_sand_steps = 1.0
            return
        with stage("fluid_velocity"):
            c.fluid_velocity()
        if c.two_phase and self.source_term:
            with stage("retention_source"):
                c.phase_source()
        self._fluid_step()
        with stage("coupling_finish"):
            c.finish()
        self.last_sand_steps = 0.0
