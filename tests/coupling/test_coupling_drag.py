"""Physics of the drag/buoyancy stage (paper 000 §4.3, notes/mpm-method.md §§3.2–3.5), on the cpu kernels
(the kernels equal the NumPy reference, test_coupling_kernels.py).

The sand grid update is mimicked by Eq. 29 without boundaries: v = (mv)/m + Δt g, with the drag impulse and
Δt × buoyancy already added to (mv) by the exchange, exactly what couplekit.sand's grid update does on nodes
away from walls and colliders.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from coupling_states import RHO_H, RHO_L, SHAPE, UNITS, grid_state, padded

from couplekit.coupling import CouplingParams, KernelOps, node_terminal_velocity
from couplekit.units import Units

F32 = float(np.finfo(np.float32).eps)


def _grid_update(m, mv, dt, g):
    """Eq. 29 on nodes with mass (no boundaries): the sand's grid velocity after all forces."""
    g = np.asarray(g, np.float64).reshape(3, 1, 1, 1)
    mm = m.astype(np.float64)
    has = mm > 0
    return np.where(has, mv.astype(np.float64) / np.where(has, mm, 1.0) + dt * g, 0.0)


def _exchange(ops, st, eps_fluid, units=UNITS, gravity=(0.0, 0.0, 0.0)):
    """The exchange, its sand fraction from the state's node volume (Eq. 25)."""
    mv = st["grid_mv"].copy()
    force = np.zeros((3, *eps_fluid.shape), np.float32)
    ops.drag_buoyancy(st["grid_m"], mv, force, st["u"], st["phi"], st["grid_vol"], eps_fluid, st["flags"], units,
                      gravity, RHO_H, RHO_L)  # fmt: skip
    return mv, force


def _fractions(ops, st, shape=SHAPE):
    """The porosity ε̃ (padded)."""
    ef = np.zeros(padded(shape), np.float32)
    ops.fractions(st["grid_vol"], st["phi"], None, None, ef, None, None, UNITS.dx, (True, True, False))
    return ef


@pytest.mark.parametrize("c_drag", [1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3])
def test_exchange_conserves_momentum_and_never_overshoots(cpu, c_drag):
    """Gravity off: Σ sand momentum + Σ fluid momentum is unchanged to float32 round-off, for drag
    coefficients over 6 orders of magnitude, and every node's slip u − v keeps its direction and shrinks.

    Round-off bound: the sand momentum is stored in float32 (mv + J rounds to ½ ulp of |mv| + |J|) and the
    fluid force is −J in float32; so |ΔP| ≤ 2 ε_32 Σ(|mv| + |J|) node by node — stated as that sum.
    """
    ops = KernelOps(cpu, CouplingParams(drag_coefficient=c_drag), two_phase=True)
    st = grid_state(np.random.default_rng(10), ops.params)
    ef = _fractions(ops, st)
    mv, force = _exchange(ops, st, ef)
    mscale, vscale = UNITS.rho * UNITS.dx**3, UNITS.dx / UNITS.dt
    sand = (mv.astype(np.float64) - st["grid_mv"]) / (mscale * vscale)  # lattice momentum gained by the sand
    fluid = force[:, 1:-1, 1:-1, 1:-1].astype(np.float64)  # lattice momentum gained by the fluid (Δt = 1)
    budget = 2 * F32 * (np.abs(st["grid_mv"]).astype(np.float64) / (mscale * vscale) + np.abs(sand)).sum()
    assert np.abs(sand).sum() > 0
    total = np.abs((sand + fluid).sum(axis=(1, 2, 3)))
    assert (total <= budget).all(), (total, budget)
    # slip before / after, per active node
    m = st["grid_m"].astype(np.float64)
    active = (m > 0) & (st["flags"][1:-1, 1:-1, 1:-1] == 0)
    rho = RHO_L + (RHO_H - RHO_L) * np.clip(st["phi"][1:-1, 1:-1, 1:-1].astype(np.float64), 0, 1)
    m_f = rho * ef[1:-1, 1:-1, 1:-1]
    u = st["u"][:, 1:-1, 1:-1, 1:-1].astype(np.float64)
    v0 = st["grid_mv"] / np.where(active, m, 1.0) / vscale
    v1 = mv / np.where(active, m, 1.0) / vscale
    r0 = (u - v0)[:, active]
    r1 = (u + fluid / m_f - v1)[:, active]
    along = (r0 * r1).sum(axis=0) / (r0 * r0).sum(axis=0)  # |r'|/|r*| when r' ∥ r*
    assert (along >= -1e-4).all(), f"slip reversed: min ratio {along.min()}"
    assert (along <= 1 + 1e-4).all(), f"slip grew: max ratio {along.max()}"
    if c_drag >= 1e2:
        assert np.median(along) < 0.5, "strong drag should remove most of the slip in one step"


