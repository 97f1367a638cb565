"""Arguments of the Python API that are not what they should be are refused with a message naming them:
step counts and frame counts that are not whole numbers ≥ 0 (a negative count once moved the step and the time
backwards, and the outputs after it carried the wrong time), a backend that is not a name, and
``with_settings`` takes a scene file's path as ``Simulation`` does."""

from __future__ import annotations

import numpy as np
import pytest

import couplekit as ck
from couplekit.simulation import with_settings

SCENE = "examples/sand_drop_small.toml"


@pytest.fixture(scope="module")
def sim():
    return ck.Simulation(ck.Scene.load(SCENE), "cpu", log=None)


@pytest.mark.parametrize(
    ("n", "error", "match"),
    [
        (-1, ValueError, "n must be 0 or more"),
        (2.5, ValueError, "n must be a whole number"),
        ("3", TypeError, "n must be a whole number of steps"),
        (True, TypeError, "n must be a whole number of steps"),
        (None, TypeError, "n must be a whole number of steps"),
        (float("nan"), ValueError, "n must be a whole number"),
    ],
)
def test_step_refuses_what_is_not_a_count(sim, n, error, match):
    before = (sim.step_count, sim.time)
    with pytest.raises(error, match=match):
        sim.step(n)
    assert (sim.step_count, sim.time) == before


def test_step_takes_whole_numbers_of_any_kind(sim):
    start = sim.step_count
    sim.step(0)
    sim.step(np.int64(2))
    sim.step(1.0)
    assert sim.step_count == start + 3


def test_run_refuses_a_fractional_frame_count(sim, tmp_path):
    with pytest.raises(ValueError, match="frames must be a whole number"):
        sim.run(frames=1.5, out=tmp_path / "r", progress=False)
    assert not (tmp_path / "r").exists() or not any((tmp_path / "r").iterdir())


def test_a_backend_that_is_not_a_name_is_named():
    with pytest.raises(TypeError, match=r"backend must be a name .*'cpu'.* got 3"):
        ck.Simulation(ck.Scene.load(SCENE), 3, log=None)


def test_with_settings_takes_a_scene_file():
    scene = with_settings(SCENE, {"time.frames": 3})
    assert scene.time.frames == 3
    assert scene.to_dict() == with_settings(ck.Scene.load(SCENE), {"time.frames": 3}).to_dict()
    with pytest.raises(TypeError, match="scene must be a Scene or a scene file's path, got int"):
        with_settings(3, {"time.frames": 3})
