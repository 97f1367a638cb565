"""SandFluidCoupler.state() / load_state(): every coupler array round-trips, a reload continues bitwise,
mismatched states are refused; Simulation checkpoints go through it (and stay in the pre-API format)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import tiny_coupled  # noqa: E402

from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402

# the keys Simulation wrote for the coupler before the coupler had state(): old checkpoints hold exactly these
_PRE_API_KEYS = {"eps_sand", "fluid_u", "eps_prev", "water", "bound_in", "bound", "d_bound", "moisture_ratio"}


def _sim(retention: bool = True) -> Simulation:
    return Simulation(Scene.from_dict(tiny_coupled(retention=retention)), backend="cpu", log=None)


@pytest.mark.parametrize("retention", [True, False], ids=["retention", "no-retention"])
def test_state_round_trips_every_array(retention):
    """Poison every coupler array with NaN, load the state back: each array equals the saved one bitwise
    (so load_state forgets none); retention arrays exist only with retention."""
    sim = _sim(retention)
    sim.step(3)
    c = sim.coupler
    st = c.state()
    expect = _PRE_API_KEYS if retention else {"eps_sand", "fluid_u", "eps_prev", "water"}
    assert set(st) == expect | {"started"} and bool(st["started"])
    for k in expect:
        getattr(c, k)[...] = np.nan
    c._started = False
    c.load_state(st)
    again = c.state()
    for k in st:
        assert np.asarray(again[k]).tobytes() == np.asarray(st[k]).tobytes(), k


def test_reload_into_a_fresh_simulation_continues_bitwise():
    a, b = _sim(), _sim()
    a.step(4)
    saved = a._states()
    assert set(saved["coupler"]) == _PRE_API_KEYS | {"started"}  # checkpoint format unchanged
    b._load_states(saved, 4)
    a.step(5)
    b.step(5)
    sa, sb = a._states(), b._states()
    for solver in sa:
        for k in sa[solver]:
            assert np.asarray(sa[solver][k]).tobytes() == np.asarray(sb[solver][k]).tobytes(), (solver, k)


def test_mismatched_states_are_refused():
    with_ret, without = _sim(True), _sim(False)
    with pytest.raises(ValueError, match="bound_in"):
        with_ret.coupler.load_state(without.coupler.state())
    st = with_ret.coupler.state()
    st["eps_prev"] = st["eps_prev"][1:]
    with pytest.raises(ValueError, match="eps_prev.*shape"):
        with_ret.coupler.load_state(st)
