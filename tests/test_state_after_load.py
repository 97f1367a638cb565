"""A simulation loaded from a checkpoint reports what the run that saved it reported, before any step.

The bug: right after ``Simulation.load`` the sand fields (``sand_fraction``, ``sand_velocity``: the sand grid of
the last step, which the restart does not need) were zero, and the diagnostics' sand-step statistics
(``sand_steps_per_step``, ``substeps_min``, ``substeps_max``) read 0, or with a multi-rate scheduler restarted
counting. The checkpoint now holds the sand grid (sparse) and the frame's statistics; a checkpoint written
without them still loads and continues bitwise.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import couplekit as ck
from couplekit.io.checkpoint import load_checkpoint, save_checkpoint

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import tiny_sand  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FIG13 = ROOT / "examples" / "fig13_sand_drop_beaker_small.toml"
FIG08 = ROOT / "examples" / "fig08_sand_densities_small.toml"

CASES = {
    "lockstep": (FIG13, None),
    "multirate:2": (FIG08, "multirate:2"),
    "subcycle:auto": (FIG08, "subcycle:auto"),
    "subcycle:2:linear": (FIG08, "subcycle:2:linear"),
    "sand-only lockstep": (None, None),
}
STEPS = 7  # odd: a multi-rate run is saved inside a block

NEW_SAND_KEYS = ("grid_nodes", "grid_m", "grid_vol", "grid_v")
NEW_SCHEDULER_KEYS = ("last_sand_steps", "frame_sand_values", "frame_sand_counts")


def _sim(case: str, **kw) -> ck.Simulation:
    path, scheduler = CASES[case]
    scene = ck.Scene.from_dict(tiny_sand()) if path is None else ck.Scene.load(path)
    return ck.Simulation(scene, "cpu", log=None, scheduler=scheduler, **kw)


def _same_arrays(a: dict, b: dict, what: str) -> None:
    assert sorted(a) == sorted(b), what
    for k in a:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        assert x.dtype == y.dtype and x.shape == y.shape, f"{what}[{k}]"
        assert x.tobytes() == y.tobytes(), f"{what}[{k}] differs"


def _wall_clock(key: str) -> bool:
    return key == "step_seconds" or key.startswith("stage_")


def _same_diagnostics(a: dict, b: dict) -> None:
    a = {k: v for k, v in a.items() if not _wall_clock(k)}
    b = {k: v for k, v in b.items() if not _wall_clock(k)}
    assert a.keys() == b.keys()
    assert {k: v for k, v in a.items() if v != b[k]} == {}, "diagnostics differ"


def _same_states(a: ck.Simulation, b: ck.Simulation) -> None:
    sa, sb = a._states(statistics=True), b._states(statistics=True)  # as save() writes them
    assert sa.keys() == sb.keys()
    for name in sa:
        _same_arrays(sa[name], sb[name], name)


@pytest.mark.parametrize("case", list(CASES))
def test_loaded_simulation_reports_what_the_saver_did(case, tmp_path):
    a = _sim(case)
    a.step(STEPS)
    path = a.save(tmp_path / "ck.h5")
    b = ck.Simulation.load(path, backend="cpu", log=None)
    fields = a.fields()
    assert fields["sand_fraction"].sum() > 0 and np.abs(fields["sand_velocity"]).sum() > 0
    _same_arrays(fields, b.fields(), "fields")
    _same_arrays(a.fields(lattice=True), b.fields(lattice=True), "lattice fields")
    _same_arrays(a.sand.fields(), b.sand.fields(), "sand grid")
    _same_arrays(a.particles(), b.particles(), "particles")
    da = a.diagnostics()
    assert da["sand_steps_per_step"] > 0 and da["substeps_max"] > 0
    _same_diagnostics(da, b.diagnostics())
    _same_states(a, b)
    # and the restart stays exact
    a.step(3)
    b.step(3)
    _same_arrays(a.fields(), b.fields(), "fields after 3 steps")
    _same_arrays(a.particles(), b.particles(), "particles after 3 steps")
    _same_diagnostics(a.diagnostics(), b.diagnostics())
    _same_states(a, b)


def test_multirate_frame_statistics_survive_the_restart(tmp_path):
    a = _sim("multirate:2")
    a.step(17)
    b = ck.Simulation.load(a.save(tmp_path / "ck.h5"), backend="cpu", log=None)
    st = a.scheduler.sand_steps()
    assert st["frame_mean"] == pytest.approx(9 / 17)  # not 0.5: the frame's count carries over the restart
    assert b.scheduler.sand_steps()["frame_mean"] == st["frame_mean"]
    frame = ("frame_mean", "frame_min", "frame_max")
    for sim in (a, b):
        sim.step(2)
    assert [a.scheduler.sand_steps()[k] for k in frame] == [b.scheduler.sand_steps()[k] for k in frame]
    for sim in (a, b):
        sim.scheduler.frame_sand_steps()  # a frame ends: the next one counts afresh, alike
        sim.step(1)
    assert [a.scheduler.sand_steps()[k] for k in frame] == [b.scheduler.sand_steps()[k] for k in frame]
    assert a.scheduler.sand_steps()["frame_mean"] == 0.0  # the 20th step (index 19) of sand_every 2 is fluid-only


def test_sand_grid_is_stored_sparsely(tmp_path):
    a = _sim("lockstep")
    a.step(STEPS)
    st = a.sand.state()
    nodes = st["grid_nodes"]
    cells = int(np.prod(a.sand.shape))
    assert 0 < nodes.size < cells // 4 and nodes.dtype == np.int32
    assert st["grid_v"].shape == (3, nodes.size)
    # a state whose grid does not fit the solver is refused, naming the keys
    bad = dict(st, grid_nodes=np.array([cells], np.int32), grid_m=np.zeros(1, np.float32),
               grid_vol=np.zeros(1, np.float32), grid_v=np.zeros((3, 1), np.float32))  # fmt: skip
    with pytest.raises(ValueError, match="grid_nodes"):
        a.sand.load_state(bad)


def _old_format(states: dict) -> dict:
    """``states`` as a checkpoint written before the sand grid and the scheduler statistics were saved."""
    old = {name: dict(st) for name, st in states.items()}
    for k in NEW_SAND_KEYS:
        del old["sand"][k]
    if "scheduler" in old:
        for k in NEW_SCHEDULER_KEYS:
            del old["scheduler"][k]
        if not old["scheduler"]:  # lockstep and multi-rate had no scheduler state then
            del old["scheduler"]
    return old


@pytest.mark.parametrize("case", ["lockstep", "multirate:2", "subcycle:2:linear"])
def test_old_checkpoint_without_the_new_entries_loads_and_continues_bitwise(case, tmp_path):
    a = _sim(case)
    a.step(STEPS)
    # in memory, as the run loop restores its last good state
    b = _sim(case)
    b._load_states(_old_format(a._states(statistics=True)), a.step_count)
    assert not b.fields()["sand_fraction"].any()  # not stored: zero until the next sand step, as before
    # and through a file, as an old couplekit wrote it
    meta = {"step": a.step_count, "time": a.time, "backend": "cpu", "couplekit": "old"}
    if a.fluid is not None:
        meta["fluid_storage"] = a.fluid.storage
    path = save_checkpoint(tmp_path / "old.h5", a.scene.to_dict(), _old_format(a._states(statistics=True)), meta)
    states = load_checkpoint(path)[1]
    assert not set(NEW_SAND_KEYS) & set(states["sand"])
    c = ck.Simulation.load(path, backend="cpu", log=None)
    for sim in (a, b, c):
        sim.step(4)
    for sim in (b, c):
        _same_arrays(a.fields(), sim.fields(), "fields")
        _same_arrays(a.particles(), sim.particles(), "particles")
        sa, ss = a._states(), sim._states()  # the restart's state (the frame's statistics restarted at the load)
        assert sa.keys() == ss.keys()
        for name in sa:
            _same_arrays(sa[name], ss[name], name)
