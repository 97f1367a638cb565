"""Every obstacle keeps its own friction (issue 15): the obstacles of a scene are one SDF collider whose friction
is sampled per grid node (the obstacle nearest the node), and the grid update (kernels/mpm_grid.cu and its NumPy
reference) reads it per node. Before, every obstacle got the largest friction of them all.

Sliding test: two floors side by side, friction 0 and 1, a sand block (2 cells thick) sliding along y at 0.5 m/s
on each, for 0.12 s. With μ = 1 the Coulomb friction of the floor's nodes removes μ |v_n| = μ g Δt of their
tangential speed per step; the nodes inside the floor carry about half the block's mass, so the block slows at
about μ g / 2 (measured: from 0.5 m/s to rest in 0.11 s, 2.6 cm). On the frictionless floor it slides on
(gravity is normal to the floor; measured 0.46 m/s after 0.12 s, 5.8 cm). With every obstacle at the largest
friction, as before, both blocks would stop.
"""

from __future__ import annotations

import numpy as np
import pytest
from sand_states import DT, DX, SHAPE, grids, particles

from couplekit.assembly import build_sand
from couplekit.backend import get_backend
from couplekit.sand import DomainWalls, SdfCollider, Wall
from couplekit.sand.boundaries import pack_colliders, pack_walls
from couplekit.scene import Scene

V0 = 0.5  # m/s along y


def two_floors(mu_a: float = 0.0, mu_b: float = 1.0) -> dict:
    """Floor A (x < 0.08 m, friction mu_a) and floor B (x >= 0.08 m, friction mu_b), top at z = 0.03 m, a sand
    block resting on each and moving along y at V0."""

    def block(x0):
        return {
            "kind": "sand",
            "velocity": [0.0, V0, 0.0],
            "geometry": {"type": "box", "min": [x0, 0.04, 0.03], "max": [x0 + 0.02, 0.08, 0.05]},
        }

    def floor(x0, x1, mu):
        return {
            "kind": "obstacle",
            "friction": mu,
            "geometry": {"type": "box", "min": [x0, -0.01, -0.01], "max": [x1, 0.25, 0.03]},
        }

    return {
        "scene": {"name": "two_floors"},
        "domain": {"size": [0.16, 0.24, 0.1], "dx": 0.01},
        "time": {"dt": 2e-4, "frame_duration": 0.01, "frames": 5},
        "sand": {"density": 1500.0, "youngs_modulus": 1e5, "cohesion": 0.0, "jitter": 0.0},
        "bodies": [block(0.03), block(0.11), floor(0.0, 0.08, mu_a), floor(0.08, 0.16, mu_b)],
        "outputs": {"preview": False},
    }


def _slide(backend: str, steps: int = 600, **frictions):
    scene = Scene.from_dict(two_floors(**frictions))
    sand, _ = build_sand(scene, get_backend(backend), lambda s: None)
    sand.step(steps)
    p = sand.particles()
    on_a = p["x"][0] < 0.08
    return p, on_a, sand


@pytest.fixture(scope="module")
def slid():
    """(particles, on floor A) after 0.12 s on the cpu kernels and on the NumPy reference."""
    return {name: _slide(name)[:2] for name in ("cpu", "numpy")}


def test_each_obstacle_keeps_its_friction(slid):
    p, on_a = slid["cpu"]
    assert 0 < on_a.sum() < on_a.size  # a block on each floor
    v_a, v_b = p["v"][1][on_a].mean(), p["v"][1][~on_a].mean()
    # frictionless floor: the block slides on (measured 0.46 m/s); μ = 1: it has stopped (measured -0.0015)
    assert v_a > 0.8 * V0, f"the block on the frictionless floor slowed to {v_a:.3f} m/s"
    assert abs(v_b) < 0.05 * V0, f"the block on the μ = 1 floor still moves at {v_b:.3f} m/s"
    travelled_a = p["x"][1][on_a].mean() - 0.06
    travelled_b = p["x"][1][~on_a].mean() - 0.06
    assert travelled_a > 0.8 * V0 * 0.12 and travelled_b < 0.5 * travelled_a  # measured 5.8 and 2.6 cm


