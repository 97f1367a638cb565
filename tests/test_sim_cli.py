"""`couplekit validate` names what `run` would refuse (and nothing for a scene it runs); the Fig. 8 examples
(three sand densities in one scene) build."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import tiny_coupled  # noqa: E402

from couplekit.cli import main  # noqa: E402
from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation, memory_estimate  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _toml(d: dict) -> str:
    """The small subset of TOML the tiny scenes need (tables, arrays of tables, numbers, strings, lists)."""
    out: list[str] = []

    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    def table(name: str, t: dict, array: bool = False) -> None:
        out.append(f"[[{name}]]" if array else f"[{name}]")
        subs = []
        for k, v in t.items():
            if isinstance(v, dict):
                subs.append((k, v))
            else:
                out.append(f"{k} = {value(v)}")
        for k, v in subs:
            table(f"{name}.{k}", v)

    for name, t in d.items():
        if isinstance(t, list):
            for item in t:
                table(name, item, array=True)
        else:
            table(name, t)
    return "\n".join(out) + "\n"


def test_validate_and_run_refuse_the_coupling_switch_alike(tmp_path, capsys):
    ok = tmp_path / "ok.toml"
    ok.write_text(_toml(tiny_coupled()))
    assert main(["validate", str(ok)]) == 0
    assert "refuses" not in capsys.readouterr().out
    d = tiny_coupled()
    d["effects"] = {"drag": False}
    bad = tmp_path / "bad.toml"
    bad.write_text(_toml(d))
    assert main(["validate", str(bad)]) == 3  # refused as run refuses it (exit 3, run's message)
    captured = capsys.readouterr()
    assert "refused:" in captured.err and "effects.drag = false" in captured.err
    assert "valid" not in captured.out


@pytest.mark.parametrize("name", ["fig08_sand_densities_small.toml"])
def test_fig08_builds_with_three_densities(name):
    """The three balls (600, 950, 1500 kg/m³) each carry their density; no refusal. (The paper-scale file
    builds the same way, it only needs more memory; `couplekit run ... --frames 2` on the small one is timed
    in the report, not here.)"""
    scene = Scene.load(ROOT / "examples" / name)
    assert memory_estimate(scene)["total"] < 2**30
    sim = Simulation(scene, backend="cpu", log=None)
    p = sim.particles()
    rho = p["mass"] / p["volume"]
    for x, expect in ((0.375, 600.0), (0.75, 950.0), (1.125, 1500.0)):
        ball = np.abs(p["x"][0] - x) < 0.1
        assert ball.sum() > 100
        np.testing.assert_allclose(rho[ball], expect, rtol=1e-6)
