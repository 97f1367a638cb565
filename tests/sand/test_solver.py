"""SandSolver: free fall, the time-step limit, seeding, bitwise determinism and restart on the cpu
backend, and a small-amplitude elastic bar against its analytic period."""

from __future__ import annotations

import math

import numpy as np
import pytest

from couplekit.sand import DomainWalls, SandParams
from couplekit.sand.seeding import combine, seed_box, seed_sdf, seed_sphere
from couplekit.sand.solver import SandSolver, TimeStepError


@pytest.mark.parametrize("seed", range(6))
def test_free_fall_is_exact(cpu, seed):
    """A sand block in free fall: every node with mass gets v + g dt, so with symplectic Euler
    v_n = v0 + n g dt and z_n = z0 + v0 n dt + g dt^2 n(n+1)/2 exactly; F stays I (no stress).  Six
    jittered seedings (the jitter moves every particle's stencil, so each seed rounds differently).

    Tolerances are float32 round-off over n = 100 steps, u = 2^-24 = 6e-8 the unit round-off:
    * velocity: every step stores v + g dt rounded (at least u |v| each, the rest of the step's roundings
      — mv/m, the 27-term gather, the APIC term — cancel to first order since the weights sum to one and C
      is round-off sized), so the error grows at most linearly, n u |v| = 6.0e-6 |v|.  Measured
      1.5-2.1e-6 |v| over eight seeds (it was 2.4e-5 before the SVD skipped round-off-level rotations).
    * position: x += dt v rounds to half an ulp of x (x < 0.5 m: ulp 3e-8 -> 1.5e-8 per step) plus the
      integrated velocity error (n dt * 6e-6 |v| ~ 4e-9 m): <= 1.6e-6 m over n steps (measured 7e-7).
    * F: I + dt C F with C of O(u |v| / dx) and the return mapping's rebuild U diag(s) V^T round F by a few
      ulp(1) = 1.2e-7 per step without a systematic drift (F returns to the same fixed point, I): bound
      2e-6, 17 ulp (measured 3.1-4.3e-7 over eight seeds)."""
    dx, dt, n = 0.01, 2e-4, 100
    u = 2.0**-24
    body = seed_box((0.12, 0.12, 0.20), (0.20, 0.20, 0.28), dx, ppc=2, jitter=0.5, seed=seed)
    v0 = np.array([0.3, -0.2, 0.5])
    sol = SandSolver(cpu, (40, 32, 32), dx, dt, SandParams(), body.x, body.volume, velocities=v0)
    z0 = sol.particles()["x"].astype(np.float64)
    sol.step(n)
    out = sol.particles()
    g = np.array([0.0, 0.0, -9.81])
    v_exact = v0 + n * g * dt
    x_exact = z0 + (v0 * n * dt + g * dt**2 * n * (n + 1) / 2)[:, None]
    assert np.max(np.abs(out["v"] - v_exact[:, None])) <= n * u * np.abs(v_exact).max()
    assert np.max(np.abs(out["x"] - x_exact)) <= 1.6e-6
    assert np.max(np.abs(out["F"] - np.eye(3).reshape(9, 1))) < 2e-6
    d = sol.diagnostics()
    assert d["mass"] == pytest.approx(body.volume.sum() * 2200.0, rel=1e-6)
    assert d["momentum_z"] == pytest.approx(d["mass"] * v_exact[2], rel=1e-5)


