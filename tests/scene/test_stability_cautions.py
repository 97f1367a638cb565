"""Set-ups a scene may ask for but that were measured to diverge are named before the run (couplekit.assembly.
stability_cautions): the paper's collision (the odd-moment floor off) below ν = 5e-4 where bounce-back walls
meet at edges (docs/fluid-stability.md, "What fails"). Printed by ``couplekit validate``, logged by a run; never a
refusal, and nothing for the shipped examples."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from couplekit.cautions import stability_cautions
from couplekit.cli import main
from couplekit.scene import Scene
from couplekit.simulation import Simulation

sys.path.insert(0, str(Path(__file__).parent))
from sim_scenes import tiny_coupled, tiny_sand  # noqa: E402

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


SMALL_DROPS = {"fig06_raindrop_small.toml", "fig17_wet_column_small.toml"}
"""Small variants whose water body is under 2 interface widths across (the raindrop 6.7 cells, the pour 7.5):
their only caution, documented in docs/examples.md."""


def test_no_shipped_example_is_cautioned():
    paths = sorted((ROOT / "examples").glob("*.toml")) + sorted((ROOT / "docs" / "cases").glob("*.toml"))
    assert len(paths) > 20
    flagged = {}
    for p in paths:
        lines = stability_cautions(Scene.load(p))
        if p.name in SMALL_DROPS:
            assert len(lines) == 1 and "(water) is only" in lines[0], (p.name, lines)
        elif lines:
            flagged[p.name] = lines
    assert flagged == {}


def _outlet_scene(face_kind: str) -> dict:
    """A 20³ box (dx = 1 cm), a pool 6 cm deep, a 4 × 4-cell water outlet in the ceiling at 0.5 m/s, the ceiling
    a wall or an outflow."""
    return {
        "scene": {"name": "outlet_in_" + face_kind},
        "domain": {"size": [0.2, 0.2, 0.2], "dx": 0.01, "boundary": {"z_max": face_kind}},
        "time": {"dt": 2.5e-4, "frame_duration": 0.01},
        "fluid": {},
        "inflows": [
            {
                "face": "z_max",
                "kind": "water",
                "velocity": [0.0, 0.0, -0.5],
                "shape": "rect",
                "center": [0.1, 0.1],
                "size": [0.04, 0.04],
            },
        ],  # fmt: skip
        "bodies": [{"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.2, 0.2, 0.06]}}],
        "outputs": {"preview": False},
    }


@pytest.mark.parametrize("dx", [0.01, 0.008])
@pytest.mark.parametrize("face_kind", ["wall", "outflow"])
def test_a_water_outlet_delivers_its_flux_in_a_wall_or_an_outflow_face(face_kind, dx):
    """A water outlet delivers its flux u A whether its face is a wall or an outflow (per 400 steps after the
    front's ramp: 8.0e-5 m³; measured 1.000x through the wall face, 0.997x through the outflow face). An outflow
    face used to let water in with the jet: 1.4-1.9x before session 28's backflow rule, 1.08x after it, because the
    phase field's outflow links passed the sharpening and diffusive fluxes of the jet's edge cells in; since
    session 29 they pass only the advective flux out (kernels/phasefield.cu pf_outflux), and the caution that
    named such an outlet is gone. At dx = 8 mm (a 5 × 5-cell outlet, Δt scaled with dx so the lattice speed stays,
    the steps with 1/dx): 1.000x and 1.000x (0.9996). Bound: 1 ± 0.03 for both."""
    from couplekit.simulation import Simulation

    d = _outlet_scene(face_kind)
    dt = 2.5e-4 * dx / 0.01
    d["domain"]["dx"], d["time"]["dt"] = dx, dt
    assert not [c for c in _cautions(d) if "water outlet" in c]
    sim = Simulation(Scene.from_dict(d), "cpu", log=None)
    sim.step(round(800 * 0.01 / dx))  # past the front's ramp
    v0 = float(sim.fields()["phi"].sum()) * dx**3
    steps = round(400 * 0.01 / dx)
    sim.step(steps)
    ratio = (float(sim.fields()["phi"].sum()) * dx**3 - v0) / (0.5 * 0.04**2 * steps * dt)
    assert ratio == pytest.approx(1.0, abs=0.03)


def test_fp16_storage_is_cautioned_where_gravity_would_be_rounded_away():
    """fluid.storage = 'fp16' rounds each stored f − w to ~2^-11 of itself; gravity's per-step increment is lost
    where the flow is faster than g_lattice / 2^-11 (tests/fluid/test_fp16_accuracy.py measures the stall). Fig.
    13 at the paper's resolution (g = 2.8e-6, expected lattice speed 0.039 > 0.0058) is cautioned with fp16, not
    with fp32; its small variant (g = 3.4e-5: 0.069, above what it expects) is not."""
    from couplekit.simulation import with_settings

    full = ROOT / "examples" / "fig13_sand_drop_beaker.toml"
    fp16 = [c for c in stability_cautions(with_settings(full, {"fluid.storage": "fp16"})) if "fp16" in c]
    assert len(fp16) == 1 and "rounded away" in fp16[0] and "0.0058" in fp16[0]
    assert not [c for c in stability_cautions(Scene.load(full)) if "fp16" in c]
    small = ROOT / "examples" / "fig13_sand_drop_beaker_small.toml"
    assert not [c for c in stability_cautions(with_settings(small, {"fluid.storage": "fp16"})) if "fp16" in c]


@pytest.mark.parametrize("radius_cells, low, high", [(0.2, None, None), (1.0, 8.0, 20.0), (2.0, 2.5, 5.0)])
def test_a_water_drop_smaller_than_its_interface_is_named(radius_cells, low, high):
    """A drop under 2 interface widths across starts with far more water than its volume (the tanh profile of
    width W around it): the caution says how much (a probe's 0.2-cell drop held ~800x its volume, 2 cells 3.6x)."""
    import re

    import numpy as np

    dx = 0.005
    d = {
        "domain": {"size": [0.12, 0.12, 0.12], "dx": dx},
        "time": {"dt": 1e-4},
        "fluid": {"phases": 2},
        "bodies": [{"kind": "water", "geometry": {"type": "sphere", "center": [0.06, 0.06, 0.06],
                                                   "radius": radius_cells * dx}}],
    }  # fmt: skip
    lines = [c for c in stability_cautions(Scene.from_dict(d)) if "bodies[0] (water) is only" in c]
    assert len(lines) == 1 and "make it at least 8 cells across" in lines[0]
    if low is not None:
        ratio = float(re.search(r"starts it with ([0-9.]+)x its volume", lines[0]).group(1))
        assert low < ratio < high
        # the ratio is what the solver starts with: its phi sum over the sphere's volume
        sim = Simulation(Scene.from_dict(d), backend="numpy", log=None)
        phi_sum = float(np.asarray(sim.fields(lattice=True)["phi"], np.float64).sum())
        assert abs(phi_sum / (4.0 / 3.0 * np.pi * radius_cells**3) / ratio - 1.0) < 0.1


def test_a_drop_two_interface_widths_across_gets_no_caution():
    d = {
        "domain": {"size": [0.12, 0.12, 0.12], "dx": 0.005},
        "time": {"dt": 1e-4},
        "fluid": {"phases": 2},
        "bodies": [{"kind": "water", "geometry": {"type": "sphere", "center": [0.06, 0.06, 0.06], "radius": 0.02}}],
    }
    assert not [c for c in stability_cautions(Scene.from_dict(d)) if "(water) is only" in c]


def test_sand_one_cell_off_the_walls_is_named():
    """``sand.wall_layers = 1`` with a fluid: the floor-wall edge current of docs/fluid-stability.md (session 25:
    Eq. 39's slip term drives it); the default 2, and sand without a fluid, get no such caution."""
    d = tiny_coupled()
    d["sand"]["wall_layers"] = 1
    named = [c for c in _cautions(d) if "wall_layers" in c]
    assert len(named) == 1 and "keep 2" in named[0], _cautions(d)
    assert not [c for c in _cautions(tiny_coupled()) if "wall_layers" in c]
    dry = tiny_sand()
    dry.setdefault("sand", {})["wall_layers"] = 1
    assert not [c for c in stability_cautions(Scene.from_dict(dry)) if "wall_layers" in c]


def test_an_absorption_rate_beyond_the_measured_one_is_named():
    """A probe (session 25): sand.absorption_rate 0.05, 0.1 and 1 (the schema admits up to 1) made a dry bed under
    water go non-finite; 0.03 ran 2000 steps. A caution above 0.03 where sand retains water, none at or below it or
    without retention."""
    d = tiny_coupled(retention=True)
    d["sand"]["absorption_rate"] = 0.05
    assert [c for c in _cautions(d) if "absorption_rate = 0.05" in c]
    d["sand"]["absorption_rate"] = 0.03
    assert not [c for c in _cautions(d) if "absorption_rate" in c]
    d = tiny_coupled(retention=False)
    d["sand"]["absorption_rate"] = 0.5
    assert not [c for c in _cautions(d) if "absorption_rate" in c]
    # given in seconds (sand.absorption_time): the caution names that key and the R_a it makes at this dt
    d = tiny_coupled(retention=True)
    d["sand"].pop("absorption_rate", None)
    dt = d["time"]["dt"]
    d["sand"]["absorption_time"] = dt / 0.05
    (c,) = [c for c in _cautions(d) if "absorption" in c]
    assert f"sand.absorption_time = {dt / 0.05:g} s" in c and "R_a = time.dt / absorption_time = 0.05" in c, c
    d["sand"]["absorption_time"] = dt / 0.029
    assert not [c for c in _cautions(d) if "absorption" in c]


def _with_dt(name: str, divide: float) -> Scene:
    d = Scene.load(ROOT / "examples" / f"{name}.toml").to_dict()
    d["time"]["dt"] = d["time"]["dt"] / divide
    return Scene.from_dict(d)


@pytest.mark.parametrize(
    "name,divide,bodies,lattice",
    [
        ("fig08_sand_densities_small", 2, ("bodies[1]", "bodies[2]", "bodies[3]"), "0.0051"),
        ("fig13_sand_drop_beaker_small", 2, ("bodies[2]",), "0.0088"),
        ("fig13_sand_drop_beaker_small", 4, ("bodies[2]",), "0.0044"),
    ],
)
def test_sand_falling_onto_water_at_a_small_time_step_is_named(name, divide, bodies, lattice):
    """Fig. 8's and Fig. 13's small variants at half (a quarter of) their time step, where their sand was measured
    to stay above the water or come back out of it (couplekit.cautions.sand_entry_caution): one caution naming the
    bodies, their lattice entry speed and the time step that brings it to the examples' 0.01; none at the file's
    time step (0.0102 and 0.0176)."""
    from couplekit.cautions import SAND_ENTRY_LATTICE_SPEED, sand_entry_caution, sand_entry_speeds

    scene = _with_dt(name, divide)
    (c,) = sand_entry_caution(scene)
    assert all(b in c for b in bodies) and f"lattice speed {lattice}" in c, c
    assert c in stability_cautions(scene)
    slowest = min(speed for _, _, speed in sand_entry_speeds(scene))
    assert f"time.dt >= {SAND_ENTRY_LATTICE_SPEED * scene.domain.dx / slowest:.3g} s" in c, c
    assert sand_entry_caution(_with_dt(name, 1)) == []


def test_the_pumping_slab_is_named_where_it_rises_and_not_where_it_sinks():
    """The caution agrees with tests/coupling/test_surface_pumping.py: its slab, 2 mm above the pool, meets the
    water at 0.198 m/s, lattice 0.0010 at Δt = 5e-5 s (it comes 22 mm out of the water: the strict xfail) and
    0.0115 at 5.8e-4 s (it sinks and floats: the control)."""
    from couplekit.cautions import sand_entry_caution

    sys.path.insert(0, str(ROOT / "tests" / "coupling"))
    from test_surface_pumping import _slab_scene

    (c,) = sand_entry_caution(Scene.from_dict(_slab_scene(5e-5)))
    assert "bodies[1]" in c and "lattice speed 0.00099" in c and "a fall of 0.002 m" in c, c
    assert sand_entry_caution(Scene.from_dict(_slab_scene(5.8e-4))) == []


def test_sand_that_does_not_fall_onto_water_gets_no_entry_caution():
    """Only sand released above a water body's top, under it along gravity: not sand resting on the floor under
    the water, not sand above dry floor beside the pool, not a single-phase fluid, not without gravity."""
    from couplekit.cautions import sand_entry_caution, sand_entry_speeds

    sys.path.insert(0, str(ROOT / "tests" / "coupling"))
    from test_surface_pumping import _slab_scene

    small_dt = 5e-5
    d = _slab_scene(small_dt)
    assert sand_entry_caution(Scene.from_dict(d))  # as built: cautioned
    on_floor = _slab_scene(small_dt)
    on_floor["bodies"][1]["geometry"] = {"type": "box", "min": [0.03, 0.03, 0.02], "max": [0.09, 0.09, 0.04]}
    beside = _slab_scene(small_dt)
    beside["bodies"][0]["geometry"] = {"type": "box", "min": [0, 0, 0], "max": [0.12, 0.02, 0.1]}
    one_phase = _slab_scene(small_dt)
    one_phase["fluid"] = {"phases": 1, "water_lattice_viscosity": 5e-4}
    one_phase["bodies"] = one_phase["bodies"][1:]
    no_gravity = _slab_scene(small_dt)
    no_gravity["domain"]["gravity"] = [0.0, 0.0, 0.0]
    for case in (on_floor, beside, one_phase, no_gravity):
        scene = Scene.from_dict(case)
        assert sand_entry_speeds(scene) == [] and sand_entry_caution(scene) == []
