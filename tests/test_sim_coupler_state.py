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
# what it writes now: not the exchange velocity (it shares the fluid's sand-velocity buffer), the sand fraction
# or the water fraction, which every step recomputes before reading them (SandFluidCoupler)
_KEYS = _PRE_API_KEYS - {"fluid_u", "eps_sand", "water"}


def _assert_same_states(a: Simulation, b: Simulation) -> None:
    """Every array of every solver's checkpoint state bitwise equal."""
    sa, sb = a._states(), b._states()
    for solver in sa:
        for k in sa[solver]:
            assert np.asarray(sa[solver][k]).tobytes() == np.asarray(sb[solver][k]).tobytes(), (solver, k)


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
    expect = _KEYS if retention else {"eps_prev"}
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
    assert set(saved["coupler"]) == _KEYS | {"started"}
    b._load_states(saved, 4)
    a.step(5)
    b.step(5)
    _assert_same_states(a, b)


def test_a_checkpoint_holding_the_exchange_velocity_still_loads_and_continues_bitwise():
    """Checkpoints before session 13 hold ``fluid_u``, ``eps_sand`` and ``water``, lockstep checkpoints before
    session 24 the fluid's ``force``: they load (and are ignored, every step recomputes them; the force lives in the
    velocity's buffer now), and the run continues as one from a checkpoint without them."""
    a, b, c = _sim(), _sim(), _sim()
    a.step(4)
    saved = a._states()
    assert "force" not in saved["fluid"]
    old = {solver: dict(arrays) for solver, arrays in saved.items()}
    old["fluid"]["force"] = np.full_like(saved["fluid"]["velocity"], np.nan)  # any value: not read
    old["coupler"]["fluid_u"] = np.full_like(saved["fluid"]["velocity"], np.nan)  # any value: not read
    old["coupler"]["eps_sand"] = np.full_like(saved["fluid"]["fluid_fraction"], np.nan)
    old["coupler"]["water"] = np.full_like(saved["coupler"]["bound"], np.nan)
    b._load_states(saved, 4)
    c._load_states(old, 4)
    b.step(3)
    c.step(3)
    _assert_same_states(b, c)


def test_mismatched_states_are_refused():
    with_ret, without = _sim(True), _sim(False)
    with pytest.raises(ValueError, match="bound_in"):
        with_ret.coupler.load_state(without.coupler.state())
    st = with_ret.coupler.state()
    st["eps_prev"] = st["eps_prev"][1:]
    with pytest.raises(ValueError, match="eps_prev.*shape"):
        with_ret.coupler.load_state(st)