def test_time_step_limit_refused_with_message(cpu):
    params = SandParams(youngs_modulus=1e6, poisson_ratio=0.3, density=2500.0)
    body = seed_box((0.05, 0.05, 0.05), (0.08, 0.08, 0.08), 0.01, ppc=1)
    dx = 0.01
    c_p = math.sqrt((params.lam + 2 * params.mu) / params.density)
    assert c_p == pytest.approx(23.2, abs=0.05)  # notes Sec. 4 table (GIC parameters)
    limit = 0.5 * dx / c_p
    with pytest.raises(TimeStepError, match=f"{limit:.4g}"):
        SandSolver(cpu, (16, 16, 16), dx, 1.01 * limit, params, body.x, body.volume)
    sol = SandSolver(cpu, (16, 16, 16), dx, 0.99 * limit, params, body.x, body.volume)
    assert sol.max_stable_dt() == pytest.approx(limit)
    # a fast body tightens the limit to the particle CFL
    fast = SandSolver(cpu, (16, 16, 16), dx, 1e-5, params, body.x, body.volume, velocities=(0, 0, 100.0))
    assert fast.max_stable_dt() == pytest.approx(0.5 * dx / 100.0, rel=1e-6)
    with pytest.raises(TimeStepError):
        fast.set_dt(1e-4)


def test_seeding_volumes_and_shapes():
    dx = 0.01
    box = seed_box((0.0, 0.0, 0.0), (0.1, 0.05, 0.02), dx, ppc=2)
    assert box.count == 20 * 10 * 4
    assert box.volume.sum() == pytest.approx(0.1 * 0.05 * 0.02)
    ball = seed_sphere((0.5, 0.5, 0.5), 0.1, dx, ppc=2)
    assert ball.volume.sum() == pytest.approx(4 / 3 * math.pi * 0.1**3, rel=0.02)
    assert np.all(np.linalg.norm(ball.x - 0.5, axis=0) < 0.1)
    shell = seed_sdf(lambda p: np.abs(np.linalg.norm(p - 0.5, axis=1) - 0.08) - 0.01, (0.4,) * 3, (0.6,) * 3, dx)
    r = np.linalg.norm(shell.x - 0.5, axis=0)
    assert shell.count > 0 and np.all((r > 0.07) & (r < 0.09))
    jit = seed_box((0.0, 0.0, 0.0), (0.1, 0.05, 0.02), dx, ppc=2, jitter=1.0, seed=3)
    assert np.max(np.abs(jit.x - box.x)) <= 0.5 * dx / 2 + 1e-12 and np.any(jit.x != box.x)
    assert combine(box, ball).count == box.count + ball.count


def _collapse(cpu, **kw):
    dx = 0.01
    # 12 288 particles: above MPM_SERIAL_PARTICLES, so the multi-threaded private-grid P2G is exercised
    body = seed_box((0.03, 0.03, 0.02), (0.19, 0.11, 0.14), dx, ppc=2, jitter=0.5, seed=1)
    assert body.count > 8192
    walls = DomainWalls.uniform("separate", 0.5)
    return SandSolver(cpu, (20, 14, 40), dx, 1.5e-4, SandParams(), body.x, body.volume, walls=walls, **kw)


def test_cpu_run_is_bitwise_deterministic_and_restartable(cpu):
    """Issue 6 needs a resumed run to equal an uninterrupted one bit for bit on the cpu backend: the
    host P2G sums each node in one order for any thread count (kernels/host_scatter.cuh), everything else is
    per particle or per node."""
    a = _collapse(cpu)
    a.step(25)
    mid = a.state()
    a.step(25)
    b = _collapse(cpu)
    b.step(50)
    c = _collapse(cpu)
    c.load_state(mid)
    c.step(25)
    pa, pb, pc = a.particles(), b.particles(), c.particles()
    assert pa["v"].std() > 0.0  # the sand did move
    for k in ("x", "v", "C", "F", "tau", "q", "vc"):
        assert np.array_equal(pa[k], pb[k]), k
        assert np.array_equal(pa[k], pc[k]), k
    assert a.time == c.time and a.steps == c.steps


