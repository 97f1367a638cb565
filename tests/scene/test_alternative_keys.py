"""A setting that gives what the scene already says in another form replaces it (couplekit.sweep.keys.drop_replaced):
an SI viscosity the lattice one, absorption_time the per-step rate, dx the resolution. Found in session 31:
docs/sweeps.md's own example set `fluid.water_viscosity` on a base that gives `water_lattice_viscosity` (as every
example does) and every point was refused as giving both; `couplekit run --set fluid.water_viscosity=...` likewise."""

from __future__ import annotations

from pathlib import Path

import pytest

from couplekit.scene import Scene, SceneError
from couplekit.simulation import with_settings
from couplekit.sweep import parse_sweep

ROOT = Path(__file__).resolve().parents[2]
FIG13 = ROOT / "examples" / "fig13_sand_drop_beaker_small.toml"  # dx 6 mm, dt 1.44e-4 s, lattice ν 5e-4 / 1e-2
FIG17 = ROOT / "examples" / "fig17_wet_column_small.toml"  # absorption_rate 0.001 per step at dt 9.6e-4 s


def test_an_si_viscosity_replaces_the_files_lattice_one():
    scene = with_settings(FIG13, {"fluid.water_viscosity": 1.25e-4, "fluid.air_viscosity": 2.5e-3})
    assert scene.fluid.water_lattice_viscosity == pytest.approx(5e-4)  # 1.25e-4 × 1.44e-4 / 0.006²: the file's
    assert scene.fluid.air_lattice_viscosity == pytest.approx(1e-2)
    halved = with_settings(FIG13, {"fluid.water_viscosity": 1.25e-4, "time.dt": 7.2e-5})
    assert halved.fluid.water_lattice_viscosity == pytest.approx(2.5e-4)  # one viscosity at the new dt
    with pytest.raises(SceneError, match="both water_viscosity and water_lattice_viscosity"):
        with_settings(FIG13, {"fluid.water_viscosity": 1.25e-4, "fluid.water_lattice_viscosity": 5e-4})


def test_absorption_time_replaces_the_files_rate_and_dx_the_resolution():
    scene = with_settings(FIG17, {"sand.absorption_time": 0.96})
    assert scene.sand.absorption_time == 0.96
    assert scene.sand.absorption_rate == pytest.approx(9.6e-4 / 0.96)  # R_a = dt / τ
    d = Scene.load(FIG13).to_dict()
    d["domain"].pop("dx")
    d["domain"]["resolution"] = [26, 26, 41]
    coarse = with_settings(Scene.from_dict(d), {"domain.dx": 0.012, "domain.size": [0.156, 0.156, 0.24]})
    assert coarse.domain.resolution == (13, 13, 20)


def test_a_sweep_of_the_time_step_at_one_si_viscosity():
    data = {
        "sweep": {
            "base": str(FIG13),
            "frames": 1,
            "set": {"fluid.water_viscosity": 1.25e-4, "fluid.air_viscosity": 2.5e-3},
            "grid": {"time.dt": [1.44e-4, 7.2e-5]},
        }
    }
    spec = parse_sweep(data)
    assert [p.invalid for p in spec.points] == [None, None]
    lattice = [Scene.from_dict(p.scene).fluid.water_lattice_viscosity for p in spec.points]
    assert lattice == pytest.approx([5e-4, 2.5e-4])
    data["sweep"]["set"]["fluid.water_lattice_viscosity"] = 5e-4  # both forms in one point: refused, named
    assert all("both water_viscosity and water_lattice_viscosity" in p.invalid for p in parse_sweep(data).points)
