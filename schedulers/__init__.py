"""Coupling schedulers (time-integration policies), shipped as ``couplekit.schedulers``.

Each scheduler advances a simulation by composing the solver stages of ``couplekit.fluid``,
``couplekit.sand`` and ``couplekit.coupling``, and reports the cost of every stage per step.

* :mod:`.lockstep` — :class:`~couplekit.schedulers.lockstep.LockstepScheduler`, paper 000's Algorithm 1:
  one MPM step per LBM step, same Δt.
"""

from .lockstep import LockstepScheduler

__all__ = ["LockstepScheduler"]
