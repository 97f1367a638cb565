"""Multi-rate blocks and frames (docs/schedulers.md): a block's one sand step is taken at its first fluid step, so
frames that fall inside a block show the sand ahead of their time; an m that does not divide a frame's steps draws
a caution naming the divisors that align, and the elastic-limit refusal names a fix that works when time.dt itself
is over the limit (both found by a probe, session 23)."""

from __future__ import annotations

import numpy as np
import pytest
from sim_scenes import tiny_coupled_moving, tiny_sand

from couplekit.cautions import stability_cautions
from couplekit.scene import Scene, SceneError
from couplekit.simulation import Simulation


def _coupled(sand_every: int, frame_steps: int) -> dict:
    """tiny_coupled_moving under multirate:sand_every with frames of ``frame_steps`` steps of 1e-5 s (the sand's
    elastic limit, 7e-5 s, admits sand_every <= 7)."""
    d = tiny_coupled_moving({"kind": "multirate", "sand_every": sand_every})
    d["time"].update({"dt": 1e-5, "frame_duration": frame_steps * 1e-5})
    return d


@pytest.mark.parametrize(
    "sand_every, frame, words",
    [
        (3, 5, "sand_every = 3 does not divide the 5 fluid steps of a frame"),  # no divisor of 5 in 2..3
        (4, 6, "scheduler.sand_every = 3 divides them"),  # 3 aligns (and 2)
        (7, 12, "up to 6 fluid steps"),
    ],
)
def test_a_block_that_does_not_fit_a_frame_is_a_caution(sand_every, frame, words):
    lines = [c for c in stability_cautions(Scene.from_dict(_coupled(sand_every, frame))) if "sand_every" in c]
    assert len(lines) == 1 and words in lines[0] and "ahead of the frame's time" in lines[0]


@pytest.mark.parametrize("sand_every, frame", [(2, 12), (3, 12), (4, 12), (1, 5)])
def test_blocks_that_fit_the_frames_draw_no_caution(sand_every, frame):
    assert not [c for c in stability_cautions(Scene.from_dict(_coupled(sand_every, frame))) if "sand_every" in c]


def test_the_sand_is_ahead_inside_a_block_by_its_steps():
    """What the caution says, measured: free flight, m = 3, after 5 fluid steps (inside the second block) the sand
    has taken two sand steps of 3 dt, its velocity that of t + dt."""
    d = tiny_sand(frames=1)
    d["sand"]["youngs_modulus"] = 1e4  # the elastic limit admits 3 dt
    d["bodies"] = d["bodies"][:1]
    d["bodies"][0]["velocity"] = [0, 0, 0.5]
    d["scheduler"] = {"kind": "multirate", "sand_every": 3}
    sim = Simulation(Scene.from_dict(d), backend="cpu", log=None)
    sim.step(5)
    dt, g = d["time"]["dt"], 9.81
    vz = float(np.mean(sim.sand.particles()["v"][2]))
    assert vz == pytest.approx(0.5 - g * (sim.time + dt), abs=1e-5)
    sim.step(1)  # the block ends: the clocks agree again
    vz = float(np.mean(sim.sand.particles()["v"][2]))
    assert vz == pytest.approx(0.5 - g * sim.time, abs=1e-5)


def test_the_elastic_refusal_names_a_time_step_that_works():
    d = tiny_coupled_moving({"kind": "multirate", "sand_every": 2})
    d["time"].update({"dt": 1e-4, "frame_duration": 5e-4})
    with pytest.raises(SceneError, match="scheduler.sand_every") as err:
        Scene.from_dict(d)
    msg = str(err.value)
    fix = float(msg.split("lower time.dt to <= ")[1].split(" s")[0])
    d["time"].update({"dt": fix, "frame_duration": 10 * fix})
    Scene.from_dict(d)  # following the fix is accepted


def test_a_frame_that_is_not_a_whole_number_of_steps_is_a_caution():
    d = tiny_sand()
    d["time"].update({"dt": 2e-5, "frame_duration": 5e-5})  # 2.5 steps: frames of 2 steps, 20 % short
    lines = [c for c in stability_cautions(Scene.from_dict(d)) if "frame_duration" in c]
    assert len(lines) == 1 and "frames are 2 steps" in lines[0] and "-20 %" in lines[0]
    d["time"]["frame_duration"] = 4e-5
    assert not [c for c in stability_cautions(Scene.from_dict(d)) if "frame_duration" in c]
