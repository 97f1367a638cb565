"""Sub-cycling scheduler: k MPM substeps of Δt/k inside every LBM step of Δt.

Paper 000 names the MPM's small time step as the bottleneck of the coupled system and sub-cycling as the way
out (its "Limitations"); the Granule-In-Cell paper (001) runs its DEM in substeps inside each fluid step with
the fluid held and hands the summed force back (its Eq. 18). This scheduler does that for the MPM, from the
solver stages Algorithm 1 uses (one code path with :mod:`.lockstep`), so the fluid can take the step its own
limits allow (lattice Mach number, relaxation time) while the sand meets its elastic and particle CFL limits.

One step (Δt, the fluid step of ``[time] dt``), stage names as :meth:`SubcycleScheduler.stage_times` reports:

1. ``fluid_velocity``: u0 = Σ f c of the current populations (the velocity the lockstep exchange sees).
2. k times, substep s = 0 … k − 1 of δt = Δt/k (the sand's Δt):

   * ``mpm_p2g``; ``volume_fractions`` with the substep's share 1/k of the fluid step's absorption (retention,
     :meth:`couplekit.coupling.reference.ReferenceOps.fractions`);
   * ``fluid_view``: what the sand sees of the fluid (s ≥ 1), u_s = u0 [+ θ (u0 − u_prev)] + A / (ρ ε_f)
     (:meth:`couplekit.coupling.reference.ReferenceOps.fluid_view`): held (``interpolation = "hold"``) or
     linear in time through the last two fluid states at the substep's start θ = s/k (``"linear"``;
     extrapolated, since the fluid's next state is computed after the substeps), plus the velocity the fluid
     gains from the drag impulse A the earlier substeps took from it. φ (the density) is held.
   * ``drag_buoyancy`` over δt, ``mpm_grid_update``, ``moisture``, ``mpm_g2p``;
   * ``substep_sums``: the substep's fluid force (−J/δt in lattice units), porosity and sand grid velocity
     into their averages over the substeps, its absorbed water dR into their sum.

3. ``substep_sums``: the averages become the fluid's inputs: force = −Σ J (the impulse the sand took, handed
   to the fluid once), porosity ε̃ = the substeps' mean, dR = their sum; ``retention_source``: S_φ (Eq. 45/57)
   from that porosity and last step's; ``sand_velocity``: the substeps' mean grid velocity (Eq. 39's input).
4. The fluid step (the lockstep stages), ``coupling_finish``.

Why this is conservative:

* Momentum: every substep's impulse J_s goes to the sand's grid momentum and −J_s into the force the fluid
  applies in its one step, so fluid + sand momentum changes by float32 round-off only, for any k and drag
  strength (tests/test_subcycle.py). The fluid-response term of ``fluid_view`` keeps each substep's implicit
  exchange consistent with the fluid it acts on: with the fluid held alone, a strong drag would pull the sand
  to the fluid's old velocity k times over and the fluid, handed the sum, would overshoot.
* Fluid volume: S_φ is computed once per fluid step from the porosity the fluid sees (the substeps' mean) and
  the one it saw in the last step, so the phase field carries Σ ε̃ φ + bound water from step to step as in
  lockstep (the source term's own conservation, Eq. 45), whatever k is.

k = 1 is the lockstep step on the cpu backend (the first substep exchanges with u0 itself and its sums are w x
with w = 1): bit for bit with lockstep's split fold off (``SandFluidCoupler.fold_sand_velocity(False)``), to
round-off with it on, the default (docs/schedulers.md). ``substeps = "auto"`` chooses each step the smallest k with δt within the MPM's
elastic and particle CFL limits (:meth:`couplekit.sand.solver.SandSolver.max_stable_dt`); more than
``max_substeps`` raises :class:`~couplekit.schedulers.base.SubstepLimitError` naming the key.

Accuracy: the sand's own integration (symplectic Euler) is first order in δt; the coupling to a held fluid is
first order in Δt. At a fixed Δt the error against a k → ∞ run therefore falls as δt = Δt/k (first order,
measured in tests/test_subcycle.py); against a fine lockstep reference it falls with k until the Δt part
dominates. What that buys in wall time: benchmarks/accuracy_vs_cost.py.
"""

