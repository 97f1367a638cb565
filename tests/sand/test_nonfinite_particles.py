"""A particle whose position or velocity is not finite never makes a kernel read or write outside the grid, and
stays visibly non-finite (never scrubbed into a valid-looking number), so the simulation's finiteness check
names it: the sand kernels and the coupling's particle kernels against their NumPy references on states with
NaN and Inf particles, and a run with one NaN velocity."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from sand_states import DT, DX, SHAPE, grids, particles

from couplekit.coupling import CouplingParams
from couplekit.coupling import KernelOps as CouplingKernelOps
from couplekit.coupling import ReferenceOps as CouplingReferenceOps
from couplekit.sand import SandParams
from couplekit.scene import Scene
from couplekit.simulation import Simulation, SimulationDiverged

sys.path.insert(0, str(Path(__file__).parents[1] / "scene"))
from sim_scenes import tiny_coupled, tiny_sand  # noqa: E402

BAD = {3: np.nan, 5: np.inf, 8: -np.inf}
"""Particle -> the value its x coordinate gets."""


def _poisoned(rng):
    p = particles(rng, n=400)
    for i, value in BAD.items():
        p["x"][0, i] = value
    p["x"][2, 11] = np.nan  # a NaN in another coordinate
    return p


def _rel(a, b):
    ok = np.isfinite(b)
    return float(np.max(np.abs(a[ok].astype(np.float64) - b[ok])) / max(np.max(np.abs(b[ok])), 1e-30))


def test_p2g_skips_non_finite_particles(kops, rops):
    """Kernel and reference scatter nothing for the poisoned particles: the grid equals the grid of the other
    particles alone, and every node is finite."""
    p = _poisoned(np.random.default_rng(1))
    keep = np.isfinite(p["x"]).all(axis=0)
    grids_out = []
    for ops, sel in ((kops, slice(None)), (rops, slice(None)), (rops, keep)):
        gm, gmv, gvol = grids()
        ops.p2g(*(p[k][..., sel] for k in ("x", "v", "C", "tau", "mass", "volume")), gm, gmv, gvol, DX, DT)
        grids_out.append((gm, gmv, gvol))
    for k, r, alone in zip(*grids_out, strict=True):
        assert np.isfinite(k).all() and np.isfinite(r).all()
        assert _rel(k, r) < 1e-5 and _rel(r, alone) < 1e-12
    assert kops.skipped_particles() == len(BAD) + 1


@pytest.mark.parametrize("field", ["x", "v"])
def test_g2p_keeps_non_finite_particles_non_finite(kops, rops, field):
    """A NaN/Inf position gathers nothing (no wild index: the host build crashed here) and leaves v, C and the
    position NaN in kernel and reference alike; the G2P clamp once turned such a position into the domain's
    corner. A NaN velocity alone is overwritten by the gather (v comes from the grid) — it is P2G that spreads
    it, tested through a run below. The finite particles match the reference as in
    tests/sand/test_kernels_vs_reference.py."""
    rng = np.random.default_rng(2)
    p = _poisoned(rng) if field == "x" else particles(rng, n=400)
    gv = (0.5 * rng.normal(size=(3, *SHAPE))).astype(np.float32)
    model = SandParams(cohesion_max=0.0).model()
    keys = ("x", "v", "C", "F", "tau", "q", "vc")
    out = []
    for ops in (kops, rops):
        st = {k: p[k].copy() for k in keys}
        ops.g2p(*(st[k] for k in keys), p["saturation"], gv, DX, DT, model)
        out.append(st)
    k, r = out
    bad = ~np.isfinite(p["x"]).all(axis=0)
    for name in ("x", "v"):
        assert np.array_equal(~np.isfinite(k[name]).all(axis=0), bad), name
        assert np.array_equal(~np.isfinite(r[name]).all(axis=0), bad), name
        assert _rel(k[name][:, ~bad], r[name][:, ~bad]) < 1e-5
    assert not np.isfinite(k["C"][:, bad]).any()


def test_coupling_particle_kernels_skip_non_finite_particles(cpu):
    """Bound-water P2G (Eq. 53) and the moisture gather (Eqs. 58, 59) with NaN/Inf particles: nothing is read or
    written for them (kernel == reference), their saturation is NaN and their moisture ratio unchanged."""
    rng = np.random.default_rng(3)
    p = _poisoned(rng)
    params = CouplingParams(retention=True)
    kops, rops = CouplingKernelOps(cpu, params, two_phase=True), CouplingReferenceOps(params, two_phase=True)
    r0 = (0.05 * rng.random(p["x"].shape[1])).astype(np.float32)
    eps_fluid = rng.random(tuple(n + 2 for n in SHAPE)).astype(np.float32)  # the water fraction's inputs
    phi = rng.random(eps_fluid.shape).astype(np.float32)
    d_bound = (1e-3 * rng.random(SHAPE)).astype(np.float32)
    grid_vol = (0.3 * DX**3 * (0.5 + rng.random(SHAPE))).astype(np.float32)
    results = []
    for ops in (kops, rops):
        bound = np.zeros(SHAPE, np.float32)
        ops.bound_water_p2g(p["x"], r0, p["volume"], bound, DX)
        r, sat = r0.copy(), np.zeros_like(r0)
        ops.particle_moisture(p["x"], r, sat, eps_fluid, phi, bound, d_bound, grid_vol, DX)
        results.append((bound, r, sat))
    (kb, kr, ks), (rb, rr, rs) = results
    bad = ~np.isfinite(p["x"]).all(axis=0)
    assert np.isfinite(kb).all() and _rel(kb, rb) < 1e-5
    assert np.isnan(ks[bad]).all() and np.isnan(rs[bad]).all() and _rel(ks[~bad], rs[~bad]) < 1e-5
    assert np.array_equal(kr[bad], r0[bad]) and _rel(kr, rr) < 1e-5


@pytest.mark.parametrize("scene", [tiny_sand, tiny_coupled], ids=["sand", "coupled"])
def test_one_nan_velocity_is_caught_and_named(scene):
    """One particle's velocity set to NaN after two steps: three more steps spread it (P2G carries it to the
    grid, G2P to the neighbours) and the finiteness check names a sand field; no particle is moved into the
    clamp's corner (the run once ended "done" with 521 particles there)."""
    sim = Simulation(Scene.from_dict(scene()), backend="cpu", threads=1, log=None)
    sim.step(2)
    v = sim.backend.to_host(sim.sand.v).copy()
    v[:, 0] = np.nan
    sim.sand.v = sim.backend.asarray(v, np.float32)
    sim.step(3)
    with pytest.raises(SimulationDiverged) as err:
        sim.check_finite()
    assert err.value.solver in ("sand", "fluid")
    x = sim.particles()["x"].astype(np.float64)
    corner = np.isclose(x, sim.scene.domain.dx).all(axis=0)
    assert not corner.any()


