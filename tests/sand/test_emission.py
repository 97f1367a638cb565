"""Sand emitted at inflows (couplekit.sand.emission) and SandSolver.append_particles: growing the particle set
is the same as building with it, the emitted count and volume are s·A·u_n·t to within one layer, emitted
particles move with the inflow, the layers form a regular sub-lattice and the jet's sand fraction is s."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.sand import DomainWalls, SandParams
from couplekit.sand.emission import InflowEmitter, JetSource, emission_sites, expected_particles
from couplekit.sand.seeding import seed_box
from couplekit.sand.solver import SandSolver, TimeStepError

SHAPE = (16, 12, 20)  # (nz, ny, nx)
DX, DT = 0.01, 2e-4
PARAMS = SandParams(youngs_modulus=1e5, density=2000.0)


def _solver(be, x=None, vol=1e-7, v=None, gravity=(0.0, 0.0, -9.81), **kw) -> SandSolver:
    x = np.zeros((3, 0)) if x is None else x
    return SandSolver(be, SHAPE, DX, DT, PARAMS, x, vol, velocities=v, gravity=gravity, allow_empty=True, **kw)


def _state_bytes(sol: SandSolver) -> dict[str, bytes]:
    st = sol.state()
    return {k: np.asarray(a).tobytes() for k, a in st.items() if k not in ("time", "steps")}


@pytest.mark.parametrize("backend", ["cpu", "numpy"])
def test_append_is_the_same_as_building_with_the_particles(cpu, backend):
    """A solver grown by append_particles (to an empty one, then to a non-empty one) steps bitwise like one
    built with all the particles: the new particles get exactly the reference state a seeded body gets
    (F = I, C = 0, τ = 0, q = 0), and nothing else in the solver depends on how the arrays grew (cpu: the
    deterministic P2G; numpy: the reference)."""
    be = cpu if backend == "cpu" else get_backend("numpy")
    a = seed_box((0.05, 0.04, 0.06), (0.09, 0.08, 0.09), DX, ppc=2, jitter=0.5, seed=1)
    b = seed_box((0.11, 0.04, 0.06), (0.14, 0.07, 0.10), DX, ppc=2, jitter=0.5, seed=2)
    va, vb = np.array([0.2, 0.0, -0.1]), np.array([-0.3, 0.1, 0.0])
    both = np.concatenate([a.x, b.x], axis=1)
    vel = np.concatenate([np.repeat(va[:, None], a.count, 1), np.repeat(vb[:, None], b.count, 1)], axis=1)
    dens = np.concatenate([np.full(a.count, 2000.0), np.full(b.count, 1500.0)])
    built = SandSolver(be, SHAPE, DX, DT, PARAMS, both, 6e-8, velocities=vel, densities=dens)
    grown = _solver(be)
    assert grown.n_particles == 0 and grown.min_density == PARAMS.density
    grown.step(2)  # an empty solver steps: empty grid, time advances
    assert grown.steps == 2 and float(be.to_host(grown.grid_m).sum()) == 0.0
    assert grown.append_particles(a.x, 6e-8, va, 2000.0) == 0
    assert grown.append_particles(b.x, 6e-8, vb, 1500.0) == a.count
    assert grown.n_particles == a.count + b.count and grown.min_density == 1500.0
    built.step(6)
    grown.step(6)
    sa, sb = _state_bytes(built), _state_bytes(grown)
    assert sa.keys() == sb.keys()
    for k in sa:
        assert sa[k] == sb[k], k


def test_append_refuses_particles_outside_and_a_time_step_it_breaks(cpu):
    sol = _solver(cpu)
    with pytest.raises(ValueError, match="outside the domain interior"):
        sol.append_particles(np.array([[0.015], [0.05], [0.05]]), 1e-7)  # x < 2 dx: in the wall band
    # lighter grains raise the P-wave speed: dt at 0.9 of the 2000 kg/m³ limit breaks the 1000 kg/m³ one
    limit = 0.5 * DX / PARAMS.p_wave_speed
    tight = SandSolver(cpu, SHAPE, DX, 0.9 * limit, PARAMS, np.zeros((3, 0)), 1e-7, allow_empty=True)
    with pytest.raises(TimeStepError, match="exceeds the stability limit"):
        tight.append_particles(np.array([[0.05], [0.05], [0.05]]), 1e-7, densities=1000.0)
    assert tight.n_particles == 0 and tight.min_density == PARAMS.density  # unchanged
    with pytest.raises(ValueError, match="no particles"):
        SandSolver(cpu, SHAPE, DX, DT, PARAMS, np.zeros((3, 0)), 1e-7)  # allow_empty defaults to False


def _source(face="x-", velocity=(0.7, 0.0, 0.2), s=0.25, k=2, mask=None) -> JetSource:
    sites = emission_sites(SHAPE, DX, face, mask, k)
    axis = "xyz".index(face[0])
    return JetSource(face, sites, velocity, s, DX / k, 2 * DX, 2000.0, SHAPE[2 - axis] * DX)


@pytest.mark.parametrize(
    ("face", "velocity", "k", "steps"),
    [("x-", (0.7, 0.0, 0.2), 2, 173), ("z+", (0.1, 0.0, -1.3), 3, 91), ("y+", (0.0, -0.45, 0.0), 1, 260)],
)
def test_emitted_count_and_volume_match_the_flux_within_one_layer(face, velocity, k, steps):
    """After N steps the emitted sand volume is s A_e u_n N Δt to within one layer (s A_e h), its particle
    count sites × floor(u_n t / h) (the last, incomplete layer is not emitted yet), every emitted particle
    carries s h³ and ϱ s h³ and starts h/2 + less than u_n Δt inside the emission plane."""
    src = _source(face, velocity, 0.25, k)
    be = get_backend("numpy")
    sol = _solver(be)
    em = InflowEmitter([src])
    for _ in range(steps):
        em.advance(sol, DT)  # the sand does not move here: only the emission is checked
    t = steps * DT
    h, n_sites = DX / k, src.sites.shape[1]
    # a whole face less the 2-cell rim of the MPM walls: (nx-4)(nz-4) cells etc., k² sites each
    plane = {"x": (SHAPE[0], SHAPE[1]), "y": (SHAPE[0], SHAPE[2]), "z": (SHAPE[1], SHAPE[2])}[face[0]]
    assert n_sites == (plane[0] - 4) * (plane[1] - 4) * k * k
    u_n = abs(velocity["xyz".index(face[0])])
    expected = src.sand_fraction * src.area * u_n * t
    volume = float(be.to_host(sol.volume).astype(np.float64).sum())
    assert abs(volume - expected) <= src.sand_fraction * src.area * h * (1 + 1e-6)
    assert volume == pytest.approx(em.emitted_volume(), rel=1e-6)
    assert sol.n_particles == n_sites * math.floor(u_n * t / h + 1e-9) == em.emitted_particles()
    assert sol.n_particles <= expected_particles(em, t)
    p = sol.particles()
    np.testing.assert_allclose(p["volume"], src.sand_fraction * h**3, rtol=1e-6)
    np.testing.assert_allclose(p["mass"], 2000.0 * src.sand_fraction * h**3, rtol=1e-6)
    axis = "xyz".index(face[0])
    depth = p["x"][axis] - 2 * DX if face[1] == "-" else (SHAPE[2 - axis] - 2) * DX - p["x"][axis]
    # every layer's centre lies h/2 + (how far the jet had gone past the layer when it was emitted, < u_n Δt)
    # inside the emission plane (the sand does not move here, so the layers are not yet h apart)
    assert np.all(depth >= 0.5 * h - 1e-6 * DX) and np.all(depth <= 0.5 * h + u_n * DT + 1e-6 * DX)
    assert np.all(depth.reshape(-1, n_sites) == depth.reshape(-1, n_sites)[:, :1])


def test_emitted_particles_move_with_the_inflow_in_their_reference_state(cpu):
    """Every emitted particle starts with the inflow velocity (all three components), F = I, C = 0, τ = 0, no
    hardening, saturation 0; the sites fill the outlet's cells (k² per cell), inside the face."""
    mask = np.zeros((SHAPE[0], SHAPE[1]), bool)  # x face: (nz, ny)
    mask[5:8, 4:8] = True  # 3 (z) x 4 (y) cells
    src = _source("x-", (0.9, 0.05, -0.1), 0.3, 2, mask)
    assert src.sites.shape[1] == 12 * 4
    lo, hi = src.sites.min(axis=1), src.sites.max(axis=1)
    np.testing.assert_allclose(lo, [4 * DX + DX / 4, 5 * DX + DX / 4])
    np.testing.assert_allclose(hi, [8 * DX - DX / 4, 8 * DX - DX / 4])
    sol = _solver(cpu)
    em = InflowEmitter([src])
    for _ in range(40):
        sol.step(1)
        em.advance(sol, DT)
        if sol.n_particles:
            break
    p = sol.particles()
    assert p["x"].shape[1] == 48
    np.testing.assert_array_equal(p["v"], np.float32(np.array(src.velocity))[:, None] + np.zeros((3, 48), np.float32))
    np.testing.assert_array_equal(p["F"], np.repeat(np.eye(3, dtype=np.float32).reshape(9, 1), 48, axis=1))
    for k in ("C", "tau", "q", "vc", "saturation"):
        assert not np.any(p[k]), k


