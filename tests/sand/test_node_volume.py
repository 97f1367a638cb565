"""The node sand volume without a volume grid (SandSolver.node_volume): where every particle has one density ϱ,
V_i = Σ_p w_ip V_p = m_i / ϱ, so the P2G scatters no volume (4 B per node less) and the coupling reads the node
mass with the scale 1/ϱ; particles of another density make the solver keep the P2G's volume grid."""

from __future__ import annotations

import numpy as np
import pytest
from sand_states import DT, DX, SHAPE, particles

from couplekit.sand import DomainWalls, ReferenceOps, SandParams, SandSolver, seed_box


def _solver(backend, densities=None, shape=(20, 14, 16), dx=0.01):
    body = seed_box((0.03, 0.03, 0.03), (0.11, 0.09, 0.13), dx, ppc=2, jitter=0.5, seed=3)
    return SandSolver(
        backend, shape, dx, 1e-4, SandParams(), body.x, body.volume, densities=densities,
        walls=DomainWalls.uniform("separate", 0.5),
    )  # fmt: skip


def _reference_volume(s: SandSolver) -> np.ndarray:
    """Σ_p w_ip V_p of the solver's particles as they are (float64, Eq. 25's numerator)."""
    return s.seeded_volume()


@pytest.mark.parametrize("backend_name", ["numpy", "cpu"])
def test_one_density_keeps_no_volume_grid_and_gives_the_p2g_volume(backend_name):
    s = _solver(backend_name)
    assert s.grid_vol is None
    arr, scale = s.node_volume
    assert arr is s.grid_m and scale == pytest.approx(1.0 / s.params.density, rel=1e-15)
    s.p2g()
    want = _reference_volume(s)
    got = s.backend.to_host(arr).astype(np.float64) * scale
    assert np.abs(got - want).max() <= 1e-6 * want.max()
    assert s.fields()["sand_volume"] == pytest.approx(want.astype(np.float32), rel=1e-5, abs=1e-6 * want.max())


@pytest.mark.parametrize("backend_name", ["numpy", "cpu"])
def test_two_densities_keep_the_p2g_volume(backend_name):
    probe = _solver(backend_name)
    rho = np.where(np.arange(probe.n_particles) % 2 == 0, 1500.0, 900.0)
    s = _solver(backend_name, densities=rho)
    assert s.grid_vol is not None and s.node_volume == (s.grid_vol, 1.0)
    s.p2g()
    want = _reference_volume(s)
    got = s.backend.to_host(s.grid_vol).astype(np.float64)
    assert np.abs(got - want).max() <= 1e-6 * want.max()


def test_particles_of_another_density_switch_to_the_volume_grid_and_keep_the_node_volume():
    s = _solver("cpu")
    s.step(3)
    before = s.fields()["sand_volume"]
    s.append_particles(np.array([[0.05], [0.05], [0.15]]), 1e-6, densities=900.0)
    assert s.grid_vol is not None and s.node_volume[1] == 1.0
    np.testing.assert_allclose(s.fields()["sand_volume"], before, rtol=1e-6, atol=1e-12)  # until the next P2G
    s.p2g()
    want = _reference_volume(s)
    assert np.abs(s.backend.to_host(s.grid_vol).astype(np.float64) - want).max() <= 1e-6 * want.max()
    # the same density again keeps the one-density solver as it is
    t = _solver("cpu")
    t.append_particles(np.array([[0.05], [0.05], [0.15]]), 1e-6, densities=t.params.density)
    assert t.grid_vol is None


