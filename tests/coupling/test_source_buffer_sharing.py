"""Last step's porosity ε̃_prev shares the fluid's S_φ buffer (SandFluidCoupler module docstring,
``share_source_buffer``): the schedulers that apply the source term set it up, it changes no result of any
scheduler (with and without retention, fp16 storage), checkpoints of either layout restart exactly, and a
scheduler without the source term keeps ε̃_prev apart so that the fluid sees S_φ = 0."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "scene"))
from couplekit.schedulers import make_scheduler  # noqa: E402
from sim_scenes import tiny_coupled_moving  # noqa: E402

from couplekit.bench.memory import allocated_summary  # noqa: E402
from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402


def _scene(scheduler: dict, retention: bool = False, storage: str = "fp32") -> dict:
    """A sand block half in the water layer and moving: ε̃ changes every step, so S_φ and ε̃_prev differ
    everywhere the sand goes."""
    d = tiny_coupled_moving(scheduler, retention)
    d["fluid"]["storage"] = storage
    return d


def _sim(scheduler: dict, share: bool, **kw) -> Simulation:
    sim = Simulation(Scene.from_dict(_scene(scheduler, **kw)), backend="cpu", log=None)
    assert sim.coupler.shares_source_buffer  # what every scheduler with the source term sets up
    if not share:
        sim.coupler.share_source_buffer(False)
    return sim


SCHEDULERS = [
    {"kind": "lockstep"},
    {"kind": "subcycle", "substeps": 3, "interpolation": "linear"},
    {"kind": "subcycle", "substeps": 2, "interpolation": "hold"},
    {"kind": "multirate", "sand_every": 1},
    {"kind": "multirate", "sand_every": 3},
]


def _assert_same_states(a: Simulation, b: Simulation) -> None:
    sa, sb = a._states(), b._states()
    assert sa.keys() == sb.keys()
    for solver in sa:
        assert sa[solver].keys() == sb[solver].keys(), solver
        for k in sa[solver]:
            if solver == "fluid" and k == "source_term":
                continue  # the shared buffer holds ε̃_prev between steps, the own one last step's S_φ
            assert np.asarray(sa[solver][k]).tobytes() == np.asarray(sb[solver][k]).tobytes(), (solver, k)


@pytest.mark.parametrize("retention", [False, True], ids=["dry", "retention"])
@pytest.mark.parametrize("scheduler", SCHEDULERS, ids=lambda s: "-".join(str(v) for v in s.values()))
def test_sharing_the_buffer_changes_nothing(scheduler, retention):
    """Every state array after 12 steps, shared buffer against two buffers: bitwise equal."""
    shared, own = _sim(scheduler, True, retention=retention), _sim(scheduler, False, retention=retention)
    assert shared.coupler.eps_prev is shared.fluid.source_term
    assert own.coupler.eps_prev is not own.fluid.source_term
    shared.step(12)
    own.step(12)
    s = np.array(own.fluid.source_term)
    assert np.abs(s).max() > 1e-4  # the source term acted ...
    eps_prev = np.array(own.coupler.eps_prev)
    assert np.abs(eps_prev[s != 0] - 1.0).max() > 0.1  # ... where the porosity is not 1
    _assert_same_states(shared, own)
    # between steps the shared buffer is last step's porosity
    assert np.array(shared.fluid.source_term).tobytes() == eps_prev.tobytes()


def test_sharing_with_fp16_storage_changes_nothing():
    shared, own = _sim({"kind": "lockstep"}, True, storage="fp16"), _sim({"kind": "lockstep"}, False, storage="fp16")
    shared.step(10)
    own.step(10)
    _assert_same_states(shared, own)


def test_sharing_saves_four_bytes_per_padded_cell():
    shared, own = _sim({"kind": "lockstep"}, True), _sim({"kind": "lockstep"}, False)
    a, b = allocated_summary(shared), allocated_summary(own)
    assert b["grid_arrays"] - a["grid_arrays"] == 4 * a["padded_cells"]


@pytest.mark.parametrize("saved_shared", [True, False], ids=["saved-shared", "saved-apart"])
def test_checkpoints_of_either_layout_restart_exactly(tmp_path, saved_shared):
    """A checkpoint written with two buffers (before the sharing: the fluid's S_φ and the coupler's ε̃_prev
    differ) restarts into the shared buffer with ε̃_prev, not S_φ, and continues bitwise as the run that
    wrote it; and the other way round."""
    sched = {"kind": "lockstep"}
    ref = _sim(sched, saved_shared)
    ref.step(6)
    path = tmp_path / "ck.h5"
    ref.save(path)
    if not saved_shared:
        st = ref._states()
        assert not np.array_equal(st["fluid"]["source_term"], st["coupler"]["eps_prev"])
    back = Simulation.load(path, backend="cpu", log=None)
    assert back.coupler.shares_source_buffer
    np.testing.assert_array_equal(np.array(back.coupler.eps_prev), np.array(ref.coupler.eps_prev))
    ref.step(6)
    back.step(6)
    _assert_same_states(back, ref)


def test_a_scheduler_without_the_source_term_keeps_the_porosity_apart():
    """source_term=False (paper Fig. 14's ablation) on a fluid built with an S_φ buffer: ε̃_prev gets a buffer of
    its own, S_φ stays 0 through the steps, and a scheduler with the source term shares again, carrying ε̃_prev."""
    sim = _sim({"kind": "lockstep"}, True)
    sim.step(3)
    eps_prev = np.array(sim.coupler.eps_prev)
    off = make_scheduler("lockstep", sim.fluid, sim.sand, sim.coupler, dt=sim.coupler.units.dt, source_term=False)
    c = sim.coupler
    assert not c.shares_source_buffer and c.eps_prev is not sim.fluid.source_term
    np.testing.assert_array_equal(np.array(c.eps_prev), eps_prev)
    assert not np.array(sim.fluid.source_term).any()
    off.step(4)
    assert not np.array(sim.fluid.source_term).any()
    eps_prev = np.array(c.eps_prev)
    assert np.array_equal(eps_prev, np.array(sim.fluid.fluid_fraction))  # finish() wrote it
    make_scheduler("lockstep", sim.fluid, sim.sand, sim.coupler, dt=sim.coupler.units.dt, source_term=True)
    assert c.shares_source_buffer
    np.testing.assert_array_equal(np.array(sim.fluid.source_term), eps_prev)
