"""The [stirring] swirl (paper 000 Fig. 11's tangential forcing), couplekit issue 6.

Validation: a stirred tank at rest spins up in the sense of the right-hand rule about the axis, and its
angular momentum about the axis grows at the torque T = Σ ρ_w φ a_θ r dV the force predicts (momentum is
conserved by the LBM until the swirl's shear reaches the walls). The velocity the solver reports after n
forced steps is the Guo-shifted u = (n − ½) a (n − 1 full kicks before the last collision plus half of the
last), so L(n) = (n − ½) T Δt, and after a forcing window of m steps L = m T Δt.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid.grid import Boundaries
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.scene import Scene
from couplekit.scene.forces import StirringForce
from couplekit.scene.schema import SceneError
from couplekit.simulation import Simulation

DX, DT, N = 0.005, 5e-4, 20  # 20³ cells of 5 mm; a 1 m/s² forcing is 5e-5 in lattice units
CENTER = (0.05, 0.05, 0.05)


def _tank(stirring: dict, phases: int = 1, water_top: float | None = None) -> dict:
    d = {
        "scene": {"name": "stirred_tank"},
        "domain": {"size": [N * DX] * 3, "dx": DX, "gravity": [0.0, 0.0, 0.0]},
        "time": {"dt": DT, "frame_duration": 10 * DT, "frames": 1},
        "fluid": {"phases": phases, "water_lattice_viscosity": 0.01, "air_lattice_viscosity": 0.01},
        "stirring": stirring,
        "outputs": {"preview": False},
    }
    if water_top is not None:
        d["bodies"] = [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [N * DX, N * DX, water_top]}}
        ]
        d["fluid"]["surface_tension"] = 0.0
    return d


def _angular_momentum(sim: Simulation, axis: np.ndarray, density: np.ndarray | None = None) -> np.ndarray:
    """L = Σ ρ (x − c) × u dV (SI, kg m²/s) of the fluid; ``density`` (kg/m³) replaces ρ (e.g. ε ρ)."""
    f = sim.fields()
    u = f["velocity"]  # m/s
    rho = f["density"] if density is None else density  # kg/m³
    nz, ny, nx = u.shape[1:]
    z, y, x = np.meshgrid(*((np.arange(n) + 0.5) * DX for n in (nz, ny, nx)), indexing="ij")
    rel = np.stack([x, y, z]) - np.asarray(CENTER)[:, None, None, None]
    return np.einsum("dzyx,zyx->d", np.cross(rel, u, axis=0), rho) * DX**3


def test_stirred_tank_spins_up_at_the_predicted_torque():
    """Single phase, walls all round, a = 2 m/s² at the rim of a cylinder of radius and half-length 6 cells
    about z through the centre. After 200 steps (u_rim = 2 m/s² × 0.1 s = 0.2 m/s, 0.02 lattice): L_z =
    (n − ½) T Δt within 1 % (the swirl's shear layer spreads √(ν n) ≈ 1.4 cells, the walls are 4 cells
    beyond the cylinder, so no momentum has left yet; measured 0.9999), L_x, L_y ≈ 0 (< 1e-3 L_z), and the
    sense is counter-clockwise seen from +z: u_y > 0 at x > centre. (With the cylinder through the whole
    height the no-slip floor and ceiling take momentum from the first step: measured 0.89 at step 200.)"""
    sim = Simulation(
        Scene.from_dict(_tank({"center": list(CENTER), "radius": 0.03, "length": 0.06, "acceleration": 2.0})),
        "cpu",
        log=None,
    )
    stir = StirringForce(sim.scene.stirring, sim.scene.domain, sim.units)
    torque = stir.torque(np.ones(sim.scene.domain.shape), 1000.0)
    # closed form of the continuum: ∫ ρ A r²/R 2π r dr h = ρ A π R³ h / 2 (the grid's staircase sum: within 3 %)
    assert abs(torque / (1000.0 * 2.0 * np.pi * 0.03**3 * 0.06 / 2) - 1) < 0.03
    # early-time profile at step 50: u_θ = A (r/R) t inside (row y = 9, z = 10, cells x = 11-13 at
    # r ≈ 1.6-3.5 cells), so u_y = A (x − c)/R t; within 3 % (measured ≤ 1 %; at step 200 the rim's jump has
    # diffused inwards and the cell at 3.5 cells is 13 % low, while L is conserved)
    sim.step(50)
    u = sim.fields()["velocity"]
    expect_u = 2.0 * (np.arange(11, 14) + 0.5 - 10.0) / 6.0 * (50 - 0.5) * DT
    np.testing.assert_allclose(u[1, 10, 9, 11:14], expect_u, rtol=0.03)
    assert u[1, 10, 10, 13] > 0 and u[1, 10, 10, 6] < 0 and u[0, 10, 13, 10] < 0
    n = 200
    sim.step(n - 50)
    L = _angular_momentum(sim, np.array([0, 0, 1.0]))
    expect = (n - 0.5) * torque * DT
    assert abs(L[2] / expect - 1) < 0.01, f"L_z / ((n - 1/2) T dt) = {L[2] / expect:.5f}"
    assert np.all(np.abs(L[:2]) < 1e-3 * L[2]), L


def test_stirring_about_another_axis_and_sign_and_window():
    """Axis along −x given as [−2, 0, 0] (any length), acceleration +1.5 m/s², forcing only for the first 100
    steps (duration = 100 Δt): L about +x is negative (counter-clockwise about −x), L_x = −100 T Δt within
    1 % after 150 steps (the forcing stopped: no half-step shift), L_y, L_z ≈ 0."""
    st = {
        "center": list(CENTER),
        "axis": [-2.0, 0.0, 0.0],
        "radius": 0.03,
        "length": 0.06,
        "acceleration": 1.5,
        "duration": 100 * DT,
    }
    sim = Simulation(Scene.from_dict(_tank(st)), "cpu", log=None)
    stir = StirringForce(sim.scene.stirring, sim.scene.domain, sim.units)
    assert stir.first_step == 0 and stir.last_step == 100
    torque = stir.torque(np.ones(sim.scene.domain.shape), 1000.0)
    sim.step(150)
    L = _angular_momentum(sim, np.array([-1.0, 0, 0]))
    assert abs(-L[0] / (100 * torque * DT) - 1) < 0.01, f"-L_x / (100 T dt) = {-L[0] / (100 * torque * DT):.5f}"
    assert np.all(np.abs(L[1:]) < 1e-3 * abs(L[0])), L


def test_stirring_acts_on_the_water_not_the_air():
    """Two phases at 1000:1.25 (800:1), water below z = 0.06 m, air above, σ = 0, the cylinder across the
    surface. The force density is ρ_w φ a: after the first step from rest every cell moves at exactly
    u = ½ ρ_w φ a / ρ(φ) (the Guo half kick; nothing else acts on a fluid at rest without gravity and
    surface tension), so water cells take ½ a and the air far above the surface (φ ~ 1e-4) a tenth of that
    or less. Tolerance 2e-3 of the water's speed: the rasterised cylinder's force is not discretely
    divergence-free at its staircase rim and ends, and the first pressure response moves cells by up to
    8e-4 of the kick (measured), also outside the cylinder. After 60 steps the total angular momentum is
    (n − ½) Σ ρ_w φ a_θ r dV Δt within 2 % (φ taken at the end: the interface diffuses little over the run;
    measured 1.001)."""
    st = {"center": list(CENTER), "radius": 0.03, "acceleration": 2.0}  # through the whole height
    sim = Simulation(Scene.from_dict(_tank(st, phases=2, water_top=0.03)), "cpu", log=None)
    stir = StirringForce(sim.scene.stirring, sim.scene.domain, sim.units)
    phi0 = np.clip(sim.fields()["phi"], 0, 1).astype(np.float64)
    sim.step(1)
    f = sim.fields()
    rho = sim.fluid.params.rho_l + (1 - sim.fluid.params.rho_l) * phi0
    expect = 0.5 * phi0 / rho * stir.acceleration * (DX / DT)  # m/s
    scale = np.abs(expect).max()
    np.testing.assert_allclose(f["velocity"], expect, rtol=0, atol=2e-3 * scale)
    # the air: a force on everything would kick each cell by ½ a; the air (φ < 1e-4) gets under a tenth of it
    air = (phi0 < 1e-4) & stir.inside
    kick = 0.5 * np.sqrt((stir.acceleration**2).sum(axis=0)) * (DX / DT)
    speed = np.sqrt((f["velocity"] ** 2).sum(axis=0))
    assert air.sum() > 500 and np.all(speed[air] < 0.1 * kick[air] + 2e-3 * scale)
    # angular momentum: the cylinder ends 4 cells from the floor and ceiling (no wall losses), across the
    # surface at z = 0.06 m
    st = {"center": list(CENTER), "radius": 0.03, "length": 0.06, "acceleration": 2.0}
    sim = Simulation(Scene.from_dict(_tank(st, phases=2, water_top=0.06)), "cpu", log=None)
    stir = StirringForce(sim.scene.stirring, sim.scene.domain, sim.units)
    sim.step(1)
    n = 60
    sim.step(n - 1)
    f = sim.fields()
    torque = stir.torque(np.clip(f["phi"], 0, 1), 1000.0)
    L = _angular_momentum(sim, np.array([0, 0, 1.0]))
    assert abs(L[2] / ((n - 0.5) * torque * DT) - 1) < 0.02, L[2] / ((n - 0.5) * torque * DT)


@pytest.mark.parametrize("backend_name", ["cpu", "numpy"])
def test_stirring_adds_to_the_force_input_and_leaves_it_alone(backend_name):
    """FluidSolver level, as in a coupled step: ``force`` holds a uniform F0 (standing in for the drag the
    coupler writes); the box is periodic, so momentum changes only by the forces. With the stirring attached,
    the fluid's momentum grows at F0 + Σ F_stir per step (the swirl has no net linear momentum: Σ F_stir = 0
    by symmetry, to float32 round-off) and its angular momentum at the stirring torque, while ``force`` itself
    still holds F0 afterwards (the stirring goes into a separate buffer, so the coupler's next overwrite of
    ``force`` loses nothing). Both backends."""
    backend = get_backend(backend_name)
    scene = Scene.from_dict(_tank({"center": list(CENTER), "radius": 0.03, "length": 0.06, "acceleration": 2.0}))
    stir = StirringForce(scene.stirring, scene.domain, scene.units())
    shape = scene.domain.shape
    solver = FluidSolver(backend, shape, FluidParams(nu_h=0.01, nu_l=0.01), Boundaries(), external_force=True)
    f0 = 1e-6
    solver.force[0][1:-1, 1:-1, 1:-1] = f0
    stir.attach(solver)
    n = 20
    solver.step(n)
    force = backend.to_host(solver.force)
    assert np.all(force[0][1:-1, 1:-1, 1:-1] == np.float32(f0)) and not force[1:].any()
    d = solver.diagnostics()
    cells = np.prod(shape)
    # periodic box: momentum_x = (n − ½) F0 × cells (the half kick of the last step), float32 round-off
    assert abs(d["momentum_x"] / ((n - 0.5) * f0 * cells) - 1) < 0.01, d["momentum_x"] / ((n - 0.5) * f0 * cells)
    a = stir.acceleration  # lattice
    u = backend.to_host(solver.velocity)[:, 1:-1, 1:-1, 1:-1].astype(np.float64)
    z, y, x = np.meshgrid(*((np.arange(k) + 0.5) for k in shape), indexing="ij")
    rel = np.stack([x, y, z]) - 10.0
    lz = (rel[0] * u[1] - rel[1] * u[0]).sum()
    tz = (rel[0] * a[1] - rel[1] * a[0]).sum()
    assert abs(lz / ((n - 0.5) * tz) - 1) < 0.01, lz / ((n - 0.5) * tz)


def test_stirring_scene_errors():
    """Refused with the key named: no [fluid]; a zero axis; a centre outside the domain; a non-positive
    radius; an unknown key."""
    d = _tank({"center": list(CENTER), "radius": 0.03, "acceleration": 2.0})
    del d["fluid"]
    d["bodies"] = [{"kind": "sand", "geometry": {"type": "box", "min": [0.02] * 3, "max": [0.04] * 3}}]
    with pytest.raises(SceneError) as e:
        Scene.from_dict(d)
    assert "stirring" in e.value.keys
    for bad, key in (
        ({"axis": [0.0, 0.0, 0.0]}, "stirring.axis"),
        ({"center": [0.05, 0.05, 0.2]}, "stirring.center"),
        ({"radius": 0.0}, "stirring.radius"),
        ({"omega": 1.0}, "stirring.omega"),
    ):
        st = {"center": list(CENTER), "radius": 0.03, "acceleration": 2.0, **bad}
        with pytest.raises(SceneError) as e:
            Scene.from_dict(_tank(st))
        assert key in e.value.keys, (key, e.value.keys)


def test_stirring_in_a_coupled_scene_adds_to_the_drag():
    """Coupled scene (two phases, a sand block resting on the floor of the stirred tank, drag and buoyancy
    on): the coupler rewrites ``force`` with the drag every step, and the stirring still spins the water up.
    The angular momentum of fluid + sand about the axis after 60 steps is (n − ½) T Δt of the water's
    torque within 5 % (the drag hands part of it to the sand, counted; the sand's pores hold water that
    the force also pushes, ε-weighted in T; buoyancy acts along z and has no torque about z; the 5 %
    covers the one-step lag of the drag's momentum exchange; measured 0.998, the sand holding 0.4 % of L).
    Had the drag overwritten the stirring, L would be ~0."""
    st = {"center": list(CENTER), "radius": 0.03, "length": 0.06, "acceleration": 2.0}
    d = _tank(st, phases=2, water_top=0.08)
    d["domain"]["gravity"] = [0.0, 0.0, -9.81]
    d["fluid"]["water_lattice_viscosity"] = 0.01
    d["sand"] = {"density": 1500.0, "youngs_modulus": 2e4, "particles_per_cell": 8}
    d["bodies"].append(
        {"kind": "sand", "geometry": {"type": "box", "min": [0.03, 0.03, 0.012], "max": [0.07, 0.07, 0.025]}}
    )
    sim = Simulation(Scene.from_dict(d), "cpu", log=None)
    assert sim.coupler is not None
    stir = StirringForce(sim.scene.stirring, sim.scene.domain, sim.units)
    n = 60
    sim.step(n)
    f = sim.fields()
    torque = stir.torque(np.clip(f["phi"], 0, 1) * f["fluid_fraction"], 1000.0)
    # fluid: ρ ε u (momentum of the fluid in the pores); sand: Σ m r × v
    rho = f["density"] * f["fluid_fraction"]
    L_fluid = _angular_momentum(sim, np.array([0, 0, 1.0]), density=rho)[2]
    p = sim.particles()
    rel = p["x"] - np.asarray(CENTER)[:, None]
    L_sand = float((p["mass"] * (rel[0] * p["v"][1] - rel[1] * p["v"][0])).sum())
    ratio = (L_fluid + L_sand) / ((n - 0.5) * torque * DT)
    assert abs(ratio - 1) < 0.05, f"(L_fluid + L_sand) / ((n - 1/2) T dt) = {ratio:.4f} (sand {L_sand:.3g})"


def test_stirred_restart_is_bitwise(tmp_path):
    """A checkpoint taken inside the forcing window (step 7 of 10) and resumed runs bitwise like the
    uninterrupted run, across the window's end (the forcing depends only on the fluid's step count and φ)."""
    st = {"center": list(CENTER), "radius": 0.03, "length": 0.06, "acceleration": 2.0, "duration": 10 * DT}
    scene = Scene.from_dict(_tank(st, phases=2, water_top=0.06))
    sim = Simulation(scene, "cpu", log=None)
    sim.step(7)
    path = sim.save(tmp_path / "stir.h5")
    sim.step(6)
    again = Simulation.load(path, backend="cpu", log=None)
    again.step(6)
    a, b = sim.fields(), again.fields()
    for k in ("velocity", "phi", "pressure"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert np.abs(a["velocity"]).max() > 0


@pytest.mark.parametrize(
    ("center_cells", "axis", "radius_cells", "length_cells", "stirs"),
    [
        ((5.0, 5.0, 5.0), (0, 0, 1), 0.5, None, False),  # the axis on cell corners: centres 0.71 cells away
        ((5.0, 5.0, 5.0), (0, 0, 1), 0.75, None, True),
        ((5.0, 5.0, 5.0), (0, 0, 1), 1.0, None, True),  # the fix the message gives
        ((5.5, 5.5, 5.0), (0, 0, 1), 0.1, None, True),  # the axis through cell centres
        ((5.0, 5.0, 5.0), (1, 1, 1), 0.2, None, True),  # the diagonal from a corner runs through cell centres
        ((5.0, 5.5, 5.0), (1, 0, 0), 0.4, None, False),  # 0.5 cells from the nearest centre row
        ((5.5, 5.5, 5.0), (0, 0, 1), 0.5, 0.5, False),  # on a cell row, but shorter than the gap between centres
    ],
)
def test_a_stirring_that_covers_no_cell_is_refused(center_cells, axis, radius_cells, length_cells, stirs):
    """A cylinder that holds no cell centre forces nothing (a probe found radius 2.5 mm at dx = 5 mm accepted,
    the water's angular momentum 3e-6 instead of 32.6): refused, naming stirring.radius and the one-cell fix;
    whether it is refused agrees with the cells StirringForce actually forces."""
    st = {
        "center": [c * DX for c in center_cells],
        "axis": list(axis),
        "radius": radius_cells * DX,
        "acceleration": 2.0,
    }
    if length_cells is not None:
        st["length"] = length_cells * DX
    d = _tank(st)
    if stirs:
        scene = Scene.from_dict(d)
        assert StirringForce(scene.stirring, scene.domain, scene.units()).inside.any()
    else:
        with pytest.raises(SceneError) as e:
            Scene.from_dict(d)
        assert "stirring.radius" in e.value.keys
        assert "holds no cell centre" in str(e.value)
