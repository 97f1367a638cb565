"""Every sand kernel against its NumPy reference (couplekit.sand.reference) on random valid states.

Tolerances: the kernels compute in float32, the reference in float64 from the same float32 inputs.
* P2G sums 27 contributions per node from ~10 particles each: relative error vs the largest entry
  <= 1e-5 (float32 eps 6e-8 times the sum length and cancellation in the stress term; measured 5e-7).
* Grid update: one division and a few products per node: <= 1e-5 of the largest speed (measured 2e-7).
* G2P: v and C are 27-term gathers (<= 1e-5 relative, measured 2e-7 / 8e-7); F, tau, q, vc go through a
  float32 SVD, logs and exps: <= 1e-4 relative to their scale (measured 3e-6 .. 9e-6); positions are
  x + dt v with |dt v| << x: <= 1e-6 relative.
"""

from __future__ import annotations

import numpy as np
import pytest
from sand_states import DT, DX, SHAPE, grids, particles

from couplekit.sand import Collider, DomainWalls, SandParams, Wall
from couplekit.sand.boundaries import pack_colliders, pack_walls


@pytest.fixture(scope="module")
def kops(kernel_backend):
    """KernelOps on cpu and on cpu-device in turn: the host and the CUDA code paths of the sand kernels."""
    from couplekit.sand import KernelOps

    return KernelOps(kernel_backend)


def _rel(a, b):
    return float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64))) / max(np.max(np.abs(b)), 1e-30))


def test_p2g_matches_reference(kops, rops):
    p = particles(np.random.default_rng(2))
    out = []
    for ops in (kops, rops):
        gm, gmv, gvol = grids()
        gm[...] = np.nan  # the P2G must overwrite every node
        ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, gvol, DX, DT)
        out.append((gm, gmv, gvol))
    for k, r in zip(*out, strict=True):
        assert np.all(np.isfinite(k))
        assert _rel(k, r) < 1e-5


def test_host_atomic_p2g_matches_reference(cpu, rops):
    from couplekit.sand import KernelOps

    atomic = KernelOps(cpu, host_atomics=True)
    p = particles(np.random.default_rng(3))
    out = []
    for ops in (atomic, rops):
        gm, gmv, gvol = grids()
        ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, gvol, DX, DT)
        out.append((gm, gmv, gvol))
    for k, r in zip(*out, strict=True):
        assert _rel(k, r) < 1e-5


def _boundary_setup(rng):
    walls = DomainWalls.from_dict(
        {"-x": Wall("sticky"), "+x": Wall("slip"), "-z": Wall("separate", 0.5), "+z": Wall("separate")}
    )
    colliders = [
        Collider(
            "sphere", (0.07, 0.05, 0.06), (0.03,), "separate", 0.3, velocity=(0.1, 0, 0), angular_velocity=(0, 0, 2)
        ),
        Collider("box", (0.05, 0.05, 0.04), (0.02, 0.01, 0.02), "sticky", velocity=(0, 0.2, 0)),
        Collider("halfspace", (0, 0, 0.0312), (0.2, 0, 1), "slip"),  # no node exactly on the plane
        Collider("cylinder", (0.07, 0.05, 0.06), (0.045, 0.03), "separate", 0.2, inverted=True),
    ]
    sdf = (rng.random(SHAPE) - 0.3).astype(np.float32)
    sdf_params = np.array([2, 0.4, 0.1, 0.0, -0.1], np.float32)
    return walls, colliders, sdf, sdf_params


@pytest.mark.parametrize("in_place", [False, True], ids=["separate", "in_place"])
@pytest.mark.parametrize("with_sdf", [0, 1])
def test_grid_update_matches_reference(kops, rops, with_sdf, in_place):
    """Kernel = reference, with the velocity written to its own array or over the momentum (SandSolver's
    layout: grid_v is grid_mv); the momentum carries a random external impulse, as the coupling's is."""
    rng = np.random.default_rng(4)
    p = particles(rng)
    gm, gmv, gvol = grids()
    rops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, gvol, DX, DT)
    gmv += (DT * 1e-3 * rng.normal(size=(3, *SHAPE))).astype(np.float32)
    walls, colliders, sdf, sdf_params = _boundary_setup(rng)
    out = []
    for ops in (kops, rops):
        mv = gmv.copy()
        gv = mv if in_place else np.full((3, *SHAPE), np.nan, np.float32)
        ops.grid_update(
            gm,
            mv,
            gv,
            DX,
            DT,
            (0.0, -1.0, -9.81),
            walls.bound,
            pack_walls(walls),
            pack_colliders(colliders),
            len(colliders),
            sdf,
            with_sdf,
            sdf_params,
        )
        out.append(gv)
        if not in_place:
            np.testing.assert_array_equal(mv, gmv)  # the momentum is input only
    assert np.all(np.isfinite(out[0]))
    assert _rel(out[0], out[1]) < 1e-5
    # the boundary conditions did something: sticky -x wall nodes are at rest (the SDF collider, applied
    # after the walls, moves some of them at its own velocity)
    if not with_sdf:
        assert np.all(out[0][:, :, :, :2] == 0)