def test_repeated_strong_exchange_relaxes_monotonically(cpu):
    """Air-light fluid, enormous drag (c = 1e3): 200 repeated exchanges drive each node to the common
    velocity P/M monotonically — the explicit update would explode here (Δt k ≫ 2)."""
    ops = KernelOps(cpu, CouplingParams(drag_coefficient=1e3), two_phase=True)
    st = grid_state(np.random.default_rng(11), ops.params)
    st["phi"][...] = 0.0  # air everywhere: m_f = ρ_l ε̃ tiny, the stiff case of notes §3.3
    ef = _fractions(ops, st)
    vscale = UNITS.dx / UNITS.dt
    mscale = UNITS.rho * UNITS.dx**3
    m = st["grid_m"].astype(np.float64)
    active = (m > 0) & (st["flags"][1:-1, 1:-1, 1:-1] == 0)
    m_s = m / mscale
    m_f = RHO_L * ef[1:-1, 1:-1, 1:-1].astype(np.float64)
    u = st["u"].copy()
    mv = st["grid_mv"].copy()
    slip = []
    for _ in range(200):
        force = np.zeros_like(u)
        ops.drag_buoyancy(st["grid_m"], mv, force, u, st["phi"], st["grid_vol"], ef, st["flags"], UNITS, (0, 0, 0),
                          RHO_H, RHO_L)  # fmt: skip
        u[:, 1:-1, 1:-1, 1:-1] += np.where(active, force[:, 1:-1, 1:-1, 1:-1] / m_f, 0.0).astype(np.float32)
        v = mv / np.where(active, m, 1.0) / vscale
        slip.append(np.linalg.norm((u[:, 1:-1, 1:-1, 1:-1] - v)[:, active], axis=0))
    slip = np.array(slip)
    assert np.isfinite(slip).all()
    assert (np.diff(slip, axis=0) <= 1e-6 + 1e-3 * slip[:-1]).all(), "slip must not grow"
    assert slip[-1].max() < 1e-2 * slip[0].max()
    # momentum is conserved through all 200 exchanges: v = P/M − (m_f/M)(u − v) node by node, with P the
    # initial momentum (tolerance: 1e-3 of the largest velocity, float32 accumulation over 200 updates)
    v = mv / np.where(active, m, 1.0) / vscale
    p0 = m_s * (st["grid_mv"] / np.where(active, m, 1.0) / vscale) + m_f * st["u"][:, 1:-1, 1:-1, 1:-1]
    big_m = m_s + m_f
    want = p0 / big_m - m_f / big_m * (u[:, 1:-1, 1:-1, 1:-1] - v)
    np.testing.assert_allclose(v[:, active], want[:, active], rtol=0, atol=1e-3 * np.abs(want[:, active]).max())


def _uniform_node_state(eps, sand_density, shape=(2, 2, 2), units=UNITS):
    cell = units.dx**3
    m = np.full(shape, sand_density * eps * cell, np.float32)
    return {
        "grid_vol": np.full(shape, eps * cell, np.float32),
        "grid_m": m,
        "grid_mv": np.zeros((3, *shape), np.float32),
        "phi": np.ones(padded(shape), np.float32),
        "u": np.zeros((3, *padded(shape)), np.float32),
        "flags": np.zeros(padded(shape), np.uint8),
    }


