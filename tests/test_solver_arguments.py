"""Arguments of the directly-driven solvers (FluidSolver, FluidParams, SandSolver, SandParams, SandFluidCoupler,
the schedulers) that are not what they should be are refused with a message naming them, instead of running
something else: a NaN CFL number or an infinite density once made the time-step limit NaN, so that no dt was
refused; NaN fluid parameters switched effects off or went non-finite at step 1; reversed densities skipped the
sharp-interface warning; ``step(2.9)`` took 2 steps and ``step(-1)`` none; a signed distance field passed as
``solid`` made every cell solid. Everything here runs on the NumPy reference backend (no kernel builds)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from couplekit.schedulers import LockstepScheduler

from couplekit.backend import get_backend
from couplekit.coupling import CouplingParams, SandFluidCoupler
from couplekit.fluid import Boundaries, FluidParams, FluidSolver
from couplekit.sand import SandParams, SandSolver, TimeStepError, seed_box
from couplekit.units import Units

NAN, INF = float("nan"), float("inf")
DX = 0.01
SAND_SHAPE = (8, 8, 8)
FLUID_SHAPE = (6, 6, 6)


@pytest.fixture(scope="module")
def be():
    return get_backend("numpy")


@pytest.fixture(scope="module")
def seeded():
    return seed_box([0.03] * 3, [0.05] * 3, DX, 8)


def _sand(be, seeded, **kw):
    args = dict(
        backend=be,
        shape=SAND_SHAPE,
        dx=DX,
        dt=1e-4,
        params=SandParams(youngs_modulus=1e5),
        positions=seeded.x,
        volumes=seeded.volume,
    )
    args.update(kw)
    return SandSolver(**args)


# ------------------------------------------------------------------------------------------------ SandParams
@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (dict(density=INF), "density must be a finite number, got inf"),
        (dict(density=NAN), "density must be a finite number, got nan"),
        (dict(youngs_modulus=INF), "youngs_modulus must be a finite number"),
        (dict(poisson_ratio=NAN), "poisson_ratio must be a finite number"),
        (dict(cohesion_max=NAN), "cohesion_max must be a finite number"),
        (dict(h0=NAN), "h0 must be a finite number"),
        (dict(h2=NAN), "h2 must be a finite number"),
        (dict(viscosity=INF), "viscosity must be a finite number"),
        (dict(density="1500"), r"density must be a finite number, got '1500' \(str\)"),
        (dict(density=True), r"density must be a finite number, got True \(bool\)"),
        (dict(h0=120.0, hardening=False), r"h0 = 120 degrees is the constant friction angle.*\(0, 90\)"),
        (
            dict(h0=-10.0),
            r"h0, h1, h2, h3 = -10, 9, 0.2, 10 make the friction angle .* range over \[-20, 3.26\] degrees.*\(0, 90\)",
        ),
    ],
)
def test_sand_params_refuse_non_finite_and_out_of_range_values(kw, match):
    with pytest.raises(ValueError, match="invalid SandParams: " + match):
        SandParams(**kw)


def test_sand_params_take_what_scenes_and_validations_use():
    SandParams()
    SandParams(hardening=False, h0=30.0, volume_correction=False)
    SandParams(density=np.float32(1500.0), youngs_modulus=np.int64(100000))
    SandParams(plasticity=False, h0=120.0)  # a purely elastic solid has no friction angle


# ------------------------------------------------------------------------------------------------ SandSolver
def test_nan_elastic_cfl_is_refused_instead_of_disabling_the_dt_limit(be, seeded):
    with pytest.raises(TimeStepError):  # the limit this solver has
        _sand(be, seeded, dt=0.05, velocities=[0.0, 0.0, -1.0])
    with pytest.raises(ValueError, match=r"elastic_cfl must be a finite number in \(0, 1\].*got nan"):
        _sand(be, seeded, dt=0.05, elastic_cfl=NAN, cfl_check_every=1)
    with pytest.raises(ValueError, match=r"cfl must be a finite number in \(0, 1\].*got nan"):
        _sand(be, seeded, dt=0.05, cfl=NAN, velocities=[0.0, 0.0, -1.0])
    s = _sand(be, seeded)
    assert math.isfinite(s.max_stable_dt()) and s.max_stable_dt() > 0


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (dict(cfl=0.0), r"cfl must be a finite number in \(0, 1\]"),
        (dict(cfl=-1.0), r"cfl must be a finite number in \(0, 1\]"),
        (dict(elastic_cfl=2.0), r"elastic_cfl must be a finite number in \(0, 1\]"),
        (dict(cfl_check_every=-5), "cfl_check_every must be 0 or more, got -5"),
        (dict(cfl_check_every=2.5), "cfl_check_every must be a whole number, got 2.5"),
        (dict(dx=INF), "dx must be a finite number > 0"),
        (dict(dx=NAN), "dx must be a finite number > 0"),
    ],
)
def test_sand_solver_refuses_bad_numbers(be, seeded, kw, match):
    with pytest.raises(ValueError, match=match):
        _sand(be, seeded, **kw)


@pytest.mark.parametrize("dt", [NAN, INF, 0.0])
def test_set_dt_refuses_what_is_not_a_time_step(be, seeded, dt):
    s = _sand(be, seeded)
    with pytest.raises(TimeStepError, match="dt must be a finite number > 0 s"):
        s.set_dt(dt)
    assert s.dt == 1e-4


def test_infinite_sand_density_is_refused(be, seeded):
    with pytest.raises(ValueError, match="density must be a finite number, got inf"):
        _sand(be, seeded, params=SandParams(density=INF))


def test_particle_arguments_name_the_argument_the_shape_and_the_expected_one(be, seeded):
    p = seeded.count
    with pytest.raises(ValueError, match=r"saturation must be in \[0, 1\].*got 5"):
        _sand(be, seeded, saturation=5.0)
    with pytest.raises(ValueError, match=r"saturation must be in \[0, 1\].*got -1"):
        _sand(be, seeded, saturation=-1.0)
    with pytest.raises(ValueError, match="saturation must be a finite number"):
        _sand(be, seeded, saturation=NAN)
    with pytest.raises(ValueError, match=r"volumes must be a finite number \(m³\), got nan"):
        _sand(be, seeded, volumes=NAN)
    with pytest.raises(
        ValueError, match=rf"volumes must be one number or one per particle, shape \({p},\), got shape \({p + 1},\)"
    ):
        _sand(be, seeded, volumes=np.full(p + 1, 1e-6))
    bad = np.full(p, 1e-6)
    bad[3] = np.inf
    with pytest.raises(ValueError, match=f"volumes must be finite .*1 of {p} values are not"):
        _sand(be, seeded, volumes=bad)
    with pytest.raises(
        ValueError, match=rf"velocities must be .* shape \(3, {p}\), got shape \({p}, 3\): transpose it"
    ):
        _sand(be, seeded, velocities=np.zeros((p, 3)))
    with pytest.raises(ValueError, match=r"velocities must be one 3-vector .*got shape \(2,\)"):
        _sand(be, seeded, velocities=[0.0, 1.0])
    with pytest.raises(ValueError, match="velocities must be finite"):
        _sand(be, seeded, velocities=[0.0, 0.0, NAN])
    with pytest.raises(ValueError, match=r"gravity must be 3 finite numbers .*got \(0, -9.81\)"):
        _sand(be, seeded, gravity=(0, -9.81))
    with pytest.raises(ValueError, match="gravity must be 3 finite numbers"):
        _sand(be, seeded, gravity=(0, 0, NAN))
    with pytest.raises(ValueError, match="densities must be a finite number"):
        _sand(be, seeded, densities=NAN)
    with pytest.raises(ValueError, match="densities must be > 0"):
        _sand(be, seeded, densities=-1500.0)
    with pytest.raises(TypeError, match="params must be a SandParams, got dict"):
        _sand(be, seeded, params={"density": 1500.0})


def test_particle_arguments_of_every_valid_form_are_taken(be, seeded):
    p = seeded.count
    s = _sand(
        be,
        seeded,
        volumes=np.full(p, seeded.volume),
        velocities=np.zeros((3, p)),
        saturation=np.full(p, 0.1),
        densities=1500.0,
        gravity=np.array([0.0, 0.0, -9.81]),
    )
    s.step(2)
    out = s.particles()
    assert np.isfinite(out["x"]).all() and np.isfinite(out["mass"]).all()
    assert _sand(be, seeded, velocities=(0.1, 0.0, -0.2)).particles()["v"][0] == pytest.approx(0.1)


def test_sand_solver_takes_a_backend_name(seeded):
    assert _sand("numpy", seeded).backend.name == "numpy"


# ------------------------------------------------------------------------------------------------ FluidParams
@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (dict(sigma=NAN), r"sigma must be a finite number in \[0, inf\)"),
        (dict(eta=NAN), r"eta must be a finite number in \[0, inf\)"),
        (dict(width=INF), r"width must be a finite number in \[2, inf\)"),
        (dict(width=0.5), r"width must be a finite number in \[2, inf\).*got 0.5"),
        (dict(rho_l=INF), r"rho_l must be a finite number in \(0, inf\)"),
        (dict(rho_h=NAN), r"rho_h must be a finite number in \(0, inf\)"),
        (dict(nu_h=NAN), r"nu_h must be a finite number in \(0, inf\)"),
        (dict(nu_l=INF), r"nu_l must be a finite number in \(0, inf\)"),
        (dict(nu_h="0.1"), r"nu_h must be a finite number .*got '0.1' \(str\)"),
        (dict(nu_h=True), r"nu_h must be a finite number .*got True \(bool\)"),
        (dict(mobility=INF), r"mobility must be a finite number in \(0, 1\]"),
        (dict(mobility=5.0), r"mobility must be a finite number in \(0, 1\]"),
        (dict(odd_lambda=NAN), r"odd_lambda must be a finite number in \[0, 1\]"),
        (dict(odd_nu_max=INF), "odd_nu_max must be a finite number"),
        (dict(odd_ramp=-1.0), r"odd_ramp must be a finite number in \[0, 64\]"),
        (dict(smagorinsky=NAN), r"smagorinsky must be a finite number in \[0, 1\]"),
        (dict(phase_trt_lambda=NAN), r"phase_trt_lambda must be a finite number in \[0, 1\]"),
        (dict(gravity=(0, 0, NAN)), "gravity must be 3 finite numbers"),
        (dict(gravity="abc"), "gravity must be 3 numbers .*got 'abc'"),
        (dict(gravity=(0, 0)), r"gravity must be 3 numbers .*got \(0, 0\)"),
        (dict(gravity=5), "gravity must be 3 numbers .*got 5"),
        (dict(gravity=(0, 0, "x")), "gravity must be 3 finite numbers"),
        (dict(store_filtered_pressure="yes"), "store_filtered_pressure must be True or False"),
    ],
)
def test_fluid_params_refuse_non_finite_and_nonsense_values(kw, match):
    with pytest.raises(ValueError, match="invalid FluidParams: " + match):
        FluidParams(**kw)


def test_fluid_params_list_every_problem_at_once():
    with pytest.raises(ValueError, match=r"sigma must .*; eta must .*; gravity must"):
        FluidParams(sigma=NAN, eta=NAN, gravity=(0, 0))


def test_fluid_params_refuse_reversed_densities():
    with pytest.raises(ValueError, match=r"rho_h = 0.00125 is below rho_l = 1: rho_h is the heavy phase.*Swap"):
        FluidParams(rho_h=1 / 800, rho_l=1.0)


def test_fluid_params_take_what_tests_scenes_and_examples_use():
    FluidParams()
    FluidParams.scene_defaults()
    FluidParams(rho_h=1.0, rho_l=1 / 800, nu_h=1e-4, nu_l=1e-2, width=3.0, sigma=1e-4, eta=2.0)
    FluidParams(width=8.0, mobility=0.04, odd_lambda=0.015, odd_ramp=3.0, smagorinsky=0.1, phase_trt_lambda=None)
    FluidParams(nu_h=np.float32(0.05), gravity=np.array([0.0, 0.0, -1e-5]), store_filtered_pressure=np.bool_(False))
    FluidParams(rho_h=2.0, rho_l=2.0, gravity=[0, 0, -1])  # equal densities (single phase), integer components


# ------------------------------------------------------------------------------------------------ FluidSolver
def test_fluid_solver_takes_a_backend_name():
    assert FluidSolver("numpy", FLUID_SHAPE, FluidParams()).backend.name == "numpy"


def test_fluid_solver_names_the_class_a_dict_should_be(be):
    with pytest.raises(TypeError, match="params must be a FluidParams, got dict"):
        FluidSolver(be, FLUID_SHAPE, {"nu_h": 0.1})
    with pytest.raises(TypeError, match=r"boundaries must be a Boundaries or None .*got dict.*Boundaries.channel"):
        FluidSolver(be, FLUID_SHAPE, FluidParams(), boundaries={"x_min": "wall"})


def test_fluid_solver_refuses_a_wrongly_shaped_pressure(be):
    with pytest.raises(ValueError, match=r"pressure must have the interior shape \(6, 6, 6\), got \(6, 5, 6\)"):
        FluidSolver(be, FLUID_SHAPE, FluidParams(), pressure=np.zeros((6, 5, 6)))
    with pytest.raises(ValueError, match=r"pressure must have the interior shape \(6, 6, 6\), got \(6, 6\)"):
        FluidSolver(be, FLUID_SHAPE, FluidParams(), pressure=np.zeros((6, 6)))  # once broadcast along z
    p = np.arange(216.0).reshape(FLUID_SHAPE)
    s = FluidSolver(be, FLUID_SHAPE, FluidParams(), pressure=p)
    np.testing.assert_array_equal(s.fields()["pressure"], p.astype(np.float32))


def test_fluid_solver_refuses_a_distance_field_as_solid_mask(be):
    sdf = np.full(FLUID_SHAPE, 0.3)  # outside every obstacle: no cell is solid
    with pytest.raises(ValueError, match=r"solid must be a boolean mask .*not all 0 or 1: .*solid=sdf < 0"):
        FluidSolver(be, FLUID_SHAPE, FluidParams(), solid=sdf)
    with pytest.raises(ValueError, match=r"solid must be a boolean mask of the interior shape \(6, 6, 6\)"):
        FluidSolver(be, FLUID_SHAPE, FluidParams(), solid=np.zeros((6, 6, 5), bool))
    mask = np.zeros(FLUID_SHAPE, bool)
    mask[:2] = True
    for given in (mask, mask.astype(np.uint8), mask.astype(float), sdf < 0):
        s = FluidSolver(be, FLUID_SHAPE, FluidParams(), solid=given)
        np.testing.assert_array_equal(s.fields()["solid"], np.asarray(given, bool))


# ------------------------------------------------------------------------------------------------ step counts
BAD_COUNTS = [
    (-1, ValueError, "n must be 0 or more, got -1"),
    (2.9, ValueError, "n must be a whole number, got 2.9"),
    (NAN, ValueError, "n must be a whole number"),
    ("3", TypeError, r"n must be a whole number of steps, got '3' \(str\)"),
    (True, TypeError, r"n must be a whole number of steps, got True \(bool\)"),
    (None, TypeError, "n must be a whole number of steps"),
]


@pytest.fixture(scope="module")
def coupled(be):
    """A sand block in a closed box of water (numpy reference ops), and its coupler."""
    shape, units = (10, 8, 8), Units(dx=0.005, dt=1e-4)
    g = units.to_lattice(-9.81, "acceleration")
    fluid = FluidSolver(
        be,
        shape,
        FluidParams(nu_h=0.1, gravity=(0, 0, g)),
        boundaries=Boundaries.channel("xyz"),
        mixture=True,
        external_force=True,
    )
    body = seed_box([0.015, 0.015, 0.02], [0.025, 0.025, 0.03], units.dx, 1)
    sand = SandSolver(be, shape, units.dx, units.dt, SandParams(density=1500, youngs_modulus=1e5), body.x, body.volume)
    return sand, fluid, SandFluidCoupler(sand, fluid, units, CouplingParams())


@pytest.mark.parametrize(("n", "error", "match"), BAD_COUNTS)
def test_solver_steps_refuse_what_is_not_a_count(be, seeded, coupled, n, error, match):
    fluid = FluidSolver(be, FLUID_SHAPE, FluidParams())
    sand = _sand(be, seeded)
    c_sand, c_fluid, coupler = coupled
    scheduler = LockstepScheduler(None, sand, None, timing=False)
    for step in (fluid.step, sand.step, coupler.step, scheduler.step):
        before = (fluid.step_count, sand.steps, sand.time, c_fluid.step_count, c_sand.steps)
        with pytest.raises(error, match=match):
            step(n)
        assert (fluid.step_count, sand.steps, sand.time, c_fluid.step_count, c_sand.steps) == before


def test_solver_steps_take_whole_numbers_of_any_kind(be, seeded, coupled):
    fluid = FluidSolver(be, FLUID_SHAPE, FluidParams())
    sand = _sand(be, seeded)
    c_sand, c_fluid, coupler = coupled
    for n in (0, np.int64(2), 1.0):
        fluid.step(n)
        sand.step(n)
    assert fluid.step_count == 3 and sand.steps == 3
    start = c_fluid.step_count
    coupler.step(0)
    coupler.step(np.int64(1))
    coupler.step(1.0)
    assert c_fluid.step_count == start + 2
    LockstepScheduler(None, sand, None, timing=False).step(np.int64(1))
    assert sand.steps == 4
