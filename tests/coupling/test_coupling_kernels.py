"""Every coupling kernel against its NumPy reference on random but valid states (cpu and cpu-device
backends: the host and the CUDA code paths).

Tolerances: the kernels compute in float32, the reference in float64 on the same float32 inputs.
* fractions: a handful of flops per node (a min, a multiply, two additions) — rtol 1e-6, atol 1e-6
  (a few float32 ulps of O(1) fractions);
* drag/buoyancy: powf/sqrtf/cbrt-like chains of ~30 flops and a v* that subtracts nearly equal SI
  numbers, — rtol 2e-5 and an atol of 1e-5 × the largest magnitude of each output;
* source: a 26-neighbour gradient sum and a division by ε̃ ≥ 0.18 — atol 1e-6 × max|S| + 1e-7;
* particle scatter/gather: 27 float32 products per particle and up to ~40 particles per node — rtol 1e-5.
"""

from __future__ import annotations

import numpy as np
import pytest
from coupling_states import GRAVITY, RHO_H, RHO_L, SHAPE, UNITS, fluid_flags, grid_state, padded, particles

from couplekit.coupling import CouplingParams, KernelOps, ReferenceOps

VARIANTS = [(False, True), (True, True), (False, False), (True, False)]
IDS = [f"retention={r}-two_phase={t}" for r, t in VARIANTS]


@pytest.fixture(scope="module")
def cpu(kernel_backend):
    """cpu and cpu-device in turn: the host code paths (the tiled scatter, kernels/host_scatter.cuh) and the CUDA ones (atomics)."""
    return kernel_backend


def _pair(cpu, retention: bool, two_phase: bool, **kw):
    params = CouplingParams(retention=retention, **kw)
    return KernelOps(cpu, params, two_phase), ReferenceOps(params, two_phase)


def _fraction_outputs(shape=SHAPE):
    return {
        "eps_fluid": np.full(padded(shape), -7.0, np.float32),
        "d_bound": np.full(shape, -7.0, np.float32),
        "bound_out": np.full(shape, -7.0, np.float32),
    }


def _run_fractions(ops, st, periodic, shape=SHAPE):
    out = _fraction_outputs(shape)
    ops.fractions(
        st["grid_vol"], st["phi"], st["bound"], st["eps_prev"], out["eps_fluid"], out["d_bound"], out["bound_out"],
        UNITS.dx, periodic,
    )  # fmt: skip
    return out


@pytest.mark.parametrize("retention, two_phase", VARIANTS, ids=IDS)
@pytest.mark.parametrize("periodic", [(True, True, False), (False, True, True)], ids=["xy-periodic", "yz-periodic"])
def test_fractions_match_reference(cpu, retention, two_phase, periodic):
    kops, rops = _pair(cpu, retention, two_phase)
    st = grid_state(np.random.default_rng(1), kops.params)
    got, want = _run_fractions(kops, st, periodic), _run_fractions(rops, st, periodic)
    for key in ("eps_fluid",) + (("d_bound", "bound_out") if retention else ()):
        np.testing.assert_allclose(got[key], want[key], rtol=1e-6, atol=1e-6, err_msg=key)
    assert (got["eps_fluid"] != -7).all(), "ghost layer left unwritten"
    if not retention:  # ε̃ = 1 − ε, ε = min(ε_max, V_i / V_cell) (Eqs. 25, 33)
        eps = np.minimum(kops.params.eps_max, st["grid_vol"].astype(np.float64) / UNITS.dx**3)
        np.testing.assert_allclose(got["eps_fluid"][1:-1, 1:-1, 1:-1], 1.0 - eps, rtol=1e-6, atol=1e-6)


def _run_drag(ops, st, eps_fluid, dt=None):
    grid_mv = st["grid_mv"].copy()
    # garbage in the force array: it is output only (interior overwritten)
    force = (np.random.default_rng(7).uniform(-1e-4, 1e-4, (3, *padded()))).astype(np.float32)
    ops.drag_buoyancy(
        st["grid_m"], grid_mv, force, st["u"], st["phi"], st["grid_vol"], eps_fluid, st["flags"], UNITS,
        GRAVITY, RHO_H, RHO_L, dt,
    )  # fmt: skip
    return grid_mv, force


