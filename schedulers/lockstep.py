"""Lockstep scheduler: paper 000's Algorithm 1, one MPM step per LBM step with the same Δt, timing every
stage.

One step of a coupled scene (a SandSolver, a FluidSolver and the SandFluidCoupler joining them), stage names
as reported by :meth:`LockstepScheduler.stage_times`:

====================================  =================================================================
stage                                 Algorithm 1 line (paper 000 equations)
====================================  =================================================================
``mpm_p2g``                           MPM_ParticlesToGrid (Eq. 24)
``volume_fractions``                  ComputeVolumeFractions (Eqs. 25, 33, 54; with retention the
                                      bound-water P2G, Eq. 53, and absorption, Eqs. 55–56)
``fluid_velocity``                    u = Σ f c of the current populations for the exchange (Eq. 13,
                                      no force shift; SandFluidCoupler docstring), over the last
                                      collision's u once its part of Eq. 39's slip term is taken
``retention_source``                  UpdateWaterRetentionAndSource: S_φ (Eqs. 45, 57)
``drag_buoyancy``                     the total force on the sand (buoyancy Eq. 31, implicit drag §4.3)
``mpm_grid_update``                   MPM_UpdateGridMomenta (Eqs. 26, 29, boundaries)
``moisture``                          saturation for cohesion (Eq. 59), moisture ratio (Eq. 58)
``mpm_g2p``                           MPM_GridToParticlesAndAdvect (Eq. 30)
``sand_velocity``                     the sand grid velocity handed to the fluid: Eq. 39's sand terms folded
                                      into the pressure update's kept population sum (no stored copy)
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

FluidSolver runs the fluid collision before the phase-field collision, the reverse of Algorithm 1's listing;
nothing differs, because within a step neither reads what the other writes: both use φ^n, and the phase field
advects with the velocity u^n of Eq. 13 (the Guo-shifted velocity the fluid collision writes, computed from
the pre-collision populations — Algorithm 1's "Update velocity field u" of LBM stage 1).

Effects are decided by the scene through what is passed: no sand → no coupler, only the fluid stages (no
coupling stage runs and no coupling field exists); no fluid → only the three MPM stages; a single-phase
fluid → no source term; no retention → the coupler allocates no bound-water field and skips its stages
(CouplingParams.retention).  ``source_term=False`` switches S_φ off for an ablation (paper Fig. 14);
with retention that also leaves the absorbed water dR in the phase field (Eq. 57 is part of S_φ), so the
ablation is meant for scenes without retention.

Timing: :mod:`couplekit.schedulers.base`.
"""

from __future__ import annotations

from .base import FLUID_STAGES, SAND_STAGES, Scheduler

__all__ = ["LockstepScheduler", "COUPLED_STAGES", "FLUID_STAGES", "SAND_STAGES", "algorithm1_step"]

COUPLED_STAGES = (
    "mpm_p2g",
    "volume_fractions",
    "fluid_velocity",
    "retention_source",
    "drag_buoyancy",
    "mpm_grid_update",
    "moisture",
    "mpm_g2p",
    "sand_velocity",
)


class LockstepScheduler(Scheduler):
    """Paper Algorithm 1: ``fluid`` (FluidSolver or None), ``sand`` (SandSolver or None) and ``coupler``
    (SandFluidCoupler of exactly these two, required when both are given) advanced together, one MPM step
    per LBM step; the MPM step must equal the LBM step. Arguments: :class:`~couplekit.schedulers.base.Scheduler`.
    """

    kind = "lockstep"
    coupled_stages = COUPLED_STAGES
    folds_sand_velocity = True

    def __init__(
        self,
        fluid=None,
        sand=None,
        coupler=None,
        source_term: bool = True,
        timing: bool = True,
        warm_up_steps: int = 0,
    ):
        if fluid is not None and sand is not None and coupler is not None and sand.dt != coupler.units.dt:
            raise ValueError(f"lockstep needs the MPM step {sand.dt} s equal to the LBM step {coupler.units.dt} s")
        super().__init__(fluid, sand, coupler, source_term, timing, warm_up_steps)

    def _coupled_step(self) -> None:
        algorithm1_step(self)
        self.last_sand_steps = 1.0

    def _sand_only_step(self) -> None:
        self._mpm_step()
        self.last_sand_steps = 1.0


def algorithm1_step(sched: Scheduler, share: float = 1.0) -> None:
    """One coupled step of paper Algorithm 1 (module docstring) through ``sched``'s timed stages, the sand's
    step covering ``share`` fluid steps of absorption (lockstep: 1; a multi-rate block of m steps: m)."""
    c, sand, stage = sched.coupler, sched.sand, sched._stage
    with stage("mpm_p2g"):
        sand.p2g()
    # the porosity before Σ f c: in lockstep the fluid velocity's part of Eq. 39's slip term (u·∇ε) is taken
    # before Σ f c is written over u (SandFluidCoupler.fold_sand_velocity); neither stage reads what the other writes
    with stage("volume_fractions"):
        c.fractions(share=share)
    with stage("fluid_velocity"):
        c.fluid_velocity()
    if c.two_phase and sched.source_term:
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
    sched._fluid_step()
    with stage("coupling_finish"):
        c.finish()
    sched._check_sand_dt()