def test_a_jet_is_a_regular_lattice_of_sand_fraction_s(cpu):
    """Without gravity a jet of sand translates rigidly (every node of a particle's stencil has mass and the
    velocity u, F stays I), so after many steps the layers stay h apart along the jet and the sand fraction of
    Eq. 25 at nodes whose stencil lies inside the jet is s: a sub-lattice of spacing dx/k with particle volume
    s (dx/k)³ gives Σ_p V_p w_ip / dx³ = s exactly (the quadratic B-spline is a partition of unity along each
    axis, sampled k times per cell). Tolerances: float32 positions advected 300 steps (|x| < 0.2 m, half an
    ulp 7.5e-9 m per step: 2.3e-6 m, bound 4e-6 m); ε a float32 sum of ≤ 27·8 terms: 1e-5 relative."""
    s, k, u = 0.2, 2, 2.0
    mask = np.zeros((SHAPE[0], SHAPE[1]), bool)
    mask[4:10, 3:9] = True  # 6 x 6 cells
    src = _source("x-", (u, 0.0, 0.0), s, k, mask)
    sol = _solver(cpu, gravity=(0.0, 0.0, 0.0), walls=DomainWalls.uniform("separate", 0.0))
    em = InflowEmitter([src])
    n = 300  # the front travels 12 cells
    for _ in range(n):
        sol.step(1)
        em.advance(sol, DT)
    h = DX / k
    p = sol.particles()
    depth = p["x"][0].astype(np.float64) - 2 * DX
    newest = 0.5 * h + em.length[0]
    j = np.round((depth - newest) / h)
    assert np.max(np.abs(depth - newest - j * h)) < 4e-6
    np.testing.assert_allclose(p["v"][0], u, rtol=1e-5)
    assert np.max(np.abs(p["F"] - np.eye(3).reshape(9, 1))) < 1e-5
    sol.p2g()
    eps = sol.fields()["sand_fraction"]  # (nz, ny, nx)
    centres = (np.arange(SHAPE[2]) + 0.5) * DX
    x_lo, x_hi = 2 * DX + newest - 0.5 * h, 2 * DX + depth.max() + 0.5 * h
    inside_x = (centres - 1.5 * DX >= x_lo - 1e-9) & (centres + 1.5 * DX <= x_hi + 1e-9)
    assert inside_x.sum() >= 6  # nodes along the jet checked
    core = eps[5:9, 4:8][:, :, inside_x]  # nodes 1.5 cells inside the 6 x 6-cell jet
    np.testing.assert_allclose(core, s, rtol=1e-5)