def test_sliding_kernel_matches_reference(slid):
    """600 steps of the cpu kernels and of the NumPy reference: float32 against float64 (measured: 4e-5 m/s,
    8e-7 m apart)."""
    (pk, ak), (pr, ar) = slid["cpu"], slid["numpy"]
    np.testing.assert_array_equal(ak, ar)
    assert np.max(np.abs(pk["v"] - pr["v"])) < 1e-3
    assert np.max(np.abs(pk["x"] - pr["x"])) < 1e-5


def test_equal_frictions_need_no_field():
    """Obstacles of one friction make the plain collider of that friction (no per-node field, as before)."""
    _, _, sand = _slide("numpy", steps=0, mu_a=0.3, mu_b=0.3)
    assert sand._sdf_friction is None and float(sand._sdf_params[1]) == pytest.approx(0.3)
    _, _, sand = _slide("numpy", steps=0, mu_a=0.0, mu_b=1.0)
    mu = sand.backend.to_host(sand._sdf_friction)
    nz, ny, nx = mu.shape
    assert np.all(mu[:, :, : nx // 2] == 0.0) and np.all(mu[:, :, nx // 2 :] == 1.0)  # the nearest floor's


def test_union_samples_the_nearest_solids_friction():
    def plane(z0):  # solid below z = z0
        return lambda p, t: p[:, 2] - z0

    collider = SdfCollider.union([plane(0.1), plane(0.3)], [0.2, 0.7])
    pts = np.array([[0.0, 0.0, z] for z in (0.0, 0.2, 0.5)])
    phi, mu = collider.sample(pts, 0.0)
    np.testing.assert_allclose(phi, [-0.3, -0.1, 0.2])  # the union: the smaller SDF
    np.testing.assert_allclose(mu, [0.7, 0.7, 0.7])  # the second solid is nearest (deeper) everywhere
    collider = SdfCollider.union([plane(0.3), lambda p, t: 0.25 - p[:, 2]], [0.2, 0.7])  # below 0.3, above 0.25
    _, mu = collider.sample(pts, 0.0)
    np.testing.assert_allclose(mu, [0.2, 0.2, 0.7])
    with pytest.raises(ValueError, match="one friction per solid"):
        SdfCollider.union([plane(0.1)], [0.1, 0.2])
    with pytest.raises(ValueError, match=">= 0"):
        SdfCollider.union([plane(0.1), plane(0.2)], [0.1, -0.2])


@pytest.mark.parametrize("per_node", [False, True])
def test_grid_update_with_node_friction_matches_reference(kops, rops, per_node):
    """One grid update on a random state with a random SDF and a random per-node friction in [0, 1.5] (half the
    nodes frictionless): kernel == reference to 1e-5 of the largest speed, as the other grid-update tests."""
    rng = np.random.default_rng(15)
    p = particles(rng)
    gm, gmv, gvol = grids()
    rops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], gm, gmv, gvol, DX, DT)
    gmv += (DT * 1e-3 * rng.normal(size=(3, *SHAPE))).astype(np.float32)  # an external impulse, as the coupling's
    walls = DomainWalls.from_dict({"-z": Wall("separate", 0.5)})
    sdf = (rng.random(SHAPE) - 0.3).astype(np.float32)
    sdf_params = np.array([2, 0.4, 0.1, 0.0, -0.1], np.float32)
    mu = np.where(rng.random(SHAPE) < 0.5, 0.0, 1.5 * rng.random(SHAPE)).astype(np.float32)
    out = []
    for ops in (kops, rops):
        gv = np.full((3, *SHAPE), np.nan, np.float32)
        ops.grid_update(
            gm, gmv, gv, DX, DT, (0.0, -1.0, -9.81), walls.bound, pack_walls(walls), pack_colliders([]), 0,
            sdf, 1, sdf_params, sdf_friction=mu if per_node else None,
        )  # fmt: skip
        out.append(gv)
    assert np.all(np.isfinite(out[0]))
    scale = float(np.max(np.abs(out[1])))
    assert float(np.max(np.abs(out[0].astype(np.float64) - out[1]))) < 1e-5 * scale
    if per_node:  # the field is read: the result differs from the one friction of sdf_params
        one = np.full((3, *SHAPE), np.nan, np.float32)
        rops.grid_update(
            gm, gmv, one, DX, DT, (0.0, -1.0, -9.81), walls.bound, pack_walls(walls), pack_colliders([]), 0,
            sdf, 1, sdf_params,
        )  # fmt: skip
        assert float(np.max(np.abs(one - out[1]))) > 1e-3 * scale
