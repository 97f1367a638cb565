"""SandFluidCoupler: the coupling fields of one sand body and one fluid, and the coupling stages of paper
Algorithm 1 between :class:`couplekit.sand.solver.SandSolver` and :class:`couplekit.fluid.solver.FluidSolver`.

The coupler owns what belongs to neither solver: last step's porosity, and with water retention the bound
water R, its increment dR and the particles' moisture ratio r_p.  The sand fraction (Eq. 25) and the water
fraction of Eq. 59 are not stored: the drag computes the first from the sand's P2G volume, the moisture the
second from the porosity, φ and R (kernels/coupling_fields.cuh), 8 B per cell.  It writes the
fluid's inputs (``fluid_fraction``, ``force``, ``source_term``, and ``sand_velocity`` or, in lockstep, Eq. 39's
sand terms folded into the pressure update) and the sand's (``grid_mv``: drag and buoyancy impulses;
``saturation``).  One lockstep step, in Algorithm 1's order::

    sand.p2g()                 # Eq. 24
    coupler.fractions()        # Eqs. 25, 33, 53–56 (retention), fluid_fraction
    coupler.fluid_velocity()   # u = Σ_j f_j c_j of the fluid's current populations (Eq. 13, no force shift)
    coupler.phase_source()     # Eqs. 45 / 57 -> fluid.source_term (two-phase fluid only)
    coupler.exchange()         # Eq. 31 buoyancy and implicit drag -> sand.grid_mv, drag -> fluid.force
    sand.grid_update()         # Eqs. 26, 29 and the sand's boundaries
    coupler.moisture()         # Eqs. 58, 59 -> sand.saturation (before G2P moves the particles)
    sand.g2p()                 # Eq. 30
    coupler.sand_velocity()    # grid velocity -> Eq. 39's sand terms (or fluid.sand_velocity, see below)
    fluid.step()
    coupler.finish()           # this step's porosity becomes last step's

:meth:`step` runs exactly that through :class:`couplekit.schedulers.lockstep.LockstepScheduler` (which
also times the stages); the multi-rate schedulers (:mod:`couplekit.schedulers.subcycle`,
:mod:`couplekit.schedulers.multirate`) call the same stages in their own order, with the arguments that
make a sand step cover part of a fluid step or several (``fractions(share)``, ``exchange(u, force)``,
``sand_velocity(grid_v)``).

Why :meth:`fluid_velocity`: the exchange must see the fluid's velocity as it is now (after the last
streaming).  FluidSolver's ``velocity`` field is the Guo-forced velocity of the last collision, before its
streaming; with it a strong drag over a sand block makes the LBM blow up within ~50 steps (c = 1e3), with
Σ f c it stays stable (tests/coupling/test_coupling_coupler.py).  Σ f c is
:meth:`couplekit.fluid.solver.FluidSolver.current_velocity`, a fluid kernel on every backend (checked
against an independent NumPy read of the populations in tests/coupling/test_coupling_fluid_velocity.py).

Where last step's porosity lives (:attr:`SandFluidCoupler.eps_prev`): with the source term applied, in the fluid's
``source_term`` buffer (:meth:`SandFluidCoupler.share_source_buffer`, set up by the schedulers), 4 B per cell
not stored twice.  ε̃_prev is last read by :meth:`phase_source` (and before it by :meth:`fractions` with
retention), whose kernel reads it at a cell before it writes S_φ there; S_φ is read by the fluid step; then
:meth:`finish` writes this step's porosity into the buffer.  Between steps it holds ε̃_prev (what a checkpoint
saves under both names).

Where the sand velocity goes (:meth:`SandFluidCoupler.fold_sand_velocity`): in lockstep nowhere, 12 B per cell
less.  Its only reader in the fluid step is the pressure update (Eq. 39: (1 − ε) ∇·v and the slip (u − v)·∇ε),
which runs first and sums the populations that :meth:`fluid_velocity` already summed for the exchange (the kept
Σ (f − w), FluidSolver.current_velocity).  So :meth:`sand_velocity` computes the sand's terms right away from the
MPM grid velocity (kernels/coupling_pressure.cu, the pressure kernel's own function on the values it would have
read) and subtracts them from the kept sum, and the pressure update adds none.  The sub-cycling and multi-rate
schedulers keep the stored sand velocity: their fluid steps read the substeps' mean, or one sand step's velocity
over a block.

Where Σ f c and the force live (:attr:`SandFluidCoupler.fluid_u`): in lockstep in the fluid's ``velocity`` buffer,
which also holds the force (FluidSolver.share_force_buffer), 12 B per cell less again.  The buffer holds the last
collision's u between steps (what ``fields()`` shows); :meth:`fluid_velocity` (after :meth:`fractions`, which
gives this step's porosity) first takes the part of Eq. 39's slip term that reads u, φ u·∇ε / ε, into the kept
sum (``coupling_pressure_slip_fluid``), then writes Σ f c over u; :meth:`phase_source` and :meth:`exchange` read
Σ f c, and the exchange writes the drag force over it cell by cell (each cell reads its own Σ f c first;
kernels/coupling_drag.cu); the collision reads the force cell by cell and writes u there; the walls' and inflows'
velocities in the ghost cells are never written.  :meth:`sand_velocity` then subtracts the rest of the terms,
((1 − ε) ∇·v − φ v·∇ε) / ε, so the slip term is rounded in two parts: the same results as a stored sand velocity
to float32 round-off, not bitwise (tests/coupling/test_exchange_velocity_buffer.py).  Neither Σ f c nor the force
is in a checkpoint of a lockstep run (every step writes both before reading them).  Otherwise Σ f c lives in the
fluid's ``sand_velocity`` buffer and the force in one of its own: Σ f c is written by :meth:`fluid_velocity` and
last read by :meth:`exchange` (and :meth:`phase_source`), the sand velocity is written after G2P by
:meth:`sand_velocity` and read by the fluid step, and every scheduler's step computes Σ f c afresh before it
reads it.  The one order where Σ f c and the sand velocity overlap is a multi-rate block of m > 1 fluid steps,
whose other steps recompute Σ f c for the source term while the fluid still needs the sand velocity of the
block's sand step: that scheduler calls :meth:`own_fluid_velocity` (:mod:`couplekit.schedulers.multirate`).  The
sub-cycling scheduler keeps its last-step copy before the sand velocity is written and reads the force in its
substeps' fluid view (:mod:`couplekit.schedulers.subcycle`).
"""