def test_a_jet_that_starts_clean_and_ramps_up_its_sand():
    """sand_start / sand_ramp: no particle before the start; each layer's particles carry s(t) h³ with
    s(t) = s (t − start) / ramp at the step that completed the layer, then s; the volume emitted is
    ∫ s(t) A_e u_n dt to within one full layer (s A_e h), since each layer's s is that of its last step."""
    start, ramp, s, u = 0.01, 0.02, 0.3, 0.8
    src = dataclasses.replace(_source("x-", (u, 0.0, 0.0), s), start=start, ramp=ramp)
    sol = _solver(get_backend("numpy"))
    em = InflowEmitter([src])
    n_start = int(start / DT)
    for _ in range(n_start - 1):
        em.advance(sol, DT)
    assert sol.n_particles == 0 and em.length[0] > 0
    n = 300  # t = 0.06 s: the ramp ends at 0.03 s
    for _ in range(n - n_start + 1):
        em.advance(sol, DT)
    t = n * DT
    integral = s * ((t - start) - 0.5 * ramp)  # ∫ s(t) dt
    expected = src.area * u * integral
    assert abs(em.emitted_volume() - expected) <= s * src.area * src.spacing
    vol = sol.particles()["volume"].astype(np.float64).reshape(-1, src.sites.shape[1])[:, 0]
    assert np.all(np.diff(vol) >= -1e-12 * vol.max()) and vol[0] < 0.2 * s * src.spacing**3
    np.testing.assert_allclose(vol[-1], s * src.spacing**3, rtol=1e-6)
    np.testing.assert_allclose(vol.sum() * src.sites.shape[1], em.emitted_volume(), rtol=1e-6)


def test_emitter_state_restores_the_accumulators():
    src = _source()
    em = InflowEmitter([src])
    sol = _solver(get_backend("numpy"))
    for _ in range(7):
        em.advance(sol, DT)
    other = InflowEmitter([src])
    other.load_state(em.state())
    assert other.length.tobytes() == em.length.tobytes() and (other.layers == em.layers).all()
    assert other.volume.tobytes() == em.volume.tobytes() and other.steps == em.steps == 7
    with pytest.raises(ValueError, match="sources"):
        InflowEmitter([src, src]).load_state(em.state())
