"""Coupling schedulers (time-integration policies), shipped as ``couplekit.schedulers``.

Each scheduler advances a simulation by composing the solver stages of ``couplekit.fluid``,
``couplekit.sand`` and ``couplekit.coupling``. The lockstep scheduler (paper 000, Algorithm 1) arrives
with the coupling work; until then this package holds no scheduler.
"""
