"""Transfers: B-spline partition of unity and first moment; P2G -> grid -> G2P conserves mass and linear
momentum; APIC keeps a rigid rotation (velocity, affine matrix, angular momentum).  Kernel (cpu) ops."""

from __future__ import annotations

import numpy as np
from sand_states import DX, SHAPE, grids, particles

from couplekit.sand import DomainWalls, SandParams
from couplekit.sand.boundaries import pack_colliders, pack_walls
from couplekit.sand.reference import bspline_weights


def test_bspline_partition_of_unity_and_first_moment():
    X = np.random.default_rng(8).uniform(0.5, 20.0, 100000)
    base, w, d = bspline_weights(X)
    assert np.all(w >= 0)
    assert np.max(np.abs(w.sum(axis=1) - 1)) < 1e-14
    assert np.max(np.abs((w * d).sum(axis=1))) < 1e-14
    # second moment = 1/4 cell^2: the APIC D_p = dx^2/4 I used by C = 4/dx^2 B
    assert np.max(np.abs((w * d**2).sum(axis=1) - 0.25)) < 1e-14


def test_kernel_weights_partition_of_unity_and_first_moment(kops):
    """Through the P2G kernel: unit masses give sum_i m_i = P; with v = 0, C = I, tau = 0 the node
    momentum is sum_p w_ip (x_i - x_p), whose total must vanish (float32: <= 1e-6 * dx * P)."""
    p = particles(np.random.default_rng(9), n=3000)
    n = p["x"].shape[1]
    gm, gmv, gvol = grids()
    ones = np.ones(n, np.float32)
    C = np.zeros((9, n), np.float32)
    C[[0, 4, 8]] = 1.0
    kops.p2g(p["x"], np.zeros((3, n), np.float32), C, np.zeros((6, n), np.float32), ones, ones, gm, gmv, gvol, DX, 0.0)
    assert abs(gm.sum(dtype=np.float64) - n) < 1e-5 * n
    assert np.max(np.abs(gmv.reshape(3, -1).sum(axis=1, dtype=np.float64))) < 1e-6 * DX * n


def _no_walls():
    walls = DomainWalls.uniform("separate", 0.0)
    return walls.bound, pack_walls(walls), pack_colliders([])


def test_transfer_conserves_mass_and_momentum(kops):
    """With stress and no gravity/walls, P2G + grid update + G2P keeps sum m v (the stress impulse is
    internal: sum_i w_ip (x_i - x_p) = 0).  float32 sums of ~1e5 terms: 1e-5 of sum m|v|."""
    rng = np.random.default_rng(10)
    p = particles(rng)
    gm, gmv, gvol = grids()
    p0 = (p["mass"] * p["v"]).sum(axis=1, dtype=np.float64)
    scale = (p["mass"] * np.abs(p["v"])).sum(dtype=np.float64)
    kops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, gvol, DX, 1e-4)
    assert abs(gm.sum(dtype=np.float64) - p["mass"].sum(dtype=np.float64)) < 1e-6 * p["mass"].sum()
    assert np.max(np.abs(gmv.reshape(3, -1).sum(axis=1, dtype=np.float64) - p0)) < 1e-5 * scale
    gv = np.zeros((3, *SHAPE), np.float32)
    bound, walls, cols = _no_walls()
    # particles stay >= 2 cells from the faces, but their stencils reach the wall layer: no wall mass moves
    kops.grid_update(
        gm,
        gmv,
        gv,
        DX,
        1e-4,
        (0.0, 0.0, 0.0),
        1,
        walls,
        cols,
        0,
        np.zeros(1, np.float32),
        0,
        np.zeros(5, np.float32),
    )
    model = SandParams().model()
    st = {k: p[k].copy() for k in ("x", "v", "C", "F", "tau", "q", "vc")}
    kops.g2p(*st.values(), p["saturation"], gv, DX, 1e-4, model)
    p1 = (p["mass"] * st["v"]).sum(axis=1, dtype=np.float64)
    assert np.max(np.abs(p1 - p0)) < 1e-5 * scale


def test_apic_preserves_rigid_rotation(kops):
    """v_p = omega x (x_p - c), C_p = [omega]_x: APIC with quadratic B-splines reproduces affine fields
    exactly, so after P2G -> G2P (dt = 0: no motion, no stress) v_p and C_p come back and the angular
    momentum L = sum m x x v + sum m (dx^2/4) axial(C - C^T) is unchanged (float32: 1e-5 relative)."""
    rng = np.random.default_rng(11)
    p = particles(rng, n=3000)
    n = p["x"].shape[1]
    omega = np.array([0.3, -1.2, 2.0])
    centre = p["x"].astype(np.float64).mean(axis=1)
    r = p["x"].astype(np.float64) - centre[:, None]
    v = np.ascontiguousarray(np.cross(omega, r.T).T, dtype=np.float32)
    W = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    C = np.repeat(W.reshape(9, 1), n, axis=1).astype(np.float32)
    m = p["mass"]
    gm, gmv, gvol = grids()
    kops.p2g(p["x"], v, C, np.zeros((6, n), np.float32), m, p["volume"], gm, gmv, gvol, DX, 0.0)
    gv = np.zeros((3, *SHAPE), np.float32)
    bound, walls, cols = _no_walls()
    kops.grid_update(
        gm,
        gmv,
        gv,
        DX,
        0.0,
        (0.0, 0.0, 0.0),
        1,
        walls,
        cols,
        0,
        np.zeros(1, np.float32),
        0,
        np.zeros(5, np.float32),
    )
    st = {
        "x": p["x"].copy(),
        "v": np.zeros_like(v),
        "C": np.zeros_like(C),
        "F": p["F"].copy(),
        "tau": np.zeros((6, n), np.float32),
        "q": p["q"].copy(),
        "vc": p["vc"].copy(),
    }
    kops.g2p(*st.values(), p["saturation"], gv, DX, 0.0, SandParams(plasticity=False).model())
    vmax = np.abs(v).max()
    assert np.max(np.abs(st["v"] - v)) < 1e-5 * vmax
    assert np.max(np.abs(st["C"] - C)) < 1e-4 * np.abs(W).max()

    def angular(vel, Cm):
        spin = (Cm.reshape(3, 3, -1) - Cm.reshape(3, 3, -1).transpose(1, 0, 2)) / 2
        axial = np.stack([spin[2, 1], spin[0, 2], spin[1, 0]])
        return (m * np.cross(p["x"].astype(np.float64).T, vel.astype(np.float64).T).T).sum(axis=1) + (
            m * DX**2 / 4 * axial * 2
        ).sum(axis=1)

    L0, L1 = angular(v, C), angular(st["v"], st["C"])
    assert np.max(np.abs(L1 - L0)) < 1e-5 * np.abs(L0).max()