MODELS = {
    "sand": SandParams(cohesion_max=0.0),
    "sand_cohesive": SandParams(cohesion_max=2000.0),
    "sand_no_hardening": SandParams(hardening=False, h0=30.0, volume_correction=False),
    "sand_cohesive_no_hardening": SandParams(hardening=False, h0=30.0, cohesion_max=2000.0),
    "elastic": SandParams(plasticity=False, youngs_modulus=1e5),
    # the viscoplastic overstress (keep = 0.69 at DT = 1e-4 s; 1.5 Pa s is the Lube-calibrated sand's)
    "sand_viscous": SandParams(cohesion_max=0.0, viscosity=6.0),
    "sand_viscous_no_hardening": SandParams(hardening=False, h0=20.0, viscosity=1.5),
}


@pytest.mark.parametrize("name", list(MODELS))
def test_g2p_matches_reference(kops, rops, name):
    rng = np.random.default_rng(5)
    p = particles(rng)
    gm, gmv, gvol = grids()
    rops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, gvol, DX, DT)
    gv = (0.5 * rng.normal(size=(3, *SHAPE))).astype(np.float32)
    model = MODELS[name].model()
    keys = ("x", "v", "C", "F", "tau", "q", "vc")
    out = []
    # an effect off has no field (SandSolver allocates none): q None without hardening, the saturation None
    # without cohesion; both ops then take the variant that never touches it
    sat = p["saturation"] if model.cohesion else None
    for ops in (kops, rops):
        st = {k: p[k].copy() for k in keys}
        if not model.hardening:
            st["q"] = None
        ops.g2p(*(st[k] for k in keys), sat, gv, DX, DT, model)
        out.append(st)
    k, r = out
    if not model.hardening:
        k["q"] = r["q"] = np.zeros(1)
    assert _rel(k["v"], r["v"]) < 1e-5
    assert _rel(k["C"], r["C"]) < 1e-5
    assert _rel(k["x"], r["x"]) < 1e-6
    assert _rel(k["F"], r["F"]) < 1e-4
    assert _rel(k["tau"], r["tau"]) < 1e-4
    assert np.max(np.abs(k["q"] - r["q"])) < 1e-4 * max(1.0, np.abs(r["q"]).max())
    assert np.max(np.abs(k["vc"] - r["vc"])) < 1e-4


@pytest.mark.parametrize("name", list(MODELS))
def test_constitutive_kernel_matches_reference(kops, rops, name):
    rng = np.random.default_rng(6)
    n = 5000
    # trial F: rotations times stretches spanning compression, extension and shear
    q_rot, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q_rot *= np.sign(np.linalg.det(q_rot))[:, None, None]
    stretch = np.exp(rng.normal(scale=0.02, size=(n, 3)))
    F = (q_rot * stretch[:, None, :]) @ np.swapaxes(q_rot, 1, 2) @ (np.eye(3) + 0.01 * rng.normal(size=(n, 3, 3)))
    F = np.ascontiguousarray(F.reshape(n, 9).T.astype(np.float32))
    q = (8 * rng.random(n)).astype(np.float32)
    vc = (0.02 * rng.random(n)).astype(np.float32)
    sat = (0.4 * rng.random(n)).astype(np.float32)
    model = MODELS[name].model()
    out = []
    for ops in (kops, rops):
        st = [F.copy(), np.zeros((6, n), np.float32), q.copy() if model.hardening else None, vc.copy()]
        ops.constitutive(*st, sat if model.cohesion else None, model, DT)
        out.append(st)
    (Fk, tk, qk, vk), (Fr, tr, qr, vr) = out
    if not model.hardening:
        qk = qr = np.zeros(1)
    assert _rel(Fk, Fr) < 1e-4
    assert _rel(tk, tr) < 1e-4
    assert np.max(np.abs(qk - qr)) < 1e-4 * max(1.0, np.abs(qr).max())
    assert np.max(np.abs(vk - vr)) < 1e-5