def test_elastic_bar_period(cpu):
    """Free-free bar, first axial mode: u(x, t) = A cos(pi x / L) cos(omega t), omega = pi c / L with the
    bar speed c = sqrt(E / rho); with nu = 0 (lambda = 0) there is no lateral coupling, so this 1D result
    holds for the 3D bar.  Started from v = v0 cos(pi x / L) (v0 = 1e-4 c: small amplitude, elastic),
    the momentum of the left half, sum m v over x < L/2, is proportional to cos(omega t + phase); its
    zero crossings give the period.  Issue 4 asks for the analytic period within 5 %."""
    dx = 0.01
    L = 0.32
    params = SandParams(plasticity=False, youngs_modulus=1e5, poisson_ratio=0.0, density=1000.0)
    c = math.sqrt(params.youngs_modulus / params.density)
    period = 2 * L / c
    x0 = 0.04
    body = seed_box((x0, 0.04, 0.04), (x0 + L, 0.08, 0.08), dx, ppc=2)
    v0 = 1e-4 * c
    vel = np.zeros_like(body.x)
    vel[0] = v0 * np.cos(math.pi * (body.x[0] - x0) / L)
    dt = 0.3 * dx / c
    sol = SandSolver(cpu, (12, 12, 40), dx, dt, params, body.x, body.volume, velocities=vel, gravity=(0.0, 0.0, 0.0))
    left = body.x[0] < x0 + L / 2
    m = sol.particles()["mass"]
    nsteps = int(1.6 * period / dt)
    signal = np.empty(nsteps)
    for k in range(nsteps):
        sol.step()
        signal[k] = np.sum(m[left] * sol.v[0][left], dtype=np.float64)
    t = dt * np.arange(1, nsteps + 1)
    s = np.sign(signal)
    idx = np.nonzero(s[1:] != s[:-1])[0]
    crossings = t[idx] - signal[idx] * dt / (signal[idx + 1] - signal[idx])  # linear interpolation
    assert len(crossings) >= 3
    measured = 2 * np.mean(np.diff(crossings))
    assert measured == pytest.approx(period, rel=0.05)


def test_numpy_backend_runs_the_reference_and_agrees(cpu):
    """The same solver code path on the numpy backend (ReferenceOps) and on the cpu backend (kernels):
    10 steps of a falling block hitting the floor (99 % of it yields) agree to float32 round-off growth:
    1e-6 m in x, 1e-4 m/s in v (|v| ~ 1 m/s) and 1e-4 in F (measured 2e-8, 1.8e-5, 1.3e-5)."""
    dx = 0.01
    body = seed_box((0.04, 0.04, 0.025), (0.10, 0.08, 0.09), dx, ppc=2, jitter=0.5, seed=5)
    kw = dict(velocities=(0.3, 0.0, -1.0), walls=DomainWalls.uniform("separate", 0.5))
    a = SandSolver(cpu, (12, 12, 16), dx, 1e-4, SandParams(), body.x, body.volume, **kw)
    b = SandSolver("numpy", (12, 12, 16), dx, 1e-4, SandParams(), body.x, body.volume, **kw)
    assert b.ops.name == "numpy"
    a.step(10)
    b.step(10)
    pa, pb = a.particles(), b.particles()
    assert np.max(np.abs(pa["x"] - pb["x"])) < 1e-6
    assert np.max(np.abs(pa["v"] - pb["v"])) < 1e-4
    assert np.max(np.abs(pa["F"] - pb["F"])) < 1e-4


