"""Set-ups a scene may ask for but that were measured to diverge are named before the run (couplekit.assembly.
stability_cautions): the paper's collision (the odd-moment floor off) below ν = 5e-4 where bounce-back walls
meet at edges (docs/fluid-stability.md, "What fails"). Printed by ``couplekit validate``, logged by a run; never a
refusal, and nothing for the shipped examples."""

from __future__ import annotations

from pathlib import Path

import pytest

from couplekit.assembly import stability_cautions
from couplekit.cli import main
from couplekit.scene import Scene
from couplekit.simulation import Simulation

ROOT = Path(__file__).resolve().parents[2]
FACES = ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")


def _tank(nu_h: float = 1e-4, odd_lambda: float | None = 0.0, phases: int = 2, boundary: dict | None = None) -> dict:
    """A 12³ tank half full of still water (single phase: full); walls on every face unless ``boundary`` says
    otherwise."""
    fluid = {"phases": phases, "water_lattice_viscosity": nu_h}
    if phases == 2:
        fluid["air_lattice_viscosity"] = 1e-2
    if odd_lambda is not None:
        fluid["odd_lambda"] = odd_lambda
    d = {
        "scene": {"name": "still_tank"},
        "domain": {"size": [0.03, 0.03, 0.03], "dx": 0.0025},
        "time": {"dt": 2e-5, "frame_duration": 2e-4, "frames": 3},
        "fluid": fluid,
        "bodies": [{"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.03, 0.03, 0.015]}}],
        "outputs": {"preview": False},
    }
    if boundary is not None:
        d["domain"]["boundary"] = boundary
    if phases == 1:  # the fluid fills the domain: no water body
        del d["bodies"]
    return d


def _cautions(d: dict) -> list[str]:
    return stability_cautions(Scene.from_dict(d))


@pytest.mark.parametrize("phases", [1, 2])
def test_the_paper_collision_at_low_viscosity_in_a_walled_tank_is_named(phases):
    (line,) = _cautions(_tank(phases=phases))
    assert "fluid.odd_lambda = 0" in line and "0.0001" in line and "walls on two axes" in line
    assert "30 steps" in line  # 3 frames of 10 steps
    assert "fluid.odd_lambda = 0.015" in line  # the fix


def test_a_floor_too_small_to_act_is_named_too():
    """Λ = 1e-5 acts only below ν = 2Λ/3 ≈ 6.7e-6: at 1e-4 the collision is the paper's."""
    (line,) = _cautions(_tank(odd_lambda=1e-5))
    assert "too small to act" in line


@pytest.mark.parametrize(
    "d",
    [
        _tank(odd_lambda=None),  # the scene default floor
        _tank(odd_lambda=0.015),
        _tank(nu_h=1e-3),  # stable at the paper's rate (the floor's threshold 5e-4)
        _tank(nu_h=1e-3, phases=1),
        _tank(boundary={f: ("wall" if f[0] == "z" else "periodic") for f in FACES}),  # flat walls on one axis
    ],
    ids=["default", "floor", "nu_1e-3", "nu_1e-3_single_phase", "walls_on_one_axis"],
)
def test_stable_set_ups_get_no_caution(d):
    assert _cautions(d) == []


def test_the_air_viscosity_counts_when_it_is_the_lowest():
    """Two phases: the floor's reference is min(ν_h, ν_l); water at 1e-3 over air at 1e-4 is below 5e-4."""
    d = _tank(nu_h=1e-3)
    d["fluid"]["air_lattice_viscosity"] = 1e-4
    (line,) = _cautions(d)
    assert "0.0001" in line


def test_an_obstacle_gives_edges_between_flat_walls():
    d = _tank(boundary={f: ("wall" if f[0] == "z" else "periodic") for f in FACES})
    d["bodies"].append(
        {"kind": "obstacle", "geometry": {"type": "box", "min": [0.01, 0.01, 0.0], "max": [0.02, 0.02, 0.01]}}
    )
    (line,) = _cautions(d)
    assert "an obstacle" in line


def test_validate_prints_the_caution_and_still_exits_0(tmp_path, capsys):
    from test_sim_cli import _toml  # the tiny TOML writer of the CLI tests

    path = tmp_path / "tank.toml"
    path.write_text(_toml(_tank()))
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    assert "valid" in out and "caution: fluid.odd_lambda = 0" in out
    path.write_text(_toml(_tank(odd_lambda=None)))
    assert main(["validate", str(path)]) == 0
    assert "caution:" not in capsys.readouterr().out


def test_a_run_logs_the_caution():
    lines: list[str] = []
    Simulation(Scene.from_dict(_tank()), backend="numpy", log=lines.append)
    assert any(line.startswith("caution: fluid.odd_lambda = 0") for line in lines)


def test_no_shipped_example_is_cautioned():
    paths = sorted((ROOT / "examples").glob("*.toml")) + sorted((ROOT / "docs" / "cases").glob("*.toml"))
    assert len(paths) > 20
    flagged = [p.name for p in paths if stability_cautions(Scene.load(p))]
    assert flagged == []
