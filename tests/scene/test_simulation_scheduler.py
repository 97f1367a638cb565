"""Simulation steps every scene through the LockstepScheduler: per-stage costs, timed == untimed bitwise,
the same state as the coupler's own step, and a bitwise coupled restart through the scheduler."""

from __future__ import annotations

import numpy as np
import pytest
from couplekit.schedulers.lockstep import COUPLED_STAGES, FLUID_STAGES, SAND_STAGES, LockstepScheduler
from sim_scenes import tiny_coupled, tiny_fluid, tiny_sand

from couplekit.scene import Scene
from couplekit.simulation import Simulation


def _sim(d: dict, **kw) -> Simulation:
    return Simulation(Scene.from_dict(d), backend="cpu", log=None, **kw)


def _state_bytes(sim: Simulation) -> dict[str, bytes]:
    return {f"{s}.{k}": np.asarray(v).tobytes() for s, st in sim._states().items() for k, v in st.items()}


@pytest.mark.parametrize(
    ("scene", "stages"),
    [
        (tiny_sand, SAND_STAGES),
        (tiny_fluid, FLUID_STAGES),
        (tiny_coupled, (*COUPLED_STAGES, *FLUID_STAGES, "coupling_finish")),
    ],
    ids=["sand", "fluid", "coupled"],
)
def test_every_scene_reports_its_stage_costs(scene, stages):
    """Simulation.stage_times lists the stages the scene runs (all of them: the tiny coupled scene has
    retention and the source term on), each timed (> 0 s); the cost report's fractions sum to 1 and it
    leaves out the first step."""
    sim = _sim(scene())
    assert isinstance(sim.scheduler, LockstepScheduler)
    sim.step(3)
    times = sim.stage_times()
    assert tuple(times) == tuple(s for s in sim.scheduler.stages())
    assert set(times) == set(stages)
    assert all(t > 0 for t in times.values()), times
    rep = sim.cost_report()
    assert abs(sum(r["fraction"] for r in rep.values()) - 1.0) < 1e-9
    # the first step (kernel loading) is left out of the report: 2 of the 3 steps are in it
    assert all(r["total"] == pytest.approx(2 * r["mean"]) for r in rep.values())
    assert sim.diagnostics()["step_seconds"] == pytest.approx(sum(times.values()))
    assert "stage costs" in sim.cost_summary() and "mpm_p2g" not in _sim(tiny_fluid()).cost_summary()


def test_timed_untimed_and_coupler_step_agree_bitwise():
    """Timing changes nothing: a timed Simulation, an untimed one, and the solvers of a third stepped by
    SandFluidCoupler.step (its own untimed scheduler) end bitwise equal after 6 steps."""
    timed, untimed, direct = _sim(tiny_coupled()), _sim(tiny_coupled(), timing=False), _sim(tiny_coupled())
    timed.step(6)
    untimed.step(6)
    assert untimed.stage_times() == {} and untimed.cost_summary() == "stage costs: not timed"
    direct.coupler.step(6)
    direct.step_count = 6
    a = _state_bytes(timed)
    assert a == _state_bytes(untimed)
    assert a == _state_bytes(direct)


def test_source_term_switch_reaches_the_scheduler():
    """effects.source_term = false: the scheduler skips the retention/source stage, and the result differs
    from the run with the source term (so the switch is not ignored)."""
    d = tiny_coupled(retention=False)
    d["effects"] = {"source_term": False}
    off, on = _sim(d), _sim(tiny_coupled(retention=False))
    assert not off.scheduler.source_term and on.scheduler.source_term
    off.step(4)
    on.step(4)
    assert "retention_source" not in off.stage_times() and "retention_source" in on.stage_times()
    phi_off, phi_on = off.fields()["phi"], on.fields()["phi"]
    assert not np.array_equal(phi_off, phi_on)


def test_coupled_restart_through_the_scheduler_is_bitwise(tmp_path):
    """Checkpoint at step 5, resume in a new Simulation (a fresh scheduler), 7 more steps: bitwise equal to
    12 uninterrupted steps; the resumed run is timed from the restart on."""
    straight = _sim(tiny_coupled())
    straight.step(12)
    first = _sim(tiny_coupled())
    first.step(5)
    first.save(tmp_path / "c.h5")
    resumed = Simulation.load(tmp_path / "c.h5", backend="cpu", log=None)
    assert resumed.scheduler.steps == 0 and resumed.cost_report() == {}
    resumed.step(7)
    assert resumed.scheduler.steps == 7 and resumed.sand.steps == 12 and resumed.fluid.step_count == 12
    assert _state_bytes(resumed) == _state_bytes(straight)


def test_run_logs_the_stage_costs(tmp_path):
    lines: list[str] = []
    sim = Simulation(Scene.from_dict(tiny_coupled()), backend="cpu", log=lines.append)
    sim.run(frames=1, out=tmp_path, progress=False)
    cost = [s for s in lines if s.startswith("stage costs")]
    assert len(cost) == 1 and "lbm_collide_stream" in cost[0] and "mpm_g2p" in cost[0]
    # a frame is 5 steps; the first (kernel loading) is left out of the summary
    assert "over 4 steps" in cost[0], cost[0]