@pytest.mark.parametrize("two_phase", [True, False], ids=["two_phase", "single_phase"])
@pytest.mark.parametrize("grain", [None, 2e-4], ids=["ball_area", "grain_area"])
@pytest.mark.parametrize("c_drag", [0.39, 390.0])
def test_drag_buoyancy_matches_reference(cpu, two_phase, grain, c_drag):
    kops, rops = _pair(cpu, True, two_phase, grain_diameter=grain, drag_coefficient=c_drag)
    st = grid_state(np.random.default_rng(2), kops.params)
    fr = _run_fractions(rops, st, (True, True, False))
    for dt in (None, UNITS.dt / 4):
        got = _run_drag(kops, st, fr["eps_fluid"], dt)
        want = _run_drag(rops, st, fr["eps_fluid"], dt)
        for name, a, b in zip(("grid_mv", "force"), got, want, strict=True):
            np.testing.assert_allclose(a, b, rtol=2e-5, atol=1e-5 * float(np.abs(b).max()), err_msg=name)
        assert np.abs(want[1]).max() > 0 and np.abs(want[0] - st["grid_mv"]).max() > 0, "state exercises no exchange"


@pytest.mark.parametrize("retention", [False, True])
def test_phase_source_matches_reference(cpu, retention):
    kops, rops = _pair(cpu, retention, True)
    rng = np.random.default_rng(3)
    st = grid_state(rng, kops.params)
    fr = _run_fractions(rops, st, (True, False, True))
    eps_prev = (fr["eps_fluid"] + rng.uniform(-0.05, 0.05, fr["eps_fluid"].shape)).astype(np.float32)
    out = []
    for ops in (kops, rops):
        source = np.full(padded(), -7.0, np.float32)
        ops.phase_source(fr["eps_fluid"], eps_prev, st["phi"], st["u"], st["flags"], fr["d_bound"], source)
        out.append(source)
    np.testing.assert_allclose(out[0], out[1], rtol=0, atol=1e-6 * float(np.abs(out[1][1:-1, 1:-1, 1:-1]).max()) + 1e-7)
    ghosts = np.ones(padded(), bool)
    ghosts[1:-1, 1:-1, 1:-1] = False
    assert (out[0][ghosts] == -7).all(), "the source kernel must not touch ghost cells"
    assert (out[0][1:-1, 1:-1, 1:-1][st["flags"][1:-1, 1:-1, 1:-1] != 0] == 0).all()


def test_bound_water_p2g_matches_reference(cpu):
    kops, rops = _pair(cpu, True, True)
    pt = particles(np.random.default_rng(4), 3000)
    got = np.full(SHAPE, -7.0, np.float32)
    want = np.zeros(SHAPE, np.float32)
    kops.bound_water_p2g(pt["x"], pt["r"], pt["vol"], got, UNITS.dx)
    rops.bound_water_p2g(pt["x"], pt["r"], pt["vol"], want, UNITS.dx)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * float(want.max()))
    # Eq. 53 sums to the particles' bound water over the cell volume (partition of unity)
    total = float((pt["r"].astype(np.float64) * pt["vol"]).sum() / UNITS.dx**3)
    assert abs(float(got.astype(np.float64).sum()) - total) <= 1e-5 * total
    again = np.zeros(SHAPE, np.float32)
    kops.bound_water_p2g(pt["x"], pt["r"], pt["vol"], again, UNITS.dx)
    if cpu.name == "cpu":
        assert np.array_equal(again, got), "host scatter must be bitwise reproducible"
    else:  # the CUDA code paths (cpu-device, cuda) add with atomics: the order, so the round-off, is not fixed
        np.testing.assert_allclose(again, got, rtol=1e-5, atol=1e-6 * float(want.max()))


