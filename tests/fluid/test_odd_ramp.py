"""The odd-rate floor ramped to the paper's rate 1 away from the walls (``FluidParams.odd_ramp``, issue 16).

couplekit.fluid.odd_ramp: r_o = r_floor + (1 − r_floor) s, s = ½ − ½ cos(π t), t = clip((d − ½) / D, 0, 1), d the
distance of a cell centre from the nearest boundary cell's face.

1. Geometry: the weights against that formula on flat walls (the distance is the distance to the nearest
   wall plane) at two box sizes and two ramp lengths; an obstacle is seen across a periodic face; the gap rule
   finds the narrowest run and nothing in wide boxes.
2. The kernel against the reference with random weights (the ramp's arithmetic), and the switches refused
   where they would be ignored.
3. Linear stability (the step linearised at rest, tests/fluid/test_wall_stability.py's bounce-back step): the
   gap rule's reason, a 5-cell box grows with the ramp (measured 1.0011, the floor everywhere 1.0000000); the
   slow tests: 8 × 8 and 12 × 12 boxes are stable (measured 1 − 2e-11, 1 − 5e-11 in
   benchmarks/results/odd_floor_ramp.json) and a 5-cell channel is not (1.00034).
4. Non-linear, on the kernels: the walled noise box decays and the still 800:1 tank stays at rest with the
   ramp, each at two sizes (what the floor everywhere does, test_wall_stability.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from fluid_states import BOUNDARY_SETS, chem_of, random_state
from test_wall_stability import _bounce_back_step, still_tank

from couplekit.backend import get_backend
from couplekit.fluid import KernelOps, ReferenceOps, from_stored, to_stored
from couplekit.fluid.grid import INTERIOR, Boundaries, build_flags
from couplekit.fluid.odd_ramp import MIN_GAP_CELLS, narrow_gap, ramp_weights
from couplekit.fluid.reference import equilibrium, odd_rate
from couplekit.fluid.solver import FluidParams, FluidSolver

LAMBDA = 0.015  # the scenes' floor


@pytest.fixture(scope="module")
def cpu():
    return get_backend("cpu", threads=1)


def _flags(shape, walls: str, solid=None):
    b = Boundaries.channel(walls)
    flags = build_flags(shape, b, solid)[0]
    return flags, tuple(b.face(a + "-").kind == "periodic" for a in "xyz")


def _cosine_ramp(shape, walls: str, D: float) -> np.ndarray:
    """The formula on the interior, from the distance to the nearest wall plane of the axes in ``walls``."""
    d = np.full(shape, np.inf)
    for axis, name in ((2, "x"), (1, "y"), (0, "z")):
        if name in walls:
            c = np.arange(shape[axis]) + 0.5
            view = [1, 1, 1]
            view[axis] = shape[axis]
            d = np.minimum(d, np.minimum(c, shape[axis] - c).reshape(view))
    t = np.clip((d - 0.5) / D, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * t)


# ------------------------------------------------------------------------------------------------- geometry
@pytest.mark.parametrize("shape", [(4, 12, 12), (9, 10, 17)])
@pytest.mark.parametrize("D", [2.0, 3.0, 4.5])
def test_weights_follow_the_cosine_ramp_from_flat_walls(shape, D):
    walls = "xy" if shape[0] == 4 else "xyz"
    flags, periodic = _flags(shape, walls)
    s = ramp_weights(flags, periodic, D)
    assert s.dtype == np.float32 and s.shape == flags.shape
    np.testing.assert_allclose(s[INTERIOR], _cosine_ramp(shape, walls, D), rtol=0, atol=1e-7)
    assert np.all(s[flags != 0] == 0.0)  # ghosts and walls carry no weight
    # the cells touching a wall keep the floor; rate 1 is reached where a cell is D + ½ from every wall
    assert s[1, 1, 5] == 0.0
    deepest = min(shape[2 - "xyz".index(a)] for a in walls) / 2
    assert bool((s[INTERIOR] > 1.0 - 1e-7).any()) == (deepest >= D + 0.5), (deepest, s.max())


def test_an_obstacle_is_seen_across_a_periodic_face():
    shape = (4, 12, 20)  # walls on y; x periodic; an obstacle in the first two x columns
    solid = np.zeros(shape, bool)
    solid[:, 5:7, 0:2] = True
    flags, periodic = _flags(shape, "y", solid)
    s = ramp_weights(flags, periodic, 3.0)[INTERIOR]
    # the last x column is the obstacle's neighbour through the periodic face: it touches it (s = 0), as does
    # the column right of it
    assert s[2, 5, 19] == 0.0 and s[2, 5, 2] == 0.0
    np.testing.assert_array_equal(s[:, 5, 18], s[:, 5, 3])  # the two sides alike
    assert s[2, 5, 10] > 0.99  # far from everything along the channel's middle


def test_gap_rule_finds_the_narrowest_run():
    flags, periodic = _flags((4, 12, 12), "xy")
    assert narrow_gap(flags, periodic) is None  # 12 cells between the walls
    assert narrow_gap(flags, periodic, below=13) == (12, "x", (0, 0, 0))
    flags, periodic = _flags((4, 12, 5), "xy")  # a 5-cell channel along x
    g = narrow_gap(flags, periodic)
    assert g is not None and g[:2] == (5, "x")
    # an obstacle 3 cells from a wall, and another across the periodic x face from a second one
    solid = np.zeros((4, 16, 20), bool)
    solid[:, 4:6, 8:12] = True  # y cells 0-3 below it: a 4-cell gap along y
    flags, periodic = _flags((4, 16, 20), "y", solid)
    assert narrow_gap(flags, periodic)[:2] == (4, "y")
    solid = np.zeros((4, 16, 20), bool)
    solid[:, 6:10, 0:2] = True
    solid[:, 6:10, 15:17] = True  # x cells 17, 18, 19 then the periodic face: a 3-cell gap across it
    flags, periodic = _flags((4, 16, 20), "y", solid)
    assert narrow_gap(flags, periodic)[:2] == (3, "x")


@pytest.mark.parametrize("width", [5, 7])
def test_solver_refuses_the_ramp_in_a_narrow_gap_and_says_how_to_fix_it(cpu, width):
    params = FluidParams(nu_h=1e-4, nu_l=1e-4, odd_lambda=LAMBDA, odd_ramp=3.0)
    with pytest.raises(ValueError, match=rf"{width} cells wide along x.*at least {MIN_GAP_CELLS}.*odd_ramp = 0"):
        FluidSolver(cpu, (4, 12, width), params, boundaries=Boundaries.channel("xy"))
    # 8 cells: accepted; and without the floor acting (ν ≥ 5e-4) the ramp is not built, so nothing is refused
    assert FluidSolver(cpu, (4, 12, 8), params, boundaries=Boundaries.channel("xy")).odd_ramp is not None
    high = FluidParams(nu_h=1e-3, nu_l=1e-3, odd_lambda=LAMBDA, odd_ramp=3.0)
    with pytest.warns(UserWarning, match="does nothing"):
        s = FluidSolver(cpu, (4, 12, width), high, boundaries=Boundaries.channel("xy"))
    assert s.odd_ramp is None and not s.ops.odd_ramp


def test_params_refuse_a_negative_ramp():
    with pytest.raises(ValueError, match="odd_ramp"):
        FluidParams(odd_ramp=-1.0)


# ------------------------------------------------------------------------------------------ kernel = reference
PARAMS = (1.0, 0.00125, 0.01, 0.05)  # rho_h, rho_l, nu_h, nu_l: with the floor 0.25, r_o = 0.11 / 0.38
GRAVITY = (1e-5, -2e-5, 3e-5)


@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("parity", [0, 1])
def test_collide_stream_with_ramp_matches_reference(kernel_backend, effects, parity):
    flags = {"les": True, "odd_rate": True, "odd_ramp": True}
    if effects == "all":
        flags.update(two_phase=True, surface_tension=True, mixture=True, external_force=True)
    ko, ro = KernelOps(kernel_backend, **flags), ReferenceOps(**flags)
    base = random_state(41 + parity, BOUNDARY_SETS["mixed"])
    noise = 1.0 + 0.05 * np.random.default_rng(7).standard_normal(base["f"].shape)
    base["f"] = to_stored(from_stored(base["f"]) * noise)
    ramp = np.random.default_rng(8).uniform(0.0, 1.0, base["flags"].shape).astype(np.float32)
    out = {}
    for name, ops, weights in (("kernel", ko, ramp), ("reference", ro, ramp), ("no ramp", ro, np.zeros_like(ramp))):
        s = {k: v.copy() for k, v in base.items()}
        ops.collide_stream(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["force"], s["pbar"], parity,
            *PARAMS, *GRAVITY, 0.1, 0.25, 1.0, chemical_potential=chem_of(ops, s), odd_ramp=weights,
        )  # fmt: skip
        out[name] = s
    state = (base["flags"] == 0) | (base["flags"] == 3)
    np.testing.assert_allclose(out["kernel"]["f"][:, state], out["reference"]["f"][:, state], rtol=0, atol=2e-6)
    np.testing.assert_allclose(out["kernel"]["velocity"], out["reference"]["velocity"], rtol=0, atol=2e-6)
    # the weights change the result (zero weights: the floor everywhere)
    assert np.abs(out["no ramp"]["f"][:, state] - out["reference"]["f"][:, state]).max() > 1e-4


@pytest.mark.parametrize("ops_class", ["kernel", "reference"])
def test_ramp_weights_need_their_build(kernel_backend, ops_class):
    make = (lambda **k: KernelOps(kernel_backend, **k)) if ops_class == "kernel" else (lambda **k: ReferenceOps(**k))
    with pytest.raises(ValueError, match="needs odd_rate=True"):
        make(odd_ramp=True)
    s = random_state(3, BOUNDARY_SETS["periodic"])
    args = (s["f"], s["flags"], s["velocity"], None, None, None, s["pbar"], 0, *PARAMS, *GRAVITY, 0.0, 0.25)
    ramp = np.ones(s["flags"].shape, np.float32)
    with pytest.raises(ValueError, match="odd_ramp weights"):
        make(odd_rate=True).collide_stream(*args, odd_ramp=ramp)  # would be ignored
    with pytest.raises(ValueError, match="odd_ramp weights"):
        make(odd_rate=True, odd_ramp=True).collide_stream(*args)  # missing


# --------------------------------------------------------------------------------------------------- linear
def _radius(shape, D: float) -> float:
    """Spectral radius of the step linearised at rest, walls on x and y, ν = 1e-4, the ramped floor."""
    from scipy.sparse.linalg import LinearOperator, eigs

    r_s = 1.0 / (3.0 * 1e-4 + 0.5)
    floor = float(odd_rate(r_s, LAMBDA))
    r_o = floor + (1.0 - floor) * _cosine_ramp(shape, "xy", D)
    step = _bounce_back_step(shape, "xy", 1e-4, LAMBDA, r_o)
    f0 = equilibrium(np.zeros((3, *shape)))
    base, h = step(f0), 1e-6

    def matvec(v):
        return ((step(f0 + h * np.asarray(v).real.reshape(f0.shape)) - base) / h).reshape(-1)

    op = LinearOperator((f0.size, f0.size), matvec=matvec, dtype=np.float64)
    vals = eigs(op, k=6, which="LM", return_eigenvectors=False, maxiter=5000, tol=1e-9, ncv=40)
    return float(np.abs(vals).max())


def test_a_ramp_in_a_five_cell_box_grows_which_is_why_narrow_gaps_are_refused():
    radius = _radius((4, 5, 5), 3.0)  # measured 1.0010996 (the paper's rate 1: 1.0070; the floor everywhere: 1)
    assert radius > 1.0005, radius


@pytest.mark.slow
@pytest.mark.parametrize("box", [(4, 8, 8), (4, 12, 12)])
def test_ramp_is_linearly_stable_with_walls_eight_and_more_cells_apart(box):
    radius = _radius(box, 3.0)
    assert radius <= 1.0 + 2e-5, radius  # the bound of test_wall_stability's cure (finite-difference Jacobian)


@pytest.mark.slow
def test_ramp_in_a_five_cell_channel_grows():
    assert _radius((4, 12, 5), 3.0) > 1.0001  # measured 1.00034


# ----------------------------------------------------------------------------------------------- non-linear
@pytest.mark.parametrize("shape", [(8, 24, 24), (8, 16, 16)])
def test_noise_in_walled_box_decays_with_the_ramp(cpu, shape):
    """test_wall_stability's 0.003-noise box with the ramp: the energy falls every 500 steps (the paper's
    collision grows it ×30 in 8 × 24 × 24, the floor everywhere decays it)."""
    v = (np.random.default_rng(0).standard_normal((3, *shape)) * 0.003).astype(np.float32)
    params = FluidParams(nu_h=1e-4, nu_l=1e-4, odd_lambda=LAMBDA, odd_ramp=3.0)
    solver = FluidSolver(cpu, shape, params, boundaries=Boundaries.channel("xy"), velocity=v)
    assert solver.ops.odd_ramp
    energy = []
    for _ in range(3):
        solver.step(500)
        energy.append(solver.diagnostics()["kinetic_energy"])
    assert np.all(np.isfinite(energy)) and np.all(np.diff(energy) < 0), energy


@pytest.mark.parametrize("n", [16, 24])
def test_still_800_to_1_tank_stays_at_rest_with_the_ramp(cpu, n):
    """test_wall_stability's still tank (ν_h = 1e-4, ν_l = 1e-2, gravity, hydrostatic start, Smagorinsky 0.1) with
    the ramp: max lattice speed < 2e-3 over 4000 steps (the NumPy prototype at 16³: 3.1e-4 to 6.8e-4; without
    the floor it blows up in the bottom corners)."""
    solver = still_tank(cpu, n, odd_ramp=3.0)
    assert solver.ops.odd_ramp
    top = 0.0
    for _ in range(8):
        solver.step(500)
        top = max(top, solver.diagnostics()["max_lattice_speed"])
    assert np.isfinite(top) and top < 2e-3, f"max lattice speed {top}"