@pytest.mark.parametrize("sand_density", [600.0, 950.0, 1500.0, 2650.0])
def test_buoyancy_balances_hydrostatics(cpu, sand_density):
    """Resting suspension in still water: F_b = −V ε ∇p with the hydrostatic ∇p = ρ g (Eq. 31 is that
    force), so the sand node accelerates by exactly (1 − ρ/ϱ) g on its first step: neutral at ϱ = ρ,
    up for 600 and 950 kg/m³, down for 1500 and 2650 (paper Fig. 8).  Tolerance: float32 of the SI
    buoyancy and momentum (1e-5 relative to g Δt)."""
    ops = KernelOps(cpu, CouplingParams(), two_phase=True)
    eps = 0.4
    st = _uniform_node_state(eps, sand_density)
    ef = _fractions(ops, st, shape=(2, 2, 2))
    g = (0.0, 0.0, -9.81)
    mv, force = _exchange(ops, st, ef, gravity=g)
    rho_si = RHO_H * UNITS.rho
    grad_p = rho_si * np.asarray(g)  # hydrostatic pressure gradient ∇p = ρ g
    want = -(eps * UNITS.dx**3) * grad_p
    # the buoyancy alone: with a vanishing drag coefficient the exchange adds exactly Δt F_b to the momentum
    # (the state starts at rest, so mv − 0 = Δt F_b; float32 of one product)
    no_drag = KernelOps(cpu, CouplingParams(drag_coefficient=1e-30), two_phase=True)
    mv_b, force_b = _exchange(no_drag, st, ef, gravity=g)
    assert np.abs(force_b).max() < 1e-20, "buoyancy is not exchanged with the fluid (its reaction is the pressure)"
    f_b = mv_b.reshape(3, -1).T.astype(np.float64) / UNITS.dt
    np.testing.assert_allclose(f_b, np.broadcast_to(want, (8, 3)), rtol=1e-6, atol=1e-12)
    v = _grid_update(st["grid_m"], mv, UNITS.dt, g)
    accel = v[2] / UNITS.dt
    want_a = (1.0 - rho_si / sand_density) * g[2]
    # drag acts on the slip created within the step, so compare with the implicit first-step value
    assert np.allclose(accel, accel.flat[0])
    assert np.sign(accel.flat[0]) == np.sign(want_a)
    assert abs(accel.flat[0]) <= abs(want_a) * (1 + 1e-5), "drag can only slow the node, never push it further"


def test_neutral_sand_stays_at_rest(cpu):
    """ϱ = ρ: weight and buoyancy cancel, the slip is zero, the drag does nothing (v stays 0)."""
    ops = KernelOps(cpu, CouplingParams(), two_phase=False)
    st = _uniform_node_state(0.5, 1000.0)
    ef = _fractions(ops, st, shape=(2, 2, 2))
    g = (0.0, -9.81, 0.0)
    for _ in range(50):
        mv, force = _exchange(ops, st, ef, gravity=g)
        v = _grid_update(st["grid_m"], mv, UNITS.dt, g)
        st["grid_mv"] = (st["grid_m"] * v).astype(np.float32)
    assert np.abs(v).max() < 1e-6 * 9.81 * UNITS.dt * 50


SETTLE_CASES = [
    (1500.0, 0.05),
    (1500.0, 0.3),
    (1500.0, 0.6),
    (2650.0, 0.6),
    (2500.0, 0.64),
    (2000.0, 0.45),
    (600.0, 0.3),
    (950.0, 0.2),
]  # (sand density kg/m³, ε): sinking and rising (paper Fig. 8's 600, 950)
SETTLE_UNITS = Units(dx=0.005, dt=4e-4)  # a long step (lattice speeds stay < 0.01) so the test settles fast


def _settle(ops, cases, units):
    """Iterate the node update (fluid held at rest by its container) from rest, one node per case, for
    25 relaxation times of the slowest node (the transient is then below 1e-10 of the terminal speed)."""
    shape = (1, 1, len(cases))
    cell = units.dx**3
    density = np.array([c[0] for c in cases])[None, None, :]
    eps = np.array([c[1] for c in cases])[None, None, :]
    st = {
        "grid_vol": (eps * cell).astype(np.float32),
        "grid_m": (density * eps * cell).astype(np.float32),
        "grid_mv": np.zeros((3, *shape), np.float32),
        "phi": np.ones(padded(shape), np.float32),
        "u": np.zeros((3, *padded(shape)), np.float32),
        "flags": np.zeros(padded(shape), np.uint8),
    }
    ef = np.zeros(padded(shape), np.float32)
    ops.fractions(st["grid_vol"], st["phi"], None, None, ef, None, None, units.dx, (True, True, True))
    rho = RHO_H * units.rho
    g = (0.0, 0.0, -9.81)
    v_t = np.array([node_terminal_velocity(d, rho, 9.81, e, units.dx, ops.params) for d, e in cases])
    g_eff = np.abs(1.0 - rho / density.ravel()) * 9.81
    steps = int(25 * (v_t / (2 * g_eff)).max() / units.dt)  # relaxation time of quadratic drag: v_t / (2 g_eff)
    assert steps < 20000, steps
    for _ in range(steps):
        mv, _ = _exchange(ops, st, ef, units=units, gravity=g)
        v = _grid_update(st["grid_m"], mv, units.dt, g)
        st["grid_mv"] = (st["grid_m"] * v).astype(np.float32)
    return v[2].ravel(), v_t, g_eff