@pytest.mark.parametrize("retention, two_phase", VARIANTS, ids=IDS)
def test_particle_moisture_matches_reference(cpu, retention, two_phase):
    """The saturation gathers the water fraction R' + ε̃ φ (Eq. 59), which the kernel computes per node from
    the porosity, φ and R' (it is not stored)."""
    kops, rops = _pair(cpu, retention, two_phase)
    rng = np.random.default_rng(5)
    st = grid_state(rng, kops.params)
    pt = particles(rng, 2000)
    fr = _run_fractions(rops, st, (True, True, True))
    res = []
    for ops in (kops, rops):
        r = pt["r"].copy()
        sat = np.full(pt["r"].shape, -7.0, np.float32)
        ops.particle_moisture(
            pt["x"], r, sat, fr["eps_fluid"], st["phi"], fr["bound_out"], fr["d_bound"], st["grid_vol"], UNITS.dx
        )
        res.append((r, sat))
    np.testing.assert_allclose(res[0][1], res[1][1], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(res[0][0], res[1][0], rtol=1e-5, atol=1e-6)
    if not retention:
        assert np.array_equal(res[0][0], pt["r"]), "without retention the moisture ratio is not touched"
    # a particle at a node's centre (weights 1/8, 3/4, 1/8 per axis) reads that node's neighbourhood; one
    # whose stencil is uniform reads the water fraction itself: check the formula at a few nodes
    ph = np.clip(st["phi"][1:-1, 1:-1, 1:-1].astype(np.float64), 0, 1) if two_phase else 1.0
    wet = fr["eps_fluid"][1:-1, 1:-1, 1:-1].astype(np.float64) * ph
    if retention:
        wet = wet + fr["bound_out"]
    from couplekit.coupling.reference import water_fraction

    np.testing.assert_allclose(
        water_fraction(fr["eps_fluid"], st["phi"] if two_phase else None, fr["bound_out"] if retention else None),
        wet, rtol=1e-12,
    )  # fmt: skip


def test_sand_velocity_matches_reference(cpu):
    kops, rops = _pair(cpu, False, True)
    grid_v = np.random.default_rng(6).uniform(-0.3, 0.3, (3, *SHAPE)).astype(np.float32)
    out = []
    for ops in (kops, rops):
        sand_v = np.full((3, *padded()), -7.0, np.float32)
        ops.sand_velocity(grid_v, sand_v, UNITS, (True, False, True))
        out.append(sand_v)
    np.testing.assert_allclose(out[0], out[1], rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(out[0][:, :, :, 0], out[0][:, :, :, -2])  # periodic x ghost = image
    np.testing.assert_array_equal(out[0][:, :, 0, :], out[0][:, :, 1, :])  # wall y ghost = nearest node


# ------------------------------------------------------------------ per-body retention (masked capacity)
def _retentive_state(rng, st):
    """A retentive sand fraction between 0 and the node's unclamped sand fraction (some nodes all
    retentive, some none), as the P2G of per-particle flags gives it."""
    frac = st["grid_vol"].astype(np.float64) / UNITS.dx**3
    share = rng.choice([0.0, 1.0, 0.3, 0.7], size=frac.shape)
    return (frac * share).astype(np.float32)


@pytest.mark.parametrize("two_phase", [True, False], ids=["two_phase", "single_phase"])
def test_masked_fractions_match_reference(cpu, two_phase):
    """Per-body retention: capacity r_max min(ε, ε_r); same tolerance as the unmasked fractions."""
    kops, rops = _pair(cpu, True, two_phase)
    rng = np.random.default_rng(11)
    st = grid_state(rng, kops.params)
    ret = _retentive_state(rng, st)
    outs = []
    for ops in (kops, rops):
        out = _fraction_outputs()
        ops.fractions(
            st["grid_vol"], st["phi"], st["bound"], st["eps_prev"], out["eps_fluid"], out["d_bound"],
            out["bound_out"], UNITS.dx, (True, True, False), ret,
        )  # fmt: skip
        outs.append(out)
    for key in ("eps_fluid", "d_bound", "bound_out"):
        np.testing.assert_allclose(outs[0][key], outs[1][key], rtol=1e-6, atol=1e-6, err_msg=key)
    # nodes without retentive sand absorb nothing; elsewhere the bound water stays within the masked capacity
    none = ret == 0
    assert none.any() and (outs[0]["d_bound"][none] <= 0).all()
    eps = np.minimum(kops.params.eps_max, st["grid_vol"].astype(np.float64) / UNITS.dx**3)
    cap = kops.params.r_max * np.minimum(eps, ret)
    grew = outs[0]["d_bound"] > 0
    assert grew.any(), "state exercises no absorption"
    assert (outs[0]["bound_out"][grew] <= cap[grew] * (1 + 1e-6) + 1e-7).all()


def test_masked_particle_moisture_matches_reference(cpu):
    """Only retentive particles gain bound water, and Σ_p r_p V_p grows by V_cell Σ dR over the retentive
    sand (same tolerances as the unmasked gather)."""
    kops, rops = _pair(cpu, True, True)
    rng = np.random.default_rng(12)
    pt = particles(rng, 2000)
    retain = (rng.uniform(size=pt["r"].shape) < 0.5).astype(np.float32)
    st = grid_state(rng, kops.params)
    retentive = np.zeros(SHAPE, np.float32)
    rops.bound_water_p2g(pt["x"], retain, pt["vol"], retentive, UNITS.dx)
    fr = _run_fractions(rops, st, (True, True, True))
    # only nodes holding retentive sand absorb (the masked capacity); increments as Eq. 55 gives them, >= 0
    d_bound = np.where(retentive > 0, rng.uniform(0.0, 2e-3, SHAPE), 0.0).astype(np.float32)
    res = []
    for ops in (kops, rops):
        r = pt["r"].copy()
        sat = np.full(pt["r"].shape, -7.0, np.float32)
        ops.particle_moisture(
            pt["x"], r, sat, fr["eps_fluid"], st["phi"], fr["bound_out"], d_bound, st["grid_vol"], UNITS.dx,
            retentive, retain,
        )  # fmt: skip
        res.append((r, sat))
    np.testing.assert_allclose(res[0][1], res[1][1], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(res[0][0], res[1][0], rtol=1e-5, atol=1e-6)
    off = retain == 0
    assert np.array_equal(res[0][0][off], pt["r"][off]), "non-retentive particles gained bound water"
    gained = float(((res[1][0].astype(np.float64) - pt["r"]) * pt["vol"]).sum()) / UNITS.dx**3
    absorbed = float(d_bound.astype(np.float64).sum())
    assert absorbed > 0 and abs(gained - absorbed) <= 1e-5 * absorbed


# ------------------------------------------------------------------ Eq. 39's sand terms, folded into the kept sum
def _sand_terms_state(rng, shape, periodic, two_phase):
    """Random fluid fields on ``shape`` with walls on the non-periodic axes, the sand's grid velocity (SI) zero
    and ε = 1 in a slab of z (rows without sand: the host skips them), and a kept sum Σ (f − w)."""
    walls = "".join(a for a, p in zip("xyz", periodic, strict=True) if not p)
    flags = fluid_flags(rng, shape, walls=walls, obstacles=4)
    pad = padded(shape)
    eps = rng.uniform(0.35, 1.0, pad).astype(np.float32)
    grid_v = rng.uniform(-0.4, 0.4, (3, *shape)).astype(np.float32)
    grid_v[:, :2] = 0.0  # the first two z layers hold no sand ...
    eps[:4] = 1.0  # ... and no porosity change around them
    return {
        "flags": flags,
        "eps": eps,
        "grid_v": grid_v,
        "vel": rng.uniform(-0.05, 0.05, (3, *pad)).astype(np.float32),
        "phi": rng.uniform(-0.05, 1.05, pad).astype(np.float32) if two_phase else None,
        "slip": (rng.random(pad) < 0.7).astype(np.uint8),
        "fsum": rng.uniform(-1e-3, 1e-3, pad).astype(np.float32),
    }


@pytest.mark.parametrize("two_phase", [True, False], ids=["two_phase", "single_phase"])
@pytest.mark.parametrize(
    "shape, periodic",
    [(SHAPE, (True, False, True)), ((6, 9, 37), (True, True, False)), ((5, 4, 19), (False, True, True))],
    ids=["small-xz-periodic", "long-rows-xy-periodic", "yz-periodic"],
)
def test_pressure_sand_terms_match_reference_and_the_stored_path(cpu, two_phase, shape, periodic):
    """Eq. 39's sand terms folded into the kept population sum in two parts (kernels/coupling_pressure.cu): the
    fluid velocity's part of the slip term φ u·∇ε / ε (``pressure_slip_fluid``, written into every interior fluid
    cell, 0 in the sand-free rows) and the rest from the MPM grid velocity (``pressure_sand_terms``, subtracted;
    the sand-free rows unchanged), each against the reference (a 26-neighbour gradient divided by ε ≥ 0.35: atol
    1e-6 × the largest term + 1e-9), exactly unchanged outside the interior fluid cells; the two reference parts
    (each stored as float32) sum to the whole terms of a stored sand velocity (1e-6 × the largest); and the
    pressure update from the folded sum equals the update from the stored sand velocity (lbm_pressure.cu,
    use_fsum 2 against 1) to float32 round-off of the sum (rows long enough for the host's bulk and tail
    vectors)."""
    from couplekit.fluid.kernel_ops import KernelOps as FluidKernelOps
    from couplekit.fluid.reference import sand_pressure_terms

    rng = np.random.default_rng(21)
    st = _sand_terms_state(rng, shape, periodic, two_phase)
    kops, rops = _pair(cpu, False, two_phase)
    fluid = np.zeros(st["flags"].shape, bool)
    fluid[1:-1, 1:-1, 1:-1] = st["flags"][1:-1, 1:-1, 1:-1] == 0
    slip_parts, rest = [], []
    for ops in (kops, rops):
        held = st["fsum"].copy()
        ops.pressure_slip_fluid(st["flags"], st["vel"], st["phi"], st["eps"], st["slip"], held)
        slip_parts.append(held)
        fsum = st["fsum"].copy()
        ops.pressure_sand_terms(st["grid_v"], st["flags"], st["phi"], st["eps"], st["slip"], fsum, UNITS, periodic)
        rest.append(fsum)
    # the fluid velocity's part: written over every interior fluid cell, nothing else
    part_k, part_r = (np.where(fluid, h.astype(np.float64), 0.0) for h in slip_parts)
    assert np.abs(part_r).max() > 1e-4
    np.testing.assert_allclose(part_k, part_r, rtol=0, atol=1e-6 * np.abs(part_r).max() + 1e-9)
    assert slip_parts[0][~fluid].tobytes() == st["fsum"][~fluid].tobytes()
    assert not slip_parts[0][1:2][fluid[1:2]].any()  # z layer 0: ε = 1 around it, 0 written
    # the rest, from the MPM grid velocity
    terms_k = rest[0].astype(np.float64) - st["fsum"]
    terms_r = rest[1].astype(np.float64) - st["fsum"]
    assert np.abs(terms_r).max() > 1e-4  # the sand's terms are not negligible here
    np.testing.assert_allclose(terms_k, terms_r, rtol=0, atol=1e-6 * np.abs(terms_r).max() + 1e-9)
    assert rest[0][~fluid].tobytes() == st["fsum"][~fluid].tobytes()
    assert rest[0][1:2].tobytes() == st["fsum"][1:2].tobytes()  # z layer 0: no sand within a row of it
    # the two parts are the whole terms (reference, float64)
    sand_v = np.zeros((3, *padded(shape)), np.float32)
    kops.sand_velocity(st["grid_v"], sand_v, UNITS, periodic)
    whole = sand_pressure_terms(st["vel"], st["phi"], st["eps"], sand_v, st["slip"], st["flags"], two_phase)
    inner = fluid[1:-1, 1:-1, 1:-1]
    np.testing.assert_allclose(
        (part_r - terms_r)[1:-1, 1:-1, 1:-1][inner], whole[inner], rtol=0, atol=1e-6 * np.abs(whole).max()
    )
    # the pressure update: the folded sum (s0 - slip part - rest, as lbm_momentum and the second kernel form it)
    # against the stored sand velocity
    fops = FluidKernelOps(cpu, two_phase=two_phase, mixture=True, external_force=True)
    folded = ((st["fsum"] - slip_parts[0]).astype(np.float32) + (rest[0] - st["fsum"])).astype(np.float32)
    folded = np.where(fluid, folded, st["fsum"]).astype(np.float32)
    f = np.zeros((27, *padded(shape)), np.float32)
    p0 = rng.uniform(-1e-3, 1e-3, padded(shape)).astype(np.float32)
    ps = []
    for sv, fsum, fold in ((sand_v, st["fsum"].copy(), False), (None, folded, True)):
        p = p0.copy()
        fops.macro_pressure(
            f, st["flags"], st["vel"], st["phi"], st["eps"], sv, st["slip"], p, 0, 1.0, 0.00125, fsum=fsum,
            sand_in_fsum=fold,
        )  # fmt: skip
        ps.append(p)
    assert not np.array_equal(ps[0], p0)
    change = np.abs(ps[0].astype(np.float64) - p0).max()
    np.testing.assert_allclose(ps[1], ps[0], rtol=0, atol=1e-5 * change)