from __future__ import annotations

import math

import numpy as np

from .base import Scheduler, SubstepLimitError

__all__ = ["SubcycleScheduler", "SUBCYCLE_STAGES", "INTERPOLATIONS"]

SUBCYCLE_STAGES = (
    "fluid_velocity",
    "mpm_p2g",
    "volume_fractions",
    "fluid_view",
    "drag_buoyancy",
    "mpm_grid_update",
    "moisture",
    "mpm_g2p",
    "substep_sums",
    "retention_source",
    "sand_velocity",
)
INTERPOLATIONS = ("hold", "linear")


class SubcycleScheduler(Scheduler):
    """k MPM substeps of Δt/k per LBM step of Δt (module docstring).

    ``substeps``: k (an integer ≥ 1) or ``"auto"``; ``max_substeps``: the cap of ``"auto"``;
    ``interpolation``: ``"hold"`` or ``"linear"``; ``dt``: the fluid step Δt in s (default ``coupler.units.dt``;
    required for a sand-only scene, whose sand is built with Δt/k). The sand solver's Δt must be Δt/k for a
    fixed k; with ``"auto"`` the scheduler sets it every step. Other arguments:
    :class:`~couplekit.schedulers.base.Scheduler`.
    """

    kind = "subcycle"
    coupled_stages = SUBCYCLE_STAGES

    def __init__(
        self,
        fluid=None,
        sand=None,
        coupler=None,
        substeps: int | str = "auto",
        interpolation: str = "hold",
        max_substeps: int = 64,
        source_term: bool = True,
        timing: bool = True,
        warm_up_steps: int = 0,
        dt: float | None = None,
    ):
        if sand is None:
            raise ValueError("sub-cycling needs a sand solver (there is nothing to sub-cycle in a fluid-only scene)")
        if substeps != "auto" and (isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1):
            raise ValueError(f"substeps must be an integer >= 1 or 'auto', got {substeps!r}")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        if not (isinstance(max_substeps, int) and max_substeps >= 1):
            raise ValueError(f"max_substeps must be an integer >= 1, got {max_substeps!r}")
        if coupler is None and dt is None:
            raise ValueError("a sand-only sub-cycled scene needs the step dt (the sand steps dt / substeps)")
        super().__init__(fluid, sand, coupler, source_term, timing, warm_up_steps, dt)
        self.substeps = substeps
        self.max_substeps = int(max_substeps)
        self.interpolation = interpolation
        if substeps != "auto" and not math.isclose(sand.dt * substeps, self.dt, rel_tol=1e-9):
            raise ValueError(f"the sand's step {sand.dt} s is not dt / substeps = {self.dt} / {substeps} s")
        self.last_sand_steps = float(substeps if substeps != "auto" else 1)
        self._u_prev = None
        self._have_prev = False
        if coupler is not None:
            xp = self.backend.xp
            f = fluid
            self._u_seen = xp.zeros_like(coupler.fluid_u)
            self._force_sub = xp.zeros_like(f.force)
            self._eps_avg = xp.zeros_like(f.fluid_fraction)
            self._grid_v_avg = xp.zeros_like(sand.grid_v)
            self._d_bound_sum = xp.zeros_like(coupler.d_bound) if coupler.retention else None
            if interpolation == "linear":
                self._u_prev = xp.zeros_like(coupler.fluid_u)

    def describe(self) -> str:
        k = f"substeps = {self.substeps}" + (f" (at most {self.max_substeps})" if self.substeps == "auto" else "")
        return f"subcycle: {k}, fluid data {self.interpolation}"

    # ------------------------------------------------------------------ substeps
    def substeps_now(self) -> int:
        """k for the coming step: the fixed k, or (``"auto"``) the smallest k with Δt/k within the sand's
        stable Δt (elastic and particle CFL at the particles' current speed)."""
        if self.substeps != "auto":
            return int(self.substeps)
        limit = self.sand.max_stable_dt()
        k = max(1, math.ceil(self.dt / limit * (1.0 - 1e-12)))
        if k > self.max_substeps:
            sand = self.sand
            elastic = sand.elastic_cfl * sand.dx / sand.p_wave_speed
            raise SubstepLimitError(
                f"the sand needs {k} substeps of the fluid step dt = {self.dt:.4g} s (its stable step is "
                f"{limit:.4g} s: elastic limit {elastic:.4g} s, particle CFL {sand.cfl} dx / max|v| with max|v| = "
                f"{sand._max_speed():.4g} m/s) but scheduler.max_substeps = {self.max_substeps}: raise "
                f"scheduler.max_substeps to >= {k}, or lower time.dt"
            )
        self.sand.dt = self.dt / k
        return k

    # ------------------------------------------------------------------ stepping
    def _sand_only_step(self) -> None:
        k = self.substeps_now()
        for _ in range(k):
            self._mpm_step()
        self.last_sand_steps = float(k)

    def _coupled_step(self) -> None:
        c, sand, f = self.coupler, self.sand, self.fluid
        stage, ops = self._stage, c.ops
        k = self.substeps_now()
        w = 1.0 / k
        prm = f.params
        with stage("fluid_velocity"):
            c.fluid_velocity()
        u_prev = self._u_prev if self._have_prev else None
        for s in range(k):
            first = s == 0
            with stage("mpm_p2g"):
                sand.p2g()
            with stage("volume_fractions"):
                c.fractions(share=w)
            u = c.fluid_u
            if not first:
                with stage("fluid_view"):
                    u = self._u_seen
                    ops.fluid_view(c.fluid_u, u_prev, f.force, f.phi, f.fluid_fraction, f.flags, u, s / k,
                                   prm.rho_h, prm.rho_l)  # fmt: skip
            with stage("drag_buoyancy"):
                c.exchange(u=u, force=self._force_sub)
            with stage("substep_sums"):
                ops.accumulate(f.force, self._force_sub, w, first)  # the fluid force: −Σ J so far
            with stage("mpm_grid_update"):
                sand.grid_update()
            with stage("moisture"):
                c.moisture()
            with stage("mpm_g2p"):
                sand.g2p()
            with stage("substep_sums"):
                ops.accumulate(self._eps_avg, f.fluid_fraction, w, first)
                ops.accumulate(self._grid_v_avg, sand.grid_v, w, first)
                if c.retention:
                    ops.accumulate(self._d_bound_sum, c.d_bound, 1.0, first)
            if self.substeps != "auto":
                self._check_sand_dt()
        with stage("substep_sums"):  # the substeps' averages become what the fluid sees
            f.fluid_fraction, self._eps_avg = self._eps_avg, f.fluid_fraction
            if c.retention:
                c.d_bound, self._d_bound_sum = self._d_bound_sum, c.d_bound
        if c.two_phase and self.source_term:
            with stage("retention_source"):
                c.phase_source()
        if self._u_prev is not None:  # before the sand velocity overwrites u0's buffer (SandFluidCoupler)
            self._u_prev[...] = c.fluid_u
            self._have_prev = True
        with stage("sand_velocity"):
            c.sand_velocity(self._grid_v_avg)
        self._fluid_step()
        with stage("coupling_finish"):
            c.finish()
        self.last_sand_steps = float(k)

    # ------------------------------------------------------------------ checkpoint
    def state(self, statistics: bool = False) -> dict[str, np.ndarray]:
        """With linear interpolation, last step's u0 (the sand's Δt is in the sand's own state); ``statistics``:
        :meth:`~couplekit.schedulers.base.Scheduler.state`."""
        st = super().state(statistics)
        if self._u_prev is not None:
            st["u_prev"] = self.backend.to_host(self._u_prev)
            st["have_prev"] = np.array(self._have_prev)
        return st

    def load_state(self, st: dict) -> None:
        super().load_state(st)
        if self._u_prev is not None:
            if "u_prev" in st:
                self._u_prev[...] = self.backend.asarray(np.asarray(st["u_prev"], np.float32), np.float32)
                self._have_prev = bool(np.asarray(st["have_prev"]))
            else:  # a checkpoint of another scheduler: start holding, as on the first step
                self._have_prev = False
