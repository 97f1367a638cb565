"""The scene key ``fluid.odd_ramp`` (the odd-rate floor ramped to the paper's rate 1 away from the walls,
couplekit.fluid.odd_ramp): it reaches the solver, costs the memory ``couplekit validate`` says, and a scene whose
walls or obstacles leave a gap narrower than the ramp accepts is refused by ``validate`` with ``run``'s message,
before anything is allocated."""

from __future__ import annotations

import numpy as np
import pytest
from test_sim_cli import _toml  # the tiny TOML writer of the CLI tests

from couplekit.assembly import check_odd_ramp_gaps, fluid_params, memory_estimate, odd_ramp_applies
from couplekit.cli import main
from couplekit.fluid.grid import INTERIOR
from couplekit.scene import Scene, SceneError
from couplekit.simulation import Simulation


def _tank(n: int = 12, odd_ramp: float = 3.0, nu_h: float = 1e-4, obstacle: dict | None = None) -> dict:
    """An n³ tank (2.5 mm cells), half full of still water, walls on every face."""
    L = n * 0.0025
    d = {
        "scene": {"name": "ramped_tank"},
        "domain": {"size": [L, L, L], "dx": 0.0025},
        "time": {"dt": 2e-5, "frame_duration": 2e-4, "frames": 2},
        "fluid": {"phases": 2, "water_lattice_viscosity": nu_h, "air_lattice_viscosity": 1e-2, "odd_ramp": odd_ramp},
        "bodies": [{"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [L, L, L / 2]}}],
        "outputs": {"preview": False},
    }
    if obstacle is not None:
        d["bodies"].append({"kind": "obstacle", "geometry": obstacle})
    return d


@pytest.mark.parametrize("n", [10, 14])
def test_the_ramp_reaches_the_solver_and_runs(n):
    scene = Scene.from_dict(_tank(n))
    assert fluid_params(scene, scene.units()).odd_ramp == 3.0 and odd_ramp_applies(scene)
    sim = Simulation(scene, backend="cpu", log=None)
    s = sim.fluid.backend.to_host(sim.fluid.odd_ramp)[INTERIOR]
    assert s.shape == (n, n, n) and s[0, 0, 0] == 0.0 and s.max() <= 1.0
    # rate 1 at the centre exactly when it lies 3.5 cells or more from every wall
    assert (s[n // 2, n // 2, n // 2] == pytest.approx(1.0, abs=1e-6)) == (n / 2 >= 3.5 + 0.5)
    sim.step(20)
    assert np.isfinite(sim.diagnostics()["max_lattice_speed"])


def test_the_memory_estimate_counts_the_weights_only_where_the_floor_acts():
    on, off = Scene.from_dict(_tank()), Scene.from_dict(_tank(odd_ramp=0.0))
    padded = 14**3
    assert memory_estimate(on)["fluid"] - memory_estimate(off)["fluid"] == 4 * padded
    # at ν = 1e-3 the floor does not act, so neither does its ramp: nothing allocated, nothing estimated
    high = Scene.from_dict(_tank(nu_h=1e-3))
    assert not odd_ramp_applies(high)
    assert memory_estimate(high)["fluid"] == memory_estimate(Scene.from_dict(_tank(odd_ramp=0.0, nu_h=1e-3)))["fluid"]
    assert Simulation(high, backend="numpy", log=None).fluid.odd_ramp is None


def test_a_negative_ramp_is_invalid():
    with pytest.raises(SceneError, match="odd_ramp"):
        Scene.from_dict(_tank(odd_ramp=-1.0))


def test_validate_refuses_a_gap_the_ramp_cannot_take_with_runs_message(tmp_path, capsys):
    # a 6-cell-wide block (x 3..8 of 12, from the floor up to cell 8) leaves 3-cell gaps along x to the walls
    block = {"type": "box", "min": [0.0075, 0.0, 0.0], "max": [0.0225, 0.03, 0.02]}
    d = _tank(12, obstacle=block)
    with pytest.raises(ValueError, match=r"3 cells wide along x.*odd_ramp = 0"):
        check_odd_ramp_gaps(Scene.from_dict(d))
    path = tmp_path / "gap.toml"
    path.write_text(_toml(d))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: odd_ramp = 3: the fluid is 3 cells wide along x")
    # run stops with the same message, before a step
    with pytest.raises(ValueError, match="3 cells wide along x"):
        Simulation(Scene.from_dict(d), backend="numpy", log=None)
    # without the ramp the same scene validates
    path.write_text(_toml(_tank(12, odd_ramp=0.0, obstacle=block)))
    assert main(["validate", str(path)]) == 0
    assert "valid" in capsys.readouterr().out
