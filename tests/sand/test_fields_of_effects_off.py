"""Fields of switched-off sand effects are not allocated: hardening's q and cohesion's saturation (sand-only
scene) are None on the solver, the kernels run their placeholder variants, the outputs report host zeros, and
checkpoints save and restore without them; a checkpoint that has them (written before they went
unallocated) still loads."""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scene"))
from sim_scenes import tiny_coupled, tiny_sand  # noqa: E402

from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402


def _off(d: dict) -> dict:
    d = copy.deepcopy(d)
    d["effects"] = {"hardening": False, "cohesion": False}
    return d


def _sim(d: dict) -> Simulation:
    return Simulation(Scene.from_dict(d), backend="cpu", log=None)


def test_sand_only_scene_without_hardening_and_cohesion_allocates_neither_field():
    on, off = _sim(tiny_sand()), _sim(_off(tiny_sand()))
    assert on.sand.q is not None and on.sand.saturation is not None
    assert off.sand.q is None and off.sand.saturation is None
    off.step(4)
    p = off.particles()
    n = off.sand.n_particles
    # reported as zeros made on the host; the friction angle is the constant h0
    assert np.all(p["saturation"] == 0) and p["saturation"].shape == (n,)
    assert np.allclose(p["friction_angle"], p["friction_angle"][0]) and np.all(np.isfinite(p["x"]))
    assert np.all(off.sand.particles()["q"] == 0)


def test_every_particle_array_is_float32_with_effects_on_and_off():
    """The outputs write particles as they come; the friction angle (computed in float64 by the model) was the one
    float64 array among them."""
    for d in (tiny_sand(), _off(tiny_sand())):
        sim = _sim(d)
        sim.step(2)
        kinds = {k: v.dtype for k, v in sim.particles().items()}
        assert all(t == np.float32 for t in kinds.values()), kinds


def test_coupled_scene_keeps_the_saturation_as_the_couplings_moisture():
    sim = _sim(_off(tiny_coupled()))
    assert sim.sand.q is None and sim.sand.saturation is not None
    sim.step(2)
    assert np.all(np.isfinite(sim.particles()["saturation"]))


def test_restart_without_the_fields_is_bitwise(tmp_path):
    straight = _sim(_off(tiny_sand()))
    straight.step(8)
    first = _sim(_off(tiny_sand()))
    first.step(3)
    first.save(tmp_path / "c.h5")
    with h5py.File(tmp_path / "c.h5") as f:
        names = []
        f.visit(names.append)
    assert not any(n.endswith("/q") or n.endswith("/saturation") for n in names), names
    resumed = Simulation.load(tmp_path / "c.h5", backend="cpu", log=None)
    resumed.step(5)
    a, b = straight.sand.state(), resumed.sand.state()
    assert a.keys() == b.keys()
    for k in a:
        assert np.asarray(a[k]).tobytes() == np.asarray(b[k]).tobytes(), k


def test_a_state_that_still_has_the_fields_loads():
    src = _sim(_off(tiny_sand()))
    src.step(3)
    st = src.sand.state()
    n = src.sand.n_particles
    old = dict(st, q=np.zeros(n, np.float32), saturation=np.zeros(n, np.float32))  # an older checkpoint's sand
    dst = _sim(_off(tiny_sand()))
    dst.sand.load_state(old)
    assert dst.sand.q is None and dst.sand.saturation is None
    assert np.asarray(dst.sand.state()["x"]).tobytes() == np.asarray(st["x"]).tobytes()