@pytest.mark.parametrize("backend", ["cpu", "numpy"])
@pytest.mark.parametrize("dx", [0.005, 0.004, 0.003])
def test_a_bed_on_the_clamp_is_not_taken_for_lost(backend, dx):
    """With sand.wall_layers = 1 a slumping block reaches G2P's clamp at the floor, x = dx: the float32 x/dx − ½
    there fell just under ½, the stencil test failed, and the particle was poisoned as lost (NaN at step 377 for
    dx = 0.005; the probe's scene). The clamp's lower bound now sits at dx (1 + 1e-6), as its upper one sits below
    (n − 1) dx: 450 steps finite, none lost, the bed down on the floor (on the bound at dx = 0.005 and 0.004,
    within 3 % of a cell above it at 0.003, measured), at three grid spacings."""
    scene = Scene.from_dict(
        {
            "scene": {"name": "bed_on_the_clamp"},
            "domain": {"size": [20 * dx, 20 * dx, 20 * dx], "dx": dx},
            "time": {"dt": 1e-4 * dx / 0.005, "frame_duration": 1e-3},
            "sand": {"density": 1500.0, "youngs_modulus": 3.537e5, "wall_layers": 1},
            "bodies": [{"kind": "sand", "geometry": {"type": "box", "min": [dx] * 3, "max": [7 * dx] * 3}}],
            "outputs": {"preview": False},
        }
    )
    sim = Simulation(scene, backend, log=None)
    for _ in range(3):
        sim.step(150)
        x = sim.particles()["x"]
        assert np.isfinite(x).all() and np.isfinite(sim.particles()["v"]).all()
    assert x[2].min() < 1.05 * dx  # the bed is down at the bound
    assert (x >= dx).all()
