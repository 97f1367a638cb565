"""Coupling schedulers (time-integration policies), shipped as ``couplekit.schedulers``.

Each scheduler advances a simulation by composing the solver stages of ``couplekit.fluid``,
``couplekit.sand`` and ``couplekit.coupling``, and reports the cost of every stage per step and the sand
steps it took (:mod:`.base`). A scene chooses one with its ``[scheduler]`` table (:func:`make_scheduler`):

* :mod:`.lockstep` — :class:`~couplekit.schedulers.lockstep.LockstepScheduler`, paper 000's Algorithm 1:
  one MPM step per LBM step, same Δt (``kind = "lockstep"``, the default);
* :mod:`.subcycle` — :class:`~couplekit.schedulers.subcycle.SubcycleScheduler`: k MPM substeps of Δt/k per
  LBM step, k fixed or chosen each step from the MPM's limits (``kind = "subcycle"``);
* :mod:`.multirate` — :class:`~couplekit.schedulers.multirate.MultirateScheduler`: one MPM step of m Δt per
  m LBM steps (``kind = "multirate"``).
"""

from __future__ import annotations

from .base import Scheduler, SubstepLimitError
from .lockstep import LockstepScheduler
from .multirate import MultirateScheduler
from .subcycle import SubcycleScheduler

__all__ = [
    "KINDS",
    "LockstepScheduler",
    "MultirateScheduler",
    "Scheduler",
    "SubcycleScheduler",
    "SubstepLimitError",
    "folds_sand_velocity",
    "make_scheduler",
    "sand_step",
    "spec_table",
]

KINDS = ("lockstep", "subcycle", "multirate")
_CLASSES = {"lockstep": LockstepScheduler, "subcycle": SubcycleScheduler, "multirate": MultirateScheduler}


def folds_sand_velocity(kind: str) -> bool:
    """Whether a coupled scene under scheduler ``kind`` keeps no stored sand velocity in its fluid
    (:attr:`Scheduler.folds_sand_velocity`): what the solvers are built with and the memory estimate counts."""
    return _CLASSES[kind].folds_sand_velocity


def sand_step(kind: str, dt: float, substeps: int | str = 1, sand_every: int = 1) -> float:
    """The sand solver's Δt under a scheduler, for a fluid (coupling) step ``dt``: dt (lockstep), dt / k
    (subcycle with a fixed k; ``"auto"``: dt, the scheduler sets it every step) or m dt (multirate)."""
    if kind == "subcycle":
        return dt if substeps == "auto" else dt / int(substeps)
    if kind == "multirate":
        return dt * int(sand_every)
    return dt


def spec_table(spec: str) -> dict:
    """The ``[scheduler]`` table of a short spec (``couplekit run --scheduler``): ``"lockstep"``,
    ``"subcycle"`` (substeps "auto"), ``"subcycle:8"``, ``"subcycle:auto"``, ``"subcycle:8:linear"``,
    ``"multirate:4"``. The table is validated with the scene it replaces the scheduler of."""
    parts = [p.strip() for p in str(spec).split(":")]
    kind, rest = parts[0], parts[1:]
    usage = "use lockstep, subcycle[:K|auto][:hold|linear] or multirate:M (e.g. subcycle:8, multirate:4)"
    if kind not in KINDS:
        raise ValueError(f"unknown scheduler {spec!r}: {usage}")
    table: dict = {"kind": kind}

    def count(text: str, what: str) -> int:
        if not (text.isascii() and text.isdigit()) or int(text) < 1:
            raise ValueError(f"scheduler {spec!r}: {what} must be a whole number >= 1, got {text!r}; {usage}")
        return int(text)

    if kind == "lockstep" and rest:
        raise ValueError(f"scheduler {spec!r}: lockstep takes no parameters; {usage}")
    if kind == "subcycle":
        if len(rest) > 2:
            raise ValueError(f"scheduler {spec!r}: too many parts; {usage}")
        if rest:
            table["substeps"] = "auto" if rest[0] == "auto" else count(rest[0], "substeps")
        if len(rest) == 2:
            if rest[1] not in ("hold", "linear"):
                raise ValueError(f"scheduler {spec!r}: interpolation must be hold or linear, got {rest[1]!r}")
            table["interpolation"] = rest[1]
    if kind == "multirate":
        if len(rest) > 1:  # e.g. multirate:2:linear: the fluid a sand step sees is not interpolated here
            raise ValueError(
                f"scheduler {spec!r}: too many parts: multirate takes one, the LBM steps per MPM step; {usage}"
            )
        if not rest:
            raise ValueError(f"scheduler {spec!r}: multirate needs the LBM steps per MPM step; {usage}")
        table["sand_every"] = count(rest[0], "sand_every")
    return table


def make_scheduler(
    kind: str,
    fluid=None,
    sand=None,
    coupler=None,
    *,
    dt: float,
    substeps: int | str = "auto",
    max_substeps: int = 64,
    interpolation: str = "hold",
    sand_every: int = 2,
    source_term: bool = True,
    timing: bool = True,
    warm_up_steps: int = 0,
) -> Scheduler:
    """The scheduler of ``kind`` (:data:`KINDS`) over the given solvers, for the coupling step ``dt`` (s).
    A scene with one solver only, or ``kind = "lockstep"``, ignores the parameters of the other kinds; a
    fluid-only scene is always stepped by the lockstep scheduler (there is one rate)."""
    if kind not in KINDS:
        raise ValueError(f"unknown scheduler kind {kind!r}; choose one of {', '.join(KINDS)}")
    common = {"source_term": source_term, "timing": timing, "warm_up_steps": warm_up_steps}
    if kind == "lockstep" or sand is None:
        return LockstepScheduler(fluid, sand, coupler, **common)
    if kind == "subcycle":
        return SubcycleScheduler(fluid, sand, coupler, substeps, interpolation, max_substeps, dt=dt, **common)
    return MultirateScheduler(fluid, sand, coupler, sand_every, dt=dt, **common)
