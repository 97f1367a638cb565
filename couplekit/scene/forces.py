"""Body forces a scene applies to the fluid: the stirring swirl of paper 000 Fig. 11.

The paper starts its centrifugal-stirring scene by "a tangential forcing to the liquid to initiate a swirl".
:class:`StirringForce` turns a scene's ``[stirring]`` table (:class:`~couplekit.scene.model.Stirring`) into a
force density on the lattice:

    a(x) = A (r / R) e_θ    for r = |x_⊥| < R and |s| ≤ L/2,   0 elsewhere,
    F(x) = ρ_w φ ε a(x)     (force density, lattice units; ρ_w = ρ_h of the fluid, φ the water fraction,
                             ε the fluid fraction of a mixture, 1 without sand),

with the axis through ``center`` along the unit vector n, s = (x − center)·n, x_⊥ = (x − center) − s n, and
e_θ = n × x_⊥ / r (counter-clockwise seen from the tip of n). ``A`` is ``acceleration`` (m/s²) at r = R, the
tangential acceleration of the water: the collision adds F/(ε ρ) (Eq. 15), so water cells (φ = 1) accelerate
by a(x), air cells by nothing, interface cells by ρ_w φ a/ρ(φ). a ∝ r is the angular acceleration A/R of a
solid body spun up about the axis: divergence-free (its curl is 2A/R n, its divergence 0), so it starts a
swirl without pushing fluid towards or away from the axis, and it vanishes on the axis.

Torque: the angular momentum of the water about the axis grows at T = Σ_cells ρ_w φ ε a_θ r dV (N m), until
viscosity carries the swirl to the walls (:meth:`StirringForce.torque`).

How it reaches the fluid: through FluidSolver's ``force`` input (``external_force=True``), which the coupler
overwrites with the drag every step (kernels/coupling_drag.cu). The stirring is therefore added at the point
of use, without touching ``force``: :meth:`StirringForce.attach` wraps the fluid's ops so that each
``collide_stream`` call receives ``force + F`` (a separate buffer) during the forcing window. Whatever wrote
``force`` (drag, or nothing) is kept and the stirring adds to it.
"""

from __future__ import annotations

import math

import numpy as np

from ..units import Units
from .model import Domain, Stirring

__all__ = ["StirringForce"]


class StirringForce:
    """The swirl of a :class:`Stirring` on the grid of ``domain`` with lattice ``units``.

    ``acceleration``: (3, nz, ny, nx) float64, the lattice acceleration a(x) on every interior cell (zero
    outside the cylinder); ``first_step`` and ``last_step``: the forced steps are those with
    ``first_step <= step < last_step`` (``last_step`` None: all later steps), the step that starts at time
    ``step × dt``.
    """

    def __init__(self, stirring: Stirring, domain: Domain, units: Units):
        self.stirring = stirring
        self.domain = domain
        self.units = units
        dx = domain.dx
        nz, ny, nx = domain.shape
        z, y, x = np.meshgrid(*((np.arange(n) + 0.5) * dx for n in (nz, ny, nx)), indexing="ij")
        rel = np.stack([x, y, z]) - np.asarray(stirring.center, np.float64)[:, None, None, None]
        n = np.asarray(stirring.axis, np.float64)
        n = n / np.linalg.norm(n)
        s = np.einsum("d,dzyx->zyx", n, rel)
        perp = rel - n[:, None, None, None] * s
        r = np.sqrt((perp**2).sum(axis=0))
        inside = r < stirring.radius
        if stirring.length is not None:
            inside &= np.abs(s) <= 0.5 * stirring.length
        # a = A r/R e_θ = (A/R) n × x_⊥ (|n × x_⊥| = r)
        cross = np.cross(n, perp, axis=0)
        a_si = (stirring.acceleration / stirring.radius) * cross * inside
        self.radius_si = r
        self.inside = inside
        self.acceleration = units.to_lattice(1.0, "acceleration") * a_si
        dt = units.dt
        self.first_step = int(math.ceil(stirring.start / dt - 1e-9))
        self.last_step = (
            None if stirring.duration is None else int(math.ceil((stirring.start + stirring.duration) / dt - 1e-9))
        )

    def active(self, step: int) -> bool:
        """Whether the step that starts at ``step × dt`` is forced."""
        return step >= self.first_step and (self.last_step is None or step < self.last_step)

    def torque(self, water: np.ndarray, water_density: float) -> float:
        """Torque (N m) about the axis on the water fraction ``water`` (nz, ny, nx) (φ, or ε φ with sand):
        Σ ρ_w water a_θ r dx³, in SI."""
        a_theta = self.stirring.acceleration * self.radius_si / self.stirring.radius * self.inside
        return float((water_density * water * a_theta * self.radius_si).sum() * self.domain.dx**3)

    def attach(self, fluid) -> None:
        """Make every ``collide_stream`` of ``fluid`` (a FluidSolver built with ``external_force=True``) add the
        stirring force density to its ``force`` input during the forcing window (module docstring)."""
        if fluid.force is None:
            raise ValueError("stirring needs a FluidSolver built with external_force=True")
        fluid.ops = _StirredOps(fluid.ops, fluid, self)


_FORCE_ARG = 5  # the force's place among collide_stream's arguments (fluid ops, FluidSolver.step)


class _StirredOps:
    """The fluid's ops with ``collide_stream`` receiving ``force + ρ_w φ ε a`` while the stirring is active;
    every other stage is the wrapped ops' own (attribute access is forwarded)."""

    def __init__(self, inner, fluid, stirring: StirringForce):
        self._inner = inner
        self._fluid = fluid
        self._stirring = stirring
        be = fluid.backend
        # the bounding box of the stirred cells in the padded arrays: only there is anything added
        cells = np.nonzero(stirring.inside)
        if cells[0].size:
            self._box = tuple(slice(int(c.min()) + 1, int(c.max()) + 2) for c in cells)
        else:
            self._box = (slice(0, 0),) * 3
        interior = np.zeros((3,) + tuple(s + 2 for s in fluid.shape), np.float32)
        interior[:, 1:-1, 1:-1, 1:-1] = stirring.acceleration * fluid.params.rho_h
        self._rho_a = be.asarray(np.ascontiguousarray(interior[(slice(None), *self._box)]))  # ρ_w a in the box
        self._total = fluid.xp.zeros_like(fluid.force)

    def __getattr__(self, name: str):
        return getattr(self._inner, name)

    def collide_stream(self, *args, **kwargs):
        fluid = self._fluid
        if not self._stirring.active(fluid.step_count):
            return self._inner.collide_stream(*args, **kwargs)
        xp, total, box = fluid.xp, self._total, self._box
        force = fluid.force
        total[...] = force
        weight = None
        if fluid.two_phase:
            weight = xp.clip(fluid.phi[box], 0.0, 1.0)
        if fluid.mixture:
            eps = fluid.fluid_fraction[box]
            weight = eps if weight is None else weight * eps
        inner = total[(slice(None), *box)]
        inner += self._rho_a if weight is None else self._rho_a * weight[None]
        # the force argument only, by its place (collide_stream(f, flags, velocity, phi, eps, force, ...)): in
        # lockstep the force is the velocity's buffer (FluidSolver.share_force_buffer), which the collide writes
        args = tuple(total if (i == _FORCE_ARG and a is force) else a for i, a in enumerate(args))
        if kwargs.get("force") is force:
            kwargs = {**kwargs, "force": total}
        return self._inner.collide_stream(*args, **kwargs)