from __future__ import annotations

import numpy as np

from ..units import Units
from . import make_coupling_ops
from .params import CouplingParams
from .reference import sand_fraction, water_fraction

__all__ = ["SandFluidCoupler"]

_STATE = ("eps_prev", "bound_in", "bound", "d_bound", "moisture_ratio", "retain")
"""Arrays of :meth:`SandFluidCoupler.state` (the retention ones only when retention is on, ``retain`` only with
per-body retention).  Not ``fluid_u`` (it shares the force's or the sand velocity's buffer), the sand fraction or the water
fraction (neither is stored): every step recomputes them before reading them.  Checkpoints that hold them
(``fluid_u``, ``eps_sand``, ``water``: before session 13) still load; those values are ignored."""


class SandFluidCoupler:
    """Coupling of ``sand`` (SandSolver) and ``fluid`` (FluidSolver) on the same grid.

    ``units``: the lattice unit system (``units.dx`` must be the sand's dx; ``units.dt`` the LBM step);
    ``params``: :class:`CouplingParams` (retention on/off, drag constants); ``moisture``: initial moisture
    ratio r_p of the particles (retention only).  ``retentive``: per-particle flags (P,) for retention on
    some sand bodies only (paper Fig. 10), or None (every particle retains when ``params.retention``).  With
    flags, only retentive sand has retention capacity (r_max times the retentive sand fraction, a P2G of the
    flags) and only retentive particles gain bound water; flags all true are the one-setting model, bitwise.
    ``emitted_retentive``: whether particles emitted later (at inflows) retain (the scene's ``sand.retention``);
    None: they retain only when every seeded particle does.
    The fluid must be built with ``mixture=True`` and ``external_force=True``; its phase field (if any)
    receives the source term.
    """

    def __init__(
        self,
        sand,
        fluid,
        units: Units,
        params: CouplingParams | None = None,
        moisture: np.ndarray | float = 0.0,
        retentive: np.ndarray | None = None,
        emitted_retentive: bool | None = None,
    ):
        if tuple(sand.shape) != tuple(fluid.shape):
            raise ValueError(f"sand grid {tuple(sand.shape)} and fluid grid {tuple(fluid.shape)} must be the same")
        if not np.isclose(sand.dx, units.dx, rtol=1e-9):
            raise ValueError(f"units.dx = {units.dx} m but the sand grid has dx = {sand.dx} m")
        if not (fluid.mixture and fluid.external_force):
            raise ValueError("the fluid must be built with mixture=True and external_force=True to be coupled")
        self.sand, self.fluid, self.units = sand, fluid, units
        if sand.saturation is None:  # cohesionless sand built without it: the moisture (Eq. 59) writes it
            sand.saturation = sand.backend.xp.zeros(sand.n_particles, dtype=np.float32)
        self.params = params or CouplingParams()
        self.two_phase = bool(fluid.two_phase)
        self.ops = make_coupling_ops(fluid.backend, self.params, self.two_phase)
        self.periodic = fluid.boundaries.periodic_axes
        xp = fluid.backend.xp
        shape = tuple(fluid.shape)
        padded = tuple(s + 2 for s in shape)
        self._fluid_u = None  # own buffer of the exchange velocity (own_fluid_velocity); else fluid.sand_velocity
        self._eps_prev = xp.ones(padded, dtype=np.float32)  # None while it lives in fluid.source_term
        self.retention = bool(self.params.retention)
        if self.retention:
            self.bound_in = xp.zeros(shape, dtype=np.float32)
            self.bound = xp.zeros(shape, dtype=np.float32)
            self.d_bound = xp.zeros(shape, dtype=np.float32)
            r = np.broadcast_to(np.asarray(moisture, dtype=np.float64), (sand.n_particles,))
            flags = None if retentive is None else np.asarray(retentive, dtype=bool).reshape(-1)
            if flags is not None and flags.shape != (sand.n_particles,):
                raise ValueError(f"retentive has {flags.size} flags for {sand.n_particles} particles")
            # particles emitted later retain as emitted_retentive says (sand.retention); None: as the bodies' do
            # when all of those retain, not otherwise
            self._emitted_retain = 0.0 if emitted_retentive is None else float(bool(emitted_retentive))
            every = flags is None or flags.all()
            if every and emitted_retentive is False:
                flags = np.ones(sand.n_particles, bool)  # the bodies' sand retains, the emitted will not
                every = False
            if not every:
                r = np.where(flags, r, 0.0)  # non-retentive particles hold no bound water
                self.retain = fluid.backend.asarray(flags.astype(np.float32), np.float32)
                self.retentive = xp.zeros(shape, dtype=np.float32)
            else:
                self.retain = self.retentive = None
            self.moisture_ratio = fluid.backend.asarray(r, np.float32)
        else:
            self.bound_in = self.bound = self.d_bound = self.moisture_ratio = None
            self.retain = self.retentive = None
        self._started = False
        self._fractions_step = None  # the fluid step at which fractions() last ran (fluid_velocity's order check)
        self._scheduler = None  # built by step()

    @property
    def fluid_u(self):
        """The exchange velocity Σ_j f_j c_j (padded, lattice units): the fluid's ``sand_velocity`` buffer, its
        ``force`` buffer, which is its ``velocity`` buffer, when the sand velocity is folded into the pressure
        update (:meth:`fold_sand_velocity`), or a buffer of its own after :meth:`own_fluid_velocity` (module
        docstring)."""
        if self._fluid_u is not None:
            return self._fluid_u
        return self.fluid.force if self.fluid.sand_velocity is None else self.fluid.sand_velocity

    @property
    def folds_sand_velocity(self) -> bool:
        """Whether the fluid keeps no sand velocity and :meth:`sand_velocity` folds Eq. 39's sand terms into the
        pressure update instead (:meth:`fold_sand_velocity`)."""
        return self.fluid.sand_velocity is None

    def fold_sand_velocity(self, fold: bool) -> None:
        """Keep no padded sand velocity and no force buffer of its own in the fluid (``fold``; 24 B per cell
        less): the fluid's velocity, Σ f c and the force share one buffer; :meth:`fluid_velocity` first takes
        the part of Eq. 39's slip term that reads the fluid velocity out of it into the kept population sum, then
        writes Σ f c over it; :meth:`exchange` writes the force over that cell by cell; :meth:`sand_velocity`
        subtracts the rest of Eq. 39's sand terms, computed from the MPM grid velocity (module docstring).  For a
        scheduler whose every fluid step follows this step's :meth:`fractions`, :meth:`fluid_velocity` and
        :meth:`exchange` in that order (lockstep); the sub-cycling and multi-rate schedulers call it with False
        (their fluid steps read a stored sand velocity).  The same results either way to float32 round-off (the
        slip term's two parts are subtracted apart; tests/coupling/test_exchange_velocity_buffer.py)."""
        if fold:
            if self._fluid_u is not None:
                raise RuntimeError(
                    "the exchange velocity has a buffer of its own (a multi-rate block): keep the sand velocity"
                )
            self.fluid.release_sand_velocity()
            self.fluid.share_force_buffer(True)
        else:
            self.fluid.keep_sand_velocity()
            self.fluid.share_force_buffer(False)

    @property
    def eps_prev(self):
        """Last step's porosity ε̃_prev (padded): a buffer of its own, or the fluid's ``source_term`` buffer
        after :meth:`share_source_buffer` (module docstring)."""
        return self.fluid.source_term if self._eps_prev is None else self._eps_prev

    @property
    def shares_source_buffer(self) -> bool:
        """Whether ε̃_prev and S_φ are one buffer (:meth:`share_source_buffer`)."""
        return self._eps_prev is None

    def share_source_buffer(self, share: bool) -> None:
        """Keep ε̃_prev in the fluid's S_φ buffer (``share``), 4 B per padded cell less, or in one of its own.

        Sharing is for a scheduler that calls :meth:`phase_source` before every fluid step and :meth:`finish`
        after it (every scheduler that applies the source term): the porosity's last reader is the source
        term's kernel itself, which reads ε̃_prev at a cell before it writes S_φ there, and the first
        writer after the fluid step is :meth:`finish`. A scheduler that does not apply the source term
        (``source_term=False``, paper Fig. 14's ablation) calls it with False, so that the fluid sees S_φ = 0.
        The values carry over either way; a no-op without a source buffer (one-phase fluid, S_φ compiled out)."""
        f = self.fluid
        if f.source_term is None or share == self.shares_source_buffer:
            return
        if share:
            f.source_term[...] = self._eps_prev
            self._eps_prev = None
        else:
            self._eps_prev = f.source_term.copy()
            f.source_term[...] = 0.0

    def own_fluid_velocity(self) -> None:
        """Give :attr:`fluid_u` a buffer of its own (12 B per padded cell), for a scheduler that computes
        Σ f c while the fluid still needs the sand velocity (a multi-rate block, module docstring)."""
        if self._fluid_u is None:
            self._fluid_u = self.fluid.backend.xp.zeros_like(self.fluid.force)  # (3, padded), float32

    # ------------------------------------------------------------------ stages
    def fluid_velocity(self) -> None:
        """``fluid_u`` := Σ_j f_j c_j of the fluid's current populations on interior fluid cells (solid cells
        and ghosts keep what the buffer held; no coupling stage reads them there):
        FluidSolver.current_velocity (module docstring). The same pass keeps Σ_j (f_j − w_j) for the fluid
        step's pressure update (``keep_fsum``), which then does not read the populations again.  With the sand
        velocity folded (:meth:`fold_sand_velocity`), ``fluid_u`` is the fluid's velocity buffer: first the part of
        Eq. 39's slip term that reads the last collision's u (φ u·∇ε / ε) goes into the kept sum, so this step's
        :meth:`fractions` (the porosity ε) must have run."""
        f = self.fluid
        if self.folds_sand_velocity:
            if self._fractions_step != f.step_count:
                raise RuntimeError(
                    "fluid_velocity() of a folding coupler (lockstep) needs this step's porosity: call fractions() "
                    "first in the same step (the lockstep scheduler's order)"
                )
            f.take_slip_fluid_part(
                lambda fsum: self.ops.pressure_slip_fluid(
                    f.flags, f.velocity, f.phi, f.fluid_fraction, f.slip_cells, fsum
                )
            )
        f.current_velocity(out=self.fluid_u, keep_fsum=True)

    def fractions(self, share: float = 1.0) -> None:
        """ε (Eq. 25), bound water (Eqs. 53–56, retention) and the porosity into ``fluid.fluid_fraction``.

        ``share``: the part of a fluid step this sand step covers (1/k for a substep, m for a multi-rate
        block; :meth:`couplekit.coupling.reference.ReferenceOps.fractions`)."""
        s, f = self.sand, self.fluid
        if self.retention and s.n_particles == 0:  # a jet's sand not emitted yet: no bound water to gather
            self.bound_in[...] = 0.0
            if self.retain is not None:
                self.retentive[...] = 0.0
        elif self.retention:
            self.ops.bound_water_p2g(s.x, self.moisture_ratio, s.volume, self.bound_in, s.dx)
            if self.retain is not None:  # the retentive sand's fraction: Eq. 53's P2G with r_p = flag
                if self.retain.shape[0] != s.n_particles:  # particles emitted since (couplekit.sand.emission)
                    self.retain = _resized(self.fluid.backend.xp, self.retain, s.n_particles, self._emitted_retain)
                self.ops.bound_water_p2g(s.x, self.retain, s.volume, self.retentive, s.dx)
        volume, scale = s.node_volume
        self.ops.fractions(
            volume, f.phi, self.bound_in, self.eps_prev, f.fluid_fraction, self.d_bound, self.bound, s.dx,
            self.periodic, self.retentive, share, volume_scale=scale,
        )  # fmt: skip
        if not self._started:
            # first step: no sand motion yet, so last step's porosity is this one (without absorption)
            self.eps_prev[...] = f.fluid_fraction
            if self.retention:
                self.eps_prev[...] = self.eps_prev + _pad(self.fluid.backend.xp, self.d_bound, self.eps_prev)
            if self.two_phase:
                # V0 of the volume controller (Eq. 52): the water this step starts from, free Σ ε̃_prev φ
                # (the porosity the phase field holds it in) + bound Σ R before this step's absorption
                free = f.pf_ops.volume_sums(f.phi, f.source_term, f.flags, self.eps_prev)[0]
                f.reset_volume_reference(free + (self._sum(self.bound_in) if self.retention else 0.0))
            self._started = True
        if self.retention and self.two_phase:
            f.held_volume = self._sum(self.bound)  # bound water after this step's absorption (Eq. 56)
        self._fractions_step = f.step_count

    @staticmethod
    def _sum(a) -> float:
        """Σ a in float64 (a backend array)."""
        return float(a.sum(dtype=np.float64))

    def phase_source(self) -> None:
        """S_φ (Eq. 45, Eq. 57 with retention) into ``fluid.source_term`` (two-phase fluids only)."""
        f = self.fluid
        if self.two_phase:
            if f.source_term is None:
                raise RuntimeError(
                    "the fluid was built without a source term (FluidSolver(source_term=False)): build it with "
                    "source_term=True, or step with the source term off (scheduler source_term=False)"
                )
            self.ops.phase_source(
                f.fluid_fraction, self.eps_prev, f.phi, self.fluid_u, f.flags, self.d_bound, f.source_term
            )

    def exchange(self, u=None, force=None) -> None:
        """Buoyancy (Eq. 31, as the impulse Δt F_b) and implicit drag over the sand's Δt into ``sand.grid_mv``, and
        −J/Δt into ``fluid.force`` (or ``force``), exchanged with the fluid velocity ``fluid_u`` (or ``u``, a
        padded velocity: what a sand substep sees of the fluid, schedulers/subcycle.py)."""
        s, f = self.sand, self.fluid
        prm = f.params
        volume, scale = s.node_volume
        if force is None:
            if f.force_shares_velocity and f.force_was_written:
                raise RuntimeError(
                    "exchange() ran already at this step: the force lives in the fluid velocity's buffer (lockstep), "
                    "so a second exchange would read the force as the fluid velocity; call it once per step"
                )
            f.force_written()
        self.ops.drag_buoyancy(
            s.grid_m, s.grid_mv, f.force if force is None else force, self.fluid_u if u is None else u,
            f.phi, volume, f.fluid_fraction, f.flags, self.units, s.gravity, prm.rho_h, prm.rho_l, s.dt,
            volume_scale=scale,
        )  # fmt: skip

    def moisture(self) -> None:
        """Saturation of every particle (Eq. 59 or its no-retention form) and, with retention, r_p (Eq. 58)."""
        s = self.sand
        if s.n_particles == 0:  # a jet's sand not emitted yet
            return
        volume, scale = s.node_volume
        self.ops.particle_moisture(
            s.x, self.moisture_ratio, s.saturation, self.fluid.fluid_fraction, self.fluid.phi, self.bound,
            self.d_bound, volume, s.dx, self.retentive, self.retain, volume_scale=scale,
        )  # fmt: skip

    def sand_velocity(self, grid_v=None) -> None:
        """The sand grid velocity (after the grid update; or ``grid_v``, e.g. the substeps' average) into
        ``fluid.sand_velocity`` (lattice units); with the sand velocity folded (:meth:`fold_sand_velocity`)
        Eq. 39's sand terms from it into the population sum this step's :meth:`fluid_velocity` kept."""
        v = self.sand.grid_v if grid_v is None else grid_v
        f = self.fluid
        if f.sand_velocity is not None:
            self.ops.sand_velocity(v, f.sand_velocity, self.units, self.periodic)
            return
        f.fold_sand_pressure_terms(
            lambda fsum: self.ops.pressure_sand_terms(
                v, f.flags, f.phi, f.fluid_fraction, f.slip_cells, fsum, self.units, self.periodic
            )
        )

    def finish(self) -> None:
        """End of the step: this step's porosity becomes last step's."""
        self.eps_prev[...] = self.fluid.fluid_fraction

    def step(self, n: int = 1) -> None:
        """``n`` lockstep steps of sand + fluid in Algorithm 1's order: the untimed
        :class:`couplekit.schedulers.lockstep.LockstepScheduler` (one code path for the stage order). ``n`` a whole
        number >= 0 (as :meth:`couplekit.simulation.Simulation.step`; the scheduler refuses anything else)."""
        if self._scheduler is None:
            from ..schedulers.lockstep import LockstepScheduler

            self._scheduler = LockstepScheduler(self.fluid, self.sand, self, timing=False)
        self._scheduler.step(n)

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, np.ndarray]:
        """Everything of the coupler a bitwise restart needs (host arrays; ``started`` as a 0-d bool array):
        the padded sand fraction, the fluid velocity of the exchange, last step's porosity, the free water
        of Eq. 59, and with retention the bound water (Eqs. 53–56) and the particles' moisture ratio."""
        be = self.fluid.backend
        st = {k: be.to_host(getattr(self, k)) for k in _STATE if getattr(self, k) is not None}
        st["started"] = np.array(self._started)
        return st

    def load_state(self, st: dict) -> None:
        """Restore a :meth:`state` dict (same grid, retention setting and particle count), in place."""
        be = self.fluid.backend
        for k in _STATE:
            mine = getattr(self, k)
            if mine is None:
                continue
            if k not in st:
                raise ValueError(f"coupler state has no {k!r} (retention {'on' if self.retention else 'off'} here)")
            a = np.asarray(st[k])
            if k == "retain" and a.ndim == 1:  # per-particle flags: the checkpoint's count (emitted particles)
                self.retain = be.asarray(a.astype(np.float32), np.float32)
                continue
            if a.shape != tuple(mine.shape):
                raise ValueError(f"coupler state {k!r} has shape {a.shape}, this coupler {tuple(mine.shape)}")
            mine[...] = be.asarray(a, np.float32)
        self._started = bool(np.asarray(st["started"]))

    # ------------------------------------------------------------------ outputs
    def fields(self) -> dict[str, np.ndarray]:
        """Host copies of the interior coupling fields: sand_fraction (Eq. 25, of the last P2G), fluid_fraction,
        water (Eq. 59 summand), and with retention bound_water; the first and the third are computed here
        (:func:`~couplekit.coupling.reference.sand_fraction`, :func:`~couplekit.coupling.reference.water_fraction`),
        as the drag and the moisture compute them, from the current fields (after a step: its porosity and the
        phase field the step ended with), float32 like the fields the solver holds."""
        be = self.fluid.backend
        phi = be.to_host(self.fluid.phi) if self.two_phase else None
        if self._started:
            volume, scale = self.sand.node_volume
            eps_sand = sand_fraction(be.to_host(volume), self.sand.dx, self.params.eps_max, scale)
            eps_fluid = be.to_host(self.fluid.fluid_fraction)
            bound = be.to_host(self.bound) if self.retention else None
        else:
            # before the first step (a run's frame 0): the seeded particles' sand fraction, and the porosity
            # Eq. 54 gives it with the bound water of their initial moisture (Eq. 53) and no uptake yet; the
            # fields above would be 0 and 1 beside particles that exist
            eps_sand = sand_fraction(self.sand.seeded_volume(), self.sand.dx, self.params.eps_max)
            bound = None
            if self.retention:
                bound = np.zeros(self.sand.shape)
                r = be.to_host(self.moisture_ratio).astype(np.float64)
                from .reference import ReferenceOps

                ReferenceOps(self.params, self.two_phase).bound_water_p2g(
                    be.to_host(self.sand.x), r, be.to_host(self.sand.volume), bound, self.sand.dx
                )
            eps = 1.0 - eps_sand - (0.0 if bound is None else bound)
            eps_fluid = np.pad(np.maximum(eps, 0.0), 1, mode="edge").astype(np.float32)
            bound = None if bound is None else bound.astype(np.float32)
        out = {
            "sand_fraction": eps_sand.astype(np.float32),
            "fluid_fraction": eps_fluid[1:-1, 1:-1, 1:-1],
            "water": water_fraction(eps_fluid, phi, bound).astype(np.float32),
        }
        if self.retention:
            out["bound_water"] = bound
        return out


def _resized(xp, a, n: int, fill: float = 0.0):
    """``a`` cut or grown to ``n`` entries, new entries ``fill``: particles appended after construction (emitted at
    inflows) retain as ``sand.retention`` says (1) or not (0; SandFluidCoupler's ``emitted_retentive``)."""
    out = xp.full(n, fill, dtype=a.dtype)
    keep = min(n, a.shape[0])
    out[:keep] = a[:keep]
    return out


def _pad(xp, a, like):
    """``a`` (nz, ny, nx) placed in the interior of an array shaped like ``like`` (zeros around)."""
    out = xp.zeros_like(like)
    out[1:-1, 1:-1, 1:-1] = a
    return out