@pytest.mark.parametrize("grain", [None, 2e-4], ids=["ball_area", "grain_area"])
def test_terminal_velocity_matches_drag_gravity_buoyancy_balance(cpu1, grain):
    """Uniform suspension node: iterating the node update reaches the closed-form terminal slip
    v = sqrt(2 (ϱ − ρ) ε V g (1 − ε)^χ / (c ρ A)) (notes §3.2).

    With the fluid held at rest, the steady post-exchange slip equals the closed form exactly (derivation:
    J = −m_s Δt g_eff at steady state and J = μ(r* − r') give Δt β |r'|² = m_s Δt g_eff); the sand's own
    speed exceeds it by the fluid recoil m_s Δt g_eff / m_f that the container removes each step.  So
    |v| − m_s Δt g_eff/m_f must equal the closed form to 1e-4 (float32: the velocity is rebuilt from the
    float32 momentum every step, ~1e-7 relative, accumulated over the relaxation).  (The recoil is an
    artefact of holding the fluid; in the full solver the fluid's pressure takes it.  The issue's 5 %
    settling test with both solvers belongs to the scheduler.)
    Runs on one thread: thousands of tiny launches, where OpenMP barriers on a loaded 2-core machine
    cost more than the work.
    """
    params = CouplingParams(grain_diameter=grain)
    ops = KernelOps(cpu1, params, two_phase=False)
    vz, want, g_eff = _settle(ops, SETTLE_CASES, SETTLE_UNITS)
    rho = RHO_H * SETTLE_UNITS.rho
    density = np.array([c[0] for c in SETTLE_CASES])
    eps = np.array([c[1] for c in SETTLE_CASES])
    recoil = density * eps / (rho * (1 - eps)) * SETTLE_UNITS.dt * g_eff
    np.testing.assert_array_equal(np.sign(vz), np.where(density > rho, -1.0, 1.0))
    np.testing.assert_allclose(np.abs(vz) - recoil, want, rtol=1e-4)


def test_paper_drag_area_settling_depends_on_cell_size_grain_area_does_not(cpu1):
    """notes §3.2: with the paper's one-ball area the node settles like a sphere of diameter
    D = (6 ε dx³/π)^(1/3), so halving dx divides the settling speed by √2; with the grain area it does not
    change.  Reference value from the note's table: dx = 5 mm, ε = 0.3, ϱ = 1500 → 13.6 cm/s.
    Compared on the steady slip (sand speed minus the held fluid's recoil); tolerance 1 % on the ratios,
    well above the 1e-4 accuracy of each slip (previous test)."""
    assert abs(node_terminal_velocity(1500.0, 1000.0, 9.81, 0.3, 0.005) - 0.136) < 0.0006
    speeds = {}
    for grain in (None, 2e-4):
        ops = KernelOps(cpu1, CouplingParams(grain_diameter=grain), two_phase=False)
        for dx in (0.005, 0.0025):
            units = Units(dx=dx, dt=SETTLE_UNITS.dt * dx / SETTLE_UNITS.dx)  # same lattice velocity scale
            vz, _, g_eff = _settle(ops, [(1500.0, 0.3)], units)
            recoil = 1500.0 * 0.3 / (1000.0 * 0.7) * units.dt * g_eff[0]  # see the terminal-velocity test
            speeds[grain, dx] = abs(vz[0]) - recoil
    ball = speeds[None, 0.005] / speeds[None, 0.0025]
    grain = speeds[2e-4, 0.005] / speeds[2e-4, 0.0025]
    assert abs(ball - math.sqrt(2)) < 0.01 * math.sqrt(2), ball
    assert abs(grain - 1.0) < 0.01, grain