def test_a_state_with_two_densities_loads_into_a_one_density_solver():
    s = _solver("cpu")
    s.step(2)
    s.append_particles(np.array([[0.05], [0.05], [0.15]]), 1e-6, densities=900.0)
    s.step(2)
    st = s.state()
    assert {"grid_nodes", "grid_m", "grid_vol", "grid_v"} <= set(st)  # the state's format is one either way
    fresh = _solver("cpu")
    fresh.load_state(st, resize=True)
    assert fresh.grid_vol is not None
    np.testing.assert_array_equal(fresh.fields()["sand_volume"], s.fields()["sand_volume"])
    s.step(3)
    fresh.step(3)
    np.testing.assert_array_equal(fresh.particles()["x"], s.particles()["x"])
    # a state of another single density (another scene's sand) likewise
    c = _solver("cpu", densities=1.2 * SandParams().density)
    c.step(2)
    d = _solver("cpu")
    d.load_state(c.state())
    assert d.grid_vol is not None
    np.testing.assert_array_equal(d.fields()["sand_volume"], c.fields()["sand_volume"])
    d.p2g()
    want = _reference_volume(d)
    assert np.abs(d.backend.to_host(d.grid_vol).astype(np.float64) - want).max() <= 1e-6 * want.max()
    # and a one-density state into a one-density solver: no volume grid, the node volume from the loaded mass
    a = _solver("cpu")
    a.step(2)
    b = _solver("cpu")
    b.load_state(a.state())
    assert b.grid_vol is None
    np.testing.assert_array_equal(b.fields()["sand_volume"], a.fields()["sand_volume"])


def test_p2g_without_volume_matches_the_reference(cpu):
    from couplekit.sand import KernelOps

    p = particles(np.random.default_rng(11))
    out = []
    for ops in (KernelOps(cpu), ReferenceOps()):
        gm, gmv = np.full(SHAPE, np.nan, np.float32), np.full((3, *SHAPE), np.nan, np.float32)
        ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, None, DX, DT)
        out.append((gm, gmv))
    for k, r in zip(*out, strict=True):
        assert np.all(np.isfinite(k))
        rel = np.abs(k.astype(np.float64) - r).max() / np.abs(r).max()
        assert rel < 1e-5  # test_kernels_vs_reference.py's tolerance


def test_a_restart_after_sand_of_a_close_density_arrived_is_bitwise():
    """A density within 1e-5 of the solver's own: the mass over volume cannot tell it apart, the state's
    one_density (NaN once the volume grid was kept) can (probe, session 23: the restart had differed)."""
    s = _solver("cpu")
    s.step(2)
    s.append_particles(np.array([[0.05], [0.05], [0.15]]), 1e-6, densities=s.params.density * (1 + 1e-6))
    assert s.grid_vol is not None
    s.step(2)
    st = s.state()
    assert np.isnan(st["one_density"])
    fresh = _solver("cpu")
    fresh.load_state(st, resize=True)
    assert fresh.grid_vol is not None
    s.step(3)
    fresh.step(3)
    np.testing.assert_array_equal(fresh.particles()["x"], s.particles()["x"])


def test_a_refused_state_changes_nothing():
    s = _solver("cpu")
    s.step(2)
    st = s.state()
    st["grid_vol"] = st["grid_vol"][:-1]  # a damaged grid part
    t = _solver("cpu")
    x0, steps0 = t.particles()["x"].copy(), t.steps
    with pytest.raises(ValueError, match="does not fit"):
        t.load_state(st)
    assert t.steps == steps0 and np.array_equal(t.particles()["x"], x0)
    st = s.state()
    st["v"] = st["v"][:2]  # a particle field of the wrong shape
    with pytest.raises(ValueError, match="shape"):
        t.load_state(st)
    assert t.steps == steps0 and np.array_equal(t.particles()["x"], x0)


def test_a_mass_float32_cannot_hold_is_refused():
    with pytest.raises(ValueError, match="fit float32"):
        _solver("cpu", densities=1e300)
    s = _solver("cpu")
    with pytest.raises(ValueError, match="fit float32"):
        s.append_particles(np.array([[0.05], [0.05], [0.15]]), 1e-6, densities=1e300)
    assert s.grid_vol is None  # nothing changed