def test_moving_colliders_push_the_sand(cpu):
    """A sticky box moving at 0.5 m/s through resting sand drags the sand it covers along at its speed,
    its centre advances by v t, and an SDF collider (a static floor bump given as a callable) is sampled
    on the nodes and holds the sand above it (separating: no sand node inside it moves inward)."""
    from couplekit.sand import Collider, SdfCollider

    dx = 0.01
    body = seed_box((0.03, 0.03, 0.02), (0.17, 0.09, 0.07), dx, ppc=2)
    plow = Collider("box", (0.06, 0.06, 0.05), (0.01, 0.04, 0.03), "sticky", velocity=(0.5, 0.0, 0.0))
    bump = SdfCollider(lambda p, t: np.linalg.norm(p - [0.14, 0.06, 0.0], axis=1) - 0.04, "separate", 0.5)
    sol = SandSolver(
        cpu, (12, 12, 20), dx, 2e-4, SandParams(), body.x, body.volume, colliders=[plow], sdf_collider=bump
    )
    sol.step(50)
    assert plow.centre[0] == pytest.approx(0.06 + 0.5 * 50 * 2e-4)
    f = sol.fields()
    pos = sol.backend.to_host(sol._colliders)[4:7]
    assert pos[0] == pytest.approx(plow.centre[0], rel=1e-6)
    # nodes with sand inside the plow move with it
    z, y, x = np.meshgrid(*(np.arange(n) for n in (12, 12, 20)), indexing="ij")
    px, py, pz = (x + 0.5) * dx, (y + 0.5) * dx, (z + 0.5) * dx
    inside = (
        (np.abs(px - plow.centre[0] + 0.5 * 2e-4) < 0.009)
        & (np.abs(py - 0.06) < 0.03)
        & (np.abs(pz - 0.05) < 0.02)
        & (f["mass"] > 0)
    )
    assert inside.sum() > 10
    assert np.allclose(f["velocity"][0][inside], 0.5, atol=1e-5)
    # inside the SDF bump no sand node moves into the solid: v . n >= 0 with n the normal the kernel uses,
    # the central difference of the sampled SDF (float32 round-off: 1e-6 m/s)
    pts = np.stack([px, py, pz], axis=-1)
    d = np.linalg.norm(pts - [0.14, 0.06, 0.0], axis=-1)
    phi = (d - 0.04).astype(np.float32).astype(np.float64)
    grad = np.stack([np.gradient(phi, axis=2), np.gradient(phi, axis=1), np.gradient(phi, axis=0)])
    n = grad / np.linalg.norm(grad, axis=0)
    vn = (n * f["velocity"]).sum(axis=0)
    sel = (phi <= 0) & (f["mass"] > 0) & (x > 0) & (x < 19) & (y > 0) & (y < 11) & (z > 0) & (z < 11)
    assert sel.sum() > 10 and np.all(vn[sel] >= -1e-6)


def test_moving_sdf_collider_is_resampled_until_it_comes_to_rest(cpu):
    """SdfCollider(moving=True, moving_until=T): sampled at construction and after every step while the last
    sample was taken before T, once at or after T (the state at rest), then never again; without
    ``moving_until`` every step. The wall at x = 0.05 m is removed at T (the container of
    ``bodies[].container_until``): after T the sampled SDF is the one without it."""
    from couplekit.sand import SdfCollider

    dx, dt, until = 0.01, 2e-4, 5.5 * 2e-4
    calls: list[float] = []

    def wall(p, t):
        calls.append(t)
        return p[:, 0] - 0.05 if t < until else np.full(p.shape[0], 1e3)

    body = seed_box((0.06, 0.03, 0.02), (0.1, 0.07, 0.05), dx, ppc=2)
    sol = SandSolver(cpu, (8, 10, 16), dx, dt, SandParams(), body.x, body.volume,
                     sdf_collider=SdfCollider(wall, "separate", moving=True, moving_until=until))  # fmt: skip
    sol.step(10)
    # at construction (t = 0) and after steps 1..6 (t = 6 dt is the first sample at or after T)
    assert len(calls) == 7 and calls[-1] == pytest.approx(6 * dt) and calls[-2] < until
    assert float(sol.backend.to_host(sol._sdf).min()) > 1.0  # the wall is gone from the sampled SDF
    calls.clear()
    always = SandSolver(cpu, (8, 10, 16), dx, dt, SandParams(), body.x, body.volume,
                        sdf_collider=SdfCollider(wall, "separate", moving=True))  # fmt: skip
    always.step(10)
    assert len(calls) == 11
